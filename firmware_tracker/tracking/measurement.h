#pragma once
// Position measurements of one segment (Quenzel et al., section III-B), the method of the previous
// tracker kept for comparison (MeasurementMethod kCenterOfMass / kEllipse); the default shape fit
// lives in shape_fit.h and pipeline.h.
//
// - Centre of mass (CoM): the mean of the segment's points. Its covariance is com_sigma_m^2 * I:
// the CoM
//   of a person's visible side moves with the viewpoint (the paper reports ~40 cm between two
//   sensors on a cylinder), which dwarfs the range noise.
// - Ellipse: the paper's two steps. First Fitzgibbon's direct least-squares ellipse fit, computed
// in the
//   numerically stable form of Halir and Flusser, gives an initial centre and orientation. Then
//   eqs. 3-4 fit an ellipse with fixed semi-axes a, b (0.25 m, 0.15 m: a person at upper-body
//   height):
//       x* = argmin_[theta, alpha, t] ||f(x)||^2                                   (3)
//       f_i(x) = S_i - ( R(alpha) * (a cos(theta_i), b sin(theta_i))^T + t )       (4)
//   over the per-point ellipse angles theta_i, the orientation alpha and the centre t, by
//   Levenberg- Marquardt with the theta_i eliminated through the Schur complement (fixed-size 3x3
//   solves). The sensor sees only the near side of a person, so t lies behind the visible points; a
//   fit whose centre is not behind the CoM, is far from it, or is too uncertain falls back to the
//   CoM (kind says which was used). Covariance of t: the (alpha, t) block of (J^T J)^-1 after
//   eliminating theta, scaled by the residual variance (floored at min_point_sigma_m^2),
//   eigenvalues floored at min_position_sigma_m^2.
//
// Frames: points and results are in the sensor frame (sensor at the origin, metres, radians). Pure
// and allocation-free: per-point scratch lives on the stack, bounded by kMaxSegmentPoints.

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>

namespace lrfnet::tracking {

// How a measurement's position was obtained (the wire's MeasurementKind).
enum class MeasurementKind : std::uint8_t { kCenterOfMass, kEllipse, kShapeFit };

// Which estimator the pipeline uses: the body centre from the known-shape fit (default), or the
// previous tracker's centre of mass / fixed-axes ellipse with its fallback to the centre of mass.
enum class MeasurementMethod : std::uint8_t { kCenterOfMass, kEllipse, kShapeFit };

// The scan plane's height: what a person looks like (one upper body, or two legs).
enum class Mount : std::uint8_t { kTorso, kLegs };

// Options of the previous tracker's estimators (MeasureSegment).
struct MeasurementOptions {
  bool fit_ellipse = true;        // false: centre of mass only
  double ellipse_major_m = 0.25;  // a in eq. 4
  double ellipse_minor_m = 0.15;  // b in eq. 4
  std::size_t min_ellipse_points = 5;
  int max_iterations = 20;
  double com_sigma_m = 0.10;
  double min_point_sigma_m = 0.01;
  double min_position_sigma_m = 0.01;
  double max_position_sigma_m = 0.30;
  double max_centre_offset_m = 0.60;  // ellipse centre to CoM
};

std::optional<std::string> Validate(const MeasurementOptions& options);

struct Measurement {
  MeasurementKind kind = MeasurementKind::kCenterOfMass;
  Eigen::Vector2d position_m = Eigen::Vector2d::Zero();  // sensor frame
  Eigen::Matrix2d covariance_m2 = Eigen::Matrix2d::Identity();
  double orientation_rad = 0.0;  // ellipse major axis direction in (-pi/2, pi/2]; 0 for CoM
  double rms_residual_m = 0.0;   // ellipse fit; 0 for CoM
  std::size_t point_count = 0;
  // Evidence for a confirmed track only (MultiTracker): it may update a confirmed track whose gate
  // it falls within, never a tentative one, and never starts or resumes a track.
  bool evidence_only = false;
  // Two legs seen still (ShapeOptions::still_legs_cov): the share of covariance_m2 this
  // measurement's error does not have, though the filter's gains are computed with it; the
  // covariance the tracker reports follows the gains with covariance_m2 less this
  // (MultiTracker, CvEkf::gain_covariance). Zero: none (positive semi-definite, no larger than
  // covariance_m2).
  Eigen::Matrix2d gain_relief_m2 = Eigen::Matrix2d::Zero();
  // ... and the object did not move since the track's last measurement: the process noise
  // predicted since is not in the reported covariance (CvEkf::RelieveGainProcessNoise).
  bool gain_still = false;
  // Two legs of a walking track (ShapeOptions::walking_legs_cov): as gain_still, the process
  // noise predicted since the last update is not in the reported covariance (the gait's share of
  // it is reported apart), though the object moved.
  bool gain_walking = false;
  // The reported covariance starts again from the filter's own before this update
  // (CvEkf::StartGainCovariance): the track's last update was gain_walking's, this one is not.
  bool gain_restart = false;
};

// Precondition: points is not empty.
Eigen::Vector2d CenterOfMass(std::span<const Eigen::Vector2d> points);

struct ConicEllipse {
  Eigen::Vector2d center_m = Eigen::Vector2d::Zero();
  double semi_major_m = 0.0;
  double semi_minor_m = 0.0;
  double orientation_rad = 0.0;  // major axis direction in (-pi/2, pi/2]
};

// Fitzgibbon direct least-squares ellipse (Halir-Flusser form). nullopt for fewer than 5 points,
// collinear or otherwise degenerate points, non-finite input, or when the best conic is not a real
// ellipse.
std::optional<ConicEllipse> FitConicEllipse(std::span<const Eigen::Vector2d> points);

// CoM, or the fixed-axes ellipse of eqs. 3-4 when options.fit_ellipse and the fit is usable. Points
// beyond kMaxSegmentPoints are ignored by the ellipse fit. Precondition: points is not empty;
// options valid.
Measurement MeasureSegment(std::span<const Eigen::Vector2d> points,
                           const MeasurementOptions& options);

}  // namespace lrfnet::tracking
