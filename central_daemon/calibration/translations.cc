#include "central_daemon/calibration/translations.h"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <cmath>

namespace lrfnet::calib {
namespace {

Eigen::Matrix2d Rotation(double yaw_rad) {
  const double c = std::cos(yaw_rad), s = std::sin(yaw_rad);
  Eigen::Matrix2d r;
  r << c, -s, s, c;
  return r;
}

}  // namespace

std::optional<std::string> Validate(const TranslationOptions& options) {
  if (!(options.prior_sigma_m > 0.0) || !std::isfinite(options.prior_sigma_m)) {
    return "prior_sigma_m must be finite and > 0";
  }
  return std::nullopt;
}

TranslationResult SolveTranslations(std::size_t n, std::size_t reference,
                                    const std::vector<double>& yaw_rad,
                                    const std::vector<RelativeMeasurement>& measurements,
                                    const std::vector<bool>& use,
                                    const TranslationOptions& options) {
  TranslationResult result;
  if (auto error = Validate(options)) {
    result.error = "invalid options: " + *error;
    return result;
  }
  if (auto error = CheckGraphInput(n, reference, measurements)) {
    result.error = *error;
    return result;
  }
  if (use.size() != measurements.size()) {
    result.error = "use has " + std::to_string(use.size()) + " flags for " +
                   std::to_string(measurements.size()) + " measurements";
    return result;
  }
  if (yaw_rad.size() != n) {
    result.error =
        "got " + std::to_string(yaw_rad.size()) + " yaws for " + std::to_string(n) + " nodes";
    return result;
  }
  for (std::size_t v = 0; v < n; ++v) {
    if (!std::isfinite(yaw_rad[v])) {
      result.error = "yaw of node " + std::to_string(v) + " is not finite";
      return result;
    }
  }
  if (options.use_covariances) {
    if (auto error = CheckGraphInput(n, reference, measurements, /*check_covariance=*/true, use)) {
      result.error = *error;
      return result;
    }
  }
  if (auto error = ConnectivityError(n, reference, measurements, use)) {
    result.error = *error;
    return result;
  }

  std::vector<Eigen::Index> column(n, -1);
  Eigen::Index next = 0;
  for (std::size_t v = 0; v < n; ++v) {
    if (v != reference) column[v] = 2 * next++;
  }
  const Eigen::Index unknowns = 2 * static_cast<Eigen::Index>(n - 1);
  std::vector<Eigen::Triplet<double>> triplets;
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(unknowns);
  std::vector<Eigen::Matrix2d> information(measurements.size(), Eigen::Matrix2d::Identity());
  std::vector<Eigen::Vector2d> offset(measurements.size());  // R(φ_s) t_sr
  std::size_t used_count = 0;
  auto add_block = [&](Eigen::Index row, Eigen::Index col, const Eigen::Matrix2d& block) {
    for (int i = 0; i < 2; ++i) {
      for (int j = 0; j < 2; ++j) triplets.emplace_back(row + i, col + j, block(i, j));
    }
  };
  for (std::size_t e = 0; e < measurements.size(); ++e) {
    const RelativeMeasurement& m = measurements[e];
    const Eigen::Matrix2d rs = Rotation(yaw_rad[m.s]);
    offset[e] = rs * m.s_from_r.translation();
    if (!use[e]) continue;
    ++used_count;
    Eigen::Matrix2d omega = Eigen::Matrix2d::Identity();
    if (options.use_covariances) {
      const Eigen::Matrix2d c = m.covariance.topLeftCorner<2, 2>();
      const Eigen::Matrix2d world = rs * (0.5 * (c + c.transpose())) * rs.transpose();
      omega = world.inverse();
    }
    if (options.use_weights) omega *= m.weight;
    information[e] = omega;
    // ρ = t_r - t_s - offset: J = [+I at r, -I at s].
    const Eigen::Index cr = column[m.r], cs = column[m.s];
    const Eigen::Vector2d g = omega * offset[e];
    if (cr >= 0) {
      add_block(cr, cr, omega);
      rhs.segment<2>(cr) += g;
    }
    if (cs >= 0) {
      add_block(cs, cs, omega);
      rhs.segment<2>(cs) -= g;
    }
    if (cr >= 0 && cs >= 0) {
      add_block(cr, cs, -omega);
      add_block(cs, cr, -omega);
    }
  }
  Eigen::SparseMatrix<double> h(unknowns, unknowns);
  h.setFromTriplets(triplets.begin(), triplets.end());
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(h);
  if (solver.info() != Eigen::Success) {
    result.error = "translations: the normal equations are singular";
    return result;
  }
  const Eigen::VectorXd x = solver.solve(rhs);
  if (solver.info() != Eigen::Success || !x.allFinite()) {
    result.error = "translations: the normal equations are singular";
    return result;
  }

  result.position_m.assign(n, Eigen::Vector2d::Zero());
  for (std::size_t v = 0; v < n; ++v) {
    if (column[v] >= 0) result.position_m[v] = x.segment<2>(column[v]);
  }
  result.residual_m.assign(measurements.size(), 0.0);
  for (std::size_t e = 0; e < measurements.size(); ++e) {
    const RelativeMeasurement& m = measurements[e];
    const Eigen::Vector2d rho = result.position_m[m.r] - result.position_m[m.s] - offset[e];
    result.residual_m[e] = rho.norm();
    if (use[e]) result.chi2 += rho.dot(information[e] * rho);
  }
  result.dof = 2 * static_cast<long>(used_count) - 2 * static_cast<long>(n - 1);
  const bool absolute = options.use_covariances && !options.use_weights;
  if (absolute) {
    result.variance_factor = 1.0;
  } else if (result.dof > 0) {
    result.variance_factor = result.chi2 / static_cast<double>(result.dof);
  } else {
    // No redundancy: the prior is the σ of a measurement of average weight.
    double mean_weight = 1.0;
    if (options.use_weights) {
      double sum = 0.0;
      for (std::size_t e = 0; e < measurements.size(); ++e)
        sum += use[e] ? measurements[e].weight : 0.0;
      mean_weight = sum / static_cast<double>(used_count);
    }
    result.variance_factor =
        mean_weight *
        (options.use_covariances ? 1.0 : options.prior_sigma_m * options.prior_sigma_m);
  }
  const Eigen::MatrixXd inverse = solver.solve(Eigen::MatrixXd::Identity(unknowns, unknowns));
  result.position_cov_m2.assign(n, Eigen::Matrix2d::Zero());
  for (std::size_t v = 0; v < n; ++v) {
    if (column[v] < 0) continue;
    const Eigen::Matrix2d block = inverse.block<2, 2>(column[v], column[v]);
    result.position_cov_m2[v] = result.variance_factor * 0.5 * (block + block.transpose());
  }
  result.ok = true;
  return result;
}

}  // namespace lrfnet::calib
