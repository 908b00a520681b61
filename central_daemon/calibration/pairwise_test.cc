#include "central_daemon/calibration/pairwise.h"

#include <gtest/gtest.h>

#include <Eigen/LU>
#include <cmath>
#include <limits>
#include <optional>
#include <random>

namespace lrfnet::calib {
namespace {

using common::DegToRad;
using common::RadToDeg;
using Eigen::Vector2d;

// ---------------------------------------------------------------------------------------------
// A small synthetic world: people walking closed polygons at constant speed, seen by sensors with
// a range and a field of view. Every contiguous stretch of visibility is one track (so a person
// who leaves and re-enters gets a new id), optionally cut into pieces of split_every_steps.

struct Person {
  std::vector<Vector2d> path;  // world frame, closed loop; one point = standing still
  double speed_mps = 1.2;
  double start_s = 0.0;  // present on [start_s, end_s)
  double end_s = 1e9;
  double offset_m = 0.0;  // where on its path the person starts
};

struct SimSensor {
  Pose2 world_from_sensor;
  double range_m = 25.0;
  double fov_deg = 360.0;
  std::size_t split_every_steps = 0;  // 0: tracks end only when visibility ends
};

struct SimOptions {
  std::size_t steps = 1200;
  double step_s = 0.05;
  double noise_m = 0.0;  // AR(1) noise per track, standard deviation
  // The observed point moves this far towards the sensor (the CoM of the seen side)...
  double com_bias_m = 0.0;
  // ...and the measurement model says it is model_bias_m (by default: what it is), with this
  // sensitivity to the minor semi-axis' correction (per metre of correction) and sigmas.
  std::optional<double> model_bias_m;
  double model_per_minor = 0.0;
  double model_sigma_m = 0.0;
  double cov_sigma_m = 0.03;                         // reported position standard deviation
  MeasurementKind kind = MeasurementKind::kEllipse;  // kCenterOfMass with com_bias_m
  double size_prior_sigma_m = 0.05;
  double shared_bias_sigma_m = 0.0;  // TrackSample::shared_bias_sigma_m of every sample
  std::uint64_t seed = 11;
};

struct Sim {
  AlignedTracks aligned;
  std::vector<std::vector<std::size_t>> person_of_track;  // [sensor][track]
};

Vector2d PathPosition(const Person& p, double t_s) {
  if (p.path.size() == 1) return p.path[0];
  double perimeter = 0.0;
  for (std::size_t i = 0; i < p.path.size(); ++i) {
    perimeter += (p.path[(i + 1) % p.path.size()] - p.path[i]).norm();
  }
  double d = std::fmod(p.offset_m + p.speed_mps * (t_s - p.start_s), perimeter);
  if (d < 0) d += perimeter;
  for (std::size_t i = 0;; i = (i + 1) % p.path.size()) {
    const Vector2d a = p.path[i], b = p.path[(i + 1) % p.path.size()];
    const double len = (b - a).norm();
    if (d <= len) return a + (b - a) * (d / len);
    d -= len;
  }
}

Sim Simulate(const std::vector<SimSensor>& sensors, const std::vector<Person>& people,
             const SimOptions& o) {
  Sim sim;
  sim.aligned.step_s = o.step_s;
  sim.aligned.steps = o.steps;
  sim.aligned.size_prior_sigma_m = o.size_prior_sigma_m;
  sim.person_of_track.resize(sensors.size());
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  const double a = 0.9, b = std::sqrt(1.0 - a * a);
  for (std::size_t si = 0; si < sensors.size(); ++si) {
    const SimSensor& sensor = sensors[si];
    SensorTracks st;
    st.id = "s" + std::to_string(si);
    const Pose2 sensor_from_world = sensor.world_from_sensor.inverse();
    for (std::size_t pi = 0; pi < people.size(); ++pi) {
      const Person& person = people[pi];
      GridTrack* open = nullptr;
      Vector2d noise = Vector2d::Zero();
      for (std::size_t k = 0; k < o.steps; ++k) {
        const double t = static_cast<double>(k) * o.step_s;
        const Vector2d w = PathPosition(person, t);
        const Vector2d local = sensor_from_world * w;
        const double bearing = std::atan2(local.y(), local.x());
        const bool visible = t >= person.start_s && t < person.end_s &&
                             local.norm() <= sensor.range_m &&
                             std::abs(bearing) <= DegToRad(sensor.fov_deg) / 2.0 + 1e-12;
        if (!visible) {
          open = nullptr;
          continue;
        }
        if (open != nullptr && sensor.split_every_steps > 0 &&
            open->samples.size() >= sensor.split_every_steps) {
          open = nullptr;
        }
        if (open == nullptr) {
          st.tracks.emplace_back();
          open = &st.tracks.back();
          open->track_id = static_cast<std::uint32_t>(st.tracks.size());
          open->first_step = k;
          open->kind = o.kind;
          sim.person_of_track[si].push_back(pi);
          noise = o.noise_m * Vector2d(gauss(rng), gauss(rng));
        }
        noise = a * noise + b * o.noise_m * Vector2d(gauss(rng), gauss(rng));
        TrackSample x;
        x.position_m = local - o.com_bias_m * local.normalized() + noise;
        x.position_cov_m2 = Eigen::Matrix2d::Identity() * (o.cov_sigma_m * o.cov_sigma_m);
        x.kind = o.kind;
        x.bias_m = static_cast<float>(o.model_bias_m.value_or(o.com_bias_m));
        x.bias_per_minor = static_cast<float>(o.model_per_minor);
        x.model_sigma_m = static_cast<float>(o.model_sigma_m);
        x.shared_bias_sigma_m = static_cast<float>(o.shared_bias_sigma_m);
        open->samples.push_back(x);
      }
    }
    // Tracks were made person by person; AlignedTracks orders them by first_step.
    std::vector<std::size_t> order(st.tracks.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(), [&](std::size_t x, std::size_t y) {
      return st.tracks[x].first_step < st.tracks[y].first_step;
    });
    SensorTracks sorted = st;
    std::vector<std::size_t> persons;
    for (std::size_t i = 0; i < order.size(); ++i) {
      sorted.tracks[i] = st.tracks[order[i]];
      persons.push_back(sim.person_of_track[si][order[i]]);
    }
    sim.person_of_track[si] = persons;
    sim.aligned.sensors.push_back(std::move(sorted));
  }
  return sim;
}

Pose2 TrueSFromR(const std::vector<SimSensor>& sensors, std::size_t r, std::size_t s) {
  return sensors[s].world_from_sensor.inverse() * sensors[r].world_from_sensor;
}

double YawErrorDeg(const Pose2& a, const Pose2& b) {
  return RadToDeg(common::RotationDistanceRad(a, b));
}
double TranslationError(const Pose2& a, const Pose2& b) {
  return common::TranslationDistanceM(a, b);
}

// Two sensors on opposite corners of a 10 m x 10 m room, facing each other.
std::vector<SimSensor> FacingPair() {
  return {{Pose2{0.0, 0.0, DegToRad(45.0)}, 25.0, 270.0, 0},
          {Pose2{10.0, 10.0, DegToRad(-135.0)}, 25.0, 270.0, 0}};
}

Person Walker(std::vector<Vector2d> path, double speed_mps, double offset_m = 0.0) {
  Person p;
  p.path = std::move(path);
  p.speed_mps = speed_mps;
  p.offset_m = offset_m;
  return p;
}

std::vector<Person> Crowd(std::size_t n) {
  std::vector<Person> all = {
      Walker({{2, 2}, {8, 3}, {7, 8}, {3, 7}}, 1.2),
      Walker({{8, 2}, {2, 8}, {8, 8}, {2, 2}}, 1.0, 3.0),   // crosses the others
      Walker({{5, 1}, {9, 6}, {5, 9}, {1, 5}}, 1.4, 5.0),   // crosses the others
      Walker({{3, 3}, {7, 3}, {7, 7}, {3, 7}}, 0.9, 7.0)};  // inside, parallel segments
  all.resize(n);
  return all;
}

void ExpectClose(const PairEstimate& e, const Pose2& truth, double yaw_deg, double dist_m) {
  EXPECT_TRUE(e.accepted) << e.reason;
  EXPECT_LT(YawErrorDeg(e.s_from_r, truth), yaw_deg);
  EXPECT_LT(TranslationError(e.s_from_r, truth), dist_m);
}

// ---------------------------------------------------------------------------------------------

TEST(PairwiseOptions, DefaultsAreValidAndBadValuesAreNamed) {
  EXPECT_FALSE(Validate(PairwiseOptions{}).has_value());
  PairwiseOptions o;
  o.model_sigma_m = 0.0;
  ASSERT_TRUE(Validate(o).has_value());
  EXPECT_NE(Validate(o)->find("model_sigma_m"), std::string::npos);
  o = {};
  o.max_ambiguity_ratio = 1.5;
  EXPECT_TRUE(Validate(o).has_value());
  o = {};
  o.intervals.min_steps = 0;
  EXPECT_TRUE(Validate(o).has_value());
  o = {};
  o.verify_gate = std::nan("");
  EXPECT_TRUE(Validate(o).has_value());
}

TEST(EstimatePair, ExactWithoutNoise) {
  const auto sensors = FacingPair();
  const Sim sim = Simulate(sensors, Crowd(1), {});
  const PairEstimate e = EstimatePair(sim.aligned, 0, 1, {});
  ExpectClose(e, TrueSFromR(sensors, 0, 1), 1e-6, 1e-6);
  EXPECT_EQ(e.r, 0u);
  EXPECT_EQ(e.s, 1u);
  EXPECT_EQ(e.matches, 1200u);
  EXPECT_LT(e.rms_m, 1e-6);
  EXPECT_EQ(e.intervals, 1u);
  EXPECT_GE(e.hypotheses, 1u);
  EXPECT_FALSE(std::isfinite(e.second_error));  // nothing else comes close
}

TEST(EstimatePair, AccurateWithNoiseAndAConsistentCovariance) {
  const auto sensors = FacingPair();
  SimOptions o;
  o.noise_m = 0.04;
  const Sim sim = Simulate(sensors, Crowd(2), o);
  const PairEstimate e = EstimatePair(sim.aligned, 0, 1, {});
  const Pose2 truth = TrueSFromR(sensors, 0, 1);
  ExpectClose(e, truth, 0.3, 0.03);
  EXPECT_NEAR(e.rms_m, 0.04 * std::sqrt(2.0) * std::sqrt(2.0), 0.03);
  // The reported uncertainty covers the actual error without being uselessly wide.
  const double sigma_yaw = std::sqrt(e.covariance(2, 2));
  const double sigma_xy = std::sqrt(e.covariance(0, 0) + e.covariance(1, 1));
  EXPECT_LT(std::abs(common::AngleDiff(e.s_from_r.yaw_rad, truth.yaw_rad)), 4.0 * sigma_yaw);
  EXPECT_LT(TranslationError(e.s_from_r, truth), 4.0 * sigma_xy);
  EXPECT_LT(RadToDeg(sigma_yaw), 0.5);
  EXPECT_LT(sigma_xy, 0.1);
}

TEST(EstimatePair, TheMeasurementModelsBiasIsRemoved) {
  // The seen side of a person is nearer the sensor; the model says by how much. Facing sensors
  // see the people between them from nearly constant directions, so unmodelled the offset would
  // shrink the baseline by both sensors' biases.
  const auto sensors = FacingPair();
  SimOptions o;
  o.noise_m = 0.03;
  o.com_bias_m = 0.17;
  o.kind = MeasurementKind::kCenterOfMass;
  const Sim sim = Simulate(sensors, Crowd(3), o);
  const Pose2 truth = TrueSFromR(sensors, 0, 1);
  ExpectClose(EstimatePair(sim.aligned, 0, 1, {}), truth, 0.3, 0.04);
  SimOptions unmodelled = o;
  unmodelled.model_bias_m = 0.0;
  const PairEstimate biased =
      EstimatePair(Simulate(sensors, Crowd(3), unmodelled).aligned, 0, 1, {});
  EXPECT_GT(TranslationError(biased.s_from_r, truth), 0.15);
}

TEST(EstimatePair, ASizeErrorIsEstimatedWhereTheViewsTellItFromTheTranslation) {
  // The body is larger than the model's prior: every centre of mass sits 0.05 m nearer its
  // sensor than the model says, which a correction of the minor semi-axis (pi/4 per metre)
  // explains. Two sensors at right angles see the people from directions that vary: observable.
  const std::vector<SimSensor> sensors = {{Pose2{0.0, 0.0, DegToRad(45.0)}, 25.0, 270.0, 0},
                                          {Pose2{10.0, 0.0, DegToRad(135.0)}, 25.0, 270.0, 0}};
  SimOptions o;
  o.noise_m = 0.02;
  o.com_bias_m = 0.17;
  o.model_bias_m = 0.12;
  o.model_per_minor = common::kPi / 4.0;
  o.kind = MeasurementKind::kCenterOfMass;
  const Sim sim = Simulate(sensors, Crowd(3), o);
  const Pose2 truth = TrueSFromR(sensors, 0, 1);
  PairDiagnostics diag;
  const PairEstimate e = EstimatePair(sim.aligned, 0, 1, {}, &diag);
  ExpectClose(e, truth, 0.3, 0.03);
  EXPECT_NEAR(diag.size_correction_m.y(), 0.05 / (common::kPi / 4.0), 0.02);
  // Held at the prior, the error goes into the translation; the covariance still carries the
  // prior's uncertainty.
  PairwiseOptions held;
  held.estimate_size_correction = false;
  const PairEstimate h = EstimatePair(sim.aligned, 0, 1, held);
  EXPECT_GT(TranslationError(h.s_from_r, truth), TranslationError(e.s_from_r, truth));
  EXPECT_LT(TranslationError(h.s_from_r, truth),
            3.0 * std::sqrt(h.covariance(0, 0) + h.covariance(1, 1)));
}

TEST(EstimatePair, HonestCovarianceCoversTheErrorOverManyRuns) {
  // 20 noise realisations of a facing pair with two people: the normalised estimation error
  // squared of (x, y, yaw) against the reported covariance must not exceed its 3 dof by much.
  const auto sensors = FacingPair();
  const Pose2 truth = TrueSFromR(sensors, 0, 1);
  double nees = 0.0;
  int within = 0;
  const int runs = 20;
  for (int k = 0; k < runs; ++k) {
    SimOptions o;
    o.noise_m = 0.04;
    o.steps = 600;
    o.seed = 100 + static_cast<std::uint64_t>(k);
    const PairEstimate e = EstimatePair(Simulate(sensors, Crowd(2), o).aligned, 0, 1, {});
    ASSERT_TRUE(e.accepted) << e.reason;
    const Eigen::Vector3d d(e.s_from_r.x_m - truth.x_m, e.s_from_r.y_m - truth.y_m,
                            common::AngleDiff(e.s_from_r.yaw_rad, truth.yaw_rad));
    const double n = d.dot(e.covariance.inverse() * d);
    nees += n;
    within += n <= 7.81 ? 1 : 0;  // chi-square 3 dof, 95 %
  }
  EXPECT_LT(nees / runs, 6.0);
  EXPECT_GE(within, 18);
}

TEST(EstimatePair, SensorBiasOfFacingViewsIsInTheCovariance) {
  // Facing sensors that see the people only in the middle of the room (8 m range): every shape
  // fit sits 0.02 m beyond the body centre along its line of sight (one standard deviation of
  // the shared bias the model allows), which adds up along the line between them and does not
  // average out over the samples. With both sensors' bias as consider parameters the covariance
  // covers the error; without, it claims what the noise alone leaves.
  std::vector<SimSensor> sensors = FacingPair();
  for (SimSensor& sensor : sensors) sensor.range_m = 8.0;
  SimOptions o;
  o.noise_m = 0.02;
  o.steps = 2400;
  o.kind = MeasurementKind::kShapeFit;
  o.com_bias_m = -0.02;
  o.model_bias_m = 0.0;
  o.shared_bias_sigma_m = 0.02;
  const Sim sim = Simulate(sensors, Crowd(4), o);
  const Pose2 truth = TrueSFromR(sensors, 0, 1);
  const PairEstimate with = EstimatePair(sim.aligned, 0, 1, {});
  PairwiseOptions off;
  off.sensor_bias = false;
  const PairEstimate without = EstimatePair(sim.aligned, 0, 1, off);
  ASSERT_TRUE(with.accepted) << with.reason;
  ASSERT_TRUE(without.accepted) << without.reason;
  const double error_m = TranslationError(with.s_from_r, truth);
  EXPECT_GT(error_m, 0.025);
  EXPECT_NEAR(TranslationError(without.s_from_r, truth), error_m, 1e-9);
  // 2-dof NEES of the translation: within chi2(2) 95 % (5.99), or beyond 3 sigma (9).
  auto nees = [&truth](const PairEstimate& e) {
    const Vector2d d = e.s_from_r.translation() - truth.translation();
    return d.dot(e.covariance.topLeftCorner<2, 2>().inverse() * d);
  };
  EXPECT_LE(nees(with), 5.99);
  EXPECT_GT(nees(without), 9.0);
  EXPECT_LT(std::sqrt(with.covariance(0, 0) + with.covariance(1, 1)), 0.06);
}

TEST(EstimatePair, FewMatchesAreWeakAndTheSameWalkRepeatedIsStrong) {
  // Sensors 12 m apart see one person together. One pass of 2.5 s along a 3 m line leaves the
  // yaw uncertain by a few degrees at the sensors' lever arm: weak, with a covariance that says so.
  // The same person walking there for a minute fixes it.
  const std::vector<SimSensor> sensors = {{Pose2{0.0, 0.0, 0.0}, 8.0, 270.0, 0},
                                          {Pose2{12.0, 0.0, common::kPi}, 8.0, 270.0, 0}};
  SimOptions o;
  o.noise_m = 0.03;
  const Pose2 truth = TrueSFromR(sensors, 0, 1);
  Person once = Walker({{5.0, -1.5}, {7.0, 0.8}, {5.0, 1.5}, {7.0, -0.8}}, 1.2);
  once.end_s = 2.5;
  const PairEstimate weak = EstimatePair(Simulate(sensors, {once}, o).aligned, 0, 1, {});
  ASSERT_TRUE(weak.accepted) << weak.reason;
  EXPECT_TRUE(weak.weak);
  EXPECT_NE(weak.weak_reason.find("weak: sigma"), std::string::npos) << weak.weak_reason;
  const double weak_sigma_deg = RadToDeg(std::sqrt(weak.covariance(2, 2)));
  EXPECT_GT(weak_sigma_deg, 1.0);
  EXPECT_LT(YawErrorDeg(weak.s_from_r, truth), 3.0 * weak_sigma_deg);
  Person often = once;
  often.end_s = 60.0;
  const PairEstimate strong = EstimatePair(Simulate(sensors, {often}, o).aligned, 0, 1, {});
  ExpectClose(strong, truth, 0.5, 0.05);
  EXPECT_FALSE(strong.weak) << strong.weak_reason;
  EXPECT_LT(RadToDeg(std::sqrt(strong.covariance(2, 2))), weak_sigma_deg / 3.0);
}

class Crowded : public ::testing::TestWithParam<std::size_t> {};

TEST_P(Crowded, VerificationPicksTheRightPairingAmongCrossingPeople) {
  const auto sensors = FacingPair();
  SimOptions o;
  o.noise_m = 0.03;
  o.com_bias_m = 0.1;
  o.kind = MeasurementKind::kCenterOfMass;
  const Sim sim = Simulate(sensors, Crowd(GetParam()), o);
  PairDiagnostics diag;
  const PairEstimate e = EstimatePair(sim.aligned, 0, 1, {}, &diag);
  ExpectClose(e, TrueSFromR(sensors, 0, 1), 0.5, 0.1);
  EXPECT_GT(e.match_fraction, 0.9);
  EXPECT_LT(diag.second_gain, 0.5 * diag.best_gain);
}

INSTANTIATE_TEST_SUITE_P(People, Crowded, ::testing::Values(2, 3, 4));

TEST(EstimatePair, WrongPairingsProduceHypothesesThatVerificationRejects) {
  // Tracks cut into 3 s pieces give many short intervals, each with every (p, q) combination of
  // four people; the wrong combinations still produce hypotheses.
  auto sensors = FacingPair();
  sensors[0].split_every_steps = 60;
  sensors[1].split_every_steps = 47;
  SimOptions o;
  o.noise_m = 0.03;
  const Sim sim = Simulate(sensors, Crowd(4), o);
  PairDiagnostics diag;
  const PairEstimate e = EstimatePair(sim.aligned, 0, 1, {}, &diag);
  ExpectClose(e, TrueSFromR(sensors, 0, 1), 0.5, 0.1);
  EXPECT_GT(e.intervals, 40u);
  EXPECT_GT(diag.clusters, 1u);  // wrong hypotheses were there to be rejected
  EXPECT_TRUE(std::isfinite(e.second_error));
  EXPECT_GT(e.second_error, e.best_error);
}

TEST(EstimatePair, UnrelatedTrackIdsAndASplitTrackDoNotMatter) {
  // r loses and re-acquires people (new ids) at other times than s, and for a while r reports a
  // second, offset track on person 0 (a split).
  auto sensors = FacingPair();
  sensors[0].split_every_steps = 90;
  sensors[1].split_every_steps = 130;
  SimOptions o;
  o.noise_m = 0.03;
  Sim sim = Simulate(sensors, Crowd(2), o);
  auto& r_tracks = sim.aligned.sensors[0].tracks;
  GridTrack ghost = r_tracks[0];
  for (auto& x : ghost.samples) x.position_m += Vector2d(0.35, -0.2);
  r_tracks.insert(r_tracks.begin() + 1, ghost);
  const PairEstimate e = EstimatePair(sim.aligned, 0, 1, {});
  ExpectClose(e, TrueSFromR(sensors, 0, 1), 0.5, 0.1);
}

TEST(EstimatePair, IndependentMotionsWithoutOverlapAreRejected) {
  // Two sensors 30 m apart with 8 m range: each sees its own people, never the other's.
  const std::vector<SimSensor> sensors = {{Pose2{0.0, 0.0, 0.0}, 8.0, 180.0, 50},
                                          {Pose2{30.0, 0.0, DegToRad(180.0)}, 8.0, 180.0, 50}};
  const std::vector<Person> people = {Walker({{2, -3}, {6, -2}, {5, 3}, {2, 2}}, 1.2),
                                      Walker({{1, 0}, {5, 1}, {6, -4}}, 1.2, 2.0),
                                      Walker({{28, 3}, {24, 2}, {25, -3}, {27, -2}}, 1.2),
                                      Walker({{26, -1}, {23, 3}, {27, 4}}, 1.2, 1.0)};
  SimOptions o;
  o.noise_m = 0.03;
  const Sim sim = Simulate(sensors, people, o);
  PairDiagnostics diag;
  const PairEstimate e = EstimatePair(sim.aligned, 0, 1, {}, &diag);
  EXPECT_GT(e.intervals, 0u);
  EXPECT_FALSE(e.accepted);
  EXPECT_FALSE(e.reason.empty());
}

TEST(EstimatePair, StraightWalksOfTwoStrangersAreRejected) {
  // Each sensor sees one person pacing up and down a straight line at the same speed, 40 m apart,
  // with tracks cut every 4 s: pieces of straight walks, and any two of them align perfectly. But
  // under such an alignment r's person lands where s sees people at other times, and nobody is
  // there.
  const std::vector<SimSensor> sensors = {{Pose2{0.0, 0.0, 0.0}, 10.0, 180.0, 80},
                                          {Pose2{40.0, 0.0, DegToRad(180.0)}, 10.0, 180.0, 80}};
  const std::vector<Person> people = {Walker({{2, -6}, {2, 6}}, 1.2),
                                      Walker({{35, 6}, {33, -5}}, 1.2, 4.0)};
  const Sim sim = Simulate(sensors, people, {});
  PairDiagnostics diag;
  const PairEstimate e = EstimatePair(sim.aligned, 0, 1, {}, &diag);
  EXPECT_GT(e.hypotheses, 0u);
  EXPECT_FALSE(e.accepted);
  // Rejected as ambiguous (another stretch of s's walk fits as well) or inconsistent (under the
  // best alignment r's walker lands where s sees nobody at that time).
  EXPECT_TRUE(e.reason.find("inconsistent") != std::string::npos ||
              e.reason.find("ambiguous") != std::string::npos)
      << e.reason;
  std::size_t visible = 0, matched = 0;
  for (std::size_t b = 0; b < kRangeBands; ++b) {
    visible += diag.r_in_s.visible[b];
    matched += diag.r_in_s.matched[b];
  }
  ASSERT_GT(visible, 0u);
  EXPECT_LT(static_cast<double>(matched) / static_cast<double>(visible), 0.35);
}

TEST(EstimatePair, TwoEquallyGoodInterpretationsAreAmbiguous) {
  // Two people walk the same loop side by side, 2 m apart, in step. r sees only one of them, s
  // both: "r's person is s's first" and "r's person is s's second" explain r's data equally well.
  const auto sensors = FacingPair();
  const Person a = Walker({{2, 2}, {6, 2.5}, {5, 6}, {2.5, 5}}, 1.0);
  Person b = a;
  for (auto& p : b.path) p += Vector2d(2.0, 0.0);
  SimOptions so;
  so.noise_m = 0.02;
  Sim sim = Simulate(sensors, {a, b}, so);
  auto& r_tracks = sim.aligned.sensors[0].tracks;
  std::vector<GridTrack> only_a;
  for (std::size_t i = 0; i < r_tracks.size(); ++i) {
    if (sim.person_of_track[0][i] == 0) only_a.push_back(r_tracks[i]);
  }
  r_tracks = only_a;
  PairDiagnostics diag;
  const PairEstimate e = EstimatePair(sim.aligned, 0, 1, {}, &diag);
  EXPECT_FALSE(e.accepted);
  EXPECT_NE(e.reason.find("ambiguous"), std::string::npos) << e.reason;
  EXPECT_GT(diag.second_gain, 0.8 * diag.best_gain);
  // With s seeing only the same person, the pair is fine.
  auto& s_tracks = sim.aligned.sensors[1].tracks;
  std::vector<GridTrack> s_only_a;
  for (std::size_t i = 0; i < s_tracks.size(); ++i) {
    if (sim.person_of_track[1][i] == 0) s_only_a.push_back(s_tracks[i]);
  }
  s_tracks = s_only_a;
  ExpectClose(EstimatePair(sim.aligned, 0, 1, {}), TrueSFromR(sensors, 0, 1), 0.3, 0.05);
}

TEST(EstimatePair, StandingPersonIsDegenerate) {
  const auto sensors = FacingPair();
  SimOptions o;
  o.noise_m = 0.02;
  const Sim sim = Simulate(sensors, {Walker({{5, 5}}, 0.0)}, o);
  const PairEstimate e = EstimatePair(sim.aligned, 0, 1, {});
  EXPECT_FALSE(e.accepted);
  EXPECT_NE(e.reason.find("degenerate"), std::string::npos) << e.reason;
}

TEST(EstimatePair, NoSimultaneousTracks) {
  const auto sensors = FacingPair();
  Person early = Crowd(1)[0];
  early.end_s = 20.0;
  Sim sim = Simulate(sensors, {early}, {});
  // s only sees the person after r lost it.
  Sim later = Simulate(sensors, {Walker({{2, 2}, {8, 3}, {7, 8}}, 1.0)}, {});
  sim.aligned.sensors[1] = later.aligned.sensors[1];
  for (auto& t : sim.aligned.sensors[1].tracks) {
    t.first_step += 600;
    t.samples.resize(std::min<std::size_t>(t.samples.size(), 600));
  }
  const PairEstimate e = EstimatePair(sim.aligned, 0, 1, {});
  EXPECT_FALSE(e.accepted);
  EXPECT_EQ(e.intervals, 0u);
  EXPECT_NE(e.reason.find("no simultaneous"), std::string::npos) << e.reason;
}

class YawCase : public ::testing::TestWithParam<double> {};

TEST_P(YawCase, RotationsAroundHalfATurnWrapCorrectly) {
  // s at 10 m on r's x axis, turned by yaw_deg: 180 degrees and yaws just either side of +-pi.
  const double yaw_deg = GetParam();
  const std::vector<SimSensor> sensors = {{Pose2{0.0, 0.0, 0.0}, 25.0, 360.0, 0},
                                          {Pose2{10.0, 0.5, DegToRad(yaw_deg)}, 25.0, 360.0, 0}};
  SimOptions o;
  o.noise_m = 0.02;
  const Sim sim = Simulate(sensors, {Walker({{3, -3}, {7, -2}, {6, 3}, {4, 2}}, 1.1)}, o);
  const Pose2 truth = TrueSFromR(sensors, 0, 1);
  const PairEstimate e = EstimatePair(sim.aligned, 0, 1, {});
  ExpectClose(e, truth, 0.3, 0.05);
  EXPECT_LE(e.s_from_r.yaw_rad, common::kPi);
  EXPECT_GT(e.s_from_r.yaw_rad, -common::kPi);
  // And the other direction is the inverse.
  const PairEstimate back = EstimatePair(sim.aligned, 1, 0, {});
  ExpectClose(back, truth.inverse(), 0.3, 0.05);
}

INSTANTIATE_TEST_SUITE_P(NearPi, YawCase, ::testing::Values(180.0, 179.7, -179.7, 0.2));

TEST(EstimatePair, DeterministicForAFixedSeed) {
  auto sensors = FacingPair();
  sensors[0].split_every_steps = 80;
  SimOptions so;
  so.noise_m = 0.04;
  so.com_bias_m = 0.1;
  so.kind = MeasurementKind::kCenterOfMass;
  const Sim sim = Simulate(sensors, Crowd(3), so);
  PairwiseOptions o;
  o.seed = 1234;
  const PairEstimate a = EstimatePair(sim.aligned, 0, 1, o);
  const PairEstimate b = EstimatePair(sim.aligned, 0, 1, o);
  EXPECT_EQ(a.accepted, b.accepted);
  EXPECT_EQ(a.s_from_r.x_m, b.s_from_r.x_m);
  EXPECT_EQ(a.s_from_r.y_m, b.s_from_r.y_m);
  EXPECT_EQ(a.s_from_r.yaw_rad, b.s_from_r.yaw_rad);
  EXPECT_EQ(a.best_error, b.best_error);
  EXPECT_EQ(a.hypotheses, b.hypotheses);
  EXPECT_EQ(a.matches, b.matches);
  // Another seed samples differently but reaches the same answer.
  o.seed = 99;
  const PairEstimate c = EstimatePair(sim.aligned, 0, 1, o);
  ASSERT_TRUE(c.accepted) << c.reason;
  EXPECT_LT(YawErrorDeg(a.s_from_r, c.s_from_r), 0.05);
  EXPECT_LT(TranslationError(a.s_from_r, c.s_from_r), 0.01);
}

TEST(EstimatePair, BadSamplesAreSkippedAndCounted) {
  const auto sensors = FacingPair();
  SimOptions so;
  so.noise_m = 0.03;
  Sim sim = Simulate(sensors, Crowd(2), so);
  auto& samples = sim.aligned.sensors[1].tracks[0].samples;
  for (std::size_t i = 0; i < samples.size(); i += 7) {
    samples[i].position_m.x() = std::nan("");
  }
  sim.aligned.sensors[0].tracks[0].samples[3].position_cov_m2.setZero();
  sim.aligned.sensors[0].tracks[0].samples[5].position_cov_m2(0, 0) =
      std::numeric_limits<double>::infinity();
  PairDiagnostics diag;
  const PairEstimate e = EstimatePair(sim.aligned, 0, 1, {}, &diag);
  ExpectClose(e, TrueSFromR(sensors, 0, 1), 0.3, 0.05);
  EXPECT_GT(diag.unusable_samples, samples.size() / 7);
}

TEST(EstimateAllPairs, HostileTracksGiveReasonsNotCrashes) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double specials[] = {
      std::nan(""), std::numeric_limits<double>::infinity(), 1e300, -1e300, 0.0, -1.0, 1e-300};
  for (int round = 0; round < 20; ++round) {
    AlignedTracks a;
    a.steps = 400;
    a.sensors.resize(3);
    for (auto& sensor : a.sensors) {
      for (int t = 0; t < 6; ++t) {
        GridTrack track;
        track.first_step = static_cast<std::size_t>(200.0 * (u(rng) + 1.0));
        track.kind = static_cast<MeasurementKind>(t % 3);
        const std::size_t n = static_cast<std::size_t>(100.0 * (u(rng) + 1.0));
        for (std::size_t k = 0; k < n; ++k) {
          TrackSample x;
          x.position_m = Vector2d(5.0 * u(rng), 5.0 * u(rng));
          if (u(rng) > 0.9) x.position_m.x() = specials[k % 7];
          if (u(rng) > 0.9) x.position_cov_m2(0, 1) = specials[(k + 3) % 7];
          if (u(rng) > 0.95) x.position_cov_m2(1, 1) = specials[(k + 5) % 7];
          track.samples.push_back(x);
        }
        sensor.tracks.push_back(track);
      }
      std::sort(sensor.tracks.begin(), sensor.tracks.end(),
                [](const GridTrack& x, const GridTrack& y) { return x.first_step < y.first_step; });
    }
    a.sensors[2].tracks.front().first_step = std::numeric_limits<std::size_t>::max() - 3;
    for (const PairEstimate& e : EstimateAllPairs(a, {})) {
      if (e.accepted) {
        EXPECT_TRUE(std::isfinite(e.s_from_r.x_m) && std::isfinite(e.s_from_r.yaw_rad));
        EXPECT_TRUE(e.covariance.allFinite());
      } else {
        EXPECT_FALSE(e.reason.empty());
      }
    }
  }
}

TEST(EstimatePair, InvalidPairIsRejectedNotACrash) {
  const Sim sim = Simulate(FacingPair(), Crowd(1), {});
  EXPECT_FALSE(EstimatePair(sim.aligned, 0, 0, {}).accepted);
  EXPECT_FALSE(EstimatePair(sim.aligned, 0, 5, {}).accepted);
  EXPECT_TRUE(AssociatePair(sim.aligned, 3, 0, Pose2{}, 1.0).empty());
}

TEST(EstimateAllPairs, ListsOnlyPairsWithSimultaneousTracks) {
  // 0 and 1 share the left room, 1 and 2 the right one; 0 and 2 never see anyone at once.
  const std::vector<SimSensor> sensors = {{Pose2{0.0, 5.0, 0.0}, 9.0, 180.0, 0},
                                          {Pose2{10.0, 0.0, DegToRad(90.0)}, 12.0, 180.0, 0},
                                          {Pose2{20.0, 5.0, DegToRad(180.0)}, 9.0, 180.0, 0}};
  Person left = Walker({{2, 2}, {7, 3}, {6, 8}, {3, 7}}, 1.2);
  Person right = Walker({{18, 2}, {13, 3}, {14, 8}, {17, 7}}, 1.1);
  left.end_s = 30.0;
  right.start_s = 30.0;
  SimOptions o;
  o.noise_m = 0.02;
  const Sim sim = Simulate(sensors, {left, right}, o);
  const auto pairs = EstimateAllPairs(sim.aligned, {});
  ASSERT_EQ(pairs.size(), 2u);
  EXPECT_EQ(pairs[0].r, 0u);
  EXPECT_EQ(pairs[0].s, 1u);
  EXPECT_EQ(pairs[1].r, 1u);
  EXPECT_EQ(pairs[1].s, 2u);
  ExpectClose(pairs[0], TrueSFromR(sensors, 0, 1), 0.3, 0.05);
  ExpectClose(pairs[1], TrueSFromR(sensors, 1, 2), 0.3, 0.05);
}

// Keeps only the steps of a sensor's tracks for which keep(step) holds, splitting tracks there
// (pieces shorter than 10 steps dropped): a sensor that detects people only part of the time.
template <typename Keep>
void KeepOnly(SensorTracks& sensor, Keep keep) {
  std::vector<GridTrack> out;
  for (const GridTrack& t : sensor.tracks) {
    GridTrack piece;
    for (std::size_t k = t.first_step; k <= t.end_step(); ++k) {
      if (k < t.end_step() && keep(k)) {
        if (piece.samples.empty()) {
          piece = t;
          piece.samples.clear();
          piece.first_step = k;
        }
        piece.samples.push_back(t.At(k));
      } else if (!piece.samples.empty()) {
        if (piece.samples.size() >= 10) out.push_back(piece);
        piece.samples.clear();
      }
    }
  }
  std::stable_sort(out.begin(), out.end(), [](const GridTrack& a, const GridTrack& b) {
    return a.first_step < b.first_step;
  });
  sensor.tracks = out;
}

TEST(EstimateAllPairs, NegativeEvidenceIsJudgedAgainstTheDetectionEachSensorShows) {
  // c sees the people 12-16 m away and tracks them only 30 % of the time. Judged against the
  // default detection probability its pairs look inconsistent; b, which c shares the same area
  // with, shows what c detects there, and a's pair with c is then accepted.
  const std::vector<SimSensor> sensors = {{Pose2{0.0, 0.0, 0.0}, 25.0, 270.0, 0},
                                          {Pose2{0.0, 6.0, 0.0}, 25.0, 270.0, 0},
                                          {Pose2{22.0, 3.0, common::kPi}, 25.0, 270.0, 0}};
  SimOptions o;
  o.noise_m = 0.02;
  o.steps = 2400;
  Sim sim = Simulate(
      sensors,
      {Walker({{6, 1}, {10, 2}, {9, 5}, {6, 4}}, 1.1), Walker({{10, 5}, {7, 1}, {6, 5}}, 1.0, 3.0)},
      o);
  KeepOnly(sim.aligned.sensors[2], [](std::size_t k) { return (k / 20) % 10 < 3; });
  const PairEstimate alone = EstimatePair(sim.aligned, 0, 2, {});
  EXPECT_FALSE(alone.accepted);
  EXPECT_NE(alone.reason.find("inconsistent"), std::string::npos) << alone.reason;
  const std::vector<PairEstimate> all = EstimateAllPairs(sim.aligned, {});
  ASSERT_EQ(all.size(), 3u);
  for (const PairEstimate& e : all) {
    ExpectClose(e, TrueSFromR(sensors, e.r, e.s), 0.5, 0.05);
    if (e.s == 2) {
      EXPECT_LT(e.expected_match_fraction, 0.5);
      EXPECT_GT(e.match_fraction, 0.5 * e.expected_match_fraction);
    }
  }
}

TEST(AssociatePair, PairsTheSamePersonOneToOne) {
  const auto sensors = FacingPair();
  SimOptions so;
  so.noise_m = 0.03;
  const Sim sim = Simulate(sensors, Crowd(4), so);
  const auto matches = AssociatePair(sim.aligned, 0, 1, TrueSFromR(sensors, 0, 1), 0.5);
  ASSERT_GT(matches.size(), 3000u);
  std::size_t same_person = 0;
  for (std::size_t i = 0; i < matches.size(); ++i) {
    const Match& m = matches[i];
    same_person += sim.person_of_track[0][m.track_r] == sim.person_of_track[1][m.track_s];
    if (i > 0 && matches[i - 1].step == m.step) {  // one-to-one within a step
      EXPECT_NE(matches[i - 1].track_r, m.track_r);
      EXPECT_NE(matches[i - 1].track_s, m.track_s);
    }
    if (i > 0) {
      EXPECT_LE(matches[i - 1].step, m.step);
    }
  }
  EXPECT_GT(static_cast<double>(same_person), 0.99 * static_cast<double>(matches.size()));
}

TEST(FitMatches, RecoversThePoseFromTrueMatches) {
  const auto sensors = FacingPair();
  const Sim sim = Simulate(sensors, Crowd(2), {});
  const Pose2 truth = TrueSFromR(sensors, 0, 1);
  const auto matches = AssociatePair(sim.aligned, 0, 1, truth, 0.5);
  const RigidFit fit = FitMatches(sim.aligned, 0, 1, matches, {});
  ASSERT_TRUE(fit.ok);
  EXPECT_LT(YawErrorDeg(fit.s_from_r, truth), 1e-6);
  EXPECT_LT(TranslationError(fit.s_from_r, truth), 1e-6);
  EXPECT_FALSE(FitMatches(sim.aligned, 0, 1, {}, {}).ok);
}

}  // namespace
}  // namespace lrfnet::calib
