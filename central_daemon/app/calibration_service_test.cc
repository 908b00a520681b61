#include "central_daemon/app/calibration_service.h"

#include <gtest/gtest.h>

#include <cmath>

namespace lrfnet::daemon {
namespace {

TEST(CalibrationSchedule, AttemptsUntilASuccessThenOnlyOnRequestOrRecalibration) {
  DaemonConfig config;
  config.calibration_attempt_interval_s = 10.0;
  CalibrationSchedule s;
  EXPECT_TRUE(AttemptDue(s, config, 100.0));  // nothing tried yet
  s.last_attempt_s = 100.0;
  EXPECT_FALSE(AttemptDue(s, config, 105.0));
  EXPECT_TRUE(AttemptDue(s, config, 110.0));
  s.last_success_s = 110.0;
  s.last_attempt_s = 110.0;
  EXPECT_FALSE(AttemptDue(s, config, 1e6));  // recalibrate_interval_s = 0: keep it
  s.requested = true;
  EXPECT_TRUE(AttemptDue(s, config, 111.0));  // SIGUSR1
  s.requested = false;
  config.calibration_recalibrate_interval_s = 600.0;
  EXPECT_FALSE(AttemptDue(s, config, 600.0));
  EXPECT_TRUE(AttemptDue(s, config, 710.0));
}

TEST(CalibrationSchedule, AutoOffOnlyOnRequest) {
  DaemonConfig config;
  config.calibration_auto = false;
  CalibrationSchedule s;
  EXPECT_FALSE(AttemptDue(s, config, 100.0));
  s.requested = true;
  EXPECT_TRUE(AttemptDue(s, config, 100.0));
}

TEST(CalibrationSchedule, BeforeTheFirstSuccessAttemptsWaitForSufficientData) {
  DaemonConfig config;
  CalibrationSchedule s;
  s.data_sufficient = false;
  EXPECT_FALSE(AttemptDue(s, config, 100.0));
  s.requested = true;  // SIGUSR1 tries anyway (and says what is missing)
  EXPECT_TRUE(AttemptDue(s, config, 100.0));
  s.requested = false;
  s.data_sufficient = true;
  EXPECT_TRUE(AttemptDue(s, config, 100.0));
}

calib::DataAssessment Assessment(std::size_t sensors,
                                 const std::vector<calib::PairData>& pairs) {
  calib::DataAssessment a;
  for (std::size_t i = 0; i < sensors; ++i) {
    calib::SensorData d;
    d.id = "s" + std::to_string(i + 1);
    d.tracks = 3;
    d.tracked_s = 30.0;
    a.sensors.push_back(d);
  }
  a.pairs = pairs;
  return a;
}

TEST(CalibrationProgress, TheWeakestLinkOfTheStrongestTreeBoundsTheProgress) {
  // s1-s2 20 s, s2-s3 5 s, s1-s3 2 s: the tree is s1-s2 (full) and s2-s3 (half of 10 s).
  const CalibrationProgress p =
      ProgressOf(Assessment(3, {{0, 1, 20.0}, {1, 2, 5.0}, {0, 2, 2.0}}), 10.0);
  EXPECT_NEAR(p.fraction, 0.75, 1e-12);
  EXPECT_FALSE(p.sufficient);
  EXPECT_NE(p.text.find("s2-s3 5.0 of 10 s"), std::string::npos) << p.text;

  const CalibrationProgress done =
      ProgressOf(Assessment(3, {{0, 1, 20.0}, {1, 2, 12.0}}), 10.0);
  EXPECT_DOUBLE_EQ(done.fraction, 1.0);
  EXPECT_TRUE(done.sufficient);
}

TEST(CalibrationProgress, AMissingLinkOrSensorWithoutTracksIsNamed) {
  CalibrationProgress p = ProgressOf(Assessment(4, {{0, 1, 10.0}, {2, 3, 10.0}}), 10.0);
  EXPECT_NEAR(p.fraction, 2.0 / 3.0, 1e-12);
  EXPECT_FALSE(p.sufficient);
  EXPECT_NE(p.text.find("1 link(s) missing"), std::string::npos) << p.text;

  calib::DataAssessment a = Assessment(3, {{0, 1, 10.0}});
  a.sensors[2].tracks = 0;
  p = ProgressOf(a, 10.0);
  EXPECT_NE(p.text.find("no tracks yet from s3"), std::string::npos) << p.text;
  EXPECT_EQ(ProgressOf(Assessment(1, {}), 10.0).text, "waiting for a second sensor");
}

TEST(CalibrationProgress, BarShowsTheFraction) {
  EXPECT_EQ(ProgressBar(0.5, 10), "[#####-----]  50%");
  EXPECT_EQ(ProgressBar(0.996, 10), "[#########-]  99%");  // 100 % only when complete
  EXPECT_EQ(ProgressBar(0.0, 4), "[----]   0%");
  EXPECT_EQ(ProgressBar(7.0, 4), "[####] 100%");
  EXPECT_EQ(ProgressBar(std::nan(""), 4), "[----]   0%");
}

TEST(CalibrationFiles, AnUnwritablePathIsAnErrorNamingIt) {
  calib::CalibrationOutcome outcome;
  outcome.ok = true;
  outcome.result.method = "quenzel";
  outcome.result.reference = "a";
  calib::SensorPose pose;
  pose.id = "a";
  pose.calibrated = true;
  outcome.result.sensors.push_back(pose);
  const std::string error =
      WriteCalibrationFiles(outcome, "/nonexistent-dir/calibration.yaml", "", {"x.rec"});
  EXPECT_NE(error.find("/nonexistent-dir/calibration.yaml"), std::string::npos) << error;
}

TEST(CalibrationConfig, OptionsAreValidatedWithTheirSection) {
  DaemonConfig config;
  EXPECT_EQ(LoadDaemonConfig("calibration:\n  method: spectral\n  weighted: true\n", config),
            std::nullopt);
  EXPECT_EQ(config.calibration.method, calib::Method::kSpectral);
  EXPECT_TRUE(config.calibration.weighted);
  DaemonConfig bad;
  const auto e = LoadDaemonConfig("calibration:\n  attempt_interval_s: 0\n", bad);
  ASSERT_TRUE(e.has_value());
  EXPECT_NE(e->find("calibration.attempt_interval_s"), std::string::npos) << *e;
  DaemonConfig bad2;
  const auto e2 = LoadDaemonConfig("calibration:\n  method: magic\n", bad2);
  ASSERT_TRUE(e2.has_value());
  EXPECT_NE(e2->find("method"), std::string::npos) << *e2;
}

}  // namespace
}  // namespace lrfnet::daemon
