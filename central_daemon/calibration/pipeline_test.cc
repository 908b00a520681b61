#include "central_daemon/calibration/pipeline.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace lrfnet::calib {
namespace {

using common::DegToRad;
using common::RadToDeg;

struct SimSensor {
  std::string id;
  Pose2 world_from_sensor;
  double range_m = 10.0;
  double half_fov_rad = DegToRad(135.0);
  double period_s = 0.04;
  double phase_s = 0.0;
};

// A person walking between random waypoints inside [x0, x1] x [y0, y1].
struct Walker {
  std::vector<Eigen::Vector2d> waypoints;
  double speed_mps = 1.2;
  double enter_s = 0.0;
  double leave_s = 1e9;

  std::optional<Eigen::Vector2d> At(double t, Eigen::Vector2d* velocity) const {
    if (t < enter_s || t > leave_s) return std::nullopt;
    double d = (t - enter_s) * speed_mps;
    for (std::size_t k = 0; k + 1 < waypoints.size(); ++k) {
      const Eigen::Vector2d seg = waypoints[k + 1] - waypoints[k];
      const double len = seg.norm();
      if (d <= len) {
        *velocity = seg / len * speed_mps;
        return waypoints[k] + seg * (d / len);
      }
      d -= len;
    }
    return std::nullopt;
  }
};

Walker RandomWalker(std::mt19937& rng, double x0, double x1, double y0, double y1, double enter_s) {
  std::uniform_real_distribution<double> ux(x0, x1), uy(y0, y1);
  Walker w;
  w.enter_s = enter_s;
  for (int k = 0; k < 40; ++k) w.waypoints.emplace_back(ux(rng), uy(rng));
  return w;
}

// Frames as a tracker would send them: every walker inside a sensor's field of view and range, in
// the sensor frame, with noise and a plausible filtered covariance.
CalibrationInput Simulate(const std::vector<SimSensor>& sensors, const std::vector<Walker>& walkers,
                          double duration_s, unsigned seed, double noise_m = 0.01) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, noise_m);
  CalibrationInput input;
  const common::UtcNs t0_ns = 1'700'000'000'000'000'000;
  for (std::size_t i = 0; i < sensors.size(); ++i) {
    const SimSensor& s = sensors[i];
    SensorRecording rec;
    rec.id = s.id;
    rec.clock_sync = ClockSync::kSynchronized;
    const Pose2 sensor_from_world = s.world_from_sensor.inverse();
    std::uint32_t counter = 0;
    for (double t = s.phase_s; t < duration_s; t += s.period_s) {
      TrackFrameData frame;
      frame.session_id = 1;
      frame.scan_start_ns = t0_ns + static_cast<common::UtcNs>(t * 1e9);
      frame.scan_period_s = s.period_s;
      frame.scan_counter = counter++;
      frame.sent_ns = frame.scan_start_ns;
      frame.receive_ns = frame.scan_start_ns;
      for (std::size_t w = 0; w < walkers.size(); ++w) {
        Eigen::Vector2d v_world;
        const auto p_world = walkers[w].At(t, &v_world);
        if (!p_world) continue;
        const Eigen::Vector2d p = sensor_from_world * *p_world;
        if (p.norm() > s.range_m || std::abs(std::atan2(p.y(), p.x())) > s.half_fov_rad) continue;
        const Eigen::Vector2d v = sensor_from_world.rotation() * v_world;
        TrackObservation o;
        o.track_id = static_cast<std::uint32_t>(w + 1);
        o.state = daemon::TrackState::kConfirmed;
        o.kind = MeasurementKind::kEllipse;
        o.x_m = static_cast<float>(p.x() + noise(rng));
        o.y_m = static_cast<float>(p.y() + noise(rng));
        o.vx_mps = static_cast<float>(v.x());
        o.vy_mps = static_cast<float>(v.y());
        o.covariance = {4e-4f, 0, 0, 0, 4e-4f, 0, 0, 0.04f, 0, 0.04f};
        o.age_scans = 10;
        frame.tracks.push_back(o);
      }
      rec.frames.push_back(std::move(frame));
    }
    input.sensors.push_back(std::move(rec));
  }
  return input;
}

// Errors of every sensor after expressing both pose sets in the reference's frame.
void ExpectClose(const CalibrationOutcome& outcome, const std::vector<SimSensor>& truth,
                 double max_t_m, double max_r_deg) {
  ASSERT_TRUE(outcome.ok) << outcome.error;
  std::size_t ref = 0;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    if (truth[i].id == outcome.result.reference) ref = i;
  }
  const Pose2 ref_from_world = truth[ref].world_from_sensor.inverse();
  for (std::size_t i = 0; i < truth.size(); ++i) {
    const SensorPose& got = outcome.result.sensors[i];
    ASSERT_TRUE(got.calibrated) << got.id;
    const Pose2 want = ref_from_world * truth[i].world_from_sensor;
    EXPECT_LT(common::TranslationDistanceM(got.world_from_sensor, want), max_t_m) << got.id;
    EXPECT_LT(RadToDeg(common::RotationDistanceRad(got.world_from_sensor, want)), max_r_deg)
        << got.id;
  }
}

// Four sensors in the corners of a 12 x 8 m hall, each facing the centre.
std::vector<SimSensor> Hall() {
  return {{"a", {0.0, 0.0, DegToRad(33.0)}},
          {"b", {12.0, 0.0, DegToRad(147.0)}},
          {"c", {12.0, 8.0, DegToRad(-147.0)}},
          {"d", {0.0, 8.0, DegToRad(-33.0)}, 10.0, DegToRad(135.0), 0.0667, 0.013}};
}

TEST(CalibratePipeline, FourSensorsTwoPeopleRecoversThePoses) {
  std::mt19937 rng(5);
  const std::vector<SimSensor> sensors = Hall();
  const std::vector<Walker> walkers = {RandomWalker(rng, 1, 11, 1, 7, 0.0),
                                       RandomWalker(rng, 1, 11, 1, 7, 5.0)};
  const CalibrationInput input = Simulate(sensors, walkers, 60.0, 1);
  CalibrationOptions options;
  const CalibrationOutcome outcome = Calibrate(input, options);
  ExpectClose(outcome, sensors, 0.05, 0.5);
  EXPECT_EQ(outcome.result.method, "quenzel");
  EXPECT_GT(outcome.result.edges.size(), 0u);
  for (const EdgeReport& e : outcome.result.edges) {
    if (e.used) {
      EXPECT_LT(e.track_residual_rms_m, 0.1) << e.r << "-" << e.s;
    }
  }
}

TEST(CalibratePipeline, HonoursTheReferenceAndNamesAnUnknownOne) {
  std::mt19937 rng(6);
  const std::vector<SimSensor> sensors = Hall();
  const CalibrationInput input =
      Simulate(sensors, {RandomWalker(rng, 1, 11, 1, 7, 0.0)}, 40.0, 2);
  CalibrationOptions options;
  options.reference = "c";
  const CalibrationOutcome outcome = Calibrate(input, options);
  ASSERT_TRUE(outcome.ok) << outcome.error;
  EXPECT_EQ(outcome.result.reference, "c");
  EXPECT_NEAR(outcome.result.sensors[2].world_from_sensor.x_m, 0.0, 1e-12);
  EXPECT_NEAR(outcome.result.sensors[2].world_from_sensor.yaw_rad, 0.0, 1e-12);
  ExpectClose(outcome, sensors, 0.05, 0.5);

  options.reference = "nope";
  const CalibrationOutcome bad = Calibrate(input, options);
  EXPECT_FALSE(bad.ok);
  EXPECT_NE(bad.error.find("'nope'"), std::string::npos) << bad.error;
}

TEST(CalibratePipeline, BaselinesRunOnTheSameData) {
  std::mt19937 rng(7);
  const std::vector<SimSensor> sensors = Hall();
  const CalibrationInput input =
      Simulate(sensors, {RandomWalker(rng, 1, 11, 1, 7, 0.0)}, 40.0, 3);
  for (Method method : {Method::kSpectral, Method::kSchenk}) {
    CalibrationOptions options;
    options.method = method;
    const CalibrationOutcome outcome = Calibrate(input, options);
    SCOPED_TRACE(ToString(method));
    EXPECT_EQ(outcome.result.method, ToString(method));
    ExpectClose(outcome, sensors, 0.15, 1.5);
  }
}

TEST(CalibratePipeline, TooLittleDataSaysWhatIsMissing) {
  std::mt19937 rng(8);
  std::vector<SimSensor> sensors = Hall();
  // Sensor "e" far away: it never sees anybody.
  sensors.push_back({"e", {100.0, 100.0, 0.0}});
  const CalibrationInput input =
      Simulate(sensors, {RandomWalker(rng, 1, 11, 1, 7, 0.0)}, 30.0, 4);
  const CalibrationOutcome outcome = Calibrate(input, CalibrationOptions{});
  EXPECT_FALSE(outcome.ok);
  EXPECT_NE(outcome.error.find("too little data"), std::string::npos) << outcome.error;
  EXPECT_NE(outcome.error.find("no tracks from e"), std::string::npos) << outcome.error;
  EXPECT_FALSE(outcome.assessment.sufficient);
  ASSERT_EQ(outcome.assessment.unlinked.size(), 1u);
  EXPECT_EQ(outcome.assessment.unlinked[0], "e");

  const CalibrationOutcome empty = Calibrate(CalibrationInput{}, CalibrationOptions{});
  EXPECT_FALSE(empty.ok);
  EXPECT_NE(empty.error.find("no sensors"), std::string::npos) << empty.error;

  CalibrationInput one = Simulate({sensors[0]}, {RandomWalker(rng, 1, 11, 1, 7, 0.0)}, 10.0, 5);
  const CalibrationOutcome single = Calibrate(one, CalibrationOptions{});
  EXPECT_FALSE(single.ok);
  EXPECT_NE(single.error.find("at least two"), std::string::npos) << single.error;
}

TEST(CalibratePipeline, DisconnectedGraphNamesTheUnconnectedSensors) {
  // Two rooms 50 m apart, each with two sensors and one person walking at the same time: the
  // sensors of one room share simultaneous tracks with the other's (so the data check passes),
  // but no pairwise estimate can link the rooms.
  std::mt19937 rng(9);
  const std::vector<SimSensor> sensors = {{"a", {0.0, 0.0, DegToRad(45.0)}},
                                          {"b", {8.0, 8.0, DegToRad(-135.0)}},
                                          {"x", {50.0, 0.0, DegToRad(45.0)}},
                                          {"y", {58.0, 8.0, DegToRad(-135.0)}}};
  const std::vector<Walker> walkers = {RandomWalker(rng, 1, 7, 1, 7, 0.0),
                                       RandomWalker(rng, 51, 57, 1, 7, 0.0)};
  const CalibrationInput input = Simulate(sensors, walkers, 40.0, 6);
  CalibrationOptions options;
  options.reference = "a";
  const CalibrationOutcome outcome = Calibrate(input, options);
  EXPECT_FALSE(outcome.ok);
  EXPECT_NE(outcome.error.find("not connected to the reference a: x, y"), std::string::npos)
      << outcome.error;
  // The connected part is still calibrated.
  EXPECT_TRUE(outcome.result.sensors[0].calibrated);
  EXPECT_TRUE(outcome.result.sensors[1].calibrated);
  EXPECT_FALSE(outcome.result.sensors[2].calibrated);
}

TEST(CalibratePipeline, InvalidOptionsAreAnError) {
  CalibrationOptions options;
  options.max_translation_residual_m = -1.0;
  const CalibrationOutcome outcome = Calibrate(CalibrationInput{}, options);
  EXPECT_FALSE(outcome.ok);
  EXPECT_NE(outcome.error.find("max_translation_residual_m"), std::string::npos);
}

TEST(CalibratePipeline, StageTimesUseTheGivenClock) {
  std::mt19937 rng(10);
  const CalibrationInput input = Simulate(Hall(), {RandomWalker(rng, 1, 11, 1, 7, 0.0)}, 20.0, 7);
  double fake_s = 0.0;
  const CalibrationOutcome outcome =
      Calibrate(input, CalibrationOptions{}, [&fake_s] { return fake_s += 1.0; });
  ASSERT_FALSE(outcome.result.timings.empty());
  EXPECT_EQ(outcome.result.timings.front().stage, "align + smoothing");
  EXPECT_EQ(outcome.result.timings.back().stage, "total");
  for (const StageTime& t : outcome.result.timings) EXPECT_GT(t.seconds, 0.0) << t.stage;
}

}  // namespace
}  // namespace lrfnet::calib
