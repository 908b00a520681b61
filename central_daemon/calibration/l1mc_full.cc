#include "central_daemon/calibration/l1mc_full.h"

#include <cmath>
#include <limits>

namespace lrfnet::calib {

L1mcFullSize L1mcFullSizeOf(std::size_t n, std::size_t measurements) {
  L1mcFullSize size;
  if (n < 2) return size;
  size.unknowns = n * (n - 1);
  size.triangles = n * (n - 1) * (n - 2) / 6;
  const std::size_t pairs = n * (n - 1) / 2;
  size.rows = measurements + pairs + size.triangles;
  size.nonzeros = measurements + 2 * pairs + 3 * size.triangles;
  return size;
}

std::vector<bool> L1mcFull::ConstraintRows() const {
  std::vector<bool> hard(measurement_rows + inverse_rows + transitivity_rows, true);
  for (std::size_t i = 0; i < measurement_rows; ++i) hard[i] = false;
  return hard;
}

L1mcFull BuildL1mcFull(std::size_t n, const std::vector<RelativeMeasurement>& measurements,
                       const std::vector<double>& start_yaw_rad, bool use_weights) {
  L1mcFull p;
  p.n = n;
  if (n < 2) return p;
  const L1mcFullSize size = L1mcFullSizeOf(n, measurements.size());
  const auto cols = static_cast<Eigen::Index>(size.unknowns);

  // The start x'.
  p.start = Eigen::VectorXd::Zero(cols);
  std::vector<bool> measured(size.unknowns, false);
  for (const RelativeMeasurement& m : measurements) {
    const std::size_t sr = p.Unknown(m.s, m.r), rs = p.Unknown(m.r, m.s);
    if (measured[sr]) continue;
    measured[sr] = measured[rs] = true;
    p.start(static_cast<Eigen::Index>(sr)) = common::NormalizeAngle(m.s_from_r.yaw_rad);
    p.start(static_cast<Eigen::Index>(rs)) = -p.start(static_cast<Eigen::Index>(sr));
  }
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = 0; j < n; ++j) {
      if (i == j || measured[p.Unknown(i, j)]) continue;
      const double psi_i = i < start_yaw_rad.size() ? start_yaw_rad[i] : 0.0;
      const double psi_j = j < start_yaw_rad.size() ? start_yaw_rad[j] : 0.0;
      p.start(static_cast<Eigen::Index>(p.Unknown(i, j))) = common::NormalizeAngle(psi_j - psi_i);
    }
  }
  auto x0 = [&](std::size_t i, std::size_t j) {
    return p.start(static_cast<Eigen::Index>(p.Unknown(i, j)));
  };

  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(size.nonzeros);
  p.b = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(size.rows));
  p.weight = Eigen::VectorXd::Ones(static_cast<Eigen::Index>(size.rows));
  Eigen::Index row = 0;
  auto add = [&](std::size_t i, std::size_t j, double value) {
    triplets.emplace_back(row, static_cast<Eigen::Index>(p.Unknown(i, j)), value);
  };
  // eq. 19: w_sr = θ (normalised).
  for (const RelativeMeasurement& m : measurements) {
    add(m.s, m.r, 1.0);
    p.b(row) = common::NormalizeAngle(m.s_from_r.yaw_rad);
    p.weight(row) = use_weights ? m.weight : 1.0;
    ++row;
  }
  p.measurement_rows = measurements.size();
  // eq. 20: w_ij + w_ji = 0.
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j) {
      add(i, j, 1.0);
      add(j, i, 1.0);
      ++row;
    }
  }
  p.inverse_rows = n * (n - 1) / 2;
  // eq. 21: w_ik + w_kj - w_ij = b_t, b_t = A_t x' - normalize(A_t x').
  // first_row[i * n + k]: row of the triangle (i, k, k + 1), for the consistency check below.
  std::vector<Eigen::Index> first_row(n * n, 0);
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t k = i + 1; k < n; ++k) {
      first_row[i * n + k] = row;
      for (std::size_t j = k + 1; j < n; ++j) {
        add(i, k, 1.0);
        add(k, j, 1.0);
        add(i, j, -1.0);
        const double sum = x0(i, k) + x0(k, j) - x0(i, j);
        p.b(row) = sum - common::NormalizeAngle(sum);
        ++row;
      }
    }
  }
  p.transitivity_rows = size.triangles;
  p.a.resize(row, cols);
  p.a.setFromTriplets(triplets.begin(), triplets.end());

  // Consistency of the offsets: a particular solution of the inverse and transitivity rows from
  // the star of node 0 (z_0j = x'_0j, z_ij from the triangle (0, i, j)), checked on every triangle.
  auto b_of = [&](std::size_t i, std::size_t k, std::size_t j) {  // i < k < j
    return p.b(first_row[i * n + k] + static_cast<Eigen::Index>(j - k - 1));
  };
  const auto size_n = static_cast<Eigen::Index>(n);
  Eigen::MatrixXd z = Eigen::MatrixXd::Zero(size_n, size_n);
  for (std::size_t j = 1; j < n; ++j) z(0, static_cast<Eigen::Index>(j)) = x0(0, j);
  for (std::size_t i = 1; i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j) {
      const auto ii = static_cast<Eigen::Index>(i), jj = static_cast<Eigen::Index>(j);
      z(ii, jj) = b_of(0, i, j) + z(0, jj) - z(0, ii);  // z_0i + z_ij - z_0j = b
    }
  }
  p.offsets_consistent = true;
  for (std::size_t i = 0; i < n && p.offsets_consistent; ++i) {
    for (std::size_t k = i + 1; k < n && p.offsets_consistent; ++k) {
      for (std::size_t j = k + 1; j < n; ++j) {
        const auto ii = static_cast<Eigen::Index>(i), kk = static_cast<Eigen::Index>(k),
                   jj = static_cast<Eigen::Index>(j);
        if (std::abs(z(ii, kk) + z(kk, jj) - z(ii, jj) - b_of(i, k, j)) > 1e-6) {
          p.offsets_consistent = false;
          break;
        }
      }
    }
  }
  return p;
}

std::vector<double> YawsFromL1mc(const L1mcFull& problem, const Eigen::VectorXd& x,
                                 std::size_t reference) {
  std::vector<double> yaw(problem.n, 0.0);
  if (reference >= problem.n ||
      x.size() != static_cast<Eigen::Index>(problem.n * (problem.n - 1))) {
    return yaw;
  }
  for (std::size_t j = 0; j < problem.n; ++j) {
    if (j == reference) continue;
    yaw[j] = common::NormalizeAngle(x(static_cast<Eigen::Index>(problem.Unknown(reference, j))));
  }
  return yaw;
}

}  // namespace lrfnet::calib
