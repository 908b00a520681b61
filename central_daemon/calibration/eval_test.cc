#include "central_daemon/calibration/eval.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <random>

namespace lrfnet::calib {
namespace {

PoseFile Poses(const std::vector<std::pair<std::string, Pose2>>& sensors,
               std::optional<std::string> reference = std::nullopt) {
  PoseFile f;
  f.sensors = sensors;
  f.calibrated.assign(sensors.size(), true);
  f.reference = std::move(reference);
  return f;
}

Pose2 P(double x, double y, double yaw_deg) {
  return {x, y, common::NormalizeAngle(common::DegToRad(yaw_deg))};
}

PoseFile Truth() {
  return Poses({{"s1", P(30, 0, 180)},
                {"s2", P(15, 25.9808, -120)},
                {"s3", P(-15, 25.9808, -60)},
                {"s4", P(-30, 0, 0)},
                {"s5", P(-15, -25.9808, 60)}});
}

TEST(Evaluate, RigidMotionOfTheWholeSetIsNoError) {
  const PoseFile truth = Truth();
  // The calibration's world is the reference sensor's frame: the truth seen from an arbitrary
  // other origin. Expressing both in the reference frame must remove it.
  const Pose2 gauge = P(-123.4, 56.7, 77.7);
  PoseFile calibration = truth;
  for (auto& [id, pose] : calibration.sensors) pose = gauge * pose;
  calibration.reference = "s3";
  // The raw poses differ a lot (so the test would catch a comparison without the gauge removal).
  EXPECT_GT(common::TranslationDistanceM(calibration.sensors[0].second, truth.sensors[0].second),
            50.0);

  const EvalResult r = Evaluate(calibration, truth, std::nullopt);
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_EQ(r.reference, "s3");
  ASSERT_EQ(r.sensors.size(), 4u);
  for (const SensorError& e : r.sensors) {
    EXPECT_NE(e.id, "s3");
    EXPECT_NEAR(e.d_r_deg, 0.0, 1e-9) << e.id;
    EXPECT_NEAR(e.d_t_m, 0.0, 1e-9) << e.id;
  }
  EXPECT_NEAR(r.mean_d_t_m, 0.0, 1e-9);
  EXPECT_TRUE(r.missing.empty());
}

TEST(Evaluate, ErrorsAreMeasuredInTheReferenceFrame) {
  const PoseFile truth = Truth();
  const Pose2 gauge = P(5, -7, 33);
  PoseFile calibration = truth;
  for (auto& [id, pose] : calibration.sensors) pose = gauge * pose;
  // s2 is off by 0.5 deg and by (0.03, 0.04) m in the reference (s1) frame.
  const Pose2 world_from_ref = calibration.sensors[0].second;
  Pose2 ref_from_s2 = world_from_ref.inverse() * calibration.sensors[1].second;
  ref_from_s2.x_m += 0.03;
  ref_from_s2.y_m += 0.04;
  ref_from_s2.yaw_rad += common::DegToRad(0.5);
  calibration.sensors[1].second = world_from_ref * ref_from_s2;

  const EvalResult r = Evaluate(calibration, truth, std::string("s1"));
  ASSERT_TRUE(r.ok) << r.error;
  ASSERT_EQ(r.sensors.size(), 4u);
  EXPECT_EQ(r.sensors[0].id, "s2");
  EXPECT_NEAR(r.sensors[0].d_r_deg, 0.5, 1e-9);
  EXPECT_NEAR(r.sensors[0].d_t_m, 0.05, 1e-9);
  for (std::size_t i = 1; i < r.sensors.size(); ++i) EXPECT_NEAR(r.sensors[i].d_t_m, 0.0, 1e-9);
  EXPECT_NEAR(r.mean_d_r_deg, 0.125, 1e-9);
  EXPECT_NEAR(r.median_d_r_deg, 0.0, 1e-9);  // even count: mean of the two middle (0, 0)
}

TEST(Evaluate, YawErrorWrapsAround180) {
  const PoseFile truth = Poses({{"a", P(0, 0, 0)}, {"b", P(1, 0, 179)}});
  const PoseFile calibration = Poses({{"a", P(0, 0, 0)}, {"b", P(1, 0, -179)}}, "a");
  const EvalResult r = Evaluate(calibration, truth, std::nullopt);
  ASSERT_TRUE(r.ok) << r.error;
  ASSERT_EQ(r.sensors.size(), 1u);
  EXPECT_NEAR(r.sensors[0].d_r_deg, 2.0, 1e-9);
}

TEST(Evaluate, MissingAndUnknownSensorsAreListed) {
  const PoseFile truth = Truth();
  PoseFile calibration = Poses(
      {{"s1", P(0, 0, 0)}, {"s2", P(1, 1, 1)}, {"s4", P(2, 2, 2)}, {"extra", P(3, 3, 3)}}, "s1");
  calibration.calibrated[2] = false;  // s4: not connected
  const EvalResult r = Evaluate(calibration, truth, std::nullopt);
  ASSERT_TRUE(r.ok) << r.error;
  ASSERT_EQ(r.sensors.size(), 1u);
  EXPECT_EQ(r.sensors[0].id, "s2");
  EXPECT_EQ(r.missing, (std::vector<std::string>{"s3", "s4", "s5"}));
  EXPECT_EQ(r.unknown, (std::vector<std::string>{"extra"}));
  const std::string table = EvalTable(r);
  EXPECT_NE(table.find("not calibrated: s3, s4, s5"), std::string::npos) << table;
  EXPECT_NE(table.find("not in the truth: extra"), std::string::npos) << table;
}

TEST(Evaluate, MeanAndMedianForOddAndEvenCounts) {
  // Position errors 1, 2, 10 (odd) and 1, 2, 3, 10 (even) along x, reference at the origin.
  PoseFile truth =
      Poses({{"r", P(0, 0, 0)}, {"a", P(0, 0, 0)}, {"b", P(0, 0, 0)}, {"c", P(0, 0, 0)}});
  PoseFile calibration =
      Poses({{"r", P(0, 0, 0)}, {"a", P(1, 0, 0)}, {"b", P(2, 0, 0)}, {"c", P(10, 0, 0)}}, "r");
  EvalResult r = Evaluate(calibration, truth, std::nullopt);
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_NEAR(r.mean_d_t_m, 13.0 / 3.0, 1e-12);
  EXPECT_NEAR(r.median_d_t_m, 2.0, 1e-12);

  truth.sensors.push_back({"d", P(0, 0, 0)});
  truth.calibrated.push_back(true);
  calibration.sensors.push_back({"d", P(0, 3, 0)});
  calibration.calibrated.push_back(true);
  r = Evaluate(calibration, truth, std::nullopt);
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_NEAR(r.mean_d_t_m, 4.0, 1e-12);
  EXPECT_NEAR(r.median_d_t_m, 2.5, 1e-12);
}

TEST(Evaluate, ReferenceProblemsAreClearErrors) {
  const PoseFile truth = Truth();
  PoseFile calibration = Poses({{"s1", P(0, 0, 0)}, {"s2", P(1, 1, 1)}}, "s1");

  EvalResult r = Evaluate(calibration, truth, std::string("s9"));
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.error, "reference sensor 's9' has no pose in the calibration");

  calibration.sensors.push_back({"x", P(0, 0, 0)});
  calibration.calibrated.push_back(true);
  r = Evaluate(calibration, truth, std::string("x"));
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.error, "reference sensor 'x' has no pose in the truth");

  const PoseFile lonely = Poses({{"s1", P(0, 0, 0)}, {"s2", P(0, 0, 0)}}, "s1");
  PoseFile only_ref = lonely;
  only_ref.calibrated[1] = false;
  r = Evaluate(only_ref, truth, std::nullopt);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.error.find("no sensor besides the reference 's1'"), std::string::npos) << r.error;

  const PoseFile disjoint = Poses({{"q1", P(0, 0, 0)}, {"q2", P(0, 0, 0)}});
  r = Evaluate(disjoint, truth, std::nullopt);
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.error, "the calibration and the truth have no calibrated sensor in common");
}

TEST(Evaluate, WithoutAReferenceTheFirstCommonSensorIsUsed) {
  const PoseFile truth = Truth();
  PoseFile calibration = Truth();
  calibration.sensors.insert(calibration.sensors.begin(), {"zz", P(0, 0, 0)});
  calibration.calibrated.insert(calibration.calibrated.begin(), true);
  const EvalResult r = Evaluate(calibration, truth, std::nullopt);
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_EQ(r.reference, "s1");
}

TEST(EvalOutput, TableAndJsonCarryTheNumbers) {
  PoseFile truth = Poses({{"r", P(0, 0, 0)}, {"a", P(0, 0, 0)}, {"b\xff\"", P(0, 0, 0)}});
  PoseFile calibration =
      Poses({{"r", P(0, 0, 0)}, {"a", P(0.1, 0, 1.5)}, {"b\xff\"", P(0, 0.3, 0)}}, "r");
  const EvalResult r = Evaluate(calibration, truth, std::nullopt);
  ASSERT_TRUE(r.ok) << r.error;

  const std::string table = EvalTable(r);
  EXPECT_NE(table.find("reference: r"), std::string::npos) << table;
  EXPECT_NE(table.find("d_R [deg]"), std::string::npos) << table;
  EXPECT_NE(table.find("1.5000"), std::string::npos) << table;
  EXPECT_NE(table.find("mean"), std::string::npos) << table;
  EXPECT_NE(table.find("median"), std::string::npos) << table;

  const std::string json = EvalJson(r);  // the invalid UTF-8 id must not throw
  EXPECT_EQ(json.find('\n'), std::string::npos);
  const auto j = nlohmann::json::parse(json);
  EXPECT_TRUE(j["ok"].get<bool>());
  EXPECT_EQ(j["reference"], "r");
  ASSERT_EQ(j["sensors"].size(), 2u);
  EXPECT_EQ(j["sensors"][0]["id"], "a");
  EXPECT_NEAR(j["sensors"][0]["d_r_deg"].get<double>(), 1.5, 1e-9);
  EXPECT_NEAR(j["sensors"][1]["d_t_m"].get<double>(), 0.3, 1e-9);
  EXPECT_NEAR(j["mean_d_t_m"].get<double>(), 0.2, 1e-9);
  EXPECT_NEAR(j["median_d_r_deg"].get<double>(), 0.75, 1e-9);

  EvalResult failed;
  failed.error = "reference sensor 'x' has no pose in the truth";
  const auto jf = nlohmann::json::parse(EvalJson(failed));
  EXPECT_FALSE(jf["ok"].get<bool>());
  EXPECT_EQ(jf["error"], failed.error);
}

}  // namespace
}  // namespace lrfnet::calib
