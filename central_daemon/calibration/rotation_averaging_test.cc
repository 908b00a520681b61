#include "central_daemon/calibration/rotation_averaging.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "central_daemon/calibration/clp_oracle.h"

namespace lrfnet::calib {
namespace {

using common::AngleDiff;
using common::DegToRad;
using common::kPi;

RelativeMeasurement Edge(std::size_t r, std::size_t s, double yaw_rad, double weight = 1.0) {
  RelativeMeasurement m;
  m.r = r;
  m.s = s;
  m.s_from_r.yaw_rad = yaw_rad;
  m.weight = weight;
  return m;
}

// Measurement of (r, s) from true yaws: θ = φ_r - φ_s (+ error), in a random 2π representative.
RelativeMeasurement Measure(const std::vector<double>& truth, std::size_t r, std::size_t s,
                            double error_rad, std::mt19937& rng) {
  const double shift = 2 * kPi * static_cast<double>(static_cast<int>(rng() % 3) - 1);
  return Edge(r, s, truth[r] - truth[s] + error_rad + shift);
}

double MaxYawError(const std::vector<double>& truth, const std::vector<double>& yaw,
                   std::size_t ref) {
  double worst = 0.0;
  for (std::size_t v = 0; v < truth.size(); ++v) {
    worst = std::max(worst, std::abs(AngleDiff(yaw[v], truth[v] - truth[ref])));
  }
  return worst;
}

// Circulant graph: every node linked to the next `k` on a ring.
std::vector<std::pair<std::size_t, std::size_t>> Circulant(std::size_t n, std::size_t k) {
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t d = 1; d <= k; ++d) pairs.emplace_back(i, (i + d) % n);
  }
  return pairs;
}

std::vector<double> RandomYaws(std::size_t n, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-kPi, kPi);
  std::vector<double> yaw(n);
  for (double& y : yaw) y = u(rng);
  return yaw;
}

TEST(AverageRotationsL1, NoiseFreeCompleteGraphIsExact) {
  std::mt19937 rng(3);
  const std::size_t n = 7;
  const std::vector<double> truth = RandomYaws(n, rng);
  std::vector<RelativeMeasurement> m;
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j) m.push_back(Measure(truth, j, i, 0.0, rng));
  }
  const RotationAveragingResult result = AverageRotationsL1(n, 2, m, {});
  ASSERT_TRUE(result.ok) << result.error;
  EXPECT_LT(MaxYawError(truth, result.yaw_rad, 2), 1e-12);
  EXPECT_EQ(result.yaw_rad[2], 0.0);
  EXPECT_TRUE(result.certified);
  EXPECT_LT(result.l1_cost, 1e-11);
  for (std::size_t e = 0; e < m.size(); ++e) {
    EXPECT_LT(std::abs(result.residual_rad[e]), 1e-12);
    EXPECT_TRUE(result.inlier[e]);
  }
  for (double y : result.yaw_rad) {
    EXPECT_GT(y, -kPi);
    EXPECT_LE(y, kPi);
  }
}

TEST(AverageRotationsL1, HandlesThe2PiWrap) {
  // True yaws on both sides of ±π; the measurements are given as θ + 2π, θ - 2π or θ, and some
  // relative yaws are themselves near ±π.
  const std::vector<double> truth = {DegToRad(179.9),   DegToRad(-179.8), DegToRad(179.5),
                                     DegToRad(-179.95), DegToRad(0.3),    DegToRad(-0.2)};
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0.0, DegToRad(0.05));
  std::vector<RelativeMeasurement> m;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    for (std::size_t j = i + 1; j < truth.size(); ++j)
      m.push_back(Measure(truth, i, j, noise(rng), rng));
  }
  // Exactly π apart (the branch cut of the normalisation) as well.
  m.push_back(Edge(4, 0, truth[4] - truth[0] + 3 * kPi - 3 * kPi));
  const RotationAveragingResult result = AverageRotationsL1(truth.size(), 0, m, {});
  ASSERT_TRUE(result.ok) << result.error;
  EXPECT_LT(MaxYawError(truth, result.yaw_rad, 0), DegToRad(0.2));
  for (std::size_t e = 0; e < m.size(); ++e) {
    EXPECT_LT(std::abs(result.residual_rad[e]), DegToRad(0.3)) << e;
    EXPECT_TRUE(result.inlier[e]);
  }
  // Noise-free: exact.
  for (std::size_t e = 0; e + 1 < m.size(); ++e) {
    const std::size_t r = m[e].r, s = m[e].s;
    m[e].s_from_r.yaw_rad =
        truth[r] - truth[s] + 2 * kPi * static_cast<double>(static_cast<int>(e % 3) - 1);
  }
  const RotationAveragingResult exact = AverageRotationsL1(truth.size(), 0, m, {});
  ASSERT_TRUE(exact.ok);
  EXPECT_LT(MaxYawError(truth, exact.yaw_rad, 0), 1e-12);
}

// A ring with chords (each node linked to the next three: six edges per node) where a third of
// the edges are wrong by 20°-180° (two of each node's six: all links of one ring distance),
// inliers noise-free: L1 recovers the inlier solution exactly and flags exactly the wrong edges.
TEST(AverageRotationsL1, RecoversTheInlierSolutionExactlyWithAThirdOfTheEdgesWrong) {
  for (unsigned seed = 1; seed <= 6; ++seed) {
    std::mt19937 rng(seed);
    const std::size_t n = 18;
    const std::vector<double> truth = RandomYaws(n, rng);
    const std::size_t bad_distance = 1 + seed % 3;
    std::vector<RelativeMeasurement> m;
    std::vector<bool> outlier;
    std::uniform_real_distribution<double> magnitude(DegToRad(20.0), kPi);
    for (const auto& [i, j] : Circulant(n, 3)) {
      const bool bad = (j + n - i) % n == bad_distance;
      const double error = bad ? (rng() % 2 ? 1.0 : -1.0) * magnitude(rng) : 0.0;
      m.push_back(Measure(truth, i, j, error, rng));
      outlier.push_back(bad);
    }
    std::size_t wrong = 0;
    for (bool b : outlier) wrong += b ? 1 : 0;
    ASSERT_EQ(3 * wrong, m.size()) << "test data";

    const RotationAveragingResult result = AverageRotationsL1(n, 0, m, {});
    ASSERT_TRUE(result.ok) << result.error;
    EXPECT_LT(MaxYawError(truth, result.yaw_rad, 0), 1e-9) << "seed " << seed;
    EXPECT_TRUE(result.certified);
    for (std::size_t e = 0; e < m.size(); ++e) EXPECT_EQ(result.inlier[e], !outlier[e]) << e;
  }
}

// The same at 40 %: each node linked to the next five (ten edges per node), all links of two ring
// distances wrong.
TEST(AverageRotationsL1, RecoversTheInlierSolutionExactlyWithFortyPercentOfTheEdgesWrong) {
  for (unsigned seed = 1; seed <= 5; ++seed) {
    std::mt19937 rng(seed);
    const std::size_t n = 22;
    const std::vector<double> truth = RandomYaws(n, rng);
    const std::size_t bad1 = 1 + seed % 5, bad2 = 1 + (seed + 2) % 5;
    std::vector<RelativeMeasurement> m;
    std::vector<bool> outlier;
    std::uniform_real_distribution<double> magnitude(DegToRad(20.0), kPi);
    for (const auto& [i, j] : Circulant(n, 5)) {
      const std::size_t d = (j + n - i) % n;
      const bool bad = d == bad1 || d == bad2;
      const double error = bad ? (rng() % 2 ? 1.0 : -1.0) * magnitude(rng) : 0.0;
      m.push_back(Measure(truth, i, j, error, rng));
      outlier.push_back(bad);
    }
    const RotationAveragingResult result = AverageRotationsL1(n, 0, m, {});
    ASSERT_TRUE(result.ok) << result.error;
    EXPECT_LT(MaxYawError(truth, result.yaw_rad, 0), 1e-9) << "seed " << seed;
    for (std::size_t e = 0; e < m.size(); ++e) EXPECT_EQ(result.inlier[e], !outlier[e]) << e;
  }
}

// Noise, 30 % outliers and random weights on a larger graph: the node form's cost and yaws equal
// the exact LP optimum (Clp) of the same node-angle problem (offsets as found), and the dual
// bound certifies it.
TEST(AverageRotationsL1, EqualsTheExactLpOptimum) {
  for (unsigned seed = 1; seed <= 4; ++seed) {
    std::mt19937 rng(100 + seed);
    const std::size_t n = 30;
    const std::vector<double> truth = RandomYaws(n, rng);
    std::normal_distribution<double> noise(0.0, DegToRad(0.5));
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::vector<RelativeMeasurement> m;
    for (const auto& [i, j] : Circulant(n, 4)) {
      const double error = u(rng) < 0.3 ? 2 * kPi * u(rng) : noise(rng);
      m.push_back(Measure(truth, i, j, error, rng));
      m.back().weight = 0.5 + 2.0 * u(rng);
    }
    RotationAveragingOptions options;
    options.use_weights = true;
    const RotationAveragingResult result = AverageRotationsL1(n, 0, m, options);
    ASSERT_TRUE(result.ok) << result.error;
    EXPECT_TRUE(result.certified);
    EXPECT_LE(result.l1_lower_bound, result.l1_cost * (1 + 1e-12));
    EXPECT_GE(result.l1_lower_bound, result.l1_cost * (1 - 1e-6));

    // The node form as an LP: rows φ_r - φ_s = b_e (b_e in the solution's 2π branch), the
    // reference fixed by leaving out its column.
    std::vector<Eigen::Triplet<double>> triplets;
    Eigen::VectorXd b(static_cast<Eigen::Index>(m.size())), w(b.size());
    auto column = [&](std::size_t v) { return static_cast<Eigen::Index>(v) - 1; };
    for (std::size_t e = 0; e < m.size(); ++e) {
      const auto row = static_cast<Eigen::Index>(e);
      if (m[e].r != 0) triplets.emplace_back(row, column(m[e].r), 1.0);
      if (m[e].s != 0) triplets.emplace_back(row, column(m[e].s), -1.0);
      b(row) = result.yaw_rad[m[e].r] - result.yaw_rad[m[e].s] - result.residual_rad[e];
      w(row) = m[e].weight;
    }
    Eigen::SparseMatrix<double> a(b.size(), static_cast<Eigen::Index>(n - 1));
    a.setFromTriplets(triplets.begin(), triplets.end());
    const LpL1Result lp = SolveL1ByLp(a, b, w, {});
    ASSERT_TRUE(lp.ok) << lp.error;
    EXPECT_NEAR(result.l1_cost, lp.cost, 1e-6 * lp.cost) << "seed " << seed;
    for (std::size_t v = 1; v < n; ++v) {
      EXPECT_NEAR(AngleDiff(result.yaw_rad[v], lp.x(column(v))), 0.0, 1e-8) << v;
    }
  }
}

TEST(AverageRotationsL1, WeightsDecideBetweenDisagreeingMeasurements) {
  // Nodes 0, 1, 2 fixed by heavy consistent edges at yaw 0; node 3 is measured at 0 from nodes 0
  // and 1 (weight 1 each) and at 0.5 rad from node 2 (weight 5).
  std::vector<RelativeMeasurement> m = {Edge(1, 0, 0.0, 10.0), Edge(2, 0, 0.0, 10.0),
                                        Edge(2, 1, 0.0, 10.0), Edge(3, 0, 0.0, 1.0),
                                        Edge(3, 1, 0.0, 1.0),  Edge(3, 2, 0.5, 5.0)};
  RotationAveragingOptions options;
  const RotationAveragingResult uniform = AverageRotationsL1(4, 0, m, options);
  ASSERT_TRUE(uniform.ok);
  EXPECT_NEAR(uniform.yaw_rad[3], 0.0, 1e-12);
  EXPECT_FALSE(uniform.inlier[5]);
  options.use_weights = true;
  const RotationAveragingResult weighted = AverageRotationsL1(4, 0, m, options);
  ASSERT_TRUE(weighted.ok);
  EXPECT_NEAR(weighted.yaw_rad[3], 0.5, 1e-12);
  EXPECT_FALSE(weighted.inlier[3]);
  EXPECT_FALSE(weighted.inlier[4]);
  EXPECT_TRUE(weighted.inlier[5]);
  EXPECT_NEAR(weighted.l1_cost, 1.0, 1e-12);  // two unit-weight edges, 0.5 rad each
}

TEST(AverageRotationsL1, OutlierThresholdDecidesTheFlags) {
  // A triangle plus a fourth node: the edge 2-0 is off by 3°.
  const std::vector<RelativeMeasurement> m = {Edge(1, 0, 0.0), Edge(2, 1, 0.0),
                                              Edge(2, 0, DegToRad(3.0)), Edge(3, 2, 0.0),
                                              Edge(3, 0, 0.0)};
  RotationAveragingOptions options;
  options.outlier_threshold_deg = 5.0;
  const RotationAveragingResult loose = AverageRotationsL1(4, 0, m, options);
  ASSERT_TRUE(loose.ok);
  EXPECT_NEAR(std::abs(loose.residual_rad[2]), DegToRad(3.0), 1e-12);
  EXPECT_TRUE(loose.inlier[2]);
  options.outlier_threshold_deg = 2.0;
  const RotationAveragingResult strict = AverageRotationsL1(4, 0, m, options);
  ASSERT_TRUE(strict.ok);
  EXPECT_FALSE(strict.inlier[2]);
  EXPECT_EQ(std::count(strict.inlier.begin(), strict.inlier.end(), false), 1);
}

TEST(AverageRotationsL1, YawSigmaFollowsTheLeastSquaresCovariance) {
  // A chain 0-1-2 has no redundancy: σ from the prior, growing along the chain.
  RotationAveragingOptions options;
  options.prior_sigma_deg = 2.0;
  const RotationAveragingResult chain =
      AverageRotationsL1(3, 0, {Edge(1, 0, 0.1), Edge(2, 1, 0.2)}, options);
  ASSERT_TRUE(chain.ok);
  EXPECT_EQ(chain.yaw_sigma_rad[0], 0.0);
  EXPECT_NEAR(chain.yaw_sigma_rad[1], DegToRad(2.0), 1e-12);
  EXPECT_NEAR(chain.yaw_sigma_rad[2], DegToRad(2.0) * std::sqrt(2.0), 1e-12);

  // Complete graph of n nodes, noise σ: the reduced Laplacian's inverse has 2/n on the diagonal,
  // so σ_v ≈ σ sqrt(2/n), with σ estimated from the residuals.
  std::mt19937 rng(5);
  const std::size_t n = 10;
  const std::vector<double> truth = RandomYaws(n, rng);
  for (double sigma_deg : {0.5, 2.0}) {
    std::normal_distribution<double> noise(0.0, DegToRad(sigma_deg));
    std::vector<RelativeMeasurement> m;
    for (std::size_t i = 0; i < n; ++i) {
      for (std::size_t j = i + 1; j < n; ++j) m.push_back(Measure(truth, i, j, noise(rng), rng));
    }
    const RotationAveragingResult result = AverageRotationsL1(n, 0, m, {});
    ASSERT_TRUE(result.ok);
    const double expected = DegToRad(sigma_deg) * std::sqrt(2.0 / static_cast<double>(n));
    for (std::size_t v = 1; v < n; ++v) {
      EXPECT_GT(result.yaw_sigma_rad[v], 0.7 * expected) << sigma_deg;
      EXPECT_LT(result.yaw_sigma_rad[v], 1.4 * expected) << sigma_deg;
    }
  }
}

TEST(AverageRotationsL1, ReportsADisconnectedGraphNamingTheNodes) {
  const std::vector<RelativeMeasurement> m = {Edge(1, 0, 0.1), Edge(2, 1, 0.1), Edge(4, 3, 0.2)};
  const RotationAveragingResult result = AverageRotationsL1(6, 0, m, {});
  EXPECT_FALSE(result.ok);
  EXPECT_EQ(result.error, "nodes 3, 4, 5 are not connected to the reference node 0");
}

TEST(AverageRotationsL1, RejectsBadInputWithAReason) {
  const std::vector<RelativeMeasurement> one = {Edge(1, 0, 0.1)};
  EXPECT_NE(AverageRotationsL1(0, 0, {}, {}).error.find("at least 2 nodes"), std::string::npos);
  EXPECT_NE(AverageRotationsL1(1, 0, {}, {}).error.find("at least 2 nodes"), std::string::npos);
  EXPECT_NE(AverageRotationsL1(2, 5, one, {}).error.find("reference node 5 out of range"),
            std::string::npos);
  std::vector<RelativeMeasurement> nan = {Edge(1, 0, 0.1),
                                          Edge(1, 0, std::numeric_limits<double>::quiet_NaN())};
  const RotationAveragingResult result = AverageRotationsL1(2, 0, nan, {});
  EXPECT_FALSE(result.ok);
  EXPECT_NE(result.error.find("measurement 1"), std::string::npos);
  EXPECT_NE(result.error.find("not finite"), std::string::npos);
  RotationAveragingOptions options;
  options.initial_yaw_rad = {0.0, 0.0, 0.0};
  EXPECT_NE(AverageRotationsL1(2, 0, one, options).error.find("initial_yaw_rad has 3 values"),
            std::string::npos);
  options.initial_yaw_rad.clear();
  options.irls_epsilon = 0.0;
  EXPECT_NE(AverageRotationsL1(2, 0, one, options).error.find("invalid options"),
            std::string::npos);
  // A huge (finite) representative of the angle is still that angle.
  const RotationAveragingResult huge =
      AverageRotationsL1(2, 0, {Edge(1, 0, 0.25 + 2 * kPi * 1e6)}, {});
  ASSERT_TRUE(huge.ok);
  EXPECT_NEAR(huge.yaw_rad[1], 0.25, 1e-8);
  // Two nodes, one measurement: the trivial answer.
  const RotationAveragingResult two = AverageRotationsL1(2, 0, one, {});
  ASSERT_TRUE(two.ok);
  EXPECT_NEAR(two.yaw_rad[1], 0.1, 1e-15);
}

TEST(RotationAveragingOptions, ValidateNamesTheBadField) {
  EXPECT_FALSE(Validate(RotationAveragingOptions{}).has_value());
  auto check = [](auto mutate, const char* field) {
    RotationAveragingOptions o;
    mutate(o);
    const auto error = Validate(o);
    ASSERT_TRUE(error.has_value()) << field;
    EXPECT_NE(error->find(field), std::string::npos) << *error;
  };
  check([](auto& o) { o.irls_epsilon = -1.0; }, "irls_epsilon");
  check([](auto& o) { o.initial_epsilon = 1e-12; }, "initial_epsilon");
  check([](auto& o) { o.epsilon_factor = 0.0; }, "epsilon_factor");
  check([](auto& o) { o.max_iterations = 0; }, "max_iterations");
  check([](auto& o) { o.max_offset_rounds = 0; }, "max_offset_rounds");
  check([](auto& o) { o.tolerance = std::numeric_limits<double>::quiet_NaN(); }, "tolerance");
  check([](auto& o) { o.outlier_threshold_deg = 0.0; }, "outlier_threshold_deg");
  check([](auto& o) { o.prior_sigma_deg = 0.0; }, "prior_sigma_deg");
  check(
      [](auto& o) {
        o.initial_yaw_rad = {0.0, std::numeric_limits<double>::infinity()};
      },
      "initial_yaw_rad");
}

TEST(ConsistentTriangles, AnOutlierClosesNoTriangle) {
  // K4 with the edge 3-2 wrong by 40°.
  const std::vector<double> truth = {0.0, 1.0, -2.0, 3.0};
  std::mt19937 rng(1);
  std::vector<RelativeMeasurement> m;
  for (std::size_t i = 0; i < 4; ++i) {
    for (std::size_t j = i + 1; j < 4; ++j) {
      m.push_back(Measure(truth, j, i, (i == 2 && j == 3) ? DegToRad(40.0) : 0.0, rng));
    }
  }
  const std::vector<std::size_t> count = ConsistentTriangles(4, m, DegToRad(5.0));
  // Edges (0,1) (0,2) (0,3) (1,2) (1,3) (2,3): the triangles without (2,3) are 012 and 013.
  EXPECT_EQ(count, (std::vector<std::size_t>{2, 1, 1, 1, 1, 0}));
}

// 100 sensors, each linked to its 4 nearest on either side of a ring, 20 % outliers: completes
// (certified) and is about as accurate as least squares on the true inliers alone.
TEST(AverageRotationsL1, HundredSensorsComplete) {
  std::mt19937 rng(7);
  const std::size_t n = 100;
  const std::vector<double> truth = RandomYaws(n, rng);
  std::normal_distribution<double> noise(0.0, DegToRad(0.5));
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<RelativeMeasurement> m, inliers;
  for (const auto& [i, j] : Circulant(n, 4)) {
    const bool bad = u(rng) < 0.2;
    m.push_back(Measure(truth, i, j, bad ? 2 * kPi * u(rng) : noise(rng), rng));
    if (!bad) inliers.push_back(m.back());
  }
  const RotationAveragingResult result = AverageRotationsL1(n, 0, m, {});
  ASSERT_TRUE(result.ok) << result.error;
  EXPECT_TRUE(result.certified);
  // Least squares on the true inliers, for comparison.
  const std::vector<double> oracle = LeastSquaresYaws(n, 0, inliers, false, truth);
  auto rms = [&](const std::vector<double>& yaw) {
    double sum = 0.0;
    for (std::size_t v = 0; v < n; ++v) sum += std::pow(AngleDiff(yaw[v], truth[v] - truth[0]), 2);
    return std::sqrt(sum / static_cast<double>(n));
  };
  std::printf("rms yaw error: L1 %.3f°, least squares on the true inliers %.3f°\n",
              common::RadToDeg(rms(result.yaw_rad)), common::RadToDeg(rms(oracle)));
  EXPECT_LT(rms(result.yaw_rad), 1.5 * rms(oracle));
  // Least squares on the edges L1 found to be inliers: as good as knowing them.
  RotationAveragingOptions options;
  options.inlier_least_squares = true;
  const RotationAveragingResult polished = AverageRotationsL1(n, 0, m, options);
  ASSERT_TRUE(polished.ok);
  std::printf("with inlier_least_squares: %.3f°\n", common::RadToDeg(rms(polished.yaw_rad)));
  EXPECT_LT(rms(polished.yaw_rad), 1.1 * rms(oracle));
}

}  // namespace
}  // namespace lrfnet::calib
