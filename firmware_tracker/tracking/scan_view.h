#pragma once
// The tracking pipeline's view of one scan, independent of the codec that produced it.
//
// Frame: the sensor frame of DESIGN.md (x forward, y left, angles counter-clockwise, radians,
// metres). Beam i points at first_angle_rad + i * angle_step_rad. A range of 0 means "no echo";
// ranges are not owned (the span must outlive the call that receives the view).

#include <array>
#include <cstddef>
#include <span>

#include "common/time.h"

namespace lrfnet::tracking {

// Upper bound on beams per scan for every fixed-capacity buffer in the pipeline (an LMS5xx at
// 0.0417° over 190° sends 4561 beams; the shipped captures have at most 1141).
inline constexpr std::size_t kMaxBeams = 4608;

struct ScanView {
  double first_angle_rad = 0.0;
  double angle_step_rad = 0.0;
  std::span<const float> range_m;
  common::UtcNs stamp_ns = 0;
  double scan_period_s = 0.0;

  double BeamAngleRad(std::size_t i) const {
    return first_angle_rad + static_cast<double>(i) * angle_step_rad;
  }
  // Half a beam step before beam i (towards beam i - 1) and after it (towards beam i + 1): where
  // the outline's tangent lies beyond the first and the last beam that returned an object.
  double EdgeBeforeRad(std::size_t i) const { return BeamAngleRad(i) - 0.5 * angle_step_rad; }
  double EdgeAfterRad(std::size_t i) const { return BeamAngleRad(i) + 0.5 * angle_step_rad; }
};

// Why a scan cannot be used at all. A status value, not a string, so rejecting a scan never
// allocates.
enum class ScanError {
  kNone = 0,
  kEmpty,
  kTooManyBeams,   // more than kMaxBeams
  kBadAngles,      // non-finite first angle, non-finite or zero step
  kBadScanPeriod,  // non-positive or non-finite
};

ScanError CheckScan(const ScanView& scan);
const char* ToString(ScanError error);

// cos and sin of every beam's angle (BeamAngleRad, the same values) and of the two angles half a
// step beside it (EdgeBeforeRad, EdgeAfterRad: a silhouette's ends) for one scan geometry, kept
// between scans: Fit recomputes them only when the first angle, the step or the beam count change.
// Fixed storage for kMaxBeams beams, no allocation.
class BeamDirections {
 public:
  // `scan` must pass CheckScan.
  void Fit(const ScanView& scan);
  double cos(std::size_t beam) const { return cos_[beam]; }
  double sin(std::size_t beam) const { return sin_[beam]; }
  // (cos, sin) of EdgeBeforeRad(beam) and EdgeAfterRad(beam).
  const std::array<double, 2>& edge_before(std::size_t beam) const { return before_[beam]; }
  const std::array<double, 2>& edge_after(std::size_t beam) const { return after_[beam]; }

 private:
  double first_angle_rad_ = 0.0;
  double angle_step_rad_ = 0.0;
  std::size_t beams_ = 0;  // 0: nothing computed yet
  std::array<double, kMaxBeams> cos_{};
  std::array<double, kMaxBeams> sin_{};
  std::array<std::array<double, 2>, kMaxBeams> before_{};
  std::array<std::array<double, 2>, kMaxBeams> after_{};
};

}  // namespace lrfnet::tracking
