#pragma once
// The constant-velocity motion model shared by the tracker's Kalman filter
// (firmware_tracker/tracking/cv_ekf.h) and the daemon's Rauch-Tung-Striebel smoother
// (central_daemon/calibration/rts.h): both must use the same F and Q, or the smoother would undo
// steps the filter never took.
//
// State x = (x_m, y_m, vx_mps, vy_mps). Continuous white acceleration with spectral density
// q = accel_psd_m2ps3 (m^2/s^3) per axis, independent axes, discretised exactly over dt_s:
//   x(t + dt) = F(dt) x(t) + w,   w ~ N(0, Q(dt, q)),
//   F(dt) = [I, dt I; 0, I],      Q_axis(dt, q) = q [dt^3/3, dt^2/2; dt^2/2, dt].
// Any dt is accepted (negative dt gives the backward transition F(dt) = F(-|dt|); Q(dt, q) is then
// not a covariance, callers only pass dt >= 0 there).
//
// Header-only, Eigen only, fixed-size, never allocates: the tracker is cross-built for aarch64 and
// must not allocate per scan.

#include <Eigen/Core>

namespace lrfnet::common {

using CvState = Eigen::Vector4d;       // (x_m, y_m, vx_mps, vy_mps)
using CvCovariance = Eigen::Matrix4d;  // of CvState

// F(dt): the state transition over dt_s seconds.
inline Eigen::Matrix4d CvTransition(double dt_s) {
  Eigen::Matrix4d f = Eigen::Matrix4d::Identity();
  f(0, 2) = dt_s;
  f(1, 3) = dt_s;
  return f;
}

// Q(dt, q): the exactly discretised process noise over dt_s >= 0 seconds.
inline Eigen::Matrix4d CvProcessNoise(double dt_s, double accel_psd_m2ps3) {
  const double q = accel_psd_m2ps3;
  const double q11 = q * dt_s * dt_s * dt_s / 3.0;
  const double q12 = q * dt_s * dt_s / 2.0;
  const double q22 = q * dt_s;
  Eigen::Matrix4d qm = Eigen::Matrix4d::Zero();
  qm(0, 0) = qm(1, 1) = q11;
  qm(0, 2) = qm(2, 0) = qm(1, 3) = qm(3, 1) = q12;
  qm(2, 2) = qm(3, 3) = q22;
  return qm;
}

// m <- F(dt) m, in place: F only adds dt times the velocity rows to the position rows (exactly the
// arithmetic of the full product, whose other terms are multiplications by 1 and additions of 0).
inline void CvApplyTransition(double dt_s, Eigen::Matrix4d& m) {
  m.row(0) += dt_s * m.row(2);
  m.row(1) += dt_s * m.row(3);
}

// m <- m F(dt)^T, in place.
inline void CvApplyTransitionTransposed(double dt_s, Eigen::Matrix4d& m) {
  m.col(0) += dt_s * m.col(2);
  m.col(1) += dt_s * m.col(3);
}

// The covariance half of CvPredict: p <- F p F^T + Q, re-symmetrised.
inline void CvPredictCovariance(double dt_s, double accel_psd_m2ps3, CvCovariance& p) {
  CvApplyTransition(dt_s, p);
  CvApplyTransitionTransposed(dt_s, p);
  const double q = accel_psd_m2ps3;
  const double q11 = q * dt_s * dt_s * dt_s / 3.0;
  const double q12 = q * dt_s * dt_s / 2.0;
  const double q22 = q * dt_s;
  p(0, 0) += q11;
  p(1, 1) += q11;
  p(2, 2) += q22;
  p(3, 3) += q22;
  p(0, 2) += q12;
  p(2, 0) += q12;
  p(1, 3) += q12;
  p(3, 1) += q12;
  p = 0.5 * (p + p.transpose()).eval();
}

// Kalman prediction over dt_s >= 0: x <- F x, p <- F p F^T + Q, p re-symmetrised (keeps p exactly
// symmetric in floating point, so Cholesky factorisations downstream see a symmetric matrix).
inline void CvPredict(double dt_s, double accel_psd_m2ps3, CvState& x, CvCovariance& p) {
  x(0) += dt_s * x(2);
  x(1) += dt_s * x(3);
  CvPredictCovariance(dt_s, accel_psd_m2ps3, p);
}

}  // namespace lrfnet::common
