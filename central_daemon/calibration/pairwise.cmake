# Dynamic intervals (III-C) and pairwise MSAC hypotheses with verification (III-D, eqs. 5-8).
add_library(lrfnet_calib_pairwise intervals.cc pairwise.cc)
target_link_libraries(lrfnet_calib_pairwise PUBLIC lrfnet_calib_types PRIVATE spdlog::spdlog)
lrfnet_warnings(lrfnet_calib_pairwise)

lrfnet_test(calib_pairwise_test SOURCES intervals_test.cc pairwise_test.cc LIBS lrfnet_calib_pairwise)
