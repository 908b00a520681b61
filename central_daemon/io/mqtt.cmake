# MQTT publishing (libmosquitto from Debian: libmosquitto-dev): lrfnet_daemon_mqtt.
pkg_check_modules(MOSQUITTO REQUIRED IMPORTED_TARGET GLOBAL libmosquitto)
add_library(lrfnet_daemon_mqtt STATIC mqtt_publisher.cc)
target_include_directories(lrfnet_daemon_mqtt PUBLIC ${PROJECT_SOURCE_DIR})
target_link_libraries(lrfnet_daemon_mqtt PRIVATE PkgConfig::MOSQUITTO PUBLIC Threads::Threads)
lrfnet_warnings(lrfnet_daemon_mqtt)

# Against a real mosquitto on a free loopback port (skipped when the broker is not installed), and a
# fake broker that stops acknowledging: delivery in order, reconnect with backoff after a broker
# restart, retained messages again after reconnect, drops counted, TLS and passwords.
lrfnet_test(mqtt_publisher_test SOURCES mqtt_publisher_test.cc LIBS lrfnet_daemon_mqtt PkgConfig::MOSQUITTO)
