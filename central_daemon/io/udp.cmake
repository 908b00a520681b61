add_library(lrfnet_daemon_udp STATIC udp_receiver.cc)
target_include_directories(lrfnet_daemon_udp PUBLIC ${PROJECT_SOURCE_DIR})
target_link_libraries(lrfnet_daemon_udp PUBLIC lrfnet_common Boost::boost Threads::Threads)
lrfnet_warnings(lrfnet_daemon_udp)

# Real sockets on loopback (IPv4, IPv6, dual stack): batches, senders, receive times, replies.
lrfnet_test(daemon_udp_test SOURCES udp_receiver_test.cc LIBS lrfnet_daemon_udp)
