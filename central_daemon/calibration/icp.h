#pragma once
// Step 6 of the calibration (Quenzel et al., section III-D, last paragraph: "we employ a
// point-to-line variant of ICP [25] already on the pairwise relative poses"): refines a pairwise
// estimate s_from_r by aligning the two sensors' static background snapshots with Censi's
// point-to-line ICP (A. Censi, "An ICP variant using a point-to-line metric", ICRA 2008), and keeps
// the result only where it makes the backgrounds more consistent.
//
// Frames: a background is polar in its sensor's frame (DESIGN.md, proto BackgroundSnapshot): beam i
// points at first_angle_rad + i * angle_step_rad, 0 rad = x forward, angles counter-clockwise; a
// range of 0 mm means no static return. s_from_r maps r's sensor frame to s's (types.h).
//
// Method: every background point gets its local line once: the least-squares line through it and
// its neighbouring beams within line_radius_m (no line across a depth jump of more than
// max_segment_length_m between adjacent beams; the window is halved while its points scatter by
// more than line_tolerance_m RMS, so that no line turns a corner). One iteration: r's background
// points are mapped into s with the current pose; each is paired with the line of its nearest s
// point (searched outward from its bearing in s's beam order, so a query costs a few beams). A pair
// is rejected when the nearest point is farther than the current correspondence distance, when that
// point has no line, or when r's sensor lies behind the line as seen by s (the two sensors would
// see opposite faces of a thin wall). The residual is the point-to-line distance
// n^T (s_from_r * p - q) (Censi's metric; his line through the two nearest points has a normal too
// noisy for the degeneracy test below). The worst trim_fraction of the pairs are dropped and the
// pose minimising the sum of squared residuals of the rest is solved exactly (Censi's closed form
// with a Lagrange multiplier). The correspondence distance is annealed geometrically from
// initial_ to final_correspondence_m over anneal_iterations; the loop stops when a step after the
// annealing is below the convergence thresholds or returns to the pose of the iteration before
// (correspondences flipping between two sets), or after max_iterations.
//
// Degeneracy: in coordinates (x, y, yaw * L), L the RMS range of r's matched points (so that a
// unit step of each moves the points by about a metre), the eigenvalue lambda_k of the Gauss-Newton
// information J^T J of the point-to-line residuals is the information along eigen-direction v_k (a
// correspondence whose normal points along v_k adds 1). A fitted normal is tilted by its fitting
// error, and a tilted normal adds information along its line where the surfaces carry none (along
// a corridor, many slightly tilted normals add up to what looks like a constraint on its axis), so
// the expected contribution of each normal's variance (from its fit) is subtracted. A direction
// left with less than min_direction_information is degenerate: the backgrounds do not determine it
// (a corridor along its axis). Degeneracy is judged at the converged pose (while the pose is wrong
// or the correspondence distance wide, wrong pairs can hide it, or fake it). When there is a
// degenerate direction, the ICP runs again from the initial estimate with every step a
// Gauss-Newton step restricted to the other directions (solution remapping of Zhang, Kaess,
// Singh, "On degeneracy of optimization-based state estimation problems", ICRA 2016): the result
// keeps the initial estimate along the degenerate direction instead of wandering along it.
//
// Consistency score (lower is better, in [0, 1]): the MSAC cost of both backgrounds against each
// other, symmetric and over every background point of both sensors:
//   score = sum over all points i of min(d_i^2, tau^2) / (tau^2 * N),  tau = inlier_distance_m,
// where d_i is the distance of a point of one background, mapped into the other sensor's frame,
// to the line of the other background's nearest point (or to that point when it has no line), and
// a point whose nearest point is farther than max(max_segment_length_m, inlier_distance_m), or
// whose line faces away from its sensor, counts as tau (it lies outside the other sensor's view,
// behind its background, or nothing matches). The denominator is fixed, so the score cannot improve
// by moving the backgrounds out of each other's view; 0 = every point of both backgrounds lies on
// the other's background, 1 = nothing in common.
//
// The refined pose is applied only if (1) the final correspondences number at least
// min_correspondences, (2) at most max_degenerate_directions directions are degenerate, (3) it
// stays within max_translation_change_m and max_yaw_change_deg of the initial estimate (ICP must
// not jump to another basin), and (4) the score drops by at least min_score_improvement. A pair
// with no common background therefore keeps its initial estimate.
//
// Pure and thread-safe (no shared state).

#include <Eigen/Core>
#include <cstddef>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "central_daemon/calibration/types.h"

namespace lrfnet::calib {

struct IcpOptions {
  int max_iterations = 50;
  // Correspondence distance (nearest s point to a mapped r point), metres, annealed geometrically
  // from the initial to the final value over the first anneal_iterations iterations (0: final from
  // the start). The initial value must cover the error of the pairwise estimate (typically a few
  // centimetres and a few tenths of a degree; 2 deg at 10 m is 0.35 m).
  double initial_correspondence_m = 0.75;
  double final_correspondence_m = 0.10;
  int anneal_iterations = 10;
  // Two adjacent beams farther apart than this span a depth jump, not a surface (a wall at 10 m
  // and 80 deg incidence has 0.5 deg beams 0.5 m apart).
  double max_segment_length_m = 0.5;
  // The local line of a background at a beam (see "Method"): fitted over the neighbouring beams
  // within line_radius_m of the beam's point (the adjacent ones also beyond it, so that the sparse
  // points of a far wall get lines too), halved while the points scatter by more than
  // line_tolerance_m (RMS) about the line.
  double line_radius_m = 0.25;
  double line_tolerance_m = 0.03;
  // Fraction of the correspondences with the largest residuals dropped every iteration.
  double trim_fraction = 0.1;
  // Fewer correspondences (after trimming) than this: no common background, not applied.
  std::size_t min_correspondences = 30;
  // The refined pose may differ from the initial one by at most this much.
  double max_translation_change_m = 0.5;
  double max_yaw_change_deg = 5.0;
  // tau of the consistency score.
  double inlier_distance_m = 0.05;
  // Beams beyond this range (and 0 = no return) are ignored, metres.
  double max_range_m = 30.0;
  // The score must drop by at least this much for the result to be applied.
  double min_score_improvement = 0.002;
  // See "Degeneracy" above: the information a direction needs (a correspondence whose normal
  // points along the direction adds 1).
  double min_direction_information = 0.5;
  // Floor of the residual standard deviation of the covariance (real backgrounds have errors
  // correlated between neighbouring beams that the RMS of a near-perfect fit does not show).
  double residual_floor_m = 0.005;
  // The residuals of neighbouring beams are correlated (a wall's points share its discretisation
  // and the fitted lines share points): the variance from the normal equations is multiplied by
  // this factor, as if every residual_correlation-th correspondence were independent. >= 1.
  double residual_correlation = 4.0;
  // Systematic floor of the covariance (beam discretisation, corners a few centimetres off, a
  // background learnt with a person standing still): added in every direction, metres at the
  // matched points' RMS range (for the yaw: this much at that range). >= 0.
  double systematic_floor_m = 0.003;
  // More degenerate directions than this at the final pose: not applied (with two, the
  // backgrounds fix a single combination of x, y and yaw; that is not worth the risk).
  int max_degenerate_directions = 1;
  // Converged when one iteration after the annealing moves less than both.
  double convergence_translation_m = 1e-5;
  double convergence_yaw_rad = 1e-6;
};

std::optional<std::string> Validate(const IcpOptions& options);

struct IcpResult {
  bool applied = false;  // the refined pose is better by the consistency measure and within bounds
  std::string reason;    // why not applied (too few common points, no improvement, moved too far,
                         // bad input); "" when applied
  Pose2 s_from_r;        // refined (== initial when not applied)
  // The consistency score (see above, lower is better) at the initial pose and at the pose the ICP
  // reached (also when that pose was not applied; equal to score_before when the ICP did not run).
  double score_before = 0.0, score_after = 0.0;
  std::size_t correspondences = 0;  // trimmed correspondences at the ICP's final pose
  int iterations = 0;               // of both runs when a degenerate direction made a second one
  // Covariance of (x_m, y_m, yaw_rad) of the ICP's pose: residual_correlation sigma^2 (J^T J)^-1
  // with sigma^2 the residual variance of the final correspondences, at least residual_floor_m^2,
  // plus systematic_floor_m^2 in every direction. Along a degenerate direction the variance is that
  // of the change bound (the pose there is the initial estimate, known no better than the bound).
  // Zero when the ICP did not run.
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  double rms_m = 0.0;              // point-to-line RMS of the final correspondences
  int degenerate_directions = 0;   // at the final pose (0..3)
  std::size_t points = 0;          // background points of both sensors in the score
  std::size_t inliers_before = 0;  // points within inlier_distance_m of the other background
  std::size_t inliers_after = 0;
};

// Why a background cannot be used (nullopt: usable): no beams, more than kMaxIcpBeams beams,
// non-finite angles, a zero step, or beams covering more than a full turn.
inline constexpr std::size_t kMaxIcpBeams = 65536;
std::optional<std::string> CheckBackground(const BackgroundScan& background);

// Refines s_from_r (the pairwise estimate g_rs) with the two backgrounds. Data-caused failure
// (invalid options or backgrounds, no common background, ...) is applied = false with a reason.
IcpResult RefineWithBackgrounds(const BackgroundScan& r_background,
                                const BackgroundScan& s_background, const Pose2& s_from_r,
                                const IcpOptions& options);

// The background's points in its sensor frame (metres), in beam order, skipping beams without a
// return (0) and beyond max_range_m (<= 0: no limit). Empty when CheckBackground fails.
std::vector<Eigen::Vector2d> BackgroundPoints(const BackgroundScan& background, double max_range_m);

// The consistency score (see above) of two backgrounds under s_from_r, without running the ICP.
// nullopt when the options or a background are invalid.
struct BackgroundConsistency {
  double score = 1.0;
  std::size_t points = 0;
  std::size_t inliers = 0;
};
std::optional<BackgroundConsistency> ScoreBackgrounds(const BackgroundScan& r_background,
                                                      const BackgroundScan& s_background,
                                                      const Pose2& s_from_r,
                                                      const IcpOptions& options);

namespace internal {
// A point-to-line correspondence: r's point p_r (r frame) belongs on the line through q_s with unit
// normal n_s (s frame).
struct LineCorrespondence {
  Eigen::Vector2d p_r = Eigen::Vector2d::Zero();
  Eigen::Vector2d q_s = Eigen::Vector2d::Zero();
  Eigen::Vector2d n_s = Eigen::Vector2d::UnitX();
};
// Censi's exact minimiser of sum_i (n_i^T (R(yaw) p_i + t - q_i))^2 over (t, yaw), for any
// rotation (no small-angle linearisation). nullopt when the lines leave the translation or the
// rotation unconstrained (fewer than two independent normals, all points at the origin).
std::optional<Pose2> SolvePointToLine(std::span<const LineCorrespondence> correspondences);
}  // namespace internal

}  // namespace lrfnet::calib
