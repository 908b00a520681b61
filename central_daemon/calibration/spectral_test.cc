#include "central_daemon/calibration/spectral.h"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <complex>
#include <random>

namespace lrfnet::calib {
namespace {

using common::AngleDiff;
using common::DegToRad;
using common::kPi;

RelativeMeasurement Measure(const std::vector<double>& truth, std::size_t r, std::size_t s,
                            double error_rad, double weight = 1.0) {
  RelativeMeasurement m;
  m.r = r;
  m.s = s;
  m.s_from_r.yaw_rad = truth[r] - truth[s] + error_rad;
  m.weight = weight;
  return m;
}

std::vector<double> SpectralRandomYaws(std::size_t n, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-kPi, kPi);
  std::vector<double> yaw(n);
  for (double& y : yaw) y = u(rng);
  return yaw;
}

double MaxYawError(const std::vector<double>& truth, const std::vector<double>& yaw) {
  double worst = 0.0;
  for (std::size_t v = 0; v < truth.size(); ++v) {
    worst = std::max(worst, std::abs(AngleDiff(yaw[v], truth[v] - truth[0])));
  }
  return worst;
}

TEST(AverageRotationsSpectral, RecoversNoiseFreeGraphsExactly) {
  std::mt19937 rng(2);
  // A plain cycle of 40 (the smallest spectral gap of these), a ring with chords, a complete graph.
  for (std::size_t k : {1u, 3u, 20u}) {
    const std::size_t n = 40;
    const std::vector<double> truth = SpectralRandomYaws(n, rng);
    std::vector<RelativeMeasurement> m;
    for (std::size_t i = 0; i < n; ++i) {
      for (std::size_t d = 1; d <= k; ++d) {
        if (k == 20 && d == 20 && i >= 20) continue;  // each pair once
        m.push_back(Measure(truth, (i + d) % n, i, 2 * kPi * static_cast<double>(i % 2)));
      }
    }
    const RotationAveragingResult result = AverageRotationsSpectral(n, 0, m, false);
    ASSERT_TRUE(result.ok) << result.error;
    EXPECT_LT(MaxYawError(truth, result.yaw_rad), 1e-9) << "k = " << k;
    EXPECT_EQ(result.yaw_rad[0], 0.0);
    for (std::size_t e = 0; e < m.size(); ++e) EXPECT_TRUE(result.inlier[e]);
  }
}

// The Krylov solver gives the eigenvector a dense eigensolver gives.
TEST(AverageRotationsSpectral, MatchesADenseEigensolver) {
  for (unsigned seed = 1; seed <= 5; ++seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    const std::size_t n = 25;
    const std::vector<double> truth = SpectralRandomYaws(n, rng);
    std::vector<RelativeMeasurement> m;
    for (std::size_t i = 0; i < n; ++i) {
      for (std::size_t j = i + 1; j < n; ++j) {
        if (j != i + 1 && u(rng) > 0.3) continue;
        m.push_back(Measure(truth, j, i, u(rng) < 0.2 ? 2 * kPi * u(rng) : 0.05 * (u(rng) - 0.5),
                            0.5 + u(rng)));
      }
    }
    Eigen::MatrixXcd h =
        Eigen::MatrixXcd::Zero(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(n));
    for (const RelativeMeasurement& e : m) {
      const auto r = static_cast<Eigen::Index>(e.r), s = static_cast<Eigen::Index>(e.s);
      h(r, s) += std::polar(e.weight, e.s_from_r.yaw_rad);
      h(s, r) += std::polar(e.weight, -e.s_from_r.yaw_rad);
    }
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXcd> eig(h);
    const Eigen::VectorXcd top = eig.eigenvectors().col(static_cast<Eigen::Index>(n) - 1);
    const std::vector<double> yaw = SpectralYaws(n, 0, m, true);
    for (std::size_t v = 0; v < n; ++v) {
      const double dense = std::arg(top(static_cast<Eigen::Index>(v)) * std::conj(top(0)));
      EXPECT_NEAR(AngleDiff(yaw[v], dense), 0.0, 1e-8) << "seed " << seed << " node " << v;
    }
  }
}

// Outliers pull on every yaw: with a third of the edges wrong (the data on which L1 recovers the
// inliers exactly, rotation_averaging_test.cc) the spectral yaws are degrees off, L1's exact.
TEST(AverageRotationsSpectral, DegradesWithOutliersWhereL1IsExact) {
  std::mt19937 rng(4);
  const std::size_t n = 18;
  const std::vector<double> truth = SpectralRandomYaws(n, rng);
  std::uniform_real_distribution<double> magnitude(DegToRad(20.0), kPi);
  std::vector<RelativeMeasurement> m;
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t d = 1; d <= 3; ++d) {
      const double error = d == 2 ? (rng() % 2 ? 1.0 : -1.0) * magnitude(rng) : 0.0;
      m.push_back(Measure(truth, i, (i + d) % n, error));
    }
  }
  const RotationAveragingResult spectral = AverageRotationsSpectral(n, 0, m, false);
  const RotationAveragingResult l1 = AverageRotationsL1(n, 0, m, {});
  ASSERT_TRUE(spectral.ok);
  ASSERT_TRUE(l1.ok);
  EXPECT_GT(MaxYawError(truth, spectral.yaw_rad), DegToRad(2.0));
  EXPECT_LT(MaxYawError(truth, l1.yaw_rad), 1e-9);
  EXPECT_GT(spectral.l1_cost, l1.l1_cost);

  // Weights that trust the inliers (e.g. Schenk's N/d) bring the spectral yaws closer.
  for (std::size_t e = 0; e < m.size(); ++e) m[e].weight = e % 3 == 1 ? 0.05 : 1.0;
  const RotationAveragingResult weighted = AverageRotationsSpectral(n, 0, m, true);
  ASSERT_TRUE(weighted.ok);
  EXPECT_LT(MaxYawError(truth, weighted.yaw_rad), 0.5 * MaxYawError(truth, spectral.yaw_rad));
}

TEST(AverageRotationsSpectral, ReportsBadInputAndDisconnectedGraphs) {
  std::vector<RelativeMeasurement> m(2);
  m[0].r = 1;
  m[0].s = 0;
  m[1].r = 3;
  m[1].s = 2;
  const RotationAveragingResult result = AverageRotationsSpectral(4, 0, m, false);
  EXPECT_FALSE(result.ok);
  EXPECT_EQ(result.error, "nodes 2, 3 are not connected to the reference node 0");
  EXPECT_FALSE(AverageRotationsSpectral(1, 0, {}, false).ok);
  m[1].s_from_r.yaw_rad = std::nan("");
  EXPECT_NE(AverageRotationsSpectral(4, 0, m, false).error.find("not finite"), std::string::npos);
}

}  // namespace
}  // namespace lrfnet::calib
