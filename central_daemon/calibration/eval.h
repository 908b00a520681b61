#pragma once
// Accuracy of a calibration against ground truth, as in Quenzel et al. Tables II-III: per sensor
// the angular error d_R [deg] and the Euclidean distance d_t [m] of its pose, after expressing both
// pose sets in the reference sensor's frame (which removes the arbitrary choice of world frame, the
// "gauge"): ref_from_sensor = inverse(world_from_ref) * world_from_sensor, in each file.

#include <optional>
#include <string>
#include <vector>

#include "central_daemon/calibration/calibration_yaml.h"

namespace lrfnet::calib {

struct SensorError {
  std::string id;
  double d_r_deg = 0.0;  // |yaw difference| wrapped to [0, 180]
  double d_t_m = 0.0;
};

struct EvalResult {
  bool ok = false;
  std::string error;                 // one line when !ok
  std::string reference;             // the sensor both pose sets were expressed in
  std::vector<SensorError> sensors;  // truth order, excluding the reference
  std::vector<std::string> missing;  // in truth but not calibrated (or not in calibration)
  std::vector<std::string> unknown;  // calibrated but not in truth (ignored)
  double mean_d_r_deg = 0.0;
  double median_d_r_deg = 0.0;  // of an even count: the mean of the two middle values
  double mean_d_t_m = 0.0;
  double median_d_t_m = 0.0;
};

// The reference is `reference` if given, else the calibration's `reference`, else the first
// calibrated sensor of the calibration that is also in the truth. Fails (ok = false, error names
// the sensor) when the reference is not calibrated in both files, or when no other sensor can be
// compared.
EvalResult Evaluate(const PoseFile& calibration, const PoseFile& truth,
                    const std::optional<std::string>& reference);

// A table a person reads: one row per sensor, then mean and median, then the missing sensors.
std::string EvalTable(const EvalResult& result);
// One JSON object on one line: {"ok", "reference", "sensors": [{"id", "d_r_deg", "d_t_m"}],
// "mean_d_r_deg", "median_d_r_deg", "mean_d_t_m", "median_d_t_m", "missing", "unknown"}, or
// {"ok": false, "error"}. Ids that are not valid UTF-8 are written with U+FFFD replacements.
std::string EvalJson(const EvalResult& result);

}  // namespace lrfnet::calib
