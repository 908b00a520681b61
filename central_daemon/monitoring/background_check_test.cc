#include "central_daemon/monitoring/background_check.h"

#include <gtest/gtest.h>

#include <cmath>

#include "central_daemon/monitoring/monitoring_test_util.h"

namespace lrfnet::monitoring {
namespace {

using testing::Room;
using testing::Snapshot;

const Pose2 kSensor{11.7, 0.3, common::DegToRad(140.0)};

// The motion a sensor moved from `before` to `after` shows in its snapshots: its new frame in its
// old one.
Pose2 MotionOf(const Pose2& before, const Pose2& after) { return before.inverse() * after; }

void ExpectMotion(const BackgroundVerdict& v, const Pose2& expected, double yaw_tol_deg,
                  double translation_tol_m) {
  EXPECT_NEAR(
      common::RadToDeg(common::AngleDiff(v.reference_from_current.yaw_rad, expected.yaw_rad)), 0.0,
      yaw_tol_deg);
  EXPECT_NEAR(v.reference_from_current.x_m, expected.x_m, translation_tol_m);
  EXPECT_NEAR(v.reference_from_current.y_m, expected.y_m, translation_tol_m);
}

TEST(BackgroundCheck, TheSameSceneWithNoiseIsUnchanged) {
  const auto reference = Snapshot(Room(), kSensor, 0.01, 1);
  const auto current = Snapshot(Room(), kSensor, 0.01, 2);
  const BackgroundVerdict v = CheckBackgrounds(reference, current, {});
  EXPECT_EQ(v.kind, BackgroundVerdictKind::kUnchanged) << v.reason;
  EXPECT_GT(v.inliers_before, 0.97);
  EXPECT_LT(std::abs(common::RadToDeg(v.motion.yaw_rad)), 0.1);
  EXPECT_LT(std::hypot(v.motion.x_m, v.motion.y_m), 0.01);
}

TEST(BackgroundCheck, ARotatedAndShiftedSensorIsFoundWithItsMotion) {
  const auto reference = Snapshot(Room(), kSensor, 0.01, 1);
  for (const Pose2& bump :
       {Pose2{0, 0, common::DegToRad(2.0)}, Pose2{0.1, 0.0, 0.0},
        Pose2{0.0, -0.3, common::DegToRad(-10.0)}, Pose2{0.4, 0.3, common::DegToRad(0.5)}}) {
    const Pose2 moved = kSensor * bump;
    const BackgroundVerdict v = CheckBackgrounds(reference, Snapshot(Room(), moved, 0.01, 2), {});
    ASSERT_EQ(v.kind, BackgroundVerdictKind::kMoved)
        << "bump " << bump.x_m << " " << bump.y_m << " " << bump.yaw_rad << ": " << v.reason;
    EXPECT_FALSE(v.partial);
    ExpectMotion(v, MotionOf(kSensor, moved), 0.05, 0.01);
    EXPECT_GT(v.inliers_after, 0.95);
    EXPECT_GT(v.chi2, 25.0);
  }
}

TEST(BackgroundCheck, AMovedObstacleIsASceneChangeNotAMove) {
  const auto reference = Snapshot(Room(), kSensor, 0.01, 1);
  // A cupboard put down 3 m in front of the sensor, and another one 10 cm in front of the wall
  // beside it (its face could be slid onto the wall).
  std::vector<testing::Wall> changed = Room();
  testing::AddBox(&changed, 8.6, 1.4, 9.6, 2.6);
  testing::AddBox(&changed, 11.2, 2.0, 11.9, 5.0);
  const BackgroundVerdict v = CheckBackgrounds(reference, Snapshot(changed, kSensor, 0.01, 2), {});
  EXPECT_EQ(v.kind, BackgroundVerdictKind::kSceneChanged) << v.reason;
  EXPECT_LT(std::abs(common::RadToDeg(v.motion.yaw_rad)), 0.2) << v.reason;
  EXPECT_LT(std::hypot(v.motion.x_m, v.motion.y_m), 0.02) << v.reason;
  // The cabinet taken away: the wall behind it appears.
  std::vector<testing::Wall> removed = Room();
  removed.erase(removed.begin() + 4, removed.begin() + 8);
  const BackgroundVerdict w = CheckBackgrounds(reference, Snapshot(removed, kSensor, 0.01, 3), {});
  EXPECT_NE(w.kind, BackgroundVerdictKind::kMoved) << w.reason;
}

TEST(BackgroundCheck, TheChangedPartOfAHalfRelearnedSnapshotShowsTheMove) {
  // What a tracker sends 2 s after its sensor was turned by 2 degrees: the beams whose new return
  // is farther have taken it, all others still hold the old background.
  const auto reference = Snapshot(Room(), kSensor, 0.005, 1);
  const Pose2 moved = kSensor * Pose2{0.0, 0.0, common::DegToRad(2.0)};
  const auto now = Snapshot(Room(), moved, 0.005, 2);
  daemon::BackgroundScan partial = reference;
  std::size_t taken = 0;
  for (std::size_t i = 0; i < partial.ranges_mm.size(); ++i) {
    const bool farther = now.ranges_mm[i] == 0 || now.ranges_mm[i] > reference.ranges_mm[i] + 150;
    if (farther && reference.ranges_mm[i] != 0) {
      partial.ranges_mm[i] = now.ranges_mm[i];
      ++taken;
    }
  }
  ASSERT_GT(taken, 20u);
  const BackgroundVerdict v = CheckBackgrounds(reference, partial, {});
  ASSERT_EQ(v.kind, BackgroundVerdictKind::kMoved) << v.reason;
  EXPECT_TRUE(v.partial);
  ExpectMotion(v, MotionOf(kSensor, moved), 0.25, 0.03);
}

TEST(BackgroundCheck, AnExpectedMotionIsNoNewMove) {
  // After a correction the reference stays in the old frame with the motion expected.
  const auto reference = Snapshot(Room(), kSensor, 0.01, 1);
  const Pose2 moved = kSensor * Pose2{0.05, 0.1, common::DegToRad(3.0)};
  const Pose2 expected = MotionOf(kSensor, moved);
  const BackgroundVerdict v =
      CheckBackgrounds(reference, Snapshot(Room(), moved, 0.01, 2), {}, expected);
  EXPECT_EQ(v.kind, BackgroundVerdictKind::kUnchanged) << v.reason;
  EXPECT_LT(std::abs(common::RadToDeg(v.motion.yaw_rad)), 0.05);
  // ... and a second bump from there is measured from the expectation.
  const Pose2 again = moved * Pose2{0.0, 0.0, common::DegToRad(-2.0)};
  const BackgroundVerdict w =
      CheckBackgrounds(reference, Snapshot(Room(), again, 0.01, 3), {}, expected);
  ASSERT_EQ(w.kind, BackgroundVerdictKind::kMoved) << w.reason;
  EXPECT_NEAR(common::RadToDeg(w.motion.yaw_rad), -2.0, 0.05);
}

TEST(BackgroundCheck, TheFitPlacesTheSensorWhereTheExpectationKeepsMorePointsOnTheScene) {
  // A sensor turned by 10 degrees, expected 0.3 degrees short of it (a pose from tracks). Some
  // beams of its snapshot still hold what it saw from there (a tracker's background follows a
  // move beam by beam): at the expected pose they lie on the scene, at the true one off it, while
  // the rest lie within inlier_distance_m either way. The count of points on the scene then keeps
  // the expectation; the ICP's fit is the true pose.
  const auto reference = Snapshot(Room(), kSensor, 0.005, 1);
  const Pose2 turned = kSensor * Pose2{0.0, 0.0, common::DegToRad(10.0)};
  const Pose2 short_of_it = kSensor * Pose2{0.0, 0.0, common::DegToRad(9.7)};
  daemon::BackgroundScan current = Snapshot(Room(), turned, 0.005, 2);
  const daemon::BackgroundScan stale = Snapshot(Room(), short_of_it, 0.005, 3);
  std::size_t replaced = 0;
  for (std::size_t i = 0; i < current.ranges_mm.size(); ++i) {
    const double d_mm = std::abs(static_cast<double>(current.ranges_mm[i]) -
                                 static_cast<double>(stale.ranges_mm[i]));
    if (d_mm > 60.0) {
      current.ranges_mm[i] = stale.ranges_mm[i];
      ++replaced;
    }
  }
  ASSERT_GT(replaced, 20u);
  const BackgroundVerdict v =
      CheckBackgrounds(reference, current, {}, MotionOf(kSensor, short_of_it));
  // The failure mode: the verdict's pose is the expectation.
  EXPECT_GT(v.inliers_before, v.fit_share);
  EXPECT_NEAR(common::RadToDeg(v.motion.yaw_rad), 0.0, 1e-9);
  ASSERT_TRUE(v.fit_found);
  EXPECT_NEAR(common::RadToDeg(common::AngleDiff(v.fit_reference_from_current.yaw_rad,
                                                 MotionOf(kSensor, turned).yaw_rad)),
              0.0, 0.05);
  EXPECT_GT(v.fit_share, 0.9);
}

TEST(BackgroundCheck, ACorridorHidesAShiftAlongItsAxis) {
  // Two long parallel walls: a shift along them leaves the scene the same.
  const std::vector<testing::Wall> corridor = {{{-30, -1.5}, {30, -1.5}}, {{-30, 1.5}, {30, 1.5}}};
  const Pose2 sensor{0, 0, 0};
  const auto reference = Snapshot(corridor, sensor, 0.005, 1);
  const BackgroundVerdict v =
      CheckBackgrounds(reference, Snapshot(corridor, Pose2{0.3, 0.0, 0.0}, 0.005, 2), {});
  EXPECT_NE(v.kind, BackgroundVerdictKind::kMoved) << v.reason;
}

TEST(BackgroundCheck, UnusableInputIsSaidNotGuessed) {
  const auto reference = Snapshot(Room(), kSensor);
  daemon::BackgroundScan empty = reference;
  std::fill(empty.ranges_mm.begin(), empty.ranges_mm.end(), 0u);
  BackgroundVerdict v = CheckBackgrounds(reference, empty, {});
  EXPECT_EQ(v.kind, BackgroundVerdictKind::kUnusable);
  EXPECT_NE(v.reason.find("too few returns"), std::string::npos) << v.reason;
  daemon::BackgroundScan other = reference;
  other.ranges_mm.pop_back();
  v = CheckBackgrounds(reference, other, {});
  EXPECT_EQ(v.kind, BackgroundVerdictKind::kUnusable);
  EXPECT_NE(v.reason.find("geometry"), std::string::npos) << v.reason;
  daemon::BackgroundScan hostile = reference;
  hostile.angle_step_rad = std::nan("");
  v = CheckBackgrounds(reference, hostile, {});
  EXPECT_EQ(v.kind, BackgroundVerdictKind::kUnusable) << v.reason;
  hostile = reference;
  for (auto& r : hostile.ranges_mm) r = 0xFFFFFFFFu;
  v = CheckBackgrounds(reference, hostile, {});
  EXPECT_EQ(v.kind, BackgroundVerdictKind::kUnusable) << v.reason;
}

TEST(BackgroundCheck, OptionsAreValidated) {
  EXPECT_FALSE(Validate(BackgroundCheckOptions{}).has_value());
  BackgroundCheckOptions o;
  o.start_yaws_deg.clear();
  EXPECT_NE(Validate(o).value_or("").find("start_yaws_deg"), std::string::npos);
  o = {};
  o.min_inlier_fraction = 1.5;
  EXPECT_NE(Validate(o).value_or("").find("min_inlier_fraction"), std::string::npos);
  o = {};
  o.inlier_distance_m = std::nan("");
  EXPECT_NE(Validate(o).value_or("").find("inlier_distance_m"), std::string::npos);
  o = {};
  o.icp.max_iterations = 0;
  EXPECT_NE(Validate(o).value_or("").find("icp."), std::string::npos);
}

}  // namespace
}  // namespace lrfnet::monitoring
