#pragma once
// Value types of what the daemon keeps from the sensors: the daemon's own representation of the
// wire messages (lrfnet.proto), made by the ingest from validated datagrams (the one place where
// protobuf is converted) and used by the store, calibration and fusion. Units and frames as in the
// proto: SI units, positions in the sensor frame, times UTC nanoseconds of the gateway clock
// (`*_ns`) unless the name says receive (`receive_ns`: the daemon's clock).

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "common/time.h"

namespace lrfnet::daemon {

enum class TrackState : std::uint8_t { kTentative, kConfirmed, kCoasting };
// kShapeFit: the body centre from a fit of the track's shape with a per-track size (proto SHAPE_FIT).
enum class MeasurementKind : std::uint8_t { kUnspecified, kCenterOfMass, kEllipse, kShapeFit };
// The object's cross-section as the tracker models it (proto ObjectShape); kUnspecified from old
// trackers, which means a person's torso with the receiver's prior size.
enum class ObjectShape : std::uint8_t { kUnspecified, kTorso, kLegs, kCylinder, kBox };
enum class MountHeight : std::uint8_t { kUnspecified, kTorso, kLegs };

// One track in one scan (proto Track).
struct TrackObservation {
  std::uint32_t track_id = 0;
  TrackState state = TrackState::kTentative;
  MeasurementKind kind = MeasurementKind::kUnspecified;
  float x_m = 0.0f;
  float y_m = 0.0f;
  float vx_mps = 0.0f;
  float vy_mps = 0.0f;
  // (x, y, vx, vy) covariance, upper triangle row-major: xx, xy, xvx, xvy, yy, yvx, yvy, vxvx,
  // vxvy, vyvy. Positive semi-definite (validated).
  std::array<float, 10> covariance{};
  std::uint32_t age_scans = 0;
  std::uint32_t points = 0;
  float ellipse_yaw_rad = 0.0f;  // major axis of the ellipse / shape, sensor frame
  // The tracker's size estimate (0 from old trackers: unknown, use a prior). Semi-axes in metres.
  ObjectShape shape = ObjectShape::kUnspecified;
  float size_major_m = 0.0f;
  float size_minor_m = 0.0f;
  float size_sigma_m = 0.0f;
};

// The tracks of one scan (proto TrackFrame), or of one part of them as received: part < part_count.
// The store merges the parts of a scan into one frame (part = 0, part_count = parts held).
struct TrackFrameData {
  std::uint64_t session_id = 0;  // tracker session (Datagram.session_id)
  common::UtcNs scan_start_ns = 0;
  double scan_period_s = 0.0;
  std::uint32_t scan_counter = 0;
  std::uint32_t part = 0;
  std::uint32_t part_count = 1;
  common::UtcNs sent_ns = 0;     // Datagram.sent_ns (gateway clock)
  common::UtcNs receive_ns = 0;  // daemon clock
  std::vector<TrackObservation> tracks;
};

// A complete background snapshot (all parts of one snapshot_id), polar, sensor frame.
struct BackgroundScan {
  std::uint64_t session_id = 0;
  std::uint32_t snapshot_id = 0;
  common::UtcNs learned_until_ns = 0;
  double first_angle_rad = 0.0;
  double angle_step_rad = 0.0;
  std::vector<std::uint32_t> ranges_mm;  // one per beam; 0 = no static return
  common::UtcNs receive_ns = 0;          // when the last part arrived
};

// The device and tracker description (proto SensorInfo).
struct SensorDescription {
  std::string model;
  std::string serial;
  std::string firmware;
  double first_angle_rad = 0.0;
  double angle_step_rad = 0.0;
  std::uint32_t beam_count = 0;
  double fov_rad = 0.0;
  double scan_frequency_hz = 0.0;
  double max_range_m = 0.0;
  std::string tracker_version;
  MeasurementKind kind = MeasurementKind::kUnspecified;
  MountHeight mount = MountHeight::kUnspecified;
  double accel_psd_m2ps3 = 0.0;  // the tracker's CV model; 0 = not sent (old tracker)
  double max_speed_mps = 0.0;    // the tracker's motion limit; 0 = not sent
};

enum class ClockSync : std::uint8_t { kUnknown, kSynchronized, kUnsynchronized, kReplay };

// The latest Health of a sensor.
struct SensorHealth {
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
  common::UtcNs sent_ns = 0;
  common::UtcNs receive_ns = 0;
};

const char* ToString(TrackState state);
const char* ToString(MeasurementKind kind);
const char* ToString(ObjectShape shape);
const char* ToString(MountHeight mount);
const char* ToString(ClockSync sync);

}  // namespace lrfnet::daemon
