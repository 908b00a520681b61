#pragma once
// L1 multiple rotation averaging (pipeline step 7; Quenzel et al. Sec. III-E, Algorithm 1 "L1MC").
//
// Problem. Yaws φ_v of world_from_v (reference fixed at 0) from the measured relative yaws θ_e of
// the measurements e = (r, s) (graph.h: φ_r = φ_s + θ_e):
//     min_φ  Σ_e w_e |wrap(φ_r - φ_s - θ_e)|           (w_e = weight if use_weights, else 1)
// i.e. the sum of the L1 residuals of the measurement rows (eq. 19) in the tangent space (eq. 18).
//
// Node-angle form. Algorithm 1 has one unknown per directed pair, w_ij ≈ φ_j - φ_i, measurement
// rows (eq. 19), inverse rows (eq. 20) and transitivity rows for every triangle (eq. 21) with the
// 2π normalisation b_t = A_t b_m - normalize(A_t b_m): O(n^3) rows (l1mc_full.h builds it). With
// the inverse and transitivity rows as hard constraints its feasible set is exactly
// {w_ij = φ_j - φ_i + 2π m_ij} for node angles φ and integers m fixed by the b_t (the triangles
// of the complete graph generate its cycle space), so its measurement part is
//     min_φ  Σ_e w_e |φ_r - φ_s - b̃_e|,   b̃_e = θ_e + 2π k_e,
// over n - 1 unknowns with one row per measurement. Here the offsets k_e are fixed by normalising
// every measurement against a solution (k_e = round((φ_r - φ_s - θ_e) / 2π): every residual in
// [-π, π], the paper's normalisation) and re-fixed against the optimum until they no longer
// change. Where the paper's offsets equal these, both forms have the same optimum;
// l1mc_full_test.cc shows it against an exact LP (Clp) on random graphs and explains where the
// paper's soft form (constraint rows weighted like measurements) and its per-triangle
// normalisation differ.
//
// Starts. The wrapped cost is not convex: the result is the exact optimum for its 2π offsets,
// which are those of a local optimum of the wrapped cost. Its minima differ by blocks of nodes
// turned against the rest where the outliers locally outweigh the inliers, so the solver starts
// from ConsensusYaws, the spectral relaxation and ConsistentTreeYaws (all discounting the
// measurements that close no consistent triangle) and keeps the lowest cost.
//
// Solver. IRLS: each iteration solves the weighted least squares with weights w_e / max(|r_e|, ε)
// (reduced graph Laplacian, sparse LDLT), ε shrinking geometrically to `irls_epsilon`. Every
// iteration gives a flow g_e = (IRLS weight) r_e, made conserved (Σ_e g_e ∂r_e/∂φ_v = 0) and
// scaled into |g_e| <= w_e: a dual-feasible point, hence the lower bound -Σ g_e b̃_e. Near the
// optimum the IRLS point is finished exactly: the spanning tree of its smallest residuals is a
// vertex of the LP; it is optimal iff the tree edges' flows, fixed by conservation from
// g_e = w_e sign(r_e) on the other edges, satisfy |g_e| <= w_e (the LP dual); a violating tree
// edge is pivoted out by moving its subtree to the weighted median of the breakpoints across the
// cut (a network-simplex step). `certified`: the yaws are that optimum up to round-off.
//
// Ties. An L1 optimum is often a whole face (e.g. a node held by as much weight on either side);
// the solver then prefers the measurements that close consistent triangles, by raising their
// weights by at most 1e-6 relative: the returned cost is within 1e-6 relative of the optimum.
//
// Pure functions; thread-safe.

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "central_daemon/calibration/graph.h"

namespace lrfnet::calib {

struct RotationAveragingOptions {
  bool use_weights = false;            // w_e = measurement weight (e.g. Schenk's N/d); else 1
  double irls_epsilon = 1e-10;         // rad: the final IRLS smoothing ε
  double initial_epsilon = 1e-2;       // rad: the first IRLS smoothing ε
  double epsilon_factor = 0.25;        // ε shrinks by this factor per IRLS iteration
  int max_iterations = 200;            // IRLS iterations per start (all offset rounds together)
  int max_offset_rounds = 10;          // re-normalisations of the 2π offsets
  double tolerance = 1e-9;             // or stop when (cost - lower bound) <= tolerance * cost
  double outlier_threshold_deg = 5.0;  // |residual| above: the edge is a rotation outlier
  // Yaw σ of a measurement (of average weight) when the inlier edges have no redundancy (a tree):
  // no residual to estimate it from.
  double prior_sigma_deg = 1.0;
  // Return the weighted least squares on the inlier edges (the fit yaw_sigma_rad describes)
  // instead of the L1 optimum: more accurate under Gaussian noise once the outliers are known
  // (L1 is a median-like estimator). Inlier flags and residuals are then those of that fit.
  bool inlier_least_squares = false;
  // Starts of the solver (the wrapped cost has local minima; the lowest cost found is kept):
  // ConsensusYaws, and with multi_start also the spectral relaxation with cycle-consistency
  // weights and ConsistentTreeYaws. A given initial_yaw_rad (size n, radians) is the only start.
  bool multi_start = true;
  std::vector<double> initial_yaw_rad;
};
std::optional<std::string> Validate(const RotationAveragingOptions& options);

struct RotationAveragingResult {
  bool ok = false;
  std::string error;
  std::vector<double> yaw_rad;       // world_from_node yaw in (-π, π], reference 0
  std::vector<double> residual_rad;  // per measurement: wrap(φ_r - φ_s - θ)
  std::vector<bool> inlier;          // |residual| <= outlier_threshold_deg
  double l1_cost = 0.0;              // Σ w_e |residual_e|
  int iterations = 0;                // IRLS iterations (L1); power/eigen solver: 0
  // Per node: σ of the yaw from the weighted least squares on the inlier edges at the L1
  // offsets, σ̂² (L_red)^-1 with L_red the weighted Laplacian without the reference row and σ̂²
  // the weighted residual variance of that least-squares fit (prior_sigma_deg when it has no
  // redundancy); the inlier edges are replaced by all edges if they do not connect the graph.
  // Reference 0.
  std::vector<double> yaw_sigma_rad;
  // L1 only:
  bool certified = false;       // exact LP optimum for the final offsets (see above)
  double l1_lower_bound = 0.0;  // a lower bound of the optimum for the final offsets
  int offset_rounds = 0;        // solves with different 2π offsets
  int pivots = 0;               // network-simplex steps of the exact finish
  int starts = 0;               // starts solved
};

// What every rotation solver checks first: the options (Validate), the graph (CheckGraphInput)
// and that the measurements connect every node to the reference. The error, or nullopt.
std::optional<std::string> CheckRotationProblem(std::size_t n, std::size_t reference,
                                                const std::vector<RelativeMeasurement>& measurements,
                                                const RotationAveragingOptions& options);

RotationAveragingResult AverageRotationsL1(std::size_t n, std::size_t reference,
                                           const std::vector<RelativeMeasurement>& measurements,
                                           const RotationAveragingOptions& options);

// ---------------------------------------------------------------------------------------------
// Building blocks, public for the baselines, the benchmark and the tests.

// The start of the L1 solver (its only job: put the inlier measurements into the right 2π
// branch). Nodes are placed greedily, the one with the most weight of placed neighbours next,
// each at the consensus of its placed neighbours' votes φ_u ± θ_e: the vote with the most weight
// within `consensus_tol_rad`, averaged over those supporters. Then up to `sweeps` passes re-vote
// every node from all its neighbours. Correct where every node's inlier votes outweigh its
// outlier votes; reference 0, yaws in (-π, π]. Inputs must pass CheckGraphInput and be connected.
std::vector<double> ConsensusYaws(std::size_t n, std::size_t reference,
                                  const std::vector<RelativeMeasurement>& measurements,
                                  bool use_weights, double consensus_tol_rad, int sweeps = 5);

// Per measurement: the number of triangles of measurements it closes consistently, i.e. with
// |wrap(sum of the relative yaws around the triangle)| <= tol_rad (cycle consistency: an outlier
// rarely closes a triangle). Measurements must pass CheckGraphInput.
std::vector<std::size_t> ConsistentTriangles(std::size_t n,
                                             const std::vector<RelativeMeasurement>& measurements,
                                             double tol_rad);

// Yaws composed along the spanning tree that prefers the measurements closing the most
// consistent triangles (then the heavier; Kruskal), reference 0, yaws in (-π, π]. Inputs must
// pass CheckGraphInput and be connected.
std::vector<double> ConsistentTreeYaws(std::size_t n, std::size_t reference,
                                       const std::vector<RelativeMeasurement>& measurements,
                                       bool use_weights, double triangle_tol_rad);

// Weighted least squares Σ w_e (φ_r - φ_s - θ_e)^2 (w_e = weight if use_weights, else 1) with
// every θ_e taken in the 2π branch nearest to `branch_yaw_rad` (size n); reference 0. Inputs
// must pass CheckGraphInput and be connected; returns all zeros if the normal equations fail.
std::vector<double> LeastSquaresYaws(std::size_t n, std::size_t reference,
                                     const std::vector<RelativeMeasurement>& measurements,
                                     bool use_weights, const std::vector<double>& branch_yaw_rad);

// Fills residual_rad, inlier, l1_cost and yaw_sigma_rad of `result` from result->yaw_rad (size
// n; inputs already checked as by AverageRotationsL1).
void FillRotationDiagnostics(std::size_t n, std::size_t reference,
                             const std::vector<RelativeMeasurement>& measurements,
                             const RotationAveragingOptions& options,
                             RotationAveragingResult* result);

// Generic weighted L1 regression by IRLS: min_x Σ_i w_i |(A x - b)_i|, A of full column rank.
// ε shrinks geometrically; every iteration yields a dual-feasible flow (projected onto
// A^T g = 0), hence a lower bound; once within 1e-2 relative, an exact vertex finish is tried.
struct L1IrlsOptions {
  double initial_epsilon = 1e-2;
  double final_epsilon = 1e-10;
  double epsilon_factor = 0.25;
  int max_iterations = 100;
  double tolerance = 1e-9;  // relative gap (cost - lower bound) / cost
};
struct L1IrlsResult {
  bool ok = false;  // false: the normal equations were singular
  Eigen::VectorXd x;
  double cost = 0.0;
  double lower_bound = 0.0;  // -g^T b for the best dual-feasible g found
  int iterations = 0;
  // An exact finish (the vertex through the smallest residuals, certified by the LP dual)
  // succeeded: x is optimal up to round-off and lower_bound = cost.
  bool exact = false;
};
L1IrlsResult SolveL1Irls(const Eigen::SparseMatrix<double>& a, const Eigen::VectorXd& b,
                         const Eigen::VectorXd& weight, const Eigen::VectorXd& x0,
                         const L1IrlsOptions& options);

}  // namespace lrfnet::calib
