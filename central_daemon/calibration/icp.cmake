# Step 6: point-to-line ICP (Censi) on two sensors' background snapshots.
add_library(lrfnet_calib_icp STATIC icp.cc)
target_link_libraries(lrfnet_calib_icp PUBLIC lrfnet_calib_types)
lrfnet_warnings(lrfnet_calib_icp)

lrfnet_test(calib_icp_test SOURCES icp_test.cc LIBS lrfnet_calib_icp)
