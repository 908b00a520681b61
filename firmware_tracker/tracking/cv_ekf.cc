#include "firmware_tracker/tracking/cv_ekf.h"

#include <Eigen/Cholesky>
#include <cmath>
#include <limits>

#include "common/cv_model.h"

namespace lrfnet::tracking {

std::optional<std::string> Validate(const CvEkfOptions& o) {
  if (!(std::isfinite(o.accel_psd_m2ps3) && o.accel_psd_m2ps3 > 0.0)) {
    return "accel_psd_m2ps3 must be > 0";
  }
  if (!(std::isfinite(o.initial_velocity_sigma_mps) && o.initial_velocity_sigma_mps > 0.0)) {
    return "initial_velocity_sigma_mps must be > 0";
  }
  return std::nullopt;
}

void CvEkf::Init(const Eigen::Vector2d& z_m, const Eigen::Matrix2d& r_m2) {
  x_ << z_m, 0.0, 0.0;
  p_.setZero();
  p_.topLeftCorner<2, 2>() = 0.5 * (r_m2 + r_m2.transpose());
  const double v2 = options_.initial_velocity_sigma_mps * options_.initial_velocity_sigma_mps;
  p_(2, 2) = v2;
  p_(3, 3) = v2;
  gain_ = false;
  gain_apart_ = false;
}

namespace {

// One copy of the prediction's covariance arithmetic for the filter's covariances and the
// predicted copies (inlined at each of its three calls, it took more instruction-cache lines).
[[gnu::noinline]] void PredictCovariance(double dt_s, double accel_psd_m2ps3,
                                         CvEkf::Covariance& p) {
  common::CvPredictSymmetricCovariance(dt_s, accel_psd_m2ps3, p);
}

}  // namespace

void CvEkf::Predict(double dt_s) {
  if (!(dt_s > 0.0) || !std::isfinite(dt_s)) return;
  // p_ and p_gain_ are exactly symmetric (Init, the Joseph updates and InflateCovariance keep
  // them so): common::CvPredict's covariance from the upper triangle, bit for bit.
  if (gain_apart_) PredictCovariance(dt_s, options_.accel_psd_m2ps3, p_gain_);
  x_(0) += dt_s * x_(2);
  x_(1) += dt_s * x_(3);
  PredictCovariance(dt_s, options_.accel_psd_m2ps3, p_);
}

void CvEkf::RelieveGainProcessNoise(double dt_s) {
  if (!gain_ || !(dt_s > 0.0) || !std::isfinite(dt_s)) return;
  if (!gain_apart_) {
    p_gain_ = p_;
    gain_apart_ = true;
  }
  // Predict's Q(dt) (the same entries; zeros elsewhere).
  p_gain_ -= common::CvProcessNoise(dt_s, options_.accel_psd_m2ps3);
}

CvEkf::Prediction CvEkf::Predicted(double dt_s) const {
  Prediction f{x_, p_};
  if (!(dt_s > 0.0) || !std::isfinite(dt_s)) return f;
  f.x(0) += dt_s * f.x(2);
  f.x(1) += dt_s * f.x(3);
  PredictCovariance(dt_s, options_.accel_psd_m2ps3, f.p);
  return f;
}

namespace {

// (I - K H) P (I - K H)^T + K R K^T for H = [I 0], P symmetric, in 2 x 2 blocks: I - K H =
// [[I - K1, 0], [-K2, I]] (K1, K2: K's position and velocity rows), so without the 4 x 4 products'
// multiplications by zero:
//   M = (I - K1) [P11 P12],  N = [P21 P22] - K2 [P11 P12],
//   P' = [[M1 (I - K1)^T, M2 - M1 K2^T], [., N2 - N1 K2^T]] + K R K^T (upper blocks; symmetric).
[[gnu::noinline]] void JosephUpdate(const Eigen::Matrix<double, 4, 2>& k, const Eigen::Matrix2d& r,
                                    Eigen::Matrix4d& p) {
  const Eigen::Matrix2d k1 = k.topRows<2>(), k2 = k.bottomRows<2>();
  const Eigen::Matrix2d a = Eigen::Matrix2d::Identity() - k1;
  const Eigen::Matrix2d p11 = p.topLeftCorner<2, 2>(), p12 = p.topRightCorner<2, 2>();
  const Eigen::Matrix2d p21 = p.bottomLeftCorner<2, 2>(), p22 = p.bottomRightCorner<2, 2>();
  const Eigen::Matrix2d m1 = a * p11, m2 = a * p12;
  const Eigen::Matrix2d n1 = p21 - k2 * p11, n2 = p22 - k2 * p12;
  const Eigen::Matrix2d rk1 = r * k1.transpose(), rk2 = r * k2.transpose();
  const Eigen::Matrix2d top_left = m1 * a.transpose() + k1 * rk1;
  const Eigen::Matrix2d top_right = m2 - m1 * k2.transpose() + k1 * rk2;
  const Eigen::Matrix2d bottom_left = n1 * a.transpose() + k2 * rk1;
  const Eigen::Matrix2d bottom_right = n2 - n1 * k2.transpose() + k2 * rk2;
  p.topLeftCorner<2, 2>() = 0.5 * (top_left + top_left.transpose());
  p.bottomRightCorner<2, 2>() = 0.5 * (bottom_right + bottom_right.transpose());
  const Eigen::Matrix2d off = 0.5 * (top_right + bottom_left.transpose());
  p.topRightCorner<2, 2>() = off;
  p.bottomLeftCorner<2, 2>() = off.transpose();
}

// The same Joseph form for a covariance p the gain k was not computed from (the gain
// covariance), multiplied out: with H = [I 0], P_1 = H P (p's top two rows) and S_p = H P H^T + R,
//   (I - K H) P (I - K H)^T + K R K^T = P - K P_1 - P_1^T K^T + K S_p K^T = P + V K^T + K V^T,
//   V = K S_p / 2 - P_1^T (4 x 2),
// 83 multiplications, two at a time down p's columns, instead of the blocks' 112 (the compiled code
// about half as long). Entry (i, j) adds to P_ij
// (V_i K_j^T) + (K_i V_j^T) and entry (j, i) the same two sums the other way round, so without
// fused multiply-adds p stays exactly symmetric; the lower triangle is copied from the upper one
// after the loop so that it does with them too (Predict reads the upper triangle only). Equal to
// JosephUpdate but for rounding; the multiplied-out form cancels like the standard Kalman update
// (P - K P_1 ...), not positive semi-definite by construction as the Joseph blocks are: harmless
// at these sizes, and the filter's own covariance (which decides the gains) keeps the blocks.
void JosephUpdateOtherGain(const Eigen::Matrix<double, 4, 2>& k, const Eigen::Matrix2d& r,
                           Eigen::Matrix4d& p) {
  const double h00 = 0.5 * (p(0, 0) + r(0, 0));
  const double h01 = 0.5 * (p(0, 1) + r(0, 1));
  const double h11 = 0.5 * (p(1, 1) + r(1, 1));
  Eigen::Matrix<double, 4, 2> v;
  v.col(0) = k.col(0) * h00 + k.col(1) * h01 - p.col(0);  // p symmetric: its rows are its columns
  v.col(1) = k.col(0) * h01 + k.col(1) * h11 - p.col(1);
  for (int j = 0; j < 4; ++j) {
    p.col(j) +=
        (v.col(0) * k(j, 0) + v.col(1) * k(j, 1)) + (k.col(0) * v(j, 0) + k.col(1) * v(j, 1));
  }
  for (int j = 1; j < 4; ++j) {
    for (int i = 0; i < j; ++i) p(j, i) = p(i, j);
  }
}

}  // namespace

double CvEkf::MahalanobisSq(const Eigen::Vector2d& z_m, const Eigen::Matrix2d& r_m2) const {
  const Eigen::Matrix2d s = p_.topLeftCorner<2, 2>() + r_m2;
  const Eigen::LLT<Eigen::Matrix2d> llt(0.5 * (s + s.transpose()));
  if (llt.info() != Eigen::Success) return std::numeric_limits<double>::infinity();
  const Eigen::Vector2d y = z_m - x_.head<2>();
  const double d2 = y.dot(llt.solve(y));
  return std::isfinite(d2) ? d2 : std::numeric_limits<double>::infinity();
}

bool CvEkf::Update(const Eigen::Vector2d& z_m, const Eigen::Matrix2d& r_m2,
                   const Eigen::Matrix2d* gain_r_m2) {
  if (!z_m.allFinite() || !r_m2.allFinite()) return false;
  const Eigen::Matrix2d r = 0.5 * (r_m2 + r_m2.transpose());
  // H = [I 0] selects the position: S = H P H^T + R is P's top-left block plus R, and P H^T its
  // left two columns. S^-1 in closed form (2 x 2, positive definite: the Cholesky condition below);
  // the products are spelt with H's structure instead of multiplying by its zeros, and no general
  // triangular solve runs per update.
  const Eigen::Matrix2d s = p_.topLeftCorner<2, 2>() + r;
  const double det = s(0, 0) * s(1, 1) - s(0, 1) * s(1, 0);
  if (!(s(0, 0) > 0.0) || !(det > 0.0) || !std::isfinite(det)) return false;
  Eigen::Matrix2d s_inv;
  s_inv << s(1, 1), -s(0, 1), -s(1, 0), s(0, 0);
  s_inv /= det;
  // K = P H^T S^-1, a column at a time: P is symmetric, so P H^T's columns are P's first two
  // (entry (i, j): P_0i S^-1_0j + P_1i S^-1_1j, as the product of P's top rows transposed forms
  // it where multiply-adds are not fused; with fused multiply-adds, as on aarch64, the last bits
  // differ from that product).
  Eigen::Matrix<double, 4, 2> k;
  k.col(0) = p_.col(0) * s_inv(0, 0) + p_.col(1) * s_inv(1, 0);
  k.col(1) = p_.col(0) * s_inv(0, 1) + p_.col(1) * s_inv(1, 1);
  const Eigen::Vector2d y = z_m - x_.head<2>();
  x_ += k.col(0) * y(0) + k.col(1) * y(1);
  // Joseph form (p_): stays positive semi-definite even with a slightly wrong gain from rounding;
  // the gain's own covariance (gain_covariance()) through the same gain, multiplied out.
  // Until an update's gain_r_m2 differs from R, the gain covariance is covariance() (the same
  // recursion with the same noise), and is not formed apart.
  if (gain_) {
    const Eigen::Matrix2d gain_r =
        gain_r_m2 != nullptr && gain_r_m2->allFinite()
            ? Eigen::Matrix2d(0.5 * (*gain_r_m2 + gain_r_m2->transpose()))
            : r;
    if (!gain_apart_ && gain_r != r) {
      p_gain_ = p_;
      gain_apart_ = true;
    }
    if (gain_apart_) JosephUpdateOtherGain(k, gain_r, p_gain_);
  }
  JosephUpdate(k, r, p_);
  return true;
}

}  // namespace lrfnet::tracking
