#include "firmware_tracker/tracking/measurement.h"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cmath>
#include <complex>

#include "common/eigen_instances.h"
#include "common/geometry.h"
#include "firmware_tracker/tracking/segmentation.h"

namespace lrfnet::tracking {

std::optional<std::string> Validate(const MeasurementOptions& o) {
  auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  if (!positive(o.ellipse_minor_m) || !positive(o.ellipse_major_m) ||
      o.ellipse_minor_m > o.ellipse_major_m) {
    return "ellipse axes must satisfy 0 < ellipse_minor_m <= ellipse_major_m";
  }
  if (o.min_ellipse_points < 4) return "min_ellipse_points must be >= 4 (3 unknowns + redundancy)";
  if (o.max_iterations < 1) return "max_iterations must be >= 1";
  if (!positive(o.com_sigma_m)) return "com_sigma_m must be > 0";
  if (!positive(o.min_point_sigma_m)) return "min_point_sigma_m must be > 0";
  if (!positive(o.min_position_sigma_m) || !positive(o.max_position_sigma_m) ||
      o.max_position_sigma_m < o.min_position_sigma_m) {
    return "need 0 < min_position_sigma_m <= max_position_sigma_m";
  }
  if (!positive(o.max_centre_offset_m)) return "max_centre_offset_m must be > 0";
  return std::nullopt;
}

Eigen::Vector2d CenterOfMass(std::span<const Eigen::Vector2d> points) {
  Eigen::Vector2d sum = Eigen::Vector2d::Zero();
  for (const auto& p : points) sum += p;
  return sum / static_cast<double>(points.size());
}

namespace {

// Major-axis directions are defined modulo pi.
double NormalizeAxisAngle(double angle_rad) {
  double a = common::NormalizeAngle(angle_rad);
  if (a <= -common::kPi / 2) a += common::kPi;
  if (a > common::kPi / 2) a -= common::kPi;
  return a;
}

Eigen::Matrix2d Rotation(double angle_rad) {
  const double c = std::cos(angle_rad), s = std::sin(angle_rad);
  Eigen::Matrix2d r;
  r << c, -s, s, c;
  return r;
}

}  // namespace

std::optional<ConicEllipse> FitConicEllipse(std::span<const Eigen::Vector2d> points) {
  if (points.size() < 5) return std::nullopt;
  for (const auto& p : points) {
    if (!p.allFinite()) return std::nullopt;
  }
  // Centre and scale to unit RMS radius first: the scatter matrices mix 4th and 0th powers of the
  // coordinates and lose precision at metre scale far from the origin.
  const Eigen::Vector2d mean = CenterOfMass(points);
  double sq = 0.0;
  for (const auto& p : points) sq += (p - mean).squaredNorm();
  const double scale = std::sqrt(sq / static_cast<double>(points.size()));
  if (!(scale > 1e-9)) return std::nullopt;

  // Halir & Flusser: design matrix split into quadratic D1 = [x^2, xy, y^2] and linear D2 = [x, y,
  // 1] parts; S1 = D1'D1, S2 = D1'D2, S3 = D2'D2.
  Eigen::Matrix3d s1 = Eigen::Matrix3d::Zero(), s2 = Eigen::Matrix3d::Zero(),
                  s3 = Eigen::Matrix3d::Zero();
  for (const auto& p : points) {
    const Eigen::Vector2d q = (p - mean) / scale;
    const Eigen::Vector3d d1(q.x() * q.x(), q.x() * q.y(), q.y() * q.y());
    const Eigen::Vector3d d2(q.x(), q.y(), 1.0);
    s1 += d1 * d1.transpose();
    s2 += d1 * d2.transpose();
    s3 += d2 * d2.transpose();
  }
  Eigen::Matrix3d s3_inv;
  bool invertible = false;
  s3.computeInverseWithCheck(s3_inv, invertible, 1e-12);
  if (!invertible) return std::nullopt;  // collinear points
  const Eigen::Matrix3d t = -s3_inv * s2.transpose();
  const Eigen::Matrix3d m = s1 + s2 * t;
  // Reduced scatter matrix premultiplied by the inverse of the constraint matrix C1 (4ac - b^2 =
  // 1).
  Eigen::Matrix3d reduced;
  reduced.row(0) = m.row(2) / 2.0;
  reduced.row(1) = -m.row(1);
  reduced.row(2) = m.row(0) / 2.0;
  if (!reduced.allFinite()) return std::nullopt;

  const Eigen::EigenSolver<Eigen::Matrix3d> solver(reduced);
  if (solver.info() != Eigen::Success) return std::nullopt;
  Eigen::Vector3d a1 = Eigen::Vector3d::Zero();
  bool found = false;
  double best_cond = 0.0;
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d v = solver.eigenvectors().col(k).real();
    const double cond = 4.0 * v(0) * v(2) - v(1) * v(1);
    if (cond > best_cond) {
      best_cond = cond;
      a1 = v;
      found = true;
    }
  }
  if (!found) return std::nullopt;
  const Eigen::Vector3d a2 = t * a1;
  const double ca = a1(0), cb = a1(1), cc = a1(2), cd = a2(0), ce = a2(1), cf = a2(2);

  Eigen::Matrix2d q;
  q << ca, cb / 2.0, cb / 2.0, cc;
  Eigen::Matrix2d q2 = 2.0 * q;
  bool q_invertible = false;
  Eigen::Matrix2d q2_inv;
  q2.computeInverseWithCheck(q2_inv, q_invertible, 1e-12);
  if (!q_invertible) return std::nullopt;
  const Eigen::Vector2d centre = q2_inv * Eigen::Vector2d(-cd, -ce);
  const double f_centre = cf + 0.5 * (cd * centre.x() + ce * centre.y());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(q);
  const Eigen::Vector2d lambda = eig.eigenvalues();  // ascending
  const double axis0_sq = -f_centre / lambda(0);
  const double axis1_sq = -f_centre / lambda(1);
  if (!(axis0_sq > 0.0 && axis1_sq > 0.0) || !std::isfinite(axis0_sq + axis1_sq))
    return std::nullopt;

  // The larger semi-axis belongs to the eigenvalue of smaller magnitude.
  const int major = std::abs(lambda(0)) < std::abs(lambda(1)) ? 0 : 1;
  const Eigen::Vector2d major_dir = eig.eigenvectors().col(major);
  ConicEllipse e;
  e.center_m = centre * scale + mean;
  e.semi_major_m = std::sqrt(major == 0 ? axis0_sq : axis1_sq) * scale;
  e.semi_minor_m = std::sqrt(major == 0 ? axis1_sq : axis0_sq) * scale;
  e.orientation_rad = NormalizeAxisAngle(std::atan2(major_dir.y(), major_dir.x()));
  if (!e.center_m.allFinite()) return std::nullopt;
  return e;
}

namespace {

struct FixedAxesFit {
  bool ok = false;
  Eigen::Vector2d centre_m = Eigen::Vector2d::Zero();
  double alpha_rad = 0.0;
  Eigen::Matrix2d covariance_m2 = Eigen::Matrix2d::Zero();
  double rms_m = 0.0;
};

// One linearisation of eq. 4 for all points: accumulates the Schur complement of the theta block.
struct Linearised {
  Eigen::Matrix3d reduced_h = Eigen::Matrix3d::Zero();  // over (alpha, tx, ty)
  Eigen::Vector3d reduced_rhs = Eigen::Vector3d::Zero();
  double cost = 0.0;
};

double Cost(std::span<const Eigen::Vector2d> pts, const double* theta, double alpha,
            const Eigen::Vector2d& t, double a, double b) {
  const Eigen::Matrix2d r = Rotation(alpha);
  double cost = 0.0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const Eigen::Vector2d e(a * std::cos(theta[i]), b * std::sin(theta[i]));
    cost += (pts[i] - (r * e + t)).squaredNorm();
  }
  return cost;
}

// Levenberg-Marquardt on eq. 3. Unknowns: theta_i (one per point) and p = (alpha, tx, ty). Each
// point's residual f_i depends on theta_i and p only, so the normal equations have a diagonal theta
// block that is eliminated exactly (Schur complement), leaving a 3x3 system per iteration.
FixedAxesFit FitFixedAxes(std::span<const Eigen::Vector2d> pts, Eigen::Vector2d t, double alpha,
                          const MeasurementOptions& o) {
  const double a = o.ellipse_major_m, b = o.ellipse_minor_m;
  const std::size_t n = pts.size();
  std::array<double, kMaxSegmentPoints> theta{};
  std::array<double, kMaxSegmentPoints> theta_trial{};
  std::array<double, kMaxSegmentPoints> h_theta{};
  std::array<Eigen::Vector3d, kMaxSegmentPoints> h_theta_p{};
  std::array<double, kMaxSegmentPoints> g_theta{};

  {
    const Eigen::Matrix2d rt = Rotation(alpha).transpose();
    for (std::size_t i = 0; i < n; ++i) {
      const Eigen::Vector2d q = rt * (pts[i] - t);
      theta[i] = std::atan2(q.y() / b, q.x() / a);
    }
  }
  const Eigen::Matrix2d j_rot = (Eigen::Matrix2d() << 0.0, -1.0, 1.0, 0.0).finished();

  // Builds the damped (lambda) normal equations at the current estimate, reduced to p.
  auto linearise = [&](double lambda, Linearised& lin) {
    const Eigen::Matrix2d r = Rotation(alpha);
    Eigen::Matrix3d h_pp = Eigen::Matrix3d::Zero();
    Eigen::Vector3d g_p = Eigen::Vector3d::Zero();
    lin.cost = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      const double c = std::cos(theta[i]), s = std::sin(theta[i]);
      const Eigen::Vector2d e(a * c, b * s);
      const Eigen::Vector2d f = pts[i] - (r * e + t);
      // Jacobians of f_i (eq. 4): d/dtheta_i, d/dalpha (dR/dalpha = R J), d/dt = -I.
      const Eigen::Vector2d j_theta = -(r * Eigen::Vector2d(-a * s, b * c));
      Eigen::Matrix<double, 2, 3> j_p;
      j_p.col(0) = -(r * (j_rot * e));
      j_p.block<2, 2>(0, 1) = -Eigen::Matrix2d::Identity();
      h_theta[i] = j_theta.squaredNorm() + lambda;
      h_theta_p[i] = j_p.transpose() * j_theta;
      g_theta[i] = j_theta.dot(f);
      h_pp += j_p.transpose() * j_p;
      g_p += j_p.transpose() * f;
      lin.cost += f.squaredNorm();
    }
    h_pp += lambda * Eigen::Matrix3d::Identity();
    lin.reduced_h = h_pp;
    lin.reduced_rhs = -g_p;
    for (std::size_t i = 0; i < n; ++i) {
      lin.reduced_h -= h_theta_p[i] * h_theta_p[i].transpose() / h_theta[i];
      lin.reduced_rhs += h_theta_p[i] * (g_theta[i] / h_theta[i]);
    }
  };

  double lambda = 1e-3;
  Linearised lin;
  for (int iter = 0; iter < o.max_iterations; ++iter) {
    linearise(lambda, lin);
    bool invertible = false;
    Eigen::Matrix3d h_inv;
    lin.reduced_h.computeInverseWithCheck(h_inv, invertible, 1e-15);
    if (!invertible) {
      lambda *= 10.0;
      continue;
    }
    const Eigen::Vector3d dp = h_inv * lin.reduced_rhs;
    for (std::size_t i = 0; i < n; ++i) {
      theta_trial[i] = theta[i] + (-g_theta[i] - h_theta_p[i].dot(dp)) / h_theta[i];
    }
    const double alpha_trial = alpha + dp(0);
    const Eigen::Vector2d t_trial = t + dp.tail<2>();
    const double cost_trial = Cost(pts, theta_trial.data(), alpha_trial, t_trial, a, b);
    if (std::isfinite(cost_trial) && cost_trial <= lin.cost) {
      std::copy_n(theta_trial.begin(), n, theta.begin());
      alpha = alpha_trial;
      t = t_trial;
      lambda = std::max(lambda / 10.0, 1e-9);
      if (dp.norm() < 1e-7) break;
    } else {
      lambda *= 10.0;
      if (lambda > 1e6) break;
    }
  }

  // Covariance at the estimate: undamped reduced normal matrix = inverse of the (alpha, t) block of
  // (J^T J)^-1; scaled by the residual variance with n*2 residuals and n + 3 unknowns.
  linearise(0.0, lin);
  FixedAxesFit fit;
  const double dof = static_cast<double>(2 * n) - static_cast<double>(n + 3);
  if (dof < 1.0) return fit;
  const double sigma2 = std::max(lin.cost / dof, o.min_point_sigma_m * o.min_point_sigma_m);
  bool invertible = false;
  Eigen::Matrix3d cov_p;
  lin.reduced_h.computeInverseWithCheck(cov_p, invertible, 1e-15);
  if (!invertible) return fit;
  cov_p *= sigma2;
  Eigen::Matrix2d cov_t = cov_p.block<2, 2>(1, 1);
  cov_t = 0.5 * (cov_t + cov_t.transpose());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov_t);
  Eigen::Vector2d ev = eig.eigenvalues();
  const double floor = o.min_position_sigma_m * o.min_position_sigma_m;
  if (!ev.allFinite() || ev(1) > o.max_position_sigma_m * o.max_position_sigma_m) return fit;
  ev = ev.cwiseMax(floor);
  fit.covariance_m2 = eig.eigenvectors() * ev.asDiagonal() * eig.eigenvectors().transpose();
  fit.centre_m = t;
  fit.alpha_rad = NormalizeAxisAngle(alpha);
  fit.rms_m = std::sqrt(lin.cost / static_cast<double>(n));
  fit.ok = t.allFinite() && std::isfinite(fit.alpha_rad);
  return fit;
}

// The visible points are the near side of the body: a plausible centre lies behind the CoM as seen
// from the sensor, and not farther from it than the body is large.
bool Plausible(const FixedAxesFit& fit, const Eigen::Vector2d& com, const MeasurementOptions& o) {
  if (!fit.ok) return false;
  const Eigen::Vector2d offset = fit.centre_m - com;
  return offset.norm() <= o.max_centre_offset_m && offset.dot(com) > 0.0;
}

}  // namespace

Measurement MeasureSegment(std::span<const Eigen::Vector2d> points, const MeasurementOptions& o) {
  Measurement m;
  m.point_count = points.size();
  const Eigen::Vector2d com = CenterOfMass(points);
  m.position_m = com;
  m.covariance_m2 = o.com_sigma_m * o.com_sigma_m * Eigen::Matrix2d::Identity();
  const double com_range_m = com.norm();
  if (!o.fit_ellipse || points.size() < o.min_ellipse_points || !com.allFinite() ||
      com_range_m < 1e-6) {
    return m;
  }
  const auto pts = points.first(std::min(points.size(), kMaxSegmentPoints));
  const Eigen::Vector2d ray = com / com_range_m;

  // Fallback start: the near surface of a body facing the sensor lies about b in front of its
  // centre, with the major axis across the line of sight.
  const Eigen::Vector2d t_default = com + o.ellipse_minor_m * ray;
  const double alpha_default = std::atan2(ray.y(), ray.x()) + common::kPi / 2;

  FixedAxesFit fit;
  if (const auto conic = FitConicEllipse(pts)) {
    const Eigen::Vector2d offset = conic->center_m - com;
    if (offset.norm() <= o.max_centre_offset_m && offset.dot(ray) > 0.0) {
      fit = FitFixedAxes(pts, conic->center_m, conic->orientation_rad, o);
    }
  }
  if (!Plausible(fit, com, o)) fit = FitFixedAxes(pts, t_default, alpha_default, o);
  if (!Plausible(fit, com, o)) return m;

  m.kind = MeasurementKind::kEllipse;
  m.position_m = fit.centre_m;
  m.covariance_m2 = fit.covariance_m2;
  m.orientation_rad = fit.alpha_rad;
  m.rms_residual_m = fit.rms_m;
  return m;
}

}  // namespace lrfnet::tracking
