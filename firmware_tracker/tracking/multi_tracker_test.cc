#include "firmware_tracker/tracking/multi_tracker.h"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <limits>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include "common/cv_model.h"

namespace lrfnet::tracking {
namespace {

constexpr common::UtcNs kT0 = 1'600'000'000 * common::kNsPerS;
constexpr common::DurationNs kPeriodNs = 40 * common::kNsPerMs;  // 25 Hz

common::UtcNs ScanNs(std::int64_t k) { return kT0 + k * kPeriodNs; }

// The tracker without its static-object handling: these tests feed objects that stand still.
MultiTrackerOptions Opts() {
  MultiTrackerOptions o;
  o.static_objects = false;
  o.report_coasting_s = o.coast_timeout_s;  // every coasting scan reported
  o.report_coasting_per_measured_s = 0.0;
  o.confirm_min_s = 0.0;  // M of N alone
  return o;
}

Measurement Meas(double x, double y, double sigma_m = 0.05) {
  Measurement m;
  m.position_m = {x, y};
  m.covariance_m2 = sigma_m * sigma_m * Eigen::Matrix2d::Identity();
  m.point_count = 12;
  return m;
}

// internal::Extrapolate moves a just-updated track back to the scan start (a negative dt of a few
// ms) by F's structure instead of 4 x 4 products: the same state and covariance as the full
// products F x and F P F^T (re-symmetrised), for either sign of dt, up to floating-point
// contraction (a few units in the last place where multiply-adds are fused, else bit for bit).
TEST(MultiTrackerTest, ExtrapolateIsTheFullProducts) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 500; ++trial) {
    Eigen::Matrix4d a;
    for (int i = 0; i < 16; ++i) a(i / 4, i % 4) = u(rng);
    Eigen::Matrix4d p = a * a.transpose() + 1e-3 * Eigen::Matrix4d::Identity();
    p = (0.5 * (p + p.transpose())).eval();
    const Eigen::Vector4d x(3.0 * u(rng), 3.0 * u(rng), u(rng), u(rng));
    const double dt_s = 0.04 * u(rng);
    const Eigen::Matrix4d f = common::CvTransition(dt_s);
    const Eigen::Vector4d x_full = f * x;
    Eigen::Matrix4d p_full = f * p * f.transpose();
    p_full = 0.5 * (p_full + p_full.transpose()).eval();
    Eigen::Vector4d x_fast = x;
    Eigen::Matrix4d p_fast = p;
    internal::Extrapolate(dt_s, x_fast, p_fast);
    const double tol = 8.0 * std::numeric_limits<double>::epsilon();
    for (int i = 0; i < 4; ++i) {
      ASSERT_NEAR(x_fast(i), x_full(i), tol * (1.0 + std::abs(x_full(i)))) << "trial " << trial;
      for (int j = 0; j < 4; ++j) {
        ASSERT_NEAR(p_fast(i, j), p_full(i, j), tol * (1.0 + p_full.cwiseAbs().maxCoeff()))
            << "trial " << trial;
      }
    }
    // A move by dt is not the identity: the test sees the function act.
    if (std::abs(dt_s * x(2)) > 1e-6) {
      ASSERT_NE(x_fast(0), x(0));
    }
  }
}

const TrackReport* FindId(const ScanTracks& out, std::uint32_t id) {
  for (const TrackReport& r : out.tracks) {
    if (r.track_id == id) return &r;
  }
  return nullptr;
}

// Feeds the same measurements for scans [k_begin, k_end).
void Feed(MultiTracker& tracker, std::int64_t k_begin, std::int64_t k_end,
          const std::vector<Measurement>& ms, ScanTracks& out) {
  for (std::int64_t k = k_begin; k < k_end; ++k) tracker.Step(ScanNs(k), ms, out);
}

TEST(MultiTrackerOptionsTest, DefaultsValidAndEachBadValueNamesItsField) {
  const MultiTrackerOptions defaults;
  EXPECT_EQ(Validate(defaults), std::nullopt);
  EXPECT_EQ(defaults.association, Association::kGlobalNearestNeighbour);
  EXPECT_LE(defaults.max_tracks, kMaxTracks);

  struct Case {
    MultiTrackerOptions options;
    const char* field;
  };
  auto with = [](auto change) {
    MultiTrackerOptions o = Opts();
    change(o);
    return o;
  };
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::vector<Case> cases = {
      {with([](auto& o) { o.confirm_hits = 0; }), "confirm_hits"},
      {with([](auto& o) { o.confirm_hits = 5; }), "confirm_hits"},  // > confirm_window (4)
      {with([](auto& o) { o.confirm_window = 33; }), "confirm_window"},
      {with([](auto& o) { o.confirm_min_s = -0.1; }), "confirm_min_s"},
      {with([](auto& o) { o.confirm_min_s = 11.0; }), "confirm_min_s"},
      {with([nan](auto& o) { o.confirm_min_s = nan; }), "confirm_min_s"},
      {with([](auto& o) { o.report_coasting_per_measured_s = -1.0; }),
       "report_coasting_per_measured_s"},
      {with([nan](auto& o) { o.report_coasting_per_measured_s = nan; }),
       "report_coasting_per_measured_s"},
      {with([](auto& o) { o.seen_gap_s = -0.1; }), "seen_gap_s"},
      {with([](auto& o) { o.gate_mahalanobis_sq = 0.0; }), "gate_mahalanobis_sq"},
      {with([nan](auto& o) { o.gate_mahalanobis_sq = nan; }), "gate_mahalanobis_sq"},
      {with([](auto& o) { o.max_gate_distance_m = -1.0; }), "max_gate_distance_m"},
      {with([](auto& o) { o.extra_measurement_sigma_m = -0.01; }), "extra_measurement_sigma_m"},
      {with([nan](auto& o) { o.recover_gate_mahalanobis_sq = nan; }),
       "recover_gate_mahalanobis_sq"},
      {with([](auto& o) { o.inflate_nis_above = 1.0; }), "inflate_nis_above"},
      {with([](auto& o) { o.inflate_nis_above = -1.0; }), "inflate_nis_above"},
      {with([](auto& o) { o.measured_noise_memory_scans = -1.0; }), "measured_noise_memory_scans"},
      {with([](auto& o) { o.measured_noise_memory_scans = 0.5; }), "measured_noise_memory_scans"},
      {with([](auto& o) { o.coast_timeout_s = 0.0; }), "coast_timeout_s"},
      {with([](auto& o) { o.resume_window_s = -1.0; }), "resume_window_s"},
      {with([](auto& o) { o.adopt_successor_m = -1.0; }), "adopt_successor_m"},
      {with([nan](auto& o) { o.adopt_successor_m = nan; }), "adopt_successor_m"},
      {with([](auto& o) { o.adopt_after_hits = 0; }), "adopt_after_hits"},
      {with([](auto& o) { o.inherit_moved_s = -1.0; }), "inherit_moved_s"},
      {with([nan](auto& o) { o.inherit_moved_s = nan; }), "inherit_moved_s"},
      {with([nan](auto& o) { o.resume_window_s = nan; }), "resume_window_s"},
      {with([](auto& o) { o.max_position_sigma_m = 0.0; }), "max_position_sigma_m"},
      {with([](auto& o) { o.max_tracks = 0; }), "max_tracks"},
      {with([](auto& o) { o.max_tracks = kMaxTracks + 1; }), "max_tracks"},
      {with([](auto& o) { o.max_time_gap_s = 0.0; }), "max_time_gap_s"},
      {with([](auto& o) { o.ekf.accel_psd_m2ps3 = -1.0; }), "ekf.accel_psd_m2ps3"},
      {with([](auto& o) { o.association = static_cast<Association>(7); }), "association"},
  };
  for (const Case& c : cases) {
    const auto error = Validate(c.options);
    ASSERT_NE(error, std::nullopt) << c.field;
    EXPECT_EQ(error->rfind(c.field, 0), 0u) << *error;
  }
}

TEST(MultiTrackerTest, ConfirmsAfterThreeOfFourScansAndHidesTentativeTracksByDefault) {
  MultiTracker tracker{Opts()};
  ScanTracks out;
  const std::vector<Measurement> here = {Meas(2.0, 1.0)};
  const std::vector<Measurement> none;
  tracker.Step(ScanNs(0), here, out);
  EXPECT_TRUE(out.tracks.empty());  // tentative: not reported
  EXPECT_EQ(tracker.track_count(), 1u);
  tracker.Step(ScanNs(1), none, out);  // a miss
  tracker.Step(ScanNs(2), here, out);
  EXPECT_TRUE(out.tracks.empty());  // 2 of 3
  tracker.Step(ScanNs(3), here, out);
  ASSERT_EQ(out.tracks.size(), 1u);  // 3 of 4
  EXPECT_EQ(out.tracks[0].track_id, 1u);
  EXPECT_EQ(out.tracks[0].state, TrackState::kConfirmed);
  EXPECT_EQ(out.tracks[0].age_scans, 3u);
  EXPECT_EQ(out.scan_start_ns, ScanNs(3));
  EXPECT_NEAR(out.tracks[0].x_m, 2.0, 0.01);
  EXPECT_EQ(tracker.counters().confirmed, 1u);
}

TEST(MultiTrackerTest, TentativeTrackIsDeletedAsSoonAsItCanNoLongerBeConfirmed) {
  MultiTrackerOptions options = Opts();
  options.report_tentative = true;
  MultiTracker tracker(options);
  ScanTracks out;
  const std::vector<Measurement> none;
  tracker.Step(ScanNs(0), std::vector<Measurement>{Meas(2.0, 1.0)}, out);
  ASSERT_EQ(out.tracks.size(), 1u);
  EXPECT_EQ(out.tracks[0].state, TrackState::kTentative);
  tracker.Step(ScanNs(1), none, out);
  EXPECT_EQ(out.tracks.size(), 1u);  // 1 hit, 2 scans left: 3 of 4 still possible
  tracker.Step(ScanNs(2), none, out);
  EXPECT_TRUE(out.tracks.empty());  // at most 2 of 4 now
  EXPECT_EQ(tracker.counters().deleted_tentative, 1u);
  EXPECT_EQ(tracker.counters().confirmed, 0u);
}

TEST(MultiTrackerTest, OneOfOneConfirmsAtBirth) {
  MultiTrackerOptions options = Opts();
  options.confirm_hits = 1;
  options.confirm_window = 1;
  MultiTracker tracker(options);
  ScanTracks out;
  tracker.Step(ScanNs(0), std::vector<Measurement>{Meas(1.0, 0.0)}, out);
  ASSERT_EQ(out.tracks.size(), 1u);
  EXPECT_EQ(out.tracks[0].state, TrackState::kConfirmed);
}

TEST(MultiTrackerTest, MahalanobisAndDistanceGates) {
  MultiTracker tracker{Opts()};
  ScanTracks out;
  Feed(tracker, 0, 20, {Meas(3.0, 0.0, 0.05)}, out);
  ASSERT_EQ(out.tracks.size(), 1u);

  // 0.4 m off with 5 cm sigmas: d2 far above 9.21, so not this track; it starts a new one.
  tracker.Step(ScanNs(20), std::vector<Measurement>{Meas(3.4, 0.0, 0.05)}, out);
  ASSERT_EQ(out.tracks.size(), 1u);
  EXPECT_EQ(out.tracks[0].state, TrackState::kCoasting);
  EXPECT_NEAR(out.tracks[0].x_m, 3.0, 0.02);
  EXPECT_EQ(tracker.track_count(), 2u);
  EXPECT_EQ(tracker.counters().created, 2u);

  // A vague measurement (1 m sigma) 1.5 m away is inside the statistical gate but beyond the 1 m
  // distance gate.
  tracker.Step(ScanNs(21), std::vector<Measurement>{Meas(3.0, 1.5, 1.0)}, out);
  ASSERT_NE(FindId(out, 1), nullptr);
  EXPECT_EQ(FindId(out, 1)->state, TrackState::kCoasting);
  EXPECT_NEAR(FindId(out, 1)->y_m, 0.0, 0.02);

  // Within 2 sigma: associated.
  tracker.Step(ScanNs(22), std::vector<Measurement>{Meas(3.05, 0.05, 0.05)}, out);
  ASSERT_NE(FindId(out, 1), nullptr);
  EXPECT_EQ(FindId(out, 1)->state, TrackState::kConfirmed);
  EXPECT_GT(FindId(out, 1)->x_m, 3.0);
}

// Two stationary tracks A at x = 0 and B at x = 1; then measurements at x = 0.6 (A: 0.6 m, B: 0.4
// m) and x = 1.7 (B: 0.7 m, beyond A's gate), both with 0.3 m sigma so that both pairs of B gate.
// The paper's greedy rule gives 0.6 to B, its closest, and leaves A without a measurement; the
// global assignment pairs both, B-1.7.
class AmbiguousAssociationTest : public ::testing::TestWithParam<Association> {};

TEST_P(AmbiguousAssociationTest, GlobalAssignmentPairsBothGreedyClosestStealsOne) {
  MultiTrackerOptions options = Opts();
  options.association = GetParam();
  MultiTracker tracker(options);
  ScanTracks out;
  Feed(tracker, 0, 10, {Meas(0.0, 0.0, 0.05), Meas(1.0, 0.0, 0.05)}, out);
  ASSERT_EQ(out.tracks.size(), 2u);
  const double a_before = FindId(out, 1)->x_m, b_before = FindId(out, 2)->x_m;
  ASSERT_NEAR(a_before, 0.0, 0.05);
  ASSERT_NEAR(b_before, 1.0, 0.05);

  tracker.Step(ScanNs(10), std::vector<Measurement>{Meas(0.6, 0.0, 0.3), Meas(1.7, 0.0, 0.3)}, out);
  ASSERT_EQ(out.tracks.size(), 2u);
  const TrackReport& a = *FindId(out, 1);
  const TrackReport& b = *FindId(out, 2);
  if (GetParam() == Association::kGlobalNearestNeighbour) {
    EXPECT_EQ(a.state, TrackState::kConfirmed);
    EXPECT_EQ(b.state, TrackState::kConfirmed);
    EXPECT_GT(a.x_m - a_before, 0.005);  // pulled towards 0.6
    EXPECT_GT(b.x_m - b_before, 0.005);  // pulled towards 1.7
  } else {
    EXPECT_EQ(a.state, TrackState::kCoasting);
    EXPECT_NEAR(a.x_m, a_before, 0.001);
    EXPECT_EQ(b.state, TrackState::kConfirmed);
    EXPECT_LT(b.x_m - b_before, -0.005);  // pulled towards 0.6
  }
  // 1.7 lies in B's gate either way: no third track.
  EXPECT_EQ(tracker.track_count(), 2u);
}

INSTANTIATE_TEST_SUITE_P(Rules, AmbiguousAssociationTest,
                         ::testing::Values(Association::kGlobalNearestNeighbour,
                                           Association::kClosest));

TEST(MultiTrackerTest, GlobalAssignmentHandlesMoreTracksThanMeasurementsAndViceVersa) {
  MultiTracker tracker{Opts()};
  ScanTracks out;
  std::vector<Measurement> five;
  for (int i = 0; i < 5; ++i) five.push_back(Meas(1.0 + 2.0 * i, 0.0));
  Feed(tracker, 0, 5, five, out);
  ASSERT_EQ(out.tracks.size(), 5u);
  // Two measurements for five tracks: the right two tracks are updated.
  tracker.Step(ScanNs(5), std::vector<Measurement>{Meas(7.0, 0.01), Meas(3.0, 0.01)}, out);
  for (const TrackReport& r : out.tracks) {
    const bool expect_update = r.track_id == 2 || r.track_id == 4;
    EXPECT_EQ(r.state, expect_update ? TrackState::kConfirmed : TrackState::kCoasting)
        << "id " << r.track_id;
  }
  // Seven measurements for five tracks: every track updated, two new tentative tracks.
  five.push_back(Meas(-5.0, 0.0));
  five.push_back(Meas(-8.0, 0.0));
  tracker.Step(ScanNs(6), five, out);
  EXPECT_EQ(out.tracks.size(), 5u);
  for (const TrackReport& r : out.tracks) EXPECT_EQ(r.state, TrackState::kConfirmed);
  EXPECT_EQ(tracker.track_count(), 7u);
}

TEST(MultiTrackerTest, ConfirmedTrackCoastsWithItsVelocityThenTimesOut) {
  MultiTracker tracker{Opts()};
  ScanTracks out;
  std::int64_t k = 0;
  for (; k < 50; ++k) {  // 2 s at 1 m/s along x
    tracker.Step(ScanNs(k),
                 std::vector<Measurement>{Meas(1.0 + 0.04 * static_cast<double>(k), 2.0, 0.02)},
                 out);
  }
  ASSERT_EQ(out.tracks.size(), 1u);
  EXPECT_NEAR(out.tracks[0].vx_mps, 1.0, 0.1);
  const common::UtcNs last_ns = ScanNs(k - 1);
  const std::vector<Measurement> none;
  // Coasting up to and including coast_timeout_s (1 s = 25 scans) after the last measurement.
  for (int i = 1; i <= 25; ++i, ++k) {
    tracker.Step(ScanNs(k), none, out);
    ASSERT_EQ(out.tracks.size(), 1u) << "scan " << i;
    EXPECT_EQ(out.tracks[0].state, TrackState::kCoasting);
    EXPECT_EQ(out.tracks[0].points, 0u);
    const double expected_x = 1.0 + 0.04 * 49 + common::NsToSeconds(ScanNs(k) - last_ns);
    EXPECT_NEAR(out.tracks[0].x_m, expected_x, 0.1);
  }
  tracker.Step(ScanNs(k), none, out);
  EXPECT_TRUE(out.tracks.empty());
  EXPECT_EQ(tracker.counters().deleted_coast_timeout, 1u);
  EXPECT_EQ(tracker.counters().deleted(), 1u);
}

TEST(MultiTrackerTest, CoastingTrackIsDeletedWhenItsPositionSigmaGrowsTooLarge) {
  MultiTrackerOptions options = Opts();
  options.coast_timeout_s = 30.0;
  options.max_position_sigma_m = 0.3;
  MultiTracker tracker(options);
  ScanTracks out;
  Feed(tracker, 0, 30, {Meas(2.0, 2.0, 0.02)}, out);
  ASSERT_EQ(out.tracks.size(), 1u);
  const std::vector<Measurement> none;
  std::int64_t k = 30;
  double last_sigma = 0.0;
  for (; k < 30 + 25 * 30; ++k) {
    tracker.Step(ScanNs(k), none, out);
    if (out.tracks.empty()) break;
    const Eigen::Matrix2d p = out.tracks[0].covariance.topLeftCorner<2, 2>();
    last_sigma = std::sqrt(p.eigenvalues().real().maxCoeff());
    EXPECT_LE(last_sigma, 0.3);
  }
  EXPECT_TRUE(out.tracks.empty());
  EXPECT_GT(last_sigma, 0.25);
  EXPECT_LT(common::NsToSeconds(ScanNs(k) - ScanNs(29)), 5.0);  // long before the timeout
  EXPECT_EQ(tracker.counters().deleted_covariance, 1u);
  EXPECT_EQ(tracker.counters().deleted_coast_timeout, 0u);
}

// A person walking at 1 m/s along x, measured for 2 s, then hidden for gap_scans scans (the
// track times out after 1 s), then measured again at `offset_m` across the walking line from
// where they walk on. Returns the reports of the scans after the gap, one per scan.
std::vector<ScanTracks> WalkHideAndReappear(const MultiTrackerOptions& options,
                                            std::int64_t gap_scans, double offset_m,
                                            MultiTrackerCounters* counters) {
  MultiTracker tracker(options);
  ScanTracks out;
  auto at = [](std::int64_t k) { return 1.0 + 0.04 * static_cast<double>(k); };
  std::int64_t k = 0;
  for (; k < 50; ++k)
    tracker.Step(ScanNs(k), std::vector<Measurement>{Meas(at(k), 2.0, 0.02)}, out);
  for (const std::int64_t end = k + gap_scans; k < end; ++k) tracker.Step(ScanNs(k), {}, out);
  std::vector<ScanTracks> after;
  for (const std::int64_t end = k + 10; k < end; ++k) {
    tracker.Step(ScanNs(k), std::vector<Measurement>{Meas(at(k), 2.0 + offset_m, 0.02)}, out);
    after.push_back(out);
  }
  *counters = tracker.counters();
  return after;
}

TEST(MultiTrackerTest, PersonFoundAgainAfterAGapWhereTheTrackExpectsThemKeepsTheirId) {
  // Hidden 1.6 s (40 scans): deleted 1 s after the last measurement, found again 0.6 s later on
  // the walking line.
  MultiTrackerCounters counters;
  const std::vector<ScanTracks> after = WalkHideAndReappear(Opts(), 40, 0.0, &counters);
  EXPECT_EQ(counters.deleted_coast_timeout, 1u);
  EXPECT_EQ(counters.resumed, 1u);
  EXPECT_EQ(counters.created, 1u);
  // Confirmed again as a new track would be (3 of 4 scans), with the id it had.
  EXPECT_TRUE(after[0].tracks.empty());
  EXPECT_TRUE(after[1].tracks.empty());
  for (std::size_t i = 2; i < after.size(); ++i) {
    ASSERT_EQ(after[i].tracks.size(), 1u) << "scan " << i;
    EXPECT_EQ(after[i].tracks[0].track_id, 1u);
    EXPECT_EQ(after[i].tracks[0].state, TrackState::kConfirmed);
  }
  // Its velocity is the walk's (from the last measurement before the gap and the new ones).
  EXPECT_NEAR(after.back().tracks[0].vx_mps, 1.0, 0.15);
  EXPECT_NEAR(after.back().tracks[0].vy_mps, 0.0, 0.15);

  // Off: the same person is a new track.
  MultiTrackerOptions off = Opts();
  off.resume_window_s = 0.0;
  const std::vector<ScanTracks> new_id = WalkHideAndReappear(off, 40, 0.0, &counters);
  ASSERT_EQ(new_id.back().tracks.size(), 1u);
  EXPECT_EQ(new_id.back().tracks[0].track_id, 2u);
  EXPECT_EQ(counters.resumed, 0u);
}

TEST(MultiTrackerTest, LostTrackIsNotResumedFarFromItsPredictionOrAfterItsWindow) {
  MultiTrackerCounters counters;
  // 1.5 m across the walking line: outside max_gate_distance_m of the prediction.
  std::vector<ScanTracks> after = WalkHideAndReappear(Opts(), 40, 1.5, &counters);
  ASSERT_EQ(after.back().tracks.size(), 1u);
  EXPECT_EQ(after.back().tracks[0].track_id, 2u);
  EXPECT_EQ(counters.resumed, 0u);
  // On the line but hidden longer than coast_timeout_s + resume_window_s (2 s).
  after = WalkHideAndReappear(Opts(), 60, 0.0, &counters);
  ASSERT_EQ(after.back().tracks.size(), 1u);
  EXPECT_EQ(after.back().tracks[0].track_id, 2u);
  EXPECT_EQ(counters.resumed, 0u);
}

TEST(MultiTrackerTest, IdsStartAtOneAndAreNeverReused) {
  MultiTrackerOptions options = Opts();
  options.resume_window_s = 0.0;  // a track found again where it was lost keeps its id
  MultiTracker tracker{options};
  ScanTracks out;
  std::set<std::uint32_t> seen;
  std::uint32_t previous = 0;
  std::int64_t k = 0;
  for (int life = 0; life < 20; ++life) {
    // Same place every time: a new track after the old one died must still get a new id.
    Feed(tracker, k, k + 5, {Meas(4.0, -1.0)}, out);
    k += 5;
    ASSERT_EQ(out.tracks.size(), 1u);
    const std::uint32_t id = out.tracks[0].track_id;
    EXPECT_GT(id, previous);
    EXPECT_TRUE(seen.insert(id).second) << "id " << id << " reused";
    previous = id;
    Feed(tracker, k, k + 30, {}, out);  // 1.2 s: timed out
    k += 30;
    ASSERT_EQ(tracker.track_count(), 0u);
    if (life == 10) tracker.Clear();
  }
  EXPECT_EQ(*seen.begin(), 1u);
  EXPECT_EQ(tracker.counters().created, 20u);
}

TEST(MultiTrackerTest, BirthsBeyondCapacityAreDroppedAndCounted) {
  MultiTrackerOptions options = Opts();
  options.max_tracks = 3;
  options.report_tentative = true;
  MultiTracker tracker(options);
  ScanTracks out;
  std::vector<Measurement> five;
  for (int i = 0; i < 5; ++i) five.push_back(Meas(1.0 + 2.0 * i, 0.0));
  tracker.Step(ScanNs(0), five, out);
  EXPECT_EQ(out.tracks.size(), 3u);
  EXPECT_EQ(tracker.counters().created, 3u);
  EXPECT_EQ(tracker.counters().dropped_capacity, 2u);
  tracker.Step(ScanNs(1), five, out);
  EXPECT_EQ(tracker.counters().dropped_capacity, 4u);
}

TEST(MultiTrackerTest, MeasurementsBeyondSegmentCapacityAreCountedNotRead) {
  MultiTrackerOptions options = Opts();
  options.max_tracks = kMaxTracks;
  MultiTracker tracker(options);
  ScanTracks out;
  std::vector<Measurement> many;
  for (std::size_t i = 0; i < kMaxSegments + 6; ++i) {
    many.push_back(Meas(static_cast<double>(i), 0.0));
  }
  Feed(tracker, 0, 3, many, out);
  EXPECT_EQ(out.tracks.size(), kMaxSegments);
  EXPECT_EQ(tracker.counters().measurements_over_capacity, 18u);
}

TEST(MultiTrackerTest, BadMeasurementsAreRejectedAndCounted) {
  MultiTrackerOptions options = Opts();
  options.report_tentative = true;
  MultiTracker tracker(options);
  ScanTracks out;
  std::vector<Measurement> bad(4, Meas(1.0, 1.0));
  bad[0].position_m.x() = std::numeric_limits<double>::quiet_NaN();
  bad[1].covariance_m2(0, 0) = std::numeric_limits<double>::infinity();
  bad[2].covariance_m2 = -Eigen::Matrix2d::Identity();
  bad[3].covariance_m2.setZero();
  tracker.Step(ScanNs(0), bad, out);
  EXPECT_TRUE(out.tracks.empty());
  EXPECT_EQ(tracker.counters().rejected_measurements, 4u);
  EXPECT_EQ(tracker.track_count(), 0u);
}

TEST(MultiTrackerTest, SplitSegmentsOfOnePersonDoNotStartExtraTracks) {
  MultiTrackerOptions options = Opts();
  options.report_tentative = true;
  MultiTracker tracker(options);
  ScanTracks out;
  // Two pieces 10 cm apart in the very first scan: one track.
  tracker.Step(ScanNs(0), std::vector<Measurement>{Meas(2.0, 0.0), Meas(2.1, 0.0)}, out);
  EXPECT_EQ(tracker.track_count(), 1u);
  Feed(tracker, 1, 10, {Meas(2.0, 0.0)}, out);
  // Later, a split: one piece updates the track, the other lies inside its gate.
  tracker.Step(ScanNs(10), std::vector<Measurement>{Meas(1.95, 0.0), Meas(2.07, 0.02)}, out);
  EXPECT_EQ(tracker.track_count(), 1u);
  EXPECT_EQ(tracker.counters().births_suppressed, 2u);
  // Someone 2 m away still starts a track.
  tracker.Step(ScanNs(11), std::vector<Measurement>{Meas(2.0, 0.0), Meas(4.0, 0.0)}, out);
  EXPECT_EQ(tracker.track_count(), 2u);
}

TEST(MultiTrackerTest, ReportCarriesKindOrientationAndPointsOfTheLastMeasurement) {
  MultiTracker tracker{Opts()};
  ScanTracks out;
  Measurement e = Meas(3.0, 1.0, 0.02);
  e.kind = MeasurementKind::kEllipse;
  e.orientation_rad = 0.3;
  e.point_count = 17;
  Feed(tracker, 0, 3, {e}, out);
  ASSERT_EQ(out.tracks.size(), 1u);
  EXPECT_EQ(out.tracks[0].kind, MeasurementKind::kEllipse);
  EXPECT_DOUBLE_EQ(out.tracks[0].ellipse_yaw_rad, 0.3);
  EXPECT_EQ(out.tracks[0].points, 17u);
  tracker.Step(ScanNs(3), std::vector<Measurement>{Meas(3.0, 1.0, 0.1)}, out);
  EXPECT_EQ(out.tracks[0].kind, MeasurementKind::kCenterOfMass);
  EXPECT_EQ(out.tracks[0].points, 12u);
  // The measurement itself and its time after the scan start (for evaluating the filter's lag).
  const std::vector<double> offsets = {0.02};
  tracker.Step(ScanNs(4), std::vector<Measurement>{Meas(3.05, 0.95, 0.1)}, offsets, out);
  EXPECT_DOUBLE_EQ(out.tracks[0].measured_x_m, 3.05);
  EXPECT_DOUBLE_EQ(out.tracks[0].measured_y_m, 0.95);
  EXPECT_NEAR(out.tracks[0].measured_offset_s, 0.02, 1e-9);
  tracker.Step(ScanNs(5), std::vector<Measurement>{}, out);
  EXPECT_EQ(out.tracks[0].kind, MeasurementKind::kCenterOfMass);
  EXPECT_EQ(out.tracks[0].points, 0u);
  EXPECT_EQ(out.tracks[0].measured_x_m, 0.0);
  EXPECT_EQ(out.tracks[0].measured_offset_s, 0.0);
}

TEST(MultiTrackerTest, EveryMeasurementOfACrowdIsGatedWhateverItsPlaceInTheList) {
  // 21 people 1.5 m apart (the gate runs on blocks of 8 measurements; 21 leaves a partial block),
  // listed in one order while the tracks are born, then reversed and without person 9: each
  // track keeps its person, the missing one coasts, and each follows its person's 5 cm step.
  MultiTracker tracker{Opts()};
  ScanTracks out;
  constexpr int kPeople = 21;
  const auto at = [](int person) {
    return Eigen::Vector2d(-6.0 + 1.5 * (person % 7), 2.0 + 1.5 * (person / 7));
  };
  std::vector<Measurement> crowd;
  for (int p = 0; p < kPeople; ++p) crowd.push_back(Meas(at(p).x(), at(p).y()));
  Feed(tracker, 0, 5, crowd, out);
  ASSERT_EQ(out.tracks.size(), static_cast<std::size_t>(kPeople));
  std::vector<std::uint32_t> id_of(kPeople, 0);
  for (const TrackReport& r : out.tracks) {
    for (int p = 0; p < kPeople; ++p) {
      if ((Eigen::Vector2d(r.x_m, r.y_m) - at(p)).norm() < 0.05) id_of[p] = r.track_id;
    }
  }
  std::vector<Measurement> reversed;
  for (int p = kPeople - 1; p >= 0; --p) {
    if (p != 9) reversed.push_back(Meas(at(p).x() + 0.05, at(p).y()));
  }
  tracker.Step(ScanNs(5), reversed, out);
  ASSERT_EQ(out.tracks.size(), static_cast<std::size_t>(kPeople));
  EXPECT_EQ(tracker.track_count(), static_cast<std::size_t>(kPeople));
  for (int p = 0; p < kPeople; ++p) {
    ASSERT_NE(id_of[p], 0u) << "person " << p;
    const TrackReport* r = FindId(out, id_of[p]);
    ASSERT_NE(r, nullptr) << "person " << p;
    EXPECT_EQ(r->state, p == 9 ? TrackState::kCoasting : TrackState::kConfirmed) << "person " << p;
    EXPECT_NEAR(r->x_m, at(p).x() + (p == 9 ? 0.0 : 0.05), 0.03) << "person " << p;
    EXPECT_GT(r->x_m, at(p).x() + (p == 9 ? -0.01 : 0.01)) << "person " << p;
  }
}

TEST(MultiTrackerTest, MeasurementTimeOffsetsGiveUnbiasedPositionsAtScanStart) {
  // A person at 1.5 m/s seen 30 ms into every scan (e.g. at the end of a 270 deg field of view).
  const double offset_s = 0.03, speed = 1.5;
  auto truth_x = [&](double t) { return 1.0 + speed * t; };
  double error_with = 0.0, error_without = 0.0;
  for (const bool use_offsets : {true, false}) {
    MultiTracker tracker{Opts()};
    ScanTracks out;
    for (std::int64_t k = 0; k < 100; ++k) {
      const double t = 0.04 * static_cast<double>(k);
      const std::vector<Measurement> ms = {Meas(truth_x(t + offset_s), 0.0, 0.01)};
      const std::vector<double> offsets = {offset_s};
      tracker.Step(ScanNs(k), ms,
                   use_offsets ? std::span<const double>(offsets) : std::span<const double>(), out);
      if (k == 99) {
        ASSERT_EQ(out.tracks.size(), 1u);
        (use_offsets ? error_with : error_without) = out.tracks[0].x_m - truth_x(t);
        EXPECT_NEAR(out.tracks[0].vx_mps, speed, 0.05);
      }
    }
  }
  EXPECT_NEAR(error_with, 0.0, 0.005);
  EXPECT_NEAR(error_without, speed * offset_s, 0.01);  // 4.5 cm ahead of the truth
}

TEST(MultiTrackerTest, SmallStepBackwardsIsCountedAndDoesNotPredict) {
  MultiTracker tracker{Opts()};
  ScanTracks out;
  for (std::int64_t k = 0; k < 30; ++k) {
    tracker.Step(ScanNs(k),
                 std::vector<Measurement>{Meas(1.0 + 0.04 * static_cast<double>(k), 0.0, 0.02)},
                 out);
  }
  ASSERT_EQ(out.tracks.size(), 1u);
  const double x_before = out.tracks[0].x_m;
  tracker.Step(ScanNs(29) - 5 * common::kNsPerMs, std::vector<Measurement>{}, out);
  EXPECT_EQ(tracker.counters().time_steps_backwards, 1u);
  EXPECT_EQ(tracker.counters().time_resets, 0u);
  ASSERT_EQ(out.tracks.size(), 1u);
  EXPECT_NEAR(out.tracks[0].x_m, x_before - 0.005, 0.002);  // moved back 5 ms, not predicted on
  EXPECT_TRUE(out.tracks[0].covariance.allFinite());
  // And it carries on normally.
  tracker.Step(ScanNs(30), std::vector<Measurement>{Meas(1.0 + 0.04 * 30, 0.0, 0.02)}, out);
  ASSERT_EQ(out.tracks.size(), 1u);
  EXPECT_EQ(out.tracks[0].track_id, 1u);
  EXPECT_EQ(out.tracks[0].state, TrackState::kConfirmed);
}

TEST(MultiTrackerTest, LargeTimeJumpsResetAllTracksAndAreCounted) {
  MultiTracker tracker{Opts()};
  ScanTracks out;
  Feed(tracker, 0, 10, {Meas(1.0, 0.0), Meas(3.0, 0.0)}, out);
  ASSERT_EQ(out.tracks.size(), 2u);
  // Clock stepped back by an hour.
  tracker.Step(ScanNs(10) - 3600 * common::kNsPerS, std::vector<Measurement>{Meas(1.0, 0.0)}, out);
  EXPECT_TRUE(out.tracks.empty());
  EXPECT_EQ(tracker.counters().time_steps_backwards, 1u);
  EXPECT_EQ(tracker.counters().time_resets, 1u);
  EXPECT_EQ(tracker.counters().deleted_time_reset, 2u);
  EXPECT_EQ(tracker.track_count(), 1u);  // the new scan's measurement starts a fresh track
  // Forward by 10 s: reset again; extreme stamps neither crash nor overflow.
  tracker.Step(ScanNs(10) - 3590 * common::kNsPerS, std::vector<Measurement>{}, out);
  EXPECT_EQ(tracker.counters().time_resets, 2u);
  tracker.Step(std::numeric_limits<common::UtcNs>::min(), std::vector<Measurement>{Meas(1, 0)},
               out);
  tracker.Step(std::numeric_limits<common::UtcNs>::max(), std::vector<Measurement>{Meas(1, 0)},
               out);
  EXPECT_EQ(tracker.counters().time_resets, 4u);
  EXPECT_EQ(tracker.track_count(), 1u);
}

// A person stands for 2 s and then walks off at 1.5 m/s (then turns by 90 degrees): the
// constant-velocity prediction of the standing track lags behind. The recovery gate and the
// covariance inflation keep the one track on them; without either, the measurements leave the
// track's 99 % gate and a second track starts beside the first (an id switch and a ghost).
struct StartResult {
  std::set<std::uint32_t> ids;
  double max_error_m = 0.0;  // of the reported track nearest the truth, while walking
  std::uint64_t recovered = 0;
};

// The distance from p to the nearest reported track (infinity without one); every reported id
// added to ids.
double NearestReport(const ScanTracks& out, const Eigen::Vector2d& p,
                     std::set<std::uint32_t>* ids) {
  double nearest = std::numeric_limits<double>::infinity();
  for (const TrackReport& t : out.tracks) {
    ids->insert(t.track_id);
    nearest = std::min(nearest, (Eigen::Vector2d(t.x_m, t.y_m) - p).norm());
  }
  return nearest;
}

StartResult StandThenWalk(const MultiTrackerOptions& o) {
  MultiTracker tracker(o);
  ScanTracks out;
  StartResult r;
  Eigen::Vector2d p(4.0, 0.0);
  for (std::int64_t k = 0; k < 150; ++k) {
    if (k >= 50 && k < 100) p.y() += 1.5 * 0.04;  // walking along +y
    if (k >= 100) p.x() += 1.5 * 0.04;            // turned: along +x
    // A body-centre fit's noise (2 cm), drawn deterministically.
    const double nx = 0.02 * std::sin(1.7 * static_cast<double>(k));
    const double ny = 0.02 * std::cos(2.3 * static_cast<double>(k));
    tracker.Step(ScanNs(k), std::vector<Measurement>{Meas(p.x() + nx, p.y() + ny, 0.02)}, out);
    const double nearest = NearestReport(out, p, &r.ids);
    if (k >= 50) r.max_error_m = std::max(r.max_error_m, nearest);
  }
  r.recovered = tracker.counters().recovered;
  return r;
}

// MultiTrackerOptions::report_gain_covariance: a walker measured with 3 mm of noise across the
// ray, told 2 cm: the reported position variance is the gain covariance's (well below the filter's
// own), also where a track is confirmed at birth (1 of 1) and never passes through confirmation.
TEST(MultiTrackerTest, GainCovarianceIsReportedHoweverATrackWasConfirmed) {
  const auto reported_var = [](std::uint32_t hits, std::uint32_t window, bool gain) {
    MultiTrackerOptions o = Opts();
    o.confirm_hits = hits;
    o.confirm_window = window;
    o.report_gain_covariance = gain;
    MultiTracker tracker(o);
    ScanTracks out;
    for (std::int64_t k = 0; k < 100; ++k) {
      const double across = 0.003 * std::sin(1.7 * static_cast<double>(k));
      tracker.Step(ScanNs(k), std::vector<Measurement>{Meas(5.0, -2.0 + 0.05 * static_cast<double>(k) + across, 0.02)},
                   out);
    }
    EXPECT_EQ(out.tracks.size(), 1u);
    return out.tracks.empty() ? 0.0 : out.tracks[0].covariance(1, 1);
  };
  const double filter = reported_var(3, 4, false);
  const double gain = reported_var(3, 4, true);
  const double at_birth = reported_var(1, 1, true);
  EXPECT_LT(gain, 0.5 * filter);
  EXPECT_NEAR(at_birth, gain, 0.1 * gain);
}

TEST(MultiTrackerTest, PersonWhoStartsWalkingOrTurnsKeepsOneTrack) {
  MultiTrackerOptions o = Opts();
  o.report_coasting_s = 0.5;
  o.extra_measurement_sigma_m = 0.0;  // as for the shape fit's measurements
  const StartResult kept = StandThenWalk(o);
  EXPECT_EQ(kept.ids.size(), 1u);
  EXPECT_LT(kept.max_error_m, 0.3);

  MultiTrackerOptions off = o;
  off.recover_gate_mahalanobis_sq = 0.0;
  off.inflate_nis_above = 0.0;
  off.adopt_successor_m = 0.0;  // which would also keep one id (the new track taken over)
  const StartResult lost = StandThenWalk(off);
  EXPECT_GT(lost.ids.size(), 1u) << "the scene no longer tests the start";
  EXPECT_EQ(lost.recovered, 0u);
}

// A refiner that moves every measurement of an existing track by a fixed offset.
class OffsetRefiner final : public MeasurementRefiner {
 public:
  explicit OffsetRefiner(Eigen::Vector2d offset_m) : offset_m_(std::move(offset_m)) {}
  bool Refine(std::size_t, common::UtcNs, const Eigen::Vector4d* predicted, const Eigen::Matrix4d*,
              TrackShape& shape, Measurement& m) override {
    shape.shape = ObjectShape::kTorso;
    if (predicted != nullptr) m.position_m += offset_m_;
    m.covariance_m2 = 0.02 * 0.02 * Eigen::Matrix2d::Identity();
    return true;
  }

 private:
  Eigen::Vector2d offset_m_;
};

TEST(MultiTrackerTest, RefinedMeasurementFarBeyondTheGateIsNotUsed) {
  const std::vector<Measurement> ms = {Meas(3.0, 0.0, 0.02)};
  for (const double offset_m : {0.05, 0.6}) {
    MultiTracker tracker(Opts());
    OffsetRefiner refiner({0.0, offset_m});
    ScanTracks out;
    tracker.Step(ScanNs(0), ms, {}, &refiner, out);  // born without an offset
    for (std::int64_t k = 1; k < 10; ++k) tracker.Step(ScanNs(k), ms, {}, &refiner, out);
    SCOPED_TRACE(offset_m);
    if (offset_m < 0.1) {
      // Near: used.
      EXPECT_EQ(tracker.counters().refine_failures, 0u);
      EXPECT_EQ(tracker.confirmed_count(), 1u);
    } else {
      // 0.6 m off a track that knows its position to 2 cm: beyond 4x the gate, never used; the
      // track is never confirmed.
      EXPECT_GE(tracker.counters().refine_failures, 3u);
      EXPECT_EQ(tracker.confirmed_count(), 0u);
    }
  }
}

// A refiner that learns a size, then (far_) moves the measurement far off and claims another size
// (true), or fails after writing that size (false).
class SizeRefiner final : public MeasurementRefiner {
 public:
  bool Refine(std::size_t, common::UtcNs, const Eigen::Vector4d* predicted, const Eigen::Matrix4d*,
              TrackShape& shape, Measurement& m) override {
    shape.shape = ObjectShape::kTorso;
    m.covariance_m2 = 0.02 * 0.02 * Eigen::Matrix2d::Identity();
    if (predicted == nullptr || mode_ == Mode::kNear) {
      shape.size_m = Eigen::Vector2d(0.25, 0.15);
      return true;
    }
    shape.size_m = Eigen::Vector2d(0.9, 0.9);
    m.position_m += Eigen::Vector2d(0.0, 0.8);
    return mode_ == Mode::kFarTaken;
  }
  enum class Mode { kNear, kFarTaken, kFails };
  Mode mode_ = Mode::kNear;
};

// MultiTracker refines a track's shape in place: a refinement it does not take (beyond the gate,
// or the refiner's failure) leaves the shape the track had.
TEST(MultiTrackerTest, ARefinementNotTakenLeavesTheTrackShapeAsItWas) {
  const std::vector<Measurement> ms = {Meas(3.0, 0.0, 0.02)};
  for (const auto mode : {SizeRefiner::Mode::kFarTaken, SizeRefiner::Mode::kFails}) {
    MultiTracker tracker(Opts());
    SizeRefiner refiner;
    ScanTracks out;
    for (std::int64_t k = 0; k < 10; ++k) tracker.Step(ScanNs(k), ms, {}, &refiner, out);
    ASSERT_EQ(out.tracks.size(), 1u);
    EXPECT_DOUBLE_EQ(out.tracks[0].size_major_m, 0.25);
    refiner.mode_ = mode;
    const std::uint64_t failures = tracker.counters().refine_failures;
    tracker.Step(ScanNs(10), ms, {}, &refiner, out);
    EXPECT_EQ(tracker.counters().refine_failures, failures + 1);
    ASSERT_EQ(out.tracks.size(), 1u);
    EXPECT_EQ(out.tracks[0].state, TrackState::kCoasting);
    EXPECT_DOUBLE_EQ(out.tracks[0].size_major_m, 0.25);
    EXPECT_DOUBLE_EQ(out.tracks[0].size_minor_m, 0.15);
  }
}

// A refiner that reports a fixed outline departure with every measurement.
class DepartureRefiner final : public MeasurementRefiner {
 public:
  explicit DepartureRefiner(double departure_m2) : departure_m2_(departure_m2) {}
  bool Refine(std::size_t, common::UtcNs, const Eigen::Vector4d*, const Eigen::Matrix4d*,
              TrackShape& shape, Measurement& m) override {
    shape.shape = ObjectShape::kTorso;
    shape.reported_departure_m2 = departure_m2_;
    m.covariance_m2 = 0.02 * 0.02 * Eigen::Matrix2d::Identity();
    return true;
  }

 private:
  double departure_m2_;
};

TEST(MultiTrackerTest, OutlineDepartureIsReportedWithMeasuredScansOnly) {
  // The same track with and without a departure of 0.05^2 m^2 per axis: the confirmed reports
  // differ by exactly that, the coasting ones not at all (their reach for the coasting checks is
  // the filter's prediction), and the filter itself never sees it.
  const std::vector<Measurement> echo = {Meas(3.0, 1.0, 0.02)};
  const auto run = [&](double departure_m2, std::vector<Eigen::Matrix2d>* confirmed,
                       std::vector<Eigen::Matrix2d>* coasting) {
    MultiTracker tracker(Opts());
    DepartureRefiner refiner(departure_m2);
    ScanTracks out;
    for (std::int64_t k = 0; k < 10; ++k) {
      tracker.Step(ScanNs(k), echo, {}, &refiner, out);
      if (!out.tracks.empty() && out.tracks[0].state == TrackState::kConfirmed) {
        confirmed->push_back(out.tracks[0].covariance.topLeftCorner<2, 2>());
      }
    }
    for (std::int64_t k = 10; k < 13; ++k) {
      tracker.Step(ScanNs(k), std::vector<Measurement>{}, {}, &refiner, out);
      ASSERT_EQ(out.tracks.size(), 1u);
      ASSERT_EQ(out.tracks[0].state, TrackState::kCoasting);
      coasting->push_back(out.tracks[0].covariance.topLeftCorner<2, 2>());
    }
  };
  std::vector<Eigen::Matrix2d> confirmed0, coasting0, confirmed1, coasting1;
  run(0.0, &confirmed0, &coasting0);
  run(0.05 * 0.05, &confirmed1, &coasting1);
  ASSERT_FALSE(confirmed0.empty());
  ASSERT_EQ(confirmed0.size(), confirmed1.size());
  for (std::size_t i = 0; i < confirmed0.size(); ++i) {
    EXPECT_TRUE(
        (confirmed1[i] - confirmed0[i]).isApprox(0.05 * 0.05 * Eigen::Matrix2d::Identity(), 1e-9))
        << i;
  }
  ASSERT_EQ(coasting0.size(), coasting1.size());
  for (std::size_t i = 0; i < coasting0.size(); ++i) {
    EXPECT_TRUE(coasting1[i].isApprox(coasting0[i], 1e-12)) << i;
  }
}

// A refiner that reports a fixed partial view's covariance with every measurement.
class PartialViewRefiner final : public MeasurementRefiner {
 public:
  explicit PartialViewRefiner(const Eigen::Matrix2d& cov_m2) : cov_m2_(cov_m2) {}
  bool Refine(std::size_t, common::UtcNs, const Eigen::Vector4d*, const Eigen::Matrix4d*,
              TrackShape& shape, Measurement& m) override {
    shape.shape = ObjectShape::kTorso;
    shape.reported_partial_cov_m2 = cov_m2_;
    m.covariance_m2 = 0.02 * 0.02 * Eigen::Matrix2d::Identity();
    return true;
  }

 private:
  Eigen::Matrix2d cov_m2_;
};

TEST(MultiTrackerTest, PartialViewCovarianceIsReportedWithMeasuredScansOnly) {
  // The same track with and without a partial view's covariance: the confirmed reports differ by
  // exactly that matrix, the coasting ones not at all, and the filter never sees it.
  const std::vector<Measurement> echo = {Meas(3.0, 1.0, 0.02)};
  Eigen::Matrix2d partial;
  partial << 0.004, 0.001, 0.001, 0.002;
  const auto run = [&](const Eigen::Matrix2d& cov_m2, std::vector<TrackReport>* confirmed,
                       std::vector<TrackReport>* coasting) {
    MultiTracker tracker(Opts());
    PartialViewRefiner refiner(cov_m2);
    ScanTracks out;
    for (std::int64_t k = 0; k < 10; ++k) {
      tracker.Step(ScanNs(k), echo, {}, &refiner, out);
      if (!out.tracks.empty() && out.tracks[0].state == TrackState::kConfirmed) {
        confirmed->push_back(out.tracks[0]);
      }
    }
    for (std::int64_t k = 10; k < 13; ++k) {
      tracker.Step(ScanNs(k), std::vector<Measurement>{}, {}, &refiner, out);
      ASSERT_EQ(out.tracks.size(), 1u);
      ASSERT_EQ(out.tracks[0].state, TrackState::kCoasting);
      coasting->push_back(out.tracks[0]);
    }
  };
  std::vector<TrackReport> confirmed0, coasting0, confirmed1, coasting1;
  run(Eigen::Matrix2d::Zero(), &confirmed0, &coasting0);
  run(partial, &confirmed1, &coasting1);
  ASSERT_FALSE(confirmed0.empty());
  ASSERT_EQ(confirmed0.size(), confirmed1.size());
  for (std::size_t i = 0; i < confirmed0.size(); ++i) {
    EXPECT_TRUE((confirmed1[i].covariance.topLeftCorner<2, 2>() -
                 confirmed0[i].covariance.topLeftCorner<2, 2>())
                    .isApprox(partial, 1e-9))
        << i;
    EXPECT_DOUBLE_EQ(confirmed1[i].x_m, confirmed0[i].x_m);
    EXPECT_DOUBLE_EQ(confirmed1[i].y_m, confirmed0[i].y_m);
  }
  ASSERT_EQ(coasting0.size(), coasting1.size());
  for (std::size_t i = 0; i < coasting0.size(); ++i) {
    EXPECT_TRUE(coasting1[i].covariance.isApprox(coasting0[i].covariance, 1e-12)) << i;
  }
}

TEST(MultiTrackerTest, CoastingTracksAreReportedOnlyBrieflyButKeptUntilTheTimeout) {
  MultiTrackerOptions options = Opts();
  options.report_coasting_s = 0.3;
  MultiTracker tracker(options);
  ScanTracks out;
  const auto at = [](std::int64_t k) {
    return std::vector<Measurement>{Meas(2.0 + 0.04 * static_cast<double>(k), 0.0)};
  };
  for (std::int64_t k = 0; k < 10; ++k) tracker.Step(ScanNs(k), at(k), out);
  ASSERT_EQ(out.tracks.size(), 1u);
  const std::uint32_t id = out.tracks[0].track_id;
  // Hidden: reported while coasting for 0.3 s (7 scans at 25 Hz), then not, but still there.
  int reported = 0;
  for (std::int64_t k = 10; k < 30; ++k) {
    tracker.Step(ScanNs(k), std::vector<Measurement>{}, out);
    reported += out.tracks.empty() ? 0 : 1;
  }
  EXPECT_EQ(reported, 7);
  EXPECT_EQ(tracker.counters().coasting_unreported, 13u);  // the other 13 coasting scans
  EXPECT_EQ(tracker.track_count(), 1u);
  // Found again within the coast timeout: the same id.
  tracker.Step(ScanNs(30), at(30), out);
  ASSERT_EQ(out.tracks.size(), 1u);
  EXPECT_EQ(out.tracks[0].track_id, id);
}

// Seen for `seen_scans` consecutive scans `period_ns` apart, then nothing: how long (s) the track
// is reported coasting afterwards.
double ReportedCoastingS(const MultiTrackerOptions& options, common::DurationNs period_ns,
                         std::int64_t seen_scans) {
  MultiTracker tracker(options);
  ScanTracks out;
  const std::vector<Measurement> echo = {Meas(3.0, 1.0)};
  for (std::int64_t k = 0; k < seen_scans; ++k) tracker.Step(kT0 + k * period_ns, echo, out);
  EXPECT_EQ(out.tracks.size(), 1u);
  double last_reported_s = 0.0;
  for (std::int64_t k = seen_scans; k < seen_scans + 200; ++k) {
    tracker.Step(kT0 + k * period_ns, std::vector<Measurement>{}, out);
    if (!out.tracks.empty()) {
      last_reported_s = common::NsToSeconds((k - seen_scans + 1) * period_ns);
    }
  }
  return last_reported_s;
}

TEST(MultiTrackerTest, TrackSeenBrieflyIsReportedCoastingForAsLongAsItWasSeenAtEveryScanRate) {
  MultiTrackerOptions options;  // report_coasting_s 0.5, report_coasting_per_measured_s 1
  options.static_objects = false;
  options.confirm_min_s = 0.0;  // confirmed by 3 of 4 as the pipeline does at upper-body height
  MultiTrackerOptions before = options;
  before.report_coasting_per_measured_s = 0.0;
  constexpr common::DurationNs k50Hz = 20 * common::kNsPerMs;
  constexpr common::DurationNs k15Hz = 200 * common::kNsPerMs / 3;
  // An echo in 4 consecutive scans (confirmed by 3 of 4): seen for 3 periods (60 ms at 50 Hz,
  // 200 ms at 15 Hz); reported coasting for that long (to within a scan), not for 0.5 s.
  EXPECT_NEAR(ReportedCoastingS(options, k50Hz, 4), 0.06, 0.021);
  EXPECT_NEAR(ReportedCoastingS(options, k15Hz, 4), 0.2, 0.067);
  EXPECT_NEAR(ReportedCoastingS(before, k50Hz, 4), 0.5, 0.021);
  EXPECT_NEAR(ReportedCoastingS(before, k15Hz, 4), 0.5, 0.067);
  // Someone seen for 1 s: reported coasting for report_coasting_s at both rates.
  EXPECT_NEAR(ReportedCoastingS(options, k50Hz, 51), 0.5, 0.021);
  EXPECT_NEAR(ReportedCoastingS(options, k15Hz, 16), 0.5, 0.067);
}

// An object at (3, 1) m walking along x at 1.2 m/s, measured in the scans k (0, 1, ...,
// `scans` - 1, `period_ns` apart) where seen(k), then gone for 1 s: when (s after its first
// measurement) it was first reported, -1 for never.
template <typename Seen>
double FirstReportedS(const MultiTrackerOptions& options, common::DurationNs period_ns,
                      std::int64_t scans, Seen seen) {
  MultiTracker tracker(options);
  ScanTracks out;
  double first_s = -1.0;
  const auto end = scans + 1 * common::kNsPerS / period_ns;
  for (std::int64_t k = 0; k < end; ++k) {
    const double t_s = common::NsToSeconds(k * period_ns);
    std::vector<Measurement> ms;
    if (k < scans && seen(k)) ms.push_back(Meas(3.0 + 1.2 * t_s, 1.0));
    tracker.Step(kT0 + k * period_ns, ms, out);
    if (!out.tracks.empty() && first_s < 0.0) first_s = t_s;
  }
  return first_s;
}

TEST(MultiTrackerTest, ConfirmationTakesAMinimumTimeAtEveryScanRateSoClutterBurstsAreNotTracks) {
  MultiTrackerOptions options = Opts();
  options.confirm_min_s = 0.2;
  MultiTrackerOptions before = Opts();  // M of N (3 of 4) alone
  constexpr common::DurationNs k50Hz = 20 * common::kNsPerMs;
  constexpr common::DurationNs k15Hz = 200 * common::kNsPerMs / 3;
  const auto always = [](std::int64_t) { return true; };
  // Leg-sized clutter in 5 consecutive scans at 50 Hz (80 ms) or 3 at 15 Hz (133 ms): M of N
  // confirms both (after 40 ms and 133 ms); with 0.2 s, neither is ever reported.
  EXPECT_NEAR(FirstReportedS(before, k50Hz, 5, always), 0.04, 1e-9);
  EXPECT_NEAR(FirstReportedS(before, k15Hz, 3, always), 0.1333, 1e-3);
  EXPECT_EQ(FirstReportedS(options, k50Hz, 5, always), -1.0);
  EXPECT_EQ(FirstReportedS(options, k15Hz, 3, always), -1.0);
  // A burst at 50 Hz that lasts 0.3 s but is seen in every other scan only (2 of 4): M of N
  // fails in its windows after the first; deleted, never reported.
  EXPECT_EQ(FirstReportedS(options, k50Hz, 15, [](std::int64_t k) { return k < 4 || k % 2 == 0; }),
            -1.0);
  // A person walking in: reported 0.2 s after the first measurement, within one scan, at both
  // rates, also when every 4th scan misses them (3 of 4 in every window).
  const double latency_50_s = FirstReportedS(options, k50Hz, 100, always);
  EXPECT_GE(latency_50_s, 0.2 - 1e-9);
  EXPECT_LE(latency_50_s, 0.22 + 1e-9);
  const double latency_15_s = FirstReportedS(options, k15Hz, 30, always);
  EXPECT_GE(latency_15_s, 0.2 - 1e-6);
  EXPECT_LE(latency_15_s, 0.2667 + 1e-3);
  const double latency_gaps_s =
      FirstReportedS(options, k50Hz, 100, [](std::int64_t k) { return k % 4 != 3; });
  EXPECT_GE(latency_gaps_s, 0.2 - 1e-9);
  EXPECT_LE(latency_gaps_s, 0.24 + 1e-9);
}

// Successors (adopt_successor_m): someone walking along +y at 1.2 m/s steps 0.6 m aside at scan 50
// (beyond every gate of a track that knows them to a few cm). A new track starts on them; with the
// rule the coasting track takes it over at its third measurement: one id, one report per scan,
// on the person from then on. Without it, the old track is reported coasting beside the person
// while the new one is confirmed: two ids, two reports in some scans.
struct SidestepResult {
  std::set<std::uint32_t> ids;
  std::size_t max_reports = 0;
  double max_error_after_m = 0.0;  // from scan 52 on, the reported track nearest the person
  std::uint64_t adopted = 0;
};
SidestepResult Sidestep(const MultiTrackerOptions& o) {
  MultiTracker tracker(o);
  ScanTracks out;
  SidestepResult r;
  for (std::int64_t k = 0; k < 100; ++k) {
    const Eigen::Vector2d p(4.0 + (k >= 50 ? 0.6 : 0.0), 1.2 * 0.04 * static_cast<double>(k));
    tracker.Step(ScanNs(k), std::vector<Measurement>{Meas(p.x(), p.y(), 0.02)}, out);
    r.max_reports = std::max(r.max_reports, out.tracks.size());
    const double nearest = NearestReport(out, p, &r.ids);
    if (k >= 52) r.max_error_after_m = std::max(r.max_error_after_m, nearest);
  }
  r.adopted = tracker.counters().adopted;
  return r;
}

TEST(MultiTrackerTest, CoastingTrackAdoptsTheTrackThatFoundItsPersonAgain) {
  MultiTrackerOptions o = Opts();
  o.adopt_successor_m = 1.0;
  const SidestepResult one = Sidestep(o);
  EXPECT_EQ(one.ids, std::set<std::uint32_t>{1u});
  EXPECT_EQ(one.max_reports, 1u);
  EXPECT_EQ(one.adopted, 1u);
  EXPECT_LT(one.max_error_after_m, 0.1);

  MultiTrackerOptions off = o;
  off.adopt_successor_m = 0.0;
  const SidestepResult two = Sidestep(off);
  EXPECT_EQ(two.ids.size(), 2u) << "the scene no longer loses the person";
  EXPECT_EQ(two.max_reports, 2u);
  EXPECT_EQ(two.adopted, 0u);
}

// A track measured beside the coasting one (two people 0.6 m apart, one hidden from scan 30) is
// someone else: not taken over, both keep their ids.
TEST(MultiTrackerTest, CoastingTrackDoesNotAdoptATrackMeasuredBesideIt) {
  MultiTrackerOptions o = Opts();
  o.adopt_successor_m = 1.0;
  MultiTracker tracker(o);
  ScanTracks out;
  bool both_reported_after = true;
  for (std::int64_t k = 0; k < 45; ++k) {
    const double y = 1.2 * 0.04 * static_cast<double>(k);
    std::vector<Measurement> ms = {Meas(4.6, y, 0.02)};
    if (k < 30) ms.push_back(Meas(4.0, y, 0.02));
    tracker.Step(ScanNs(k), ms, out);
    if (k >= 31) both_reported_after = both_reported_after && out.tracks.size() == 2;
  }
  EXPECT_EQ(tracker.counters().adopted, 0u);
  EXPECT_TRUE(both_reported_after);
  ASSERT_EQ(out.tracks.size(), 2u);
  EXPECT_EQ(out.tracks[1].track_id, 2u);
  EXPECT_EQ(out.tracks[1].state, TrackState::kCoasting);
}

// A person walks 2 s along y at x = 4 m, stands 1 s, is hidden 2.5 s (lost after the coast
// timeout; no resume window) and stands on where they were. With a box put down 0.6 m beside
// them while they were still measured (box_too), which never moves.
struct RestartResult {
  int reported_after = 0;  // scans from 1 s after the person is seen again with a report on them
  int box_reports = 0;
  std::uint64_t inherited = 0;
};
RestartResult StandAfterRestart(const MultiTrackerOptions& o, bool box_too) {
  MultiTracker tracker(o);
  ScanTracks out;
  RestartResult r;
  const Eigen::Vector2d stand(4.0, 1.2 * 0.04 * 50.0);
  const Eigen::Vector2d box = stand + Eigen::Vector2d(0.0, 0.6);
  for (std::int64_t k = 0; k < 260; ++k) {
    const Eigen::Vector2d p =
        k < 50 ? Eigen::Vector2d(4.0, 1.2 * 0.04 * static_cast<double>(k)) : stand;
    std::vector<Measurement> ms;
    if (k < 75 || k >= 137) ms.push_back(Meas(p.x(), p.y(), 0.02));
    if (box_too && k >= 70) ms.push_back(Meas(box.x(), box.y(), 0.02));
    tracker.Step(ScanNs(k), ms, out);
    for (const TrackReport& t : out.tracks) {
      const Eigen::Vector2d at(t.x_m, t.y_m);
      if ((at - box).norm() < 0.2) ++r.box_reports;
      if (k >= 162 && (at - stand).norm() < 0.2) ++r.reported_after;
    }
  }
  r.inherited = tracker.counters().inherited_moved;
  return r;
}

TEST(MultiTrackerTest, ATrackRestartedWhereAMovedOneWasLostInheritsItsMovedState) {
  MultiTrackerOptions o = Opts();
  o.static_objects = true;
  o.resume_window_s = 0.0;
  const RestartResult with = StandAfterRestart(o, false);
  EXPECT_EQ(with.inherited, 1u);
  EXPECT_EQ(with.reported_after, 260 - 162);

  MultiTrackerOptions off = o;
  off.inherit_moved_s = 0.0;
  const RestartResult without = StandAfterRestart(off, false);
  EXPECT_EQ(without.inherited, 0u);
  EXPECT_EQ(without.reported_after, 0);  // never moved: unreported, then the background's

  // The box first measured beside the person before they were lost is something else: it stays
  // unreported; the person's new track still inherits.
  const RestartResult box = StandAfterRestart(o, true);
  EXPECT_EQ(box.box_reports, 0);
  EXPECT_EQ(box.inherited, 1u);
  EXPECT_EQ(box.reported_after, 260 - 162);
}

}  // namespace
}  // namespace lrfnet::tracking
