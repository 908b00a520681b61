# The calibration.yaml reader (lrfnetd's calibration.initial and --calibration-in, lrfnet eval) and its
# round trip through the writer. The fuzz build has no calibration libraries: there the reader's
# source is compiled into the target. Seeds: calibration_yaml_seeds.cc.
if(LRFNET_FUZZ)
  lrfnet_fuzz_target(calibration_yaml_fuzz
    SOURCES calibration_yaml_fuzz.cc
            ${PROJECT_SOURCE_DIR}/central_daemon/calibration/calibration_yaml.cc
    LIBS lrfnet_common lrfnet_daemon_ingest yaml-cpp spdlog::spdlog Eigen3::Eigen)
else()
  lrfnet_fuzz_target(calibration_yaml_fuzz SOURCES calibration_yaml_fuzz.cc LIBS lrfnet_calib_output)
endif()
if(TARGET make_fuzz_corpus)
  target_sources(make_fuzz_corpus PRIVATE calibration_yaml_seeds.cc)
  target_link_libraries(make_fuzz_corpus PRIVATE lrfnet_calib_output)
endif()
