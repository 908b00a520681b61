#pragma once
// Serialises the tracker's reports into lrfnet.proto `Datagram`s of at most kMaxPayloadBytes (1328)
// each, so that they stay within 1400 bytes when sealed (SealingSink).
//
// Runtime: nanopb, not libprotobuf(-lite). nanopb generates plain C structs from the same .proto,
// with every string, bytes and repeated field a fixed array sized in lrfnet.options (a field
// without a bound is a generator error), and encodes them into a caller-provided byte buffer. So
// there is no heap allocation by construction, the memory of the whole path is known at compile
// time, and the runtime is a 40 kB static library that cross-builds without libprotobuf. The bytes
// are the protobuf wire format: the daemon decodes them with libprotobuf (uplink_wire_test proves
// it field by field). protobuf-lite would need reused messages whose std::string / RepeatedField
// capacity has grown before counting starts, gives no size bound at compile time, and is a much
// larger dependency on the gateway. (Debian builds the nanopb runtime with PB_ENABLE_MALLOC; it
// allocates only for FT_POINTER fields, which the options exclude.)
//
// Contract:
// - Every datagram carries version 1, the sensor id, the session id and a sequence number that
//   starts at 0 and grows by 1 per datagram handed to the sink (an encoding failure, counted,
//   consumes none).
// - Track frames: one per scan, split into parts of kTracksPerPart tracks (part 0..part_count-1,
//   same scan_start_ns); a scan without tracks is still one part, so the daemon sees every scan.
//   Tracks with a non-finite position, velocity or covariance are dropped (counted). Covariance:
//   upper triangle of the (x, y, vx, vy) covariance, row-major (xx, xy, xvx, xvy, yy, yvx, yvy,
//   vxvx, vxvy, vyvy), as floats. ellipse_yaw_rad is sent for kinds ellipse and shape fit (the
//   shape's axis a); shape, size_major_m, size_minor_m and size_sigma_m for tracks with a shape
//   state (kind shape fit; lrfnet.proto documents their meaning), else left at 0 (unspecified).
// - Background snapshots: the model's per-beam range (metres, 0 = free) as millimetres, rounded,
//   clamped to [1, kMaxRangeMm] (clamps counted); 0, negative and non-finite ranges are 0 = free.
//   Split into parts of kBeamsPerPart consecutive beams; every part carries the same snapshot_id,
//   which grows by one per snapshot starting at 0.
// - Strings of SensorInfo are cut to their bound (counted) and non-printable-ASCII bytes become
//   '?', so the proto3 string fields are always valid UTF-8.
// - sent_ns is the caller's gateway UTC time for all datagrams of one call.
// Not thread-safe; no allocation after construction.

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "common/datagram_auth.h"
#include "common/time.h"
#include "firmware_tracker/io/system_clock.h"
#include "firmware_tracker/tracking/measurement.h"
#include "firmware_tracker/tracking/track_report.h"
#include "lrfnet.nanopb.h"

namespace lrfnet::io {

inline constexpr std::size_t kMaxDatagramBytes = 1400;
// What the encoder may use of a datagram: the rest is room for the authenticated envelope
// (SealingSink, common/datagram_auth.h), so that a sealed datagram stays within 1400 bytes.
// Unsealed datagrams keep the same parts.
inline constexpr std::size_t kMaxPayloadBytes = kMaxDatagramBytes - auth::kMaxOverheadBytes;
// Measured worst cases (uplink tests): 11 tracks -> 1298 bytes, 398 beams -> 1328 bytes.
inline constexpr std::size_t kTracksPerPart = 11;
inline constexpr std::size_t kBeamsPerPart = 398;
inline constexpr std::uint32_t kMaxRangeMm = (1u << 21) - 1;  // 3 varint bytes
inline constexpr std::size_t kMaxSensorIdLength = 32;
// An encoded Track (without its tag and length in the frame): at most 106 bytes (lrfnet.options).
inline constexpr std::size_t kMaxTrackBytes = 127;

static_assert(sizeof(lrfnet_proto_TrackFrame::tracks) / sizeof(lrfnet_proto_Track) ==
              kTracksPerPart);
static_assert(sizeof(lrfnet_proto_BackgroundSnapshot::ranges_mm) / sizeof(std::uint32_t) ==
              kBeamsPerPart);
static_assert(sizeof(lrfnet_proto_Datagram::sensor_id) == kMaxSensorIdLength + 1);

// Where serialised datagrams go: the UDP uplink, a recording, or both (DatagramFanout).
class DatagramSink {
 public:
  virtual ~DatagramSink() = default;
  // One serialised Datagram of at most kMaxPayloadBytes; the bytes are valid during the call only.
  // sent_ns is the datagram's own sent_ns field.
  virtual void Send(std::span<const std::uint8_t> datagram, common::UtcNs sent_ns) = 0;
  // The datagrams Sent after BeginBatch() may be held until EndBatch(), which passes on every one
  // still held, in the order they were sent (the UDP uplink: all of them in one system call). A
  // sink that passes each datagram on at once ignores both (the defaults).
  virtual void BeginBatch() {}
  virtual void EndBatch() {}
};

// Hands every datagram to up to kMaxSinks sinks in the order they were added. Not owning.
class DatagramFanout final : public DatagramSink {
 public:
  static constexpr std::size_t kMaxSinks = 4;
  // False when full or null.
  [[nodiscard]] bool Add(DatagramSink* sink);
  void Send(std::span<const std::uint8_t> datagram, common::UtcNs sent_ns) override;
  void BeginBatch() override;
  void EndBatch() override;

 private:
  std::array<DatagramSink*, kMaxSinks> sinks_{};
  std::size_t count_ = 0;
};

// [A-Za-z0-9_.-]{1,32}
bool IsValidSensorId(std::string_view id);

struct DatagramEncoderOptions {
  std::string sensor_id;         // IsValidSensorId
  std::uint64_t session_id = 0;  // random per tracker start (the caller draws it)
};
std::optional<std::string> Validate(const DatagramEncoderOptions& options);

// The background model as the snapshot sends it. The span must outlive the call.
struct BackgroundSnapshotView {
  common::UtcNs learned_until_ns = 0;
  double first_angle_rad = 0.0;  // sensor frame
  double angle_step_rad = 0.0;
  std::span<const float> range_m;  // per beam, 0 = free (BackgroundModel::background_range_m())
};

// Health payload; see lrfnet.proto `Health` for the meaning of each field.
struct HealthReport {
  std::uint64_t scans = 0;
  std::uint64_t bad_frames = 0;
  std::uint64_t decode_errors = 0;
  std::uint64_t reconnects = 0;
  std::uint64_t dropped_tracks = 0;
  std::uint64_t datagrams_sent = 0;
  std::uint64_t send_errors = 0;
  float scan_cpu_us_mean = 0.0f;
  float scan_cpu_us_max = 0.0f;
  ClockSync clock_sync = ClockSync::kUnknown;
  float clock_error_estimate_s = 0.0f;
  double tick_offset_s = 0.0;
  double tick_drift_ppm = 0.0;
  std::uint64_t device_restarts = 0;
};

// SensorInfo payload. Views must outlive the call.
struct SensorInfoReport {
  std::string_view model;     // <= 64 bytes sent
  std::string_view serial;    // <= 32 bytes sent
  std::string_view firmware;  // <= 64 bytes sent
  double first_angle_rad = 0.0;
  double angle_step_rad = 0.0;
  std::uint32_t beam_count = 0;
  double fov_rad = 0.0;
  double scan_frequency_hz = 0.0;
  double max_range_m = 0.0;
  std::string_view tracker_version;  // <= 64 bytes sent
  tracking::MeasurementKind kind = tracking::MeasurementKind::kCenterOfMass;
  tracking::Mount mount = tracking::Mount::kTorso;
  double accel_psd_m2ps3 = 0.0;  // the tracker's constant-velocity model
  double max_speed_mps = 0.0;    // and its speed limit
};

struct DatagramEncoderCounters {
  std::uint64_t datagrams = 0;  // handed to a sink
  std::uint64_t bytes = 0;
  std::uint64_t track_frames = 0;
  std::uint64_t track_parts = 0;
  std::uint64_t tracks = 0;
  std::uint64_t dropped_tracks = 0;  // non-finite values (or, never seen, not encodable)
  std::uint64_t snapshots = 0;
  std::uint64_t snapshot_parts = 0;
  std::uint64_t clamped_ranges = 0;
  std::uint64_t health = 0;
  std::uint64_t sensor_info = 0;
  std::uint64_t truncated_strings = 0;
  // nanopb refused to encode (cannot happen within the static bounds; counted all the same).
  std::uint64_t encode_errors = 0;
};

class DatagramEncoder {
 public:
  // Precondition: Validate(options) is nullopt (checked; aborts otherwise).
  explicit DatagramEncoder(const DatagramEncoderOptions& options);

  // Returns the number of datagrams handed to the sink (>= 1 unless encoding failed).
  std::size_t EncodeTracks(const tracking::ScanTracks& scan, common::UtcNs sent_ns,
                           DatagramSink& sink);
  // Returns the number of parts handed to the sink; an empty snapshot sends nothing and uses no id.
  std::size_t EncodeBackground(const BackgroundSnapshotView& snapshot, common::UtcNs sent_ns,
                               DatagramSink& sink);
  bool EncodeHealth(const HealthReport& health, common::UtcNs sent_ns, DatagramSink& sink);
  bool EncodeSensorInfo(const SensorInfoReport& info, common::UtcNs sent_ns, DatagramSink& sink);

  std::uint64_t next_sequence() const { return sequence_; }
  std::uint32_t next_snapshot_id() const { return snapshot_id_; }
  const DatagramEncoderCounters& counters() const { return counters_; }

 private:
  void StartDatagram(pb_size_t payload_tag, common::UtcNs sent_ns);
  bool Emit(common::UtcNs sent_ns, DatagramSink& sink);
  // message_'s header and track frame (without tracks) with the encoded tracks [first, first +
  // count) as its tracks.
  bool EmitTrackFrame(std::size_t first, std::size_t count, common::UtcNs sent_ns,
                      DatagramSink& sink);
  void CopyString(std::string_view text, char* out, std::size_t capacity);

  std::array<char, kMaxSensorIdLength + 1> sensor_id_{};
  std::uint64_t session_id_ = 0;
  std::uint64_t sequence_ = 0;
  std::uint32_t snapshot_id_ = 0;
  DatagramEncoderCounters counters_;
  lrfnet_proto_Datagram message_{};
  std::array<std::uint8_t, kMaxPayloadBytes> buffer_{};
  std::array<std::array<std::uint8_t, kMaxTrackBytes>, tracking::kMaxTracks> track_bytes_{};
  std::array<std::size_t, tracking::kMaxTracks> track_sizes_{};
};

}  // namespace lrfnet::io
