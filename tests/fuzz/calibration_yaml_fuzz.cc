// Fuzz target for the calibration.yaml reader (lrfnetd's calibration.initial / --calibration-in,
// `lrfnet eval`): arbitrary bytes as one file's text (seeds: files the writer made, the simulator's
// truth format, files from before the covariance and bias keys, damaged copies).
// Properties checked with __builtin_trap:
//   - ParsePoseYaml either succeeds, or fails with a non-empty one-line error and leaves *out as it
//     was;
//   - on success the file has sensors with unique ids, every parallel vector has one entry per
//     sensor, a calibrated sensor's pose is finite and within the documented bounds with yaw in
//     (-pi, pi], a covariance is finite, symmetric, positive semi-definite (within rounding), a
//     radial bias is finite with sigma >= 0, `reference` names a calibrated sensor, and the track
//     residual is a number >= 0;
//   - what was read, written again by CalibrationYaml, reads back with the same ids, calibrated
//     flags, poses (to 1e-9), flags and mount verdicts (the writer's output always reads).

#include <Eigen/Eigenvalues>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <numbers>
#include <set>
#include <string>

#include "central_daemon/calibration/calibration_yaml.h"
#include "common/eigen_instances.h"
#include "common/geometry.h"

namespace {

using lrfnet::calib::CalibrationResult;
using lrfnet::calib::PoseFile;
using lrfnet::calib::SensorPose;

void Check(bool ok) {
  if (!ok) __builtin_trap();
}

bool Finite(const Eigen::Matrix3d& m) { return m.allFinite(); }

void CheckCovariance(const Eigen::Matrix3d& c) {
  Check(Finite(c));
  Check((c - c.transpose()).cwiseAbs().maxCoeff() <= 1e-12 * (1.0 + c.cwiseAbs().maxCoeff()));
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(c, Eigen::EigenvaluesOnly);
  Check(eig.eigenvalues().minCoeff() >= -1e-9 * (1.0 + c.cwiseAbs().maxCoeff()));
}

void CheckFile(const PoseFile& f) {
  const std::size_t n = f.sensors.size();
  Check(n > 0);
  Check(f.calibrated.size() == n && f.radial_bias.size() == n && f.covariance.size() == n &&
        f.flag.size() == n && f.mount_looks_like_legs.size() == n);
  std::set<std::string> ids;
  for (std::size_t i = 0; i < n; ++i) {
    const auto& [id, pose] = f.sensors[i];
    Check(ids.insert(id).second);
    if (f.calibrated[i]) {
      Check(std::isfinite(pose.x_m) && std::isfinite(pose.y_m) && std::isfinite(pose.yaw_rad));
      Check(std::abs(pose.x_m) <= lrfnet::calib::kMaxPoseCoordinateM &&
            std::abs(pose.y_m) <= lrfnet::calib::kMaxPoseCoordinateM);
      Check(pose.yaw_rad > -std::numbers::pi - 1e-12 && pose.yaw_rad <= std::numbers::pi + 1e-12);
    }
    if (f.covariance[i]) CheckCovariance(*f.covariance[i]);
    if (f.radial_bias[i]) {
      Check(std::isfinite(f.radial_bias[i]->bias_m) && std::isfinite(f.radial_bias[i]->sigma_m));
      Check(f.radial_bias[i]->sigma_m >= 0.0);
      Check(std::abs(f.radial_bias[i]->bias_m) <= lrfnet::calib::kMaxRadialBiasM);
    }
  }
  if (f.reference) {
    const auto at = f.Find(*f.reference);
    Check(at.has_value() && f.calibrated[*at]);
  }
  if (f.track_residual_rms_m) {
    Check(std::isfinite(*f.track_residual_rms_m) && *f.track_residual_rms_m >= 0.0);
  }
}

CalibrationResult ResultOf(const PoseFile& f) {
  CalibrationResult r;
  r.method = "fuzz";
  if (f.reference) r.reference = *f.reference;
  for (std::size_t i = 0; i < f.sensors.size(); ++i) {
    SensorPose p;
    p.id = f.sensors[i].first;
    p.calibrated = f.calibrated[i];
    p.world_from_sensor = f.sensors[i].second;
    if (f.covariance[i]) p.covariance = *f.covariance[i];
    p.radial_bias = f.radial_bias[i];
    p.flag = f.flag[i];
    p.mount_looks_like_legs = f.mount_looks_like_legs[i];
    r.sensors.push_back(p);
  }
  if (f.track_residual_rms_m) r.track_residual_rms_m = *f.track_residual_rms_m;
  return r;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  PoseFile file;
  file.reference = "untouched";
  std::string error;
  if (!lrfnet::calib::ParsePoseYaml(text, &file, &error)) {
    Check(!error.empty() && error.find('\n') == std::string::npos);
    Check(file.sensors.empty() && file.reference == "untouched");
    return 0;
  }
  CheckFile(file);

  // Written again, it reads back the same.
  const std::string again = lrfnet::calib::CalibrationYaml(ResultOf(file), {"fuzz", {}});
  PoseFile back;
  std::string back_error;
  Check(lrfnet::calib::ParsePoseYaml(again, &back, &back_error));
  CheckFile(back);
  Check(back.sensors.size() == file.sensors.size());
  for (std::size_t i = 0; i < file.sensors.size(); ++i) {
    Check(back.sensors[i].first == file.sensors[i].first);
    Check(back.calibrated[i] == file.calibrated[i]);
    Check(back.mount_looks_like_legs[i] == file.mount_looks_like_legs[i]);
    Check(back.flag[i] == file.flag[i]);
    if (!file.calibrated[i]) continue;
    const auto& a = file.sensors[i].second;
    const auto& b = back.sensors[i].second;
    Check(std::abs(a.x_m - b.x_m) <= 1e-9 * (1.0 + std::abs(a.x_m)));
    Check(std::abs(a.y_m - b.y_m) <= 1e-9 * (1.0 + std::abs(a.y_m)));
    Check(std::abs(lrfnet::common::AngleDiff(a.yaw_rad, b.yaw_rad)) <= 1e-9);
  }
  return 0;
}
