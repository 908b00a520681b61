#include "firmware_tracker/tracking/segmentation.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include "common/geometry.h"
#include "firmware_tracker/tracking/tracking_test_util.h"

namespace lrfnet::tracking {
namespace {

// A scan of `n` beams, 0.5° apart, all at `range_m`.
struct MaskScan {
  explicit MaskScan(std::size_t n, float range_m = 5.0f) : ranges(n, range_m), mask(n, 0) {}
  ScanView view() const {
    return {common::DegToRad(-90.0), common::DegToRad(0.5), ranges, 0, 0.04};
  }
  void Mark(std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) mask[i] = 1;
  }
  std::vector<float> ranges;
  std::vector<std::uint8_t> mask;
};

TEST(SegmentationOptionsTest, DefaultsValidAndBadValuesRejected) {
  EXPECT_EQ(Validate(SegmentationOptions{}), std::nullopt);
  SegmentationOptions o;
  o.min_points = 0;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.max_points = kMaxSegmentPoints + 1;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.max_width_m = 0.0;
  EXPECT_NE(Validate(o), std::nullopt);
  EXPECT_EQ(Validate(RangeStepCutOptions{}), std::nullopt);
  RangeStepCutOptions r;
  r.max_piece_width_m = r.min_piece_width_m;
  EXPECT_NE(Validate(r), std::nullopt);
}

TEST(SegmentationTest, TwoSeparatedGroupsGiveTwoSegmentsWithSensorFramePoints) {
  MaskScan s(361);
  s.Mark(100, 106);
  s.Mark(200, 210);
  SegmentList out;
  SegmentScan(s.view(), s.mask, SegmentationOptions{}, out);
  ASSERT_EQ(out.segments.size(), 2u);
  EXPECT_EQ(out.segments[0].begin_beam, 100u);
  EXPECT_EQ(out.segments[0].end_beam, 106u);
  EXPECT_EQ(out.segments[1].begin_beam, 200u);
  EXPECT_EQ(out.segments[1].end_beam, 210u);
  const auto pts = out.Points(out.segments[1]);
  ASSERT_EQ(pts.size(), 10u);
  // Beam 200 points at -90° + 100° = +10°: in front, slightly to the left.
  EXPECT_NEAR(pts[0].x(), 5.0 * std::cos(common::DegToRad(10.0)), 1e-5);
  EXPECT_NEAR(pts[0].y(), 5.0 * std::sin(common::DegToRad(10.0)), 1e-5);
}

TEST(SegmentationTest, OneListFollowsChangingBeamGeometries) {
  // The list keeps its beams' directions between scans: a scan with another first angle, step or
  // beam count must not reuse them. Points are r * (cos, sin) of the beam's angle, bit for bit.
  SegmentList out;
  const std::vector<std::pair<double, double>> geometries = {
      {-90.0, 0.5}, {-90.0, 0.5}, {-45.0, 0.5}, {-45.0, 0.25}, {-45.0, 0.25}, {-90.0, 0.5}};
  for (std::size_t k = 0; k < geometries.size(); ++k) {
    MaskScan s(k == 4 ? 541 : 361, 3.0f + static_cast<float>(k));
    s.Mark(0, s.mask.size());  // every beam: the first segment starts at beam 0
    ScanView view = s.view();
    view.first_angle_rad = common::DegToRad(geometries[k].first);
    view.angle_step_rad = common::DegToRad(geometries[k].second);
    SegmentScan(view, s.mask, SegmentationOptions{}, out);
    ASSERT_FALSE(out.segments.empty()) << k;
    for (const Segment& seg : out.segments) {
      const auto pts = out.Points(seg);
      for (std::size_t b = 0; b < pts.size(); ++b) {
        const double angle_rad = view.BeamAngleRad(seg.begin_beam + b);
        const double r = s.ranges[seg.begin_beam + b];
        ASSERT_EQ(pts[b].x(), r * std::cos(angle_rad)) << "scan " << k << " beam " << b;
        ASSERT_EQ(pts[b].y(), r * std::sin(angle_rad)) << "scan " << k << " beam " << b;
      }
    }
  }
}

// The table's silhouette directions: the cosine and sine of the angles half a step beside each
// beam (ScanView::EdgeBeforeRad, EdgeAfterRad), the same values as libm's of those angles, for
// either sign of the step.
TEST(SegmentationTest, BeamTableHoldsTheEdgeDirectionsHalfAStepBesideEachBeam) {
  for (const double step : {common::DegToRad(0.1667), common::DegToRad(-0.5)}) {
    std::vector<float> ranges(761, 5.0f);
    ScanView scan;
    scan.first_angle_rad = common::DegToRad(-95.0);
    scan.angle_step_rad = step;
    scan.range_m = ranges;
    scan.scan_period_s = 0.04;
    const auto table_storage = std::make_unique<BeamDirections>();  // large: not on the stack
    BeamDirections& table = *table_storage;
    table.Fit(scan);
    for (std::size_t i = 0; i < ranges.size(); i += 7) {
      const double before = scan.EdgeBeforeRad(i), after = scan.EdgeAfterRad(i);
      EXPECT_NEAR(before, scan.BeamAngleRad(i) - 0.5 * step, 1e-15);  // towards beam i - 1
      EXPECT_NEAR(after, scan.BeamAngleRad(i) + 0.5 * step, 1e-15);
      EXPECT_EQ(table.edge_before(i)[0], std::cos(before));
      EXPECT_EQ(table.edge_before(i)[1], std::sin(before));
      EXPECT_EQ(table.edge_after(i)[0], std::cos(after));
      EXPECT_EQ(table.edge_after(i)[1], std::sin(after));
    }
  }
}

TEST(SegmentationTest, SingleBeamNoiseIsDropped) {
  MaskScan s(361);
  s.Mark(50, 51);
  s.Mark(150, 151);
  s.Mark(250, 254);
  SegmentList out;
  SegmentScan(s.view(), s.mask, SegmentationOptions{}, out);
  ASSERT_EQ(out.segments.size(), 1u);
  EXPECT_EQ(out.segments[0].begin_beam, 250u);
  EXPECT_EQ(out.points_m.size(), 4u);
}

TEST(SegmentationTest, MissingBeamGapUpToLimitJoinsBeyondSplits) {
  SegmentationOptions o;
  o.max_missing_beams = 2;
  MaskScan s(361);
  s.Mark(100, 104);
  s.Mark(106, 110);  // 2 missing beams: joined
  s.Mark(113, 117);  // 3 missing beams: split
  SegmentList out;
  SegmentScan(s.view(), s.mask, o, out);
  ASSERT_EQ(out.segments.size(), 2u);
  EXPECT_EQ(out.segments[0].begin_beam, 100u);
  EXPECT_EQ(out.segments[0].end_beam, 110u);
  EXPECT_EQ(out.segments[0].point_count, 8u);
  EXPECT_EQ(out.segments[1].begin_beam, 113u);
}

// SeeThroughCuts: two bodies at 5 m, 12 beams each (0.48 m across), two beams between them that
// the segmentation joins across (one segment about 1.1 m wide); what those two beams returned
// decides whether the segment is cut between the bodies.
struct TwoBodies {
  explicit TwoBodies(float between_m) : s(361) {
    s.Mark(100, 112);
    s.Mark(114, 126);
    s.ranges[112] = s.ranges[113] = between_m;
    SegmentationOptions o;
    o.max_width_m = 2.0;
    SegmentScan(s.view(), s.mask, o, list);
  }
  std::size_t Cuts(double min_width_m, std::array<std::size_t, 3>& cuts) const {
    return SeeThroughCuts(s.view(), list, list.segments[0], SegmentationOptions{}, min_width_m,
                          cuts);
  }
  MaskScan s;
  SegmentList list;
};

TEST(SegmentationTest, SeeThroughCutsWhereBeamsBetweenTwoBodiesReturnedFromBeyond) {
  std::array<std::size_t, 3> cuts{};
  const TwoBodies wall_behind(8.0f);  // 3 m behind: beyond the jump limit (0.3 m at 5 m)
  ASSERT_EQ(wall_behind.list.segments.size(), 1u);
  EXPECT_GT(wall_behind.list.segments[0].width_m, 1.0);
  ASSERT_EQ(wall_behind.Cuts(0.7, cuts), 1u);
  EXPECT_EQ(cuts[0], 12u);  // the second body's first point
  const TwoBodies no_echo(0.0f);
  ASSERT_EQ(no_echo.Cuts(0.7, cuts), 1u);
  EXPECT_EQ(cuts[0], 12u);
  // A return within the jump limit behind the bodies (a surface they stand against): not seen
  // through, one object as far as the scan tells.
  const TwoBodies close_behind(5.2f);
  EXPECT_EQ(close_behind.Cuts(0.7, cuts), 0u);
  // Narrower than min_width_m (one body with a dropout): whole.
  EXPECT_EQ(wall_behind.Cuts(1.2, cuts), 0u);
}

TEST(SegmentationTest, SeeThroughCutsLeaveNoPieceBelowMinPoints) {
  MaskScan s(361);
  s.Mark(100, 101);  // one point, then two beams seen through, then a body
  s.Mark(103, 125);
  s.ranges[101] = s.ranges[102] = 9.0f;
  SegmentationOptions o;
  o.max_width_m = 2.0;
  SegmentList list;
  SegmentScan(s.view(), s.mask, o, list);
  ASSERT_EQ(list.segments.size(), 1u);
  std::array<std::size_t, 3> cuts{};
  EXPECT_EQ(SeeThroughCuts(s.view(), list, list.segments[0], o, 0.7, cuts), 0u);
}

// RangeStepCuts: what a scan at 0.5 degrees shows of round bodies (radius 0.22 m, a person's
// shoulders) and straight faces, each beam returning from the nearest outline it meets.
struct Outlines {
  MaskScan s{361, 0.0f};
  void Circle(double range_m, double bearing_deg, double radius_m) {
    const Eigen::Vector2d c = range_m * Eigen::Vector2d(std::cos(common::DegToRad(bearing_deg)),
                                                        std::sin(common::DegToRad(bearing_deg)));
    for (std::size_t i = 0; i < s.ranges.size(); ++i) {
      const double a = common::DegToRad(-90.0 + 0.5 * static_cast<double>(i));
      const Eigen::Vector2d u(std::cos(a), std::sin(a));
      const double along = u.dot(c);
      const double across2 = c.squaredNorm() - along * along;
      if (across2 >= radius_m * radius_m) continue;
      Hit(i, along - std::sqrt(radius_m * radius_m - across2));
    }
  }
  // A straight face from p to q.
  void Face(const Eigen::Vector2d& p, const Eigen::Vector2d& q) {
    for (std::size_t i = 0; i < s.ranges.size(); ++i) {
      const double a = common::DegToRad(-90.0 + 0.5 * static_cast<double>(i));
      const Eigen::Vector2d u(std::cos(a), std::sin(a));
      const Eigen::Vector2d d = q - p;
      const double den = u.x() * d.y() - u.y() * d.x();
      if (std::abs(den) < 1e-12) continue;
      const double t = (p.x() * d.y() - p.y() * d.x()) / den;  // along the beam
      const double w = (p.x() * u.y() - p.y() * u.x()) / den;  // along the face
      if (t > 0.0 && w >= 0.0 && w <= 1.0) Hit(i, t);
    }
  }
  void Hit(std::size_t i, double r) {
    if (s.mask[i] == 0 || r < s.ranges[i]) s.ranges[i] = static_cast<float>(r);
    s.mask[i] = 1;
  }
  SegmentList Segments() const {
    SegmentList list;
    SegmentScan(s.view(), s.mask, SegmentationOptions{}, list);
    return list;
  }
};

TEST(SegmentationTest, RangeStepCutsBetweenTwoPeopleWithNoBeamBetweenThem) {
  Outlines o;
  o.Circle(4.2, -3.4, 0.23);  // the nearer person
  o.Circle(4.35, 2.7, 0.23);  // the other, 0.15 m farther, its shoulder behind the first's
  const SegmentList list = o.Segments();
  ASSERT_EQ(list.segments.size(), 1u);  // no beam sees through: one segment
  const Segment& s = list.segments[0];
  EXPECT_GT(s.width_m, 0.8);
  std::array<std::size_t, 3> cuts{};
  ASSERT_EQ(RangeStepCuts(list, s, RangeStepCutOptions{}, cuts), 1u);
  const auto pts = list.Points(s);
  // The first piece is the nearer person's (all within 0.24 m of its centre), the rest the other's.
  const Eigen::Vector2d a =
      4.2 * Eigen::Vector2d(std::cos(common::DegToRad(-3.4)), std::sin(common::DegToRad(-3.4)));
  for (std::size_t k = 0; k < pts.size(); ++k) {
    EXPECT_EQ((pts[k] - a).norm() < 0.24, k < cuts[0]) << k;
  }
  // Narrower than min_width_m: whole.
  RangeStepCutOptions narrow;
  narrow.min_width_m = 1.5;
  EXPECT_EQ(RangeStepCuts(list, s, narrow, cuts), 0u);
}

TEST(SegmentationTest, RangeStepCutsWhereTheNearerHidesTheOthersNearestPoint) {
  // The farther person's nearest point lies just beside the nearer one's silhouette: its outline
  // at the step rises less than min_turn_m from there (the nearer one hides the rest of its turn).
  Outlines o;
  o.Circle(4.0, -4.0, 0.23);
  o.Circle(4.3, 0.5, 0.23);
  const SegmentList list = o.Segments();
  ASSERT_EQ(list.segments.size(), 1u);
  const Segment& s = list.segments[0];
  RangeStepCutOptions hidden;
  hidden.min_width_m = 0.6;
  std::array<std::size_t, 3> cuts{};
  ASSERT_EQ(RangeStepCuts(list, s, hidden, cuts), 1u);
  const auto pts = list.Points(s);
  const Eigen::Vector2d a =
      4.0 * Eigen::Vector2d(std::cos(common::DegToRad(-4.0)), std::sin(common::DegToRad(-4.0)));
  for (std::size_t k = 0; k < pts.size(); ++k) {
    EXPECT_EQ((pts[k] - a).norm() < 0.24, k < cuts[0]) << k;
  }
  // Both pieces asked to turn at the step: whole.
  RangeStepCutOptions both_turn = hidden;
  both_turn.hidden_far_piece = false;
  EXPECT_EQ(RangeStepCuts(list, s, both_turn, cuts), 0u);
}

TEST(SegmentationTest, RangeStepCutsKeepAStraightFaceWithWhatStandsBehindItsEnd) {
  // A cart's face, 0.5 m across, seen obliquely, its pusher standing behind its far end: the face
  // is not curved, so not a body of its own (with any straight run taken for one: cut).
  Outlines o;
  o.Face({3.95, -0.5}, {4.1, -0.02});
  o.Circle(4.35, 2.7, 0.23);
  const SegmentList list = o.Segments();
  ASSERT_EQ(list.segments.size(), 1u);
  ASSERT_GT(list.segments[0].width_m, 0.8);
  std::array<std::size_t, 3> cuts{};
  EXPECT_EQ(RangeStepCuts(list, list.segments[0], RangeStepCutOptions{}, cuts), 0u);
  RangeStepCutOptions flat;
  flat.min_bulge_m = 0.0;
  EXPECT_EQ(RangeStepCuts(list, list.segments[0], flat, cuts), 1u);
  // One round body alone, however wide the limits allow: no step, no cut.
  Outlines one;
  one.Circle(3.0, 0.0, 0.45);
  const SegmentList whole = one.Segments();
  ASSERT_EQ(whole.segments.size(), 1u);
  RangeStepCutOptions wide;
  wide.min_width_m = 0.5;
  wide.max_piece_width_m = 1.0;
  EXPECT_EQ(RangeStepCuts(whole, whole.segments[0], wide, cuts), 0u);
}

TEST(SegmentationTest, RangeJumpSplitsNeighbouringBeams) {
  MaskScan s(361);
  s.Mark(100, 110);
  for (std::size_t i = 105; i < 110; ++i) s.ranges[i] = 6.0f;  // a person behind another
  SegmentList out;
  SegmentScan(s.view(), s.mask, SegmentationOptions{}, out);
  ASSERT_EQ(out.segments.size(), 2u);
  EXPECT_EQ(out.segments[0].end_beam, 105u);
  EXPECT_EQ(out.segments[1].begin_beam, 105u);
}

TEST(SegmentationTest, JumpThresholdGrowsWithRange) {
  // At 20 m, 0.5° beams are 17 cm apart: beyond the 15 cm base, within base + 0.03 * 20.
  MaskScan s(361, 20.0f);
  s.Mark(100, 104);
  SegmentList out;
  SegmentationOptions o;
  SegmentScan(s.view(), s.mask, o, out);
  EXPECT_EQ(out.segments.size(), 1u);
  o.jump_per_m = 0.0;
  SegmentScan(s.view(), s.mask, o, out);
  EXPECT_EQ(out.segments.size(), 0u) << "every point alone, dropped as single-beam noise";
}

TEST(SegmentationTest, WideSegmentsAreSplitIntoPiecesNoWiderThanMax) {
  MaskScan s(361, 5.0f);
  s.Mark(100, 160);  // 30° at 5 m: a 2.6 m long object
  SegmentationOptions o;
  o.max_width_m = 0.8;
  SegmentList out;
  SegmentScan(s.view(), s.mask, o, out);
  ASSERT_GE(out.segments.size(), 3u);
  std::size_t points = 0;
  for (const Segment& seg : out.segments) {
    EXPECT_LE(seg.width_m, o.max_width_m + 1e-9);
    points += seg.point_count;
  }
  EXPECT_EQ(points, 60u);
}

TEST(SegmentationTest, MinWidthAndMinPointsDrop) {
  MaskScan s(361, 5.0f);
  s.Mark(100, 103);  // 3 points, ~9 cm wide
  SegmentationOptions o;
  o.min_points = 4;
  SegmentList out;
  SegmentScan(s.view(), s.mask, o, out);
  EXPECT_TRUE(out.segments.empty());
  o = {};
  o.min_width_m = 0.2;
  SegmentScan(s.view(), s.mask, o, out);
  EXPECT_TRUE(out.segments.empty());
  EXPECT_TRUE(out.points_m.empty()) << "points of dropped segments are released";
}

TEST(SegmentationTest, MoreSegmentsThanCapacityAreCountedNotOverflowed) {
  MaskScan s(kMaxBeams, 5.0f);
  std::size_t groups = 0;
  for (std::size_t i = 0; i + 2 < kMaxBeams; i += 6, ++groups) s.Mark(i, i + 2);
  ASSERT_GT(groups, kMaxSegments);
  SegmentList out;
  SegmentScan(s.view(), s.mask, SegmentationOptions{}, out);
  EXPECT_EQ(out.segments.size(), kMaxSegments);
  EXPECT_EQ(out.dropped_segments, groups - kMaxSegments);
  EXPECT_EQ(out.points_m.size(), 2 * kMaxSegments);
}

TEST(SegmentationTest, ShortMaskBadScanAndNoEchoBeamsAreSafe) {
  MaskScan s(361, 5.0f);
  s.Mark(100, 110);
  s.ranges[104] = 0.0f;  // no echo inside the group: skipped, within the missing-beam allowance
  SegmentList out;
  SegmentScan(s.view(), std::span<const std::uint8_t>(s.mask).first(107), SegmentationOptions{},
              out);
  ASSERT_EQ(out.segments.size(), 1u);
  EXPECT_EQ(out.segments[0].point_count, 6u);
  ScanView bad = s.view();
  bad.angle_step_rad = 0.0;
  SegmentScan(bad, s.mask, SegmentationOptions{}, out);
  EXPECT_TRUE(out.segments.empty());
}

// The segmentation rule as the header states it, one beam at a time, for comparison: a point joins
// the open segment when no more than max_missing_beams beams lie between, its jump is within the
// limit, the segment holds fewer than max_points and the point lies within max_width_m of the
// first.
struct ReferenceSegments {
  std::vector<Segment> segments;
  std::vector<Eigen::Vector2d> points;
  std::uint64_t dropped = 0;  // beyond kMaxSegments
};
ReferenceSegments ReferenceSegmentScan(const ScanView& scan, const std::vector<std::uint8_t>& mask,
                                       const SegmentationOptions& o) {
  ReferenceSegments out;
  std::vector<std::size_t> beams;
  std::vector<Eigen::Vector2d> open;
  const auto close = [&] {
    if (open.empty()) return;
    const double width_m = (open.back() - open.front()).norm();
    if (open.size() >= o.min_points && !(width_m < o.min_width_m)) {
      if (out.segments.size() == kMaxSegments) {
        ++out.dropped;
      } else {
        out.segments.push_back(
            {beams.front(), beams.back() + 1, out.points.size(), open.size(), width_m});
        out.points.insert(out.points.end(), open.begin(), open.end());
      }
    }
    open.clear();
    beams.clear();
  };
  for (std::size_t i = 0; i < scan.range_m.size(); ++i) {
    const double r = scan.range_m[i];
    if (mask[i] == 0 || !(std::isfinite(r) && r > 0.0)) continue;
    const double angle = scan.first_angle_rad + static_cast<double>(i) * scan.angle_step_rad;
    const Eigen::Vector2d p(r * std::cos(angle), r * std::sin(angle));
    if (!open.empty() &&
        !(i - beams.back() - 1 <= o.max_missing_beams &&
          (p - open.back()).norm() <= o.jump_base_m + o.jump_per_m * r &&
          open.size() < o.max_points && (p - open.front()).norm() <= o.max_width_m)) {
      close();
    }
    open.push_back(p);
    beams.push_back(i);
  }
  close();
  return out;
}

TEST(SegmentationTest, RandomScansGiveTheSegmentsOfTheRuleBeamByBeam) {
  std::mt19937_64 rng(2028);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  SegmentList out;
  std::size_t compared_segments = 0;
  for (int trial = 0; trial < 300; ++trial) {
    MaskScan s(400, 5.0f);
    double range = 1.0 + 9.0 * unit(rng);
    for (std::size_t i = 0; i < s.ranges.size(); ++i) {
      const double u = unit(rng);
      // A walk in range with jumps, runs of foreground, and beams without a return.
      range = u < 0.1 ? 0.5 + 15.0 * unit(rng) : std::max(0.3, range + 0.1 * (unit(rng) - 0.5));
      s.ranges[i] = u > 0.97 ? 0.0f : u > 0.96 ? std::nanf("") : static_cast<float>(range);
      if (i == 0 || unit(rng) < 0.15)
        s.mask[i] = unit(rng) < 0.6 ? 1 : 0;
      else
        s.mask[i] = s.mask[i - 1];
    }
    SegmentationOptions o;
    o.max_missing_beams = static_cast<std::size_t>(rng() % 4);
    o.min_points = 1 + static_cast<std::size_t>(rng() % 3);
    o.max_points = o.min_points + static_cast<std::size_t>(rng() % 12);
    o.min_width_m = 0.1 * unit(rng);
    o.max_width_m = o.min_width_m + 0.2 + 1.2 * unit(rng);
    ASSERT_EQ(Validate(o), std::nullopt);
    SegmentScan(s.view(), s.mask, o, out);
    const ReferenceSegments want = ReferenceSegmentScan(s.view(), s.mask, o);
    ASSERT_EQ(out.segments.size(), want.segments.size()) << "trial " << trial;
    ASSERT_EQ(out.points_m.size(), want.points.size()) << "trial " << trial;
    EXPECT_EQ(out.dropped_segments, want.dropped);
    for (std::size_t k = 0; k < want.segments.size(); ++k) {
      const Segment& got = out.segments[k];
      const Segment& ref = want.segments[k];
      EXPECT_EQ(got.begin_beam, ref.begin_beam);
      EXPECT_EQ(got.end_beam, ref.end_beam);
      EXPECT_EQ(got.first_point, ref.first_point);
      EXPECT_EQ(got.point_count, ref.point_count);
      EXPECT_NEAR(got.width_m, ref.width_m, 1e-12);
    }
    for (std::size_t k = 0; k < want.points.size(); ++k) {
      EXPECT_NEAR((out.points_m[k] - want.points[k]).norm(), 0.0, 1e-12);
    }
    compared_segments += want.segments.size();
  }
  EXPECT_GT(compared_segments, 3000u);
}

TEST(SegmentationTest, PersonInSyntheticScanIsOneSegment) {
  testing::SyntheticScanner scanner;
  const std::vector<testing::Body> people = {{{3.0, 1.0}, 0.25, 0.15, 0.3},
                                             {{3.0, -1.0}, 0.25, 0.15, -0.3}};
  const ScanView scan = scanner.Render(0, {}, people);
  std::vector<std::uint8_t> mask(scan.range_m.size());
  for (std::size_t i = 0; i < mask.size(); ++i) mask[i] = scan.range_m[i] > 0.0f ? 1 : 0;
  SegmentList out;
  SegmentScan(scan, mask, SegmentationOptions{}, out);
  ASSERT_EQ(out.segments.size(), 2u);
  auto mean_y = [&](std::size_t k) {
    double sum = 0.0;
    for (const auto& p : out.Points(out.segments[k])) sum += p.y();
    return sum / static_cast<double>(out.segments[k].point_count);
  };
  // Beams run counter-clockwise: the person on the right (negative y) comes first.
  EXPECT_NEAR(mean_y(0), -1.0, 0.2);
  EXPECT_NEAR(mean_y(1), 1.0, 0.2);
}

}  // namespace
TEST(SegmentationTest, DeepTailsAreTheEndRunsBeyondTheNearestPointByTheDepth) {
  SegmentList list;
  // One segment along one bearing: ranges 8.6, 8.3 | 7.9, 7.85, 7.9, 8.0 | 8.4 (metres).
  for (const double r : {8.6, 8.3, 7.9, 7.85, 7.9, 8.0, 8.4}) {
    (void)list.points_m.push_back(Eigen::Vector2d(r, 0.0));
  }
  Segment s;
  s.point_count = list.points_m.size();
  // Beyond 7.85 + 0.35 = 8.2: two points at the start, one at the end.
  DeepTails t = FindDeepTails(list, s, 0.35);
  EXPECT_EQ(t.lead, 2u);
  EXPECT_EQ(t.trail, 1u);
  // Beyond 8.35: one at either end (8.3 is not).
  t = FindDeepTails(list, s, 0.5);
  EXPECT_EQ(t.lead, 1u);
  EXPECT_EQ(t.trail, 1u);
  // Nothing beyond 8.85.
  t = FindDeepTails(list, s, 1.0);
  EXPECT_EQ(t.lead + t.trail, 0u);
}

}  // namespace lrfnet::tracking
