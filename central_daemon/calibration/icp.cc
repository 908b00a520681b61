#include "central_daemon/calibration/icp.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdarg>
#include <cstdint>
#include <cstdio>

#include "common/eigen_instances.h"

namespace lrfnet::calib {
namespace {

using common::kPi;
using internal::LineCorrespondence;

__attribute__((format(printf, 1, 2))) std::string Format(const char* format, ...) {
  char buffer[256];
  va_list args;
  va_start(args, format);
  std::vsnprintf(buffer, sizeof(buffer), format, args);
  va_end(args);
  return buffer;
}

bool Finite(const Pose2& pose) {
  return std::isfinite(pose.x_m) && std::isfinite(pose.y_m) && std::isfinite(pose.yaw_rad);
}

constexpr std::size_t kBlockBeams = 8;

// One background per beam, so that beam adjacency (which points may share a line) and the bearing
// lookup stay as the sensor measured them (the polar form CSM keeps, STYLE.md).
struct PolarCloud {
  double first_angle_rad = 0.0;
  double step_abs_rad = 0.0;
  double direction = 1.0;                // sign of the angle step: -1 when beams run clockwise
  std::vector<Eigen::Vector2d> point_m;  // per beam; meaningful where valid
  std::vector<std::uint8_t> valid;
  std::vector<std::uint32_t> valid_beams;
  // sin^2 and cos of k beams' angle, k = 0..beams, capped at 90 deg: the bounds of FindNearest
  // without a sine per candidate.
  std::vector<double> sin2_of_offset;
  std::vector<double> cos_of_offset;
  // Per block of kBlockBeams consecutive beams (from beam 0): the range interval of its valid
  // beams (min > max when it has none).
  std::vector<double> block_min_range_m;
  std::vector<double> block_max_range_m;
  // Per beam: the background's local line there (FitLines), when it has one.
  std::vector<Eigen::Vector2d> line_point_m;  // on the line (centroid of the fitted points)
  std::vector<Eigen::Vector2d> line_normal;   // unit, facing the sensor
  std::vector<double> line_angle_var_rad2;    // variance of the normal's direction from the fit
  std::vector<std::uint8_t> has_line;

  std::size_t beams() const { return point_m.size(); }

  // Fractional beam index of the bearing of p; of the two readings modulo a full turn, the one
  // nearer the scanned span, so that points just outside the field of view still search its edge.
  double BeamIndex(const Eigen::Vector2d& p) const {
    const double span_rad = static_cast<double>(beams() - 1) * step_abs_rad;
    double offset_rad = (std::atan2(p.y(), p.x()) - first_angle_rad) * direction;
    offset_rad -= 2.0 * kPi * std::floor(offset_rad / (2.0 * kPi));  // [0, 2 pi)
    if (offset_rad > kPi + 0.5 * span_rad) offset_rad -= 2.0 * kPi;
    return offset_rad / step_abs_rad;
  }
};

// Precondition: CheckBackground(background) passed.
PolarCloud MakeCloud(const BackgroundScan& background, double max_range_m) {
  PolarCloud cloud;
  cloud.first_angle_rad = background.first_angle_rad;
  cloud.step_abs_rad = std::abs(background.angle_step_rad);
  cloud.direction = background.angle_step_rad < 0.0 ? -1.0 : 1.0;
  const std::size_t n = background.ranges_mm.size();
  cloud.point_m.assign(n, Eigen::Vector2d::Zero());
  cloud.valid.assign(n, 0);
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t range_mm = background.ranges_mm[i];
    if (range_mm == 0) continue;
    const double range_m = 1e-3 * static_cast<double>(range_mm);
    if (max_range_m > 0.0 && range_m > max_range_m) continue;
    const double angle_rad =
        background.first_angle_rad + static_cast<double>(i) * background.angle_step_rad;
    cloud.point_m[i] = range_m * Eigen::Vector2d(std::cos(angle_rad), std::sin(angle_rad));
    cloud.valid[i] = 1;
    cloud.valid_beams.push_back(static_cast<std::uint32_t>(i));
  }
  cloud.sin2_of_offset.resize(n + 1);
  cloud.cos_of_offset.resize(n + 1);
  for (std::size_t k = 0; k <= n; ++k) {
    const double offset_rad = std::min(static_cast<double>(k) * cloud.step_abs_rad, 0.5 * kPi);
    cloud.sin2_of_offset[k] = offset_rad >= 0.5 * kPi ? 1.0 : std::pow(std::sin(offset_rad), 2);
    cloud.cos_of_offset[k] = offset_rad >= 0.5 * kPi ? 0.0 : std::cos(offset_rad);
  }
  const std::size_t blocks = (n + kBlockBeams - 1) / kBlockBeams;
  cloud.block_min_range_m.assign(blocks, HUGE_VAL);
  cloud.block_max_range_m.assign(blocks, -HUGE_VAL);
  for (const std::uint32_t i : cloud.valid_beams) {
    const double range_m = cloud.point_m[i].norm();
    double& lo = cloud.block_min_range_m[i / kBlockBeams];
    double& hi = cloud.block_max_range_m[i / kBlockBeams];
    lo = std::min(lo, range_m);
    hi = std::max(hi, range_m);
  }
  return cloud;
}

// Nearest valid point of `cloud` to p within max_dist_m, or -1. Searches outward from p's bearing,
// with two exact lower bounds on the distance to what lies further out:
// - a beam at angular offset a (below 90 deg) holds no point nearer than |p| sin(a), which ends
// each
//   side after about asin(max_dist / |p|) / step beams;
// - a block of kBlockBeams beams whose nearest beam is at offset a and whose ranges lie in
//   [min, max] holds no point nearer than the nearest point of that range interval on the ray at
//   offset a (the distance to a point grows with its offset at any fixed range), so a block of
//   wall in front of or far behind p is skipped whole: points hidden from the other sensor cost a
//   few blocks, not the whole window.
// Offsets are rounded down to whole beams, which only loosens the bounds.
std::ptrdiff_t FindNearest(const PolarCloud& cloud, const Eigen::Vector2d& p, double max_dist_m) {
  const double rho_m = p.norm();
  if (!(rho_m > 1e-6) || cloud.beams() == 0) return -1;
  const auto n = static_cast<std::ptrdiff_t>(cloud.beams());
  const double center = cloud.BeamIndex(p);
  const std::ptrdiff_t start = std::clamp<std::ptrdiff_t>(std::lround(center), 0, n - 1);
  double best_d2 = max_dist_m * max_dist_m;
  std::ptrdiff_t best = -1;
  const double rho2_m2 = rho_m * rho_m;
  const auto whole_offset = [&](std::ptrdiff_t j) {
    return std::min(static_cast<std::size_t>(std::abs(static_cast<double>(j) - center)),
                    cloud.beams());
  };
  // Lower bound of the squared distance to the block holding beam j, given its offset.
  const auto block_bound2 = [&](std::ptrdiff_t j, std::size_t whole) {
    const std::size_t b = static_cast<std::size_t>(j) / kBlockBeams;
    const double lo = cloud.block_min_range_m[b], hi = cloud.block_max_range_m[b];
    if (lo > hi) return HUGE_VAL;  // no valid beam in the block
    const double cos_a = cloud.cos_of_offset[whole];
    const double range_m = std::clamp(rho_m * cos_a, lo, hi);
    return rho2_m2 + range_m * range_m - 2.0 * rho_m * range_m * cos_a;
  };
  const auto consider = [&](std::ptrdiff_t j) {
    if (cloud.valid[j] == 0) return;
    const double d2 = (p - cloud.point_m[j]).squaredNorm();
    if (d2 < best_d2) {
      best_d2 = d2;
      best = j;
    }
  };
  // Upward: beams start, start + 1, ...; `start` may lie just below the centre, which the rounded
  // offset covers (0 there).
  for (std::ptrdiff_t j = start; j < n;) {
    const std::size_t whole = whole_offset(j);
    const double sin2 = cloud.sin2_of_offset[whole];
    if (static_cast<double>(j) >= center && (sin2 >= 1.0 || rho2_m2 * sin2 >= best_d2)) break;
    if (j % static_cast<std::ptrdiff_t>(kBlockBeams) == 0 && block_bound2(j, whole) >= best_d2) {
      j += static_cast<std::ptrdiff_t>(kBlockBeams);
      continue;
    }
    consider(j);
    ++j;
  }
  // Downward: beams start - 1, start - 2, ...
  for (std::ptrdiff_t j = start - 1; j >= 0;) {
    const std::size_t whole = whole_offset(j);
    const double sin2 = cloud.sin2_of_offset[whole];
    if (static_cast<double>(j) <= center && (sin2 >= 1.0 || rho2_m2 * sin2 >= best_d2)) break;
    if ((j + 1) % static_cast<std::ptrdiff_t>(kBlockBeams) == 0 &&
        block_bound2(j, whole) >= best_d2) {
      j -= static_cast<std::ptrdiff_t>(kBlockBeams);
      continue;
    }
    consider(j);
    --j;
  }
  return best;
}

struct Line {
  Eigen::Vector2d q_m;
  Eigen::Vector2d n;  // unit normal facing the cloud's sensor; zero when `point_only`
  double angle_var_rad2 = 0.0;
  bool point_only = false;
};

// The local line of the background around each beam: the least-squares line through the beam's
// point and its chain-connected neighbours (each at most max_segment_length_m from the previous
// one: no line across a depth jump) within line_radius_m of it (the nearest neighbour on each side
// also beyond, so that the sparse points of a far wall get lines too). When the points scatter
// about the line by more than line_tolerance_m (RMS), the window spans a corner: it is halved until
// it is straight; a beam whose three nearest points are not straight has no line. Censi's line
// through only the two nearest points, and lines cut short by testing each new point against the
// line of the few before it, have normals tilted by a good fraction of a radian at a few
// centimetres' beam spacing and centimetre noise; the tilts bias the solution and fake information
// along a degenerate direction (a corridor's axis) that the degeneracy test must see as absent.
void FitLines(PolarCloud& cloud, const IcpOptions& options) {
  constexpr std::ptrdiff_t kMaxBeamsPerSide = 16;
  const auto n = static_cast<std::ptrdiff_t>(cloud.beams());
  cloud.line_point_m.assign(cloud.beams(), Eigen::Vector2d::Zero());
  cloud.line_normal.assign(cloud.beams(), Eigen::Vector2d::Zero());
  cloud.line_angle_var_rad2.assign(cloud.beams(), 0.0);
  cloud.has_line.assign(cloud.beams(), 0);
  // Counter-clockwise first, whichever way the beams are numbered, so that a scan gives the same
  // lines in either order.
  const std::ptrdiff_t steps[2] = {cloud.direction > 0 ? 1 : -1, cloud.direction > 0 ? -1 : 1};
  for (const std::uint32_t beam : cloud.valid_beams) {
    const auto i = static_cast<std::ptrdiff_t>(beam);
    const Eigen::Vector2d& centre = cloud.point_m[i];
    for (double radius_m = options.line_radius_m;; radius_m *= 0.5) {
      // Moments of the points relative to the centre point (no cancellation at long ranges).
      double count = 1.0, sx = 0.0, sy = 0.0, sxx = 0.0, sxy = 0.0, syy = 0.0;
      std::ptrdiff_t ends[2] = {i, i};
      bool open[2] = {true, true};
      while (open[0] || open[1]) {
        for (int side = 0; side < 2; ++side) {
          if (!open[side]) continue;
          const std::ptrdiff_t k = ends[side] + steps[side];
          if (k < 0 || k >= n || cloud.valid[k] == 0 || std::abs(k - i) > kMaxBeamsPerSide ||
              (cloud.point_m[k] - cloud.point_m[ends[side]]).norm() >
                  options.max_segment_length_m ||
              (std::abs(k - i) > 1 && (cloud.point_m[k] - centre).norm() > radius_m)) {
            open[side] = false;
            continue;
          }
          const Eigen::Vector2d d = cloud.point_m[k] - centre;
          count += 1.0;
          sx += d.x();
          sy += d.y();
          sxx += d.x() * d.x();
          sxy += d.x() * d.y();
          syy += d.y() * d.y();
          ends[side] = k;
        }
      }
      if (count < 3.0) break;  // two points alone make a normal as noisy as Censi's segment
      const Eigen::Vector2d mean = Eigen::Vector2d(sx, sy) / count;
      const double cxx = sxx / count - mean.x() * mean.x();
      const double cxy = sxy / count - mean.x() * mean.y();
      const double cyy = syy / count - mean.y() * mean.y();
      const double root = std::sqrt(0.25 * (cxx - cyy) * (cxx - cyy) + cxy * cxy);
      const double smaller = std::max(0.5 * (cxx + cyy) - root, 0.0);
      const double larger = 0.5 * (cxx + cyy) + root;
      if (smaller > options.line_tolerance_m * options.line_tolerance_m) {
        if (count <= 3.0) break;
        continue;  // a corner: try half the window
      }
      // Eigenvector of the smaller eigenvalue of [[cxx, cxy], [cxy, cyy]].
      const Eigen::Vector2d a(cxy, smaller - cxx), b(smaller - cyy, cxy);
      Eigen::Vector2d normal = a.squaredNorm() >= b.squaredNorm() ? a : b;
      if (!(normal.norm() > 0.0) || !(larger > 0.0)) break;
      normal.normalize();
      const Eigen::Vector2d point = centre + mean;
      if (normal.dot(point) > 0.0) normal = -normal;
      cloud.line_point_m[i] = point;
      cloud.line_normal[i] = normal;
      // Slope variance of a least-squares line: residual variance / (count * spread variance).
      cloud.line_angle_var_rad2[i] = smaller / ((count - 2.0) * larger);
      cloud.has_line[i] = 1;
      break;
    }
  }
}

// The background's line at beam j (FitLines); with allow_point, a beam without a line is returned
// as a point.
std::optional<Line> LineAt(const PolarCloud& cloud, std::ptrdiff_t j, bool allow_point) {
  if (cloud.has_line[j] != 0) {
    return Line{cloud.line_point_m[j], cloud.line_normal[j], cloud.line_angle_var_rad2[j], false};
  }
  if (allow_point) return Line{cloud.point_m[j], Eigen::Vector2d::Zero(), 0.0, true};
  return std::nullopt;
}

// Both sensors must see a surface from the same side: the other sensor's origin (in this cloud's
// frame) must lie in front of the line, or the pair is the two faces of a thin wall.
bool SameSide(const Line& line, const Eigen::Vector2d& other_origin) {
  return line.point_only || line.n.dot(other_origin - line.q_m) > 0.0;
}

struct Scored {
  LineCorrespondence c;
  double abs_residual_m = 0.0;
  double angle_var_rad2 = 0.0;  // of the line's normal
};

// The point-to-line correspondences of r's points under s_from_r, nearest point within max_dist_m.
void FindCorrespondences(const PolarCloud& r, const PolarCloud& s, const Pose2& s_from_r,
                         double max_dist_m, std::vector<Scored>& out) {
  out.clear();
  const Eigen::Matrix2d rotation = s_from_r.rotation();
  const Eigen::Vector2d origin_r_in_s = s_from_r.translation();
  for (const std::uint32_t i : r.valid_beams) {
    const Eigen::Vector2d& p_r = r.point_m[i];
    const Eigen::Vector2d p_s = rotation * p_r + origin_r_in_s;
    const std::ptrdiff_t j = FindNearest(s, p_s, max_dist_m);
    if (j < 0) continue;
    const std::optional<Line> line = LineAt(s, j, false);
    if (!line || !SameSide(*line, origin_r_in_s)) continue;
    out.push_back(
        {{p_r, line->q_m, line->n}, std::abs(line->n.dot(p_s - line->q_m)), line->angle_var_rad2});
  }
}

// Keeps the best (1 - trim_fraction) of the correspondences, by residual.
void Trim(std::vector<Scored>& scored, double trim_fraction) {
  const auto drop =
      static_cast<std::size_t>(std::floor(trim_fraction * static_cast<double>(scored.size())));
  if (drop == 0) return;
  const std::size_t keep = scored.size() - drop;
  std::nth_element(
      scored.begin(), scored.begin() + static_cast<std::ptrdiff_t>(keep), scored.end(),
      [](const Scored& a, const Scored& b) { return a.abs_residual_m < b.abs_residual_m; });
  scored.resize(keep);
}

// One direction of the consistency score: sum of min(d^2, tau^2) / tau^2 over a's points mapped
// into b, and how many lie within tau.
void ScoreDirection(const PolarCloud& a, const PolarCloud& b, const Pose2& b_from_a,
                    const IcpOptions& options, double& cost, std::size_t& inliers) {
  const double tau_m = options.inlier_distance_m;
  const double search_m = std::max(options.max_segment_length_m, tau_m);
  const Eigen::Vector2d origin_a_in_b = b_from_a.translation();
  const Eigen::Matrix2d rotation = b_from_a.rotation();
  for (const std::uint32_t i : a.valid_beams) {
    const Eigen::Vector2d p = rotation * a.point_m[i] + origin_a_in_b;
    double d_m = tau_m;
    const std::ptrdiff_t j = FindNearest(b, p, search_m);
    if (j >= 0) {
      const std::optional<Line> line = LineAt(b, j, true);
      if (line && SameSide(*line, origin_a_in_b)) {
        d_m = line->point_only ? (p - line->q_m).norm() : std::abs(line->n.dot(p - line->q_m));
      }
    }
    if (d_m < tau_m) {
      ++inliers;
      cost += (d_m * d_m) / (tau_m * tau_m);
    } else {
      cost += 1.0;
    }
  }
}

BackgroundConsistency Score(const PolarCloud& r, const PolarCloud& s, const Pose2& s_from_r,
                            const IcpOptions& options) {
  BackgroundConsistency out;
  double cost = 0.0;
  ScoreDirection(r, s, s_from_r, options, cost, out.inliers);
  ScoreDirection(s, r, s_from_r.inverse(), options, cost, out.inliers);
  out.points = r.valid_beams.size() + s.valid_beams.size();
  out.score = out.points > 0 ? cost / static_cast<double>(out.points) : 1.0;
  return out;
}

// Gauss-Newton information of the point-to-line residuals at `pose` in scaled coordinates
// (x, y, yaw * scale_m), so that the three eigenvalues compare: a unit step of each moves the
// points by about a metre.
struct Information {
  Eigen::Matrix3d h = Eigen::Matrix3d::Zero();  // sum J^T J
  Eigen::Vector3d g = Eigen::Vector3d::Zero();  // sum J^T e
  double sum_e2 = 0.0;
  double scale_m = 1.0;
  Eigen::Matrix3d vectors = Eigen::Matrix3d::Identity();  // eigenvectors of h, ascending
  Eigen::Vector3d values = Eigen::Vector3d::Zero();
  std::array<bool, 3> degenerate{};
  int degenerate_count = 0;
};

// scale_m <= 0: the RMS range of r's matched points.
Information ComputeInformation(std::span<const Scored> scored, const Pose2& pose,
                               const IcpOptions& options, double scale_m = 0.0) {
  Information info;
  if (scale_m > 0.0) {
    info.scale_m = scale_m;
  } else {
    const double count = static_cast<double>(std::max<std::size_t>(scored.size(), 1));
    double sum_r2 = 0.0;
    for (const Scored& s : scored) sum_r2 += s.c.p_r.squaredNorm();
    info.scale_m = std::max(std::sqrt(sum_r2 / count), 1e-3);
  }
  const Eigen::Matrix2d rotation = pose.rotation();
  const Eigen::Vector2d t = pose.translation();
  for (const Scored& s : scored) {
    const Eigen::Vector2d rp = rotation * s.c.p_r;
    const double e = s.c.n_s.dot(rp + t - s.c.q_s);
    // d(R p)/d yaw = R J p with J the 90 deg rotation: (-rp.y, rp.x).
    const Eigen::Vector3d jac(s.c.n_s.x(), s.c.n_s.y(),
                              s.c.n_s.dot(Eigen::Vector2d(-rp.y(), rp.x())) / info.scale_m);
    info.h += jac * jac.transpose();
    info.g += jac * e;
    info.sum_e2 += e * e;
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(info.h);
  info.values = solver.eigenvalues();
  info.vectors = solver.eigenvectors();
  // The eigenvalue lambda_k = sum (J_i v_k)^2 is the information along v_k, but a normal tilted
  // by its fitting error delta adds delta^2 ((t, t . R J p / L) . v_k)^2 (t the line's tangent)
  // even where the surfaces carry none: along a corridor, many slightly tilted normals add up to an
  // eigenvalue that looks like a constraint on its axis. So the expected contribution of the
  // normals' own variance is taken off before the test.
  Eigen::Vector3d noise_information = Eigen::Vector3d::Zero();
  for (const Scored& s : scored) {
    const Eigen::Vector2d rp = rotation * s.c.p_r;
    const Eigen::Vector2d tangent(-s.c.n_s.y(), s.c.n_s.x());
    const Eigen::Vector3d tilt(tangent.x(), tangent.y(),
                               tangent.dot(Eigen::Vector2d(-rp.y(), rp.x())) / info.scale_m);
    const Eigen::Vector3d along = info.vectors.transpose() * tilt;
    noise_information += s.angle_var_rad2 * along.cwiseProduct(along);
  }
  for (int k = 0; k < 3; ++k) {
    info.degenerate[k] =
        !(info.values[k] - noise_information[k] >= options.min_direction_information) ||
        !(info.values[k] > 0.0);
    info.degenerate_count += info.degenerate[k] ? 1 : 0;
  }
  return info;
}

// Orthonormal directions in the scaled coordinates of an Information (columns), and the matrices
// of a system restricted to them (fixed capacity: no allocation).
using Directions = Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, 3>;
using SmallMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 3, 3>;

// The degenerate (or the other) eigen-directions of `info`.
Directions Eigendirections(const Information& info, bool degenerate) {
  Directions out(3, degenerate ? info.degenerate_count : 3 - info.degenerate_count);
  for (int k = 0, column = 0; k < 3; ++k) {
    if (info.degenerate[k] == degenerate) out.col(column++) = info.vectors.col(k);
  }
  return out;
}

// The Gauss-Newton step restricted to the span of `free` (solution remapping of Zhang et al.
// 2016): along the other directions the pose does not move. nullopt when the restricted system is
// singular.
std::optional<Pose2> RestrictedGaussNewtonStep(const Information& info, const Pose2& pose,
                                               const Directions& free) {
  Eigen::Vector3d step = Eigen::Vector3d::Zero();
  if (free.cols() > 0) {
    const SmallMatrix reduced = free.transpose() * info.h * free;
    const Eigen::LDLT<SmallMatrix> ldlt(reduced);
    if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0.0)) return std::nullopt;
    step = -free * ldlt.solve(free.transpose() * info.g);
  }
  return Pose2{pose.x_m + step[0], pose.y_m + step[1],
               common::NormalizeAngle(pose.yaw_rad + step[2] / info.scale_m)};
}

bool WithinBounds(const Pose2& pose, const Pose2& initial, const IcpOptions& options) {
  return common::TranslationDistanceM(pose, initial) <= options.max_translation_change_m &&
         common::RotationDistanceRad(pose, initial) <= common::DegToRad(options.max_yaw_change_deg);
}

}  // namespace

std::optional<std::string> Validate(const IcpOptions& o) {
  if (o.max_iterations < 1) return "max_iterations must be >= 1";
  if (!(std::isfinite(o.final_correspondence_m) && o.final_correspondence_m > 0.0)) {
    return "final_correspondence_m must be > 0";
  }
  if (!(std::isfinite(o.initial_correspondence_m) &&
        o.initial_correspondence_m >= o.final_correspondence_m)) {
    return "initial_correspondence_m must be finite and >= final_correspondence_m";
  }
  if (o.anneal_iterations < 0) return "anneal_iterations must be >= 0";
  if (!(std::isfinite(o.max_segment_length_m) && o.max_segment_length_m > 0.0)) {
    return "max_segment_length_m must be > 0";
  }
  if (!(o.trim_fraction >= 0.0 && o.trim_fraction <= 0.9)) {
    return "trim_fraction must be in [0, 0.9]";
  }
  if (o.min_correspondences < 4) return "min_correspondences must be >= 4";
  if (!(std::isfinite(o.max_translation_change_m) && o.max_translation_change_m > 0.0)) {
    return "max_translation_change_m must be > 0";
  }
  if (!(o.max_yaw_change_deg > 0.0 && o.max_yaw_change_deg <= 180.0)) {
    return "max_yaw_change_deg must be in (0, 180]";
  }
  if (!(std::isfinite(o.inlier_distance_m) && o.inlier_distance_m > 0.0)) {
    return "inlier_distance_m must be > 0";
  }
  if (!(std::isfinite(o.max_range_m) && o.max_range_m > 0.0)) return "max_range_m must be > 0";
  if (!(o.min_score_improvement >= 0.0 && o.min_score_improvement < 1.0)) {
    return "min_score_improvement must be in [0, 1)";
  }
  if (!(std::isfinite(o.line_radius_m) && o.line_radius_m > 0.0)) {
    return "line_radius_m must be > 0";
  }
  if (!(std::isfinite(o.line_tolerance_m) && o.line_tolerance_m > 0.0)) {
    return "line_tolerance_m must be > 0";
  }
  if (!(std::isfinite(o.residual_correlation) && o.residual_correlation >= 1.0)) {
    return "residual_correlation must be >= 1";
  }
  if (!(std::isfinite(o.systematic_floor_m) && o.systematic_floor_m >= 0.0)) {
    return "systematic_floor_m must be >= 0";
  }
  if (!(std::isfinite(o.residual_floor_m) && o.residual_floor_m > 0.0)) {
    return "residual_floor_m must be > 0";
  }
  if (!(std::isfinite(o.min_direction_information) && o.min_direction_information >= 0.0)) {
    return "min_direction_information must be >= 0";
  }
  if (o.max_degenerate_directions < 0 || o.max_degenerate_directions > 3) {
    return "max_degenerate_directions must be in [0, 3]";
  }
  if (!(std::isfinite(o.convergence_translation_m) && o.convergence_translation_m >= 0.0 &&
        std::isfinite(o.convergence_yaw_rad) && o.convergence_yaw_rad >= 0.0)) {
    return "convergence thresholds must be >= 0";
  }
  return std::nullopt;
}

std::optional<std::string> CheckBackground(const BackgroundScan& background) {
  const std::size_t n = background.ranges_mm.size();
  if (n == 0) return "background has no beams";
  if (n > kMaxIcpBeams) return Format("background has %zu beams (at most %zu)", n, kMaxIcpBeams);
  if (!std::isfinite(background.first_angle_rad) || !std::isfinite(background.angle_step_rad)) {
    return std::string("background angles are not finite");
  }
  if (std::abs(background.first_angle_rad) > 2.0 * kPi) {
    return Format("background first angle %.3f rad is outside [-2 pi, 2 pi]",
                  background.first_angle_rad);
  }
  if (background.angle_step_rad == 0.0) return std::string("background angle step is zero");
  // A span beyond a full turn means the beam count does not match the angle step.
  const double span_rad = static_cast<double>(n - 1) * std::abs(background.angle_step_rad);
  if (span_rad > 2.0 * kPi * (1.0 + 1e-9)) {
    return Format(
        "background beam count %zu and angle step %.4f deg span %.1f deg, more than a full turn", n,
        common::RadToDeg(background.angle_step_rad), common::RadToDeg(span_rad));
  }
  return std::nullopt;
}

std::vector<Eigen::Vector2d> BackgroundPoints(const BackgroundScan& background,
                                              double max_range_m) {
  std::vector<Eigen::Vector2d> out;
  if (CheckBackground(background)) return out;
  const PolarCloud cloud = MakeCloud(background, max_range_m);
  out.reserve(cloud.valid_beams.size());
  for (const std::uint32_t i : cloud.valid_beams) out.push_back(cloud.point_m[i]);
  return out;
}

std::optional<BackgroundConsistency> ScoreBackgrounds(const BackgroundScan& r_background,
                                                      const BackgroundScan& s_background,
                                                      const Pose2& s_from_r,
                                                      const IcpOptions& options) {
  if (Validate(options) || CheckBackground(r_background) || CheckBackground(s_background) ||
      !Finite(s_from_r)) {
    return std::nullopt;
  }
  PolarCloud r = MakeCloud(r_background, options.max_range_m);
  PolarCloud s = MakeCloud(s_background, options.max_range_m);
  FitLines(r, options);
  FitLines(s, options);
  return Score(r, s, s_from_r, options);
}

namespace internal {

// Censi (ICRA 2008), section IV: with x = (t_x, t_y, cos yaw, sin yaw) each residual is linear,
// n_i^T (M_i x - q_i) with M_i = [I, P_i], P_i = [[p_x, -p_y], [p_y, p_x]], so the cost is the
// quadratic x^T M x - 2 c^T x + const, minimised subject to x_3^2 + x_4^2 = 1 with a Lagrange
// multiplier lambda: (M + lambda W) x = c, W = diag(0, 0, 1, 1). Eliminating t leaves
// (S + lambda I) r = h for r = (cos, sin), S = D - B^T A^-1 B, h = c_r - B^T A^-1 c_t, and |r| = 1
// gives Censi's quartic in lambda, whose largest real root is the global minimum (S + lambda I must
// be positive semi-definite there). We find that root as the unique zero of the secular equation
// |(S + lambda I)^-1 h|^2 = 1 on (-s_min, inf), where it is monotone, by bisection: the same
// multiplier without the ill-conditioning of a companion-matrix root finder.
std::optional<Pose2> SolvePointToLine(std::span<const LineCorrespondence> correspondences) {
  Eigen::Matrix2d a = Eigen::Matrix2d::Zero();
  Eigen::Matrix2d b = Eigen::Matrix2d::Zero();
  Eigen::Matrix2d d = Eigen::Matrix2d::Zero();
  Eigen::Vector2d c_t = Eigen::Vector2d::Zero();
  Eigen::Vector2d c_r = Eigen::Vector2d::Zero();
  for (const LineCorrespondence& c : correspondences) {
    const Eigen::Matrix2d weight = c.n_s * c.n_s.transpose();
    Eigen::Matrix2d p;
    p << c.p_r.x(), -c.p_r.y(), c.p_r.y(), c.p_r.x();
    a += weight;
    b += weight * p;
    d += p.transpose() * weight * p;
    c_t += weight * c.q_s;
    c_r += p.transpose() * weight * c.q_s;
  }
  const double det_a = a.determinant();
  if (!(det_a > 1e-9 * a.trace() * a.trace())) return std::nullopt;
  const Eigen::Matrix2d a_inv = a.inverse();
  Eigen::Matrix2d s = d - b.transpose() * a_inv * b;
  s = 0.5 * (s + s.transpose());
  const Eigen::Vector2d h = c_r - b.transpose() * a_inv * c_t;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> solver(s);
  const Eigen::Vector2d& s_values = solver.eigenvalues();  // ascending
  const Eigen::Vector2d h_rot = solver.eigenvectors().transpose() * h;
  const double h_norm = h.norm();
  if (!(h_norm > 1e-12 * std::max(1.0, s_values.cwiseAbs().maxCoeff()))) return std::nullopt;

  const auto secular = [&](double lambda) {
    const double u = h_rot[0] / (s_values[0] + lambda);
    const double v = h_rot[1] / (s_values[1] + lambda);
    return u * u + v * v - 1.0;
  };
  double lo = -s_values[0];           // secular -> +inf (unless h_rot[0] == 0)
  double hi = -s_values[0] + h_norm;  // secular <= 0
  for (int k = 0; k < 200 && hi - lo > 1e-15 * (std::abs(lo) + std::abs(hi) + 1e-300); ++k) {
    const double mid = 0.5 * (lo + hi);
    if (mid <= lo || mid >= hi) break;
    if (secular(mid) > 0.0) {
      lo = mid;
    } else {
      hi = mid;
    }
  }
  const double lambda = hi;
  if (!(s_values[0] + lambda > 0.0)) return std::nullopt;
  const Eigen::Vector2d r_rot(h_rot[0] / (s_values[0] + lambda), h_rot[1] / (s_values[1] + lambda));
  Eigen::Vector2d r = solver.eigenvectors() * r_rot;
  // |r| < 1 here means the hard case of the multiplier (h orthogonal to the weakest direction of
  // S): two mirror-image minima; let the caller fall back to Gauss-Newton.
  if (!(std::abs(r.norm() - 1.0) < 1e-6)) return std::nullopt;
  r.normalize();
  const Eigen::Vector2d t = a_inv * (c_t - b * r);
  const Pose2 pose{t.x(), t.y(), std::atan2(r.y(), r.x())};
  if (!Finite(pose)) return std::nullopt;
  return pose;
}

}  // namespace internal

namespace {

// Directions the ICP must not move along: the degenerate eigen-directions found at the end of a
// first run, in its scaled coordinates.
struct Frozen {
  Directions directions;  // degenerate (columns)
  Directions free;        // the orthonormal complement
  double scale_m = 1.0;
};

struct IcpRun {
  Pose2 pose;
  int iterations = 0;
  bool out_of_bounds = false;
};

// The ICP iterations from `initial` (see the header). With `frozen`, every step is a Gauss-Newton
// step within frozen->free, so the pose keeps the initial estimate along the frozen directions.
IcpRun RunIcp(const PolarCloud& r, const PolarCloud& s, const Pose2& initial,
              const IcpOptions& options, const Frozen* frozen, std::vector<Scored>& scored,
              std::vector<LineCorrespondence>& lines) {
  IcpRun run;
  run.pose = initial;
  Pose2 previous = initial;
  bool degenerate_seen = false;
  const double anneal_ratio = options.final_correspondence_m / options.initial_correspondence_m;
  const double scale_m = frozen != nullptr ? frozen->scale_m : 0.0;
  for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
    const bool annealed = iteration >= options.anneal_iterations;
    const double max_dist_m =
        annealed ? options.final_correspondence_m
                 : options.initial_correspondence_m *
                       std::pow(anneal_ratio, static_cast<double>(iteration) /
                                                  static_cast<double>(options.anneal_iterations));
    FindCorrespondences(r, s, run.pose, max_dist_m, scored);
    Trim(scored, options.trim_fraction);
    run.iterations = iteration + 1;
    if (scored.size() < options.min_correspondences) break;

    const Information info = ComputeInformation(scored, run.pose, options, scale_m);
    // Once degenerate at the final distance, stay on the restricted steps: alternating with the
    // closed form while an eigenvalue hovers at the threshold would not converge.
    if (annealed && info.degenerate_count > 0) degenerate_seen = true;
    std::optional<Pose2> next;
    if (frozen == nullptr && info.degenerate_count == 0 && !degenerate_seen) {
      lines.clear();
      for (const Scored& c : scored) lines.push_back(c.c);
      next = internal::SolvePointToLine(lines);
    }
    if (!next) {
      // Frozen or degenerate directions (or the closed form's hard case): a few restricted
      // Gauss-Newton steps on the same correspondences reach their minimum in the free ones.
      Pose2 stepped = run.pose;
      for (int k = 0; k < 3; ++k) {
        const Information local =
            k == 0 ? info : ComputeInformation(scored, stepped, options, scale_m);
        const std::optional<Pose2> step = RestrictedGaussNewtonStep(
            local, stepped, frozen != nullptr ? frozen->free : Eigendirections(local, false));
        if (!step) break;  // singular within the free directions: stay
        stepped = *step;
      }
      next = stepped;
    }
    if (!next || !Finite(*next)) break;
    const double moved_m = common::TranslationDistanceM(*next, run.pose);
    const double turned_rad = common::RotationDistanceRad(*next, run.pose);
    // A pose the iteration before last returns to: the correspondences flip between two sets.
    const bool cycle =
        iteration >= 2 &&
        common::TranslationDistanceM(*next, previous) <= options.convergence_translation_m &&
        common::RotationDistanceRad(*next, previous) <= options.convergence_yaw_rad;
    previous = run.pose;
    run.pose = *next;
    if (!WithinBounds(run.pose, initial, options)) {
      run.out_of_bounds = true;  // no need to follow it into another basin
      break;
    }
    if (annealed && (cycle || (moved_m <= options.convergence_translation_m &&
                               turned_rad <= options.convergence_yaw_rad))) {
      break;
    }
  }
  return run;
}

}  // namespace

IcpResult RefineWithBackgrounds(const BackgroundScan& r_background,
                                const BackgroundScan& s_background, const Pose2& s_from_r,
                                const IcpOptions& options) {
  IcpResult result;
  result.s_from_r = s_from_r;
  if (const auto error = Validate(options)) {
    result.reason = "invalid ICP options: " + *error;
    return result;
  }
  if (!Finite(s_from_r)) {
    result.reason = "initial pose is not finite";
    return result;
  }
  if (const auto error = CheckBackground(r_background)) {
    result.reason = "r: " + *error;
    return result;
  }
  if (const auto error = CheckBackground(s_background)) {
    result.reason = "s: " + *error;
    return result;
  }
  PolarCloud r = MakeCloud(r_background, options.max_range_m);
  PolarCloud s = MakeCloud(s_background, options.max_range_m);
  FitLines(r, options);
  FitLines(s, options);
  for (const auto& [cloud, name] : {std::pair{&r, "r"}, std::pair{&s, "s"}}) {
    if (cloud->valid_beams.size() < options.min_correspondences) {
      result.reason =
          Format("%s background has %zu points within %.1f m (need %zu)", name,
                 cloud->valid_beams.size(), options.max_range_m, options.min_correspondences);
      return result;
    }
  }

  const BackgroundConsistency before = Score(r, s, s_from_r, options);
  result.score_before = result.score_after = before.score;
  result.points = before.points;
  result.inliers_before = result.inliers_after = before.inliers;

  std::vector<Scored> scored;
  scored.reserve(r.valid_beams.size());
  std::vector<LineCorrespondence> lines;
  lines.reserve(r.valid_beams.size());
  const auto final_correspondences = [&](const Pose2& pose) {
    FindCorrespondences(r, s, pose, options.final_correspondence_m, scored);
    Trim(scored, options.trim_fraction);
    result.correspondences = scored.size();
    return scored.size() >= options.min_correspondences;
  };
  const auto too_few = [&](bool out_of_bounds) {
    result.reason =
        Format("too few common background points: %zu correspondences within %.2f m (need %zu)",
               scored.size(), options.final_correspondence_m, options.min_correspondences);
    if (out_of_bounds) result.reason += " after moving beyond the bounds";
    return result;
  };

  // The degenerate directions are those of the converged pose: while the pose is still wrong, or
  // the correspondence distance still wide, wrong pairs can hide a degeneracy (and move the pose
  // along it) or fake one. When there are any, the ICP runs again from the initial estimate with
  // those directions frozen, so that the result keeps the initial estimate along them.
  IcpRun run = RunIcp(r, s, s_from_r, options, nullptr, scored, lines);
  result.iterations = run.iterations;
  if (!final_correspondences(run.pose)) return too_few(run.out_of_bounds);
  Information info = ComputeInformation(scored, run.pose, options);
  int degenerate = info.degenerate_count;
  std::optional<Frozen> frozen;
  if (degenerate > 0 && degenerate <= options.max_degenerate_directions && !run.out_of_bounds) {
    frozen = Frozen{Eigendirections(info, true), Eigendirections(info, false), info.scale_m};
    const IcpRun second = RunIcp(r, s, s_from_r, options, &*frozen, scored, lines);
    run.pose = second.pose;
    run.out_of_bounds = second.out_of_bounds;
    result.iterations += second.iterations;
    if (!final_correspondences(run.pose)) return too_few(run.out_of_bounds);
    info = ComputeInformation(scored, run.pose, options, frozen->scale_m);
    // Where the second run ended, the backgrounds may determine even less (a weak direction at
    // the threshold in a small common part).
    degenerate = std::max(degenerate, info.degenerate_count);
  }
  result.degenerate_directions = degenerate;
  const Pose2 pose = run.pose;

  // Covariance: sigma^2 (V^T H V)^-1 within the free directions V; along the frozen ones, the
  // bound of the change (the estimate there is the initial one).
  const double n = static_cast<double>(scored.size());
  result.rms_m = std::sqrt(info.sum_e2 / n);
  const double sigma2 = std::max(info.sum_e2 / (n - 3.0), std::pow(options.residual_floor_m, 2));
  const Directions free = frozen ? frozen->free : Eigendirections(info, false);
  const Directions fixed = frozen ? frozen->directions : Eigendirections(info, true);
  Eigen::Matrix3d cov_scaled = Eigen::Matrix3d::Zero();
  if (free.cols() > 0) {
    const SmallMatrix reduced = free.transpose() * info.h * free;
    cov_scaled +=
        options.residual_correlation * sigma2 * free * reduced.inverse() * free.transpose();
  }
  cov_scaled += std::pow(options.systematic_floor_m, 2) * Eigen::Matrix3d::Identity();
  const double yaw_bound_m = common::DegToRad(options.max_yaw_change_deg) * info.scale_m;
  for (Eigen::Index k = 0; k < fixed.cols(); ++k) {
    const Eigen::Vector3d v = fixed.col(k);
    const double variance =
        (v[0] * v[0] + v[1] * v[1]) * std::pow(options.max_translation_change_m, 2) +
        v[2] * v[2] * yaw_bound_m * yaw_bound_m;
    cov_scaled += variance * v * v.transpose();
  }
  const Eigen::Vector3d unscale(1.0, 1.0, 1.0 / info.scale_m);
  result.covariance = unscale.asDiagonal() * cov_scaled * unscale.asDiagonal();

  const BackgroundConsistency after = Score(r, s, pose, options);
  result.score_after = after.score;
  result.inliers_after = after.inliers;

  const double moved_m = common::TranslationDistanceM(pose, s_from_r);
  const double turned_deg = common::RadToDeg(common::RotationDistanceRad(pose, s_from_r));
  if (run.out_of_bounds || !WithinBounds(pose, s_from_r, options)) {
    result.reason = Format(
        "moved too far from the initial estimate: %.3f m, %.2f deg (bounds %.3f m, %.2f deg)",
        moved_m, turned_deg, options.max_translation_change_m, options.max_yaw_change_deg);
    return result;
  }
  if (degenerate > options.max_degenerate_directions) {
    result.reason = Format(
        "the common background determines only %d of the 3 directions of the pose (more than %d "
        "degenerate)",
        3 - degenerate, options.max_degenerate_directions);
    return result;
  }
  if (!(after.score <= before.score - options.min_score_improvement)) {
    result.reason = Format(
        "no improvement of the background consistency: score %.4f -> %.4f (needs to drop by "
        "%.4f)",
        before.score, after.score, options.min_score_improvement);
    return result;
  }
  result.applied = true;
  result.s_from_r = pose;
  return result;
}

}  // namespace lrfnet::calib
