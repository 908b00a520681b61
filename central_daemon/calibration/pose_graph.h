#pragma once
// The weighted least-squares finish of the global step (pipeline step 7) and the graph analysis
// behind the hypotheses of the pipeline.
//
// Least squares. After the L1 rotation averaging has named the outlier edges, the inlier edges
// are solved jointly for every pose (x_m, y_m, yaw_rad of world_from_node, the reference fixed at
// the identity) with their covariances (graph.h RelativeMeasurement::covariance, the honest
// pairwise ones): Gauss-Newton on
//
//     sum_e  r_e^T Sigma_e^-1 r_e,   r_e = x(T_s^-1 T_r) - x(s_from_r)   (yaw wrapped),
//
// which re-estimates the translations together with the rotations (a translation measured in
// frame s moves with s's yaw; solving the yaws first and then the translations with the yaws
// fixed, as Quenzel et al. do, ignores that the yaws are uncertain). Covariance: the inverse of
// the normal matrix times max(1, chi^2 / dof) (dof = 3 m - 3 (n - 1); with dof = 0 the edges'
// covariances are taken as they are). Each edge's residual is also returned in sigma units
// (sqrt of r^T (Sigma_e + J Sigma J^T)^-1 r, its Mahalanobis distance against the solution
// without itself not being computed: the leave-in value, conservative for judging consistency).
//
// Cycle support. An edge whose misclosure only shows in one cycle cannot be told apart from the
// other edges of that cycle by any robust estimator (the L1 optimum of a single cycle is a whole
// face: any one edge can absorb the misclosure). CycleSupport counts, per edge, the edge-disjoint
// paths between its two ends that avoid it (capped at `cap`): 0 for a bridge, 1 for an edge of
// exactly one independent cycle, >= 2 where a majority can speak.
//
// Pure functions; thread-safe.

#include <Eigen/Core>
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "central_daemon/calibration/graph.h"

namespace lrfnet::calib {

struct PoseGraphOptions {
  int max_iterations = 20;
  double tolerance = 1e-10;  // stop when the step is below this (metres and radians)
  // Each edge's covariance is floored at these standard deviations (its eigenvalues in x, y and
  // yaw): a covariance of a few micrometres would make one edge dominate regardless of the others.
  double min_sigma_m = 1e-4;
  double min_sigma_rad = 1e-6;
};
std::optional<std::string> Validate(const PoseGraphOptions& options);

struct PoseGraphResult {
  bool ok = false;
  std::string error;
  std::vector<Pose2> world_from_node;       // reference: identity
  std::vector<Eigen::Matrix3d> covariance;  // (x_m, y_m, yaw_rad) per node; reference: zero
  std::vector<double> residual_sigma;       // per measurement (used or not), see above
  std::vector<double> residual_chi2;        // per measurement: r^T Sigma_e^-1 r
  double chi2 = 0.0;                        // over the used measurements
  long dof = 0;
  double variance_factor = 1.0;  // the factor applied to the covariance (>= 1)
  int iterations = 0;
};

// Gauss-Newton from `initial` (size n; e.g. the L1 yaws with the least-squares translations) over
// the measurements flagged in `use` (one flag per measurement). Errors (ok = false): bad input
// (CheckGraphInput with covariances, the full 3x3 checked), sizes, nodes not connected to the
// reference through the used measurements, a singular system.
PoseGraphResult SolvePoseGraph(std::size_t n, std::size_t reference,
                               const std::vector<RelativeMeasurement>& measurements,
                               const std::vector<bool>& use, const std::vector<Pose2>& initial,
                               const PoseGraphOptions& options = {});

// The relative pose s_from_r the poses imply and its covariance from the joint covariance
// (first-order; the cross-covariance of r and s is not known here and taken as zero).
struct RelativeFromPoses {
  Pose2 s_from_r;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
};
RelativeFromPoses RelativePose(const Pose2& world_from_r, const Eigen::Matrix3d& cov_r,
                               const Pose2& world_from_s, const Eigen::Matrix3d& cov_s);

// Mahalanobis distance (sigma units) between a measured s_from_r and one from the poses, with the
// sum of both covariances; +inf when that sum is not positive definite.
double MeasurementDistanceSigma(const Pose2& measured, const Eigen::Matrix3d& measured_cov,
                                const RelativeFromPoses& predicted);

// Per measurement flagged in `use`: the number of edge-disjoint paths between its ends in the
// graph of the other used measurements, at most `cap`. Measurements not used: 0.
std::vector<int> CycleSupport(std::size_t n, const std::vector<RelativeMeasurement>& measurements,
                              const std::vector<bool>& use, int cap = 2);

}  // namespace lrfnet::calib
