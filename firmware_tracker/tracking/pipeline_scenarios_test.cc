// The whole per-scan pipeline on synthetic scenes (SyntheticScanner: an LMS1xx-like scanner at
// 25 Hz, 0.5 deg, 270 deg, 20 m, 1 cm range noise; people as 0.25 m x 0.15 m ellipses moving
// during the scan), with asserted outcomes a user of the tracks would notice: one id per person,
// positions and velocities close to the truth, no tracks from noise or from a door opening away
// from the sensor.

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <random>
#include <set>
#include <span>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "common/eigen_instances.h"
#include "common/mount_check.h"
#include "firmware_tracker/tracking/pipeline.h"
#include "firmware_tracker/tracking/tracking_test_util.h"

namespace lrfnet::tracking {
namespace {

using testing::Body;
using testing::Room;
using testing::ScannerConfig;
using testing::SyntheticScanner;
using testing::Wall;

using testing::kRateHz;
constexpr double kLearnedS = 6.0;  // background learning (5 s) is over; people enter after this

// Scan k of a sensor that turns once per period_ms, the given ranges from first_angle_rad on.
ScanView RangesScan(std::span<const float> ranges, double first_angle_rad, double step_rad,
                    std::int64_t k, std::int64_t period_ms) {
  ScanView scan;
  scan.first_angle_rad = first_angle_rad;
  scan.angle_step_rad = step_rad;
  scan.range_m = ranges;
  scan.stamp_ns = 1'600'000'000 * common::kNsPerS + k * period_ms * common::kNsPerMs;
  scan.scan_period_s = 1e-3 * static_cast<double>(period_ms);
  return scan;
}

// A knee-height sensor at 25 Hz, 361 beams of 0.5 deg from -90 deg, every beam at background_m
// until the background is learnt (kLearnedS), then walk_scans more scans: draw(i, ranges) writes
// scan i of the walk over ranges reset to background_m (i < 0 while learning: draw is not
// called), seen(i, tracks) sees every scan's tracks. The pipeline's counters at the end.
template <typename Draw, typename Seen>
PipelineCounters RunKneeWalk(const TrackerOptions& options, float background_m,
                             std::int64_t walk_scans, Draw draw, Seen seen) {
  constexpr std::size_t kBeams = 361;
  constexpr double kStepRad = 0.5 * common::kPi / 180.0;
  TrackingPipeline pipeline(options);
  std::vector<float> ranges(kBeams);
  const auto k0 = static_cast<std::int64_t>(kLearnedS * 25.0);
  for (std::int64_t k = 0; k < k0 + walk_scans; ++k) {
    std::fill(ranges.begin(), ranges.end(), background_m);
    const std::int64_t i = k - k0;
    if (i >= 0) draw(i, ranges);
    const ScanView scan = RangesScan(ranges, -0.5 * common::kPi, kStepRad, k, 40);
    seen(i, pipeline.Process(scan, static_cast<std::uint32_t>(k)));
  }
  return pipeline.counters();
}

// In RunKneeWalk's scans: a leg (radius 0.06 m) at range_m whose centre lies on fractional beam c,
// drawn where it is nearer than what the beam returns already.
void DrawKneeLeg(std::vector<float>& ranges, double c, double range_m) {
  constexpr double kStepRad = 0.5 * common::kPi / 180.0;
  for (auto b = static_cast<std::size_t>(c - 3.0); b <= static_cast<std::size_t>(c + 3.0); ++b) {
    const double d = (static_cast<double>(b) - c) * kStepRad * range_m;
    if (std::abs(d) < 0.06) {
      ranges[b] = std::min(ranges[b], static_cast<float>(range_m - std::sqrt(0.06 * 0.06 - d * d)));
    }
  }
}

// In RunKneeWalk's scans: the beam of an object's centre that comes in from the side, 10 beams
// (0.44 m at 5 m) over move_scans, then still.
double SlideInBeam(std::int64_t i, std::int64_t move_scans) {
  return 170.0 +
         (10.0 / static_cast<double>(move_scans)) * static_cast<double>(std::min(i, move_scans));
}

// A person moving through keyframes (time s, position m) with linear interpolation; absent before
// the first and after the last keyframe. Shoulders (major axis) across the walking direction.
class Walker {
 public:
  struct Key {
    double t_s;
    Eigen::Vector2d p_m;
  };
  explicit Walker(std::vector<Key> keys) : keys_(std::move(keys)) {}

  // Walks waypoints at speed_mps starting at start_s.
  static Walker Path(double start_s, const std::vector<Eigen::Vector2d>& waypoints,
                     double speed_mps) {
    std::vector<Key> keys = {{start_s, waypoints.front()}};
    for (std::size_t i = 1; i < waypoints.size(); ++i) {
      const double leg_s = (waypoints[i] - waypoints[i - 1]).norm() / speed_mps;
      keys.push_back({keys.back().t_s + leg_s, waypoints[i]});
    }
    return Walker(keys);
  }

  std::optional<Eigen::Vector2d> At(double t_s) const {
    if (t_s < keys_.front().t_s || t_s > keys_.back().t_s) return std::nullopt;
    for (std::size_t i = 1; i < keys_.size(); ++i) {
      if (t_s <= keys_[i].t_s) {
        const double span = keys_[i].t_s - keys_[i - 1].t_s;
        const double u = span > 0.0 ? (t_s - keys_[i - 1].t_s) / span : 1.0;
        return keys_[i - 1].p_m + u * (keys_[i].p_m - keys_[i - 1].p_m);
      }
    }
    return keys_.back().p_m;
  }

  Eigen::Vector2d VelocityAt(double t_s) const {
    for (std::size_t i = 1; i < keys_.size(); ++i) {
      if (t_s <= keys_[i].t_s) {
        const double span = keys_[i].t_s - keys_[i - 1].t_s;
        return span > 0.0 ? Eigen::Vector2d((keys_[i].p_m - keys_[i - 1].p_m) / span)
                          : Eigen::Vector2d::Zero();
      }
    }
    return Eigen::Vector2d::Zero();
  }

  // Body yaw: across the direction of the last leg that moved.
  double YawAt(double t_s) const {
    double yaw = 0.0;
    for (std::size_t i = 1; i < keys_.size(); ++i) {
      const Eigen::Vector2d d = keys_[i].p_m - keys_[i - 1].p_m;
      if (d.norm() > 1e-9) yaw = std::atan2(d.y(), d.x()) + common::kPi / 2;
      if (t_s <= keys_[i].t_s) break;
    }
    return yaw;
  }

  double start_s() const { return keys_.front().t_s; }
  double end_s() const { return keys_.back().t_s; }

 private:
  std::vector<Key> keys_;
};

struct Frame {
  double t_s = 0.0;
  std::vector<TrackReport> tracks;
  std::vector<std::optional<Eigen::Vector2d>> truth;  // per walker, at the scan start
  std::size_t segments = 0;
};

// The legs of a walker at knee height, as the simulator moves them (tools/sim/targets.h): stride
// L(v) = 1.4 m (v / 1.3 m/s)^0.6, each foot on the ground for 60 % of a cycle while the body passes
// over it, the knee 45 % of the way from the hip to the foot; standing, side by side.
class Legs {
 public:
  static constexpr double kRadiusM = 0.06;
  static constexpr double kHipM = 0.09;

  explicit Legs(const Walker& walker) : walker_(walker) {
    // Gait phase (cycles walked) every kStepS.
    double phase = 0.0;
    for (double t = walker.start_s(); t <= walker.end_s() + kStepS; t += kStepS) {
      phases_.push_back(phase);
      const double speed = walker.VelocityAt(t).norm();
      if (Stride(speed) > 0.0) phase += speed * kStepS / Stride(speed);
    }
  }
  static double Stride(double speed) {
    return speed > 0.0 ? std::min(2.0, 1.4 * std::pow(speed / 1.3, 0.6)) : 0.0;
  }
  static double Foot(double phase) {
    const double u = phase - std::floor(phase);
    if (u < 0.6) return 0.3 - u;
    return -0.3 + 0.3 * (1.0 - std::cos(common::kPi * (u - 0.6) / 0.4));
  }
  double Phase(double t_s) const {
    const auto i = static_cast<std::size_t>(std::max(0.0, (t_s - walker_.start_s()) / kStepS));
    return phases_[std::min(i, phases_.size() - 1)];
  }
  // Appends the two legs at t_s (nothing when the walker is absent).
  void Add(double t_s, std::vector<Body>& out) const {
    const auto p = walker_.At(t_s);
    if (!p) return;
    const double heading = walker_.YawAt(t_s) - common::kPi / 2;
    const Eigen::Vector2d forward(std::cos(heading), std::sin(heading));
    const Eigen::Vector2d left(-forward.y(), forward.x());
    const double stride = Stride(walker_.VelocityAt(t_s).norm());
    for (int leg = 0; leg < 2; ++leg) {
      const double foot = Foot(Phase(t_s) + 0.5 * leg) * stride;
      out.push_back(testing::Cylinder(
          *p + (leg == 0 ? kHipM : -kHipM) * left + 0.45 * foot * forward, kRadiusM));
    }
  }

 private:
  static constexpr double kStepS = 0.005;
  const Walker& walker_;
  std::vector<double> phases_;
};

struct Scene {
  std::vector<Wall> walls = Room();
  std::vector<Body> statics;  // pillars etc., present from the start
  std::vector<Walker> walkers;
  // Per walker: the upper body's semi-axes (default 0.25 x 0.15).
  std::vector<Eigen::Vector2d> sizes;
  // The scanner at knee height: walkers show two legs (Legs).
  bool legs = false;
  // Walls that change with time (a door), added to `walls`.
  std::function<std::vector<Wall>(double)> moving_walls;
};

struct SceneRun {
  std::vector<Frame> frames;
  std::unique_ptr<TrackingPipeline> pipeline;
};

// The tracker configured for the synthetic scanner: pencil beams (the silhouette ends half a step
// beyond the last beam that hits), and bodies that are ellipses.
TrackerOptions Synthetic() {
  TrackerOptions o;
  o.shape.beam_divergence_rad = 0.0;
  o.shape.person_exponent = 2.0;
  return o;
}

SceneRun Simulate(const Scene& scene, double duration_s,
                  const TrackerOptions& options = Synthetic(),
                  const ScannerConfig& scanner_config = {}) {
  SceneRun run;
  run.pipeline = std::make_unique<TrackingPipeline>(options);
  SyntheticScanner scanner(scanner_config);
  std::vector<Body> bodies;
  std::vector<Legs> legs;
  for (const Walker& w : scene.walkers) legs.emplace_back(w);
  auto bodies_at = [&](double t_s) -> const std::vector<Body>& {
    bodies = scene.statics;
    for (std::size_t i = 0; i < scene.walkers.size(); ++i) {
      const Walker& w = scene.walkers[i];
      if (scene.legs) {
        legs[i].Add(t_s, bodies);
        continue;
      }
      const Eigen::Vector2d size =
          i < scene.sizes.size() ? scene.sizes[i] : Eigen::Vector2d(0.25, 0.15);
      if (const auto p = w.At(t_s)) bodies.push_back({*p, size.x(), size.y(), w.YawAt(t_s)});
    }
    return bodies;
  };
  const auto scans = static_cast<std::int64_t>(std::lround(duration_s * kRateHz));
  for (std::int64_t k = 0; k < scans; ++k) {
    const double t_s = scanner.ScanTimeS(k);
    std::vector<Wall> walls = scene.walls;
    if (scene.moving_walls) {
      for (const Wall& w : scene.moving_walls(t_s)) walls.push_back(w);
    }
    const ScanView scan = scanner.RenderTimed(k, walls, bodies_at);
    const ScanTracks& out = run.pipeline->Process(scan, static_cast<std::uint32_t>(k));
    EXPECT_EQ(out.scan_start_ns, scan.stamp_ns);
    EXPECT_EQ(out.scan_counter, static_cast<std::uint32_t>(k));
    Frame f;
    f.t_s = t_s;
    f.tracks.assign(out.tracks.begin(), out.tracks.end());
    for (const Walker& w : scene.walkers) f.truth.push_back(w.At(t_s));
    f.segments = run.pipeline->last_segment_count();
    run.frames.push_back(std::move(f));
  }
  return run;
}

Eigen::Vector2d Position(const TrackReport& r) { return {r.x_m, r.y_m}; }

// The mean error and NEES of the confirmed tracks within max_error_m of walker 0's truth, from
// from_s on, summed over runs by Add and divided by Mean.
struct ConfirmedError {
  double error_m = 0.0, nees = 0.0;
  int n = 0;
  void Add(const SceneRun& run, double from_s, double max_error_m) {
    for (const Frame& f : run.frames) {
      if (!f.truth[0] || f.t_s < from_s) continue;
      for (const TrackReport& r : f.tracks) {
        const Eigen::Vector2d e = Position(r) - *f.truth[0];
        if (r.state != TrackState::kConfirmed || e.norm() > max_error_m) continue;
        error_m += e.norm();
        nees += e.dot(r.covariance.topLeftCorner<2, 2>().ldlt().solve(e));
        ++n;
      }
    }
  }
  void Mean() {
    if (n == 0) return;
    error_m /= n;
    nees /= n;
  }
};

// Id of the reported track nearest to walker w's truth within radius_m, 0 if none.
std::uint32_t MatchedId(const Frame& f, std::size_t w, double radius_m) {
  if (!f.truth[w]) return 0;
  std::uint32_t best_id = 0;
  double best = radius_m;
  for (const TrackReport& r : f.tracks) {
    const double d = (Position(r) - *f.truth[w]).norm();
    if (d < best) {
      best = d;
      best_id = r.track_id;
    }
  }
  return best_id;
}

const TrackReport* Find(const Frame& f, std::uint32_t id) {
  for (const TrackReport& r : f.tracks) {
    if (r.track_id == id) return &r;
  }
  return nullptr;
}

// Two runs of one scene whose options change only what is reported: every confirmed report of
// `run` has its track's report in `old` in the same frame at the same position, and
// compare(frame index, report, old report) checks the rest.
template <typename Compare>
void ForEachReportPair(const SceneRun& run, const SceneRun& old, Compare compare) {
  ASSERT_EQ(run.frames.size(), old.frames.size());
  for (std::size_t k = 0; k < run.frames.size(); ++k) {
    for (const TrackReport& r : run.frames[k].tracks) {
      if (r.state != TrackState::kConfirmed) continue;
      const TrackReport* o = Find(old.frames[k], r.track_id);
      ASSERT_NE(o, nullptr);
      EXPECT_NEAR(r.x_m, o->x_m, 1e-9);
      EXPECT_NEAR(r.y_m, o->y_m, 1e-9);
      compare(k, r, *o);
    }
  }
}

// Reports that a report-only option widened (ForEachReportPair's pairs against the truth): the
// added covariance must be positive semi-definite (a box's one face adds a rank-one term where the
// fit lies on the face's normal); their NEES summed with the new and the old one.
struct WidenedReports {
  int wider = 0, same = 0;
  double nees = 0.0, nees_before = 0.0;
  void Add(const TrackReport& r, const TrackReport& o, const Eigen::Vector2d& truth) {
    const Eigen::Matrix2d c = r.covariance.topLeftCorner<2, 2>();
    const Eigen::Matrix2d c_old = o.covariance.topLeftCorner<2, 2>();
    if ((c - c_old).norm() < 1e-12) {
      ++same;
      return;
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> added(Eigen::Matrix2d(c - c_old));
    EXPECT_GE(added.eigenvalues().minCoeff(), -1e-12);
    ++wider;
    const Eigen::Vector2d e = Eigen::Vector2d(r.x_m, r.y_m) - truth;
    nees += e.dot(c.inverse() * e);
    nees_before += e.dot(c_old.inverse() * e);
  }
};

// MultiTrackerOptions::report_gain_covariance off: the filter's own covariance, so that one report
// term's option compares alone (the terms below also decide where the measured noise is taken).
TrackerOptions GainCovarianceOff(TrackerOptions o) {
  o.tracking.report_gain_covariance = false;
  return o;
}

std::set<std::uint32_t> AllReportedIds(const SceneRun& run) {
  std::set<std::uint32_t> ids;
  for (const Frame& f : run.frames) {
    for (const TrackReport& r : f.tracks) ids.insert(r.track_id);
  }
  return ids;
}

// Follows walker w over [from_s, to_s]: the ids matched in each frame (0 = unmatched).
struct Follow {
  std::map<std::uint32_t, int> frames_per_id;
  int frames = 0;
  int unmatched = 0;
  double mean_error_m = 0.0;
  double max_error_m = 0.0;
  double mean_velocity_error_mps = 0.0;
};

// A run before and after a change, as the test's properties "before" and "after"; returns the two
// for a failure's trace.
std::string RecordBeforeAfter(const std::string& before, const std::string& after) {
  ::testing::Test::RecordProperty("before", before);
  ::testing::Test::RecordProperty("after", after);
  return "before: " + before + "; after: " + after;
}

std::string Describe(const Follow& f) {
  std::string s = "frames " + std::to_string(f.frames) + ", unmatched " +
                  std::to_string(f.unmatched) + ", ids:";
  for (const auto& [id, n] : f.frames_per_id)
    s += " " + std::to_string(id) + "x" + std::to_string(n);
  s += ", mean error " + std::to_string(f.mean_error_m) + " m, max " +
       std::to_string(f.max_error_m) + " m, mean velocity error " +
       std::to_string(f.mean_velocity_error_mps) + " m/s";
  return s;
}

Follow FollowWalker(const SceneRun& run, const Walker& walker, std::size_t w, double from_s,
                    double to_s, double radius_m = 0.5) {
  Follow result;
  double error_sum = 0.0, velocity_error_sum = 0.0;
  int matched = 0;
  for (const Frame& f : run.frames) {
    if (f.t_s < from_s || f.t_s > to_s || !f.truth[w]) continue;
    ++result.frames;
    const std::uint32_t id = MatchedId(f, w, radius_m);
    if (id == 0) {
      ++result.unmatched;
      continue;
    }
    ++result.frames_per_id[id];
    const TrackReport& r = *Find(f, id);
    const double e = (Position(r) - *f.truth[w]).norm();
    error_sum += e;
    result.max_error_m = std::max(result.max_error_m, e);
    velocity_error_sum += (Eigen::Vector2d(r.vx_mps, r.vy_mps) - walker.VelocityAt(f.t_s)).norm();
    ++matched;
  }
  if (matched > 0) {
    result.mean_error_m = error_sum / matched;
    result.mean_velocity_error_mps = velocity_error_sum / matched;
  }
  return result;
}

TrackerOptions WithKind(MeasurementKind kind) {
  TrackerOptions o = Synthetic();
  o.method = kind == MeasurementKind::kEllipse        ? MeasurementMethod::kEllipse
             : kind == MeasurementKind::kCenterOfMass ? MeasurementMethod::kCenterOfMass
                                                      : MeasurementMethod::kShapeFit;
  return o;
}

TEST(TrackerOptionsTest, DefaultsValidAndErrorsNameTheSectionAndField) {
  EXPECT_EQ(Validate(Synthetic()), std::nullopt);
  TrackerOptions o;
  o.tracking.confirm_hits = 0;
  ASSERT_NE(Validate(o), std::nullopt);
  EXPECT_EQ(Validate(o)->rfind("tracking.confirm_hits", 0), 0u) << *Validate(o);
  o = {};
  o.tracking.ekf.accel_psd_m2ps3 = 0.0;
  EXPECT_EQ(Validate(o)->rfind("tracking.ekf.accel_psd_m2ps3", 0), 0u) << *Validate(o);
  o = {};
  o.background.absorb_after_s = -1.0;
  EXPECT_EQ(Validate(o)->rfind("background.absorb_after_s", 0), 0u) << *Validate(o);
  o = {};
  o.segmentation.max_points = 0;
  EXPECT_EQ(Validate(o)->rfind("segmentation.max_points", 0), 0u) << *Validate(o);
  o = {};
  o.measurement.com_sigma_m = 0.0;
  EXPECT_EQ(Validate(o)->rfind("measurement.com_sigma_m", 0), 0u) << *Validate(o);
  o = {};
  o.shape.seen_through_margin_m = -0.1;
  EXPECT_EQ(Validate(o)->rfind("shape.seen_through_margin_m", 0), 0u) << *Validate(o);
  o = {};
  o.tracking.moving_speed_mps = -1.0;
  EXPECT_EQ(Validate(o)->rfind("tracking.moving_speed_mps", 0), 0u) << *Validate(o);
  o = {};
  o.shape.unseen_coasting_m = -0.1;
  EXPECT_EQ(Validate(o)->rfind("shape.unseen_coasting_m", 0), 0u) << *Validate(o);
  o = {};
  o.shape.coasting_max_sigma_m = -0.1;
  EXPECT_EQ(Validate(o)->rfind("shape.coasting_max_sigma_m", 0), 0u) << *Validate(o);
  o = {};
  o.shape.legs_coasting_max_sigma_m = -0.1;
  EXPECT_EQ(Validate(o)->rfind("shape.legs_coasting_max_sigma_m", 0), 0u) << *Validate(o);
  o = {};
  o.shape.legs_report_coasting_s = -0.1;
  EXPECT_EQ(Validate(o)->rfind("shape.legs_report_coasting_s", 0), 0u) << *Validate(o);
  o = {};
  o.shape.walking_legs_sigma_m = o.shape.gait_sigma_m + 0.01;
  EXPECT_EQ(Validate(o)->rfind("shape.walking_legs_sigma_m", 0), 0u) << *Validate(o);
  o = {};
  o.shape.torso_edge_echo_min_far_share = 1.0;
  EXPECT_EQ(Validate(o)->rfind("shape.torso_edge_echo_min_far_share", 0), 0u) << *Validate(o);
  o.shape.torso_edge_echo_min_far_share = 0.2;
  o.shape.deep_mixed_pixel_behind_ratio = -1.0;
  EXPECT_EQ(Validate(o)->rfind("shape.deep_mixed_pixel_behind_ratio", 0), 0u) << *Validate(o);
  o.shape.deep_mixed_pixel_behind_ratio = std::nan("");
  EXPECT_EQ(Validate(o)->rfind("shape.deep_mixed_pixel_behind_ratio", 0), 0u) << *Validate(o);
  o = {};
  o.shape.still_legs_max_depth_m = -0.1;
  EXPECT_EQ(Validate(o)->rfind("shape.still_legs_max_depth_m", 0), 0u) << *Validate(o);
  o = {};
  o.shape.mixed_leg_max_gap_m = std::nan("");
  EXPECT_EQ(Validate(o)->rfind("shape.mixed_leg_max_gap_m", 0), 0u) << *Validate(o);
  o = {};
  o.shape.step_seam.min_step_m = 0.0;
  EXPECT_EQ(Validate(o)->rfind("shape.step_seam.min_step_m", 0), 0u) << *Validate(o);
  o = {};
  o.shape.step_seam_person_max_a_m = 0.0;
  EXPECT_EQ(Validate(o)->rfind("shape.step_seam_person_max_a_m", 0), 0u) << *Validate(o);
  o = {};
  o.shape.step_seam_person_max_b_m = -1.0;
  EXPECT_EQ(Validate(o)->rfind("shape.step_seam_person_max_b_m", 0), 0u) << *Validate(o);
  o = {};
  o.shape.step_seam_size_margin_m = -0.1;
  EXPECT_EQ(Validate(o)->rfind("shape.step_seam_size_margin_m", 0), 0u) << *Validate(o);
  o = {};
  o.shape.deep_tail_depth_m = 0.0;
  EXPECT_EQ(Validate(o)->rfind("shape.deep_tail_depth_m", 0), 0u) << *Validate(o);
  o = {};
  o.shape.deep_tail_centre_bias_sigma_m = -0.01;
  EXPECT_EQ(Validate(o)->rfind("shape.deep_tail_centre_bias_sigma_m", 0), 0u) << *Validate(o);
  o = {};
  o.shape.recent_veil_s = -0.1;
  EXPECT_EQ(Validate(o)->rfind("shape.recent_veil_s", 0), 0u) << *Validate(o);
  o.shape.recent_veil_s = std::nan("");
  EXPECT_EQ(Validate(o)->rfind("shape.recent_veil_s", 0), 0u) << *Validate(o);
  o = {};
  o.shape.box_size_floor_sigma_m = -0.01;
  EXPECT_EQ(Validate(o)->rfind("shape.box_size_floor_sigma_m", 0), 0u) << *Validate(o);
  o = {};
  o.shape.centre_bias_across_sigma_m = std::nan("");
  EXPECT_EQ(Validate(o)->rfind("shape.centre_bias_across_sigma_m", 0), 0u) << *Validate(o);
  o = {};
  o.shape.outline_departure_gain = -0.5;
  EXPECT_EQ(Validate(o)->rfind("shape.outline_departure_gain", 0), 0u) << *Validate(o);
  o.shape.outline_departure_gain = std::nan("");
  EXPECT_EQ(Validate(o)->rfind("shape.outline_departure_gain", 0), 0u) << *Validate(o);
  o = {};
  o.shape.outline_fixed_share = 0.0;
  EXPECT_EQ(Validate(o)->rfind("shape.outline_fixed_share", 0), 0u) << *Validate(o);
  o.shape.outline_fixed_share = 1.5;
  EXPECT_EQ(Validate(o)->rfind("shape.outline_fixed_share", 0), 0u) << *Validate(o);
  o = {};
  o.shape.outline_model_share = 0.0;
  EXPECT_EQ(Validate(o)->rfind("shape.outline_model_share", 0), 0u) << *Validate(o);
  o.shape.outline_model_share = std::nan("");
  EXPECT_EQ(Validate(o)->rfind("shape.outline_model_share", 0), 0u) << *Validate(o);
  o = {};
  o.shape.outline_departure_gain = 0.0;  // off: the shares are not used, but still checked
  EXPECT_EQ(Validate(o), std::nullopt);
}

// ShapeOptions::outline_departure_gain: residuals at or below the range noise (0.015 + 0.001 R)
// add nothing; beyond it, gain^2 (rms^2 - noise^2).
TEST(PipelineScenarioTest, OutlineDepartureIsTheResidualBeyondTheRangeNoise) {
  ShapeOptions o;
  o.outline_departure_gain = 1.5;
  o.fit.point_sigma_m = 0.015;
  o.fit.point_sigma_per_m = 0.001;
  // At 5 m the noise is 0.02 m: an RMS of 0.05 m departs by sqrt(0.0025 - 0.0004).
  EXPECT_NEAR(internal::OutlineDepartureVar(o, 0.05, 5.0), 2.25 * (0.0025 - 0.0004), 1e-12);
  EXPECT_EQ(internal::OutlineDepartureVar(o, 0.02, 5.0), 0.0);
  EXPECT_EQ(internal::OutlineDepartureVar(o, 0.01, 5.0), 0.0);
  // At 15 m the noise is 0.03 m: the same RMS departs less.
  EXPECT_NEAR(internal::OutlineDepartureVar(o, 0.05, 15.0), 2.25 * (0.0025 - 0.0009), 1e-12);
  o.outline_departure_gain = 0.0;
  EXPECT_EQ(internal::OutlineDepartureVar(o, 0.05, 5.0), 0.0);
}

class CrossingTest : public ::testing::TestWithParam<MeasurementKind> {};

TEST_P(CrossingTest, OnePersonCrossingTheRoomIsOneTrackCloseToTheTruth) {
  const MeasurementKind kind = GetParam();
  Scene scene;
  const double speed = 1.2;
  scene.walkers = {Walker::Path(kLearnedS, {{1.5, -4.0}, {6.0, 4.0}}, speed)};
  const Walker& walker = scene.walkers[0];
  const SceneRun run = Simulate(scene, walker.end_s() + 2.0, WithKind(kind));

  // One confirmed track, ever; a user sees one person.
  const std::set<std::uint32_t> ids = AllReportedIds(run);
  ASSERT_EQ(ids.size(), 1u);
  // Confirmed within half a second of entering, and the same id until the person leaves.
  const Follow f = FollowWalker(run, walker, 0, walker.start_s() + 0.5, walker.end_s());
  SCOPED_TRACE(Describe(f));
  EXPECT_EQ(f.unmatched, 0);
  ASSERT_EQ(f.frames_per_id.size(), 1u);
  // Steady state (after the velocity converged).
  const Follow steady = FollowWalker(run, walker, 0, walker.start_s() + 1.5, walker.end_s());
  SCOPED_TRACE(Describe(steady));
  if (kind == MeasurementKind::kEllipse) {
    EXPECT_LT(steady.mean_error_m, 0.02);
    EXPECT_LT(steady.max_error_m, 0.06);
  } else {
    // The CoM of the visible side lies in front of the body's centre (by about b = 0.15 m): the
    // bias the paper's ellipse step removes.
    EXPECT_GT(steady.mean_error_m, 0.08);
    EXPECT_LT(steady.mean_error_m, 0.2);
    EXPECT_LT(steady.max_error_m, 0.3);
  }
  EXPECT_LT(steady.mean_velocity_error_mps, 0.15);

  // Every report carries the configured measurement kind; gone shortly after the person left.
  std::size_t with_kind = 0, reports = 0;
  for (const Frame& fr : run.frames) {
    for (const TrackReport& r : fr.tracks) {
      ++reports;
      with_kind += r.kind == kind ? 1 : 0;
      if (r.kind == MeasurementKind::kEllipse) {
        EXPECT_NE(r.ellipse_yaw_rad, 0.0);
      }
    }
    if (fr.t_s > walker.end_s() + 1.2) {
      EXPECT_TRUE(fr.tracks.empty()) << "t " << fr.t_s;
    }
  }
  EXPECT_GT(static_cast<double>(with_kind), 0.9 * static_cast<double>(reports));
}

INSTANTIATE_TEST_SUITE_P(Kinds, CrossingTest,
                         ::testing::Values(MeasurementKind::kCenterOfMass,
                                           MeasurementKind::kEllipse),
                         [](const auto& param_info) {
                           return std::string(param_info.param == MeasurementKind::kEllipse
                                                  ? "Ellipse"
                                                  : "CenterOfMass");
                         });

TEST(PipelineScenarioTest, BeamTimeCorrectionRemovesTheIntraScanLag) {
  // Walking fast across the left of the field of view, where beams are measured ~25 ms after the
  // scan start.
  Scene scene;
  scene.walkers = {Walker::Path(kLearnedS, {{-1.0, 3.5}, {3.5, 3.5}}, 1.8)};
  const Walker& walker = scene.walkers[0];
  double mean_error[2] = {0.0, 0.0};
  for (const bool correct : {false, true}) {
    TrackerOptions options = Synthetic();
    options.correct_beam_time = correct;
    const SceneRun run = Simulate(scene, walker.end_s() + 0.5, options);
    const Follow f = FollowWalker(run, walker, 0, walker.start_s() + 1.0, walker.end_s());
    SCOPED_TRACE(Describe(f));
    ASSERT_EQ(f.frames_per_id.size(), 1u);
    mean_error[correct ? 1 : 0] = f.mean_error_m;
  }
  EXPECT_LT(mean_error[1], 0.015);
  EXPECT_GT(mean_error[0], mean_error[1] + 0.02);  // 1.8 m/s * ~25 ms = 4.5 cm without
}

TEST(PipelineScenarioTest, TwoPeoplePassingEachOtherKeepTheirIds) {
  // Opposite directions on parallel lines 0.7 m apart; the near one hides the far one briefly.
  Scene scene;
  scene.walkers = {Walker::Path(kLearnedS, {{3.0, -4.0}, {3.0, 4.0}}, 1.2),
                   Walker::Path(kLearnedS, {{3.7, 4.0}, {3.7, -4.0}}, 1.2)};
  const SceneRun run = Simulate(scene, scene.walkers[0].end_s() + 2.0);
  std::set<std::uint32_t> ids;
  for (std::size_t w = 0; w < 2; ++w) {
    const Walker& walker = scene.walkers[w];
    const Follow f = FollowWalker(run, walker, w, walker.start_s() + 0.5, walker.end_s());
    SCOPED_TRACE("walker " + std::to_string(w) + ": " + Describe(f));
    ASSERT_EQ(f.frames_per_id.size(), 1u);  // never matched to another id: no swap
    EXPECT_LE(f.unmatched, 3);
    ids.insert(f.frames_per_id.begin()->first);
  }
  EXPECT_EQ(ids.size(), 2u);
  EXPECT_EQ(AllReportedIds(run), ids);
}

// A person walking past the sensor 2-3 m away at 0.25 deg: 20-40 points a scan, an outline the
// model's. The filter is given 1.5 cm per scan for what the fit cannot know
// (ShapeOptions::centre_model_sigma_m); these scans scatter across the ray by millimetres, and the
// filter's own covariance reported the centre several times less certain than it is. The
// covariance of the gains applied, with the noise across the ray measured from the innovations
// (MultiTrackerOptions::report_gain_covariance, measured_noise_memory_scans), is nearer the error
// (what is left is the shared allowances: this body has neither sway nor another shape than the
// model's); the tracks are the same.
ConfirmedError CloseManyPointWalker(bool gain_covariance) {
  Scene scene;
  scene.walkers = {Walker::Path(kLearnedS, {{2.0, -3.0}, {3.0, 3.0}}, 1.2)};
  TrackerOptions options = WithKind(MeasurementKind::kShapeFit);
  options.tracking.report_gain_covariance = gain_covariance;
  ScannerConfig scanner;
  scanner.angle_step_rad = common::DegToRad(0.25);
  scanner.beams = 1081;
  const SceneRun run = Simulate(scene, scene.walkers[0].end_s() + 1.0, options, scanner);
  ConfirmedError out;
  out.Add(run, kLearnedS + 1.5, 0.3);
  out.Mean();
  return out;
}

TEST(PipelineScenarioTest, ACloseManyPointPersonIsReportedAsCertainAsItIs) {
  const ConfirmedError before = CloseManyPointWalker(false);
  const ConfirmedError after = CloseManyPointWalker(true);
  const auto describe = [](const ConfirmedError& e) {
    return "error " + std::to_string(e.error_m) + " m, NEES " + std::to_string(e.nees) + " (" +
           std::to_string(e.n) + ")";
  };
  SCOPED_TRACE("before: " + describe(before) + "; after: " + describe(after));
  RecordProperty("before", describe(before));
  RecordProperty("after", describe(after));
  ASSERT_GT(after.n, 50);
  EXPECT_EQ(after.n, before.n);
  EXPECT_DOUBLE_EQ(after.error_m, before.error_m);
  EXPECT_LT(after.error_m, 0.01);
  // Before: NEES 0.10 (the reported sigma three times the error); now nearly twice that, never
  // more confident than the error allows (2: honest).
  EXPECT_GT(after.nees, 1.6 * before.nees);
  EXPECT_LT(after.nees, 2.0);
}

// PipelineCounters::shape_fit_evaluations: every shape fit counted once, by the evaluations of its
// objective (at least one: the start); a person walking in the open converges within a few.
TEST(PipelineScenarioTest, ShapeFitsAreCountedByTheirEvaluations) {
  Scene scene;
  scene.walkers = {Walker::Path(kLearnedS, {{1.5, -4.0}, {6.0, 4.0}}, 1.2)};
  const SceneRun run = Simulate(scene, scene.walkers[0].end_s() + 2.0);
  const PipelineCounters& c = run.pipeline->counters();
  const auto& histogram = c.shape_fit_evaluations;
  std::uint64_t fits = 0, within_three = 0;
  for (std::size_t e = 0; e < histogram.size(); ++e) {
    fits += histogram[e];
    if (e >= 1 && e <= 3) within_three += histogram[e];
  }
  EXPECT_EQ(histogram[0], 0u);
  EXPECT_GT(c.shape_fits, 100u);
  EXPECT_EQ(fits, c.shape_fits + c.failed_shape_fits);
  EXPECT_GT(static_cast<double>(within_three), 0.9 * static_cast<double>(fits));
}

TEST(PipelineScenarioTest, TwoPeoplePassingSideBySideKeepTheirIds) {
  // Walking towards and away from the sensor 0.6 m apart: at the crossing the gap between them is
  // 10 cm, so their points may merge into one segment for a few scans.
  Scene scene;
  scene.walkers = {Walker::Path(kLearnedS, {{1.5, 0.3}, {7.0, 0.3}}, 1.2),
                   Walker::Path(kLearnedS, {{7.0, -0.3}, {1.5, -0.3}}, 1.2)};
  const SceneRun run = Simulate(scene, scene.walkers[0].end_s() + 2.0);
  std::set<std::uint32_t> ids;
  for (std::size_t w = 0; w < 2; ++w) {
    const Walker& walker = scene.walkers[w];
    const Follow f =
        FollowWalker(run, walker, w, walker.start_s() + 0.5, walker.end_s() - 0.2, 0.3);
    SCOPED_TRACE("walker " + std::to_string(w) + ": " + Describe(f));
    ASSERT_EQ(f.frames_per_id.size(), 1u);
    ids.insert(f.frames_per_id.begin()->first);
  }
  EXPECT_EQ(ids.size(), 2u);
}

TEST(PipelineScenarioTest, PersonStoppingForFourSecondsKeepsTheIdAndStaysForeground) {
  Scene scene;
  const Eigen::Vector2d stop(4.0, 0.0);
  const double speed = 1.2;
  const double arrive_s = kLearnedS + (stop - Eigen::Vector2d(2.0, -3.0)).norm() / speed;
  const double leave_s = arrive_s + 4.0;
  scene.walkers = {
      Walker({{kLearnedS, {2.0, -3.0}},
              {arrive_s, stop},
              {leave_s, stop},
              {leave_s + (Eigen::Vector2d(6.0, 3.0) - stop).norm() / speed, {6.0, 3.0}}})};
  const Walker& walker = scene.walkers[0];
  const SceneRun run = Simulate(scene, walker.end_s() + 3.0);

  const Follow f = FollowWalker(run, walker, 0, walker.start_s() + 0.5, walker.end_s());
  SCOPED_TRACE(Describe(f));
  EXPECT_EQ(f.unmatched, 0);
  ASSERT_EQ(f.frames_per_id.size(), 1u);
  EXPECT_EQ(AllReportedIds(run).size(), 1u);
  const Follow standing = FollowWalker(run, walker, 0, arrive_s + 1.0, leave_s);
  SCOPED_TRACE(Describe(standing));
  EXPECT_LT(standing.mean_error_m, 0.05);
  EXPECT_LT(standing.mean_velocity_error_mps, 0.15);
  // Measured (not coasting) while standing: the person did not become background.
  const std::uint32_t id = f.frames_per_id.begin()->first;
  for (const Frame& fr : run.frames) {
    if (fr.t_s < arrive_s || fr.t_s > leave_s) continue;
    const TrackReport* r = Find(fr, id);
    ASSERT_NE(r, nullptr) << "t " << fr.t_s;
    EXPECT_EQ(r->state, TrackState::kConfirmed) << "t " << fr.t_s;
  }
  EXPECT_EQ(run.pipeline->background().counters().absorbed_beams, 0u);
  // Nothing left behind where the person stood.
  EXPECT_EQ(run.frames.back().segments, 0u);
  EXPECT_TRUE(run.frames.back().tracks.empty());
}

// A person walks in, stops at 5 m and stands; a panel carried past 1 m in front of the sensor
// hides them for 2.5 s (longer than the coast timeout and the resume window: their track is
// lost). The track born on them when the panel is gone lies where the lost one was last measured
// and inherits its moved state (tracking.inherit_moved_s): reported again at once and kept; with
// that off it waits to move, is never reported and is handed to the background as never moved.
TEST(PipelineScenarioTest, AStandingPersonWhoseTrackRestartsAfterAnOcclusionStaysReported) {
  Scene scene;
  const Eigen::Vector2d stop(5.0, 0.0);
  const double speed = 1.2;
  const double arrive_s = kLearnedS + (stop - Eigen::Vector2d(3.0, -3.0)).norm() / speed;
  const double hidden_s = arrive_s + 1.5;
  const double seen_s = hidden_s + 2.5;
  const double leave_s = seen_s + 6.0;
  scene.walkers = {Walker({{kLearnedS, {3.0, -3.0}}, {arrive_s, stop}, {leave_s, stop}})};
  scene.moving_walls = [hidden_s, seen_s](double t_s) {
    if (t_s < hidden_s || t_s >= seen_s) return std::vector<Wall>{};
    return std::vector<Wall>{{{1.0, -0.3}, {1.0, 0.3}}};
  };
  const Walker& walker = scene.walkers[0];
  auto run_with = [&](double inherit_moved_s) {
    TrackerOptions o = Synthetic();
    o.tracking.inherit_moved_s = inherit_moved_s;
    const SceneRun run = Simulate(scene, leave_s, o);
    const Follow before = FollowWalker(run, walker, 0, walker.start_s() + 0.5, hidden_s);
    SCOPED_TRACE(Describe(before));
    EXPECT_EQ(before.unmatched, 0);  // reported while walking in and standing
    return FollowWalker(run, walker, 0, seen_s + 0.5, leave_s);
  };
  const Follow with = run_with(Synthetic().tracking.inherit_moved_s);
  SCOPED_TRACE(Describe(with));
  EXPECT_EQ(with.unmatched, 0);
  EXPECT_EQ(with.frames_per_id.size(), 1u);
  EXPECT_LT(with.mean_error_m, 0.05);
  const Follow without = run_with(0.0);
  SCOPED_TRACE(Describe(without));
  EXPECT_GT(without.unmatched, without.frames / 2);
}

TEST(PipelineScenarioTest, OcclusionBehindAPillarCoastsAndReacquiresTheSameId) {
  // A 0.4 m pillar 2 m in front of the sensor; the person walks behind it at 4.5 m: fully hidden
  // for ~0.5 s, partly for ~1 s.
  Scene scene;
  scene.statics = {testing::Cylinder({2.0, 0.0}, 0.2)};
  scene.walkers = {Walker::Path(kLearnedS, {{4.5, -3.5}, {4.5, 3.5}}, 1.2)};
  const Walker& walker = scene.walkers[0];
  const SceneRun run = Simulate(scene, walker.end_s() + 2.0);

  const Follow f = FollowWalker(run, walker, 0, walker.start_s() + 0.5, walker.end_s(), 0.6);
  SCOPED_TRACE(Describe(f));
  ASSERT_EQ(f.frames_per_id.size(), 1u);
  // Not reported while fully hidden beyond the first shape.unseen_coasting_m of coasting (0.3 m,
  // 0.25 s at 1.2 m/s: nothing of it in the scan, it may have turned behind the pillar).
  EXPECT_LE(f.unmatched, 9);
  {
    // Without that limit (nor shape.coasting_max_sigma_m), not reported only while hidden longer
    // than report_coasting_s (0.5 s).
    TrackerOptions no_limit = Synthetic();
    no_limit.shape.unseen_coasting_m = 0.0;
    no_limit.shape.coasting_max_sigma_m = 0.0;
    const SceneRun all = Simulate(scene, walker.end_s() + 2.0, no_limit);
    const Follow g = FollowWalker(all, walker, 0, walker.start_s() + 0.5, walker.end_s(), 0.6);
    SCOPED_TRACE(Describe(g));
    EXPECT_LE(g.unmatched, 5);
    EXPECT_GE(f.unmatched, g.unmatched + 2);
  }
  EXPECT_EQ(AllReportedIds(run).size(), 1u);
  const std::uint32_t id = f.frames_per_id.begin()->first;
  int coasting = 0;
  for (const Frame& fr : run.frames) {
    const TrackReport* r = Find(fr, id);
    if (r != nullptr && r->state == TrackState::kCoasting) ++coasting;
  }
  EXPECT_GE(coasting, 5);  // 0.2 s or more without a measurement
  // Re-acquired: measured again and accurate after the pillar.
  const double visible_again_s = walker.start_s() + (3.5 + 0.9) / 1.2;
  const Follow after = FollowWalker(run, walker, 0, visible_again_s + 0.5, walker.end_s());
  SCOPED_TRACE(Describe(after));
  EXPECT_LT(after.mean_error_m, 0.03);
  const TrackReport* last =
      Find(run.frames[static_cast<std::size_t>(walker.end_s() * kRateHz) - 2], id);
  ASSERT_NE(last, nullptr);
  EXPECT_EQ(last->state, TrackState::kConfirmed);
}

// A person walking across the room vanishes at x = 4.5 m (as through a door in the floor plan):
// the wall behind their predicted position is seen at once, so their coasting track is no longer
// reported; with the check off it is reported at its prediction for report_coasting_s. (Hidden by
// a pillar instead, the coasting track stays reported: the test above.)
TEST(PipelineScenarioTest, ACoastingTrackIsNotReportedWhereTheScanSeesThroughIt) {
  Scene scene;
  scene.walkers = {Walker::Path(kLearnedS, {{4.5, -3.0}, {4.5, 0.5}}, 1.2)};
  const Walker& walker = scene.walkers[0];
  auto coasting_reports = [&](const TrackerOptions& options) {
    const SceneRun run = Simulate(scene, walker.end_s() + 1.5, options);
    int coasting = 0, before = 0;
    for (const Frame& f : run.frames) {
      for (const TrackReport& r : f.tracks) {
        if (f.t_s > walker.end_s() && r.state == TrackState::kCoasting) ++coasting;
        if (f.t_s > walker.start_s() + 0.5 && f.t_s < walker.end_s()) ++before;
      }
    }
    EXPECT_GT(before, 50);  // tracked while walking
    return coasting;
  };
  TrackerOptions off = Synthetic();
  off.shape.seen_through_margin_m = 0.0;
  off.shape.unseen_coasting_m = 0.0;
  EXPECT_GE(coasting_reports(off), 8);
  EXPECT_LE(coasting_reports(Synthetic()), 1);
}

// The reports of a walker's track: how many fell while it walked (from 0.5 s after its start),
// and on_coasting called for each coasting report after its walk ended.
template <typename OnCoasting>
int ReportsAroundTheWalk(const SceneRun& run, const Walker& walker, OnCoasting&& on_coasting) {
  int walking = 0;
  for (const Frame& f : run.frames) {
    for (const TrackReport& r : f.tracks) {
      if (f.t_s > walker.start_s() + 0.5 && f.t_s < walker.end_s()) ++walking;
      if (f.t_s <= walker.end_s() || r.state != TrackState::kCoasting) continue;
      on_coasting(r);
    }
  }
  return walking;
}

// A coasting-sigma rule's run: the walker's coasting reports after its walk, how many of them had a
// position sigma (square root of half the trace) above max_sigma_m, and the rule's counter.
struct CoastingSigmaResult {
  int coasting = 0;
  int coasting_beyond = 0;  // reported with a sigma above max_sigma_m
  std::uint64_t dropped = 0;
};

template <typename Counter>
CoastingSigmaResult CoastingReportsBeyond(const Scene& scene, const TrackerOptions& options,
                                          double max_sigma_m, Counter&& counter) {
  const Walker& walker = scene.walkers[0];
  const SceneRun run = Simulate(scene, walker.end_s() + 1.5, options);
  CoastingSigmaResult result;
  const int before = ReportsAroundTheWalk(run, walker, [&](const TrackReport& r) {
    ++result.coasting;
    const Eigen::Matrix2d p = r.covariance.topLeftCorner<2, 2>();
    if (std::sqrt(0.5 * p.trace()) > max_sigma_m) ++result.coasting_beyond;
  });
  EXPECT_GT(before, 50);  // tracked while walking
  result.dropped = counter(run.pipeline->counters());
  return result;
}

// A coasting-sigma rule's effect: without it some coasting reports exceed the limit and nothing is
// dropped; with it none does, the track is still reported while within it, and the rule counted.
void ExpectOnlyWithinTheLimit(const CoastingSigmaResult& without, const CoastingSigmaResult& with) {
  EXPECT_GE(without.coasting_beyond, 1) << without.coasting;
  EXPECT_EQ(without.dropped, 0u);
  EXPECT_EQ(with.coasting_beyond, 0);
  EXPECT_GE(with.coasting, 1);  // reported while still within it
  EXPECT_LT(with.coasting, without.coasting);
  EXPECT_GE(with.dropped, 1u);
}

// A person walking towards the front wall leaves the view 0.3 m before it (as round a corner or
// through a side door): the straight prediction runs on into the wall, the beams across it return
// from the wall at or just behind it, none from in front of it. Reported until it has coasted
// shape.unseen_coasting_m (0.3 m: 0.25 s at 1.2 m/s), not for all of report_coasting_s (0.5 s,
// 0.6 m) as with the check off. (Hidden behind a pillar, the track stays reported: the test above.)
TEST(PipelineScenarioTest, ACoastingTrackIsNotReportedWhereTheScanShowsNothingOfIt) {
  Scene scene;
  scene.walkers = {Walker::Path(kLearnedS, {{3.0, -2.0}, {7.7, -2.0}}, 1.2)};
  const Walker& walker = scene.walkers[0];
  struct Result {
    int coasting = 0;
    double farthest_m = 0.0;  // coasted distance of the last coasting report
    std::uint64_t dropped = 0;
  };
  auto run_with = [&](const TrackerOptions& options) {
    const SceneRun run = Simulate(scene, walker.end_s() + 1.5, options);
    Result result;
    const int before = ReportsAroundTheWalk(run, walker, [&](const TrackReport& r) {
      ++result.coasting;
      result.farthest_m = std::max(result.farthest_m, std::hypot(r.vx_mps, r.vy_mps) * r.coasted_s);
    });
    EXPECT_GT(before, 50);                                 // tracked while walking
    EXPECT_EQ(run.pipeline->counters().seen_through, 0u);  // the wall is right behind it
    result.dropped = run.pipeline->counters().unseen_coasting;
    return result;
  };
  TrackerOptions off = Synthetic();
  off.shape.unseen_coasting_m = 0.0;
  off.shape.coasting_max_sigma_m = 0.0;  // reported whatever its sigma: the test below
  const Result without = run_with(off);
  EXPECT_GE(without.farthest_m, 0.5);
  EXPECT_EQ(without.dropped, 0u);
  const Result with = run_with(Synthetic());
  EXPECT_GE(with.coasting, 1);  // the first 0.3 m are reported
  EXPECT_GT(with.farthest_m, 0.2);
  EXPECT_LE(with.farthest_m, 0.3);
  EXPECT_GE(without.coasting, with.coasting + 4);
  EXPECT_GE(with.dropped, 4u);
}

// A door 1 m wide, hinged at (3, -1), closed towards +y while the background is learned; it swings
// open by 90 deg within 1.5 s from t = 8 s and stays open.
std::function<std::vector<Wall>(double)> SwingingDoor(double open_direction) {
  return [open_direction](double t_s) {
    const double u = std::clamp((t_s - 8.0) / 1.5, 0.0, 1.0);
    const double angle = common::kPi / 2 + open_direction * u * common::kPi / 2;
    const Eigen::Vector2d hinge(3.0, -1.0);
    return std::vector<Wall>{{hinge, hinge + Eigen::Vector2d(std::cos(angle), std::sin(angle))}};
  };
}

TEST(PipelineScenarioTest, DoorOpeningAwayIntoTheBackgroundGivesNoTrackAndRecedes) {
  Scene scene;
  scene.moving_walls = SwingingDoor(-1.0);  // towards +x: away from the sensor
  // Later someone walks behind where the closed door was.
  scene.walkers = {Walker::Path(14.0, {{5.5, -3.0}, {5.5, 2.5}}, 1.2)};
  const SceneRun run = Simulate(scene, 20.0);
  for (const Frame& f : run.frames) {
    if (f.t_s < 14.0) {
      EXPECT_TRUE(f.tracks.empty()) << "t " << f.t_s;
    }
  }
  EXPECT_GT(run.pipeline->background().counters().receded_beams, 10u);
  EXPECT_EQ(run.pipeline->tracker().counters().confirmed, 1u);
  // The background behind the old door position receded: the person is tracked there too.
  const Follow f = FollowWalker(run, scene.walkers[0], 0, 14.5, scene.walkers[0].end_s());
  SCOPED_TRACE(Describe(f));
  ASSERT_EQ(f.frames_per_id.size(), 1u);
  EXPECT_EQ(f.unmatched, 0);
}

TEST(PipelineScenarioTest, DoorSwingingTowardsTheSensorBecomesBackgroundSoonAfterItStops) {
  // The open door stands in front of the learned background. While it swings it may be a track; a
  // flat leaf that stands still is not a person: two seconds after it stopped it is background and
  // nothing is tracked there any more.
  Scene scene;
  scene.moving_walls = SwingingDoor(+1.0);  // towards -x: into the room
  const TrackerOptions options = Synthetic();
  const double open_s = 9.5;
  const double gone_s = open_s + options.tracking.static_object_to_background_s + 1.0;
  const SceneRun run = Simulate(scene, gone_s + 5.0, options);
  double last_track_s = 0.0;
  for (const Frame& f : run.frames) {
    if (!f.tracks.empty()) last_track_s = f.t_s;
  }
  EXPECT_LT(last_track_s, gone_s);
  EXPECT_EQ(run.pipeline->counters().absorbed_objects, 1u);
  EXPECT_GT(run.pipeline->background().counters().absorbed_beams, 10u);
  EXPECT_TRUE(run.frames.back().tracks.empty());
  EXPECT_EQ(run.frames.back().segments, 0u);
}

TEST(PipelineScenarioTest,
     WithoutStaticObjectHandlingTheDoorStaysATrackUntilTheBackgroundAbsorbsIt) {
  // The previous behaviour: tracked as an object at rest for the background's absorb_after_s.
  Scene scene;
  scene.moving_walls = SwingingDoor(+1.0);
  TrackerOptions options = Synthetic();
  options.tracking.static_objects = false;
  options.background.absorb_after_s = 10.0;
  const double open_s = 9.5;
  const SceneRun run = Simulate(scene, open_s + options.background.absorb_after_s + 4.0, options);
  double last_track_s = 0.0;
  for (const Frame& f : run.frames) {
    if (!f.tracks.empty()) last_track_s = f.t_s;
    if (f.t_s > open_s + 1.5 && f.t_s < open_s + options.background.absorb_after_s - 1.0) {
      ASSERT_EQ(f.tracks.size(), 1u) << "t " << f.t_s;
    }
  }
  EXPECT_GT(last_track_s, open_s + options.background.absorb_after_s - 1.0);
  EXPECT_EQ(run.pipeline->counters().absorbed_objects, 0u);
  EXPECT_TRUE(run.frames.back().tracks.empty());
}

TEST(PipelineScenarioTest, BoardMovedAndLeftBecomesBackgroundAndAPersonWhoStopsIsKept) {
  // A chair's backrest (a 0.45 m board) pushed 2 m across the room and left at t = 10 s; a person
  // who walks in and stands for 15 s, well beyond the two seconds after which the board is gone.
  Scene scene;
  scene.moving_walls = [](double t_s) {
    const double u = std::clamp((t_s - 8.0) / 2.0, 0.0, 1.0);
    const Eigen::Vector2d c(5.0, -3.0 + 2.0 * u);
    return std::vector<Wall>{{c - Eigen::Vector2d(0.0, 0.225), c + Eigen::Vector2d(0.0, 0.225)}};
  };
  const Eigen::Vector2d stop(4.0, 2.0);
  const double arrive_s = 8.0 + (stop - Eigen::Vector2d(1.5, 4.0)).norm() / 1.2;
  scene.walkers = {Walker({{8.0, {1.5, 4.0}}, {arrive_s, stop}, {arrive_s + 15.0, stop}})};
  const SceneRun run = Simulate(scene, arrive_s + 15.0, Synthetic());
  for (const Frame& f : run.frames) {
    if (f.t_s < 10.0 + 3.5) continue;
    // Only the person is left: one track, on them.
    ASSERT_EQ(f.tracks.size(), 1u) << "t " << f.t_s;
    EXPECT_LT((Position(f.tracks[0]) - stop).norm(), 0.1) << "t " << f.t_s;
  }
  const Follow standing = FollowWalker(run, scene.walkers[0], 0, arrive_s + 0.5, arrive_s + 14.9);
  SCOPED_TRACE(Describe(standing));
  EXPECT_EQ(standing.unmatched, 0);
  EXPECT_EQ(standing.frames_per_id.size(), 1u);
  EXPECT_EQ(run.pipeline->counters().absorbed_objects, 1u);
}

TEST(PipelineScenarioTest, APersonWhoStopsFarFromTheSensorWithTheirBackToItIsKept) {
  // Walks away from the sensor and stands 10 m from it for 10 s, the back towards it: 4 or 5
  // points of a 0.23 x 0.14 m back, whose curvature is about the size of the range noise there.
  // Still a person, never background.
  Scene scene;
  const Eigen::Vector2d stop(10.0, 2.5);
  const Eigen::Vector2d start(2.0, 2.5);
  const double arrive_s = 8.0 + (stop - start).norm() / 1.2;
  scene.walkers = {Walker({{8.0, start}, {arrive_s, stop}, {arrive_s + 10.0, stop}})};
  scene.sizes = {{0.23, 0.14}};
  const SceneRun run = Simulate(scene, arrive_s + 10.0, Synthetic());
  const Follow standing = FollowWalker(run, scene.walkers[0], 0, arrive_s + 0.5, arrive_s + 9.9);
  SCOPED_TRACE(Describe(standing));
  EXPECT_EQ(standing.unmatched, 0);
  EXPECT_EQ(standing.frames_per_id.size(), 1u);
  EXPECT_EQ(run.pipeline->counters().absorbed_objects, 0u);
}

// Someone stands where the background is learned, then walks away 0.3 m beside the line of sight
// they stood on: the beams on one side of them see past their own former place, which the
// background model still holds nearer, and are classed background. The segment's end there is no
// silhouette (ShapeOptions::receded_background_edge_m): with it taken as one, the fit squeezed
// the body between the wrong pair of rays: mean error 0.040 -> 0.028 m.
TEST(PipelineScenarioTest, AWalkerLeavingTheirOwnLearnedPlaceIsMeasuredWhole) {
  const Eigen::Vector2d u(std::cos(common::DegToRad(14.0)), std::sin(common::DegToRad(14.0)));
  const Eigen::Vector2d n(-u.y(), u.x());
  const Eigen::Vector2d stand = 5.8 * u;
  const Eigen::Vector2d aside = stand + 0.3 * n;
  const Eigen::Vector2d away = aside + 4.0 * u;
  Scene scene;
  scene.walkers = {Walker({{0.0, stand}, {8.0, stand}, {8.5, aside}, {8.5 + 4.0 / 0.6, away}})};
  scene.sizes = {{0.23, 0.14}};
  for (const double edge : {0.3, 0.0}) {
    TrackerOptions o = Synthetic();
    o.shape.receded_background_edge_m = edge;
    const SceneRun run = Simulate(scene, 8.5 + 4.0 / 0.6, o);
    const Follow walking = FollowWalker(run, scene.walkers[0], 0, 9.5, 8.4 + 4.0 / 0.6);
    std::printf("receded_background_edge_m %.1f: %s\n", edge, Describe(walking).c_str());
    EXPECT_EQ(walking.unmatched, 0);
    if (edge > 0.0) {
      EXPECT_LT(walking.mean_error_m, 0.033);
    } else {
      EXPECT_GT(walking.mean_error_m, 0.035);  // as before
    }
  }
}

TEST(PipelineScenarioTest, AnObjectThatNeverMovesBecomesBackgroundWithoutBeingReported) {
  // A box put down at t = 8 s where the sensor did not see it arrive (it appears at once).
  Scene scene;
  scene.moving_walls = [](double t_s) {
    if (t_s < 8.0) return std::vector<Wall>{};
    return std::vector<Wall>{{{4.0, -1.5}, {4.0, -1.1}}, {{4.0, -1.1}, {4.4, -1.1}}};
  };
  const TrackerOptions options = Synthetic();
  const SceneRun run =
      Simulate(scene, 8.0 + options.tracking.never_moved_to_background_s + 2.0, options);
  EXPECT_TRUE(AllReportedIds(run).empty());
  EXPECT_EQ(run.pipeline->counters().absorbed_objects, 1u);
  EXPECT_EQ(run.frames.back().segments, 0u);
}

// A person who appears walking (1 m/s, across the line of sight at 4 m) is reported from the scan
// their track is confirmed in (3 of 4 scans), its speed being clear; with
// tracking.moving_speed_mps off only once they left still_radius_m (0.25 m, 0.25 s) around where
// the track started. (A box that appears and never moves is never reported: the test below.)
TEST(PipelineScenarioTest, APersonWalkingInIsReportedFromTheirConfirmation) {
  Scene scene;
  scene.walkers = {Walker::Path(kLearnedS, {{4.0, -2.0}, {4.0, 2.0}}, 1.0)};
  const Walker& walker = scene.walkers[0];
  auto first_report_s = [&](const TrackerOptions& options) {
    const SceneRun run = Simulate(scene, walker.end_s() + 0.5, options);
    EXPECT_EQ(AllReportedIds(run).size(), 1u);
    for (const Frame& f : run.frames) {
      if (!f.tracks.empty()) return f.t_s - walker.start_s();
    }
    return 1e9;
  };
  TrackerOptions off = Synthetic();
  off.tracking.moving_speed_mps = 0.0;
  const double without = first_report_s(off);
  const double with = first_report_s(Synthetic());
  EXPECT_LE(with, 4.5 / kRateHz);  // the 3rd or 4th scan with the person
  EXPECT_GE(without, 0.2);
  EXPECT_GE(without - with, 2.0 / kRateHz);
}

TEST(PipelineScenarioTest, NoiseOnlyNeverConfirmsATrack) {
  // Noisier than the scanner's spec, with 1 % spurious returns (dust) and 2 % dropouts.
  Scene scene;
  const ScannerConfig noisy{
      .noise_sigma_m = 0.02, .seed = 11, .spurious_fraction = 0.01, .dropout_fraction = 0.02};
  const SceneRun run = Simulate(scene, 70.0, Synthetic(), noisy);
  EXPECT_TRUE(AllReportedIds(run).empty());
  EXPECT_EQ(run.pipeline->tracker().counters().confirmed, 0u);
  // The spurious returns did reach the tracker: it rejected them, not an earlier stage.
  EXPECT_GT(run.pipeline->counters().segments, 0u);
  EXPECT_EQ(run.pipeline->background().counters().absorbed_beams, 0u);
}

TEST(PipelineScenarioTest, RejectedScansAreCountedAndTracksCoastThroughThem) {
  const Walker walker = Walker::Path(kLearnedS, {{2.0, -3.0}, {2.0, 3.0}}, 1.0);
  auto pipeline = std::make_unique<TrackingPipeline>(Synthetic());
  SyntheticScanner scanner;
  std::vector<Body> bodies;
  const auto room = Room();
  std::uint32_t id = 0;
  std::uint64_t bad_scans = 0;
  for (std::int64_t k = 0; k < static_cast<std::int64_t>(11.0 * kRateHz); ++k) {
    bodies.clear();
    if (const auto p = walker.At(scanner.ScanTimeS(k))) bodies.push_back({*p});
    ScanView scan = scanner.Render(k, room, bodies);
    const bool bad = k % 25 == 0 && k > 200;
    if (bad) {
      scan.scan_period_s = 0.0;
      ++bad_scans;
    }
    const ScanTracks& out = pipeline->Process(scan, static_cast<std::uint32_t>(k));
    if (bad) {
      EXPECT_EQ(pipeline->last_scan_error(), ScanError::kBadScanPeriod);
      ASSERT_EQ(out.tracks.size(), 1u);
      EXPECT_EQ(out.tracks[0].state, TrackState::kCoasting);
    }
    if (!out.tracks.empty()) {
      if (id == 0) id = out.tracks[0].track_id;
      EXPECT_EQ(out.tracks[0].track_id, id);
    }
  }
  EXPECT_NE(id, 0u);
  EXPECT_EQ(bad_scans, 2u);
  EXPECT_EQ(pipeline->counters().rejected_scans, bad_scans);
  EXPECT_EQ(pipeline->background().counters().rejected_scans, bad_scans);
  EXPECT_NEAR(static_cast<double>(pipeline->counters().learning_scans), 5.0 * kRateHz, 2.0);
}

TrackerOptions LegsOptions() {
  TrackerOptions o = Synthetic();
  o.shape.mount = Mount::kLegs;
  return o;
}

TEST(PipelineScenarioTest, LegsAtKneeHeightAreOnePersonInEveryGaitPhase) {
  Scene scene;
  scene.legs = true;
  scene.walkers = {Walker::Path(kLearnedS, {{2.0, -4.0}, {4.5, 3.5}}, 1.3)};
  const Walker& walker = scene.walkers[0];
  const SceneRun run = Simulate(scene, walker.end_s() + 1.0, LegsOptions());
  EXPECT_EQ(AllReportedIds(run).size(), 1u);
  const Follow f = FollowWalker(run, walker, 0, walker.start_s() + 0.6, walker.end_s());
  SCOPED_TRACE(Describe(f));
  EXPECT_EQ(f.frames_per_id.size(), 1u);
  EXPECT_LE(f.unmatched, 2);
  // The body centre, not a leg, at every phase of the gait (ten bins of a stride).
  const Legs legs(walker);
  std::array<double, 10> sum{}, count{};
  for (const Frame& fr : run.frames) {
    if (fr.t_s < walker.start_s() + 1.0 || fr.t_s > walker.end_s() || fr.tracks.size() != 1) {
      continue;
    }
    const double phase = legs.Phase(fr.t_s);
    const auto bin = static_cast<std::size_t>(10.0 * (phase - std::floor(phase))) % 10;
    sum[bin] += (Position(fr.tracks[0]) - *fr.truth[0]).norm();
    count[bin] += 1;
  }
  for (std::size_t b = 0; b < 10; ++b) {
    ASSERT_GT(count[b], 3) << "bin " << b;
    EXPECT_LT(sum[b] / count[b], 0.06) << "bin " << b;
  }
  EXPECT_GT(run.pipeline->counters().leg_pairs, 100u);
  for (const Frame& fr : run.frames) {
    for (const TrackReport& r : fr.tracks) {
      EXPECT_EQ(r.shape, ObjectShape::kLegs);
      EXPECT_NEAR(r.size_major_m, Legs::kRadiusM, 0.02);
    }
  }
}

// At knee height a person walking across the room vanishes at x = 4.5 m (as through a door): the
// beams across every place their legs could stand return from the wall behind, and at 4.5 m they
// lie closer together than a leg is wide, so the coasting track is no longer reported; with
// shape.legs_seen_through off it is reported at its prediction (for report_coasting_s).
TEST(PipelineScenarioTest, AKneeHeightCoastingTrackIsNotReportedWhereTheScanSeesThroughItsLegs) {
  Scene scene;
  scene.legs = true;
  scene.walkers = {Walker::Path(kLearnedS, {{4.5, -3.0}, {4.5, 0.5}}, 1.2)};
  const Walker& walker = scene.walkers[0];
  struct Result {
    int coasting = 0;
    std::uint64_t dropped = 0;
  };
  auto run_with = [&](const TrackerOptions& options) {
    const SceneRun run = Simulate(scene, walker.end_s() + 1.5, options);
    Result result;
    int before = 0;
    for (const Frame& f : run.frames) {
      for (const TrackReport& r : f.tracks) {
        if (f.t_s > walker.end_s() && r.state == TrackState::kCoasting) ++result.coasting;
        if (f.t_s > walker.start_s() + 0.5 && f.t_s < walker.end_s()) ++before;
      }
    }
    EXPECT_GT(before, 50);  // tracked while walking
    result.dropped = run.pipeline->counters().legs_seen_through;
    return result;
  };
  TrackerOptions off = LegsOptions();
  off.shape.legs_seen_through = false;
  const Result without = run_with(off);
  EXPECT_GE(without.coasting, 5);
  EXPECT_EQ(without.dropped, 0u);
  const Result with = run_with(LegsOptions());
  EXPECT_LE(with.coasting, 1);
  EXPECT_GE(with.dropped, 4u);
}

// At knee height a person walking across the room vanishes at x = 4.5 m (as through a door) with
// the scan seeing through nothing (shape.legs_seen_through off in both runs): the coasting track is
// reported only while its position sigma stays within shape.legs_coasting_max_sigma_m (here
// 0.06 m, below what this track's sigma grows to within legs_report_coasting_s; the default, a
// leg's diameter, is reached by tracks measured from one or two beams per leg far out); with the
// rule off it is reported whatever its sigma, for all of legs_report_coasting_s.
TEST(PipelineScenarioTest, AKneeHeightCoastingTrackIsReportedOnlyWhileItsSigmaIsWithinALeg) {
  Scene scene;
  scene.legs = true;
  scene.walkers = {Walker::Path(kLearnedS, {{4.5, -3.0}, {4.5, 0.5}}, 1.2)};
  constexpr double kMaxSigmaM = 0.06;
  auto run_with = [&](const TrackerOptions& options) {
    return CoastingReportsBeyond(scene, options, kMaxSigmaM, [](const PipelineCounters& c) {
      return c.legs_coasting_uncertain;
    });
  };
  TrackerOptions off = LegsOptions();
  off.shape.legs_seen_through = false;
  off.shape.legs_coasting_max_sigma_m = 0.0;
  TrackerOptions on = LegsOptions();
  on.shape.legs_seen_through = false;
  on.shape.legs_coasting_max_sigma_m = kMaxSigmaM;
  ExpectOnlyWithinTheLimit(run_with(off), run_with(on));
  // The default: a leg's diameter.
  EXPECT_DOUBLE_EQ(TrackerOptions{}.shape.legs_coasting_max_sigma_m,
                   2.0 * TrackerOptions{}.shape.leg_radius_m);
}

// At upper-body height a person walking across the room vanishes at x = 4.5 m (as through a
// door) with neither the see-through nor the nothing-seen check (both off in both runs): the
// coasting track is reported only while its position sigma stays within
// shape.coasting_max_sigma_m (here 0.05 m, below what this track's sigma grows to within
// report_coasting_s; the default, the body's half-depth, is reached by tracks measured from a few
// beams far out or coasting longer); with the rule off it is reported whatever its sigma, for
// all of report_coasting_s.
TEST(PipelineScenarioTest, AnUpperBodyCoastingTrackIsReportedOnlyWhileItsSigmaIsWithinTheBody) {
  Scene scene;
  scene.walkers = {Walker::Path(kLearnedS, {{4.5, -3.0}, {4.5, 0.5}}, 1.2)};
  constexpr double kMaxSigmaM = 0.05;
  auto run_with = [&](double max_sigma_m) {
    TrackerOptions options = Synthetic();
    options.shape.seen_through_margin_m = 0.0;
    options.shape.unseen_coasting_m = 0.0;
    options.shape.coasting_max_sigma_m = max_sigma_m;
    return CoastingReportsBeyond(scene, options, kMaxSigmaM,
                                 [](const PipelineCounters& c) { return c.coasting_uncertain; });
  };
  ExpectOnlyWithinTheLimit(run_with(0.0), run_with(kMaxSigmaM));
  // The default: the body's half-depth.
  EXPECT_DOUBLE_EQ(TrackerOptions{}.shape.coasting_max_sigma_m,
                   TrackerOptions{}.shape.person_minor_m);
}

TEST(PipelineScenarioTest, TwoPeopleSideBySideAtKneeHeightKeepTheirLegsAndIds) {
  Scene scene;
  scene.legs = true;
  scene.walkers = {Walker::Path(kLearnedS, {{2.0, -4.0}, {2.0, 4.0}}, 1.2),
                   Walker::Path(kLearnedS, {{2.8, -4.0}, {2.8, 4.0}}, 1.2)};
  const SceneRun run = Simulate(scene, scene.walkers[0].end_s() + 1.0, LegsOptions());
  std::set<std::uint32_t> ids;
  for (std::size_t w = 0; w < 2; ++w) {
    const Follow f = FollowWalker(run, scene.walkers[w], w, scene.walkers[w].start_s() + 0.6,
                                  scene.walkers[w].end_s(), 0.35);
    SCOPED_TRACE("walker " + std::to_string(w) + ": " + Describe(f));
    ASSERT_EQ(f.frames_per_id.size(), 1u);
    EXPECT_LE(f.unmatched, 5);
    EXPECT_LT(f.mean_error_m, 0.06);
    ids.insert(f.frames_per_id.begin()->first);
  }
  EXPECT_EQ(ids.size(), 2u);
  EXPECT_EQ(AllReportedIds(run), ids);
}

// A walker crossing the line of sight at range_m who stops on it for 3 s, side-on to the
// sensor: walking, one leg hides the other twice a stride; standing, the near leg hides the far
// one all the time. The tracked centre's mean error and NEES (measured confirmed tracks) while
// walking and while standing, with or without ShapeOptions::hidden_leg_behind.
struct CrossingError {
  double walking_error_m = 0.0, walking_nees = 0.0;
  double standing_error_m = 0.0, standing_nees = 0.0;
  int walking = 0, standing = 0;
  std::uint64_t single_legs = 0, legs_behind = 0;
};
CrossingError CrossAtKneeHeight(double range_m, double step_deg, bool hidden_leg_behind,
                                double wall_x_m = 15.0) {
  Scene scene;
  scene.legs = true;
  scene.walls = {{{wall_x_m, -7.0}, {wall_x_m, 7.0}},
                 {{-2.0, 7.0}, {15.0, 7.0}},
                 {{-2.0, -7.0}, {15.0, -7.0}},
                 {{-2.0, 7.0}, {-2.0, -7.0}}};
  const double speed = 1.3;
  const double arrive_s = kLearnedS + 2.5 / speed;
  const double leave_s = arrive_s + 3.0;
  scene.walkers = {Walker({{kLearnedS, {range_m, -2.5}},
                           {arrive_s, {range_m, 0.0}},
                           {leave_s, {range_m, 0.0}},
                           {leave_s + 2.5 / speed, {range_m, 2.5}}})};
  TrackerOptions options = LegsOptions();
  options.shape.hidden_leg_behind = hidden_leg_behind;
  ScannerConfig scanner;
  scanner.angle_step_rad = common::DegToRad(step_deg);
  scanner.beams = static_cast<std::size_t>(std::lround(270.0 / step_deg)) + 1;
  const SceneRun run = Simulate(scene, scene.walkers[0].end_s() + 0.5, options, scanner);
  CrossingError out;
  for (const Frame& f : run.frames) {
    if (!f.truth[0] || f.t_s < kLearnedS + 1.0) continue;
    const bool standing = f.t_s > arrive_s + 0.5 && f.t_s < leave_s;
    const bool walking = f.t_s < arrive_s || f.t_s > leave_s + 0.5;
    if (!standing && !walking) continue;
    for (const TrackReport& r : f.tracks) {
      const Eigen::Vector2d e = Position(r) - *f.truth[0];
      if (r.state != TrackState::kConfirmed || e.norm() > 0.4) continue;
      const double nees = e.dot(r.covariance.topLeftCorner<2, 2>().ldlt().solve(e));
      (standing ? out.standing_error_m : out.walking_error_m) += e.norm();
      (standing ? out.standing_nees : out.walking_nees) += nees;
      ++(standing ? out.standing : out.walking);
    }
  }
  if (out.walking > 0) {
    out.walking_error_m /= out.walking;
    out.walking_nees /= out.walking;
  }
  if (out.standing > 0) {
    out.standing_error_m /= out.standing;
    out.standing_nees /= out.standing;
  }
  out.single_legs = run.pipeline->counters().single_legs;
  out.legs_behind = run.pipeline->counters().legs_behind;
  return out;
}

std::string Describe(const CrossingError& c) {
  return "walking " + std::to_string(c.walking_error_m) + " m, NEES " +
         std::to_string(c.walking_nees) + " (" + std::to_string(c.walking) + "), standing " +
         std::to_string(c.standing_error_m) + " m, NEES " + std::to_string(c.standing_nees) + " (" +
         std::to_string(c.standing) + "); single legs " + std::to_string(c.single_legs) +
         ", hidden behind " + std::to_string(c.legs_behind);
}

TEST(PipelineScenarioTest, OneLegHidingTheOtherIsMeasuredAsTheCentreBehindIt) {
  // 5 m at 0.5 deg (3 beams a leg), 12 m at 0.25 deg (2-3 beams a leg).
  for (const auto& [range_m, step_deg] : {std::pair{5.0, 0.5}, std::pair{12.0, 0.25}}) {
    const CrossingError before = CrossAtKneeHeight(range_m, step_deg, false);
    const CrossingError after = CrossAtKneeHeight(range_m, step_deg, true);
    const std::string at = std::to_string(static_cast<int>(range_m)) + "m";
    SCOPED_TRACE(at + ": before: " + Describe(before) + "; after: " + Describe(after));
    RecordProperty("before_" + at, Describe(before));
    RecordProperty("after_" + at, Describe(after));
    ASSERT_GT(before.standing, 40);
    ASSERT_GT(after.standing, 40);
    ASSERT_GT(after.walking, 40);
    EXPECT_EQ(before.legs_behind, 0u);
    EXPECT_GT(after.legs_behind, 50u);
    // Standing side-on, the near leg alone: before, its centre (the hip's 0.09 m off); now the
    // body centre, within what the covariance says.
    EXPECT_GT(before.standing_error_m, 0.06);
    EXPECT_LT(after.standing_error_m, 0.04);
    EXPECT_LT(after.standing_nees, 3.0);
    // Walking: not worse, and honest (its pairs weighted towards the standing leg,
    // shape.stance_leg_weight, lie nearer the centre than the gait allowance they carry).
    EXPECT_LT(after.walking_error_m, before.walking_error_m + 0.005);
    EXPECT_GT(after.walking_nees, 0.15);
    EXPECT_LT(after.walking_nees, 3.0);
  }
  // At 14 m and 0.5 deg (12 cm between beams) a leg beside could fall between two beams: nothing
  // there is no sign of a hidden leg, and a single leg stays a single leg.
  const CrossingError far = CrossAtKneeHeight(14.0, 0.5, true);
  SCOPED_TRACE("14 m: " + Describe(far));
  EXPECT_GT(far.single_legs, 20u);
  EXPECT_EQ(far.legs_behind, 0u);
  // In front of a wall 0.35 m behind the body, the beams beside the leg return from within the
  // legs' reach: the other leg could stand there, so a single leg stays a single leg.
  const CrossingError wall = CrossAtKneeHeight(5.0, 0.5, true, 5.35);
  SCOPED_TRACE("5 m before a wall: " + Describe(wall));
  EXPECT_GT(wall.single_legs, 20u);
  EXPECT_EQ(wall.legs_behind, 0u);
}

// A walker going straight away from the sensor along the x axis (legs side by side across the
// line of sight, both seen), until at 1.5 s a screen appears close to the sensor that hides
// everything right of the walk (y < 0): from then on only the left leg is seen, in every phase
// of the stride, and nothing hides the right leg behind it. The tracked centre's error along and
// across the walk (measured confirmed tracks) while one leg is seen, with or without
// ShapeOptions::single_leg_across_walk.
struct OneLegWalk {
  double along_mean_m = 0.0, along_abs_m = 0.0, across_mean_m = 0.0, across_abs_m = 0.0;
  double error_m = 0.0, nees = 0.0;
  int n = 0;
  std::uint64_t across_walk = 0;
  std::uint64_t side_uncertain = 0;
  std::uint64_t side_from_view = 0;
  std::uint64_t side_view_contested = 0;
};
// mirrored: the screen hides the left leg instead of the right. side_uncertainty:
// ShapeOptions::single_leg_side_uncertainty; screen_from_s: when the screen appears after the
// walker starts.
OneLegWalk WalkWithOneLegSeen(bool across_walk, bool mirrored, bool side_uncertainty = true,
                              double screen_from_s = 1.5, double skip_s = 0.5,
                              bool side_from_view = true, double from_x_m = 2.0,
                              double to_x_m = 9.0, double beam_divergence_rad = 0.0) {
  Scene scene;
  scene.legs = true;
  scene.walls = {{{15.0, -7.0}, {15.0, 7.0}},
                 {{-2.0, 7.0}, {15.0, 7.0}},
                 {{-2.0, -7.0}, {15.0, -7.0}},
                 {{-2.0, 7.0}, {-2.0, -7.0}}};
  const double speed = 1.3;
  const double start_s = kLearnedS, screen_s = start_s + screen_from_s;
  scene.walkers = {Walker::Path(start_s, {{from_x_m, 0.0}, {to_x_m, 0.0}}, speed)};
  const double side = mirrored ? -1.0 : 1.0;
  scene.moving_walls = [screen_s, side](double t_s) {
    return t_s < screen_s ? std::vector<Wall>{}
                          : std::vector<Wall>{{{0.6, -1.5 * side}, {0.6, -0.002 * side}}};
  };
  TrackerOptions options = LegsOptions();
  options.shape.single_leg_across_walk = across_walk;
  options.shape.single_leg_side_uncertainty = side_uncertainty;
  options.shape.single_leg_side_from_view = side_from_view;
  options.shape.beam_divergence_rad = beam_divergence_rad;
  const SceneRun run = Simulate(scene, scene.walkers[0].end_s() + 0.2, options);
  OneLegWalk out;
  for (const Frame& f : run.frames) {
    // From half a second after the screen appears (the two-leg past forgotten) to the end.
    if (!f.truth[0] || f.t_s < screen_s + skip_s) continue;
    for (const TrackReport& r : f.tracks) {
      const Eigen::Vector2d e = Position(r) - *f.truth[0];
      if (r.state != TrackState::kConfirmed || e.norm() > 0.4) continue;
      out.along_mean_m += e.x();
      out.along_abs_m += std::abs(e.x());
      out.across_mean_m += e.y();
      out.across_abs_m += std::abs(e.y());
      out.error_m += e.norm();
      out.nees += e.dot(r.covariance.topLeftCorner<2, 2>().ldlt().solve(e));
      ++out.n;
    }
  }
  if (out.n > 0) {
    for (double* v : {&out.along_mean_m, &out.along_abs_m, &out.across_mean_m, &out.across_abs_m,
                      &out.error_m, &out.nees}) {
      *v /= out.n;
    }
  }
  out.across_walk = run.pipeline->counters().legs_across_walk;
  out.side_uncertain = run.pipeline->counters().legs_side_uncertain;
  out.side_from_view = run.pipeline->counters().legs_side_from_view;
  out.side_view_contested = run.pipeline->counters().legs_side_view_contested;
  return out;
}

std::string Describe(const OneLegWalk& w) {
  return "along mean " + std::to_string(w.along_mean_m) + " m (|.| " +
         std::to_string(w.along_abs_m) + "), across mean " + std::to_string(w.across_mean_m) +
         " m (|.| " + std::to_string(w.across_abs_m) + "), error " + std::to_string(w.error_m) +
         " m, NEES " + std::to_string(w.nees) + " (" + std::to_string(w.n) + "), across the walk " +
         std::to_string(w.across_walk) + " (side uncertain " + std::to_string(w.side_uncertain) +
         ", from the view " + std::to_string(w.side_from_view) + ", view contested " +
         std::to_string(w.side_view_contested) + ")";
}

// ShapeOptions::single_leg_from_standing: walking along x at 1.2 m/s, the left leg (+y) stood at
// (0, 0.09) at the last two-leg measurement 0.1 s ago and the right one is seen swinging at
// (0.15, -0.09): the standing knee now at 0.06 m (half the body's 0.12 m), the centre 0.6 of the
// way from the seen leg to it along the walk: 0.6 0.06 + 0.4 0.15 = 0.096 m; across the walk the
// seen leg's (the hip is added by the caller). Variance along the walk: 0.36 (0.0004 + 0.03^2)
// + 0.16 0.0009 + 0.05^2.
TEST(PipelineScenarioTest, LoneLegCentreFromTheStandingLegAlongTheWalk) {
  ShapeOptions o;
  o.stance_leg_weight = 0.6;
  o.gait_sigma_m = 0.05;
  double var = 0.0;
  const Eigen::Vector2d c = internal::LoneLegCentreFromStanding(
      o, {1.0, 0.0}, {1.2, 0.0}, {0.15, -0.09}, 0.0009, {0.0, 0.09}, 0.0004, 0.1, &var);
  EXPECT_NEAR(c.x(), 0.096, 1e-12);
  EXPECT_NEAR(c.y(), -0.09, 1e-12);
  EXPECT_NEAR(var, 0.36 * (0.0004 + 0.0009) + 0.16 * 0.0009 + 0.0025, 1e-12);
  // No time since: the standing knee where it was, nothing carried.
  const Eigen::Vector2d now = internal::LoneLegCentreFromStanding(
      o, {1.0, 0.0}, {1.2, 0.0}, {0.15, -0.09}, 0.0009, {0.0, 0.09}, 0.0004, 0.0, &var);
  EXPECT_NEAR(now.x(), 0.06, 1e-12);
  EXPECT_NEAR(var, 0.36 * 0.0004 + 0.16 * 0.0009 + 0.0025, 1e-12);
}

// A walker going straight away from the sensor along x at 1.2 m/s, legs side by side across the
// line of sight; a screen near the sensor hides the right leg (y < 0) for 5 scans out of every 17
// (0.2 s of 0.68 s, at every phase of the ~1.1 s gait cycle over the walk). The reported centre's
// error along the walk while the screen stands, with and without
// ShapeOptions::single_leg_from_standing.
struct HiddenLegWindows {
  double along_abs_m = 0.0, along_rms_m = 0.0, nees = 0.0;
  int n = 0;
  std::uint64_t from_standing = 0;
};
HiddenLegWindows WalkWithOneLegHiddenAtTimes(bool from_standing) {
  Scene scene;
  scene.legs = true;
  scene.walls = {{{15.0, -7.0}, {15.0, 7.0}},
                 {{-2.0, 7.0}, {15.0, 7.0}},
                 {{-2.0, -7.0}, {15.0, -7.0}},
                 {{-2.0, 7.0}, {-2.0, -7.0}}};
  const double start_s = kLearnedS;
  scene.walkers = {Walker::Path(start_s, {{2.0, 0.0}, {9.0, 0.0}}, 1.2)};
  auto screened = [start_s](double t_s) {
    if (t_s < start_s + 1.0) return false;
    const auto k = static_cast<long>(std::floor((t_s - start_s) * kRateHz + 0.5));
    return k % 17 < 5;
  };
  scene.moving_walls = [screened](double t_s) {
    return screened(t_s) ? std::vector<Wall>{{{0.6, -1.5}, {0.6, -0.002}}} : std::vector<Wall>{};
  };
  TrackerOptions options = LegsOptions();
  options.shape.single_leg_from_standing = from_standing;
  const SceneRun run = Simulate(scene, scene.walkers[0].end_s() + 0.2, options);
  HiddenLegWindows out;
  for (const Frame& f : run.frames) {
    if (!f.truth[0] || !screened(f.t_s)) continue;
    for (const TrackReport& r : f.tracks) {
      const Eigen::Vector2d e = Position(r) - *f.truth[0];
      if (r.state != TrackState::kConfirmed || e.norm() > 0.4) continue;
      out.along_abs_m += std::abs(e.x());
      out.along_rms_m += e.x() * e.x();
      out.nees += e.dot(r.covariance.topLeftCorner<2, 2>().ldlt().solve(e));
      ++out.n;
    }
  }
  if (out.n > 0) {
    out.along_abs_m /= out.n;
    out.along_rms_m = std::sqrt(out.along_rms_m / out.n);
    out.nees /= out.n;
  }
  out.from_standing = run.pipeline->counters().legs_along_from_standing;
  return out;
}

std::string Describe(const HiddenLegWindows& w) {
  return "along |.| " + std::to_string(w.along_abs_m) + " m, RMS " + std::to_string(w.along_rms_m) +
         " m, NEES " + std::to_string(w.nees) + " (" + std::to_string(w.n) + "), from standing " +
         std::to_string(w.from_standing);
}

TEST(PipelineScenarioTest, LoneLegCentreAlongTheWalkFromTheStandingLeg) {
  const HiddenLegWindows before = WalkWithOneLegHiddenAtTimes(false);
  const HiddenLegWindows after = WalkWithOneLegHiddenAtTimes(true);
  SCOPED_TRACE(RecordBeforeAfter(Describe(before), Describe(after)));
  // Measured: before along RMS 0.0285 m, after 0.0216 m (35 screened scans, 12 from standing).
  ASSERT_GT(before.n, 30);
  ASSERT_GT(after.n, 30);
  EXPECT_EQ(before.from_standing, 0u);
  EXPECT_GT(after.from_standing, 10u);
  EXPECT_LT(after.along_rms_m, before.along_rms_m - 0.005);
  EXPECT_LT(after.nees, 3.0);
}

// ShapeOptions::single_leg_side_uncertainty: the likelier side's weight and the other side's
// variance (known answers).
TEST(PipelineScenarioTest, SingleLegSideWeightIsTheTwoSidesMixture) {
  // hip 0.1 m, offset 0.1 m, s^2 0.01 m^2: tanh(1) = 0.761594.
  EXPECT_NEAR(internal::SingleLegSideWeight(0.1, 0.1, 0.01), 0.761594, 1e-6);
  EXPECT_NEAR(internal::SingleLegSideWeight(0.1, -0.1, 0.01), 0.761594, 1e-6);
  // A prediction certain to 2 cm: the side is sure.
  EXPECT_GT(internal::SingleLegSideWeight(0.1, 0.1, 0.0004), 0.9999);
  EXPECT_EQ(internal::SingleLegSideWeight(0.1, 0.0, 0.01), 0.0);
  EXPECT_EQ(internal::SingleLegSideWeight(0.1, 0.05, 0.0), 1.0);
  // The second moment about the likelier side: (2 hip)^2 (1 - q), q = (1 + w) / 2.
  EXPECT_NEAR(internal::SingleLegOtherSideVar(0.1, 0.761594), 0.04 * (1.0 - 0.880797), 1e-6);
  EXPECT_EQ(internal::SingleLegOtherSideVar(0.1, 1.0), 0.0);
  EXPECT_NEAR(internal::SingleLegOtherSideVar(0.1, 0.0), 0.02, 1e-12);
  EXPECT_NEAR(internal::SingleLegOtherSideVar(0.1, -1.0), 0.02, 1e-12);
  // The counting threshold: w = 0.95 is q = 0.975 (the other side 2.5 %), reached at
  // hip |offset| / s^2 = atanh(0.95) = 1.831781; hip 0.1 m, offset 0.1 m: s^2 = 0.01 / 1.831781.
  EXPECT_NEAR(0.5 * (1.0 + internal::kSideKnownWeight), 0.975, 1e-12);
  EXPECT_NEAR(internal::SingleLegSideWeight(0.1, 0.1, 0.01 / 1.831781), 0.95, 1e-6);
  EXPECT_LT(internal::SingleLegSideWeight(0.1, 0.1, 0.01 / 1.82), internal::kSideKnownWeight);
  EXPECT_GT(internal::SingleLegSideWeight(0.1, 0.1, 0.01 / 1.84), internal::kSideKnownWeight);
}

// ShapeOptions::stance_leg_weight: walking along x, the left leg (+y) moved 0.02 m since the last
// two-leg measurement and the right one swung 0.1 m forward: the centre lies 0.6 of the way from
// the swinging leg to the standing one. The legs are matched to the last ones by their side,
// whatever their order.
TEST(PipelineScenarioTest, StanceWeightedCentreWeighsTheStandingLegAlongTheWalk) {
  ShapeOptions o;
  const Eigen::Vector2d forward(1.0, 0.0);
  const std::array<Eigen::Vector2d, 2> last{Eigen::Vector2d(0.0, 0.1), Eigen::Vector2d(-0.2, -0.1)};
  const std::array<Eigen::Vector2d, 2> now{Eigen::Vector2d(-0.1, -0.1), Eigen::Vector2d(0.02, 0.1)};
  const std::array<double, 2> sure{1e-4, 1e-4};
  const internal::StanceCentre c =
      internal::StanceWeightedCentre(o, forward, now, sure, last, sure, 0.04, 0.05);
  EXPECT_EQ(c.standing, 1);
  EXPECT_NEAR(c.weight, 0.6, 1e-6);  // tanh(0.05 * 0.08 / 4e-4) = tanh(10)
  EXPECT_NEAR(c.centre_m.x(), 0.6 * 0.02 + 0.4 * -0.1, 1e-6);
  EXPECT_NEAR(c.centre_m.y(), 0.6 * 0.1 + 0.4 * -0.1, 1e-6);
  // The same with the legs' noise: tanh(0.05 * 0.08 / 0.004) = tanh(1) of the way to 0.6.
  const std::array<double, 2> noisy{1e-3, 1e-3};
  const internal::StanceCentre n =
      internal::StanceWeightedCentre(o, forward, now, noisy, last, noisy, 0.04, 0.05);
  EXPECT_EQ(n.standing, 1);
  EXPECT_NEAR(n.weight, 0.5 + 0.1 * 0.761594, 1e-6);
  EXPECT_NEAR(n.centre_m.x(), -0.1 + n.weight * 0.12, 1e-6);
  EXPECT_NEAR(n.centre_m.y(), -0.1 + n.weight * 0.2, 1e-6);
  // Legs that moved alike (both standing): the midpoint; a last measurement too old, or the
  // option at 0.5: the midpoint, no leg taken as standing.
  const std::array<Eigen::Vector2d, 2> alike{Eigen::Vector2d(-0.18, -0.1),
                                             Eigen::Vector2d(0.02, 0.1)};
  const internal::StanceCentre both =
      internal::StanceWeightedCentre(o, forward, alike, sure, last, sure, 0.04, 0.05);
  EXPECT_NEAR(both.weight, 0.5, 1e-6);
  EXPECT_NEAR(both.centre_m.x(), -0.08, 1e-6);
  EXPECT_NEAR(both.centre_m.y(), 0.0, 1e-6);
  EXPECT_EQ(internal::StanceWeightedCentre(o, forward, now, sure, last, sure, 0.2, 0.25).standing,
            -1);
  ShapeOptions off = o;
  off.stance_leg_weight = 0.5;
  const internal::StanceCentre mid =
      internal::StanceWeightedCentre(off, forward, now, sure, last, sure, 0.04, 0.05);
  EXPECT_EQ(mid.standing, -1);
  EXPECT_NEAR(mid.centre_m.x(), -0.04, 1e-12);
  EXPECT_NEAR(mid.centre_m.y(), 0.0, 1e-12);
}

// A walker at knee height: the legs' midpoint runs ahead of and behind the hip with the gait (the
// swinging leg farther from it than the standing one); weighted towards the standing leg the
// measured centre, and the track, stay nearer the body centre along the walk.
TEST(PipelineScenarioTest, TwoLegsWeightedTowardsTheStandingLegFollowTheBodyCentre) {
  Scene scene;
  scene.legs = true;
  scene.walkers = {Walker::Path(kLearnedS, {{2.0, -4.0}, {4.5, 3.5}}, 1.3)};
  const Walker& walker = scene.walkers[0];
  const auto along_rms = [&](const TrackerOptions& options, std::uint64_t* weighted) {
    const SceneRun run = Simulate(scene, walker.end_s() + 1.0, options);
    double sum2 = 0.0, n = 0.0;
    for (const Frame& fr : run.frames) {
      if (fr.t_s < walker.start_s() + 1.0 || fr.t_s > walker.end_s() || fr.tracks.size() != 1 ||
          !fr.truth[0]) {
        continue;
      }
      const Eigen::Vector2d v = walker.VelocityAt(fr.t_s);
      if (!(v.norm() > 0.5)) continue;
      const double e = (Position(fr.tracks[0]) - *fr.truth[0]).dot(v.normalized());
      sum2 += e * e;
      n += 1.0;
    }
    *weighted = run.pipeline->counters().stance_weighted_pairs;
    return n > 0.0 ? std::sqrt(sum2 / n) : 1.0;
  };
  std::uint64_t weighted = 0, weighted_off = 0;
  const double rms = along_rms(LegsOptions(), &weighted);
  TrackerOptions off = LegsOptions();
  off.shape.stance_leg_weight = 0.5;
  const double rms_off = along_rms(off, &weighted_off);
  EXPECT_GT(weighted, 100u);
  EXPECT_EQ(weighted_off, 0u);
  EXPECT_LT(rms, 0.9 * rms_off) << rms << " vs " << rms_off;
}

TEST(PipelineScenarioTest, OneLegOfAWalkerIsMeasuredAsTheCentreAcrossTheWalk) {
  for (const bool mirrored : {false, true}) {
    const OneLegWalk before = WalkWithOneLegSeen(false, mirrored);
    const OneLegWalk after = WalkWithOneLegSeen(true, mirrored);
    const double side = mirrored ? -1.0 : 1.0;
    SCOPED_TRACE(std::string(mirrored ? "right leg seen" : "left leg seen") +
                 "; before: " + Describe(before) + "; after: " + Describe(after));
    RecordProperty("before", Describe(before));
    RecordProperty("after", Describe(after));
    ASSERT_GT(before.n, 60);
    ASSERT_GT(after.n, 60);
    EXPECT_EQ(before.across_walk, 0u);
    EXPECT_GT(after.across_walk, 60u);
    // Before: the track follows the leg it sees, the hip (0.09 m) to that side of the centre.
    EXPECT_GT(side * before.across_mean_m, 0.05);
    // After: the centre, across the walk and along it over every phase of the stride.
    EXPECT_LT(std::abs(after.across_mean_m), 0.03);
    EXPECT_LT(after.across_abs_m, 0.035);
    EXPECT_LT(std::abs(after.along_mean_m), 0.05);
    EXPECT_LT(after.error_m, before.error_m - 0.03);
    EXPECT_GT(after.nees, 0.2);
    EXPECT_LT(after.nees, 3.0);
  }
}

// ShapeOptions::single_leg_side_uncertainty on the walker of WalkWithOneLegSeen whose right (or
// left) leg is hidden from 0.3 s or 1.5 s after the start, the side taken from the prediction
// (single_leg_side_from_view off: here the view tells every side): a young track's prediction is
// less sure across the walk; where the hip offset is not sure against it (the other side more
// likely than 2.5 %) the scan is counted and its covariance across the walk widened by the other
// side's share, never narrowed; the same scans are measured across the walk, and the positions stay
// within millimetres of taking every side as sure.
TEST(PipelineScenarioTest, OneLegSideIsWeighedAgainstThePredictionsError) {
  for (const bool mirrored : {false, true}) {
    for (const double screen_from_s : {0.3, 1.5}) {
      const OneLegWalk sure = WalkWithOneLegSeen(true, mirrored, false, screen_from_s, 0.0, false);
      const OneLegWalk weighed =
          WalkWithOneLegSeen(true, mirrored, true, screen_from_s, 0.0, false);
      SCOPED_TRACE(std::string(mirrored ? "right leg seen" : "left leg seen") + " from " +
                   std::to_string(screen_from_s) + " s; sure: " + Describe(sure) +
                   "; weighed: " + Describe(weighed));
      ASSERT_GT(sure.n, 60);
      EXPECT_EQ(weighed.n, sure.n);
      EXPECT_GT(weighed.side_uncertain, 0u);
      EXPECT_LT(weighed.side_uncertain, weighed.across_walk);
      EXPECT_EQ(weighed.across_walk, sure.across_walk);
      EXPECT_LT(weighed.nees, sure.nees);
      EXPECT_NEAR(weighed.error_m, sure.error_m, 0.002);
      EXPECT_LT(std::abs(weighed.across_mean_m), 0.03);
    }
  }
}

// ShapeOptions::single_leg_side_from_view: the walker's right leg hidden by the screen from 0.1 s
// after the start (a track born while both legs were seen only briefly). From the prediction alone
// the track settles on the seen left leg (a hip to the left of the centre) and no side is told
// from it, or (the mirrored walk) takes the wrong side and grows sure of it, fed its own
// measurements there (two hips off); the scan sees through every place the other leg could stand
// left of the seen one (the far wall behind), not right of it (the screen): the centre is on the
// right.
TEST(PipelineScenarioTest, OneLegSideIsTakenFromWhereTheScanSeesThrough) {
  for (const bool mirrored : {false, true}) {
    const OneLegWalk prediction = WalkWithOneLegSeen(true, mirrored, true, 0.1, 0.5, false);
    const OneLegWalk view = WalkWithOneLegSeen(true, mirrored, true, 0.1, 0.5, true);
    SCOPED_TRACE(std::string(mirrored ? "right leg seen" : "left leg seen") +
                 "; prediction: " + Describe(prediction) + "; view: " + Describe(view));
    ASSERT_GT(view.n, 60);
    ASSERT_GT(prediction.n, 60);
    // From the prediction alone: a hip (0.1 m) or two off across the walk, towards the seen leg
    // (on it, or with the centre confidently on the wrong side of it).
    const double side = mirrored ? -1.0 : 1.0;
    EXPECT_GT(side * prediction.across_mean_m, 0.05);
    // From the view: the centre, at least 3 cm better on average; where a confident prediction
    // contests the view's side, only for a few scans (the view's side, weighed, brings it over).
    EXPECT_LT(view.error_m, prediction.error_m - 0.03);
    EXPECT_GT(view.side_from_view, 60u);
    EXPECT_LT(view.side_view_contested, 5u);
    EXPECT_LT(std::abs(view.across_mean_m), 0.03);
    EXPECT_LT(view.error_m, 0.09);
    EXPECT_GT(view.nees, 0.2);
    EXPECT_LT(view.nees, 3.0);
  }
}

// ShapeOptions::single_leg_side_from_view beyond 2 leg_radius_m / beam_divergence_rad (8 m with
// beam_divergence_rad 0.015): the same walker from 9.5 m to 13.5 m, one leg hidden from 1.5 s; a
// beam's footprint there is wider than a leg, a leg at the other side's places need not have
// returned a beam, and the side comes from the prediction alone.
TEST(PipelineScenarioTest, OneLegSideIsNotTakenFromTheViewBeyondALegsFootprint) {
  const OneLegWalk far = WalkWithOneLegSeen(true, false, true, 1.5, 0.5, true, 9.5, 13.5, 0.015);
  SCOPED_TRACE("far: " + Describe(far));
  EXPECT_GT(far.across_walk, 10u);
  EXPECT_EQ(far.side_from_view, 0u);
  EXPECT_EQ(far.side_view_contested, 0u);
}

// A person walking away from the sensor along the x axis to 11 m, where they stand (legs side by
// side across the line of sight, 0.06 m apart): at 0.5 deg (0.096 m between beams) each leg
// returns one or two beams, and where no beam falls between them both legs make one segment of
// two or three points, wider across the ray than a leg. The standing person's error (confirmed
// tracks from 0.5 s after the stop), with or without ShapeOptions::split_few_point_legs, over
// lateral offsets that move the beams across the legs.
struct StandingRuns : ConfirmedError {
  std::uint64_t counted = 0;               // the pipeline counter chosen, summed over the runs
  std::vector<Eigen::Vector2d> positions;  // every report's, in the runs' order
};

// A person at knee height in a 17 x 14 m room walking from `from_m` (once the background is
// learned) to `to_m` in 2 s and standing there for 3 s; the stop at kWalkAndStandStopS.
constexpr double kWalkAndStandStopS = kLearnedS + 2.0;
SceneRun WalkAndStandAtKneeHeight(const Eigen::Vector2d& from_m, const Eigen::Vector2d& to_m,
                                  const TrackerOptions& options) {
  Scene scene;
  scene.legs = true;
  scene.walls = {{{15.0, -7.0}, {15.0, 7.0}},
                 {{-2.0, 7.0}, {15.0, 7.0}},
                 {{-2.0, -7.0}, {15.0, -7.0}},
                 {{-2.0, 7.0}, {-2.0, -7.0}}};
  const double stop_s = kWalkAndStandStopS;
  scene.walkers = {Walker({{kLearnedS, from_m}, {stop_s, to_m}, {stop_s + 3.0, to_m}})};
  return Simulate(scene, stop_s + 3.0, options);
}

// WalkAndStandAtKneeHeight from each walk's start to its end with LegsOptions() as `configure`
// sets them, scored from `score_from_s` after the stop; `counter` summed into counted.
StandingRuns StandAtKneeHeight(
    const std::vector<std::pair<Eigen::Vector2d, Eigen::Vector2d>>& walks, double score_from_s,
    const std::function<void(TrackerOptions&)>& configure,
    std::uint64_t PipelineCounters::*counter) {
  StandingRuns out;
  for (const auto& [from_m, to_m] : walks) {
    TrackerOptions options = LegsOptions();
    configure(options);
    const SceneRun run = WalkAndStandAtKneeHeight(from_m, to_m, options);
    out.Add(run, kWalkAndStandStopS + score_from_s, 0.4);
    out.counted += run.pipeline->counters().*counter;
    for (const Frame& f : run.frames) {
      for (const TrackReport& r : f.tracks) out.positions.push_back(Position(r));
    }
  }
  out.Mean();
  return out;
}

std::string Describe(const StandingRuns& s, const std::string& counted) {
  return "error " + std::to_string(s.error_m) + " m, NEES " + std::to_string(s.nees) + " (" +
         std::to_string(s.n) + "), " + counted + " " + std::to_string(s.counted);
}

StandingRuns StandFarAtKneeHeight(bool split) {
  std::vector<std::pair<Eigen::Vector2d, Eigen::Vector2d>> walks;
  for (const double y : {0.0, 0.02, 0.04, 0.06, 0.08}) walks.push_back({{9.0, y}, {11.0, y}});
  return StandAtKneeHeight(
      walks, 0.5, [split](TrackerOptions& o) { o.shape.split_few_point_legs = split; },
      &PipelineCounters::split_few_point_legs);
}

TEST(PipelineScenarioTest, TwoLegsSideBySideInOneFewPointSegmentAreMeasuredAsAPair) {
  const StandingRuns before = StandFarAtKneeHeight(false);
  const StandingRuns after = StandFarAtKneeHeight(true);
  SCOPED_TRACE(RecordBeforeAfter(Describe(before, "split"), Describe(after, "split")));
  ASSERT_GT(before.n, 200);
  ASSERT_GT(after.n, 200);
  EXPECT_EQ(before.counted, 0u);
  EXPECT_GT(after.counted, 50u);
  // Before: one circle through both legs' beams; now the legs' midpoint, within what the
  // covariance says.
  EXPECT_LT(after.error_m, before.error_m - 0.01);
  EXPECT_LT(after.error_m, 0.04);
  EXPECT_GT(after.nees, 0.2);
  EXPECT_LT(after.nees, 3.0);
}

TEST(PipelineScenarioTest, DeepLegExcessDepthIsWhatLiesBeyondOneLegsVisibleHalf) {
  const ShapeOptions o = LegsOptions().shape;
  // Nearest at 6 m: one leg spans at most 0.06 + 2 x 0.015 + 3 (0.015 + 0.0002 x 6) = 0.1386 m.
  const std::array<Eigen::Vector2d, 2> deep = {Eigen::Vector2d(6.0, 0.0),
                                               Eigen::Vector2d(6.25, 0.0)};
  EXPECT_NEAR(internal::DeepLegExcessDepth(o, deep), 0.25 - 0.1386, 1e-9);
  const std::array<Eigen::Vector2d, 2> leg = {Eigen::Vector2d(6.0, 0.0),
                                              Eigen::Vector2d(6.1, 0.05)};
  EXPECT_EQ(internal::DeepLegExcessDepth(o, leg), 0.0);
  EXPECT_EQ(internal::DeepLegExcessDepth(o, std::span(deep).first(1)), 0.0);
}

// A person walking across the line of sight at knee height, 6-9 m out at 0.5 deg: one leg stands
// behind the other along the ray (the hip across the walk), and where a beam grazes both, or the
// far leg shows past the near one's edge, a segment of two or three points spreads deeper along
// the ray than one leg. The confirmed track's error and NEES with or without
// ShapeOptions::deep_legs_as_pair.
struct CrossingDeep : ConfirmedError {
  std::uint64_t deep_pairs = 0;
};
CrossingDeep CrossAtKneeHeight(bool deep) {
  CrossingDeep out;
  for (const double x : {6.0, 7.0, 8.0, 9.0}) {
    Scene scene;
    scene.legs = true;
    scene.walkers = {Walker::Path(kLearnedS, {{x, -4.0}, {x, 4.0}}, 1.3)};
    TrackerOptions options = LegsOptions();
    options.shape.deep_legs_as_pair = deep;
    const SceneRun run = Simulate(scene, scene.walkers[0].end_s(), options);
    out.Add(run, 0.0, 0.5);
    out.deep_pairs += run.pipeline->counters().deep_leg_pairs;
  }
  out.Mean();
  return out;
}

std::string Describe(const CrossingDeep& c) {
  return "error " + std::to_string(c.error_m) + " m, NEES " + std::to_string(c.nees) + " (" +
         std::to_string(c.n) + "), deep pairs " + std::to_string(c.deep_pairs);
}

TEST(PipelineScenarioTest, ADeepFewPointLegOfAConfirmedTrackIsMeasuredAsItsTwoLegs) {
  const CrossingDeep before = CrossAtKneeHeight(false);
  const CrossingDeep after = CrossAtKneeHeight(true);
  SCOPED_TRACE(RecordBeforeAfter(Describe(before), Describe(after)));
  ASSERT_GT(before.n, 200);
  ASSERT_GT(after.n, 200);
  EXPECT_EQ(before.deep_pairs, 0u);
  EXPECT_GT(after.deep_pairs, 10u);
  EXPECT_LT(after.error_m, before.error_m);
  // (With the standing leg weighted, shape.stance_leg_weight, the pairs' error is smaller than
  // the gait allowance they are reported with.)
  EXPECT_GT(after.nees, 0.15);
  EXPECT_LT(after.nees, 3.0);
}

// ShapeOptions::touching_legs_along_ray: two legs with no beam between them (the second part
// starting at or before the first's end beam), not a deep pair, add leg_radius_m^2 / 3 along the
// ray (the farther leg's centre uniform within +-2 leg_radius_m, the midpoint's a quarter).
TEST(PipelineScenarioTest, TouchingLegsAlongRayVarIsTheFartherLegsDiameterOnTheMidpoint) {
  ShapeOptions o;
  o.leg_radius_m = 0.06;
  ObservationPart first, second;
  first.begin_beam = 4;
  first.end_beam = 10;
  second.begin_beam = 10;
  second.end_beam = 14;
  EXPECT_DOUBLE_EQ(internal::TouchingLegsAlongRayVar(o, first, second, false), 0.0012);
  second.begin_beam = 11;  // one beam between them: separated
  EXPECT_EQ(internal::TouchingLegsAlongRayVar(o, first, second, false), 0.0);
  second.begin_beam = 10;
  EXPECT_EQ(internal::TouchingLegsAlongRayVar(o, first, second, true), 0.0);  // a deep pair
  o.leg_radius_m = 0.05;
  EXPECT_DOUBLE_EQ(internal::TouchingLegsAlongRayVar(o, first, second, false), 0.0025 / 3.0);
  o.touching_legs_along_ray = false;
  EXPECT_EQ(internal::TouchingLegsAlongRayVar(o, first, second, false), 0.0);
}

// A person walking towards the sensor and standing at 8-9 m, legs side by side across the line of
// sight (0.06 m apart, the beams 0.07-0.08 m): the legs often touch in the scan. Confirmed tracks
// from 0.5 s after the stop, with or without ShapeOptions::touching_legs_along_ray.
struct StandingTouching : ConfirmedError {
  std::uint64_t touching = 0;
};
StandingTouching StandWithTouchingLegs(bool along_ray) {
  StandingTouching out;
  for (const double y : {0.0, 0.02, 0.04}) {
    for (const double x : {8.0, 9.0}) {
      TrackerOptions options = LegsOptions();
      options.shape.touching_legs_along_ray = along_ray;
      const SceneRun run = WalkAndStandAtKneeHeight({x + 2.5, y}, {x, y}, options);
      out.Add(run, kWalkAndStandStopS + 0.5, 0.4);
      out.touching += run.pipeline->counters().touching_leg_pairs;
    }
  }
  out.Mean();
  return out;
}

std::string Describe(const StandingTouching& s) {
  return "error " + std::to_string(s.error_m) + " m, NEES " + std::to_string(s.nees) + " (" +
         std::to_string(s.n) + "), touching " + std::to_string(s.touching);
}

TEST(PipelineScenarioTest, TouchingLegsAreMeasuredWithTheFartherLegsDepthAlongTheRay) {
  const StandingTouching before = StandWithTouchingLegs(false);
  const StandingTouching after = StandWithTouchingLegs(true);
  SCOPED_TRACE(RecordBeforeAfter(Describe(before), Describe(after)));
  ASSERT_GT(before.n, 200);
  ASSERT_GT(after.n, 200);
  EXPECT_EQ(before.touching, 0u);
  EXPECT_GT(after.touching, 50u);
  // The covariance along the ray grows (the error as small as before), within what it says.
  EXPECT_LT(after.nees, before.nees);
  EXPECT_LT(after.error_m, before.error_m + 0.005);
  EXPECT_GT(after.nees, 0.1);
  EXPECT_LT(after.nees, 3.0);
}

// ShapeOptions::still_legs_cov: two legs still where each, matched to the last two in the order
// that moved them less, lies within the 99 % bound (9.21 times the summed variances) of where it
// stood, at most stance_memory_s before.
TEST(PipelineScenarioTest, LegsStillWithinTheFitsBoundOfWhereTheyStood) {
  ShapeOptions o;
  o.stance_memory_s = 0.15;
  const std::array<Eigen::Vector2d, 2> last{Eigen::Vector2d(4.0, -0.1), Eigen::Vector2d(4.0, 0.1)};
  const std::array<double, 2> var{1e-4, 1e-4};  // bound: 9.21 * 2e-4, a 0.043 m step
  const std::array<Eigen::Vector2d, 2> near{Eigen::Vector2d(4.02, 0.1),
                                            Eigen::Vector2d(4.0, -0.13)};  // swapped, 2-3 cm
  EXPECT_TRUE(internal::LegsStill(o, near, var, last, var, 0.04));
  EXPECT_FALSE(internal::LegsStill(o, near, var, last, var, 0.2));  // beyond stance_memory_s
  EXPECT_FALSE(internal::LegsStill(o, near, var, last, var, 0.0));
  const std::array<Eigen::Vector2d, 2> stepped{Eigen::Vector2d(4.0, -0.1),
                                               Eigen::Vector2d(3.95, 0.1)};  // one leg 5 cm
  EXPECT_FALSE(internal::LegsStill(o, stepped, var, last, var, 0.04));
  const std::array<double, 2> wide{2e-4, 2e-4};  // bound: a 0.061 m step
  EXPECT_TRUE(internal::LegsStill(o, stepped, wide, last, wide, 0.04));
}

// A person walking towards the sensor and standing at 4-5 m, legs side by side across the line of
// sight (clear of each other in the scan). Confirmed tracks from 1 s after the stop, with or
// without ShapeOptions::still_legs_cov: the same positions, reported as they are off.
StandingRuns StandStillAtKneeHeight(bool still_cov) {
  std::vector<std::pair<Eigen::Vector2d, Eigen::Vector2d>> walks;
  for (const double y : {-0.5, 0.0, 0.4}) {
    for (const double x : {4.0, 5.0}) walks.push_back({{x + 2.5, y}, {x, y}});
  }
  return StandAtKneeHeight(
      walks, 1.0, [still_cov](TrackerOptions& o) { o.shape.still_legs_cov = still_cov; },
      &PipelineCounters::still_leg_pairs);
}

TEST(PipelineScenarioTest, StillLegsAreReportedWithoutTheGaitAndTheUnrealisedAcceleration) {
  const StandingRuns before = StandStillAtKneeHeight(false);
  const StandingRuns after = StandStillAtKneeHeight(true);
  const std::string still = "still pairs";
  SCOPED_TRACE(RecordBeforeAfter(Describe(before, still), Describe(after, still)));
  ASSERT_GT(before.n, 200);
  EXPECT_EQ(before.counted, 0u);
  EXPECT_GT(after.counted, 100u);
  // The tracks are the same; only the reported covariance shrinks towards the error.
  ASSERT_EQ(after.positions.size(), before.positions.size());
  for (std::size_t i = 0; i < after.positions.size(); ++i) {
    ASSERT_EQ(after.positions[i], before.positions[i]) << i;
  }
  EXPECT_EQ(after.n, before.n);
  EXPECT_LT(before.nees, 0.5);
  EXPECT_GT(after.nees, 2.0 * before.nees);
  EXPECT_LT(after.nees, 3.0);
}

// ShapeOptions::walking_legs_cov: one person at a time walking at knee height (1.2 m/s) across
// the line of sight at 4 and 6 m, obliquely and towards the sensor, both legs seen in most scans.
// The same tracks with and without it; on its scans the report narrows towards the error (the
// gait allowance the filter's gains average, 5 cm per scan, is reported as the stance-weighted
// midpoint's offset that successive scans share), and the reports of every other scan are the
// filter's covariance as before: a leg that stands alone or a pair that is not walking starts
// the reported covariance again from the filter's.
TEST(PipelineScenarioTest, WalkingLegsAreReportedWithTheGaitAsAnOffsetScansShare) {
  const std::vector<std::vector<Eigen::Vector2d>> paths = {{{4.0, -4.0}, {4.0, 4.0}},
                                                           {{6.0, 4.0}, {6.0, -4.0}},
                                                           {{2.0, -3.0}, {8.0, 3.0}},
                                                           {{10.0, 0.5}, {2.5, 0.5}}};
  // Pairs of reports that differ: their NEES with the old and the new covariance, summed.
  int relieved = 0, same = 0, narrower = 0;
  double nees_old = 0.0, nees_new = 0.0;
  ConfirmedError before, after;
  for (const auto& path : paths) {
    Scene scene;
    scene.legs = true;
    scene.walkers = {Walker::Path(kLearnedS, path, 1.2)};
    const double end_s = kLearnedS + (path[1] - path[0]).norm() / 1.2;
    TrackerOptions options = LegsOptions();
    options.shape.walking_legs_cov = false;
    const SceneRun old = Simulate(scene, end_s, options);
    options.shape.walking_legs_cov = true;
    const SceneRun run = Simulate(scene, end_s, options);
    before.Add(old, kLearnedS + 1.0, 0.4);
    after.Add(run, kLearnedS + 1.0, 0.4);
    ForEachReportPair(run, old, [&](std::size_t k, const TrackReport& r, const TrackReport& o) {
      const Eigen::Matrix2d c = r.covariance.topLeftCorner<2, 2>();
      const Eigen::Matrix2d c_old = o.covariance.topLeftCorner<2, 2>();
      if ((c - c_old).norm() < 1e-12) {
        ++same;
        return;
      }
      ++relieved;
      // Narrower, but where a track's first walking scans took less of the gait allowance out of
      // the gains' covariance than the shared offset adds.
      if (c.trace() < c_old.trace()) ++narrower;
      if (!run.frames[k].truth[0]) return;
      const Eigen::Vector2d e = Position(r) - *run.frames[k].truth[0];
      nees_new += e.dot(c.inverse() * e);
      nees_old += e.dot(c_old.inverse() * e);
    });
  }
  before.Mean();
  after.Mean();
  const std::string text = "before: error " + std::to_string(before.error_m) + " m, NEES " +
                           std::to_string(before.nees) + "; after: NEES " +
                           std::to_string(after.nees) + "; reports narrowed " +
                           std::to_string(relieved) + " (" + std::to_string(narrower) +
                           " narrower; NEES " + std::to_string(nees_old) + " -> " +
                           std::to_string(nees_new) + " summed), same " + std::to_string(same);
  SCOPED_TRACE(text);
  RecordProperty("result", text);
  ASSERT_GT(before.n, 300);
  EXPECT_EQ(after.n, before.n);
  // Most of a walk's reports narrow; those before the track walks and after a lone leg do not.
  EXPECT_GT(relieved, before.n / 2);
  EXPECT_GT(same, 10);
  EXPECT_GT(narrower, 9 * relieved / 10);
  // The gait allowance was most of the reported covariance: the narrowed reports' NEES grows by
  // half at least, and the whole stays honest (2 for 2 dof).
  EXPECT_GT(nees_new, 1.5 * nees_old);
  EXPECT_GT(after.nees, 1.3 * before.nees);
  EXPECT_LT(after.nees, 3.0);
}

// Six people crossing the room one after another (1.5 s apart, alternating directions), of the
// sizes given (upper body) or as legs.
Scene SixCrossing(std::vector<Eigen::Vector2d> sizes, bool legs) {
  Scene scene;
  scene.legs = legs;
  scene.sizes = std::move(sizes);
  for (int i = 0; i < 6; ++i) {
    const double x = 2.0 + 0.9 * i, y = i % 2 == 0 ? -4.0 : 4.0;
    scene.walkers.push_back(Walker::Path(kLearnedS + 1.5 * i, {{x, y}, {x + 0.5, -y}}, 1.2));
  }
  return scene;
}

// The mount check as the tracker's gateway runs it (common::MountWatch) over a run's reports.
common::MountCheck MountCheckOf(const SceneRun& run) {
  common::MountWatch<kMaxTracks, 32> watch;
  for (const Frame& f : run.frames) {
    for (const TrackReport& r : f.tracks) {
      if (r.state != TrackState::kConfirmed || r.shape == ObjectShape::kBox ||
          r.shape == ObjectShape::kLegs) {
        continue;
      }
      watch.Add(r.track_id, std::hypot(r.vx_mps, r.vy_mps),
                std::min(r.size_major_m, r.size_minor_m));
    }
    watch.EndScan();
  }
  watch.EndScan();  // every track ends with the run
  return watch.verdict();
}

TEST(PipelineScenarioTest, MountCheckFindsLegsUnderAnUpperBodyMountAndNothingElse) {
  const Scene legs = SixCrossing({}, true);
  const double end_s = legs.walkers.back().end_s() + 1.0;
  // Knee height, configured as upper body (the default): the torso fit settles on a leg's size.
  const common::MountCheck wrong = MountCheckOf(Simulate(legs, end_s, Synthetic()));
  EXPECT_TRUE(wrong.decided) << wrong.tracks;
  EXPECT_TRUE(wrong.looks_like_legs)
      << wrong.leg_sized << " of " << wrong.tracks << ", median " << wrong.median_half_width_m;
  RecordProperty("legs_as_torso", std::to_string(wrong.leg_sized) + " of " +
                                      std::to_string(wrong.tracks) + " leg-sized, median " +
                                      std::to_string(wrong.median_half_width_m));
  // Configured for legs: the reports are legs, which the check leaves alone.
  const common::MountCheck right_legs = MountCheckOf(Simulate(legs, end_s, LegsOptions()));
  EXPECT_FALSE(right_legs.decided);
  EXPECT_FALSE(right_legs.looks_like_legs);
  // Upper body at upper-body height: people of varying size and a child (0.15 x 0.09 m).
  const Scene torso = SixCrossing(
      {{0.25, 0.15}, {0.15, 0.09}, {0.22, 0.13}, {0.27, 0.16}, {0.2, 0.12}, {0.24, 0.14}}, false);
  const common::MountCheck right = MountCheckOf(Simulate(torso, end_s, Synthetic()));
  EXPECT_TRUE(right.decided) << right.tracks;
  EXPECT_FALSE(right.looks_like_legs)
      << right.leg_sized << " of " << right.tracks << ", median " << right.median_half_width_m;
  EXPECT_GT(right.median_half_width_m, wrong.median_half_width_m + 0.03);
  RecordProperty("torso", std::to_string(right.leg_sized) + " of " + std::to_string(right.tracks) +
                              " leg-sized, median " + std::to_string(right.median_half_width_m));
}

// A box (a forklift, a trolley) of half-lengths half_x_m, half_y_m along the axes, whose centre
// moves from `from` to `to` at speed_mps once the background is learned, added to the scene's
// moving walls.
struct MovingBox {
  double start_s = 0.0, end_s = 0.0;
  std::function<std::optional<Eigen::Vector2d>(double)> centre_at;  // nullopt outside its run
};

MovingBox AddMovingBox(Scene& scene, const Eigen::Vector2d& from, const Eigen::Vector2d& to,
                       double speed_mps, double half_x_m, double half_y_m) {
  MovingBox box;
  box.start_s = kLearnedS;
  box.end_s = box.start_s + (to - from).norm() / speed_mps;
  box.centre_at = [=, start_s = box.start_s,
                   end_s = box.end_s](double t_s) -> std::optional<Eigen::Vector2d> {
    if (t_s < start_s || t_s > end_s) return std::nullopt;
    return from + (t_s - start_s) / (end_s - start_s) * (to - from);
  };
  scene.moving_walls = [centre_at = box.centre_at, half_x_m, half_y_m](double t_s) {
    const auto c = centre_at(t_s);
    if (!c) return std::vector<Wall>{};
    const Eigen::Vector2d u(0.0, half_y_m), v(half_x_m, 0.0);
    return std::vector<Wall>{{*c + u + v, *c - u + v},
                             {*c - u + v, *c - u - v},
                             {*c - u - v, *c + u - v},
                             {*c + u - v, *c + u + v}};
  };
  return box;
}

TEST(PipelineScenarioTest, ForkliftAtFourMetresPerSecondNeedsTheLimitsRaised) {
  // A 1.2 x 0.8 m forklift crossing the room at 4 m/s.
  Scene scene;
  const MovingBox box = AddMovingBox(scene, {4.5, -4.0}, {4.5, 4.5}, 4.0, 0.4, 0.6);
  const auto& centre_at = box.centre_at;
  const double start_s = box.start_s, end_s = box.end_s;
  const auto follow = [&](const TrackerOptions& options, std::set<std::uint32_t>* ids) {
    const SceneRun run = Simulate(scene, end_s + 0.5, options);
    double error_sum = 0.0;
    int matched = 0, frames = 0;
    for (const Frame& f : run.frames) {
      const auto c = centre_at(f.t_s);
      if (!c || f.t_s < start_s + 0.4) continue;
      ++frames;
      for (const TrackReport& r : f.tracks) {
        if ((Position(r) - *c).norm() > 0.5) continue;
        ids->insert(r.track_id);
        error_sum += (Position(r) - *c).norm();
        ++matched;
        break;
      }
    }
    EXPECT_GT(frames, 40);
    return std::make_pair(matched, matched > 0 ? error_sum / matched : 1.0);
  };
  TrackerOptions forklift_site = Synthetic();
  forklift_site.tracking.max_speed_mps = 6.0;
  forklift_site.tracking.ekf.accel_psd_m2ps3 = 2.0;
  forklift_site.tracking.ekf.initial_velocity_sigma_mps = 4.0;
  forklift_site.tracking.max_gate_distance_m = 1.5;
  forklift_site.segmentation.max_width_m = 1.8;
  std::set<std::uint32_t> ids;
  const auto [matched, mean_error] = follow(forklift_site, &ids);
  EXPECT_EQ(ids.size(), 1u);
  EXPECT_GT(matched, 40);
  // Seen from its side, the box's depth shows only at its ends: the centre is off by part of it.
  EXPECT_LT(mean_error, 0.2);
  // With the walking defaults it is not followed as one object (without split_deep_tail: cutting
  // off the box's receding end kept it at 0.14 m there).
  TrackerOptions walking = Synthetic();
  walking.shape.split_deep_tail = false;
  std::set<std::uint32_t> walking_ids;
  const auto [walking_matched, walking_error] = follow(walking, &walking_ids);
  EXPECT_TRUE(walking_ids.size() != 1 || walking_matched < matched / 2 || walking_error > 0.15)
      << walking_ids.size() << " ids, " << walking_matched << " matched, " << walking_error;
}

// ShapeOptions::box_rejoin_pieces: a 1.2 x 0.7 m trolley passing obliquely at 0.8 m/s shows an
// outline up to 1.3 m across the ray, which the segmentation's width limit (1.0 m) cuts in two;
// on a confirmed box track's predicted rectangle the pieces are one observation again, without
// they start person-sized tracks beside the trolley's.
struct TrolleyPieces {
  int frames = 0;        // scans with the trolley in view, after its first second
  int extra_scans = 0;   // confirmed reports within 1.5 m of it other than the nearest one
  double error_m = 0.0;  // mean distance of the nearest confirmed report within 0.5 m
  std::uint64_t rejoined = 0;
};

TrolleyPieces PassTrolley(bool rejoin) {
  Scene scene;
  const MovingBox box = AddMovingBox(scene, {5.3, -4.2}, {5.3, 0.0}, 0.8, 0.35, 0.6);
  const auto& centre_at = box.centre_at;
  const double start_s = box.start_s, end_s = box.end_s;
  TrackerOptions options = Synthetic();
  options.shape.box_rejoin_pieces = rejoin;
  const SceneRun run = Simulate(scene, end_s + 0.2, options);
  TrolleyPieces out;
  int matched = 0;
  for (const Frame& f : run.frames) {
    const auto c = centre_at(f.t_s);
    if (!c || f.t_s < start_s + 1.0) continue;
    ++out.frames;
    double nearest = 1e9;
    int near = 0;
    for (const TrackReport& r : f.tracks) {
      if (r.state != TrackState::kConfirmed) continue;
      const double d = (Position(r) - *c).norm();
      if (d > 1.5) continue;
      ++near;
      nearest = std::min(nearest, d);
    }
    if (near > 1) out.extra_scans += near - 1;
    if (nearest <= 0.5) {
      out.error_m += nearest;
      ++matched;
    }
  }
  if (matched > 0) out.error_m /= matched;
  out.rejoined = run.pipeline->counters().box_pieces_rejoined;
  return out;
}

TEST(PipelineTest, InsideGrownBoxIsInsideTheRectangleGrownOnEverySide) {
  // A box centred at (5, 1), half-lengths 0.6 along yaw 90 degrees (y) and 0.35 across (x).
  const Eigen::Vector2d c(5.0, 1.0), size(0.6, 0.35);
  const double yaw = common::kPi / 2;
  const std::array<Eigen::Vector2d, 2> corner = {Eigen::Vector2d(5.34, 1.59),
                                                 Eigen::Vector2d(4.66, 0.41)};
  EXPECT_TRUE(internal::InsideGrownBox(c, size, yaw, 0.0, corner));
  const std::array<Eigen::Vector2d, 2> beyond_end = {Eigen::Vector2d(5.0, 1.0),
                                                     Eigen::Vector2d(5.0, 1.75)};
  EXPECT_FALSE(internal::InsideGrownBox(c, size, yaw, 0.1, beyond_end));
  EXPECT_TRUE(internal::InsideGrownBox(c, size, yaw, 0.2, beyond_end));
  const std::array<Eigen::Vector2d, 1> beyond_side = {Eigen::Vector2d(5.5, 1.0)};
  EXPECT_FALSE(internal::InsideGrownBox(c, size, yaw, 0.1, beyond_side));
  EXPECT_TRUE(internal::InsideGrownBox(c, size, yaw, 0.2, beyond_side));
  EXPECT_FALSE(internal::InsideGrownBox(c, size, yaw, 1.0, std::span<const Eigen::Vector2d>()));
}

TEST(PipelineScenarioTest, AnObliqueTrolleysPiecesOnItsPredictedOutlineAreOneObservation) {
  const TrolleyPieces before = PassTrolley(false), after = PassTrolley(true);
  const auto describe = [](const TrolleyPieces& t) {
    return "frames " + std::to_string(t.frames) + ", extra " + std::to_string(t.extra_scans) +
           ", error " + std::to_string(t.error_m) + ", rejoined " + std::to_string(t.rejoined);
  };
  SCOPED_TRACE("before: " + describe(before) + "; after: " + describe(after));
  EXPECT_EQ(before.rejoined, 0u);
  EXPECT_GT(after.rejoined, 0u);
  EXPECT_LT(after.extra_scans, before.extra_scans);
}

// ShapeOptions::split_see_through: two people walking side by side towards the sensor from 7 m to
// 3 m, 0.6 m apart (centre to centre) across the line of sight, their bodies 0.5 m across: from
// about 4 m on one or two beams pass between them to the wall behind, which the segmentation
// joins across (max_missing_beams 2). Cut there, each keeps a track of its own on its body; as
// one segment, one track stands between the two.
struct SideBySide {
  int frames = 0;        // scans with both in view, after the first second
  int both_held = 0;     // ... with a confirmed report within 0.15 m of each, two ids
  double error_m = 0.0;  // mean distance of each one's nearest confirmed report (within 0.5 m)
  std::size_t ids = 0;   // confirmed ids ever reported within 0.5 m of either
  std::uint64_t splits = 0;
  std::uint64_t seams = 0;  // ShapeOptions::split_step_seam
};

// `behind_m`: the second walks that much farther from the sensor; `apart_m`: across the line of
// sight, centre to centre.
SideBySide WalkSideBySide(bool split, bool seam = true, double behind_m = 0.0, double apart_m = 0.6,
                          bool hidden_far_piece = true) {
  Scene scene;
  scene.walkers = {
      Walker::Path(kLearnedS, {{7.0, -1.3}, {3.0, -1.3}}, 1.0),
      Walker::Path(kLearnedS, {{7.0 + behind_m, -1.3 + apart_m}, {3.0 + behind_m, -1.3 + apart_m}},
                   1.0)};
  TrackerOptions options = Synthetic();
  options.shape.split_see_through = split;
  options.shape.split_step_seam = seam;
  options.shape.step_seam.hidden_far_piece = hidden_far_piece;
  const SceneRun run = Simulate(scene, kLearnedS + 4.2, options);
  SideBySide out;
  std::set<std::uint32_t> ids;
  int matched = 0;
  for (const Frame& f : run.frames) {
    if (!f.truth[0] || !f.truth[1] || f.t_s < kLearnedS + 1.0) continue;
    ++out.frames;
    std::array<std::uint32_t, 2> held{};
    std::array<double, 2> nearest{1e9, 1e9};
    for (std::size_t w = 0; w < 2; ++w) {
      for (const TrackReport& r : f.tracks) {
        if (r.state != TrackState::kConfirmed) continue;
        const double d = (Position(r) - *f.truth[w]).norm();
        if (d <= 0.5) ids.insert(r.track_id);
        if (d < nearest[w]) {
          nearest[w] = d;
          held[w] = r.track_id;
        }
      }
      if (nearest[w] <= 0.5) {
        out.error_m += nearest[w];
        ++matched;
      }
    }
    if (nearest[0] <= 0.15 && nearest[1] <= 0.15 && held[0] != held[1]) ++out.both_held;
  }
  if (matched > 0) out.error_m /= matched;
  out.ids = ids.size();
  out.splits = run.pipeline->counters().see_through_splits;
  out.seams = run.pipeline->counters().step_seam_splits;
  return out;
}

TEST(PipelineScenarioTest, PeopleSideBySideWithBeamsBetweenThemKeepATrackEach) {
  const SideBySide before = WalkSideBySide(false), after = WalkSideBySide(true);
  const auto describe = [](const SideBySide& t) {
    return "frames " + std::to_string(t.frames) + ", both held " + std::to_string(t.both_held) +
           ", error " + std::to_string(t.error_m) + ", ids " + std::to_string(t.ids) + ", splits " +
           std::to_string(t.splits);
  };
  SCOPED_TRACE("before: " + describe(before) + "; after: " + describe(after));
  EXPECT_EQ(before.splits, 0u);
  EXPECT_GT(after.splits, 0u);
  // As one segment (before: 11 of 76 scans, 0.26 m, 4 ids) the track stands between them.
  EXPECT_LT(before.both_held, before.frames / 2);
  EXPECT_GT(before.error_m, 0.1);
  // Cut (75 of 76 scans, 0.02 m, 2 ids): each one's track on its body throughout.
  EXPECT_GE(after.both_held, after.frames * 9 / 10);
  EXPECT_LT(after.error_m, 0.05);
  EXPECT_EQ(after.ids, 2u);
}

// ShapeOptions::split_step_seam: the same walk, the second 0.2 m behind the first and 0.5 m
// beside it: the farther one's near shoulder lies behind the nearer one's edge on most scans, no
// beam passes between them (the see-through cut finds nothing), only the range steps. Cut at the
// step, each keeps a track of its own (before: 0 of 76 scans, 0.42 m; after: 75, 0.02 m).
TEST(PipelineScenarioTest, PeopleSideBySideWithNoBeamBetweenThemKeepATrackEach) {
  const SideBySide before = WalkSideBySide(true, false, 0.2, 0.5);
  const SideBySide after = WalkSideBySide(true, true, 0.2, 0.5);
  const auto describe = [](const SideBySide& t) {
    return "frames " + std::to_string(t.frames) + ", both held " + std::to_string(t.both_held) +
           ", error " + std::to_string(t.error_m) + ", ids " + std::to_string(t.ids) + ", seams " +
           std::to_string(t.seams);
  };
  SCOPED_TRACE("before: " + describe(before) + "; after: " + describe(after));
  EXPECT_EQ(before.seams, 0u);
  EXPECT_GT(after.seams, 0u);
  EXPECT_LT(before.both_held, before.frames / 2);
  EXPECT_GT(before.error_m, 0.1);
  EXPECT_GE(after.both_held, after.frames * 9 / 10);
  EXPECT_LT(after.error_m, 0.05);
  EXPECT_EQ(after.ids, 2u);
}

// ShapeOptions::step_seam_size_guard: a 0.9 x 0.6 m cart pushed towards the sensor from 7.5 m to
// 2.5 m at 0.9 m/s, a person walking beside it (0.5 m nearer the line of sight, 0.4 m ahead).
// The tracker learns the cart as a person first, its semi-axis growing towards
// box_min_half_length_m; cut from the person at the range step, its piece stays person-sized and
// a third track appears beside the two (without the guard: 62 cuts, 52 such scans; with it: 0
// cuts, 0 scans), the cart's own error as without the cut.
struct CartAndWalker {
  int frames = 0;
  int cart_held = 0, walker_held = 0;  // scans with a confirmed report within 0.5 m
  int extra_scans = 0;  // confirmed reports within 1 m of the cart nearest to neither
  double cart_error_m = 0.0;
  std::uint64_t seams = 0;
};

CartAndWalker PushCartBesideWalker(bool guard) {
  Scene scene;
  const MovingBox box = AddMovingBox(scene, {7.5, 1.0}, {2.5, 1.0}, 0.9, 0.45, 0.3);
  scene.walkers = {Walker::Path(kLearnedS, {{7.9, 0.5}, {2.9, 0.5}}, 0.9)};
  TrackerOptions options = Synthetic();
  options.shape.step_seam_size_guard = guard;
  // The step seam's guard alone (split_deep_tail cuts such a segment before the step seam sees it).
  options.shape.split_deep_tail = false;
  const SceneRun run = Simulate(scene, box.end_s, options);
  CartAndWalker out;
  for (const Frame& f : run.frames) {
    const auto c = box.centre_at(f.t_s);
    if (!c || !f.truth[0] || f.t_s < box.start_s + 1.0) continue;
    ++out.frames;
    const TrackReport* cart = nullptr;
    const TrackReport* walker = nullptr;
    for (const TrackReport& r : f.tracks) {
      if (r.state != TrackState::kConfirmed) continue;
      if (!cart || (Position(r) - *c).norm() < (Position(*cart) - *c).norm()) cart = &r;
      if (!walker ||
          (Position(r) - *f.truth[0]).norm() < (Position(*walker) - *f.truth[0]).norm()) {
        walker = &r;
      }
    }
    if (cart && (Position(*cart) - *c).norm() <= 0.5) {
      ++out.cart_held;
      out.cart_error_m += (Position(*cart) - *c).norm();
    }
    if (walker && (Position(*walker) - *f.truth[0]).norm() <= 0.5) ++out.walker_held;
    for (const TrackReport& r : f.tracks) {
      if (r.state == TrackState::kConfirmed && &r != cart && &r != walker &&
          (Position(r) - *c).norm() < 1.0) {
        ++out.extra_scans;
      }
    }
  }
  if (out.cart_held > 0) out.cart_error_m /= out.cart_held;
  out.seams = run.pipeline->counters().step_seam_splits;
  return out;
}

TEST(PipelineScenarioTest, ACartLearnedAsAPersonIsNotCutFromThePersonBesideIt) {
  const CartAndWalker before = PushCartBesideWalker(false), after = PushCartBesideWalker(true);
  const auto describe = [](const CartAndWalker& t) {
    return "frames " + std::to_string(t.frames) + ", cart held " + std::to_string(t.cart_held) +
           ", walker held " + std::to_string(t.walker_held) + ", extra " +
           std::to_string(t.extra_scans) + ", cart error " + std::to_string(t.cart_error_m) +
           ", seams " + std::to_string(t.seams);
  };
  SCOPED_TRACE("before: " + describe(before) + "; after: " + describe(after));
  EXPECT_GT(before.seams, 20u);
  EXPECT_EQ(after.seams, 0u);
  EXPECT_GT(before.extra_scans, 20);
  EXPECT_LT(after.extra_scans, before.extra_scans / 4);
  EXPECT_GE(after.cart_held, before.cart_held);
  EXPECT_LE(after.cart_error_m, before.cart_error_m + 0.01);
  EXPECT_GE(after.walker_held, before.walker_held - 2);
}

// ShapeOptions::box_unseen_depth_cov: a box's (semi-axes 0.6 along yaw 90 deg, 0.35 across)
// centre covariance with the isotropic size term 0.06^2; its half-width b not shown: along x
// (axis b) the variance becomes max(size state's 0.01^2, 0.2^2), along y it stays; with a shown
// as well nothing changes; a size state less certain than 0.2 m counts as it is.
TEST(PipelineTest, BoxUnseenCentreCovIsTheUnseenSemiAxisAlongItsAxis) {
  const double floor_var = 0.06 * 0.06;
  const Eigen::Matrix2d cov = (0.01 * 0.01 + floor_var) * Eigen::Matrix2d::Identity();
  const Eigen::Matrix2d size_cov = 0.01 * 0.01 * Eigen::Matrix2d::Identity();
  const double yaw = common::kPi / 2;
  const Eigen::Matrix2d b_unseen =
      internal::BoxUnseenCentreCov(cov, floor_var, size_cov, yaw, {true, false}, 0.2);
  EXPECT_NEAR(b_unseen(0, 0), 0.01 * 0.01 + 0.2 * 0.2, 1e-12);
  EXPECT_NEAR(b_unseen(1, 1), cov(1, 1), 1e-12);
  EXPECT_NEAR(b_unseen(0, 1), 0.0, 1e-12);
  const Eigen::Matrix2d both =
      internal::BoxUnseenCentreCov(cov, floor_var, size_cov, yaw, {true, true}, 0.2);
  EXPECT_TRUE(both.isApprox(cov));
  Eigen::Matrix2d wide_size = size_cov;
  wide_size(1, 1) = 0.3 * 0.3;
  const Eigen::Matrix2d wide =
      internal::BoxUnseenCentreCov(cov, floor_var, wide_size, yaw, {true, false}, 0.2);
  EXPECT_NEAR(wide(0, 0), 0.01 * 0.01 + 0.3 * 0.3, 1e-12);
}

// ShapeOptions::box_unseen_depth_cov: a 1.2 x 0.7 m trolley pushed along y at x = 5.3 m is seen
// on its long side near y = 0, its depth (x, along the ray) not shown: the reported sigma along
// x is at least box_unseen_sigma_m (0.2 m) there; without, the size floor's (0.06 m) and the
// filter's.
double TrolleyBroadsideSigmaX(bool unseen_cov, bool seen_extent_cov, std::uint64_t* widened,
                              std::uint64_t* bounded = nullptr) {
  Scene scene;
  const MovingBox box = AddMovingBox(scene, {5.3, -4.2}, {5.3, 0.0}, 0.8, 0.35, 0.6);
  TrackerOptions options = Synthetic();
  options.shape.box_unseen_depth_cov = unseen_cov;
  options.shape.box_seen_extent_cov = seen_extent_cov;
  // The box's own covariance alone (split_deep_tail keeps the trolley's receding face off its fit
  // until it is a box: after 0.210 -> 0.199 m).
  options.shape.split_deep_tail = false;
  const SceneRun run = Simulate(scene, box.end_s + 0.2, options);
  double var = 0.0;
  int n = 0;
  for (const Frame& f : run.frames) {
    const auto c = box.centre_at(f.t_s);
    if (!c || f.t_s < box.start_s + 1.0 || c->y() < -1.0) continue;
    for (const TrackReport& r : f.tracks) {
      if (r.state != TrackState::kConfirmed || r.shape != ObjectShape::kBox) continue;
      if ((Position(r) - *c).norm() > 0.5) continue;
      var += r.covariance(0, 0);
      ++n;
    }
  }
  *widened = run.pipeline->counters().box_unseen_widened;
  if (bounded != nullptr) *bounded = run.pipeline->counters().box_semi_axes_bounded;
  return n > 0 ? std::sqrt(var / n) : 0.0;
}

TEST(PipelineScenarioTest, ABroadsideTrolleysUnseenDepthIsInItsReportedCovariance) {
  std::uint64_t widened_before = 0, widened_after = 0;
  const double before = TrolleyBroadsideSigmaX(false, false, &widened_before);
  const double after = TrolleyBroadsideSigmaX(true, false, &widened_after);
  SCOPED_TRACE("sigma x before " + std::to_string(before) + ", after " + std::to_string(after));
  EXPECT_EQ(widened_before, 0u);
  EXPECT_GT(widened_after, 0u);
  EXPECT_GT(before, 0.0);
  EXPECT_LT(before, 0.15);
  EXPECT_GE(after, 0.2);
}

// ShapeOptions::box_size_from_faces_seen_at_knee: a 1.2 x 0.7 m cart with a shelf at knee height
// pushed at 0.8 m/s across the sensor's view along y at x = 5 m (its long side shown, its width
// not), then straight at the sensor along x (end-on, its front shown, its length not). Returns
// the mean error along the line of sight of its confirmed box track within 1 m of it over the
// end-on leg (negative: nearer than the cart's centre) and sets *matches. Measured: -0.54 m (26
// matches) learning both semi-axes from every fit (the width shrinks to 0.01 m while only the
// side shows, the length while only the front does), -0.16 m (64) with the option.
double KneeCartEndOnRadialError(bool faces_seen_at_knee, int* matches) {
  Scene scene;
  scene.legs = true;
  const double start_s = kLearnedS, speed = 0.8;
  const Eigen::Vector2d a(5.0, -3.0), b(5.0, 0.5), last(1.8, 0.5);
  const double turn_s = start_s + (b - a).norm() / speed;
  const double end_s = turn_s + (last - b).norm() / speed;
  // Centre and unit heading at t_s (nullopt outside the run).
  const auto pose = [=](double t_s) -> std::optional<std::pair<Eigen::Vector2d, Eigen::Vector2d>> {
    if (t_s < start_s || t_s > end_s) return std::nullopt;
    if (t_s < turn_s) {
      return std::make_pair(Eigen::Vector2d(a + (t_s - start_s) * speed * (b - a).normalized()),
                            Eigen::Vector2d((b - a).normalized()));
    }
    return std::make_pair(Eigen::Vector2d(b + (t_s - turn_s) * speed * (last - b).normalized()),
                          Eigen::Vector2d((last - b).normalized()));
  };
  scene.moving_walls = [pose](double t_s) {
    std::vector<Wall> walls;
    const auto p = pose(t_s);
    if (!p) return walls;
    const Eigen::Vector2d u = 0.6 * p->second,
                          v = 0.35 * Eigen::Vector2d(-p->second.y(), p->second.x());
    const Eigen::Vector2d& c = p->first;
    walls = {{c + u + v, c - u + v},
             {c - u + v, c - u - v},
             {c - u - v, c + u - v},
             {c + u - v, c + u + v}};
    return walls;
  };
  TrackerOptions options = Synthetic();
  options.shape.mount = Mount::kLegs;
  options.shape.box_size_from_faces_seen_at_knee = faces_seen_at_knee;
  const SceneRun run = Simulate(scene, end_s + 0.2, options);
  double radial = 0.0;
  *matches = 0;
  for (const Frame& f : run.frames) {
    const auto p = pose(f.t_s);
    if (!p || f.t_s < turn_s + 1.0) continue;
    for (const TrackReport& r : f.tracks) {
      if (r.state != TrackState::kConfirmed || r.shape != ObjectShape::kBox) continue;
      const Eigen::Vector2d e = Position(r) - p->first;
      if (e.norm() > 1.0) continue;
      radial += e.dot(p->first.normalized());
      ++*matches;
    }
  }
  return *matches > 0 ? radial / *matches : 0.0;
}

TEST(PipelineScenarioTest, AKneeHeightCartSeenEndOnKeepsTheLengthItShowedBroadside) {
  int before_n = 0, after_n = 0;
  const double before = KneeCartEndOnRadialError(false, &before_n);
  const double after = KneeCartEndOnRadialError(true, &after_n);
  SCOPED_TRACE("radial mean before " + std::to_string(before) + " (" + std::to_string(before_n) +
               "), after " + std::to_string(after) + " (" + std::to_string(after_n) + ")");
  ASSERT_GT(before_n, 20);
  ASSERT_GT(after_n, 20);
  EXPECT_LT(before, -0.3);
  EXPECT_GT(after, -0.2);
  EXPECT_LT(after, 0.1);
}

// ShapeOptions::box_seen_extent_cov: the same trolley, coming into view obliquely (its front end
// towards the sensor, seen whole between two silhouette ends) before it passes broadside: its
// half-width b, the depth along x at broadside, was seen whole in those views; the reported sigma
// along x is no longer at least box_unseen_sigma_m there (it was, taking only the scan at hand).
TEST(PipelineScenarioTest, ABoxsDepthSeenWholeBeforeIsNotWidenedWhereTheScanHidesIt) {
  std::uint64_t widened_before = 0, widened_after = 0, bounded_before = 0, bounded_after = 0;
  const double before = TrolleyBroadsideSigmaX(true, false, &widened_before, &bounded_before);
  const double after = TrolleyBroadsideSigmaX(true, true, &widened_after, &bounded_after);
  SCOPED_TRACE("sigma x before " + std::to_string(before) + ", after " + std::to_string(after) +
               ", bounded " + std::to_string(bounded_after));
  EXPECT_EQ(bounded_before, 0u);
  EXPECT_GT(bounded_after, 0u);
  EXPECT_GE(before, 0.2);
  EXPECT_GT(after, 0.0);
  EXPECT_LT(after, 0.19);  // the filter's own sigma along x is about 0.15 m here
}

// ShapeOptions::box_seen_extent_cov: points along a box's axis at yaw 30 deg, from -0.5 to +0.3 m
// along it and 0.1 m to one side: half extents 0.4 along, 0 across. A semi-axis never seen whole:
// uniform between max(seen, 0.2) and 0.9: seen 0.35 gives (0.55)^2 / 12, seen 0.1 (0.7)^2 / 12,
// seen beyond the prior's largest 0; seen whole: the state's squared difference from it.
// BoxSeenCentreCov: the bias in every direction and per axis the largest of the floor, the size
// state's variance and the unbounded semi-axis's.
TEST(PipelineTest, BoxHalfVarIsTheUniformBetweenWhatWasSeenAndThePriorsLargest) {
  const double yaw = common::kPi / 6;
  const Eigen::Vector2d e1(std::cos(yaw), std::sin(yaw)), e2(-e1.y(), e1.x());
  const Eigen::Vector2d c(4.0, 1.0);
  const std::array<Eigen::Vector2d, 3> points = {c - 0.5 * e1 + 0.1 * e2, c + 0.1 * e2,
                                                 c + 0.3 * e1 + 0.1 * e2};
  const Eigen::Vector2d half = internal::BoxHalfExtents(points, yaw);
  EXPECT_NEAR(half.x(), 0.4, 1e-12);
  EXPECT_NEAR(half.y(), 0.0, 1e-12);
  EXPECT_TRUE(internal::BoxHalfExtents(std::span<const Eigen::Vector2d>(), yaw).isZero());
  EXPECT_NEAR(internal::BoxHalfVar(0.35, 0.0, 0.5, 0.2, 0.9), 0.55 * 0.55 / 12.0, 1e-12);
  EXPECT_NEAR(internal::BoxHalfVar(0.1, 0.0, 0.5, 0.2, 0.9), 0.7 * 0.7 / 12.0, 1e-12);
  EXPECT_EQ(internal::BoxHalfVar(1.0, 0.0, 0.5, 0.2, 0.9), 0.0);
  // Seen whole at 0.58, the state says 0.43: (0.15)^2.
  EXPECT_NEAR(internal::BoxHalfVar(0.58, 0.58, 0.43, 0.2, 0.9), 0.15 * 0.15, 1e-12);
  // Bias 0.03 m; floor 0.06 m; size state 0.01 m along a, 0.08 m along b; a unbounded (0.2 m).
  const Eigen::Matrix2d size_cov = Eigen::Vector2d(0.01 * 0.01, 0.08 * 0.08).asDiagonal();
  const Eigen::Matrix2d cov =
      internal::BoxSeenCentreCov(0.03 * 0.03, 0.06 * 0.06, size_cov, yaw, {0.2 * 0.2, 0.0});
  EXPECT_NEAR(e1.dot(cov * e1), 0.03 * 0.03 + 0.2 * 0.2, 1e-12);
  EXPECT_NEAR(e2.dot(cov * e2), 0.03 * 0.03 + 0.08 * 0.08, 1e-12);
  EXPECT_NEAR(e1.dot(cov * e2), 0.0, 1e-12);
  const Eigen::Matrix2d bounded =
      internal::BoxSeenCentreCov(0.03 * 0.03, 0.06 * 0.06, size_cov, yaw, {0.0, 0.0});
  EXPECT_NEAR(e1.dot(bounded * e1), 0.03 * 0.03 + 0.06 * 0.06, 1e-12);
}

// HalfExtentsAlong (the segment excess's and the box's extents) forms both projections of a point
// at once: bit for bit the half ranges of the two dot products p.dot(e1) and p.dot(e2), over random
// point sets of 1 to 40 points in random directions (where multiply-adds are not fused).
TEST(PipelineTest, HalfExtentsAlongAreTheDotProductsHalfRangesBitForBit) {
  std::mt19937 rng(20261129);
  std::uniform_real_distribution<double> coordinate(-8.0, 8.0), angle(-common::kPi, common::kPi);
  std::vector<Eigen::Vector2d> points;
  for (int trial = 0; trial < 400; ++trial) {
    points.resize(static_cast<std::size_t>(1 + trial % 40));
    for (Eigen::Vector2d& p : points) p = Eigen::Vector2d(coordinate(rng), coordinate(rng));
    const double a = angle(rng);
    const Eigen::Vector2d e1(std::cos(a), std::sin(a)), e2(-e1.y(), e1.x());
    double lo1 = std::numeric_limits<double>::infinity(), lo2 = lo1, hi1 = -lo1, hi2 = -lo1;
    for (const Eigen::Vector2d& p : points) {
      lo1 = std::min(lo1, p.dot(e1));
      hi1 = std::max(hi1, p.dot(e1));
      lo2 = std::min(lo2, p.dot(e2));
      hi2 = std::max(hi2, p.dot(e2));
    }
    const Eigen::Vector2d half = internal::HalfExtentsAlong(points, e1);
#ifdef __FP_FAST_FMA
    // Fused multiply-adds (aarch64) may fuse either product of a sum: up to its rounding.
    const double tol = 64.0 * std::numeric_limits<double>::epsilon();
    ASSERT_NEAR(half.x(), 0.5 * (hi1 - lo1), tol) << trial;
    ASSERT_NEAR(half.y(), 0.5 * (hi2 - lo2), tol) << trial;
#else
    ASSERT_EQ(half.x(), 0.5 * (hi1 - lo1)) << trial;
    ASSERT_EQ(half.y(), 0.5 * (hi2 - lo2)) << trial;
#endif
  }
}

// NearestOtherSquares (each measurement's nearest other, ShapeOptions::neighbour_sigma_m) takes two
// pairs at a time and the odd one alone: against each point's squared distance to every other,
// for 0 to 9 points (odd and even counts) on a coarse grid (equal distances and coincident points)
// and off it, from infinity and from lower values kept where no other point is nearer.
TEST(PipelineTest, NearestOtherSquaresAreTheLeastSquaredDistanceToAnotherPoint) {
  std::mt19937 rng(20261129);
  std::uniform_int_distribution<int> cell(-3, 3);
  std::uniform_real_distribution<double> coordinate(-8.0, 8.0), start(0.0, 40.0);
  constexpr double kInf = std::numeric_limits<double>::infinity();
  for (int trial = 0; trial < 2000; ++trial) {
    const std::size_t n = static_cast<std::size_t>(trial % 10);
    const bool grid = trial % 3 == 0;
    const bool from_inf = trial % 4 != 1;
    std::vector<double> x(n), y(n), out(n), expected(n);
    for (std::size_t i = 0; i < n; ++i) {
      x[i] = grid ? 0.5 * cell(rng) : coordinate(rng);
      y[i] = grid ? 0.5 * cell(rng) : coordinate(rng);
      out[i] = expected[i] = from_inf ? kInf : start(rng);
    }
    for (std::size_t i = 0; i < n; ++i) {
      for (std::size_t k = 0; k < n; ++k) {
        if (k == i) continue;
        const double dx = x[k] - x[i], dy = y[k] - y[i];
        expected[i] = std::min(expected[i], dx * dx + dy * dy);
      }
    }
    internal::NearestOtherSquares(x, y, out);
    for (std::size_t i = 0; i < n; ++i) {
      if (n == 1 && from_inf) {
        ASSERT_EQ(out[i], kInf) << trial;  // no other point
      }
#ifdef __FP_FAST_FMA
      // Fused multiply-adds (aarch64) may fuse either product of a sum: up to its rounding (the
      // squares up to 512 m^2); infinity (no other point nearer) exactly.
      if (std::isinf(expected[i])) {
        ASSERT_EQ(out[i], expected[i]) << trial << " " << i;
      } else {
        ASSERT_NEAR(out[i], expected[i], 1e-12) << trial << " " << i;
      }
#else
      ASSERT_EQ(out[i], expected[i]) << trial << " " << i;
#endif
    }
  }
}

// NearestAlong (the nearest point along a part's ray) takes two points at a time and the odd one
// alone: against std::min over start and each point's p.dot(ray), for 0 to 9 points (odd and even
// counts), the least one at every position in turn (the last of an odd count alone), ties and
// a start below all of them.
TEST(PipelineTest, NearestAlongIsTheLeastProjectionOrStart) {
  std::mt19937 rng(20261130);
  std::uniform_real_distribution<double> coordinate(-8.0, 8.0), angle(-common::kPi, common::kPi);
  std::vector<Eigen::Vector2d> points;
  for (int trial = 0; trial < 2000; ++trial) {
    const std::size_t n = static_cast<std::size_t>(trial % 10);
    points.resize(n);
    for (Eigen::Vector2d& p : points) p = Eigen::Vector2d(coordinate(rng), coordinate(rng));
    const double a = angle(rng);
    const Eigen::Vector2d ray(std::cos(a), std::sin(a));
    if (n > 0) {
      // The least projection at position trial / 10 % n: that point moved 30 m against the ray
      // (the others' projections lie within 8 sqrt(2) m of 0), a tie where it is copied onto
      // another.
      const std::size_t least = static_cast<std::size_t>(trial / 10) % n;
      points[least] -= 30.0 * ray;
      if (n > 1 && trial % 7 == 0) points[(least + 1) % n] = points[least];
    }
    const double start = trial % 5 == 0 ? -50.0 : 12.0;  // below every projection, or above some
    double expected = start;
    for (const Eigen::Vector2d& p : points) expected = std::min(expected, p.dot(ray));
    const double nearest = internal::NearestAlong(points, ray, start);
#ifdef __FP_FAST_FMA
    ASSERT_NEAR(nearest, expected, 64.0 * std::numeric_limits<double>::epsilon()) << trial;
#else
    ASSERT_EQ(nearest, expected) << trial;
#endif
  }
}

// ShapeOptions::box_drop_occluders: the points of a box's near end (x = 4.55, the box centred at
// (5, 0), 0.9 x 0.6 m along x) are kept, a pusher's two legs 0.35 m in front of it are not, and
// where the segment ends on them that silhouette end is no longer the box's.
TEST(PipelineTest, BoxUnoccludedPointsLeavesOutWhatStandsInFrontOfTheBox) {
  ShapeOptions o;
  std::vector<Eigen::Vector2d> points;
  for (int i = 0; i <= 12; ++i) points.emplace_back(4.55, -0.28 + 0.04 * i);  // the near end
  points.emplace_back(4.2, 0.05);  // a leg in front of it, at the segment's last point
  std::vector<Eigen::Vector2d> kept(points.size());
  Silhouette silhouette;
  silhouette.first_valid = silhouette.last_valid = true;
  const std::size_t n = internal::BoxUnoccludedPoints(
      o, Eigen::Vector2d(5.0, 0.0), Eigen::Vector2d(0.45, 0.3), 0.0, points, kept, &silhouette);
  EXPECT_EQ(n, 13u);
  for (std::size_t i = 0; i < n; ++i) EXPECT_EQ(kept[i], points[i]);
  EXPECT_TRUE(silhouette.first_valid);
  EXPECT_FALSE(silhouette.last_valid);
  // A leg in the middle of the face: dropped, both ends stay silhouettes.
  points = {{4.55, -0.2}, {4.55, -0.1}, {4.2, 0.0}, {4.2, 0.04}, {4.55, 0.1}, {4.55, 0.2}};
  silhouette.last_valid = true;
  EXPECT_EQ(internal::BoxUnoccludedPoints(o, Eigen::Vector2d(5.0, 0.0), Eigen::Vector2d(0.45, 0.3),
                                          0.0, points, kept, &silhouette),
            4u);
  EXPECT_EQ(kept[2], points[4]);
  EXPECT_TRUE(silhouette.first_valid && silhouette.last_valid);
  // Points in front of the box but continuous with its face (no range step where they meet it:
  // a face turned from the box's expected one) are the box's.
  points = {{4.55, -0.2}, {4.55, -0.1}, {4.5, 0.0}, {4.45, 0.1}, {4.4, 0.2}};
  EXPECT_EQ(internal::BoxUnoccludedPoints(o, Eigen::Vector2d(5.0, 0.0), Eigen::Vector2d(0.45, 0.3),
                                          0.0, points, kept, &silhouette),
            5u);
  // A leg whose one side meets the face through a mixed echo (no step there): still dropped.
  points = {{4.55, -0.2}, {4.55, -0.1}, {4.5, -0.05}, {4.45, 0.0},
            {4.2, 0.05},  {4.2, 0.1},   {4.55, 0.15}, {4.55, 0.2}};
  EXPECT_EQ(internal::BoxUnoccludedPoints(o, Eigen::Vector2d(5.0, 0.0), Eigen::Vector2d(0.45, 0.3),
                                          0.0, points, kept, &silhouette),
            5u);
  EXPECT_EQ(kept[2], points[2]);
  EXPECT_EQ(kept[3], points[6]);
  // A point 2 cm in front of the face is range noise (3 sigma at 4.5 m: 0.07 m): kept.
  points = {{4.53, 0.0}};
  EXPECT_EQ(internal::BoxUnoccludedPoints(o, Eigen::Vector2d(5.0, 0.0), Eigen::Vector2d(0.45, 0.3),
                                          0.0, points, kept, &silhouette),
            1u);
}

// ShapeOptions::person_drop_beyond_reach: a person predicted at (5, 0) (a round body of radius
// 0.2 m: reach 0.2 m; prediction sigma 0.02 m) shows the near half of its outline, and the segment
// goes on with another object's points beside it. In front (x = 4.7, 0.2 m nearer than the
// person's end point): left out, that end an occluder's edge. Behind (x = 5.3): left out, that end
// the person's silhouette half a step outside its last point's beam. Continuous with the outline
// (no range step), or where fewer than two points would stay: every point kept.
TEST(PipelineTest, PersonReachablePointsLeavesOutAnotherObjectBesideThePerson) {
  ShapeOptions o;
  const Eigen::Vector2d centre(5.0, 0.0);
  const Eigen::Matrix2d cov = 0.02 * 0.02 * Eigen::Matrix2d::Identity();
  const double step = 0.5 * common::kPi / 180.0;
  EXPECT_DOUBLE_EQ(internal::SuperellipseReach(Eigen::Vector2d(0.2, 0.2), 2.0), 0.2);
  EXPECT_NEAR(internal::SuperellipseReach(Eigen::Vector2d(0.23, 0.14), 2.5),
              0.23 * std::pow(2.0, 0.1), 1e-12);
  // The factor alone: SuperellipseReach is max(size) times it, bit for bit.
  EXPECT_EQ(internal::SuperellipseReachFactor(2.0), 1.0);
  EXPECT_EQ(internal::SuperellipseReachFactor(1.5), 1.0);
  EXPECT_NEAR(internal::SuperellipseReachFactor(2.5), std::pow(2.0, 0.1), 1e-15);
  for (const double p : {2.0, 2.5, 3.0, 4.0}) {
    EXPECT_EQ(internal::SuperellipseReach(Eigen::Vector2d(0.23, 0.14), p),
              0.23 * internal::SuperellipseReachFactor(p));
  }
  std::vector<Eigen::Vector2d> person;
  for (int i = -6; i <= 6; ++i) {
    const double phi = 10.0 * i * common::kPi / 180.0;
    person.push_back(centre + 0.2 * Eigen::Vector2d(-std::cos(phi), std::sin(phi)));
  }
  const double reach = internal::SuperellipseReach(Eigen::Vector2d(0.2, 0.2), 2.0);
  std::vector<Eigen::Vector2d> kept(32);
  const auto with = [&](double x) {
    std::vector<Eigen::Vector2d> points = person;
    for (int i = 0; i < 4; ++i) points.emplace_back(x, 0.25 + 0.05 * i);
    return points;
  };
  Silhouette s;
  s.first_valid = s.last_valid = true;
  std::vector<Eigen::Vector2d> points = with(4.7);
  EXPECT_EQ(internal::PersonReachablePoints(o, centre, cov, reach, points, step, kept, &s),
            person.size());
  for (std::size_t i = 0; i < person.size(); ++i) EXPECT_EQ(kept[i], person[i]);
  EXPECT_TRUE(s.first_valid);
  EXPECT_FALSE(s.last_valid);
  EXPECT_FALSE(s.last_edge_unit_known);
  EXPECT_DOUBLE_EQ(s.last_edge_rad, std::atan2(person.back().y(), person.back().x()) + 0.5 * step);
  s = Silhouette{};
  s.first_valid = true;
  points = with(5.3);
  EXPECT_EQ(internal::PersonReachablePoints(o, centre, cov, reach, points, step, kept, &s),
            person.size());
  EXPECT_TRUE(s.first_valid && s.last_valid);
  EXPECT_DOUBLE_EQ(s.last_edge_rad, std::atan2(person.back().y(), person.back().x()) + 0.5 * step);
  // Beyond reach but at the end point's range, beam after beam: the same surface, kept.
  points = person;
  const double r_end = person.back().norm(),
               a_end = std::atan2(person.back().y(), person.back().x());
  for (int i = 1; i <= 4; ++i) {
    points.push_back(r_end *
                     Eigen::Vector2d(std::cos(a_end + 0.02 * i), std::sin(a_end + 0.02 * i)));
  }
  s = Silhouette{};
  const std::vector<Eigen::Vector2d> before = kept;
  EXPECT_EQ(internal::PersonReachablePoints(o, centre, cov, reach, points, step, kept, &s),
            points.size());
  EXPECT_FALSE(s.first_valid || s.last_valid);
  EXPECT_EQ(kept, before);  // Nothing left out: the caller reads points, not kept.
  // One point of the person and the other object's: nothing left out.
  points = {person[6], {4.7, 0.25}, {4.7, 0.3}};
  EXPECT_EQ(internal::PersonReachablePoints(o, centre, cov, reach, points, step, kept, &s), 3u);
}

// ShapeOptions::partial_view_size_sigma_m: an upper-body person's fit with one silhouette end or
// none takes the size's sigma in its shared covariance at 0.04 m (a whole view's floor, 0.006 m,
// otherwise); two ends, a leg or the option at 0: the whole view's floor.
TEST(PipelineTest, PartialViewSizeFloorSaysTheHiddenExtentIsUnknown) {
  ShapeOptions o;
  EXPECT_DOUBLE_EQ(o.partial_view_size_sigma_m, 0.04);
  EXPECT_DOUBLE_EQ(internal::PartialViewSizeFloor(o, true, 1, 0.006), 0.04);
  EXPECT_DOUBLE_EQ(internal::PartialViewSizeFloor(o, true, 0, 0.006), 0.04);
  EXPECT_DOUBLE_EQ(internal::PartialViewSizeFloor(o, true, 2, 0.006), 0.006);
  EXPECT_DOUBLE_EQ(internal::PartialViewSizeFloor(o, false, 1, 0.006), 0.006);
  EXPECT_DOUBLE_EQ(internal::PartialViewSizeFloor(o, true, 1, 0.06), 0.06);
  o.partial_view_size_sigma_m = 0.0;
  EXPECT_DOUBLE_EQ(internal::PartialViewSizeFloor(o, true, 1, 0.006), 0.006);
  o.partial_view_size_sigma_m = -0.01;
  EXPECT_TRUE(Validate(o).has_value());
}

// ShapeOptions::box_size_from_faces_seen: a 0.9 x 0.6 m box at 5 m (0.5 deg beams) seen end-on
// shows its half-width only, broadside its half-length only, at 45 deg both; a side seen at a
// grazing angle, across fewer than three beams, shows nothing.
TEST(PipelineTest, BoxFacesShownAreTheFacesTheSensorSees) {
  const Eigen::Vector2d centre(5.0, 0.0), size(0.45, 0.3);
  const double step = 0.5 * common::kPi / 180.0;  // 0.044 m between beams at 5 m
  EXPECT_EQ(internal::BoxFacesShown(centre, size, 0.0, step), (std::array<bool, 2>{false, true}));
  EXPECT_EQ(internal::BoxFacesShown(centre, size, common::kPi / 2, step),
            (std::array<bool, 2>{true, false}));
  EXPECT_EQ(internal::BoxFacesShown(centre, size, common::kPi / 4, step),
            (std::array<bool, 2>{true, true}));
  // Turned by 5 deg: the side's 0.9 m spans 0.08 m across the ray, under three beams (0.13 m).
  EXPECT_EQ(internal::BoxFacesShown(centre, size, 5.0 * common::kPi / 180.0, step),
            (std::array<bool, 2>{false, true}));
  // Turned by 15 deg: 0.23 m, five beams.
  EXPECT_EQ(internal::BoxFacesShown(centre, size, 15.0 * common::kPi / 180.0, step),
            (std::array<bool, 2>{true, true}));
}

// A box's size state 0.4 x 0.3 m (sigma 0.1 m each) and a fit whose posterior says 0.5 x 0.3 m
// (sigma 0.05 m each), share 0.25: per axis the information 100 + 0.25 (400 - 100) = 175, the
// variance 1 / 175, the mean (100 0.4 + 0.25 (400 0.5 - 100 0.4)) / 175 = 0.45714 m. A semi-axis
// the scan did not show keeps its mean and variance, also where the fit agrees with the state.
TEST(PipelineTest, LearnSizeTakesNothingOnASemiAxisTheScanDidNotShow) {
  const Eigen::Matrix2d state_cov = 0.01 * Eigen::Matrix2d::Identity();
  const Eigen::Matrix2d fit_cov = 0.0025 * Eigen::Matrix2d::Identity();
  TrackShape shape;
  shape.size_m = {0.4, 0.3};
  shape.size_cov_m2 = state_cov;
  internal::LearnSize({0.5, 0.3}, fit_cov, 0.25, {true, true}, shape);
  EXPECT_NEAR(shape.size_m.x(), 0.32 / 0.7, 1e-12);
  EXPECT_NEAR(shape.size_m.y(), 0.3, 1e-12);
  EXPECT_NEAR(shape.size_cov_m2(0, 0), 1.0 / 175.0, 1e-12);
  EXPECT_NEAR(shape.size_cov_m2(1, 1), 1.0 / 175.0, 1e-12);
  // The half-length not shown (an end-on view): it stays, the half-width learns as before.
  shape.size_m = {0.4, 0.3};
  shape.size_cov_m2 = state_cov;
  internal::LearnSize({0.5, 0.35}, fit_cov, 0.25, {false, true}, shape);
  EXPECT_DOUBLE_EQ(shape.size_m.x(), 0.4);
  EXPECT_DOUBLE_EQ(shape.size_cov_m2(0, 0), 0.01);
  EXPECT_NEAR(shape.size_m.y(), (100.0 * 0.3 + 0.25 * (400.0 * 0.35 - 100.0 * 0.3)) / 175.0, 1e-12);
  EXPECT_NEAR(shape.size_cov_m2(1, 1), 1.0 / 175.0, 1e-12);
  // The fit agreeing with the state on the axis not shown moves it neither.
  shape.size_m = {0.4, 0.3};
  shape.size_cov_m2 = state_cov;
  for (int i = 0; i < 100; ++i)
    internal::LearnSize({0.4, 0.3}, fit_cov, 0.25, {false, true}, shape);
  EXPECT_DOUBLE_EQ(shape.size_m.x(), 0.4);
  EXPECT_DOUBLE_EQ(shape.size_cov_m2(0, 0), 0.01);
}

// ShapeOptions::person_size_across_ray: 0.23 x 0.14 m axes (a across, b along the ray) give the
// shoulders' half-width across the ray its full weight front-on, the half-depth none; from the
// side the other way round; at 60 deg between axis a and the ray a quarter and three quarters.
TEST(PipelineTest, PersonAxisWeightsAreEachSemiAxisShareAcrossTheRay) {
  const Eigen::Vector2d centre(3.0, 4.0);  // the ray at atan2(4, 3)
  const double ray = std::atan2(4.0, 3.0);
  const auto front_on = internal::PersonAxisWeights(centre, ray + common::kPi / 2);
  EXPECT_NEAR(front_on[0], 1.0, 1e-12);
  EXPECT_NEAR(front_on[1], 0.0, 1e-12);
  const auto side_on = internal::PersonAxisWeights(centre, ray + common::kPi);
  EXPECT_NEAR(side_on[0], 0.0, 1e-12);
  EXPECT_NEAR(side_on[1], 1.0, 1e-12);
  const auto oblique = internal::PersonAxisWeights(centre, ray - common::kPi / 3);
  EXPECT_NEAR(oblique[0], 0.75, 1e-12);
  EXPECT_NEAR(oblique[1], 0.25, 1e-12);
  EXPECT_EQ(internal::PersonAxisWeights(Eigen::Vector2d::Zero(), 0.3),
            (std::array<double, 2>{1.0, 1.0}));
}

// LearnSizeWeighted: weights {1, 1} are LearnSize with both semi-axes shown, {1, 0} LearnSize with
// b not shown (the numbers of LearnSizeTakesNothingOnASemiAxisTheScanDidNotShow); a half weight
// takes half the information: 100 + 0.5 0.25 (400 - 100) = 137.5.
TEST(PipelineTest, LearnSizeWeightedTakesEachSemiAxisByItsWeight) {
  const Eigen::Matrix2d state_cov = 0.01 * Eigen::Matrix2d::Identity();
  const Eigen::Matrix2d fit_cov = 0.0025 * Eigen::Matrix2d::Identity();
  TrackShape shape;
  shape.size_m = {0.4, 0.3};
  shape.size_cov_m2 = state_cov;
  internal::LearnSizeWeighted({0.5, 0.35}, fit_cov, 0.25, {1.0, 1.0}, shape);
  EXPECT_NEAR(shape.size_m.x(), 0.32 / 0.7, 1e-12);
  EXPECT_NEAR(shape.size_m.y(), (100.0 * 0.3 + 0.25 * (400.0 * 0.35 - 100.0 * 0.3)) / 175.0, 1e-12);
  EXPECT_NEAR(shape.size_cov_m2(0, 0), 1.0 / 175.0, 1e-12);
  shape.size_m = {0.4, 0.3};
  shape.size_cov_m2 = state_cov;
  internal::LearnSizeWeighted({0.5, 0.35}, fit_cov, 0.25, {1.0, 0.0}, shape);
  EXPECT_NEAR(shape.size_m.x(), 0.32 / 0.7, 1e-12);
  EXPECT_DOUBLE_EQ(shape.size_m.y(), 0.3);
  EXPECT_DOUBLE_EQ(shape.size_cov_m2(1, 1), 0.01);
  shape.size_m = {0.4, 0.3};
  shape.size_cov_m2 = state_cov;
  internal::LearnSizeWeighted({0.5, 0.35}, fit_cov, 0.25, {0.5, 0.5}, shape);
  EXPECT_NEAR(shape.size_cov_m2(0, 0), 1.0 / 137.5, 1e-12);
  EXPECT_NEAR(shape.size_m.x(), 0.4 + (0.5 * 0.25 * 400.0 * 0.1) / 137.5, 1e-12);
}

// A 0.23 x 0.14 m person rounder than the model (an ellipse against the default exponent 2.5)
// walking straight away from the sensor from 1.5 to 9.5 m: every fit reads the rounder arc as a
// deeper body. With ShapeOptions::person_size_across_ray the half-depth along the ray is not
// learned from that view: the reported b stays near the prior (a run: 0.146 m) and the centre's
// mean error along the ray is what each scan's own fit reads into the arc (+0.024 m); learned
// from every fit (false), b grows to 0.19 m and the centre lies twice as far behind (+0.051 m).
TEST(PipelineScenarioTest, APersonWalkingAlongTheRayKeepsTheDepthPrior) {
  Scene scene;
  scene.walkers = {Walker::Path(kLearnedS, {{1.5, 0.3}, {9.5, 0.3}}, 1.2)};
  scene.sizes = {{0.23, 0.14}};
  TrackerOptions options = Synthetic();
  options.shape.person_exponent = TrackerOptions().shape.person_exponent;
  const auto run_with = [&](bool across_ray, double* minor_m, double* radial_m) {
    options.shape.person_size_across_ray = across_ray;
    const SceneRun run = Simulate(scene, scene.walkers[0].end_s(), options);
    double radial = 0.0;
    int n = 0;
    *minor_m = 0.0;
    for (const Frame& f : run.frames) {
      if (!f.truth[0] || f.t_s < kLearnedS + 1.0) continue;
      for (const TrackReport& r : f.tracks) {
        const Eigen::Vector2d e = Position(r) - *f.truth[0];
        if (r.state != TrackState::kConfirmed || e.norm() > 0.4) continue;
        radial += e.dot(f.truth[0]->normalized());
        ++n;
        *minor_m = r.size_minor_m;
      }
    }
    ASSERT_GT(n, 50);
    *radial_m = radial / n;
  };
  double minor = 0.0, radial = 0.0, minor_before = 0.0, radial_before = 0.0;
  run_with(true, &minor, &radial);
  run_with(false, &minor_before, &radial_before);
  RecordProperty("minor_m", std::to_string(minor));
  RecordProperty("minor_m_before", std::to_string(minor_before));
  RecordProperty("radial_m", std::to_string(radial));
  RecordProperty("radial_m_before", std::to_string(radial_before));
  EXPECT_LT(minor, 0.15);
  EXPECT_GT(minor_before, 0.17);
  EXPECT_LT(std::abs(radial), 0.03);
  EXPECT_GT(radial_before, radial + 0.02);
}

TEST(PipelineScenarioTest, CovarianceOfPeopleOfDifferentSizesMatchesTheirError) {
  // Four people of different builds crossing and turning in front of the sensor: the normalised
  // error squared (NEES, 2 dof) of measured confirmed tracks has a mean near 2. The synthetic
  // people here are the model's own ellipses in an empty room, so the shared outline error is the
  // 2 cm of a clean outline, the default since the silhouette's end no longer shrinks bodies; on
  // the cluttered, superelliptic people of tracking_benchmark's scenes it gives a mean NEES of 2.0
  // (upper body) and 2.3 (legs).
  TrackerOptions options = Synthetic();
  options.shape.centre_bias_sigma_m = 0.02;
  Scene scene;
  scene.walkers = {Walker::Path(kLearnedS, {{1.5, -4.0}, {6.0, 0.0}, {2.0, 4.0}}, 1.2),
                   Walker::Path(kLearnedS + 1.0, {{7.0, -4.0}, {3.0, -1.0}, {6.5, 3.0}}, 1.0),
                   Walker::Path(kLearnedS + 2.0, {{-1.0, 4.0}, {3.0, 2.5}, {7.0, -3.5}}, 1.4),
                   Walker::Path(kLearnedS + 0.5, {{6.5, 4.0}, {6.0, -4.0}}, 0.8)};
  scene.sizes = {{0.22, 0.13}, {0.27, 0.16}, {0.2, 0.12}, {0.25, 0.15}};
  const SceneRun run = Simulate(scene, kLearnedS + 12.0, options);
  double nees = 0.0;
  int n = 0;
  for (const Frame& f : run.frames) {
    for (std::size_t w = 0; w < scene.walkers.size(); ++w) {
      if (!f.truth[w] || f.t_s < scene.walkers[w].start_s() + 1.0) continue;
      for (const TrackReport& r : f.tracks) {
        const Eigen::Vector2d e = Position(r) - *f.truth[w];
        if (r.state != TrackState::kConfirmed || e.norm() > 0.4) continue;
        nees += e.dot(r.covariance.topLeftCorner<2, 2>().ldlt().solve(e));
        ++n;
      }
    }
  }
  ASSERT_GT(n, 500);
  EXPECT_GT(nees / n, 1.0);
  EXPECT_LT(nees / n, 3.5);
  RecordProperty("mean_nees", std::to_string(nees / n));
}

// The reported covariance against the error of a person whose build is unlike the prior (0.29 x
// 0.18 m against 0.23 x 0.14 m), walking across the line of sight at 3, 8 and 15 m (seen from one
// side), over three noise draws each. Per range, RMS over the measured confirmed tracks: the
// reported radial and across sigmas contain the error in that direction; the shared error is
// reported along the ray (across: the silhouette's beam step, growing with range), so the across
// sigma is below the radial one and below what the same error reported in every direction gave
// (centre_bias_along_ray false); the NEES mean stays below 3 at every range and above the
// isotropic one. On these clean ellipses (the model's own outline, no clutter) the error is 3-18
// mm and the NEES mean is far below 2 (a run: 0.09 / 0.32 / 0.23 at 3 / 8 / 15 m, isotropic 0.05
// / 0.28 / 0.20): the filter's own covariance already gives 0.16 / 0.48 / 0.27 without any shared
// term (centre_model_sigma_m per measurement), so this scene cannot show the band of 1.5-3;
// tracking_benchmark's scenes (superelliptic people, clutter) are where it is checked.
struct RayErrors {
  double radial_sq = 0.0, across_sq = 0.0, sigma_radial_sq = 0.0, sigma_across_sq = 0.0;
  double nees = 0.0;
  int n = 0;
  double Rms(double sum) const { return std::sqrt(sum / n); }
};

RayErrors WalkAcrossTheRay(const TrackerOptions& options, double range_m) {
  RayErrors out;
  for (std::uint32_t seed = 1; seed <= 3; ++seed) {
    ScannerConfig config;
    config.seed = seed;
    Scene scene;
    scene.walls = {};
    scene.walkers = {Walker::Path(kLearnedS, {{range_m, -2.5}, {range_m, 2.5}}, 1.0)};
    scene.sizes = {{0.29, 0.18}};
    const Walker& walker = scene.walkers[0];
    const SceneRun run = Simulate(scene, walker.end_s(), options, config);
    for (const Frame& f : run.frames) {
      if (!f.truth[0] || f.t_s < walker.start_s() + 1.0) continue;
      const Eigen::Vector2d u = f.truth[0]->normalized();
      const Eigen::Vector2d w(-u.y(), u.x());
      for (const TrackReport& r : f.tracks) {
        const Eigen::Vector2d e = Position(r) - *f.truth[0];
        if (r.state != TrackState::kConfirmed || e.norm() > 0.4) continue;
        const Eigen::Matrix2d p = r.covariance.topLeftCorner<2, 2>();
        out.radial_sq += e.dot(u) * e.dot(u);
        out.across_sq += e.dot(w) * e.dot(w);
        out.sigma_radial_sq += u.dot(p * u);
        out.sigma_across_sq += w.dot(p * w);
        out.nees += e.dot(p.ldlt().solve(e));
        ++out.n;
      }
    }
  }
  return out;
}

TEST(PipelineScenarioTest, CovarianceAlongAndAcrossTheRayContainsTheErrorAtEveryRange) {
  // The fixed allowances' two forms against each other (the measured outline departure, the same
  // in every direction, is AModelLikeOutlineIsReportedWithTheFixedAllowancesCut's).
  TrackerOptions options = Synthetic();
  options.shape.outline_departure_gain = 0.0;
  ASSERT_TRUE(options.shape.centre_bias_along_ray);
  TrackerOptions isotropic = options;
  isotropic.shape.centre_bias_along_ray = false;
  double previous_sigma_across = 0.0;
  for (const double range_m : {3.0, 8.0, 15.0}) {
    SCOPED_TRACE(range_m);
    const RayErrors e = WalkAcrossTheRay(options, range_m);
    const RayErrors before = WalkAcrossTheRay(isotropic, range_m);
    ASSERT_GT(e.n, 150);
    ASSERT_GT(before.n, 150);
    const double sigma_radial = e.Rms(e.sigma_radial_sq);
    const double sigma_across = e.Rms(e.sigma_across_sq);
    EXPECT_LE(e.Rms(e.radial_sq), sigma_radial);
    EXPECT_LE(e.Rms(e.across_sq), sigma_across);
    EXPECT_LT(sigma_across, sigma_radial);
    EXPECT_LT(sigma_across, before.Rms(before.sigma_across_sq));
    EXPECT_GT(sigma_across, previous_sigma_across);
    previous_sigma_across = sigma_across;
    EXPECT_LT(e.nees / e.n, 3.0);
    EXPECT_GT(e.nees / e.n, before.nees / before.n);
    RecordProperty("nees_at_" + std::to_string(static_cast<int>(range_m)) + "_m",
                   std::to_string(e.nees / e.n));
  }
}

// The model's own outline (an ellipse, no clutter) at 8 m: its residuals are the range noise, so
// with the departure measured (ShapeOptions::outline_departure_gain) the fixed allowances for the
// outline are cut: the reported sigmas shrink towards the error (the NEES rises) and still contain
// it (RMS error within the RMS sigma in both directions). With the gain 0 the sigmas are the
// whole fixed allowances.
TEST(PipelineScenarioTest, AModelLikeOutlineIsReportedWithTheFixedAllowancesCut) {
  const TrackerOptions options = Synthetic();
  ASSERT_GT(options.shape.outline_departure_gain, 0.0);
  TrackerOptions before = options;
  before.shape.outline_departure_gain = 0.0;
  const RayErrors e = WalkAcrossTheRay(options, 8.0);
  const RayErrors old = WalkAcrossTheRay(before, 8.0);
  ASSERT_GT(e.n, 150);
  ASSERT_GT(old.n, 150);
  EXPECT_LT(e.Rms(e.sigma_radial_sq), 0.9 * old.Rms(old.sigma_radial_sq));
  EXPECT_LT(e.Rms(e.sigma_across_sq), old.Rms(old.sigma_across_sq));
  EXPECT_LE(e.Rms(e.radial_sq), e.Rms(e.sigma_radial_sq));
  EXPECT_LE(e.Rms(e.across_sq), e.Rms(e.sigma_across_sq));
  EXPECT_GT(e.nees / e.n, old.nees / old.n);
  EXPECT_LT(e.nees / e.n, 3.0);
  RecordProperty("nees", std::to_string(e.nees / e.n));
  RecordProperty("nees_before", std::to_string(old.nees / old.n));
}

// ShapeOptions::partial_view_shared: a person walks past a pillar that hides part of them for
// about a second. On the measured scans whose outline ends at the pillar's edge (fewer than two
// silhouette ends), the fit places the hidden side from the priors, and the same prior error is
// shared by every such scan: the rule reports the fit's centre covariance on top of the filter's.
// The positions are the same either way (the filter is not changed); on those scans the reported
// covariance is larger by the fit's, and the NEES over them lower. Off: no scan counted, the same
// covariance as a whole view.
TEST(PipelineScenarioTest, APartialViewIsReportedWithItsFitsCovariance) {
  Scene scene;
  scene.statics = {testing::Cylinder({2.0, 0.0}, 0.2)};
  scene.walkers = {Walker::Path(kLearnedS, {{4.5, -3.5}, {4.5, 3.5}}, 1.2)};
  const Walker& walker = scene.walkers[0];
  // The term alone: the gain covariance's measured noise (which these terms gate) left out.
  const TrackerOptions options = GainCovarianceOff(Synthetic());
  ASSERT_TRUE(options.shape.partial_view_shared);
  TrackerOptions before = options;
  before.shape.partial_view_shared = false;
  const SceneRun run = Simulate(scene, walker.end_s() + 1.0, options);
  const SceneRun old = Simulate(scene, walker.end_s() + 1.0, before);
  EXPECT_GT(run.pipeline->counters().partial_view_widened, 5u);
  EXPECT_EQ(old.pipeline->counters().partial_view_widened, 0u);
  WidenedReports widened;
  ForEachReportPair(run, old, [&](std::size_t k, const TrackReport& r, const TrackReport& o) {
    // Larger by a positive definite matrix where widened: the fit's covariance.
    if (run.frames[k].truth[0]) widened.Add(r, o, *run.frames[k].truth[0]);
  });
  EXPECT_GE(widened.wider, 5);
  EXPECT_GT(widened.same, 100);  // a whole view: reported as before
  EXPECT_LT(widened.nees, widened.nees_before);
}

// ShapeOptions::neighbour_sigma_m: neighbour_sigma_m^2 (1 - d / neighbour_distance_m) per axis
// within neighbour_distance_m, nothing beyond it or with the sigma 0.
TEST(PipelineTest, NeighbourVarFallsToZeroAtTheNeighbourDistance) {
  ShapeOptions o;
  o.neighbour_distance_m = 1.0;
  o.neighbour_sigma_m = 0.06;
  EXPECT_NEAR(internal::NeighbourVar(o, 0.0), 0.0036, 1e-15);
  EXPECT_NEAR(internal::NeighbourVar(o, 0.5), 0.0018, 1e-15);
  EXPECT_NEAR(internal::NeighbourVar(o, 0.75), 0.0009, 1e-15);
  EXPECT_EQ(internal::NeighbourVar(o, 1.0), 0.0);
  EXPECT_EQ(internal::NeighbourVar(o, 3.0), 0.0);
  EXPECT_EQ(internal::NeighbourVar(o, std::numeric_limits<double>::infinity()), 0.0);
  o.neighbour_sigma_m = 0.0;
  EXPECT_EQ(internal::NeighbourVar(o, 0.5), 0.0);
}

// ShapeOptions::segment_excess_shared: points the body cannot hold widen the report along the
// direction they extend in, by the excess squared over 12 (a uniform distribution's variance);
// the outermost points' noise (two sigmas at either end) and a body's reach (twice across the
// ray, once along it: its near half) are not excess.
TEST(PipelineTest, SegmentExcessCovIsTheUniformVarianceOfWhatTheBodyCannotHold) {
  const Eigen::Vector2d centre(5.0, 0.0);
  // Across the ray: 1.0 m of points, a body reaching 0.3 m, noise 0.01 m: excess 0.36 m.
  const std::array<Eigen::Vector2d, 3> across = {
      Eigen::Vector2d(4.9, -0.5), Eigen::Vector2d(4.9, 0.0), Eigen::Vector2d(4.9, 0.5)};
  const Eigen::Matrix2d a = internal::SegmentExcessCov(across, centre, 0.3, 0.01);
  EXPECT_NEAR(a(1, 1), 0.36 * 0.36 / 12.0, 1e-12);
  EXPECT_NEAR(a(0, 0), 0.0, 1e-12);
  EXPECT_NEAR(a(0, 1), 0.0, 1e-12);
  // Along the ray: 0.6 m deep, the near half of a 0.3 m reach shows: excess 0.26 m.
  const std::array<Eigen::Vector2d, 2> along = {Eigen::Vector2d(4.7, 0.0),
                                                Eigen::Vector2d(5.3, 0.0)};
  const Eigen::Matrix2d b = internal::SegmentExcessCov(along, centre, 0.3, 0.01);
  EXPECT_NEAR(b(0, 0), 0.26 * 0.26 / 12.0, 1e-12);
  EXPECT_NEAR(b(1, 1), 0.0, 1e-12);
  // One body's outline: nothing.
  const std::array<Eigen::Vector2d, 3> one = {
      Eigen::Vector2d(4.9, -0.25), Eigen::Vector2d(4.8, 0.0), Eigen::Vector2d(4.9, 0.25)};
  EXPECT_TRUE(internal::SegmentExcessCov(one, centre, 0.3, 0.01).isZero());
  EXPECT_TRUE(internal::SegmentExcessCov(std::span<const Eigen::Vector2d>(across.data(), 1), centre,
                                         0.3, 0.01)
                  .isZero());
}

// ShapeOptions::segment_excess_shared: a person walks towards the sensor beside a cart pushed
// 0.5 m from them (PushCartBesideWalker's scene): in many scans the two are one segment, wider
// than a person, and which part of it is the person's is not known. The positions are the same
// either way; such scans are reported wider along the excess (a positive semi-definite
// difference) and their NEES is lower, not far below 1 (before 2.07, after 0.91 over 67 reports
// with 0.11 m of error). Off: none counted.
TEST(PipelineScenarioTest, APersonBesideACartInOneSegmentIsReportedWiderAlongIt) {
  Scene scene;
  const MovingBox box = AddMovingBox(scene, {7.5, 1.0}, {2.5, 1.0}, 0.9, 0.45, 0.3);
  scene.walkers = {Walker::Path(kLearnedS, {{7.9, 0.5}, {2.9, 0.5}}, 0.9)};
  const double end_s = box.end_s;
  // The term alone: the neighbour's fixed allowance and the gain covariance's measured noise
  // (which these terms gate) left out.
  TrackerOptions options = GainCovarianceOff(Synthetic());
  options.shape.neighbour_sigma_m = 0.0;
  ASSERT_TRUE(options.shape.segment_excess_shared);
  TrackerOptions before = options;
  before.shape.segment_excess_shared = false;
  const SceneRun run = Simulate(scene, end_s + 0.5, options);
  const SceneRun old = Simulate(scene, end_s + 0.5, before);
  EXPECT_GT(run.pipeline->counters().segment_excess_widened, 20u);
  EXPECT_EQ(old.pipeline->counters().segment_excess_widened, 0u);
  // The reports widened (the same positions), against the nearer walker's truth.
  int wider = 0, same = 0;
  double nees = 0.0, nees_before = 0.0, error_m = 0.0;
  ForEachReportPair(run, old, [&](std::size_t k, const TrackReport& r, const TrackReport& o) {
    const Eigen::Matrix2d c = r.covariance.topLeftCorner<2, 2>();
    const Eigen::Matrix2d c_old = o.covariance.topLeftCorner<2, 2>();
    if ((c - c_old).norm() < 1e-12) {
      ++same;
      return;
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> added(Eigen::Matrix2d(c - c_old));
    EXPECT_GE(added.eigenvalues().minCoeff(), -1e-12);
    EXPECT_GT(added.eigenvalues().maxCoeff(), 0.0);
    const Frame& f = run.frames[k];
    const auto centre = box.centre_at(f.t_s);
    if (!f.truth[0] || !centre) return;
    const Eigen::Vector2d p = Position(r);
    const Eigen::Vector2d e = (p - *f.truth[0]).norm() < (p - *centre).norm()
                                  ? Eigen::Vector2d(p - *f.truth[0])
                                  : Eigen::Vector2d(p - *centre);
    ++wider;
    error_m += e.norm();
    nees += e.dot(c.inverse() * e);
    nees_before += e.dot(c_old.inverse() * e);
  });
  ASSERT_GT(wider, 0);
  nees /= wider;
  nees_before /= wider;
  error_m /= wider;
  SCOPED_TRACE("widened " + std::to_string(wider) + " of " + std::to_string(wider + same) +
               ", error " + std::to_string(error_m) + " m, NEES " + std::to_string(nees_before) +
               " -> " + std::to_string(nees));
  RecordProperty("nees_before", std::to_string(nees_before));
  RecordProperty("nees_after", std::to_string(nees));
  EXPECT_GE(wider, 20);
  EXPECT_GT(same, 100);
  EXPECT_GT(error_m, 0.05);
  EXPECT_LT(nees, 0.8 * nees_before);
  EXPECT_GT(nees, 0.5);
}

// ShapeOptions::box_view_shared: where a segment is a box's outline, the second moment of
// the box's centre about the fit's. One face across the ray at 4 m, both ends seen: the centre
// lies behind its middle by h, uniform over [0.2, 0.9] m, so along the ray E[(h - 0.15)^2] about a
// fit 0.15 m behind the face, nothing across it; an end the beam beyond continues lets the face go
// on (the uniform's (1.8 - 0.6)^2 / 12 across); legs in front of it are left out. Two faces at a
// corner: the middle of the diagonal. A side of two points beyond the corner: one face, the corner
// its end. A person's arc: nothing.
TEST(PipelineTest, BoxViewCovPutsTheCentreWhereTheRectangleDoes) {
  ShapeOptions o;
  o.box_prior_min_half_m = 0.2;
  o.box_prior_max_half_m = 0.9;
  const double noise = 0.01;
  internal::OutlineEnd seen;
  seen.silhouette = true;
  seen.beyond_returned_none = true;
  std::vector<Eigen::Vector2d> face;
  for (int i = 0; i <= 12; ++i) face.emplace_back(4.0, -0.3 + 0.05 * i);
  int faces = -1;
  double longest = 0.0;
  const Eigen::Matrix2d one = internal::BoxViewCov(o, face, Eigen::Vector2d(4.15, 0.0), noise, seen,
                                                   seen, &faces, &longest);
  EXPECT_EQ(faces, 1);
  EXPECT_NEAR(longest, 0.6, 1e-9);
  const double mean_h = 0.55, mean_h2 = (0.04 + 0.18 + 0.81) / 3.0;
  EXPECT_NEAR(one(0, 0), 0.15 * 0.15 - 2.0 * 0.15 * mean_h + mean_h2, 1e-9);
  EXPECT_NEAR(one(1, 1), 0.0, 1e-9);
  EXPECT_NEAR(one(0, 1), 0.0, 1e-9);
  // A 0.9 m deep cart's centre (4.45, 0): the fit's error within the reported sigma.
  EXPECT_LT(0.3 * 0.3 / one(0, 0), 1.0);
  // Two legs in front of the face's middle (the pusher's, in the same segment): left out, the
  // same face.
  std::vector<Eigen::Vector2d> pushed = face;
  pushed[5] = Eigen::Vector2d(3.6, pushed[5].y());
  pushed[7] = Eigen::Vector2d(3.6, pushed[7].y());
  const Eigen::Matrix2d behind_legs = internal::BoxViewCov(o, pushed, Eigen::Vector2d(4.15, 0.0),
                                                           noise, seen, seen, &faces, &longest);
  EXPECT_EQ(faces, 1);
  EXPECT_NEAR((behind_legs - one).norm(), 0.0, 1e-9);
  internal::OutlineEnd goes_on = seen;
  goes_on.beyond_returned_none = false;
  goes_on.beyond_valid = true;
  goes_on.beyond_m = Eigen::Vector2d(4.0, -0.35);
  const Eigen::Matrix2d cut = internal::BoxViewCov(o, face, Eigen::Vector2d(4.15, 0.0), noise,
                                                   goes_on, seen, &faces, &longest);
  EXPECT_EQ(faces, 1);
  EXPECT_NEAR(cut(1, 1), 1.2 * 1.2 / 12.0, 1e-9);
  // The second moments against a Monte Carlo of the same box (h uniform, each unseen end's
  // extension e uniform over [0, e_max], the centre moved by e / 2 towards it): about a fit off
  // the face's middle, the mean shifts' cross terms count, and two unseen ends' shifts cancel.
  std::mt19937 rng(29);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const auto monte_carlo = [&](const Eigen::Vector2d& middle, const Eigen::Vector2d& normal,
                               const std::vector<std::pair<Eigen::Vector2d, double>>& ends,
                               const Eigen::Vector2d& fit_m) {
    constexpr int kSamples = 400000;
    Eigen::Matrix2d m = Eigen::Matrix2d::Zero();
    for (int i = 0; i < kSamples; ++i) {
      Eigen::Vector2d c = middle + (0.2 + 0.7 * unit(rng)) * normal;
      for (const auto& [toward, e_max] : ends) c += 0.5 * e_max * unit(rng) * toward;
      m += (c - fit_m) * (c - fit_m).transpose();
    }
    return Eigen::Matrix2d(m / kSamples);
  };
  const Eigen::Vector2d off_middle(4.15, 0.05);
  const Eigen::Matrix2d cut_off =
      internal::BoxViewCov(o, face, off_middle, noise, goes_on, seen, &faces, &longest);
  const Eigen::Matrix2d cut_mc = monte_carlo(Eigen::Vector2d(4.0, 0.0), Eigen::Vector2d(1.0, 0.0),
                                             {{Eigen::Vector2d(0.0, -1.0), 1.2}}, off_middle);
  EXPECT_NEAR(cut_off(0, 1), -0.14, 1e-9);  // E[h - 0.15] E[-e / 2 - 0.05] = 0.4 (-0.35)
  EXPECT_LT((cut_off - cut_mc).cwiseAbs().maxCoeff(), 2e-3);
  internal::OutlineEnd goes_on_last = goes_on;
  goes_on_last.beyond_m = Eigen::Vector2d(4.0, 0.35);
  const Eigen::Matrix2d cut_both =
      internal::BoxViewCov(o, face, off_middle, noise, goes_on, goes_on_last, &faces, &longest);
  const Eigen::Matrix2d both_mc = monte_carlo(
      Eigen::Vector2d(4.0, 0.0), Eigen::Vector2d(1.0, 0.0),
      {{Eigen::Vector2d(0.0, -1.0), 1.2}, {Eigen::Vector2d(0.0, 1.0), 1.2}}, off_middle);
  EXPECT_NEAR(cut_both(1, 1), 0.05 * 0.05 + 2.0 * 1.2 * 1.2 / 48.0, 1e-9);
  EXPECT_LT((cut_both - both_mc).cwiseAbs().maxCoeff(), 2e-3);
  // A corner: the faces y = 3 (x 3.9 -> 3) and x = 3 (y 3 -> 3.6), in scan order.
  std::vector<Eigen::Vector2d> corner;
  for (int i = 0; i < 9; ++i) corner.emplace_back(3.9 - 0.1 * i, 3.0);
  for (int i = 0; i <= 6; ++i) corner.emplace_back(3.0, 3.0 + 0.1 * i);
  const Eigen::Vector2d fit(3.2, 3.15);
  const Eigen::Matrix2d two =
      internal::BoxViewCov(o, corner, fit, noise, seen, seen, &faces, &longest);
  EXPECT_EQ(faces, 2);
  EXPECT_NEAR(longest, 0.9, 1e-9);  // the longer side: longer than a body at upper-body height
  const Eigen::Vector2d delta = Eigen::Vector2d(3.45, 3.3) - fit;
  EXPECT_NEAR((two - delta * delta.transpose()).norm(), 0.0, 1e-9);
  // Its first end (x = 3.9) not seen to end: the side goes on by up to 1.8 - 0.9 m along +x.
  internal::OutlineEnd side_goes_on = goes_on;
  side_goes_on.beyond_m = Eigen::Vector2d(4.0, 3.0);
  const Eigen::Matrix2d two_cut =
      internal::BoxViewCov(o, corner, fit, noise, side_goes_on, seen, &faces, &longest);
  EXPECT_EQ(faces, 2);
  const Eigen::Matrix2d two_mc = monte_carlo(Eigen::Vector2d(3.45, 3.3), Eigen::Vector2d::Zero(),
                                             {{Eigen::Vector2d(1.0, 0.0), 0.9}}, fit);
  EXPECT_NEAR(two_cut(0, 0), 0.25 * 0.25 + 0.25 * 0.9 / 2.0 + 0.9 * 0.9 / 12.0, 1e-9);
  EXPECT_LT((two_cut - two_mc).cwiseAbs().maxCoeff(), 2e-3);
  // The far side's two points only beyond the corner (grazing): the near face alone, from
  // x = 3.9 to the corner at x = 3 (its middle 0.25 m beyond the fit along x), its end at the
  // corner seen.
  std::vector<Eigen::Vector2d> grazing(corner.begin(), corner.begin() + 12);
  const Eigen::Matrix2d near_face =
      internal::BoxViewCov(o, grazing, fit, noise, seen, seen, &faces, &longest);
  EXPECT_EQ(faces, 1);
  EXPECT_NEAR(longest, 0.9, 1e-9);
  EXPECT_NEAR(near_face(0, 0), 0.25 * 0.25, 1e-9);
  // Along y, the face's normal: the unseen depth behind the fit 0.15 m behind the face.
  EXPECT_NEAR(near_face(1, 1), 0.15 * 0.15 - 2.0 * 0.15 * mean_h + mean_h2, 1e-9);
  // Three points beyond it: a side, two faces.
  std::vector<Eigen::Vector2d> short_side(corner.begin(), corner.begin() + 13);
  internal::BoxViewCov(o, short_side, fit, noise, seen, seen, &faces, &longest);
  EXPECT_EQ(faces, 2);
  // A person's front: an arc of 0.23 x 0.14 m, 5 m away.
  std::vector<Eigen::Vector2d> arc;
  for (int i = 0; i <= 10; ++i) {
    const double t = -1.2 + 0.24 * i;
    arc.emplace_back(5.0 - 0.14 * std::cos(t), 0.23 * std::sin(t));
  }
  const Eigen::Matrix2d none =
      internal::BoxViewCov(o, arc, Eigen::Vector2d(5.0, 0.0), noise, seen, seen, &faces, &longest);
  EXPECT_EQ(faces, 0);
  EXPECT_TRUE(none.isZero());
}

// ShapeOptions::box_view_shared: at knee height a cart 0.9 m long and 0.6 m wide is pushed
// face-on towards the sensor from 8 m to 2.5 m. Its track is fitted as a body (half its width is
// short of a box's length), put at the face the scans show, a quarter of a metre or more in front
// of the cart's centre, and was reported as sure of it as of a person's. The positions are the
// same either way; with the box's view, its measured reports cover the error.
TEST(PipelineScenarioTest, ACartPushedFaceOnAtKneeHeightIsReportedToReachBehindItsFace) {
  Scene scene;
  const MovingBox box = AddMovingBox(scene, {8.0, 0.2}, {2.5, 0.2}, 1.0, 0.45, 0.3);
  TrackerOptions options = Synthetic();
  options.shape.mount = Mount::kLegs;
  ASSERT_TRUE(options.shape.box_view_shared);
  TrackerOptions before = options;
  before.shape.box_view_shared = false;
  const SceneRun run = Simulate(scene, box.end_s + 0.2, options);
  const SceneRun old = Simulate(scene, box.end_s + 0.2, before);
  EXPECT_GT(run.pipeline->counters().box_view_widened, 20u);
  EXPECT_EQ(old.pipeline->counters().box_view_widened, 0u);
  WidenedReports reports;
  double error_m = 0.0, across_m2 = 0.0;
  ForEachReportPair(run, old, [&](std::size_t k, const TrackReport& r, const TrackReport& o) {
    const auto centre = box.centre_at(run.frames[k].t_s);
    if (!centre || r.shape == ObjectShape::kBox) return;
    const int wider = reports.wider;
    reports.Add(r, o, *centre);
    if (reports.wider == wider) return;
    error_m += (Position(r) - *centre).norm();
    across_m2 += (r.covariance - o.covariance)(1, 1);
  });
  ASSERT_GT(reports.wider, 0);
  const double nees = reports.nees / reports.wider;
  const double nees_before = reports.nees_before / reports.wider;
  error_m /= reports.wider;
  SCOPED_TRACE("widened " + std::to_string(reports.wider) + " of " +
               std::to_string(reports.wider + reports.same) + ", error " + std::to_string(error_m) +
               " m, NEES " + std::to_string(nees_before) + " -> " + std::to_string(nees));
  RecordProperty("nees_before", std::to_string(nees_before));
  RecordProperty("nees_after", std::to_string(nees));
  EXPECT_GE(reports.wider, 20);
  EXPECT_GT(error_m, 0.2);
  // Both ends of the face seen (the floor beyond them far, off the face's line): the face is the
  // cart's whole width, nothing added across the ray but the fit's offset from its middle.
  EXPECT_LT(across_m2 / reports.wider, 0.01);
  EXPECT_GT(nees_before, 9.21);
  EXPECT_LT(nees, 3.0);
  EXPECT_GT(nees, 0.3);
}

// ShapeOptions::box_view_at_torso: at upper-body height a cart 1.2 m long and 0.6 m wide crosses
// the room broadside at 5 m, its long side (longer than two box_min_half_length_m) facing the
// sensor: while its track is fitted as a body its reports are widened. A person walking the same
// path (a front, no wider than a body) and a cart 0.6 m square seen at its corner (an outline
// wider than a body, each face shorter than a cart's): never.
TEST(PipelineScenarioTest, AnUpperBodyCartsLongSideIsReportedAsABoxButAPersonIsNot) {
  const TrackerOptions options = Synthetic();
  ASSERT_EQ(options.shape.mount, Mount::kTorso);
  ASSERT_TRUE(options.shape.box_view_shared && options.shape.box_view_at_torso);
  Scene cart;
  const MovingBox box = AddMovingBox(cart, {5.0, -3.0}, {5.0, 3.0}, 1.0, 0.3, 0.6);
  EXPECT_GT(Simulate(cart, box.end_s + 0.2, options).pipeline->counters().box_view_widened, 0u);
  TrackerOptions before = options;
  before.shape.box_view_at_torso = false;
  EXPECT_EQ(Simulate(cart, box.end_s + 0.2, before).pipeline->counters().box_view_widened, 0u);
  Scene square;
  const MovingBox small = AddMovingBox(square, {2.5, 5.0}, {5.0, 2.5}, 1.0, 0.3, 0.3);
  EXPECT_EQ(Simulate(square, small.end_s + 0.2, options).pipeline->counters().box_view_widened, 0u);
  Scene person;
  person.walkers = {Walker::Path(kLearnedS, {{5.0, -3.0}, {5.0, 3.0}}, 1.2)};
  EXPECT_EQ(Simulate(person, person.walkers[0].end_s() + 0.2, options)
                .pipeline->counters()
                .box_view_widened,
            0u);
}

// ShapeOptions::box_view_shared: the cart of the test above with a board 3 m from the sensor
// hiding the far end of its face from 5 m on (the segment ends at the board's edge, no
// silhouette): the face may go on behind it, so its reports are widened along the face by far
// more than with both ends seen.
TEST(PipelineScenarioTest, ACartFaceHiddenAtOneEndIsReportedToGoOnBehindTheOccluder) {
  TrackerOptions options = Synthetic();
  options.shape.mount = Mount::kLegs;
  TrackerOptions before = options;
  before.shape.box_view_shared = false;
  const auto along_face = [&](bool post) {
    Scene scene;
    const MovingBox box = AddMovingBox(scene, {8.0, 0.2}, {2.5, 0.2}, 1.0, 0.45, 0.3);
    if (post) scene.walls.push_back({{3.0, 0.3}, {3.0, 0.9}});
    const SceneRun run = Simulate(scene, box.end_s + 0.2, options);
    const SceneRun old = Simulate(scene, box.end_s + 0.2, before);
    double sum_m2 = 0.0;
    int wider = 0;
    ForEachReportPair(run, old, [&](std::size_t, const TrackReport& r, const TrackReport& o) {
      const double added_m2 = (r.covariance - o.covariance)(1, 1);
      if (std::abs(added_m2) < 1e-12) return;
      sum_m2 += added_m2;
      ++wider;
    });
    SCOPED_TRACE(std::string(post ? "post" : "no post") + ": widened " + std::to_string(wider));
    EXPECT_GT(wider, 10);
    return wider > 0 ? sum_m2 / wider : 0.0;
  };
  const double seen_m2 = along_face(false);
  const double hidden_m2 = along_face(true);
  RecordProperty("along_face_seen_m2", std::to_string(seen_m2));
  RecordProperty("along_face_hidden_m2", std::to_string(hidden_m2));
  EXPECT_GT(hidden_m2, seen_m2 + 0.02);
}

// ShapeOptions::neighbour_sigma_m: two people walk past each other 0.7 m apart at 4.5-5.2 m.
// While the other is within neighbour_distance_m, each one's measured scans are reported wider by
// a multiple of the identity (the positions are the same either way: the filter is not changed);
// apart, as before. Off: none counted, every report as a lone person's.
TEST(PipelineScenarioTest, APersonBesideAnotherIsReportedWider) {
  Scene scene;
  scene.walkers = {Walker::Path(kLearnedS, {{4.5, -3.5}, {4.5, 3.5}}, 1.2),
                   Walker::Path(kLearnedS, {{5.2, 3.5}, {5.2, -3.5}}, 1.2)};
  const double end_s = std::max(scene.walkers[0].end_s(), scene.walkers[1].end_s());
  // The term alone: the gain covariance's measured noise (which these terms gate) left out.
  const TrackerOptions options = GainCovarianceOff(Synthetic());
  ASSERT_GT(options.shape.neighbour_sigma_m, 0.0);
  TrackerOptions before = options;
  before.shape.neighbour_sigma_m = 0.0;
  const SceneRun run = Simulate(scene, end_s + 0.5, options);
  const SceneRun old = Simulate(scene, end_s + 0.5, before);
  EXPECT_GT(run.pipeline->counters().neighbour_widened, 20u);
  EXPECT_EQ(old.pipeline->counters().neighbour_widened, 0u);
  int wider = 0, same = 0;
  ForEachReportPair(run, old, [&](std::size_t, const TrackReport& r, const TrackReport& o) {
    const Eigen::Matrix2d added =
        r.covariance.topLeftCorner<2, 2>() - o.covariance.topLeftCorner<2, 2>();
    if (added.norm() < 1e-12) {
      ++same;
      return;
    }
    ++wider;
    EXPECT_GT(added(0, 0), 0.0);
    EXPECT_NEAR(added(0, 0), added(1, 1), 1e-12);
    EXPECT_NEAR(added(0, 1), 0.0, 1e-12);
    EXPECT_LE(added(0, 0), options.shape.neighbour_sigma_m * options.shape.neighbour_sigma_m);
  });
  EXPECT_GE(wider, 20);
  EXPECT_GT(same, 100);
}

// ShapeOptions::underdetermined_fit_shared: a scanner with a coarse 1.5 deg step sees a person
// walking across its view at 7 m with two or three beams, fewer points and silhouette ends than
// the fit's five parameters: the fit's centre is what its priors make of them, shared by the
// scans. The positions are the same either way; such scans are reported with the fit's centre
// covariance added (a positive definite difference), and their NEES is lower. Off: none counted.
TEST(PipelineScenarioTest, AnUnderdeterminedFitIsReportedWithItsFitsCovariance) {
  Scene scene;
  scene.walkers = {Walker::Path(kLearnedS, {{7.0, -3.0}, {7.0, 3.0}}, 1.2)};
  const Walker& walker = scene.walkers[0];
  ScannerConfig coarse;
  coarse.angle_step_rad = common::DegToRad(1.5);
  coarse.beams = 181;
  // The term alone: the gain covariance's measured noise (which these terms gate) left out.
  const TrackerOptions options = GainCovarianceOff(Synthetic());
  ASSERT_TRUE(options.shape.underdetermined_fit_shared);
  TrackerOptions before = options;
  before.shape.underdetermined_fit_shared = false;
  const SceneRun run = Simulate(scene, walker.end_s() + 0.5, options, coarse);
  const SceneRun old = Simulate(scene, walker.end_s() + 0.5, before, coarse);
  EXPECT_GT(run.pipeline->counters().underdetermined_fit_widened, 20u);
  EXPECT_EQ(old.pipeline->counters().underdetermined_fit_widened, 0u);
  WidenedReports widened;
  ForEachReportPair(run, old, [&](std::size_t k, const TrackReport& r, const TrackReport& o) {
    if (run.frames[k].truth[0]) widened.Add(r, o, *run.frames[k].truth[0]);
  });
  EXPECT_GE(widened.wider, 20);
  EXPECT_LT(widened.nees, widened.nees_before);
}

TEST(PipelineScenarioTest, AWideBeamDoesNotPullTheCentreTowardsTheSensor) {
  // A 0.25 m cylinder crossing the line of sight at 8-10 m, scanned at 0.5 deg by beams that return
  // it when their centre ray is on it (a beam of the LMS1xx's 15 mrad, wider than the step,
  // returns the body when at least half its energy falls on it): with the default divergence the
  // silhouette still ends half a step beyond the last beam, so the learnt size is the body's and
  // the centre is not pulled towards the sensor. Taking the tangent at the last beam's centre (as
  // the tracker did when the divergence exceeded the step) put the centre 0.035 m in front of the
  // body here.
  TrackerOptions options = Synthetic();
  options.shape.beam_divergence_rad = TrackerOptions{}.shape.beam_divergence_rad;
  ASSERT_GT(options.shape.beam_divergence_rad, common::DegToRad(0.5));
  Scene scene;
  scene.walls = {};
  scene.walkers = {Walker::Path(kLearnedS, {{9.0, -4.0}, {9.0, 4.0}}, 1.0)};
  scene.sizes = {{0.25, 0.25}};
  const Walker& walker = scene.walkers[0];
  const SceneRun run = Simulate(scene, walker.end_s(), options);
  double radial_sum = 0.0, across_sum = 0.0, size_sum = 0.0;
  int n = 0;
  for (const Frame& f : run.frames) {
    if (!f.truth[0] || f.t_s < walker.start_s() + 2.0) continue;
    const Eigen::Vector2d los = f.truth[0]->normalized();
    for (const TrackReport& r : f.tracks) {
      const Eigen::Vector2d e = Position(r) - *f.truth[0];
      if (r.state != TrackState::kConfirmed || e.norm() > 0.4) continue;
      radial_sum += e.dot(los);
      across_sum += std::abs(e.x() * los.y() - e.y() * los.x());
      size_sum += 0.5 * (r.size_major_m + r.size_minor_m);
      ++n;
    }
  }
  ASSERT_GT(n, 100);
  // Now: radial +0.003 m, size 0.251 m.
  EXPECT_LT(std::abs(radial_sum / n), 0.015) << "radial " << radial_sum / n;
  EXPECT_LT(across_sum / n, 0.02);
  EXPECT_NEAR(size_sum / n, 0.25, 0.02);
  RecordProperty("mean_radial_error_m", std::to_string(radial_sum / n));
  RecordProperty("mean_size_m", std::to_string(size_sum / n));
}

// A person walking from 29.5 m to 26.5 m towards the scanner in front of a wall at 31 m, scanned by
// an LMS1xx at 0.25 deg (beam footprint 0.43 m at 28 m, as wide as the shoulders; 4 beams on them):
// the beams at the body's edges fall partly on the wall and return one range between the two (half
// way here, as a receiver merging both echoes does). Results of a run: the radial error of the
// confirmed tracks (+: beyond the body centre) and their mean NEES.
struct MixedPixelRun {
  double radial_mean_m = 0.0;
  double nees_mean = 0.0;
  int matches = 0;
};

// Confirmed tracks within 0.5 m of one body's true centre, summed over a run's scans: their error
// along the line of sight (+: beyond the body centre), its length and their NEES.
struct AlongRayScore {
  double radial_sum_m = 0.0;
  double error_sum_m = 0.0;
  double nees_sum = 0.0;
  int matches = 0;
  void Add(const ScanTracks& out, const Eigen::Vector2d& truth) {
    const Eigen::Vector2d los = truth.normalized();
    for (const TrackReport& r : out.tracks) {
      const Eigen::Vector2d e = Position(r) - truth;
      if (r.state != TrackState::kConfirmed || e.norm() > 0.5) continue;
      radial_sum_m += e.dot(los);
      error_sum_m += e.norm();
      nees_sum += e.dot(r.covariance.topLeftCorner<2, 2>().ldlt().solve(e));
      ++matches;
    }
  }
  double Mean(double sum) const { return matches > 0 ? sum / matches : 0.0; }
};

// Walkers (each a 0.25 x 0.15 m body) past walls, every scan's ranges changed by mix(clean, mixed)
// before the pipeline sees them; the first walker scored from 1 s after it starts.
template <typename Mix>
AlongRayScore RunMixedScans(SyntheticScanner& scanner, TrackingPipeline& pipeline,
                            const std::vector<Wall>& walls, const std::vector<Walker>& walkers,
                            Mix mix) {
  std::vector<Body> bodies;
  std::vector<float> mixed;
  AlongRayScore score;
  const Walker& scored = walkers.front();
  const auto scans = static_cast<std::int64_t>(std::lround(scored.end_s() * kRateHz));
  for (std::int64_t k = 0; k < scans; ++k) {
    const double t_s = scanner.ScanTimeS(k);
    bodies.clear();
    for (const Walker& w : walkers) {
      if (const auto p = w.At(t_s)) bodies.push_back({*p, 0.25, 0.15, w.YawAt(t_s)});
    }
    const ScanView clean = scanner.Render(k, walls, bodies);
    mixed.assign(clean.range_m.begin(), clean.range_m.end());
    mix(clean, mixed);
    ScanView scan = clean;
    scan.range_m = mixed;
    const ScanTracks& out = pipeline.Process(scan, static_cast<std::uint32_t>(k));
    const auto truth = scored.At(t_s);
    if (!truth || t_s < scored.start_s() + 1.0) continue;
    score.Add(out, *truth);
  }
  return score;
}

MixedPixelRun RunMixedPixels(const TrackerOptions& options) {
  ScannerConfig config;
  config.max_range_m = 40.0;
  config.angle_step_rad = common::DegToRad(0.25);
  config.beams = 1081;
  SyntheticScanner scanner(config);
  TrackingPipeline pipeline(options);
  const std::vector<Wall> walls = {{{31.0, -8.0}, {31.0, 8.0}}};
  const Walker walker = Walker::Path(kLearnedS, {{29.5, 0.5}, {26.5, 0.5}}, 1.0);
  const AlongRayScore score = RunMixedScans(
      scanner, pipeline, walls, {walker}, [](const ScanView& clean, std::vector<float>& mixed) {
        // The first and last beam on the body: half on the wall behind.
        for (std::size_t i = 1; i + 1 < mixed.size(); ++i) {
          const auto on_body = [&](std::size_t j) {
            return clean.range_m[j] > 0.0f && clean.range_m[j] < 30.0f;
          };
          if (on_body(i) && (!on_body(i - 1) || !on_body(i + 1))) {
            mixed[i] = 0.5f * (clean.range_m[i] +
                               (on_body(i - 1) ? clean.range_m[i + 1] : clean.range_m[i - 1]));
          }
        }
      });
  return {score.Mean(score.radial_sum_m), score.Mean(score.nees_sum), score.matches};
}

TEST(PipelineScenarioTest, MixedPixelsAtAFarBodysEdgesDoNotPushItsCentreAway) {
  TrackerOptions options;
  options.background.max_range_m = 40.0;
  options.shape.person_exponent = 2.0;
  // The body the mixed pixels widen becomes a box without them left out: its covariance, with the
  // box's unseen depth in it (box_unseen_depth_cov), would hide how far off its centre is.
  options.shape.box_unseen_depth_cov = false;
  options.shape.box_seen_extent_cov = false;
  // The mixed-pixel rule alone (split_deep_tail cuts such edge points off too).
  options.shape.split_deep_tail = false;
  const MixedPixelRun with = RunMixedPixels(options);
  options.shape.mixed_pixel_min_footprint_m = 0.0;
  const MixedPixelRun without = RunMixedPixels(options);
  // About 50 scans of the walk are scored with either.
  ASSERT_GT(with.matches, 30);
  ASSERT_GT(without.matches, 30);
  // Measured: -0.026 m with the mixed edge points left out of the fit, +0.34 m with them (NEES 1.4
  // against 30).
  EXPECT_LT(std::abs(with.radial_mean_m), 0.06) << "without: " << without.radial_mean_m;
  EXPECT_GT(without.radial_mean_m, 0.2);
  // The covariance still covers the error.
  EXPECT_GT(with.nees_mean, 0.3);
  EXPECT_LT(with.nees_mean, 3.0);
  EXPECT_GT(without.nees_mean, 9.0);
}

// Two people walking side by side towards the sensor, the second 0.7 m behind and 0.35 m to the
// side of the first: the first hides most of the second, and the beam at the first one's edge
// returns a mixed pixel halfway to the second (as a footprint on both does). Through it the
// segmentation's jump limit joins the second one's visible sliver to the first one's segment.
struct DeepTailRun {
  double radial_mean_m = 0.0;  // the first person's matched track, along the ray
  double error_mean_m = 0.0;
  int matches = 0;
  std::uint64_t cuts = 0;
};

DeepTailRun RunDeepTail(const TrackerOptions& options) {
  SyntheticScanner scanner;
  TrackingPipeline pipeline(options);
  const std::vector<Wall> walls = {{{12.0, -6.0}, {12.0, 6.0}}};
  const Walker front = Walker::Path(kLearnedS, {{9.5, 0.0}, {6.5, 0.0}}, 1.0);
  const Walker behind = Walker::Path(kLearnedS, {{10.2, 0.35}, {7.2, 0.35}}, 1.0);
  const AlongRayScore score = RunMixedScans(
      scanner, pipeline, walls, {front, behind},
      [](const ScanView& clean, std::vector<float>& mixed) {
        // A body's edge beam beside a body behind it (not the wall): the mean of the two ranges.
        for (std::size_t i = 1; i + 1 < mixed.size(); ++i) {
          for (const std::size_t j : {i - 1, i + 1}) {
            if (clean.range_m[i] > 0.0f && clean.range_m[j] > clean.range_m[i] + 0.2f &&
                clean.range_m[j] < 11.0f) {
              mixed[i] = 0.5f * (clean.range_m[i] + clean.range_m[j]);
            }
          }
        }
      });
  return {score.Mean(score.radial_sum_m), score.Mean(score.error_sum_m), score.matches,
          pipeline.counters().deep_tail_cuts};
}

TEST(PipelineScenarioTest, APersonBehindJoinedThroughAMixedPixelDoesNotPullTheCentreBack) {
  TrackerOptions options;
  const DeepTailRun with = RunDeepTail(options);
  options.shape.split_deep_tail = false;
  const DeepTailRun without = RunDeepTail(options);
  // About 50 scans of the walk are scored with either.
  ASSERT_GT(with.matches, 30);
  ASSERT_GT(without.matches, 30);
  EXPECT_GT(with.cuts, 30u);
  EXPECT_EQ(without.cuts, 0u);
  // Measured: +0.048 m along the ray (mean error 0.064 m) with the tail cut off, +0.233 m (0.253
  // m) with it.
  EXPECT_LT(std::abs(with.radial_mean_m), 0.08) << "without: " << without.radial_mean_m;
  EXPECT_GT(without.radial_mean_m, 0.15);
  EXPECT_LT(with.error_mean_m, 0.1) << "without: " << without.error_mean_m;
  EXPECT_GT(without.error_mean_m, 0.2);
}

// A scanner whose beams have a footprint (an LMS1xx's 15 mrad at 0.5 deg and 50 Hz, 30 m): five
// rays at -1, -1/2, 0, 1/2, 1 half-widths carrying 10, 20, 40, 20, 10 % of the energy; a beam
// returns its nearest surface when it carries at least 80 % of the energy, what lies behind when
// it carries at most 20 %, and between those a mixed pixel, the energy-weighted mean range (as
// tools/sim's device model, and real scanners at edges).
class FootprintScanner {
 public:
  static constexpr double kDivergenceRad = 0.015;
  FootprintScanner() {
    for (std::size_t j = 0; j < kRays; ++j) {
      ScannerConfig c;
      c.rate_hz = 50.0;
      c.max_range_m = 30.0;
      c.seed = static_cast<std::uint32_t>(11 + j);
      c.first_angle_rad += 0.5 * kDivergenceRad * kOffset[j];
      rays_.push_back(std::make_unique<SyntheticScanner>(c));
    }
    ranges_.resize(rays_[0]->config().beams);
  }
  double ScanTimeS(std::int64_t k) const { return rays_[0]->ScanTimeS(k); }

  template <typename BodiesAt>
  ScanView Render(std::int64_t k, std::span<const Wall> walls, const BodiesAt& bodies_at) {
    std::array<ScanView, kRays> views;
    for (std::size_t j = 0; j < kRays; ++j) views[j] = rays_[j]->RenderTimed(k, walls, bodies_at);
    for (std::size_t i = 0; i < ranges_.size(); ++i) {
      double nearest = std::numeric_limits<double>::infinity();
      for (const ScanView& v : views) {
        if (v.range_m[i] > 0.0f) nearest = std::min(nearest, static_cast<double>(v.range_m[i]));
      }
      double near_w = 0.0, near_sum = 0.0, far_w = 0.0, far_sum = 0.0;
      for (std::size_t j = 0; j < kRays; ++j) {
        const double r = views[j].range_m[i];
        if (!(r > 0.0)) continue;
        (r < nearest + 0.1 ? near_w : far_w) += kWeight[j];
        (r < nearest + 0.1 ? near_sum : far_sum) += kWeight[j] * r;
      }
      double out = 0.0;
      if (near_w >= 0.8 - 1e-9 || (near_w > 0.0 && far_w == 0.0)) {
        out = near_sum / near_w;
      } else if (near_w <= 0.2 + 1e-9) {
        out = far_w > 0.0 ? far_sum / far_w : 0.0;
      } else {
        out = (near_sum + far_sum) / (near_w + far_w);
      }
      ranges_[i] = static_cast<float>(out);
    }
    ScanView view = views[0];
    view.first_angle_rad = ScannerConfig{}.first_angle_rad;
    view.range_m = ranges_;
    return view;
  }

 private:
  static constexpr std::size_t kRays = 5;
  static constexpr std::array<double, kRays> kOffset = {-1.0, -0.5, 0.0, 0.5, 1.0};
  static constexpr std::array<double, kRays> kWeight = {0.1, 0.2, 0.4, 0.2, 0.1};
  std::vector<std::unique_ptr<SyntheticScanner>> rays_;
  std::vector<float> ranges_;
};

// One person walking at knee height across a hall 16 m deep with a pillar and a cabinet, scanned
// with a real beam footprint: beyond ~8 m a leg fills no beam, and the beams on it report mixed
// pixels between the leg and the wall, leg-sized pieces up to metres behind the person. They must
// not become tracks: every reported track is the person's.
TEST(PipelineScenarioTest, MixedPixelsBehindLegsAtKneeHeightGiveNoFalseTracks) {
  const std::vector<Wall> hall = {{{16.0, -8.0}, {16.0, 8.0}},
                                  {{16.0, 8.0}, {-1.0, 8.0}},
                                  {{-1.0, 8.0}, {-1.0, -8.0}},
                                  {{-1.0, -8.0}, {16.0, -8.0}}};
  const std::vector<Body> statics = {testing::Cylinder({13.0, 3.0}, 0.2),
                                     {{12.0, -5.0}, 0.6, 0.3, 0.4}};
  const Walker walker =
      Walker::Path(kLearnedS, {{7.0, -5.0}, {8.5, 5.0}, {6.0, 0.0}, {9.0, -3.0}}, 1.2);
  const Legs legs(walker);
  std::vector<Body> bodies;
  const auto bodies_at = [&](double t_s) -> const std::vector<Body>& {
    bodies = statics;
    legs.Add(t_s, bodies);
    return bodies;
  };
  struct Outcome {
    std::map<std::uint32_t, std::pair<int, int>> reports;  // per id: matched, unmatched
    int person_frames = 0, matched = 0;
    PipelineCounters counters;
    // Tracks unmatched in more than half of their reports (tracking_benchmark's false tracks),
    // and their unmatched reports.
    int FalseTracks() const {
      int n = 0;
      for (const auto& [id, mu] : reports) n += mu.second > mu.first ? 1 : 0;
      return n;
    }
    int FalseReports() const {
      int n = 0;
      for (const auto& [id, mu] : reports) n += mu.second > mu.first ? mu.second : 0;
      return n;
    }
  };
  const auto run = [&](bool drop, double recent_veil_s = 0.0) {
    TrackerOptions options;
    options.shape.mount = Mount::kLegs;
    options.shape.drop_mixed_pixel_legs = drop;
    // The rules of one scan alone unless asked (shape.recent_veil_s: below).
    options.shape.recent_veil_s = recent_veil_s;
    // The mixed-pixel rules alone: the confirmation in time takes most of the mixed pixels' false
    // tracks too, and costs this sparsely seen walker (in ~25 % of the scans at 7-9 m) most of
    // their track: matched in 28 % instead of 81 % of the scans (see confirm_min_s).
    options.tracking.confirm_min_s = 0.0;
    TrackingPipeline pipeline(options);
    FootprintScanner scanner;
    Outcome out;
    const auto scans = static_cast<std::int64_t>((walker.end_s() + 1.0) * 50.0);
    for (std::int64_t k = 0; k < scans; ++k) {
      const double t_s = scanner.ScanTimeS(k);
      const ScanView scan = scanner.Render(k, hall, bodies_at);
      const ScanTracks& tracks = pipeline.Process(scan, static_cast<std::uint32_t>(k));
      const auto truth = walker.At(t_s);
      bool matched = false;
      for (const TrackReport& r : tracks.tracks) {
        const bool near = truth && (Position(r) - *truth).norm() <= 0.5;
        ++(near ? out.reports[r.track_id].first : out.reports[r.track_id].second);
        matched = matched || near;
      }
      if (truth && t_s > walker.start_s() + 1.0) {
        ++out.person_frames;
        out.matched += matched ? 1 : 0;
      }
    }
    out.counters = pipeline.counters();
    return out;
  };
  const Outcome now = run(true);
  const Outcome before = run(false);
  RecordProperty("false_tracks", std::to_string(now.FalseTracks()) + " (" +
                                     std::to_string(before.FalseTracks()) + " keeping them)");
  RecordProperty("false_reports", std::to_string(now.FalseReports()) + " (" +
                                      std::to_string(before.FalseReports()) + " keeping them)");
  // The scene makes mixed pixels that become tracks when they are taken for legs (now: 4 false
  // tracks, 663 reports).
  EXPECT_GE(before.FalseTracks(), 3);
  EXPECT_GT(before.FalseReports(), 400);
  // Dropped, one short-lived false track is left (now: 26 reports, 0.5 s, born while the
  // person's own track lagged 0.3 m behind a turn).
  EXPECT_LE(now.FalseTracks(), 1);
  EXPECT_LT(now.FalseReports(), 40);
  EXPECT_GT(now.counters.veiled_segments, 50u);
  EXPECT_GT(now.counters.shadowed_legs, 50u);
  // The person is tracked as well as with the mixed pixels kept (here 82 % of the scans after the
  // first second: at 8-9 m a 0.12 m leg often fills no beam of a 0.13 m footprint).
  ASSERT_GT(now.person_frames, 700);
  EXPECT_GT(now.matched, 0.75 * now.person_frames);
  EXPECT_GE(now.matched, before.matched - now.person_frames / 100);
  // shape.recent_veil_s alone (the rules of one scan off): the echoes behind the return their
  // beams had in the last 0.3 s are dropped, and with them the false tracks (here 1 short one,
  // 11 reports), the person tracked as well.
  const Outcome recent = run(false, 0.3);
  RecordProperty("false_tracks_recent_veil", std::to_string(recent.FalseTracks()));
  EXPECT_LE(recent.FalseTracks(), 1);
  EXPECT_LT(recent.FalseReports(), 40);
  EXPECT_GT(recent.counters.recently_veiled, 50u);
  EXPECT_GE(recent.matched, before.matched - recent.person_frames / 100);
}

// ShapeOptions::torso_edge_echo: a person walking at upper-body height across a hall 20 m from
// the sensor (0.5 deg, 15 mrad: two beams' footprints reach past an edge), its back wall at 24 m.
// The two beams beside the body's far edge report a mix of the body and the wall, 1.5 m behind
// the body: a two-beam piece that walks with the person. Taken for a body it starts a track
// where nobody is; as evidence only it starts none, and the person is tracked as well. A piece
// 1.2 m behind the body with the wall 10 m behind (a second person almost in line: a mix would
// lie at least 2 m behind) starts its track as before.
struct EdgeEchoes {
  int far_reports = 0;  // reports farther than 0.5 m from the person
  int person_frames = 0, matched = 0;
  std::uint64_t echoes = 0;
};

EdgeEchoes WalkPastEdgeEchoes(bool echo_rule, double behind_m, double wall_m = 24.0) {
  const std::vector<Wall> hall = {{{wall_m, -9.0}, {wall_m, 9.0}},
                                  {{wall_m, 9.0}, {-1.0, 9.0}},
                                  {{-1.0, 9.0}, {-1.0, -9.0}},
                                  {{-1.0, -9.0}, {wall_m, -9.0}}};
  const Walker walker = Walker::Path(kLearnedS, {{20.0, -4.0}, {20.0, 4.0}}, 1.0);
  TrackerOptions options;
  options.shape.torso_edge_echo = echo_rule;
  TrackingPipeline pipeline(options);
  ScannerConfig config;
  config.max_range_m = 40.0;
  SyntheticScanner scanner(config);
  EdgeEchoes out;
  std::vector<Body> bodies;
  std::vector<float> ranges;
  const auto scans = static_cast<std::int64_t>((walker.end_s() + 0.5) * scanner.config().rate_hz);
  for (std::int64_t k = 0; k < scans; ++k) {
    const double t_s = scanner.ScanTimeS(k);
    ScanView scan = scanner.RenderTimed(k, hall, [&](double bt_s) -> const std::vector<Body>& {
      bodies.clear();
      if (const auto p = walker.At(bt_s)) bodies.push_back({*p, 0.25, 0.15, walker.YawAt(bt_s)});
      return bodies;
    });
    ranges.assign(scan.range_m.begin(), scan.range_m.end());
    // The body's beams (nearer than the wall), the two after its last one: the mix.
    std::size_t last = ranges.size();
    for (std::size_t i = 0; i < ranges.size(); ++i) {
      const double angle = scan.first_angle_rad + static_cast<double>(i) * scan.angle_step_rad;
      if (std::abs(angle) < 0.4 && ranges[i] > 0.0f && ranges[i] < 22.0f) last = i;
    }
    if (last + 2 < ranges.size()) {
      for (std::size_t j = last + 1; j <= last + 2; ++j) {
        ranges[j] = ranges[last] + static_cast<float>(behind_m);
      }
    }
    scan.range_m = ranges;
    const ScanTracks& tracks = pipeline.Process(scan, static_cast<std::uint32_t>(k));
    const auto truth = walker.At(t_s);
    bool held = false;
    for (const TrackReport& r : tracks.tracks) {
      const bool near = truth && (Position(r) - *truth).norm() <= 0.5;
      out.far_reports += near ? 0 : 1;
      held = held || near;
    }
    if (truth && t_s > walker.start_s() + 1.0) {
      ++out.person_frames;
      out.matched += held ? 1 : 0;
    }
  }
  out.echoes = pipeline.counters().torso_edge_echoes;
  return out;
}

TEST(PipelineScenarioTest, EdgeEchoesBehindAFarPersonAtUpperBodyHeightStartNoTrack) {
  const EdgeEchoes before = WalkPastEdgeEchoes(false, 1.5), now = WalkPastEdgeEchoes(true, 1.5);
  const EdgeEchoes in_line = WalkPastEdgeEchoes(true, 1.2, 30.0);
  const auto describe = [](const EdgeEchoes& e) {
    return "far reports " + std::to_string(e.far_reports) + ", matched " +
           std::to_string(e.matched) + " of " + std::to_string(e.person_frames) + ", echoes " +
           std::to_string(e.echoes);
  };
  SCOPED_TRACE("before: " + describe(before) + "; now: " + describe(now) +
               "; in line: " + describe(in_line));
  EXPECT_EQ(before.echoes, 0u);
  EXPECT_GT(before.far_reports, before.person_frames / 2);  // a second track behind the person
  EXPECT_GT(now.echoes, 0u);
  EXPECT_EQ(now.far_reports, 0);
  ASSERT_GT(now.person_frames, 100);
  EXPECT_GE(now.matched, before.matched - now.person_frames / 100);
  EXPECT_GT(now.matched, now.person_frames * 9 / 10);
  // Nearer than a mix with the wall: its track as before.
  EXPECT_LE(in_line.echoes, static_cast<std::uint64_t>(in_line.person_frames / 20));
  EXPECT_GT(in_line.far_reports, in_line.person_frames / 2);
}

// Knee height, 50 Hz, 0.25 deg: a person at 15 m returned by a single beam (their legs fill no
// beam's 0.22 m footprint) walks across the view; 3 m behind them, 5 beams (0.33 m across) to the
// side, their other leg's mixed pixels form a 3-beam leg-sized segment that walks with them. Beside
// the return (within max_missing_beams + 1 = 3 beams) the old rule sees nothing nearer; within
// leg_pairing_distance_m of it, the segment is the person's shadow. A real pair of legs 1.2 m
// beside the return is kept.
TEST(PipelineScenarioTest, MixedPixelsWithinAPersonsReachOfANearerReturnAreNotLegs) {
  constexpr std::size_t kBeams = 541;
  constexpr double kStepRad = 0.25 * common::kPi / 180.0;
  const auto run = [&](bool whole_person, bool real_legs, bool wall = false) {
    TrackerOptions options;
    options.shape.mount = Mount::kLegs;
    options.shape.drop_mixed_pixel_legs_whole_person = whole_person;
    // At 18 m a leg covers less than half a footprint: that rule alone would start no track.
    options.shape.far_legs_no_birth = false;
    TrackingPipeline pipeline(options);
    std::vector<float> ranges(kBeams);
    std::set<std::uint32_t> ids;
    std::uint64_t veiled_before = 0;
    for (std::int64_t k = 0; k < static_cast<std::int64_t>((kLearnedS + 3.0) * 50.0); ++k) {
      const double t_s = static_cast<double>(k) / 50.0;
      std::fill(ranges.begin(), ranges.end(), 30.0f);
      if (t_s >= kLearnedS) {
        // One beam every 8 scans: 0.49 m/s across at 18 m.
        const auto near = static_cast<std::size_t>(200 + (k - 300) / 8);
        ranges[near] = 15.0f;
        // A wall's end instead of a person: 2 m of beams at 15 m ending at the same beam.
        if (wall)
          std::fill(ranges.begin() + 100, ranges.begin() + static_cast<std::ptrdiff_t>(near) + 1,
                    15.0f);
        for (std::size_t b = near + 5; b < near + 8; ++b) ranges[b] = 18.0f;
        if (real_legs) {
          // Two legs 1.2 m (+ 0.3 m) across at 15 m: 4 beams each, 0.15 m apart.
          for (std::size_t b = near + 18; b < near + 22; ++b) ranges[b] = 15.0f;
          for (std::size_t b = near + 24; b < near + 28; ++b) ranges[b] = 15.0f;
        }
      } else if (k == 299) {
        veiled_before = pipeline.counters().veiled_segments;
      }
      const ScanView scan =
          RangesScan(ranges, -0.5 * static_cast<double>(kBeams - 1) * kStepRad, kStepRad, k, 20);
      for (const TrackReport& r : pipeline.Process(scan, static_cast<std::uint32_t>(k)).tracks) {
        ids.insert(r.track_id);
      }
    }
    return std::make_pair(ids.size(), pipeline.counters().veiled_segments - veiled_before);
  };
  const auto [tracks_now, veiled_now] = run(true, false);
  const auto [tracks_before, veiled_before] = run(false, false);
  EXPECT_EQ(tracks_now, 0u);
  EXPECT_GE(veiled_now, 140u);  // every scan of the 3 s
  EXPECT_EQ(tracks_before, 1u);
  EXPECT_EQ(veiled_before, 0u);
  // A person walking beside the single return, beyond the pairing distance: tracked.
  const auto [tracks_beside, veiled_beside] = run(true, true);
  EXPECT_EQ(tracks_beside, 1u);
  EXPECT_GE(veiled_beside, 140u);
  // The same segment 5 beams beside a wall's end is not a person's shadow (a wall's mixed pixels
  // lie at its edge beam only): kept, as without the rule.
  const auto [tracks_wall, veiled_wall] = run(true, false, true);
  EXPECT_EQ(tracks_wall, 1u);
  EXPECT_EQ(veiled_wall, 0u);
}

// Knee height, 25 Hz, 0.5 deg, a wall at 30 m: a far leg (27 m, where the beam's footprint,
// 0.41 m, is three times a leg) grazed by two adjacent beams whose echoes, part leg and part wall,
// lie 0.7 m apart in range: a piece 0.74 m long, all of it along the line of sight (one beam's
// spacing, 0.24 m, across); or by three (0.47 m across: within the leg's diameter and a
// footprint). It moves across the view at 0.74 m/s for 3 s. With
// shape.drop_deep_mixed_pixel_pieces it is no object (dropped every scan, no track); without, it
// was measured as a wide object and reported as a track. The same piece seen by a scanner whose
// beam diverges 4 mrad (a leg fills its footprint out to 30 m: the echoes are the leg's), and an
// object 0.52 m wide across the beams at 20 m, are kept: one track each, with or without the rule.
TEST(PipelineScenarioTest, FarPiecesDeepAlongTheRayAreMixedPixelsNotObjects) {
  constexpr std::size_t kBeams = 361;
  constexpr double kStepRad = 0.5 * common::kPi / 180.0;
  enum class Piece { kDeepFar, kDeepFarThreeBeams, kDeepFarNarrowBeam, kWideFar };
  const auto run = [&](bool rule, Piece piece) {
    TrackerOptions options;
    options.shape.mount = Mount::kLegs;
    options.shape.drop_deep_mixed_pixel_pieces = rule;
    if (piece == Piece::kDeepFarNarrowBeam) options.shape.beam_divergence_rad = 0.004;
    TrackingPipeline pipeline(options);
    std::vector<float> ranges(kBeams);
    std::set<std::uint32_t> ids;
    std::uint64_t dropped_before = 0;
    const auto k0 = static_cast<std::int64_t>(kLearnedS * 25.0);
    for (std::int64_t k = 0; k < k0 + 75; ++k) {
      std::fill(ranges.begin(), ranges.end(), 30.0f);
      if (k >= k0) {
        const auto b = static_cast<std::size_t>(150 + (k - k0) / 8);
        switch (piece) {
          case Piece::kDeepFar:
          case Piece::kDeepFarNarrowBeam:
            ranges[b] = 26.9f;
            ranges[b + 1] = 27.6f;
            break;
          case Piece::kDeepFarThreeBeams:
            ranges[b] = 26.9f;
            ranges[b + 1] = 27.6f;
            ranges[b + 2] = 27.2f;
            break;
          case Piece::kWideFar:
            std::fill(ranges.begin() + static_cast<std::ptrdiff_t>(b),
                      ranges.begin() + static_cast<std::ptrdiff_t>(b + 4), 20.0f);
            break;
        }
      } else if (k == k0 - 1) {
        dropped_before = pipeline.counters().veiled_segments;
      }
      const ScanView scan = RangesScan(ranges, -0.5 * common::kPi, kStepRad, k, 40);
      for (const TrackReport& r : pipeline.Process(scan, static_cast<std::uint32_t>(k)).tracks) {
        ids.insert(r.track_id);
      }
    }
    return std::make_pair(ids.size(), pipeline.counters().veiled_segments - dropped_before);
  };
  for (const Piece piece : {Piece::kDeepFar, Piece::kDeepFarThreeBeams}) {
    const auto [deep_now, dropped_now] = run(true, piece);
    EXPECT_EQ(deep_now, 0u) << static_cast<int>(piece);
    EXPECT_EQ(dropped_now, 75u) << static_cast<int>(piece);  // every scan
    const auto [deep_before, dropped_without] = run(false, piece);
    EXPECT_EQ(deep_before, 1u) << static_cast<int>(piece);
    EXPECT_EQ(dropped_without, 0u) << static_cast<int>(piece);
  }
  for (const bool rule : {true, false}) {
    for (const Piece piece : {Piece::kDeepFarNarrowBeam, Piece::kWideFar}) {
      const auto [tracks, dropped] = run(rule, piece);
      EXPECT_EQ(tracks, 1u) << rule << " " << static_cast<int>(piece);
      EXPECT_EQ(dropped, 0u) << rule << " " << static_cast<int>(piece);
    }
  }
}

// Knee height, 25 Hz, 0.5 deg (0.105 m between beams at 12 m, where a leg fills no beam's
// footprint): a person walks straight away from the sensor from 12 m at 0.75 m/s for 3 s, legs in
// radial stride, the near one returned by two beams, the far one 0.45 m behind it and 0.2 m to
// the side by two more: one segment 0.56 m long, 0.31 m across the ray, a deep piece by its shape,
// over more beams (4) than one leg's footprint touches there (3).
// The wall behind stands 18 m farther (30 m): nothing for those echoes to mix with, so with
// shape.deep_mixed_pixel_behind_ratio the piece is kept (one track, counted as kept every scan);
// with the ratio 0 it is dropped by its shape (no track). The same shape 12 m away with a wall
// 1.2 m behind the piece's far end (within 4 times its 0.47 m depth: mixed pixels between the near
// leg and the wall) is dropped either way.
TEST(PipelineScenarioTest, DeepPieceIsDroppedOnlyWithASurfaceBehindToMixWith) {
  constexpr std::size_t kBeams = 361;
  constexpr double kStepRad = 0.5 * common::kPi / 180.0;
  const auto run = [&](double ratio, float wall_m) {
    TrackerOptions options;
    options.shape.mount = Mount::kLegs;
    options.shape.deep_mixed_pixel_behind_ratio = ratio;
    TrackingPipeline pipeline(options);
    std::vector<float> ranges(kBeams);
    std::set<std::uint32_t> ids;
    std::uint64_t dropped_before = 0, kept_before = 0;
    const auto k0 = static_cast<std::int64_t>(kLearnedS * 25.0);
    for (std::int64_t k = 0; k < k0 + 75; ++k) {
      std::fill(ranges.begin(), ranges.end(), wall_m);
      if (k >= k0) {
        // Walking away keeps the gap to a near wall: the wall is the piece's surface behind.
        const float walked =
            wall_m < 20.0f ? 0.0f : 0.03f * static_cast<float>(k - k0);  // 0.75 m/s
        const float near_leg[] = {12.0f, 12.02f, 12.45f, 12.47f};
        for (std::size_t i = 0; i < 4; ++i) ranges[180 + i] = near_leg[i] + walked;
      } else if (k == k0 - 1) {
        dropped_before = pipeline.counters().veiled_segments;
        kept_before = pipeline.counters().deep_pieces_kept;
      }
      const ScanView scan = RangesScan(ranges, -0.5 * common::kPi, kStepRad, k, 40);
      for (const TrackReport& r : pipeline.Process(scan, static_cast<std::uint32_t>(k)).tracks) {
        ids.insert(r.track_id);
      }
    }
    return std::make_tuple(ids.size(), pipeline.counters().veiled_segments - dropped_before,
                           pipeline.counters().deep_pieces_kept - kept_before);
  };
  const auto [stride_tracks, stride_dropped, stride_kept] = run(4.0, 30.0f);
  EXPECT_EQ(stride_tracks, 1u);
  EXPECT_EQ(stride_dropped, 0u);
  EXPECT_EQ(stride_kept, 75u);
  const auto [shape_tracks, shape_dropped, shape_kept] = run(0.0, 30.0f);
  EXPECT_EQ(shape_tracks, 0u);
  EXPECT_EQ(shape_dropped, 75u);
  EXPECT_EQ(shape_kept, 0u);
  for (const double ratio : {4.0, 0.0}) {
    const auto [mixed_tracks, mixed_dropped, mixed_kept] = run(ratio, 13.67f);
    EXPECT_EQ(mixed_tracks, 0u) << ratio;
    EXPECT_EQ(mixed_dropped, 75u) << ratio;
    EXPECT_EQ(mixed_kept, 0u) << ratio;
  }
}

// Knee height, 25 Hz, 0.5 deg, a wall at 16 m: a leg at 12 m (its footprint 0.18 m, wider than
// the leg) moves across the view by one beam every 4 scans. In the first scan on a pair of beams
// it fills most of their footprint (both return 12.0 m); in the next three its share falls and
// the echoes, mixed with the wall, lie at 13.6, 14.2 and 13.6 m: 1.6-2.2 m behind the return the
// same beams had one to three scans (0.04-0.12 s) earlier, more than the pairing distance (0.7 m)
// and what a body at tracking.max_speed_mps (2.5 m/s) moves meanwhile (0.1-0.3 m), and no nearer
// return beside them in their own scan. With shape.recent_veil_s those three scans' pieces are
// dropped (counted in recently_veiled, 3 of every 4 scans) and no track stands behind the leg;
// without, none is dropped. A person walking straight away at 12-13.8 m at 1.5 m/s (0.06 m per
// scan along the same beams; two legs 5 beams, 0.52 m, apart) is never dropped: each
// beam's earlier returns lie nearer only by what the walk moves.
TEST(PipelineScenarioTest, EchoesBehindTheReturnTheirBeamsHadAScanBeforeAreMixedPixels) {
  constexpr std::size_t kBeams = 361;
  constexpr double kStepRad = 0.5 * common::kPi / 180.0;
  const auto run = [&](double recent_veil_s, bool walker) {
    TrackerOptions options;
    // The walker's legs are drawn as whole returns on two beams each up to the wall, where a
    // 15 mrad footprint (0.22 m at 14.5 m) would make them mixed pixels: not what
    // shape.mixed_leg_max_gap_m measures.
    options.shape.mixed_leg_max_gap_m = 0.0;
    options.shape.mount = Mount::kLegs;
    options.shape.recent_veil_s = recent_veil_s;
    TrackingPipeline pipeline(options);
    std::vector<float> ranges(kBeams);
    std::set<std::uint32_t> ids;
    std::uint64_t veiled_before = 0;
    const auto k0 = static_cast<std::int64_t>(kLearnedS * 25.0);
    for (std::int64_t k = 0; k < k0 + 75; ++k) {
      std::fill(ranges.begin(), ranges.end(), 16.0f);
      if (k >= k0) {
        const std::int64_t i = k - k0;
        if (walker) {
          const float r = 12.0f + 0.06f * static_cast<float>(i);
          for (const std::size_t b : {std::size_t{175}, std::size_t{180}}) {
            ranges[b] = r;
            ranges[b + 1] = r + 0.01f;  // 5 beams (0.52 m) apart: one person
          }
        } else {
          const auto b = static_cast<std::size_t>(150 + i / 4);
          const float phase[] = {12.0f, 13.6f, 14.2f, 13.6f};
          ranges[b] = ranges[b + 1] = phase[i % 4];
        }
      } else if (k == k0 - 1) {
        veiled_before = pipeline.counters().recently_veiled;
      }
      const ScanView scan = RangesScan(ranges, -0.5 * common::kPi, kStepRad, k, 40);
      for (const TrackReport& r : pipeline.Process(scan, static_cast<std::uint32_t>(k)).tracks) {
        if (std::hypot(r.x_m, r.y_m) > 13.0 && !walker) ids.insert(r.track_id);
        if (walker) ids.insert(r.track_id);
      }
    }
    return std::make_pair(ids.size(), pipeline.counters().recently_veiled - veiled_before);
  };
  const auto [behind_now, veiled_now] = run(0.3, false);
  EXPECT_EQ(behind_now, 0u);
  EXPECT_EQ(veiled_now, 56u);  // scans 1-3 of each of the 19 cycles (the last one cut at scan 2)
  const auto [behind_before, veiled_before] = run(0.0, false);
  EXPECT_EQ(veiled_before, 0u);
  (void)behind_before;
  const auto [walker_tracks, walker_veiled] = run(0.3, true);
  EXPECT_EQ(walker_tracks, 1u);
  EXPECT_EQ(walker_veiled, 0u);
}

// Knee height, 25 Hz, 0.5 deg, a wall at 16 m: a person stands at 13 m (legs on beams 176-177 and
// 181-182, 0.57 m apart) until confirmed. Two scans before the end, something nearer crosses beam
// 179 between the legs (12.0 m, one scan); in the last scan only that beam returns, at 13.1 m,
// within the pairing distance of the track: a single-beam leg for it, but behind the return the
// same beam had 0.08 s before by more than the pairing distance and what a body at 2.5 m/s moves
// meanwhile. With shape.recent_veil_s it is dropped (counted in recently_veiled), no single-beam
// leg; without, it is taken as one.
TEST(PipelineScenarioTest, ASingleBeamBehindItsBeamsRecentNearerReturnIsNoLeg) {
  constexpr std::size_t kBeams = 361;
  constexpr double kStepRad = 0.5 * common::kPi / 180.0;
  const auto run = [&](double recent_veil_s) {
    TrackerOptions options;
    options.shape.mount = Mount::kLegs;
    options.shape.recent_veil_s = recent_veil_s;
    TrackingPipeline pipeline(options);
    std::vector<float> ranges(kBeams);
    const auto k0 = static_cast<std::int64_t>(kLearnedS * 25.0);
    const std::int64_t last = k0 + 50;
    PipelineCounters before_last;
    for (std::int64_t k = 0; k <= last; ++k) {
      std::fill(ranges.begin(), ranges.end(), 16.0f);
      if (k >= k0 && k < last) {
        for (const std::size_t b :
             {std::size_t{176}, std::size_t{177}, std::size_t{181}, std::size_t{182}}) {
          ranges[b] = 13.0f;
        }
        if (k == last - 2) ranges[179] = 12.0f;
      } else if (k == last) {
        ranges[179] = 13.1f;
        before_last = pipeline.counters();
      }
      const ScanView scan = RangesScan(ranges, -0.5 * common::kPi, kStepRad, k, 40);
      (void)pipeline.Process(scan, static_cast<std::uint32_t>(k));
    }
    return std::make_pair(pipeline.counters().recently_veiled - before_last.recently_veiled,
                          pipeline.counters().single_beam_legs - before_last.single_beam_legs);
  };
  const auto [veiled_now, single_now] = run(0.3);
  EXPECT_EQ(veiled_now, 1u);
  EXPECT_EQ(single_now, 0u);
  const auto [veiled_before, single_before] = run(0.0);
  EXPECT_EQ(veiled_before, 0u);
  EXPECT_EQ(single_before, 1u);
}

// Knee height, 25 Hz, 0.5 deg: a person walks across the view at 10 m (0.44 m/s), each leg
// returned by 2 beams (one segment split into two legs), then for 1 s by a single beam each, 3
// beams apart (two one-point segments, below min_points), then by 2 beams again. With
// shape.single_beam_legs the confirmed track is measured from the single beams (one id, within a
// few centimetres of the body centre); without, it coasts through that second. Single beams
// alone never start a track.
TEST(PipelineScenarioTest, SingleBeamLegsUpdateAConfirmedTrackButStartNone) {
  constexpr std::size_t kBeams = 361;
  constexpr double kStepRad = 0.5 * common::kPi / 180.0;
  constexpr double kFirstRad = -0.5 * common::kPi;
  struct Run {
    std::set<std::uint32_t> ids;
    int single_scans = 0, measured = 0;
    double error_sum_m = 0.0, error_max_m = 0.0;
    std::uint64_t created = 0, single_beam_legs = 0;
  };
  const auto run = [&](bool single_beam_legs, bool single_from_start) {
    TrackerOptions options;
    options.shape.mount = Mount::kLegs;
    options.shape.single_beam_legs = single_beam_legs;
    TrackingPipeline pipeline(options);
    std::vector<float> ranges(kBeams);
    Run out;
    const auto k0 = static_cast<std::int64_t>(kLearnedS * 25.0);
    for (std::int64_t k = 0; k < k0 + 100; ++k) {
      std::fill(ranges.begin(), ranges.end(), 30.0f);
      const bool walking = k >= k0;
      const std::int64_t i = k - k0;
      const bool single = walking && (single_from_start || (i >= 50 && i < 75));
      const auto c = static_cast<std::size_t>(120 + std::max<std::int64_t>(i, 0) / 5);
      if (walking) {
        ranges[c - 2] = 10.0f;
        ranges[c + 2] = 10.0f;
        if (!single) ranges[c - 1] = ranges[c + 1] = 10.0f;
      }
      const ScanView scan = RangesScan(ranges, kFirstRad, kStepRad, k, 40);
      const ScanTracks& tracks = pipeline.Process(scan, static_cast<std::uint32_t>(k));
      for (const TrackReport& r : tracks.tracks) out.ids.insert(r.track_id);
      if (!single || single_from_start) continue;
      ++out.single_scans;
      // Truth at the scan start: the legs' midpoint, a leg radius behind their front.
      const double bearing = kFirstRad + static_cast<double>(c) * kStepRad;
      const Eigen::Vector2d truth = 10.06 * Eigen::Vector2d(std::cos(bearing), std::sin(bearing));
      for (const TrackReport& r : tracks.tracks) {
        if (r.state != TrackState::kConfirmed) continue;
        ++out.measured;
        const double e = (Eigen::Vector2d(r.x_m, r.y_m) - truth).norm();
        out.error_sum_m += e;
        out.error_max_m = std::max(out.error_max_m, e);
      }
    }
    out.created = pipeline.tracker().counters().created;
    out.single_beam_legs = pipeline.counters().single_beam_legs;
    return out;
  };
  const Run now = run(true, false);
  const Run before = run(false, false);
  ASSERT_EQ(now.single_scans, 25);
  EXPECT_EQ(now.ids.size(), 1u);
  EXPECT_GE(now.measured, 24);  // every single-beam scan
  EXPECT_GE(now.single_beam_legs, 24u);
  EXPECT_LT(now.error_sum_m / std::max(now.measured, 1), 0.05);
  EXPECT_LT(now.error_max_m, 0.12);
  EXPECT_EQ(before.measured, 0);  // coasting through the single-beam second
  EXPECT_EQ(before.single_beam_legs, 0u);
  // Single beams only: evidence for no track, the start of none.
  const Run alone = run(true, true);
  EXPECT_EQ(alone.created, 0u);
  EXPECT_TRUE(alone.ids.empty());
}

// ShapeOptions::single_beam_partner: knee height, 25 Hz, 0.5 deg, a person walks across the view
// at 5 m (nearer than a lone beam counts as a leg: 0.06 m < 5 m x 0.5 deg), each leg returned by 3
// beams, 4 beams apart; then for 1 s the right leg by one beam (its inner edge) only, then by 3
// again. With the option the confirmed track takes the left leg and that beam as its pair (one
// id, every such scan counted, the centre within a few centimetres); without, the lone beam is
// dropped and the track is measured from the left leg alone.
TEST(PipelineScenarioTest, ALoneBeamPartnersAConfirmedTracksSegmentLeg) {
  constexpr double kStepRad = 0.5 * common::kPi / 180.0;
  struct Run {
    std::set<std::uint32_t> ids;
    int single_scans = 0, measured = 0;
    double error_sum_m = 0.0;
    std::uint64_t partners = 0;
  };
  const auto run = [&](bool partner) {
    TrackerOptions options;
    options.shape.mount = Mount::kLegs;
    options.shape.single_beam_partner = partner;
    Run out;
    const auto single = [](std::int64_t i) { return i >= 50 && i < 75; };
    const auto centre = [](std::int64_t i) {
      return static_cast<std::size_t>(120 + std::max<std::int64_t>(i, 0) / 5);
    };
    const auto draw = [&](std::int64_t i, std::vector<float>& ranges) {
      const std::size_t c = centre(i);
      for (std::size_t b = c - 4; b <= c - 2; ++b) ranges[b] = 5.0f;
      ranges[c + 2] = 5.0f;
      if (!single(i)) ranges[c + 3] = ranges[c + 4] = 5.0f;
    };
    const auto seen = [&](std::int64_t i, const ScanTracks& tracks) {
      for (const TrackReport& r : tracks.tracks) out.ids.insert(r.track_id);
      if (!single(i)) return;
      ++out.single_scans;
      // Truth: the legs' midpoint, a leg radius behind their front.
      const double bearing = -0.5 * common::kPi + static_cast<double>(centre(i)) * kStepRad;
      const Eigen::Vector2d truth = 5.06 * Eigen::Vector2d(std::cos(bearing), std::sin(bearing));
      for (const TrackReport& r : tracks.tracks) {
        if (r.state != TrackState::kConfirmed) continue;
        ++out.measured;
        out.error_sum_m += (Eigen::Vector2d(r.x_m, r.y_m) - truth).norm();
      }
    };
    out.partners = RunKneeWalk(options, 30.0f, 100, draw, seen).single_beam_partners;
    return out;
  };
  const Run now = run(true);
  const Run before = run(false);
  ASSERT_EQ(now.single_scans, 25);
  EXPECT_EQ(now.ids.size(), 1u);
  EXPECT_GE(now.partners, 24u);
  EXPECT_EQ(before.partners, 0u);
  EXPECT_GE(now.measured, 24);
  const double now_mean = now.error_sum_m / std::max(now.measured, 1);
  const double before_mean = before.error_sum_m / std::max(before.measured, 1);
  EXPECT_LT(now_mean, 0.05);        // 0.027 m
  EXPECT_GT(before_mean, 0.1);      // 0.129 m: the left leg alone
}

// ShapeOptions::edge_echo_no_birth: knee height, 25 Hz, 0.5 deg, a wall at 9 m; a person walks
// along it at 8 m (each leg 2 beams, 3 wall beams between them) and the 2 beams beyond the right
// leg's edge return mixed echoes at 8.5 m (between the leg and the wall, beyond the segmentation's
// jump: a piece of their own). With the option that piece starts no track (one
// id); without, it becomes a second track behind the person.
TEST(PipelineScenarioTest, AnEdgesMixedEchoStartsNoTrack) {
  const auto run = [&](bool no_birth, std::uint64_t* counted) {
    TrackerOptions options;
    options.shape.mount = Mount::kLegs;
    options.shape.edge_echo_no_birth = no_birth;
    std::set<std::uint32_t> ids;
    const auto draw = [](std::int64_t i, std::vector<float>& ranges) {
      const auto c = static_cast<std::size_t>(150 + i / 5);
      ranges[c - 3] = ranges[c - 2] = 8.0f;
      ranges[c + 2] = ranges[c + 3] = 8.0f;
      ranges[c + 4] = ranges[c + 5] = 8.5f;
    };
    const auto seen = [&](std::int64_t, const ScanTracks& tracks) {
      for (const TrackReport& r : tracks.tracks) {
        if (r.state == TrackState::kConfirmed) ids.insert(r.track_id);
      }
    };
    *counted = RunKneeWalk(options, 9.0f, 100, draw, seen).edge_echo_births;
    return ids.size();
  };
  std::uint64_t now_counted = 0, before_counted = 0;
  EXPECT_EQ(run(true, &now_counted), 1u);
  EXPECT_GE(now_counted, 90u);
  EXPECT_EQ(run(false, &before_counted), 2u);
  EXPECT_EQ(before_counted, 0u);
}

// ShapeOptions::lone_beam_edge_echo: knee height, 25 Hz, 0.5 deg, a wall at 20 m; a person walks
// across the view at 14 m (a leg fills no beam's footprint there: 14 m x 15 mrad = 0.21 m), the
// near leg at 14 m and the far one at 14.3 m, each returned by 2 beams, 3 beams apart; then for 1 s
// the near leg by one beam at 14 m, the far one hidden behind it, and the beam beside it returns
// that edge's mixed echo at 14.65 m (between the leg and the wall, beyond the segmentation's jump:
// a lone beam of its own). With the option that beam is no leg (counted in every such scan) and
// the track stays at the person (mean range 14.11 m: the near leg's centre 14.06 m, the body's
// about 14.16 m); without, it is paired with the leg as the other one and pulls the track away from
// the sensor (14.43 m).
TEST(PipelineScenarioTest, ALoneBeamBesideANearerLegIsItsMixedEchoNotALeg) {
  struct Run {
    std::set<std::uint32_t> ids;
    int echo_scans = 0, reported = 0;
    double range_sum_m = 0.0;
    std::uint64_t echoes = 0;
  };
  const auto run = [&](bool drop_echo) {
    TrackerOptions options;
    options.shape.mount = Mount::kLegs;
    options.shape.lone_beam_edge_echo = drop_echo;
    Run out;
    const auto draw = [](std::int64_t i, std::vector<float>& ranges) {
      const auto c = static_cast<std::size_t>(120 + i / 5);
      if (i >= 50) {
        ranges[c - 2] = 14.0f;
        ranges[c - 1] = 14.65f;
      } else {
        ranges[c - 3] = ranges[c - 2] = 14.0f;
        ranges[c + 2] = ranges[c + 3] = 14.3f;
      }
    };
    const auto seen = [&](std::int64_t i, const ScanTracks& tracks) {
      const bool echo = i >= 50;
      for (const TrackReport& r : tracks.tracks) {
        if (r.state != TrackState::kConfirmed) continue;
        out.ids.insert(r.track_id);
        if (!echo) continue;
        ++out.reported;
        out.range_sum_m += std::hypot(r.x_m, r.y_m);
      }
      if (echo) ++out.echo_scans;
    };
    out.echoes = RunKneeWalk(options, 20.0f, 75, draw, seen).lone_beam_edge_echoes;
    return out;
  };
  const Run now = run(true);
  const Run before = run(false);
  ASSERT_EQ(now.echo_scans, 25);
  EXPECT_EQ(now.ids.size(), 1u);
  EXPECT_GE(now.echoes, 24u);
  EXPECT_EQ(before.echoes, 0u);
  ASSERT_GT(now.reported, 0);
  ASSERT_GT(before.reported, 0);
  const double now_range = now.range_sum_m / now.reported;
  const double before_range = before.range_sum_m / before.reported;
  EXPECT_LT(now_range, 14.2);      // 14.11 m
  EXPECT_GT(before_range, 14.35);  // 14.43 m
}

// ShapeOptions::far_legs_no_birth: knee height, 25 Hz, 1/3 deg, a wall at 30 m; legs walk across
// the view, each returned by 2 beams, 3 beams between them, for 3 s. At 18 m a leg covers at most
// half of a beam's footprint (18 m x 15 mrad = 0.27 m >= 4 x 0.06 m): with the option they start no
// track (counted in every scan), without they are one. At 12 m (0.18 m) they are one track either
// way.
TEST(PipelineScenarioTest, LegsTooFarToFillHalfAFootprintStartNoTrack) {
  constexpr std::size_t kBeams = 361;
  constexpr double kStepRad = common::kPi / 3.0 / 180.0;
  constexpr double kFirstRad = -0.5 * common::kPi;
  const auto run = [&](bool no_birth, float range_m, std::uint64_t* counted) {
    TrackerOptions options;
    options.shape.mount = Mount::kLegs;
    options.shape.far_legs_no_birth = no_birth;
    TrackingPipeline pipeline(options);
    std::vector<float> ranges(kBeams);
    std::set<std::uint32_t> ids;
    const auto k0 = static_cast<std::int64_t>(kLearnedS * 25.0);
    for (std::int64_t k = 0; k < k0 + 75; ++k) {
      std::fill(ranges.begin(), ranges.end(), 30.0f);
      if (k >= k0) {
        const auto c = static_cast<std::size_t>(120 + (k - k0) / 5);
        ranges[c - 3] = ranges[c - 2] = range_m;
        ranges[c + 2] = ranges[c + 3] = range_m;
      }
      const ScanView scan = RangesScan(ranges, kFirstRad, kStepRad, k, 40);
      const ScanTracks& tracks = pipeline.Process(scan, static_cast<std::uint32_t>(k));
      for (const TrackReport& r : tracks.tracks) {
        if (r.state == TrackState::kConfirmed) ids.insert(r.track_id);
      }
    }
    *counted = pipeline.counters().far_leg_births;
    return ids.size();
  };
  std::uint64_t counted = 0;
  EXPECT_EQ(run(true, 18.0f, &counted), 0u);
  EXPECT_GE(counted, 70u);
  EXPECT_EQ(run(false, 18.0f, &counted), 1u);
  EXPECT_EQ(counted, 0u);
  EXPECT_EQ(run(true, 12.0f, &counted), 1u);
  EXPECT_EQ(counted, 0u);
}

// ShapeOptions::leg_edge_in_mixed_beam: knee height, 0.5 deg, a wall at 5 m; a leg at 3 m
// returned by beams 180-183 (the last at 3.02 m), beam 184 a mixed echo at 3.6 m (its share of
// the leg w = (5 - 3.6) / (5 - 3.02) = 0.71), beam 179 the wall. The last edge lies within beam
// 184's footprint, (w - 0.5) beam_divergence_rad beyond its centre; the first stays half a step
// beyond beam 180. Without the option both are half a step beyond the last returning beam.
TEST(PipelineScenarioTest, ALegsEdgeLiesWithinTheMixedEchoBeyondIt) {
  constexpr std::size_t kBeams = 361;
  constexpr double kStepRad = 0.5 * common::kPi / 180.0;
  constexpr double kFirstRad = -0.5 * common::kPi;
  const auto edges = [&](bool in_mixed_beam, std::uint64_t* counted) {
    TrackerOptions options;
    options.shape.mount = Mount::kLegs;
    options.shape.leg_edge_in_mixed_beam = in_mixed_beam;
    TrackingPipeline pipeline(options);
    std::vector<float> ranges(kBeams);
    const auto k0 = static_cast<std::int64_t>(kLearnedS * 25.0);
    std::optional<Silhouette> found;
    for (std::int64_t k = 0; k <= k0; ++k) {
      std::fill(ranges.begin(), ranges.end(), 5.0f);
      if (k == k0) {
        ranges[180] = 3.02f;
        ranges[181] = 3.0f;
        ranges[182] = 3.0f;
        ranges[183] = 3.02f;
        ranges[184] = 3.6f;
      }
      (void)pipeline.Process(RangesScan(ranges, kFirstRad, kStepRad, k, 40),
                             static_cast<std::uint32_t>(k));
    }
    for (const Observation& ob : pipeline.observations()) {
      for (std::size_t p = 0; p < ob.part_count; ++p) {
        if (ob.parts[p].begin_beam == 180) found = ob.parts[p].silhouette;
      }
    }
    *counted = pipeline.counters().leg_edges_in_mixed_beam;
    return found;
  };
  const double divergence = ShapeOptions{}.beam_divergence_rad;
  std::uint64_t counted = 0, counted_before = 0;
  const std::optional<Silhouette> now = edges(true, &counted);
  const std::optional<Silhouette> before = edges(false, &counted_before);
  ASSERT_TRUE(now.has_value());
  ASSERT_TRUE(before.has_value());
  ASSERT_TRUE(now->first_valid && now->last_valid);
  const auto angle = [&](double beam) { return kFirstRad + beam * kStepRad; };
  EXPECT_NEAR(now->first_edge_rad, angle(179.5), 1e-9);
  // The edge point's range is 3.02 m: w = (5 - 3.6) / (5 - 3.02).
  EXPECT_NEAR(now->last_edge_rad, angle(184.0) + (1.4 / 1.98 - 0.5) * divergence, 1e-6);
  EXPECT_EQ(counted, 1u);
  EXPECT_NEAR(before->first_edge_rad, angle(179.5), 1e-9);
  EXPECT_NEAR(before->last_edge_rad, angle(183.5), 1e-9);
  EXPECT_EQ(counted_before, 0u);
}

TEST(TrackerOptionsTest, ConfirmationInTimeAppliesAtKneeHeightOnly) {
  TrackerOptions options;
  ASSERT_GT(options.tracking.confirm_min_s, 0.0);
  EXPECT_EQ(TrackingPipeline(options).tracker().options().confirm_min_s, 0.0);
  options.shape.mount = Mount::kLegs;
  EXPECT_EQ(TrackingPipeline(options).tracker().options().confirm_min_s,
            options.tracking.confirm_min_s);
}

TEST(TrackerOptionsTest, LostTracksAreResumedAtUpperBodyHeightOnly) {
  TrackerOptions options;
  ASSERT_GT(options.tracking.resume_window_s, 0.0);
  EXPECT_EQ(TrackingPipeline(options).tracker().options().resume_window_s,
            options.tracking.resume_window_s);
  options.shape.mount = Mount::kLegs;
  EXPECT_EQ(TrackingPipeline(options).tracker().options().resume_window_s, 0.0);
}

// Coasting tracks are reported for tracking.report_coasting_s (0.5 s) at upper-body height and for
// shape.legs_report_coasting_s (0.3 s) at knee height; 0 there, or a shorter
// tracking.report_coasting_s, leaves tracking.report_coasting_s.
TEST(TrackerOptionsTest, CoastingTracksAreReportedForLessTimeAtKneeHeight) {
  TrackerOptions options;
  ASSERT_EQ(options.tracking.report_coasting_s, 0.5);
  ASSERT_EQ(options.shape.legs_report_coasting_s, 0.3);
  EXPECT_EQ(TrackingPipeline(options).tracker().options().report_coasting_s, 0.5);
  options.shape.mount = Mount::kLegs;
  EXPECT_EQ(TrackingPipeline(options).tracker().options().report_coasting_s, 0.3);
  options.tracking.report_coasting_s = 0.2;
  EXPECT_EQ(TrackingPipeline(options).tracker().options().report_coasting_s, 0.2);
  options.tracking.report_coasting_s = 0.5;
  options.shape.legs_report_coasting_s = 0.0;
  EXPECT_EQ(TrackingPipeline(options).tracker().options().report_coasting_s, 0.5);
}

// The flatness rule's test "would a person's back over this extent stand out of the noise" without
// the p-th root: known answers (the whole back, u = 1: 0.298 b; an ellipse's back over half its
// width: 0.298 b (1 - sqrt(3) / 2)) and the same answer as the RMS itself on either side of it.
TEST(PersonBackLineRms, RootFreeTestAgreesWithTheRms) {
  ShapeOptions o;
  o.person_major_m = 0.23;
  o.person_minor_m = 0.14;
  o.person_exponent = 2.5;
  EXPECT_NEAR(internal::PersonBackLineRms(o, 0.46), 0.298 * 0.14, 1e-15);
  EXPECT_TRUE(internal::PersonBackLineRmsAbove(o, 0.46, 0.298 * 0.14 * (1.0 - 1e-9)));
  EXPECT_FALSE(internal::PersonBackLineRmsAbove(o, 0.46, 0.298 * 0.14 * (1.0 + 1e-9)));
  EXPECT_FALSE(internal::PersonBackLineRmsAbove(o, 0.46, 0.5));
  o.person_exponent = 2.0;
  const double half_width = 0.298 * 0.14 * (1.0 - std::sqrt(3.0) / 2.0);
  EXPECT_NEAR(internal::PersonBackLineRms(o, 0.23), half_width, 1e-15);
  EXPECT_TRUE(internal::PersonBackLineRmsAbove(o, 0.23, half_width * (1.0 - 1e-9)));
  EXPECT_FALSE(internal::PersonBackLineRmsAbove(o, 0.23, half_width * (1.0 + 1e-9)));
  for (const double p : {2.0, 2.5, 3.0}) {
    o.person_exponent = p;
    for (int e = 1; e <= 60; ++e) {
      const double extent = 0.01 * e;
      const double rms = internal::PersonBackLineRms(o, extent);
      for (const double t : {0.0, 0.5 * rms, rms * (1.0 - 1e-9), rms * (1.0 + 1e-9), 2.0 * rms}) {
        EXPECT_EQ(internal::PersonBackLineRmsAbove(o, extent, t), rms > t)
            << "p " << p << " extent " << extent << " threshold " << t;
      }
    }
  }
  EXPECT_FALSE(internal::PersonBackLineRmsAbove(o, 0.3, std::nan("")));
}

// shape.recent_veil_s against real far people behind a nearer moving one, at knee height with the
// simulator's legs: the tracker models the real beam (beam_divergence_rad 0.015, so that beyond
// ~8 m a leg fills no beam and the rule applies) while the synthetic scanner's beams are pencils
// (no mixed pixels: every far echo is a real leg). Walker 1 is the far person; from far_from_s on
// (confirmed) to the end of its walk it must keep one id that is reported within 0.5 m for all
// but a few scans (a short gap while the near person covers it): max_unmatched without the rule,
// max_unmatched_veiled with it (the gap the rule adds is its cost on such a scene).
struct VeilCase {
  VeilCase() {
    scene.legs = true;
    scene.walls = {{{16.0, -7.0}, {16.0, 7.0}},
                   {{-2.0, 7.0}, {16.0, 7.0}},
                   {{-2.0, -7.0}, {16.0, -7.0}},
                   {{-2.0, 7.0}, {-2.0, -7.0}}};
  }
  Scene scene;  // a hall 18 m x 14 m, its far wall at 16 m
  double far_from_s = 0.0;
  int max_unmatched = 0, max_unmatched_veiled = 0;
  double max_mean_error_m = 0.15;
};
std::pair<Follow, std::uint64_t> FollowFarWithVeil(const VeilCase& c, double recent_veil_s,
                                                   std::size_t w = 1) {
  TrackerOptions options = LegsOptions();
  options.shape.beam_divergence_rad = TrackerOptions().shape.beam_divergence_rad;
  options.shape.recent_veil_s = recent_veil_s;
  const Walker& far = c.scene.walkers[w];
  const SceneRun run = Simulate(c.scene, far.end_s() + 0.5, options);
  return {FollowWalker(run, far, w, c.far_from_s, far.end_s(), 0.5),
          run.pipeline->counters().recently_veiled};
}
void ExpectFarKept(const VeilCase& c, std::size_t w = 1) {
  for (const double veil_s : {0.3, 0.0}) {
    const auto [f, veiled] = FollowFarWithVeil(c, veil_s, w);
    SCOPED_TRACE("recent_veil_s " + std::to_string(veil_s) + ", recently_veiled " +
                 std::to_string(veiled) + ": " + Describe(f));
    EXPECT_EQ(f.frames_per_id.size(), 1u);
    EXPECT_LE(f.unmatched, veil_s > 0.0 ? c.max_unmatched_veiled : c.max_unmatched);
    EXPECT_LT(f.mean_error_m, c.max_mean_error_m);
  }
}

// Disabled: the rear person is never tracked here with either setting (recently_veiled stays 0:
// the loss is not this rule's; shape.drop_mixed_pixel_legs drops their legs, beside and within
// leg_pairing_distance_m across the ray of the nearer person's: veiled_segments 127 and 158), kept
// to show the scene.
// 1) Two people walk away one behind the other along nearly the same ray (1.2 m/s), the rear one
// 2 m behind and 0.6 m aside (the front one's legs hide one of the rear one's at times), from
// 9.5 to 12.5 m at 0.5 m/s: the rear one's beams had the front one's legs
// (nearer by ~1.5 m) a moment before.
TEST(PipelineScenarioTest, DISABLED_RecentVeilKeepsAFarPersonWalkingBehindANearerOne) {
  VeilCase c;
  c.scene.walkers = {Walker::Path(kLearnedS, {{7.5, 0.0}, {10.5, 0.0}}, 0.5),
                     Walker::Path(kLearnedS, {{9.5, 0.6}, {12.5, 0.6}}, 0.5)};
  c.far_from_s = kLearnedS + 1.0;
  c.max_unmatched = 10;
  c.max_unmatched_veiled = 10;
  ExpectFarKept(c);
}

// 2) A near person (3.5 m) walks across the view at 1.2 m/s in front of a far person walking
// slowly across at 11 m (0.5 m/s): the near one covers the far one's ray for ~0.2 s.
TEST(PipelineScenarioTest, RecentVeilKeepsAFarPersonWhenANearOneCrossesInFront) {
  VeilCase c;
  c.scene.walkers = {Walker::Path(kLearnedS + 2.0, {{3.5, -2.0}, {3.5, 2.0}}, 1.2),
                     Walker::Path(kLearnedS, {{11.0, -1.5}, {11.0, 1.5}}, 0.5)};
  c.far_from_s = kLearnedS + 1.0;
  c.max_unmatched = 3;         // measured: 0
  c.max_unmatched_veiled = 3;  // measured: 1 (8 when a near return's age alone counted)
  ExpectFarKept(c);
}

// 3) A far person walks slowly across at 12 m (0.3 m/s), seen past and between the legs of a near
// person walking slowly across at 4 m (0.4 m/s) on nearly the same rays.
TEST(PipelineScenarioTest, RecentVeilKeepsAFarPersonSeenBetweenTheLegsOfANearOne) {
  VeilCase c;
  c.scene.walkers = {Walker::Path(kLearnedS, {{4.0, -0.8}, {4.0, 0.8}}, 0.4),
                     Walker::Path(kLearnedS, {{12.0, -1.2}, {12.0, 1.2}}, 0.3)};
  c.far_from_s = kLearnedS + 1.5;
  c.max_unmatched = 10;         // measured: 7 (0.28 s)
  c.max_unmatched_veiled = 10;  // measured: 7 (34 when a near return's age alone counted)
  ExpectFarKept(c);
}

// Disabled: the rear person is never tracked here with either setting (recently_veiled stays 0:
// the loss is not this rule's; shape.drop_mixed_pixel_legs drops their legs, beside and within
// leg_pairing_distance_m across the ray of the nearer person's: veiled_segments 127 and 158), kept
// to show the scene.
// 4) Two far people walk across side by side at 10 and 11 m (0.5 m/s), the rear one 0.6 m
// beside the front one's line of sight (its nearer leg hidden at times): both keep their track.
TEST(PipelineScenarioTest, DISABLED_RecentVeilKeepsTwoFarPeopleOnePartlyBehindTheOther) {
  VeilCase c;
  c.scene.walkers = {Walker::Path(kLearnedS, {{10.0, -2.0}, {10.0, 2.0}}, 0.5),
                     Walker::Path(kLearnedS, {{11.0, -1.6}, {11.0, 2.4}}, 0.5)};
  c.far_from_s = kLearnedS + 1.0;
  c.max_unmatched = 10;
  c.max_unmatched_veiled = 10;
  ExpectFarKept(c, 1);
  ExpectFarKept(c, 0);
}

// ShapeOptions::still_legs_max_depth_m: knee height, 25 Hz, 0.5 deg, a wall at 11 m. A chair's leg
// too thin to fill a beam, in front of someone standing behind it, returns on its one beam a range
// between the two, and the beams beside it a leg-like arc: a pair of "legs" 0.5 m apart along the
// ray, the nearer a single beam. It comes in from the side (the chair pushed there, 2 s) and
// stands for 12 s. A person's two legs side by side (0.2 m apart across the ray) walk in and stand
// as long. The pair is handed to the background once it has stood still; the person is kept.
TEST(PipelineScenarioTest, AStillKneeHeightPairDeepAlongTheRayBehindASingleBeamIsNotAPerson) {
  constexpr double kStepRad = 0.5 * common::kPi / 180.0;
  constexpr double kRangeM = 5.0;
  constexpr std::int64_t kMoveScans = 50, kScans = 350;
  // A leg at kRangeM + depth_m whose centre lies on fractional beam c.
  const auto leg = [&](std::vector<float>& ranges, double c, double depth_m) {
    DrawKneeLeg(ranges, c, kRangeM + depth_m);
  };
  // Beam of the object's centre: 10 beams (0.44 m) in 2 s, then still.
  const auto centre = [&](std::int64_t i) { return SlideInBeam(i, kMoveScans); };
  struct Run {
    int late_reports = 0;  // reported confirmed tracks near the object in the last 3 s
    std::uint64_t absorbed = 0;
  };
  const auto run = [&](bool person, double max_depth_m) {
    TrackerOptions options;
    options.shape.mount = Mount::kLegs;
    options.shape.still_legs_max_depth_m = max_depth_m;
    Run out;
    const auto draw = [&](std::int64_t i, std::vector<float>& ranges) {
      const double c = centre(i);
      if (person) {
        // Legs 0.2 m apart across the ray: 2.3 beams either side of the centre.
        leg(ranges, c - 2.3, 0.0);
        leg(ranges, c + 2.3, 0.0);
      } else {
        // The mixed echoes' arc 0.5 m behind the single beam beside it.
        leg(ranges, c, 0.5);
        ranges[static_cast<std::size_t>(std::lround(c)) + 2] = static_cast<float>(kRangeM);
      }
    };
    const auto seen = [&](std::int64_t i, const ScanTracks& tracks) {
      if (i < kScans - 75) return;
      const double bearing = -0.5 * common::kPi + centre(i) * kStepRad;
      for (const TrackReport& r : tracks.tracks) {
        const double off =
            std::abs(std::remainder(std::atan2(r.y_m, r.x_m) - bearing, 2.0 * common::kPi));
        if (r.state == TrackState::kConfirmed && off < 0.1) ++out.late_reports;
      }
    };
    out.absorbed = RunKneeWalk(options, 11.0f, kScans, draw, seen).absorbed_objects;
    return out;
  };
  const Run pair_now = run(false, 0.4);
  const Run pair_before = run(false, 0.0);
  const Run person_now = run(true, 0.4);
  const Run person_before = run(true, 0.0);
  EXPECT_EQ(pair_now.late_reports, 0);
  EXPECT_GE(pair_now.absorbed, 1u);
  EXPECT_EQ(pair_before.late_reports, 75);
  EXPECT_EQ(person_now.late_reports, 75);
  EXPECT_EQ(person_before.late_reports, 75);
  EXPECT_EQ(person_now.absorbed, 0u);
}

// ShapeOptions::occluded_gap_depth_m: knee height, 25 Hz, 0.5 deg, a wall at 11 m. A trolley seen
// end-on (its near face 0.55 m wide across the ray at 5.5 m, its centre 0.5 m behind that) with
// its pusher's two legs 0.6 m in front of the face's middle: the scan shows the face's two ends
// either side of the legs, each bounded by the legs' occluding edges on the side facing the
// other. They come in from the side (2 s) and stand for 8 s. Measured against the trolley's
// centre, a track on the face's ends reports an error 0.5 m along the ray with a covariance that
// covers it (NEES at most the 99 % bound, 9.21, where without the option it is far above); a
// person's two legs side by side with nothing between them are reported exactly as without it.
TEST(PipelineScenarioTest, KneeHeightPairWithSomethingNearerBetweenCoversAnObjectBehindIt) {
  constexpr double kStepRad = 0.5 * common::kPi / 180.0;
  constexpr double kFaceM = 5.5, kLegsM = 4.9;
  constexpr std::int64_t kMoveScans = 50, kScans = 250;
  const auto leg = DrawKneeLeg;
  // Beam of the objects' centre line: 10 beams in 2 s, then still.
  const auto centre = [&](std::int64_t i) { return SlideInBeam(i, kMoveScans); };
  const auto bearing = [&](std::int64_t i) { return -0.5 * common::kPi + centre(i) * kStepRad; };
  struct Run {
    std::vector<double> nees;          // per late scan, the track nearest the trolley's centre
    std::vector<TrackReport> reports;  // every confirmed report in the late scans
    std::uint64_t widened = 0;         // PipelineCounters::occluded_gap_widened
  };
  const auto run = [&](bool trolley, double depth_m) {
    TrackerOptions options;
    options.shape.mount = Mount::kLegs;
    options.shape.occluded_gap_depth_m = depth_m;
    Run out;
    const auto draw = [&](std::int64_t i, std::vector<float>& ranges) {
      const double c = centre(i);
      if (trolley) {
        const double half_beams = 0.275 / (kFaceM * kStepRad);
        for (auto b = static_cast<std::size_t>(std::ceil(c - half_beams));
             b <= static_cast<std::size_t>(std::floor(c + half_beams)); ++b) {
          const double along = (static_cast<double>(b) - c) * kStepRad;
          ranges[b] = static_cast<float>(kFaceM / std::cos(along));
        }
        leg(ranges, c - 0.1 / (kLegsM * kStepRad), kLegsM);
        leg(ranges, c + 0.1 / (kLegsM * kStepRad), kLegsM);
      } else {
        leg(ranges, c - 0.1 / (kFaceM * kStepRad), kFaceM);
        leg(ranges, c + 0.1 / (kFaceM * kStepRad), kFaceM);
      }
    };
    const auto seen = [&](std::int64_t i, const ScanTracks& tracks) {
      if (i < kScans - 75) return;
      const Eigen::Vector2d truth = (trolley ? kFaceM + 0.5 : kFaceM) *
                                    Eigen::Vector2d(std::cos(bearing(i)), std::sin(bearing(i)));
      double best = std::numeric_limits<double>::infinity(), nees = 0.0;
      for (const TrackReport& r : tracks.tracks) {
        if (r.state != TrackState::kConfirmed) continue;
        out.reports.push_back(r);
        const Eigen::Vector2d e = Eigen::Vector2d(r.x_m, r.y_m) - truth;
        // The face's ends' track, not the pusher's legs' (0.6 m nearer).
        if (Eigen::Vector2d(r.x_m, r.y_m).norm() < kFaceM - 0.3 || e.norm() >= best) continue;
        best = e.norm();
        nees = e.dot(r.covariance.topLeftCorner<2, 2>().ldlt().solve(e));
      }
      if (std::isfinite(best)) out.nees.push_back(nees);
    };
    out.widened = RunKneeWalk(options, 11.0f, kScans, draw, seen).occluded_gap_widened;
    return out;
  };
  const Run now = run(true, 0.5);
  const Run before = run(true, 0.0);
  ASSERT_EQ(now.nees.size(), 75u);
  ASSERT_EQ(before.nees.size(), 75u);
  const double now_max = *std::max_element(now.nees.begin(), now.nees.end());
  const double before_min = *std::min_element(before.nees.begin(), before.nees.end());
  EXPECT_LE(now_max, 9.21);
  EXPECT_GT(before_min, 30.0);
  EXPECT_GE(now.widened, 75u);
  EXPECT_EQ(before.widened, 0u);
  const Run person_now = run(false, 0.5);
  const Run person_before = run(false, 0.0);
  ASSERT_EQ(person_now.reports.size(), person_before.reports.size());
  ASSERT_GE(person_now.reports.size(), 75u);
  for (std::size_t k = 0; k < person_now.reports.size(); ++k) {
    EXPECT_EQ(person_now.reports[k].x_m, person_before.reports[k].x_m);
    EXPECT_EQ(person_now.reports[k].y_m, person_before.reports[k].y_m);
    EXPECT_EQ(person_now.reports[k].covariance, person_before.reports[k].covariance);
  }
  EXPECT_EQ(person_now.widened, 0u);
}

// ShapeOptions::occluded_gap_depth_m: depth^2 / 3 along the ray where a beam lies between the two
// parts and neither part's silhouette ends on the side facing the other; else 0.
TEST(PipelineScenarioTest, OccludedGapAlongRayVarNeedsABeamBetweenAndOccludedInnerEnds) {
  ShapeOptions o;
  o.occluded_gap_depth_m = 0.5;
  ObservationPart first, second;
  first.begin_beam = 4;
  first.end_beam = 8;
  second.begin_beam = 12;
  second.end_beam = 15;
  first.silhouette.first_valid = true;
  second.silhouette.last_valid = true;
  EXPECT_DOUBLE_EQ(internal::OccludedGapAlongRayVar(o, first, second), 0.25 / 3.0);
  EXPECT_DOUBLE_EQ(internal::OccludedGapAlongRayVar(o, second, first), 0.25 / 3.0);  // any order
  first.silhouette.last_valid = true;  // the first's inner end is its silhouette: a leg's
  EXPECT_EQ(internal::OccludedGapAlongRayVar(o, first, second), 0.0);
  first.silhouette.last_valid = false;
  second.silhouette.first_valid = true;
  EXPECT_EQ(internal::OccludedGapAlongRayVar(o, first, second), 0.0);
  second.silhouette.first_valid = false;
  second.begin_beam = 8;  // touching: no beam between them
  EXPECT_EQ(internal::OccludedGapAlongRayVar(o, first, second), 0.0);
  second.begin_beam = 12;
  o.occluded_gap_depth_m = 0.0;
  EXPECT_EQ(internal::OccludedGapAlongRayVar(o, first, second), 0.0);
  TrackerOptions bad;
  bad.shape.occluded_gap_depth_m = -0.1;
  ASSERT_TRUE(Validate(bad).has_value());
  EXPECT_EQ(Validate(bad)->rfind("shape.occluded_gap_depth_m", 0), 0u) << *Validate(bad);
}

namespace {

// A person walking across the line of sight at range_m, from -9 deg on at speed_mps, seen at 25 Hz:
// their centre's bearing and position at scan i.
struct AcrossRayWalk {
  double range_m = 0.0;
  double speed_mps = 0.0;
  double BearingRad(std::int64_t i) const {
    return -9.0 * common::kPi / 180.0 + speed_mps * static_cast<double>(i) / 25.0 / range_m;
  }
  Eigen::Vector2d CentreM(std::int64_t i) const {
    return range_m * Eigen::Vector2d(std::cos(BearingRad(i)), std::sin(BearingRad(i)));
  }
};

// Two legs (radius 0.06 m, centres side_m either side of the person at range_m, bearing_rad) before
// a wall at wall_m as a receiver returns them (the simulator's rule): each beam's share s of its
// footprint (1.5 % of the range wide, evenly lit) the legs cover; the leg's range from s 0.8 on,
// the wall's up to 0.2 (left as drawn), the energy-weighted mean between.
void DrawLegsBeforeWall(double range_m, double wall_m, double bearing_rad, double side_m,
                        double step_rad, std::vector<float>& ranges) {
  constexpr double kLegM = 0.06;
  const double footprint_m = range_m * 0.015;
  for (std::size_t b = 0; b < ranges.size(); ++b) {
    const double angle = -0.5 * common::kPi + static_cast<double>(b) * step_rad;
    double share = 0.0;
    for (const double side : {-side_m, side_m}) {
      const double offset = range_m * (bearing_rad - angle) + side;  // leg centre off the beam
      const double lo = std::max(offset - kLegM, -0.5 * footprint_m);
      const double hi = std::min(offset + kLegM, 0.5 * footprint_m);
      share += std::max(hi - lo, 0.0) / footprint_m;
    }
    if (share <= 0.2) continue;
    const double leg = range_m - kLegM;
    ranges[b] = static_cast<float>(share >= 0.8 ? leg : share * leg + (1.0 - share) * wall_m);
  }
}

// Distance of truth_m to the nearest confirmed track (confirmed_only) or to the nearest track not
// tentative; infinity without one.
double NearestTrackM(const ScanTracks& tracks, const Eigen::Vector2d& truth_m,
                     bool confirmed_only) {
  double best = std::numeric_limits<double>::infinity();
  for (const TrackReport& r : tracks.tracks) {
    if (confirmed_only ? r.state != TrackState::kConfirmed : r.state == TrackState::kTentative) {
      continue;
    }
    best = std::min(best, (Eigen::Vector2d(r.x_m, r.y_m) - truth_m).norm());
  }
  return best;
}

}  // namespace

// ShapeOptions::mixed_leg_max_gap_m: knee height, 25 Hz, 0.5 deg, a wall at 12.2 m. A person walks
// across the line of sight at 11 m (legs 0.2 m apart across the ray, radius 0.06 m): a beam's
// footprint there (0.165 m) is wider than a leg, so each beam on a leg returns the energy-weighted
// mean of leg and wall, its share s the part of the footprint the leg covers (evenly lit; the leg
// alone from s 0.8 on, the wall alone up to 0.2). Fitted to those points, the track walked behind
// the person; measured from the returns' range deficits it walks with them.
TEST(PipelineScenarioTest, AFarLegSeenOnlyAsMixedPixelsBeforeANearWallIsMeasuredAtTheLeg) {
  constexpr double kStepRad = 0.5 * common::kPi / 180.0;
  constexpr double kRangeM = 11.0, kWallM = 12.2, kSpeedMps = 0.8;
  constexpr std::int64_t kScans = 125;
  const AcrossRayWalk walk{kRangeM, kSpeedMps};
  const auto draw = [&](std::int64_t i, std::vector<float>& ranges) {
    DrawLegsBeforeWall(kRangeM, kWallM, walk.BearingRad(i), 0.1, kStepRad, ranges);
  };
  struct Run {
    int measured = 0;  // scans of the last 2 s with a confirmed track within 1 m of the person
    double error_sum_m = 0.0;
    std::uint64_t mixed = 0;
  };
  const auto run = [&](double max_gap_m) {
    TrackerOptions options;
    options.shape.mount = Mount::kLegs;
    options.shape.mixed_leg_max_gap_m = max_gap_m;
    Run out;
    const auto seen = [&](std::int64_t i, const ScanTracks& tracks) {
      if (i < kScans - 50) return;
      const Eigen::Vector2d truth = walk.CentreM(i);
      const double best = NearestTrackM(tracks, truth, true);
      if (best < 1.0) {
        ++out.measured;
        out.error_sum_m += best;
      }
    };
    out.mixed =
        RunKneeWalk(options, static_cast<float>(kWallM), kScans, draw, seen).mixed_pixel_legs;
    return out;
  };
  const Run now = run(1.5);
  const Run before = run(0.0);
  const double now_mean = now.error_sum_m / std::max(now.measured, 1);
  const double before_mean = before.error_sum_m / std::max(before.measured, 1);
  EXPECT_EQ(now.measured, 50);
  EXPECT_EQ(before.measured, 50);
  EXPECT_GE(now.mixed, 200u);  // both legs in most scans (250)
  EXPECT_EQ(before.mixed, 0u);
  EXPECT_LT(now_mean, 0.2);      // 0.115 m
  EXPECT_GT(before_mean, 0.35);  // 0.441 m: behind the person along the ray
}

// ShapeOptions::mixed_leg_band_variance: knee height, 25 Hz, 0.5 deg, a wall at 9.5 m. A person
// walks across the line of sight at 8.3 m (legs 0.4 m apart across the ray, radius 0.06 m), every
// fourth scan unseen: a beam's footprint there (0.125 m) is wider than a leg, but a leg covers
// most of one beam's (the leg alone from s 0.8 on, the wall alone up to 0.2, as the simulator)
// and mixes with the wall in its neighbours'. The deficits put the leg at or near its nearest
// return; with the radius' share of the whole 1.2 m gap along the ray (0.3 m sigma) the track's
// sigma passed legs_coasting_max_sigma_m whenever it went unseen (unreported there, a fragment
// each time) and the filter kept behind the person; with the spread held at that return it stays
// reported and with the person.
TEST(PipelineScenarioTest, AFarLegReturningABeamAloneBeforeANearWallStaysReportedWhenUnseen) {
  constexpr double kStepRad = 0.5 * common::kPi / 180.0;
  constexpr double kRangeM = 8.3, kWallM = 9.5, kSpeedMps = 0.8;
  constexpr std::int64_t kScans = 125;
  const AcrossRayWalk walk{kRangeM, kSpeedMps};
  const auto unseen = [](std::int64_t i) { return i % 4 == 3; };
  const auto draw = [&](std::int64_t i, std::vector<float>& ranges) {
    if (!unseen(i)) DrawLegsBeforeWall(kRangeM, kWallM, walk.BearingRad(i), 0.2, kStepRad, ranges);
  };
  struct Run {
    int reported = 0;         // scans of the last 2 s with a track within 0.5 m of the person
    int unseen_reported = 0;  // ... of them the unseen scans
    double error_sum_m = 0.0;
    std::uint64_t mixed = 0;
  };
  const auto run = [&](bool band) {
    TrackerOptions options;
    options.shape.mount = Mount::kLegs;
    options.shape.mixed_leg_band_variance = band;
    Run out;
    const auto seen = [&](std::int64_t i, const ScanTracks& tracks) {
      if (i < kScans - 50) return;
      const Eigen::Vector2d truth = walk.CentreM(i);
      const double best = NearestTrackM(tracks, truth, false);
      if (best < 0.5) {
        ++out.reported;
        out.unseen_reported += unseen(i) ? 1 : 0;
        out.error_sum_m += best;
      }
    };
    out.mixed =
        RunKneeWalk(options, static_cast<float>(kWallM), kScans, draw, seen).mixed_pixel_legs;
    return out;
  };
  const Run now = run(true);
  const Run before = run(false);
  EXPECT_GE(now.mixed, 50u);  // measured from the deficits in both runs
  EXPECT_GE(before.mixed, 50u);
  EXPECT_GE(now.reported, 40);        // 44 of 50
  EXPECT_LE(before.reported, 34);     // 28
  EXPECT_GE(now.unseen_reported, 5);  // 7 of 12 unseen scans
  EXPECT_EQ(before.unseen_reported, 0);
  EXPECT_LT(now.error_sum_m / now.reported, 0.12);                     // 0.080 m
  EXPECT_GT(before.error_sum_m / std::max(before.reported, 1), 0.15);  // 0.197 m
}

}  // namespace
}  // namespace lrfnet::tracking
