#pragma once
// The full formulation of Quenzel et al.'s Algorithm 1 ("L1MC", Sec. III-E), for tests and the
// benchmark; production uses the equivalent node-angle form (rotation_averaging.h).
//
// Unknowns: one tangent angle per directed pair, x_ij = w_ij ≈ φ_j - φ_i (eq. 18; R_ij = R_i^T R_j,
// eq. 1), i != j: n (n - 1) columns. Rows, in this order:
//   measurement  (eq. 19)  x_sr = normalize(θ_e)                per measurement e = (r, s), weight
//   w_e inverse      (eq. 20)  x_ij + x_ji = 0                      per pair i < j transitivity
//   (eq. 21)  x_ik + x_kj - x_ij = b_t             per triangle i < k < j
// with b_t = A_t x' - normalize(A_t x') (the paper's 2π normalisation; a multiple of 2π) for the
// start x': x'_sr = normalize(θ_e) and x'_rs = -x'_sr for measured pairs (the first measurement
// of a pair), x'_ij = wrap(ψ_j - ψ_i) with ψ = start_yaw_rad for unmeasured pairs. (The paper
// computes A_t b_m with the measurements only; an unmeasured pair then counts as 0, which makes
// the offsets of the triangles with an unmeasured pair inconsistent with each other whenever a
// yaw difference exceeds π/2 - hence a start for those pairs.)
//
// The paper minimises ||A x - b||_1 over all rows ("soft" form, constraint rows weighted 1).
// With the inverse and transitivity rows as hard constraints instead, the feasible set is
// {x_ij = φ_j - φ_i + 2π m_ij} when the offsets are consistent (offsets_consistent), and the
// problem is the node-angle form (see rotation_averaging.h); l1mc_full_test.cc shows both against
// an exact LP. Size: O(n^3) rows (all triangles).
//
// Pure functions; thread-safe.

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <cstddef>
#include <vector>

#include "central_daemon/calibration/graph.h"

namespace lrfnet::calib {

struct L1mcFullSize {
  std::size_t unknowns = 0;
  std::size_t rows = 0;
  std::size_t nonzeros = 0;
  std::size_t triangles = 0;
};
L1mcFullSize L1mcFullSizeOf(std::size_t n, std::size_t measurements);

struct L1mcFull {
  std::size_t n = 0;
  std::size_t measurement_rows = 0;
  std::size_t inverse_rows = 0;
  std::size_t transitivity_rows = 0;
  Eigen::SparseMatrix<double> a;  // (rows) x (n (n - 1)), entries ±1
  Eigen::VectorXd b;
  Eigen::VectorXd weight;  // per row: w_e for measurement rows, 1 for the others
  Eigen::VectorXd start;   // x'
  // The inverse and transitivity rows have an exact solution (their 2π offsets agree on every
  // cycle); false: the hard form is infeasible.
  bool offsets_consistent = false;

  // Column of x_ij (i != j, both < n).
  std::size_t Unknown(std::size_t i, std::size_t j) const {
    return i * (n - 1) + (j < i ? j : j - 1);
  }
  // Per row: true for the inverse and transitivity rows.
  std::vector<bool> ConstraintRows() const;
};

// Algorithm 1 for the measurements (which must pass CheckGraphInput). use_weights: measurement
// rows weighted by the measurement weight ("weighting both sides of the measurement equations").
L1mcFull BuildL1mcFull(std::size_t n, const std::vector<RelativeMeasurement>& measurements,
                       const std::vector<double>& start_yaw_rad, bool use_weights);

// Yaws relative to the reference from a solution x: φ_j = x_{reference, j} (the paper's "upper
// n x nN rows"), wrapped to (-π, π]; reference 0.
std::vector<double> YawsFromL1mc(const L1mcFull& problem, const Eigen::VectorXd& x,
                                 std::size_t reference);

}  // namespace lrfnet::calib
