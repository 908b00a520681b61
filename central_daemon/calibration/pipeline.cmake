# The whole pipeline (Calibrate) and its data assessment.
add_library(lrfnet_calibration STATIC pipeline.cc placement.cc)
target_include_directories(lrfnet_calibration PUBLIC ${PROJECT_SOURCE_DIR})
target_link_libraries(lrfnet_calibration PUBLIC lrfnet_calib_types lrfnet_calib_align
                      lrfnet_calib_pairwise lrfnet_calib_icp lrfnet_calib_global lrfnet_calib_refine
                      lrfnet_calib_schenk)
lrfnet_warnings(lrfnet_calibration)

if(EXISTS ${CMAKE_CURRENT_SOURCE_DIR}/pipeline_test.cc)
  lrfnet_test(calib_pipeline_test SOURCES pipeline_test.cc LIBS lrfnet_calibration)
endif()
