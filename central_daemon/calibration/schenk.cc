#include "central_daemon/calibration/schenk.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>

namespace lrfnet::calib {
namespace {

using common::AngleDiff;
using common::NormalizeAngle;

constexpr double kInf = std::numeric_limits<double>::infinity();

bool Finite(const Eigen::Vector2d& p) { return std::isfinite(p.x()) && std::isfinite(p.y()); }

// RMS distance of the points to their centroid: how far a track moved, independent of the frame.
double Extent(const std::vector<Eigen::Vector2d>& points) {
  if (points.empty()) return 0.0;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const auto& p : points) mean += p;
  mean /= static_cast<double>(points.size());
  double sum = 0.0;
  for (const auto& p : points) sum += (p - mean).squaredNorm();
  return std::sqrt(sum / static_cast<double>(points.size()));
}

std::string SensorName(const AlignedTracks& tracks, std::size_t i) {
  const std::string& id = tracks.sensors[i].id;
  return id.empty() ? "#" + std::to_string(i) : id;
}

// Eq. 7: combining the weight of neighbour n with that of the constraint (series springs, i.e.
// adding variances); the fixed reference has infinite weight.
double SeriesWeight(double w_n, double w_mn) {
  if (std::isinf(w_n)) return w_mn;
  const double sum = w_n + w_mn;
  return sum > 0.0 ? w_n * w_mn / sum : 0.0;
}

struct Neighbour {
  std::size_t n = 0;
  Pose2 n_from_m;                // θ̌_{m,n}: m's pose in n's frame (eq. 6)
  Eigen::Vector2d bearing_in_m;  // n's position in m's frame (eq. 10, see the header)
  double weight = 0.0;           // w_{m,n}
};

// Eq. 10 with our reading (header): argmin over φ of Σ |wrap(φ - δ_i)|. The cost is piecewise
// linear on the circle with its convex kinks at the δ_i, so the minimum is at one of them; a flat
// optimal arc (e.g. two neighbours) is represented by its middle.
std::optional<double> CircularMedian(const std::vector<double>& deltas) {
  if (deltas.empty()) return std::nullopt;
  std::vector<double> cost(deltas.size(), 0.0);
  double best = kInf;
  for (std::size_t i = 0; i < deltas.size(); ++i) {
    for (double d : deltas) cost[i] += std::abs(AngleDiff(deltas[i], d));
    best = std::min(best, cost[i]);
  }
  double sx = 0.0, sy = 0.0;
  std::size_t first = deltas.size();
  for (std::size_t i = 0; i < deltas.size(); ++i) {
    if (cost[i] > best + 1e-9) continue;
    if (first == deltas.size()) first = i;
    sx += std::cos(deltas[i]);
    sy += std::sin(deltas[i]);
  }
  if (std::hypot(sx, sy) < 1e-9) return deltas[first];  // antipodal tie: no middle
  return std::atan2(sy, sx);
}

// Target points of the ICP in a uniform grid with cells of the correspondence distance, so that a
// nearest-neighbour query within that distance looks at 3x3 cells.
class PointGrid {
 public:
  PointGrid(std::vector<Eigen::Vector2d> points, double cell_m)
      : points_(std::move(points)), cell_m_(cell_m) {
    cells_.reserve(points_.size());
    for (std::uint32_t i = 0; i < points_.size(); ++i) {
      if (auto key = KeyOf(points_[i])) cells_.emplace_back(*key, i);
    }
    std::sort(cells_.begin(), cells_.end());
  }

  // Nearest point closer than max_m, if any.
  std::optional<Eigen::Vector2d> Nearest(const Eigen::Vector2d& q, double max_m) const {
    const auto c = CellOf(q);
    if (!c) return std::nullopt;
    double best_sq = max_m * max_m;
    std::optional<Eigen::Vector2d> best;
    for (std::int64_t dx = -1; dx <= 1; ++dx) {
      for (std::int64_t dy = -1; dy <= 1; ++dy) {
        const std::int64_t key = Pack(c->first + dx, c->second + dy);
        auto it =
            std::lower_bound(cells_.begin(), cells_.end(), std::make_pair(key, std::uint32_t{0}));
        for (; it != cells_.end() && it->first == key; ++it) {
          const double d_sq = (points_[it->second] - q).squaredNorm();
          if (d_sq < best_sq) {
            best_sq = d_sq;
            best = points_[it->second];
          }
        }
      }
    }
    return best;
  }

 private:
  // Cells beyond ±1e9 cannot be packed (points that far away are not background anyway).
  std::optional<std::pair<std::int64_t, std::int64_t>> CellOf(const Eigen::Vector2d& p) const {
    const double fx = std::floor(p.x() / cell_m_), fy = std::floor(p.y() / cell_m_);
    if (!(std::abs(fx) < 1e9 && std::abs(fy) < 1e9)) return std::nullopt;
    return std::make_pair(static_cast<std::int64_t>(fx), static_cast<std::int64_t>(fy));
  }
  static std::int64_t Pack(std::int64_t ix, std::int64_t iy) {
    constexpr std::int64_t kOffset = std::int64_t{1} << 30;  // > 1e9: both terms stay positive
    return (ix + kOffset) * (std::int64_t{1} << 31) + (iy + kOffset);
  }
  std::optional<std::int64_t> KeyOf(const Eigen::Vector2d& p) const {
    const auto c = CellOf(p);
    if (!c) return std::nullopt;
    return Pack(c->first, c->second);
  }

  std::vector<Eigen::Vector2d> points_;
  double cell_m_;
  std::vector<std::pair<std::int64_t, std::uint32_t>> cells_;
};

struct Correspondences {
  std::vector<Eigen::Vector2d> source_world;
  std::vector<Eigen::Vector2d> target_world;
  double mean_distance_m = 0.0;
};

void FindCorrespondences(const std::vector<Eigen::Vector2d>& source_sensor,
                         const Pose2& world_from_sensor, const PointGrid& grid, double max_m,
                         Correspondences& out) {
  out.source_world.clear();
  out.target_world.clear();
  const Eigen::Matrix2d rotation = world_from_sensor.rotation();
  const Eigen::Vector2d translation = world_from_sensor.translation();
  double sum = 0.0;
  for (const auto& p : source_sensor) {
    const Eigen::Vector2d w = rotation * p + translation;
    if (auto t = grid.Nearest(w, max_m)) {
      out.source_world.push_back(w);
      out.target_world.push_back(*t);
      sum += (*t - w).norm();
    }
  }
  out.mean_distance_m =
      out.source_world.empty() ? 0.0 : sum / static_cast<double>(out.source_world.size());
}

}  // namespace

std::optional<std::string> Validate(const SchenkOptions& o) {
  auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  if (!positive(o.association_threshold_m)) return "association_threshold_m must be > 0";
  if (o.min_common_samples < 3) return "min_common_samples must be >= 3";
  if (!(std::isfinite(o.min_track_extent_m) && o.min_track_extent_m >= 0.0))
    return "min_track_extent_m must be >= 0";
  if (!positive(o.min_mean_distance_m)) return "min_mean_distance_m must be > 0";
  if (o.relaxation_iterations < 0) return "relaxation_iterations must be >= 0";
  if (!(positive(o.relaxation_step) && o.relaxation_step <= 1.0))
    return "relaxation_step must be in (0, 1]";
  if (!positive(o.relaxation_tolerance_m)) return "relaxation_tolerance_m must be > 0";
  if (!positive(o.relaxation_tolerance_rad)) return "relaxation_tolerance_rad must be > 0";
  if (!(std::isfinite(o.relaxation_min_bearing_distance_m) &&
        o.relaxation_min_bearing_distance_m >= 0.0))
    return "relaxation_min_bearing_distance_m must be >= 0";
  if (!positive(o.icp_max_correspondence_m)) return "icp_max_correspondence_m must be > 0";
  if (o.icp_iterations < 1) return "icp_iterations must be >= 1";
  if (o.icp_min_correspondences < 3) return "icp_min_correspondences must be >= 3";
  if (!positive(o.icp_tolerance_m)) return "icp_tolerance_m must be > 0";
  if (!positive(o.icp_tolerance_rad)) return "icp_tolerance_rad must be > 0";
  if (o.icp_sweeps < 1) return "icp_sweeps must be >= 1";
  return std::nullopt;
}

PointSetAlignment AlignPointSets(std::span<const Eigen::Vector2d> r_points,
                                 std::span<const Eigen::Vector2d> s_points) {
  PointSetAlignment out;
  const std::size_t n = r_points.size();
  if (n < 2 || s_points.size() != n) return out;
  Eigen::Vector2d mean_r = Eigen::Vector2d::Zero(), mean_s = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    mean_r += r_points[i];
    mean_s += s_points[i];
  }
  mean_r /= static_cast<double>(n);
  mean_s /= static_cast<double>(n);
  // In 2D the SVD solution of Besl-McKay (rotation R = V U^T of the cross-covariance, det = +1)
  // reduces to this angle: it maximises Σ q_i^T R p_i over proper rotations.
  double dot = 0.0, cross = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d p = r_points[i] - mean_r, q = s_points[i] - mean_s;
    dot += p.dot(q);
    cross += p.x() * q.y() - p.y() * q.x();
  }
  const double yaw = NormalizeAngle(std::atan2(cross, dot));
  const Eigen::Matrix2d rotation = Pose2{0.0, 0.0, yaw}.rotation();
  const Eigen::Vector2d t = mean_s - rotation * mean_r;
  out.s_from_r = {t.x(), t.y(), yaw};
  // Eq. 2: the mean Euclidean (not squared) distance after the alignment.
  double sum = 0.0;
  for (std::size_t i = 0; i < n; ++i) sum += (rotation * r_points[i] + t - s_points[i]).norm();
  out.mean_distance_m = sum / static_cast<double>(n);
  out.ok = std::isfinite(out.mean_distance_m);
  return out;
}

std::vector<SchenkEdge> BuildSchenkEdges(const AlignedTracks& tracks,
                                         const SchenkOptions& options) {
  std::vector<SchenkEdge> edges;
  const std::size_t sensor_count = tracks.sensors.size();
  std::vector<Eigen::Vector2d> pair_r, pair_s;        // one trimmed track pair
  std::vector<Eigen::Vector2d> virtual_r, virtual_s;  // eq. 3
  for (std::size_t r = 0; r < sensor_count; ++r) {
    for (std::size_t s = r + 1; s < sensor_count; ++s) {
      SchenkEdge edge;
      edge.r = r;
      edge.s = s;
      virtual_r.clear();
      virtual_s.clear();
      const auto& tracks_r = tracks.sensors[r].tracks;
      const auto& tracks_s = tracks.sensors[s].tracks;
      for (std::size_t a = 0; a < tracks_r.size(); ++a) {
        const GridTrack& ta = tracks_r[a];
        for (std::size_t b = 0; b < tracks_s.size(); ++b) {
          const GridTrack& tb = tracks_s[b];
          // III-B: trim both to the time steps they share.
          const std::size_t lo = std::max(ta.first_step, tb.first_step);
          const std::size_t hi = std::min(ta.end_step(), tb.end_step());
          if (hi <= lo || hi - lo < options.min_common_samples) continue;
          pair_r.clear();
          pair_s.clear();
          for (std::size_t k = lo; k < hi; ++k) {
            const Eigen::Vector2d& p = ta.At(k).position_m;
            const Eigen::Vector2d& q = tb.At(k).position_m;
            if (!Finite(p) || !Finite(q)) continue;
            pair_r.push_back(p);
            pair_s.push_back(q);
          }
          if (pair_r.size() < options.min_common_samples) continue;
          if (Extent(pair_r) < options.min_track_extent_m ||
              Extent(pair_s) < options.min_track_extent_m)
            continue;
          ++edge.compared;
          const PointSetAlignment fit = AlignPointSets(pair_r, pair_s);
          if (!fit.ok || !(fit.mean_distance_m < options.association_threshold_m)) continue;
          edge.associations.push_back({a, b, pair_r.size(), fit.mean_distance_m});
          virtual_r.insert(virtual_r.end(), pair_r.begin(), pair_r.end());
          virtual_s.insert(virtual_s.end(), pair_s.begin(), pair_s.end());
        }
      }
      if (edge.compared == 0) continue;
      if (!edge.associations.empty()) {
        // III-C: the virtual tracks are time-synchronous, so they align like one track pair.
        const PointSetAlignment fit = AlignPointSets(virtual_r, virtual_s);
        if (fit.ok) {
          edge.s_from_r = fit.s_from_r;
          edge.n = virtual_r.size();
          edge.d_m = fit.mean_distance_m;
          edge.weight = static_cast<double>(edge.n) /
                        std::max(edge.d_m, options.min_mean_distance_m);  // eq. 4
        }
      }
      edges.push_back(std::move(edge));
    }
  }
  return edges;
}

SchenkPlacement PlaceGreedy(std::size_t sensor_count, std::vector<SchenkEdge>& edges,
                            std::size_t reference) {
  SchenkPlacement out;
  out.world_from_sensor.assign(sensor_count, Pose2::Identity());
  out.placed.assign(sensor_count, false);
  out.node_weight.assign(sensor_count, 0.0);
  if (reference >= sensor_count) return out;
  out.placed[reference] = true;
  out.node_weight[reference] = kInf;
  out.order.push_back(reference);
  for (auto& e : edges) e.placement = false;
  // III-D: always the heaviest edge with exactly one placed end (see the header).
  while (true) {
    std::size_t best = edges.size();
    for (std::size_t k = 0; k < edges.size(); ++k) {
      const SchenkEdge& e = edges[k];
      if (e.n == 0 || e.r >= sensor_count || e.s >= sensor_count) continue;
      if (out.placed[e.r] == out.placed[e.s]) continue;
      if (best == edges.size() || e.weight > edges[best].weight) best = k;
    }
    if (best == edges.size()) break;
    SchenkEdge& e = edges[best];
    e.placement = true;
    const bool r_placed = out.placed[e.r];
    const std::size_t from = r_placed ? e.r : e.s;
    const std::size_t to = r_placed ? e.s : e.r;
    // Eq. 5: the new sensor's pose is the placed one's composed with the constraint.
    out.world_from_sensor[to] = r_placed ? out.world_from_sensor[from] * e.s_from_r.inverse()
                                         : out.world_from_sensor[from] * e.s_from_r;
    out.placed[to] = true;
    out.node_weight[to] = SeriesWeight(out.node_weight[from], e.weight);
    out.order.push_back(to);
  }
  return out;
}

int RelaxSchenk(const std::vector<SchenkEdge>& edges, std::size_t reference,
                const std::vector<bool>& placed, const SchenkOptions& options,
                std::vector<Pose2>& world_from_sensor, std::vector<double>& node_weight) {
  const std::size_t count = world_from_sensor.size();
  if (placed.size() != count || node_weight.size() != count || reference >= count) return 0;
  std::vector<std::vector<Neighbour>> neighbours(count);
  for (const SchenkEdge& e : edges) {
    if (e.n == 0 || e.r >= count || e.s >= count || !placed[e.r] || !placed[e.s]) continue;
    const Pose2 r_from_s = e.s_from_r.inverse();
    neighbours[e.r].push_back({e.s, e.s_from_r, r_from_s.translation(), e.weight});
    neighbours[e.s].push_back({e.r, r_from_s, e.s_from_r.translation(), e.weight});
  }

  std::vector<Eigen::Vector2d> new_position(count);
  std::vector<double> new_weight(count);
  std::vector<double> deltas;
  int iteration = 0;
  while (iteration < options.relaxation_iterations) {
    ++iteration;
    double max_move_m = 0.0, max_turn_rad = 0.0;
    // Eqs. 6-9 for every sensor from the poses of the previous iteration.
    for (std::size_t m = 0; m < count; ++m) {
      new_position[m] = world_from_sensor[m].translation();
      new_weight[m] = node_weight[m];
      if (m == reference || !placed[m] || neighbours[m].empty()) continue;
      Eigen::Vector2d sum = Eigen::Vector2d::Zero();
      double w_m = 0.0;
      for (const Neighbour& nb : neighbours[m]) {
        const Eigen::Vector2d estimate =
            world_from_sensor[nb.n] * nb.n_from_m.translation();      // eq. 6
        const double v = SeriesWeight(node_weight[nb.n], nb.weight);  // eq. 7
        w_m += v;                                                     // eq. 8
        sum += v * estimate;
      }
      if (!(w_m > 0.0) || !std::isfinite(w_m)) continue;
      new_position[m] = sum / w_m;  // eq. 9
      new_weight[m] = w_m;
    }
    for (std::size_t m = 0; m < count; ++m) {
      if (m == reference || !placed[m]) continue;
      const Eigen::Vector2d old = world_from_sensor[m].translation();
      const Eigen::Vector2d moved = old + options.relaxation_step * (new_position[m] - old);
      max_move_m = std::max(max_move_m, (moved - old).norm());
      world_from_sensor[m].x_m = moved.x();
      world_from_sensor[m].y_m = moved.y();
      node_weight[m] = new_weight[m];
    }
    // Eq. 10 for every sensor, on the new positions.
    std::vector<double> new_yaw(count);
    for (std::size_t m = 0; m < count; ++m) {
      new_yaw[m] = world_from_sensor[m].yaw_rad;
      if (m == reference || !placed[m]) continue;
      deltas.clear();
      for (const Neighbour& nb : neighbours[m]) {
        const Eigen::Vector2d to_n =
            world_from_sensor[nb.n].translation() - world_from_sensor[m].translation();
        if (to_n.norm() <= options.relaxation_min_bearing_distance_m ||
            nb.bearing_in_m.norm() <= options.relaxation_min_bearing_distance_m)
          continue;
        deltas.push_back(NormalizeAngle(std::atan2(to_n.y(), to_n.x()) -
                                        std::atan2(nb.bearing_in_m.y(), nb.bearing_in_m.x())));
      }
      if (auto yaw = CircularMedian(deltas)) {
        const double turn = options.relaxation_step * AngleDiff(*yaw, world_from_sensor[m].yaw_rad);
        new_yaw[m] = NormalizeAngle(world_from_sensor[m].yaw_rad + turn);
        max_turn_rad = std::max(max_turn_rad, std::abs(turn));
      }
    }
    for (std::size_t m = 0; m < count; ++m) world_from_sensor[m].yaw_rad = new_yaw[m];
    if (max_move_m <= options.relaxation_tolerance_m &&
        max_turn_rad <= options.relaxation_tolerance_rad)
      break;
  }
  return iteration;
}

std::vector<Eigen::Vector2d> BackgroundPoints(const BackgroundScan& background) {
  std::vector<Eigen::Vector2d> points;
  if (!std::isfinite(background.first_angle_rad) || !std::isfinite(background.angle_step_rad))
    return points;
  points.reserve(background.ranges_mm.size());
  for (std::size_t i = 0; i < background.ranges_mm.size(); ++i) {
    if (background.ranges_mm[i] == 0) continue;
    const double range_m = 1e-3 * static_cast<double>(background.ranges_mm[i]);
    const double angle_rad =
        background.first_angle_rad + static_cast<double>(i) * background.angle_step_rad;
    points.emplace_back(range_m * std::cos(angle_rad), range_m * std::sin(angle_rad));
  }
  return points;
}

std::vector<SchenkIcpReport> RefineSchenkIcp(const AlignedTracks& tracks, std::size_t reference,
                                             const std::vector<bool>& placed,
                                             const std::vector<std::size_t>& order,
                                             const SchenkOptions& options,
                                             std::vector<Pose2>& world_from_sensor) {
  const std::size_t count = tracks.sensors.size();
  std::vector<SchenkIcpReport> reports(count);
  if (placed.size() != count || world_from_sensor.size() != count) return reports;
  std::vector<std::vector<Eigen::Vector2d>> points(count);
  for (std::size_t i = 0; i < count; ++i) {
    if (placed[i] && tracks.sensors[i].background) {
      points[i] = BackgroundPoints(*tracks.sensors[i].background);
    }
  }
  const double max_m = options.icp_max_correspondence_m;
  Correspondences corr;
  // The map grows from the reference in placement order: a sensor is aligned onto the sensors
  // already aligned, never onto one whose pose the ICP has yet to correct.
  std::vector<bool> in_map(count, false);
  if (reference < count) in_map[reference] = true;
  for (int sweep = 0; sweep < options.icp_sweeps; ++sweep) {
    for (std::size_t m : order) {
      if (m >= count || m == reference || !placed[m]) continue;
      in_map[m] = true;
      if (points[m].empty()) continue;
      std::vector<Eigen::Vector2d> target;
      for (std::size_t j = 0; j < count; ++j) {
        if (j == m || !placed[j] || (options.icp_growing_map && !in_map[j])) continue;
        for (const auto& p : points[j]) target.push_back(world_from_sensor[j] * p);
      }
      if (target.empty()) continue;
      const PointGrid grid(std::move(target), max_m);
      SchenkIcpReport& report = reports[m];
      Pose2 pose = world_from_sensor[m];
      for (int it = 0; it < options.icp_iterations; ++it) {
        FindCorrespondences(points[m], pose, grid, max_m, corr);
        if (it == 0 && sweep == 0) report.mean_distance_before_m = corr.mean_distance_m;
        if (corr.source_world.size() < options.icp_min_correspondences) break;
        const PointSetAlignment step = AlignPointSets(corr.source_world, corr.target_world);
        if (!step.ok) break;
        pose = step.s_from_r * pose;  // the step maps world points of m onto the map
        report.applied = true;
        ++report.iterations;
        if (step.s_from_r.translation().norm() < options.icp_tolerance_m &&
            std::abs(step.s_from_r.yaw_rad) < options.icp_tolerance_rad)
          break;
      }
      FindCorrespondences(points[m], pose, grid, max_m, corr);
      report.correspondences = corr.source_world.size();
      report.mean_distance_after_m = corr.mean_distance_m;
      world_from_sensor[m] = pose;
    }
  }
  return reports;
}

SchenkResult CalibrateSchenk(const AlignedTracks& tracks, std::size_t reference,
                             const SchenkOptions& options) {
  SchenkResult result;
  const std::size_t count = tracks.sensors.size();
  result.world_from_sensor.assign(count, Pose2::Identity());
  result.placed.assign(count, false);
  if (auto error = Validate(options)) {
    result.message = "invalid Schenk options: " + *error;
    return result;
  }
  if (count == 0) {
    result.message = "no sensors";
    return result;
  }
  if (reference >= count) {
    result.message = "reference index " + std::to_string(reference) + " out of range (" +
                     std::to_string(count) + " sensors)";
    return result;
  }

  result.edges = BuildSchenkEdges(tracks, options);
  SchenkPlacement placement = PlaceGreedy(count, result.edges, reference);
  result.world_from_sensor = std::move(placement.world_from_sensor);
  result.placed = std::move(placement.placed);
  result.placement_order = std::move(placement.order);
  result.node_weight = std::move(placement.node_weight);
  for (SchenkEdge& e : result.edges) e.used = e.n > 0 && result.placed[e.r] && result.placed[e.s];

  result.relaxation_iterations = RelaxSchenk(result.edges, reference, result.placed, options,
                                             result.world_from_sensor, result.node_weight);
  if (options.use_icp) {
    result.icp = RefineSchenkIcp(tracks, reference, result.placed, result.placement_order, options,
                                 result.world_from_sensor);
  }

  std::vector<bool> has_constraint(count, false);
  for (const SchenkEdge& e : result.edges) {
    if (e.n == 0) continue;
    has_constraint[e.r] = true;
    has_constraint[e.s] = true;
  }
  std::string unplaced;
  for (std::size_t i = 0; i < count; ++i) {
    if (result.placed[i]) continue;
    if (!unplaced.empty()) unplaced += "; ";
    unplaced += "'" + SensorName(tracks, i) + "' (" +
                (has_constraint[i]
                     ? "not connected to the reference '" + SensorName(tracks, reference) + "'"
                     : std::string("no track associated with any other sensor")) +
                ")";
  }
  result.ok = unplaced.empty();
  if (!result.ok) result.message = "could not place: " + unplaced;
  return result;
}

}  // namespace lrfnet::calib
