#include "central_daemon/app/config.h"

#include <cmath>

#include "common/host_port.h"

namespace lrfnet::daemon {
namespace {

using common::ConfigVisitor;
using common::VisitInteger;

std::optional<std::string> Prefixed(const std::string& section,
                                    const std::optional<std::string>& error) {
  if (!error) return std::nullopt;
  return section + "." + *error;
}

void VisitListen(DaemonConfig& c, ConfigVisitor& v) {
  v.Section("listen", "The UDP socket the trackers send to. Changes need a restart.");
  v.Field("address", c.listen,
          "ADDR:PORT to bind: an IPv4 or IPv6 address (IPv6 in brackets) or a name. \"[::]\" "
          "receives IPv4 and IPv6. --listen.");
  VisitInteger(v, "receive_buffer_bytes", c.receiver.receive_buffer_bytes,
          "Requested kernel receive buffer (SO_RCVBUF; beyond net.core.rmem_max only with "
          "CAP_NET_ADMIN). Absorbs bursts while the daemon is busy; the status line shows kernel "
          "drops.");
  VisitInteger(v, "batch_datagrams", c.receiver.batch_datagrams,
               "Datagrams taken per recvmmsg call (1..1024).");
}

void VisitRecord(DaemonConfig& c, ConfigVisitor& v) {
  v.Section("record",
            "The recording of everything received (lrfnet.proto RecordEntry stream). Changes "
            "need a restart.");
  v.Field("path", c.record_path, "File to write; empty: no recording. --record.");
  VisitInteger(v, "max_file_mb", c.record_max_file_mb,
               "Start the next file (PATH.1, PATH.2, ...) when a file reaches this size; 0: never.");
  v.Field("flush_interval_s", c.record_flush_interval_s,
          "Data reaches the file at least this often: a kill loses at most this much.");
}

void VisitValidation(ValidationOptions& o, ConfigVisitor& v) {
  v.Section("validation",
            "Datagrams outside these bounds are dropped and counted per sensor and reason.");
  v.Field("max_future_s", o.max_future_s,
          "A datagram stamped further than this ahead of its receive time is refused; also the "
          "slack of scan and snapshot stamps after the send stamp.");
  v.Field("max_stamp_age_s", o.max_stamp_age_s,
          "A scan or snapshot stamped further than this before its datagram's send stamp is "
          "refused.");
  v.Field("max_clock_offset_s", o.max_clock_offset_s,
          "When > 0: refuse datagrams whose send stamp differs from the receive time by more "
          "(strict live sites). 0 accepts replays of old captures.");
  v.Field("max_position_m", o.max_position_m, "Largest accepted |x|, |y| of a track.");
  v.Field("max_speed_mps", o.max_speed_mps, "Largest accepted |vx|, |vy| of a track.");
  v.Field("max_object_size_m", o.max_object_size_m,
          "Largest accepted size semi-axis (and its sigma) of a track, metres.");
  VisitInteger(v, "max_tracks_per_frame", o.max_tracks_per_frame, "Tracks in one datagram.");
  VisitInteger(v, "max_part_count", o.max_part_count, "Parts of one frame or snapshot (<= 64).");
  VisitInteger(v, "max_background_beams", o.max_background_beams,
               "Beams of one background snapshot.");
}

void VisitSensors(DaemonConfig& c, ConfigVisitor& v) {
  IngestOptions& o = c.ingest;
  v.Section("sensors", "Per-sensor state: sequence numbers, silence, requests.");
  VisitInteger(v, "max_sensors", o.max_sensors,
               "Sensor ids tracked at most; datagrams of further ids are refused. Needs a restart.");
  VisitInteger(v, "reorder_window_datagrams", o.reorder_window_datagrams,
               "A skipped sequence number counts as lost once this many newer ones arrived "
               "(<= 65536). Needs a restart.");
  VisitInteger(v, "max_sequence_jump", o.max_sequence_jump,
               "A jump further ahead within one session is a sequence reset.");
  v.Field("silent_after_s", o.silent_after_s, "No datagram for this long: the sensor is silent.");
  v.Field("send_requests", c.send_requests,
          "Ask trackers for their sensor info and background snapshot when the daemon lacks them.");
  v.Field("request_interval_s", o.request_interval_s, "At most one request per sensor this often.");
}

void VisitStore(DaemonConfig& c, ConfigVisitor& v) {
  v.Section("store",
            "Retention of the track frames kept for calibration and fusion: frames older than "
            "max_age_s (receive time) are dropped, and when the store exceeds max_mb the oldest "
            "frames of all sensors go first. The newest background of each sensor is always kept. "
            "A sensor at 50 Hz with 5 tracks takes about 90 MB per hour.");
  v.Field("max_age_s", c.store.max_age_s, "Keep frames this long.");
  VisitInteger(v, "max_mb", c.store_max_mb, "Memory bound of the store (estimate), MiB.");
}

void VisitStatus(DaemonConfig& c, ConfigVisitor& v) {
  v.Section("status", "The status line in the log.");
  v.Field("interval_s", c.status_interval_s, "A status line this often; 0: none.");
}

constexpr std::string_view kMethodNames[] = {"quenzel", "spectral", "schenk"};
static_assert(static_cast<int>(calib::Method::kSchenk) == 2);

void VisitCalibration(DaemonConfig& c, ConfigVisitor& v) {
  v.Section("calibration",
            "Finding every sensor's pose from the tracks (Quenzel et al.). The daemon tries every "
            "attempt_interval_s until the data connects all sensors, then keeps the result; "
            "SIGUSR1 calibrates at once. Runs on a worker thread over a copy of the newest "
            "window_s of tracks.");
  v.Field("auto", c.calibration_auto, "Calibrate by itself once enough data is in.");
  v.Field("attempt_interval_s", c.calibration_attempt_interval_s,
          "Time between attempts while the calibration is missing.");
  v.Field("window_s", c.calibration_window_s, "Use the newest this many seconds of tracks.");
  v.Field("recalibrate_interval_s", c.calibration_recalibrate_interval_s,
          "After a calibration, calibrate again this often; 0: keep it.");
  v.Field("output", c.calibration_output,
          "Write calibration.yaml here (replaced atomically); empty: only log it. "
          "--calibration-out.");
  v.Field("report_dir", c.calibration_report_dir,
          "Write the report (pictures, residuals) into this folder; empty: none.");
  common::VisitEnum(v, "method", c.calibration.method, kMethodNames,
                    "quenzel (robust), spectral or schenk (baselines).");
  v.Field("reference", c.calibration.reference,
          "The sensor at the origin; empty: the best-connected one.");
  v.Field("weighted", c.calibration.weighted,
          "Weight the edges of the global step by Schenk's N/d (helps when about half of the "
          "pairwise estimates are wrong).");
  v.Field("icp", c.calibration.use_icp, "Refine the pairwise poses on the background scans.");
  v.Field("refine", c.calibration.refine,
          "Joint refinement of all poses over every associated observation.");
  v.Field("min_pair_overlap_s", c.calibration.min_pair_overlap_s,
          "Seconds of simultaneous tracks that link two sensors in the data check; the first "
          "attempt waits until every sensor is linked (the progress shown).");
  v.Field("initial", c.calibration_initial,
          "Start from this calibration.yaml (fuse at once until a new calibration replaces it); "
          "empty: none. --calibration-in.");
}

void VisitFusion(DaemonConfig& c, ConfigVisitor& v) {
  fusion::FusionOptions& o = c.fusion;
  v.Section("fusion",
            "Once calibrated, every sensor's tracks in the world frame, the same person seen by "
            "several sensors merged into one fused track (ids kept across sensor hand-over), "
            "streamed as JSON over UDP and recorded as JSON lines.");
  v.Field("enabled", c.fusion_enabled, "Fuse tracks once a calibration exists.");
  v.Field("publish", c.fusion_publish,
          "Send the fused tracks as JSON datagrams to this HOST:PORT; empty: none. --fused-udp.");
  v.Field("record", c.fusion_record,
          "Append the fused tracks as JSON lines to this file; empty: none. --fused-out.");
  v.Field("publish_hz", c.fusion_publish_hz, "Fused tracks are published this often.");
  v.Field("gate_mahalanobis2", o.gate_mahalanobis2,
          "Association gate, squared Mahalanobis distance of positions (2 dof).");
  v.Field("gate_max_distance_m", o.gate_max_distance_m, "Association gate in metres.");
  v.Field("accel_psd", o.accel_psd, "Process noise of the fused tracks, m^2/s^3.");
  v.Field("position_noise_floor_m2", o.position_noise_floor_m2,
          "Added to every sensor's position variance (calibration and object-centre errors).");
  v.Field("max_coast_s", o.max_coast_s, "A fused track without updates is deleted after this.");
  v.Field("source_timeout_s", o.source_timeout_s,
          "A sensor's track without frames for this long leaves its fused track.");
  VisitInteger(v, "confirm_updates", o.confirm_updates, "Updates before a fused track is confirmed.");
}

void VisitLiveView(DaemonConfig& c, ConfigVisitor& v) {
  v.Section("live_view",
            "A web page (HTTP + WebSocket) with the sensors, their fields of view and backgrounds, "
            "raw and fused tracks, the calibration state and each sensor's health.");
  v.Field("listen", c.live_view_listen,
          "ADDR:PORT to serve the page on (port 0: any free port); empty: off. --live-view.");
  v.Field("publish_hz", c.live_view_publish_hz, "Updates sent to the page per second.");
  VisitInteger(v, "max_clients", c.live_view_max_clients, "Browser connections served at most.");
  VisitInteger(v, "background_points", c.live_view_background_points,
               "Background points per sensor sent to the page (decimated).");
}

}  // namespace

void VisitDaemonConfig(DaemonConfig& c, ConfigVisitor& v) {
  VisitListen(c, v);
  VisitRecord(c, v);
  VisitValidation(c.ingest.validation, v);
  VisitSensors(c, v);
  VisitStore(c, v);
  VisitStatus(c, v);
  VisitCalibration(c, v);
  VisitFusion(c, v);
  VisitLiveView(c, v);
}

std::optional<std::string> Validate(DaemonConfig& c) {
  std::string error;
  const auto endpoint = common::ParseHostPort(c.listen, "listen.address", 0, &error, true);
  if (!endpoint) return error;
  c.receiver.address = endpoint->host;
  c.receiver.port = endpoint->port;
  if (auto e = Prefixed("listen", Validate(c.receiver))) return e;
  if (c.record_max_file_mb > (std::uint64_t{1} << 30))
    return "record.max_file_mb: must be <= 2^30";
  if (!(c.record_flush_interval_s > 0.0 && c.record_flush_interval_s <= 60.0))
    return "record.flush_interval_s: must be in (0, 60]";
  if (auto e = Validate(c.ingest)) return *e;
  if (c.store_max_mb < 1 || c.store_max_mb > (std::uint64_t{1} << 30))
    return "store.max_mb: must be in [1, 2^30]";
  c.store.max_bytes = static_cast<std::size_t>(c.store_max_mb) << 20;
  if (auto e = Prefixed("store", Validate(c.store))) return e;
  if (!(c.status_interval_s >= 0.0 && c.status_interval_s <= 3600.0))
    return "status.interval_s: must be in [0, 3600]";
  if (!(c.calibration_attempt_interval_s >= 1.0 && c.calibration_attempt_interval_s <= 86400.0))
    return "calibration.attempt_interval_s: must be in [1, 86400]";
  if (!(c.calibration_window_s >= 1.0 && c.calibration_window_s <= 1e6))
    return "calibration.window_s: must be in [1, 1e6]";
  if (!(c.calibration_recalibrate_interval_s >= 0.0 &&
        c.calibration_recalibrate_interval_s <= 1e7))
    return "calibration.recalibrate_interval_s: must be in [0, 1e7]";
  if (auto e = Prefixed("calibration", calib::Validate(c.calibration))) return e;
  if (!c.fusion_publish.empty() &&
      !common::ParseHostPort(c.fusion_publish, "fusion.publish", 0, &error))
    return error;
  if (!(c.fusion_publish_hz >= 0.1 && c.fusion_publish_hz <= 1000.0))
    return "fusion.publish_hz: must be in [0.1, 1000]";
  if (auto e = Prefixed("fusion", fusion::Validate(c.fusion))) return e;
  if (!c.live_view_listen.empty() &&
      !common::ParseHostPort(c.live_view_listen, "live_view.listen", 0, &error, true))
    return error;
  if (!(c.live_view_publish_hz >= 0.1 && c.live_view_publish_hz <= 100.0))
    return "live_view.publish_hz: must be in [0.1, 100]";
  if (c.live_view_max_clients < 1 || c.live_view_max_clients > 10000)
    return "live_view.max_clients: must be in [1, 10000]";
  if (c.live_view_background_points > 100000)
    return "live_view.background_points: must be <= 100000";
  return std::nullopt;
}

std::optional<std::string> LoadDaemonConfig(std::string_view yaml_text, DaemonConfig& config) {
  if (auto e = common::LoadYamlConfig(yaml_text,
                                      [&](ConfigVisitor& v) { VisitDaemonConfig(config, v); }))
    return e;
  return Validate(config);
}

std::string PrintDaemonConfig(const DaemonConfig& config) {
  DaemonConfig copy = config;
  return common::PrintYamlConfig(
      [&](ConfigVisitor& v) { VisitDaemonConfig(copy, v); },
      "lrfnetd configuration (YAML). Every option with its default; lrfnetd --print-config\n"
      "prints this file, --config FILE reads one. Keys left out keep their defaults; unknown\n"
      "keys are errors. Units are in the names (_s, _m, _mps, _mb). SIGHUP reloads the file.");
}

RecordingWriterOptions RecordingOptions(const DaemonConfig& config, const std::string& writer) {
  RecordingWriterOptions o;
  o.path = config.record_path;
  o.writer = writer;
  o.max_file_bytes = config.record_max_file_mb << 20;
  o.flush_interval_s = config.record_flush_interval_s;
  return o;
}

}  // namespace lrfnet::daemon
