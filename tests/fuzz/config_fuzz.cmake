# The files an operator writes: the tracker's and the daemon's config, simulator scenarios, key files
# and a calibration.yaml's history (config_fuzz.cc). Ordinary build only: its readers live in the
# tracker's and the daemon's app libraries, which the libFuzzer tree does not build; there it runs its
# seeds (config_seeds.cc) and their mutations as a test.
if(NOT LRFNET_FUZZ)
  lrfnet_fuzz_target(config_fuzz SOURCES config_fuzz.cc
    LIBS lrfnet_tracker_app lrfnet_daemon_app lrfnet_sim lrfnet_auth lrfnet_calib_output)
  if(TARGET make_fuzz_corpus)
    target_sources(make_fuzz_corpus PRIVATE config_seeds.cc)
    target_link_libraries(make_fuzz_corpus PRIVATE lrfnet_tracker_app lrfnet_daemon_app lrfnet_sim
                                                   lrfnet_auth lrfnet_calib_output)
  endif()
endif()
