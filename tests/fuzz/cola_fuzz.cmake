# Framer + telegram header + scan decoder on arbitrary bytes. The seed writer (cola_seeds.cc) is
# compiled into make_fuzz_corpus.
lrfnet_fuzz_target(cola_fuzz SOURCES cola_fuzz.cc LIBS lrfnet_cola)
