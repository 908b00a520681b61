#include "central_daemon/monitoring/track_check.h"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <cmath>

#include "central_daemon/monitoring/monitoring_test_util.h"

namespace lrfnet::monitoring {
namespace {

using testing::Frames;
using testing::TwoPeople;

constexpr common::UtcNs kT0 = 1'700'000'000'000'000'000;
const Pose2 kPoseA{0.3, 0.3, common::DegToRad(40.0)};
const Pose2 kPoseB{11.7, 0.3, common::DegToRad(140.0)};
const Pose2 kPoseC{11.7, 7.7, common::DegToRad(-140.0)};

struct Scene {
  std::vector<daemon::TrackFrameData> s1, s2, s3;
  std::vector<PlacedFrames> Others() const { return {{"s1", kPoseA, &s1}, {"s3", kPoseC, &s3}}; }
};

// Ten seconds of `people` (two unless said) seen by three sensors; s2 stands at `s2_true`.
Scene Walk(const Pose2& s2_true, double t0_s = 0.0, double t1_s = 10.0,
           const std::vector<testing::Walker>& people = TwoPeople()) {
  Scene s;
  s.s1 = Frames(people, kPoseA, t0_s, t1_s, kT0, 11, 1);
  s.s2 = Frames(people, s2_true, t0_s, t1_s, kT0, 12, 2);
  s.s3 = Frames(people, kPoseC, t0_s, t1_s, kT0, 13, 3);
  return s;
}

// Two more people on loops of their own.
std::vector<testing::Walker> FourPeople() {
  std::vector<testing::Walker> p = TwoPeople();
  p.push_back({{{1.5, 6.5}, {5, 6.5}, {5, 1.2}, {1.5, 1.2}}, 1.1, 1.0});
  p.push_back({{{10.5, 1.5}, {10.5, 6.5}, {7.5, 4.5}}, 0.9, 2.0});
  return p;
}

TEST(TrackCheck, TracksThatAgreeFindNoMove) {
  const Scene scene = Walk(kPoseB);
  const TrackFit fit = CheckTracks(scene.s2, kPoseB, scene.Others(), {});
  ASSERT_TRUE(fit.enough) << fit.reason;
  EXPECT_FALSE(fit.moved) << fit.reason;
  EXPECT_LT(fit.chi2, 25.0) << fit.reason;
  EXPECT_LT(std::abs(common::RadToDeg(fit.correction.yaw_rad)), 0.2) << fit.reason;
  EXPECT_LT(std::hypot(fit.correction.x_m, fit.correction.y_m), 0.03) << fit.reason;
}

TEST(TrackCheck, ATrackOffsetIsAMoveWithItsCorrection) {
  // s2 was turned by 2 degrees or pushed 20 cm; the calibration still has the old pose. Ten
  // seconds of four people: the fit's covariance is the calibration's honest one, with an error of
  // its own per person (matched track pair) that no number of samples averages out, so that a
  // 10 cm push (chi2 ~19 here) or a push and a turn that cancel over the room (0.1 m and -1 deg:
  // chi2 ~7) are below min_chi2 in one window; their corrections are still estimated right.
  for (const Pose2& bump : {Pose2{0, 0, common::DegToRad(2.0)}, Pose2{0.2, 0.0, 0.0},
                            Pose2{0.0, 0.2, common::DegToRad(1.0)}}) {
    const Pose2 moved = kPoseB * bump;
    const Scene scene = Walk(moved, 0.0, 10.0, FourPeople());
    const TrackFit fit = CheckTracks(scene.s2, kPoseB, scene.Others(), {});
    ASSERT_TRUE(fit.enough) << fit.reason;
    EXPECT_TRUE(fit.moved) << fit.reason;
    EXPECT_NEAR(common::RadToDeg(common::AngleDiff(fit.correction.yaw_rad, bump.yaw_rad)), 0.0,
                0.15)
        << fit.reason;
    EXPECT_NEAR(fit.correction.x_m, bump.x_m, 0.03) << fit.reason;
    EXPECT_NEAR(fit.correction.y_m, bump.y_m, 0.03) << fit.reason;
    // The fitted pose is the new truth.
    EXPECT_LT(common::TranslationDistanceM(fit.world_from_sensor, moved), 0.03) << fit.reason;
  }
}

// The sensor's reports moved out along its lines of sight by bias_m (a shape fit's shared bias).
std::vector<daemon::TrackFrameData> RadiallyBiased(std::vector<daemon::TrackFrameData> frames,
                                                   double bias_m) {
  for (daemon::TrackFrameData& f : frames) {
    for (daemon::TrackObservation& o : f.tracks) {
      const double range_m = std::hypot(o.x_m, o.y_m);
      const double scale = (range_m + bias_m) / range_m;
      o.x_m = static_cast<float>(o.x_m * scale);
      o.y_m = static_cast<float>(o.y_m * scale);
    }
  }
  return frames;
}

TEST(TrackCheck, TheSensorsSharedBiasIsInTheBaselineNotInTheTestOfAMove) {
  // s2's tracker puts every centre 3 cm beyond the body (1.5 times the shared bias's prior). The
  // baseline, measured right after the pose was set, holds what that does to the fit; a later
  // window that did not move stays below min_chi2, and a 0.2 m push of two people's 10 s is
  // tested against the fit's covariance without the bias's consider term (which the baseline
  // cancels): chi2 ~48 here, ~32 against the whole covariance.
  constexpr double kBiasM = 0.03;
  const Scene before = Walk(kPoseB, 0.0, 10.0);
  const TrackFit learn =
      CheckTracks(RadiallyBiased(before.s2, kBiasM), kPoseB, before.Others(), {});
  ASSERT_TRUE(learn.enough) << learn.reason;
  const Pose2 baseline = learn.correction;

  const Scene still = Walk(kPoseB, 10.0, 20.0);
  const TrackFit unmoved =
      CheckTracks(RadiallyBiased(still.s2, kBiasM), kPoseB, still.Others(), {}, baseline);
  ASSERT_TRUE(unmoved.enough) << unmoved.reason;
  EXPECT_FALSE(unmoved.moved) << unmoved.reason;
  EXPECT_LT(unmoved.chi2, 25.0) << unmoved.reason;

  const Pose2 pushed = kPoseB * Pose2{0.2, 0.0, 0.0};
  const Scene after = Walk(pushed, 20.0, 30.0);
  const TrackFit fit =
      CheckTracks(RadiallyBiased(after.s2, kBiasM), kPoseB, after.Others(), {}, baseline);
  ASSERT_TRUE(fit.enough) << fit.reason;
  EXPECT_GT(fit.covariance_sensor_bias.trace(), 0.0);
  const Pose2 expected = kPoseB * baseline;
  const Eigen::Vector3d delta(fit.world_from_sensor.x_m - expected.x_m,
                              fit.world_from_sensor.y_m - expected.y_m,
                              common::AngleDiff(fit.world_from_sensor.yaw_rad, expected.yaw_rad));
  const double chi2_whole = delta.dot(fit.covariance.ldlt().solve(delta));
  EXPECT_GT(fit.chi2, chi2_whole);
  EXPECT_TRUE(fit.moved) << fit.reason;
  EXPECT_NEAR(fit.correction.x_m - baseline.x_m, 0.2, 0.04) << fit.reason;
}

TEST(TrackCheck, ALargeMoveIsFoundBySearchingFromScratch) {
  // 10 degrees: at 8 m the tracks land 1.4 m away, beyond the association gate.
  const Pose2 moved = kPoseB * Pose2{0.0, 0.0, common::DegToRad(10.0)};
  const Scene scene = Walk(moved, 0.0, 20.0);
  const TrackFit detect = CheckTracks(scene.s2, kPoseB, scene.Others(), {});
  EXPECT_TRUE(detect.moved) << detect.reason;
  const TrackFit fit = EstimateFromTracks(scene.s2, kPoseB, scene.Others(), {});
  ASSERT_TRUE(fit.enough) << fit.reason;
  EXPECT_NEAR(common::RadToDeg(common::AngleDiff(fit.world_from_sensor.yaw_rad, moved.yaw_rad)),
              0.0, 0.2)
      << fit.reason;
  EXPECT_LT(common::TranslationDistanceM(fit.world_from_sensor, moved), 0.05) << fit.reason;
}

TEST(TrackCheck, TooFewTracksAreNotEnoughNeverAMove) {
  const Scene scene = Walk(kPoseB * Pose2{0.0, 0.0, common::DegToRad(5.0)}, 0.0, 1.5);
  const TrackFit fit = CheckTracks(scene.s2, kPoseB, scene.Others(), {});
  EXPECT_FALSE(fit.enough);
  EXPECT_FALSE(fit.moved);
  EXPECT_FALSE(fit.reason.empty());
  // Nobody else to compare with.
  EXPECT_FALSE(CheckTracks(scene.s2, kPoseB, {}, {}).enough);
  // A person standing still fixes no rotation, and a box does not count at all.
  const std::vector<testing::Walker> standing = {{{{6, 4}, {6.001, 4}}, 0.0001, 0.0}};
  const auto s1 = Frames(standing, kPoseA, 0, 10, kT0, 11, 1);
  const auto s2 = Frames(standing, kPoseB * Pose2{0.2, 0, 0}, 0, 10, kT0, 12, 2);
  const std::vector<PlacedFrames> others = {{"s1", kPoseA, &s1}};
  const TrackFit still = CheckTracks(s2, kPoseB, others, {});
  EXPECT_FALSE(still.enough) << still.reason;
  EXPECT_FALSE(still.moved) << still.reason;
}

TEST(TrackCheck, HostileTracksAreIgnored) {
  Scene scene = Walk(kPoseB);
  for (auto& f : scene.s2) {
    daemon::TrackObservation bad = f.tracks.front();
    bad.track_id = 99;
    bad.x_m = std::nanf("");
    f.tracks.push_back(bad);
    bad.track_id = 98;
    bad.x_m = 1e30f;
    bad.covariance.fill(-1.0f);
    f.tracks.push_back(bad);
  }
  const TrackFit fit = CheckTracks(scene.s2, kPoseB, scene.Others(), {});
  ASSERT_TRUE(fit.enough) << fit.reason;
  EXPECT_FALSE(fit.moved) << fit.reason;
  EXPECT_TRUE(std::isfinite(fit.world_from_sensor.x_m));
}

TEST(TrackCheck, TheWorldRecordingRotatesPositionsVelocitiesAndCovariances) {
  daemon::TrackFrameData f;
  f.session_id = 5;
  f.scan_start_ns = kT0;
  daemon::TrackObservation o;
  o.track_id = 3;
  o.x_m = 1.0f;
  o.y_m = 0.0f;
  o.vx_mps = 1.0f;
  o.covariance = {0.04f, 0, 0, 0, 0.01f, 0, 0, 1.0f, 0, 1.0f};
  o.kind = daemon::MeasurementKind::kCenterOfMass;
  f.tracks.push_back(o);
  const std::vector<daemon::TrackFrameData> frames = {f};
  const Pose2 pose{2.0, 3.0, common::DegToRad(90.0)};
  const daemon::MeasurementModelOptions model;
  const calib::SensorRecording w = WorldRecording({{"a", pose, &frames}}, model);
  ASSERT_EQ(w.frames.size(), 1u);
  const daemon::TrackObservation& t = w.frames[0].tracks[0];
  // A centre of mass lies short of the body centre along the sensor's line of sight (+x here,
  // +y in the world): moved out by the model's bias in the sensor's frame, then placed.
  const daemon::CorrectedPosition centre = daemon::CorrectedPositionOf(o, model);
  const double bias_m = centre.x_m - 1.0;
  EXPECT_GT(bias_m, 0.05);
  EXPECT_NEAR(centre.y_m, 0.0, 1e-9);
  EXPECT_NEAR(t.x_m, 2.0, 1e-6);
  EXPECT_NEAR(t.y_m, 4.0 + bias_m, 1e-6);
  EXPECT_NEAR(t.vx_mps, 0.0, 1e-6);
  EXPECT_NEAR(t.vy_mps, 1.0, 1e-6);
  // xx <- yy, yy <- xx, each with what the model does not know.
  EXPECT_NEAR(t.covariance[0], 0.01 + centre.extra_variance_m2, 1e-6);
  EXPECT_NEAR(t.covariance[4], 0.04 + centre.extra_variance_m2, 1e-6);
  EXPECT_EQ(t.kind, daemon::MeasurementKind::kShapeFit);
  EXPECT_NE(w.frames[0].session_id, 5u);
}

}  // namespace
}  // namespace lrfnet::monitoring
