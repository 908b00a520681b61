add_library(lrfnet_daemon_io STATIC
  recording_writer.cc
  recording_decoder.cc
  recording_file_source.cc
  udp_capture_source.cc
  datagram_source.cc)
target_include_directories(lrfnet_daemon_io PUBLIC ${PROJECT_SOURCE_DIR})
target_link_libraries(lrfnet_daemon_io PUBLIC lrfnet_proto lrfnet_capture lrfnet_common)
lrfnet_warnings(lrfnet_daemon_io)
if(LRFNET_FUZZ)
  # Coverage feedback from the decoder itself, not only from the fuzz target.
  target_compile_options(lrfnet_daemon_io PRIVATE -fsanitize=fuzzer-no-link,address,undefined)
endif()

# Writer, decoder and both file kinds on real files in a temporary folder; the tracker's own
# recordings (lrfnet_uplink's nanopb writer) read back too.
lrfnet_test(daemon_io_test
  SOURCES recording_writer_test.cc recording_decoder_test.cc datagram_source_test.cc
  LIBS lrfnet_daemon_io lrfnet_proto lrfnet_uplink)
