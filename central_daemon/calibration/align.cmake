# Steps 1 and 3: every sensor's tracks on one UTC grid, RTS-smoothed (align.h, rts.h).
add_library(lrfnet_calib_align STATIC align.cc rts.cc)
target_link_libraries(lrfnet_calib_align PUBLIC lrfnet_calib_types)
lrfnet_warnings(lrfnet_calib_align)

# The tests generate their tracks with the tracker's own filter (lrfnet_tracking, pure).
lrfnet_test(calib_align_test SOURCES align_test.cc rts_test.cc LIBS lrfnet_calib_align lrfnet_tracking)
