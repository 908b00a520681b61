#include "central_daemon/calibration/calibration_yaml.h"

#include <gtest/gtest.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>

#include "common/eigen_instances.h"

namespace lrfnet::calib {
namespace {

SensorPose MakePose(const std::string& id, double x, double y, double yaw_deg, bool calibrated,
                    double sigma_m = 0.01) {
  SensorPose p;
  p.id = id;
  p.calibrated = calibrated;
  p.world_from_sensor = {x, y, common::NormalizeAngle(common::DegToRad(yaw_deg))};
  p.covariance = Eigen::Vector3d(sigma_m * sigma_m, 4 * sigma_m * sigma_m, 1e-6).asDiagonal();
  return p;
}

CalibrationResult MakeResult() {
  CalibrationResult r;
  r.method = "quenzel";
  r.reference = "s1";
  r.sensors.push_back(MakePose("s1", 0, 0, 0, true, 0.0));
  // Values that need every digit: thirds, a yaw next to the +-180 wrap, tiny and large numbers.
  r.sensors.push_back(MakePose("s2", 1.0 / 3.0, -25.980762113533157, 179.99999999, true));
  r.sensors.push_back(MakePose("q\"uote: #x", 1e-12, 12345.678901234567, -179.99999999, true));
  r.sensors.push_back(MakePose("<s&1>\ttab\\", -7.25, 3.5e-7, 33.333333333333336, true));
  r.sensors.push_back(MakePose("s5", 0, 0, 0, false));
  EdgeReport used;
  used.r = "s1";
  used.s = "s2";
  used.used = true;
  used.status = "used";
  used.matches = 812;
  used.rms_m = 0.0213;
  used.rotation_residual_deg = 0.012;
  used.icp_applied = true;
  EdgeReport outlier = used;
  outlier.s = "q\"uote: #x";
  outlier.used = false;
  outlier.status = "rotation outlier (41.2 deg)";
  r.edges = {used, outlier};
  r.timings = {{"align", 0.0123}, {"pairwise", 0.41}};
  r.refined = true;
  r.refine_cost_before = 12.5;
  r.refine_cost_after = 9.75;
  r.refine_observations = 9000;
  r.track_residual_rms_m = 0.031;
  r.warnings = {"sensor s5: clock \"unsynchronized\""};
  return r;
}

// A live calibration says which data it was computed from; the file still reads back.
TEST(CalibrationYaml, TheInputWindowIsWrittenAndTheFileReadsBack) {
  YamlContext context;
  context.inputs = {"lrfnetd"};
  EXPECT_EQ(CalibrationYaml(MakeResult(), context).find("input_window:"), std::string::npos);
  context.received_until_ns = 1'700'000'012'345'678'901;
  context.scan_from_ns = 1'700'000'000'000'000'000;
  const std::string yaml = CalibrationYaml(MakeResult(), context);
  EXPECT_NE(yaml.find("\ninput_window: {received_until_utc_ns: 1700000012345678901, "
                      "scan_from_utc_ns: 1700000000000000000}\n"),
            std::string::npos)
      << yaml;
  PoseFile file;
  std::string error;
  ASSERT_TRUE(ParsePoseYaml(yaml, &file, &error)) << error << "\n" << yaml;
  EXPECT_EQ(file.sensors.size(), MakeResult().sensors.size());
}

TEST(CalibrationYaml, RoundTripGivesTheSamePoses) {
  const CalibrationResult result = MakeResult();
  const std::string yaml = CalibrationYaml(result, {"2024-05-01T12:00:00Z", {"a.rec", "b c.pcap"}});
  PoseFile file;
  std::string error;
  ASSERT_TRUE(ParsePoseYaml(yaml, &file, &error)) << error << "\n" << yaml;
  ASSERT_EQ(file.sensors.size(), result.sensors.size());
  ASSERT_TRUE(file.reference.has_value());
  EXPECT_EQ(*file.reference, "s1");
  for (std::size_t i = 0; i < result.sensors.size(); ++i) {
    const SensorPose& want = result.sensors[i];
    const auto& [id, pose] = file.sensors[i];
    EXPECT_EQ(id, want.id);
    EXPECT_EQ(file.calibrated[i], want.calibrated) << id;
    if (!want.calibrated) continue;
    EXPECT_NEAR(pose.x_m, want.world_from_sensor.x_m, 1e-9) << id;
    EXPECT_NEAR(pose.y_m, want.world_from_sensor.y_m, 1e-9) << id;
    EXPECT_NEAR(common::AngleDiff(pose.yaw_rad, want.world_from_sensor.yaw_rad), 0.0, 1e-9) << id;
  }
}

TEST(CalibrationYaml, RadialBiasRoundTripsAndFilesWithoutItStillRead) {
  CalibrationResult result = MakeResult();
  result.sensors[0].radial_bias = RadialBiasEstimate{-0.019873456789012345, 0.0041234567891, true};
  result.sensors[1].radial_bias = RadialBiasEstimate{0.0, 0.02, false};
  // Not written for a sensor without a pose, nor when not finite.
  result.sensors[3].radial_bias = RadialBiasEstimate{std::nan(""), 0.02, true};
  result.sensors[4].radial_bias = RadialBiasEstimate{0.01, 0.02, true};
  const std::string yaml = CalibrationYaml(result, {});
  PoseFile file;
  std::string error;
  ASSERT_TRUE(ParsePoseYaml(yaml, &file, &error)) << error << "\n" << yaml;
  ASSERT_EQ(file.radial_bias.size(), result.sensors.size());
  for (std::size_t i : {0u, 1u}) {
    const RadialBiasEstimate& want = *result.sensors[i].radial_bias;
    ASSERT_TRUE(file.radial_bias[i].has_value()) << i;
    EXPECT_EQ(file.radial_bias[i]->bias_m, want.bias_m) << i;  // every digit
    EXPECT_NEAR(file.radial_bias[i]->sigma_m, want.sigma_m, 1e-6 * want.sigma_m) << i;  // 6 digits
    EXPECT_EQ(file.radial_bias[i]->estimated, want.estimated) << i;
  }
  for (std::size_t i : {2u, 3u, 4u}) EXPECT_FALSE(file.radial_bias[i].has_value()) << i;
  const YAML::Node root = YAML::Load(yaml);
  EXPECT_TRUE(root["sensors"][0]["radial_bias_estimated"].as<bool>());
  EXPECT_FALSE(root["sensors"][1]["radial_bias_estimated"].as<bool>());
  EXPECT_FALSE(root["sensors"][4]["radial_bias_m"].IsDefined());
  // Documented in the file's header.
  EXPECT_NE(yaml.find("#   radial_bias_m"), std::string::npos);
  EXPECT_NE(yaml.find("sigma_radial_bias_m"), std::string::npos);
  // What the file reads back is what PoseFileOf gives.
  const PoseFile direct = PoseFileOf(result);
  ASSERT_EQ(direct.radial_bias.size(), file.radial_bias.size());
  for (std::size_t i = 0; i < direct.radial_bias.size(); ++i) {
    EXPECT_EQ(direct.radial_bias[i].has_value(), file.radial_bias[i].has_value()) << i;
  }

  // A file without the keys (written before, or a truth.yaml): no bias, the poses as before.
  const std::string old =
      "reference: a\nsensors:\n  - {id: a, x_m: 0, y_m: 0, yaw_deg: 0}\n"
      "  - {id: b, x_m: 1, y_m: 2, yaw_deg: 3, sigma_x_m: 0.01}\n";
  ASSERT_TRUE(ParsePoseYaml(old, &file, &error)) << error;
  ASSERT_EQ(file.radial_bias.size(), 2u);
  EXPECT_FALSE(file.radial_bias[0].has_value());
  EXPECT_FALSE(file.radial_bias[1].has_value());
  EXPECT_NEAR(file.sensors[1].second.y_m, 2.0, 1e-12);
}

TEST(CalibrationYaml, FlagsAndTheAmbiguityAreWrittenAndThePosesStillRead) {
  CalibrationResult result = MakeResult();
  result.sensors[1].flag = "placed by a weak pair only: \"few\" matches";
  result.sensors[4].flag = "ambiguous: two placements explain the data equally";
  result.ambiguity = "s5: two placements explain the data equally; walk where s1 and s5 see";
  const std::string yaml = CalibrationYaml(result, {});
  const YAML::Node root = YAML::Load(yaml);
  EXPECT_EQ(root["sensors"][1]["flag"].as<std::string>(), result.sensors[1].flag);
  EXPECT_FALSE(root["sensors"][1]["cov_xy_m2"].IsNull());
  EXPECT_FALSE(root["sensors"][0]["flag"].IsDefined());
  EXPECT_EQ(root["sensors"][4]["flag"].as<std::string>(), result.sensors[4].flag);
  EXPECT_FALSE(root["sensors"][4]["calibrated"].as<bool>());
  EXPECT_EQ(root["quality"]["ambiguity"].as<std::string>(), result.ambiguity);
  EXPECT_FALSE(root["quality"]["scale"].IsDefined());
  result.scale_note =
      "scale not observable: the people's size and the layout's scale explain the data alike";
  EXPECT_EQ(YAML::Load(CalibrationYaml(result, {}))["quality"]["scale"].as<std::string>(),
            result.scale_note);
  // Readers of poses are not disturbed.
  PoseFile file;
  std::string error;
  ASSERT_TRUE(ParsePoseYaml(yaml, &file, &error)) << error;
  EXPECT_TRUE(file.calibrated[1]);
  EXPECT_FALSE(file.calibrated[4]);
}

// A covariance with every cross term (x, y, yaw): what a joint refinement gives a sensor far from
// the reference (yaw and position correlated through the lever arm).
Eigen::Matrix3d CorrelatedCovariance(double sigma_m, double sigma_yaw_rad, double lever_m) {
  Eigen::Matrix3d j = Eigen::Matrix3d::Identity();
  j(0, 2) = -0.6 * lever_m;
  j(1, 2) = 0.8 * lever_m;
  const Eigen::Vector3d d(sigma_m * sigma_m, 0.5 * sigma_m * sigma_m,
                          sigma_yaw_rad * sigma_yaw_rad);
  return j * d.asDiagonal() * j.transpose();
}

TEST(CalibrationYaml, CovarianceFlagsAndMountRoundTrip) {
  CalibrationResult result = MakeResult();
  result.sensors[1].covariance = CorrelatedCovariance(0.004, common::DegToRad(0.05), 12.0);
  result.sensors[2].covariance = CorrelatedCovariance(0.0123456789, common::DegToRad(1.7), 30.0);
  // Yaw and position perfectly correlated: rounding to six digits must not make it indefinite.
  result.sensors[3].covariance = CorrelatedCovariance(0.0, common::DegToRad(0.3), 7.0);
  result.sensors[2].mount_looks_like_legs = true;
  result.sensors[2].flag = "q: tracks look like legs; set shape.mount: legs on its tracker";
  result.sensors[4].mount_looks_like_legs = true;
  result.sensors[4].flag = "s5: tracks look like legs";
  const std::string yaml = CalibrationYaml(result, {});
  PoseFile file;
  std::string error;
  ASSERT_TRUE(ParsePoseYaml(yaml, &file, &error)) << error << "\n" << yaml;
  ASSERT_EQ(file.covariance.size(), result.sensors.size());
  ASSERT_EQ(file.flag.size(), result.sensors.size());
  ASSERT_EQ(file.mount_looks_like_legs.size(), result.sensors.size());
  for (std::size_t i = 0; i < 4; ++i) {
    const Eigen::Matrix3d& want = result.sensors[i].covariance;
    ASSERT_TRUE(file.covariance[i].has_value()) << i;
    const Eigen::Matrix3d& got = *file.covariance[i];
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) {
        // Six digits of each sigma and cross term.
        const double scale = std::sqrt(want(r, r) * want(c, c));
        EXPECT_NEAR(got(r, c), want(r, c), 2e-5 * scale + 1e-300) << i << " " << r << c;
      }
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(got);
    EXPECT_GE(eig.eigenvalues().minCoeff(), -1e-15 * std::max(1e-300, got.maxCoeff())) << i << "\n"
                                                                                       << got;
    EXPECT_EQ(got, got.transpose()) << i;
  }
  EXPECT_FALSE(file.covariance[4].has_value());  // not calibrated: no pose, no sigmas
  EXPECT_EQ(file.mount_looks_like_legs, (std::vector<bool>{false, false, true, false, true}));
  for (std::size_t i = 0; i < result.sensors.size(); ++i)
    EXPECT_EQ(file.flag[i], result.sensors[i].flag) << i;
  EXPECT_NE(yaml.find("#   mount_looks_like_legs"), std::string::npos);
  ASSERT_TRUE(file.track_residual_rms_m.has_value());
  EXPECT_NEAR(*file.track_residual_rms_m, result.track_residual_rms_m, 1e-9);
  EXPECT_NE(yaml.find("cov_xyaw_m_deg"), std::string::npos);
  // PoseFileOf gives the same without the text.
  const PoseFile direct = PoseFileOf(result);
  EXPECT_EQ(direct.mount_looks_like_legs, file.mount_looks_like_legs);
  EXPECT_EQ(direct.flag, file.flag);
  ASSERT_EQ(direct.covariance.size(), file.covariance.size());
  for (std::size_t i = 0; i < direct.covariance.size(); ++i)
    EXPECT_EQ(direct.covariance[i].has_value(), file.covariance[i].has_value()) << i;

  // A covariance that is not finite is written as zeros and still reads.
  result.sensors[1].covariance(0, 1) = result.sensors[1].covariance(1, 0) = std::nan("");
  result.sensors[1].covariance(2, 2) = std::numeric_limits<double>::infinity();
  ASSERT_TRUE(ParsePoseYaml(CalibrationYaml(result, {}), &file, &error)) << error;
  EXPECT_EQ((*file.covariance[1])(0, 1), 0.0);
  EXPECT_EQ((*file.covariance[1])(2, 2), 0.0);
  // A file from before (sigmas and cov_xy_m2 only): that covariance, no flags.
  ASSERT_TRUE(
      ParsePoseYaml("sensors:\n  - {id: a, x_m: 1, y_m: 2, yaw_deg: 3, sigma_x_m: 0.02, "
                    "sigma_y_m: 0.01, sigma_yaw_deg: 0.5, cov_xy_m2: -0.0001}\n",
                    &file, &error))
      << error;
  ASSERT_TRUE(file.covariance[0].has_value());
  EXPECT_NEAR((*file.covariance[0])(0, 0), 4e-4, 1e-15);
  EXPECT_NEAR((*file.covariance[0])(0, 1), -1e-4, 1e-15);
  EXPECT_NEAR((*file.covariance[0])(2, 2), std::pow(common::DegToRad(0.5), 2), 1e-15);
  EXPECT_EQ((*file.covariance[0])(0, 2), 0.0);
  EXPECT_FALSE(file.mount_looks_like_legs[0]);
  EXPECT_EQ(file.flag[0], "");
  EXPECT_FALSE(file.track_residual_rms_m.has_value());
  // A residual that is not a number is not written (the file still reads).
  result.track_residual_rms_m = std::nan("");
  ASSERT_TRUE(ParsePoseYaml(CalibrationYaml(result, {}), &file, &error)) << error;
  EXPECT_FALSE(file.track_residual_rms_m.has_value());
}

TEST(CalibrationYaml, PoseFileOfMatchesWhatTheFileReadsBack) {
  const CalibrationResult result = MakeResult();
  PoseFile read;
  std::string error;
  ASSERT_TRUE(ParsePoseYaml(CalibrationYaml(result, {}), &read, &error)) << error;
  const PoseFile direct = PoseFileOf(result);
  EXPECT_EQ(direct.reference, read.reference);
  EXPECT_EQ(direct.calibrated, read.calibrated);
  ASSERT_EQ(direct.sensors.size(), read.sensors.size());
  for (std::size_t i = 0; i < read.sensors.size(); ++i) {
    EXPECT_EQ(direct.sensors[i].first, read.sensors[i].first);
    if (read.calibrated[i]) {
      EXPECT_NEAR(direct.sensors[i].second.x_m, read.sensors[i].second.x_m, 1e-9);
    }
  }
}

TEST(CalibrationYaml, IsDocumentedAndCarriesTheQualitySection) {
  const std::string yaml = CalibrationYaml(MakeResult(), {"2024-05-01T12:00:00Z", {"a.rec"}});
  // A person reading the file first sees what the fields mean.
  EXPECT_EQ(yaml.rfind("# ", 0), 0u);
  EXPECT_NE(yaml.find("# reference"), std::string::npos);
  EXPECT_NE(yaml.find("sigma_"), std::string::npos);

  const YAML::Node root = YAML::Load(yaml);
  EXPECT_EQ(root["method"].as<std::string>(), "quenzel");
  EXPECT_EQ(root["created_utc"].as<std::string>(), "2024-05-01T12:00:00Z");
  EXPECT_EQ(root["inputs"][0].as<std::string>(), "a.rec");
  const YAML::Node s2 = root["sensors"][1];
  EXPECT_NEAR(s2["sigma_x_m"].as<double>(), 0.01, 1e-9);
  EXPECT_NEAR(s2["sigma_y_m"].as<double>(), 0.02, 1e-9);
  EXPECT_NEAR(s2["sigma_yaw_deg"].as<double>(), 0.0572958, 1e-6);
  EXPECT_EQ(root["sensors"][4]["calibrated"].as<bool>(), false);
  EXPECT_FALSE(root["sensors"][4]["x_m"].IsDefined());

  const YAML::Node q = root["quality"];
  EXPECT_EQ(q["sensors_calibrated"].as<int>(), 4);
  EXPECT_EQ(q["edges_used"].as<int>(), 1);
  EXPECT_EQ(q["edges_not_used"].as<int>(), 1);
  ASSERT_EQ(q["edges"].size(), 2u);
  EXPECT_EQ(q["edges"][1]["s"].as<std::string>(), "q\"uote: #x");
  EXPECT_EQ(q["edges"][1]["status"].as<std::string>(), "rotation outlier (41.2 deg)");
  EXPECT_EQ(q["edges"][0]["matches"].as<int>(), 812);
  EXPECT_TRUE(q["edges"][0]["icp_applied"].as<bool>());
  EXPECT_TRUE(q["joint_refinement"]["applied"].as<bool>());
  EXPECT_DOUBLE_EQ(q["joint_refinement"]["cost_after"].as<double>(), 9.75);
  EXPECT_EQ(q["warnings"][0].as<std::string>(), "sensor s5: clock \"unsynchronized\"");
  EXPECT_EQ(q["timings_s"][1]["stage"].as<std::string>(), "pairwise");
}

TEST(CalibrationYaml, NonFinitePoseIsWrittenAsNotCalibratedAndStillReads) {
  CalibrationResult result = MakeResult();
  result.sensors[1].world_from_sensor.x_m = std::numeric_limits<double>::quiet_NaN();
  result.edges.clear();
  result.timings.clear();
  result.warnings.clear();
  const std::string yaml = CalibrationYaml(result, {});
  PoseFile file;
  std::string error;
  ASSERT_TRUE(ParsePoseYaml(yaml, &file, &error)) << error;
  EXPECT_FALSE(file.calibrated[1]);
  EXPECT_TRUE(file.calibrated[2]);
  EXPECT_EQ(YAML::Load(yaml)["quality"]["edges"].size(), 0u);

  // A failed calibration: nothing placed, not even the reference.
  for (SensorPose& s : result.sensors) s.calibrated = false;
  ASSERT_TRUE(ParsePoseYaml(CalibrationYaml(result, {}), &file, &error)) << error;
  EXPECT_FALSE(file.reference.has_value());
  result.reference.clear();
  EXPECT_TRUE(ParsePoseYaml(CalibrationYaml(result, {}), &file, &error)) << error;
}

TEST(PoseYaml, ReadsTheSimulatorTruthFormat) {
  // As tools/sim writes it: quoted ids, flow maps, more sections after `sensors`.
  const std::string truth = R"(# Ground truth written by lrfnet sim.
scenario: "quenzel_sim"
seed: 3
sensors:
  - {id: "s1", x_m: 30, y_m: 0, yaw_deg: 180}
  - {id: "s2", x_m: 15, y_m: 25.9808, yaw_deg: -120}
  - {id: s3, x_m: -15, y_m: 25.9808, yaw_deg: 300}
devices:
  - id: "s1"
    model: lms111
    clock: {offset_s: 2043.013409685009, drift_ppm: -0.17625138618372915}
targets:
  - {id: "cylinder", shape: cylinder, radius_m: 0.25, enter_s: 0, leave_s: 120}
)";
  PoseFile file;
  std::string error;
  ASSERT_TRUE(ParsePoseYaml(truth, &file, &error)) << error;
  EXPECT_FALSE(file.reference.has_value());
  ASSERT_EQ(file.sensors.size(), 3u);
  EXPECT_EQ(file.sensors[2].first, "s3");
  EXPECT_DOUBLE_EQ(file.sensors[1].second.y_m, 25.9808);
  EXPECT_NEAR(file.sensors[0].second.yaw_rad, common::kPi, 1e-12);
  EXPECT_NEAR(file.sensors[2].second.yaw_rad, common::DegToRad(-60), 1e-12);  // wrapped
  EXPECT_TRUE(file.calibrated[0] && file.calibrated[1] && file.calibrated[2]);
  ASSERT_TRUE(file.Find("s2").has_value());
  EXPECT_EQ(*file.Find("s2"), 1u);
  EXPECT_FALSE(file.Find("s9").has_value());
}

struct Hostile {
  const char* name;
  std::string text;
  std::string expected;  // substring of the error
};

TEST(PoseYaml, HostileInputGivesOneClearLine) {
  const std::string ok_entry = "{id: a, x_m: 1, y_m: 2, yaw_deg: 3}";
  const std::vector<Hostile> cases = {
      {"empty file", "", "empty; expected a map with a `sensors` list"},
      {"only comments", "# nothing\n", "empty; expected a map with a `sensors` list"},
      {"scalar", "hello", "expected a map with a `sensors` list"},
      {"no sensors", "reference: a\n", "sensors: missing key"},
      {"sensors not a list", "sensors: 3\n", "sensors: expected a list"},
      {"empty list", "sensors: []\n", "sensors: empty list"},
      {"entry not a map", "sensors: [3]\n", "sensors[0]: expected a map"},
      {"no id", "sensors: [{x_m: 1, y_m: 2, yaw_deg: 3}]\n", "sensors[0].id: missing key"},
      {"id is a list", "sensors: [{id: [1], x_m: 1, y_m: 2, yaw_deg: 3}]\n",
       "sensors[0].id: expected a non-empty string"},
      {"duplicate id", "sensors: [" + ok_entry + ", " + ok_entry + "]\n",
       "line 1: sensors[1].id: duplicate id (sensor 'a')"},
      {"missing yaw", "sensors:\n  - {id: a, x_m: 1, y_m: 2}\n",
       "line 2: sensors[0].yaw_deg: missing key (sensor 'a')"},
      {"non-numeric", "sensors:\n  - {id: a, x_m: abc, y_m: 2, yaw_deg: 3}\n",
       "line 2: sensors[0].x_m: expected a number, got 'abc' (sensor 'a')"},
      {"trailing junk", "sensors: [{id: a, x_m: 1m, y_m: 2, yaw_deg: 3}]\n",
       "sensors[0].x_m: expected a number, got '1m'"},
      {"yaml nan", "sensors: [{id: a, x_m: .nan, y_m: 2, yaw_deg: 3}]\n",
       "sensors[0].x_m: expected a number, got '.nan'"},
      {"nan", "sensors: [{id: a, x_m: 1, y_m: nan, yaw_deg: 3}]\n",
       "sensors[0].y_m: expected a finite number, got 'nan'"},
      {"inf", "sensors: [{id: a, x_m: 1, y_m: 2, yaw_deg: -inf}]\n",
       "sensors[0].yaw_deg: expected a finite number, got '-inf'"},
      {"overflow", "sensors: [{id: a, x_m: 1e400, y_m: 2, yaw_deg: 3}]\n",
       "sensors[0].x_m: expected a finite number, got '1e400'"},
      {"out of range", "sensors: [{id: a, x_m: 1e8, y_m: 2, yaw_deg: 3}]\n",
       "sensors[0].x_m: 1e8 is out of range"},
      {"number is a map", "sensors: [{id: a, x_m: {v: 1}, y_m: 2, yaw_deg: 3}]\n",
       "sensors[0].x_m: expected a number"},
      {"calibrated not a bool", "sensors: [{id: a, calibrated: maybe}]\n",
       "sensors[0].calibrated: expected true or false"},
      {"reference unknown", "reference: b\nsensors: [" + ok_entry + "]\n",
       "reference: 'b' is not in `sensors`"},
      {"reference uncalibrated",
       "reference: b\nsensors: [" + ok_entry + ", {id: b, calibrated: false}]\n",
       "reference: 'b' is not calibrated"},
      {"bias without its sigma",
       "sensors: [{id: a, x_m: 1, y_m: 2, yaw_deg: 3, radial_bias_m: 0.01, "
       "radial_bias_estimated: true}]\n",
       "sensors[0].sigma_radial_bias_m: missing key (sensor 'a')"},
      {"bias flag alone",
       "sensors: [{id: a, x_m: 1, y_m: 2, yaw_deg: 3, radial_bias_estimated: false}]\n",
       "sensors[0].radial_bias_m: missing key"},
      {"bias without its flag",
       "sensors: [{id: a, x_m: 1, y_m: 2, yaw_deg: 3, radial_bias_m: 0.01, "
       "sigma_radial_bias_m: 0.02}]\n",
       "sensors[0].radial_bias_estimated: missing key"},
      {"bias flag not a bool",
       "sensors: [{id: a, x_m: 1, y_m: 2, yaw_deg: 3, radial_bias_m: 0.01, "
       "sigma_radial_bias_m: 0.02, radial_bias_estimated: yes}]\n",
       "sensors[0].radial_bias_estimated: expected true or false"},
      {"bias not finite",
       "sensors: [{id: a, x_m: 1, y_m: 2, yaw_deg: 3, radial_bias_m: inf, "
       "sigma_radial_bias_m: 0.02, radial_bias_estimated: true}]\n",
       "sensors[0].radial_bias_m: expected a finite number"},
      {"bias out of range",
       "sensors: [{id: a, x_m: 1, y_m: 2, yaw_deg: 3, radial_bias_m: 1e3, "
       "sigma_radial_bias_m: 0.02, radial_bias_estimated: true}]\n",
       "sensors[0].radial_bias_m: 1e3 is out of range"},
      {"negative bias sigma",
       "sensors: [{id: a, x_m: 1, y_m: 2, yaw_deg: 3, radial_bias_m: 0.01, "
       "sigma_radial_bias_m: -0.02, radial_bias_estimated: true}]\n",
       "sensors[0].sigma_radial_bias_m: expected a number >= 0"},
      {"negative sigma", "sensors: [{id: a, x_m: 1, y_m: 2, yaw_deg: 3, sigma_y_m: -0.1}]\n",
       "sensors[0].sigma_y_m: expected a number >= 0 (sensor 'a')"},
      {"sigma not finite", "sensors: [{id: a, x_m: 1, y_m: 2, yaw_deg: 3, sigma_yaw_deg: inf}]\n",
       "sensors[0].sigma_yaw_deg: expected a finite number"},
      {"correlation above 1",
       "sensors: [{id: a, x_m: 1, y_m: 2, yaw_deg: 3, sigma_x_m: 0.1, sigma_y_m: 0.1, "
       "sigma_yaw_deg: 1, cov_xy_m2: 0.02}]\n",
       "sensors[0].cov_xy_m2: |0.02| is beyond sigma_x_m * sigma_y_m"},
      {"cross term without sigmas",
       "sensors: [{id: a, x_m: 1, y_m: 2, yaw_deg: 3, cov_yyaw_m_deg: 1}]\n",
       "sensors[0].cov_yyaw_m_deg: without sigma_x_m, sigma_y_m, sigma_yaw_deg"},
      {"cross term not a number",
       "sensors: [{id: a, x_m: 1, y_m: 2, yaw_deg: 3, sigma_x_m: 1, cov_xyaw_m_deg: [1]}]\n",
       "sensors[0].cov_xyaw_m_deg: expected a number"},
      {"mount flag not a bool",
       "sensors: [{id: a, x_m: 1, y_m: 2, yaw_deg: 3, mount_looks_like_legs: 1}]\n",
       "sensors[0].mount_looks_like_legs: expected true or false"},
      {"flag a list", "sensors: [{id: a, calibrated: false, flag: [x]}]\n",
       "sensors[0].flag: expected a string"},
      {"residual negative", "sensors: [" + ok_entry + "]\nquality: {track_residual_rms_m: -1}\n",
       "quality.track_residual_rms_m: expected a number >= 0"},
      {"residual not a number", "sensors: [" + ok_entry + "]\nquality: {track_residual_rms_m: x}\n",
       "quality.track_residual_rms_m: expected a number, got 'x'"},
      {"not yaml", "sensors: [{id: a, x_m: 1\n", "not valid YAML"},
      {"tab indentation", "sensors:\n\t- {id: a}\n", "not valid YAML"},
      {"bad escape", "sensors: [{id: \"a\\\x01\"}]\n",
       "not valid YAML: unknown escape character: ?"},
      {"binary", std::string("sensors:\0\x01\x02", 11), "binary data, not a YAML pose file"},
  };
  for (const Hostile& c : cases) {
    PoseFile file;
    file.reference = "untouched";
    std::string error;
    EXPECT_FALSE(ParsePoseYaml(c.text, &file, &error)) << c.name;
    EXPECT_NE(error.find(c.expected), std::string::npos)
        << c.name << ": got '" << error << "', expected '" << c.expected << "'";
    EXPECT_EQ(error.find('\n'), std::string::npos) << c.name << ": " << error;
    EXPECT_EQ(file.reference, "untouched") << c.name << ": output written on failure";
  }
}

TEST(PoseYaml, UncalibratedSensorNeedsNoPose) {
  PoseFile file;
  std::string error;
  ASSERT_TRUE(ParsePoseYaml(
      "sensors: [{id: a, x_m: 0, y_m: 0, yaw_deg: 0}, {id: b, calibrated: false}]", &file, &error))
      << error;
  EXPECT_FALSE(file.calibrated[1]);
}

TEST(PoseYaml, BinaryGarbageAndDeepNestingAreErrorsNotCrashes) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 200; ++trial) {
    std::string text(static_cast<std::size_t>(rng() % 300), '\0');
    for (char& c : text) c = static_cast<char>(rng() & 0xff);
    if (trial % 2 == 0) text = "sensors:\n  - {id: a, x_m: " + text;
    PoseFile file;
    std::string error;
    if (!ParsePoseYaml(text, &file, &error)) {
      EXPECT_FALSE(error.empty());
      EXPECT_EQ(error.find_first_of("\n\r"), std::string::npos) << error;
    }
  }
  PoseFile file;
  std::string error;
  EXPECT_FALSE(ParsePoseYaml(std::string(100000, '[') + std::string(100000, ']'), &file, &error));
  EXPECT_FALSE(error.empty());
  EXPECT_FALSE(ParsePoseYaml("sensors: " + std::string(100000, '{'), &file, &error));
  EXPECT_FALSE(error.empty());
}

class PoseFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("lrfnet_pose_file_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string Write(const std::string& name, const std::string& text) {
    const std::string path = (dir_ / name).string();
    std::ofstream(path, std::ios::binary) << text;
    return path;
  }
  std::filesystem::path dir_;
};

TEST_F(PoseFileTest, ErrorsNameTheFileAndLine) {
  const std::string path = Write("bad.yaml", "sensors:\n  - {id: a, x_m: 1, y_m: 2, yaw_deg: x}\n");
  PoseFile file;
  std::string error;
  EXPECT_FALSE(ReadPoseFile(path, &file, &error));
  EXPECT_EQ(error.rfind(path + ":2: sensors[0].yaw_deg", 0), 0u) << error;

  EXPECT_FALSE(ReadPoseFile((dir_ / "absent.yaml").string(), &file, &error));
  EXPECT_NE(error.find("absent.yaml: cannot open"), std::string::npos) << error;
  EXPECT_FALSE(ReadPoseFile(dir_.string(), &file, &error));
  EXPECT_EQ(error, dir_.string() + ": is a directory, not a pose file");
}

TEST_F(PoseFileTest, ReadsAWrittenCalibration) {
  const std::string path = Write("calibration.yaml", CalibrationYaml(MakeResult(), {}));
  PoseFile file;
  std::string error;
  ASSERT_TRUE(ReadPoseFile(path, &file, &error)) << error;
  EXPECT_EQ(file.sensors.size(), 5u);
}

TEST_F(PoseFileTest, OversizedFileIsRefused) {
  const std::string path = Write("huge.yaml", std::string(kMaxPoseFileBytes + 10, '#'));
  PoseFile file;
  std::string error;
  EXPECT_FALSE(ReadPoseFile(path, &file, &error));
  EXPECT_NE(error.find("larger than"), std::string::npos) << error;
}

}  // namespace
}  // namespace lrfnet::calib
