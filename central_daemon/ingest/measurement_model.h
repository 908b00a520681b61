#pragma once
// What is left of the measurement bias of a tracked position (DESIGN.md "Measurement model"): the
// one model of it, per sample, used by calibration (pairwise estimates, their verification, the
// joint refinement) and fusion alike. Pure functions on values (sensor frame, metres, radians).
//
// A tracker reports a point of the object it measured with some estimator (TrackObservation::kind)
// from the object's visible side. A laser scanner sees the near side only, so unless the estimator
// places its point at the centre of the body, the reported point lies closer to the sensor than
// the body centre, along the line of sight. This model gives that offset, its uncertainty, and the
// part of it that depends on the size of the body the tracker did not measure:
//
//   reported = centre - b u,   u = unit vector from the sensor to the object,
//   b = b0 + db/dmajor * d_major + db/dminor * d_minor   (d_*: correction of the prior's semi-axes)
//
// The body is an ellipse with semi-axes (major, minor) (a person's torso: major across the
// shoulders, i.e. perpendicular to the walking direction). Seen along a line of sight at angle psi
// to its major axis it reaches
//
//   h(psi) = (cos^2 psi / major^2 + sin^2 psi / minor^2)^(-1/2)
//
// in front of its centre (the half depth along the line of sight). Per estimator:
//   - centre of mass of the visible contour (kCenterOfMass; and kUnspecified, which old trackers
//     send for the same estimator): the beams of a scanner are uniform in angle, i.e. (at a range
//     much larger than the body) uniform across the line of sight; the contour's depth averaged
//     uniformly over the visible width is pi/4 h (a cylinder of radius R: pi R / 4, ~0.2 m for
//     R = 0.25 m), whatever the number of points (their phase is random), so b = pi/4 h(psi);
//   - fixed-axes ellipse (kEllipse, Quenzel et al. eqs. 3-4 with a, b fixed): the fitted ellipse
//     touches the visible side and puts its centre h_fixed(psi) behind it, so b = h(psi) -
//     h_fixed(psi) (0 for a body of the fixed size; a 0.25 m cylinder gives ~0.1 m);
//   - shape fit (kShapeFit): the body centre from a fit with the track's own size: b = 0, with the
//     residual uncertainty of that size (TrackObservation::size_sigma_m, or a default).
// The body's axes come from the tracker's size estimate when it sends one (size_major_m > 0) and
// otherwise from the prior (options); psi from the ellipse orientation the tracker fitted, else
// from the walking direction (the major axis across it) when the object moves, else unknown: b and
// its spread are then averaged over all psi.
//
// What the model does not know goes into two standard deviations: size_sigma_m (radial, of b: the
// size's uncertainty that is not the shared prior correction; e.g. the tracker's size_sigma_m) and
// sigma_m (isotropic, the per-sample scatter of the estimator around that, beyond the tracker's own
// covariance: contour sampling, partial views, a fit that settles on another orientation).

#include <cstdint>
#include <optional>
#include <string>

#include "central_daemon/ingest/sensor_data.h"

namespace lrfnet::daemon {

struct MeasurementModelOptions {
  // The body of an object whose tracker sends no size (old trackers; centre-of-mass and
  // fixed-axes ellipse trackers): a person's torso at upper-body height (Quenzel et al.: the
  // ellipse a = 0.25 m, b = 0.15 m "fits a human at upper body height"). Semi-axes, metres.
  double prior_major_m = 0.25;
  double prior_minor_m = 0.15;
  // One standard deviation of each prior semi-axis: how much the people (or objects) of a site
  // may differ from it. A size correction is shared by every sample of prior size (calibration
  // estimates it where the data observe it, else carries this uncertainty).
  double prior_size_sigma_m = 0.05;
  // Legs at knee height (ObjectShape::kLegs without a size): one leg's cross-section radius.
  double prior_leg_radius_m = 0.06;
  // The fixed semi-axes of the tracker's ellipse fit (its measurement.ellipse_major_m / _minor_m).
  double ellipse_major_m = 0.25;
  double ellipse_minor_m = 0.15;
  // Residual radial uncertainty of a shape fit whose tracker sends no size_sigma_m.
  double shape_fit_size_sigma_m = 0.02;
  // One standard deviation of what is left of a shape fit's bias along the line of sight and
  // shared by every sample of one sensor (CentreBias::shared_sigma_m): the fit's size and centre
  // settle a little off for the people and the view a sensor has, the same way for all its
  // tracks. tracking_benchmark measures it per scene and mount: the torso shape fit's mean radial
  // error per shipped scene is -0.017 to +0.023 m (office_distributed +0.019 m). The other kinds'
  // shared bias is the size correction of the prior (per_major_m_per_m, per_minor_m_per_m).
  double shape_fit_shared_bias_sigma_m = 0.02;
  // Per-sample scatter beyond the tracker's covariance, by estimator (isotropic, 1 sigma).
  double com_sigma_m = 0.03;
  double ellipse_sigma_m = 0.03;
  double shape_fit_sigma_m = 0.02;
  double unspecified_sigma_m = 0.05;
  // The walking direction gives the body's orientation only above this speed.
  double min_heading_speed_mps = 0.3;
};

// nullopt when valid, else the reason naming the field.
std::optional<std::string> Validate(const MeasurementModelOptions& options);

// What the tracker measured one position with (a TrackObservation, or a smoothed sample of one).
struct MeasurementContext {
  MeasurementKind kind = MeasurementKind::kUnspecified;
  std::uint32_t points = 0;  // points of the segment (0: coasting or unknown)
  double x_m = 0.0;          // the reported position, sensor frame
  double y_m = 0.0;
  double vx_mps = 0.0;  // velocity, sensor frame (the walking direction)
  double vy_mps = 0.0;
  bool has_ellipse_yaw = false;  // the tracker fitted an orientation (kind kEllipse / kShapeFit)
  double ellipse_yaw_rad = 0.0;  // its major axis, sensor frame
  ObjectShape shape = ObjectShape::kUnspecified;
  double size_major_m = 0.0;  // the tracker's size estimate; 0: none (use the prior)
  double size_minor_m = 0.0;
  double size_sigma_m = 0.0;
};

// The context of one observation as the tracker sent it.
MeasurementContext ContextOf(const TrackObservation& observation);

// See the header comment: reported = centre - b u, b = toward_sensor_m + per_major_m_per_m *
// d_major + per_minor_m_per_m * d_minor.
struct CentreBias {
  double toward_sensor_m = 0.0;
  // Sensitivity of b to a correction of the prior's semi-axes (0 when the tracker measured the
  // size itself, or for a shape fit).
  double per_major_m_per_m = 0.0;
  double per_minor_m_per_m = 0.0;
  double size_sigma_m = 0.0;  // radial, 1 sigma, not shared with other samples' prior correction
  double sigma_m = 0.0;       // isotropic, 1 sigma
  // Radial, 1 sigma, one value shared by all samples of one sensor and kind (not in size_sigma_m
  // or sigma_m: it does not average out over a sensor's samples).
  double shared_sigma_m = 0.0;
};

CentreBias CentreBiasOf(const MeasurementContext& context, const MeasurementModelOptions& options);

// h(psi) of the header comment: how far an ellipse with these semi-axes reaches in front of its
// centre along a line of sight at angle psi_rad to its major axis. Semi-axes > 0.
double HalfDepthM(double major_m, double minor_m, double psi_rad);

// The body centre an observation implies (its position moved out along the line of sight by the
// expected bias) and the variance to add isotropically to its position covariance for what the
// model does not know (sigma_m^2 plus the size uncertainty, the prior's included, along the line
// of sight, spread isotropically: an upper bound of both directions). For consumers that do not
// estimate the size correction (fusion).
struct CorrectedPosition {
  double x_m = 0.0;
  double y_m = 0.0;
  double extra_variance_m2 = 0.0;
};
CorrectedPosition CorrectedPositionOf(const TrackObservation& observation,
                                      const MeasurementModelOptions& options);

}  // namespace lrfnet::daemon
