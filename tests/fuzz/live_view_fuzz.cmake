# The live view's request handling (Beast's request parser with the server's limits, routes,
# responses) on arbitrary connection bytes. Seeds: live_view_seeds.cc, written by make_fuzz_corpus.
lrfnet_fuzz_target(http_request_fuzz SOURCES live_view_fuzz.cc LIBS lrfnet_live_view_http)
if(TARGET make_fuzz_corpus)
  target_sources(make_fuzz_corpus PRIVATE live_view_seeds.cc)
endif()
