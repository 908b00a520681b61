# The tracker's request decoder on arbitrary datagrams. Seeds are written by make_fuzz_corpus with the
# uplink's own encoders (requests, track frames, snapshots, health, hostile variants).
lrfnet_fuzz_target(request_fuzz SOURCES request_fuzz.cc LIBS lrfnet_uplink)
if(TARGET make_fuzz_corpus)
  target_link_libraries(make_fuzz_corpus PRIVATE lrfnet_uplink)
endif()
