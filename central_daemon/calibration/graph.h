#pragma once
// The pose graph of the global step (pipeline step 7): nodes are sensors 0..n-1, one `reference`
// node is fixed at the identity, and every edge is a relative measurement of a sensor pair.
//
// Convention: a measurement of the pair (r, s) is s_from_r (Pose2: yaw θ, translation t_sr), so
//   world_from_r = world_from_s * s_from_r,   i.e.   φ_r = φ_s + θ (mod 2π),  t_r = t_s + R(φ_s)
//   t_sr
// with φ_v the yaw and t_v the position of world_from_v. In Quenzel et al.'s notation (eq. 1,
// R_ij = R_i^T R_j, tangent angle w_ij = φ_j - φ_i) the measurement is w_sr = θ.
//
// Pure functions; thread-safe.

#include <Eigen/Core>
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "common/geometry.h"

namespace lrfnet::calib {

using common::Pose2;

struct RelativeMeasurement {
  std::size_t r = 0;
  std::size_t s = 0;
  Pose2 s_from_r;
  double weight = 1.0;  // > 0; e.g. Schenk's N/d (used where the options ask for weights)
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Identity();  // of (x, y, yaw) of s_from_r
};

// Union-find over nodes 0..n-1 (path halving). Find and Union take node indices < n.
class DisjointSets {
 public:
  explicit DisjointSets(std::size_t n) : parent_(n) {
    for (std::size_t i = 0; i < n; ++i) parent_[i] = i;
  }
  std::size_t Find(std::size_t i) {
    while (parent_[i] != i) i = parent_[i] = parent_[parent_[i]];
    return i;
  }
  // Joins the sets of a and b; false when they were one set already.
  bool Union(std::size_t a, std::size_t b) {
    a = Find(a);
    b = Find(b);
    if (a == b) return false;
    parent_[a] = b;
    return true;
  }

 private:
  std::vector<std::size_t> parent_;
};

// Nodes not connected to `reference` through measurements (sorted ascending). Measurements with
// an index >= n are ignored; reference >= n: every node is unconnected.
std::vector<std::size_t> UnconnectedNodes(std::size_t n, std::size_t reference,
                                          const std::vector<RelativeMeasurement>& measurements);

// "1, 4, 7" (at most `max_listed` indices, then ", ... (K more)").
std::string FormatNodeList(const std::vector<std::size_t>& nodes, std::size_t max_listed = 20);

// Checks what every global solver needs: n >= 2, reference < n, every measurement with r, s < n,
// r != s, finite yaw, translation and weight, weight > 0; when `check_covariance`: the translation
// block of the covariance finite, symmetric and positive definite (only for the measurements
// flagged in `covariance_of`, all when it is empty). Returns a one-line reason naming the
// measurement, or nullopt. Connectivity is not checked here (see ConnectivityError).
std::optional<std::string> CheckGraphInput(std::size_t n, std::size_t reference,
                                           const std::vector<RelativeMeasurement>& measurements,
                                           bool check_covariance = false,
                                           const std::vector<bool>& covariance_of = {});

// "nodes 3, 5 are not connected to the reference node 0" for the measurements flagged in `use`
// (all when `use` is empty), or nullopt when every node is connected.
std::optional<std::string> ConnectivityError(std::size_t n, std::size_t reference,
                                             const std::vector<RelativeMeasurement>& measurements,
                                             const std::vector<bool>& use = {});

// Yaws of the nodes (reference 0) by composing the measurements along a breadth-first spanning
// tree from the reference (ties: lowest measurement index first). Unreached nodes get 0.
std::vector<double> SpanningTreeYaws(std::size_t n, std::size_t reference,
                                     const std::vector<RelativeMeasurement>& measurements);

}  // namespace lrfnet::calib
