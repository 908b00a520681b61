#include "central_daemon/calibration/translations.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace lrfnet::calib {
namespace {

using common::kPi;

// s_from_r from the true world poses.
RelativeMeasurement Measure(const std::vector<Pose2>& world_from, std::size_t r, std::size_t s) {
  RelativeMeasurement m;
  m.r = r;
  m.s = s;
  m.s_from_r = world_from[s].inverse() * world_from[r];
  return m;
}

std::vector<double> Yaws(const std::vector<Pose2>& world_from) {
  std::vector<double> yaw;
  for (const Pose2& p : world_from) yaw.push_back(p.yaw_rad - world_from[0].yaw_rad);
  return yaw;
}

TEST(SolveTranslations, ExactOnNoiseFreeInput) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const std::size_t n = 8;
  std::vector<Pose2> world_from(n);
  for (std::size_t v = 1; v < n; ++v) world_from[v] = {10 * u(rng), 10 * u(rng), kPi * u(rng)};
  std::vector<RelativeMeasurement> m;
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j) {
      if (j == i + 1 || u(rng) > 0.3)
        m.push_back(Measure(world_from, (i + j) % 2 ? i : j, (i + j) % 2 ? j : i));
    }
  }
  for (bool covariances : {false, true}) {
    TranslationOptions options;
    options.use_covariances = covariances;
    const TranslationResult result =
        SolveTranslations(n, 0, Yaws(world_from), m, std::vector<bool>(m.size(), true), options);
    ASSERT_TRUE(result.ok) << result.error;
    for (std::size_t v = 0; v < n; ++v) {
      EXPECT_NEAR((result.position_m[v] - world_from[v].translation()).norm(), 0.0, 1e-10) << v;
    }
    for (double r : result.residual_m) EXPECT_LT(r, 1e-10);
    EXPECT_EQ(result.position_cov_m2[0], Eigen::Matrix2d::Zero());
  }
}

TEST(SolveTranslations, WeightsAverageParallelMeasurements) {
  // Node 1 measured at x = 1 m (weight 3) and x = 2 m (weight 1) from node 0: weighted mean 1.25.
  std::vector<RelativeMeasurement> m(2);
  for (auto& e : m) {
    e.r = 1;
    e.s = 0;
  }
  m[0].s_from_r = {1.0, 0.0, 0.0};
  m[0].weight = 3.0;
  m[1].s_from_r = {2.0, 0.0, 0.0};
  m[1].weight = 1.0;
  TranslationOptions options;
  const TranslationResult plain = SolveTranslations(2, 0, {0.0, 0.0}, m, {true, true}, options);
  ASSERT_TRUE(plain.ok);
  EXPECT_NEAR(plain.position_m[1].x(), 1.5, 1e-12);
  options.use_weights = true;
  const TranslationResult weighted = SolveTranslations(2, 0, {0.0, 0.0}, m, {true, true}, options);
  ASSERT_TRUE(weighted.ok);
  EXPECT_NEAR(weighted.position_m[1].x(), 1.25, 1e-12);
  EXPECT_NEAR(weighted.residual_m[0], 0.25, 1e-12);
  EXPECT_NEAR(weighted.residual_m[1], 0.75, 1e-12);
  // χ² = 3 * 0.25² + 0.75² = 0.75, dof = 2 * 2 - 2 = 2: σ̂² = 0.375; H = 4 I: cov = σ̂² / 4.
  EXPECT_NEAR(weighted.position_cov_m2[1](0, 0), 0.375 / 4.0, 1e-12);
  EXPECT_NEAR(weighted.position_cov_m2[1](1, 1), 0.375 / 4.0, 1e-12);
  // Only the flagged measurements take part.
  const TranslationResult first = SolveTranslations(2, 0, {0.0, 0.0}, m, {true, false}, options);
  ASSERT_TRUE(first.ok);
  EXPECT_NEAR(first.position_m[1].x(), 1.0, 1e-12);
  EXPECT_NEAR(first.residual_m[1], 1.0, 1e-12);  // reported for unused measurements too
  // A tree: σ from the prior.
  EXPECT_NEAR(first.position_cov_m2[1](0, 0), options.prior_sigma_m * options.prior_sigma_m, 1e-15);
}

TEST(SolveTranslations, CovariancesAreRotatedIntoTheWorldAndCombined) {
  // Node 0 sits at yaw 90°: a measurement's frame-0 x axis is the world's y axis. Two parallel
  // measurements of node 1's position from node 0, each precise along a different axis of frame 0.
  const double yaw0 = kPi / 2;
  std::vector<RelativeMeasurement> m(2);
  for (auto& e : m) {
    e.r = 1;
    e.s = 0;
    e.covariance = Eigen::Matrix3d::Identity();
  }
  m[0].s_from_r = {1.0, 0.0, 0.0};  // frame 0: x precise (σ² 0.01), y loose (σ² 1)
  m[0].covariance(0, 0) = 0.01;
  m[1].s_from_r = {2.0, 1.0, 0.0};  // frame 0: y precise, x loose
  m[1].covariance(1, 1) = 0.01;
  TranslationOptions options;
  options.use_covariances = true;
  // Reference 1 at the origin: t_0 = t_1 - R(yaw0) t_s... solved for node 0 instead.
  const TranslationResult result = SolveTranslations(2, 1, {yaw0, 0.0}, m, {true, true}, options);
  ASSERT_TRUE(result.ok) << result.error;
  // Per-axis information-weighted mean in frame 0: x ≈ (1/0.01 * 1 + 1 * 2) / 101, y ≈ (1 * 0
  // + 1/0.01 * 1) / 101; node 0 = -(R(yaw0) * that).
  const Eigen::Vector2d in_frame0((100.0 * 1.0 + 1.0 * 2.0) / 101.0,
                                  (1.0 * 0.0 + 100.0 * 1.0) / 101.0);
  const Eigen::Vector2d expected = -(Pose2{0.0, 0.0, yaw0}.rotation() * in_frame0);
  EXPECT_NEAR((result.position_m[0] - expected).norm(), 0.0, 1e-12);
  // With covariances (no weights) H^-1 is the covariance: 1/101 per frame-0 axis, rotated.
  EXPECT_NEAR(result.position_cov_m2[0](0, 0), 1.0 / 101.0, 1e-12);
  EXPECT_NEAR(result.position_cov_m2[0](1, 1), 1.0 / 101.0, 1e-12);
  EXPECT_NEAR(result.variance_factor, 1.0, 0.0);

  // An anisotropic single measurement: the covariance turns with node 0's yaw.
  const TranslationResult one = SolveTranslations(2, 1, {yaw0, 0.0}, m, {true, false}, options);
  ASSERT_TRUE(one.ok);
  EXPECT_NEAR(one.position_cov_m2[0](0, 0), 1.0, 1e-12);   // world x = frame-0 y (loose)
  EXPECT_NEAR(one.position_cov_m2[0](1, 1), 0.01, 1e-12);  // world y = frame-0 x (precise)
}

TEST(SolveTranslations, ReportsDisconnectedUseAndBadInput) {
  std::vector<Pose2> world_from = {{0, 0, 0}, {1, 0, 0.1}, {2, 0, 0.2}, {3, 0, 0.3}};
  std::vector<RelativeMeasurement> m = {Measure(world_from, 1, 0), Measure(world_from, 2, 1),
                                        Measure(world_from, 3, 2)};
  const std::vector<double> yaw = Yaws(world_from);
  const TranslationResult cut = SolveTranslations(4, 0, yaw, m, {true, false, true}, {});
  EXPECT_FALSE(cut.ok);
  EXPECT_EQ(cut.error, "nodes 2, 3 are not connected to the reference node 0");
  EXPECT_NE(SolveTranslations(4, 0, yaw, m, {true}, {}).error.find("flags"), std::string::npos);
  EXPECT_NE(SolveTranslations(4, 0, {0.0}, m, {true, true, true}, {}).error.find("yaws"),
            std::string::npos);
  std::vector<double> nan_yaw = yaw;
  nan_yaw[2] = std::nan("");
  EXPECT_NE(SolveTranslations(4, 0, nan_yaw, m, {true, true, true}, {}).error.find("node 2"),
            std::string::npos);
  EXPECT_FALSE(SolveTranslations(1, 0, {0.0}, {}, {}, {}).ok);
  m[1].s_from_r.x_m = std::nan("");
  EXPECT_NE(SolveTranslations(4, 0, yaw, m, {true, true, true}, {}).error.find("measurement 1"),
            std::string::npos);
  m[1].s_from_r.x_m = 1.0;
  m[1].covariance(1, 1) = 0.0;  // singular translation block
  TranslationOptions options;
  options.use_covariances = true;
  EXPECT_NE(
      SolveTranslations(4, 0, yaw, m, {true, true, true}, options).error.find("measurement 1"),
      std::string::npos);
  // ... but not when that measurement is not used (the graph must still be connected).
  m.push_back(Measure(world_from, 2, 0));
  EXPECT_TRUE(SolveTranslations(4, 0, yaw, m, {true, false, true, true}, options).ok);
  options.prior_sigma_m = 0.0;
  EXPECT_NE(SolveTranslations(4, 0, yaw, m, {true, true, true, true}, options)
                .error.find("invalid options"),
            std::string::npos);
}

}  // namespace
}  // namespace lrfnet::calib
