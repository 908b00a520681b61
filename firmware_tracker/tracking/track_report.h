#pragma once
// What the tracking pipeline reports per scan: the value types the uplink serialises. Sensor frame
// (x forward, y left, metres, radians, DESIGN.md), times in gateway UTC.

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>

#include "common/fixed_capacity.h"
#include "common/time.h"
#include "firmware_tracker/tracking/measurement.h"

namespace lrfnet::tracking {

// Compile-time bound on simultaneous tracks of one sensor; the configured maximum is at most this.
inline constexpr std::size_t kMaxTracks = 64;

// What kind of object a track follows, as the tracker models its cross-section (the wire's
// ObjectShape). kUnspecified: the previous tracker's measurements (no shape state).
enum class ObjectShape : std::uint8_t { kUnspecified, kTorso, kLegs, kCylinder, kBox };

enum class TrackState : std::uint8_t {
  kTentative,  // not yet confirmed (M of N)
  kConfirmed,  // confirmed and updated by a measurement in this scan
  kCoasting,   // confirmed, predicted only (no measurement in this scan)
};

struct TrackReport {
  std::uint32_t track_id = 0;  // stable for the track's life, never reused within a session
  TrackState state = TrackState::kTentative;
  MeasurementKind kind = MeasurementKind::kCenterOfMass;  // of the last measurement used
  double x_m = 0.0;
  double y_m = 0.0;
  double vx_mps = 0.0;
  double vy_mps = 0.0;
  Eigen::Matrix4d covariance = Eigen::Matrix4d::Identity();  // of (x, y, vx, vy)
  std::uint32_t age_scans = 0;                               // scans since the track was created
  std::uint32_t points = 0;  // points of the associated segment(s) (0 when coasting)
  // The scan's measurement the track was updated with (sensor frame, as refined), and its time
  // after the scan start; 0 when coasting. Not on the wire: for evaluating the filter's lag.
  double measured_x_m = 0.0;
  double measured_y_m = 0.0;
  double measured_offset_s = 0.0;
  // Time since the last measurement (0 when measured in this scan). Not on the wire.
  double coasted_s = 0.0;
  // kEllipse: major axis of the fitted ellipse; kShapeFit: direction of the shape's axis a.
  double ellipse_yaw_rad = 0.0;
  // The track's shape state (kShapeFit): semi-axes a (along ellipse_yaw_rad) and b of the torso
  // ellipse, the box's half-lengths, the cylinder's radius (both), or a leg's radius (kLegs, both);
  // size_sigma_m: the square root of the largest eigenvalue of their covariance.
  ObjectShape shape = ObjectShape::kUnspecified;
  double size_major_m = 0.0;
  double size_minor_m = 0.0;
  double size_sigma_m = 0.0;
};

// The tracks of one scan, valid at scan_start_ns (all tracks are predicted to that time).
struct ScanTracks {
  common::UtcNs scan_start_ns = 0;
  double scan_period_s = 0.0;
  std::uint32_t scan_counter = 0;
  common::FixedVector<TrackReport, kMaxTracks> tracks;
};

}  // namespace lrfnet::tracking
