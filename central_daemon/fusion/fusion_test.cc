#include "central_daemon/fusion/fusion.h"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <random>
#include <set>

#include "central_daemon/fusion/fusion_test_util.h"
#include "common/eigen_instances.h"

namespace lrfnet::fusion {
namespace {

using common::DegToRad;
using common::Pose2;
using common::UtcNs;
using daemon::TrackFrameData;
using daemon::TrackObservation;
using daemon::TrackState;
using testing::AtSeconds;
using testing::Scene;
using testing::SimPerson;
using testing::SimSensor;
using testing::Walker;

TrackObservation Obs(std::uint32_t id, double x, double y, double vx = 0.0, double vy = 0.0,
                     double sigma_m = 0.05) {
  TrackObservation o;
  o.track_id = id;
  o.state = TrackState::kConfirmed;
  o.x_m = static_cast<float>(x);
  o.y_m = static_cast<float>(y);
  o.vx_mps = static_cast<float>(vx);
  o.vy_mps = static_cast<float>(vy);
  const auto var = static_cast<float>(sigma_m * sigma_m);
  o.covariance = {var, 0, 0, 0, var, 0, 0, 0.01f, 0, 0.01f};
  return o;
}

TrackFrameData FrameAt(double t_s, std::vector<TrackObservation> tracks,
                       std::uint64_t session = 1) {
  TrackFrameData f;
  f.session_id = session;
  f.scan_start_ns = AtSeconds(t_s);
  f.scan_period_s = 0.04;
  f.tracks = std::move(tracks);
  return f;
}

SensorPlacement Placed(const std::string& id, double x, double y, double yaw_deg) {
  SensorPlacement p;
  p.id = id;
  p.world_from_sensor = Pose2{x, y, DegToRad(yaw_deg)};
  p.covariance = Eigen::Vector3d(1e-4, 1e-4, 1e-6).asDiagonal();
  return p;
}

bool AllFinite(const FusedTrack& t) {
  return std::isfinite(t.x_m) && std::isfinite(t.y_m) && std::isfinite(t.vx_mps) &&
         std::isfinite(t.vy_mps) && t.covariance.array().isFinite().all();
}

SimSensor Sensor(const std::string& id, double x, double y, double yaw_deg, double phase_s = 0.0) {
  SimSensor s;
  s.id = id;
  s.truth = Pose2{x, y, DegToRad(yaw_deg)};
  s.phase_s = phase_s;
  return s;
}

// Every Fuser test runs with both methods.
class MethodTest : public ::testing::TestWithParam<FusionMethod> {
 protected:
  FusionOptions Options() const {
    FusionOptions o;
    o.method = GetParam();
    return o;
  }
  bool FusedFilter() const { return GetParam() == FusionMethod::kFusedFilter; }
};
class FuserTest : public MethodTest {};
class FuserSceneTest : public MethodTest {};
std::string MethodName(const ::testing::TestParamInfo<FusionMethod>& info) {
  return info.param == FusionMethod::kFusedFilter ? "FusedFilter" : "LatestStates";
}
INSTANTIATE_TEST_SUITE_P(Methods, FuserTest,
                         ::testing::Values(FusionMethod::kFusedFilter, FusionMethod::kLatestStates),
                         MethodName);
INSTANTIATE_TEST_SUITE_P(Methods, FuserSceneTest,
                         ::testing::Values(FusionMethod::kFusedFilter, FusionMethod::kLatestStates),
                         MethodName);

// ---------------------------------------------------------------------------------------------
// ToWorld

TEST(ToWorldTest, MatchesHandComputedValues) {
  // Sensor at (1, 2) looking along +y: sensor x is world y, sensor y is world -x.
  SensorPlacement placement;
  placement.world_from_sensor = Pose2{1.0, 2.0, DegToRad(90.0)};
  placement.covariance = Eigen::Vector3d(0.0025, 0.0025, 1e-4).asDiagonal();
  TrackObservation o = Obs(7, 3.0, 0.0, 1.0, 0.0);
  o.covariance = {0.01f, 0, 0, 0, 0.04f, 0, 0, 0.09f, 0, 0.16f};

  const WorldTrack w = ToWorld(placement, "s1", 42, o);
  EXPECT_EQ(w.sensor_id, "s1");
  EXPECT_EQ(w.track_id, 7u);
  EXPECT_EQ(w.stamp_ns, 42);
  EXPECT_NEAR(w.x_m, 1.0, 1e-12);
  EXPECT_NEAR(w.y_m, 5.0, 1e-12);
  EXPECT_NEAR(w.vx_mps, 0.0, 1e-12);
  EXPECT_NEAR(w.vy_mps, 1.0, 1e-12);
  // R P R^T swaps the axes; the yaw variance moves the point across the beam (3 m lever arm,
  // dp/dyaw = (-3, 0)) and the velocity too (dv/dyaw = (-1, 0)), correlated.
  EXPECT_NEAR(w.position_covariance(0, 0), 0.04 + 0.0025 + 9.0 * 1e-4, 1e-7);
  EXPECT_NEAR(w.position_covariance(1, 1), 0.01 + 0.0025, 1e-7);
  EXPECT_NEAR(w.position_covariance(0, 1), 0.0, 1e-7);
  EXPECT_NEAR(w.covariance(2, 2), 0.16 + 1e-4, 1e-7);
  EXPECT_NEAR(w.covariance(3, 3), 0.09, 1e-7);
  EXPECT_NEAR(w.covariance(0, 2), 3.0 * 1e-4, 1e-7);
  EXPECT_NEAR(w.covariance(2, 0), 3.0 * 1e-4, 1e-7);
  EXPECT_TRUE((w.position_covariance.array() == w.covariance.topLeftCorner<2, 2>().array()).all());
}

TEST(ToWorldTest, CovarianceMatchesMonteCarlo) {
  SensorPlacement placement;
  placement.world_from_sensor = Pose2{2.0, -1.0, DegToRad(30.0)};
  Eigen::Matrix3d pose_cov;
  pose_cov << 0.04 * 0.04, 0.0004, 0.0002, 0.0004, 0.03 * 0.03, -0.0001, 0.0002, -0.0001,
      std::pow(DegToRad(1.5), 2);
  placement.covariance = pose_cov;
  TrackObservation o = Obs(1, 6.0, 2.0, 0.8, -0.3);
  Eigen::Matrix4d local;
  local << 0.0025, 0.0010, 0.0005, 0.0, 0.0010, 0.0040, 0.0, 0.0008, 0.0005, 0.0, 0.0400, 0.0050,
      0.0, 0.0008, 0.0050, 0.0300;
  o.covariance = {0.0025f, 0.0010f, 0.0005f, 0.0f,    0.0040f,
                  0.0f,    0.0008f, 0.0400f, 0.0050f, 0.0300f};
  const WorldTrack w = ToWorld(placement, "s", 0, o);

  std::mt19937 rng(11);
  std::normal_distribution<double> n01(0.0, 1.0);
  const Eigen::Matrix3d lp = pose_cov.llt().matrixL();
  const Eigen::Matrix4d ll = local.llt().matrixL();
  constexpr int kSamples = 200000;
  std::vector<Eigen::Vector4d> samples;
  samples.reserve(kSamples);
  Eigen::Vector4d mean = Eigen::Vector4d::Zero();
  for (int i = 0; i < kSamples; ++i) {
    const Eigen::Vector3d dp = lp * Eigen::Vector3d(n01(rng), n01(rng), n01(rng));
    const Eigen::Vector4d dl = ll * Eigen::Vector4d(n01(rng), n01(rng), n01(rng), n01(rng));
    const Pose2 pose{2.0 + dp(0), -1.0 + dp(1), DegToRad(30.0) + dp(2)};
    const Eigen::Vector2d p = pose * Eigen::Vector2d(6.0 + dl(0), 2.0 + dl(1));
    const Eigen::Vector2d v = pose.rotation() * Eigen::Vector2d(0.8 + dl(2), -0.3 + dl(3));
    samples.emplace_back(p.x(), p.y(), v.x(), v.y());
    mean += samples.back();
  }
  mean /= kSamples;
  Eigen::Matrix4d cov = Eigen::Matrix4d::Zero();
  for (const auto& s : samples) cov += (s - mean) * (s - mean).transpose();
  cov /= kSamples - 1;

  EXPECT_NEAR(mean(0), w.x_m, 0.005);
  EXPECT_NEAR(mean(1), w.y_m, 0.005);
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) {
      const double scale = std::sqrt(cov(r, r) * cov(c, c));
      EXPECT_NEAR(w.covariance(r, c), cov(r, c), 0.02 * scale) << "entry " << r << "," << c;
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Options and placements

TEST(FusionOptionsTest, DefaultsAreValidAndBadValuesNamed) {
  EXPECT_FALSE(Validate(FusionOptions{}));
  FusionOptions o;
  o.gate_mahalanobis2 = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(Validate(o).value_or("").find("gate_mahalanobis2"), std::string::npos);
  o = {};
  o.position_noise_floor_m2 = 0.0;
  EXPECT_NE(Validate(o).value_or("").find("position_noise_floor_m2"), std::string::npos);
  o = {};
  o.agree_mahalanobis2 = 20.0;
  EXPECT_NE(Validate(o).value_or("").find("agree_mahalanobis2"), std::string::npos);
  o = {};
  o.confirm_updates = 0;
  EXPECT_TRUE(Validate(o));
  o = {};
  o.max_tracks_per_frame = 0;
  EXPECT_TRUE(Validate(o));
  o = {};
  o.sensor_bias_memory = 3;  // below sensor_bias_min_samples
  EXPECT_NE(Validate(o).value_or("").find("sensor_bias_memory"), std::string::npos);
  o = {};
  o.max_sensor_bias_m = std::numeric_limits<double>::infinity();
  EXPECT_NE(Validate(o).value_or("").find("max_sensor_bias_m"), std::string::npos);
  o = {};
  o.sensor_bias_offset_sigma_fraction = -0.1;
  EXPECT_NE(Validate(o).value_or("").find("sensor_bias_offset_sigma_fraction"), std::string::npos);
  o = {};
  o.sensor_bias_pose_prior_scale = 0.0;
  EXPECT_NE(Validate(o).value_or("").find("sensor_bias_pose_prior_scale"), std::string::npos);
  o = {};
  o.merge_centre_spread_m = -0.01;
  EXPECT_NE(Validate(o).value_or("").find("merge_centre_spread_m"), std::string::npos);
  o = {};
  o.merge_centre_spread_m = o.merge_max_distance_m + 0.1;
  EXPECT_NE(Validate(o).value_or("").find("merge_centre_spread_m"), std::string::npos);
  o = {};
  o.ended_report_s = 0.0;
  EXPECT_NE(Validate(o).value_or("").find("ended_report_s"), std::string::npos);
  o.ended_report_s = 4000.0;
  EXPECT_NE(Validate(o).value_or("").find("ended_report_s"), std::string::npos);
}

// Every id `out` reports (tracks, hidden, ended) in exactly one of its lists, and every id in
// `seen` (reported in the tracks before) still in one of them; adds the tracks' ids to `seen`.
void ExpectEveryIdAccounted(const FusionOutput& out, std::set<std::uint64_t>& seen) {
  std::map<std::uint64_t, int> in;
  for (const FusedTrack& t : out.tracks) ++in[t.id];
  for (const HiddenFusedTrack& h : out.hidden) ++in[h.id];
  for (const EndedFusedTrack& e : out.ended) ++in[e.id];
  for (const auto& [id, n] : in) EXPECT_EQ(n, 1) << "id " << id << " in " << n << " lists";
  for (const std::uint64_t id : seen) EXPECT_EQ(in.count(id), 1u) << "id " << id << " unaccounted";
  for (const FusedTrack& t : out.tracks) seen.insert(t.id);
}

TEST_P(FuserTest, InvalidPlacementsAreIgnoredAndCounted) {
  Fuser fuser(Options());
  SensorPlacement nan_pose = Placed("a", 0, 0, 0);
  nan_pose.world_from_sensor.yaw_rad = std::numeric_limits<double>::quiet_NaN();
  SensorPlacement negative = Placed("b", 0, 0, 0);
  negative.covariance(2, 2) = -1.0;
  SensorPlacement nan_cov = Placed("c", 0, 0, 0);
  nan_cov.covariance(0, 1) = std::numeric_limits<double>::quiet_NaN();
  fuser.SetPlacements({nan_pose, negative, nan_cov, Placed("d", 1, 2, 3)});
  EXPECT_EQ(fuser.counters().placements_invalid, 3u);
  EXPECT_FALSE(fuser.HasPlacement("a"));
  EXPECT_FALSE(fuser.HasPlacement("b"));
  EXPECT_FALSE(fuser.HasPlacement("c"));
  EXPECT_TRUE(fuser.HasPlacement("d"));
  fuser.AddFrame("a", FrameAt(1.0, {Obs(1, 1, 1)}));
  EXPECT_EQ(fuser.counters().frames_unplaced, 1u);
}

TEST_P(FuserTest, UnplacedSensorIsCountedAndIgnored) {
  Fuser fuser(Options());
  fuser.SetPlacements({Placed("a", 0, 0, 0)});
  for (int k = 0; k < 10; ++k) {
    fuser.AddFrame("ghost", FrameAt(1.0 + 0.04 * k, {Obs(1, 2, 0)}));
    fuser.AddFrame("a", FrameAt(1.01 + 0.04 * k, {Obs(1, 5, 0)}));
  }
  EXPECT_EQ(fuser.counters().frames, 20u);
  EXPECT_EQ(fuser.counters().frames_unplaced, 10u);
  const auto fused = fuser.Snapshot(AtSeconds(1.4));
  ASSERT_EQ(fused.size(), 1u);
  EXPECT_NEAR(fused[0].x_m, 5.0, 0.01);
  ASSERT_EQ(fused[0].sources.size(), 1u);
  EXPECT_EQ(fused[0].sources[0].sensor_id, "a");
  for (const WorldTrack& w : fuser.WorldTracks(AtSeconds(1.4))) EXPECT_EQ(w.sensor_id, "a");
}

// ---------------------------------------------------------------------------------------------
// Lifecycle

TEST_P(FuserTest, TentativeConfirmedCoastingDeleted) {
  FusionOptions o = Options();
  o.report_sourceless = true;  // the coasting track is reported until deleted
  Fuser fuser(o);
  fuser.SetPlacements({Placed("a", 0, 0, 0)});
  fuser.AddFrame("a", FrameAt(1.00, {Obs(1, 3, 0, 1, 0)}));
  EXPECT_TRUE(fuser.Snapshot(AtSeconds(1.0)).empty());
  auto tentative = fuser.Snapshot(AtSeconds(1.0), true);
  ASSERT_EQ(tentative.size(), 1u);
  EXPECT_EQ(tentative[0].state, FusedState::kTentative);
  fuser.AddFrame("a", FrameAt(1.04, {Obs(1, 3.04, 0, 1, 0)}));
  fuser.AddFrame("a", FrameAt(1.08, {Obs(1, 3.08, 0, 1, 0)}));
  auto confirmed = fuser.Snapshot(AtSeconds(1.1));
  ASSERT_EQ(confirmed.size(), 1u);
  EXPECT_EQ(confirmed[0].state, FusedState::kConfirmed);
  EXPECT_EQ(confirmed[0].updates, 3u);
  EXPECT_EQ(confirmed[0].first_ns, AtSeconds(1.0));
  EXPECT_EQ(confirmed[0].stamp_ns, AtSeconds(1.1));
  EXPECT_NEAR(confirmed[0].x_m, 3.1, 0.01);  // predicted to the snapshot time
  // No more frames: coasting, then deleted after max_coast_s.
  fuser.Tick(AtSeconds(1.5));
  ASSERT_EQ(fuser.Snapshot(AtSeconds(1.5)).size(), 1u);
  EXPECT_EQ(fuser.Snapshot(AtSeconds(1.5))[0].sources.size(), 1u);
  fuser.Tick(AtSeconds(1.6));
  auto coasting = fuser.Snapshot(AtSeconds(1.6));
  ASSERT_EQ(coasting.size(), 1u);
  EXPECT_EQ(coasting[0].state, FusedState::kCoasting);
  EXPECT_TRUE(coasting[0].sources.empty());  // unbound after source_timeout_s
  EXPECT_EQ(fuser.counters().sources_timed_out, 1u);
  EXPECT_NEAR(coasting[0].x_m, 3.6, 0.02);
  const double deleted_s = 1.08 + Options().max_coast_s + 0.02;
  fuser.Tick(AtSeconds(deleted_s - 0.04));
  EXPECT_EQ(fuser.Snapshot(AtSeconds(deleted_s - 0.04)).size(), 1u);
  fuser.Tick(AtSeconds(deleted_s));
  EXPECT_TRUE(fuser.Snapshot(AtSeconds(deleted_s), true).empty());
  EXPECT_EQ(fuser.counters().fused_deleted, 1u);
}

TEST_P(FuserTest, TentativeLocalTracksIgnoredUnlessAllowed) {
  for (const bool allow : {false, true}) {
    FusionOptions options = Options();
    options.use_tentative_sources = allow;
    Fuser fuser(options);
    fuser.SetPlacements({Placed("a", 0, 0, 0)});
    for (int k = 0; k < 5; ++k) {
      TrackObservation o = Obs(1, 3, 0);
      o.state = TrackState::kTentative;
      fuser.AddFrame("a", FrameAt(1.0 + 0.04 * k, {o}));
    }
    EXPECT_EQ(fuser.Snapshot(AtSeconds(1.2), true).size(), allow ? 1u : 0u);
    EXPECT_EQ(fuser.counters().observations_ignored, allow ? 0u : 5u);
    EXPECT_EQ(fuser.WorldTracks(AtSeconds(1.2)).size(), 1u);  // still drawn as a raw track
  }
}

// ---------------------------------------------------------------------------------------------
// Scenes

// Error statistics of one person seen by several sensors.
struct Errors {
  double fused_sum2 = 0.0;
  std::size_t fused_n = 0;
  std::map<std::string, std::pair<double, std::size_t>> sensor_sum2;
  std::set<std::uint64_t> ids;
  std::size_t samples_not_one = 0;
  std::size_t samples = 0;
  double Rms() const { return std::sqrt(fused_sum2 / static_cast<double>(fused_n)); }
  double SensorRms(const std::string& s) const {
    const auto& [sum, n] = sensor_sum2.at(s);
    return std::sqrt(sum / static_cast<double>(n));
  }
};

TEST_P(FuserSceneTest, OnePersonTwoSensorsGivesOneMoreAccurateTrack) {
  Scene scene;
  // Facing each other: each sees the near side of the person (bias towards itself).
  scene.sensors = {Sensor("a", 0, 0, 0), Sensor("b", 10, 0, 180, 0.013)};
  for (auto& s : scene.sensors) s.bias_m = 0.1;
  scene.people = {Walker({3, -3}, {7, 3}, 1.0)};
  Fuser fuser(Options());
  fuser.SetPlacements(scene.Placements());
  Errors e;
  scene.Run(fuser, 7.0, 0.1, [&](double t, UtcNs now) {
    if (t < 0.5) return;
    const Eigen::Vector2d truth = scene.people[0].position(t);
    const auto fused = fuser.Snapshot(now);
    ++e.samples;
    if (fused.size() != 1) ++e.samples_not_one;
    for (const FusedTrack& f : fused) {
      e.ids.insert(f.id);
      e.fused_sum2 += (Eigen::Vector2d(f.x_m, f.y_m) - truth).squaredNorm();
      ++e.fused_n;
      EXPECT_EQ(f.sources.size(), 2u);
    }
    for (const WorldTrack& w : fuser.WorldTracks(now)) {
      // The raw track is at its own scan time; compare with the truth then.
      const double tw = common::NsToSeconds(w.stamp_ns - AtSeconds(0));
      auto& [sum, n] = e.sensor_sum2[w.sensor_id];
      sum += (Eigen::Vector2d(w.x_m, w.y_m) - scene.people[0].position(tw)).squaredNorm();
      ++n;
      ASSERT_TRUE(w.fused_id.has_value());
      ASSERT_FALSE(e.ids.empty());
      EXPECT_EQ(*w.fused_id, *e.ids.begin());
    }
  });
  EXPECT_EQ(e.samples_not_one, 0u);
  EXPECT_EQ(e.ids.size(), 1u);
  const double rms_a = e.SensorRms("a"), rms_b = e.SensorRms("b");
  EXPECT_LT(e.Rms(), 0.7 * std::min(rms_a, rms_b))
      << "fused " << e.Rms() << " a " << rms_a << " b " << rms_b;
  EXPECT_EQ(fuser.counters().fused_created, 1u);
  EXPECT_EQ(fuser.counters().bindings, 1u);
}

// One person walking from a's field of view into b's; a sees x < a_max, b sees x > b_min.
struct HandOverResult {
  std::set<std::uint64_t> ids_while_seen;
  std::vector<std::uint64_t> id_sequence;
  std::size_t samples_more_than_one = 0;
  FusionCounters counters;
};

HandOverResult HandOver(const FusionOptions& options, double a_max, double b_min,
                        bool same_sensor = false) {
  Scene scene;
  scene.sensors = {Sensor("a", -3, -4, 60), Sensor("b", 3, -4, 120, 0.011)};
  scene.sensors[0].sees = [=](const Eigen::Vector2d& p) { return p.x() < a_max; };
  scene.sensors[1].sees = [=](const Eigen::Vector2d& p) { return p.x() > b_min; };
  if (same_sensor) {
    // One sensor, the person hidden in between (its tracker starts a new id afterwards).
    scene.sensors.pop_back();
    scene.sensors[0].sees = [=](const Eigen::Vector2d& p) {
      return p.x() < a_max || p.x() > b_min;
    };
  }
  scene.people = {Walker({-5, 1}, {5, 1}, 1.2)};
  Fuser fuser(options);
  fuser.SetPlacements(scene.Placements());
  HandOverResult r;
  scene.Run(fuser, 8.3, 0.05, [&](double t, UtcNs now) {
    if (t < 0.3) return;
    const auto fused = fuser.Snapshot(now);
    if (fused.size() > 1) ++r.samples_more_than_one;
    const auto* f = testing::Nearest(fused, scene.people[0].position(t), 1.0);
    if (f == nullptr) return;
    r.ids_while_seen.insert(f->id);
    if (r.id_sequence.empty() || r.id_sequence.back() != f->id) r.id_sequence.push_back(f->id);
  });
  r.counters = fuser.counters();
  return r;
}

TEST_P(FuserSceneTest, HandOverWithOverlapKeepsTheId) {
  const HandOverResult r = HandOver(Options(), 1.0, -1.0);
  EXPECT_EQ(r.ids_while_seen.size(), 1u);
  EXPECT_EQ(r.samples_more_than_one, 0u);
  EXPECT_EQ(r.counters.handovers, 1u);
  EXPECT_EQ(r.counters.fused_created, 1u);
}

TEST_P(FuserSceneTest, HandOverWithShortGapKeepsTheId) {
  // 0.6 m at 1.2 m/s: 0.5 s unseen (plus b's tentative frames) < max_coast_s.
  const HandOverResult r = HandOver(Options(), -0.3, 0.3);
  EXPECT_EQ(r.ids_while_seen.size(), 1u);
  EXPECT_EQ(r.samples_more_than_one, 0u);
  EXPECT_EQ(r.counters.handovers, 1u);
}

TEST_P(FuserSceneTest, SameSensorNewLocalIdAfterOcclusionKeepsTheId) {
  // 0.2 s hidden: the old local track is still bound (source_timeout_s) when the new one binds
  // and replaces it; 0.5 s: the old one has timed out.
  for (const double half_gap_m : {0.12, 0.3}) {
    const HandOverResult r = HandOver(Options(), -half_gap_m, half_gap_m, true);
    EXPECT_EQ(r.ids_while_seen.size(), 1u) << half_gap_m;
    EXPECT_EQ(r.samples_more_than_one, 0u) << half_gap_m;
    EXPECT_EQ(r.counters.handovers, 0u) << half_gap_m;
    EXPECT_EQ(r.counters.bindings, 1u) << half_gap_m;
    EXPECT_EQ(r.counters.sources_timed_out, half_gap_m < 0.2 ? 0u : 1u) << half_gap_m;
  }
}

TEST_P(FuserSceneTest, GapLongerThanMaxCoastGivesANewId) {
  // 3 m at 1.2 m/s: 2.5 s unseen > max_coast_s.
  const HandOverResult r = HandOver(Options(), -1.5, 1.5);
  EXPECT_EQ(r.id_sequence.size(), 2u);
  EXPECT_EQ(r.counters.fused_created, 2u);
  EXPECT_EQ(r.counters.fused_deleted, 1u);
}

// Two people; returns, for each, the fused ids nearest to them at samples where they are at least
// min_separation_m apart, and the samples where a person had not exactly one fused track near.
struct TwoPeopleResult {
  std::set<std::uint64_t> ids[2];
  std::size_t samples_not_one = 0;
  std::size_t samples = 0;
  FusionCounters counters;
};

TwoPeopleResult RunTwoPeople(const FusionOptions& options, Scene& scene, double duration_s,
                             double min_separation_m, double skip_from_s = -1.0,
                             double skip_to_s = -1.0) {
  Fuser fuser(options);
  fuser.SetPlacements(scene.Placements());
  TwoPeopleResult r;
  scene.Run(fuser, duration_s, 0.05, [&](double t, UtcNs now) {
    if (t < 0.3 || (t >= skip_from_s && t < skip_to_s)) return;
    const Eigen::Vector2d p0 = scene.people[0].position(t), p1 = scene.people[1].position(t);
    if ((p0 - p1).norm() < min_separation_m) return;
    const auto fused = fuser.Snapshot(now);
    ++r.samples;
    for (int i = 0; i < 2; ++i) {
      const Eigen::Vector2d p = i == 0 ? p0 : p1;
      if (testing::CountNear(fused, p, 0.5) != 1) ++r.samples_not_one;
      if (const auto* f = testing::Nearest(fused, p, 0.5)) r.ids[i].insert(f->id);
    }
  });
  r.counters = fuser.counters();
  return r;
}

TEST_P(FuserSceneTest, CrossingPeopleKeepTheirIds) {
  Scene scene;
  scene.sensors = {Sensor("a", 0, -8, 90), Sensor("b", 0, 8, -90, 0.017)};
  scene.people = {Walker({-5, -2}, {5, 2}, 1.2), Walker({-5, 2}, {5, -2}, 1.2, 0.3)};
  const TwoPeopleResult r = RunTwoPeople(Options(), scene, 9.0, 1.0);
  EXPECT_EQ(r.ids[0].size(), 1u);
  EXPECT_EQ(r.ids[1].size(), 1u);
  EXPECT_NE(*r.ids[0].begin(), *r.ids[1].begin());
  EXPECT_EQ(r.samples_not_one, 0u);
  EXPECT_EQ(r.counters.fused_created, 2u);
  EXPECT_EQ(r.counters.sources_drifted, 0u);
  EXPECT_EQ(r.counters.fused_merged, 0u);
}

TEST_P(FuserSceneTest, TwoPeopleSideBySideSeenByOneSensorStayTwo) {
  Scene scene;
  scene.sensors = {Sensor("a", 0, -6, 90)};
  scene.people = {Walker({-4, 0}, {4, 0}, 1.0), Walker({-4, 0.35}, {4, 0.35}, 1.0)};
  const TwoPeopleResult r = RunTwoPeople(Options(), scene, 8.0, 0.0);
  EXPECT_EQ(r.ids[0].size(), 1u);
  EXPECT_EQ(r.ids[1].size(), 1u);
  EXPECT_EQ(r.counters.fused_created, 2u);
  EXPECT_EQ(r.counters.fused_merged, 0u);
}

// A's tracker exchanges the ids of the two people at 3 s (B, if present, does not).
TwoPeopleResult TrackerIdSwitch(const FusionOptions& options, bool with_b) {
  Scene scene;
  scene.sensors = {Sensor("a", 0, -6, 90)};
  if (with_b) scene.sensors.push_back(Sensor("b", 0, 6, -90, 0.02));
  scene.people = {Walker({-5, -1}, {5, -1}, 1.2), Walker({5, 1}, {-5, 1}, 1.2)};
  scene.remap = [](std::size_t sensor, double t, std::size_t, std::uint32_t id) {
    return sensor == 0 && t >= 3.0 ? 3u - id : id;
  };
  // Recovery takes drift_updates frames of a: leave out 0.2 s after the switch.
  return RunTwoPeople(options, scene, 8.0, 0.0, 3.0, 3.2);
}

TEST_P(FuserSceneTest, TrackerIdSwitchWithASecondSensorFusedIdsFollowThePeople) {
  const TwoPeopleResult r = TrackerIdSwitch(Options(), true);
  EXPECT_EQ(r.ids[0].size(), 1u);
  EXPECT_EQ(r.ids[1].size(), 1u);
  EXPECT_NE(*r.ids[0].begin(), *r.ids[1].begin());
  EXPECT_EQ(r.samples_not_one, 0u);
  if (FusedFilter()) {
    // The fused tracks take each other's source: both re-bound in the frame of the switch.
    EXPECT_EQ(r.counters.source_rebinds, 2u);
    EXPECT_EQ(r.counters.sources_drifted, 0u);
  } else {
    EXPECT_EQ(r.counters.sources_drifted, 2u);
  }
  EXPECT_EQ(r.counters.fused_created, 2u);
}

TEST_P(FuserSceneTest, TrackerIdSwitchOfASingleSensorFusedIdsFollowThePeople) {
  const TwoPeopleResult r = TrackerIdSwitch(Options(), false);
  EXPECT_EQ(r.ids[0].size(), 1u);
  EXPECT_EQ(r.ids[1].size(), 1u);
  EXPECT_NE(*r.ids[0].begin(), *r.ids[1].begin());
  EXPECT_EQ(r.samples_not_one, 0u);
  if (FusedFilter()) {
    // The fused tracks take each other's source: both re-bound in the frame of the switch.
    EXPECT_EQ(r.counters.source_rebinds, 2u);
    EXPECT_EQ(r.counters.sources_drifted, 0u);
  } else {
    EXPECT_EQ(r.counters.sources_drifted, 2u);
  }
  EXPECT_EQ(r.counters.fused_created, 2u);
}

TEST_P(FuserSceneTest, TrackerIdSwitchWhilePassingCloseByFusedIdsFollowThePeople) {
  // Crossing at right angles 0.3 m apart, a's tracker exchanges them at the closest approach:
  // the swapped tracks are still inside every gate then, and move apart from there.
  Scene scene;
  scene.sensors = {Sensor("a", 0, -7, 90), Sensor("b", 0, 7, -90, 0.013)};
  for (auto& s : scene.sensors) s.bias_m = 0.1;
  scene.people = {Walker({-4.8, -0.15}, {4.8, -0.15}, 1.2), Walker({0.15, -4.8}, {0.15, 4.8}, 1.2)};
  scene.remap = [](std::size_t sensor, double t, std::size_t, std::uint32_t id) {
    return sensor == 0 && t >= 4.0 ? 3u - id : id;
  };
  Fuser fuser(Options());
  fuser.SetPlacements(scene.Placements());
  std::set<std::uint64_t> ids[2];
  double max_error_m = 0.0;
  scene.Run(fuser, 7.0, 0.05, [&](double t, UtcNs now) {
    if (t < 0.5) return;
    const auto fused = fuser.Snapshot(now);
    for (std::size_t i = 0; i < 2; ++i) {
      const Eigen::Vector2d p = scene.people[i].position(t);
      const auto* f = testing::Nearest(fused, p, 1.0);
      ASSERT_NE(f, nullptr) << t;
      // Near the crossing the nearest track may be the other person's: judge ids away from it.
      if (std::abs(t - 4.0) > 0.4) ids[i].insert(f->id);
      max_error_m = std::max(max_error_m, (Eigen::Vector2d(f->x_m, f->y_m) - p).norm());
    }
  });
  EXPECT_EQ(ids[0].size(), 1u);
  EXPECT_EQ(ids[1].size(), 1u);
  EXPECT_NE(*ids[0].begin(), *ids[1].begin());
  if (FusedFilter()) {
    EXPECT_GE(fuser.counters().source_rebinds, 2u);
  } else {
    // One swapped source may be replaced by the other (struck) instead of drifting out itself.
    EXPECT_GE(fuser.counters().sources_drifted, 1u);
    EXPECT_GT(fuser.counters().source_exclusions, 0u);
  }
  EXPECT_LT(max_error_m, 0.3);  // the swapped tracks never dragged a fused track along
}

TEST_P(FuserSceneTest, TrackerRestartReusedIdsDoNotCaptureOldBindings) {
  Scene scene;
  scene.sensors = {Sensor("a", 0, -6, 90)};
  scene.people = {Walker({-5, -1}, {5, -1}, 1.2), Walker({5, 1}, {-5, 1}, 1.2)};
  scene.sensors[0].silent = [](double t) { return t >= 3.0 && t < 3.3; };
  bool restarted = false;
  scene.before_frame = [&](Scene& s, std::size_t sensor, double t) {
    if (sensor == 0 && t >= 3.3 && !restarted) {
      s.RestartTracker(0);
      restarted = true;
    }
  };
  // The new session numbers the people the other way round: its id 1 is the old id 2's person.
  scene.remap = [](std::size_t, double t, std::size_t, std::uint32_t id) {
    return t >= 3.3 ? 3u - id : id;
  };
  // Without the drift test, which would also catch the jump of a captured binding.
  FusionOptions no_drift = Options();
  no_drift.drift_updates = 1'000'000;
  const TwoPeopleResult r = RunTwoPeople(no_drift, scene, 7.0, 0.0, 3.0, 3.5);
  EXPECT_TRUE(restarted);
  EXPECT_EQ(r.ids[0].size(), 1u);
  EXPECT_EQ(r.ids[1].size(), 1u);
  EXPECT_NE(*r.ids[0].begin(), *r.ids[1].begin());
  EXPECT_EQ(r.samples_not_one, 0u);
  EXPECT_EQ(r.counters.session_changes, 1u);
  EXPECT_EQ(r.counters.fused_created, 2u);
}

// ---------------------------------------------------------------------------------------------
// Calibration changes

TEST_P(FuserSceneTest, NewCalibrationMidRunKeepsTheIds) {
  Scene scene;
  scene.sensors = {Sensor("a", 0, 0, 0), Sensor("b", 10, 0, 180, 0.013)};
  scene.people = {Walker({2, -2}, {8, 2}, 1.0), Walker({8, -2}, {2, 2}, 1.0, 0.5)};
  Fuser fuser(Options());
  fuser.SetPlacements(scene.Placements());
  bool changed = false;
  scene.before_frame = [&](Scene& s, std::size_t, double t) {
    if (t >= 3.0 && !changed) {
      // A slightly different calibration (still within the gates of the old one).
      std::vector<SensorPlacement> p = s.Placements();
      p[1].world_from_sensor.x_m += 0.15;
      p[1].world_from_sensor.yaw_rad += DegToRad(1.0);
      fuser.SetPlacements(p);
      changed = true;
    }
  };
  std::set<std::uint64_t> ids[2];
  std::size_t not_one = 0;
  scene.Run(fuser, 7.0, 0.05, [&](double t, UtcNs now) {
    if (t < 1.0) return;
    if ((scene.people[0].position(t) - scene.people[1].position(t)).norm() < 1.2) return;
    const auto fused = fuser.Snapshot(now);
    for (int i = 0; i < 2; ++i) {
      const Eigen::Vector2d p = scene.people[static_cast<std::size_t>(i)].position(t);
      if (testing::CountNear(fused, p, 0.6) != 1) ++not_one;
      if (const auto* f = testing::Nearest(fused, p, 0.6)) ids[i].insert(f->id);
    }
  });
  EXPECT_TRUE(changed);
  EXPECT_EQ(ids[0].size(), 1u);
  EXPECT_EQ(ids[1].size(), 1u);
  EXPECT_EQ(not_one, 0u);
  EXPECT_EQ(fuser.counters().fused_created, 2u);
  EXPECT_EQ(fuser.counters().sources_drifted, 0u);
}

TEST_P(FuserSceneTest, DuplicatesOfABadCalibrationMergeIntoTheOlderId) {
  Scene scene;
  scene.sensors = {Sensor("a", 0, 0, 0), Sensor("b", 10, 0, 180, 0.013)};
  scene.sensors[1].placed = Pose2{12.0, 0.0, common::kPi};  // 2 m off: no association possible
  scene.people = {Walker({3, -3}, {7, 3}, 1.0)};
  Fuser fuser(Options());
  fuser.SetPlacements(scene.Placements());
  bool changed = false;
  std::set<std::uint64_t> before;
  scene.before_frame = [&](Scene& s, std::size_t, double t) {
    if (t >= 3.0 && !changed) {
      for (const auto& f : fuser.Snapshot(AtSeconds(t))) before.insert(f.id);
      s.sensors[1].placed.reset();
      fuser.SetPlacements(s.Placements());
      changed = true;
    }
  };
  std::set<std::uint64_t> after;
  std::size_t not_one_after = 0;
  scene.Run(fuser, 6.0, 0.05, [&](double t, UtcNs now) {
    if (t < 3.5) return;
    const auto fused = fuser.Snapshot(now);
    if (fused.size() != 1) ++not_one_after;
    for (const auto& f : fused) {
      after.insert(f.id);
      EXPECT_EQ(f.sources.size(), 2u);
    }
  });
  ASSERT_EQ(before.size(), 2u);
  EXPECT_EQ(not_one_after, 0u);
  ASSERT_EQ(after.size(), 1u);
  EXPECT_EQ(*after.begin(), *before.begin());  // the older id
  EXPECT_EQ(fuser.counters().fused_merged, 1u);
  // The output says the younger id ended, merged into the older one.
  const FusionOutput out = fuser.Output(AtSeconds(6.0));
  std::size_t merged = 0;
  for (const EndedFusedTrack& e : out.ended) {
    if (e.reason != FusedEndReason::kMerged) continue;
    ++merged;
    EXPECT_EQ(e.id, *before.rbegin());
    EXPECT_EQ(e.merged_into, *before.begin());
    EXPECT_GT(e.ended_ns, AtSeconds(3.0));
  }
  EXPECT_EQ(merged, 1u);
  ASSERT_EQ(out.tracks.size(), 1u);
  EXPECT_EQ(out.tracks[0].id, *before.begin());
}

// ---------------------------------------------------------------------------------------------
// The fused filter: known answers

// A standing person seen by two sensors whose trackers filter their measurements (standard
// deviations a_sigma_m and b_sigma_m, process noise tracker_psd). With the centres' offsets made
// negligible, the fused track must be what one filter on all measurements of both trackers gives:
// the recovered measurements are the trackers' own. Returns the largest |difference| of the
// positions and the ratio of the fused to that filter's position variance at the end.
struct CentralComparison {
  double position_difference_m = 0.0;
  double variance_ratio = 0.0;
  double single_variance_ratio = 0.0;  // fused / the better tracker's own variance
};

CentralComparison CompareWithCentralFilter(double a_sigma_m, double b_sigma_m, double tracker_psd,
                                           std::optional<double> told_psd) {
  Scene scene;
  scene.sensors = {Sensor("a", 0, 0, 0), Sensor("b", 10, 0, 180, 0.013)};
  scene.sensors[0].noise_m = scene.sensors[0].reported_sigma_m = a_sigma_m;
  scene.sensors[1].noise_m = scene.sensors[1].reported_sigma_m = b_sigma_m;
  for (auto& s : scene.sensors) {
    s.pose_covariance.setZero();
    s.tracker_accel_psd = tracker_psd;
  }
  scene.people = {Walker({4, 1}, {4, 1}, 0.0)};
  FusionOptions o;
  o.centre_sigma_shape_fit_m = o.centre_sigma_ellipse_m = o.centre_sigma_com_m = 1e-4;
  o.adapt_covariances = false;
  o.accel_psd = 0.5;
  // One filter on every measurement of both trackers (world frame, the same model).
  common::CvState xc = common::CvState::Zero();
  common::CvCovariance pc = common::CvCovariance::Identity();
  double tc = -1.0;
  scene.on_measurement = [&](std::size_t, double t, std::size_t, const Eigen::Vector2d& z,
                             double sigma) {
    const double r = sigma * sigma;
    if (tc < 0.0) {
      xc << z, 0.0, 0.0;
      pc = Eigen::Vector4d(r, r, 2.25, 2.25).asDiagonal();
    } else {
      common::CvPredict(t - tc, o.accel_psd, xc, pc);
      const Eigen::Matrix2d s_inv = (pc.topLeftCorner<2, 2>() + r * Eigen::Matrix2d::Identity())
                                        .llt()
                                        .solve(Eigen::Matrix2d::Identity());
      const Eigen::Matrix<double, 4, 2> gain = pc.leftCols<2>() * s_inv;
      xc += gain * (z - xc.head<2>());
      pc -= gain * pc.topRows<2>();
      pc = (0.5 * (pc + pc.transpose())).eval();
    }
    tc = t;
  };
  Fuser fuser(o);
  fuser.SetPlacements(scene.Placements());
  if (told_psd) {
    fuser.SetTrackerModel("a", *told_psd);
    fuser.SetTrackerModel("b", *told_psd);
  }
  CentralComparison out;
  double last_sample_s = 0.0;
  scene.Run(fuser, 6.0, 0.1, [&](double t, UtcNs) { last_sample_s = t; });
  const auto fused = fuser.Snapshot(AtSeconds(tc));
  EXPECT_EQ(fused.size(), 1u);
  if (fused.size() != 1) return out;
  out.position_difference_m = (Eigen::Vector2d(fused[0].x_m, fused[0].y_m) - xc.head<2>()).norm();
  out.variance_ratio = fused[0].covariance(0, 0) / pc(0, 0);
  double best = std::numeric_limits<double>::infinity();
  for (const WorldTrack& w : fuser.WorldTracks(AtSeconds(tc))) {
    // The tracker's own estimate at the same time.
    common::CvState x(w.x_m, w.y_m, w.vx_mps, w.vy_mps);
    common::CvCovariance p = w.covariance;
    common::CvPredict(tc - common::NsToSeconds(w.stamp_ns - AtSeconds(0.0)), tracker_psd, x, p);
    best = std::min(best, p(0, 0));
  }
  out.single_variance_ratio = fused[0].covariance(0, 0) / best;
  EXPECT_GT(last_sample_s, 5.0);
  return out;
}

TEST(FusedFilterTest, TwoTrackersGiveWhatOneFilterOnAllTheirMeasurementsGives) {
  const CentralComparison c = CompareWithCentralFilter(0.03, 0.08, 0.5, std::nullopt);
  EXPECT_LT(c.position_difference_m, 0.002);
  EXPECT_NEAR(c.variance_ratio, 1.0, 0.05);
  // And that is better than the better tracker alone (0.03 m): a 0.08 m sensor adds 1/7 of its
  // information.
  EXPECT_LT(c.single_variance_ratio, 0.95);
}

TEST(FusedFilterTest, TrackersWithAnotherProcessNoiseAreRecoveredWhenTold) {
  // Trackers with a process noise 4x the assumed one: told, the result is exact again.
  const CentralComparison told = CompareWithCentralFilter(0.03, 0.08, 2.0, 2.0);
  EXPECT_LT(told.position_difference_m, 0.002);
  EXPECT_NEAR(told.variance_ratio, 1.0, 0.05);
  // Not told (0.5 assumed): each frame seems to carry less information; the fused track is then
  // less certain than it could be, never more.
  const CentralComparison untold = CompareWithCentralFilter(0.03, 0.08, 2.0, std::nullopt);
  EXPECT_LT(untold.position_difference_m, 0.01);
  EXPECT_GT(untold.variance_ratio, 1.0);
}

TEST(FusedFilterTest, CentreOffsetsAreNotAveragedAwayByRepeatedFrames) {
  // One sensor, a standing person: its centre offset (0.03 m along the line of sight, 0.015 m
  // across) stays in the fused covariance however many frames come; a second sensor on the
  // other side halves it (independent offsets).
  for (const bool two : {false, true}) {
    Scene scene;
    scene.sensors = {Sensor("a", 0, 0, 0)};
    if (two) scene.sensors.push_back(Sensor("b", 8, 0, 180, 0.013));
    for (auto& s : scene.sensors) {
      s.pose_covariance.setZero();
      s.noise_m = s.reported_sigma_m = 0.02;
    }
    scene.people = {Walker({4, 0}, {4, 0}, 0.0)};
    FusionOptions o;
    o.adapt_covariances = false;
    Fuser fuser(o);
    fuser.SetPlacements(scene.Placements());
    scene.Run(fuser, 10.0, 1.0, nullptr);
    const auto fused = fuser.Snapshot(AtSeconds(9.99));
    ASSERT_EQ(fused.size(), 1u);
    const double radial = o.centre_sigma_com_m;  // the scene's trackers say centre of mass
    const double lateral = o.centre_lateral_fraction * radial;
    const double expected_xx = two ? radial * radial / 2.0 : radial * radial;
    const double expected_yy = two ? lateral * lateral / 2.0 : lateral * lateral;
    EXPECT_GT(fused[0].covariance(0, 0), expected_xx) << two;
    EXPECT_LT(fused[0].covariance(0, 0), 1.2 * expected_xx + 1e-4) << two;
    EXPECT_GT(fused[0].covariance(1, 1), expected_yy) << two;
    EXPECT_LT(fused[0].covariance(1, 1), 1.2 * expected_yy + 1e-4) << two;
  }
}

TEST(FusedFilterTest, RawDetectionsAreUsedFrameByFrame) {
  // A client that sends every frame's detection with its covariance instead of a filter's
  // state: each frame is a measurement of its own.
  Scene scene;
  scene.sensors = {Sensor("a", 0, 0, 0), Sensor("b", 10, 0, 180, 0.013)};
  for (auto& s : scene.sensors) {
    s.filtered = false;
    s.noise_m = s.reported_sigma_m = 0.05;
  }
  scene.people = {Walker({3, -3}, {7, 3}, 1.0)};
  Fuser fuser;
  fuser.SetPlacements(scene.Placements());
  double sum2 = 0.0;
  std::size_t n = 0;
  std::set<std::uint64_t> ids;
  scene.Run(fuser, 7.0, 0.1, [&](double t, UtcNs now) {
    if (t < 1.0) return;
    for (const FusedTrack& f : fuser.Snapshot(now)) {
      sum2 += (Eigen::Vector2d(f.x_m, f.y_m) - scene.people[0].position(t)).squaredNorm();
      ++n;
      ids.insert(f.id);
    }
  });
  EXPECT_EQ(ids.size(), 1u);
  EXPECT_EQ(fuser.counters().sources_unfiltered, 2u);
  ASSERT_GT(n, 50u);
  // Two sensors at 25 Hz with 0.05 m each, filtered: well below one raw detection's error.
  EXPECT_LT(std::sqrt(sum2 / static_cast<double>(n)), 0.04);
}

TEST(FusedFilterTest, AnOverConfidentTrackerIsScaledUp) {
  // b's tracker claims 5 mm where its measurements scatter by 5 cm; a is honest.
  Scene scene;
  scene.sensors = {Sensor("a", 0, 0, 0), Sensor("b", 10, 0, 180, 0.013)};
  scene.sensors[0].noise_m = scene.sensors[0].reported_sigma_m = 0.03;
  scene.sensors[1].noise_m = 0.05;
  scene.sensors[1].reported_sigma_m = 0.005;
  scene.people = {Walker({2, -3}, {8, 3}, 0.3)};
  Fuser fuser;
  fuser.SetPlacements(scene.Placements());
  double nees = 0.0;
  std::size_t n = 0;
  std::set<std::uint64_t> ids;
  scene.Run(fuser, 30.0, 0.1, [&](double t, UtcNs now) {
    if (t < 20.0) return;
    for (const FusedTrack& f : fuser.Snapshot(now)) {
      const Eigen::Vector2d e = Eigen::Vector2d(f.x_m, f.y_m) - scene.people[0].position(t);
      nees += e.dot(f.covariance.topLeftCorner<2, 2>().llt().solve(e));
      ++n;
      ids.insert(f.id);
    }
  });
  const CovarianceScales scales = fuser.covariance_scales();
  EXPECT_GT(scales.trackers.at("b"), 4.0);
  EXPECT_LT(scales.trackers.at("a"), 1.5);
  EXPECT_DOUBLE_EQ(scales.pose, 1.0);
  EXPECT_EQ(ids.size(), 1u);
  ASSERT_GT(n, 50u);
  EXPECT_LT(nees / static_cast<double>(n), 4.0);
}

// ---------------------------------------------------------------------------------------------
// Ids through tracker errors and gaps

// Two people crossing 0.3 m apart at right angles; at the closest approach sensor a's tracker
// exchanges their local tracks (each filter goes on with the other person; no jump of its
// reported state, only of its measurements). b (when present) does not.
TEST_P(FuserSceneTest, ExchangedLocalTracksFusedIdsFollowThePeople) {
  for (const bool with_b : {true, false}) {
    Scene scene;
    scene.sensors = {Sensor("a", 0, -7, 90)};
    if (with_b) scene.sensors.push_back(Sensor("b", -7, 0, 0, 0.013));
    scene.people = {Walker({-4.8, -0.15}, {4.8, -0.15}, 1.2),
                    Walker({0.15, -4.8}, {0.15, 4.8}, 1.2)};
    bool exchanged = false;
    scene.before_frame = [&](Scene& s, std::size_t sensor, double t) {
      if (sensor == 0 && t >= 4.0 && !exchanged) {
        s.ExchangeLocalTracks(0, 0, 1);
        exchanged = true;
      }
    };
    Fuser fuser(Options());
    fuser.SetPlacements(scene.Placements());
    std::set<std::uint64_t> ids[2];
    std::size_t not_one = 0;
    scene.Run(fuser, 7.5, 0.05, [&](double t, UtcNs now) {
      if (t < 0.5 || std::abs(t - 4.0) < 0.5) return;  // near the crossing: ambiguous
      const auto fused = fuser.Snapshot(now);
      for (std::size_t i = 0; i < 2; ++i) {
        const Eigen::Vector2d p = scene.people[i].position(t);
        if (testing::CountNear(fused, p, 0.4) != 1) ++not_one;
        if (const auto* f = testing::Nearest(fused, p, 0.4)) ids[i].insert(f->id);
      }
    });
    ASSERT_TRUE(exchanged);
    if (!FusedFilter()) {
      // Earlier releases: the combination of latest states follows the exchanged tracks.
      continue;
    }
    EXPECT_EQ(ids[0].size(), 1u) << with_b;
    EXPECT_EQ(ids[1].size(), 1u) << with_b;
    EXPECT_NE(*ids[0].begin(), *ids[1].begin()) << with_b;
    EXPECT_EQ(not_one, 0u) << with_b;
    EXPECT_GE(fuser.counters().source_rebinds, 2u) << with_b;
  }
}

TEST_P(FuserSceneTest, GapInEverySensorsViewShorterThanTheCoastTimeKeepsTheId) {
  // Two sensors lose the person behind the same pillar for 1.2 m (1.0 s at 1.2 m/s, plus the
  // trackers' tentative frames); both trackers start new ids afterwards.
  Scene scene;
  scene.sensors = {Sensor("a", -3, -4, 60), Sensor("b", 3, -4, 120, 0.011)};
  for (auto& s : scene.sensors) {
    s.sees = [](const Eigen::Vector2d& p) { return std::abs(p.x()) > 0.6; };
  }
  scene.people = {Walker({-5, 1}, {5, 1}, 1.2)};
  const FusionOptions options = Options();
  ASSERT_GT(options.max_coast_s, 1.2);
  Fuser fuser(options);
  fuser.SetPlacements(scene.Placements());
  std::vector<std::uint64_t> id_sequence;
  std::size_t more_than_one = 0;
  scene.Run(fuser, 8.3, 0.05, [&](double t, UtcNs now) {
    if (t < 0.3) return;
    const auto fused = fuser.Snapshot(now);
    if (fused.size() > 1) ++more_than_one;
    const auto* f = testing::Nearest(fused, scene.people[0].position(t), 1.0);
    if (f != nullptr && (id_sequence.empty() || id_sequence.back() != f->id)) {
      id_sequence.push_back(f->id);
    }
  });
  EXPECT_EQ(id_sequence.size(), 1u);
  EXPECT_EQ(more_than_one, 0u);
  EXPECT_EQ(fuser.counters().fused_created, 1u);
  EXPECT_EQ(fuser.counters().bindings, FusedFilter() ? 3u : 3u);  // b first, then a and b again
}

TEST_P(FuserSceneTest, FalseTrackOfOneSensorNeitherStealsNorPullsAPerson) {
  // Sensor a reports a standing object 0.7 m beside the walking person's path for 2 s (a
  // reflection, a coat on a chair); b never sees it.
  Scene scene;
  scene.sensors = {Sensor("a", 0, -6, 90), Sensor("b", 0, 6, -90, 0.013)};
  SimPerson ghost = Walker({0.3, 0.7}, {0.3, 0.7}, 0.0);
  ghost.seen_by = [](std::size_t sensor, double t) { return sensor == 0 && t >= 2.0 && t < 4.0; };
  scene.people = {Walker({-4, 0}, {4, 0}, 1.2), ghost};
  const FusionOptions options = Options();
  Fuser fuser(options);
  fuser.SetPlacements(scene.Placements());
  std::set<std::uint64_t> person_ids;
  double max_error_m = 0.0;
  std::size_t ghost_seen = 0, ghost_after = 0, person_not_one = 0;
  scene.Run(fuser, 8.0, 0.05, [&](double t, UtcNs now) {
    if (t < 0.5) return;
    const auto fused = fuser.Snapshot(now);
    const Eigen::Vector2d person = scene.people[0].position(t);
    const auto* f = testing::Nearest(fused, person, 0.3);
    ASSERT_NE(f, nullptr) << t;
    person_ids.insert(f->id);
    max_error_m = std::max(max_error_m, (Eigen::Vector2d(f->x_m, f->y_m) - person).norm());
    if (testing::CountNear(fused, person, 0.3) != 1) ++person_not_one;
    const std::size_t near_ghost = testing::CountNear(fused, {0.3, 0.7}, 0.2);
    if (t > 2.5 && t < 4.0) ghost_seen += near_ghost > 0 ? 1 : 0;
    if (t > 4.0 + options.max_coast_s + 0.1) ghost_after += near_ghost;
  });
  EXPECT_EQ(person_ids.size(), 1u);
  EXPECT_LT(max_error_m, 0.12);
  EXPECT_EQ(person_not_one, 0u);
  EXPECT_GT(ghost_seen, 20u);  // one sensor's track is a fused track (nothing says it is false)
  EXPECT_EQ(ghost_after, 0u);  // and it is gone max_coast_s after its last frame
  EXPECT_EQ(fuser.counters().fused_merged, 0u);
}

TEST(FusedFilterTest, APersonWhoStopsAtOnceKeepsTheId) {
  // 2 m/s to standing within one frame, seen by a tracker that measures to 3 mm: the motion
  // model does not expect it; the track is widened and keeps its source and id.
  Scene scene;
  scene.sensors = {Sensor("a", 0, -6, 90)};
  scene.sensors[0].noise_m = scene.sensors[0].reported_sigma_m = 0.003;
  scene.people = {Walker({-4, 0}, {0.5, 0}, 2.0)};
  FusionOptions o;
  o.centre_sigma_com_m = 0.005;  // and its centre is that good
  Fuser fuser(o);
  fuser.SetPlacements(scene.Placements());
  std::set<std::uint64_t> ids;
  double max_error_m = 0.0;
  scene.Run(fuser, 6.0, 0.05, [&](double t, UtcNs now) {
    if (t < 0.5) return;
    const auto fused = fuser.Snapshot(now);
    ASSERT_EQ(fused.size(), 1u) << t;
    ids.insert(fused[0].id);
    max_error_m = std::max(
        max_error_m,
        (Eigen::Vector2d(fused[0].x_m, fused[0].y_m) - scene.people[0].position(t)).norm());
  });
  EXPECT_EQ(ids.size(), 1u);
  EXPECT_GT(fuser.counters().manoeuvres, 0u);
  EXPECT_EQ(fuser.counters().sources_drifted, 0u);
  EXPECT_LT(max_error_m, 0.25);
}

TEST(FusedFilterTest, ALocalTrackSentAgainAfterTheSourceTimeoutFeedsItsFusedTrackAgain) {
  // One sensor: its tracker holds a walker's coasting track unsent for 0.7 s (longer than
  // source_timeout_s) and sends it again with its id, 0.35 m behind where the fused track
  // coasted to (the walker slowed). In the same frame it starts a track on someone standing
  // 0.1 m from there. The returning track feeds the fused track it fed before (the standing
  // person does not take it over), the standing person gets a fused track of its own, and no
  // fused track is left without a source.
  const FusionOptions o;
  ASSERT_LT(o.source_timeout_s, 0.7);
  ASSERT_GT(o.max_coast_s, 0.7);
  Fuser fuser(o);
  fuser.SetPlacements({Placed("a", 0, 0, 0)});
  const auto walker_x = [](double t) { return 2.0 + 1.5 * (t - 1.0) - (t > 3.5 ? 0.35 : 0.0); };
  const double standing_x = 2.0 + 1.5 * 2.76;
  std::set<std::uint64_t> walker_ids;
  for (int k = 0; k <= 100; ++k) {
    const double t = 1.0 + 0.04 * k;
    std::vector<TrackObservation> tracks;
    if (t < 3.02 || t > 3.74) tracks.push_back(Obs(1, walker_x(t), 1.0, 1.5, 0.0));
    if (t > 3.74) tracks.push_back(Obs(2, standing_x, 1.1));
    fuser.AddFrame("a", FrameAt(t, std::move(tracks)));
    const UtcNs now = AtSeconds(t);
    fuser.Tick(now);
    const auto fused = fuser.Snapshot(now, true);
    if (const auto* f = testing::Nearest(fused, Eigen::Vector2d(walker_x(t), 1.0), 0.3)) {
      walker_ids.insert(f->id);
    }
  }
  EXPECT_EQ(walker_ids.size(), 1u);
  EXPECT_EQ(fuser.counters().sources_timed_out, 1u);
  EXPECT_EQ(fuser.counters().sources_returned, 1u);
  EXPECT_EQ(fuser.counters().fused_created, 2u);  // the walker's and the standing person's
  const auto fused = fuser.Snapshot(AtSeconds(5.0));
  ASSERT_EQ(fused.size(), 2u);
  const auto* walker = testing::Nearest(fused, Eigen::Vector2d(walker_x(5.0), 1.0), 0.3);
  const auto* standing = testing::Nearest(fused, Eigen::Vector2d(standing_x, 1.1), 0.3);
  ASSERT_NE(walker, nullptr);
  ASSERT_NE(standing, nullptr);
  EXPECT_EQ(walker_ids.count(walker->id), 1u);
  EXPECT_NE(standing->id, walker->id);
  for (const FusedTrack& f : fused) EXPECT_EQ(f.sources.size(), 1u) << f.id;
}

// Step k (every 0.04 s from t = 1 s) of the scene below: track 1 until 2.3 s, track 2 0.1 m
// beside it from 2 s on; the frame added and the fuser ticked. Returns t.
double StepLeftBehind(Fuser& fuser, int k) {
  const double t = 1.0 + 0.04 * k;
  const double x = 3.0 + 1.0 * (t - 1.0);
  std::vector<TrackObservation> tracks;
  if (t < 2.3) tracks.push_back(Obs(1, x, 1.0, 1.0, 0.0));
  if (t >= 2.0) tracks.push_back(Obs(2, x, 1.1, 1.0, 0.0));
  fuser.AddFrame("a", FrameAt(t, std::move(tracks)));
  fuser.Tick(AtSeconds(t));
  return t;
}

// One sensor's tracker follows a walker with track 1, starts a second track (2) on the same
// walker 0.1 m beside it at t = 2 s and drops track 1 at t = 2.3 s. Track 2 starts a fused track
// of its own (the walker's fused track took track 1 in that frame); once track 1 is gone its fused
// track coasts beside the one track 2 feeds. Returns the fused tracks seen at t = 3 s and the
// counters.
std::pair<std::vector<FusedTrack>, FusionCounters> RunLeftBehind(bool merge_sourceless) {
  FusionOptions o;
  o.merge_sourceless = merge_sourceless;
  o.report_sourceless = !merge_sourceless;  // earlier releases: both off / on
  Fuser fuser(o);
  fuser.SetPlacements({Placed("a", 0, 0, 0)});
  std::vector<FusedTrack> at_3s;
  for (int k = 0; k <= 50; ++k) {
    const double t = StepLeftBehind(fuser, k);
    if (k == 50) at_3s = fuser.Snapshot(AtSeconds(t));
  }
  return {at_3s, fuser.counters()};
}

// The output of the left-behind run: the younger id (2) ends merged into the older (1), which
// goes on with 2's estimate; at every step every id reported before is accounted for.
TEST(FusedFilterTest, OutputReportsAMergedIdWithTheIdItGoesOnAs) {
  Fuser fuser{FusionOptions{}};
  fuser.SetPlacements({Placed("a", 0, 0, 0)});
  std::set<std::uint64_t> seen;
  FusionOutput out;
  for (int k = 0; k <= 50; ++k) {
    const double t = StepLeftBehind(fuser, k);
    out = fuser.Output(AtSeconds(t));
    // The tracks are Snapshot's.
    const auto snapshot = fuser.Snapshot(AtSeconds(t));
    ASSERT_EQ(out.tracks.size(), snapshot.size());
    for (std::size_t i = 0; i < snapshot.size(); ++i) {
      EXPECT_EQ(out.tracks[i].id, snapshot[i].id);
      EXPECT_EQ(out.tracks[i].x_m, snapshot[i].x_m);
      EXPECT_EQ(out.tracks[i].covariance, snapshot[i].covariance);
    }
    ExpectEveryIdAccounted(out, seen);
  }
  EXPECT_EQ(seen, (std::set<std::uint64_t>{1, 2}));
  ASSERT_EQ(out.ended.size(), 1u);
  EXPECT_EQ(out.ended[0].id, 2u);
  EXPECT_EQ(out.ended[0].reason, FusedEndReason::kMerged);
  EXPECT_EQ(out.ended[0].merged_into, 1u);
  ASSERT_EQ(out.tracks.size(), 1u);
  EXPECT_EQ(out.tracks[0].id, 1u);
  EXPECT_TRUE(out.hidden.empty());
  // A gap in the data longer than ended_report_s: the end is still reported after it (no
  // output took it in between), 1 has timed out meanwhile.
  const UtcNs later = AtSeconds(3.0 + FusionOptions{}.ended_report_s + 1.0);
  fuser.Tick(later);
  const FusionOutput much_later = fuser.Output(later);
  ASSERT_EQ(much_later.ended.size(), 2u);
  EXPECT_EQ(much_later.ended[0].id, 2u);
  EXPECT_EQ(much_later.ended[0].reason, FusedEndReason::kMerged);
  EXPECT_EQ(much_later.ended[1].id, 1u);
  EXPECT_EQ(much_later.ended[1].reason, FusedEndReason::kTimedOut);
  // Its outputs now span more than ended_report_s: forgotten at the next Tick; 1's end stays
  // (first output just now).
  fuser.Tick(later + 40'000'000);
  const FusionOutput next = fuser.Output(later + 40'000'000);
  ASSERT_EQ(next.ended.size(), 1u);
  EXPECT_EQ(next.ended[0].id, 1u);
  EXPECT_EQ(next.ended[0].reason, FusedEndReason::kTimedOut);
}

// The left-behind run looked at only (Output with EndsRead::kPeek, as the fused tracks' publish
// and a live view do): its ends are not marked read, so however long the outputs looked at span
// they stay; their ended_report_s runs from the first output read with kMark, in the time of
// such outputs alone.
TEST(FusedFilterTest, OutputsOnlyLookedAtKeepTheEndsForTheReaders) {
  Fuser fuser{FusionOptions{}};
  fuser.SetPlacements({Placed("a", 0, 0, 0)});
  const double report_s = FusionOptions{}.ended_report_s;
  for (int k = 0; k <= 50; ++k) {
    const double t = StepLeftBehind(fuser, k);
    fuser.Output(AtSeconds(t), false, Fuser::EndsRead::kPeek);
  }
  // Looked at over more than ended_report_s: 2's end (and 1's, timed out meanwhile) stay.
  for (double t = 4.0; t < 4.0 + 2.0 * report_s; t += 1.0) {
    fuser.Tick(AtSeconds(t));
    fuser.Output(AtSeconds(t), false, Fuser::EndsRead::kPeek);
  }
  const double read_s = 4.0 + 2.0 * report_s;
  fuser.Tick(AtSeconds(read_s));
  const FusionOutput read = fuser.Output(AtSeconds(read_s));  // read: marked now
  ASSERT_EQ(read.ended.size(), 2u);
  EXPECT_EQ(read.ended[0].id, 2u);
  EXPECT_EQ(read.ended[1].id, 1u);
  // Looks later than ended_report_s after the read do not advance the reads' time: kept.
  fuser.Tick(AtSeconds(read_s + report_s + 1.0));
  EXPECT_EQ(
      fuser.Output(AtSeconds(read_s + report_s + 1.0), false, Fuser::EndsRead::kPeek).ended.size(),
      2u);
  // A read then, and a Tick: forgotten.
  fuser.MarkEndsRead(AtSeconds(read_s + report_s + 1.0));
  fuser.Tick(AtSeconds(read_s + report_s + 1.04));
  EXPECT_TRUE(fuser.Output(AtSeconds(read_s + report_s + 1.04)).ended.empty());
}

// A walker leaves the only sensor's view at t = 2 s and is not seen again: once its source timed
// out the fused id is hidden (kept, not reported: with its last update's time and place), and
// max_coast_s after that update it ends as timed out.
TEST(FusedFilterTest, OutputHoldsAHiddenIdUntilItTimesOut) {
  Fuser fuser{FusionOptions{}};
  fuser.SetPlacements({Placed("a", 0, 0, 0)});
  std::set<std::uint64_t> seen;
  double hidden_from = -1.0, ended_at = -1.0;
  for (int k = 0; k <= 80; ++k) {
    const double t = 1.0 + 0.04 * k;
    std::vector<TrackObservation> tracks;
    if (t < 2.0) tracks.push_back(Obs(1, 3.0 + (t - 1.0), 1.0, 1.0, 0.0));
    fuser.AddFrame("a", FrameAt(t, std::move(tracks)));
    fuser.Tick(AtSeconds(t));
    const FusionOutput out = fuser.Output(AtSeconds(t));
    ExpectEveryIdAccounted(out, seen);
    if (!out.hidden.empty() && hidden_from < 0.0) {
      hidden_from = t;
      ASSERT_EQ(out.hidden.size(), 1u);
      EXPECT_EQ(out.hidden[0].id, 1u);
      // The last frame with the track.
      EXPECT_NEAR(static_cast<double>(out.hidden[0].last_ns - AtSeconds(1.96)), 0.0, 1e3);
      EXPECT_NEAR(out.hidden[0].x_m, 3.96, 0.05);
      EXPECT_NEAR(out.hidden[0].y_m, 1.0, 0.05);
      EXPECT_EQ(out.hidden[0].last_sensor, "a");
    }
    if (!out.ended.empty() && ended_at < 0.0) {
      ended_at = t;
      ASSERT_EQ(out.ended.size(), 1u);
      EXPECT_EQ(out.ended[0].id, 1u);
      EXPECT_EQ(out.ended[0].reason, FusedEndReason::kTimedOut);
      EXPECT_EQ(out.ended[0].merged_into, 0u);
      EXPECT_EQ(out.ended[0].ended_ns, AtSeconds(t));
      EXPECT_TRUE(out.hidden.empty());
    }
  }
  EXPECT_EQ(seen, std::set<std::uint64_t>{1});
  EXPECT_NEAR(hidden_from, 1.96 + FusionOptions{}.source_timeout_s, 0.05);
  EXPECT_NEAR(ended_at, 1.96 + FusionOptions{}.max_coast_s, 0.05);
}

// Without Tick (fusion disabled) a hidden id older than max_coast_s is no longer listed as
// hidden: it would otherwise be held by the consumers for good.
TEST(FusedFilterTest, OutputDoesNotHoldAnIdOlderThanMaxCoastWithoutTick) {
  Fuser fuser{FusionOptions{}};
  fuser.SetPlacements({Placed("a", 0, 0, 0)});
  for (int k = 0; k <= 40; ++k) {
    const double t = 1.0 + 0.04 * k;
    std::vector<TrackObservation> tracks;
    if (t < 2.0) tracks.push_back(Obs(1, 3.0 + (t - 1.0), 1.0, 1.0, 0.0));
    fuser.AddFrame("a", FrameAt(t, std::move(tracks)));
    fuser.Tick(AtSeconds(t));
  }
  // Hidden now (its source timed out), and still within max_coast_s of its last update.
  const double last_s = 1.96;
  const FusionOutput hidden = fuser.Output(AtSeconds(2.6));
  EXPECT_TRUE(hidden.tracks.empty());
  ASSERT_EQ(hidden.hidden.size(), 1u);
  EXPECT_EQ(hidden.hidden[0].id, 1u);
  const double coast_s = FusionOptions{}.max_coast_s;
  EXPECT_EQ(fuser.Output(AtSeconds(last_s + coast_s - 0.1)).hidden.size(), 1u);
  // No Tick since: past max_coast_s the id is neither reported nor hidden.
  const FusionOutput later = fuser.Output(AtSeconds(last_s + coast_s + 0.1));
  EXPECT_TRUE(later.tracks.empty());
  EXPECT_TRUE(later.hidden.empty());
  EXPECT_TRUE(fuser.Output(AtSeconds(last_s + 100.0 * coast_s)).hidden.empty());
}

// A track seen in one frame only (tentative, never reported) ends without a trace in the output;
// confirmed ids that end are listed, and beyond max_fused_tracks kept ends the oldest is
// forgotten and counted.
TEST(FusedFilterTest, OutputListsOnlyEndsOfConfirmedIdsAndCountsEvictedOnes) {
  FusionOptions options;
  options.max_fused_tracks = 2;
  Fuser fuser{options};
  fuser.SetPlacements({Placed("a", 0, 0, 0)});
  // A flicker at 1 s: one frame, then the walker alone.
  double t = 1.0;
  fuser.AddFrame("a", FrameAt(t, {Obs(9, 6.0, -2.0, 0.0, 0.0)}));
  fuser.Tick(AtSeconds(t));
  for (int k = 1; k <= 100; ++k) {
    t = 1.0 + 0.04 * k;
    fuser.AddFrame("a", FrameAt(t, {}));
    fuser.Tick(AtSeconds(t));
  }
  EXPECT_EQ(fuser.counters().fused_created, 1u);
  EXPECT_EQ(fuser.counters().fused_deleted, 1u);
  EXPECT_TRUE(fuser.Output(AtSeconds(t)).ended.empty());
  // Three walkers confirmed one after the other, each timing out: two ends kept, one evicted.
  std::uint32_t local = 10;
  for (int walker = 0; walker < 3; ++walker, ++local) {
    for (int k = 0; k < 25; ++k) {
      t += 0.04;
      fuser.AddFrame("a", FrameAt(t, {Obs(local, 3.0 + 0.04 * k, 1.0, 1.0, 0.0)}));
      fuser.Tick(AtSeconds(t));
    }
    for (int k = 0; k < 100; ++k) {
      t += 0.04;
      fuser.AddFrame("a", FrameAt(t, {}));
      fuser.Tick(AtSeconds(t));
    }
  }
  const FusionOutput out = fuser.Output(AtSeconds(t));
  ASSERT_EQ(out.ended.size(), 2u);
  EXPECT_EQ(out.ended[0].reason, FusedEndReason::kTimedOut);
  EXPECT_EQ(out.ended[1].reason, FusedEndReason::kTimedOut);
  EXPECT_LT(out.ended[0].id, out.ended[1].id);
  EXPECT_EQ(fuser.counters().ended_evicted, 1u);
}

TEST(FusedFilterTest, AFusedTrackLeftBehindByItsSourcesMergesIntoTheTrackThatTookItsObject) {
  const auto [before, before_counters] = RunLeftBehind(false);
  ASSERT_EQ(before_counters.fused_created, 2u);
  EXPECT_EQ(before.size(), 2u);  // the left-behind track coasts beside the walker's
  EXPECT_EQ(before_counters.fused_merged_sourceless, 0u);
  const auto [after, counters] = RunLeftBehind(true);
  ASSERT_EQ(counters.fused_created, 2u);
  EXPECT_EQ(counters.fused_merged_sourceless, 1u);
  ASSERT_EQ(after.size(), 1u);
  EXPECT_EQ(after[0].id, 1u);  // the older id kept
  ASSERT_EQ(after[0].sources.size(), 1u);
  EXPECT_EQ(after[0].sources[0].track_id, 2u);
  EXPECT_NEAR(after[0].y_m, 1.1, 0.03);  // the measured track's estimate, not a blend
}

// Two sensors 1 m apart, (1.5, 0) and (2.5, 0), look at person A standing at (2, 4). Person B walks
// slowly across in front of A, 0.4 m nearer the sensors (y = 3.6, at 0.45 m/s: within the merge's
// speed gate of A's standing track). A sensor does not see A while B's body (0.25 m radius) is on
// its line of sight to A; both are blocked while B is within about 0.2 m of x = 2 (0.9 s). The
// trackers drop A when they lose it and start new tracks on A when they see it again. Returns
// the fused ids nearest A and B (within 0.3 m) before and after the hiding, and the counters.
struct HiddenBehindResult {
  std::set<std::uint64_t> a_before, a_after, b_before, b_after;
  FusionCounters counters;
};
HiddenBehindResult RunHiddenBehindPasserBy(const FusionOptions& options) {
  Scene scene;
  scene.sensors = {Sensor("a", 1.5, 0, 90), Sensor("b", 2.5, 0, 90, 0.02)};
  const Eigen::Vector2d a_pos(2.0, 4.0);
  const SimPerson b = Walker({-1.0, 3.6}, {5.0, 3.6}, 0.45);
  SimPerson a;
  a.position = [=](double) { return a_pos; };
  std::vector<Eigen::Vector2d> sensor_at;
  for (const SimSensor& s : scene.sensors) sensor_at.push_back(s.truth.translation());
  a.seen_by = [=](std::size_t s, double t) {
    // B's distance to the line of sight from the sensor to A.
    const Eigen::Vector2d ray = a_pos - sensor_at[s], to_b = b.position(t) - sensor_at[s];
    const double along = std::clamp(to_b.dot(ray) / ray.squaredNorm(), 0.0, 1.0);
    return (to_b - along * ray).norm() > 0.25;
  };
  scene.people = {a, b};
  // B blocks both sensors' view of A from about 6.2 s to 7.1 s.
  Fuser fuser(options);
  fuser.SetPlacements(scene.Placements());
  HiddenBehindResult r;
  scene.Run(fuser, 12.0, 0.05, [&](double t, UtcNs now) {
    if (t < 1.0 || (t > 5.0 && t < 8.0)) return;
    const auto fused = fuser.Snapshot(now);
    const auto* fa = testing::Nearest(fused, a_pos, 0.3);
    const auto* fb = testing::Nearest(fused, b.position(t), 0.3);
    if (fa != nullptr) (t < 5.0 ? r.a_before : r.a_after).insert(fa->id);
    if (fb != nullptr) (t < 5.0 ? r.b_before : r.b_after).insert(fb->id);
  });
  r.counters = fuser.counters();
  return r;
}

TEST(FusedFilterTest, APersonHiddenBehindAPasserByKeepsItsIdAndIsNotMergedIntoIt) {
  // Without the shadow test (earlier releases): A's fused track, without sources, coasting within
  // the merge gates of B's, is merged into it: B goes on with A's (older) id, A gets a new one.
  FusionOptions no_shadow;
  no_shadow.merge_sourceless_shadow_m = 0.0;
  const HiddenBehindResult before = RunHiddenBehindPasserBy(no_shadow);
  ASSERT_EQ(before.a_before.size(), 1u);
  ASSERT_EQ(before.b_before.size(), 1u);
  EXPECT_EQ(before.counters.fused_merged_sourceless, 1u);
  EXPECT_EQ(before.b_after, before.a_before);
  EXPECT_NE(before.a_after, before.a_before);

  const HiddenBehindResult r = RunHiddenBehindPasserBy(FusionOptions{});
  EXPECT_GT(r.counters.merge_sourceless_shadowed, 0u);
  ASSERT_EQ(r.a_before.size(), 1u);
  ASSERT_EQ(r.b_before.size(), 1u);
  EXPECT_NE(*r.a_before.begin(), *r.b_before.begin());
  EXPECT_EQ(r.a_after, r.a_before);  // A's id after it reappears
  EXPECT_EQ(r.b_after, r.b_before);  // B's id after it passed
  EXPECT_EQ(r.counters.fused_merged_sourceless, 0u);
}

TEST(FusedFilterTest, AFusedTrackNoTrackerHoldsIsKeptForItsIdButNotReported) {
  // A walker leaves the only sensor's view at t = 2 s (its tracker drops the track) and its
  // tracker starts a new track where the fused track coasted to at t = 2.7 s.
  const auto run = [](bool report_sourceless, std::size_t* reported_at_2_6,
                      std::set<std::uint64_t>* ids) {
    FusionOptions o;
    o.report_sourceless = report_sourceless;
    Fuser fuser(o);
    fuser.SetPlacements({Placed("a", 0, 0, 0)});
    for (int k = 0; k <= 50; ++k) {
      const double t = 1.0 + 0.04 * k;
      const double x = 3.0 + 1.0 * (t - 1.0);
      std::vector<TrackObservation> tracks;
      if (t < 2.0) tracks.push_back(Obs(1, x, 1.0, 1.0, 0.0));
      if (t > 2.7) tracks.push_back(Obs(2, x, 1.0, 1.0, 0.0));
      fuser.AddFrame("a", FrameAt(t, std::move(tracks)));
      fuser.Tick(AtSeconds(t));
      const auto fused = fuser.Snapshot(AtSeconds(t));
      if (std::abs(t - 2.6) < 0.02) *reported_at_2_6 = fused.size();
      for (const FusedTrack& f : fused) ids->insert(f.id);
    }
    return fuser.counters();
  };
  std::size_t before = 0, after = 0;
  std::set<std::uint64_t> before_ids, after_ids;
  const FusionCounters before_counters = run(true, &before, &before_ids);
  const FusionCounters counters = run(false, &after, &after_ids);
  EXPECT_EQ(before, 1u);  // coasting with no tracker holding it
  EXPECT_EQ(before_counters.fused_unreported_sourceless, 0u);
  EXPECT_EQ(after, 0u);
  EXPECT_EQ(counters.fused_unreported_sourceless, 1u);
  EXPECT_EQ(after_ids, before_ids);  // the new track picks up the kept id
  EXPECT_EQ(after_ids.size(), 1u);
}

// Two sensors face each other across a walker; their trackers report covariances narrow across
// the line of sight (1 cm) and their centres 0.4 m apart across it (what each sees of the body,
// and the sensors' clocks). The second sensor's track does not fit the first's fused track and
// starts its own; the merge test with the centres' spread joins them, the covariances alone do
// not.
constexpr double kApart = 0.4;
std::pair<std::size_t, FusionCounters> RunNarrowCovariances(double spread_m) {
  FusionOptions o;
  o.merge_centre_spread_m = spread_m;
  o.learn_sensor_bias = false;
  Fuser fuser(o);
  fuser.SetPlacements({Placed("a", 0, 0, 0), Placed("b", 10, 0, 180)});
  auto narrow = [](std::uint32_t id, double x, double y, double vy) {
    TrackObservation obs = Obs(id, x, y, 0.0, vy);
    obs.covariance[0] = 0.05f * 0.05f;  // along the line of sight (sensor x)
    obs.covariance[4] = 0.01f * 0.01f;  // across it
    return obs;
  };
  std::size_t tracks_at_end = 0;
  for (int k = 0; k <= 100; ++k) {
    const double t = 1.0 + 0.04 * k;
    const double y = 0.5 * (t - 1.0);  // walking across both lines of sight at 0.5 m/s
    fuser.AddFrame("a", FrameAt(t, {narrow(1, 5.0, y, 0.5)}));
    // b sees the walker at world (5, y + kApart): in its frame (5, -(y + kApart)).
    fuser.AddFrame("b", FrameAt(t + 0.01, {narrow(4, 5.0, -(y + kApart), -0.5)}));
    fuser.Tick(AtSeconds(t + 0.01));
    if (k == 100) tracks_at_end = fuser.Snapshot(AtSeconds(t + 0.01)).size();
  }
  return {tracks_at_end, fuser.counters()};
}

TEST(FusedFilterTest, NarrowCovariancesOfTwoSensorsOnOneBodyAreMergedWithTheCentreSpread) {
  const auto [before, before_counters] = RunNarrowCovariances(0.0);
  ASSERT_EQ(before_counters.fused_created, 2u);  // b's track did not fit a's fused track
  EXPECT_EQ(before, 2u);
  EXPECT_EQ(before_counters.fused_merged, 0u);
  const auto [after, counters] = RunNarrowCovariances(0.1);
  ASSERT_EQ(counters.fused_created, 2u);
  EXPECT_EQ(counters.fused_merged, 1u);
  EXPECT_GT(counters.merge_checks_spread, 0u);
  EXPECT_EQ(after, 1u);
}

// ---------------------------------------------------------------------------------------------
// Sensor bias (fusion.h, "Sensor bias")

// Four people walking circles of 2 m at 1 m/s in front of three sensors (a, the calibration's
// reference, exact; b and c with the default pose covariance) for duration_s; each sensor's
// centres offset towards it by its bias_m. Returns the fused error (mean vector and RMS) over
// the last 20 s and the learnt biases.
struct BiasRun {
  Eigen::Vector2d mean_error = Eigen::Vector2d::Zero();
  double rms_m = 0.0;
  std::vector<SensorBias> biases;
  const SensorBias* Of(const std::string& id) const {
    for (const SensorBias& b : biases) {
      if (b.sensor_id == id && b.kind == daemon::MeasurementKind::kCenterOfMass) return &b;
    }
    return nullptr;
  }
};

BiasRun RunBiasScene(bool learn, const std::vector<double>& bias_m,
                     const std::function<void(Scene&)>& adjust = nullptr, double duration_s = 60.0,
                     const std::function<void(FusionOptions&)>& configure = nullptr) {
  Scene scene;
  scene.sensors = {Sensor("a", 0, 0, 0), Sensor("b", 10, 0, 180, 0.013),
                   Sensor("c", 5, 9, -90, 0.027)};
  scene.sensors[0].pose_covariance.setZero();
  for (std::size_t s = 0; s < scene.sensors.size(); ++s) {
    scene.sensors[s].bias_m = bias_m[s];
    scene.sensors[s].noise_m = scene.sensors[s].reported_sigma_m = 0.03;
  }
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector2d centre(3.0 + 4.0 * (k % 2), 2.0 + 4.0 * (k / 2));
    const double phase = 1.3 * k, direction = k % 2 == 0 ? 1.0 : -1.0;
    SimPerson person;
    person.position = [=](double t) {
      const double a = phase + direction * t / 2.0;  // 1 m/s on a 2 m radius
      return Eigen::Vector2d(centre + 2.0 * Eigen::Vector2d(std::cos(a), std::sin(a)));
    };
    scene.people.push_back(person);
  }
  if (adjust) adjust(scene);
  FusionOptions o;
  o.learn_sensor_bias = learn;
  if (configure) configure(o);
  Fuser fuser(o);
  fuser.SetPlacements(scene.Placements());
  BiasRun out;
  std::size_t n = 0;
  double sum2 = 0.0;
  scene.Run(fuser, duration_s, 0.1, [&](double t, UtcNs now) {
    if (t < duration_s - 20.0) return;
    const auto fused = fuser.Snapshot(now);
    for (const SimPerson& person : scene.people) {
      const Eigen::Vector2d truth = person.position(t);
      const FusedTrack* f = testing::Nearest(fused, truth, 0.5);
      if (f == nullptr) continue;
      const Eigen::Vector2d e = Eigen::Vector2d(f->x_m, f->y_m) - truth;
      out.mean_error += e;
      sum2 += e.squaredNorm();
      ++n;
    }
  });
  EXPECT_GT(n, 700u);
  out.mean_error /= static_cast<double>(std::max<std::size_t>(n, 1));
  out.rms_m = std::sqrt(sum2 / static_cast<double>(std::max<std::size_t>(n, 1)));
  out.biases = fuser.sensor_biases();
  return out;
}

TEST(SensorBiasTest, ARadialOffsetIsLearntWithinItsSigmaAndTakenOut) {
  // b's centres sit 0.06 m towards it, a's and c's are unbiased.
  const BiasRun learnt = RunBiasScene(true, {0.0, 0.06, 0.0});
  const BiasRun old = RunBiasScene(false, {0.0, 0.06, 0.0});
  const SensorBias* b = learnt.Of("b");
  ASSERT_NE(b, nullptr);
  EXPECT_TRUE(b->applied);
  EXPECT_TRUE(b->offset_applied);
  EXPECT_GE(b->samples, 10u);
  EXPECT_LT(b->sigma_m, 0.03);
  EXPECT_GT(b->radial_m, 2.0 * b->sigma_m);  // told from no offset
  EXPECT_NEAR(b->radial_m, 0.06, 2.0 * b->sigma_m) << "sigma " << b->sigma_m;
  for (const std::string id : {"a", "c"}) {
    const SensorBias* other = learnt.Of(id);
    ASSERT_NE(other, nullptr) << id;
    EXPECT_NEAR(other->radial_m, 0.0, 2.0 * other->sigma_m) << id << " sigma " << other->sigma_m;
  }
  // The reference's placement is not moved (its covariance is zero).
  const SensorBias* a = learnt.Of("a");
  EXPECT_LT(std::abs(a->dx_m) + std::abs(a->dy_m), 1e-6);
  EXPECT_LT(std::abs(a->dyaw_rad), 1e-7);
  // The fused positions: b's pull taken out.
  EXPECT_LT(learnt.mean_error.norm(), 0.01) << learnt.mean_error.transpose();
  EXPECT_GT(old.mean_error.norm(), learnt.mean_error.norm()) << old.mean_error.transpose();
  EXPECT_LT(learnt.rms_m, old.rms_m);
  // Off: nothing is learnt (the earlier release).
  EXPECT_TRUE(old.biases.empty());
}

TEST(SensorBiasTest, AnImpreciseOffsetIsNotTakenOut) {
  // b's centres sit 0.06 m towards it; after 25 s (2 samples suffice here) its offset is learnt
  // with a sigma above a third of the kind's centre sigma (0.12 m): it stays in b's frames for
  // the fused tracks' offset states, while the placement is corrected.
  const auto few = [](FusionOptions& o) { o.sensor_bias_min_samples = 2; };
  const BiasRun run = RunBiasScene(true, {0.0, 0.06, 0.0}, nullptr, 25.0, few);
  const BiasRun always = RunBiasScene(true, {0.0, 0.06, 0.0}, nullptr, 25.0, [&](FusionOptions& o) {
    few(o);
    o.sensor_bias_offset_sigma_fraction = 10.0;
  });
  const SensorBias* b = run.Of("b");
  ASSERT_NE(b, nullptr);
  EXPECT_TRUE(b->applied);
  EXPECT_GT(b->sigma_m, 0.33 * 0.12);
  EXPECT_FALSE(b->offset_applied) << b->radial_m << " sigma " << b->sigma_m;
  ASSERT_NE(always.Of("b"), nullptr);
  EXPECT_TRUE(always.Of("b")->offset_applied);
  std::printf("imprecise offset: fused RMS %.4f m, taken out anyway %.4f m; b %.3f +- %.3f m\n",
              run.rms_m, always.rms_m, b->radial_m, b->sigma_m);
}

TEST(SensorBiasTest, APlacementErrorIsLearntWithinItsSigma) {
  // c is placed 0.06 m east and 0.4 deg off of where it is, with a covariance that says 0.05 m
  // and 0.5 deg; b has a radial offset of 0.04 m besides.
  const double dyaw = DegToRad(0.4);
  const auto adjust = [&](Scene& scene) {
    SimSensor& c = scene.sensors[2];
    c.placed = Pose2{c.truth.x_m + 0.06, c.truth.y_m, c.truth.yaw_rad + dyaw};
    c.pose_covariance =
        Eigen::Vector3d(0.05 * 0.05, 0.05 * 0.05, std::pow(DegToRad(0.5), 2)).asDiagonal();
  };
  const BiasRun learnt = RunBiasScene(true, {0.0, 0.04, 0.0}, adjust);
  const BiasRun old = RunBiasScene(false, {0.0, 0.04, 0.0}, adjust);
  const SensorBias* c = learnt.Of("c");
  ASSERT_NE(c, nullptr);
  EXPECT_TRUE(c->applied);
  EXPECT_NEAR(c->dx_m, 0.06, 2.0 * std::sqrt(c->pose_covariance(0, 0)));
  EXPECT_NEAR(c->dy_m, 0.0, 2.0 * std::sqrt(c->pose_covariance(1, 1)));
  EXPECT_NEAR(c->dyaw_rad, dyaw, 2.0 * std::sqrt(c->pose_covariance(2, 2)));
  EXPECT_LT(std::sqrt(c->pose_covariance(0, 0)), 0.02);
  const SensorBias* b = learnt.Of("b");
  ASSERT_NE(b, nullptr);
  EXPECT_NEAR(b->radial_m, 0.04, 2.0 * b->sigma_m) << "sigma " << b->sigma_m;
  EXPECT_LT(learnt.rms_m, 0.8 * old.rms_m) << learnt.rms_m << " vs " << old.rms_m;
}

TEST(SensorBiasTest, ASensorAloneLearnsNothingAndIsNotMoved) {
  // Only a sees the people: its offset cannot be told from where they are.
  const auto only_a = [](Scene& scene) {
    scene.sensors.resize(1);
    scene.sensors[0].pose_covariance = Eigen::Vector3d(1e-4, 1e-4, 1e-6).asDiagonal();
  };
  const BiasRun learnt = RunBiasScene(true, {0.06, 0.0, 0.0}, only_a, 30.0);
  const BiasRun old = RunBiasScene(false, {0.06, 0.0, 0.0}, only_a, 30.0);
  EXPECT_TRUE(learnt.biases.empty());
  EXPECT_DOUBLE_EQ(learnt.rms_m, old.rms_m);
}

// ---------------------------------------------------------------------------------------------
// Time

TEST_P(FuserTest, StaleAndOutOfOrderFramesAreCountedAndDropped) {
  Fuser fuser(Options());
  fuser.SetPlacements({Placed("a", 0, 0, 0), Placed("b", 0, 0, 0)});
  for (int k = 0; k <= 10; ++k) {
    const double t = 1.0 + 0.04 * k;
    fuser.AddFrame("a", FrameAt(t, {Obs(1, 3 + 0.04 * k, 0, 1, 0)}));
  }
  const auto before = fuser.Snapshot(AtSeconds(1.4));
  ASSERT_EQ(before.size(), 1u);
  // The same scan again, and an older one, far from the truth: dropped.
  fuser.AddFrame("a", FrameAt(1.4, {Obs(1, 9, 9)}));
  fuser.AddFrame("a", FrameAt(1.2, {Obs(1, 9, 9)}));
  EXPECT_EQ(fuser.counters().frames_stale, 2u);
  // b is 0.6 s late: dropped; 0.3 s late: used, fused at the newer time.
  fuser.AddFrame("b", FrameAt(0.8, {Obs(4, 9, 9)}));
  EXPECT_EQ(fuser.counters().frames_out_of_order, 1u);
  fuser.AddFrame("b", FrameAt(1.1, {Obs(4, 3.1, 0, 1, 0)}));
  EXPECT_EQ(fuser.counters().frames_out_of_order, 1u);
  const auto after = fuser.Snapshot(AtSeconds(1.4));
  ASSERT_EQ(after.size(), 1u);
  EXPECT_EQ(after[0].id, before[0].id);
  EXPECT_EQ(after[0].sources.size(), 2u);
  EXPECT_NEAR(after[0].x_m, 3.4, 0.05);
  EXPECT_NEAR(after[0].y_m, 0.0, 0.05);
  TrackFrameData before_1970 = FrameAt(0, {Obs(1, 3, 0)});
  before_1970.scan_start_ns = -5;
  fuser.AddFrame("a", before_1970);
  EXPECT_EQ(fuser.counters().frames_invalid, 1u);
  EXPECT_EQ(fuser.counters().frames_stale, 2u);
}

TEST_P(FuserTest, PartsOfAScanAreAddedOnce) {
  Fuser fuser(Options());
  fuser.SetPlacements({Placed("a", 0, 0, 0)});
  for (int k = 0; k < 4; ++k) {
    TrackFrameData first = FrameAt(1.0 + 0.04 * k, {Obs(1, 3, 0)});
    first.scan_counter = static_cast<std::uint32_t>(k);
    first.part_count = 2;
    TrackFrameData second = first;
    second.part = 1;
    second.tracks = {Obs(2, 3, 4)};
    fuser.AddFrame("a", first);
    fuser.AddFrame("a", second);
    fuser.AddFrame("a", second);  // again: stale
  }
  EXPECT_EQ(fuser.counters().frames_stale, 4u);
  EXPECT_EQ(fuser.counters().observations, 8u);
  const auto fused = fuser.Snapshot(AtSeconds(1.12));
  ASSERT_EQ(fused.size(), 2u);
  EXPECT_NEAR(fused[0].y_m, 0.0, 0.01);
  EXPECT_NEAR(fused[1].y_m, 4.0, 0.01);
  EXPECT_EQ(fused[1].updates, 4u);
}

// ---------------------------------------------------------------------------------------------
// Hostile values

TEST_P(FuserTest, HostileValuesAreSkippedAndCountedNeverNaN) {
  FusionOptions options = Options();
  options.max_tracks_per_frame = 20;
  Fuser fuser(options);
  fuser.SetPlacements({Placed("a", 1, 1, 30)});
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  std::vector<TrackObservation> bad;
  bad.push_back(Obs(2, nan, 0));
  bad.push_back(Obs(3, 0, 0, inf, 0));
  TrackObservation negative = Obs(4, 1, 1);
  negative.covariance[0] = -1.0f;
  bad.push_back(negative);
  TrackObservation huge = Obs(5, 1, 1);
  huge.covariance[4] = 1e30f;
  bad.push_back(huge);
  TrackObservation not_psd = Obs(6, 1, 1);
  not_psd.covariance[1] = 1.0f;  // |xy| > sqrt(xx yy)
  bad.push_back(not_psd);
  TrackObservation nan_cov = Obs(7, 1, 1);
  nan_cov.covariance[9] = nan;
  bad.push_back(nan_cov);
  bad.push_back(Obs(8, 1e9, 0));
  bad.push_back(Obs(9, 1, 1, 1e6, 0));
  for (int k = 0; k < 5; ++k) {
    std::vector<TrackObservation> tracks = bad;
    tracks.push_back(Obs(1, 4 + 0.04 * k, 2, 1, 0));
    tracks.push_back(Obs(1, -4, -2));  // the same id twice in one frame
    fuser.AddFrame("a", FrameAt(1.0 + 0.04 * k, tracks));
  }
  EXPECT_EQ(fuser.counters().observations_invalid, 5u * 9u);
  EXPECT_EQ(fuser.counters().observations, 5u);
  // Far too many tracks in a frame.
  std::vector<TrackObservation> many;
  for (std::uint32_t i = 0; i < 1000; ++i) many.push_back(Obs(100 + i, 0.1 * i, 50));
  fuser.AddFrame("a", FrameAt(1.3, many));
  EXPECT_EQ(fuser.counters().observations_over_capacity, 980u);

  const auto fused = fuser.Snapshot(AtSeconds(1.3), true);
  for (const auto& f : fused) EXPECT_TRUE(AllFinite(f));
  const auto* person =
      testing::Nearest(fused, Pose2{1, 1, DegToRad(30)} * Eigen::Vector2d(4.2, 2), 0.5);
  ASSERT_NE(person, nullptr);
  EXPECT_EQ(person->state, FusedState::kConfirmed);
  for (const auto& w : fuser.WorldTracks(AtSeconds(1.3))) {
    EXPECT_TRUE(std::isfinite(w.x_m) && std::isfinite(w.y_m));
    EXPECT_TRUE(w.covariance.array().isFinite().all());
  }
  // Extreme stamps do not overflow anything.
  fuser.AddFrame("a", FrameAt(2.0, {Obs(1, 4, 2)}));
  TrackFrameData far = FrameAt(0, {Obs(1, 4, 2)});
  far.scan_start_ns = std::numeric_limits<UtcNs>::max();
  fuser.AddFrame("a", far);
  fuser.Tick(std::numeric_limits<UtcNs>::min());
  fuser.Tick(std::numeric_limits<UtcNs>::max());
  for (const auto& f : fuser.Snapshot(std::numeric_limits<UtcNs>::max(), true)) {
    EXPECT_TRUE(AllFinite(f));
  }
}

// Random, mostly hostile input: never a crash, never a non-finite output, bounded state.
TEST_P(FuserTest, RandomInputNeverBreaksIt) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const float specials[] = {std::numeric_limits<float>::quiet_NaN(),
                            std::numeric_limits<float>::infinity(),
                            -1e30f,
                            1e30f,
                            -0.0f,
                            std::numeric_limits<float>::denorm_min()};
  FusionOptions options = Options();
  options.max_fused_tracks = 200;
  Fuser fuser(options);
  const std::vector<std::string> ids = {"a", "b", "c", "d"};
  auto random_placements = [&] {
    std::vector<SensorPlacement> p;
    for (const auto& id : ids) {
      SensorPlacement s = Placed(id, 10 * u(rng), 10 * u(rng), 180 * u(rng));
      if (rng() % 8 == 0) s.covariance(rng() % 3, rng() % 3) = specials[rng() % 6];
      p.push_back(s);
    }
    return p;
  };
  fuser.SetPlacements(random_placements());
  double t = 1.0;
  for (int k = 0; k < 3000; ++k) {
    t += rng() % 50 == 0 ? -0.3 : 0.01 * static_cast<double>(rng() % 5);
    std::vector<TrackObservation> tracks;
    const std::size_t n = rng() % 12;
    for (std::size_t i = 0; i < n; ++i) {
      TrackObservation o = Obs(static_cast<std::uint32_t>(rng() % 8), 5 + 5 * u(rng), 5 * u(rng),
                               u(rng), u(rng), 0.01 + 0.2 * std::abs(u(rng)));
      o.state = static_cast<TrackState>(rng() % 3);
      if (rng() % 10 == 0) o.x_m = specials[rng() % 6];
      if (rng() % 10 == 0) o.covariance[rng() % 10] = specials[rng() % 6];
      if (rng() % 10 == 0) o.covariance[rng() % 10] = static_cast<float>(u(rng));
      if (rng() % 10 == 0) {
        // Valid but extreme: tiny or huge, x and y almost perfectly correlated.
        const float v = rng() % 2 == 0 ? 1e-12f : 20.0f;
        o.covariance = {v, 0.999f * v, 0.0f, 0.0f, v, 0.0f, 0.0f, v, 0.0f, v};
      }
      tracks.push_back(o);
    }
    TrackFrameData frame = FrameAt(t, tracks, rng() % 200 == 0 ? rng() : 1);
    frame.part = rng() % 4 == 0 ? static_cast<std::uint32_t>(rng() % 3) : 0u;
    fuser.AddFrame(ids[rng() % ids.size()], frame);
    if (rng() % 500 == 0) fuser.SetPlacements(random_placements());
    if (rng() % 300 == 0) {
      fuser.SetTrackerModel(ids[rng() % ids.size()],
                            rng() % 2 == 0 ? specials[rng() % 6] : 100.0 * std::abs(u(rng)));
    }
    if (k % 10 == 0) {
      fuser.Tick(AtSeconds(t));
      const auto fused = fuser.Snapshot(AtSeconds(t), true);
      EXPECT_LE(fused.size(), options.max_fused_tracks);
      for (const auto& f : fused) {
        ASSERT_TRUE(AllFinite(f)) << "frame " << k;
        const Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> eig(f.covariance);
        EXPECT_GE(eig.eigenvalues().minCoeff(), -1e-9 * std::max(1.0, f.covariance.norm()))
            << "frame " << k;
        std::set<std::string> sensors;
        for (const auto& s : f.sources) EXPECT_TRUE(sensors.insert(s.sensor_id).second);
      }
      for (const auto& w : fuser.WorldTracks(AtSeconds(t))) {
        ASSERT_TRUE(std::isfinite(w.x_m) && std::isfinite(w.y_m) && std::isfinite(w.vx_mps));
      }
      EXPECT_FALSE(FusedTrackDatagrams(fused, AtSeconds(t)).empty());
    }
  }
  EXPECT_GT(fuser.counters().observations_invalid, 0u);
  EXPECT_GT(fuser.counters().fused_created, 0u);
}

TEST_P(FuserTest, FusedTrackCapacityIsBounded) {
  FusionOptions options = Options();
  options.max_fused_tracks = 10;
  Fuser fuser(options);
  fuser.SetPlacements({Placed("a", 0, 0, 0)});
  std::vector<TrackObservation> many;
  for (std::uint32_t i = 0; i < 30; ++i) many.push_back(Obs(i + 1, 2.0 * i, 3));
  fuser.AddFrame("a", FrameAt(1.0, many));
  EXPECT_EQ(fuser.Snapshot(AtSeconds(1.0), true).size(), 10u);
  EXPECT_EQ(fuser.counters().fused_over_capacity, 20u);
}

TEST_P(FuserTest, IsMovable) {
  Fuser a(Options());
  a.SetPlacements({Placed("a", 0, 0, 0)});
  for (int k = 0; k < 3; ++k) a.AddFrame("a", FrameAt(1.0 + 0.04 * k, {Obs(1, 3, 0)}));
  Fuser b(std::move(a));
  EXPECT_EQ(b.Snapshot(AtSeconds(1.1)).size(), 1u);
  Fuser c(Options());
  c = std::move(b);
  c.AddFrame("a", FrameAt(1.2, {Obs(1, 3, 0)}));
  EXPECT_EQ(c.Snapshot(AtSeconds(1.2)).size(), 1u);
  EXPECT_TRUE(c.HasPlacement("a"));
}

}  // namespace
}  // namespace lrfnet::fusion
