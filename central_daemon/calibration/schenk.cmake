# Baseline of Schenk et al. (papers/001): SVD track association, virtual tracks, N/d weights,
# greedy placement, mass-spring relaxation, close-points-only ICP on the backgrounds.
add_library(lrfnet_calib_schenk STATIC schenk.cc)
target_include_directories(lrfnet_calib_schenk PUBLIC ${PROJECT_SOURCE_DIR})
target_link_libraries(lrfnet_calib_schenk PUBLIC lrfnet_calib_types Eigen3::Eigen)
lrfnet_warnings(lrfnet_calib_schenk)

lrfnet_test(calib_schenk_test SOURCES schenk_test.cc LIBS lrfnet_calib_schenk)
