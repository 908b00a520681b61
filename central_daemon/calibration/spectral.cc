#include "central_daemon/calibration/spectral.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <complex>
#include <random>

#include "common/eigen_instances.h"

namespace lrfnet::calib {
namespace {

using Complex = std::complex<double>;

// y = H x for the sparse Hermitian H of the header.
void Apply(const std::vector<RelativeMeasurement>& measurements, bool use_weights,
           const Eigen::VectorXcd& x, Eigen::VectorXcd* y) {
  y->setZero(x.size());
  for (const RelativeMeasurement& m : measurements) {
    const Complex h = std::polar(use_weights ? m.weight : 1.0, m.s_from_r.yaw_rad);
    const auto r = static_cast<Eigen::Index>(m.r), s = static_cast<Eigen::Index>(m.s);
    (*y)(r) += h * x(s);
    (*y)(s) += std::conj(h) * x(r);
  }
}

}  // namespace

std::vector<double> SpectralYaws(std::size_t n, std::size_t reference,
                                 const std::vector<RelativeMeasurement>& measurements,
                                 bool use_weights) {
  std::vector<double> yaw(n, 0.0);
  if (n == 0 || reference >= n) return yaw;
  const auto size = static_cast<Eigen::Index>(n);
  // Lanczos with full re-orthogonalisation: the top eigenpair of H from a Krylov space, O(k m +
  // k^2 n) for k steps instead of the O(n^3) of a dense eigensolver; exact (up to round-off) when
  // k reaches n. Stops when the Ritz residual |β_k s_k| is below 1e-12 |θ|.
  std::mt19937 rng(12345);  // a fixed start: deterministic results
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::VectorXcd q(size);
  for (Eigen::Index i = 0; i < size; ++i) q(i) = Complex(normal(rng), normal(rng));
  q.normalize();
  std::vector<Eigen::VectorXcd> basis;
  std::vector<double> alpha, beta;
  Eigen::VectorXcd w(size);
  Eigen::VectorXd top_s;
  double scale = 0.0;  // largest Lanczos coefficient: the scale of H
  for (Eigen::Index k = 0; k < size; ++k) {
    basis.push_back(q);
    Apply(measurements, use_weights, q, &w);
    if (k > 0) w -= beta.back() * basis[static_cast<std::size_t>(k - 1)];
    alpha.push_back(q.dot(w).real());  // q^H w, real for Hermitian H
    w -= alpha.back() * q;
    for (int pass = 0; pass < 2; ++pass) {
      for (const Eigen::VectorXcd& b : basis) w -= b.dot(w) * b;
    }
    const double b_next = w.norm();
    scale = std::max({scale, std::abs(alpha.back()), b_next});
    // The Ritz pair is checked every few steps (a dense solve of the small tridiagonal matrix),
    // and at the end: the Krylov space is exhausted or became invariant.
    const bool last = k + 1 == size || b_next <= 1e-14 * scale;
    if (k % 8 == 7 || last) {
      const auto m = static_cast<Eigen::Index>(alpha.size());
      Eigen::MatrixXd t = Eigen::MatrixXd::Zero(m, m);
      for (Eigen::Index i = 0; i < m; ++i) {
        t(i, i) = alpha[static_cast<std::size_t>(i)];
        if (i + 1 < m) t(i, i + 1) = t(i + 1, i) = beta[static_cast<std::size_t>(i)];
      }
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(t);
      if (eig.info() != Eigen::Success) break;
      top_s = eig.eigenvectors().col(m - 1);
      const double theta = eig.eigenvalues()(m - 1);
      if (last || b_next * std::abs(top_s(m - 1)) <= 1e-12 * std::max(std::abs(theta), 1e-300)) {
        break;
      }
    }
    beta.push_back(b_next);
    q = w / b_next;
  }
  Eigen::VectorXcd top = Eigen::VectorXcd::Zero(size);
  for (Eigen::Index i = 0; i < top_s.size(); ++i)
    top += top_s(i) * basis[static_cast<std::size_t>(i)];
  const Complex ref = top(static_cast<Eigen::Index>(reference));
  for (std::size_t v = 0; v < n; ++v) {
    yaw[v] = std::arg(top(static_cast<Eigen::Index>(v)) * std::conj(ref));
  }
  yaw[reference] = 0.0;
  return yaw;
}

RotationAveragingResult AverageRotationsSpectral(
    std::size_t n, std::size_t reference, const std::vector<RelativeMeasurement>& measurements,
    const RotationAveragingOptions& options) {
  RotationAveragingResult result;
  if (auto error = CheckRotationProblem(n, reference, measurements, options)) {
    result.error = *error;
    return result;
  }
  result.yaw_rad = SpectralYaws(n, reference, measurements, options.use_weights);
  FillRotationDiagnostics(n, reference, measurements, options, &result);
  result.ok = true;
  return result;
}

RotationAveragingResult AverageRotationsSpectral(
    std::size_t n, std::size_t reference, const std::vector<RelativeMeasurement>& measurements,
    bool use_weights) {
  RotationAveragingOptions options;
  options.use_weights = use_weights;
  return AverageRotationsSpectral(n, reference, measurements, options);
}

}  // namespace lrfnet::calib
