# TCP reassembler on arbitrary segment sequences; packet parser on arbitrary frames. Input formats and
# the seed writer (capture_seeds.cc, compiled into make_fuzz_corpus) are described in capture_seeds.h.
lrfnet_fuzz_target(reassembler_fuzz SOURCES reassembler_fuzz.cc LIBS lrfnet_capture)
lrfnet_fuzz_target(packet_fuzz SOURCES packet_fuzz.cc LIBS lrfnet_capture)
