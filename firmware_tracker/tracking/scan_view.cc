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
