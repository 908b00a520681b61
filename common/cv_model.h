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

// p <- F(dt) p F(dt)^T for an exactly symmetric p (the Kalman filter's covariances, kept symmetric
// after every step), bit for bit what CvApplyTransition, CvApplyTransitionTransposed and the
// re-symmetrisation 0.5 (m + m^T) give, from p's upper triangle. With P symmetric, every entry of
// the two in-place passes but (0, 1) comes out the same in both triangles (the same products of
// the same entries in the same order), so only (0, 1) is averaged; the velocity block is not
// touched: 13 multiplications and 13 additions, against 32 and 32 for the two passes and the
// average.
inline void CvTransitionSymmetric(double dt_s, CvCovariance& p) {
  const double dt = dt_s;
  const double p00 = p(0, 0), p01 = p(0, 1), p02 = p(0, 2), p03 = p(0, 3);
  const double p11 = p(1, 1), p12 = p(1, 2), p13 = p(1, 3);
  const double p22 = p(2, 2), p23 = p(2, 3), p33 = p(3, 3);
  // Rows 0 and 1 plus dt times rows 2 and 3, in columns 2 and 3 (the columns' pass leaves those).
  const double a02 = p02 + dt * p22;
  const double a03 = p03 + dt * p23;
  const double a12 = p12 + dt * p23;
  const double a13 = p13 + dt * p33;
  // Columns 0 and 1: the rows' pass, then dt times columns 2 and 3 of it. (0, 1) and (1, 0) add
  // the same terms in another order.
  const double a00 = (p00 + dt * p02) + dt * a02;
  const double a11 = (p11 + dt * p13) + dt * a13;
  const double a01 = 0.5 * (((p01 + dt * p12) + dt * a03) + ((p01 + dt * p03) + dt * a12));
  p(0, 0) = a00;
  p(1, 1) = a11;
  p(0, 1) = p(1, 0) = a01;
  p(0, 2) = p(2, 0) = a02;
  p(0, 3) = p(3, 0) = a03;
  p(1, 2) = p(2, 1) = a12;
  p(1, 3) = p(3, 1) = a13;
}

// CvPredictCovariance for an exactly symmetric p, bit for bit the same result (see
// CvTransitionSymmetric): p <- F p F^T + Q.
inline void CvPredictSymmetricCovariance(double dt_s, double accel_psd_m2ps3, CvCovariance& p) {
  CvTransitionSymmetric(dt_s, p);
  const double q = accel_psd_m2ps3;
  const double q11 = q * dt_s * dt_s * dt_s / 3.0;
  const double q12 = q * dt_s * dt_s / 2.0;
  const double q22 = q * dt_s;
  p(0, 0) += q11;
  p(1, 1) += q11;
  p(2, 2) += q22;
  p(3, 3) += q22;
  p(0, 2) += q12;
  p(2, 0) = p(0, 2);
  p(1, 3) += q12;
  p(3, 1) = p(1, 3);
}

// Kalman prediction over dt_s >= 0: x <- F x, p <- F p F^T + Q, p re-symmetrised (keeps p exactly
// symmetric in floating point, so Cholesky factorisations downstream see a symmetric matrix).
inline void CvPredict(double dt_s, double accel_psd_m2ps3, CvState& x, CvCovariance& p) {
  x(0) += dt_s * x(2);
  x(1) += dt_s * x(3);
  CvPredictCovariance(dt_s, accel_psd_m2ps3, p);
}

}  // namespace lrfnet::common
