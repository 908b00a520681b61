#include "central_daemon/calibration/pose_graph.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>

#include "common/eigen_instances.h"

namespace lrfnet::calib {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// r = x(T_s^-1 T_r) - x(measured) and its Jacobians with respect to (x, y, yaw) of r and s.
struct EdgeLinearization {
  Eigen::Vector3d e;
  Eigen::Matrix3d d_r;
  Eigen::Matrix3d d_s;
};

EdgeLinearization Linearize(const Pose2& r, const Pose2& s, const Pose2& measured) {
  const double c = std::cos(s.yaw_rad), sn = std::sin(s.yaw_rad);
  const double dx = r.x_m - s.x_m, dy = r.y_m - s.y_m;
  EdgeLinearization l;
  l.e = Eigen::Vector3d(c * dx + sn * dy - measured.x_m, -sn * dx + c * dy - measured.y_m,
                        common::NormalizeAngle(r.yaw_rad - s.yaw_rad - measured.yaw_rad));
  l.d_r << c, sn, 0.0, -sn, c, 0.0, 0.0, 0.0, 1.0;
  l.d_s << -c, -sn, -sn * dx + c * dy, sn, -c, -c * dx - sn * dy, 0.0, 0.0, -1.0;
  return l;
}

// The information of a measurement: its covariance (symmetrised, eigenvalues floored) inverted.
std::optional<Eigen::Matrix3d> InformationOf(const Eigen::Matrix3d& covariance,
                                             const PoseGraphOptions& o) {
  if (!covariance.allFinite()) return std::nullopt;
  const Eigen::Matrix3d sym = 0.5 * (covariance + covariance.transpose());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(sym);
  if (eig.info() != Eigen::Success) return std::nullopt;
  // Floors in the metric of each direction: a direction mostly in yaw gets the yaw floor.
  Eigen::Vector3d values = eig.eigenvalues();
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d v = eig.eigenvectors().col(k);
    const double floor = (v.x() * v.x() + v.y() * v.y()) * o.min_sigma_m * o.min_sigma_m +
                         v.z() * v.z() * o.min_sigma_rad * o.min_sigma_rad;
    values(k) = std::max(values(k), floor);
  }
  return eig.eigenvectors() * values.cwiseInverse().asDiagonal() * eig.eigenvectors().transpose();
}

}  // namespace

std::optional<std::string> Validate(const PoseGraphOptions& o) {
  if (o.max_iterations < 1) return "max_iterations must be >= 1";
  if (!(std::isfinite(o.tolerance) && o.tolerance > 0.0)) return "tolerance must be > 0";
  if (!(std::isfinite(o.min_sigma_m) && o.min_sigma_m > 0.0)) return "min_sigma_m must be > 0";
  if (!(std::isfinite(o.min_sigma_rad) && o.min_sigma_rad > 0.0)) {
    return "min_sigma_rad must be > 0";
  }
  return std::nullopt;
}

RelativeFromPoses RelativePose(const Pose2& world_from_r, const Eigen::Matrix3d& cov_r,
                               const Pose2& world_from_s, const Eigen::Matrix3d& cov_s) {
  RelativeFromPoses out;
  out.s_from_r = world_from_s.inverse() * world_from_r;
  const EdgeLinearization l = Linearize(world_from_r, world_from_s, out.s_from_r);
  out.covariance = l.d_r * cov_r * l.d_r.transpose() + l.d_s * cov_s * l.d_s.transpose();
  return out;
}

double MeasurementDistanceSigma(const Pose2& measured, const Eigen::Matrix3d& measured_cov,
                                const RelativeFromPoses& predicted) {
  const Eigen::Vector3d e(predicted.s_from_r.x_m - measured.x_m,
                          predicted.s_from_r.y_m - measured.y_m,
                          common::NormalizeAngle(predicted.s_from_r.yaw_rad - measured.yaw_rad));
  const Eigen::Matrix3d sum = measured_cov + predicted.covariance;
  const Eigen::LLT<Eigen::Matrix3d> llt(0.5 * (sum + sum.transpose()));
  if (!sum.allFinite() || llt.info() != Eigen::Success) return kInf;
  const double d2 = e.dot(llt.solve(e));
  return std::isfinite(d2) && d2 >= 0.0 ? std::sqrt(d2) : kInf;
}

PoseGraphResult SolvePoseGraph(std::size_t n, std::size_t reference,
                               const std::vector<RelativeMeasurement>& measurements,
                               const std::vector<bool>& use, const std::vector<Pose2>& initial,
                               const PoseGraphOptions& options) {
  PoseGraphResult out;
  const auto fail = [&](std::string why) {
    out.ok = false;
    out.error = std::move(why);
    return out;
  };
  if (auto e = Validate(options)) return fail("invalid options: " + *e);
  if (use.size() != measurements.size()) return fail("use flags do not match the measurements");
  if (initial.size() != n) return fail("initial poses do not match the nodes");
  if (auto e = CheckGraphInput(n, reference, measurements, false)) return fail(*e);
  for (const Pose2& p : initial) {
    if (!std::isfinite(p.x_m) || !std::isfinite(p.y_m) || !std::isfinite(p.yaw_rad)) {
      return fail("initial poses must be finite");
    }
  }
  if (auto e = ConnectivityError(n, reference, measurements, use)) return fail(*e);
  std::vector<Eigen::Matrix3d> info(measurements.size(), Eigen::Matrix3d::Zero());
  for (std::size_t k = 0; k < measurements.size(); ++k) {
    if (!use[k]) continue;
    const auto i = InformationOf(measurements[k].covariance, options);
    if (!i) return fail("measurement " + std::to_string(k) + " has no usable covariance");
    info[k] = *i;
  }

  // Unknowns: 3 per node but the reference.
  std::vector<Eigen::Index> column(n, -1);
  Eigen::Index dim = 0;
  for (std::size_t v = 0; v < n; ++v) {
    if (v != reference) {
      column[v] = dim;
      dim += 3;
    }
  }
  std::vector<Pose2> pose = initial;
  // The reference is the identity; the others keep their pose relative to it.
  const Pose2 ref_from_world = initial[reference].inverse();
  for (Pose2& p : pose) p = ref_from_world * p;
  pose[reference] = Pose2::Identity();

  Eigen::MatrixXd h(dim, dim);
  Eigen::VectorXd g(dim);
  const auto assemble = [&](double* chi2) {
    h.setZero();
    g.setZero();
    *chi2 = 0.0;
    for (std::size_t k = 0; k < measurements.size(); ++k) {
      if (!use[k]) continue;
      const RelativeMeasurement& m = measurements[k];
      const EdgeLinearization l = Linearize(pose[m.r], pose[m.s], m.s_from_r);
      *chi2 += l.e.dot(info[k] * l.e);
      const std::size_t nodes[2] = {m.r, m.s};
      const Eigen::Matrix3d* jac[2] = {&l.d_r, &l.d_s};
      for (int a = 0; a < 2; ++a) {
        if (column[nodes[a]] < 0) continue;
        const Eigen::Matrix3d jt_info = jac[a]->transpose() * info[k];
        g.segment<3>(column[nodes[a]]) += jt_info * l.e;
        for (int b = 0; b < 2; ++b) {
          if (column[nodes[b]] < 0) continue;
          h.block<3, 3>(column[nodes[a]], column[nodes[b]]) += jt_info * *jac[b];
        }
      }
    }
  };
  double chi2 = 0.0;
  Eigen::LDLT<Eigen::MatrixXd> ldlt;
  for (int it = 0; it < options.max_iterations; ++it) {
    assemble(&chi2);
    ldlt.compute(h);
    if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) {
      return fail("the least-squares system is singular");
    }
    const Eigen::VectorXd step = -ldlt.solve(g);
    if (!step.allFinite()) return fail("the least-squares step is not finite");
    for (std::size_t v = 0; v < n; ++v) {
      if (column[v] < 0) continue;
      pose[v].x_m += step(column[v]);
      pose[v].y_m += step(column[v] + 1);
      pose[v].yaw_rad = common::NormalizeAngle(pose[v].yaw_rad + step(column[v] + 2));
    }
    out.iterations = it + 1;
    if (step.cwiseAbs().maxCoeff() < options.tolerance) break;
  }
  assemble(&chi2);
  ldlt.compute(h);
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) {
    return fail("the least-squares system is singular");
  }
  const Eigen::MatrixXd inverse = ldlt.solve(Eigen::MatrixXd::Identity(dim, dim));
  if (!inverse.allFinite()) return fail("the least-squares covariance is not finite");

  std::size_t used = 0;
  for (bool u : use) used += u ? 1 : 0;
  out.dof = 3 * static_cast<long>(used) - static_cast<long>(dim);
  out.chi2 = chi2;
  out.variance_factor = out.dof > 0 ? std::max(1.0, chi2 / static_cast<double>(out.dof)) : 1.0;
  out.world_from_node = pose;
  out.covariance.assign(n, Eigen::Matrix3d::Zero());
  for (std::size_t v = 0; v < n; ++v) {
    if (column[v] < 0) continue;
    const Eigen::Matrix3d c = out.variance_factor * inverse.block<3, 3>(column[v], column[v]);
    out.covariance[v] = 0.5 * (c + c.transpose());
  }
  out.residual_sigma.assign(measurements.size(), 0.0);
  out.residual_chi2.assign(measurements.size(), 0.0);
  for (std::size_t k = 0; k < measurements.size(); ++k) {
    const RelativeMeasurement& m = measurements[k];
    if (m.r >= n || m.s >= n) continue;
    if (use[k]) {
      const EdgeLinearization l = Linearize(pose[m.r], pose[m.s], m.s_from_r);
      out.residual_chi2[k] = l.e.dot(info[k] * l.e);
    }
    const RelativeFromPoses predicted =
        RelativePose(pose[m.r], out.covariance[m.r], pose[m.s], out.covariance[m.s]);
    out.residual_sigma[k] = MeasurementDistanceSigma(m.s_from_r, m.covariance, predicted);
  }
  out.ok = true;
  return out;
}

std::vector<int> CycleSupport(std::size_t n, const std::vector<RelativeMeasurement>& measurements,
                              const std::vector<bool>& use, int cap) {
  std::vector<int> out(measurements.size(), 0);
  std::vector<std::vector<std::size_t>> adjacent(n);
  for (std::size_t k = 0; k < measurements.size(); ++k) {
    if (k < use.size() && use[k] && measurements[k].r < n && measurements[k].s < n &&
        measurements[k].r != measurements[k].s) {
      adjacent[measurements[k].r].push_back(k);
      adjacent[measurements[k].s].push_back(k);
    }
  }
  // Unit-capacity undirected max flow by augmenting paths (BFS), each edge usable once in either
  // direction: flow[k] = +1 (r -> s), -1 (s -> r) or 0.
  std::vector<int> flow(measurements.size(), 0);
  std::vector<std::size_t> via(n);
  std::vector<bool> seen(n);
  for (std::size_t k = 0; k < measurements.size(); ++k) {
    if (k >= use.size() || !use[k]) continue;
    const std::size_t source = measurements[k].r, sink = measurements[k].s;
    if (source >= n || sink >= n || source == sink) continue;
    std::fill(flow.begin(), flow.end(), 0);
    int paths = 0;
    while (paths < cap) {
      std::fill(seen.begin(), seen.end(), false);
      std::vector<std::size_t> queue = {source};
      seen[source] = true;
      for (std::size_t head = 0; head < queue.size() && !seen[sink]; ++head) {
        const std::size_t u = queue[head];
        for (std::size_t e : adjacent[u]) {
          if (e == k) continue;
          const bool forward = measurements[e].r == u;
          const std::size_t v = forward ? measurements[e].s : measurements[e].r;
          // Residual capacity from u to v: 1 - flow(u -> v), flow(u -> v) in {-1, 0, 1}.
          const int f = forward ? flow[e] : -flow[e];
          if (f >= 1 || seen[v]) continue;
          seen[v] = true;
          via[v] = e;
          queue.push_back(v);
        }
      }
      if (!seen[sink]) break;
      for (std::size_t v = sink; v != source;) {
        const std::size_t e = via[v];
        const bool forward = measurements[e].s == v;  // traversed r -> s
        flow[e] += forward ? 1 : -1;
        v = forward ? measurements[e].r : measurements[e].s;
      }
      ++paths;
    }
    out[k] = paths;
  }
  return out;
}

}  // namespace lrfnet::calib
