#include "firmware_tracker/tracking/pipeline.h"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "common/eigen_instances.h"
#include "common/geometry.h"

namespace lrfnet::tracking {
namespace {

bool Positive(double v) { return std::isfinite(v) && v > 0.0; }

// Updates of the flatness evidence before a track may be judged not person-like.
constexpr std::uint32_t kMinFlatnessUpdates = 5;
// The running mean of the flatness becomes an exponential one after this many updates.
constexpr double kFlatnessMemory = 20.0;
// Scans over which a track's outline departure is averaged (ShapeOptions::outline_departure_gain).
constexpr double kDepartureMemory = 10.0;
// Fits with fewer points carry no flatness evidence (two points always lie on a line).
constexpr std::size_t kMinFlatnessPoints = 4;
// RMS distance to their principal line of points spread evenly over an arc of sagitta s: the
// parabola v = k u^2 on [-h, h] less its mean, sqrt(1/5 - 1/9) k h^2 = 0.298 s.
constexpr double kArcLineRmsShare = 0.298;
// ShapeOptions::box_drop_occluders: a box's point nearer than the box along its beam by more than
// this many sigmas of the range noise and the outline's model error lies in front of it.
constexpr double kOccluderSigmas = 3.0;
// ShapeOptions::box_size_from_faces_seen: a face shows its length where at least this many beams
// fall across it (fewer cannot tell its length from where its corners lie between beams).
constexpr double kFaceMinBeams = 3.0;
// ShapeOptions::split_see_through: at most this many cuts per segment (four people side by side).
constexpr std::size_t kMaxSeeThroughCuts = 3;

// x^p for x >= 0: the common exponents by algebra (2: x x; 2.5: x x sqrt(x)), others by pow.
double PowerOf(double x, double p) {
  if (p == 2.0) return x * x;
  if (p == 2.5) return x * x * std::sqrt(x);
  return std::pow(x, p);
}

}  // namespace

namespace internal {

// What the points of a person's back (the prior's upper body seen from behind, its flattest view)
// spread over extent_m show of their principal line: kArcLineRmsShare times the sagitta b (1 - v)
// of the superellipse |u/a|^p + |v/b|^p = 1 over |u| <= extent_m / 2.
double PersonBackLineRms(const ShapeOptions& o, double extent_m) {
  const double u = std::min(1.0, 0.5 * extent_m / o.person_major_m);
  const double v = std::pow(1.0 - std::pow(u, o.person_exponent), 1.0 / o.person_exponent);
  return kArcLineRmsShare * o.person_minor_m * (1.0 - v);
}

// PersonBackLineRms(o, extent_m) > threshold_m without the p-th root: with s = kArcLineRmsShare b,
// s (1 - v) > t <=> v < w = 1 - t / s, and for v, w >= 0 (both sides to the power p, monotonic)
// <=> 1 - u^p < w^p; never where w <= 0 (v >= 0). With p = 2.5 two square roots instead of two
// pow calls.
bool PersonBackLineRmsAbove(const ShapeOptions& o, double extent_m, double threshold_m) {
  const double u = std::min(1.0, 0.5 * extent_m / o.person_major_m);
  const double w = 1.0 - threshold_m / (kArcLineRmsShare * o.person_minor_m);
  if (!(w > 0.0)) return false;
  return 1.0 - PowerOf(u, o.person_exponent) < PowerOf(w, o.person_exponent);
}

double SingleLegSideWeight(double hip_m, double offset_m, double s2_m2) {
  if (!(s2_m2 > 0.0)) return 1.0;
  return std::tanh(hip_m * std::abs(offset_m) / s2_m2);
}

double SingleLegOtherSideVar(double hip_m, double weight) {
  return 2.0 * hip_m * hip_m * (1.0 - std::clamp(weight, 0.0, 1.0));
}

double OutlineDepartureVar(const ShapeOptions& o, double rms_m, double range_m) {
  const double noise = o.fit.point_sigma_m + o.fit.point_sigma_per_m * range_m;
  const double excess = rms_m * rms_m - noise * noise;
  if (!(excess > 0.0)) return 0.0;
  return o.outline_departure_gain * o.outline_departure_gain * excess;
}

StanceCentre StanceWeightedCentre(const ShapeOptions& o, const Eigen::Vector2d& forward,
                                  const std::array<Eigen::Vector2d, 2>& legs_m,
                                  const std::array<double, 2>& legs_var_m2,
                                  const std::array<Eigen::Vector2d, 2>& last_m,
                                  const std::array<double, 2>& last_var_m2, double dt_s,
                                  double step_m) {
  StanceCentre out;
  out.centre_m = 0.5 * (legs_m[0] + legs_m[1]);
  if (!(dt_s > 0.0 && dt_s <= o.stance_memory_s) || o.stance_leg_weight == 0.5) return out;
  // A leg keeps its side of the walk: matched by the order across it.
  const Eigen::Vector2d left(-forward.y(), forward.x());
  const bool now_0_left = legs_m[0].dot(left) >= legs_m[1].dot(left);
  const bool last_0_left = last_m[0].dot(left) >= last_m[1].dot(left);
  const std::size_t j0 = now_0_left == last_0_left ? 0 : 1;  // the last leg matched to legs_m[0]
  const double d0 = (legs_m[0] - last_m[j0]).dot(forward);
  const double d1 = (legs_m[1] - last_m[1 - j0]).dot(forward);
  const double var = legs_var_m2[0] + legs_var_m2[1] + last_var_m2[0] + last_var_m2[1];
  const double diff = d0 - d1;
  // Two hypotheses, the displacements' difference +-step_m (the standing knee moves at about half
  // the body's speed, the swinging one at one and a half times it or more), with variance var:
  // the slower leg stands with probability q, 1 / (1 + exp(-2 step |diff| / var)); the weight
  // moves from 1/2 towards stance_leg_weight by 2 q - 1 = tanh(step |diff| / var).
  const double certainty =
      var > 0.0 ? std::tanh(std::max(0.0, step_m) * std::abs(diff) / var) : 1.0;
  if (!(certainty > 0.0)) return out;
  out.standing = d0 < d1 ? 0 : 1;
  out.weight = 0.5 + certainty * (o.stance_leg_weight - 0.5);
  // The weight on the standing leg, the rest on the swinging one: along the walk the hip's
  // offsets from the two knees cancel; across it the body leans over the standing foot.
  out.m[out.standing] = out.weight * Eigen::Matrix2d::Identity();
  out.m[1 - out.standing] = (1.0 - out.weight) * Eigen::Matrix2d::Identity();
  out.centre_m = out.weight * legs_m[out.standing] + (1.0 - out.weight) * legs_m[1 - out.standing];
  return out;
}

Eigen::Vector2d LoneLegCentreFromStanding(const ShapeOptions& o, const Eigen::Vector2d& forward,
                                          const Eigen::Vector2d& velocity_mps,
                                          const Eigen::Vector2d& leg_m, double leg_var_m2,
                                          const Eigen::Vector2d& standing_m, double standing_var_m2,
                                          double dt_s, double* along_var_m2) {
  // The standing knee, about halfway between the planted foot and the hip, moves at about half
  // the body's speed: carried forward by half the displacement since it was seen, known to half.
  const Eigen::Vector2d displacement = velocity_mps * std::max(0.0, dt_s);
  const Eigen::Vector2d standing_now = standing_m + 0.5 * displacement;
  const double carried = 0.25 * displacement.norm();
  const double w = o.stance_leg_weight;
  // As for two seen legs (stance_leg_weight): w on the standing leg, 1 - w on the swinging one.
  const double along = (w * standing_now + (1.0 - w) * leg_m).dot(forward);
  if (along_var_m2 != nullptr) {
    *along_var_m2 = w * w * (standing_var_m2 + carried * carried) +
                    (1.0 - w) * (1.0 - w) * leg_var_m2 + o.gait_sigma_m * o.gait_sigma_m;
  }
  return leg_m + (along - leg_m.dot(forward)) * forward;
}

double DeepLegExcessDepth(const ShapeOptions& o, std::span<const Eigen::Vector2d> pts) {
  if (pts.size() < 2) return 0.0;
  double nearest = std::numeric_limits<double>::infinity(), farthest = 0.0;
  for (const Eigen::Vector2d& p : pts) {
    const double range = p.norm();
    nearest = std::min(nearest, range);
    farthest = std::max(farthest, range);
  }
  const double noise = o.fit.point_sigma_m + o.fit.point_sigma_per_m * nearest;
  const double deepest = o.leg_radius_m + 2.0 * o.leg_radius_sigma_m + 3.0 * noise;
  return std::max(0.0, farthest - nearest - deepest);
}

bool LegsStill(const ShapeOptions& o, const std::array<Eigen::Vector2d, 2>& legs_m,
               const std::array<double, 2>& legs_var_m2,
               const std::array<Eigen::Vector2d, 2>& last_m,
               const std::array<double, 2>& last_var_m2, double dt_s) {
  if (!(dt_s > 0.0 && dt_s <= o.stance_memory_s)) return false;
  const auto moved = [&](std::size_t k, std::size_t j) {
    return (legs_m[k] - last_m[j]).squaredNorm();
  };
  const bool swapped = moved(0, 1) + moved(1, 0) < moved(0, 0) + moved(1, 1);
  for (std::size_t k = 0; k < 2; ++k) {
    const std::size_t j = swapped ? 1 - k : k;
    if (!(moved(k, j) <= kStillLegsChi2 * (legs_var_m2[k] + last_var_m2[j]))) return false;
  }
  return true;
}

double TouchingLegsAlongRayVar(const ShapeOptions& o, const ObservationPart& first,
                               const ObservationPart& second, bool deep_pair) {
  if (!o.touching_legs_along_ray || deep_pair || second.begin_beam > first.end_beam) return 0.0;
  // The farther leg's centre uniform within +-2 leg_radius_m along the ray (4 r^2 / 3), the
  // midpoint's a quarter of that.
  return o.leg_radius_m * o.leg_radius_m / 3.0;
}

double OccludedGapAlongRayVar(const ShapeOptions& o, const ObservationPart& a,
                              const ObservationPart& b) {
  if (!(o.occluded_gap_depth_m > 0.0)) return 0.0;
  const ObservationPart& first = a.begin_beam <= b.begin_beam ? a : b;
  const ObservationPart& second = a.begin_beam <= b.begin_beam ? b : a;
  if (second.begin_beam <= first.end_beam) return 0.0;  // touching: no beam between them
  if (first.silhouette.last_valid || second.silhouette.first_valid) return 0.0;
  // The centre uniform over [0, D] behind the midpoint: E[x^2] = D^2 / 3.
  return o.occluded_gap_depth_m * o.occluded_gap_depth_m / 3.0;
}

std::size_t BoxUnoccludedPoints(const ShapeOptions& o, const Eigen::Vector2d& centre_m,
                                const Eigen::Vector2d& size_m, double yaw_rad,
                                std::span<const Eigen::Vector2d> points,
                                std::span<Eigen::Vector2d> kept, Silhouette* silhouette,
                                double extra_margin_m) {
  const double c = std::cos(yaw_rad), s = std::sin(yaw_rad);
  Eigen::Matrix2d to_box;
  to_box << c, s, -s, c;                                // R(yaw)^T
  const Eigen::Vector2d origin = to_box * (-centre_m);  // the sensor in the box's frame
  const std::size_t n = std::min(points.size(), kMaxSegmentPoints);
  // Entries 0 .. n - 1 written before they are read (the whole arrays not cleared: 4.5 KiB a
  // call).
  std::array<bool, kMaxSegmentPoints> in_front;
  // A point's margin, taken only where a test reads it (a root and a division; most points lie
  // on the box and never need it).
  const auto margin_of = [&](std::size_t i) {
    const double noise = o.fit.point_sigma_m + o.fit.point_sigma_per_m * points[i].norm();
    return kOccluderSigmas * common::Hypot(noise, o.fit.model_sigma_m);
  };
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d& p = points[i];
    const double range = p.norm();
    const double noise = o.fit.point_sigma_m + o.fit.point_sigma_per_m * range;
    in_front[i] = false;
    if (!(range > 0.0)) continue;
    // Where the point's beam enters the box (slab test in the box's frame): a beam returns the
    // first surface it meets, so a return nearer than that by more than the range noise is
    // something standing in front of the box.
    const Eigen::Vector2d dir = to_box * (p / range);
    double enter = 0.0, leave = std::numeric_limits<double>::infinity();
    for (int k = 0; k < 2; ++k) {
      if (std::abs(dir(k)) < 1e-12) {
        if (std::abs(origin(k)) > size_m(k)) leave = -1.0;
        continue;
      }
      const double t0 = (-size_m(k) - origin(k)) / dir(k);
      const double t1 = (size_m(k) - origin(k)) / dir(k);
      enter = std::max(enter, std::min(t0, t1));
      leave = std::min(leave, std::max(t0, t1));
    }
    // hypot(a, b) >= max(a, b) (glibc's hypot is faithfully rounded and max(a, b) a double), so a
    // point not nearer than the smaller margin allows is not in front: the hypot only for the rest.
    const double least_margin = kOccluderSigmas * std::max(noise, o.fit.model_sigma_m);
    in_front[i] = enter <= leave && range < enter - least_margin - extra_margin_m &&
                  range < enter - kOccluderSigmas * common::Hypot(noise, o.fit.model_sigma_m) -
                              extra_margin_m;
  }
  // Something in front of the box is a surface of its own: where a run of such points meets the
  // box's points, the range steps by more than the noise. A run that does not (a face turned
  // from the box's expected one) is the box's after all.
  for (std::size_t i = 0; i < n;) {
    if (!in_front[i]) {
      ++i;
      continue;
    }
    std::size_t end = i;
    while (end < n && in_front[end]) ++end;
    const bool stepped_before = i > 0 && points[i - 1].norm() - points[i].norm() > margin_of(i - 1);
    const bool stepped_after =
        end < n && points[end].norm() - points[end - 1].norm() > margin_of(end);
    if (!stepped_before && !stepped_after) {
      for (std::size_t k = i; k < end; ++k) in_front[k] = false;
    }
    i = end;
  }
  std::size_t count = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!in_front[i] && count < kept.size()) kept[count++] = points[i];
  }
  // The box's outline goes on behind an occluder at the segment's end: that end is not its
  // silhouette.
  if (n > 0 && in_front[0]) silhouette->first_valid = false;
  if (n > 0 && in_front[n - 1]) silhouette->last_valid = false;
  return count;
}

double PartialViewSizeFloor(const ShapeOptions& o, bool body, int edges, double floor_m) {
  return body && edges < 2 ? std::max(floor_m, o.partial_view_size_sigma_m) : floor_m;
}

double NeighbourVar(const ShapeOptions& o, double distance_m) {
  if (!(distance_m < o.neighbour_distance_m)) return 0.0;
  return o.neighbour_sigma_m * o.neighbour_sigma_m *
         (1.0 - std::max(0.0, distance_m) / o.neighbour_distance_m);
}

SegmentExtent SegmentExtents(std::span<const Eigen::Vector2d> points,
                             const Eigen::Vector2d& centre_m) {
  SegmentExtent out;
  const double range_m = centre_m.norm();
  if (points.size() < 2 || !(range_m > 0.0)) return out;
  out.along_dir = centre_m / range_m;
  const Eigen::Vector2d half = HalfExtentsAlong(points, out.along_dir);
  out.along_m = 2.0 * half.x();
  out.across_m = 2.0 * half.y();
  return out;
}

Eigen::Matrix2d SegmentExcessCov(const SegmentExtent& extent, double reach_m, double noise_m) {
  // A body shows at most its width (twice its reach) across the ray and its near half (its
  // reach) along it; the outermost points' noise (two sigmas at each end) widens either.
  const double margin_m = 4.0 * noise_m;
  const double across_m = std::max(0.0, extent.across_m - 2.0 * reach_m - margin_m);
  const double along_m = std::max(0.0, extent.along_m - reach_m - margin_m);
  const Eigen::Vector2d& u = extent.along_dir;
  const Eigen::Vector2d w(-u.y(), u.x());
  return (along_m * along_m / 12.0) * u * u.transpose() +
         (across_m * across_m / 12.0) * w * w.transpose();
}

namespace {

// The principal line of points: their mean, the line's unit direction and the RMS distance of the
// points to it (the smaller eigenvalue of their scatter, closed form for a symmetric 2x2): the
// line of closest fit, orthogonal distances (Pearson 1901, "On lines and planes of closest fit to
// systems of points in space", Phil. Mag. 2(11)).
struct PrincipalLine {
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  Eigen::Vector2d dir = Eigen::Vector2d::UnitX();
  double rms_m = 0.0;
};
// The line from the points' mean and their scatter (second moment about the mean, per point).
PrincipalLine LineFromScatter(const Eigen::Vector2d& mean, const Eigen::Matrix2d& scatter) {
  PrincipalLine line;
  line.mean = mean;
  const double d = 0.5 * (scatter(0, 0) - scatter(1, 1));
  const double r = std::sqrt(d * d + scatter(0, 1) * scatter(0, 1));
  line.rms_m = std::sqrt(std::max(0.0, 0.5 * scatter.trace() - r));
  const double angle = 0.5 * std::atan2(2.0 * scatter(0, 1), scatter(0, 0) - scatter(1, 1));
  line.dir = Eigen::Vector2d(std::cos(angle), std::sin(angle));
  return line;
}
PrincipalLine FitPrincipalLine(std::span<const Eigen::Vector2d> points) {
  if (points.empty()) return PrincipalLine{};
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const Eigen::Vector2d& p : points) mean += p;
  mean /= static_cast<double>(points.size());
  Eigen::Matrix2d scatter = Eigen::Matrix2d::Zero();
  for (const Eigen::Vector2d& p : points) scatter += (p - mean) * (p - mean).transpose();
  return LineFromScatter(mean, scatter / static_cast<double>(points.size()));
}

// Where a box's centre lies about a point: a mean offset and a variance (BoxViewCov adds the
// unseen depth and the unseen ends' shifts to it, independent of one another).
struct CentreSpread {
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  Eigen::Matrix2d var = Eigen::Matrix2d::Zero();
  // The second moment about the point.
  Eigen::Matrix2d SecondMoment() const { return mean * mean.transpose() + var; }
};

// A face whose far end was not seen (an occluder's edge, the field of view's end) goes on by e
// beyond it, uniform over [0, e_max], e_max = 2 max_half_m - seen_m; the box's centre moves by
// e / 2 towards that end (unit `toward`): mean e_max / 4, variance e_max^2 / 48 along it (second
// moment e_max^2 / 12).
void AddUnseenEnd(double max_half_m, double seen_m, const Eigen::Vector2d& toward,
                  CentreSpread* spread) {
  const double e_max = std::max(0.0, 2.0 * max_half_m - seen_m);
  spread->mean += 0.25 * e_max * toward;
  spread->var += (e_max * e_max / 48.0) * toward * toward.transpose();
}

// Whether a face from `from_m` to its end `end_m` ends there (internal::OutlineEnd): a silhouette
// whose next beam returned nothing, or from a point off the face's line by more than two range
// sigmas (a point on it: the face goes on, cut from the segment by the width limit or, seen at a
// grazing angle, by the segmentation's jump).
bool FaceEndSeen(const internal::OutlineEnd& end, const Eigen::Vector2d& from_m,
                 const Eigen::Vector2d& end_m, double noise_m) {
  if (!end.silhouette) return false;
  if (!end.beyond_valid) return end.beyond_returned_none;
  const Eigen::Vector2d dir = (end_m - from_m).normalized();
  const Eigen::Vector2d d = end.beyond_m - end_m;
  return std::abs(d.x() * dir.y() - d.y() * dir.x()) > 2.0 * noise_m || d.dot(dir) < 0.0;
}

// BoxViewCov: the points a side beyond a corner needs besides the corner to count as a face.
constexpr std::size_t kCornerSidePoints = 3;

// BoxViewCov's one face from first_m to last_m (points within two range sigmas of their principal
// line `line`): the centre half the box's depth h behind the face's middle, h uniform over the
// prior's half-lengths.
Eigen::Matrix2d OneFaceCov(const ShapeOptions& o, const Eigen::Vector2d& first_m,
                           const Eigen::Vector2d& last_m, const PrincipalLine& line,
                           const Eigen::Vector2d& centre_m, double noise_m,
                           const OutlineEnd& first_end, const OutlineEnd& last_end) {
  const double h_min = o.box_prior_min_half_m;
  const double h_max = o.box_prior_max_half_m;
  Eigen::Vector2d normal(-line.dir.y(), line.dir.x());
  if (normal.dot(line.mean) < 0.0) normal = -normal;
  const double ta = (first_m - line.mean).dot(line.dir);
  const double tb = (last_m - line.mean).dot(line.dir);
  const Eigen::Vector2d end_a = line.mean + ta * line.dir;
  const Eigen::Vector2d end_b = line.mean + tb * line.dir;
  const Eigen::Vector2d middle = 0.5 * (end_a + end_b);
  const double seen_m = std::abs(tb - ta);
  // The centre behind the middle by h, uniform over [h_min, h_max] (mean and variance along the
  // normal), moved along the face towards each end not seen to end.
  CentreSpread spread;
  spread.mean = middle - centre_m + 0.5 * (h_min + h_max) * normal;
  spread.var = ((h_max - h_min) * (h_max - h_min) / 12.0) * normal * normal.transpose();
  const Eigen::Vector2d towards_b = tb >= ta ? line.dir : Eigen::Vector2d(-line.dir);
  if (!FaceEndSeen(first_end, end_b, end_a, noise_m)) {
    AddUnseenEnd(h_max, seen_m, -towards_b, &spread);
  }
  if (!FaceEndSeen(last_end, end_a, end_b, noise_m)) {
    AddUnseenEnd(h_max, seen_m, towards_b, &spread);
  }
  return spread.SecondMoment();
}

// BoxViewCov's one face with something in front of part of it (a pusher's legs, in the same
// segment): the points nearer the sensor than the line by more than kOccluderSigmas range sigmas
// left out and the line refitted, a few rounds from the line of all points `line`; a face where
// at least half the points, kMinFlatnessPoints or more over at least flat_min_extent_m, lie within
// two range sigmas of their line. An end whose outer point was left out is not seen (the face may
// go on behind what stands in front of it).
Eigen::Matrix2d OccludedFaceCov(const ShapeOptions& o, std::span<const Eigen::Vector2d> points,
                                const PrincipalLine& line, const Eigen::Vector2d& centre_m,
                                double noise_m, const OutlineEnd& first_end,
                                const OutlineEnd& last_end, int* faces, double* longest_m) {
  constexpr int kRounds = 3;
  const double cut_m = kOccluderSigmas * noise_m;
  PrincipalLine face = line;
  std::size_t kept = points.size(), first = 0, last = points.size() - 1;
  for (int round = 0; round < kRounds; ++round) {
    Eigen::Vector2d normal(-face.dir.y(), face.dir.x());
    if (normal.dot(face.mean) < 0.0) normal = -normal;
    Eigen::Vector2d sum = Eigen::Vector2d::Zero();
    std::size_t count = 0;
    for (const Eigen::Vector2d& p : points) {
      if ((p - face.mean).dot(normal) < -cut_m) continue;
      sum += p;
      ++count;
    }
    if (count < kMinFlatnessPoints || 2 * count < points.size()) return Eigen::Matrix2d::Zero();
    const Eigen::Vector2d mean = sum / static_cast<double>(count);
    Eigen::Matrix2d scatter = Eigen::Matrix2d::Zero();
    first = points.size();
    for (std::size_t i = 0; i < points.size(); ++i) {
      if ((points[i] - face.mean).dot(normal) < -cut_m) continue;
      scatter += (points[i] - mean) * (points[i] - mean).transpose();
      if (first == points.size()) first = i;
      last = i;
    }
    face = LineFromScatter(mean, scatter / static_cast<double>(count));
    const bool same = count == kept;
    kept = count;
    if (same && round > 0) break;
  }
  if (kept == points.size() || !(face.rms_m <= 2.0 * noise_m) ||
      !((points[last] - points[first]).norm() >= o.flat_min_extent_m)) {
    return Eigen::Matrix2d::Zero();
  }
  const OutlineEnd unseen;
  *faces = 1;
  *longest_m = (points[last] - points[first]).norm();
  return OneFaceCov(o, points[first], points[last], face, centre_m, noise_m,
                    first == 0 ? first_end : unseen, last + 1 == points.size() ? last_end : unseen);
}

}  // namespace

Eigen::Matrix2d BoxViewCov(const ShapeOptions& o, std::span<const Eigen::Vector2d> points,
                           const Eigen::Vector2d& centre_m, double noise_m,
                           const OutlineEnd& first_end, const OutlineEnd& last_end, int* faces,
                           double* longest_m) {
  *faces = 0;
  *longest_m = 0.0;
  const std::size_t n = points.size();
  if (n < kMinFlatnessPoints) return Eigen::Matrix2d::Zero();
  const Eigen::Vector2d& a = points.front();
  const Eigen::Vector2d& b = points.back();
  if (!((b - a).norm() >= o.flat_min_extent_m)) return Eigen::Matrix2d::Zero();
  const double straight_m = 2.0 * noise_m;
  const PrincipalLine line = FitPrincipalLine(points);
  if (line.rms_m <= straight_m) {
    *faces = 1;
    *longest_m = (b - a).norm();
    return OneFaceCov(o, a, b, line, centre_m, noise_m, first_end, last_end);
  }
  // Two faces (the L-shape of a rectangle's corner, as in Zhang et al. 2017, "Efficient L-shape
  // fitting for vehicle detection using laser scanners", IEEE IV): split at the point farthest
  // from the chord (Douglas and Peucker 1973, "Algorithms for the reduction of the number of
  // points required to represent a digitized line or its caricature", Cartographica 10(2)); each
  // side straight, the corner between them nearer the sensor than the chord's middle (a box seen
  // from outside) and the sides far from parallel (a rectangle's at right angles).
  const Eigen::Vector2d chord = (b - a).normalized();
  std::size_t k = 0;
  double farthest_m = -1.0;
  for (std::size_t i = 1; i + 1 < n; ++i) {
    const Eigen::Vector2d d = points[i] - a;
    const double dist_m = std::abs(d.x() * chord.y() - d.y() * chord.x());
    if (dist_m > farthest_m) {
      farthest_m = dist_m;
      k = i;
    }
  }
  const Eigen::Vector2d& corner = points[k];
  const Eigen::Vector2d middle = 0.5 * (a + b);
  if (k == 0 || !((corner - middle).dot(middle) < 0.0)) {
    return OccludedFaceCov(o, points, line, centre_m, noise_m, first_end, last_end, faces,
                           longest_m);
  }
  // A side of fewer than kCornerSidePoints points of its own beyond the corner (seen at a grazing
  // angle) shows where the other face begins, not how long it is: one face, the corner its end.
  const std::span<const Eigen::Vector2d> side_a = points.subspan(0, k + 1);
  const std::span<const Eigen::Vector2d> side_b = points.subspan(k);
  OutlineEnd at_corner;
  at_corner.silhouette = true;
  at_corner.beyond_returned_none = true;
  if (side_b.size() < kCornerSidePoints + 1 || side_a.size() < kCornerSidePoints + 1) {
    const bool keep_a = side_a.size() >= side_b.size();
    const std::span<const Eigen::Vector2d> face = keep_a ? side_a : side_b;
    const PrincipalLine face_line = FitPrincipalLine(face);
    if (face.size() < kMinFlatnessPoints || !(face_line.rms_m <= straight_m)) {
      return OccludedFaceCov(o, points, line, centre_m, noise_m, first_end, last_end, faces,
                             longest_m);
    }
    *faces = 1;
    *longest_m = (face.back() - face.front()).norm();
    return keep_a ? OneFaceCov(o, face.front(), face.back(), face_line, centre_m, noise_m,
                               first_end, at_corner)
                  : OneFaceCov(o, face.front(), face.back(), face_line, centre_m, noise_m,
                               at_corner, last_end);
  }
  const PrincipalLine first = FitPrincipalLine(side_a);
  const PrincipalLine second = FitPrincipalLine(side_b);
  if (!(first.rms_m <= straight_m && second.rms_m <= straight_m) ||
      !(std::abs(first.dir.dot(second.dir)) <= 0.5)) {
    return OccludedFaceCov(o, points, line, centre_m, noise_m, first_end, last_end, faces,
                           longest_m);
  }
  // The centre in the middle of the diagonal between the outer ends, moved along each side not
  // seen to end.
  const double h_max = o.box_prior_max_half_m;
  CentreSpread spread;
  spread.mean = middle - centre_m;
  if (!FaceEndSeen(first_end, corner, a, noise_m)) {
    AddUnseenEnd(h_max, (a - corner).norm(), (a - corner).normalized(), &spread);
  }
  if (!FaceEndSeen(last_end, corner, b, noise_m)) {
    AddUnseenEnd(h_max, (b - corner).norm(), (b - corner).normalized(), &spread);
  }
  *faces = 2;
  *longest_m = std::max((a - corner).norm(), (b - corner).norm());
  return spread.SecondMoment();
}

Eigen::Matrix2d SegmentExcessCov(std::span<const Eigen::Vector2d> points,
                                 const Eigen::Vector2d& centre_m, double reach_m, double noise_m) {
  return SegmentExcessCov(SegmentExtents(points, centre_m), reach_m, noise_m);
}

double SuperellipseReachFactor(double exponent) {
  return std::pow(2.0, 0.5 - 1.0 / std::max(exponent, 2.0));
}

double SuperellipseReach(const Eigen::Vector2d& size_m, double exponent) {
  return std::max(size_m.x(), size_m.y()) * SuperellipseReachFactor(exponent);
}

std::size_t PersonReachablePoints(const ShapeOptions& o, const Eigen::Vector2d& centre_m,
                                  const Eigen::Matrix2d& centre_cov_m2, double reach_m,
                                  std::span<const Eigen::Vector2d> points, double step_rad,
                                  std::span<Eigen::Vector2d> kept, Silhouette* silhouette) {
  const std::size_t n = std::min(points.size(), kMaxSegmentPoints);
  const auto noise_of = [&](const Eigen::Vector2d& p) {
    return o.fit.point_sigma_m + o.fit.point_sigma_per_m * p.norm();
  };
  // Beyond reach: farther from the predicted centre than any point of the body can be, by more
  // than what the range noise, the outline's departure and the prediction leave open.
  const auto beyond = [&](const Eigen::Vector2d& p) {
    const Eigen::Vector2d d = p - centre_m;
    const double dist = d.norm();
    if (!(dist > reach_m)) return false;
    const Eigen::Vector2d u = d / dist;
    const double noise = noise_of(p);
    const double var = noise * noise + o.fit.model_sigma_m * o.fit.model_sigma_m +
                       std::max(0.0, u.dot(centre_cov_m2 * u));
    return dist - reach_m > kOccluderSigmas * std::sqrt(var);
  };
  // A surface of its own: the range steps where the run meets the person's points.
  const auto stepped = [&](const Eigen::Vector2d& inner, const Eigen::Vector2d& outer) {
    return std::abs(outer.norm() - inner.norm()) >
           kOccluderSigmas * common::Hypot(noise_of(inner), noise_of(outer));
  };
  std::size_t begin = 0, end = n;
  while (begin < n && beyond(points[begin])) ++begin;
  while (end > begin && beyond(points[end - 1])) --end;
  if (begin > 0 && (begin >= n || !stepped(points[begin], points[begin - 1]))) begin = 0;
  if (end < n && (end == 0 || !stepped(points[end - 1], points[end]))) end = n;
  if (end < begin + 2 || (begin == 0 && end == n)) {
    // Nothing left out: kept is read only where the count falls short of points.size().
    if (n < points.size()) {
      for (std::size_t i = 0; i < n; ++i) kept[i] = points[i];
    }
    return n;
  }
  for (std::size_t i = begin; i < end; ++i) kept[i - begin] = points[i];
  // The run nearer than the person's end point hides the outline beyond it; behind it, the
  // outline ended between the two beams.
  const auto nearest = [&](std::size_t from, std::size_t to) {
    double r = std::numeric_limits<double>::infinity();
    for (std::size_t i = from; i < to; ++i) r = std::min(r, points[i].norm());
    return r;
  };
  const auto edge_rad = [&](const Eigen::Vector2d& p, double outwards) {
    return std::atan2(p.y(), p.x()) + outwards * 0.5 * step_rad;
  };
  if (begin > 0) {
    silhouette->first_valid = nearest(0, begin) > points[begin].norm();
    silhouette->first_edge_rad = edge_rad(points[begin], -1.0);
    silhouette->first_edge_unit_known = false;
  }
  if (end < n) {
    silhouette->last_valid = nearest(end, n) > points[end - 1].norm();
    silhouette->last_edge_rad = edge_rad(points[end - 1], 1.0);
    silhouette->last_edge_unit_known = false;
  }
  return end - begin;
}

std::array<bool, 2> BoxFacesShown(const Eigen::Vector2d& centre_m, const Eigen::Vector2d& size_m,
                                  double yaw_rad, double step_rad) {
  const double range = centre_m.norm();
  if (!(range > 0.0) || !(step_rad > 0.0)) return {true, true};
  const Eigen::Vector2d e1(std::cos(yaw_rad), std::sin(yaw_rad)), e2(-e1.y(), e1.x());
  const Eigen::Vector2d u = centre_m / range, w(-u.y(), u.x());
  const Eigen::Vector2d sensor(-centre_m.dot(e1), -centre_m.dot(e2));  // in the box's frame
  const double beam_m = range * step_rad;
  // Semi-axis a is the half-length of the sides (normal e2), b of the ends (normal e1): a face
  // shows it where it faces the sensor and kFaceMinBeams beams fall across it.
  const bool a_shown = std::abs(sensor.y()) > size_m.y() &&
                       2.0 * size_m.x() * std::abs(w.dot(e1)) >= kFaceMinBeams * beam_m;
  const bool b_shown = std::abs(sensor.x()) > size_m.x() &&
                       2.0 * size_m.y() * std::abs(w.dot(e2)) >= kFaceMinBeams * beam_m;
  return {a_shown, b_shown};
}

Eigen::Matrix2d BoxUnseenCentreCov(const Eigen::Matrix2d& cov_m2, double size_var_m2,
                                   const Eigen::Matrix2d& size_cov_m2, double yaw_rad,
                                   const std::array<bool, 2>& shown, double unseen_sigma_m) {
  Eigen::Matrix2d cov = cov_m2;
  const Eigen::Vector2d e1(std::cos(yaw_rad), std::sin(yaw_rad)), e2(-e1.y(), e1.x());
  for (int k = 0; k < 2; ++k) {
    if (shown[static_cast<std::size_t>(k)]) continue;
    const Eigen::Vector2d& e = k == 0 ? e1 : e2;
    const double extra = std::max(size_cov_m2(k, k), unseen_sigma_m * unseen_sigma_m) - size_var_m2;
    if (extra > 0.0) cov += extra * e * e.transpose();
  }
  return cov;
}

Eigen::Vector2d HalfExtentsAlong(std::span<const Eigen::Vector2d> points,
                                 const Eigen::Vector2d& e1) {
  if (points.empty()) return Eigen::Vector2d::Zero();
  // Both projections at once, (p.dot(e1), p.dot(e2)) = x (e1.x, e2.x) + y (e1.y, e2.y) with
  // e2 = (-e1.y, e1.x): the same products summed in the same order as the two dot products (bit
  // for bit on x86-64; where multiply-adds are fused, e.g. aarch64, the lanes and the dot products
  // may round differently in the last bit), a point's coordinates broadcast instead of two
  // horizontal sums.
  const Eigen::Array2d by_x(e1.x(), -e1.y());
  const Eigen::Array2d by_y(e1.y(), e1.x());
  Eigen::Array2d lo = Eigen::Array2d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Array2d hi = -lo;
  for (const Eigen::Vector2d& p : points) {
    const Eigen::Array2d uv = p.x() * by_x + p.y() * by_y;
    lo = lo.min(uv);
    hi = hi.max(uv);
  }
  return 0.5 * (hi - lo).matrix();
}

void NearestOtherSquares(std::span<const double> x, std::span<const double> y,
                         std::span<double> out) {
  // Each pair's distance once, (a - b) and (b - a) squared alike, two pairs at a time with the
  // same arithmetic as one, dx dx + dy dy (bit for bit on x86-64; where multiply-adds are fused,
  // e.g. aarch64, the lanes and the odd pair may round differently in the last bit), and the same
  // minima in any order: squares are never -0 and no NaN reaches here (finite positions). (Eigen's
  // min of two lanes is x86's minpd in std::min's operand order, which keeps the running minimum
  // where d2 is NaN; NEON's fmin would take the NaN and order -0 below +0.)
  const std::size_t n = out.size();
  constexpr double kInf = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < n; ++i) {
    const double xi = x[i], yi = y[i];
    Eigen::Array2d nearest_i = Eigen::Array2d::Constant(kInf);
    std::size_t k = i + 1;
    for (; k + 2 <= n; k += 2) {
      const Eigen::Array2d dx = Eigen::Map<const Eigen::Array2d>(x.data() + k) - xi;
      const Eigen::Array2d dy = Eigen::Map<const Eigen::Array2d>(y.data() + k) - yi;
      const Eigen::Array2d d2 = dx * dx + dy * dy;
      nearest_i = nearest_i.min(d2);
      Eigen::Map<Eigen::Array2d> nearest_k(out.data() + k);
      nearest_k = nearest_k.min(d2);
    }
    double nearest = std::min(out[i], std::min(nearest_i(0), nearest_i(1)));
    for (; k < n; ++k) {
      const double dx = x[k] - xi, dy = y[k] - yi;
      const double d2 = dx * dx + dy * dy;
      nearest = std::min(nearest, d2);
      out[k] = std::min(out[k], d2);
    }
    out[i] = nearest;
  }
}

Eigen::Vector2d BoxHalfExtents(std::span<const Eigen::Vector2d> points, double yaw_rad) {
  if (points.empty()) return Eigen::Vector2d::Zero();
  return HalfExtentsAlong(points, Eigen::Vector2d(std::cos(yaw_rad), std::sin(yaw_rad)));
}

double BoxHalfVar(double seen_half_m, double whole_half_m, double size_half_m, double min_half_m,
                  double max_half_m) {
  if (whole_half_m > 0.0) return (size_half_m - whole_half_m) * (size_half_m - whole_half_m);
  const double lo = std::max(seen_half_m, min_half_m);
  const double range = std::max(max_half_m, lo) - lo;
  return range * range / 12.0;  // a uniform distribution's variance
}

Eigen::Matrix2d BoxSeenCentreCov(double bias_var_m2, double floor_var_m2,
                                 const Eigen::Matrix2d& size_cov_m2, double yaw_rad,
                                 const std::array<double, 2>& half_var_m2) {
  Eigen::Matrix2d cov = bias_var_m2 * Eigen::Matrix2d::Identity();
  const Eigen::Vector2d e1(std::cos(yaw_rad), std::sin(yaw_rad)), e2(-e1.y(), e1.x());
  for (int k = 0; k < 2; ++k) {
    const Eigen::Vector2d& e = k == 0 ? e1 : e2;
    cov += std::max({floor_var_m2, size_cov_m2(k, k), half_var_m2[static_cast<std::size_t>(k)]}) *
           e * e.transpose();
  }
  return cov;
}

// Whether p lies within the box (centre_m, half-lengths size_m along e1 and e2) grown by margin_m.
static bool InGrownBox(const Eigen::Vector2d& p, const Eigen::Vector2d& centre_m,
                       const Eigen::Vector2d& size_m, const Eigen::Vector2d& e1,
                       const Eigen::Vector2d& e2, double margin_m) {
  const Eigen::Vector2d d = p - centre_m;
  return !(std::abs(d.dot(e1)) > size_m.x() + margin_m ||
           std::abs(d.dot(e2)) > size_m.y() + margin_m);
}

bool InsideGrownBox(const Eigen::Vector2d& centre_m, const Eigen::Vector2d& size_m, double yaw_rad,
                    double margin_m, std::span<const Eigen::Vector2d> points) {
  if (points.empty()) return false;
  const Eigen::Vector2d e1(std::cos(yaw_rad), std::sin(yaw_rad)), e2(-e1.y(), e1.x());
  return std::all_of(points.begin(), points.end(), [&](const Eigen::Vector2d& p) {
    return InGrownBox(p, centre_m, size_m, e1, e2, margin_m);
  });
}

bool AnyInsideGrownBox(const Eigen::Vector2d& centre_m, const Eigen::Vector2d& size_m,
                       double yaw_rad, double margin_m, std::span<const Eigen::Vector2d> points) {
  if (points.empty()) return false;
  const Eigen::Vector2d e1(std::cos(yaw_rad), std::sin(yaw_rad)), e2(-e1.y(), e1.x());
  return std::any_of(points.begin(), points.end(), [&](const Eigen::Vector2d& p) {
    return InGrownBox(p, centre_m, size_m, e1, e2, margin_m);
  });
}

namespace {

// The track's size information and the fit's (LearnSize, LearnSizeWeighted); false where either
// covariance is singular.
bool SizeInformation(const TrackShape& shape, const Eigen::Matrix2d& size_cov,
                     Eigen::Matrix2d& prior_info, Eigen::Matrix2d& post_info) {
  bool ok_prior = false, ok_post = false;
  shape.size_cov_m2.computeInverseWithCheck(prior_info, ok_prior, 1e-18);
  size_cov.computeInverseWithCheck(post_info, ok_post, 1e-18);
  return ok_prior && ok_post;
}

// The learned size where it is finite and positive (LearnSize, LearnSizeWeighted).
void StoreSize(const Eigen::Vector2d& mean, const Eigen::Matrix2d& cov, TrackShape& shape) {
  if (!mean.allFinite() || !(mean.minCoeff() > 0.0)) return;
  shape.size_m = mean;
  shape.size_cov_m2 = 0.5 * (cov + cov.transpose());
}

}  // namespace

std::array<double, 2> PersonAxisWeights(const Eigen::Vector2d& centre_m, double yaw_rad) {
  const double range = centre_m.norm();
  if (!(range > 0.0)) return {1.0, 1.0};
  // cos of the angle between axis a and the ray: a's share across the ray is 1 - c^2.
  const double c = (std::cos(yaw_rad) * centre_m.x() + std::sin(yaw_rad) * centre_m.y()) / range;
  const double along = std::min(1.0, c * c);
  return {1.0 - along, along};
}

void LearnSizeWeighted(const Eigen::Vector2d& size, const Eigen::Matrix2d& size_cov, double share,
                       const std::array<double, 2>& weights, TrackShape& shape) {
  Eigen::Matrix2d prior_info, post_info;
  if (!SizeInformation(shape, size_cov, prior_info, post_info)) return;
  // D (share (post - prior)) D with D = diag(sqrt(weights)): PSD where the fit's is.
  const Eigen::Vector2d root(std::sqrt(std::max(0.0, weights[0])),
                             std::sqrt(std::max(0.0, weights[1])));
  const Eigen::Matrix2d gained =
      share * root.asDiagonal() * (post_info - prior_info) * root.asDiagonal();
  Eigen::Matrix2d cov;
  bool ok = false;
  (prior_info + gained).computeInverseWithCheck(cov, ok, 1e-18);
  if (!ok || !cov.allFinite()) return;
  // Innovation form (LearnSize), each semi-axis's pull scaled by its weight.
  Eigen::Vector2d pull = share * post_info * (size - shape.size_m);
  pull(0) *= std::max(0.0, weights[0]);
  pull(1) *= std::max(0.0, weights[1]);
  const Eigen::Vector2d mean = shape.size_m + cov * pull;
  StoreSize(mean, cov, shape);
}

void LearnSize(const Eigen::Vector2d& size, const Eigen::Matrix2d& size_cov, double share,
               const std::array<bool, 2>& shown, TrackShape& shape) {
  Eigen::Matrix2d prior_info, post_info;
  if (!SizeInformation(shape, size_cov, prior_info, post_info)) return;
  Eigen::Matrix2d gained = share * (post_info - prior_info);
  for (int k = 0; k < 2; ++k) {
    if (shown[k]) continue;
    gained.row(k).setZero();
    gained.col(k).setZero();
  }
  const Eigen::Matrix2d info = prior_info + gained;
  Eigen::Matrix2d cov;
  bool ok = false;
  info.computeInverseWithCheck(cov, ok, 1e-18);
  if (!ok || !cov.allFinite()) return;
  Eigen::Vector2d mean;
  if (shown[0] && shown[1]) {
    mean =
        cov * (prior_info * shape.size_m + share * (post_info * size - prior_info * shape.size_m));
  } else {
    // The same mean in innovation form, state + cov share post_info (size - state), with the
    // pull on a semi-axis the scan did not show taken away: no information on it, no move of it
    // (the information form would still move it by the fit's own prior share).
    Eigen::Vector2d pull = share * post_info * (size - shape.size_m);
    for (int k = 0; k < 2; ++k) {
      if (!shown[k]) pull(k) = 0.0;
    }
    mean = shape.size_m + cov * pull;
  }
  StoreSize(mean, cov, shape);
}

}  // namespace internal

namespace {

// Sizes are learned only from fits whose yaw prior is at least this certain (a walking person).
constexpr double kMaxLearningYawSigmaRad = 0.6;
// A track is a cylinder when its learned semi-axes differ by less than this share of a, after this
// many updates.
constexpr double kCylinderAxisShare = 0.1;
constexpr std::uint32_t kMinCylinderUpdates = 25;
using internal::kSideKnownWeight;
// ShapeOptions::single_leg_side_from_view: at most this many steps between the places checked for
// the other leg along the walk on each side.
constexpr int kMaxSidePlaces = 16;
// Pairing legs around a track: a single leg costs this much more than a pair.
constexpr double kSingleLegPenaltyM = 0.25;

// The beams on either side of an edge whose footprint (beam_divergence_rad wide) reaches past it:
// ceil(beam_divergence_rad / 2 step) + 1.
std::size_t FootprintBeams(double beam_divergence_rad, double angle_step_rad) {
  const double step = std::max(std::abs(angle_step_rad), 1e-9);
  return static_cast<std::size_t>(std::ceil(0.5 * beam_divergence_rad / step)) + 1;
}

// Share of a fit's size information the track's state takes (see LearnSize).
constexpr double kSizeLearningShare = 0.25;

const TrackerOptions& Checked(const TrackerOptions& o) {
  if (Validate(o)) std::abort();
  return o;
}

TrackerOptions Resolved(TrackerOptions o) {
  o.measurement.fit_ellipse = o.method == MeasurementMethod::kEllipse;
  // Lost tracks are not resumed at knee height: what comes near a leg track's coasted prediction
  // is as often someone else's single leg or a chair's (tracking_benchmark: knee-height precision
  // 0.667 -> 0.659 with it, upper body 0.9895 -> 0.9890).
  if (o.shape.mount == Mount::kLegs) o.tracking.resume_window_s = 0.0;
  // Confirmation in time at knee height only: at upper-body height it costs missed scans and
  // removes little (tracking_benchmark, upper body per sensor at 0.2 s: precision 0.9902 -> 0.9925
  // but MOTA 0.924 -> 0.917 and NEES 1.62 -> 1.45, below its target range).
  if (o.shape.mount != Mount::kLegs) o.tracking.confirm_min_s = 0.0;
  // Successors taken over at knee height only: at upper-body height the adopted young filter's
  // errors cost more than the false scans it removes (tracking_benchmark, upper body per sensor:
  // precision 0.9902 -> 0.9904, id switches 4.70 -> 4.45, but MOTP 0.0286 -> 0.0289, p95 0.0781
  // -> 0.0790).
  if (o.shape.mount != Mount::kLegs) o.tracking.adopt_successor_m = 0.0;
  // The measured noise across the ray at upper-body height only: at knee height the legs' midpoint
  // moves across the ray with the stride (which leg is seen, which stands), an error successive
  // scans share and the innovations do not show (tracking_benchmark, knee height per sensor: NEES
  // 1.61 -> 2.79, fused 1.92 -> 2.95).
  if (o.shape.mount == Mount::kLegs) o.tracking.measured_noise_memory_scans = 0.0;
  // Coasting reports at knee height for a shorter time (ShapeOptions::legs_report_coasting_s).
  if (o.shape.mount == Mount::kLegs && o.shape.legs_report_coasting_s > 0.0) {
    o.tracking.report_coasting_s =
        std::min(o.tracking.report_coasting_s, o.shape.legs_report_coasting_s);
  }
  return o;
}

double Range(const Eigen::Vector2d& p) { return p.norm(); }

// The beams [lo, hi] whose directions lie within half_angle_rad of position_m's bearing (either
// sign of the scan's angle step), among the first `beams`; false when none is in the field of view.
bool BeamsAcross(const ScanView& scan, const Eigen::Vector2d& position_m, double half_angle_rad,
                 std::size_t beams, std::size_t* lo, std::size_t* hi) {
  const double bearing = std::atan2(position_m.y(), position_m.x());
  const double step = scan.angle_step_rad;
  const double a = (bearing - half_angle_rad - scan.first_angle_rad) / step;
  const double b = (bearing + half_angle_rad - scan.first_angle_rad) / step;
  const double first = std::ceil(std::min(a, b)), last = std::floor(std::max(a, b));
  if (!(first >= 0.0 && last < static_cast<double>(beams) && first <= last)) return false;
  *lo = static_cast<std::size_t>(first);
  *hi = static_cast<std::size_t>(last);
  return true;
}

// How far a piece's points spread across the line of sight through their middle.
double AcrossWidth(std::span<const Eigen::Vector2d> pts) {
  if (pts.empty()) return 0.0;
  const Eigen::Vector2d mid = 0.5 * (pts.front() + pts.back());
  const double range = mid.norm();
  if (!(range > 0.0)) return 0.0;
  const Eigen::Vector2d across(-mid.y() / range, mid.x() / range);
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (const Eigen::Vector2d& p : pts) {
    const double a = p.dot(across);
    lo = std::min(lo, a);
    hi = std::max(hi, a);
  }
  return hi - lo;
}

}  // namespace

std::optional<std::string> Validate(const ShapeOptions& o) {
  if (o.mount != Mount::kTorso && o.mount != Mount::kLegs) return "mount must be torso or legs";
  if (auto e = Validate(o.fit)) return *e;
  if (!Positive(o.person_minor_m) || !Positive(o.person_major_m) ||
      o.person_minor_m > o.person_major_m) {
    return "need 0 < person_minor_m <= person_major_m";
  }
  if (!Positive(o.person_size_sigma_m)) return "person_size_sigma_m must be > 0";
  if (!(std::isfinite(o.person_exponent) && o.person_exponent >= 2.0 &&
        o.person_exponent <= 20.0)) {
    return "person_exponent must be in [2, 20]";
  }
  if (!Positive(o.box_min_half_length_m) || o.box_min_half_length_m <= o.person_major_m) {
    return "box_min_half_length_m must be > person_major_m";
  }
  if (!Positive(o.leg_radius_m) || !Positive(o.leg_radius_sigma_m)) {
    return "leg_radius_m and leg_radius_sigma_m must be > 0";
  }
  if (!Positive(o.leg_pairing_distance_m) || o.leg_pairing_distance_m <= 2.0 * o.leg_radius_m) {
    return "leg_pairing_distance_m must be > 2 leg_radius_m";
  }
  if (!(std::isfinite(o.person_min_leg_radius_m) && o.person_min_leg_radius_m >= 0.0)) {
    return "person_min_leg_radius_m must be >= 0";
  }
  if (!(std::isfinite(o.mixed_leg_max_gap_m) && o.mixed_leg_max_gap_m >= 0.0)) {
    return "mixed_leg_max_gap_m must be >= 0";
  }
  if (!(std::isfinite(o.occluded_gap_depth_m) && o.occluded_gap_depth_m >= 0.0)) {
    return "occluded_gap_depth_m must be >= 0";
  }
  if (!(std::isfinite(o.still_legs_max_depth_m) && o.still_legs_max_depth_m >= 0.0)) {
    return "still_legs_max_depth_m must be >= 0";
  }
  if (!(std::isfinite(o.hip_half_width_m) && o.hip_half_width_m >= 0.0)) {
    return "hip_half_width_m must be >= 0";
  }
  if (!Positive(o.gait_sigma_m)) return "gait_sigma_m must be > 0";
  if (!(std::isfinite(o.still_legs_sigma_m) && o.still_legs_sigma_m >= 0.0 &&
        o.still_legs_sigma_m <= o.gait_sigma_m)) {
    return "still_legs_sigma_m must be in [0, gait_sigma_m]";
  }
  if (!(std::isfinite(o.walking_legs_sigma_m) && o.walking_legs_sigma_m >= 0.0 &&
        o.walking_legs_sigma_m <= o.gait_sigma_m)) {
    return "walking_legs_sigma_m must be in [0, gait_sigma_m]";
  }
  if (!(std::isfinite(o.still_legs_max_speed_mps) && o.still_legs_max_speed_mps >= 0.0)) {
    return "still_legs_max_speed_mps must be >= 0";
  }
  if (!(std::isfinite(o.stance_leg_weight) && o.stance_leg_weight >= 0.5 &&
        o.stance_leg_weight <= 1.0)) {
    return "stance_leg_weight must be in [0.5, 1]";
  }
  if (!(std::isfinite(o.stance_memory_s) && o.stance_memory_s >= 0.0)) {
    return "stance_memory_s must be >= 0";
  }
  if (!(std::isfinite(o.standing_leg_memory_s) && o.standing_leg_memory_s >= 0.0)) {
    return "standing_leg_memory_s must be >= 0";
  }
  if (!Positive(o.walking_speed_mps)) return "walking_speed_mps must be > 0";
  if (!Positive(o.walking_yaw_sigma_rad)) return "walking_yaw_sigma_rad must be > 0";
  if (!(std::isfinite(o.yaw_drift_rad_per_s) && o.yaw_drift_rad_per_s >= 0.0)) {
    return "yaw_drift_rad_per_s must be >= 0";
  }
  if (!(std::isfinite(o.size_drift_m_per_sqrt_s) && o.size_drift_m_per_sqrt_s >= 0.0)) {
    return "size_drift_m_per_sqrt_s must be >= 0";
  }
  if (!Positive(o.centre_model_sigma_m)) return "centre_model_sigma_m must be > 0";
  if (!(std::isfinite(o.outline_departure_gain) && o.outline_departure_gain >= 0.0)) {
    return "outline_departure_gain must be >= 0";
  }
  if (!(std::isfinite(o.outline_fixed_share) && o.outline_fixed_share > 0.0 &&
        o.outline_fixed_share <= 1.0)) {
    return "outline_fixed_share must be in (0, 1]";
  }
  if (!(std::isfinite(o.outline_model_share) && o.outline_model_share > 0.0 &&
        o.outline_model_share <= 1.0)) {
    return "outline_model_share must be in (0, 1]";
  }
  if (!(std::isfinite(o.size_floor_sigma_m) && o.size_floor_sigma_m >= 0.0)) {
    return "size_floor_sigma_m must be >= 0";
  }
  if (!(std::isfinite(o.partial_view_size_sigma_m) && o.partial_view_size_sigma_m >= 0.0)) {
    return "partial_view_size_sigma_m must be >= 0";
  }
  if (!(std::isfinite(o.box_size_floor_sigma_m) && o.box_size_floor_sigma_m >= 0.0)) {
    return "box_size_floor_sigma_m must be >= 0";
  }
  if (!(std::isfinite(o.centre_bias_sigma_m) && o.centre_bias_sigma_m >= 0.0)) {
    return "centre_bias_sigma_m must be >= 0";
  }
  if (!(std::isfinite(o.centre_bias_across_sigma_m) && o.centre_bias_across_sigma_m >= 0.0)) {
    return "centre_bias_across_sigma_m must be >= 0";
  }
  if (!(std::isfinite(o.flat_rms_m) && o.flat_rms_m >= 0.0)) return "flat_rms_m must be >= 0";
  if (!(std::isfinite(o.flat_min_extent_m) && o.flat_min_extent_m >= 0.0)) {
    return "flat_min_extent_m must be >= 0";
  }
  if (!Positive(o.association_sigma_m)) return "association_sigma_m must be > 0";
  if (!(std::isfinite(o.seen_through_margin_m) && o.seen_through_margin_m >= 0.0)) {
    return "seen_through_margin_m must be >= 0";
  }
  if (!(std::isfinite(o.unseen_coasting_m) && o.unseen_coasting_m >= 0.0)) {
    return "unseen_coasting_m must be >= 0";
  }
  if (!(std::isfinite(o.legs_report_coasting_s) && o.legs_report_coasting_s >= 0.0)) {
    return "legs_report_coasting_s must be >= 0";
  }
  if (!(std::isfinite(o.coasting_max_sigma_m) && o.coasting_max_sigma_m >= 0.0)) {
    return "coasting_max_sigma_m must be >= 0";
  }
  if (!(std::isfinite(o.legs_coasting_max_sigma_m) && o.legs_coasting_max_sigma_m >= 0.0)) {
    return "legs_coasting_max_sigma_m must be >= 0";
  }
  if (!(std::isfinite(o.beam_divergence_rad) && o.beam_divergence_rad >= 0.0)) {
    return "beam_divergence_rad must be >= 0";
  }
  if (!(std::isfinite(o.beam_exit_diameter_m) && o.beam_exit_diameter_m >= 0.0)) {
    return "beam_exit_diameter_m must be >= 0";
  }
  if (!(std::isfinite(o.mixed_pixel_min_footprint_m) && o.mixed_pixel_min_footprint_m >= 0.0)) {
    return "mixed_pixel_min_footprint_m must be >= 0 (0: off)";
  }
  if (!(std::isfinite(o.receded_background_edge_m) && o.receded_background_edge_m >= 0.0)) {
    return "receded_background_edge_m must be >= 0 (0: off)";
  }
  if (!(std::isfinite(o.receded_background_margin_m) && o.receded_background_margin_m >= 0.0)) {
    return "receded_background_margin_m must be >= 0";
  }
  if (!(std::isfinite(o.recent_veil_s) && o.recent_veil_s >= 0.0 && o.recent_veil_s <= 2.0)) {
    return "recent_veil_s must be in [0, 2]";
  }
  if (!(std::isfinite(o.deep_mixed_pixel_behind_ratio) && o.deep_mixed_pixel_behind_ratio >= 0.0)) {
    return "deep_mixed_pixel_behind_ratio must be >= 0";
  }
  if (!(std::isfinite(o.mixed_pixel_min_gap_m) && o.mixed_pixel_min_gap_m >= 0.0)) {
    return "mixed_pixel_min_gap_m must be >= 0";
  }
  if (!Positive(o.neighbour_distance_m)) return "neighbour_distance_m must be > 0";
  if (!(std::isfinite(o.neighbour_sigma_m) && o.neighbour_sigma_m >= 0.0)) {
    return "neighbour_sigma_m must be >= 0 (0: off)";
  }
  if (!Positive(o.box_rejoin_sigmas)) return "box_rejoin_sigmas must be > 0";
  if (!(std::isfinite(o.see_through_min_width_m) && o.see_through_min_width_m >= 0.0)) {
    return "see_through_min_width_m must be >= 0";
  }
  if (!(o.torso_edge_echo_min_far_share >= 0.0 && o.torso_edge_echo_min_far_share < 1.0)) {
    return "torso_edge_echo_min_far_share must be in [0, 1)";
  }
  if (auto e = Validate(o.step_seam)) return "step_seam." + *e;
  if (!Positive(o.step_seam_person_max_a_m)) return "step_seam_person_max_a_m must be > 0";
  if (!Positive(o.step_seam_person_max_b_m)) return "step_seam_person_max_b_m must be > 0";
  if (!(std::isfinite(o.deep_tail_depth_m) && o.deep_tail_depth_m > 0.0)) {
    return "deep_tail_depth_m must be > 0";
  }
  if (!(std::isfinite(o.deep_tail_centre_bias_sigma_m) && o.deep_tail_centre_bias_sigma_m >= 0.0)) {
    return "deep_tail_centre_bias_sigma_m must be >= 0";
  }
  if (!(std::isfinite(o.step_seam_size_margin_m) && o.step_seam_size_margin_m >= 0.0)) {
    return "step_seam_size_margin_m must be >= 0";
  }
  if (!Positive(o.box_size_sigma_m)) return "box_size_sigma_m must be > 0";
  if (!Positive(o.box_unseen_sigma_m)) return "box_unseen_sigma_m must be > 0";
  if (!Positive(o.box_prior_min_half_m) || !(o.box_prior_max_half_m > o.box_prior_min_half_m) ||
      !std::isfinite(o.box_prior_max_half_m)) {
    return "box_prior_min_half_m must be > 0 and box_prior_max_half_m > box_prior_min_half_m";
  }
  return std::nullopt;
}

std::optional<std::string> Validate(const TrackerOptions& o) {
  if (auto e = Validate(o.background)) return "background." + *e;
  if (auto e = Validate(o.segmentation)) return "segmentation." + *e;
  if (o.method != MeasurementMethod::kCenterOfMass && o.method != MeasurementMethod::kEllipse &&
      o.method != MeasurementMethod::kShapeFit) {
    return "measurement.kind must be center_of_mass, ellipse or shape_fit";
  }
  if (auto e = Validate(o.measurement)) return "measurement." + *e;
  if (auto e = Validate(o.shape)) return "shape." + *e;
  if (auto e = Validate(o.tracking)) return "tracking." + *e;
  return std::nullopt;
}

MeasurementKind KindOf(MeasurementMethod method) {
  switch (method) {
    case MeasurementMethod::kCenterOfMass:
      return MeasurementKind::kCenterOfMass;
    case MeasurementMethod::kEllipse:
      return MeasurementKind::kEllipse;
    case MeasurementMethod::kShapeFit:
      return MeasurementKind::kShapeFit;
  }
  return MeasurementKind::kShapeFit;
}

// The upper-body fit's parameters: centre (2), semi-axes (2), yaw (ShapeOptions::
// underdetermined_fit_shared).
constexpr std::size_t kBodyFitParameters = 5;

// The shape fit of an observation with what its track knows (MeasurementRefiner).
class TrackingPipeline::Refiner final : public MeasurementRefiner {
 public:
  // evaluations: where the fits are counted by their evaluations (PipelineCounters).
  Refiner(const TrackingPipeline& pipeline, std::span<std::uint64_t> evaluations)
      : p_(pipeline), evaluations_(evaluations) {}

  bool Refine(std::size_t source, common::UtcNs at_ns, const Eigen::Vector4d* predicted,
              const Eigen::Matrix4d* predicted_cov, TrackShape& shape,
              Measurement& measurement) override {
    if (source >= p_.observations_.size()) return false;
    const Observation& ob = p_.observations_[source];
    const ShapeOptions& o = p_.options_.shape;
    if (shape.shape == ObjectShape::kUnspecified) {
      Init(ob, at_ns, shape);
    } else {
      // What the state forgets between scans.
      const double dt_s = std::max(0.0, common::NsToSeconds(at_ns - shape.stamp_ns));
      shape.size_cov_m2 += o.size_drift_m_per_sqrt_s * o.size_drift_m_per_sqrt_s * dt_s *
                           Eigen::Matrix2d::Identity();
      const double drift = o.yaw_drift_rad_per_s * dt_s;
      shape.yaw_sigma_rad =
          std::min(kUnknownYawSigmaRad,
                   std::sqrt(shape.yaw_sigma_rad * shape.yaw_sigma_rad + drift * drift));
    }
    // An observation of the other kind than the track's (legs of a cart's track, a cart's outline
    // for a person's legs): not this track's measurement.
    if (ob.legs != (shape.model == ShapeModel::kCircle)) return false;
    const bool ok =
        ob.legs ? RefineLegs(source, ob, at_ns, predicted, predicted_cov, shape, measurement)
                : RefineBody(ob, predicted, predicted_cov, shape, measurement);
    if (!ok) return false;
    // ShapeOptions::outline_departure_gain: at upper-body height the fit's residuals measure how
    // far the outline departs from the model; the fixed allowances for it shrink to
    // outline_fixed_share (shared) and outline_model_share (per scan).
    const bool measured_outline =
        o.mount == Mount::kTorso && !ob.legs && o.outline_departure_gain > 0.0;
    // ShapeOptions::partial_view_shared, underdetermined_fit_shared: the fit's own centre
    // covariance, before the per-scan allowance below, where the outline is seen to one end or
    // none, or where its points and silhouette ends are no more than the fit's parameters.
    const bool body =
        o.mount == Mount::kTorso && !ob.legs && shape.model == ShapeModel::kSuperellipse;
    // The fit's silhouette ends and points where it left a run beyond the person's reach out
    // (ShapeOptions::person_drop_beyond_reach), else the observation's.
    const bool reach_dropped = body && body_fit_reduced_;
    const int edges = reach_dropped ? body_fit_edges_ : SilhouetteEdges(ob);
    std::size_t points = 0;
    for (std::size_t k = 0; k < ob.part_count; ++k) points += ob.parts[k].point_count;
    if (reach_dropped) points = body_fit_points_;
    const bool partial = body && o.partial_view_shared && edges < 2;
    const bool underdetermined = body && o.underdetermined_fit_shared &&
                                 points + static_cast<std::size_t>(edges) <= kBodyFitParameters;
    shape.reported_partial_cov_m2 = partial || underdetermined
                                        ? Eigen::Matrix2d(measurement.covariance_m2)
                                        : Eigen::Matrix2d::Zero();
    if (partial) ++partial_widened;
    // ShapeOptions::neighbour_sigma_m: the nearest other observation of the scan.
    shape.reported_neighbour_m2 = 0.0;
    if (body && o.neighbour_sigma_m > 0.0 && source < p_.measurements_.size()) {
      shape.reported_neighbour_m2 = internal::NeighbourVar(o, NearestOtherM(source));
      if (shape.reported_neighbour_m2 > 0.0) ++neighbour_widened;
    }
    if (underdetermined) ++underdetermined_widened;
    // ShapeOptions::segment_excess_shared.
    shape.reported_excess_cov_m2.setZero();
    // The outline's bounding box's squared diagonal where the segment excess measured it, else -1
    // (ShapeOptions::box_view_at_torso reads it).
    double outline_diagonal_m2 = -1.0;
    if (body && o.segment_excess_shared && ob.part_count > 0) {
      const internal::SegmentExtent extent =
          internal::SegmentExtents(ReliablePoints(ob.parts[0]), measurement.position_m);
      outline_diagonal_m2 = extent.along_m * extent.along_m + extent.across_m * extent.across_m;
      const double noise_m =
          o.fit.point_sigma_m + o.fit.point_sigma_per_m * measurement.position_m.norm();
      // The reach is at least the larger semi-axis (SuperellipseReachFactor >= 1): the reach's pow
      // only where the extents could leave an excess beyond that (most fits leave none).
      const double semi_max_m = std::max(shape.size_m.x(), shape.size_m.y());
      if (extent.across_m - 4.0 * noise_m > 2.0 * semi_max_m ||
          extent.along_m - 4.0 * noise_m > semi_max_m) {
        shape.reported_excess_cov_m2 = internal::SegmentExcessCov(
            extent, internal::SuperellipseReach(shape.size_m, shape.exponent), noise_m);
      }
      if (!shape.reported_excess_cov_m2.isZero()) ++segment_excess_widened;
    }
    // ShapeOptions::box_view_shared.
    shape.reported_box_view_cov_m2.setZero();
    if (o.box_view_shared && !ob.legs && shape.model == ShapeModel::kSuperellipse &&
        ob.part_count > 0 &&
        (o.mount != Mount::kTorso || BoxViewAtTorsoPossible(o, ob, outline_diagonal_m2))) {
      shape.reported_box_view_cov_m2 = BoxViewShared(o, ob, measurement.position_m);
    }
    // ShapeOptions::occluded_gap_depth_m: two legs with something nearer between them may be one
    // surface's ends behind it, the centre of its object behind them; the same in every scan
    // while it stands, so reported, not given to the filter (as a box's view above).
    if (ob.legs && ob.part_count == 2) {
      const double gap_var = internal::OccludedGapAlongRayVar(o, ob.parts[0], ob.parts[1]);
      const double gap_range_m = measurement.position_m.norm();
      if (gap_var > 0.0 && gap_range_m > 0.0) {
        const Eigen::Vector2d ray = measurement.position_m / gap_range_m;
        shape.reported_box_view_cov_m2 = gap_var * ray * ray.transpose();
        ++occluded_gap_widened;
      }
    }
    const double share = measured_outline ? o.outline_fixed_share : 1.0;
    const double model_sigma_m =
        (measured_outline ? o.outline_model_share : 1.0) * o.centre_model_sigma_m;
    measurement.covariance_m2 += model_sigma_m * model_sigma_m * Eigen::Matrix2d::Identity();
    double departure_var = 0.0;
    if (measured_outline) {
      departure_var = internal::OutlineDepartureVar(o, measurement.rms_residual_m,
                                                    measurement.position_m.norm());
      if (departure_var > 0.0) ++widened;
      shape.departure_m2 += (departure_var - shape.departure_m2) /
                            std::min(kDepartureMemory, static_cast<double>(shape.updates + 1));
    }
    measurement.kind = MeasurementKind::kShapeFit;
    // What successive measurements share goes into the report: the size state's error (never
    // taken as smaller than the floor) and the outline's departure from the model.
    const double floor_m = shape.model == ShapeModel::kBox
                               ? std::max(share * o.size_floor_sigma_m, o.box_size_floor_sigma_m)
                               : share * o.size_floor_sigma_m;
    const double bias_sigma_m =
        share * (o.mount == Mount::kTorso && o.split_deep_tail ? o.deep_tail_centre_bias_sigma_m
                                                               : o.centre_bias_sigma_m);
    const double range_m = measurement.position_m.norm();
    shape.reported_bias_relief_m2.setZero();
    if (o.centre_bias_along_ray && range_m > 0.0 && shape.model != ShapeModel::kBox) {
      const double step_rad = ob.part_count > 0 ? ob.parts[0].silhouette.step_rad : 0.0;
      // ShapeOptions::partial_view_size_sigma_m.
      const double bias_floor_m = internal::PartialViewSizeFloor(o, body, edges, floor_m);
      if (bias_floor_m > floor_m) ++partial_size_floored;
      shape.centre_bias_cov_m2 =
          CentreBiasAlongRay(shape, measurement.position_m / range_m, range_m, step_rad, edges,
                             bias_floor_m, bias_sigma_m, o);
      if (measurement.gain_still) {
        // ShapeOptions::still_legs_cov: two legs seen still share the fixed allowances cut to
        // outline_fixed_share, in the reports of measured scans.
        shape.reported_bias_relief_m2 =
            shape.centre_bias_cov_m2 - CentreBiasAlongRay(shape, measurement.position_m / range_m,
                                                          range_m, step_rad, edges,
                                                          o.outline_fixed_share * bias_floor_m,
                                                          o.outline_fixed_share * bias_sigma_m, o);
      }
    } else {
      const double size_var =
          std::max({shape.size_cov_m2(0, 0), shape.size_cov_m2(1, 1), floor_m * floor_m});
      shape.centre_bias_cov_m2 =
          (bias_sigma_m * bias_sigma_m + size_var) * Eigen::Matrix2d::Identity();
      if (shape.model == ShapeModel::kBox && o.box_seen_extent_cov && ob.part_count > 0) {
        // ShapeOptions::box_seen_extent_cov: per box axis, the centre is as uncertain as that
        // semi-axis: learned where the track saw it whole, else anywhere between what was seen
        // of it and the prior's largest (the half-width at most the half-length seen whole).
        const Eigen::Vector2d& seen = shape.box_seen_half_m;
        const Eigen::Vector2d& whole = shape.box_whole_half_m;
        const double max_b = whole.x() > 0.0 ? std::min(o.box_prior_max_half_m, shape.size_m.x())
                                             : o.box_prior_max_half_m;
        const std::array<double, 2> half_var = {
            internal::BoxHalfVar(seen.x(), whole.x(), shape.size_m.x(), o.box_prior_min_half_m,
                                 o.box_prior_max_half_m),
            internal::BoxHalfVar(seen.y(), whole.y(), shape.size_m.y(), o.box_prior_min_half_m,
                                 max_b)};
        shape.centre_bias_cov_m2 =
            internal::BoxSeenCentreCov(bias_sigma_m * bias_sigma_m, floor_m * floor_m,
                                       shape.size_cov_m2, shape.yaw_rad, half_var);
        if (!(whole.x() > 0.0) || !(whole.y() > 0.0)) ++box_unseen_widened;
      } else if (shape.model == ShapeModel::kBox && o.box_unseen_depth_cov && ob.part_count > 0) {
        // ShapeOptions::box_unseen_depth_cov: along a box axis whose semi-axis the scan does not
        // show, the centre is as uncertain as that semi-axis.
        const std::array<bool, 2> shown =
            internal::BoxFacesShown(measurement.position_m, shape.size_m, shape.yaw_rad,
                                    std::abs(ob.parts[0].silhouette.step_rad));
        shape.centre_bias_cov_m2 =
            internal::BoxUnseenCentreCov(shape.centre_bias_cov_m2, size_var, shape.size_cov_m2,
                                         shape.yaw_rad, shown, o.box_unseen_sigma_m);
        if (!shown[0] || !shown[1]) ++box_unseen_widened;
      }
    }
    // The outline's departure in this scan, or on average over the track's recent scans, is
    // shared by successive scans as the outline is (a second object in the segment, a partial
    // view, arms held out): reported, not given to the filter as noise it could average away.
    shape.reported_departure_m2 =
        measured_outline ? std::max(departure_var, shape.departure_m2) : 0.0;
    shape.stamp_ns = at_ns;
    ++shape.updates;
    if (source < refined_cov.size()) {
      refined_cov[source] = measurement.covariance_m2;
      refined_step[source] = scans;
    }
    return true;
  }

  // Per observation of the scan: the covariance of the measurement last refined from it (valid
  // where refined_step is the current count of scans), and its legs' fitted radii (0 where none);
  // TrackingPipeline::RefinedCovariance and LegRadius.
  std::uint64_t scans = 0;
  std::array<Eigen::Matrix2d, kMaxSegments> refined_cov{};
  std::array<std::uint64_t, kMaxSegments> refined_step{};
  std::array<std::array<double, 2>, kMaxSegments> leg_radius{};
  std::array<std::array<Eigen::Vector2d, 2>, kMaxSegments> leg_centre{};

  std::uint64_t fits = 0;
  std::uint64_t failed = 0;
  std::uint64_t across_walk = 0;
  std::uint64_t side_uncertain = 0;
  std::uint64_t side_from_view = 0;
  std::uint64_t view_contested = 0;
  std::uint64_t along_from_standing = 0;
  std::uint64_t widened = 0;
  std::uint64_t partial_widened = 0;
  std::uint64_t underdetermined_widened = 0;
  std::uint64_t stance_weighted = 0;
  std::uint64_t touching = 0;
  std::uint64_t still_legs = 0;
  std::uint64_t mixed_legs = 0;
  std::uint64_t box_occluded = 0;
  std::uint64_t box_unseen_sizes = 0;
  std::uint64_t box_unseen_widened = 0;
  std::uint64_t box_bounded = 0;
  std::uint64_t person_across_ray = 0;
  std::uint64_t person_beyond_reach = 0;
  std::uint64_t partial_size_floored = 0;
  std::uint64_t person_size_kept = 0;
  std::uint64_t neighbour_widened = 0;
  std::uint64_t segment_excess_widened = 0;
  std::uint64_t occluded_gap_widened = 0;
  std::uint64_t box_view_widened = 0;

  // ShapeOptions::box_view_shared: the first (or last) end of the outline ReliablePoints(part)
  // and what the beam beyond it returned: the mixed pixel ReliablePoints left out there, else the
  // beam beside the part's.
  internal::OutlineEnd OutlineEndAt(const ObservationPart& part, bool first_end) const {
    internal::OutlineEnd end;
    end.silhouette = first_end ? part.silhouette.first_valid : part.silhouette.last_valid;
    const std::span<const Eigen::Vector2d> all = Points(part);
    const std::size_t mixed = (part.first_mixed ? 1 : 0) + (part.last_mixed ? 1 : 0);
    if ((first_end ? part.first_mixed : part.last_mixed) && all.size() > mixed) {
      end.beyond_valid = true;
      end.beyond_m = first_end ? all.front() : all.back();
      return end;
    }
    if (p_.scan_ == nullptr) return end;
    const ScanView& scan = *p_.scan_;
    if (first_end && part.begin_beam == 0) return end;  // the field of view's end
    const std::size_t beam = first_end ? part.begin_beam - 1 : part.end_beam;
    if (beam >= scan.range_m.size()) return end;
    const double r = static_cast<double>(scan.range_m[beam]);
    if (!(std::isfinite(r) && r > 0.0)) {
      end.beyond_returned_none = true;
      return end;
    }
    const double angle = scan.BeamAngleRad(beam);
    end.beyond_valid = true;
    end.beyond_m = Eigen::Vector2d(r * std::cos(angle), r * std::sin(angle));
    return end;
  }

  // ShapeOptions::box_view_shared: the covariance reported for a body fit at `position_m` from
  // the observation's outline (zero where it is no box's), counted.
  Eigen::Matrix2d BoxViewShared(const ShapeOptions& o, const Observation& ob,
                                const Eigen::Vector2d& position_m) {
    const double noise_m = o.fit.point_sigma_m + o.fit.point_sigma_per_m * position_m.norm();
    const ObservationPart& part = ob.parts[0];
    int faces = 0;
    double longest_m = 0.0;
    Eigen::Matrix2d cov =
        internal::BoxViewCov(o, ReliablePoints(part), position_m, noise_m, OutlineEndAt(part, true),
                             OutlineEndAt(part, false), &faces, &longest_m);
    // ShapeOptions::box_view_at_torso.
    if (o.mount == Mount::kTorso &&
        (!o.box_view_at_torso || !(longest_m > 2.0 * o.box_min_half_length_m))) {
      return Eigen::Matrix2d::Zero();
    }
    if (faces > 0) ++box_view_widened;
    return cov;
  }

  // ShapeOptions::box_view_at_torso: whether the outline may hold a face longer than a body can be.
  // Every face BoxViewCov finds joins two of the outline's points, no farther apart than the
  // diagonal of their bounding box (in any frame; diagonal_m2 its square where known, else < 0):
  // a person's outline (most upper-body fits) is left at that.
  bool BoxViewAtTorsoPossible(const ShapeOptions& o, const Observation& ob,
                              double diagonal_m2) const {
    if (!o.box_view_at_torso) return false;
    if (diagonal_m2 < 0.0) {
      const std::span<const Eigen::Vector2d> outline = ReliablePoints(ob.parts[0]);
      if (outline.empty()) return false;
      Eigen::Vector2d lo = outline[0];
      Eigen::Vector2d hi = outline[0];
      for (const Eigen::Vector2d& q : outline) {
        lo = lo.cwiseMin(q);
        hi = hi.cwiseMax(q);
      }
      diagonal_m2 = (hi - lo).squaredNorm();
    }
    return diagonal_m2 > 4.0 * o.box_min_half_length_m * o.box_min_half_length_m;
  }

  // How many of the observation's two outline ends are silhouettes (MakePart: not an occluder's
  // edge, not the field of view's end).
  static int SilhouetteEdges(const Observation& ob) {
    if (ob.part_count == 0) return 0;
    return (ob.parts[0].silhouette.first_valid ? 1 : 0) +
           (ob.parts[ob.part_count - 1].silhouette.last_valid ? 1 : 0);
  }

  // dh/d(a, b) of the body's extent h(n; a, b) in direction n (the support function's analytic
  // derivative; a circle's extent is its radius a).
  static Eigen::Vector2d ExtentJacobian(const TrackShape& shape, const Eigen::Vector2d& n) {
    if (shape.model == ShapeModel::kCircle) return Eigen::Vector2d(1.0, 0.0);
    Eigen::Vector2d jacobian = Eigen::Vector2d::Zero();
    ShapeSupport(shape.model, shape.size_m, shape.yaw_rad, n, shape.exponent, &jacobian);
    return jacobian;
  }
  // ExtentJacobian in two directions n0 and n1 at once (the same values as one at a time).
  static void ExtentJacobians(const TrackShape& shape, const Eigen::Vector2d& n0,
                              const Eigen::Vector2d& n1, Eigen::Vector2d* j0, Eigen::Vector2d* j1) {
    if (shape.model == ShapeModel::kCircle) {
      *j0 = *j1 = Eigen::Vector2d(1.0, 0.0);
      return;
    }
    ShapeSupportPair(shape.model, shape.size_m, shape.yaw_rad, n0, n1, shape.exponent, j0, j1);
  }

  // ShapeOptions::centre_bias_along_ray: u the unit ray from the sensor through the centre at
  // range_m, step_rad the scan's beam step, edges the silhouette ends (SilhouetteEdges), floor_m
  // the size's floor and bias_sigma_m the outline's sigma along the ray.
  static Eigen::Matrix2d CentreBiasAlongRay(const TrackShape& shape, const Eigen::Vector2d& u,
                                            double range_m, double step_rad, int edges,
                                            double floor_m, double bias_sigma_m,
                                            const ShapeOptions& o) {
    // The size's covariance, each semi-axis no more certain than the floor (a PSD diagonal added).
    Eigen::Matrix2d size_cov = shape.size_cov_m2;
    size_cov(0, 0) += std::max(0.0, floor_m * floor_m - size_cov(0, 0));
    size_cov(1, 1) += std::max(0.0, floor_m * floor_m - size_cov(1, 1));
    // Along the ray: the centre lies h(-u) behind the visible side, a size error dsize moves it
    // by J dsize. With fewer than two silhouette ends the extent across the ray is needed too
    // (below): both directions' derivatives at once (the same values as one at a time).
    const Eigen::Vector2d w(-u.y(), u.x());
    Eigen::Vector2d j_radial, j_across = Eigen::Vector2d::Zero();
    if (edges < 2) {
      ExtentJacobians(shape, -u, w, &j_radial, &j_across);
    } else {
      j_radial = ExtentJacobian(shape, -u);
    }
    const double radial_var = j_radial.dot(size_cov * j_radial) + bias_sigma_m * bias_sigma_m;
    // Across: each silhouette end lies uniformly within one beam step of its last returning beam,
    // variance (R step)^2 / 12, shared by the scans of a track while it moves less than a beam
    // spacing across the ray; the centre is the mean of the two ends (half that variance). With
    // one end or none a silhouette, the centre lies the body's extent across from what is seen:
    // the size's error moves it across too.
    const double width_m = range_m * step_rad;
    double across_var = o.centre_bias_across_sigma_m * o.centre_bias_across_sigma_m +
                        width_m * width_m / (12.0 * std::max(1, edges));
    if (edges < 2) across_var += j_across.dot(size_cov * j_across);
    const Eigen::Matrix2d along = u * u.transpose();
    return radial_var * along + across_var * (Eigen::Matrix2d::Identity() - along);
  }

 private:
  void Init(const Observation& ob, common::UtcNs at_ns, TrackShape& shape) const {
    const ShapeOptions& o = p_.options_.shape;
    shape = TrackShape{};
    if (ob.legs) {
      shape.shape = ObjectShape::kLegs;
      shape.model = ShapeModel::kCircle;
      shape.size_m = Eigen::Vector2d(o.leg_radius_m, o.leg_radius_m);
      shape.size_cov_m2 = o.leg_radius_sigma_m * o.leg_radius_sigma_m * Eigen::Matrix2d::Identity();
    } else {
      shape.shape = ObjectShape::kTorso;
      shape.model = ShapeModel::kSuperellipse;
      shape.exponent = o.person_exponent;
      shape.size_m = Eigen::Vector2d(o.person_major_m, o.person_minor_m);
      shape.size_cov_m2 =
          o.person_size_sigma_m * o.person_size_sigma_m * Eigen::Matrix2d::Identity();
    }
    shape.stamp_ns = at_ns;
  }

  // The distance from measurement `source` to the nearest other one of the scan (infinite: none).
  double NearestOtherM(std::size_t source) {
    if (source >= p_.measurements_.size()) return std::numeric_limits<double>::infinity();
    if (nearest_step_ != scans) NearestOthers();
    return std::sqrt(nearest_m2_[source]);
  }

  // Per measurement of the scan, the squared distance to the nearest other one (ShapeOptions::
  // neighbour_sigma_m), once per scan for all of them rather than once per refinement
  // (internal::NearestOtherSquares, from copies of the positions in x and y arrays).
  void NearestOthers() {
    const std::span<const Measurement> m = p_.measurements_.span();
    const std::size_t n = m.size();
    for (std::size_t i = 0; i < n; ++i) {
      nearest_x_m_[i] = m[i].position_m.x();
      nearest_y_m_[i] = m[i].position_m.y();
      nearest_m2_[i] = std::numeric_limits<double>::infinity();
    }
    internal::NearestOtherSquares(std::span<const double>(nearest_x_m_.data(), n),
                                  std::span<const double>(nearest_y_m_.data(), n),
                                  std::span<double>(nearest_m2_.data(), n));
    nearest_step_ = scans;
  }

  // internal::SuperellipseReachFactor(exponent), the pow only where the exponent differs from the
  // last one asked (the same value: one pow per exponent rather than one per fit).
  double ReachFactor(double exponent) {
    if (!(exponent == reach_exponent_)) {
      reach_exponent_ = exponent;
      reach_factor_ = internal::SuperellipseReachFactor(exponent);
    }
    return reach_factor_;
  }

  void CountEvaluations(const ShapeFitResult& fit) {
    const auto bin = std::min<std::size_t>(static_cast<std::size_t>(std::max(0, fit.evaluations)),
                                           evaluations_.size() - 1);
    ++evaluations_[bin];
  }

  std::span<const Eigen::Vector2d> Points(const ObservationPart& part) const {
    return p_.segments_.points_m.span().subspan(part.first_point, part.point_count);
  }

  // The part's points whose range the fit can use: without its mixed edge points
  // (ShapeOptions::mixed_pixel_min_footprint_m); where those are all there is, the nearest of them
  // (a mixed pixel lies behind the body, the nearest the least).
  std::span<const Eigen::Vector2d> ReliablePoints(const ObservationPart& part) const {
    const std::span<const Eigen::Vector2d> all = Points(part);
    const std::size_t drop_first = part.first_mixed ? 1 : 0;
    const std::size_t drop_last = part.last_mixed && all.size() > drop_first ? 1 : 0;
    if (all.size() > drop_first + drop_last) {
      return all.subspan(drop_first, all.size() - drop_first - drop_last);
    }
    if (all.empty() || drop_first + drop_last == 0) return all;
    const std::size_t nearest = all.size() > 1 && all[1].norm() < all[0].norm() ? 1 : 0;
    return all.subspan(nearest, 1);
  }

  bool RefineBody(const Observation& ob, const Eigen::Vector4d* predicted,
                  const Eigen::Matrix4d* predicted_cov, TrackShape& shape, Measurement& m) {
    const ShapeOptions& o = p_.options_.shape;
    body_fit_reduced_ = false;
    if (shape.model == ShapeModel::kSuperellipse && shape.size_m.x() > o.box_min_half_length_m) {
      // A cart: from now on its outline is a rectangle, whose depth the person prior does not know.
      shape.model = ShapeModel::kBox;
      const double box_var = o.box_size_sigma_m * o.box_size_sigma_m;
      shape.size_cov_m2(0, 0) = std::max(shape.size_cov_m2(0, 0), box_var);
      shape.size_cov_m2(1, 1) = std::max(shape.size_cov_m2(1, 1), box_var);
    }
    if (shape.model == ShapeModel::kSuperellipse && shape.updates >= kMinCylinderUpdates &&
        shape.size_m.x() - shape.size_m.y() < kCylinderAxisShare * shape.size_m.x()) {
      shape.exponent = 2.0;  // round: a cylinder
    }
    ShapePrior prior;
    prior.model = shape.model;
    prior.exponent = shape.exponent;
    prior.size_m = shape.size_m;
    prior.size_cov_m2 = shape.size_cov_m2;
    prior.yaw_rad = shape.yaw_rad;
    prior.yaw_sigma_rad = shape.yaw_sigma_rad;
    if (predicted != nullptr) {
      prior.centre_guess_m = predicted->head<2>();
      const Eigen::Vector2d v = predicted->tail<2>();
      const double speed = v.norm();
      if (speed > o.walking_speed_mps) {
        // Facing the walking direction: shoulders across it, a cart's length along it.
        const double heading = std::atan2(v.y(), v.x());
        prior.yaw_rad = shape.model == ShapeModel::kBox ? heading : heading + common::kPi / 2;
        double direction_sigma = 0.0;
        if (predicted_cov != nullptr) {
          const Eigen::Matrix2d vc = predicted_cov->bottomRightCorner<2, 2>();
          direction_sigma = std::sqrt(std::max(0.0, 0.5 * vc.trace())) / speed;
        }
        // The root of the sum of squares (within an ulp of hypot; no overflow at these sizes).
        prior.yaw_sigma_rad = std::sqrt(o.walking_yaw_sigma_rad * o.walking_yaw_sigma_rad +
                                        direction_sigma * direction_sigma);
      }
    }
    const ObservationPart& part = ob.parts[0];
    std::span<const Eigen::Vector2d> points = ReliablePoints(part);
    Silhouette silhouette = part.silhouette;
    const bool occluders = shape.model == ShapeModel::kBox && o.box_drop_occluders;
    bool occluded = false;
    if (occluders && predicted != nullptr && predicted_cov != nullptr) {
      // ShapeOptions::box_drop_occluders: first against the predicted box (its near face is what
      // the track's measurements put there), widened by the prediction's sigma along the ray.
      const Eigen::Vector2d c = predicted->head<2>();
      const double range = c.norm();
      const double along_var =
          range > 0.0 ? (c / range).dot(predicted_cov->topLeftCorner<2, 2>() * (c / range)) : 0.0;
      const std::size_t kept =
          internal::BoxUnoccludedPoints(o, c, shape.size_m, prior.yaw_rad, points, kept_points_,
                                        &silhouette, kOccluderSigmas * std::sqrt(along_var));
      if (kept >= 2 && kept < std::min(points.size(), kMaxSegmentPoints)) {
        points = std::span<const Eigen::Vector2d>(kept_points_.data(), kept);
        occluded = true;
      } else {
        silhouette = part.silhouette;
      }
    }
    if (shape.model == ShapeModel::kSuperellipse && o.mount == Mount::kTorso &&
        o.person_drop_beyond_reach && predicted != nullptr && predicted_cov != nullptr) {
      // ShapeOptions::person_drop_beyond_reach.
      const Eigen::Vector2d reach_size =
          shape.size_m + 2.0 * Eigen::Vector2d(std::sqrt(std::max(0.0, shape.size_cov_m2(0, 0))),
                                               std::sqrt(std::max(0.0, shape.size_cov_m2(1, 1))));
      const std::size_t kept = internal::PersonReachablePoints(
          o, predicted->head<2>(), predicted_cov->topLeftCorner<2, 2>(),
          std::max(reach_size.x(), reach_size.y()) * ReachFactor(shape.exponent), points,
          part.silhouette.step_rad *
              (p_.scan_ != nullptr && p_.scan_->angle_step_rad < 0 ? -1.0 : 1.0),
          kept_points_, &silhouette);
      // Points beyond kMaxSegmentPoints are not taken by the fit either: only a shorter count
      // left something out.
      if (kept < std::min(points.size(), kMaxSegmentPoints)) {
        points = std::span<const Eigen::Vector2d>(kept_points_.data(), kept);
        ++person_beyond_reach;
        body_fit_reduced_ = true;
        body_fit_points_ = kept;
        body_fit_edges_ = (silhouette.first_valid ? 1 : 0) + (silhouette.last_valid ? 1 : 0);
      }
    }
    ShapeFitResult fit = FitShape(points, silhouette, prior, o.fit);
    CountEvaluations(fit);
    if (!fit.ok) {
      ++failed;
      return false;
    }
    ++fits;
    // The points and silhouette of the fit kept (ShapeOptions::box_seen_extent_cov).
    std::span<const Eigen::Vector2d> fit_points = points;
    Silhouette fit_silhouette = silhouette;
    if (occluders) {
      // ... then against the fitted one: the points in front of it are another object's (its
      // pusher); the box refitted without them, behind an occluder's edge there.
      Silhouette refit_silhouette = silhouette;
      const std::size_t kept = internal::BoxUnoccludedPoints(
          o, fit.centre_m, fit.size_m, fit.yaw_rad, points, kept_points_, &refit_silhouette, 0.0);
      if (kept >= 2 && kept < std::min(points.size(), kMaxSegmentPoints)) {
        const ShapeFitResult refit =
            FitShape(std::span<const Eigen::Vector2d>(kept_points_.data(), kept), refit_silhouette,
                     prior, o.fit);
        CountEvaluations(refit);
        if (refit.ok) {
          fit = refit;
          occluded = true;
          fit_points = std::span<const Eigen::Vector2d>(kept_points_.data(), kept);
          fit_silhouette = refit_silhouette;
        }
      }
    }
    if (occluded) ++box_occluded;
    if (shape.model == ShapeModel::kBox && o.box_seen_extent_cov) {
      // ShapeOptions::box_seen_extent_cov: what this view shows of each semi-axis.
      const Eigen::Vector2d half = internal::BoxHalfExtents(fit_points, fit.yaw_rad);
      shape.box_seen_half_m = shape.box_seen_half_m.cwiseMax(half);
      // At knee height a cart's outline is its castors' and legs', not its faces: no view shows a
      // face whole there.
      if (o.mount == Mount::kTorso && fit_silhouette.first_valid && fit_silhouette.last_valid) {
        // The faces as far as the points show them, not as far as the fit's size would: a yaw
        // a little off makes the learned length seem to show beside an end seen head-on.
        const std::array<bool, 2> shown = internal::BoxFacesShown(
            fit.centre_m, half, fit.yaw_rad, std::abs(part.silhouette.step_rad));
        for (int k = 0; k < 2; ++k) {
          if (!shown[static_cast<std::size_t>(k)] || !(half(k) > 0.0)) continue;
          if (!(shape.box_whole_half_m(k) > 0.0)) ++box_bounded;
          shape.box_whole_half_m(k) = half(k);
        }
      }
    }
    m.position_m = fit.centre_m;
    m.covariance_m2 = fit.centre_cov_m2;
    m.orientation_rad = fit.yaw_rad;
    m.rms_residual_m = fit.rms_m;
    m.point_count = part.point_count;
    Eigen::Vector2d size = fit.size_m;
    Eigen::Matrix2d size_cov = fit.size_cov_m2;
    double yaw = fit.yaw_rad;
    if (shape.model == ShapeModel::kSuperellipse && size.x() < size.y()) {
      // The same ellipse with a the larger semi-axis.
      std::swap(size.x(), size.y());
      std::swap(size_cov(0, 0), size_cov(1, 1));
      yaw += common::kPi / 2;
    }
    // Size learning. Only where the orientation is known: without it, what the outline shows cannot
    // be told apart into size and orientation. And only a share kSizeLearningShare of what the scan
    // says: model errors of successive scans are alike, not independent.
    // ShapeOptions::person_size_min_points.
    const bool enough_points =
        shape.model != ShapeModel::kSuperellipse || fit.points_used >= o.person_size_min_points;
    if (!enough_points) ++person_size_kept;
    if (enough_points &&
        (prior.yaw_sigma_rad < kMaxLearningYawSigmaRad || shape.model == ShapeModel::kBox)) {
      std::array<bool, 2> shown = {true, true};
      if (shape.model == ShapeModel::kBox &&
          (o.box_size_from_faces_seen ||
           (o.mount == Mount::kLegs && o.box_size_from_faces_seen_at_knee))) {
        // ShapeOptions::box_size_from_faces_seen(_at_knee).
        shown = internal::BoxFacesShown(fit.centre_m, size, yaw, part.silhouette.step_rad);
        if (!shown[0] || !shown[1]) ++box_unseen_sizes;
      }
      if (shape.model == ShapeModel::kSuperellipse && o.mount == Mount::kTorso &&
          o.person_size_across_ray) {
        // ShapeOptions::person_size_across_ray.
        internal::LearnSizeWeighted(size, size_cov, kSizeLearningShare,
                                    internal::PersonAxisWeights(fit.centre_m, yaw), shape);
        ++person_across_ray;
      } else {
        LearnSize(size, size_cov, shape, shown);
      }
    }
    shape.yaw_rad = common::RemainderHalfTurn(yaw);  // std::remainder(yaw, pi), bit for bit
    shape.yaw_sigma_rad = fit.yaw_sigma_rad;
    shape.shape = shape.model == ShapeModel::kBox ? ObjectShape::kBox
                  : shape.exponent == 2.0         ? ObjectShape::kCylinder
                                                  : ObjectShape::kTorso;
    // Flatness: the points' distance to their principal line beyond the range noise. Evidence only
    // where the points can tell a person from a board: a person's back over this extent would stand
    // out of the range noise (far away, a few points of a back are as straight as a board's).
    const double range = fit.centre_m.norm();
    const double noise = o.fit.point_sigma_m + o.fit.point_sigma_per_m * range;
    if (fit.extent_m >= o.flat_min_extent_m && fit.points_used >= kMinFlatnessPoints &&
        internal::PersonBackLineRmsAbove(o, fit.extent_m, noise)) {
      const double v = fit.line_rms_m * fit.line_rms_m - noise * noise;
      shape.flatness_m2 += (v - shape.flatness_m2) /
                           std::min(kFlatnessMemory, static_cast<double>(++flat_count(shape)));
    }
    shape.person_like =
        flat_count(shape) < kMinFlatnessUpdates || shape.flatness_m2 > o.flat_rms_m * o.flat_rms_m;
    return true;
  }

  bool RefineLegs(std::size_t source, const Observation& ob, common::UtcNs at_ns,
                  const Eigen::Vector4d* predicted, const Eigen::Matrix4d* predicted_cov,
                  TrackShape& shape, Measurement& m) {
    const ShapeOptions& o = p_.options_.shape;
    std::array<ShapeFitResult, 2> legs;
    // ShapeOptions::walking_legs_cov: set below for a walking pair; any other update after one
    // starts the reported covariance again from the filter's.
    shape.reported_gait_m2 = 0.0F;
    m.gain_walking = false;
    m.gain_restart = shape.walking_relieved;
    shape.walking_relieved = false;
    std::size_t points = 0;
    ShapePrior prior;
    prior.model = ShapeModel::kCircle;
    prior.size_m = shape.size_m;
    prior.size_cov_m2 = shape.size_cov_m2;
    for (std::size_t k = 0; k < ob.part_count; ++k) {
      legs[k] = FitShape(Points(ob.parts[k]), ob.parts[k].silhouette, prior, o.fit);
      CountEvaluations(legs[k]);
      points += ob.parts[k].point_count;
      if (!legs[k].ok) {
        ++failed;
        return false;
      }
      ++fits;
      const ObservationPart& part = ob.parts[k];
      const double mixed_range = part.mixed_leg_centre_m.norm();
      if (part.mixed_leg_along_var_m2 > 0.0 && mixed_range > 0.0) {
        // ShapeOptions::mixed_leg_max_gap_m: the points are mixed pixels behind the leg; its
        // centre from their range deficits, along the ray as uncertain as that estimate.
        const Eigen::Vector2d ray = part.mixed_leg_centre_m / mixed_range;
        legs[k].centre_m = part.mixed_leg_centre_m;
        legs[k].centre_cov_m2 += part.mixed_leg_along_var_m2 * ray * ray.transpose();
        ++mixed_legs;
      }
    }
    m.point_count = points;
    m.orientation_rad = 0.0;
    if (source < leg_radius.size()) {
      leg_radius[source] = {legs[0].size_m.x(), ob.part_count == 2 ? legs[1].size_m.x() : 0.0};
      leg_centre[source] = {legs[0].centre_m,
                            ob.part_count == 2 ? legs[1].centre_m : Eigen::Vector2d::Zero()};
    }
    const double prior_info = 1.0 / std::max(shape.size_cov_m2(0, 0), 1e-12);
    if (ob.part_count == 2) {
      const std::array<Eigen::Vector2d, 2> now{legs[0].centre_m, legs[1].centre_m};
      const std::array<double, 2> now_var{0.5 * legs[0].centre_cov_m2.trace(),
                                          0.5 * legs[1].centre_cov_m2.trace()};
      internal::StanceCentre centre;
      centre.centre_m = 0.5 * (now[0] + now[1]);
      // ShapeOptions::stance_leg_weight: a walking track's standing leg weighs more.
      Eigen::Vector2d forward;
      const double legs_dt_s = common::NsToSeconds(at_ns - shape.legs_ns);
      const bool walking = WalkingDirection(predicted, predicted_cov, &forward);
      if (shape.legs_ns != 0 && walking) {
        centre = internal::StanceWeightedCentre(o, forward, now, now_var, shape.legs_m,
                                                shape.legs_var_m2, legs_dt_s,
                                                predicted->tail<2>().norm() * legs_dt_s);
        if (centre.standing >= 0) ++stance_weighted;
      }
      // ShapeOptions::still_legs_cov: a standing track's legs where they stood, nothing else
      // within the pairing reach.
      const bool still =
          o.still_legs_cov && shape.legs_ns != 0 && predicted != nullptr &&
          predicted->tail<2>().norm() <= o.still_legs_max_speed_mps &&
          internal::LegsStill(o, now, now_var, shape.legs_m, shape.legs_var_m2, legs_dt_s) &&
          NearestOtherM(source) > o.leg_pairing_distance_m;
      // ShapeOptions::single_leg_from_standing: the standing leg, where at least half sure.
      shape.legs_standing = -1;
      if (centre.standing >= 0 && o.stance_leg_weight > 0.5 &&
          centre.weight - 0.5 >= 0.5 * (o.stance_leg_weight - 0.5)) {
        shape.legs_standing = centre.standing;
      }
      // ShapeOptions::still_legs_max_depth_m: a still track's legs one behind the other along the
      // ray, deeper than a standing person's; a walking track's pairs count as not deep (the
      // share is of its recent two-leg measurements, a stride may stand deep along the ray).
      Eigen::Vector2d walk;
      const Eigen::Vector2d mid = 0.5 * (now[0] + now[1]);
      if (o.still_legs_max_depth_m > 0.0 && predicted != nullptr && predicted_cov != nullptr &&
          mid.norm() > 0.0) {
        double deep = 0.0;
        if (!WalkingDirection(predicted, predicted_cov, &walk)) {
          const double depth = std::abs((now[1] - now[0]).dot(mid / mid.norm()));
          const std::size_t nearer = now[0].norm() <= now[1].norm() ? 0 : 1;
          if (depth > o.still_legs_max_depth_m && ob.parts[nearer].point_count == 1) deep = 1.0;
        }
        shape.still_deep_pair_share +=
            (deep - shape.still_deep_pair_share) /
            std::min(kFlatnessMemory, static_cast<double>(++shape.still_pair_updates));
      }
      shape.legs_m = now;
      shape.legs_var_m2 = now_var;
      shape.legs_ns = at_ns;
      m.position_m = centre.centre_m;
      m.covariance_m2 = centre.m[0] * legs[0].centre_cov_m2 * centre.m[0].transpose() +
                        centre.m[1] * legs[1].centre_cov_m2 * centre.m[1].transpose() +
                        o.gait_sigma_m * o.gait_sigma_m * Eigen::Matrix2d::Identity();
      // ShapeOptions::still_legs_cov: of the gait and the centre model's allowance (added with
      // the refinement) the feet's stance is left; the filter's R stays.
      m.gain_still = still;
      m.gain_relief_m2.setZero();
      if (still) {
        m.gain_relief_m2 =
            (o.gait_sigma_m * o.gait_sigma_m + o.centre_model_sigma_m * o.centre_model_sigma_m -
             o.still_legs_sigma_m * o.still_legs_sigma_m) *
            Eigen::Matrix2d::Identity();
        ++still_legs;
      } else if (o.walking_legs_cov && walking &&
                 NearestOtherM(source) > o.leg_pairing_distance_m + 2.0 * o.hip_half_width_m) {
        // ShapeOptions::walking_legs_cov: the gait's offset is shared by successive scans, not
        // noise the gains average: out of the gain covariance's R, into the report.
        m.gain_relief_m2 = o.gait_sigma_m * o.gait_sigma_m * Eigen::Matrix2d::Identity();
        m.gain_walking = true;
        m.gain_restart = false;
        shape.reported_gait_m2 =
            static_cast<float>(o.walking_legs_sigma_m * o.walking_legs_sigma_m);
        shape.walking_relieved = true;
      }
      m.rms_residual_m = std::max(legs[0].rms_m, legs[1].rms_m);
      const double range = m.position_m.norm();
      if (ob.deep_pair && range > 0.0) {
        // ShapeOptions::deep_legs_as_pair: what lies behind the nearer leg may be echoes mixed
        // between the two legs, nearer than the far leg: the midpoint anywhere within half the
        // parts' depth apart along the ray.
        const Eigen::Vector2d ray = m.position_m / range;
        const double depth = std::abs((legs[1].centre_m - legs[0].centre_m).dot(ray));
        m.covariance_m2 += (0.25 * depth * depth) * ray * ray.transpose();
      }
      // ShapeOptions::touching_legs_along_ray: touching legs, the farther cut by the nearer's
      // occluding edge, its centre known along the ray to within a leg's diameter.
      const double touching_var =
          internal::TouchingLegsAlongRayVar(o, ob.parts[0], ob.parts[1], ob.deep_pair);
      if (touching_var > 0.0 && range > 0.0) {
        const Eigen::Vector2d ray = m.position_m / range;
        m.covariance_m2 += touching_var * ray * ray.transpose();
        ++touching;
      }
      // Both legs measured the same radius, each with the track's prior: count the prior once.
      const double i0 = 1.0 / std::max(legs[0].size_cov_m2(0, 0), 1e-12);
      const double i1 = 1.0 / std::max(legs[1].size_cov_m2(0, 0), 1e-12);
      const double info = std::max(prior_info, i0 + i1 - prior_info);
      const double radius =
          (i0 * legs[0].size_m.x() + i1 * legs[1].size_m.x() - prior_info * shape.size_m.x()) /
          std::max(1e-12, i0 + i1 - prior_info);
      shape.size_m = Eigen::Vector2d::Constant(std::isfinite(radius) ? radius : shape.size_m.x());
      shape.size_cov_m2 = Eigen::Matrix2d::Constant(1.0 / info);
    } else {
      m.position_m = legs[0].centre_m;
      const double range = legs[0].centre_m.norm();
      WalkSide side;
      if (ob.partner_behind && range > 0.0) {
        // The other leg hidden behind it (ShapeOptions::hidden_leg_behind): the centre, the legs'
        // midpoint, at least hip_half_width_m farther along the line of sight; the hidden leg
        // within the shadow, +-leg_radius_m across it (the midpoint +-leg_radius_m / 2: variance
        // leg_radius_m^2 / 12 for a uniform place), and the midpoint's swing as for two legs.
        const Eigen::Vector2d ray = legs[0].centre_m / range;
        const Eigen::Vector2d across(-ray.y(), ray.x());
        m.position_m += o.hip_half_width_m * ray;
        m.covariance_m2 = legs[0].centre_cov_m2 +
                          o.gait_sigma_m * o.gait_sigma_m * Eigen::Matrix2d::Identity() +
                          (o.leg_radius_m * o.leg_radius_m / 12.0) * across * across.transpose();
      } else if (WalkingSide(predicted, predicted_cov, legs[0].centre_m, legs[0].centre_cov_m2,
                             side)) {
        // One leg of a walking track (ShapeOptions::single_leg_across_walk): the centre
        // hip_half_width_m across the walk from it, on the side WalkingSide found: the side the
        // scan shows (single_leg_side_from_view: sure, only the sway and hip width, gait_sigma_m,
        // across the walk) or else the side the prediction lies (gait_sigma_m, and with
        // single_leg_side_uncertainty the other side's share 2 hip^2 (1 - w), which vanishes as
        // the weight w nears 1); ahead or behind it by a stride phase that successive scans share:
        // within the legs' reach along the walk.
        const Eigen::Vector2d left = side.towards_centre;
        const Eigen::Vector2d forward(left.y(), -left.x());
        const double hip = o.hip_half_width_m;
        m.position_m += hip * left;
        const double reach = 0.5 * o.leg_pairing_distance_m;
        double across2 = o.gait_sigma_m * o.gait_sigma_m;
        if (o.single_leg_side_uncertainty && !side.sure) {
          across2 += internal::SingleLegOtherSideVar(hip, side.weight);
          if (side.weight < kSideKnownWeight) ++side_uncertain;
        }
        m.covariance_m2 = legs[0].centre_cov_m2 + reach * reach * forward * forward.transpose() +
                          across2 * left * left.transpose();
        // ShapeOptions::single_leg_from_standing: the hidden leg stood at the last two-leg
        // measurement and stands still; the seen one is the other (its side across the walk).
        const double since_s = common::NsToSeconds(at_ns - shape.legs_ns);
        if (o.single_leg_from_standing && shape.legs_ns != 0 && shape.legs_standing >= 0 &&
            since_s > 0.0 && since_s <= o.standing_leg_memory_s) {
          // The seen leg lies opposite the centre: the remembered leg farther against `left`.
          const int seen = shape.legs_m[0].dot(left) < shape.legs_m[1].dot(left) ? 0 : 1;
          if (seen != shape.legs_standing) {
            const Eigen::Vector2d v = predicted->tail<2>();
            const Eigen::Vector2d walk = v / v.norm();
            double along2 = 0.0;
            const Eigen::Vector2d centre = internal::LoneLegCentreFromStanding(
                o, walk, v, legs[0].centre_m, 0.0, shape.legs_m[shape.legs_standing],
                shape.legs_var_m2[shape.legs_standing], since_s, &along2);
            m.position_m += (centre - legs[0].centre_m).dot(walk) * walk;
            // The seen leg's fit enters along the walk with 1 - stance_leg_weight, across it
            // whole.
            const Eigen::Vector2d side_of_walk(-walk.y(), walk.x());
            const Eigen::Matrix2d j = (1.0 - o.stance_leg_weight) * walk * walk.transpose() +
                                      side_of_walk * side_of_walk.transpose();
            m.covariance_m2 = j * legs[0].centre_cov_m2 * j.transpose() +
                              along2 * walk * walk.transpose() + across2 * left * left.transpose();
            ++along_from_standing;
          }
        }
        ++across_walk;
      } else {
        // One leg: the body centre lies beside it (the hip) and ahead or behind (the stride).
        const double extent2 =
            o.hip_half_width_m * o.hip_half_width_m + 4.0 * o.gait_sigma_m * o.gait_sigma_m;
        m.covariance_m2 = legs[0].centre_cov_m2 + extent2 * Eigen::Matrix2d::Identity();
      }
      m.rms_residual_m = legs[0].rms_m;
      shape.size_m = legs[0].size_m;
      shape.size_cov_m2 = legs[0].size_cov_m2;
    }
    shape.shape = ObjectShape::kLegs;
    ++flat_count(shape);
    shape.person_like =
        (flat_count(shape) < kMinFlatnessUpdates ||
         shape.size_m.x() >= o.person_min_leg_radius_m) &&
        !(shape.still_pair_updates >= kMinFlatnessUpdates && shape.still_deep_pair_share > 0.5);
    return true;
  }

  // Whether a track predicted at `predicted` walks (speed at least walking_speed_mps and twice its
  // sigma); then *forward is the unit walking direction.
  bool WalkingDirection(const Eigen::Vector4d* predicted, const Eigen::Matrix4d* predicted_cov,
                        Eigen::Vector2d* forward) const {
    if (predicted == nullptr || predicted_cov == nullptr) return false;
    const Eigen::Vector2d v = predicted->tail<2>();
    const double speed = v.norm();
    const double speed_sigma = std::sqrt(0.5 * predicted_cov->bottomRightCorner<2, 2>().trace());
    if (!(speed >= p_.options_.shape.walking_speed_mps && speed >= 2.0 * speed_sigma)) return false;
    *forward = v / speed;
    return true;
  }

  // WalkingSide's answer: the unit vector across the walk from the leg towards the centre, the
  // weight w = 2 q - 1 of that side (internal::SingleLegSideWeight) and whether the side is sure
  // (taken from the scan: nothing of the other side added).
  struct WalkSide {
    Eigen::Vector2d towards_centre = Eigen::Vector2d::Zero();
    double weight = 0.0;
    bool sure = false;
  };

  // ShapeOptions::single_leg_across_walk: whether a track predicted at `predicted` walks (speed at
  // least walking_speed_mps and twice its sigma) with the side of its centre across the walk known
  // for the leg at `leg_m` (fit covariance `leg_cov`). The side: with single_leg_side_from_view,
  // the one the scan leaves for the other leg (every place on the other side seen through; sure),
  // or where the prediction is confident (weight at least kSideKnownWeight) of the opposite side,
  // the same side not sure (weight 0, counted in view_contested); else the side the predicted
  // centre lies on when it is more than hip_half_width_m / 2 from the leg across the walk, its
  // weight from the predicted centre's offset against its variance across the walk (the
  // prediction's, the leg fit's and the sway's).
  bool WalkingSide(const Eigen::Vector4d* predicted, const Eigen::Matrix4d* predicted_cov,
                   const Eigen::Vector2d& leg_m, const Eigen::Matrix2d& leg_cov, WalkSide& out) {
    const ShapeOptions& o = p_.options_.shape;
    Eigen::Vector2d forward;
    if (!o.single_leg_across_walk || !WalkingDirection(predicted, predicted_cov, &forward)) {
      return false;
    }
    const Eigen::Vector2d left(-forward.y(), forward.x());
    const double hip = o.hip_half_width_m;
    const double offset = (predicted->head<2>() - leg_m).dot(left);
    const bool predicted_side = std::abs(offset) > 0.5 * hip;
    const double s2 = left.dot(predicted_cov->topLeftCorner<2, 2>() * left) +
                      left.dot(leg_cov * left) + o.gait_sigma_m * o.gait_sigma_m;
    const double weight = internal::SingleLegSideWeight(hip, offset, s2);
    if (o.single_leg_side_from_view && p_.scan_ != nullptr) {
      const int view = SideFromView(leg_m, left);  // +1 left, -1 right, 0 unknown
      if (view != 0) {
        out.towards_centre = view > 0 ? left : Eigen::Vector2d(-left);
        if (predicted_side && weight >= kSideKnownWeight && (offset > 0.0) != (view > 0)) {
          // A confident prediction against the view: the two disagree, neither side is sure.
          // The prediction's confidence grows from its own past sides (a track that took the
          // wrong side once keeps being fed measurements there), the view is each scan's own: its
          // side, with the other side's whole share (w = 0).
          out.weight = 0.0;
          out.sure = false;
          ++view_contested;
        } else {
          out.weight = 1.0;
          out.sure = true;
          ++side_from_view;
        }
        return true;
      }
    }
    if (!predicted_side) return false;
    out.towards_centre = offset > 0.0 ? left : Eigen::Vector2d(-left);
    out.weight = weight;
    out.sure = false;
    return true;
  }

  // ShapeOptions::single_leg_side_from_view: the side of the leg at `leg_m` across the walk
  // (`left` its unit vector) the other leg, and so the centre, stands on as the scan shows it: +1
  // along `left`, -1 against it, 0 unknown. The other leg stands 2 hip_half_width_m across the walk
  // within the legs' reach along it, at places a_i = -reach + i (2 reach / n), i = 0..n,
  // n = min(kMaxSidePlaces, ceil(2 reach / leg_radius_m)); a side is open when every place there is
  // seen through (OtherLegSeenThrough); exactly one side open: the centre is on the other.
  int SideFromView(const Eigen::Vector2d& leg_m, const Eigen::Vector2d& left) const {
    const ShapeOptions& o = p_.options_.shape;
    const ScanView& scan = *p_.scan_;
    const double span = 2.0 * o.hip_half_width_m;
    const double reach = 0.5 * o.leg_pairing_distance_m;
    const Eigen::Vector2d fwd(left.y(), -left.x());
    const double footprint = std::max(std::abs(scan.angle_step_rad), o.beam_divergence_rad);
    // A side can be open only where a leg at its farthest place (an end of the places' segment:
    // the range is convex along it) would have returned a beam: beams there closer than a leg.
    const auto may_open = [&](double s) {
      const Eigen::Vector2d c = leg_m + s * span * left;
      const double far = std::max((c - reach * fwd).norm(), (c + reach * fwd).norm());
      return far * footprint < 2.0 * o.leg_radius_m;
    };
    const bool may_left = may_open(1.0);
    const bool may_right = may_open(-1.0);
    if (!may_left && !may_right) return 0;
    const int n = std::min(
        kMaxSidePlaces,
        std::max(1, static_cast<int>(std::ceil(2.0 * reach / std::max(o.leg_radius_m, 1e-3)))));
    const double step = 2.0 * reach / n;
    // Every place on the side seen through; stops at the first that is not.
    const auto open = [&](double s) {
      const Eigen::Vector2d c = leg_m + s * span * left;
      for (int i = 0; i <= n; ++i) {
        if (!p_.OtherLegSeenThrough(scan, c + (-reach + i * step) * fwd)) return false;
      }
      return true;
    };
    // Exactly one side open decides: the first side's answer leaves the second to be checked
    // either way (open where the first is closed, closed where it is open).
    const bool left_open = may_left && open(1.0);
    const bool right_open = may_right && open(-1.0);
    if (left_open == right_open) return 0;
    return left_open ? -1 : 1;
  }

  static void LearnSize(const Eigen::Vector2d& size, const Eigen::Matrix2d& size_cov,
                        TrackShape& shape, const std::array<bool, 2>& shown = {true, true}) {
    internal::LearnSize(size, size_cov, kSizeLearningShare, shown, shape);
  }

  // Updates that carried flatness evidence (kept in the state's spare counter: updates counts all).
  static std::uint32_t& flat_count(TrackShape& shape) { return shape.evidence_updates; }

  const TrackingPipeline& p_;
  std::span<std::uint64_t> evaluations_;
  // ShapeOptions::box_drop_occluders: a box's points without those in front of it.
  std::array<Eigen::Vector2d, kMaxSegmentPoints> kept_points_{};
  // The last RefineBody's fit without a run beyond the person's reach
  // (ShapeOptions::person_drop_beyond_reach): its points and silhouette ends.
  bool body_fit_reduced_ = false;
  std::size_t body_fit_points_ = 0;
  int body_fit_edges_ = 0;
  // internal::SuperellipseReachFactor of the last exponent asked (ReachFactor): a track's exponent
  // changes seldom, a pow per fit cost more than the rest of the reach test.
  double reach_exponent_ = std::numeric_limits<double>::quiet_NaN();
  double reach_factor_ = 0.0;
  // NearestOthers' squared distances, valid where nearest_step_ is the current count of scans.
  std::array<double, kMaxSegments> nearest_m2_{};
  std::array<double, kMaxSegments> nearest_x_m_{};  // NearestOthers' copies of the positions
  std::array<double, kMaxSegments> nearest_y_m_{};
  std::uint64_t nearest_step_ = 0;
};

TrackingPipeline::TrackingPipeline(const TrackerOptions& options)
    : options_(Resolved(Checked(options))),
      background_(options.background),
      tracker_(options_.tracking),
      refiner_(std::make_unique<Refiner>(*this, counters_.shape_fit_evaluations)) {
  configured_mixed_leg_max_gap_m_ = options_.shape.mixed_leg_max_gap_m;
}

double ResolvedEchoSeparationM(std::string_view device_name) {
  return device_name.substr(0, 4) == "LMS5" ? 0.5 : 0.0;
}

void TrackingPipeline::SetResolvedEchoSeparation(double resolved_echo_m) {
  options_.shape.mixed_leg_max_gap_m =
      std::isfinite(resolved_echo_m) && resolved_echo_m > 0.0
          ? std::min(configured_mixed_leg_max_gap_m_, resolved_echo_m)
          : configured_mixed_leg_max_gap_m_;
}

TrackingPipeline::~TrackingPipeline() = default;

std::optional<Eigen::Matrix2d> TrackingPipeline::RefinedCovariance(std::size_t observation) const {
  if (observation >= refiner_->refined_cov.size() ||
      refiner_->refined_step[observation] != refiner_->scans) {
    return std::nullopt;
  }
  return refiner_->refined_cov[observation];
}

Eigen::Vector2d TrackingPipeline::LegCentre(std::size_t observation, std::size_t part) const {
  return observation < refiner_->leg_centre.size() && part < 2
             ? refiner_->leg_centre[observation][part]
             : Eigen::Vector2d::Zero();
}

double TrackingPipeline::LegRadius(std::size_t observation, std::size_t part) const {
  return observation < refiner_->leg_radius.size() && part < 2
             ? refiner_->leg_radius[observation][part]
             : 0.0;
}

ObservationPart TrackingPipeline::MakePart(const ScanView& scan, const Segment& segment,
                                           std::size_t first, std::size_t count) const {
  ObservationPart part;
  MakePartIn(scan, segment, first, count, part);
  return part;
}

void TrackingPipeline::MakePartIn(const ScanView& scan, const Segment& segment, std::size_t first,
                                  std::size_t count, ObservationPart& part) const {
  part.first_point = segment.first_point + first;
  part.point_count = count;
  const auto points = segments_.points_m.span().subspan(part.first_point, count);
  // Beams of the part's first and last point (a split part does not start at the segment's).
  const auto beam_of = [&](const Eigen::Vector2d& p) {
    const double k = (std::atan2(p.y(), p.x()) - scan.first_angle_rad) / scan.angle_step_rad;
    return static_cast<std::size_t>(
        std::clamp(std::llround(k), 0LL, static_cast<long long>(scan.range_m.size()) - 1));
  };
  part.begin_beam = first == 0 ? segment.begin_beam : beam_of(points.front());
  part.end_beam =
      first + count == segment.point_count ? segment.end_beam : beam_of(points.back()) + 1;
  Silhouette& s = part.silhouette;
  // The outline's tangent lies between the last beam that returned it and the first that did not:
  // half a step outwards on average, whatever the beam's width. A beam returns the object when at
  // least half of its energy falls on it, i.e. (a symmetric beam on a body wider than the beam)
  // when its centre ray does: the wider beam does not move the tangent inwards. Taking it at the
  // last beam's centre (as this did with the divergence above the step) made every silhouette a
  // step narrower than the body, and the fit learnt sizes ~0.04 m too small and put the centre
  // that much towards the sensor (tracking_benchmark --breakdown: radial mean -0.034 m at torso
  // height; a 0.25 m cylinder learnt as 0.21 x 0.19 m).
  const double step = std::abs(scan.angle_step_rad);
  const double direction = scan.angle_step_rad < 0 ? -1.0 : 1.0;
  s.step_rad = step;
  s.first_edge_rad = scan.EdgeBeforeRad(part.begin_beam);
  s.last_edge_rad = scan.EdgeAfterRad(part.end_beam - 1);
  // Their directions from the segmentation's table of this scan (the same values as the cosine
  // and sine of the angles): the fit then needs no sincos for its edges.
  s.first_edge_unit = segments_.directions.edge_before(part.begin_beam);
  s.last_edge_unit = segments_.directions.edge_after(part.end_beam - 1);
  s.first_edge_unit_known = s.last_edge_unit_known = true;
  // An edge is the outline's when the beam beyond it saw nothing nearer (no echo, the background,
  // something behind): a nearer return is an occluder, and the field of view's end hides the rest.
  // ShapeOptions::receded_background_edge_m: not where the beam returned from the body's range
  // over a background model that holds something nearer there.
  const double receded_m = options_.shape.receded_background_edge_m;
  const auto foreground = background_.foreground();
  const auto background_m = background_.background_range_m();
  const auto clear = [&](std::size_t beam, const Eigen::Vector2d& edge_point) {
    const float r = scan.range_m[beam];
    if (!(std::isfinite(r) && r > 0.0f)) return true;
    const double edge_range = Range(edge_point);
    const double range = static_cast<double>(r);
    if (receded_m > 0.0 && beam < foreground.size() && foreground[beam] == 0 &&
        beam < background_m.size() && background_m[beam] > 0.0f &&
        std::abs(range - edge_range) <= receded_m &&
        range >
            static_cast<double>(background_m[beam]) + options_.shape.receded_background_margin_m) {
      return false;
    }
    return range > edge_range - 0.1;
  };
  s.first_valid = part.begin_beam > 0 && clear(part.begin_beam - 1, points.front());
  s.last_valid = part.end_beam < scan.range_m.size() && clear(part.end_beam, points.back());
  if (options_.shape.mount == Mount::kLegs && options_.shape.leg_edge_in_mixed_beam) {
    // ShapeOptions::leg_edge_in_mixed_beam: a beam beyond the edge that returned from between the
    // part and what lies beyond it is a mixed echo, its range the energy-weighted mean of the two:
    // its share of the part's surface w = (r_beyond - r) / (r_beyond - r_edge), and the tangent
    // within its footprint, (w - 1/2) beam_divergence_rad from its centre towards the part's
    // outside (energy spread evenly across the footprint).
    const std::size_t n = scan.range_m.size();
    const auto in_mixed_beam = [&](bool valid, std::size_t beam, std::size_t beyond,
                                   const Eigen::Vector2d& edge_point, double outside,
                                   double& edge_rad) {
      if (!valid || beam >= n || beyond >= n) return false;
      const double r = static_cast<double>(scan.range_m[beam]);
      const double r_beyond = static_cast<double>(scan.range_m[beyond]);
      const double r_edge = Range(edge_point);
      // One edge within the footprint only where the footprint is narrower than a leg.
      if (!(r_edge * options_.shape.beam_divergence_rad + options_.shape.beam_exit_diameter_m <
            2.0 * options_.shape.leg_radius_m)) {
        return false;
      }
      const double noise =
          3.0 * (options_.shape.fit.point_sigma_m + options_.shape.fit.point_sigma_per_m * r_edge);
      if (!(std::isfinite(r) && std::isfinite(r_beyond) && r > r_edge + noise &&
            r_beyond > r + noise)) {
        return false;
      }
      const double w = std::clamp((r_beyond - r) / (r_beyond - r_edge), 0.0, 1.0);
      edge_rad = scan.BeamAngleRad(beam) + outside * (w - 0.5) * options_.shape.beam_divergence_rad;
      return true;
    };
    part.first_edge_in_mixed_beam =
        part.begin_beam >= 2 &&
        in_mixed_beam(s.first_valid, part.begin_beam - 1, part.begin_beam - 2, points.front(),
                      -direction, s.first_edge_rad);
    part.last_edge_in_mixed_beam = in_mixed_beam(s.last_valid, part.end_beam, part.end_beam + 1,
                                                 points.back(), direction, s.last_edge_rad);
    // An edge moved into its mixed beam: its direction is the fit's to compute.
    if (part.first_edge_in_mixed_beam) s.first_edge_unit_known = false;
    if (part.last_edge_in_mixed_beam) s.last_edge_unit_known = false;
  }
  if (options_.shape.mount == Mount::kLegs) MixedPixelLeg(scan, points, part);
  MarkMixedPixels(scan, points, part);
}

// ShapeOptions::mixed_leg_max_gap_m. Each beam b returns r_b = s_b r_leg + (1 - s_b) f_b (the
// energy-weighted mean of the leg's echo and the surface's behind it), so its deficit
// d_b = f_b - r_b = s_b (f_b - r_leg); summed over the beams, sum(s_b) = 2 leg_radius_m / (r_leg
// step) (a beam profile of unit energy, sampled at the beams' spacing r_leg step, integrated over
// the leg's width) gives sum(d_b) = (f - r_leg) 2 leg_radius_m / (r_leg step), f the d-weighted
// mean of the f_b, solved for r_leg.
// ShapeOptions::mixed_leg_band_variance: a receiver reports an echo under this share of the beam's
// energy not at all (the other echo alone), as ShapeOptions::deep_mixed_pixel_behind_ratio.
constexpr double kMixedPixelMinorShare = 0.2;
void TrackingPipeline::MixedPixelLeg(const ScanView& scan, std::span<const Eigen::Vector2d> points,
                                     ObservationPart& part) const {
  const ShapeOptions& o = options_.shape;
  if (!(o.mixed_leg_max_gap_m > 0.0) || points.empty() || !background_.learned()) return;
  const double step = std::abs(scan.angle_step_rad);
  double nearest_m = std::numeric_limits<double>::infinity();
  for (const Eigen::Vector2d& p : points) nearest_m = std::min(nearest_m, Range(p));
  // The leg fills no footprint: every beam on it is part leg, part what is behind.
  if (!(nearest_m * o.beam_divergence_rad >= 2.0 * o.leg_radius_m) || !(step > 0.0)) return;
  const double footprint_m = nearest_m * o.beam_divergence_rad + o.beam_exit_diameter_m;
  if (static_cast<double>(part.end_beam - part.begin_beam) >
      std::floor((2.0 * o.leg_radius_m + footprint_m) / (nearest_m * step)) + 1.0) {
    return;  // wider than one leg's beams
  }
  const auto background = background_.background_range_m();
  double deficit_sum = 0.0;
  double behind_sum = 0.0;
  std::size_t returns = 0;
  Eigen::Vector2d bearing = Eigen::Vector2d::Zero();
  for (std::size_t b = part.begin_beam; b < part.end_beam; ++b) {
    if (b >= background.size() || b >= scan.range_m.size()) return;
    const auto r = static_cast<double>(scan.range_m[b]);
    const auto f = static_cast<double>(background[b]);
    if (!(std::isfinite(r) && r > 0.0)) continue;  // a beam without echo within the part
    // Each return must have a learned surface behind it, near enough to mix with.
    if (!(f > r && f - r <= o.mixed_leg_max_gap_m)) return;
    const double d = f - r;
    ++returns;
    deficit_sum += d;
    behind_sum += d * f;
    const double angle = scan.BeamAngleRad(b);
    bearing += d * Eigen::Vector2d(std::cos(angle), std::sin(angle));
  }
  if (!(deficit_sum > 0.0) || !(bearing.norm() > 0.0)) return;
  const double f = behind_sum / deficit_sum;
  // The front of a leg of radius_m that leaves these deficits, never behind the nearest return (a
  // mixed return lies behind the leg).
  const auto front_for = [&](double radius_m) {
    return std::min(f / (1.0 + step * deficit_sum / (2.0 * std::max(radius_m, 1e-3))), nearest_m);
  };
  const double front_m = front_for(o.leg_radius_m);
  const double gap_m = f - front_m;
  const double relative = o.leg_radius_sigma_m / o.leg_radius_m;
  part.mixed_leg_centre_m = (front_m + o.leg_radius_m) * bearing.normalized();
  part.mixed_leg_along_var_m2 = gap_m * gap_m * (relative * relative + 0.01);
  // ShapeOptions::mixed_leg_band_variance: where a beam may return the leg alone, the radius'
  // share is the spread of the fronts one sigma either side of it, each held at the nearest return.
  if (o.mixed_leg_band_variance && returns >= 2 &&
      (1.0 - kMixedPixelMinorShare) * footprint_m <= 2.0 * o.leg_radius_m &&
      front_for(o.leg_radius_m - 2.0 * o.leg_radius_sigma_m) < nearest_m) {
    const double band_m = 0.5 * (front_for(o.leg_radius_m + o.leg_radius_sigma_m) -
                                 front_for(o.leg_radius_m - o.leg_radius_sigma_m));
    part.mixed_leg_along_var_m2 = band_m * band_m + 0.01 * gap_m * gap_m;
  }
}

void TrackingPipeline::MarkMixedPixels(const ScanView& scan,
                                       std::span<const Eigen::Vector2d> points,
                                       ObservationPart& part) const {
  const ShapeOptions& o = options_.shape;
  if (o.mount != Mount::kTorso || !(o.mixed_pixel_min_footprint_m > 0.0) || points.empty()) return;
  // An edge point is mixed where the footprint at it is wide enough and the neighbour beam beyond
  // it returned from more than mixed_pixel_min_gap_m behind it (no echo: nothing to mix with).
  const auto mixed = [&](std::size_t beam, const Eigen::Vector2d& edge_point) {
    const double range = Range(edge_point);
    if (range * o.beam_divergence_rad + o.beam_exit_diameter_m < o.mixed_pixel_min_footprint_m) {
      return false;
    }
    const float r = scan.range_m[beam];
    return std::isfinite(r) && r > 0.0f && static_cast<double>(r) - range > o.mixed_pixel_min_gap_m;
  };
  part.first_mixed = part.begin_beam > 0 && mixed(part.begin_beam - 1, points.front());
  part.last_mixed = part.end_beam < scan.range_m.size() && mixed(part.end_beam, points.back());
}

void TrackingPipeline::AddObservation(const ScanView& scan, const Observation& observation) {
  if (observations_.full()) {
    ++counters_.dropped_segments;
    return;
  }
  (void)observations_.push_back(observation);
  MeasureObservation(scan, observations_.back());
}

void TrackingPipeline::MeasureObservation(const ScanView& scan, const Observation& observation) {
  const ShapeOptions& o = options_.shape;
  // First position for association: behind the nearest point of each part by the prior's extent;
  // along the ray as uncertain as the object is large (a cart's depth is not the prior's).
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  Eigen::Vector2d ray_sum = Eigen::Vector2d::Zero();
  double extent = 0.0;
  std::size_t points = 0;
  for (std::size_t k = 0; k < observation.part_count; ++k) {
    const ObservationPart& part = observation.parts[k];
    counters_.leg_edges_in_mixed_beam +=
        (part.first_edge_in_mixed_beam ? 1 : 0) + (part.last_edge_in_mixed_beam ? 1 : 0);
    const auto pts = segments_.points_m.span().subspan(part.first_point, part.point_count);
    // The ray half way between the first and the last point's: the sum of their unit vectors
    // (the direction at the mean of their bearings, without atan2, cos and sin; a part spans far
    // less than half a turn, so the sum is never near zero).
    const double front_range = Range(pts.front());
    const double back_range = Range(pts.back());
    const Eigen::Vector2d bisector = pts.front() / front_range + pts.back() / back_range;
    const double bisector_norm = bisector.norm();
    Eigen::Vector2d ray = bisector / bisector_norm;
    if (!(bisector_norm > 1e-9) || !ray.allFinite()) {
      const double mid = 0.5 * (std::atan2(pts.front().y(), pts.front().x()) +
                                std::atan2(pts.back().y(), pts.back().x()));
      ray = Eigen::Vector2d(std::cos(mid), std::sin(mid));
    }
    const double nearest = internal::NearestAlong(pts, ray, front_range);
    const double width = (pts.back() - pts.front()).norm();
    extent = std::max(extent, width);
    const double depth = observation.legs
                             ? o.leg_radius_m
                             : std::max(0.5 * (o.person_major_m + o.person_minor_m), 0.5 * width);
    if (observation.legs && part.mixed_leg_along_var_m2 > 0.0) {
      centre += part.mixed_leg_centre_m;  // ShapeOptions::mixed_leg_max_gap_m
    } else {
      centre += (nearest + depth) * ray;
    }
    ray_sum += ray;
    points += part.point_count;
  }
  centre /= static_cast<double>(observation.part_count);
  Measurement m;
  m.kind = MeasurementKind::kShapeFit;
  m.position_m = centre;
  double sigma = o.association_sigma_m;
  if (observation.legs && observation.part_count == 1)
    sigma = std::sqrt(sigma * sigma + o.hip_half_width_m * o.hip_half_width_m);
  // Roots of sums of squares (within an ulp of hypot; no overflow at these sizes); for legs
  // hypot(sigma, 0), |sigma| exactly.
  const double along =
      observation.legs ? std::abs(sigma) : std::sqrt(sigma * sigma + 0.25 * extent * extent);
  const Eigen::Vector2d u = ray_sum.normalized();
  m.covariance_m2 = sigma * sigma * Eigen::Matrix2d::Identity() +
                    (along * along - sigma * sigma) * u * u.transpose();
  m.point_count = points;
  const std::size_t begin = observation.parts[0].begin_beam;
  const std::size_t end = observation.parts[observation.part_count - 1].end_beam;
  const double beam_s = std::abs(scan.angle_step_rad) / (2.0 * common::kPi) * scan.scan_period_s;
  const double middle_beam =
      0.5 * static_cast<double>(std::min(begin, end) + std::max(begin, end) - 1);
  const double offset_s =
      options_.correct_beam_time ? std::clamp(middle_beam * beam_s, 0.0, scan.scan_period_s) : 0.0;
  (void)measurements_.push_back(m);
  (void)offsets_s_.push_back(offset_s);
}

void TrackingPipeline::BuildObservations(const ScanView& scan) {
  if (options_.shape.mount == Mount::kTorso) {
    // Each observation is built in its slot of observations_ (one copy of ~300 bytes less per
    // segment than building it aside and adding it).
    // The tracks are predicted on the first run of pieces only (most scans have none).
    std::optional<std::size_t> tracks;
    const auto& segments = segments_.segments;
    for (std::size_t i = 0; i < segments.size();) {
      const std::size_t first = i;
      const std::size_t last =
          options_.shape.box_rejoin_pieces ? BoxPiecesEnd(i, scan.stamp_ns, tracks) : i;
      // ShapeOptions::box_rejoin_pieces: the pieces as the one segment they would have been.
      Segment s = JoinedPieces(first, last);
      counters_.box_pieces_rejoined += last - i;
      const bool whole = last == i;  // no box pieces rejoined
      i = last + 1;
      if (observations_.full()) {
        ++counters_.dropped_segments;  // as AddObservation counts it
        continue;
      }
      // ShapeOptions::split_deep_tail: the ends deeper than a body left out. The tail can make the
      // segment wider than the segmentation's max_width_m, which then cut it (the body too) in
      // pieces: those pieces are taken together where no piece lies wholly in a tail (an object
      // behind that is itself that wide) and the body without its tails is no wider than
      // max_width_m.
      DeepTails tails;
      bool tail = false;
      if (options_.shape.split_deep_tail && whole) {
        const std::size_t chain = WidthPiecesEnd(first);
        const auto try_tail = [&](std::size_t end_piece) {
          const Segment m = JoinedPieces(first, end_piece);
          const DeepTails t = FindDeepTails(segments_, m, options_.shape.deep_tail_depth_m);
          const std::size_t body_n = m.point_count - t.lead - t.trail;
          if (t.lead + t.trail == 0 || body_n < options_.segmentation.min_points) return false;
          if (end_piece > first) {
            if (t.lead >= segments[first].point_count ||
                t.trail >= segments[end_piece].point_count) {
              return false;
            }
            const auto pts = segments_.Points(m);
            if ((pts[m.point_count - 1 - t.trail] - pts[t.lead]).norm() >
                options_.segmentation.max_width_m) {
              return false;
            }
          }
          if (OnConfirmedBox(m, scan.stamp_ns, tracks, true)) return false;
          tails = t;
          s = m;
          i = end_piece + 1;
          return true;
        };
        tail = (chain > first && try_tail(chain)) || try_tail(first);
      }
      s.width_m = (segments_.points_m[s.first_point + s.point_count - 1] -
                   segments_.points_m[s.first_point])
                      .norm();
      // ShapeOptions::split_see_through (not the pieces of a box rejoined above).
      std::array<std::size_t, kMaxSeeThroughCuts + 1> starts{};
      std::size_t pieces = 1;
      if (options_.shape.split_see_through && whole && !tail) {
        pieces += SeeThroughCuts(scan, segments_, s, options_.segmentation,
                                 options_.shape.see_through_min_width_m,
                                 std::span<std::size_t>(starts).subspan(1));
      }
      bool seam = false;  // the cuts are at range steps (ShapeOptions::split_step_seam)
      if (options_.shape.split_step_seam && whole && !tail && pieces == 1) {
        pieces += RangeStepCuts(segments_, s, options_.shape.step_seam,
                                std::span<std::size_t>(starts).subspan(1));
        seam = pieces > 1;
      }
      if (pieces > 1 && OnConfirmedBox(s, scan.stamp_ns, tracks, seam)) pieces = 1;
      // ShapeOptions::split_deep_tail: the body between the tails, the tails left out.
      std::size_t end_used = s.point_count;
      if (tail) {
        counters_.deep_tail_cuts += (tails.lead > 0 ? 1 : 0) + (tails.trail > 0 ? 1 : 0);
        starts[0] = tails.lead;
        end_used = s.point_count - tails.trail;
      }
      // ShapeOptions::torso_edge_echo (an uncut segment only).
      const bool echo =
          pieces == 1 && !tail && options_.shape.torso_edge_echo && TorsoEdgeEcho(scan, s);
      for (std::size_t p = 0; p < pieces; ++p) {
        const std::size_t end = p + 1 < pieces ? starts[p + 1] : end_used;
        if (p > 0) {
          if (observations_.full()) {
            ++counters_.dropped_segments;
            break;
          }
          ++(seam ? counters_.step_seam_splits : counters_.see_through_splits);
        }
        Observation* ob = observations_.emplace_slot();
        MakePartIn(scan, s, starts[p], end - starts[p], ob->parts[0]);
        ob->part_count = 1;
        const std::size_t before = measurements_.size();
        MeasureObservation(scan, *ob);
        if (echo && measurements_.size() > before) {
          ++counters_.torso_edge_echoes;
          measurements_[before].evidence_only = true;
        }
      }
    }
    return;
  }
  // Legs: every segment narrow enough for a pair of legs holds one or two legs.
  const ShapeOptions& o = options_.shape;
  const double pair_width = 2.0 * (o.hip_half_width_m + o.leg_radius_m) + 0.1;
  leg_parts_.clear();
  for (const Segment& s : segments_.segments) {
    const auto pts = segments_.Points(s);
    if (o.drop_deep_mixed_pixel_pieces && s.width_m > pair_width &&
        DeepMixedPixels(pts, pair_width)) {
      if (SurfaceBehind(scan, s)) {
        ++counters_.veiled_segments;
        continue;
      }
      ++counters_.deep_pieces_kept;
    }
    if (o.drop_mixed_pixel_legs && s.width_m <= pair_width && Veiled(scan, s)) {
      ++counters_.veiled_segments;
      continue;
    }
    if (o.recent_veil_s > 0.0 && s.width_m <= pair_width && RecentlyVeiled(scan, s)) {
      ++counters_.recently_veiled;
      continue;
    }
    if (s.width_m > pair_width) {
      Observation ob;
      ob.parts[0] = MakePart(scan, s, 0, s.point_count);
      ob.part_count = 1;
      AddObservation(scan, ob);
      continue;
    }
    const std::size_t split = LegSplit(s, pts);
    if (split == 0) {
      ObservationPart part = MakePart(scan, s, 0, s.point_count);
      // ShapeOptions::deep_legs_as_pair: where the points are deeper along the ray than one leg,
      // the place of the widest gap (nearer leg | what lies behind it).
      if (o.deep_legs_as_pair && pts.size() >= 2 && pts.size() < 4 &&
          internal::DeepLegExcessDepth(o, pts) > 0.0) {
        double widest = -1.0;
        for (std::size_t i = 1; i < pts.size(); ++i) {
          const double gap = (pts[i] - pts[i - 1]).norm();
          if (gap > widest) {
            widest = gap;
            part.deep_split = i;
          }
        }
      }
      (void)leg_parts_.push_back(part);
    } else {
      (void)leg_parts_.push_back(MakePart(scan, s, 0, split));
      (void)leg_parts_.push_back(MakePart(scan, s, split, s.point_count - split));
    }
  }
  single_beam_first_ = leg_parts_.size();
  leg_partner_only_.fill(false);
  const std::size_t tracks = tracker_.Predict(scan.stamp_ns, predictions_);
  if (o.single_beam_legs) AddSingleBeamLegs(scan, tracks);
  PairLegs(scan, tracks);
}

namespace {

// A confirmed box track's position and size variance for rejoining pieces: the size no more
// certain than when the track became a box (a view cut into pieces shows part of the outline only,
// and what the track learned from such views is not its size).
double BoxStateVar(const ShapeOptions& o, const TrackPrediction& pr) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> position(pr.covariance_m2,
                                                                Eigen::EigenvaluesOnly);
  return std::max({pr.size_cov_m2(0, 0), pr.size_cov_m2(1, 1),
                   o.box_size_sigma_m * o.box_size_sigma_m}) +
         position.eigenvalues().maxCoeff();
}

// How far outside that box's predicted outline a piece at range_m may lie and still be the box's:
// box_rejoin_sigmas of the range noise, the model's departure and the state's spread together.
double BoxRejoinMargin(const ShapeOptions& o, double state_var, double range_m) {
  const double noise = o.fit.point_sigma_m + o.fit.point_sigma_per_m * range_m;
  return o.box_rejoin_sigmas * std::sqrt(noise * noise + o.fit.model_sigma_m * o.fit.model_sigma_m +
                                         std::max(0.0, state_var));
}

}  // namespace

// ShapeOptions::split_see_through: a piece of segment s lies on a confirmed box track's predicted
// rectangle, grown as box_rejoin_pieces grows it (a cart and its pusher: the box's fit leaves the
// pusher out, box_drop_occluders).
bool TrackingPipeline::OnConfirmedBox(const Segment& s, common::UtcNs stamp_ns,
                                      std::optional<std::size_t>& tracks, bool seam) {
  const ShapeOptions& o = options_.shape;
  if (!tracks) tracks = tracker_.Predict(stamp_ns, predictions_);
  const auto pts = segments_.Points(s);
  const double range = Range(pts.front());
  for (std::size_t t = 0; t < *tracks; ++t) {
    const TrackPrediction& pr = predictions_[t];
    if (seam && o.step_seam_size_guard && pr.model != ShapeModel::kBox &&
        (pr.size_m.x() > o.step_seam_person_max_a_m ||
         pr.size_m.y() > o.step_seam_person_max_b_m)) {
      // ShapeOptions::step_seam_size_guard: a cart the tracker still learns as another shape.
      if (internal::AnyInsideGrownBox(pr.position_m, pr.size_m, pr.yaw_rad,
                                      o.step_seam_size_margin_m, pts)) {
        return true;
      }
    }
    // ShapeOptions::split_step_seam: also a box track not yet confirmed.
    if (pr.model != ShapeModel::kBox || !(pr.confirmed || seam)) continue;
    const double margin = BoxRejoinMargin(o, BoxStateVar(o, pr), range);
    if (internal::AnyInsideGrownBox(pr.position_m, pr.size_m, pr.yaw_rad, margin, pts)) {
      return true;
    }
  }
  return false;
}

Segment TrackingPipeline::JoinedPieces(std::size_t first, std::size_t last) const {
  Segment s = segments_.segments[first];
  for (std::size_t k = first + 1; k <= last; ++k) {
    s.end_beam = segments_.segments[k].end_beam;
    s.point_count += segments_.segments[k].point_count;
  }
  return s;
}

std::size_t TrackingPipeline::WidthPiecesEnd(std::size_t first) const {
  const auto& segments = segments_.segments;
  const SegmentationOptions& so = options_.segmentation;
  // The run of pieces from `first` the segmentation cut only for their width (or point count).
  std::size_t chain = first;
  std::size_t points = segments[first].point_count;
  while (chain + 1 < segments.size()) {
    const Segment& a = segments[chain];
    const Segment& b = segments[chain + 1];
    if (b.first_point != a.first_point + a.point_count || b.begin_beam < a.end_beam ||
        b.begin_beam - a.end_beam > so.max_missing_beams ||
        points + b.point_count > kMaxSegmentPoints) {
      break;
    }
    const Eigen::Vector2d& p = segments_.points_m[b.first_point];
    const Eigen::Vector2d& q = segments_.points_m[a.first_point + a.point_count - 1];
    if ((p - q).norm() > so.jump_base_m + so.jump_per_m * Range(p)) break;
    points += b.point_count;
    ++chain;
  }
  return chain;
}

std::size_t TrackingPipeline::BoxPiecesEnd(std::size_t first, common::UtcNs stamp_ns,
                                           std::optional<std::size_t>& tracks) {
  const auto& segments = segments_.segments;
  const ShapeOptions& o = options_.shape;
  const std::size_t chain = WidthPiecesEnd(first);
  if (chain == first) return first;
  if (!tracks) tracks = tracker_.Predict(stamp_ns, predictions_);
  std::size_t best = first;
  for (std::size_t t = 0; t < *tracks; ++t) {
    const TrackPrediction& pr = predictions_[t];
    if (!pr.confirmed || pr.model != ShapeModel::kBox) continue;
    const double state_var = BoxStateVar(o, pr);
    std::size_t end = first;
    for (std::size_t k = first; k <= chain; ++k) {
      const Segment& s = segments[k];
      const double margin = BoxRejoinMargin(o, state_var, Range(segments_.points_m[s.first_point]));
      if (!internal::InsideGrownBox(pr.position_m, pr.size_m, pr.yaw_rad, margin,
                                    segments_.Points(s))) {
        break;
      }
      end = k;
    }
    if (end > best) best = end;
  }
  return best;
}

std::size_t TrackingPipeline::LegSplit(const Segment& segment,
                                       std::span<const Eigen::Vector2d> pts) {
  const ShapeOptions& o = options_.shape;
  if (pts.size() < 2) return 0;
  // Two legs that touch: split at the widest gap between consecutive points, each leg at least
  // two points where there are four or more and the segment is wider than a leg with margin.
  // ShapeOptions::split_few_point_legs: with fewer points, one point each where the beams' centres
  // spread across the line of sight wider than a leg two sigmas above the prior radius can (a
  // beam returns a leg only where its centre ray falls on it).
  const bool few = pts.size() < 4;
  if (few) {
    const double widest_leg = 2.0 * (o.leg_radius_m + 2.0 * o.leg_radius_sigma_m);
    if (!(o.split_few_point_legs && AcrossWidth(pts) > widest_leg)) return 0;
  } else if (!(segment.width_m > 2.0 * o.leg_radius_m + 0.08)) {
    return 0;
  }
  const std::size_t min_part = few ? 1 : 2;
  std::size_t split = 0;
  double widest = 0.0;
  for (std::size_t i = min_part; i + min_part <= pts.size(); ++i) {
    const double gap = (pts[i] - pts[i - 1]).norm();
    if (gap > widest) {
      widest = gap;
      split = i;
    }
  }
  if (few && split > 0) ++counters_.split_few_point_legs;
  return split;
}

// A piece (wider than a pair of legs, pair_width_m: BuildObservations') no wider across the line of
// sight than a pair of legs or than one leg's beams (its diameter and a beam's footprint), all of
// it where a leg fills no beam's footprint (ShapeOptions::drop_deep_mixed_pixel_pieces).
bool TrackingPipeline::DeepMixedPixels(std::span<const Eigen::Vector2d> pts,
                                       double pair_width_m) const {
  const ShapeOptions& o = options_.shape;
  if (pts.empty()) return false;
  double nearest_m = std::numeric_limits<double>::infinity();
  for (const Eigen::Vector2d& p : pts) nearest_m = std::min(nearest_m, p.norm());
  const double footprint_m = nearest_m * o.beam_divergence_rad + o.beam_exit_diameter_m;
  if (AcrossWidth(pts) > std::max(pair_width_m, 2.0 * o.leg_radius_m + footprint_m)) return false;
  return nearest_m * o.beam_divergence_rad >= 2.0 * o.leg_radius_m;
}

// The evidence a deep piece's points are mixed pixels
// (ShapeOptions::deep_mixed_pixel_behind_ratio): a mixed range m = w n + (1 - w) f of a near echo n
// and a far one f, each weight at least s, puts f no more than (1 - s) / s (m - n) behind m. The
// piece's nearest point stands for n, its farthest for m; a beam of the piece whose learned
// background lies behind the nearest point and no more than ratio times the depth behind the
// farthest is that surface f. Where every point may be mixed (the nearest one too, so the depth
// understates how far f lies), the piece spans no more beams than one leg touches: those whose
// footprint reaches it, (2 leg_radius_m + footprint) / (range x step) + 1 (as Veiled bounds its
// pieces by the footprint's beams).
bool TrackingPipeline::SurfaceBehind(const ScanView& scan, const Segment& segment) const {
  const ShapeOptions& o = options_.shape;
  const double ratio = o.deep_mixed_pixel_behind_ratio;
  if (!(ratio > 0.0)) return true;
  const auto pts = segments_.Points(segment);
  double nearest_m = std::numeric_limits<double>::infinity();
  double farthest_m = 0.0;
  for (const Eigen::Vector2d& p : pts) {
    const double r = p.norm();
    nearest_m = std::min(nearest_m, r);
    farthest_m = std::max(farthest_m, r);
  }
  const double spacing_m = nearest_m * std::abs(scan.angle_step_rad);
  const double footprint_m = nearest_m * o.beam_divergence_rad + o.beam_exit_diameter_m;
  if (spacing_m > 0.0 && static_cast<double>(segment.end_beam - segment.begin_beam) <=
                             std::floor((2.0 * o.leg_radius_m + footprint_m) / spacing_m) + 1.0) {
    return true;  // within one leg's beams
  }
  const double limit_m = farthest_m + ratio * (farthest_m - nearest_m);
  const auto background = background_.background_range_m();
  for (std::size_t b = segment.begin_beam; b < segment.end_beam && b < background.size(); ++b) {
    const double f = static_cast<double>(background[b]);
    if (f > nearest_m && f <= limit_m) return true;  // 0 = free: no surface
  }
  return false;
}

// Single-beam legs (ShapeOptions::single_beam_legs): foreground beams in no segment, within the
// pairing distance of a confirmed track's prediction and not veiled, as one-point leg parts after
// the segments' (from single_beam_first_ on).
void TrackingPipeline::AddSingleBeamLegs(const ScanView& scan, std::size_t tracks) {
  const ShapeOptions& o = options_.shape;
  const double reach = o.hip_half_width_m + o.leg_radius_m;
  bool any_confirmed = false;
  for (std::size_t t = 0; t < tracks; ++t)
    any_confirmed = any_confirmed || predictions_[t].confirmed;
  if (!any_confirmed) return;
  const auto foreground = background_.foreground();
  const auto& segs = segments_.segments;
  std::size_t next = 0;  // segments are in beam order
  for (std::size_t b = 0; b < foreground.size() && b < scan.range_m.size(); ++b) {
    while (next < segs.size() && segs[next].end_beam <= b) ++next;
    if (next < segs.size() && segs[next].begin_beam <= b) continue;  // in a segment
    const float r = scan.range_m[b];
    if (foreground[b] == 0 || !(std::isfinite(r) && r > 0.0f)) continue;
    const double angle = scan.BeamAngleRad(b);
    const Eigen::Vector2d p =
        static_cast<double>(r) * Eigen::Vector2d(std::cos(angle), std::sin(angle));
    // Only where a leg may return one beam (narrower than two beams' spacing): nearer, a lone
    // beam is clutter or a mixed pixel -- unless it may be a segment leg's partner
    // (ShapeOptions::single_beam_partner; PairLegs takes it only as that).
    const bool partner_only =
        o.leg_radius_m >= static_cast<double>(r) * std::abs(scan.angle_step_rad);
    if (partner_only && !(o.single_beam_partner && NearSegmentLeg(p))) continue;
    // Near exactly one confirmed track: between two, whose it is is unknown.
    // And only one that still knows where the legs are (its position sigma within their reach):
    // a track coasting for long would follow whatever beam flickers near it.
    std::size_t near_tracks = 0, known = 0;
    for (std::size_t t = 0; t < tracks; ++t) {
      if (!predictions_[t].confirmed ||
          (predictions_[t].position_m - p).norm() > o.leg_pairing_distance_m) {
        continue;
      }
      ++near_tracks;
      if (0.5 * predictions_[t].covariance_m2.trace() <= reach * reach) ++known;
    }
    if (near_tracks != 1 || known != 1 || leg_parts_.full() || !segments_.points_m.push_back(p)) {
      continue;
    }
    Segment single;
    single.begin_beam = b;
    single.end_beam = b + 1;
    single.first_point = segments_.points_m.size() - 1;
    single.point_count = 1;
    if (o.drop_mixed_pixel_legs && Veiled(scan, single)) {
      segments_.points_m.pop_back();
      continue;
    }
    if (o.recent_veil_s > 0.0 && RecentlyVeiled(scan, single)) {
      ++counters_.recently_veiled;
      segments_.points_m.pop_back();
      continue;
    }
    if (o.lone_beam_edge_echo && LoneBeamBesideNearer(scan, b)) {
      ++counters_.lone_beam_edge_echoes;
      segments_.points_m.pop_back();
      continue;
    }
    leg_partner_only_[leg_parts_.size()] = partner_only;
    (void)leg_parts_.push_back(MakePart(scan, single, 0, 1));
  }
}

// ShapeOptions::lone_beam_edge_echo: beam b has a return within a footprint's beams
// (ceil(beam_divergence_rad / 2 step) + 1, as BesideNearerEdge) nearer than it by more than the
// segmentation's jump at its range and by at most leg_pairing_distance_m + 2 leg_radius_m.
bool TrackingPipeline::LoneBeamBesideNearer(const ScanView& scan, std::size_t b) const {
  const SegmentationOptions& g = options_.segmentation;
  const ShapeOptions& o = options_.shape;
  const std::size_t footprint_beams = FootprintBeams(o.beam_divergence_rad, scan.angle_step_rad);
  const auto r = static_cast<double>(scan.range_m[b]);
  const double limit_m = r - (g.jump_base_m + g.jump_per_m * r);
  // ... and near enough to be taken for that return's other leg (within the pairing distance of
  // its centre): an echo farther behind pairs with no leg of it, and a real leg there beside a
  // much nearer edge (a screen, a wall's end) is kept.
  const double bound_m = r - o.leg_pairing_distance_m - 2.0 * o.leg_radius_m;
  const std::size_t n = scan.range_m.size();
  for (std::size_t k = 1; k <= footprint_beams; ++k) {
    for (const std::size_t j : {b >= k ? b - k : n, b + k}) {
      if (j >= n) continue;
      const auto rj = static_cast<double>(scan.range_m[j]);
      if (std::isfinite(rj) && rj > 0.0 && rj < limit_m && rj >= bound_m) return true;
    }
  }
  return false;
}

// The nearest range among the beams within footprint_beams of [begin_beam, end_beam) on either side
// that return nearer than nearest_m by more than the segmentation's jump at that range; infinity:
// none (BesideNearerEdge, TorsoEdgeEcho).
double TrackingPipeline::NearerReturnBeside(const ScanView& scan, std::size_t begin_beam,
                                            std::size_t end_beam, double nearest_m,
                                            std::size_t footprint_beams) const {
  const SegmentationOptions& g = options_.segmentation;
  const double limit_m = nearest_m - (g.jump_base_m + g.jump_per_m * nearest_m);
  const std::size_t n = scan.range_m.size();
  double edge_m = std::numeric_limits<double>::infinity();
  const auto nearer = [&](std::size_t b) {
    const float r = scan.range_m[b];
    if (std::isfinite(r) && r > 0.0f && static_cast<double>(r) < limit_m) {
      edge_m = std::min(edge_m, static_cast<double>(r));
    }
  };
  for (std::size_t k = 1; k <= footprint_beams; ++k) {
    if (begin_beam >= k) nearer(begin_beam - k);
    if (end_beam + k - 1 < n) nearer(end_beam + k - 1);
  }
  return edge_m;
}

// ShapeOptions::torso_edge_echo: at most a footprint's beams (as BesideNearerEdge), with a return
// within as many beams of either end nearer than its nearest point by more than the segmentation's
// jump at that range, and a learned background behind it such that the nearer surface's share of
// a mix at its range is at most 1 - torso_edge_echo_min_far_share.
bool TrackingPipeline::TorsoEdgeEcho(const ScanView& scan, const Segment& s) const {
  const ShapeOptions& o = options_.shape;
  const std::size_t footprint_beams = FootprintBeams(o.beam_divergence_rad, scan.angle_step_rad);
  if (s.point_count == 0 || s.point_count > footprint_beams) return false;
  double range = std::numeric_limits<double>::infinity();
  for (const Eigen::Vector2d& p : segments_.Points(s)) range = std::min(range, p.norm());
  // Only where a body seen side-on (2 person_minor_m) spans no more beams than that: nearer, a
  // person returns more beams than an edge's mix, and a piece this small is part of one.
  if (o.torso_edge_echo_far_only &&
      range * std::abs(scan.angle_step_rad) * static_cast<double>(footprint_beams) <
          2.0 * o.person_minor_m) {
    return false;
  }
  const double nearer_m =
      NearerReturnBeside(scan, s.begin_beam, s.end_beam, range, footprint_beams);
  if (!std::isfinite(nearer_m)) return false;
  // A mix of the nearer surface (share w) and the background behind (range f, 0 = free: nothing
  // to mix with) lies at w nearer + (1 - w) f: behind the nearer one by at least the far surface's
  // least share of (f - nearer). A body just behind the nearer one (a pair side by side seen
  // almost in line) lies nearer than that.
  const auto background = background_.background_range_m();
  double behind_m = 0.0;
  for (std::size_t b = s.begin_beam; b < s.end_beam && b < background.size(); ++b) {
    behind_m = std::max(behind_m, static_cast<double>(background[b]));
  }
  if (!(behind_m > range)) return false;
  return range - nearer_m >= o.torso_edge_echo_min_far_share * (behind_m - nearer_m);
}

// A segment's leg (leg_parts_ before single_beam_first_) whose centre lies within
// leg_pairing_distance_m of the centre of a leg whose front is at p
// (ShapeOptions::single_beam_partner).
bool TrackingPipeline::NearSegmentLeg(const Eigen::Vector2d& p) const {
  const ShapeOptions& o = options_.shape;
  const Eigen::Vector2d centre = p + o.leg_radius_m * p.normalized();
  for (std::size_t i = 0; i < single_beam_first_; ++i) {
    const ObservationPart& part = leg_parts_[i];
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    for (std::size_t k = 0; k < part.point_count; ++k)
      mean += segments_.points_m[part.first_point + k];
    mean /= static_cast<double>(std::max<std::size_t>(part.point_count, 1));
    if ((mean + o.leg_radius_m * mean.normalized() - centre).norm() <= o.leg_pairing_distance_m) {
      return true;
    }
  }
  return false;
}

// Mixed pixels of a nearer leg's edge (ShapeOptions::drop_mixed_pixel_legs): a segment beside a
// return nearer by more than the segmentation's jump and the legs' pairing distance, where a leg
// no longer fills a beam's footprint, that spans no more beams than a footprint reaches beyond
// the edge or lies between two such returns.
bool TrackingPipeline::Veiled(const ScanView& scan, const Segment& segment) const {
  const SegmentationOptions& g = options_.segmentation;
  const ShapeOptions& o = options_.shape;
  const auto pts = segments_.Points(segment);
  const double step = std::abs(scan.angle_step_rad);
  const std::size_t footprint_beams = FootprintBeams(o.beam_divergence_rad, step);
  const std::size_t reach = g.max_missing_beams + 1;
  const auto nearer = [&](std::size_t beam, const Eigen::Vector2d& p) {
    const float r = scan.range_m[beam];
    if (!(std::isfinite(r) && r > 0.0f)) return false;
    // Nearer than a leg fills a beam's footprint, a leg's beams return the leg: a mixed pixel
    // is a single beam at its edge, which segmentation drops (min_points).
    if (static_cast<double>(r) * o.beam_divergence_rad < 2.0 * o.leg_radius_m) return false;
    const double range = Range(p);
    return static_cast<double>(r) <
           range - std::max(g.jump_base_m + g.jump_per_m * range, o.leg_pairing_distance_m);
  };
  const std::size_t n = scan.range_m.size();
  bool before = false, after = false;
  for (std::size_t k = 1; k <= reach; ++k) {
    before = before || (segment.begin_beam >= k && nearer(segment.begin_beam - k, pts.front()));
    after = after || (segment.end_beam + k - 1 < n && nearer(segment.end_beam + k - 1, pts.back()));
  }
  if ((before && after) ||
      ((before || after) && segment.end_beam - segment.begin_beam <= footprint_beams)) {
    return true;
  }
  if (!o.drop_mixed_pixel_legs_whole_person) return false;
  // The piece must be no wider than a hidden leg's mixed pixels: a footprint beyond the leg's
  // own beams (a wider piece is not one leg's shadow).
  const auto leg_beams = static_cast<std::size_t>(
      std::ceil(2.0 * o.leg_radius_m / std::max(Range(pts.front()) * step, 1e-6)));
  if (segment.end_beam - segment.begin_beam > footprint_beams + leg_beams) return false;
  // The other leg of a person a nearer beam returns lies within leg_pairing_distance_m of it:
  // a beam k steps away is in that leg's shadow when k steps span at most that much at its range.
  // nearer() needs a range of at least 2 leg_radius_m / beam_divergence_rad, which bounds k.
  const double min_near_m = 2.0 * o.leg_radius_m / std::max(o.beam_divergence_rad, 1e-6);
  const auto widest = static_cast<std::size_t>(
      std::ceil(std::atan(o.leg_pairing_distance_m / min_near_m) / std::max(step, 1e-6)));
  // ... and only where that nearer return can be a person: the run of beams around it at its range
  // (within the segmentation's jump) spans no more than a person's legs (leg_pairing_distance_m)
  // plus a footprint. The edge of a wall, a machine or a shelf has mixed pixels at its edge beam
  // only (the rule above); people walking behind it within the pairing distance are real legs.
  const auto narrow = [&](std::size_t beam) {
    const auto r = static_cast<double>(scan.range_m[beam]);
    const double tolerance = g.jump_base_m + g.jump_per_m * r;
    const auto most = static_cast<std::size_t>(std::ceil(
                          (o.leg_pairing_distance_m + r * o.beam_divergence_rad) / (r * step))) +
                      1;
    const auto same = [&](std::size_t j) {
      const float rj = scan.range_m[j];
      return std::isfinite(rj) && rj > 0.0f && std::abs(static_cast<double>(rj) - r) <= tolerance;
    };
    std::size_t count = 1;
    for (std::size_t j = beam; j > 0 && count <= most && same(j - 1); --j) ++count;
    for (std::size_t j = beam + 1; j < n && count <= most && same(j); ++j) ++count;
    return count <= most;
  };
  const auto within = [&](std::size_t beam, std::size_t k, const Eigen::Vector2d& p) {
    return static_cast<double>(scan.range_m[beam]) * std::tan(static_cast<double>(k) * step) <=
               o.leg_pairing_distance_m &&
           nearer(beam, p) && narrow(beam);
  };
  for (std::size_t k = reach + 1; k <= std::min(widest, n); ++k) {
    if ((segment.begin_beam >= k && within(segment.begin_beam - k, k, pts.front())) ||
        (segment.end_beam + k - 1 < n && within(segment.end_beam + k - 1, k, pts.back()))) {
      return true;
    }
  }
  return false;
}

// ShapeOptions::recent_veil_s: a leg-sized segment, where a leg fills no beam, behind the nearer
// foreground returns its beams (each, or a neighbour) had in the recent scans, by more than the
// segmentation's jump and the pairing distance plus what a body at max_speed_mps moves meanwhile.
bool TrackingPipeline::RecentlyVeiled(const ScanView& scan, const Segment& segment) const {
  const SegmentationOptions& g = options_.segmentation;
  const ShapeOptions& o = options_.shape;
  const std::size_t n = scan.range_m.size();
  if (recent_beams_ != n || segment.end_beam > n || segment.begin_beam >= segment.end_beam) {
    return false;
  }
  const auto pts = segments_.Points(segment);
  double nearest_m = std::numeric_limits<double>::infinity();
  for (const Eigen::Vector2d& p : pts) nearest_m = std::min(nearest_m, p.norm());
  if (!(nearest_m * o.beam_divergence_rad >= 2.0 * o.leg_radius_m)) return false;
  const double margin_m =
      std::max(g.jump_base_m + g.jump_per_m * nearest_m, o.leg_pairing_distance_m);
  // A nearer object still in beam b's footprint now, wide enough to fill a beam where it stands,
  // fills a neighbouring beam of this scan: that beam returns nearer than the segment now.
  const auto nearer_now = [&](std::size_t b) {
    const auto near_return = [&](std::size_t j) {
      const float r = scan.range_m[j];
      return std::isfinite(r) && r > 0.0f && static_cast<double>(r) < nearest_m - margin_m;
    };
    return (b > 0 && near_return(b - 1)) || (b + 1 < n && near_return(b + 1));
  };
  // Beyond this range a leg-wide object can lie partly in a beam without filling a neighbour.
  const double fills_a_beam_m =
      2.0 * o.leg_radius_m / (std::abs(scan.angle_step_rad) + o.beam_divergence_rad);
  const auto nearer = [&](std::size_t beam, bool present_now) {
    const float r = recent_near_m_[beam];
    if (!(r > 0.0f)) return false;
    const double age_s = common::NsToSeconds(scan.stamp_ns - recent_near_ns_[beam]);
    if (!(age_s > 0.0 && age_s <= o.recent_veil_s)) return false;
    if (static_cast<double>(r) <= fills_a_beam_m && !present_now) return false;
    return static_cast<double>(r) < nearest_m - margin_m - options_.tracking.max_speed_mps * age_s;
  };
  for (std::size_t b = segment.begin_beam; b < segment.end_beam; ++b) {
    const bool now = nearer_now(b);
    if (!(nearer(b, now) || (b > 0 && nearer(b - 1, now)) || (b + 1 < n && nearer(b + 1, now)))) {
      return false;
    }
  }
  return true;
}

void TrackingPipeline::NoteRecentReturns(const ScanView& scan) {
  const std::size_t n = std::min(scan.range_m.size(), kMaxBeams);
  const auto foreground = background_.foreground();
  if (recent_beams_ != scan.range_m.size()) {
    recent_near_m_.fill(0.0f);
    recent_beams_ = scan.range_m.size();
  }
  for (std::size_t b = 0; b < n; ++b) {
    const float r = scan.range_m[b];
    const bool fg = b < foreground.size() && foreground[b] != 0 && std::isfinite(r) && r > 0.0f;
    const bool expired =
        common::NsToSeconds(scan.stamp_ns - recent_near_ns_[b]) > options_.shape.recent_veil_s;
    if (fg && (expired || !(recent_near_m_[b] > 0.0f) || r <= recent_near_m_[b])) {
      recent_near_m_[b] = r;
      recent_near_ns_[b] = scan.stamp_ns;
    } else if (expired) {
      recent_near_m_[b] = 0.0f;
    }
  }
}

// One leg whose partner is hidden behind it (ShapeOptions::hidden_leg_behind): every other beam
// that passes within the pairing distance of the leg passes through that disc (no echo, or a
// return beyond it), or returns from straight behind the leg (the hidden leg's edge, a mixed
// pixel); a return inside the disc or in front of it could be the other leg or hide it. And a leg
// beside it would have returned a whole beam (the beams' spacing and footprint are narrower than
// a leg).
bool TrackingPipeline::PartnerBehind(const ScanView& scan, const ObservationPart& part,
                                     const Eigen::Vector2d& centre_m) const {
  const ShapeOptions& o = options_.shape;
  const double range = centre_m.norm();
  const double step = std::abs(scan.angle_step_rad);
  const double reach = o.leg_pairing_distance_m;
  if (!(range > reach) || !(step > 0.0)) return false;
  if ((range + reach) * std::max(step, o.beam_divergence_rad) >= 2.0 * o.leg_radius_m) {
    return false;
  }
  const std::size_t n = scan.range_m.size();
  const Eigen::Vector2d ray = centre_m / range;
  const double behind_min = 2.0 * o.hip_half_width_m - o.leg_radius_m;
  const double shadow = 2.0 * o.leg_radius_m + step * range;
  // The beams that pass within `reach` of the leg: asin(reach / range) either side.
  const auto beams = static_cast<std::size_t>(std::ceil(std::asin(reach / range) / step)) + 1;
  // At the edge of the field of view the other leg may stand beyond it: not known to be hidden.
  if (part.begin_beam < beams || part.end_beam + beams > n) return false;
  const std::size_t first = part.begin_beam - beams;
  const std::size_t last = part.end_beam + beams;
  for (std::size_t b = first; b < last; ++b) {
    if (b >= part.begin_beam && b < part.end_beam) continue;
    const float r = scan.range_m[b];
    if (!(std::isfinite(r) && r > 0.0f)) continue;  // no echo: the beam passed
    const double angle = scan.BeamAngleRad(b);
    const Eigen::Vector2d u(std::cos(angle), std::sin(angle));
    const double past = std::abs(u.x() * centre_m.y() - u.y() * centre_m.x());
    if (past >= reach) continue;
    const double leaves = u.dot(centre_m) + std::sqrt(reach * reach - past * past);
    if (static_cast<double>(r) >= leaves) continue;
    const Eigen::Vector2d d = static_cast<double>(r) * u - centre_m;
    const double along = d.dot(ray);
    const double across = std::abs(d.x() * ray.y() - d.y() * ray.x());
    if (along < behind_min || across > shadow) return false;
  }
  return true;
}

void TrackingPipeline::PairLegs(const ScanView& scan, std::size_t tracks) {
  const ShapeOptions& o = options_.shape;
  const std::size_t n = leg_parts_.size();
  for (std::size_t i = 0; i < n; ++i) {
    const ObservationPart& part = leg_parts_[i];
    const auto pts = segments_.points_m.span().subspan(part.first_point, part.point_count);
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    for (const auto& p : pts) mean += p;
    mean /= static_cast<double>(pts.size());
    leg_centres_m_[i] = mean + o.leg_radius_m * mean.normalized();
    leg_used_[i] = false;
  }
  const auto emit = [&](std::size_t a, std::size_t b) {
    Observation ob;
    ob.legs = true;
    ob.parts[0] = leg_parts_[a];
    ob.part_count = 1;
    leg_used_[a] = true;
    if (b != a) {
      // In scan order, so the observation's beams run from its first part to its last.
      if (leg_parts_[b].begin_beam < leg_parts_[a].begin_beam) {
        ob.parts[1] = ob.parts[0];
        ob.parts[0] = leg_parts_[b];
      } else {
        ob.parts[1] = leg_parts_[b];
      }
      ob.part_count = 2;
      leg_used_[b] = true;
      ++counters_.leg_pairs;
    } else {
      ++counters_.single_legs;
      ob.partner_behind =
          o.hidden_leg_behind && PartnerBehind(scan, leg_parts_[a], leg_centres_m_[a]);
      if (ob.partner_behind) ++counters_.legs_behind;
    }
    const std::size_t before = measurements_.size();
    AddObservation(scan, ob);
    if (a >= single_beam_first_ || b >= single_beam_first_) {
      ++counters_.single_beam_legs;
      if (measurements_.size() > before) measurements_[before].evidence_only = true;
    } else if (o.far_legs_no_birth && measurements_.size() > before &&
               std::min(leg_centres_m_[a].norm(), leg_centres_m_[b].norm()) *
                       o.beam_divergence_rad >=
                   4.0 * o.leg_radius_m) {
      // ShapeOptions::far_legs_no_birth: a leg there covers at most half of a beam's footprint.
      ++counters_.far_leg_births;
      measurements_[before].evidence_only = true;
    } else if (b == a && o.edge_echo_no_birth && measurements_.size() > before &&
               BesideNearerEdge(scan, leg_parts_[a])) {
      ++counters_.edge_echo_births;
      measurements_[before].evidence_only = true;
    }
  };
  // Around the live tracks, confirmed first: the pair (or single leg) nearest to the prediction.
  const double reach = o.leg_pairing_distance_m;
  // Legs straight behind a confirmed track, farther than its own legs reach, are mixed
  // pixels of its legs (at knee height a beam's footprint is as wide as a leg from a few metres
  // on, and its echo lies between the leg and what is behind): nothing behind a person's legs can
  // be seen through them.
  for (std::size_t t = 0; o.drop_mixed_pixel_legs && t < tracks; ++t) {
    if (!predictions_[t].confirmed) continue;
    const Eigen::Vector2d& c = predictions_[t].position_m;
    const double range = c.norm();
    if (!(range > reach)) continue;
    const Eigen::Vector2d ray = c / range;
    const double half_width = o.hip_half_width_m + o.leg_radius_m +
                              0.5 * (o.beam_divergence_rad + std::abs(scan.angle_step_rad)) * range;
    for (std::size_t a = 0; a < n; ++a) {
      if (leg_used_[a]) continue;
      const Eigen::Vector2d d = leg_centres_m_[a] - c;
      const double behind = d.dot(ray);
      if (behind > reach && std::abs(d.x() * ray.y() - d.y() * ray.x()) < half_width) {
        leg_used_[a] = true;
        ++counters_.shadowed_legs;
      }
    }
  }
  // The segments' legs [first, last) nearest to prediction c: a pair or a single leg.
  const auto nearest = [&](const Eigen::Vector2d& c, std::size_t first, std::size_t last,
                           std::size_t& best_a, std::size_t& best_b) {
    double best = 0.6 * reach;
    best_a = best_b = n;
    for (std::size_t a = first; a < last; ++a) {
      if (leg_used_[a] || leg_partner_only_[a] || (leg_centres_m_[a] - c).norm() > reach) continue;
      // A single leg counts as lying its hip offset from the centre, and as worse than a pair that
      // fits: the other leg is usually there.
      const double single =
          std::max(0.0, (leg_centres_m_[a] - c).norm() - o.hip_half_width_m) + kSingleLegPenaltyM;
      if (single < best) {
        best = single;
        best_a = best_b = a;
      }
      for (std::size_t b = a + 1; b < last; ++b) {
        if (leg_used_[b] || leg_partner_only_[b] ||
            (leg_centres_m_[a] - leg_centres_m_[b]).norm() > reach) {
          continue;
        }
        const double d = (0.5 * (leg_centres_m_[a] + leg_centres_m_[b]) - c).norm();
        if (d < best) {
          best = d;
          best_a = a;
          best_b = b;
        }
      }
    }
  };
  // ShapeOptions::deep_legs_as_pair: a confirmed track's single leg deeper than a leg, with the
  // track's predicted centre beyond the near leg's front, is its two legs, the nearer and what
  // lies behind it, measured as a pair.
  const auto emit_deep = [&](std::size_t a) {
    const ObservationPart& whole = leg_parts_[a];
    Segment seg;
    seg.begin_beam = whole.begin_beam;
    seg.end_beam = whole.end_beam;
    seg.first_point = whole.first_point;
    seg.point_count = whole.point_count;
    Observation ob;
    ob.legs = true;
    ob.parts[0] = MakePart(scan, seg, 0, whole.deep_split);
    ob.parts[1] = MakePart(scan, seg, whole.deep_split, whole.point_count - whole.deep_split);
    ob.part_count = 2;
    ob.deep_pair = true;
    leg_used_[a] = true;
    ++counters_.leg_pairs;
    ++counters_.deep_leg_pairs;
    AddObservation(scan, ob);
  };
  for (std::size_t t = 0; t < tracks; ++t) {
    std::size_t best_a = n, best_b = n;
    nearest(predictions_[t].position_m, 0, single_beam_first_, best_a, best_b);
    if (best_a < n && best_a == best_b && predictions_[t].confirmed &&
        leg_parts_[best_a].deep_split > 0 &&
        (predictions_[t].position_m - leg_centres_m_[best_a]).dot(leg_centres_m_[best_a]) >
            -o.leg_radius_m * leg_centres_m_[best_a].norm()) {
      emit_deep(best_a);
      continue;
    }
    // A confirmed track that found no leg of a segment: its single-beam legs (evidence only).
    if (best_a == n && predictions_[t].confirmed) {
      nearest(predictions_[t].position_m, single_beam_first_, n, best_a, best_b);
    } else if (o.single_beam_partner && best_a < n && best_a == best_b &&
               predictions_[t].confirmed) {
      best_b = SingleBeamPartner(scan, predictions_[t].position_m, best_a);
      if (best_b != best_a) ++counters_.single_beam_partners;
    }
    if (best_a < n) emit(best_a, best_b);
  }
  // The rest (single-beam legs never): nearest neighbours within the pairing distance, then
  // single legs.
  for (std::size_t a = single_beam_first_; a < n; ++a) leg_used_[a] = true;
  for (;;) {
    double best = reach;
    std::size_t best_a = n, best_b = n;
    for (std::size_t a = 0; a < n; ++a) {
      if (leg_used_[a]) continue;
      for (std::size_t b = a + 1; b < n; ++b) {
        if (leg_used_[b]) continue;
        const double d = (leg_centres_m_[a] - leg_centres_m_[b]).norm();
        if (d <= best) {
          best = d;
          best_a = a;
          best_b = b;
        }
      }
    }
    if (best_a == n) break;
    emit(best_a, best_b);
  }
  for (std::size_t a = 0; a < n; ++a) {
    if (!leg_used_[a]) emit(a, a);
  }
}

// ShapeOptions::edge_echo_no_birth: the part spans no more beams than those whose footprint
// reaches past an edge, and a beam within as many beams beyond either end returns nearer than the
// part's nearest point by more than the segmentation's jump (a mixed range lies between the edge's
// and the background's).
bool TrackingPipeline::BesideNearerEdge(const ScanView& scan, const ObservationPart& part) const {
  const ShapeOptions& o = options_.shape;
  const std::size_t footprint_beams = FootprintBeams(o.beam_divergence_rad, scan.angle_step_rad);
  if (part.end_beam - part.begin_beam > footprint_beams) return false;
  double nearest_m = std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k < part.point_count; ++k) {
    nearest_m = std::min(nearest_m, segments_.points_m[part.first_point + k].norm());
  }
  const double edge_m =
      NearerReturnBeside(scan, part.begin_beam, part.end_beam, nearest_m, footprint_beams);
  if (!std::isfinite(edge_m)) return false;
  // A mixed range m = w n + (1 - w) f (each weight at least s) has the far surface f no more than
  // deep_mixed_pixel_behind_ratio (1 - s) / s times m - n behind it: the learned background of
  // one of the part's beams lies there (SurfaceBehind's bound).
  const double ratio = o.deep_mixed_pixel_behind_ratio;
  if (!(ratio > 0.0)) return true;
  const double limit_far_m = nearest_m + ratio * (nearest_m - edge_m);
  const auto background = background_.background_range_m();
  for (std::size_t b = part.begin_beam; b < part.end_beam && b < background.size(); ++b) {
    const double f = static_cast<double>(background[b]);
    if (f > nearest_m && f <= limit_far_m) return true;  // 0 = free: no surface
  }
  return false;
}

// ShapeOptions::single_beam_partner: the single-beam leg that pairs with segment leg a for the
// confirmed track predicted at c -- within leg_pairing_distance_m of it, the pair's midpoint nearer
// to c than the single leg counts (PairLegs' nearest), not the edge's mixed echo (a beam within a
// footprint's beams of the leg's edge, returning from behind the leg's nearest point) -- else a.
std::size_t TrackingPipeline::SingleBeamPartner(const ScanView& scan, const Eigen::Vector2d& c,
                                                std::size_t a) const {
  const ShapeOptions& o = options_.shape;
  const ObservationPart& leg = leg_parts_[a];
  double nearest_m = std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k < leg.point_count; ++k) {
    nearest_m = std::min(nearest_m, segments_.points_m[leg.first_point + k].norm());
  }
  const std::size_t footprint_beams = FootprintBeams(o.beam_divergence_rad, scan.angle_step_rad);
  double best =
      std::max(0.0, (leg_centres_m_[a] - c).norm() - o.hip_half_width_m) + kSingleLegPenaltyM;
  std::size_t partner = a;
  for (std::size_t b = single_beam_first_; b < leg_parts_.size(); ++b) {
    if (leg_used_[b] || (leg_centres_m_[b] - leg_centres_m_[a]).norm() > o.leg_pairing_distance_m) {
      continue;
    }
    const ObservationPart& beam = leg_parts_[b];
    const bool beside = beam.begin_beam + footprint_beams >= leg.begin_beam &&
                        beam.begin_beam < leg.end_beam + footprint_beams;
    if (beside && segments_.points_m[beam.first_point].norm() > nearest_m) continue;
    const double d = (0.5 * (leg_centres_m_[a] + leg_centres_m_[b]) - c).norm();
    if (d < best) {
      best = d;
      partner = b;
    }
  }
  return partner;
}

void TrackingPipeline::MeasureLegacy(const ScanView& scan) {
  // The mirror turns 2 pi per scan period; beam 0 is measured at the scan start.
  const double beam_s = std::abs(scan.angle_step_rad) / (2.0 * common::kPi) * scan.scan_period_s;
  for (const Segment& s : segments_.segments) {
    const Measurement m = MeasureSegment(segments_.Points(s), options_.measurement);
    ++(m.kind == MeasurementKind::kEllipse ? counters_.ellipse_measurements
                                           : counters_.com_measurements);
    const double middle_beam = 0.5 * static_cast<double>(s.begin_beam + s.end_beam - 1);
    const double offset_s = options_.correct_beam_time
                                ? std::clamp(middle_beam * beam_s, 0.0, scan.scan_period_s)
                                : 0.0;
    Observation ob;
    ob.parts[0] = MakePart(scan, s, 0, s.point_count);
    ob.part_count = 1;
    // All have kMaxSegments slots, as many as there are segments.
    (void)observations_.push_back(ob);
    (void)measurements_.push_back(m);
    (void)offsets_s_.push_back(offset_s);
  }
}

void TrackingPipeline::AbsorbStatic(const ScanView& scan) {
  for (const std::size_t source : tracker_.absorbed_sources()) {
    if (source >= observations_.size()) continue;
    const Observation& ob = observations_[source];
    for (std::size_t k = 0; k < ob.part_count; ++k) {
      background_.Absorb(scan, ob.parts[k].begin_beam, ob.parts[k].end_beam);
    }
    ++counters_.absorbed_objects;
  }
}

bool TrackingPipeline::SeenThrough(const ScanView& scan, const Eigen::Vector2d& position_m,
                                   double half_width_m, double max_beam_gap_m) const {
  const double range = position_m.norm();
  if (!(range > half_width_m)) return false;
  // A leg at the region's far side falls between two beams farther apart than its width there,
  // and a beam wider than it returns a mixed pixel between it and what lies behind.
  if (max_beam_gap_m > 0.0 &&
      !((range + half_width_m) *
            std::max(std::abs(scan.angle_step_rad), options_.shape.beam_divergence_rad) <
        max_beam_gap_m)) {
    return false;
  }
  std::size_t lo = 0, hi = 0;
  if (!BeamsAcross(scan, position_m, std::atan(half_width_m / range), scan.range_m.size(), &lo,
                   &hi)) {
    return false;  // outside the field of view: unknown
  }
  std::size_t beyond = 0;
  for (std::size_t i = lo; i <= hi; ++i) {
    const double r = scan.range_m[i];
    if (!(r > 0.0)) continue;                                             // no echo: unknown
    if (r <= range + options_.shape.seen_through_margin_m) return false;  // could be the person
    ++beyond;
  }
  return beyond >= 2;
}

bool TrackingPipeline::OtherLegSeenThrough(const ScanView& scan,
                                           const Eigen::Vector2d& leg_m) const {
  const ShapeOptions& o = options_.shape;
  const double range = leg_m.norm();
  const double r = o.leg_radius_m;
  if (!(range > 2.0 * r)) return false;
  // A leg there would have returned a beam: beams closer together than its width.
  if (!(range * std::max(std::abs(scan.angle_step_rad), o.beam_divergence_rad) < 2.0 * r)) {
    return false;
  }
  std::size_t lo = 0, hi = 0;
  if (!BeamsAcross(scan, leg_m, std::asin(r / range), scan.range_m.size(), &lo, &hi)) return false;
  std::size_t beyond = 0;
  for (std::size_t i = lo; i <= hi; ++i) {
    const double b = scan.range_m[i];
    if (!(b > 0.0)) continue;                                    // no echo: unknown
    if (b <= range + r + o.seen_through_margin_m) return false;  // could be the leg or hide it
    ++beyond;
  }
  // Two echoes beyond, as SeenThrough asks, where the window holds two beams.
  return beyond >= std::min<std::size_t>(2, hi - lo + 1);
}

bool TrackingPipeline::HiddenBehindNearer(const ScanView& scan, const Eigen::Vector2d& position_m,
                                          double reach_m) const {
  const double range = position_m.norm();
  if (!(range > reach_m)) return false;
  const std::span<const std::uint8_t> foreground = background_.foreground();
  std::size_t lo = 0, hi = 0;
  if (!BeamsAcross(scan, position_m, std::asin(reach_m / range),
                   std::min(scan.range_m.size(), foreground.size()), &lo, &hi)) {
    return false;
  }
  for (std::size_t i = lo; i <= hi; ++i) {
    const double r = scan.range_m[i];
    if (foreground[i] != 0 && r > 0.0 && r < range - reach_m) return true;
  }
  return false;
}

bool TrackingPipeline::ForegroundNear(const ScanView& scan, const Eigen::Vector2d& position_m,
                                      double sigma_m) const {
  const double reach_m = options_.shape.person_major_m + 2.0 * sigma_m;
  const double range = position_m.norm();
  if (!(range > reach_m)) return true;  // at the sensor: unknown
  const std::span<const std::uint8_t> foreground = background_.foreground();
  std::size_t lo = 0, hi = 0;
  if (!BeamsAcross(scan, position_m, std::asin(reach_m / range),
                   std::min(scan.range_m.size(), foreground.size()), &lo, &hi)) {
    return true;  // outside the field of view: unknown
  }
  // The beams' directions from the segmentation's table of this scan (SegmentScan ran before: the
  // same cos and sin of the same angles, without a sincos per beam).
  const BeamDirections& directions = segments_.directions;
  for (std::size_t i = lo; i <= hi; ++i) {
    const double r = scan.range_m[i];
    if (foreground[i] == 0 || !(r > 0.0)) continue;
    if ((r * Eigen::Vector2d(directions.cos(i), directions.sin(i)) - position_m).norm() <= reach_m)
      return true;
  }
  return false;
}

void TrackingPipeline::DropCoasting(const ScanView& scan) {
  const ShapeOptions& o = options_.shape;
  const bool torso = o.mount == Mount::kTorso;
  std::size_t kept = 0;
  for (std::size_t i = 0; i < tracks_.tracks.size(); ++i) {
    const TrackReport& r = tracks_.tracks[i];
    if (r.state == TrackState::kCoasting) {
      const Eigen::Matrix2d p = r.covariance.topLeftCorner<2, 2>();
      const double sigma_m = std::sqrt(std::max(0.0, 0.5 * p.trace()));
      const Eigen::Vector2d position(r.x_m, r.y_m);
      // At knee height the beams pass between a person's legs: neither upper-body check.
      // The body's half-width and two sigma of where the track may be.
      if (torso && o.seen_through_margin_m > 0.0 &&
          SeenThrough(scan, position, o.person_major_m + 2.0 * sigma_m, 0.0)) {
        ++counters_.seen_through;
        continue;
      }
      // Knee height: where its legs may stand, with beams no leg can fall between.
      if (!torso && o.legs_seen_through && o.seen_through_margin_m > 0.0 &&
          SeenThrough(scan, position,
                      0.5 * o.leg_pairing_distance_m + o.leg_radius_m + 2.0 * sigma_m,
                      2.0 * o.leg_radius_m)) {
        ++counters_.legs_seen_through;
        continue;
      }
      // Knee height: only while the prediction still says where a leg stands (its sigma within
      // legs_coasting_max_sigma_m); beyond, the report is as likely beside the person as at them.
      // Not where something nearer hides where its legs may stand (someone walking past in front).
      if (!torso && o.legs_coasting_max_sigma_m > 0.0 && sigma_m > o.legs_coasting_max_sigma_m &&
          !HiddenBehindNearer(scan, position,
                              0.5 * o.leg_pairing_distance_m + o.leg_radius_m + 2.0 * sigma_m)) {
        ++counters_.legs_coasting_uncertain;
        continue;
      }
      // Upper body: only while the prediction still says where the body stands.
      // A box's reported covariance carries its unseen depth (box_unseen_depth_cov), up to
      // box_unseen_sigma_m^2 along one axis, half of that in sigma_m^2: not where it stands.
      // With box_seen_extent_cov, its unbounded semi-axis's variance at most the prior's.
      const double prior_range_m = o.box_prior_max_half_m - o.box_prior_min_half_m;
      const double unseen_var_m2 = o.box_seen_extent_cov
                                       ? std::max(o.box_unseen_sigma_m * o.box_unseen_sigma_m,
                                                  prior_range_m * prior_range_m / 12.0)
                                       : o.box_unseen_sigma_m * o.box_unseen_sigma_m;
      const double max_sigma_m =
          (o.box_unseen_depth_cov || o.box_seen_extent_cov) && r.shape == ObjectShape::kBox
              ? std::sqrt(o.coasting_max_sigma_m * o.coasting_max_sigma_m + 0.5 * unseen_var_m2)
              : o.coasting_max_sigma_m;
      if (torso && o.coasting_max_sigma_m > 0.0 && sigma_m > max_sigma_m) {
        ++counters_.coasting_uncertain;
        continue;
      }
      // Compared with a threshold only: the root of the sum of squares (within an ulp of hypot).
      const double coasted_m = std::sqrt(r.vx_mps * r.vx_mps + r.vy_mps * r.vy_mps) * r.coasted_s;
      if (torso && o.unseen_coasting_m > 0.0 && coasted_m > o.unseen_coasting_m &&
          !ForegroundNear(scan, position, sigma_m)) {
        ++counters_.unseen_coasting;
        continue;
      }
    }
    if (kept != i) tracks_.tracks[kept] = r;
    ++kept;
  }
  while (tracks_.tracks.size() > kept) tracks_.tracks.pop_back();
}

const ScanTracks& TrackingPipeline::Process(const ScanView& scan, std::uint32_t scan_counter) {
  ++counters_.scans;
  segments_.segments.clear();
  segments_.points_m.clear();
  segments_.dropped_segments = 0;
  observations_.clear();
  measurements_.clear();
  offsets_s_.clear();

  const BackgroundResult bg = background_.Update(scan);
  last_scan_error_ = bg.scan_error;
  const bool shape_fit = options_.method == MeasurementMethod::kShapeFit;
  if (bg.scan_error != ScanError::kNone) {
    ++counters_.rejected_scans;
  } else if (!bg.learned) {
    ++counters_.learning_scans;
  } else {
    SegmentScan(scan, background_.foreground(), options_.segmentation, segments_);
    counters_.segments += segments_.segments.size();
    counters_.dropped_segments += segments_.dropped_segments;
    if (shape_fit) {
      BuildObservations(scan);
      if (options_.shape.mount == Mount::kLegs && options_.shape.recent_veil_s > 0.0) {
        NoteRecentReturns(scan);
      }
    } else {
      MeasureLegacy(scan);
    }
  }

  const std::uint64_t fits_before = refiner_->fits, failed_before = refiner_->failed;
  const std::uint64_t across_walk_before = refiner_->across_walk;
  const std::uint64_t side_uncertain_before = refiner_->side_uncertain;
  const std::uint64_t side_from_view_before = refiner_->side_from_view;
  const std::uint64_t view_contested_before = refiner_->view_contested;
  const std::uint64_t along_from_standing_before = refiner_->along_from_standing;
  const std::uint64_t widened_before = refiner_->widened;
  const std::uint64_t partial_widened_before = refiner_->partial_widened;
  const std::uint64_t underdetermined_before = refiner_->underdetermined_widened;
  const std::uint64_t stance_weighted_before = refiner_->stance_weighted;
  const std::uint64_t touching_before = refiner_->touching;
  const std::uint64_t still_legs_before = refiner_->still_legs;
  const std::uint64_t mixed_legs_before = refiner_->mixed_legs;
  const std::uint64_t box_occluded_before = refiner_->box_occluded;
  const std::uint64_t box_unseen_widened_before = refiner_->box_unseen_widened;
  const std::uint64_t box_unseen_before = refiner_->box_unseen_sizes;
  const std::uint64_t box_bounded_before = refiner_->box_bounded;
  const std::uint64_t person_across_ray_before = refiner_->person_across_ray;
  const std::uint64_t person_beyond_reach_before = refiner_->person_beyond_reach;
  const std::uint64_t partial_size_floored_before = refiner_->partial_size_floored;
  const std::uint64_t neighbour_widened_before = refiner_->neighbour_widened;
  const std::uint64_t segment_excess_widened_before = refiner_->segment_excess_widened;
  const std::uint64_t occluded_gap_widened_before = refiner_->occluded_gap_widened;
  const std::uint64_t box_view_widened_before = refiner_->box_view_widened;
  const std::uint64_t person_size_kept_before = refiner_->person_size_kept;
  scan_ = &scan;
  ++refiner_->scans;
  tracker_.Step(scan.stamp_ns, measurements_.span(), offsets_s_.span(),
                shape_fit ? refiner_.get() : nullptr, tracks_);
  scan_ = nullptr;
  counters_.shape_fits += refiner_->fits - fits_before;
  counters_.failed_shape_fits += refiner_->failed - failed_before;
  counters_.legs_across_walk += refiner_->across_walk - across_walk_before;
  counters_.legs_side_uncertain += refiner_->side_uncertain - side_uncertain_before;
  counters_.legs_side_from_view += refiner_->side_from_view - side_from_view_before;
  counters_.legs_side_view_contested += refiner_->view_contested - view_contested_before;
  counters_.legs_along_from_standing += refiner_->along_from_standing - along_from_standing_before;
  counters_.outline_departure_widened += refiner_->widened - widened_before;
  counters_.partial_view_widened += refiner_->partial_widened - partial_widened_before;
  counters_.underdetermined_fit_widened +=
      refiner_->underdetermined_widened - underdetermined_before;
  counters_.stance_weighted_pairs += refiner_->stance_weighted - stance_weighted_before;
  counters_.touching_leg_pairs += refiner_->touching - touching_before;
  counters_.still_leg_pairs += refiner_->still_legs - still_legs_before;
  counters_.mixed_pixel_legs += refiner_->mixed_legs - mixed_legs_before;
  counters_.box_occluded_fits += refiner_->box_occluded - box_occluded_before;
  counters_.box_unseen_widened += refiner_->box_unseen_widened - box_unseen_widened_before;
  counters_.box_sizes_unseen += refiner_->box_unseen_sizes - box_unseen_before;
  counters_.box_semi_axes_bounded += refiner_->box_bounded - box_bounded_before;
  counters_.person_sizes_across_ray += refiner_->person_across_ray - person_across_ray_before;
  counters_.person_beyond_reach_fits += refiner_->person_beyond_reach - person_beyond_reach_before;
  counters_.partial_view_size_floored +=
      refiner_->partial_size_floored - partial_size_floored_before;
  counters_.neighbour_widened += refiner_->neighbour_widened - neighbour_widened_before;
  counters_.segment_excess_widened +=
      refiner_->segment_excess_widened - segment_excess_widened_before;
  counters_.occluded_gap_widened += refiner_->occluded_gap_widened - occluded_gap_widened_before;
  counters_.box_view_widened += refiner_->box_view_widened - box_view_widened_before;
  counters_.person_sizes_kept_few_points += refiner_->person_size_kept - person_size_kept_before;
  if (bg.scan_error == ScanError::kNone && bg.learned) {
    AbsorbStatic(scan);
    if (shape_fit) DropCoasting(scan);
  }
  tracks_.scan_counter = scan_counter;
  tracks_.scan_period_s = bg.scan_error == ScanError::kNone ? scan.scan_period_s : 0.0;
  return tracks_;
}

}  // namespace lrfnet::tracking
