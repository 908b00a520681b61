# The daemon's parsers: the ingest's datagram decoder and validation (datagram_fuzz), and the
# recording / UDP capture reader (recording_fuzz). Seeds: daemon_seeds.h, written by make_fuzz_corpus.
lrfnet_fuzz_target(datagram_fuzz SOURCES datagram_fuzz.cc LIBS lrfnet_daemon_ingest)
lrfnet_fuzz_target(recording_fuzz SOURCES recording_fuzz.cc LIBS lrfnet_daemon_io)
# The authenticated envelope: the daemon's verifier with and without keys, the tracker's request
# decoder with keys (tests/fuzz/auth_fuzz_keys.h).
lrfnet_fuzz_target(auth_fuzz SOURCES auth_fuzz.cc LIBS lrfnet_daemon_ingest lrfnet_uplink)
if(TARGET make_fuzz_corpus)
  target_sources(make_fuzz_corpus PRIVATE datagram_seeds.cc recording_seeds.cc auth_seeds.cc)
  target_link_libraries(make_fuzz_corpus PRIVATE lrfnet_daemon_ingest lrfnet_daemon_io lrfnet_uplink)
endif()
