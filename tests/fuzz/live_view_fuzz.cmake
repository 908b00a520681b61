# The live view's request handling (Beast's request parser with the server's limits, routes,
# responses) on arbitrary connection bytes. Seeds: live_view_seeds.cc, written by make_fuzz_corpus.
lrfnet_fuzz_target(http_request_fuzz SOURCES live_view_fuzz.cc LIBS lrfnet_live_view_http)
if(TARGET make_fuzz_corpus)
  target_sources(make_fuzz_corpus PRIVATE live_view_seeds.cc)
endif()

# What a Foxglove client sends the live view (subscriptions, other ops, hostile JSON, binary).
# Seeds: foxglove_seeds.cc.
if(NOT TARGET nlohmann_json::nlohmann_json)
  find_package(nlohmann_json 3 REQUIRED)  # the fuzz build does not find it at the top level
endif()
lrfnet_fuzz_target(foxglove_fuzz SOURCES foxglove_fuzz.cc LIBS lrfnet_live_view_http nlohmann_json::nlohmann_json)
if(TARGET make_fuzz_corpus)
  target_sources(make_fuzz_corpus PRIVATE foxglove_seeds.cc)
endif()
