# Cost of authenticated datagrams per datagram (tracker sealing vs unsealed; the daemon's
# verification where the daemon is built). Plain timing loop (no Google Benchmark), so it also
# cross-builds for the gateway: scripts/bench.sh runs the aarch64 build under qemu-user.
add_executable(auth_benchmark ${PROJECT_SOURCE_DIR}/tests/bench/auth_benchmark.cc)
target_link_libraries(auth_benchmark PRIVATE lrfnet_uplink lrfnet_auth)
if(TARGET lrfnet_daemon_ingest)
  target_link_libraries(auth_benchmark PRIVATE lrfnet_daemon_ingest)
  target_compile_definitions(auth_benchmark PRIVATE LRFNET_BENCH_DAEMON=1)
endif()
lrfnet_warnings(auth_benchmark)
