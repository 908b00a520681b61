add_library(lrfnet_sick_client STATIC sick_client.cc)
target_include_directories(lrfnet_sick_client PUBLIC ${PROJECT_SOURCE_DIR})
target_link_libraries(lrfnet_sick_client PUBLIC lrfnet_cola Boost::boost spdlog::spdlog Threads::Threads)
lrfnet_warnings(lrfnet_sick_client)

# Backoff, option validation and the client against a scripted device on loopback (the emulator-based link
# tests live in tests/; these stay tracker-only so they also run in the aarch64 build).
lrfnet_test(sick_client_test SOURCES sick_client_test.cc LIBS lrfnet_sick_client)
