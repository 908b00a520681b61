#include "central_daemon/calibration/refine.h"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <functional>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace lrfnet::calib {
namespace {

using common::DegToRad;
using common::RadToDeg;

using Path = std::function<Eigen::Vector2d(double)>;  // world position at time t (s)

struct SynthOptions {
  std::size_t steps = 1200;  // one minute at 20 Hz
  double step_s = 0.05;
  double range_m = 30.0;
  double noise_m = 0.02;           // white position noise per sample
  double reported_sigma_m = 0.02;  // the sample covariance is reported_sigma^2 I
  double com_bias_m = 0.0;         // observed centre shifted this far toward the sensor
  // What the measurement model says the shift is (default: what it is), its sensitivity to a
  // correction of the prior's minor semi-axis and the prior's sigma (types.h TrackSample).
  std::optional<double> model_bias_m;
  double model_per_minor = 0.0;
  double size_prior_sigma_m = 0.05;
  double shared_bias_sigma_m = 0.0;  // TrackSample::shared_bias_sigma_m of every sample
  MeasurementKind kind = MeasurementKind::kEllipse;
  unsigned seed = 1;
};

// Every sensor tracks every object while it is within range; one GridTrack per visible run.
AlignedTracks MakeTracks(const std::vector<Pose2>& world_from_sensor,
                         const std::vector<Path>& paths, const SynthOptions& o) {
  std::mt19937 rng(o.seed);
  std::normal_distribution<double> noise(0.0, 1.0);
  AlignedTracks tracks;
  tracks.step_s = o.step_s;
  tracks.steps = o.steps;
  tracks.size_prior_sigma_m = o.size_prior_sigma_m;
  for (std::size_t s = 0; s < world_from_sensor.size(); ++s) {
    SensorTracks sensor;
    sensor.id = "s" + std::to_string(s);
    const Pose2 sensor_from_world = world_from_sensor[s].inverse();
    std::uint32_t next_id = 1;
    for (const Path& path : paths) {
      GridTrack* open = nullptr;
      for (std::size_t k = 0; k < o.steps; ++k) {
        const Eigen::Vector2d p = path(tracks.TimeOf(k));
        const Eigen::Vector2d to_object = p - world_from_sensor[s].translation();
        if (to_object.norm() > o.range_m) {
          open = nullptr;
          continue;
        }
        if (open == nullptr) {
          sensor.tracks.emplace_back();
          open = &sensor.tracks.back();
          open->track_id = next_id++;
          open->kind = o.kind;
          open->first_step = k;
        }
        const Eigen::Vector2d seen = p - o.com_bias_m * to_object.normalized();
        TrackSample sample;
        sample.position_m =
            sensor_from_world * seen + o.noise_m * Eigen::Vector2d(noise(rng), noise(rng));
        sample.position_cov_m2 =
            o.reported_sigma_m * o.reported_sigma_m * Eigen::Matrix2d::Identity();
        sample.kind = o.kind;
        sample.bias_m = static_cast<float>(o.model_bias_m.value_or(o.com_bias_m));
        sample.bias_per_minor = static_cast<float>(o.model_per_minor);
        sample.shared_bias_sigma_m = static_cast<float>(o.shared_bias_sigma_m);
        open->samples.push_back(sample);
      }
    }
    tracks.sensors.push_back(std::move(sensor));
  }
  return tracks;
}

// Smooth closed curves inside a 10 m x 10 m room (periods of tens of seconds).
std::vector<Path> RoomPaths() {
  return {
      [](double t) {
        return Eigen::Vector2d(5.0 + 3.5 * std::cos(0.21 * t), 5.0 + 3.0 * std::sin(0.33 * t));
      },
      [](double t) {
        return Eigen::Vector2d(5.0 + 2.5 * std::sin(0.17 * t + 1.0),
                               5.0 + 3.5 * std::cos(0.27 * t));
      },
      [](double t) {
        return Eigen::Vector2d(5.0 + 4.0 * std::cos(0.13 * t + 2.0),
                               5.0 + 2.0 * std::sin(0.41 * t + 0.5));
      },
  };
}

// Four sensors in the corners of the room, looking inward.
std::vector<Pose2> RoomSensors() {
  return {{0.2, 0.3, DegToRad(45.0)},
          {9.8, 0.1, DegToRad(135.0)},
          {9.9, 9.7, DegToRad(-135.0)},
          {0.1, 9.9, DegToRad(-45.0)}};
}

std::vector<Pose2> Perturb(std::vector<Pose2> poses, std::size_t reference, double offset_m,
                           double yaw_rad) {
  for (std::size_t s = 0; s < poses.size(); ++s) {
    if (s == reference) continue;
    const double a = 1.3 * static_cast<double>(s) + 0.4;  // a different direction per sensor
    poses[s].x_m += offset_m * std::cos(a);
    poses[s].y_m += offset_m * std::sin(a);
    poses[s].yaw_rad += (s % 2 == 0 ? 1.0 : -1.0) * yaw_rad;
  }
  return poses;
}

double MaxTranslationError(const std::vector<Pose2>& a, const std::vector<Pose2>& b) {
  double e = 0.0;
  for (std::size_t s = 0; s < a.size(); ++s)
    e = std::max(e, common::TranslationDistanceM(a[s], b[s]));
  return e;
}
double MaxRotationError(const std::vector<Pose2>& a, const std::vector<Pose2>& b) {
  double e = 0.0;
  for (std::size_t s = 0; s < a.size(); ++s)
    e = std::max(e, common::RotationDistanceRad(a[s], b[s]));
  return e;
}

// The synthetic tracks' only error is their reported white noise.
JointRefineOptions EllipseOptions() {
  JointRefineOptions o;
  o.model_sigma_per_m = 0.0;
  return o;
}

TEST(JointRefineOptionsTest, DefaultsAreValidAndBadValuesAreNamed) {
  EXPECT_FALSE(Validate(JointRefineOptions{}).has_value());
  JointRefineOptions o;
  o.association_gate_m = 0.0;
  ASSERT_TRUE(Validate(o).has_value());
  EXPECT_NE(Validate(o)->find("association_gate_m"), std::string::npos);
  o = {};
  o.initial_association_gate_m = 0.4;  // below the final gate
  EXPECT_TRUE(Validate(o).has_value());
  o = {};
  o.segment_sigma_per_m = -0.1;
  EXPECT_TRUE(Validate(o).has_value());
  o = {};
  o.max_size_scale_correlation = 0.0;
  EXPECT_TRUE(Validate(o).has_value());
  o = {};
  o.sensor_bias_max_data_sigma = -0.5;
  ASSERT_TRUE(Validate(o).has_value());
  EXPECT_NE(Validate(o)->find("sensor_bias_max_data_sigma"), std::string::npos);
  o = {};
  o.loss_scale = std::nan("");
  EXPECT_TRUE(Validate(o).has_value());
  o = {};
  o.step_stride = 0;
  EXPECT_TRUE(Validate(o).has_value());
  o = {};
  o.association_rounds = 0;
  EXPECT_TRUE(Validate(o).has_value());
  o = {};
  o.threads = 0;
  EXPECT_TRUE(Validate(o).has_value());
}

TEST(RefineJointlyTest, PerturbedPosesConvergeBackToTruth) {
  const std::vector<Pose2> truth = RoomSensors();
  const AlignedTracks tracks = MakeTracks(truth, RoomPaths(), {});
  const std::vector<Pose2> initial = Perturb(truth, 0, 0.05, DegToRad(1.0));
  const JointRefineResult r =
      RefineJointly(tracks, initial, std::vector<bool>(4, true), 0, EllipseOptions());
  ASSERT_TRUE(r.ok) << r.message;
  // 2 cm white noise over ~900 objects: the poses are determined to a few millimetres.
  EXPECT_LT(MaxTranslationError(r.world_from_sensor, truth), 0.005);
  EXPECT_LT(RadToDeg(MaxRotationError(r.world_from_sensor, truth)), 0.05);
  EXPECT_LT(r.cost_after, r.cost_before);
  EXPECT_LT(r.rms_after_m, 0.5 * r.rms_before_m);
  EXPECT_NEAR(r.rms_after_m, 0.02, 0.005);  // the noise level (objects absorb part of it)
  EXPECT_GT(r.observations, 2000u);
  EXPECT_GT(r.objects, 600u);
  EXPECT_EQ(r.steps, 300u);  // every 4th of 1200 steps, all with objects
  EXPECT_EQ(r.stride, 4u);
  for (std::size_t s = 0; s < 4; ++s) {
    EXPECT_TRUE(r.refined[s]);
    EXPECT_GT(r.sensor_observations[s], 500u);
  }
}

TEST(RefineJointlyTest, NoiseFreeInputConvergesExactly) {
  const std::vector<Pose2> truth = RoomSensors();
  SynthOptions synth;
  synth.noise_m = 0.0;
  const AlignedTracks tracks = MakeTracks(truth, RoomPaths(), synth);
  const std::vector<Pose2> initial = Perturb(truth, 0, 0.05, DegToRad(1.0));
  const JointRefineResult r =
      RefineJointly(tracks, initial, std::vector<bool>(4, true), 0, EllipseOptions());
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_LT(MaxTranslationError(r.world_from_sensor, truth), 1e-6);
  EXPECT_LT(MaxRotationError(r.world_from_sensor, truth), 1e-6);
  EXPECT_LT(r.rms_after_m, 1e-6);
}

TEST(RefineJointlyTest, ReferenceStaysFixedAndOthersFollowIt) {
  const std::vector<Pose2> truth = RoomSensors();
  SynthOptions synth;
  synth.noise_m = 0.0;
  const AlignedTracks tracks = MakeTracks(truth, RoomPaths(), synth);
  // The initial poses live in another world frame (the reference sensor's pose differs from the
  // truth): the others must be placed relative to the reference, not to the truth.
  const Pose2 other_world_from_world{3.0, -2.0, DegToRad(20.0)};
  std::vector<Pose2> initial;
  for (const Pose2& p : truth) initial.push_back(other_world_from_world * p);
  initial = Perturb(initial, 2, 0.05, DegToRad(1.0));
  const JointRefineResult r =
      RefineJointly(tracks, initial, std::vector<bool>(4, true), 2, EllipseOptions());
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_EQ(r.world_from_sensor[2].x_m, initial[2].x_m);
  EXPECT_EQ(r.world_from_sensor[2].y_m, initial[2].y_m);
  EXPECT_EQ(r.world_from_sensor[2].yaw_rad, initial[2].yaw_rad);
  EXPECT_TRUE(r.covariance[2].isZero());
  for (std::size_t s = 0; s < 4; ++s) {
    const Pose2 got = r.world_from_sensor[2].inverse() * r.world_from_sensor[s];
    const Pose2 want = truth[2].inverse() * truth[s];
    EXPECT_LT(common::TranslationDistanceM(got, want), 1e-6) << s;
    EXPECT_LT(common::RotationDistanceRad(got, want), 1e-6) << s;
  }
}

TEST(RefineJointlyTest, UncalibratedSensorIsUntouchedAndIgnored) {
  const std::vector<Pose2> truth = RoomSensors();
  SynthOptions synth;
  synth.noise_m = 0.0;
  const AlignedTracks tracks = MakeTracks(truth, RoomPaths(), synth);
  std::vector<Pose2> initial = Perturb(truth, 0, 0.05, DegToRad(1.0));
  // A wrong pose 0.3 m off: were its tracks used, they would pull the others away from the truth.
  initial[3] = {truth[3].x_m + 0.3, truth[3].y_m, truth[3].yaw_rad};
  const JointRefineResult r =
      RefineJointly(tracks, initial, {true, true, true, false}, 0, EllipseOptions());
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_EQ(r.world_from_sensor[3].x_m, initial[3].x_m);
  EXPECT_EQ(r.world_from_sensor[3].y_m, initial[3].y_m);
  EXPECT_EQ(r.world_from_sensor[3].yaw_rad, initial[3].yaw_rad);
  EXPECT_FALSE(r.refined[3]);
  EXPECT_EQ(r.sensor_observations[3], 0u);
  EXPECT_TRUE(r.covariance[3].isZero());
  for (std::size_t s = 0; s < 3; ++s) {
    EXPECT_LT(common::TranslationDistanceM(r.world_from_sensor[s], truth[s]), 1e-6) << s;
  }
}

TEST(RefineJointlyTest, WrongTrackIsDownWeightedByTheRobustLoss) {
  const std::vector<Pose2> truth = RoomSensors();
  AlignedTracks tracks = MakeTracks(truth, RoomPaths(), {});
  // Sensor 1 follows the wrong thing for 20 s of one of its tracks: 0.35 m beside the person
  // (inside the association gate, so it is associated and must be down-weighted).
  GridTrack& wrong = tracks.sensors[1].tracks.front();
  ASSERT_GE(wrong.samples.size(), 600u);
  for (std::size_t k = 100; k < 500; ++k) wrong.samples[k].position_m += Eigen::Vector2d(0.0, 0.35);
  const std::vector<Pose2> initial = Perturb(truth, 0, 0.05, DegToRad(1.0));

  const JointRefineResult robust =
      RefineJointly(tracks, initial, std::vector<bool>(4, true), 0, EllipseOptions());
  ASSERT_TRUE(robust.ok) << robust.message;
  JointRefineOptions plain_options = EllipseOptions();
  plain_options.loss = RobustLoss::kNone;
  const JointRefineResult plain =
      RefineJointly(tracks, initial, std::vector<bool>(4, true), 0, plain_options);
  ASSERT_TRUE(plain.ok) << plain.message;

  const double robust_error = common::TranslationDistanceM(robust.world_from_sensor[1], truth[1]);
  const double plain_error = common::TranslationDistanceM(plain.world_from_sensor[1], truth[1]);
  EXPECT_LT(robust_error, 0.005);
  EXPECT_GT(plain_error, 3.0 * robust_error);
  EXPECT_GE(robust.downweighted, 80u);  // ~100 used steps of the wrong track
  EXPECT_EQ(plain.downweighted, 0u);
}

TEST(RefineJointlyTest, TooFewObservationsFailWithAClearMessage) {
  const std::vector<Pose2> truth = RoomSensors();
  SynthOptions synth;
  synth.steps = 10;  // half a second: 3 used steps
  const AlignedTracks tracks = MakeTracks(truth, RoomPaths(), synth);
  const std::vector<Pose2> initial = Perturb(truth, 0, 0.05, DegToRad(1.0));
  const JointRefineResult r =
      RefineJointly(tracks, initial, std::vector<bool>(4, true), 0, EllipseOptions());
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.message.find("too few associated observations"), std::string::npos) << r.message;
  EXPECT_NE(r.message.find("need 20"), std::string::npos) << r.message;
  for (std::size_t s = 0; s < 4; ++s) {
    EXPECT_EQ(r.world_from_sensor[s].x_m, initial[s].x_m);
    EXPECT_EQ(r.world_from_sensor[s].yaw_rad, initial[s].yaw_rad);
  }
}

TEST(RefineJointlyTest, BadInputGivesAReasonNotACrash) {
  const std::vector<Pose2> truth = RoomSensors();
  SynthOptions synth;
  synth.steps = 200;
  AlignedTracks tracks = MakeTracks(truth, RoomPaths(), synth);
  const std::vector<bool> all(4, true);
  EXPECT_NE(RefineJointly(tracks, {truth[0]}, all, 0, {}).message.find("size mismatch"),
            std::string::npos);
  EXPECT_NE(RefineJointly(tracks, truth, all, 7, {}).message.find("out of range"),
            std::string::npos);
  EXPECT_NE(
      RefineJointly(tracks, truth, {false, true, true, true}, 0, {}).message.find("not calibrated"),
      std::string::npos);
  JointRefineOptions bad;
  bad.step_stride = 0;
  EXPECT_NE(RefineJointly(tracks, truth, all, 0, bad).message.find("invalid options"),
            std::string::npos);
  std::vector<Pose2> nan_pose = truth;
  nan_pose[1].yaw_rad = std::nan("");
  EXPECT_NE(RefineJointly(tracks, nan_pose, all, 0, {}).message.find("not finite"),
            std::string::npos);

  // Broken samples are counted and skipped; a track claiming steps beyond the grid is clipped.
  tracks.sensors[1].tracks[0].samples[0].position_m.x() = std::nan("");
  tracks.sensors[1].tracks[0].samples[4].position_cov_m2 << 1.0, 0.0, 0.0, -1.0;
  tracks.sensors[2].tracks[0].samples.resize(tracks.sensors[2].tracks[0].samples.size() + 500);
  GridTrack beyond;
  beyond.first_step = 100000;
  beyond.samples.resize(3);
  tracks.sensors[3].tracks.push_back(beyond);
  const JointRefineResult r = RefineJointly(tracks, truth, all, 0, EllipseOptions());
  EXPECT_TRUE(r.ok) << r.message;
  EXPECT_EQ(r.rejected_samples, 2u);
}

TEST(RefineJointlyTest, ChainWhereOnlyNeighboursOverlap) {
  // Five sensors along a 32 m corridor, 8 m range, 7 m apart: each sees only its neighbours' ends.
  std::vector<Pose2> truth;
  for (int i = 0; i < 5; ++i) {
    truth.push_back(
        {1.0 + 7.0 * i, (i % 2 == 0) ? 0.2 : 2.8, DegToRad(i % 2 == 0 ? 10.0 : -170.0)});
  }
  std::vector<Path> paths = {
      [](double t) {
        return Eigen::Vector2d(15.0 - 14.0 * std::cos(0.1 * t), 1.2 + 0.3 * std::sin(t));
      },
      [](double t) { return Eigen::Vector2d(15.0 + 14.0 * std::cos(0.08 * t + 0.5), 1.8); },
  };
  SynthOptions synth;
  synth.range_m = 8.0;
  synth.steps = 2400;  // two minutes: each walker passes every overlap a few times
  const AlignedTracks tracks = MakeTracks(truth, paths, synth);
  // Sensors 0 and 2 are 14 m apart: no common view.
  const std::vector<Pose2> initial = Perturb(truth, 0, 0.05, DegToRad(1.0));
  const JointRefineResult r =
      RefineJointly(tracks, initial, std::vector<bool>(5, true), 0, EllipseOptions());
  ASSERT_TRUE(r.ok) << r.message;
  for (std::size_t s = 1; s < 5; ++s) {
    EXPECT_TRUE(r.refined[s]);
    EXPECT_LT(common::TranslationDistanceM(r.world_from_sensor[s], truth[s]), 0.02) << s;
    EXPECT_LT(RadToDeg(common::RotationDistanceRad(r.world_from_sensor[s], truth[s])), 0.1) << s;
  }
  // The uncertainty grows along the chain.
  EXPECT_LT(r.covariance[1](2, 2), r.covariance[4](2, 2));
  EXPECT_LT(r.covariance[1](0, 0) + r.covariance[1](1, 1),
            r.covariance[4](0, 0) + r.covariance[4](1, 1));
}

TEST(RefineJointlyTest, SensorWithoutSharedViewIsHeldAndNamed) {
  std::vector<Pose2> truth = RoomSensors();
  truth.push_back({50.0, 50.0, 0.0});  // far away: sees nothing the others see
  SynthOptions synth;
  synth.range_m = 15.0;
  const AlignedTracks tracks = MakeTracks(truth, RoomPaths(), synth);
  const std::vector<Pose2> initial = Perturb(truth, 0, 0.05, DegToRad(1.0));
  const JointRefineResult r =
      RefineJointly(tracks, initial, std::vector<bool>(5, true), 0, EllipseOptions());
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_FALSE(r.refined[4]);
  EXPECT_EQ(r.world_from_sensor[4].x_m, initial[4].x_m);
  EXPECT_NE(r.message.find("held at the initial pose"), std::string::npos) << r.message;
  EXPECT_NE(r.message.find("s4"), std::string::npos) << r.message;
  EXPECT_LT(common::TranslationDistanceM(r.world_from_sensor[1], truth[1]), 0.005);
}

TEST(RefineJointlyTest, ReassociationRecoversObservationsOutsideTheFirstGate) {
  const std::vector<Pose2> truth = RoomSensors();
  const AlignedTracks tracks = MakeTracks(truth, RoomPaths(), {});
  // 3 degrees: far objects are displaced by ~0.5 m and miss the gate in the first round.
  std::vector<Pose2> initial = truth;
  initial[1].yaw_rad += DegToRad(3.0);
  JointRefineOptions one = EllipseOptions();
  one.association_rounds = 1;
  one.initial_association_gate_m = one.association_gate_m;
  one.estimate_size_correction = false;
  const JointRefineResult once = RefineJointly(tracks, initial, std::vector<bool>(4, true), 0, one);
  const JointRefineResult again =
      RefineJointly(tracks, initial, std::vector<bool>(4, true), 0, EllipseOptions());
  ASSERT_TRUE(once.ok) << once.message;
  ASSERT_TRUE(again.ok) << again.message;
  EXPECT_EQ(once.rounds, 1);
  EXPECT_GE(again.rounds, 2);
  EXPECT_GT(again.sensor_observations[1], once.sensor_observations[1] + 50);
  EXPECT_LT(common::TranslationDistanceM(again.world_from_sensor[1], truth[1]), 0.005);
  EXPECT_LT(RadToDeg(common::RotationDistanceRad(again.world_from_sensor[1], truth[1])), 0.05);
}

RelativePoseConstraint TrueConstraint(const std::vector<Pose2>& truth, std::size_t r, std::size_t s,
                                      double sigma_m, double sigma_rad);

TEST(RefineJointlyTest, SizeErrorIsEstimatedWhereTheDataObserveIt) {
  // A cylinder larger than the model's prior body: every centre of mass lies 0.04 m nearer its
  // sensor than the model says. Four sensors in the corners see it from every side, and the
  // background (a wall both 0 and 1 see) fixes the layout's scale: the size correction is
  // observable apart from the scale, estimated, and the poses are right.
  const std::vector<Pose2> truth = RoomSensors();
  SynthOptions synth;
  synth.kind = MeasurementKind::kCenterOfMass;
  synth.com_bias_m = 0.16;
  synth.model_bias_m = 0.12;
  synth.model_per_minor = common::kPi / 4.0;
  synth.noise_m = 0.03;
  synth.reported_sigma_m = 0.03;
  const AlignedTracks tracks = MakeTracks(truth, RoomPaths(), synth);
  const std::vector<Pose2> initial = Perturb(truth, 0, 0.10, DegToRad(1.5));
  const std::vector<bool> all(4, true);
  const std::vector<RelativePoseConstraint> wall = {
      TrueConstraint(truth, 0, 1, 0.003, DegToRad(0.03))};
  const JointRefineResult r = RefineJointly(tracks, initial, all, 0, {}, wall);
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_TRUE(r.size_correction_estimated[1]) << r.message;
  EXPECT_LT(r.size_scale_correlation[1], 0.9);
  EXPECT_NEAR(r.size_correction_m.y(), 0.04 / (common::kPi / 4.0), 0.01);
  for (std::size_t s = 1; s < 4; ++s) {
    EXPECT_LT(common::TranslationDistanceM(r.world_from_sensor[s], truth[s]), 0.01) << s;
    EXPECT_LT(RadToDeg(common::RotationDistanceRad(r.world_from_sensor[s], truth[s])), 0.05) << s;
  }
  // Held at the prior, the error goes into the sensors' positions, but no farther than the
  // covariance, which carries the prior's uncertainty, says.
  JointRefineOptions held;
  held.estimate_size_correction = false;
  const JointRefineResult h = RefineJointly(tracks, initial, all, 0, held, wall);
  ASSERT_TRUE(h.ok) << h.message;
  EXPECT_GT(MaxTranslationError(h.world_from_sensor, truth), 0.02);
  for (std::size_t s = 1; s < 4; ++s) {
    const double sigma = std::sqrt(h.covariance[s](0, 0) + h.covariance[s](1, 1));
    EXPECT_LT(common::TranslationDistanceM(h.world_from_sensor[s], truth[s]), 2.0 * sigma) << s;
  }
}

TEST(RefineJointlyTest, SizeErrorThatLooksLikeTheScaleIsNotEstimatedAndItsPriorCoversTheError) {
  // Two sensors 18 m apart facing each other, the cylinder walking near the line between them:
  // both see it from opposite sides, so a larger body and sensors nearer each other explain the
  // data alike. The correction is held at the prior (not observable apart from the scale) and
  // the reported covariance covers the error it leaves.
  const std::vector<Pose2> truth = {{0.0, 0.0, 0.0}, {18.0, 0.5, common::kPi}};
  const std::vector<Path> paths = {[](double t) {
    return Eigen::Vector2d(9.0 + 6.0 * std::sin(0.2 * t), 0.3 * std::sin(0.7 * t));
  }};
  SynthOptions synth;
  synth.kind = MeasurementKind::kCenterOfMass;
  synth.com_bias_m = 0.20;
  synth.model_bias_m = 0.15;
  synth.model_per_minor = common::kPi / 4.0;
  const AlignedTracks tracks = MakeTracks(truth, paths, synth);
  const JointRefineResult r =
      RefineJointly(tracks, Perturb(truth, 0, 0.05, DegToRad(0.5)), {true, true}, 0, {});
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_FALSE(r.size_correction_estimated[0]);
  EXPECT_FALSE(r.size_correction_estimated[1]);
  EXPECT_GT(r.size_scale_correlation[1], 0.9);
  EXPECT_EQ(r.size_correction_m.y(), 0.0);
  EXPECT_NE(r.message.find("not observable apart from the scale"), std::string::npos) << r.message;
  // The sensors sit 2 x 0.05 m nearer each other than they are...
  const double error = common::TranslationDistanceM(r.world_from_sensor[1], truth[1]);
  EXPECT_GT(error, 0.06);
  // ...which the prior's uncertainty (0.05 m of the minor semi-axis, pi/4 of it per sensor) in
  // the covariance covers.
  const double sigma = std::sqrt(r.covariance[1](0, 0) + r.covariance[1](1, 1));
  EXPECT_LT(error, 2.0 * sigma);
  EXPECT_LT(sigma, 0.3);
}

TEST(RefineJointlyTest, AnnealedGateRecoversDegreesAtALongLeverArm) {
  // A sensor 25 m from the reference, its initial yaw 3 degrees off: its observations of the
  // people near the reference are displaced by more than a metre, beyond the final gate.
  const std::vector<Pose2> truth = {{0.0, 0.0, 0.0}, {25.0, 0.0, common::kPi}};
  const std::vector<Path> paths = {
      [](double t) {
        return Eigen::Vector2d(4.0 + 3.0 * std::cos(0.3 * t), 2.0 * std::sin(0.45 * t));
      },
      [](double t) {
        return Eigen::Vector2d(5.0 + 2.0 * std::sin(0.25 * t), 3.0 * std::cos(0.35 * t));
      }};
  const AlignedTracks tracks = MakeTracks(truth, paths, {});
  std::vector<Pose2> initial = truth;
  initial[1].yaw_rad += DegToRad(3.0);
  const JointRefineResult r = RefineJointly(tracks, initial, {true, true}, 0, EllipseOptions());
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_LT(RadToDeg(common::RotationDistanceRad(r.world_from_sensor[1], truth[1])), 0.05);
  EXPECT_LT(common::TranslationDistanceM(r.world_from_sensor[1], truth[1]), 0.02);
  // With the final gate from the start, the far objects never associate.
  JointRefineOptions fixed_gate = EllipseOptions();
  fixed_gate.initial_association_gate_m = fixed_gate.association_gate_m;
  const JointRefineResult f = RefineJointly(tracks, initial, {true, true}, 0, fixed_gate);
  EXPECT_TRUE(!f.ok ||
              RadToDeg(common::RotationDistanceRad(f.world_from_sensor[1], truth[1])) > 0.5);
}

RelativePoseConstraint TrueConstraint(const std::vector<Pose2>& truth, std::size_t r, std::size_t s,
                                      double sigma_m, double sigma_rad) {
  RelativePoseConstraint c;
  c.r = r;
  c.s = s;
  c.s_from_r = truth[s].inverse() * truth[r];
  c.covariance =
      Eigen::Vector3d(sigma_m * sigma_m, sigma_m * sigma_m, sigma_rad * sigma_rad).asDiagonal();
  return c;
}

TEST(RefineJointlyTest, RelativePoseConstraintsFixWhatTheTracksModelLeavesOpen) {
  // The tracks' model misses a size error, and the corner views cannot tell it from the layout's
  // scale: alone, the tracks pull the sensors inward. Walls (background ICP) fixing 0-1 and 1-2 to
  // a few millimetres fix the scale, and with it the size and sensor 3, which has only tracks.
  const std::vector<Pose2> truth = RoomSensors();
  SynthOptions synth;
  synth.kind = MeasurementKind::kCenterOfMass;
  synth.com_bias_m = 0.16;
  synth.model_bias_m = 0.10;
  synth.model_per_minor = common::kPi / 4.0;
  const AlignedTracks tracks = MakeTracks(truth, RoomPaths(), synth);
  const std::vector<Pose2> initial = Perturb(truth, 0, 0.05, DegToRad(1.0));
  const std::vector<bool> all(4, true);
  const JointRefineResult tracks_only = RefineJointly(tracks, initial, all, 0, {});
  ASSERT_TRUE(tracks_only.ok) << tracks_only.message;
  EXPECT_GT(common::TranslationDistanceM(tracks_only.world_from_sensor[2], truth[2]), 0.03);

  const std::vector<RelativePoseConstraint> constraints = {
      TrueConstraint(truth, 0, 1, 0.002, DegToRad(0.02)),
      TrueConstraint(truth, 1, 2, 0.002, DegToRad(0.02))};
  const JointRefineResult r = RefineJointly(tracks, initial, all, 0, {}, constraints);
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_EQ(r.constraints_used, 2u);
  EXPECT_EQ(r.constraints_rejected, 0u);
  for (std::size_t s = 1; s < 4; ++s) {
    EXPECT_LT(common::TranslationDistanceM(r.world_from_sensor[s], truth[s]), 0.01) << s;
    EXPECT_LT(RadToDeg(common::RotationDistanceRad(r.world_from_sensor[s], truth[s])), 0.05) << s;
  }
  EXPECT_LT(r.constraint_rms_sigma, 3.0);
  EXPECT_NE(r.message.find("2 relative-pose constraints"), std::string::npos) << r.message;
}

TEST(RefineJointlyTest, AWrongConstraintLosesAgainstTheTracks) {
  // An ICP that slid half a metre along a wall, claiming 2 mm: robust like the observations, it
  // cannot drag the sensor away from what thousands of consistent observations say.
  const std::vector<Pose2> truth = RoomSensors();
  const AlignedTracks tracks = MakeTracks(truth, RoomPaths(), {});
  RelativePoseConstraint slid = TrueConstraint(truth, 0, 1, 0.002, DegToRad(0.02));
  slid.s_from_r.x_m += 0.5;
  const JointRefineResult r = RefineJointly(tracks, Perturb(truth, 0, 0.05, DegToRad(1.0)),
                                            std::vector<bool>(4, true), 0, {}, {slid});
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_LT(MaxTranslationError(r.world_from_sensor, truth), 0.02);
  EXPECT_GT(r.constraint_rms_sigma, 100.0);
}

TEST(RefineJointlyTest, ConstraintLinksASensorWithoutSharedTracks) {
  std::vector<Pose2> truth = RoomSensors();
  truth.push_back({50.0, 50.0, DegToRad(30.0)});  // sees nothing the others see
  SynthOptions synth;
  synth.range_m = 15.0;
  const AlignedTracks tracks = MakeTracks(truth, RoomPaths(), synth);
  const std::vector<Pose2> initial = Perturb(truth, 0, 0.05, DegToRad(1.0));
  const JointRefineResult r =
      RefineJointly(tracks, initial, std::vector<bool>(5, true), 0, EllipseOptions(),
                    {TrueConstraint(truth, 2, 4, 0.002, DegToRad(0.02))});
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_TRUE(r.refined[4]);
  EXPECT_EQ(r.sensor_observations[4], 0u);
  // Placed through sensor 2, itself placed by the tracks to a few millimetres.
  EXPECT_LT(common::TranslationDistanceM(r.world_from_sensor[4], truth[4]), 0.05);
  EXPECT_LT(RadToDeg(common::RotationDistanceRad(r.world_from_sensor[4], truth[4])), 0.1);
  EXPECT_GT(r.covariance[4](0, 0), r.covariance[2](0, 0));
}

TEST(RefineJointlyTest, UnusableConstraintsAreCountedAndIgnored) {
  const std::vector<Pose2> truth = RoomSensors();
  const AlignedTracks tracks = MakeTracks(truth, RoomPaths(), {});
  const std::vector<Pose2> initial = Perturb(truth, 0, 0.05, DegToRad(1.0));
  std::vector<RelativePoseConstraint> bad(6, TrueConstraint(truth, 0, 1, 0.001, 0.001));
  bad[0].s = 9;                            // out of range
  bad[1].s = 0;                            // r == s
  bad[2].s = 3;                            // sensor 3 is not calibrated
  bad[3].covariance(0, 0) = -1.0;          // not positive definite
  bad[4].covariance(0, 1) = 0.5;           // not symmetric
  bad[5].s_from_r.yaw_rad = std::nan("");  // not finite
  const JointRefineResult r =
      RefineJointly(tracks, initial, {true, true, true, false}, 0, EllipseOptions(), bad);
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_EQ(r.constraints_rejected, 6u);
  EXPECT_EQ(r.constraints_used, 0u);
  EXPECT_LT(common::TranslationDistanceM(r.world_from_sensor[1], truth[1]), 0.005);
}

TEST(RefineJointlyTest, CovarianceMatchesTheSpreadOverNoiseDraws) {
  const std::vector<Pose2> truth = RoomSensors();
  JointRefineOptions options = EllipseOptions();
  options.loss = RobustLoss::kNone;
  options.step_stride = 8;
  options.observation_correlation_steps = 1.0;  // white noise: every sample is independent
  options.segment_sigma_m = 0.0;                // and no track has an offset of its own
  options.segment_sigma_per_m = 0.0;
  double nees_sum = 0.0;
  constexpr int kRuns = 20;
  for (int run = 0; run < kRuns; ++run) {
    SynthOptions synth;
    synth.seed = static_cast<unsigned>(100 + run);
    synth.noise_m = 0.05;
    synth.reported_sigma_m = 0.05;
    const AlignedTracks tracks = MakeTracks(truth, RoomPaths(), synth);
    const JointRefineResult r =
        RefineJointly(tracks, truth, std::vector<bool>(4, true), 0, options);
    ASSERT_TRUE(r.ok) << r.message;
    EXPECT_NEAR(r.variance_factor, 1.0, 0.15);
    for (std::size_t s = 1; s < 4; ++s) {
      const Eigen::Vector3d e(r.world_from_sensor[s].x_m - truth[s].x_m,
                              r.world_from_sensor[s].y_m - truth[s].y_m,
                              common::AngleDiff(r.world_from_sensor[s].yaw_rad, truth[s].yaw_rad));
      nees_sum += e.dot(r.covariance[s].ldlt().solve(e));
    }
  }
  // Normalised estimation error squared: 3 on average for a consistent covariance.
  const double nees = nees_sum / (3.0 * kRuns);
  EXPECT_GT(nees, 1.5);
  EXPECT_LT(nees, 5.0);
}

// Two rooms joined by a doorway at (10, 5): two sensors in each, tied to each other by walls
// (constraints of a few millimetres), and six people walking back and forth between the rooms,
// each sensor seeing them within 5 m (the views overlap only around the doorway; every pass is a
// new track). Every shape-fit centre sits 0.02 m beyond the body centre along its line of sight
// (one standard deviation of the shared bias the model allows, the same for every sensor): seen
// from both sides, room B comes out ~0.04 m towards room A, which no number of samples averages.
std::vector<Pose2> DoorwaySensors() {
  return {{6.0, 5.0, 0.0},
          {6.0, 7.0, DegToRad(-25.0)},
          {14.0, 5.0, DegToRad(180.0)},
          {14.0, 3.0, DegToRad(155.0)}};
}

AlignedTracks DoorwayTracks(const std::vector<Pose2>& sensors) {
  std::vector<Path> doorway;
  for (int i = 0; i < 6; ++i) {
    const double k = static_cast<double>(i);
    doorway.push_back([k](double t) {
      return Eigen::Vector2d(10.0 + 3.0 * std::sin((0.11 + 0.017 * k) * t + 1.1 * k),
                             5.0 + 0.6 * std::sin((0.29 + 0.031 * k) * t + 0.7 * k));
    });
  }
  SynthOptions synth;
  synth.kind = MeasurementKind::kShapeFit;
  synth.com_bias_m = -0.02;  // away from the sensor
  synth.model_bias_m = 0.0;  // what a shape fit's model says
  synth.shared_bias_sigma_m = 0.02;
  synth.range_m = 5.0;
  synth.steps = 2400;
  return MakeTracks(sensors, doorway, synth);
}

// The 2-dof NEES of a sensor's position error: within chi2(2) 95 % (5.99) for a covariance that
// covers the error, beyond 3 sigma (9) for one that does not.
double PositionNees(const JointRefineResult& r, const std::vector<Pose2>& truth, std::size_t s) {
  const Eigen::Vector2d e = r.world_from_sensor[s].translation() - truth[s].translation();
  return e.dot(r.covariance[s].topLeftCorner<2, 2>().ldlt().solve(e));
}

TEST(RefineJointlyTest, SensorBiasHeldAcrossADoorwayIsInTheCovariance) {
  // The biases held at their prior (not estimated): as a consider parameter each sensor's bias
  // puts the error into the covariance; without it the covariance only knows the noise.
  const std::vector<Pose2> truth = DoorwaySensors();
  const AlignedTracks tracks = DoorwayTracks(truth);
  const std::vector<RelativePoseConstraint> walls = {
      TrueConstraint(truth, 0, 1, 0.002, DegToRad(0.02)),
      TrueConstraint(truth, 2, 3, 0.002, DegToRad(0.02))};
  const std::vector<Pose2> initial = Perturb(truth, 0, 0.05, DegToRad(0.5));
  JointRefineOptions options;
  options.estimate_sensor_bias = false;
  const JointRefineResult with =
      RefineJointly(tracks, initial, std::vector<bool>(4, true), 0, options, walls);
  options.sensor_bias = false;
  const JointRefineResult without =
      RefineJointly(tracks, initial, std::vector<bool>(4, true), 0, options, walls);
  ASSERT_TRUE(with.ok) << with.message;
  ASSERT_TRUE(without.ok) << without.message;
  for (std::size_t s = 1; s < 4; ++s) {
    EXPECT_LE(PositionNees(with, truth, s), 5.99) << s;
    // Honest, not meaningless: of the order of the bias prior.
    EXPECT_LT(std::sqrt(with.covariance[s].topLeftCorner<2, 2>().trace()), 0.06) << s;
  }
  for (std::size_t s = 2; s < 4; ++s) {
    // The same poses (the consider parameter is not estimated), room B off by the bias.
    const double error_m = common::TranslationDistanceM(with.world_from_sensor[s], truth[s]);
    EXPECT_GT(error_m, 0.025) << s;
    EXPECT_NEAR(common::TranslationDistanceM(without.world_from_sensor[s], truth[s]), error_m,
                1e-9);
    EXPECT_GT(PositionNees(without, truth, s), 9.0) << s;
  }
}

TEST(RefineJointlyTest, SensorBiasIsEstimatedWhereWallsMakeItObservable) {
  // The walls tie each room's two sensors, which see one person from different directions: only
  // the right bias of each explains their disagreement in every direction. Estimated, room B is
  // placed to millimetres; the reported biases are the true -0.02 m (beyond the centre).
  const std::vector<Pose2> truth = DoorwaySensors();
  const AlignedTracks tracks = DoorwayTracks(truth);
  const std::vector<RelativePoseConstraint> walls = {
      TrueConstraint(truth, 0, 1, 0.002, DegToRad(0.02)),
      TrueConstraint(truth, 2, 3, 0.002, DegToRad(0.02))};
  const JointRefineResult r = RefineJointly(tracks, Perturb(truth, 0, 0.05, DegToRad(0.5)),
                                            std::vector<bool>(4, true), 0, {}, walls);
  ASSERT_TRUE(r.ok) << r.message;
  ASSERT_EQ(r.sensor_bias_estimated.size(), 4u);
  for (std::size_t s = 0; s < 4; ++s) {
    EXPECT_TRUE(r.sensor_bias_estimated[s]) << s << ": " << r.sensor_bias_data_sigma[s];
    EXPECT_LT(r.sensor_bias_data_sigma[s], 0.5) << s;
    EXPECT_NEAR(r.sensor_bias_m[s], -0.02, 0.01) << s;
    // Its uncertainty after the refinement: well below the 0.02 m prior, and covering the error.
    ASSERT_EQ(r.sensor_bias_sigma_m.size(), 4u);
    EXPECT_GT(r.sensor_bias_sigma_m[s], 0.0) << s;
    EXPECT_LT(r.sensor_bias_sigma_m[s], 0.01) << s;
    EXPECT_LE(std::abs(r.sensor_bias_m[s] + 0.02), 3.0 * r.sensor_bias_sigma_m[s]) << s;
  }
  for (std::size_t s = 1; s < 4; ++s) {
    EXPECT_LT(common::TranslationDistanceM(r.world_from_sensor[s], truth[s]), 0.01) << s;
    EXPECT_LE(PositionNees(r, truth, s), 5.99) << s;
  }
  EXPECT_NE(r.message.find("shared radial bias estimated"), std::string::npos) << r.message;

  // Two facing sensors alone: a bias of either is a translation along the line between them, the
  // data cannot tell them apart; held at the prior, which the covariance carries.
  const std::vector<Pose2> facing = {truth[0], truth[2]};
  const std::vector<Pose2> pair_initial = {truth[0], Perturb(facing, 0, 0.05, 0.0)[1]};
  const JointRefineResult p =
      RefineJointly(DoorwayTracks(facing), pair_initial, std::vector<bool>(2, true), 0, {});
  ASSERT_TRUE(p.ok) << p.message;
  EXPECT_FALSE(p.sensor_bias_estimated[0]) << p.sensor_bias_data_sigma[0];
  EXPECT_FALSE(p.sensor_bias_estimated[1]) << p.sensor_bias_data_sigma[1];
  for (std::size_t s = 0; s < 2; ++s) {
    EXPECT_EQ(p.sensor_bias_m[s], 0.0) << s;
    EXPECT_NEAR(p.sensor_bias_sigma_m[s], 0.02, 1e-6) << s;  // its prior
  }
  EXPECT_GT(common::TranslationDistanceM(p.world_from_sensor[1], facing[1]), 0.025);
  EXPECT_LE(PositionNees(p, facing, 1), 5.99);
}

}  // namespace
}  // namespace lrfnet::calib
