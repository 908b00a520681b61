#include "firmware_tracker/tracking/scan_view.h"

#include <cmath>

namespace lrfnet::tracking {

ScanError CheckScan(const ScanView& scan) {
  if (scan.range_m.empty()) return ScanError::kEmpty;
  if (scan.range_m.size() > kMaxBeams) return ScanError::kTooManyBeams;
  if (!std::isfinite(scan.first_angle_rad) || !std::isfinite(scan.angle_step_rad) ||
      scan.angle_step_rad == 0.0) {
    return ScanError::kBadAngles;
  }
  if (!std::isfinite(scan.scan_period_s) || scan.scan_period_s <= 0.0) {
    return ScanError::kBadScanPeriod;
  }
  return ScanError::kNone;
}

void BeamDirections::Fit(const ScanView& scan) {
  const std::size_t beams = scan.range_m.size();
  if (beams == beams_ && scan.first_angle_rad == first_angle_rad_ &&
      scan.angle_step_rad == angle_step_rad_) {
    return;
  }
  first_angle_rad_ = scan.first_angle_rad;
  angle_step_rad_ = scan.angle_step_rad;
  beams_ = beams;
  for (std::size_t i = 0; i < beams; ++i) {
    const double angle_rad = scan.BeamAngleRad(i);
    cos_[i] = std::cos(angle_rad);
    sin_[i] = std::sin(angle_rad);
    const double before_rad = scan.EdgeBeforeRad(i), after_rad = scan.EdgeAfterRad(i);
    before_[i] = {std::cos(before_rad), std::sin(before_rad)};
    after_[i] = {std::cos(after_rad), std::sin(after_rad)};
  }
}

const char* ToString(ScanError error) {
  switch (error) {
    case ScanError::kNone:
      return "ok";
    case ScanError::kEmpty:
      return "scan has no beams";
    case ScanError::kTooManyBeams:
      return "scan has more beams than the tracker's capacity";
    case ScanError::kBadAngles:
      return "scan angles are not finite or the step is zero";
    case ScanError::kBadScanPeriod:
      return "scan period is not a positive finite number";
  }
  return "unknown scan error";
}

}  // namespace lrfnet::tracking
