#include "central_daemon/calibration/graph.h"

#include <Eigen/Cholesky>
#include <cmath>
#include <deque>

namespace lrfnet::calib {
namespace {

bool Finite(const Pose2& p) {
  return std::isfinite(p.x_m) && std::isfinite(p.y_m) && std::isfinite(p.yaw_rad);
}

// Adjacency lists over the usable measurements (indices < n, r != s, flagged in `use`).
std::vector<std::vector<std::size_t>> Adjacency(std::size_t n,
                                                const std::vector<RelativeMeasurement>& m,
                                                const std::vector<bool>& use) {
  std::vector<std::vector<std::size_t>> adj(n);
  for (std::size_t e = 0; e < m.size(); ++e) {
    if (!use.empty() && (e >= use.size() || !use[e])) continue;
    if (m[e].r >= n || m[e].s >= n || m[e].r == m[e].s) continue;
    adj[m[e].r].push_back(e);
    adj[m[e].s].push_back(e);
  }
  return adj;
}

std::vector<bool> Reached(std::size_t n, std::size_t reference,
                          const std::vector<RelativeMeasurement>& m, const std::vector<bool>& use) {
  std::vector<bool> reached(n, false);
  if (reference >= n) return reached;
  const auto adj = Adjacency(n, m, use);
  std::deque<std::size_t> queue{reference};
  reached[reference] = true;
  while (!queue.empty()) {
    const std::size_t v = queue.front();
    queue.pop_front();
    for (std::size_t e : adj[v]) {
      const std::size_t u = m[e].r == v ? m[e].s : m[e].r;
      if (!reached[u]) {
        reached[u] = true;
        queue.push_back(u);
      }
    }
  }
  return reached;
}

std::vector<std::size_t> NotReached(const std::vector<bool>& reached) {
  std::vector<std::size_t> out;
  for (std::size_t v = 0; v < reached.size(); ++v) {
    if (!reached[v]) out.push_back(v);
  }
  return out;
}

}  // namespace

std::vector<std::size_t> UnconnectedNodes(std::size_t n, std::size_t reference,
                                          const std::vector<RelativeMeasurement>& measurements) {
  return NotReached(Reached(n, reference, measurements, {}));
}

std::string FormatNodeList(const std::vector<std::size_t>& nodes, std::size_t max_listed) {
  std::string out;
  for (std::size_t i = 0; i < nodes.size() && i < max_listed; ++i) {
    if (i > 0) out += ", ";
    out += std::to_string(nodes[i]);
  }
  if (nodes.size() > max_listed) {
    out += ", ... (" + std::to_string(nodes.size() - max_listed) + " more)";
  }
  return out;
}

std::optional<std::string> CheckGraphInput(std::size_t n, std::size_t reference,
                                           const std::vector<RelativeMeasurement>& measurements,
                                           bool check_covariance,
                                           const std::vector<bool>& covariance_of) {
  if (n < 2) return "need at least 2 nodes, got " + std::to_string(n);
  if (reference >= n) {
    return "reference node " + std::to_string(reference) +
           " out of range (n = " + std::to_string(n) + ")";
  }
  for (std::size_t e = 0; e < measurements.size(); ++e) {
    const RelativeMeasurement& m = measurements[e];
    const std::string which = "measurement " + std::to_string(e) + " (" + std::to_string(m.r) +
                              ", " + std::to_string(m.s) + ")";
    if (m.r >= n || m.s >= n)
      return which + ": node index out of range (n = " + std::to_string(n) + ")";
    if (m.r == m.s) return which + ": relates a node to itself";
    if (!Finite(m.s_from_r)) return which + ": pose is not finite";
    if (!std::isfinite(m.weight) || !(m.weight > 0.0))
      return which + ": weight must be finite and > 0";
    if (check_covariance &&
        (covariance_of.empty() || (e < covariance_of.size() && covariance_of[e]))) {
      const Eigen::Matrix2d c = m.covariance.topLeftCorner<2, 2>();
      if (!c.allFinite()) return which + ": translation covariance is not finite";
      const Eigen::Matrix2d sym = 0.5 * (c + c.transpose());
      Eigen::LLT<Eigen::Matrix2d> llt(sym);
      if (llt.info() != Eigen::Success ||
          !((sym - c).cwiseAbs().maxCoeff() <= 1e-9 * c.cwiseAbs().maxCoeff())) {
        return which + ": translation covariance is not symmetric positive definite";
      }
    }
  }
  return std::nullopt;
}

std::optional<std::string> ConnectivityError(std::size_t n, std::size_t reference,
                                             const std::vector<RelativeMeasurement>& measurements,
                                             const std::vector<bool>& use) {
  const std::vector<std::size_t> missing = NotReached(Reached(n, reference, measurements, use));
  if (missing.empty()) return std::nullopt;
  return std::string(missing.size() == 1 ? "node " : "nodes ") + FormatNodeList(missing) +
         (missing.size() == 1 ? " is" : " are") + " not connected to the reference node " +
         std::to_string(reference);
}

std::vector<double> SpanningTreeYaws(std::size_t n, std::size_t reference,
                                     const std::vector<RelativeMeasurement>& measurements) {
  std::vector<double> yaw(n, 0.0);
  if (reference >= n) return yaw;
  const auto adj = Adjacency(n, measurements, {});
  std::vector<bool> reached(n, false);
  std::deque<std::size_t> queue{reference};
  reached[reference] = true;
  while (!queue.empty()) {
    const std::size_t v = queue.front();
    queue.pop_front();
    for (std::size_t e : adj[v]) {
      const RelativeMeasurement& m = measurements[e];
      const std::size_t u = m.r == v ? m.s : m.r;
      if (reached[u]) continue;
      reached[u] = true;
      // φ_r = φ_s + θ
      yaw[u] = common::NormalizeAngle(u == m.r ? yaw[v] + m.s_from_r.yaw_rad
                                               : yaw[v] - m.s_from_r.yaw_rad);
      queue.push_back(u);
    }
  }
  return yaw;
}

}  // namespace lrfnet::calib
