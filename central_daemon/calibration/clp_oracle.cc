#include "central_daemon/calibration/clp_oracle.h"

#include <ClpSimplex.hpp>
#include <CoinFinite.hpp>
#include <cmath>

namespace lrfnet::calib {

LpL1Result SolveL1ByLp(const Eigen::SparseMatrix<double>& a_in, const Eigen::VectorXd& b,
                       const Eigen::VectorXd& weight, const std::vector<bool>& hard) {
  LpL1Result result;
  const Eigen::Index rows = a_in.rows(), cols = a_in.cols();
  if (b.size() != rows || weight.size() != rows ||
      (!hard.empty() && hard.size() != static_cast<std::size_t>(rows))) {
    result.error = "sizes of A, b, weight and hard do not agree";
    return result;
  }
  Eigen::SparseMatrix<double, Eigen::ColMajor> a = a_in;
  a.makeCompressed();
  auto is_hard = [&](Eigen::Index i) { return !hard.empty() && hard[static_cast<std::size_t>(i)]; };

  // Columns: x (free), then e+ and e- for every soft row.
  std::vector<CoinBigIndex> start{0};
  std::vector<int> index;
  std::vector<double> value, col_lb, col_ub, objective;
  for (Eigen::Index c = 0; c < cols; ++c) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(a, c); it; ++it) {
      index.push_back(static_cast<int>(it.row()));
      value.push_back(it.value());
    }
    start.push_back(static_cast<CoinBigIndex>(index.size()));
    col_lb.push_back(-COIN_DBL_MAX);
    col_ub.push_back(COIN_DBL_MAX);
    objective.push_back(0.0);
  }
  for (Eigen::Index i = 0; i < rows; ++i) {
    if (is_hard(i)) continue;
    for (double sign : {-1.0, 1.0}) {
      index.push_back(static_cast<int>(i));
      value.push_back(sign);
      start.push_back(static_cast<CoinBigIndex>(index.size()));
      col_lb.push_back(0.0);
      col_ub.push_back(COIN_DBL_MAX);
      objective.push_back(weight(i));
    }
  }
  std::vector<double> row_bound(b.data(), b.data() + rows);

  ClpSimplex model;
  model.setLogLevel(0);
  model.loadProblem(static_cast<int>(col_lb.size()), static_cast<int>(rows), start.data(),
                    index.data(), value.data(), col_lb.data(), col_ub.data(), objective.data(),
                    row_bound.data(), row_bound.data());
  model.setPrimalTolerance(1e-10);
  model.setDualTolerance(1e-10);
  model.dual();
  if (model.isProvenPrimalInfeasible()) {
    result.infeasible = true;
    result.error = "the hard rows are infeasible";
    return result;
  }
  if (!model.isProvenOptimal()) {
    result.error = "Clp did not reach an optimum (status " + std::to_string(model.status()) + ")";
    return result;
  }
  const double* solution = model.getColSolution();
  result.x = Eigen::Map<const Eigen::VectorXd>(solution, cols);
  const Eigen::VectorXd r = a * result.x - b;
  for (Eigen::Index i = 0; i < rows; ++i) {
    if (!is_hard(i)) result.cost += weight(i) * std::abs(r(i));
  }
  result.ok = true;
  return result;
}

}  // namespace lrfnet::calib
