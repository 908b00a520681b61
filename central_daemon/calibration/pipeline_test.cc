#include "central_daemon/calibration/pipeline.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <tuple>
#include <utility>

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
  // A bias the measurement model does not know: every reported position this much farther from
  // the sensor along its line of sight than the body centre (a torso fit to a pair of legs at knee
  // height puts the centre behind them).
  double unknown_bias_m = 0.0;
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
        Eigen::Vector2d p = sensor_from_world * *p_world;
        if (p.norm() > s.range_m || std::abs(std::atan2(p.y(), p.x())) > s.half_fov_rad) continue;
        p += s.unknown_bias_m * p.normalized();
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

// A background as a scanner at `world_from_sensor` sees the closed polygon `room` (270 deg,
// 0.5 deg beams, 20 m range; no noise).
BackgroundScan CastBackground(const std::vector<Eigen::Vector2d>& room,
                              const Pose2& world_from_sensor) {
  const auto cross = [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return a.x() * b.y() - a.y() * b.x();
  };
  BackgroundScan scan;
  scan.first_angle_rad = DegToRad(-135.0);
  scan.angle_step_rad = DegToRad(0.5);
  const Eigen::Vector2d origin = world_from_sensor.translation();
  for (int i = 0; i < 541; ++i) {
    const double angle = world_from_sensor.yaw_rad + scan.first_angle_rad + i * scan.angle_step_rad;
    const Eigen::Vector2d dir(std::cos(angle), std::sin(angle));
    double best = HUGE_VAL;
    for (std::size_t k = 0; k < room.size(); ++k) {
      const Eigen::Vector2d a = room[k], e = room[(k + 1) % room.size()] - a;
      const double denom = cross(dir, e);
      if (std::abs(denom) < 1e-12) continue;
      const double t = cross(a - origin, e) / denom;
      const double u = cross(a - origin, dir) / denom;
      if (t > 1e-6 && u >= 0.0 && u <= 1.0) best = std::min(best, t);
    }
    scan.ranges_mm.push_back(best <= 20.0 ? static_cast<std::uint32_t>(std::lround(best * 1000.0))
                                          : 0u);
  }
  return scan;
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

// ---------------------------------------------------------------------------------------------
// Weak pairs, weakly cycled graphs and their hypotheses (known answers).

// A walker going round a small quadrilateral (about 2 m across, times `scale`) centred at
// (cx, cy), many times.
Walker Loop(double cx, double cy, double enter_s = 0.0, double leave_s = 1e9,
            double speed_mps = 1.1, double scale = 1.0) {
  Walker w;
  w.enter_s = enter_s;
  w.leave_s = leave_s;
  w.speed_mps = speed_mps;
  for (int lap = 0; lap < 40; ++lap) {
    w.waypoints.emplace_back(cx - 1.0 * scale, cy - 1.0 * scale);
    w.waypoints.emplace_back(cx + 1.2 * scale, cy - 0.8 * scale);
    w.waypoints.emplace_back(cx + 0.9 * scale, cy + 1.1 * scale);
    w.waypoints.emplace_back(cx - 1.1 * scale, cy + 0.7 * scale);
  }
  return w;
}

std::size_t Accepted(const std::vector<PairEstimate>& pairs) {
  return static_cast<std::size_t>(std::count_if(pairs.begin(), pairs.end(),
                                                [](const PairEstimate& p) { return p.accepted; }));
}

// Four sensors on a diamond, each facing the centre, 7.5 m range: each sees its two neighbours'
// shared corner, never the opposite sensor's. The graph is one 4-cycle a-b-c-d-a.
std::vector<SimSensor> Ring() {
  std::vector<SimSensor> out = {{"a", {-8.0, 0.0, 0.0}},
                                {"b", {0.0, 8.0, DegToRad(-90.0)}},
                                {"c", {8.0, 0.0, DegToRad(180.0)}},
                                {"d", {0.0, -8.0, DegToRad(90.0)}}};
  for (SimSensor& s : out) s.range_m = 7.5;
  return out;
}

// People in every corner, each walking a loop of their own size and speed for 12 s, five after
// one another (so every pair has several tracks, each with its own systematic offset).
std::vector<Walker> RingWalkers() {
  std::vector<Walker> out;
  const double cx[4] = {-4.0, 4.0, 4.0, -4.0}, cy[4] = {4.0, 4.0, -4.0, -4.0};
  for (int corner = 0; corner < 4; ++corner) {
    for (int visit = 0; visit < 5; ++visit) {
      const double enter = 12.0 * visit + 0.7 * corner;
      out.push_back(Loop(cx[corner], cy[corner], enter, enter + 11.0, 0.9 + 0.1 * (visit + corner),
                         0.8 + 0.1 * ((visit + 2 * corner) % 5)));
    }
  }
  return out;
}

// The pairs of aligned input, with the one of ids (r, s) replaced by `edit` of it.
template <typename Edit>
std::vector<PairEstimate> PairsWith(const AlignedTracks& tracks, const std::string& r,
                                    const std::string& s, Edit edit) {
  std::vector<PairEstimate> pairs = EstimateAllPairs(tracks, {});
  for (PairEstimate& p : pairs) {
    if (tracks.sensors[p.r].id == r && tracks.sensors[p.s].id == s) edit(p);
  }
  return pairs;
}

TEST(CalibrateHypotheses, ACorruptedPairOfASingleCycleIsFoundByTheRawObservations) {
  // One pair 6 degrees and 0.8 m off, far beyond its covariance, in the graph's only cycle: no
  // robust average can tell which pair of the cycle is wrong (each lies in one cycle). The
  // placements without each pair in turn are judged on all raw observations.
  const std::vector<SimSensor> sensors = Ring();
  const CalibrationInput input = Simulate(sensors, RingWalkers(), 60.0, 11);
  const AlignedTracks tracks = Align(input, {});
  const auto pairs = PairsWith(tracks, "a", "b", [](PairEstimate& p) {
    ASSERT_TRUE(p.accepted) << p.reason;
    p.s_from_r.yaw_rad += DegToRad(6.0);
    p.s_from_r.x_m += 0.8;
  });
  ASSERT_EQ(Accepted(pairs), 4u);
  CalibrationOptions options;
  options.refine = false;  // the placements themselves, not what the refinement makes of them
  options.reference = "c";
  const CalibrationOutcome outcome = CalibrateFromPairs(tracks, pairs, options);
  ExpectClose(outcome, sensors, 0.05, 0.2);
  ASSERT_GE(outcome.result.hypotheses.size(), 4u);
  for (const HypothesisReport& h : outcome.result.hypotheses) {
    EXPECT_EQ(h.chosen, h.description == "without a-b") << h.description << " " << h.cost;
  }
  EXPECT_TRUE(outcome.result.ambiguity.empty()) << outcome.result.ambiguity;
  for (const EdgeReport& e : outcome.result.edges) {
    if (e.status.rfind("rejected", 0) == 0) continue;  // the diagonals: no common view
    EXPECT_EQ(e.used, !(e.r == "a" && e.s == "b")) << e.r << "-" << e.s << ": " << e.status;
  }
  // With the refinement too.
  options.refine = true;
  ExpectClose(CalibrateFromPairs(tracks, pairs, options), sensors, 0.05, 0.2);
}

TEST(CalibrateHypotheses, AMisclosureTheDataCannotPlaceIsReportedNotPicked) {
  // b's pairs were measured when nobody walked where b sees (no track of b remains in the data),
  // and they disagree: a-b says one thing, b-c 6 degrees another. Either placement of b explains
  // every remaining observation equally: b is refused, named, with the walks that would decide.
  std::vector<Walker> walkers;  // c-d and d-a only
  for (const Walker& w : RingWalkers()) {
    if (w.waypoints[0].y() < 0.0) walkers.push_back(w);
  }
  const std::vector<SimSensor> sensors = Ring();
  const CalibrationInput input = Simulate(sensors, walkers, 60.0, 12);
  const AlignedTracks tracks = Align(input, {});
  std::vector<PairEstimate> pairs = EstimateAllPairs(tracks, {});
  ASSERT_EQ(Accepted(pairs), 2u);
  const auto truth_of = [&](std::size_t r, std::size_t s) {
    return sensors[s].world_from_sensor.inverse() * sensors[r].world_from_sensor;
  };
  for (const auto& [r, s, dyaw] : {std::tuple<std::size_t, std::size_t, double>{0, 1, 3.0},
                                   std::tuple<std::size_t, std::size_t, double>{1, 2, 3.0}}) {
    PairEstimate p;
    p.r = r;
    p.s = s;
    p.accepted = true;
    p.s_from_r = truth_of(r, s);
    p.s_from_r.yaw_rad += DegToRad(dyaw);
    p.covariance = Eigen::Vector3d(1e-4, 1e-4, std::pow(DegToRad(0.1), 2)).asDiagonal();
    p.matches = 500;
    pairs.push_back(p);
  }
  CalibrationOptions options;
  options.reference = "d";
  const CalibrationOutcome outcome = CalibrateFromPairs(tracks, pairs, options);
  EXPECT_FALSE(outcome.ok);
  EXPECT_NE(outcome.error.find("cannot place b"), std::string::npos) << outcome.error;
  EXPECT_NE(outcome.error.find("explain the data equally"), std::string::npos) << outcome.error;
  EXPECT_NE(outcome.error.find("walk where"), std::string::npos) << outcome.error;
  EXPECT_FALSE(outcome.result.sensors[1].calibrated);
  EXPECT_EQ(outcome.result.sensors[1].flag.rfind("ambiguous", 0), 0u);
  // The others are placed (d at the origin, a and c by their data).
  for (std::size_t i : {0, 2, 3}) EXPECT_TRUE(outcome.result.sensors[i].calibrated) << i;
}

TEST(CalibratePipeline, AChainOfBridgesWithShortOverlapsIsPlacedWithCovariancesThatSaySo) {
  // Five sensors along a corridor, 10 m apart, 7 m range: neighbours share a few metres of it,
  // walked a few times: every pair is a bridge (no cycle), most weak. Every sensor is placed,
  // those hanging on weak pairs flagged, and the errors, which grow along the chain, stay within
  // the reported uncertainty.
  std::vector<SimSensor> sensors;
  for (int i = 0; i < 5; ++i) {
    sensors.push_back({std::string(1, static_cast<char>('a' + i)),
                       {10.0 * i, 0.0, DegToRad(i % 2 == 0 ? 90.0 : -90.0)}});
    sensors.back().range_m = 7.0;
    sensors.back().half_fov_rad = DegToRad(90.0);
  }
  for (SimSensor& s : sensors) s.world_from_sensor.y_m = s.world_from_sensor.yaw_rad > 0 ? -2.0 : 2.0;
  // One person at a time, zig-zagging along the corridor and back, each with a gait of their own.
  const auto zigzag = [](double amplitude, double wavelength, double speed, double enter,
                         double leave) {
    Walker w;
    w.speed_mps = speed;
    w.enter_s = enter;
    w.leave_s = leave;
    for (int pass = 0; pass < 2; ++pass) {
      for (double x = -3.0; x <= 43.0; x += wavelength / 2.0) {
        const double at = pass == 0 ? x : 40.0 - x;
        const int k = static_cast<int>(std::lround((at + 3.0) / (wavelength / 2.0)));
        w.waypoints.emplace_back(at, k % 2 == 0 ? -amplitude : amplitude);
      }
    }
    return w;
  };
  const CalibrationInput input = Simulate(
      sensors, {zigzag(0.8, 5.0, 1.3, 0.0, 75.0), zigzag(1.1, 3.0, 1.0, 75.0, 180.0)}, 180.0, 13,
      0.02);
  CalibrationOptions options;
  options.reference = "a";
  const CalibrationOutcome outcome = Calibrate(input, options);
  ASSERT_TRUE(outcome.ok) << outcome.error;
  std::size_t flagged = 0;
  for (std::size_t i = 1; i < sensors.size(); ++i) {
    const SensorPose& got = outcome.result.sensors[i];
    ASSERT_TRUE(got.calibrated) << got.id;
    flagged += got.flag.empty() ? 0 : 1;
    const Pose2 want = sensors[0].world_from_sensor.inverse() * sensors[i].world_from_sensor;
    const double dt = common::TranslationDistanceM(got.world_from_sensor, want);
    const double dyaw = common::RotationDistanceRad(got.world_from_sensor, want);
    EXPECT_LT(dt, 3.0 * std::sqrt(got.covariance(0, 0) + got.covariance(1, 1))) << got.id;
    EXPECT_LT(dyaw, 3.0 * std::sqrt(got.covariance(2, 2))) << got.id;
    EXPECT_LT(dt, 0.5) << got.id;
  }
  EXPECT_GT(flagged, 0u);
  std::size_t used = 0;
  for (const EdgeReport& e : outcome.result.edges) used += e.used ? 1 : 0;
  EXPECT_EQ(used, 4u);
}

// The hall's four sensors and a fifth, e, looking into the hall's corner from outside (range
// 6 m); two people walk everywhere, a third loops through e's corner.
std::pair<std::vector<SimSensor>, std::vector<Walker>> HallWithLeaf() {
  std::mt19937 rng(14);
  std::vector<SimSensor> sensors = Hall();
  sensors.push_back({"e", {15.0, -3.0, DegToRad(135.0)}});
  sensors.back().range_m = 6.0;
  std::vector<Walker> walkers = {RandomWalker(rng, 1, 11, 1, 7, 0.0),
                                 RandomWalker(rng, 1, 11, 1, 7, 5.0)};
  walkers.push_back(Loop(11.0, 1.0, 10.0, 13.5));
  return {sensors, walkers};
}

TEST(CalibratePipeline, ALeafOnAWeakPairIsPlacedWithALargeCovarianceAndAFlag) {
  // The hall's four sensors see two people everywhere; a fifth, e, looks into the hall's corner
  // from outside and sees one of them for a few seconds only.
  const auto [sensors, walkers] = HallWithLeaf();
  const CalibrationInput input = Simulate(sensors, walkers, 60.0, 15);
  CalibrationOptions options;
  options.reference = "a";
  const CalibrationOutcome outcome = Calibrate(input, options);
  ASSERT_TRUE(outcome.ok) << outcome.error;
  const SensorPose& e = outcome.result.sensors[4];
  ASSERT_TRUE(e.calibrated);
  EXPECT_NE(e.flag.find("weak pair"), std::string::npos) << e.flag;
  const Pose2 want = sensors[0].world_from_sensor.inverse() * sensors[4].world_from_sensor;
  const double sigma_t = std::sqrt(e.covariance(0, 0) + e.covariance(1, 1));
  EXPECT_LT(common::TranslationDistanceM(e.world_from_sensor, want), 2.0 * sigma_t);
  EXPECT_LT(common::RotationDistanceRad(e.world_from_sensor, want),
            2.0 * std::sqrt(e.covariance(2, 2)));
  // Large: the hall's sensors are placed far better than the leaf.
  for (std::size_t i = 1; i < 4; ++i) {
    EXPECT_TRUE(outcome.result.sensors[i].flag.empty()) << outcome.result.sensors[i].flag;
    EXPECT_GT(sigma_t, 3.0 * std::sqrt(outcome.result.sensors[i].covariance(0, 0) +
                                       outcome.result.sensors[i].covariance(1, 1)));
  }
}

TEST(CalibratePipeline, ALeafOnOneWeakPairKeepsThePairsPlacementUnlessTheRefinementContradictsIt) {
  // The leaf e of the test above, its weak pair's estimate turned by one of its standard
  // deviations: the joint refinement moves e by about that much, which the pair's own uncertainty
  // explains, so e keeps the pairs' placement (relative to the sensor it hangs on: exactly the
  // pair's estimate) and says so; the method before it took the refinement's pose. The same turn
  // with a covariance that claims a tenth of it: the move contradicts the pair, the refinement's
  // pose is taken.
  const auto [sensors, walkers] = HallWithLeaf();
  const AlignedTracks tracks = Align(Simulate(sensors, walkers, 60.0, 15), {});
  // e's pair with most matches is its only one (the others rejected): e hangs on it alone.
  std::vector<PairEstimate> estimated = EstimateAllPairs(tracks, {});
  const PairEstimate* leaf_pair = nullptr;
  for (const PairEstimate& p : estimated) {
    if (p.accepted && (p.r == 4 || p.s == 4) && (!leaf_pair || p.matches > leaf_pair->matches)) {
      leaf_pair = &p;
    }
  }
  ASSERT_NE(leaf_pair, nullptr);
  for (PairEstimate& p : estimated) {
    if ((p.r == 4 || p.s == 4) && &p != leaf_pair) {
      p.accepted = false;
      p.reason = "left out by the test";
    }
  }
  ASSERT_TRUE(leaf_pair->weak);
  const double yaw_sigma_rad = std::sqrt(leaf_pair->covariance(2, 2));
  ASSERT_GT(RadToDeg(yaw_sigma_rad), 0.5);
  const auto turned = [&](double covariance_scale) {
    std::vector<PairEstimate> pairs = estimated;
    for (PairEstimate& p : pairs) {
      if (p.r != leaf_pair->r || p.s != leaf_pair->s) continue;
      p.s_from_r.yaw_rad += yaw_sigma_rad;
      p.covariance *= covariance_scale;
    }
    return pairs;
  };
  const auto leaf_relative = [&](const CalibrationOutcome& o) {  // s_from_r of the leaf's pair
    return o.result.sensors[leaf_pair->s].world_from_sensor.inverse() *
           o.result.sensors[leaf_pair->r].world_from_sensor;
  };
  const Pose2 truth = sensors[0].world_from_sensor.inverse() * sensors[4].world_from_sensor;
  CalibrationOptions options;
  options.reference = "a";
  std::vector<PairEstimate> pairs = turned(1.0);
  const CalibrationOutcome kept = CalibrateFromPairs(tracks, pairs, options);
  ASSERT_TRUE(kept.ok) << kept.error;
  ASSERT_TRUE(kept.result.refined);
  // Ellipse trackers: no shared radial bias in the model, none reported.
  for (const SensorPose& s : kept.result.sensors) EXPECT_FALSE(s.radial_bias.has_value()) << s.id;
  Pose2 want;
  for (const PairEstimate& p : pairs) {
    if (p.r == leaf_pair->r && p.s == leaf_pair->s) want = p.s_from_r;
  }
  const Pose2 got = leaf_relative(kept);
  EXPECT_NEAR(got.x_m, want.x_m, 1e-9);
  EXPECT_NEAR(got.y_m, want.y_m, 1e-9);
  EXPECT_NEAR(common::AngleDiff(got.yaw_rad, want.yaw_rad), 0.0, 1e-9);
  bool said = false;
  for (const std::string& w : kept.result.warnings) {
    said |= w.find("would move e") != std::string::npos &&
            w.find("kept the pairs' placement") != std::string::npos;
  }
  EXPECT_TRUE(said);
  const SensorPose& e = kept.result.sensors[4];
  EXPECT_NE(e.flag.find("weak pair"), std::string::npos) << e.flag;
  // It names what data would place it: the sensors whose pairs with it saw people but were left
  // out.
  EXPECT_NE(e.flag.find("would place it"), std::string::npos) << e.flag;
  EXPECT_LT(common::RotationDistanceRad(e.world_from_sensor, truth),
            2.0 * std::sqrt(e.covariance(2, 2)));
  EXPECT_LT(common::TranslationDistanceM(e.world_from_sensor, truth),
            2.0 * std::sqrt(e.covariance(0, 0) + e.covariance(1, 1)));
  // The hall's sensors are refined as before: the leaf's decision is its own.
  options.weak_refine_min_move_sigma = 0.0;
  const CalibrationOutcome before = CalibrateFromPairs(tracks, pairs, options);
  ASSERT_TRUE(before.ok) << before.error;
  const double moved_rad = std::abs(common::AngleDiff(leaf_relative(before).yaw_rad, want.yaw_rad));
  EXPECT_GT(moved_rad, 0.3 * yaw_sigma_rad) << RadToDeg(moved_rad);
  EXPECT_LT(moved_rad, 2.8 * yaw_sigma_rad) << RadToDeg(moved_rad);
  for (std::size_t i = 1; i < 4; ++i) {
    EXPECT_LT(common::TranslationDistanceM(kept.result.sensors[i].world_from_sensor,
                                           before.result.sensors[i].world_from_sensor),
              1e-9)
        << i;
  }
  // A pair that claims a tenth of that uncertainty: the same move is ten of its sigmas.
  options.weak_refine_min_move_sigma = CalibrationOptions{}.weak_refine_min_move_sigma;
  const CalibrationOutcome moved = CalibrateFromPairs(tracks, turned(0.01), options);
  ASSERT_TRUE(moved.ok) << moved.error;
  EXPECT_GT(std::abs(common::AngleDiff(leaf_relative(moved).yaw_rad, want.yaw_rad)),
            0.3 * yaw_sigma_rad);
  for (const std::string& w : moved.result.warnings) {
    EXPECT_EQ(w.find("kept the pairs' placement"), std::string::npos) << w;
  }
}

// The hall with walls around it (notched so that no wall is seen alone); sensor c's tracks biased
// by `bias_m` the model does not know, and recorded while c was turned by `tracks_turn_deg` from
// where it learnt its background.
CalibrationOutcome HallWithWallsAndABiasedSensor(double bias_m, double tracks_turn_deg,
                                                 std::vector<SimSensor>* sensors,
                                                 double others_bias_m = 0.0,
                                                 const CalibrationOptions& given = {},
                                                 double b_bias_m = 0.0) {
  std::mt19937 rng(16);
  *sensors = Hall();
  for (SimSensor& s : *sensors) s.unknown_bias_m = others_bias_m;
  (*sensors)[2].unknown_bias_m = bias_m;
  if (b_bias_m != 0.0) (*sensors)[1].unknown_bias_m = b_bias_m;
  std::vector<SimSensor> while_tracking = *sensors;
  while_tracking[2].world_from_sensor.yaw_rad += DegToRad(tracks_turn_deg);
  const std::vector<Walker> walkers = {RandomWalker(rng, 1, 11, 1, 7, 0.0),
                                       RandomWalker(rng, 1, 11, 1, 7, 5.0)};
  CalibrationInput input = Simulate(while_tracking, walkers, 60.0, 17);
  const std::vector<Eigen::Vector2d> room = {{-1.0, -1.0}, {5.0, -1.0},  {5.0, -1.6}, {7.0, -1.6},
                                             {7.0, -1.0},  {13.0, -1.0}, {13.0, 3.5}, {13.6, 3.5},
                                             {13.6, 4.5},  {13.0, 4.5},  {13.0, 9.0}, {-1.0, 9.0}};
  for (std::size_t i = 0; i < sensors->size(); ++i) {
    input.sensors[i].background = CastBackground(room, (*sensors)[i].world_from_sensor);
  }
  CalibrationOptions options = given;
  options.reference = "a";
  return Calibrate(input, options);
}

// Position and yaw errors of sensor i against the truth, and whether 3 sigma cover them.
struct Judged {
  double dt_m = 0.0, dyaw_rad = 0.0;
  bool covered = false;
};
Judged Judge(const CalibrationOutcome& outcome, const std::vector<SimSensor>& truth,
             std::size_t i) {
  const SensorPose& got = outcome.result.sensors[i];
  const Pose2 want = truth[0].world_from_sensor.inverse() * truth[i].world_from_sensor;
  Judged j;
  j.dt_m = common::TranslationDistanceM(got.world_from_sensor, want);
  j.dyaw_rad = common::RotationDistanceRad(got.world_from_sensor, want);
  j.covered = j.dt_m <= 3.0 * std::sqrt(got.covariance(0, 0) + got.covariance(1, 1)) &&
              j.dyaw_rad <= 3.0 * std::sqrt(got.covariance(2, 2));
  return j;
}

TEST(CalibratePipeline, WallsPlaceASensorWhoseTracksCarryABiasTheModelDoesNotKnow) {
  // c's tracks put everyone 0.12 m too far from it (legs at knee height fitted as a torso): its
  // pairs are off by about that much with covariances of a few centimetres. The walls, which fix
  // every direction, win; the joint refinement, which would follow the tracks, is not kept where
  // it moves a sensor beyond the pairs' uncertainty. No sensor's error exceeds 3 sigma.
  std::vector<SimSensor> sensors;
  const CalibrationOutcome outcome = HallWithWallsAndABiasedSensor(0.12, 0.0, &sensors);
  ASSERT_TRUE(outcome.ok) << outcome.error;
  for (std::size_t i = 1; i < sensors.size(); ++i) {
    const Judged j = Judge(outcome, sensors, i);
    EXPECT_LT(j.dt_m, 0.03) << sensors[i].id;
    EXPECT_LT(RadToDeg(j.dyaw_rad), 0.2) << sensors[i].id;
    EXPECT_TRUE(j.covered) << sensors[i].id << " " << j.dt_m << " m " << RadToDeg(j.dyaw_rad)
                           << " deg";
  }
  std::size_t icp = 0;
  for (const EdgeReport& e : outcome.result.edges) {
    if ((e.r == "c" || e.s == "c") && e.used) icp += e.icp_applied ? 1 : 0;
  }
  EXPECT_GE(icp, 2u);
}

TEST(CalibratePipeline, TheRefinementIsNotKeptWhereItBreaksAPairsWalls) {
  // b's and c's tracks both put everyone 0.12 m too far from them (two knee-height scanners whose
  // tracker fits a torso to legs). The per-sensor test is off (it sums the refinement's own
  // covariance, wide where its robust loss gave a wall constraint up): the wall test alone (off by
  // default) keeps the walls' placement, and without it the refinement follows the tracks.
  CalibrationOptions options;
  options.refine_max_disagreement_sigma = std::numeric_limits<double>::infinity();
  options.refine_max_wall_residual_sigma = 3.5;
  std::vector<SimSensor> sensors;
  const CalibrationOutcome walls =
      HallWithWallsAndABiasedSensor(0.12, 0.0, &sensors, 0.0, options, 0.12);
  ASSERT_TRUE(walls.ok) << walls.error;
  bool said = false;
  for (const std::string& w : walls.result.warnings) {
    said |= w.find("off its background alignment") != std::string::npos;
  }
  EXPECT_TRUE(said);
  double worst_walls_m = 0.0;
  for (std::size_t i = 1; i < sensors.size(); ++i) {
    const Judged j = Judge(walls, sensors, i);
    worst_walls_m = std::max(worst_walls_m, j.dt_m);
    EXPECT_LT(j.dt_m, 0.03) << sensors[i].id;
    EXPECT_LT(RadToDeg(j.dyaw_rad), 0.2) << sensors[i].id;
    EXPECT_TRUE(j.covered) << sensors[i].id << " " << j.dt_m << " m " << RadToDeg(j.dyaw_rad)
                           << " deg";
  }
  options.refine_max_wall_residual_sigma = std::numeric_limits<double>::infinity();
  const CalibrationOutcome tracks =
      HallWithWallsAndABiasedSensor(0.12, 0.0, &sensors, 0.0, options, 0.12);
  ASSERT_TRUE(tracks.ok) << tracks.error;
  EXPECT_TRUE(tracks.result.refined);
  double worst_tracks_m = 0.0;
  for (std::size_t i = 1; i < sensors.size(); ++i) {
    worst_tracks_m = std::max(worst_tracks_m, Judge(tracks, sensors, i).dt_m);
  }
  EXPECT_GT(worst_tracks_m, 2.0 * worst_walls_m);
  CalibrationOptions bad;
  bad.refine_max_wall_residual_sigma = 0.0;
  EXPECT_TRUE(Validate(bad).has_value());
}

TEST(CalibratePipeline, TracksThatContradictTheWallsLeaveTheirPairsUncertainNotWrong) {
  // c's tracks were recorded 1 degree away from where it learnt its background: tracks and walls
  // disagree beyond what either's covariance (and the bias allowed for) explains, and a pair
  // cannot tell which is right. It keeps the tracks' estimate with a covariance that covers the
  // walls' pose, as a candidate: c is placed, flagged, and both of its poses lie within 3 sigma.
  std::vector<SimSensor> sensors;
  const CalibrationOutcome outcome = HallWithWallsAndABiasedSensor(0.0, 1.6, &sensors);
  ASSERT_TRUE(outcome.ok) << outcome.error;
  for (std::size_t i = 1; i < sensors.size(); ++i) {
    const Judged j = Judge(outcome, sensors, i);  // the walls' pose
    EXPECT_TRUE(j.covered) << sensors[i].id << " " << j.dt_m << " m " << RadToDeg(j.dyaw_rad)
                           << " deg";
  }
  sensors[2].world_from_sensor.yaw_rad += DegToRad(1.6);
  const Judged tracks_pose = Judge(outcome, sensors, 2);
  EXPECT_TRUE(tracks_pose.covered)
      << tracks_pose.dt_m << " m " << RadToDeg(tracks_pose.dyaw_rad) << " deg";
  EXPECT_FALSE(outcome.result.sensors[2].flag.empty());
  std::size_t disagreeing = 0;
  for (const PairEstimate& p : outcome.pairs) {
    if (p.weak && p.weak_reason.find("disagrees with the tracks") != std::string::npos) {
      ++disagreeing;
      EXPECT_TRUE(outcome.tracks.sensors[p.r].id == "c" || outcome.tracks.sensors[p.s].id == "c");
    }
  }
  EXPECT_GE(disagreeing, 1u);
}

TEST(CalibrateScale, ALayoutWhoseScaleThePeoplesSizeExplainsSaysSoAndItsSigmaCoversTheError) {
  // The diamond: every person is seen by two neighbours from directions 90 degrees apart across
  // the layout, and the people are larger than the model's prior (their positions come 0.08 m
  // closer to each sensor than it expects). A larger size and a smaller layout explain the data
  // alike: the size is held at its prior, the result says the scale is not observable, and the
  // prior's uncertainty in the covariances covers the error.
  std::vector<SimSensor> sensors = Ring();
  for (SimSensor& s : sensors) s.unknown_bias_m = -0.08;
  const CalibrationInput input = Simulate(sensors, RingWalkers(), 60.0, 18);
  CalibrationOptions options;
  options.reference = "a";
  const CalibrationOutcome outcome = Calibrate(input, options);
  ASSERT_TRUE(outcome.ok) << outcome.error;
  EXPECT_EQ(outcome.result.scale_note.rfind("scale not observable", 0), 0u)
      << outcome.result.scale_note;
  double worst_m = 0.0;
  for (std::size_t i = 1; i < sensors.size(); ++i) {
    const Judged j = Judge(outcome, sensors, i);
    worst_m = std::max(worst_m, j.dt_m);
    EXPECT_TRUE(j.covered) << sensors[i].id << " " << j.dt_m << " m " << RadToDeg(j.dyaw_rad)
                           << " deg";
  }
  EXPECT_GT(worst_m, 0.1);  // the layout did shrink: the statement is not idle

  // The hall with the same people, but walls that every sensor sees: the walls fix the scale,
  // nothing is said about it, and the poses are right.
  std::vector<SimSensor> hall;
  const CalibrationOutcome observable = HallWithWallsAndABiasedSensor(-0.08, 0.0, &hall, -0.08);
  ASSERT_TRUE(observable.ok) << observable.error;
  EXPECT_TRUE(observable.result.scale_note.empty()) << observable.result.scale_note;
  ExpectClose(observable, hall, 0.03, 0.2);
}

// The input as shape-fit trackers configured for upper-body height send it: each track's learned
// size (semi-axes major x minor; `legs_sensor`'s tracks leg-sized, 0.2 x 0.066 m, the others a
// torso's) and, so that each sensor has enough tracks to judge, a new track id every 10 s.
void AsShapeFitTrackers(CalibrationInput* input, std::size_t legs_sensor) {
  for (std::size_t i = 0; i < input->sensors.size(); ++i) {
    SensorRecording& rec = input->sensors[i];
    rec.description = daemon::SensorDescription{};
    rec.description->kind = MeasurementKind::kShapeFit;
    rec.description->mount = daemon::MountHeight::kTorso;
    const common::UtcNs t0_ns = rec.frames.front().scan_start_ns;
    for (TrackFrameData& f : rec.frames) {
      const auto part = static_cast<std::uint32_t>((f.scan_start_ns - t0_ns) / 10'000'000'000);
      for (TrackObservation& o : f.tracks) {
        o.track_id += 100 * part;
        o.kind = MeasurementKind::kShapeFit;
        o.shape = daemon::ObjectShape::kTorso;
        o.size_major_m = i == legs_sensor ? 0.2f : 0.23f;
        o.size_minor_m = i == legs_sensor ? 0.066f : 0.14f;
        o.size_sigma_m = 0.02f;
      }
    }
  }
}

TEST(CalibratePipeline, ASensorWhoseTracksLookLikeLegsIsFlaggedAndItsSigmaCoversTheError) {
  // The hall without walls in range; c is a knee-height scanner left at the default mount: its
  // tracker fits a torso to two legs (leg-sized tracks) and puts everyone 0.12 m farther from it
  // than the body centre. Nothing but the tracks places it.
  std::mt19937 rng(16);
  std::vector<SimSensor> sensors = Hall();
  sensors[2].unknown_bias_m = 0.12;
  const std::vector<Walker> walkers = {RandomWalker(rng, 1, 11, 1, 7, 0.0),
                                       RandomWalker(rng, 1, 11, 1, 7, 5.0)};
  CalibrationInput input = Simulate(sensors, walkers, 60.0, 17);
  AsShapeFitTrackers(&input, 2);
  CalibrationOptions options;
  options.reference = "a";
  const CalibrationOutcome outcome = Calibrate(input, options);
  ASSERT_TRUE(outcome.ok) << outcome.error;
  ASSERT_EQ(outcome.mount_checks.size(), 4u);
  for (std::size_t i = 0; i < 4; ++i) {
    EXPECT_TRUE(outcome.mount_checks[i].decided) << sensors[i].id;
    EXPECT_EQ(outcome.mount_checks[i].looks_like_legs, i == 2) << sensors[i].id;
    EXPECT_EQ(outcome.result.sensors[i].mount_looks_like_legs, i == 2) << sensors[i].id;
  }
  const std::string& flag = outcome.result.sensors[2].flag;
  EXPECT_NE(flag.find("c: tracks look like legs"), std::string::npos) << flag;
  EXPECT_NE(flag.find("median half-width 0.07 m"), std::string::npos) << flag;
  EXPECT_NE(flag.find("set shape.mount: legs on its tracker"), std::string::npos) << flag;
  for (std::size_t i : {1, 3}) EXPECT_TRUE(outcome.result.sensors[i].flag.empty()) << i;
  for (std::size_t i = 1; i < sensors.size(); ++i) {
    const Judged j = Judge(outcome, sensors, i);
    EXPECT_TRUE(j.covered) << sensors[i].id << " " << j.dt_m << " m " << RadToDeg(j.dyaw_rad)
                           << " deg";
  }
  // The bias prior lets the pairs through c estimate its offset: c is placed within 3 cm.
  const auto sigma_t_m = [](const CalibrationOutcome& o) {
    const Eigen::Matrix3d& c = o.result.sensors[2].covariance;
    return std::sqrt(c(0, 0) + c(1, 1));
  };
  const Judged checked = Judge(outcome, sensors, 2);
  EXPECT_LT(checked.dt_m, 0.03);
  EXPECT_LT(checked.dt_m, 2.0 * sigma_t_m(outcome));
  // Without the check the same data put c 0.1 m off, beyond 2 sigma, and say nothing.
  options.check_mount = false;
  const CalibrationOutcome unchecked = Calibrate(input, options);
  ASSERT_TRUE(unchecked.ok) << unchecked.error;
  EXPECT_TRUE(unchecked.result.sensors[2].flag.empty());
  EXPECT_FALSE(unchecked.result.sensors[2].mount_looks_like_legs);
  // Refined, every sensor carries its shared radial bias; without walls nothing ties sensors that
  // see one person from different directions, so none is observed: each held at 0 with its
  // 0.02 m prior (c's 0.12 m is what the mount check is for).
  ASSERT_TRUE(unchecked.result.refined);
  for (const SensorPose& s : unchecked.result.sensors) {
    ASSERT_TRUE(s.radial_bias.has_value()) << s.id;
    EXPECT_FALSE(s.radial_bias->estimated) << s.id;
    EXPECT_EQ(s.radial_bias->bias_m, 0.0) << s.id;
    EXPECT_NEAR(s.radial_bias->sigma_m, 0.02, 1e-6) << s.id;
  }
  const Judged j = Judge(unchecked, sensors, 2);
  EXPECT_GT(j.dt_m, 0.08);
  EXPECT_GT(j.dt_m, 2.0 * sigma_t_m(unchecked)) << sigma_t_m(unchecked);
}

}  // namespace
}  // namespace lrfnet::calib
