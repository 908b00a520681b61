#pragma once
// Segmentation of foreground beams into objects (Quenzel et al., section III-B: "close measurements
// on dynamic objects are clustered into segments").
//
// Jump-distance clustering over consecutive beams: a foreground point joins the open segment when
// its Euclidean distance to the segment's last point is at most jump_base_m + jump_per_m * range
// (range of the new point) and at most max_missing_beams non-foreground beams lie between them. A
// segment whose extent (first to current point) would exceed max_width_m is closed and a new one
// starts at that point. Segments with fewer than min_points points (single-beam noise with the
// default 2) or narrower than min_width_m are dropped; a segment reaching kMaxSegmentPoints is
// closed and the next point starts a new one.
//
// Points are in the sensor frame (x forward, y left, metres). Output storage is fixed: at most
// kMaxSegments segments, whose points share one pool of kMaxBeams points; segments that do not fit
// are dropped and counted. Segment() never allocates. Not thread-safe.

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>

#include "common/fixed_capacity.h"
#include "firmware_tracker/tracking/scan_view.h"

namespace lrfnet::tracking {

inline constexpr std::size_t kMaxSegments = 64;
inline constexpr std::size_t kMaxSegmentPoints = 512;

struct SegmentationOptions {
  double jump_base_m = 0.15;
  double jump_per_m = 0.03;
  std::size_t max_missing_beams = 2;
  std::size_t min_points = 2;
  std::size_t max_points = kMaxSegmentPoints;
  double min_width_m = 0.0;
  double max_width_m = 1.0;
};

std::optional<std::string> Validate(const SegmentationOptions& options);

struct Segment {
  std::size_t begin_beam = 0;   // first beam
  std::size_t end_beam = 0;     // one past the last beam
  std::size_t first_point = 0;  // into SegmentList::points
  std::size_t point_count = 0;
  double width_m = 0.0;  // first to last point
};

struct SegmentList {
  common::FixedVector<Segment, kMaxSegments> segments;
  common::FixedVector<Eigen::Vector2d, kMaxBeams> points_m;  // sensor frame
  std::uint64_t dropped_segments = 0;  // did not fit into kMaxSegments (this scan)
  BeamDirections directions;           // of the last scan's beams, reused while they stay the same

  std::span<const Eigen::Vector2d> Points(const Segment& s) const {
    return points_m.span().subspan(s.first_point, s.point_count);
  }
};

// Fills `out` (cleared first) from a scan and its per-beam foreground mask (same length as the
// scan; a shorter mask treats the missing beams as background). The scan must pass CheckScan (else
// `out` stays empty). Options must be valid (checked by the caller through Validate).
void SegmentScan(const ScanView& scan, std::span<const std::uint8_t> foreground,
                 const SegmentationOptions& options, SegmentList& out);

// Where segment `s` of `list` (filled by SegmentScan from `scan`) holds objects side by side: the
// points k (1 <= k < point_count, in order) before which lie one or more beams that saw through the
// segment, each either without a return or with one farther than both points around it by more
// than the jump limit at their range (jump_base_m + jump_per_m * range). A convex body hides what
// lies behind it on every beam across it, so such a beam passes between two objects that the
// segmentation joined across up to max_missing_beams beams (or, without a return, a dropout on a
// dark body: min_width_m keeps those whole). Only for segments wider (first to last
// point) than min_width_m; a cut is kept where each piece it leaves has at least min_points points.
// Writes at most cuts.size() cuts in increasing order and returns their count.
std::size_t SeeThroughCuts(const ScanView& scan, const SegmentList& list, const Segment& s,
                           const SegmentationOptions& options, double min_width_m,
                           std::span<std::size_t> cuts);

// Of segment `s` of `list`: how many of its first points (lead) and of its last points (trail), in
// runs from either end, lie farther from the sensor than the segment's nearest point by more than
// depth_m. The nearest point is in neither run.
struct DeepTails {
  std::size_t lead = 0;
  std::size_t trail = 0;
};
DeepTails FindDeepTails(const SegmentList& list, const Segment& s, double depth_m);

// Where segment `s` of `list` holds two convex bodies that touch in the view with no beam between
// them: the points k (in order) where the range steps by more than options.min_step_m from point
// k - 1 while the outline turns there from receding to approaching. A convex body's range along
// its outline falls to its nearest point and rises again (one minimum), so a point where the range
// jumps with both neighbouring points farther than the nearest of their own side is the seam of
// two bodies. Each piece is body-sized: at least options.min_piece_points points, first to last
// point between min_piece_width_m and max_piece_width_m, and its end at the cut lies farther than
// its nearest point by more than min_turn_m. Only for segments wider than min_width_m. Writes at
// most cuts.size() cuts in increasing order and returns their count.
// hidden_far_piece: the piece on the farther side of the step need not turn there: where the
// nearer body hides part of the farther one, the farther piece's end at the step is where the
// nearer one's silhouette cuts its outline, not an end of that outline (a pair seen one partly
// behind the other). false: both pieces turn at the step.
struct RangeStepCutOptions {
  double min_width_m = 0.8;
  double min_step_m = 0.1;
  std::size_t min_piece_points = 3;
  double min_piece_width_m = 0.2;
  double max_piece_width_m = 0.7;
  double min_turn_m = 0.05;
  double min_bulge_m = 0.03;
  bool hidden_far_piece = true;
};
std::optional<std::string> Validate(const RangeStepCutOptions& options);
std::size_t RangeStepCuts(const SegmentList& list, const Segment& s,
                          const RangeStepCutOptions& options, std::span<std::size_t> cuts);

}  // namespace lrfnet::tracking
