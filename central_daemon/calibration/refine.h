#pragma once
// Joint refinement (pipeline step 8; beyond Quenzel et al., the global non-linear refinement of
// MSG-Cal, papers/003): one non-linear least-squares problem over all sensor poses and the
// positions of the tracked objects, using every associated track observation with its covariance
// instead of only the pairwise estimates. Started from the rotation averaging + translations.
//
// Problem. At every used grid step k (every `step_stride`-th), each calibrated sensor's track
// samples are mapped into the world with the current poses and associated across sensors into
// objects (greedy nearest-pair clustering within `association_gate_m`, at most one observation per
// sensor and object; objects seen by fewer than two sensors are dropped). Unknowns: the pose
// (x_m, y_m, yaw_rad) of every free sensor (the reference and uncalibrated sensors are fixed) and
// a world position o_j per object. Residual of an observation z (sensor frame, covariance S_z) of
// object j by sensor s with world_from_sensor = (R_s, t_s):
//
//     r = L^-1 (v - b_kind v / |v| - z),   v = R_s^T (o_j - t_s),
//     L L^T = S_z + (sigma_kind^2 + (sigma_per_m |z|)^2) I,
//
// i.e. whitened in the sensor frame. b_kind is the radial bias of the tracked centre toward the
// sensor (the centre of mass of a person's visible contour lies on the near side), fixed or
// estimated (JointRefineOptions::estimate_radial_bias). Optionally, relative poses known
// independently of the tracks (RelativePoseConstraint, e.g. the background ICP of step 6: walls
// fix a relative pose to millimetres where tracks give centimetres) add
//
//     r_c = L_c^-1 (x(T_s^-1 T_r) - x(s_from_r)),   L_c L_c^T = covariance,
//
// x = (x_m, y_m, yaw_rad), the yaw difference wrapped. Cost = 1/2 (w sum rho(|r|^2) +
// sum |r_c|^2): rho the robust loss (Ceres' convention), w = min(1, stride /
// observation_correlation_steps). Constraints get no robust loss: the caller vouches for them (a
// down-weighted constraint would lose against thousands of samples whatever its accuracy).
//
// Solved with Ceres (Levenberg-Marquardt; Schur complement with the objects eliminated, dense or
// sparse by the number of sensors); then re-associated with the refined poses and solved again
// until the association no longer changes (at most `association_rounds` solves).
//
// Measured on the shipped scenarios (simulator -> tracker -> alignment), started from the rotation
// averaging + translations without ICP: mean rotation error 1-6.5x lower (schenk_C 0.78 -> 0.12
// deg), mean translation error 1.02-4.5x lower (schenk_C 0.22 -> 0.05 m), in 2-50 ms. What stays
// are systematic centre errors that look like sensor translations (the radial bias changes with
// range and view, so one constant per kind is not identifiable: estimation is off by default).
// Where walls were matched by ICP, pass those pairs as constraints: alone, the tracks pull
// sub-millimetre ICP poses to centimetres.
//
// Thread-safety: pure function over value types; concurrent calls are safe.

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "central_daemon/calibration/types.h"

namespace lrfnet::calib {

enum class RobustLoss { kNone, kHuber, kCauchy };

enum class RefineLinearSolver {
  kAuto,  // dense Schur up to `dense_schur_max_sensors` free sensors, else sparse Schur
  kDenseSchur,
  kSparseSchur,  // SuiteSparse / CXSparse / Eigen sparse, whichever Ceres was built with
};

struct JointRefineOptions {
  // Association: two observations of different sensors at one grid step may belong to one object
  // when their world positions are at most this far apart (metres; complete linkage: every pair of
  // an object's observations). Must exceed the spread of one person's centre between views
  // (~0.2-0.4 m for centre-of-mass tracks) plus the error of the initial poses at range, and stay
  // below the distance of two people walking side by side.
  double association_gate_m = 0.5;
  // Model standard deviation added isotropically to every observation's covariance, by
  // measurement kind: a tracked centre depends on the side the object is seen from (the centre of
  // mass of the visible contour moves by ~0.1-0.2 m with the view; the fitted ellipse centre much
  // less). Metres.
  double model_sigma_com_m = 0.10;
  double model_sigma_ellipse_m = 0.03;
  double model_sigma_unspecified_m = 0.10;
  // Plus this much per metre of range (added in quadrature): far away a person gets a few beams
  // only (0.5 deg is 0.17 m at 20 m), the ellipse fit falls back to the centre of mass and the
  // centre's error grows with the range. 0.01 was best on the shipped scenarios (0: 10-30 %
  // larger errors on the corridor scenes, ~15 % smaller on the rooms).
  double model_sigma_per_m = 0.01;
  // Radial bias of the tracked centre toward the sensor, by measurement kind (metres; the value
  // used when not estimated, the start value otherwise). The centre of mass of a person's visible
  // contour lies ~0.1-0.2 m closer to the sensor than the person's centre (pi r / 4 for a
  // cylinder of radius r sampled at uniform beam angles). Left unmodelled it is nearly
  // indistinguishable from a translation of the sensor along its viewing direction and pulls
  // every sensor toward the scene by about its size. The ellipse fit places its centre behind
  // the visible points, leaving a small bias when a person's size differs from the fixed axes.
  double radial_bias_com_m = 0.10;
  double radial_bias_ellipse_m = 0.0;
  double radial_bias_unspecified_m = 0.0;
  // Estimate one bias per kind jointly with the poses (for kinds with at least
  // `min_bias_observations` associated observations). Exact when the bias is one constant and
  // the objects are seen at varied ranges from different sides; with the tracker's real centres
  // (a bias that grows with the range as the ellipse fit falls back to the centre of mass) the
  // constant trades against the scale of the layout and made 4 of 6 shipped scenarios worse.
  bool estimate_radial_bias = false;
  std::size_t min_bias_observations = 100;
  // Robust loss on the squared whitened residual; scale in whitened units (standard deviations).
  RobustLoss loss = RobustLoss::kCauchy;
  double loss_scale = 3.0;
  // Use every k-th grid step (smoothed tracks are strongly correlated from step to step; this
  // bounds the problem size). If more than `max_steps` steps would be used, the stride grows.
  std::size_t step_stride = 4;
  std::size_t max_steps = 4000;
  // Smoothed tracks are correlated over about this many grid steps (1 s on the 0.05 s grid): each
  // used sample's cost is weighted by min(1, stride / observation_correlation_steps). It does not
  // change a track-only solution, but it keeps the covariance honest and lets relative-pose
  // constraints weigh what they should against thousands of samples.
  double observation_correlation_steps = 20.0;
  int max_iterations = 50;     // per solve
  int association_rounds = 3;  // solves, each after a (re-)association with the current poses
  // Too little data: fewer associated observations in total, or fewer for a sensor (that sensor
  // is then held at its initial pose and reported as not refined).
  std::size_t min_observations = 20;
  std::size_t min_sensor_observations = 10;
  // Safety net: a sensor moving farther than this from its initial pose means the association
  // went wrong; the result is then rejected (ok = false, initial poses kept).
  double max_correction_m = 1.0;
  double max_correction_rad = 0.0872664626;  // 5 degrees
  RefineLinearSolver linear_solver = RefineLinearSolver::kAuto;
  std::size_t dense_schur_max_sensors = 40;
  int threads = 1;
  // Ceres' convergence tests: relative cost change and relative step. The robust loss makes the
  // last iterations converge only linearly (Ceres drops the curvature of rho when rho'' < 0), so
  // tighter values cost iterations for digits far below the statistical uncertainty.
  double function_tolerance = 1e-8;
  double parameter_tolerance = 1e-8;
  // Multiply the covariance by the a-posteriori variance factor when it exceeds 1 (the model
  // sigmas were too optimistic).
  bool scale_covariance_by_variance_factor = true;
};

std::optional<std::string> Validate(const JointRefineOptions& options);

// A relative pose between two sensors known independently of the tracks.
struct RelativePoseConstraint {
  std::size_t r = 0, s = 0;  // indices into AlignedTracks::sensors, r != s
  Pose2 s_from_r;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Identity();  // of (x_m, y_m, yaw_rad), SPD
};

struct JointRefineResult {
  bool ok = false;
  std::string message;  // why not (too few observations, solver failure, ...); notes when ok
  // Refined (== initial for sensors not refined and on failure).
  std::vector<Pose2> world_from_sensor;
  // (x_m, y_m, yaw_rad) per sensor from the Gauss-Newton approximation J^T W J at the solution
  // (objects and estimated biases marginalised, robust weights rho', the correlation weight w),
  // times max(1, variance_factor) when scale_covariance_by_variance_factor. Systematic centre
  // errors are not in it. Zero for the reference and for sensors not refined (and on failure).
  std::vector<Eigen::Matrix3d> covariance;
  // Per sensor: took part (calibrated, connected to the reference through shared objects or
  // constraints, with enough observations or a constraint). The reference counts as refined.
  std::vector<bool> refined;
  std::vector<std::size_t> sensor_observations;  // associated observations per sensor (last round)
  // Cost (see above) at the initial poses and biases and at the final ones, both with the final
  // association and the object positions optimal for those poses.
  double cost_before = 0.0, cost_after = 0.0;
  // RMS over observations of |R_s^T (o - t_s) - z| (metres), before and after, like the costs.
  double rms_before_m = 0.0, rms_after_m = 0.0;
  // Radial bias per measurement kind at the solution, indexed by MeasurementKind (kUnspecified,
  // kCenterOfMass, kEllipse); `radial_bias_estimated` says which were estimated (else as given).
  std::array<double, 3> radial_bias_m{};
  std::array<bool, 3> radial_bias_estimated{};
  // (sum rho(|r|^2) + sum |r_c|^2) / (residuals - unknowns) at the solution, without w.
  double variance_factor = 0.0;
  std::size_t observations = 0;      // associated observations in the final problem
  std::size_t objects = 0;           // object positions (one per object per used step)
  std::size_t steps = 0;             // grid steps used (with at least one object)
  std::size_t stride = 0;            // the stride actually used
  std::size_t downweighted = 0;      // observations with robust weight rho' < 0.5 at the solution
  std::size_t rejected_samples = 0;  // track samples with a non-finite position or a bad covariance
  std::size_t constraints_used = 0;  // relative-pose constraints in the final problem
  double constraint_rms_sigma = 0.0;  // RMS of their whitened residuals at the solution
  // Constraints ignored: an index out of range or equal, a sensor not calibrated, a non-finite
  // pose or a covariance that is not symmetric positive definite.
  std::size_t constraints_rejected = 0;
  int rounds = 0;              // solves done
  int iterations = 0;          // Ceres iterations over all rounds
  double solver_time_s = 0.0;  // as reported by Ceres
};

// `world_from_sensor`, `calibrated`: one entry per tracks.sensors entry. `calibrated[i]` false:
// sensor i is not part of the problem (its pose is returned unchanged). `reference` must be
// calibrated and is held fixed. Size mismatches and a bad reference give ok = false.
// `constraints`: optional relative-pose measurements (see above); they also link sensors that
// share too few tracks, but the problem still needs `min_observations` track observations.
JointRefineResult RefineJointly(const AlignedTracks& tracks,
                                const std::vector<Pose2>& world_from_sensor,
                                const std::vector<bool>& calibrated, std::size_t reference,
                                const JointRefineOptions& options,
                                const std::vector<RelativePoseConstraint>& constraints = {});

}  // namespace lrfnet::calib
