# Tracker side of the wire: datagrams (nanopb, static structs generated from proto/lrfnet.proto at
# build time with the host's nanopb_generator.py; no libprotobuf, so it cross-builds), the UDP uplink,
# the recording writer, the request decoder and the kernel clock status.
find_package(nanopb CONFIG REQUIRED)
find_program(LRFNET_NANOPB_GENERATOR nanopb_generator.py REQUIRED)

set(LRFNET_NANOPB_DIR ${CMAKE_CURRENT_BINARY_DIR}/nanopb)
add_custom_command(
  OUTPUT ${LRFNET_NANOPB_DIR}/lrfnet.nanopb.c ${LRFNET_NANOPB_DIR}/lrfnet.nanopb.h
  COMMAND ${CMAKE_COMMAND} -E make_directory ${LRFNET_NANOPB_DIR}
  COMMAND ${LRFNET_NANOPB_GENERATOR} -q --error-on-unmatched -e .nanopb
          -f ${CMAKE_CURRENT_SOURCE_DIR}/lrfnet.options
          -I ${PROJECT_SOURCE_DIR}/proto -D ${LRFNET_NANOPB_DIR}
          ${PROJECT_SOURCE_DIR}/proto/lrfnet.proto
  DEPENDS ${PROJECT_SOURCE_DIR}/proto/lrfnet.proto ${CMAKE_CURRENT_SOURCE_DIR}/lrfnet.options
  COMMENT "nanopb: lrfnet.proto -> lrfnet.nanopb.{h,c}"
  VERBATIM)

add_library(lrfnet_uplink STATIC
  ${LRFNET_NANOPB_DIR}/lrfnet.nanopb.c
  system_clock.cc
  datagram_encoder.cc
  request_decoder.cc
  udp_uplink.cc
  sealing_sink.cc
  recording_writer.cc)
target_include_directories(lrfnet_uplink PUBLIC ${PROJECT_SOURCE_DIR} ${LRFNET_NANOPB_DIR})
target_link_libraries(lrfnet_uplink PUBLIC lrfnet_tracking lrfnet_common lrfnet_auth
                                           nanopb::protobuf-nanopb-static)
lrfnet_warnings(lrfnet_uplink)
lrfnet_hot_code(lrfnet_uplink)
lrfnet_per_track_sources(lrfnet_uplink datagram_encoder.cc)
if(LRFNET_FUZZ)
  target_compile_options(lrfnet_uplink PRIVATE -fsanitize=fuzzer-no-link,address,undefined)
endif()

# Encoder, request decoder, recording and UDP loopback, checked with the nanopb decoder: no libprotobuf,
# so these also run in the tracker-only (aarch64) build.
lrfnet_test(uplink_test
  SOURCES datagram_encoder_test.cc request_decoder_test.cc recording_writer_test.cc
          udp_uplink_test.cc system_clock_test.cc sealed_uplink_test.cc
  LIBS lrfnet_uplink)

# Replaces the global allocation functions, so it is its own binary.
lrfnet_test(uplink_alloc_test SOURCES uplink_alloc_test.cc LIBS lrfnet_uplink lrfnet_alloc_counter)

# Wire compatibility with the daemon's decoder: the same datagrams and recordings parsed by libprotobuf.
if(NOT LRFNET_TRACKER_ONLY AND NOT LRFNET_FUZZ)
  find_package(Protobuf REQUIRED)
  lrfnet_test(uplink_wire_test SOURCES uplink_wire_test.cc LIBS lrfnet_uplink lrfnet_proto)
endif()
