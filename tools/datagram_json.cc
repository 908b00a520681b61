#include "tools/datagram_json.h"

#include <charconv>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <optional>
#include <string>

#include "common/datagram_auth.h"
#include "lrfnet.pb.h"

namespace lrfnet::tools {
namespace {

using nlohmann::json;

// A float field as the shortest decimal that reads back as the same float: a double converted
// from 0.1f would print as 0.10000000149011612.
json Float(float v) {
  if (!std::isfinite(v)) return nullptr;
  char buf[32];
  const auto result = std::to_chars(buf, buf + sizeof buf - 1, v);
  *result.ptr = '\0';
  return std::strtod(buf, nullptr);
}

json Double(double v) {
  if (!std::isfinite(v)) return nullptr;
  return v;
}

// Proto3 JSON mapping: the value's name, or its number when the schema has no name for it (an
// open enum keeps unknown values).
template <typename NameFn>
json Enum(int value, NameFn name_of) {
  const std::string& name = name_of(value);
  if (name.empty()) return value;
  return name;
}

json TrackStateJson(int v) {
  return Enum(v, [](int x) -> const std::string& {
    return proto::TrackState_Name(static_cast<proto::TrackState>(x));
  });
}
json MeasurementKindJson(int v) {
  return Enum(v, [](int x) -> const std::string& {
    return proto::MeasurementKind_Name(static_cast<proto::MeasurementKind>(x));
  });
}
json ObjectShapeJson(int v) {
  return Enum(v, [](int x) -> const std::string& {
    return proto::ObjectShape_Name(static_cast<proto::ObjectShape>(x));
  });
}
json MountHeightJson(int v) {
  return Enum(v, [](int x) -> const std::string& {
    return proto::MountHeight_Name(static_cast<proto::MountHeight>(x));
  });
}
json ClockSyncJson(int v) {
  return Enum(v, [](int x) -> const std::string& {
    return proto::ClockSyncState_Name(static_cast<proto::ClockSyncState>(x));
  });
}
json VersionJson(int v) {
  return Enum(v, [](int x) -> const std::string& {
    return proto::ProtocolVersion_Name(static_cast<proto::ProtocolVersion>(x));
  });
}

json TrackJson(const proto::Track& t) {
  json covariance = json::array();
  for (const float c : t.covariance()) covariance.push_back(Float(c));
  return {{"track_id", t.track_id()},
          {"state", TrackStateJson(t.state())},
          {"kind", MeasurementKindJson(t.kind())},
          {"x_m", Float(t.x_m())},
          {"y_m", Float(t.y_m())},
          {"vx_mps", Float(t.vx_mps())},
          {"vy_mps", Float(t.vy_mps())},
          {"covariance", std::move(covariance)},
          {"age_scans", t.age_scans()},
          {"points", t.points()},
          {"ellipse_yaw_rad", Float(t.ellipse_yaw_rad())},
          {"shape", ObjectShapeJson(t.shape())},
          {"size_major_m", Float(t.size_major_m())},
          {"size_minor_m", Float(t.size_minor_m())},
          {"size_sigma_m", Float(t.size_sigma_m())}};
}

json TrackFrameJson(const proto::TrackFrame& f) {
  json tracks = json::array();
  for (const proto::Track& t : f.tracks()) tracks.push_back(TrackJson(t));
  return {{"scan_start_ns", f.scan_start_ns()}, {"scan_period_s", Double(f.scan_period_s())},
          {"scan_counter", f.scan_counter()},   {"part", f.part()},
          {"part_count", f.part_count()},       {"tracks", std::move(tracks)}};
}

json BackgroundJson(const proto::BackgroundSnapshot& b) {
  json ranges = json::array();
  for (const std::uint32_t r : b.ranges_mm()) ranges.push_back(r);
  return {{"snapshot_id", b.snapshot_id()},
          {"learned_until_ns", b.learned_until_ns()},
          {"first_angle_rad", Double(b.first_angle_rad())},
          {"angle_step_rad", Double(b.angle_step_rad())},
          {"beam_count", b.beam_count()},
          {"part", b.part()},
          {"part_count", b.part_count()},
          {"first_beam", b.first_beam()},
          {"ranges_mm", std::move(ranges)}};
}

json HealthJson(const proto::Health& h) {
  return {{"scans", h.scans()},
          {"bad_frames", h.bad_frames()},
          {"decode_errors", h.decode_errors()},
          {"reconnects", h.reconnects()},
          {"dropped_tracks", h.dropped_tracks()},
          {"datagrams_sent", h.datagrams_sent()},
          {"send_errors", h.send_errors()},
          {"scan_cpu_us_mean", Float(h.scan_cpu_us_mean())},
          {"scan_cpu_us_max", Float(h.scan_cpu_us_max())},
          {"clock_sync", ClockSyncJson(h.clock_sync())},
          {"clock_error_estimate_s", Float(h.clock_error_estimate_s())},
          {"tick_offset_s", Double(h.tick_offset_s())},
          {"tick_drift_ppm", Double(h.tick_drift_ppm())},
          {"device_restarts", h.device_restarts()}};
}

json SensorInfoJson(const proto::SensorInfo& s) {
  return {{"model", s.model()},
          {"serial", s.serial()},
          {"firmware", s.firmware()},
          {"first_angle_rad", Double(s.first_angle_rad())},
          {"angle_step_rad", Double(s.angle_step_rad())},
          {"beam_count", s.beam_count()},
          {"fov_rad", Double(s.fov_rad())},
          {"scan_frequency_hz", Double(s.scan_frequency_hz())},
          {"max_range_m", Double(s.max_range_m())},
          {"tracker_version", s.tracker_version()},
          {"kind", MeasurementKindJson(s.kind())},
          {"mount", MountHeightJson(s.mount())},
          {"accel_psd_m2ps3", Double(s.accel_psd_m2ps3())},
          {"max_speed_mps", Double(s.max_speed_mps())}};
}

json RequestJson(const proto::Request& r) {
  return {{"send_sensor_info", r.send_sensor_info()}, {"send_background", r.send_background()}};
}

std::string Dump(const json& j) {
  // Strings come from the wire and the file: never let a bad byte sequence throw.
  return j.dump(-1, ' ', false, json::error_handler_t::replace);
}

std::optional<proto::Datagram> Parse(std::span<const std::uint8_t> bytes) {
  proto::Datagram datagram;
  if (bytes.size() > static_cast<std::size_t>(std::numeric_limits<int>::max()) ||
      !datagram.ParseFromArray(bytes.data(), static_cast<int>(bytes.size()))) {
    return std::nullopt;
  }
  return datagram;
}

// A datagram's protobuf bytes and what its envelope said (see the header).
struct Opened {
  std::span<const std::uint8_t> payload;  // empty when it cannot be read
  bool sealed = false;
  bool verified = false;
  bool refused = false;
  json auth;  // null when not sealed
};

Opened Open(std::span<const std::uint8_t> bytes, daemon::DatagramVerifier* verifier) {
  Opened o;
  o.payload = bytes;
  if (!auth::LooksSealed(bytes)) return o;
  o.sealed = true;
  o.payload = {};
  auth::Envelope e;
  const auth::HeaderError header = auth::ParseEnvelope(bytes, &e);
  if (header != auth::HeaderError::kNone) {
    o.refused = true;
    o.auth = {{"verified", false}, {"error", "auth_header"}, {"detail", auth::ToString(header)}};
    return o;
  }
  o.auth = {{"sensor_id", std::string(e.sensor_id)},
            {"epoch", e.epoch},
            {"key_id", e.key_id},
            {"counter", e.counter},
            {"encrypted", e.encrypted},
            {"direction", e.direction == auth::Direction::kToDaemon ? "to_daemon" : "to_tracker"},
            {"verified", false}};
  if (verifier == nullptr) {
    if (e.encrypted) {
      o.refused = true;
      o.auth["error"] = "encrypted";
    } else {
      o.payload = e.payload;
    }
    return o;
  }
  const daemon::AuthResult r = verifier->Verify(bytes, 0);
  if (!r.ok()) {
    o.refused = true;
    o.auth["error"] = daemon::ToString(r.failure);
    return o;
  }
  verifier->Commit(r);
  o.verified = true;
  o.auth["verified"] = true;
  o.payload = r.payload;
  return o;
}

json OpenedJson(common::UtcNs receive_ns, std::string_view source, std::size_t size,
                const Opened& opened) {
  std::optional<proto::Datagram> datagram;
  if (!opened.payload.empty()) datagram = Parse(opened.payload);
  json j;
  if (datagram) {
    j = DatagramFieldsJson(*datagram);
  } else if (!opened.refused) {
    j = json{{"error", kNotADatagram}};
  } else {
    j = json::object();
  }
  if (opened.sealed) j["auth"] = opened.auth;
  j["receive_ns"] = receive_ns;
  j["source"] = std::string(source);
  j["size"] = size;
  return j;
}

}  // namespace

std::string_view DatagramKindName(const proto::Datagram& datagram) {
  switch (datagram.payload_case()) {
    case proto::Datagram::kTrackFrame:
      return "track_frame";
    case proto::Datagram::kBackground:
      return "background";
    case proto::Datagram::kHealth:
      return "health";
    case proto::Datagram::kSensorInfo:
      return "sensor_info";
    case proto::Datagram::kRequest:
      return "request";
    case proto::Datagram::PAYLOAD_NOT_SET:
      break;
  }
  return "none";
}

json DatagramFieldsJson(const proto::Datagram& d) {
  json j = {{"version", VersionJson(d.version())},
            {"sensor_id", d.sensor_id()},
            {"sequence", d.sequence()},
            {"sent_ns", d.sent_ns()},
            {"session_id", d.session_id()},
            {"kind", std::string(DatagramKindName(d))}};
  switch (d.payload_case()) {
    case proto::Datagram::kTrackFrame:
      j["track_frame"] = TrackFrameJson(d.track_frame());
      break;
    case proto::Datagram::kBackground:
      j["background"] = BackgroundJson(d.background());
      break;
    case proto::Datagram::kHealth:
      j["health"] = HealthJson(d.health());
      break;
    case proto::Datagram::kSensorInfo:
      j["sensor_info"] = SensorInfoJson(d.sensor_info());
      break;
    case proto::Datagram::kRequest:
      j["request"] = RequestJson(d.request());
      break;
    case proto::Datagram::PAYLOAD_NOT_SET:
      break;
  }
  return j;
}

json DatagramJson(common::UtcNs receive_ns, std::string_view source,
                  std::span<const std::uint8_t> bytes, daemon::DatagramVerifier* verifier) {
  return OpenedJson(receive_ns, source, bytes.size(), Open(bytes, verifier));
}

std::string DatagramJsonLine(common::UtcNs receive_ns, std::string_view source,
                             std::span<const std::uint8_t> bytes,
                             daemon::DatagramVerifier* verifier) {
  return Dump(DatagramJson(receive_ns, source, bytes, verifier));
}

namespace {

void AddOpened(DatagramSummary& s, common::UtcNs receive_ns, std::size_t size,
               const Opened& opened) {
  ++s.datagrams;
  s.bytes += size;
  if (!s.first_receive_ns) s.first_receive_ns = receive_ns;
  if (s.last_receive_ns && receive_ns < *s.last_receive_ns) ++s.receive_time_steps_back;
  s.last_receive_ns = receive_ns;
  s.sealed += opened.sealed ? 1 : 0;
  s.verified += opened.verified ? 1 : 0;
  if (opened.refused) {
    ++s.auth_refused;
    return;
  }
  const std::optional<proto::Datagram> datagram =
      opened.payload.empty() ? std::nullopt : Parse(opened.payload);
  if (!datagram) {
    ++s.parse_errors;
    return;
  }
  auto& by_kind = s.by_kind;
  auto& by_sensor_kind = s.by_sensor_kind;
  const std::string kind(DatagramKindName(*datagram));
  ++by_kind[kind];
  auto sensor = by_sensor_kind.find(datagram->sensor_id());
  if (sensor == by_sensor_kind.end()) {
    if (by_sensor_kind.size() >= kMaxSummarySensors) {
      ++s.sensors_over_limit;
      return;
    }
    sensor =
        by_sensor_kind.emplace(datagram->sensor_id(), std::map<std::string, std::uint64_t>{}).first;
  }
  ++sensor->second[kind];
}

}  // namespace

void DatagramSummary::Add(common::UtcNs receive_ns, std::span<const std::uint8_t> datagram_bytes,
                          daemon::DatagramVerifier* verifier) {
  AddOpened(*this, receive_ns, datagram_bytes.size(), Open(datagram_bytes, verifier));
}

std::string DatagramSummaryJson(const DatagramSummary& s, const daemon::DatagramSource& source) {
  const daemon::DatagramSourceCounters& c = source.counters();
  const bool recording = source.kind() == daemon::DatagramFileKind::kRecording;
  json file = {{"kind", recording ? "recording" : "capture"},
               {"datagrams", c.datagrams},
               {"files", c.files},
               {"packets", c.packets},
               {"malformed_packets", c.malformed_packets},
               {"other_packets", c.other_packets}};
  if (recording) {
    file["format_version"] = source.format_version();
    file["created_ns"] = source.created_ns();
    file["writer"] = source.writer();
  }
  json sensors = json::object();
  for (const auto& [sensor, kinds] : s.by_sensor_kind) sensors[sensor] = kinds;
  json j = {{"datagrams", s.datagrams},
            {"bytes", s.bytes},
            {"parse_errors", s.parse_errors},
            {"sealed", s.sealed},
            {"verified", s.verified},
            {"auth_refused", s.auth_refused},
            {"first_receive_ns", s.first_receive_ns ? json(*s.first_receive_ns) : json(nullptr)},
            {"last_receive_ns", s.last_receive_ns ? json(*s.last_receive_ns) : json(nullptr)},
            {"receive_time_steps_back", s.receive_time_steps_back},
            {"kinds", s.by_kind},
            {"sensors", std::move(sensors)},
            {"sensors_over_limit", s.sensors_over_limit},
            {"file", std::move(file)}};
  if (!source.error().empty()) j["error"] = source.error();
  return Dump(j);
}

bool DumpDatagrams(daemon::DatagramSource& source, std::ostream* out, DatagramSummary* summary,
                   std::string* error, daemon::DatagramVerifier* verifier) {
  daemon::ReceivedDatagram datagram;
  while (true) {
    const daemon::SourceStatus status = source.Next(&datagram);
    if (status == daemon::SourceStatus::kEnd) return true;
    if (status == daemon::SourceStatus::kError) {
      *error = source.error();
      return false;
    }
    // Opened once: with keys, a second verification would see its own counter as replayed.
    const Opened opened = Open(datagram.bytes, verifier);
    if (out != nullptr) {
      *out << Dump(OpenedJson(datagram.receive_ns, datagram.source, datagram.bytes.size(), opened))
           << '\n';
    }
    if (summary != nullptr) AddOpened(*summary, datagram.receive_ns, datagram.bytes.size(), opened);
  }
}

}  // namespace lrfnet::tools
