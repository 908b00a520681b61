# Joint refinement (step 8): Ceres over all sensor poses and per-step object positions.
find_package(Ceres REQUIRED)
add_library(lrfnet_calib_refine STATIC refine.cc)
target_link_libraries(lrfnet_calib_refine PUBLIC lrfnet_calib_types PRIVATE Ceres::ceres)
lrfnet_warnings(lrfnet_calib_refine)

lrfnet_test(calib_refine_test SOURCES refine_test.cc LIBS lrfnet_calib_refine)
