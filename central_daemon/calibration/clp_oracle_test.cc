#include "central_daemon/calibration/clp_oracle.h"

#include <gtest/gtest.h>

namespace lrfnet::calib {
namespace {

Eigen::SparseMatrix<double> Dense(const Eigen::MatrixXd& m) { return m.sparseView(); }

TEST(SolveL1ByLp, WeightedMedianOfOneUnknown) {
  // min Σ w_i |x - b_i|: the weighted median.
  const Eigen::MatrixXd a = Eigen::MatrixXd::Ones(3, 1);
  const Eigen::Vector3d b(1.0, 2.0, 10.0);
  const LpL1Result unit = SolveL1ByLp(Dense(a), b, Eigen::Vector3d::Ones(), {});
  ASSERT_TRUE(unit.ok) << unit.error;
  EXPECT_NEAR(unit.x(0), 2.0, 1e-9);
  EXPECT_NEAR(unit.cost, 9.0, 1e-9);
  const LpL1Result weighted = SolveL1ByLp(Dense(a), b, Eigen::Vector3d(1.0, 1.0, 5.0), {});
  ASSERT_TRUE(weighted.ok);
  EXPECT_NEAR(weighted.x(0), 10.0, 1e-9);
  EXPECT_NEAR(weighted.cost, 17.0, 1e-9);
}

TEST(SolveL1ByLp, HardRowsAreEqualities) {
  // x0 - x1 = 0 (hard), x0 ≈ 1, x1 ≈ 3 (soft): x0 = x1 anywhere in [1, 3], cost 2.
  Eigen::MatrixXd a(3, 2);
  a << 1, -1, 1, 0, 0, 1;
  const LpL1Result result = SolveL1ByLp(Dense(a), Eigen::Vector3d(0.0, 1.0, 3.0),
                                        Eigen::Vector3d::Ones(), {true, false, false});
  ASSERT_TRUE(result.ok);
  EXPECT_NEAR(result.x(0), result.x(1), 1e-9);
  EXPECT_NEAR(result.cost, 2.0, 1e-9);
}

TEST(SolveL1ByLp, ReportsInfeasibleHardRowsAndBadSizes) {
  Eigen::MatrixXd a(2, 1);
  a << 1, 1;
  const LpL1Result infeasible =
      SolveL1ByLp(Dense(a), Eigen::Vector2d(0.0, 1.0), Eigen::Vector2d::Ones(), {true, true});
  EXPECT_FALSE(infeasible.ok);
  EXPECT_TRUE(infeasible.infeasible);
  const LpL1Result bad =
      SolveL1ByLp(Dense(a), Eigen::Vector3d::Zero(), Eigen::Vector2d::Ones(), {});
  EXPECT_FALSE(bad.ok);
  EXPECT_FALSE(bad.error.empty());
}

}  // namespace
}  // namespace lrfnet::calib
