# Sensor tick -> gateway UTC (minimum-offset rule with drift), part of lrfnet_tracking.
include_guard(GLOBAL)
target_sources(lrfnet_tracking PRIVATE ${CMAKE_CURRENT_LIST_DIR}/clock_mapper.cc)
lrfnet_test(clock_mapper_test SOURCES ${CMAKE_CURRENT_LIST_DIR}/clock_mapper_test.cc LIBS lrfnet_tracking)
