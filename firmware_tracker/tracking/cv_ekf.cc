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
}

void CvEkf::Predict(double dt_s) {
  if (!(dt_s > 0.0) || !std::isfinite(dt_s)) return;
  common::CvPredict(dt_s, options_.accel_psd_m2ps3, x_, p_);
}

double CvEkf::MahalanobisSq(const Eigen::Vector2d& z_m, const Eigen::Matrix2d& r_m2) const {
  const Eigen::Matrix2d s = p_.topLeftCorner<2, 2>() + r_m2;
  const Eigen::LLT<Eigen::Matrix2d> llt(0.5 * (s + s.transpose()));
  if (llt.info() != Eigen::Success) return std::numeric_limits<double>::infinity();
  const Eigen::Vector2d y = z_m - x_.head<2>();
  const double d2 = y.dot(llt.solve(y));
  return std::isfinite(d2) ? d2 : std::numeric_limits<double>::infinity();
}

bool CvEkf::Update(const Eigen::Vector2d& z_m, const Eigen::Matrix2d& r_m2) {
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
  const Eigen::Matrix<double, 4, 2> k = p_.topRows<2>().transpose() * s_inv;  // K = P H^T S^-1
  x_ += k * (z_m - x_.head<2>());
  // Joseph form: stays positive semi-definite even with a slightly wrong gain from rounding.
  Eigen::Matrix4d i_kh = Eigen::Matrix4d::Identity();
  i_kh.leftCols<2>() -= k;
  p_ = i_kh * p_ * i_kh.transpose() + k * r * k.transpose();
  p_ = 0.5 * (p_ + p_.transpose()).eval();
  return true;
}

}  // namespace lrfnet::tracking
