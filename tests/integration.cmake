# Integration tests: real sockets on loopback, the shared captures (skipped with a message when absent), and
# the built binaries.

# A test that starts the three binaries: their paths as compile definitions, built before it.
function(lrfnet_uses_binaries name)
  if(TARGET ${name})
    target_compile_definitions(${name} PRIVATE
      LRFNET_TOOL_BINARY="$<TARGET_FILE:lrfnet>"
      LRFNET_TRACKER_BINARY="$<TARGET_FILE:lrfnet-tracker>"
      LRFNET_DAEMON_BINARY="$<TARGET_FILE:lrfnetd>")
    add_dependencies(${name} lrfnet lrfnet-tracker lrfnetd)
  endif()
endfunction()

# `lrfnet dump` against the golden files of the shared captures; the emulated devices' replies
# against the recorded devices' replies.
lrfnet_test(golden_test SOURCES golden_test.cc
            LIBS lrfnet_dump lrfnet_emulator nlohmann_json::nlohmann_json)

# Emulator -> SickClient over loopback: every scan of a capture (or of the synthetic source) arrives.
lrfnet_test(loopback_test SOURCES loopback_test.cc LIBS lrfnet_emulator lrfnet_sick_client lrfnet_dump)

# SICK's driver's start-up dialogue per device family, CoLa-B and CoLa-A, against the emulator;
# `lrfnet emulate` and `lrfnet sim --serve` stopping at once on SIGINT/SIGTERM.
lrfnet_test(link_dialogue_test SOURCES link_dialogue_test.cc link_process_test.cc LIBS lrfnet_emulator)
if(TARGET link_dialogue_test)
  target_compile_definitions(link_dialogue_test PRIVATE LRFNET_TOOL_BINARY="$<TARGET_FILE:lrfnet>")
  add_dependencies(link_dialogue_test lrfnet)
endif()

# SickClient against a misbehaving device: stalls, broken frames, garbage, sFA, restarts, silence, refusal.
lrfnet_test(link_faults_test SOURCES link_faults_test.cc LIBS lrfnet_emulator lrfnet_sick_client)

# The binaries: exit codes, one-line errors, --help, replay, and emulator + tracker as processes.
lrfnet_test(cli_test SOURCES cli_test.cc LIBS lrfnet_dump)
if(TARGET cli_test)
  target_compile_definitions(cli_test PRIVATE LRFNET_TOOL_BINARY="$<TARGET_FILE:lrfnet>"
                                              LRFNET_TRACKER_BINARY="$<TARGET_FILE:lrfnet-tracker>")
  add_dependencies(cli_test lrfnet lrfnet-tracker)
endif()

# lrfnet-tracker's outputs: --print-config, --replay --out recordings (read with libprotobuf), live
# --uplink over UDP with Requests answered.
lrfnet_test(tracker_cli_test SOURCES tracker_cli_test.cc LIBS lrfnet_proto)
if(TARGET tracker_cli_test)
  target_compile_definitions(tracker_cli_test PRIVATE
    LRFNET_TOOL_BINARY="$<TARGET_FILE:lrfnet>"
    LRFNET_TRACKER_BINARY="$<TARGET_FILE:lrfnet-tracker>"
    LRFNET_TRACKER_CONFIG_FILE="${PROJECT_SOURCE_DIR}/firmware_tracker/config/lrfnet-tracker.yaml")
  add_dependencies(tracker_cli_test lrfnet lrfnet-tracker)
endif()

# `lrfnet dump` and `lrfnet replay` on recordings and UDP captures: JSON lines, rotation parts,
# replay into a loopback socket (bytes, order, senders, timing, IPv6, SIGINT), exit codes.
lrfnet_test(datagram_tools_test SOURCES datagram_tools_test.cc
            LIBS lrfnet_dump lrfnet_proto lrfnet_capture nlohmann_json::nlohmann_json)
if(TARGET datagram_tools_test)
  target_compile_definitions(datagram_tools_test PRIVATE LRFNET_TOOL_BINARY="$<TARGET_FILE:lrfnet>")
  add_dependencies(datagram_tools_test lrfnet)
endif()

# lrfnetd as a process: several tracker replays -> daemon -> recording identical to what was sent;
# loss / reordering / duplicates / restart; hostile datagrams; SIGKILL durability; SIGHUP; --input.
# auth_cli_test.cc: authenticated datagrams end to end: lrfnet keys, tracker --key -> lrfnetd --keys
# over UDP, forged / bit-flipped / wrong-epoch / wrong-key / unknown / unsigned / replayed datagrams
# counted and refused, the stored state after a restart, the offline readers with and without keys.
lrfnet_test(daemon_cli_test SOURCES daemon_cli_test.cc auth_cli_test.cc
            LIBS lrfnet_daemon_io lrfnet_uplink lrfnet_auth lrfnet_proto nlohmann_json::nlohmann_json)
lrfnet_uses_binaries(daemon_cli_test)
if(TARGET daemon_cli_test)
  target_compile_definitions(daemon_cli_test PRIVATE
    LRFNET_DAEMON_CONFIG_FILE="${PROJECT_SOURCE_DIR}/central_daemon/config/lrfnetd.yaml")
endif()

# The calibration chain as processes: lrfnet sim → lrfnet-tracker --replay per sensor → lrfnet calibrate /
# lrfnetd --input → lrfnet eval; accuracy bounds on the simulated setup of Quenzel et al.; one-line errors.
lrfnet_test(calibration_cli_test SOURCES calibration_cli_test.cc
            LIBS lrfnet_calib_output nlohmann_json::nlohmann_json yaml-cpp)
lrfnet_uses_binaries(calibration_cli_test)

# The whole chain live, like the demo: lrfnet sim --serve → lrfnet-tracker per device → lrfnetd
# (calibrates by itself, fuses, live view); one tracker killed and restarted while fusing.
lrfnet_test(system_test SOURCES system_test.cc LIBS nlohmann_json::nlohmann_json)
lrfnet_uses_binaries(system_test)

# `lrfnet export` read back with independent parsers (yaml-cpp for the ROS 2 launch file, urdfdom
# for the URDF when installed, the CSV by hand): transforms compose back to the calibration.
lrfnet_test(export_cli_test SOURCES export_cli_test.cc LIBS yaml-cpp Eigen3::Eigen)
lrfnet_uses_binaries(export_cli_test)
pkg_check_modules(URDFDOM IMPORTED_TARGET urdfdom)
if(TARGET export_cli_test AND URDFDOM_FOUND)
  target_link_libraries(export_cli_test PRIVATE PkgConfig::URDFDOM)
  target_compile_definitions(export_cli_test PRIVATE LRFNET_HAVE_URDFDOM=1)
endif()

# lrfnetd's MQTT output against a real mosquitto (skipped when not installed): a short simulated
# scene offline (objects vs the truth, zone counts vs the paths, libmosquitto and mosquitto_sub
# subscribers, every message against central_daemon/schemas with ajv) and live through a broker
# restart; the last will.
lrfnet_test(mqtt_system_test SOURCES mqtt_system_test.cc
            LIBS PkgConfig::MOSQUITTO nlohmann_json::nlohmann_json)
lrfnet_uses_binaries(mqtt_system_test)
if(TARGET mqtt_system_test)
  target_compile_definitions(mqtt_system_test PRIVATE
    LRFNET_NODE_DIR="${PROJECT_SOURCE_DIR}/tests/node"
    LRFNET_SCHEMA_DIR="${PROJECT_SOURCE_DIR}/central_daemon/schemas")
endif()

# The binaries under a fake service manager (sd_notify socket, watchdog): ready, watchdog while
# scans flow, none while the scanner link hangs, status and stopping. In system_test's binary (one
# link less); its tests stay separate ctest entries (ServiceTest.*).
if(TARGET system_test)
  target_sources(system_test PRIVATE service_test.cc)
endif()
