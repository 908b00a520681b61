#include "firmware_tracker/io/datagram_encoder.h"

#include <pb_encode.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace lrfnet::io {
namespace {

lrfnet_proto_TrackState ToProto(tracking::TrackState state) {
  switch (state) {
    case tracking::TrackState::kTentative:
      return lrfnet_proto_TrackState_TRACK_STATE_TENTATIVE;
    case tracking::TrackState::kConfirmed:
      return lrfnet_proto_TrackState_TRACK_STATE_CONFIRMED;
    case tracking::TrackState::kCoasting:
      return lrfnet_proto_TrackState_TRACK_STATE_COASTING;
  }
  return lrfnet_proto_TrackState_TRACK_STATE_UNSPECIFIED;
}

lrfnet_proto_MeasurementKind ToProto(tracking::MeasurementKind kind) {
  switch (kind) {
    case tracking::MeasurementKind::kCenterOfMass:
      return lrfnet_proto_MeasurementKind_MEASUREMENT_KIND_CENTER_OF_MASS;
    case tracking::MeasurementKind::kEllipse:
      return lrfnet_proto_MeasurementKind_MEASUREMENT_KIND_ELLIPSE;
    case tracking::MeasurementKind::kShapeFit:
      return lrfnet_proto_MeasurementKind_MEASUREMENT_KIND_SHAPE_FIT;
  }
  return lrfnet_proto_MeasurementKind_MEASUREMENT_KIND_UNSPECIFIED;
}

lrfnet_proto_ObjectShape ToProto(tracking::ObjectShape shape) {
  switch (shape) {
    case tracking::ObjectShape::kUnspecified:
      return lrfnet_proto_ObjectShape_OBJECT_SHAPE_UNSPECIFIED;
    case tracking::ObjectShape::kTorso:
      return lrfnet_proto_ObjectShape_OBJECT_SHAPE_TORSO;
    case tracking::ObjectShape::kLegs:
      return lrfnet_proto_ObjectShape_OBJECT_SHAPE_LEGS;
    case tracking::ObjectShape::kCylinder:
      return lrfnet_proto_ObjectShape_OBJECT_SHAPE_CYLINDER;
    case tracking::ObjectShape::kBox:
      return lrfnet_proto_ObjectShape_OBJECT_SHAPE_BOX;
  }
  return lrfnet_proto_ObjectShape_OBJECT_SHAPE_UNSPECIFIED;
}

lrfnet_proto_MountHeight ToProto(tracking::Mount mount) {
  switch (mount) {
    case tracking::Mount::kTorso:
      return lrfnet_proto_MountHeight_MOUNT_HEIGHT_TORSO;
    case tracking::Mount::kLegs:
      return lrfnet_proto_MountHeight_MOUNT_HEIGHT_LEGS;
  }
  return lrfnet_proto_MountHeight_MOUNT_HEIGHT_UNSPECIFIED;
}

lrfnet_proto_ClockSyncState ToProto(ClockSync sync) {
  switch (sync) {
    case ClockSync::kUnknown:
      return lrfnet_proto_ClockSyncState_CLOCK_SYNC_UNSPECIFIED;
    case ClockSync::kSynchronized:
      return lrfnet_proto_ClockSyncState_CLOCK_SYNC_SYNCHRONIZED;
    case ClockSync::kUnsynchronized:
      return lrfnet_proto_ClockSyncState_CLOCK_SYNC_UNSYNCHRONIZED;
    case ClockSync::kReplay:
      return lrfnet_proto_ClockSyncState_CLOCK_SYNC_REPLAY;
  }
  return lrfnet_proto_ClockSyncState_CLOCK_SYNC_UNSPECIFIED;
}

// Protobuf wire format written directly, with nanopb's rules for proto3 fields: in field-number
// order, defaults left out (a zero number, a float or double whose bits are all zero (nanopb writes
// -0.0), an empty string or repeated field). For the track frames, which are most of the traffic:
// pb_encode walks the field descriptors for every field of every message. The caller sizes the
// output (the bounds are static).
class WireWriter {
 public:
  explicit WireWriter(std::uint8_t* out) : out_(out) {}

  std::size_t size() const { return n_; }

  void Tag(std::uint32_t field, pb_wire_type_t wire_type) {
    Raw((std::uint64_t{field} << 3) | static_cast<std::uint64_t>(wire_type));
  }
  // The bytes are stored through a local pointer and counted in a local: a store through a byte
  // pointer may alias n_, which would otherwise be reloaded after every byte (and a copy through a
  // local array takes a call of memcpy for its variable length).
  void Raw(std::uint64_t v) {
    std::uint8_t* const p = out_ + n_;
    std::size_t k = 0;
    while (v >= 0x80) {
      p[k++] = static_cast<std::uint8_t>(v | 0x80);
      v >>= 7;
    }
    p[k++] = static_cast<std::uint8_t>(v);
    n_ += k;
  }
  void Bytes(const std::uint8_t* data, std::size_t size) {
    std::memcpy(out_ + n_, data, size);
    n_ += size;
  }
  void Le32(std::uint32_t v) {
    const std::uint8_t bytes[4] = {static_cast<std::uint8_t>(v), static_cast<std::uint8_t>(v >> 8),
                                   static_cast<std::uint8_t>(v >> 16),
                                   static_cast<std::uint8_t>(v >> 24)};
    Bytes(bytes, 4);
  }
  // uint32, uint64 and non-negative enums; int64 as its two's complement (10 bytes when negative).
  void Varint(std::uint32_t field, std::uint64_t v) {
    if (v == 0) return;
    Tag(field, PB_WT_VARINT);
    Raw(v);
  }
  void Int64(std::uint32_t field, std::int64_t v) { Varint(field, static_cast<std::uint64_t>(v)); }
  void Fixed32(std::uint32_t field, float v) {
    const std::uint32_t bits = FloatBits(v);
    if (bits == 0) return;
    Tag(field, PB_WT_32BIT);
    Le32(bits);
  }
  void Fixed64(std::uint32_t field, double v) {
    std::uint64_t bits = 0;
    std::memcpy(&bits, &v, sizeof bits);
    if (bits == 0) return;
    Tag(field, PB_WT_64BIT);
    Le32(static_cast<std::uint32_t>(bits));
    Le32(static_cast<std::uint32_t>(bits >> 32));
  }
  void String(std::uint32_t field, const char* text, std::size_t size) {
    if (size == 0) return;
    Tag(field, PB_WT_STRING);
    Raw(size);
    Bytes(reinterpret_cast<const std::uint8_t*>(text), size);
  }
  // A nested message already written: tag, length, bytes.
  void Message(std::uint32_t field, const std::uint8_t* data, std::size_t size) {
    Tag(field, PB_WT_STRING);
    Raw(size);
    Bytes(data, size);
  }

  static std::uint32_t FloatBits(float v) {
    std::uint32_t bits = 0;
    std::memcpy(&bits, &v, sizeof bits);
    return bits;
  }

 private:
  std::uint8_t* out_;
  std::size_t n_ = 0;
};

// One Track, written straight from the report (no lrfnet_proto_Track in between: that struct's
// clearing and copying cost more than the writing); at most kMaxTrackBytes. The values are the
// report's as floats, the fields and bytes those nanopb writes for the Track the report converts
// to (the ellipse's yaw only where the kind is not the centre of mass, the shape's fields only
// where it is specified). *finite: false when a value sent is not finite as a float (such a track
// would poison the daemon's filters); decided by one sum of v - v over the values sent, NaN only if
// one is not finite.
std::size_t WriteTrack(const tracking::TrackReport& r, std::uint8_t* out, bool* finite) {
  const auto x = static_cast<float>(r.x_m);
  const auto y = static_cast<float>(r.y_m);
  const auto vx = static_cast<float>(r.vx_mps);
  const auto vy = static_cast<float>(r.vy_mps);
  // Upper triangle, row-major (the order documented in lrfnet.proto).
  std::array<float, 10> cov;
  std::size_t n = 0;
  for (int row = 0; row < 4; ++row) {
    for (int col = row; col < 4; ++col) cov[n++] = static_cast<float>(r.covariance(row, col));
  }
  const bool has_yaw = r.kind != tracking::MeasurementKind::kCenterOfMass;
  const bool has_shape = r.shape != tracking::ObjectShape::kUnspecified;
  const float yaw = has_yaw ? static_cast<float>(r.ellipse_yaw_rad) : 0.0f;
  const float major = has_shape ? static_cast<float>(r.size_major_m) : 0.0f;
  const float minor = has_shape ? static_cast<float>(r.size_minor_m) : 0.0f;
  const float sigma = has_shape ? static_cast<float>(r.size_sigma_m) : 0.0f;
  float nan_if_not_finite = (x - x) + (y - y) + (vx - vx) + (vy - vy) + (yaw - yaw) +
                            (major - major) + (minor - minor) + (sigma - sigma);
  for (const float v : cov) nan_if_not_finite += v - v;
  *finite = nan_if_not_finite == nan_if_not_finite;

  WireWriter w(out);
  w.Varint(1, r.track_id);
  w.Varint(2, static_cast<std::uint32_t>(ToProto(r.state)));
  w.Varint(3, static_cast<std::uint32_t>(ToProto(r.kind)));
  w.Fixed32(4, x);
  w.Fixed32(5, y);
  w.Fixed32(6, vx);
  w.Fixed32(7, vy);
  // Packed: tag, byte length, the values.
  w.Tag(8, PB_WT_STRING);
  w.Raw(4u * cov.size());
  if constexpr (std::endian::native == std::endian::little) {
    w.Bytes(reinterpret_cast<const std::uint8_t*>(cov.data()), sizeof cov);  // the same bytes
  } else {
    for (const float v : cov) w.Le32(WireWriter::FloatBits(v));
  }
  w.Varint(9, r.age_scans);
  w.Varint(10, r.points);
  w.Fixed32(11, yaw);
  w.Varint(12, static_cast<std::uint32_t>(ToProto(r.shape)));  // 0 where unspecified
  w.Fixed32(13, major);
  w.Fixed32(14, minor);
  w.Fixed32(15, sigma);
  return w.size();
}

std::size_t VarintBytes(std::size_t v) {
  std::size_t n = 1;
  while (v >= 0x80) {
    v >>= 7;
    ++n;
  }
  return n;
}

}  // namespace

bool DatagramFanout::Add(DatagramSink* sink) {
  if (sink == nullptr || count_ == kMaxSinks) return false;
  sinks_[count_++] = sink;
  return true;
}

void DatagramFanout::Send(std::span<const std::uint8_t> datagram, common::UtcNs sent_ns) {
  for (std::size_t i = 0; i < count_; ++i) sinks_[i]->Send(datagram, sent_ns);
}

void DatagramFanout::BeginBatch() {
  for (std::size_t i = 0; i < count_; ++i) sinks_[i]->BeginBatch();
}

void DatagramFanout::EndBatch() {
  for (std::size_t i = 0; i < count_; ++i) sinks_[i]->EndBatch();
}

bool IsValidSensorId(std::string_view id) {
  if (id.empty() || id.size() > kMaxSensorIdLength) return false;
  return std::all_of(id.begin(), id.end(), [](char c) {
    return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' ||
           c == '.' || c == '-';
  });
}

std::optional<std::string> Validate(const DatagramEncoderOptions& options) {
  if (!IsValidSensorId(options.sensor_id))
    return "sensor id '" + options.sensor_id + "' must match [A-Za-z0-9_.-]{1,32}";
  return std::nullopt;
}

DatagramEncoder::DatagramEncoder(const DatagramEncoderOptions& options)
    : session_id_(options.session_id) {
  if (const auto error = Validate(options)) {
    std::fprintf(stderr, "DatagramEncoder: invalid options: %s\n", error->c_str());
    std::abort();
  }
  std::memcpy(sensor_id_.data(), options.sensor_id.data(), options.sensor_id.size());
}

void DatagramEncoder::StartDatagram(pb_size_t payload_tag, common::UtcNs sent_ns) {
  message_.version = lrfnet_proto_ProtocolVersion_PROTOCOL_VERSION_1;
  std::memcpy(message_.sensor_id, sensor_id_.data(), sensor_id_.size());
  message_.sequence = sequence_;
  message_.sent_ns = sent_ns;
  message_.session_id = session_id_;
  message_.which_payload = payload_tag;
}

bool DatagramEncoder::Emit(common::UtcNs sent_ns, DatagramSink& sink) {
  pb_ostream_t stream = pb_ostream_from_buffer(buffer_.data(), buffer_.size());
  if (!pb_encode(&stream, lrfnet_proto_Datagram_fields, &message_)) {
    ++counters_.encode_errors;
    return false;
  }
  sink.Send(std::span<const std::uint8_t>(buffer_.data(), stream.bytes_written), sent_ns);
  ++sequence_;
  ++counters_.datagrams;
  counters_.bytes += stream.bytes_written;
  return true;
}

void DatagramEncoder::CopyString(std::string_view text, char* out, std::size_t capacity) {
  const std::size_t n = std::min(text.size(), capacity - 1);
  if (n < text.size()) ++counters_.truncated_strings;
  for (std::size_t i = 0; i < n; ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    out[i] = (c >= 0x20 && c < 0x7f) ? static_cast<char>(c) : '?';
  }
  out[n] = '\0';
}

std::size_t DatagramEncoder::EncodeTracks(const tracking::ScanTracks& scan, common::UtcNs sent_ns,
                                          DatagramSink& sink) {
  ++counters_.track_frames;
  // Every track is converted and encoded once, into its slot, by WriteTrack. nanopb sizes a
  // submessage before it writes it, so a Track inside a TrackFrame inside a Datagram would be
  // encoded four times; the frame is assembled here from the encoded tracks instead, in field
  // order (the same bytes).
  std::size_t valid = 0;
  for (std::size_t i = 0; i < scan.tracks.size(); ++i) {
    // A track not finite is written into the next slot too, and that slot taken by the next one.
    bool finite = true;
    track_sizes_[valid] = WriteTrack(scan.tracks[i], track_bytes_[valid].data(), &finite);
    valid += finite ? 1 : 0;
  }
  counters_.dropped_tracks += scan.tracks.size() - valid;
  const std::size_t parts = std::max<std::size_t>(1, (valid + kTracksPerPart - 1) / kTracksPerPart);

  std::size_t sent = 0;
  for (std::size_t part = 0; part < parts; ++part) {
    const std::size_t first = part * kTracksPerPart;
    const std::size_t count = std::min(kTracksPerPart, valid - std::min(valid, first));
    StartDatagram(lrfnet_proto_Datagram_track_frame_tag, sent_ns);
    lrfnet_proto_TrackFrame& frame = message_.payload.track_frame;
    frame.scan_start_ns = scan.scan_start_ns;
    frame.scan_period_s = scan.scan_period_s;
    frame.scan_counter = scan.scan_counter;
    frame.part = static_cast<std::uint32_t>(part);
    frame.part_count = static_cast<std::uint32_t>(parts);
    frame.tracks_count = 0;
    if (EmitTrackFrame(first, count, sent_ns, sink)) {
      ++sent;
      ++counters_.track_parts;
      counters_.tracks += count;
    }
  }
  return sent;
}

bool DatagramEncoder::EmitTrackFrame(std::size_t first, std::size_t count, common::UtcNs sent_ns,
                                     DatagramSink& sink) {
  // The frame's own fields (1-5) first, to know its length; then the datagram's fields (1-5), the
  // frame's tag and length, the frame's fields and its tracks (field 6), each with its tag and
  // length: the order and bytes of nanopb's pb_encode of message_ with those tracks.
  const lrfnet_proto_TrackFrame& frame = message_.payload.track_frame;
  std::array<std::uint8_t, 64> head{};
  WireWriter h(head.data());
  h.Int64(1, frame.scan_start_ns);
  h.Fixed64(2, frame.scan_period_s);
  h.Varint(3, frame.scan_counter);
  h.Varint(4, frame.part);
  h.Varint(5, frame.part_count);
  std::size_t frame_bytes = h.size();
  for (std::size_t i = first; i < first + count; ++i) {
    frame_bytes += 1 + VarintBytes(track_sizes_[i]) + track_sizes_[i];
  }
  const std::size_t id_length = std::strlen(message_.sensor_id);
  // Widest header: version, sensor id, three 10-byte varints, the frame's tag and length.
  const std::size_t widest_header = 2 + 2 + id_length + 3 * 11 + 1 + VarintBytes(frame_bytes);
  if (widest_header + frame_bytes > buffer_.size()) {
    ++counters_.encode_errors;
    return false;
  }
  WireWriter w(buffer_.data());
  w.Varint(1, static_cast<std::uint32_t>(message_.version));
  w.String(2, message_.sensor_id, id_length);
  w.Varint(3, message_.sequence);
  w.Int64(4, message_.sent_ns);
  w.Varint(5, message_.session_id);
  w.Tag(lrfnet_proto_Datagram_track_frame_tag, PB_WT_STRING);
  w.Raw(frame_bytes);
  w.Bytes(head.data(), h.size());
  for (std::size_t i = first; i < first + count; ++i) {
    w.Message(lrfnet_proto_TrackFrame_tracks_tag, track_bytes_[i].data(), track_sizes_[i]);
  }
  sink.Send(std::span<const std::uint8_t>(buffer_.data(), w.size()), sent_ns);
  ++sequence_;
  ++counters_.datagrams;
  counters_.bytes += w.size();
  return true;
}

std::size_t DatagramEncoder::EncodeBackground(const BackgroundSnapshotView& snapshot,
                                              common::UtcNs sent_ns, DatagramSink& sink) {
  const std::size_t beams = snapshot.range_m.size();
  if (beams == 0) return 0;
  ++counters_.snapshots;
  const std::size_t parts = (beams + kBeamsPerPart - 1) / kBeamsPerPart;
  std::size_t sent = 0;
  for (std::size_t part = 0; part < parts; ++part) {
    StartDatagram(lrfnet_proto_Datagram_background_tag, sent_ns);
    lrfnet_proto_BackgroundSnapshot& s = message_.payload.background;
    s.snapshot_id = snapshot_id_;
    s.learned_until_ns = snapshot.learned_until_ns;
    s.first_angle_rad = snapshot.first_angle_rad;
    s.angle_step_rad = snapshot.angle_step_rad;
    s.beam_count = static_cast<std::uint32_t>(beams);
    s.part = static_cast<std::uint32_t>(part);
    s.part_count = static_cast<std::uint32_t>(parts);
    const std::size_t first = part * kBeamsPerPart;
    const std::size_t count = std::min(kBeamsPerPart, beams - first);
    s.first_beam = static_cast<std::uint32_t>(first);
    s.ranges_mm_count = static_cast<pb_size_t>(count);
    for (std::size_t i = 0; i < count; ++i) {
      const float r_m = snapshot.range_m[first + i];
      std::uint32_t mm = 0;
      if (std::isfinite(r_m) && r_m > 0.0f) {
        const double v = std::round(static_cast<double>(r_m) * 1000.0);
        if (v > static_cast<double>(kMaxRangeMm)) {
          mm = kMaxRangeMm;
          ++counters_.clamped_ranges;
        } else {
          mm = std::max<std::uint32_t>(1,
                                       static_cast<std::uint32_t>(v));  // a return is never "free"
        }
      }
      s.ranges_mm[i] = mm;
    }
    if (Emit(sent_ns, sink)) {
      ++sent;
      ++counters_.snapshot_parts;
    }
  }
  ++snapshot_id_;
  return sent;
}

bool DatagramEncoder::EncodeHealth(const HealthReport& h, common::UtcNs sent_ns,
                                   DatagramSink& sink) {
  StartDatagram(lrfnet_proto_Datagram_health_tag, sent_ns);
  lrfnet_proto_Health& p = message_.payload.health;
  p = lrfnet_proto_Health{};
  p.scans = h.scans;
  p.bad_frames = h.bad_frames;
  p.decode_errors = h.decode_errors;
  p.reconnects = h.reconnects;
  p.dropped_tracks = h.dropped_tracks;
  p.datagrams_sent = h.datagrams_sent;
  p.send_errors = h.send_errors;
  p.scan_cpu_us_mean = h.scan_cpu_us_mean;
  p.scan_cpu_us_max = h.scan_cpu_us_max;
  p.clock_sync = ToProto(h.clock_sync);
  p.clock_error_estimate_s = h.clock_error_estimate_s;
  p.tick_offset_s = h.tick_offset_s;
  p.tick_drift_ppm = h.tick_drift_ppm;
  p.device_restarts = h.device_restarts;
  const bool ok = Emit(sent_ns, sink);
  counters_.health += ok ? 1 : 0;
  return ok;
}

bool DatagramEncoder::EncodeSensorInfo(const SensorInfoReport& info, common::UtcNs sent_ns,
                                       DatagramSink& sink) {
  StartDatagram(lrfnet_proto_Datagram_sensor_info_tag, sent_ns);
  lrfnet_proto_SensorInfo& p = message_.payload.sensor_info;
  p = lrfnet_proto_SensorInfo{};
  CopyString(info.model, p.model, sizeof(p.model));
  CopyString(info.serial, p.serial, sizeof(p.serial));
  CopyString(info.firmware, p.firmware, sizeof(p.firmware));
  CopyString(info.tracker_version, p.tracker_version, sizeof(p.tracker_version));
  p.first_angle_rad = info.first_angle_rad;
  p.angle_step_rad = info.angle_step_rad;
  p.beam_count = info.beam_count;
  p.fov_rad = info.fov_rad;
  p.scan_frequency_hz = info.scan_frequency_hz;
  p.max_range_m = info.max_range_m;
  p.kind = ToProto(info.kind);
  p.mount = ToProto(info.mount);
  p.accel_psd_m2ps3 = info.accel_psd_m2ps3;
  p.max_speed_mps = info.max_speed_mps;
  const bool ok = Emit(sent_ns, sink);
  counters_.sensor_info += ok ? 1 : 0;
  return ok;
}

}  // namespace lrfnet::io
