#include "common/geometry.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <utility>
#include <vector>

namespace lrfnet::common {
namespace {

TEST(AngleTest, NormalizeWrapsIntoHalfOpenInterval) {
  EXPECT_NEAR(NormalizeAngle(3 * kPi), kPi, 1e-12);
  EXPECT_NEAR(NormalizeAngle(-kPi), kPi, 1e-12);
  EXPECT_NEAR(NormalizeAngle(-3 * kPi / 2), kPi / 2, 1e-12);
  EXPECT_NEAR(NormalizeAngle(0.1 + 20 * kPi), 0.1, 1e-9);
  EXPECT_NEAR(AngleDiff(DegToRad(179), DegToRad(-179)), DegToRad(-2), 1e-12);
}

// The same bits as std::remainder(a, pi), on every side of each boundary of its fast paths.
TEST(AngleTest, RemainderHalfTurnIsLibmRemainderBitForBit) {
  std::vector<double> angles = {0.0,
                                -0.0,
                                kPi,
                                -kPi,
                                2 * kPi,
                                1e-300,
                                1e300,
                                std::numeric_limits<double>::infinity(),
                                -std::numeric_limits<double>::infinity()};
  for (const double edge : {kPi / 2, kPi, 1.5 * kPi, 3 * kPi / 2, 2 * kPi}) {
    for (const double sign : {1.0, -1.0}) {
      double below = sign * edge, above = sign * edge;
      for (int k = 0; k < 4; ++k) {
        angles.push_back(below);
        angles.push_back(above);
        below = std::nextafter(below, 0.0);
        above = std::nextafter(above, sign * 10.0);
      }
    }
  }
  for (int i = -200000; i <= 200000; ++i) angles.push_back(i * 2.5e-5 * kPi);
  for (const double a : angles) {
    const double expected = std::remainder(a, kPi);
    const double got = RemainderHalfTurn(a);
    EXPECT_EQ(std::bit_cast<std::uint64_t>(got), std::bit_cast<std::uint64_t>(expected))
        << "a = " << a << " got " << got << " expected " << expected;
  }
  EXPECT_TRUE(std::isnan(RemainderHalfTurn(std::numeric_limits<double>::quiet_NaN())));
  // Known answers: a yaw beyond a quarter turn maps onto the axis' other end.
  EXPECT_NEAR(RemainderHalfTurn(kPi / 2 + 0.25), 0.25 - kPi / 2, 1e-15);
  EXPECT_DOUBLE_EQ(RemainderHalfTurn(4.0), 4.0 - kPi);
  EXPECT_DOUBLE_EQ(RemainderHalfTurn(-2.0), -2.0 + kPi);
  EXPECT_EQ(std::signbit(RemainderHalfTurn(-kPi)), std::signbit(std::remainder(-kPi, kPi)));
}

// The same bits as glibc's hypot on x86-64 (elsewhere libm may take another kernel: within an ulp
// there), over magnitudes and ratios from equal to beyond 2^54, and on each side of the ranges that
// go to libm.
TEST(HypotTest, HypotIsLibmHypotBitForBit) {
  std::vector<std::pair<double, double>> pairs = {
      {3.0, 4.0},      {-3.0, 4.0},      {0.0, 0.0},     {0.0, -2.5},    {1.0, 1.0},
      {1.0, 0x1p-54},  {1.0, 0x1p-53},   {0x1p511, 1.0}, {0x1p512, 1.0}, {1.0, 0x1p-459},
      {1.0, 0x1p-460}, {1e-300, 1e-300}, {1e300, 1e300}};
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> exponent(-8.0, 8.0), ratio_exponent(-20.0, 0.0);
  std::uniform_real_distribution<double> mantissa(1.0, 2.0);
  std::bernoulli_distribution negative(0.5);
  for (int i = 0; i < 200000; ++i) {
    const double a = std::ldexp(mantissa(rng), static_cast<int>(exponent(rng)));
    // Ratios log-uniform down to 2^-20 and, one pair in eight, near 1 (both branches of the
    // kernel's correction).
    const double b = i % 8 == 0 ? a * (1.0 - 0.5 * (mantissa(rng) - 1.0))
                                : a * std::exp2(ratio_exponent(rng)) * mantissa(rng);
    pairs.emplace_back(negative(rng) ? -a : a, negative(rng) ? -b : b);
  }
  for (const auto& [x, y] : pairs) {
    const double expected = std::hypot(x, y);
    const double got = Hypot(x, y);
#if defined(__x86_64__) && defined(__GLIBC__)
    EXPECT_EQ(std::bit_cast<std::uint64_t>(got), std::bit_cast<std::uint64_t>(expected))
        << "x = " << x << " y = " << y << " got " << got << " expected " << expected;
#else
    EXPECT_LE(std::abs(got - expected), std::nextafter(expected, 2 * expected) - expected);
#endif
  }
  constexpr double kInf = std::numeric_limits<double>::infinity();
  EXPECT_EQ(Hypot(kInf, std::numeric_limits<double>::quiet_NaN()), kInf);
  EXPECT_TRUE(std::isnan(Hypot(1.0, std::numeric_limits<double>::quiet_NaN())));
  EXPECT_EQ(Hypot(3.0, -4.0), 5.0);
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
