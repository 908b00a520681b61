#include "central_daemon/app/config.h"

#include <yaml-cpp/yaml.h>

#include <cmath>

#include "common/host_port.h"
#include "common/one_line.h"

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

void VisitAuth(DaemonConfig& c, ConfigVisitor& v) {
  v.Section("auth",
            "Authenticated datagrams (lrfnet.proto, common/datagram_auth.h): with keys, a datagram "
            "is verified before it is decoded, and unsigned, forged, replayed, stale and wrong-key "
            "datagrams are dropped and counted per reason; Requests go out sealed. Without keys "
            "the network is unauthenticated (warned at start, in the status line and the live "
            "view). Changes need a restart.");
  v.Field("keys", c.auth_keys_dir,
          "Folder of the sensor keys (sensor-<id>-e<epoch>.key from lrfnet keys derive; every "
          "sensor with a key is known, others are refused), or $CREDENTIALS_DIRECTORY for "
          "systemd credentials. Empty: unauthenticated. --keys.");
  v.Field("state_dir", c.auth_state_dir,
          "Where the newest epoch and highest counter of every sensor are kept, so that a "
          "restarted daemon refuses yesterday's datagrams. Empty: $STATE_DIRECTORY (systemd's "
          "StateDirectory) when set, else not kept. --state-dir.");
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

constexpr std::string_view kFusionMethodNames[] = {"fused_filter", "latest_states"};
static_assert(static_cast<int>(fusion::FusionMethod::kLatestStates) == 1);

void VisitFusion(DaemonConfig& c, ConfigVisitor& v) {
  fusion::FusionOptions& o = c.fusion;
  v.Section("fusion",
            "Once calibrated, every sensor's tracks in the world frame, the same person seen by "
            "several sensors merged into one fused track (ids kept across sensor hand-over, "
            "tracker id swaps and short gaps in every sensor's view), streamed as JSON over UDP "
            "and recorded as JSON lines. SIGHUP applies everything but publish and record (those "
            "need a restart); changed fusion options (but ended_report_s alone) start the fused "
            "tracks afresh (new ids, never one given before).");
  v.Field("enabled", c.fusion_enabled, "Fuse tracks once a calibration exists.");
  v.Field("publish", c.fusion_publish,
          "Send the fused tracks as JSON datagrams to this HOST:PORT; empty: none. --fused-udp.");
  v.Field("record", c.fusion_record,
          "Append the fused tracks as JSON lines to this file; empty: none. --fused-out.");
  v.Field("publish_hz", c.fusion_publish_hz, "Fused tracks are published this often.");
  common::VisitEnum(v, "method", o.method, kFusionMethodNames,
                    "fused_filter: one filter per fused track on every sensor's new information, "
                    "each sensor's centre offset a state of it (covariances that contain the "
                    "error). latest_states: the earlier releases' combination of the sources' "
                    "latest states.");
  v.Field("gate_mahalanobis2", o.gate_mahalanobis2,
          "Association gate, squared Mahalanobis distance of positions (2 dof; 13.8 = 99.9 %).");
  v.Field("gate_max_distance_m", o.gate_max_distance_m,
          "Association gate in metres on top of the statistical one.");
  v.Field("accel_psd", o.accel_psd,
          "Process noise of the fused tracks' constant-velocity model (white acceleration), "
          "m^2/s^3.");
  v.Field("tracker_accel_psd", o.tracker_accel_psd,
          "The trackers' own process noise, m^2/s^3, for trackers that do not send theirs "
          "(fused_filter: each frame's measurement is recovered with it; too low is safe, too "
          "high over-confident).");
  v.Field("centre_sigma_shape_fit_m", o.centre_sigma_shape_fit_m,
          "fused_filter: standard deviation of the offset between the centre a shape-fit track "
          "reports and the body's centre, along the line of sight; it changes slowly, so "
          "repeated frames of one sensor do not average it away, other sensors' views do.");
  v.Field("centre_sigma_ellipse_m", o.centre_sigma_ellipse_m,
          "fused_filter: the same for ellipse measurements (older trackers).");
  v.Field("centre_sigma_com_m", o.centre_sigma_com_m,
          "fused_filter: the same for centre-of-mass measurements (older trackers and unknown "
          "kinds).");
  v.Field("centre_lateral_fraction", o.centre_lateral_fraction,
          "fused_filter: the centre offset across the line of sight, as a fraction of the one "
          "along it (0..1].");
  v.Field("centre_correlation_s", o.centre_correlation_s,
          "fused_filter: correlation time of a sensor's centre offset, seconds.");
  v.Field("binding_bonus", o.binding_bonus,
          "fused_filter: a track's frame goes to the fused track it is bound to unless another "
          "fits better by this much (squared Mahalanobis distance + ln det); larger trusts the "
          "trackers' ids more, 0 re-associates every frame.");
  v.Field("adapt_covariances", o.adapt_covariances,
          "fused_filter: scale the calibration's pose covariances and a tracker's covariances up "
          "when the data show them too small (never below what was reported).");
  v.Field("learn_sensor_bias", o.learn_sensor_bias,
          "fused_filter: learn each sensor's constant centre offset (per measurement kind) and "
          "the error of its placement from where other sensors see the same people, and take "
          "them out of its frames (--stats-out: fusion.sensor_biases). Off: each fused track's "
          "offset state alone (earlier releases).");
  VisitInteger(v, "sensor_bias_min_samples", o.sensor_bias_min_samples,
               "fused_filter: samples (one per local track and sensor_bias_sample_s of views "
               "shared with other sensors) before a learnt bias is applied.");
  v.Field("sensor_bias_sample_s", o.sensor_bias_sample_s,
          "fused_filter: seconds of a local track's shared views per sample of its sensor's "
          "bias.");
  v.Field("max_sensor_bias_m", o.max_sensor_bias_m,
          "fused_filter: learnt centre offsets are clamped to +-this, metres.");
  v.Field("sensor_bias_offset_sigma_fraction", o.sensor_bias_offset_sigma_fraction,
          "fused_filter: a learnt centre offset is taken out of the frames only when its sigma "
          "is at most this fraction of its kind's centre_sigma (the placement's error is "
          "corrected regardless).");
  v.Field("manoeuvre_max_distance_m", o.manoeuvre_max_distance_m,
          "fused_filter: a bound track's frame within this distance of its fused track that the "
          "gate refused is a stop or sharp turn: the fused track widens to take it.");
  v.Field("max_coast_s", o.max_coast_s,
          "A fused track without updates is deleted after this; until then it coasts and keeps "
          "its id for a person hidden from every sensor. Longer keeps more ids in crowds and "
          "ghosts longer where people leave the view.");
  v.Field("coast_after_s", o.coast_after_s,
          "A fused track without updates for this long is published as coasting.");
  v.Field("source_timeout_s", o.source_timeout_s,
          "A sensor's track without frames for this long leaves its fused track.");
  v.Field("max_out_of_order_s", o.max_out_of_order_s,
          "Frames older than the newest frame of any sensor by more are dropped (counted).");
  VisitInteger(v, "confirm_updates", o.confirm_updates,
               "Updates before a fused track is confirmed.");
  v.Field("use_tentative_sources", o.use_tentative_sources,
          "Also use the trackers' tentative tracks (earlier, more false tracks).");
  VisitInteger(v, "drift_updates", o.drift_updates,
               "A track's frames in a row that do not fit its fused track before it is unbound.");
  VisitInteger(v, "merge_updates", o.merge_updates,
               "Consistent checks in a row after which two fused tracks of disjoint sensors are "
               "one object (the younger merged into the older id).");
  v.Field("merge_max_distance_m", o.merge_max_distance_m,
          "Two fused tracks further apart are never merged.");
  v.Field("merge_max_speed_difference_mps", o.merge_max_speed_difference_mps,
          "Two fused tracks whose velocities differ more are never merged.");
  v.Field("merge_centre_spread_m", o.merge_centre_spread_m,
          "fused_filter: spread (m, per axis) of two sensors' centres of one body added to both "
          "tracks' covariances in the merge test (each sensor sees another side); 0: the "
          "covariances alone.");
  v.Field("report_sourceless", o.report_sourceless,
          "fused_filter: also publish a fused track no sensor's track is bound to any more "
          "(coasting until max_coast_s); off: kept for its id, not published (an id may then "
          "leave the published objects and come back: zones and MQTT hold it while the fusion "
          "keeps it).");
  v.Field("ended_report_s", o.ended_report_s,
          "How long (s, of the outputs the zones and MQTT take, from the first that listed the "
          "end) the fusion keeps telling them that an id ended and why (merged into another id, "
          "timed out), so they end it at once. At least two periods of zones.update_hz and of "
          "mqtt.objects_hz; at most max_fused_tracks ends are kept (beyond that the oldest is "
          "forgotten, counted as ended_evicted; such an id falls to zones.absent_hold_s).");
  v.Field("merge_sourceless", o.merge_sourceless,
          "fused_filter: a fused track without sources coasting on a measured one is merged "
          "into it rather than left beside it as a second track.");
  v.Field("merge_sourceless_shadow_m", o.merge_sourceless_shadow_m,
          "fused_filter: a person's radius (m) for merge_sourceless: a fused track without sources "
          "standing in the shadow of a measured one (behind it along the line of sight of every "
          "sensor that saw it last by more than this) was hidden by it and is not merged into it; "
          "0: no shadow test.");
  v.Field("position_noise_floor_m2", o.position_noise_floor_m2,
          "latest_states: added to every source's position variance (calibration and centre "
          "errors).");
  v.Field("velocity_noise_floor_m2ps2", o.velocity_noise_floor_m2ps2,
          "latest_states: added to every source's velocity variance.");
  v.Field("agree_mahalanobis2", o.agree_mahalanobis2,
          "latest_states: agreement with a fused track's reference (drift test).");
  v.Field("drift_reference_max_age_s", o.drift_reference_max_age_s,
          "latest_states: a lone source is judged against a reference at most this old.");
  v.Field("max_speed_mps", o.max_speed_mps, "Tracks faster than this are ignored (counted).");
  VisitInteger(v, "max_fused_tracks", o.max_fused_tracks,
               "Fused tracks at most (memory bound); further ones are not created (counted).");
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
  v.Field("token_file", c.live_view_token_file,
          "A file holding the access token (lrfnet keys token; mode 0600), or "
          "$CREDENTIALS_DIRECTORY/NAME. With a token, the page, /state and the WebSocket need it "
          "(?token=... in the URL, or an 'Authorization: Bearer' header). Required when listen "
          "is not a loopback address. --live-view-token-file.");
}

void VisitZones(DaemonConfig& c, ConfigVisitor& v) {
  v.Section("zones",
            "Named areas (polygons) and lines in the world frame, counted from the fused tracks: "
            "occupancy, inbound / outbound counts since start and dwell times (published over "
            "MQTT, drawn in the live view). Changes need a restart.");
  v.StructuredField(
      "list", c.zones_list,
      "The zones: a list of {name: NAME, polygon: [[x_m, y_m], ...]} (at least 3 vertices) or "
      "{name: NAME, line: [[x_m, y_m], [x_m, y_m]]}. Names are [A-Za-z0-9_-] (an MQTT topic "
      "level). A line counts crossings by direction: inbound is towards its left side (walking "
      "from its first point to its second, the left hand), outbound towards its right. A polygon "
      "counts entries (inbound) and exits (outbound).");
  v.Field("hysteresis_m", c.zone_options.hysteresis_m,
          "A track must be this far past a polygon's edge or a line to change sides, so a person "
          "standing on it is counted once. Zones should be wider than twice this.");
  v.Field("update_hz", c.zones_update_hz, "The zones are evaluated this often (fused-track time).");
  v.Field("absent_hold_s", c.absent_hold_s,
          "An id absent from the fused tracks is held (the zones keep its side, region and "
          "dwell, MQTT its path) while the fusion keeps it unpublished (a hidden person it may "
          "publish again), and ends at once when the fusion ends it (merged into another id: "
          "folded into that one; timed out: its exit, as of when it disappeared). This is how "
          "long an absent id the fusion says nothing of is held before it is gone (e.g. an end "
          "reported longer than fusion.ended_report_s ago). Negative: fusion.max_coast_s. 0: at "
          "once.");
}

void VisitMqtt(DaemonConfig& c, ConfigVisitor& v) {
  MqttConfig& m = c.mqtt;
  v.Section("mqtt",
            "Publishing to an MQTT broker (JSON, see central_daemon/schemas): "
            "<topic_prefix>/<site>/objects (the fused objects at objects_hz), "
            "<topic_prefix>/<site>/objects/ended (objects that left the list for good, and why), "
            "<topic_prefix>/<site>/zones/<name> (each zone's state when it changes and every "
            "zones_interval_s), <topic_prefix>/<site>/calibration (retained, when it changes), "
            "<topic_prefix>/<site>/sensors/<id>/health (retained), <topic_prefix>/<site>/status "
            "(retained; \"offline\" is the daemon's last will). Publishing never waits for the "
            "broker: messages go through a bounded queue, drops are counted. Changes need a "
            "restart.");
  v.Field("broker", m.broker, "HOST:PORT of the broker (1883; 8883 with TLS); empty: off. --mqtt.");
  v.Field("site", m.site, "The site's name in the topics ([A-Za-z0-9_.-]). --mqtt-site.");
  v.Field("topic_prefix", m.topic_prefix, "First level(s) of every topic.");
  v.Field("client_id", m.client_id, "MQTT client id; empty: lrfnetd-<site>.");
  v.Field("username", m.username, "User name for the broker; empty: none.");
  v.Field("password", m.password, "Password for the broker (keep the config file private).");
  v.Field("tls", m.tls, "Connect with TLS.");
  v.Field("tls_ca_file", m.tls_ca_file,
          "PEM file of the CA(s) that signed the broker's certificate; empty: the system's CAs.");
  v.Field("tls_cert_file", m.tls_cert_file,
          "Client certificate (PEM) for brokers that ask; empty: none.");
  v.Field("tls_key_file", m.tls_key_file, "The client certificate's private key (PEM).");
  v.Field("tls_insecure", m.tls_insecure,
          "Do not check the broker's host name against its certificate (tests only).");
  VisitInteger(v, "keepalive_s", m.keepalive_s, "MQTT keep-alive, seconds (5..3600).");
  v.Field("objects_hz", m.objects_hz, "Object lists per second.");
  VisitInteger(v, "objects_qos", m.objects_qos, "QoS of the object lists (0 or 1).");
  VisitInteger(v, "qos", m.qos, "QoS of zones, calibration, health and status (0 or 1).");
  VisitInteger(v, "path_points", m.path_points, "Points of each object's path (0: no path).");
  v.Field("path_interval_s", m.path_interval_s, "Time between two points of a path.");
  v.Field("zones_interval_s", m.zones_interval_s,
          "Every zone's state is published at least this often (and at once when it changes).");
  v.Field("health_interval_s", m.health_interval_s,
          "Every sensor's health is published at least this often (and at once when its state "
          "changes).");
  VisitInteger(v, "queue_messages", m.queue_messages,
               "Messages waiting for the broker at most; more are dropped and counted.");
  v.Field("reconnect_min_s", m.reconnect_min_s,
          "First wait before reconnecting; doubles after every failure up to reconnect_max_s.");
  v.Field("reconnect_max_s", m.reconnect_max_s, "Longest wait between reconnection attempts.");
}

// zones.list: [{name, polygon | line}, ...] -> zones.
std::optional<std::string> ParseZones(const std::string& text, std::vector<zones::Zone>* out) {
  out->clear();
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    return "zones.list: " + e.msg;
  }
  if (!root || root.IsNull()) return std::nullopt;
  if (!root.IsSequence()) return std::string("zones.list: expected a list of zones");
  for (std::size_t i = 0; i < root.size(); ++i) {
    const std::string where = "zones.list[" + std::to_string(i) + "]";
    const YAML::Node item = root[i];
    if (!item.IsMap()) return where + ": expected {name: ..., polygon: [...]} or {name, line}";
    zones::Zone zone;
    int shapes = 0;
    for (const auto& entry : item) {
      const std::string key = entry.first.IsScalar() ? entry.first.Scalar() : "?";
      if (key == "name") {
        if (!entry.second.IsScalar()) return where + ".name: expected a string";
        zone.name = entry.second.Scalar();
      } else if (key == "polygon" || key == "line") {
        ++shapes;
        zone.kind = key == "line" ? zones::ZoneKind::kLine : zones::ZoneKind::kPolygon;
        if (!entry.second.IsSequence())
          return where + "." + key + ": expected a list of [x_m, y_m]";
        if (entry.second.size() > zones::kMaxZonePoints)
          return where + "." + key + ": too many points";
        for (const YAML::Node& p : entry.second) {
          double x = 0.0, y = 0.0;
          if (!p.IsSequence() || p.size() != 2 || !p[0].IsScalar() || !p[1].IsScalar() ||
              !YAML::convert<double>::decode(p[0], x) || !YAML::convert<double>::decode(p[1], y)) {
            return where + "." + key + ": expected points [x_m, y_m]";
          }
          zone.points.push_back({x, y});
        }
      } else {
        return where + "." + key + ": unknown key (name, polygon, line)";
      }
    }
    if (shapes != 1) return where + ": give exactly one of polygon or line";
    if (auto e = zones::Validate(zone)) return where + ": " + *e;
    out->push_back(std::move(zone));
  }
  if (auto e = zones::Validate(std::span<const zones::Zone>(*out))) return "zones.list: " + *e;
  return std::nullopt;
}

bool TopicLevelOk(const std::string& s) {
  if (s.empty() || s.size() > 64) return false;
  for (const char ch : s) {
    const bool ok = (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') ||
                    (ch >= '0' && ch <= '9') || ch == '_' || ch == '-' || ch == '.';
    if (!ok) return false;
  }
  return true;
}

std::optional<std::string> CheckEndedReport(const fusion::FusionOptions& fusion,
                                            const DaemonConfig& rates) {
  // The zones and the object list learn of an end only while the fusion reports it.
  if (!rates.zones.empty() && fusion.ended_report_s < 2.0 / rates.zones_update_hz) {
    return "fusion.ended_report_s: must be at least two periods of zones.update_hz";
  }
  if (!rates.mqtt.broker.empty() && rates.mqtt.objects_hz > 0.0 &&
      fusion.ended_report_s < 2.0 / rates.mqtt.objects_hz) {
    return "fusion.ended_report_s: must be at least two periods of mqtt.objects_hz";
  }
  return std::nullopt;
}

std::optional<std::string> ValidateZonesAndMqtt(DaemonConfig& c) {
  if (auto e = ParseZones(c.zones_list, &c.zones)) return e;
  if (!(c.absent_hold_s <= 3600.0)) return "zones.absent_hold_s: must be at most 3600";
  // The default follows fusion.max_coast_s (unbounded there), at most the zones' own bound.
  c.zone_options.absent_hold_s =
      c.absent_hold_s < 0.0 ? std::min(c.fusion.max_coast_s, 3600.0) : c.absent_hold_s;
  if (auto e = Prefixed("zones", zones::Validate(c.zone_options))) return e;
  if (!(c.zones_update_hz >= 0.1 && c.zones_update_hz <= 100.0))
    return "zones.update_hz: must be in [0.1, 100]";
  const MqttConfig& m = c.mqtt;
  std::string error;
  if (!m.broker.empty() && !common::ParseHostPort(m.broker, "mqtt.broker", 0, &error)) return error;
  if (!TopicLevelOk(m.site))
    return "mqtt.site: must be 1-64 characters of A-Z, a-z, 0-9, _, - and .";
  if (m.topic_prefix.empty() || m.topic_prefix.size() > 128 ||
      m.topic_prefix.find_first_of("+#") != std::string::npos || m.topic_prefix.front() == '/' ||
      m.topic_prefix.back() == '/')
    return "mqtt.topic_prefix: must be 1-128 characters without + and #, not starting or ending "
           "with /";
  if (m.client_id.size() > 128) return "mqtt.client_id: at most 128 characters";
  if (!m.password.empty() && m.username.empty()) return "mqtt.password: needs mqtt.username";
  if (m.tls_cert_file.empty() != m.tls_key_file.empty())
    return "mqtt.tls_cert_file: give both tls_cert_file and tls_key_file, or neither";
  if (!m.tls && (!m.tls_ca_file.empty() || !m.tls_cert_file.empty()))
    return "mqtt.tls: the tls_* files need tls: true";
  if (m.keepalive_s < 5 || m.keepalive_s > 3600) return "mqtt.keepalive_s: must be in [5, 3600]";
  if (!(m.objects_hz >= 0.1 && m.objects_hz <= 100.0))
    return "mqtt.objects_hz: must be in [0.1, 100]";
  if (m.objects_qos < 0 || m.objects_qos > 1) return "mqtt.objects_qos: must be 0 or 1";
  if (m.qos < 0 || m.qos > 1) return "mqtt.qos: must be 0 or 1";
  if (m.path_points < 0 || m.path_points > 1000) return "mqtt.path_points: must be in [0, 1000]";
  if (!(m.path_interval_s >= 0.01 && m.path_interval_s <= 3600.0))
    return "mqtt.path_interval_s: must be in [0.01, 3600]";
  if (!(m.zones_interval_s >= 0.01 && m.zones_interval_s <= 3600.0))
    return "mqtt.zones_interval_s: must be in [0.01, 3600]";
  if (!(m.health_interval_s >= 0.1 && m.health_interval_s <= 3600.0))
    return "mqtt.health_interval_s: must be in [0.1, 3600]";
  if (m.queue_messages < 1 || m.queue_messages > 1000000)
    return "mqtt.queue_messages: must be in [1, 1000000]";
  if (!(m.reconnect_min_s >= 0.01 && m.reconnect_min_s <= m.reconnect_max_s &&
        m.reconnect_max_s <= 3600.0))
    return "mqtt.reconnect_min_s: need 0.01 <= reconnect_min_s <= reconnect_max_s <= 3600";
  // After the rates' own checks, so a bad rate is reported as itself.
  return CheckEndedReport(c.fusion, c);
}

void VisitMonitoring(DaemonConfig& c, ConfigVisitor& v) {
  monitoring::MonitorOptions& o = c.monitoring;
  monitoring::BackgroundCheckOptions& b = o.background;
  monitoring::TrackCheckOptions& t = o.tracks;
  v.Section("monitoring",
            "Once calibrated, whether every sensor still stands where the calibration put it. Each "
            "new background snapshot of a sensor is aligned with the one in place when its pose "
            "was set (point-to-line ICP): when the whole static scene moved together (or the part "
            "the tracker has re-learned so far), the sensor moved. Every track_period_s its tracks "
            "of the last track_window_s are compared with the other sensors' (the rigid "
            "correction that fits them best, tested against its covariance). A moved sensor is "
            "flagged (log, status line, live view, stats), its tracks leave the fused output at "
            "once, its pose is estimated again with the others held fixed (from the background "
            "where the scene has structure, else from its tracks) and calibration.output is "
            "rewritten with the event in its `history`; then it is fused again. A scene that "
            "changed while the tracks agree (furniture moved) becomes the new reference "
            "background instead.");
  v.Field("enabled", c.monitoring_enabled, "Watch the sensors once calibrated.");
  v.Field("background_min_yaw_deg", b.min_yaw_deg,
          "A background motion this large (degrees) or background_min_translation_m is a move.");
  v.Field("background_min_translation_m", b.min_translation_m, "See background_min_yaw_deg.");
  v.Field("background_min_chi2", b.min_chi2,
          "... and only when this significant: chi^2 of (x, y, yaw) against the ICP covariance "
          "(inflated by 9; 3 dof).");
  v.Field("background_inlier_distance_m", b.inlier_distance_m,
          "A snapshot point within this distance of the reference polyline lies on the scene.");
  v.Field("background_min_inlier_gain", b.min_inlier_gain,
          "The share of the snapshot's points on the reference scene must grow by this much "
          "under the motion (0..1): the whole scene moved, not a cart.");
  VisitInteger(v, "background_min_changed_points", b.min_changed_points,
               "Points off the reference scene needed to judge the changed part alone (while the "
               "tracker re-learns its background after a move).");
  v.Field("background_unchanged_margin_m", b.unchanged_margin_m,
          "The trackers' background margin: under the motion of the changed part, the unchanged "
          "points must stay this close to the reference scene.");
  v.Field("background_min_changed_fraction", b.min_changed_fraction,
          "A snapshot with this share of its points off the reference scene and no common motion "
          "changed by itself (furniture): re-learned once the tracks agree.");
  v.Field("track_window_s", o.track_window_s, "Seconds of tracks in each track check.");
  v.Field("track_period_s", o.track_period_s, "A track check this often, seconds.");
  VisitInteger(v, "track_confirmations", o.track_confirmations,
               "Consecutive track checks that must find a move before the sensor is flagged.");
  VisitInteger(v, "tracks_min_matches", t.min_matches,
               "Associated observations (0.05 s grid steps) a track check needs.");
  v.Field("tracks_min_yaw_deg", t.min_yaw_deg,
          "A track correction this large (degrees) or tracks_min_translation_m is a move.");
  v.Field("tracks_min_translation_m", t.min_translation_m, "See tracks_min_yaw_deg.");
  v.Field("tracks_min_chi2", t.min_chi2,
          "... and only when this significant: chi^2 of the correction against the fit's "
          "covariance (3 dof).");
  v.Field("correct_min_inliers", o.correct_min_inliers,
          "A snapshot corrects a moved sensor's pose when this share of its points lies on the "
          "reference scene under the ICP's motion; short of 0.97 (a snapshot that may still mix "
          "the old scene with the new while the tracker re-learns) only when the tracks since "
          "the flag place the sensor to within 0.1 deg / 0.025 m (one standard deviation) and "
          "within twice that of it.");
  v.Field("correction_min_tracks_s", o.correction_min_tracks_s,
          "Without such a snapshot, the pose is estimated from the tracks since the flag once "
          "there are this many seconds of them.");
  v.Field("relearn_background", o.relearn_background,
          "Re-learn the reference background of a sensor whose scene changed while its tracks "
          "agree.");
}

std::optional<std::string> ValidateMonitoring(const DaemonConfig& c) {
  std::optional<std::string> e = monitoring::Validate(c.monitoring);
  if (!e) return std::nullopt;
  // "background.min_yaw_deg ..." names the key background_min_yaw_deg of the section.
  for (const char* group : {"background.", "tracks."}) {
    if (e->rfind(group, 0) == 0) (*e)[std::string_view(group).size() - 1] = '_';
  }
  return "monitoring." + *e;
}

}  // namespace

bool IsLoopbackHost(std::string_view host) {
  if (host == "localhost" || host == "::1" || host == "0:0:0:0:0:0:0:1") return true;
  // 127.0.0.0/8 as a dotted quad.
  if (host.rfind("127.", 0) != 0) return false;
  int dots = 0;
  for (const char ch : host) {
    if (ch == '.') {
      ++dots;
    } else if (ch < '0' || ch > '9') {
      return false;
    }
  }
  return dots == 3;
}

void VisitDaemonConfig(DaemonConfig& c, ConfigVisitor& v) {
  VisitListen(c, v);
  VisitRecord(c, v);
  VisitAuth(c, v);
  VisitValidation(c.ingest.validation, v);
  VisitSensors(c, v);
  VisitStore(c, v);
  VisitStatus(c, v);
  VisitCalibration(c, v);
  VisitFusion(c, v);
  VisitLiveView(c, v);
  VisitZones(c, v);
  VisitMqtt(c, v);
  VisitMonitoring(c, v);
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
  if (!c.live_view_listen.empty()) {
    // A bare port: loopback only.
    if (c.live_view_listen.find_first_not_of("0123456789") == std::string::npos)
      c.live_view_listen = "127.0.0.1:" + c.live_view_listen;
    const auto live =
        common::ParseHostPort(c.live_view_listen, "live_view.listen", 0, &error, true);
    if (!live) return error;
    if (!IsLoopbackHost(live->host) && c.live_view_token_file.empty()) {
      return "live_view.listen: " + c.live_view_listen +
             " is reachable from other hosts: set live_view.token_file (lrfnet keys token) or "
             "listen on 127.0.0.1";
    }
  }
  if (!(c.live_view_publish_hz >= 0.1 && c.live_view_publish_hz <= 100.0))
    return "live_view.publish_hz: must be in [0.1, 100]";
  if (c.live_view_max_clients < 1 || c.live_view_max_clients > 10000)
    return "live_view.max_clients: must be in [1, 10000]";
  if (c.live_view_background_points > 100000)
    return "live_view.background_points: must be <= 100000";
  if (auto e = ValidateZonesAndMqtt(c)) return e;
  if (auto e = ValidateMonitoring(c)) return e;
  return std::nullopt;
}

std::optional<std::string> ValidateEndedReport(const fusion::FusionOptions& fusion,
                                               const DaemonConfig& rates) {
  return CheckEndedReport(fusion, rates);
}

std::optional<std::string> LoadDaemonConfig(std::string_view yaml_text, DaemonConfig& config) {
  if (auto e = common::LoadYamlConfig(yaml_text,
                                      [&](ConfigVisitor& v) { VisitDaemonConfig(config, v); }))
    return e;
  // Validate quotes values of the file (zone names, addresses): one line whatever they hold.
  if (auto e = Validate(config)) return common::OneLine(*e, 1000);
  return std::nullopt;
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
