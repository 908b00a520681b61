#include "central_daemon/ingest/measurement_model.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace lrfnet::daemon {
namespace {

constexpr double kPi = std::numbers::pi;
// The visible contour's centre of mass lies pi/4 of the half depth in front of the centre (see the
// header: the depth sqrt(1 - t^2) averaged over t uniform in [-1, 1]).
constexpr double kComFraction = kPi / 4.0;
// Orientations averaged over when the body's orientation is unknown (psi in [0, pi), symmetric).
constexpr int kPsiSamples = 16;
// Below this range the line of sight is undefined; no object sits on a sensor.
constexpr double kMinRangeM = 1e-3;

bool Positive(double v) { return std::isfinite(v) && v > 0.0; }

// h(psi) and its derivatives with respect to the two semi-axes.
struct Depth {
  double h = 0.0;
  double per_major = 0.0;
  double per_minor = 0.0;
};

Depth DepthOf(double major_m, double minor_m, double psi_rad) {
  const double c = std::cos(psi_rad), s = std::sin(psi_rad);
  const double q = c * c / (major_m * major_m) + s * s / (minor_m * minor_m);
  Depth d;
  d.h = 1.0 / std::sqrt(q);
  const double h3 = d.h * d.h * d.h;
  d.per_major = h3 * c * c / (major_m * major_m * major_m);
  d.per_minor = h3 * s * s / (minor_m * minor_m * minor_m);
  return d;
}

// b and its sensitivities for one orientation (see the header comment).
CentreBias AtOrientation(MeasurementKind kind, double major_m, double minor_m, double psi_rad,
                         const MeasurementModelOptions& o) {
  CentreBias b;
  const Depth body = DepthOf(major_m, minor_m, psi_rad);
  switch (kind) {
    case MeasurementKind::kEllipse: {
      const Depth fixed = DepthOf(o.ellipse_major_m, o.ellipse_minor_m, psi_rad);
      b.toward_sensor_m = body.h - fixed.h;
      b.per_major_m_per_m = body.per_major;
      b.per_minor_m_per_m = body.per_minor;
      break;
    }
    case MeasurementKind::kShapeFit:
      break;
    case MeasurementKind::kCenterOfMass:
    case MeasurementKind::kUnspecified:
      b.toward_sensor_m = kComFraction * body.h;
      b.per_major_m_per_m = kComFraction * body.per_major;
      b.per_minor_m_per_m = kComFraction * body.per_minor;
      break;
  }
  return b;
}

double SigmaOf(MeasurementKind kind, const MeasurementModelOptions& o) {
  switch (kind) {
    case MeasurementKind::kCenterOfMass:
      return o.com_sigma_m;
    case MeasurementKind::kEllipse:
      return o.ellipse_sigma_m;
    case MeasurementKind::kShapeFit:
      return o.shape_fit_sigma_m;
    case MeasurementKind::kUnspecified:
      break;
  }
  return o.unspecified_sigma_m;
}

}  // namespace

std::optional<std::string> Validate(const MeasurementModelOptions& o) {
  if (!Positive(o.prior_major_m) || !Positive(o.prior_minor_m)) {
    return "prior_major_m and prior_minor_m must be > 0";
  }
  if (!(o.prior_major_m <= 5.0 && o.prior_minor_m <= 5.0)) {
    return "prior_major_m and prior_minor_m must be at most 5 m";
  }
  if (!(std::isfinite(o.prior_size_sigma_m) && o.prior_size_sigma_m >= 0.0 &&
        o.prior_size_sigma_m <= 5.0)) {
    return "prior_size_sigma_m must be in [0, 5]";
  }
  if (!Positive(o.prior_leg_radius_m) || o.prior_leg_radius_m > 5.0) {
    return "prior_leg_radius_m must be in (0, 5]";
  }
  if (!Positive(o.ellipse_major_m) || !Positive(o.ellipse_minor_m) || o.ellipse_major_m > 5.0 ||
      o.ellipse_minor_m > 5.0) {
    return "ellipse_major_m and ellipse_minor_m must be in (0, 5]";
  }
  for (const double v : {o.shape_fit_size_sigma_m, o.shape_fit_shared_bias_sigma_m, o.com_sigma_m,
                         o.ellipse_sigma_m, o.shape_fit_sigma_m, o.unspecified_sigma_m}) {
    if (!(std::isfinite(v) && v >= 0.0 && v <= 5.0)) {
      return "shape_fit_size_sigma_m, shape_fit_shared_bias_sigma_m and *_sigma_m must be in "
             "[0, 5]";
    }
  }
  if (!(std::isfinite(o.min_heading_speed_mps) && o.min_heading_speed_mps >= 0.0)) {
    return "min_heading_speed_mps must be >= 0";
  }
  return std::nullopt;
}

double HalfDepthM(double major_m, double minor_m, double psi_rad) {
  return DepthOf(major_m, minor_m, psi_rad).h;
}

MeasurementContext ContextOf(const TrackObservation& o) {
  MeasurementContext c;
  c.kind = o.kind;
  c.points = o.points;
  c.x_m = o.x_m;
  c.y_m = o.y_m;
  c.vx_mps = o.vx_mps;
  c.vy_mps = o.vy_mps;
  c.has_ellipse_yaw = o.kind == MeasurementKind::kEllipse || o.kind == MeasurementKind::kShapeFit;
  c.ellipse_yaw_rad = o.ellipse_yaw_rad;
  c.shape = o.shape;
  c.size_major_m = o.size_major_m;
  c.size_minor_m = o.size_minor_m;
  c.size_sigma_m = o.size_sigma_m;
  return c;
}

CentreBias CentreBiasOf(const MeasurementContext& c, const MeasurementModelOptions& o) {
  CentreBias out;
  out.sigma_m = SigmaOf(c.kind, o);
  const double range = std::hypot(c.x_m, c.y_m);
  if (!std::isfinite(range) || range < kMinRangeM) return out;

  if (c.kind == MeasurementKind::kShapeFit) {
    // The body centre with the track's own size: what is left is that size's error.
    out.size_sigma_m =
        Positive(c.size_sigma_m) ? std::min(c.size_sigma_m, 5.0) : o.shape_fit_size_sigma_m;
    out.shared_sigma_m = o.shape_fit_shared_bias_sigma_m;
    return out;
  }

  // The body: the tracker's size when it measured one, else the prior (whose correction the
  // caller may estimate: the sensitivities).
  const bool measured_size = Positive(c.size_major_m) && Positive(c.size_minor_m) &&
                             c.size_major_m <= 5.0 && c.size_minor_m <= 5.0;
  double major = o.prior_major_m, minor = o.prior_minor_m;
  bool shared_prior = true;
  if (measured_size) {
    major = std::max(c.size_major_m, c.size_minor_m);
    minor = std::min(c.size_major_m, c.size_minor_m);
    shared_prior = false;
  } else if (c.shape == ObjectShape::kLegs) {
    major = minor = o.prior_leg_radius_m;
    shared_prior = false;
  }

  // The body's orientation: the tracker's fitted axis, else the walking direction (the major axis
  // across it), else unknown.
  const double line_of_sight = std::atan2(c.y_m, c.x_m);
  const double speed = std::hypot(c.vx_mps, c.vy_mps);
  bool known = true;
  double major_axis = 0.0;
  if (c.has_ellipse_yaw && std::isfinite(c.ellipse_yaw_rad)) {
    major_axis = c.ellipse_yaw_rad;
  } else if (std::isfinite(speed) && speed >= o.min_heading_speed_mps && speed > 0.0) {
    major_axis = std::atan2(c.vy_mps, c.vx_mps) + 0.5 * kPi;
  } else {
    known = false;
  }

  double spread = 0.0;  // radial spread of b over the unknown orientation
  if (known || major == minor) {
    const CentreBias b = AtOrientation(c.kind, major, minor, line_of_sight - major_axis, o);
    out.toward_sensor_m = b.toward_sensor_m;
    out.per_major_m_per_m = b.per_major_m_per_m;
    out.per_minor_m_per_m = b.per_minor_m_per_m;
  } else {
    double sum = 0.0, sum2 = 0.0, pa = 0.0, pb = 0.0;
    for (int k = 0; k < kPsiSamples; ++k) {
      const double psi = (k + 0.5) * kPi / kPsiSamples;
      const CentreBias b = AtOrientation(c.kind, major, minor, psi, o);
      sum += b.toward_sensor_m;
      sum2 += b.toward_sensor_m * b.toward_sensor_m;
      pa += b.per_major_m_per_m;
      pb += b.per_minor_m_per_m;
    }
    const double mean = sum / kPsiSamples;
    out.toward_sensor_m = mean;
    out.per_major_m_per_m = pa / kPsiSamples;
    out.per_minor_m_per_m = pb / kPsiSamples;
    spread = std::sqrt(std::max(0.0, sum2 / kPsiSamples - mean * mean));
  }

  double size_sigma = 0.0;
  if (measured_size && Positive(c.size_sigma_m)) {
    // The size's own uncertainty moves b by its sensitivity to both axes.
    const double k = std::hypot(out.per_major_m_per_m, out.per_minor_m_per_m);
    size_sigma = k * std::min(c.size_sigma_m, 5.0);
  }
  if (!shared_prior) {
    out.per_major_m_per_m = 0.0;
    out.per_minor_m_per_m = 0.0;
  }
  out.size_sigma_m = std::hypot(size_sigma, spread);
  return out;
}

CorrectedPosition CorrectedPositionOf(const TrackObservation& observation,
                                      const MeasurementModelOptions& options) {
  const MeasurementContext c = ContextOf(observation);
  const CentreBias b = CentreBiasOf(c, options);
  CorrectedPosition out;
  out.x_m = c.x_m;
  out.y_m = c.y_m;
  const double range = std::hypot(c.x_m, c.y_m);
  if (std::isfinite(range) && range >= kMinRangeM) {
    out.x_m += b.toward_sensor_m * c.x_m / range;
    out.y_m += b.toward_sensor_m * c.y_m / range;
  }
  const double prior =
      options.prior_size_sigma_m * std::hypot(b.per_major_m_per_m, b.per_minor_m_per_m);
  out.extra_variance_m2 = b.sigma_m * b.sigma_m + b.size_sigma_m * b.size_sigma_m + prior * prior;
  return out;
}

}  // namespace lrfnet::daemon
