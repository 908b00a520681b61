#include "firmware_tracker/tracking/segmentation.h"

#include <algorithm>
#include <cmath>

namespace lrfnet::tracking {

std::optional<std::string> Validate(const SegmentationOptions& o) {
  if (!(std::isfinite(o.jump_base_m) && o.jump_base_m > 0.0)) return "jump_base_m must be > 0";
  if (!(std::isfinite(o.jump_per_m) && o.jump_per_m >= 0.0)) return "jump_per_m must be >= 0";
  if (o.min_points < 1) return "min_points must be >= 1";
  if (o.max_points < o.min_points || o.max_points > kMaxSegmentPoints) {
    return "max_points must be in [min_points, kMaxSegmentPoints]";
  }
  if (!(std::isfinite(o.min_width_m) && o.min_width_m >= 0.0)) return "min_width_m must be >= 0";
  if (!(std::isfinite(o.max_width_m) && o.max_width_m > o.min_width_m)) {
    return "max_width_m must be finite and greater than min_width_m";
  }
  return std::nullopt;
}

void SegmentScan(const ScanView& scan, std::span<const std::uint8_t> foreground,
                 const SegmentationOptions& options, SegmentList& out) {
  out.segments.clear();
  out.points_m.clear();
  out.dropped_segments = 0;
  if (CheckScan(scan) != ScanError::kNone) return;
  out.directions.Fit(scan);

  // The open segment's state in locals (its first and last point held here as well as in the
  // pool): the per-beam tests read no member and no pool entry. The same tests on the same values
  // as before, the cheap integer ones first (each test is pure, so their order changes nothing).
  const double jump_base_m = options.jump_base_m, jump_per_m = options.jump_per_m;
  const double max_width_m = options.max_width_m;
  const std::size_t max_missing_beams = options.max_missing_beams;
  const std::size_t max_points = options.max_points;
  bool open = false;
  std::size_t begin_beam = 0, last_beam = 0, first_point = 0, count = 0;
  Eigen::Vector2d first_p = Eigen::Vector2d::Zero(), last_p = Eigen::Vector2d::Zero();
  const auto close = [&] {
    open = false;
    const double width_m = (last_p - first_p).norm();
    if (count >= options.min_points && !(width_m < options.min_width_m)) {
      Segment s;
      s.begin_beam = begin_beam;
      s.end_beam = last_beam + 1;
      s.first_point = first_point;
      s.point_count = count;
      s.width_m = width_m;
      if (out.segments.push_back(s)) return;
      ++out.dropped_segments;
    }
    // Shrinking only; FixedVector::resize would also be able to grow with uninitialised values.
    while (out.points_m.size() > first_point) out.points_m.pop_back();
  };

  const std::size_t n = std::min(scan.range_m.size(), foreground.size());
  for (std::size_t i = 0; i < n; ++i) {
    const double r = scan.range_m[i];
    if (foreground[i] == 0 || !(std::isfinite(r) && r > 0.0)) continue;
    const Eigen::Vector2d p(r * out.directions.cos(i), r * out.directions.sin(i));
    if (open) {
      if (i - last_beam - 1 <= max_missing_beams && count < max_points &&
          (p - last_p).norm() <= jump_base_m + jump_per_m * r &&
          (p - first_p).norm() <= max_width_m) {
        (void)out.points_m.push_back(p);  // the pool holds one point per beam: cannot overflow
        last_p = p;
        last_beam = i;
        ++count;
        continue;
      }
      close();
    }
    open = true;
    begin_beam = i;
    last_beam = i;
    first_point = out.points_m.size();
    count = 1;
    first_p = p;
    last_p = p;
    (void)out.points_m.push_back(p);
  }
  if (open) close();
}

std::size_t SeeThroughCuts(const ScanView& scan, const SegmentList& list, const Segment& s,
                           const SegmentationOptions& options, double min_width_m,
                           std::span<std::size_t> cuts) {
  if (cuts.empty() || s.point_count < 2 * options.min_points || !(s.width_m > min_width_m)) {
    return 0;
  }
  const auto pts = list.Points(s);
  const std::size_t end_beam = std::min(s.end_beam, scan.range_m.size());
  // The segment's points in beam order: point k is beam b's where b's range along its direction
  // (SegmentScan's table of this scan) gives the very same point.
  const auto is_point = [&](std::size_t b, const Eigen::Vector2d& p) {
    const double r = scan.range_m[b];
    return r * list.directions.cos(b) == p.x() && r * list.directions.sin(b) == p.y();
  };
  std::size_t count = 0, k = 0, last_cut = 0;
  bool through = false;  // beams since point k - 1 all saw through
  bool gap = false;      // and there was at least one
  for (std::size_t b = s.begin_beam; b < end_beam && k < pts.size(); ++b) {
    if (is_point(b, pts[k])) {
      if (k > 0 && gap && through && k - last_cut >= options.min_points &&
          pts.size() - k >= options.min_points) {
        cuts[count++] = k;
        last_cut = k;
        if (count == cuts.size()) break;
      }
      ++k;
      through = true;
      gap = false;
      continue;
    }
    if (k == 0) continue;
    const double r = scan.range_m[b];
    const double near = std::max(pts[k - 1].norm(), pts[k].norm());
    const bool beyond = !(std::isfinite(r) && r > 0.0) ||
                        r > near + options.jump_base_m + options.jump_per_m * near;
    through = through && beyond;
    gap = true;
  }
  return count;
}

std::optional<std::string> Validate(const RangeStepCutOptions& o) {
  if (!(std::isfinite(o.min_width_m) && o.min_width_m >= 0.0)) return "min_width_m must be >= 0";
  if (!(std::isfinite(o.min_step_m) && o.min_step_m > 0.0)) return "min_step_m must be > 0";
  if (o.min_piece_points < 2) return "min_piece_points must be >= 2";
  if (!(std::isfinite(o.min_piece_width_m) && o.min_piece_width_m >= 0.0 &&
        std::isfinite(o.max_piece_width_m) && o.max_piece_width_m > o.min_piece_width_m)) {
    return "min_piece_width_m must be >= 0 and max_piece_width_m finite and greater";
  }
  if (!(std::isfinite(o.min_turn_m) && o.min_turn_m >= 0.0)) return "min_turn_m must be >= 0";
  if (!(std::isfinite(o.min_bulge_m) && o.min_bulge_m >= 0.0)) return "min_bulge_m must be >= 0";
  return std::nullopt;
}

DeepTails FindDeepTails(const SegmentList& list, const Segment& s, double depth_m) {
  DeepTails tails;
  const auto pts = list.Points(s);
  if (pts.size() < 2) return tails;
  // On squared ranges: one square root per segment.
  double nearest2 = pts[0].squaredNorm();
  for (std::size_t i = 1; i < pts.size(); ++i) nearest2 = std::min(nearest2, pts[i].squaredNorm());
  const double limit = std::sqrt(nearest2) + depth_m;
  const double limit2 = limit * limit;
  while (tails.lead < pts.size() && pts[tails.lead].squaredNorm() > limit2) ++tails.lead;
  while (tails.trail < pts.size() - tails.lead &&
         pts[pts.size() - 1 - tails.trail].squaredNorm() > limit2) {
    ++tails.trail;
  }
  return tails;
}

std::size_t RangeStepCuts(const SegmentList& list, const Segment& s,
                          const RangeStepCutOptions& options, std::span<std::size_t> cuts) {
  if (cuts.empty() || s.point_count < 2 * options.min_piece_points ||
      !(s.width_m > options.min_width_m)) {
    return 0;
  }
  const auto pts = list.Points(s);
  const std::size_t n = pts.size();
  // Whether points [a, b) form one body-sized piece whose end `end` (a or b - 1) lies beyond its
  // nearest point.
  // `hidden`: the piece may be a body the other hides in part, its end at the cut no end of its
  // outline (no turn asked of it).
  const auto body = [&](std::size_t a, std::size_t b, std::size_t end, bool hidden) {
    if (b - a < options.min_piece_points) return false;
    const double width = (pts[b - 1] - pts[a]).norm();
    if (width < options.min_piece_width_m || width > options.max_piece_width_m) return false;
    double nearest = pts[a].norm();
    for (std::size_t i = a + 1; i < b; ++i) nearest = std::min(nearest, pts[i].norm());
    if (!hidden && !(pts[end].norm() > nearest + options.min_turn_m)) return false;
    // Curved: a point between the ends lies nearer the sensor than their chord by min_bulge_m (a
    // box's face is straight).
    const Eigen::Vector2d chord = pts[b - 1] - pts[a];
    Eigen::Vector2d normal(-chord.y(), chord.x());
    normal.normalize();
    if (normal.dot(pts[a]) > 0.0) normal = -normal;  // towards the sensor
    double bulge = 0.0;
    for (std::size_t i = a + 1; i + 1 < b; ++i) {
      bulge = std::max(bulge, normal.dot(pts[i] - pts[a]));
    }
    return bulge > options.min_bulge_m;
  };
  std::size_t count = 0, last_cut = 0;
  for (std::size_t k = options.min_piece_points; k + options.min_piece_points <= n; ++k) {
    if (!(std::abs(pts[k].norm() - pts[k - 1].norm()) > options.min_step_m)) continue;
    // The piece after the cut reaches to the next step's seam or the segment's end.
    std::size_t next = n;
    for (std::size_t j = k + options.min_piece_points; j + options.min_piece_points <= n; ++j) {
      if (std::abs(pts[j].norm() - pts[j - 1].norm()) > options.min_step_m) {
        next = j;
        break;
      }
    }
    // RangeStepCutOptions::hidden_far_piece: the farther piece at the step may be the body the
    // nearer one hides in part.
    const bool left_far = pts[k - 1].norm() > pts[k].norm();
    const bool left_hidden = options.hidden_far_piece && left_far;
    const bool right_hidden = options.hidden_far_piece && !left_far;
    if (!body(last_cut, k, k - 1, left_hidden) ||
        !(body(k, next, k, right_hidden) || body(k, n, k, right_hidden))) {
      continue;
    }
    cuts[count++] = k;
    last_cut = k;
    if (count == cuts.size()) break;
  }
  return count;
}

}  // namespace lrfnet::tracking
