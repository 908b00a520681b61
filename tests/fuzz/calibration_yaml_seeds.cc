// calibration_yaml_fuzz seeds: calibration.yaml files the writer made (poses with every digit, a
// yaw next to the wrap, correlated covariances, estimated and held radial biases, flags, a mount
// verdict, a sensor not placed), the simulator's truth format, a file from before the covariance and
// bias keys, and damaged copies (cut at several places, a key's value replaced by garbage).

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "central_daemon/calibration/calibration_yaml.h"
#include "tests/fuzz/daemon_seeds.h"

namespace lrfnet::fuzz {
namespace {

calib::SensorPose Pose(const std::string& id, double x, double y, double yaw_rad, bool calibrated) {
  calib::SensorPose p;
  p.id = id;
  p.calibrated = calibrated;
  p.world_from_sensor = {x, y, yaw_rad};
  return p;
}

calib::CalibrationResult Result() {
  calib::CalibrationResult r;
  r.method = "quenzel";
  r.reference = "s1";
  r.sensors.push_back(Pose("s1", 0, 0, 0, true));
  calib::SensorPose s2 = Pose("s2", 1.0 / 3.0, -25.980762113533157, 3.1415926, true);
  s2.covariance << 1e-4, 2e-5, 1e-6, 2e-5, 4e-4, -3e-6, 1e-6, -3e-6, 1e-5;
  s2.radial_bias = calib::RadialBiasEstimate{0.0123, 0.004, true};
  calib::SensorPose s3 = Pose("q\"uote: #x", 1e-12, 12345.678901234567, -3.1415926, true);
  s3.covariance = Eigen::Vector3d(1e-3, 1e-3, 1e-4).asDiagonal();
  s3.radial_bias = calib::RadialBiasEstimate{0.0, 0.02, false};
  s3.flag = "hangs on weak pairs only";
  s3.mount_looks_like_legs = true;
  calib::SensorPose s4 = Pose("s4", 0, 0, 0, false);
  s4.flag = "refused: two placements explain the data equally well";
  r.sensors = {r.sensors[0], s2, s3, s4};
  r.refined = true;
  r.track_residual_rms_m = 0.031;
  r.warnings = {"sensor s4: not connected"};
  return r;
}

void Write(const std::filesystem::path& path, const std::string& text) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << text;
}

}  // namespace

void WriteCalibrationYamlSeeds(const std::string& dir) {
  const std::filesystem::path out = dir;
  std::vector<std::string> seeds;
  const std::string written = calib::CalibrationYaml(Result(), {"2026-01-01T00:00:00Z", {"a.rec"}});
  seeds.push_back(written);
  seeds.push_back(R"(scenario: "quenzel_sim"
sensors:
  - {id: "s1", x_m: 30, y_m: 0, yaw_deg: 180}
  - {id: s3, x_m: -15, y_m: 25.9808, yaw_deg: 300}
targets:
  - {id: "cylinder", shape: cylinder, radius_m: 0.25}
)");
  seeds.push_back(R"(reference: a
sensors:
  - id: a
    x_m: 0
    y_m: 0
    yaw_deg: 0
    sigma_x_m: 0
    sigma_y_m: 0
    sigma_yaw_deg: 0
  - id: b
    x_m: 4.5
    y_m: -1.25
    yaw_deg: 91.5
    sigma_x_m: 0.01
    sigma_y_m: 0.02
    sigma_yaw_deg: 0.1
    cov_xy_m2: 0.0001
  - {id: c, calibrated: false}
quality: {track_residual_rms_m: 0.04}
)");
  // Damaged copies of the writer's file: cut at several places, a value replaced by garbage.
  for (const double share : {0.1, 0.33, 0.5, 0.77, 0.95}) {
    seeds.push_back(written.substr(0, static_cast<std::size_t>(share * static_cast<double>(written.size()))));
  }
  for (const char* key : {"x_m:", "sigma_x_m:", "cov_xyaw_m_deg:", "radial_bias_m:",
                          "mount_looks_like_legs:", "reference:"}) {
    const std::size_t at = written.find(key);
    if (at == std::string::npos) continue;
    const std::size_t end = written.find('\n', at);
    std::string bad = written;
    bad.replace(at, end - at, std::string(key) + " [nan, {x: .inf}]");
    seeds.push_back(bad);
  }
  for (std::size_t i = 0; i < seeds.size(); ++i) {
    Write(out / ("seed_" + std::to_string(i) + ".yaml"), seeds[i]);
  }
}

}  // namespace lrfnet::fuzz
