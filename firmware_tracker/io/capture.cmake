add_library(lrfnet_capture STATIC pcap_reader.cc packet_parser.cc tcp_reassembler.cc capture_stream.cc)
target_include_directories(lrfnet_capture PUBLIC ${PROJECT_SOURCE_DIR})
target_link_libraries(lrfnet_capture PUBLIC lrfnet_common PkgConfig::PCAP)
lrfnet_warnings(lrfnet_capture)
if(LRFNET_FUZZ)
  # Coverage feedback from the library code the fuzz targets exercise, not only from the targets.
  target_compile_options(lrfnet_capture PRIVATE -fsanitize=fuzzer-no-link,address,undefined)
endif()

lrfnet_test(capture_test
  SOURCES packet_parser_test.cc tcp_reassembler_test.cc capture_stream_test.cc
  LIBS lrfnet_capture)
