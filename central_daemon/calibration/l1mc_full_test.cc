// The paper's full formulation (Algorithm 1) against the production node-angle form, both checked
// with an exact LP (Clp).
//
// What is equivalent, and in what sense (see also rotation_averaging.h):
//  * Hard form: with the inverse (eq. 20) and transitivity (eq. 21) rows as equality constraints
//    and consistent 2π offsets b_t, every feasible x is x_ij = φ_j - φ_i + 2π m_ij for node angles
//    φ and fixed integers m (the triangles of the complete graph generate its cycle space), so
//    min ||A_m x - b_m||_1 over them is the node form min Σ w_e |φ_r - φ_s - b̃_e| with the offsets
//    of b̃_e fixed by the b_t. The node form fixes its offsets by normalising against its own
//    solution; when the two agree the optima coincide: the same cost, the same yaws where the
//    optimum is unique (generic weights), and the node-form yaws optimal for the full form where it
//    is not (unit weights: an L1 optimum often is a whole face, e.g. a node held by an even
//    number of edges, half on either side).
//  * Consistency of the b_t: the paper normalises each triangle's sum on its own. Noise-free
//    triangles (and triangles with one outlier whose error is not near ±π) normalise consistently,
//    but two outliers in a triangle whose errors add up beyond π, or an outlier error near ±π
//    plus noise, make neighbouring triangles pick different 2π branches; then no x satisfies all
//    transitivity rows: the hard form is infeasible (offsets_consistent = false, and Clp agrees).
//    The node form has no such failure: its offsets come from one solution, so they are
//    consistent by construction.
//  * Soft form (the paper's literal min ||A x - b||_1, every row weighted like a measurement):
//    an exact penalty of the hard form as long as the constraint rows can carry the measurements'
//    pull at unit multipliers. With unit weights and consistent offsets the optimal cost equals the
//    hard form's in these tests; with measurement weights above 1 (Schenk's N/d weights are
//    typically much larger) it is cheaper to break a transitivity row than to leave a heavy
//    measurement's residual, the constraints stop holding and an outlier on an edge at the
//    reference goes straight into the extracted yaw. Where the offsets are inconsistent it pays 2π
//    on the inconsistent rows and its yaws are pulled accordingly.

#include "central_daemon/calibration/l1mc_full.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <random>

#include "central_daemon/calibration/clp_oracle.h"
#include "central_daemon/calibration/rotation_averaging.h"

namespace lrfnet::calib {
namespace {

using common::AngleDiff;
using common::DegToRad;
using common::kPi;

struct Case {
  std::size_t n = 0;
  std::vector<double> truth;
  std::vector<RelativeMeasurement> m;
};

// 4-8 sensors with yaws near ±π and 0 (relative yaws near 0 and ±π), a path plus random chords,
// 1° noise, a quarter of the edges wrong by 0.5-3 rad, every measurement in a random 2π
// representative; random weights or unit weights.
Case RandomCase(unsigned seed, bool random_weights) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> noise(0.0, DegToRad(1.0));
  Case c;
  c.n = 4 + rng() % 5;
  for (std::size_t v = 0; v < c.n; ++v) {
    const double base = std::array<double, 3>{kPi, -kPi, 0.0}[rng() % 3];
    c.truth.push_back(common::NormalizeAngle(base + (u(rng) - 0.5) * 0.3));
  }
  for (std::size_t i = 0; i < c.n; ++i) {
    for (std::size_t j = i + 1; j < c.n; ++j) {
      if (j != i + 1 && u(rng) > 0.6) continue;
      RelativeMeasurement m;
      m.r = u(rng) < 0.5 ? i : j;
      m.s = m.r == i ? j : i;
      double theta = c.truth[m.r] - c.truth[m.s] + noise(rng);
      if (u(rng) < 0.25) theta += (u(rng) < 0.5 ? -1 : 1) * (0.5 + 2.5 * u(rng));
      theta += 2 * kPi * static_cast<double>(static_cast<int>(rng() % 3) - 1);
      m.s_from_r.yaw_rad = theta;
      m.weight = random_weights ? 0.5 + 1.5 * u(rng) : 1.0;
      c.m.push_back(m);
    }
  }
  return c;
}

TEST(L1mcFull, SizeGrowsWithAllTriangles) {
  const L1mcFullSize size = L1mcFullSizeOf(100, 300);
  EXPECT_EQ(size.triangles, 161700u);  // the count at 100 sensors
  EXPECT_EQ(size.unknowns, 9900u);
  EXPECT_EQ(size.rows, 300u + 4950u + 161700u);
  EXPECT_EQ(size.nonzeros, 300u + 2u * 4950u + 3u * 161700u);
  const Case c = RandomCase(1, false);
  const L1mcFull full = BuildL1mcFull(c.n, c.m, SpanningTreeYaws(c.n, 0, c.m), false);
  const L1mcFullSize expected = L1mcFullSizeOf(c.n, c.m.size());
  EXPECT_EQ(static_cast<std::size_t>(full.a.rows()), expected.rows);
  EXPECT_EQ(static_cast<std::size_t>(full.a.cols()), expected.unknowns);
  EXPECT_EQ(static_cast<std::size_t>(full.a.nonZeros()), expected.nonzeros);
}

TEST(L1mcFull, RowsFollowAlgorithm1) {
  // Noise-free, yaws on both sides of ±π, measurements in other 2π representatives.
  const std::vector<double> truth = {0.0, DegToRad(179.0), DegToRad(-178.0), DegToRad(20.0)};
  std::vector<RelativeMeasurement> m(3);
  m[0].r = 1, m[0].s = 0, m[0].s_from_r.yaw_rad = truth[1] - truth[0] + 2 * kPi;
  m[1].r = 1, m[1].s = 2, m[1].s_from_r.yaw_rad = truth[1] - truth[2] - 2 * kPi;
  m[2].r = 3, m[2].s = 2, m[2].s_from_r.yaw_rad = truth[3] - truth[2];
  const L1mcFull full = BuildL1mcFull(4, m, SpanningTreeYaws(4, 0, m), false);
  EXPECT_EQ(full.measurement_rows, 3u);
  EXPECT_EQ(full.inverse_rows, 6u);
  EXPECT_EQ(full.transitivity_rows, 4u);
  const Eigen::MatrixXd a(full.a);
  // eq. 19: x_sr = normalize(θ).
  EXPECT_EQ(a(0, static_cast<Eigen::Index>(full.Unknown(0, 1))), 1.0);
  EXPECT_EQ(a.row(0).cwiseAbs().sum(), 1.0);
  EXPECT_NEAR(full.b(0), common::NormalizeAngle(truth[1] - truth[0]), 1e-15);
  // eq. 20: x_01 + x_10 = 0.
  EXPECT_EQ(a(3, static_cast<Eigen::Index>(full.Unknown(0, 1))), 1.0);
  EXPECT_EQ(a(3, static_cast<Eigen::Index>(full.Unknown(1, 0))), 1.0);
  // eq. 21 for (0, 1, 2): x_01 + x_12 - x_02.
  EXPECT_EQ(a(9, static_cast<Eigen::Index>(full.Unknown(0, 1))), 1.0);
  EXPECT_EQ(a(9, static_cast<Eigen::Index>(full.Unknown(1, 2))), 1.0);
  EXPECT_EQ(a(9, static_cast<Eigen::Index>(full.Unknown(0, 2))), -1.0);
  // The start x' (wrapped true relative yaws) satisfies every row; b_t holds the 2π offsets.
  EXPECT_TRUE(full.offsets_consistent);
  EXPECT_LT((full.a * full.start - full.b).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_NEAR(std::abs(full.b(9)), 2 * kPi, 1e-12);  // 179° + 3° - (-178°) wraps
  const std::vector<double> yaw = YawsFromL1mc(full, full.start, 0);
  for (std::size_t v = 0; v < 4; ++v) EXPECT_NEAR(AngleDiff(yaw[v], truth[v]), 0.0, 1e-12);
}

// The equivalence on random graphs, against the exact LP of the full formulation.
TEST(L1mcFull, HardFormEqualsTheNodeFormOnRandomGraphs) {
  int consistent = 0, unique_compared = 0;
  for (unsigned seed = 1; seed <= 80; ++seed) {
    const bool random_weights = seed % 2 == 0;
    const Case c = RandomCase(seed, random_weights);
    RotationAveragingOptions options;
    options.use_weights = random_weights;
    const RotationAveragingResult node = AverageRotationsL1(c.n, 0, c.m, options);
    ASSERT_TRUE(node.ok) << node.error;
    const L1mcFull full = BuildL1mcFull(c.n, c.m, SpanningTreeYaws(c.n, 0, c.m), random_weights);
    const std::vector<bool> hard = full.ConstraintRows();
    const LpL1Result lp = SolveL1ByLp(full.a, full.b, full.weight, hard);
    ASSERT_EQ(lp.ok, full.offsets_consistent) << "seed " << seed << ": " << lp.error;
    if (!lp.ok) {
      EXPECT_TRUE(lp.infeasible) << "seed " << seed;
      continue;
    }
    ++consistent;
    // The same optimal cost (the node form's tie-break moves it by at most 1e-6 relative).
    EXPECT_NEAR(node.l1_cost, lp.cost, 1e-6 * lp.cost + 1e-9) << "seed " << seed;
    const std::vector<double> lp_yaw = YawsFromL1mc(full, lp.x, 0);
    if (random_weights) {
      ++unique_compared;
      for (std::size_t v = 0; v < c.n; ++v) {
        EXPECT_NEAR(AngleDiff(node.yaw_rad[v], lp_yaw[v]), 0.0, 1e-6) << "seed " << seed;
      }
    }
    // The node-form yaws, carried into the full form (x_ij of the LP solution moved by the yaw
    // differences), satisfy the constraint rows and attain the LP optimum.
    Eigen::VectorXd x = lp.x;
    for (std::size_t i = 0; i < c.n; ++i) {
      for (std::size_t j = 0; j < c.n; ++j) {
        if (i == j) continue;
        const double di = AngleDiff(node.yaw_rad[i], lp_yaw[i]);
        const double dj = AngleDiff(node.yaw_rad[j], lp_yaw[j]);
        x(static_cast<Eigen::Index>(full.Unknown(i, j))) += dj - di;
      }
    }
    const Eigen::VectorXd r = full.a * x - full.b;
    double cost = 0.0;
    for (Eigen::Index row = 0; row < r.size(); ++row) {
      if (hard[static_cast<std::size_t>(row)]) {
        EXPECT_NEAR(r(row), 0.0, 1e-9) << "seed " << seed;
      } else {
        cost += full.weight(row) * std::abs(r(row));
      }
    }
    EXPECT_NEAR(cost, lp.cost, 1e-6 * lp.cost + 1e-9) << "seed " << seed;
  }
  // The test exercised the equivalence (the rest had inconsistent offsets).
  std::printf("80 random graphs: %d with consistent offsets, %d of them with generic weights\n",
              consistent, unique_compared);
  EXPECT_GE(consistent, 40);
  EXPECT_GE(unique_compared, 20);
}

TEST(L1mcFull, SoftFormWithUnitWeightsHasTheHardFormsCost) {
  int compared = 0;
  for (unsigned seed = 1; seed <= 80; seed += 2) {
    const Case c = RandomCase(seed, false);
    const L1mcFull full = BuildL1mcFull(c.n, c.m, SpanningTreeYaws(c.n, 0, c.m), false);
    if (!full.offsets_consistent) continue;
    const LpL1Result hard = SolveL1ByLp(full.a, full.b, full.weight, full.ConstraintRows());
    const LpL1Result soft = SolveL1ByLp(full.a, full.b, full.weight, {});
    ASSERT_TRUE(hard.ok && soft.ok);
    EXPECT_NEAR(soft.cost, hard.cost, 1e-9 * hard.cost + 1e-9) << "seed " << seed;
    ++compared;
  }
  EXPECT_GE(compared, 20);
}

TEST(L1mcFull, SoftFormWithHeavyMeasurementsLetsAnOutlierThrough) {
  // K4, all yaws 0, the measurement of (1, 0) wrong by 1 rad; every weight 3.
  std::vector<RelativeMeasurement> m;
  for (std::size_t i = 0; i < 4; ++i) {
    for (std::size_t j = i + 1; j < 4; ++j) {
      RelativeMeasurement e;
      e.r = j;
      e.s = i;
      e.s_from_r.yaw_rad = (i == 0 && j == 1) ? 1.0 : 0.0;
      e.weight = 3.0;
      m.push_back(e);
    }
  }
  RotationAveragingOptions options;
  options.use_weights = true;
  const RotationAveragingResult node = AverageRotationsL1(4, 0, m, options);
  ASSERT_TRUE(node.ok);
  for (double yaw : node.yaw_rad) EXPECT_NEAR(yaw, 0.0, 1e-12);  // the outlier is rejected
  EXPECT_NEAR(node.l1_cost, 3.0, 1e-9);
  const L1mcFull full = BuildL1mcFull(4, m, SpanningTreeYaws(4, 0, m), true);
  const LpL1Result hard = SolveL1ByLp(full.a, full.b, full.weight, full.ConstraintRows());
  const LpL1Result soft = SolveL1ByLp(full.a, full.b, full.weight, {});
  ASSERT_TRUE(hard.ok && soft.ok);
  EXPECT_NEAR(hard.cost, 3.0, 1e-9);
  EXPECT_NEAR(YawsFromL1mc(full, hard.x, 0)[1], 0.0, 1e-9);
  // Soft: breaking the two transitivity rows through (0, 1) (weight 1 each) is cheaper than the
  // heavy measurement's residual, and the outlier becomes node 1's yaw.
  EXPECT_NEAR(soft.cost, 2.0, 1e-9);
  EXPECT_NEAR(YawsFromL1mc(full, soft.x, 0)[1], 1.0, 1e-9);
}

// The generic IRLS (used by the benchmark on the full formulation) reaches the LP optimum of the
// soft form, and its dual bound brackets it.
TEST(L1mcFull, IrlsReachesTheLpOptimumOfTheSoftForm) {
  for (unsigned seed = 2; seed <= 12; seed += 2) {
    const Case c = RandomCase(seed, true);
    const L1mcFull full = BuildL1mcFull(c.n, c.m, SpanningTreeYaws(c.n, 0, c.m), true);
    const LpL1Result lp = SolveL1ByLp(full.a, full.b, full.weight, {});
    ASSERT_TRUE(lp.ok);
    L1IrlsOptions options;
    options.tolerance = 1e-7;
    options.max_iterations = 200;
    const L1IrlsResult irls = SolveL1Irls(full.a, full.b, full.weight, full.start, options);
    ASSERT_TRUE(irls.ok);
    EXPECT_TRUE(irls.exact) << "seed " << seed;
    EXPECT_NEAR(irls.cost, lp.cost, 1e-6 * lp.cost) << "seed " << seed;
    EXPECT_LE(irls.lower_bound, lp.cost * (1 + 1e-9) + 1e-12);
    EXPECT_GE(irls.lower_bound, lp.cost * (1 - 1e-6));
  }
}

TEST(L1mcFull, InconsistentTriangleOffsetsMakeTheHardFormInfeasible) {
  // K4, all yaws 0; the measurement of (1, 0) wrong by 179.5°, and ±1° on two other edges, so the
  // two triangles through (0, 1) sum to 180.5° and 178.5°: normalised into different 2π branches.
  std::vector<RelativeMeasurement> m;
  auto add = [&](std::size_t r, std::size_t s, double yaw_deg) {
    RelativeMeasurement e;
    e.r = r;
    e.s = s;
    e.s_from_r.yaw_rad = DegToRad(yaw_deg);
    m.push_back(e);
  };
  add(1, 0, 179.5);
  add(2, 0, 0.0);
  add(2, 1, 1.0);
  add(3, 0, 0.0);
  add(3, 1, -1.0);
  add(3, 2, 0.0);
  const L1mcFull full = BuildL1mcFull(4, m, SpanningTreeYaws(4, 0, m), false);
  EXPECT_FALSE(full.offsets_consistent);
  const LpL1Result hard = SolveL1ByLp(full.a, full.b, full.weight, full.ConstraintRows());
  EXPECT_FALSE(hard.ok);
  EXPECT_TRUE(hard.infeasible);
  // The node form is not affected: the outlier is rejected, the others agree within 1°.
  const RotationAveragingResult node = AverageRotationsL1(4, 0, m, {});
  ASSERT_TRUE(node.ok);
  for (double yaw : node.yaw_rad) EXPECT_LE(std::abs(yaw), DegToRad(1.0) + 1e-12);
  EXPECT_FALSE(node.inlier[0]);
}

}  // namespace
}  // namespace lrfnet::calib
