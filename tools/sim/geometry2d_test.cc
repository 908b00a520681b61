#include "tools/sim/geometry2d.h"

#include <gtest/gtest.h>

#include <cmath>

namespace lrfnet::sim {
namespace {

Ray RayAt(Vec2 origin, double angle_deg) {
  const double a = angle_deg * 3.14159265358979323846 / 180.0;
  return {origin, {std::cos(a), std::sin(a)}};
}

TEST(RaySegment, HitsAWallAtTheHandComputedDistance) {
  const Segment wall{{10, -20}, {10, 20}};
  EXPECT_NEAR(RaySegment(RayAt({0, 0}, 0), wall), 10.0, 1e-12);
  EXPECT_NEAR(RaySegment(RayAt({0, 0}, 30), wall),
              10.0 / std::cos(30 * 3.14159265358979323846 / 180), 1e-12);
  EXPECT_EQ(RaySegment(RayAt({0, 0}, 180), wall), kNoHit);  // behind the origin
  EXPECT_EQ(RaySegment(RayAt({0, 0}, 90), wall), kNoHit);   // parallel
  EXPECT_EQ(RaySegment(RayAt({0, 0}, 70), wall), kNoHit);   // passes beyond the end (y = 27.5)
  EXPECT_EQ(RaySegment(RayAt({10, 0}, 0), wall), kNoHit);   // starting on the wall
}

TEST(RayCircle, NearSideOfTheCircleAndNothingFromInside) {
  EXPECT_NEAR(RayCircle(RayAt({0, 0}, 0), {5, 0}, 0.5), 4.5, 1e-12);
  // 1° off axis: 5 cos(1°) − sqrt(0.25 − 25 sin²(1°)).
  const double a = 3.14159265358979323846 / 180.0;
  EXPECT_NEAR(RayCircle(RayAt({0, 0}, 1), {5, 0}, 0.5),
              5 * std::cos(a) - std::sqrt(0.25 - 25 * std::sin(a) * std::sin(a)), 1e-12);
  EXPECT_EQ(RayCircle(RayAt({0, 0}, 10), {5, 0}, 0.5), kNoHit);
  EXPECT_EQ(RayCircle(RayAt({5, 0}, 0), {5, 0}, 0.5), kNoHit);
}

TEST(RayEllipse, AxisAAlongTheEllipseYaw) {
  // Semi-axes a = 0.25 (along yaw), b = 0.15. With yaw 0 axis a lies along x: a ray along x
  // hits at 4 − a.
  EXPECT_NEAR(RayEllipse(RayAt({0, 0}, 0), {4, 0}, 0.25, 0.15, 0.0), 3.75, 1e-12);
  EXPECT_NEAR(RayEllipse(RayAt({0, 0}, 0), {4, 0}, 0.25, 0.15, 3.14159265358979323846 / 2), 3.85,
              1e-12);
  EXPECT_EQ(RayEllipse(RayAt({0, 0}, 90), {4, 0}, 0.25, 0.15, 0.0), kNoHit);
}

TEST(RaySuperellipse, BetweenTheEllipseAndItsBoundingBox) {
  constexpr double kPi = 3.14159265358979323846;
  // On the axes every exponent gives the same hit: 4 - a along a, 4 - b along b.
  EXPECT_NEAR(RaySuperellipse(RayAt({0, 0}, 0), {4, 0}, 0.25, 0.15, 2.7, 0.0), 3.75, 1e-9);
  EXPECT_NEAR(RaySuperellipse(RayAt({0, 0}, 0), {4, 0}, 0.25, 0.15, 2.7, kPi / 2), 3.85, 1e-9);
  // Exponent 2 is the ellipse.
  const Ray oblique = RayAt({0, 0}, 1.5);
  EXPECT_NEAR(RaySuperellipse(oblique, {4, 0}, 0.25, 0.15, 2.0, 0.7),
              RayEllipse(oblique, {4, 0}, 0.25, 0.15, 0.7), 1e-12);
  // Towards a corner the superellipse bulges out of the ellipse towards its box, and the hit point
  // lies on the curve.
  for (const double p : {2.3, 3.0, 4.0}) {
    const Ray ray{{-3.0, -3.0}, {std::sqrt(0.5), std::sqrt(0.5)}};
    const double t = RaySuperellipse(ray, {0, 0}, 0.25, 0.15, p, 0.0);
    ASSERT_NE(t, kNoHit) << p;
    EXPECT_LT(t, RayEllipse(ray, {0, 0}, 0.25, 0.15, 0.0)) << p;
    EXPECT_GT(t, RayBox(ray, {0, 0}, 0.25, 0.15, 0.0)) << p;
    const Vec2 hit = ray.origin + t * ray.dir;
    EXPECT_NEAR(std::pow(std::abs(hit.x / 0.25), p) + std::pow(std::abs(hit.y / 0.15), p), 1.0,
                1e-9)
        << p;
  }
  EXPECT_EQ(RaySuperellipse(RayAt({0, 0}, 10), {4, 0}, 0.25, 0.15, 3.0, 0.0), kNoHit);
  EXPECT_EQ(RaySuperellipse(RayAt({4, 0}, 0), {4, 0}, 0.25, 0.15, 3.0, 0.0), kNoHit);  // inside
}

TEST(RayBox, SlabsAlongTheBoxYaw) {
  constexpr double kPi = 3.14159265358979323846;
  EXPECT_NEAR(RayBox(RayAt({0, 0}, 0), {4, 0}, 0.5, 0.2, 0.0), 3.5, 1e-12);
  EXPECT_NEAR(RayBox(RayAt({0, 0}, 0), {4, 0}, 0.5, 0.2, kPi / 2), 3.8, 1e-12);
  // Rotated by 45 degrees the near corner points at the sensor.
  EXPECT_NEAR(RayBox(RayAt({0, 0}, 0), {4, 0}, 0.5, 0.5, kPi / 4), 4.0 - 0.5 * std::sqrt(2.0),
              1e-12);
  EXPECT_EQ(RayBox(RayAt({0, 0}, 20), {4, 0}, 0.5, 0.2, 0.0), kNoHit);
  EXPECT_EQ(RayBox(RayAt({4, 0}, 0), {4, 0}, 0.5, 0.2, 0.0), kNoHit);
}

TEST(Polygons, SimplePolygonChecksNameTheProblem) {
  EXPECT_FALSE(CheckSimplePolygon({{0, 0}, {1, 0}, {1, 1}, {0, 1}}).has_value());
  const auto bowtie = CheckSimplePolygon({{0, 0}, {1, 1}, {1, 0}, {0, 1}});
  ASSERT_TRUE(bowtie.has_value());
  EXPECT_NE(bowtie->find("cross"), std::string::npos) << *bowtie;
  const auto two = CheckSimplePolygon({{0, 0}, {1, 0}});
  ASSERT_TRUE(two.has_value());
  EXPECT_NE(two->find("at least 3"), std::string::npos);
  const auto flat = CheckSimplePolygon({{0, 0}, {1, 0}, {2, 0}});
  ASSERT_TRUE(flat.has_value());
  const auto repeated = CheckSimplePolygon({{0, 0}, {1, 0}, {1, 1}, {1, 0}});
  ASSERT_TRUE(repeated.has_value());
  EXPECT_NE(repeated->find("same point"), std::string::npos);
}

TEST(Polygons, InsideAndDistances) {
  const std::vector<Vec2> l_shape{{0, 0}, {8, 0}, {8, 3.5}, {4, 3.5}, {4, 7}, {0, 7}};
  EXPECT_TRUE(PointInPolygon({1, 1}, l_shape));
  EXPECT_TRUE(PointInPolygon({2, 6}, l_shape));
  EXPECT_FALSE(PointInPolygon({6, 6}, l_shape));
  EXPECT_NEAR(PolygonArea(l_shape), 8 * 3.5 + 4 * 3.5, 1e-12);
  EXPECT_NEAR(PointSegmentDistance({0, 1}, {{-1, 0}, {1, 0}}), 1.0, 1e-12);
  EXPECT_NEAR(PointSegmentDistance({3, 0}, {{-1, 0}, {1, 0}}), 2.0, 1e-12);
  EXPECT_TRUE(SegmentsIntersect({{0, 0}, {2, 2}}, {{0, 2}, {2, 0}}));
  EXPECT_TRUE(SegmentsIntersect({{0, 0}, {1, 0}}, {{1, 0}, {1, 1}}));  // touching
  EXPECT_FALSE(SegmentsIntersect({{0, 0}, {1, 0}}, {{0, 1}, {1, 1}}));
  EXPECT_NEAR(SegmentSegmentDistance({{0, 0}, {1, 0}}, {{0, 1}, {1, 1}}), 1.0, 1e-12);
}

}  // namespace
}  // namespace lrfnet::sim
