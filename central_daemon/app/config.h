#pragma once
// Configuration of lrfnetd: the UDP socket, the recording, datagram validation, per-sensor state,
// the track store's retention and the status line, loaded from a YAML file (`--config FILE`) and
// printed with its documentation by `--print-config`. Command-line flags override the file.
// SIGHUP reloads the file: everything except listen.*, record.*, fusion.publish and fusion.record
// applies at once.
// SIGUSR1 calibrates at once with the data held.

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "central_daemon/calibration/pipeline.h"
#include "central_daemon/fusion/fusion.h"
#include "central_daemon/ingest/ingest.h"
#include "central_daemon/io/recording_writer.h"
#include "central_daemon/io/udp_receiver.h"
#include "central_daemon/monitoring/monitor.h"
#include "central_daemon/store/track_store.h"
#include "central_daemon/zones/zones.h"
#include "common/config_yaml.h"

namespace lrfnet::daemon {

inline constexpr std::uint16_t kDefaultPort = 5800;

// Section `mqtt`: what lrfnetd publishes to an MQTT broker (see central_daemon/app/mqtt_service.h).
struct MqttConfig {
  std::string broker;         // HOST:PORT; empty: no MQTT
  std::string site = "site";  // topic level: <topic_prefix>/<site>/...
  std::string topic_prefix = "lrfnet";
  std::string client_id;  // empty: "lrfnetd-<site>"
  std::string username;   // empty: none
  std::string password;
  bool tls = false;
  std::string tls_ca_file;    // empty with tls: the system's CAs
  std::string tls_cert_file;  // client certificate (with tls_key_file); empty: none
  std::string tls_key_file;
  bool tls_insecure = false;  // do not check the broker's host name against its certificate
  std::int64_t keepalive_s = 30;
  double objects_hz = 5.0;
  std::int64_t objects_qos = 0;
  std::int64_t qos = 1;  // zones, calibration, health, status
  std::int64_t path_points = 10;
  double path_interval_s = 0.5;
  double zones_interval_s = 1.0;
  double health_interval_s = 5.0;
  std::int64_t queue_messages = 1000;
  double reconnect_min_s = 0.5;
  double reconnect_max_s = 30.0;
};

struct DaemonConfig {
  std::string listen = "[::]:5800";   // ADDR:PORT ("[::]" takes IPv4 and IPv6)
  UdpReceiverOptions receiver;         // address/port are set from `listen`
  std::string record_path;             // empty: no recording
  std::uint64_t record_max_file_mb = 1024;  // rotation size; 0 = never rotate
  double record_flush_interval_s = 1.0;
  IngestOptions ingest;
  bool send_requests = true;
  TrackStoreOptions store;
  std::uint64_t store_max_mb = 2048;   // store.max_bytes in MiB
  double status_interval_s = 5.0;      // 0 = no status line
  // Calibration (section `calibration`).
  bool calibration_auto = true;           // calibrate once enough data is in
  double calibration_attempt_interval_s = 10.0;
  double calibration_window_s = 600.0;    // the newest this many seconds of tracks
  double calibration_recalibrate_interval_s = 0.0;  // after success; 0 = keep the calibration
  std::string calibration_output;         // calibration.yaml to write; empty: log only
  std::string calibration_report_dir;     // report folder; empty: none
  calib::CalibrationOptions calibration;  // method, reference, weights, icp, refine, min overlap
  std::string calibration_initial;        // calibration.yaml to start from; empty: none
  // Fusion (section `fusion`).
  bool fusion_enabled = true;
  std::string fusion_publish;             // HOST:PORT for the UDP/JSON stream; empty: none
  std::string fusion_record;              // JSON lines file of the fused tracks; empty: none
  double fusion_publish_hz = 10.0;
  fusion::FusionOptions fusion;
  // Live view (section `live_view`).
  std::string live_view_listen;           // ADDR:PORT of the web page; empty: off
  double live_view_publish_hz = 5.0;
  std::uint64_t live_view_max_clients = 32;
  std::uint64_t live_view_background_points = 720;  // per sensor, decimated
  std::string live_view_token_file;  // access token; required when listening beyond loopback
  // Zones (section `zones`).
  std::string zones_list = "[]";   // the zones as YAML text (flow style), parsed by Validate
  std::vector<zones::Zone> zones;  // from zones_list
  zones::ZoneOptions zone_options;  // absent_hold_s: set by Validate from absent_hold_s below
  double zones_update_hz = 10.0;
  // How long an id absent from the fused tracks that the fusion reports neither hidden nor ended
  // is held before zones and MQTT take it as gone [s] (hidden ids are held while the fusion
  // keeps them, ended ones end at once); negative: fusion.max_coast_s.
  double absent_hold_s = -1.0;
  // MQTT (section `mqtt`).
  MqttConfig mqtt;
  // Authenticated datagrams (section `auth`); changes need a restart.
  std::string auth_keys_dir;   // folder of sensor keys; empty: not authenticated
  std::string auth_state_dir;  // where the replay state is kept; empty: $STATE_DIRECTORY
  // Monitoring (section `monitoring`): moved sensors flagged, left out of the fusion, corrected.
  bool monitoring_enabled = true;
  monitoring::MonitorOptions monitoring;
};

// Lists every option (sections listen, record, auth, validation, sensors, store, status,
// calibration, fusion, live_view, zones, mqtt, monitoring).
void VisitDaemonConfig(DaemonConfig& config, common::ConfigVisitor& visitor);

// 127.0.0.0/8, ::1 or localhost: an address only this host can reach.
bool IsLoopbackHost(std::string_view host);

// Every option, with the prefix of its section ("store.max_age_s: must be > 0"). Also parses
// `listen` into receiver.address/port and `zones.list` into zones.
std::optional<std::string> Validate(DaemonConfig& config);

// fusion.ended_report_s of `fusion` against the rates at which the zones (zones.update_hz, when
// there are zones) and MQTT objects (mqtt.objects_hz, with a broker) of `rates` take the
// fusion's output: at least two of their periods. Validate checks a config against its own
// rates; a reload checks the new fusion options against the running config's (the zones and
// MQTT keep the rates they started with).
std::optional<std::string> ValidateEndedReport(const fusion::FusionOptions& fusion,
                                               const DaemonConfig& rates);

// Loads a YAML document over `config` and validates the result.
std::optional<std::string> LoadDaemonConfig(std::string_view yaml_text, DaemonConfig& config);

// The documented YAML of `config` (the defaults for a default-constructed one).
std::string PrintDaemonConfig(const DaemonConfig& config);

// The recording options of the config (path, rotation, flush), writer "lrfnetd <version>".
RecordingWriterOptions RecordingOptions(const DaemonConfig& config, const std::string& writer);

}  // namespace lrfnet::daemon
