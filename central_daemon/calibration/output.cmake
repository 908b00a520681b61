# Step 9 and the evaluation: calibration.yaml (write, and read with truth.yaml), d_R / d_t against
# ground truth, and the report folder (SVG, PNG via a small canvas and zlib, CSV, Markdown).
find_package(ZLIB REQUIRED)
add_library(lrfnet_calib_output STATIC calibration_yaml.cc eval.cc report.cc raster.cc
                                       pose_history.cc)
target_include_directories(lrfnet_calib_output PUBLIC ${PROJECT_SOURCE_DIR})
# spdlog only for its fmt (this library does not log).
target_link_libraries(lrfnet_calib_output PUBLIC lrfnet_calib_types yaml-cpp ZLIB::ZLIB
                                          PRIVATE nlohmann_json::nlohmann_json spdlog::spdlog)
lrfnet_warnings(lrfnet_calib_output)

lrfnet_test(calib_output_test
            SOURCES calibration_yaml_test.cc eval_test.cc raster_test.cc report_test.cc
                    pose_history_test.cc
            LIBS lrfnet_calib_output ZLIB::ZLIB nlohmann_json::nlohmann_json)
