#include "central_daemon/app/calibration_service.h"

#include <gtest/gtest.h>

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
