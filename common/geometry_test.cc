#include "common/geometry.h"

#include <gtest/gtest.h>

namespace lrfnet::common {
namespace {

TEST(AngleTest, NormalizeWrapsIntoHalfOpenInterval) {
  EXPECT_NEAR(NormalizeAngle(3 * kPi), kPi, 1e-12);
  EXPECT_NEAR(NormalizeAngle(-kPi), kPi, 1e-12);
  EXPECT_NEAR(NormalizeAngle(-3 * kPi / 2), kPi / 2, 1e-12);
  EXPECT_NEAR(NormalizeAngle(0.1 + 20 * kPi), 0.1, 1e-9);
  EXPECT_NEAR(AngleDiff(DegToRad(179), DegToRad(-179)), DegToRad(-2), 1e-12);
}

TEST(Pose2Test, ComposeWithInverseIsIdentity) {
  const Pose2 a{1.5, -2.0, DegToRad(130)};
  const Pose2 id = a * a.inverse();
  EXPECT_NEAR(id.x_m, 0, 1e-12);
  EXPECT_NEAR(id.y_m, 0, 1e-12);
  EXPECT_NEAR(id.yaw_rad, 0, 1e-12);
}

TEST(Pose2Test, TransformsPointsAsWorldFromSensor) {
  // Sensor at (2, 1) looking along +y: its forward axis (x) is the world's +y.
  const Pose2 world_from_sensor{2.0, 1.0, DegToRad(90)};
  const Eigen::Vector2d p_world = world_from_sensor * Eigen::Vector2d(3.0, 0.0);
  EXPECT_NEAR(p_world.x(), 2.0, 1e-12);
  EXPECT_NEAR(p_world.y(), 4.0, 1e-12);
  const Pose2 a{1, 2, 0.3}, b{-1, 0.5, -2.0}, c{0.2, 0.1, 3.0};
  const Pose2 l = (a * b) * c, r = a * (b * c);
  EXPECT_NEAR(l.x_m, r.x_m, 1e-12);
  EXPECT_NEAR(l.y_m, r.y_m, 1e-12);
  EXPECT_NEAR(AngleDiff(l.yaw_rad, r.yaw_rad), 0, 1e-12);
}

}  // namespace
}  // namespace lrfnet::common
