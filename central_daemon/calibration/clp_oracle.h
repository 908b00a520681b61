#pragma once
// Exact weighted L1 regression as a linear program solved by COIN-OR Clp (simplex): the oracle
// the tests compare the IRLS solvers with. Test-only (library lrfnet_calib_clp_oracle); slow
// for large problems (simplex on O(n^3) rows).
//
//   min  Σ_{soft rows i} w_i (e+_i + e-_i)
//   s.t. a_i x - e+_i + e-_i = b_i   (soft rows),   a_i x = b_i   (hard rows),
//        x free, e+ >= 0, e- >= 0.
//
// Thread-safe (one Clp model per call).

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <string>
#include <vector>

namespace lrfnet::calib {

struct LpL1Result {
  bool ok = false;          // an optimal solution was found
  bool infeasible = false;  // the hard rows have no solution
  std::string error;
  Eigen::VectorXd x;
  double cost = 0.0;  // Σ w_i |a_i x - b_i| over the soft rows
};

// `hard`: one flag per row (empty: no hard rows). weight: one per row (ignored for hard rows).
LpL1Result SolveL1ByLp(const Eigen::SparseMatrix<double>& a, const Eigen::VectorXd& b,
                       const Eigen::VectorXd& weight, const std::vector<bool>& hard);

}  // namespace lrfnet::calib
