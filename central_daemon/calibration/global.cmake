# Global step (pipeline step 7): pose graph, L1 rotation averaging (node-angle form of Quenzel et
# al.'s Algorithm 1), least-squares translations, spectral relaxation [21], and the paper's full
# formulation for tests and the benchmark. Eigen only.
add_library(lrfnet_calib_global STATIC
  graph.cc
  rotation_averaging.cc
  spectral.cc
  translations.cc
  pose_graph.cc
  l1mc_full.cc)
target_include_directories(lrfnet_calib_global PUBLIC ${PROJECT_SOURCE_DIR})
target_link_libraries(lrfnet_calib_global PUBLIC lrfnet_calib_types)
lrfnet_warnings(lrfnet_calib_global)

# The exact LP oracle (COIN-OR Clp) for the tests: never linked into production code.
if(BUILD_TESTING AND NOT LRFNET_FUZZ)
  pkg_check_modules(CLP REQUIRED IMPORTED_TARGET clp)
  add_library(lrfnet_calib_clp_oracle STATIC clp_oracle.cc)
  target_include_directories(lrfnet_calib_clp_oracle PUBLIC ${PROJECT_SOURCE_DIR})
  target_link_libraries(lrfnet_calib_clp_oracle PUBLIC Eigen3::Eigen PkgConfig::CLP)
  lrfnet_warnings(lrfnet_calib_clp_oracle)

  lrfnet_test(calib_global_test
    SOURCES graph_test.cc rotation_averaging_test.cc spectral_test.cc translations_test.cc
            l1mc_full_test.cc clp_oracle_test.cc
    LIBS lrfnet_calib_global lrfnet_calib_clp_oracle)
endif()
