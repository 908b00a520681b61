#pragma once
// Joint refinement (pipeline step 8; beyond Quenzel et al., the global non-linear refinement of
// MSG-Cal, papers/003): one non-linear least-squares problem over all sensor poses and the
// positions of the tracked objects, using every associated track observation with its covariance
// instead of only the pairwise estimates. Started from the rotation averaging + translations.
//
// Problem. At every used grid step k (every `step_stride`-th), each calibrated sensor's track
// samples are mapped into the world with the current poses and associated across sensors into
// objects (greedy nearest-pair clustering within the association gate, at most one observation per
// sensor and object; objects seen by fewer than two sensors are dropped). Unknowns: the pose
// (x_m, y_m, yaw_rad) of every free sensor (the reference and uncalibrated sensors are fixed), a
// world position o_j per object, and the shared correction d = (d_major, d_minor) of the prior body
// size of the measurement model (types.h TrackSample). Residual of a sample (sensor frame; body
// centre c + J d by the measurement model, CentreOf / CentrePerSizeCorrection, covariance S
// = CentreCovariance) of object j by sensor s with world_from_sensor = (R_s, t_s):
//
//     r = L^-1 (R_s^T (o_j - t_s) - c - J d),   L L^T = S + (model_sigma_per_m |c|)^2 I,
//
// i.e. whitened in the sensor frame; plus the prior of d, |d|^2 / prior_sigma^2 (prior_sigma =
// AlignedTracks::size_prior_sigma_m). Optionally, relative poses known independently of the tracks
// (RelativePoseConstraint, e.g. the background ICP of step 6: walls fix a relative pose to
// millimetres where tracks give centimetres) add
//
//     r_c = L_c^-1 (x(T_s^-1 T_r) - x(s_from_r)),   L_c L_c^T = covariance,
//
// x = (x_m, y_m, yaw_rad), the yaw difference wrapped. Cost = 1/2 (w sum rho(|r|^2) +
// sum rho_c(|r_c|^2) + |d|^2 / prior_sigma^2): rho the robust loss (Ceres' convention), rho_c a
// Cauchy loss at constraint_loss_scale (a constraint the tracks contradict by many sigmas, e.g. an
// ICP that slid along a wall, loses its pull), w = min(1, stride / observation_correlation_steps).
//
// The association gate is annealed: the first round associates within initial_association_gate_m
// (so that poses a few degrees off at a 20 m lever arm still find their objects), every later
// round within a geometrically smaller gate down to association_gate_m, and the rounds continue at
// that gate until the association no longer changes (at most `association_rounds` solves).
//
// Size correction: estimated only where the data observe it apart from the layout's scale (a
// size error moves every sensor's samples along its line of sight, which for views from opposite
// sides shrinks or grows the whole layout): after a solve with d free, the correlation of each
// component with the scale of the layout (the sensors' positions relative to the reference
// stretched uniformly) is computed from the data alone (d's prior left out); a component
// correlated beyond max_size_scale_correlation, or which the data determine no better than its
// prior, is held at 0 and solved again. Either way the covariance marginalises d under its prior,
// so the prior's uncertainty is in every pose's covariance where the data cannot remove it.
//
// Solved with Ceres (Levenberg-Marquardt; Schur complement with the objects eliminated, dense or
// sparse by the number of sensors).
//
// Covariance: the Gauss-Newton approximation at the solution (objects eliminated, d marginalised,
// robust weights rho', the correlation weight w) times max(1, variance factor), plus a systematic
// floor: every track of every sensor carries an offset of its own (its person's size, a
// view-dependent error) that does not average out over its samples, modelled as a constant 2D
// offset per track (segment_sigma_*) and propagated through the estimator.
//
// Sensor bias: what is left of the measurement bias after the model (TrackSample::
// shared_bias_sigma_m: a shape fit's centre settles a little off along the line of sight, the same
// way for all of one sensor's tracks) is one unknown b_s per sensor, shared by every sample and
// every pair of that sensor. Seen from opposite sides (two groups of sensors facing each other
// across a room, each group tied by walls) it adds up along the line between the sensors, exactly
// like a translation: the tracks cannot tell b_s from the poses, so it is not estimated but
// carried as a "consider" parameter at its prior, b_s ~ N(0, shared_bias_sigma^2) (the consider
// covariance of Schmidt's filter; Bierman, "Factorization Methods for Discrete Sequential
// Estimation", 1977, ch. VII; Tapley, Schutz, Born, "Statistical Orbit Determination", 2004,
// sec. 6.3): with H the reduced normal matrix of the poses and H_theta_b = J_theta^T W J_b,
//
//     Sigma_pose += S Sigma_b S^T,   S = -H^-1 H_theta_b,
//
// so the samples of one sensor, however many and in however many pairs, never shrink that part of
// the uncertainty. sensor_bias = false leaves it out (the behaviour before).
// Where the data do observe a sensor's bias (walls tie sensors that see one person from different
// directions, so the same b_s must explain their disagreement in every direction), it is
// estimated (estimate_sensor_bias): after the association has settled (and the size decision),
// each b_s's standard deviation from the data alone (every pose free, the size under its prior)
// is computed; those at most sensor_bias_max_data_sigma of the prior are solved for with their
// prior, the others held at 0. In the covariance the estimated ones are marginalised under their
// prior (with the systematic floor's response through them) and the held ones enter as consider
// terms (S from the system extended by the estimated ones).
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
  // when their world positions are at most the gate apart (metres; complete linkage: every pair of
  // an object's observations). The final gate must exceed the spread of one person's centre
  // between views plus the remaining pose error at range, and stay below the distance of two
  // people walking side by side; the first round's must cover the initial poses' error at range
  // (3 deg at 20 m is 1 m).
  double association_gate_m = 0.5;
  double initial_association_gate_m = 1.5;
  // Isotropic standard deviation per metre of range added to every sample (in quadrature with its
  // covariance and its model's): far away a person gets a few beams only.
  double model_sigma_per_m = 0.0;
  // Estimate the shared size correction where it is observable (see above); false: hold it at 0
  // (its prior uncertainty is still in the covariance).
  bool estimate_size_correction = true;
  double max_size_scale_correlation = 0.9;
  // Robust loss on the squared whitened residual; scale in whitened units (standard deviations).
  RobustLoss loss = RobustLoss::kCauchy;
  double loss_scale = 3.0;
  // Cauchy scale of the relative-pose constraints, whitened units.
  double constraint_loss_scale = 3.0;
  // Use every k-th grid step (smoothed tracks are strongly correlated from step to step; this
  // bounds the problem size). If more than `max_steps` steps would be used, the stride grows.
  std::size_t step_stride = 4;
  std::size_t max_steps = 4000;
  // Smoothed tracks are correlated over about this many grid steps (1 s on the 0.05 s grid): each
  // used sample's cost is weighted by min(1, stride / observation_correlation_steps). It does not
  // change a track-only solution, but it keeps the covariance honest and lets relative-pose
  // constraints weigh what they should against thousands of samples.
  double observation_correlation_steps = 20.0;
  // The systematic floor of the covariance: one standard deviation of each track's own constant
  // offset (metres, 2D), segment_sigma_m plus segment_sigma_per_m times the track's mean range.
  double segment_sigma_m = 0.015;
  double segment_sigma_per_m = 0.003;
  // Carry each sensor's shared radial bias as a consider parameter in the covariance (see "Sensor
  // bias" above).
  bool sensor_bias = true;
  bool estimate_sensor_bias = true;
  double sensor_bias_max_data_sigma = 0.5;
  int max_iterations = 50;     // per solve
  int association_rounds = 5;  // solves, each after a (re-)association with the current poses
  // Too little data: fewer associated observations in total, or fewer for a sensor (that sensor
  // is then held at its initial pose and reported as not refined).
  std::size_t min_observations = 20;
  std::size_t min_sensor_observations = 10;
  // Safety net: a sensor moving farther than this from its initial pose means the association
  // went wrong; the result is then rejected (ok = false, initial poses kept).
  double max_correction_m = 2.0;
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
  // (x_m, y_m, yaw_rad) per sensor (see "Covariance" above). Zero for the reference and for
  // sensors not refined (and on failure).
  std::vector<Eigen::Matrix3d> covariance;
  // Per sensor: took part (calibrated, connected to the reference through shared objects or
  // constraints, with enough observations or a constraint). The reference counts as refined.
  std::vector<bool> refined;
  std::vector<std::size_t> sensor_observations;  // associated observations per sensor (last round)
  // Cost (see above) at the initial poses and size correction and at the final ones, both with the
  // final association, the estimated sensor biases and the object positions optimal for those
  // poses.
  double cost_before = 0.0, cost_after = 0.0;
  // RMS over observations of |R_s^T (o - t_s) - z| (metres), before and after, like the costs.
  double rms_before_m = 0.0, rms_after_m = 0.0;
  // The shared size correction (d_major, d_minor) at the solution, whether each component was
  // estimated (else held at 0: not observable apart from the layout's scale), the correlation of
  // each with the layout's scale and its standard deviation from the data alone (before the
  // decision; +inf: the data do not determine it).
  Eigen::Vector2d size_correction_m = Eigen::Vector2d::Zero();
  std::array<bool, 2> size_correction_estimated{};
  std::array<double, 2> size_scale_correlation{};
  std::array<double, 2> size_data_sigma_m{};
  // Per sensor (refine.h "Sensor bias"): how far its reported points lie towards it from the body
  // centres beyond the measurement model, as estimated (0 where not estimated); whether it was
  // estimated; its standard deviation from the data alone in units of its prior (+inf: none).
  std::vector<double> sensor_bias_m;
  std::vector<bool> sensor_bias_estimated;
  std::vector<double> sensor_bias_data_sigma;
  // Per sensor: the standard deviation of sensor_bias_m after the refinement (metres): an
  // estimated one's marginal under its prior (the variance factor, the systematic floor and the
  // held ones' consider terms included), a held one's prior; 0 without a bias model. An estimated
  // one can exceed the prior: the floor (each matched track pair's own constant offset) is not in
  // the estimator's weights, and through few pairs it moves the estimate more than the data and
  // the prior pin it (the posterior of those alone stays below the prior).
  // Holding such a bias instead (the floor counted in the decision) was measured worse in a
  // three-sensor room (mean 0.0044 deg / 0.0093 m -> 0.0180 deg / 0.0124 m) and is not done.
  std::vector<double> sensor_bias_sigma_m;
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
