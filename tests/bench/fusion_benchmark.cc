// Track fusion on synthetic scenes: six sensors around a 30 m x 20 m hall whose calibrated poses
// are slightly wrong (drawn from the covariance they report), 10-50 people walking between random
// waypoints, and per sensor an emulated tracker: a constant-velocity Kalman filter on centre
// measurements that are offset towards the sensor (per sensor, per track and with the turning
// torso), occlusion by other people, coasting, new ids after a loss, random track losses, id swaps
// when two people meet, and false tracks. Every scene runs with the fused filter (the default)
// and with the latest-states combination of earlier releases, on the same seeds.
//
// Reports the fused position RMS and 95th percentile against the best single sensor's, the
// normalised estimation error squared (NEES) of the fused and of the single-sensor tracks, id
// switches per person-minute (fused ids), the fraction of time a visible person has exactly one
// fused track, false fused tracks, and the update time per frame. Prints a markdown table and
// writes it to FILE.
//
//   fusion_benchmark [--out FILE] [--seconds S] [--seeds N] [--scene NAME/PEOPLE]
//   (FILE: results/fusion_benchmark.md; S: simulated seconds per run, default 120; N: runs per
//   row, default 3; --scene: only the rows of that scene, e.g. "tracker errors/25")

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include "central_daemon/fusion/fusion.h"
#include "common/cv_model.h"
#include "common/geometry.h"
#include "common/time.h"

namespace {

using Clock = std::chrono::steady_clock;
namespace common = lrfnet::common;
namespace daemon = lrfnet::daemon;
namespace fusion = lrfnet::fusion;
using common::UtcNs;
using Eigen::Vector2d;

constexpr UtcNs kT0 = 1'700'000'000LL * common::kNsPerS;
constexpr double kHallX = 30.0, kHallY = 20.0;
constexpr double kTrajectoryStep = 0.01;  // s
constexpr double kPersonRadius = 0.25;    // m, for occlusion
constexpr double kSample = 0.1;           // s between evaluations
constexpr double kWarmUp = 2.0;           // s before the first evaluation
constexpr double kMatchRadius = 1.0;      // m: a fused track this close can be the person's
constexpr double kChi2_95 = 5.991;        // chi-square, 2 dof, 95 %

UtcNs At(double t_s) { return kT0 + common::SecondsToNs(t_s); }

// The emulated trackers' errors. Each measurement of a person's centre is
//   z = c + (o_sensor + o_track + o_turn) u + o_lateral l + n,
// c the true centre, u the unit vector towards the sensor, l across it; o_sensor ~ U(min, max) per
// sensor (what the sensor's view of a body leaves), o_track ~ N(0, track_sigma) per local track
// (its size estimate), o_turn and o_lateral AR(1) processes per person and sensor (the torso
// turning with the gait), n white with sigma noise_m + noise_per_m * range. The tracker's
// measurement covariance is honest about the spread of these (not their correlation in time):
// radial variance noise^2 + E[o_sensor^2] + track_sigma^2 + turn_sigma^2, lateral noise^2 +
// lateral_sigma^2. Legacy trackers (centre of mass of the visible side) are offset by 0.08-0.20 m
// and claim 0.11 m per axis.
struct TrackerErrors {
  bool legacy = false;
  double sensor_offset_min_m = 0.0, sensor_offset_max_m = 0.05;
  double track_offset_sigma_m = 0.03;
  double turn_sigma_m = 0.02, turn_tau_s = 1.0;
  double lateral_sigma_m = 0.015, lateral_tau_s = 0.5;
  double noise_m = 0.01, noise_per_m = 0.003;
  double accel_psd = 0.5;  // the tracker's constant-velocity filter
  std::uint32_t tentative_frames = 3;
  double coast_s = 1.0;  // coasting, then deleted (a new id when seen again)
  // Errors of the tracker's bookkeeping (0 for "ideal trackers").
  double swap_probability = 0.3;  // per encounter (two tracked people closer than swap_distance)
  double swap_distance_m = 0.5;
  double loss_rate_hz = 0.05;   // random local track losses per track-second
  double loss_gap_s = 0.2;      // until the person is picked up again (a new id)
  double false_rate_hz = 0.03;  // false tracks born per sensor-second (0.5-4 s each)
};

struct Config {
  std::string name;
  std::size_t people = 25;
  TrackerErrors errors;
  double pose_error_scale = 1.0;  // pose errors drawn from scale^2 * reported covariance
  fusion::FusionMethod method = fusion::FusionMethod::kFusedFilter;
  bool learn_sensor_bias = true;  // fused filter: FusionOptions::learn_sensor_bias
  // fused filter: FusionOptions::sensor_bias_offset_sigma_fraction (< 0: the default)
  double offset_sigma_fraction = -1.0;
  // fused filter: the earlier release's merging and reporting (merge_sourceless off,
  // report_sourceless on).
  bool earlier_merge = false;
};

struct Trajectories {
  std::vector<std::vector<Vector2d>> points;  // per person, every kTrajectoryStep
  Vector2d At(std::size_t p, double t) const {
    const auto& pts = points[p];
    const double k = std::clamp(t / kTrajectoryStep, 0.0, static_cast<double>(pts.size() - 2));
    const auto i = static_cast<std::size_t>(k);
    const double f = k - static_cast<double>(i);
    return pts[i] * (1.0 - f) + pts[i + 1] * f;
  }
  Vector2d Velocity(std::size_t p, double t) const {
    return (At(p, t + kTrajectoryStep) - At(p, t - kTrajectoryStep)) / (2.0 * kTrajectoryStep);
  }
};

// Random waypoints in the hall, 0.8-1.5 m/s, sometimes pausing for up to 3 s.
Trajectories Walk(std::size_t people, double seconds, std::mt19937& rng) {
  std::uniform_real_distribution<double> ux(1.0, kHallX - 1.0), uy(1.0, kHallY - 1.0),
      speed(0.8, 1.5), u01(0.0, 1.0), pause(0.0, 3.0);
  Trajectories t;
  const auto steps = static_cast<std::size_t>(seconds / kTrajectoryStep) + 3;
  for (std::size_t p = 0; p < people; ++p) {
    Vector2d pos(ux(rng), uy(rng)), goal(ux(rng), uy(rng));
    double v = speed(rng), wait = 0.0;
    std::vector<Vector2d> pts;
    pts.reserve(steps);
    for (std::size_t k = 0; k < steps; ++k) {
      pts.push_back(pos);
      if (wait > 0.0) {
        wait -= kTrajectoryStep;
        continue;
      }
      const Vector2d d = goal - pos;
      const double step = v * kTrajectoryStep;
      if (d.norm() <= step) {
        pos = goal;
        goal = Vector2d(ux(rng), uy(rng));
        v = speed(rng);
        if (u01(rng) < 0.3) wait = pause(rng);
      } else {
        pos += d.normalized() * step;
      }
    }
    t.points.push_back(std::move(pts));
  }
  return t;
}

struct Sensor {
  std::string id;
  common::Pose2 truth;
  fusion::SensorPlacement placement;  // what the fuser is told
  double range_m = 14.0;
  double half_fov_rad = common::DegToRad(95.0);
  double phase_s = 0.0;
  double period_s = 0.04;
};

std::vector<Sensor> MakeSensors(double pose_error_scale, std::mt19937& rng) {
  const struct {
    double x, y, yaw_deg;
  } poses[] = {{0, 0, 45}, {15, 0, 90}, {30, 0, 135}, {30, 20, -135}, {15, 20, -90}, {0, 20, -45}};
  std::normal_distribution<double> n01(0.0, 1.0);
  std::uniform_real_distribution<double> phase(0.0, 0.04);
  const Eigen::Matrix3d covariance =
      Eigen::Vector3d(0.03 * 0.03, 0.03 * 0.03, std::pow(common::DegToRad(0.3), 2)).asDiagonal();
  const Eigen::Matrix3d l = covariance.llt().matrixL();
  std::vector<Sensor> sensors;
  for (std::size_t i = 0; i < 6; ++i) {
    Sensor s;
    s.id = "s" + std::to_string(i + 1);
    s.truth = common::Pose2{poses[i].x, poses[i].y, common::DegToRad(poses[i].yaw_deg)};
    s.phase_s = phase(rng);
    // The first sensor is the reference of the calibration: exact, zero covariance.
    const Eigen::Vector3d e =
        i == 0 ? Eigen::Vector3d::Zero()
               : Eigen::Vector3d(pose_error_scale *
                                 (l * Eigen::Vector3d(n01(rng), n01(rng), n01(rng))));
    s.placement.id = s.id;
    s.placement.world_from_sensor =
        common::Pose2{s.truth.x_m + e(0), s.truth.y_m + e(1), s.truth.yaw_rad + e(2)};
    s.placement.covariance = i == 0 ? Eigen::Matrix3d::Zero() : covariance;
    sensors.push_back(s);
  }
  return sensors;
}

// A local track: the tracker's constant-velocity Kalman filter (sensor frame) and its bookkeeping.
struct KfTrack {
  bool active = false;
  std::uint32_t id = 0;
  std::uint32_t hits = 0;
  double t_s = 0.0;          // of x, p
  double last_meas_s = 0.0;  // latest measurement
  double offset_m = 0.0;     // o_track
  common::CvState x = common::CvState::Zero();
  common::CvCovariance p = common::CvCovariance::Identity();
};

// One sensor's emulated tracker.
class LocalTracker {
 public:
  LocalTracker(std::size_t people, const TrackerErrors& errors, std::uint32_t seed)
      : e_(errors), people_(people), rng_(seed) {
    std::uniform_real_distribution<double> offset(e_.sensor_offset_min_m, e_.sensor_offset_max_m);
    if (e_.legacy) offset = std::uniform_real_distribution<double>(0.08, 0.20);
    sensor_offset_m_ = offset(rng_);
    const double mean = 0.5 * (e_.sensor_offset_min_m + e_.sensor_offset_max_m);
    const double width = e_.sensor_offset_max_m - e_.sensor_offset_min_m;
    sensor_offset_ms_ = mean * mean + width * width / 12.0;
  }

  daemon::TrackFrameData Frame(const Sensor& s, const Trajectories& traj, double t) {
    const double dt = last_t_ < 0.0 ? s.period_s : t - last_t_;
    last_t_ = t;
    std::normal_distribution<double> n01(0.0, 1.0);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    const double a_turn = std::exp(-dt / e_.turn_tau_s), b_turn = std::sqrt(1.0 - a_turn * a_turn);
    const double a_lat = std::exp(-dt / e_.lateral_tau_s), b_lat = std::sqrt(1.0 - a_lat * a_lat);

    // Visibility: range, field of view, occlusion by a nearer person.
    std::vector<char> visible(people_.size(), 0);
    std::vector<double> dist(people_.size()), bearing(people_.size());
    for (std::size_t p = 0; p < people_.size(); ++p) {
      const Vector2d d = traj.At(p, t) - s.truth.translation();
      dist[p] = d.norm();
      bearing[p] = std::atan2(d.y(), d.x());
      visible[p] = dist[p] <= s.range_m &&
                   std::abs(common::AngleDiff(bearing[p], s.truth.yaw_rad)) <= s.half_fov_rad;
    }
    for (std::size_t p = 0; p < people_.size(); ++p) {
      if (!visible[p]) continue;
      for (std::size_t q = 0; q < people_.size(); ++q) {
        if (q == p || dist[q] >= dist[p] - 0.1) continue;
        if (std::abs(common::AngleDiff(bearing[p], bearing[q])) <
            std::atan2(kPersonRadius, dist[q])) {
          visible[p] = 0;
          break;
        }
      }
    }

    daemon::TrackFrameData frame;
    frame.session_id = 1;
    frame.scan_start_ns = At(t);
    frame.scan_period_s = s.period_s;
    frame.scan_counter = frames_++;
    const common::Pose2 sensor_from_world = s.truth.inverse();
    for (std::size_t p = 0; p < people_.size(); ++p) {
      Person& me = people_[p];
      me.turn = a_turn * me.turn + b_turn * e_.turn_sigma_m * n01(rng_);
      me.lateral = a_lat * me.lateral + b_lat * e_.lateral_sigma_m * n01(rng_);
      if (visible[p] && !me.track.active && t >= me.lost_until) {
        Start(me.track);
      }
      if (!me.track.active) continue;
      if (u01(rng_) < e_.loss_rate_hz * dt) {
        me.track.active = false;
        me.lost_until = t + e_.loss_gap_s;
        continue;
      }
      if (visible[p]) {
        const Vector2d c = traj.At(p, t);
        const Vector2d u = (s.truth.translation() - c).normalized();
        const Vector2d l(-u.y(), u.x());
        const double noise = e_.noise_m + e_.noise_per_m * dist[p];
        const Vector2d z = c + (sensor_offset_m_ + me.track.offset_m + me.turn) * u +
                           me.lateral * l + noise * Vector2d(n01(rng_), n01(rng_));
        Measure(me.track, sensor_from_world * z, sensor_from_world.rotation() * u, noise, t);
      }
      if (!Report(me.track, t, frame)) continue;
    }
    // False tracks: reflections, a door, a chair moved (not people, but they move like objects).
    if (u01(rng_) < e_.false_rate_hz * dt) {
      std::uniform_real_distribution<double> range(1.0, 12.0),
          angle(-s.half_fov_rad, s.half_fov_rad), life(0.5, 4.0);
      FalseObject f;
      const double r = range(rng_), a = angle(rng_);
      f.pos = s.truth * Vector2d(r * std::cos(a), r * std::sin(a));
      const double heading = 2.0 * common::kPi * u01(rng_);
      f.vel = u01(rng_) < 0.5 ? Vector2d::Zero()
                              : Vector2d(0.3 * std::cos(heading), 0.3 * std::sin(heading));
      f.until = t + life(rng_);
      Start(f.track);
      false_.push_back(f);
    }
    for (auto it = false_.begin(); it != false_.end();) {
      if (t > it->until) {
        it = false_.erase(it);
        continue;
      }
      it->pos += dt * it->vel;
      const Vector2d u = (s.truth.translation() - it->pos).normalized();
      Measure(it->track, sensor_from_world * (it->pos + 0.03 * Vector2d(n01(rng_), n01(rng_))),
              sensor_from_world.rotation() * u, 0.03, t);
      Report(it->track, t, frame);
      ++it;
    }

    // Id swaps: two tracked people meet (closer than swap_distance_m, farther before) and the
    // tracker's association exchanges them: each filter goes on with the other person.
    for (std::size_t p = 0; p < people_.size(); ++p) {
      for (std::size_t q = p + 1; q < people_.size(); ++q) {
        const bool close = (traj.At(p, t) - traj.At(q, t)).norm() < e_.swap_distance_m;
        const auto key = p * people_.size() + q;
        const bool was_close = close_.count(key) != 0;
        if (close && !was_close) {
          close_.insert(key);
          const bool tracked = people_[p].track.active && people_[q].track.active;
          const bool swap = tracked && u01(rng_) < e_.swap_probability;
          if (swap) std::swap(people_[p].track, people_[q].track);
          encounters_.push_back(Encounter{t, p, q, tracked && visible[p] && visible[q], swap});
        } else if (!close && was_close) {
          close_.erase(key);
        }
      }
    }
    return frame;
  }

  struct Encounter {
    double t_s;
    std::size_t p, q;  // p < q
    bool seen;         // both tracked and measured
    bool swapped;
  };
  const std::vector<Encounter>& encounters() const { return encounters_; }
  double sensor_offset_m() const { return sensor_offset_m_; }

 private:
  struct Person {
    KfTrack track;
    double lost_until = 0.0;
    double turn = 0.0, lateral = 0.0;  // o_turn, o_lateral
  };
  struct FalseObject {
    Vector2d pos, vel;
    double until = 0.0;
    KfTrack track;
  };

  void Start(KfTrack& k) {
    std::normal_distribution<double> n01(0.0, 1.0);
    k = KfTrack{};
    k.active = true;
    k.id = next_id_++;
    k.offset_m = e_.track_offset_sigma_m * n01(rng_);
  }

  // The measurement z (sensor frame) with the tracker's covariance: radial along u_s (towards the
  // sensor, sensor frame), lateral across.
  void Measure(KfTrack& k, const Vector2d& z, const Vector2d& u_s, double noise, double t) {
    Eigen::Matrix2d r;
    if (e_.legacy) {
      r = (0.10 * 0.10 + 0.05 * 0.05) * Eigen::Matrix2d::Identity();
    } else {
      const double radial = noise * noise + sensor_offset_ms_ +
                            e_.track_offset_sigma_m * e_.track_offset_sigma_m +
                            e_.turn_sigma_m * e_.turn_sigma_m;
      const double lateral = noise * noise + e_.lateral_sigma_m * e_.lateral_sigma_m;
      const Vector2d l(-u_s.y(), u_s.x());
      r = radial * u_s * u_s.transpose() + lateral * l * l.transpose();
    }
    if (k.hits == 0) {
      k.x << z, 0.0, 0.0;
      k.p.setZero();
      k.p.topLeftCorner<2, 2>() = r;
      k.p(2, 2) = k.p(3, 3) = 1.5 * 1.5;
    } else {
      common::CvPredict(t - k.t_s, e_.accel_psd, k.x, k.p);
      const Eigen::Matrix2d s_inv =
          (k.p.topLeftCorner<2, 2>() + r).llt().solve(Eigen::Matrix2d::Identity());
      const Eigen::Matrix<double, 4, 2> gain = k.p.leftCols<2>() * s_inv;
      k.x += gain * (z - k.x.head<2>());
      k.p -= gain * k.p.topRows<2>();
      k.p = (0.5 * (k.p + k.p.transpose())).eval();
    }
    k.t_s = t;
    k.last_meas_s = t;
    ++k.hits;
  }

  // Appends the track's report at t (predicted when it was not measured); false when it timed out.
  bool Report(KfTrack& k, double t, daemon::TrackFrameData& frame) {
    if (!k.active || k.hits == 0) return false;
    daemon::TrackObservation o;
    o.state = daemon::TrackState::kConfirmed;
    if (k.last_meas_s < t) {
      if (t - k.last_meas_s > e_.coast_s) {
        k.active = false;
        return false;
      }
      common::CvPredict(t - k.t_s, e_.accel_psd, k.x, k.p);
      k.t_s = t;
      o.state = daemon::TrackState::kCoasting;
    } else if (k.hits <= e_.tentative_frames) {
      o.state = daemon::TrackState::kTentative;
    }
    o.track_id = k.id;
    o.kind =
        e_.legacy ? daemon::MeasurementKind::kCenterOfMass : daemon::MeasurementKind::kShapeFit;
    o.x_m = static_cast<float>(k.x(0));
    o.y_m = static_cast<float>(k.x(1));
    o.vx_mps = static_cast<float>(k.x(2));
    o.vy_mps = static_cast<float>(k.x(3));
    std::size_t i = 0;
    for (int row = 0; row < 4; ++row) {
      for (int col = row; col < 4; ++col) o.covariance[i++] = static_cast<float>(k.p(row, col));
    }
    o.age_scans = k.hits;
    frame.tracks.push_back(o);
    return true;
  }

  TrackerErrors e_;
  double sensor_offset_m_ = 0.0;
  double sensor_offset_ms_ = 0.0;  // E[o_sensor^2]
  std::vector<Person> people_;
  std::vector<FalseObject> false_;
  std::mt19937 rng_;
  std::uint32_t next_id_ = 1;
  std::uint32_t frames_ = 0;
  double last_t_ = -1.0;
  std::set<std::size_t> close_;
  std::vector<Encounter> encounters_;
};

// Pairs people and tracks greedily by distance within kMatchRadius; returns, per person, the
// index of its track or -1.
std::vector<int> Match(const std::vector<Vector2d>& people, const std::vector<Vector2d>& tracks) {
  std::vector<std::tuple<double, std::size_t, std::size_t>> pairs;
  for (std::size_t p = 0; p < people.size(); ++p) {
    for (std::size_t t = 0; t < tracks.size(); ++t) {
      const double d = (people[p] - tracks[t]).norm();
      if (d <= kMatchRadius) pairs.emplace_back(d, p, t);
    }
  }
  std::sort(pairs.begin(), pairs.end());
  std::vector<int> match(people.size(), -1);
  std::vector<char> used(tracks.size(), 0);
  for (const auto& [d, p, t] : pairs) {
    if (match[p] >= 0 || used[t]) continue;
    match[p] = static_cast<int>(t);
    used[t] = 1;
  }
  return match;
}

double Nees2(const Vector2d& error, const Eigen::Matrix2d& covariance) {
  const Eigen::LLT<Eigen::Matrix2d> llt(covariance);
  if (llt.info() != Eigen::Success) return 1e9;
  return error.dot(llt.solve(error));
}

struct Totals {
  std::vector<double> fused_errors;
  // The fused errors by the number of sensors with a confirmed track on the person: 0, 1, 2, 3+.
  std::vector<std::vector<double>> fused_errors_by_views = std::vector<std::vector<double>>(4);
  std::vector<std::vector<double>> sensor_errors = std::vector<std::vector<double>>(6);
  // Per sensor, on the samples where it has a confirmed track on a person who also has a
  // matched fused track: that sensor's error and the fused track's.
  std::vector<std::vector<double>> paired_sensor = std::vector<std::vector<double>>(6);
  std::vector<std::vector<double>> paired_fused = std::vector<std::vector<double>>(6);
  double fused_nees_sum = 0.0, sensor_nees_sum = 0.0;
  std::size_t fused_nees_n = 0, fused_nees_inside = 0, sensor_nees_n = 0;
  std::size_t switches = 0;
  double person_seconds = 0.0;
  std::size_t visible_samples = 0;
  std::size_t exactly_one = 0;
  std::size_t unmatched_fused = 0;
  std::size_t samples = 0;
  std::vector<double> update_us;
  std::size_t frames = 0;
  std::size_t tracker_swaps = 0;            // per sensor
  std::size_t swap_events = 0;              // encounters in which some sensor swapped
  std::size_t correctable_swap_events = 0;  // ... and another sensor saw both and did not
  fusion::FusionCounters counters;
  // Learnt sensor offsets (fused filter, learn_sensor_bias) against the true o_sensor, at the end
  // of each run: errors, and how many of them are within 2 sigma.
  std::vector<double> bias_errors;
  std::size_t bias_inside_2sigma = 0;
  // Their placements' errors before and after the learnt correction (sums of squares).
  double pose_before_m2 = 0.0, pose_after_m2 = 0.0, yaw_before_rad2 = 0.0, yaw_after_rad2 = 0.0;

  void Add(const fusion::FusionCounters& c) {
    counters.sources_drifted += c.sources_drifted;
    counters.source_rebinds += c.source_rebinds;
    counters.fused_merged += c.fused_merged;
    counters.handovers += c.handovers;
    counters.fused_created += c.fused_created;
  }
};

void Run(const Config& config, double seconds, std::uint32_t seed, Totals& totals) {
  std::mt19937 rng(seed);
  const Trajectories traj = Walk(config.people, seconds + 1.0, rng);
  std::vector<Sensor> sensors = MakeSensors(config.pose_error_scale, rng);
  std::vector<LocalTracker> trackers;
  for (std::size_t s = 0; s < sensors.size(); ++s) {
    trackers.emplace_back(config.people, config.errors, seed * 31u + static_cast<std::uint32_t>(s));
  }
  fusion::FusionOptions options;
  options.method = config.method;
  options.learn_sensor_bias = config.learn_sensor_bias;
  if (config.earlier_merge) {
    options.merge_sourceless = false;
    options.report_sourceless = true;
  }
  if (config.offset_sigma_fraction >= 0.0) {
    options.sensor_bias_offset_sigma_fraction = config.offset_sigma_fraction;
  }
  // The earlier releases' defaults with their method.
  if (config.method == fusion::FusionMethod::kLatestStates) {
    options.max_coast_s = 1.0;
    options.accel_psd = 1.0;
  }
  fusion::Fuser fuser(options);
  std::vector<fusion::SensorPlacement> placements;
  for (const Sensor& s : sensors) placements.push_back(s.placement);
  fuser.SetPlacements(placements);

  std::vector<std::pair<double, std::size_t>> events;
  for (std::size_t s = 0; s < sensors.size(); ++s) {
    for (double t = sensors[s].phase_s; t < seconds; t += sensors[s].period_s)
      events.emplace_back(t, s);
  }
  std::sort(events.begin(), events.end());

  std::vector<std::int64_t> last_id(config.people, -1);
  std::map<std::string, std::size_t> sensor_index;
  for (std::size_t s = 0; s < sensors.size(); ++s) sensor_index[sensors[s].id] = s;
  // Whether a person was visible to some sensor in the last frames (= a track should exist).
  std::vector<double> last_visible(config.people, -1e9);
  std::vector<std::map<std::uint32_t, fusion::WorldTrack>> latest_tracks(sensors.size());
  auto evaluate = [&](double t) {
    const UtcNs now = At(t);
    fuser.Tick(now);
    if (t < kWarmUp) return;
    ++totals.samples;
    std::vector<Vector2d> people, fused_pos;
    for (std::size_t p = 0; p < config.people; ++p) people.push_back(traj.At(p, t));
    const auto fused = fuser.Snapshot(now);
    for (const auto& f : fused) fused_pos.emplace_back(f.x_m, f.y_m);
    // CLEAR MOT: a person keeps the fused track matched before while it stays within the radius;
    // the others are matched greedily by distance.
    std::vector<int> match(config.people, -1);
    std::vector<char> taken(fused.size(), 0);
    for (std::size_t p = 0; p < config.people; ++p) {
      if (last_id[p] < 0) continue;
      for (std::size_t k = 0; k < fused.size(); ++k) {
        if (fused[k].id == static_cast<std::uint64_t>(last_id[p]) && !taken[k] &&
            (fused_pos[k] - people[p]).norm() <= kMatchRadius) {
          match[p] = static_cast<int>(k);
          taken[k] = 1;
        }
      }
    }
    {
      std::vector<Vector2d> free_people, free_tracks;
      std::vector<std::size_t> people_index, track_index;
      for (std::size_t p = 0; p < config.people; ++p) {
        if (match[p] >= 0) continue;
        free_people.push_back(people[p]);
        people_index.push_back(p);
      }
      for (std::size_t k = 0; k < fused.size(); ++k) {
        if (taken[k]) continue;
        free_tracks.push_back(fused_pos[k]);
        track_index.push_back(k);
      }
      const std::vector<int> m = Match(free_people, free_tracks);
      for (std::size_t i = 0; i < m.size(); ++i) {
        if (m[i] >= 0)
          match[people_index[i]] = static_cast<int>(track_index[static_cast<std::size_t>(m[i])]);
      }
    }
    std::vector<char> track_used(fused.size(), 0);
    for (std::size_t p = 0; p < config.people; ++p) {
      if (match[p] >= 0) track_used[static_cast<std::size_t>(match[p])] = 1;
    }
    for (const char used : track_used) totals.unmatched_fused += used ? 0 : 1;
    std::vector<double> fused_error(config.people, -1.0);
    for (std::size_t p = 0; p < config.people; ++p) {
      const bool visible = t - last_visible[p] < 0.2;
      if (match[p] >= 0) {
        const auto& f = fused[static_cast<std::size_t>(match[p])];
        const Vector2d error = fused_pos[static_cast<std::size_t>(match[p])] - people[p];
        totals.fused_errors.push_back(error.norm());
        fused_error[p] = error.norm();
        if (f.state == fusion::FusedState::kConfirmed) {
          const double nees = Nees2(error, f.covariance.topLeftCorner<2, 2>());
          totals.fused_nees_sum += std::min(nees, 1e4);
          ++totals.fused_nees_n;
          totals.fused_nees_inside += nees <= kChi2_95 ? 1 : 0;
        }
        if (last_id[p] >= 0 && static_cast<std::uint64_t>(last_id[p]) != f.id) ++totals.switches;
        last_id[p] = static_cast<std::int64_t>(f.id);
      }
      if (!visible) continue;
      totals.person_seconds += kSample;
      ++totals.visible_samples;
      // Fused tracks that are nearer to this person than to anybody else, within the radius.
      std::size_t mine = 0;
      for (const Vector2d& fp : fused_pos) {
        const double d = (fp - people[p]).norm();
        if (d > kMatchRadius) continue;
        bool nearest = true;
        for (std::size_t q = 0; q < config.people && nearest; ++q) {
          if (q != p && (fp - people[q]).norm() < d) nearest = false;
        }
        mine += nearest ? 1 : 0;
      }
      totals.exactly_one += mine == 1 ? 1 : 0;
    }
    // Single sensors: their confirmed raw tracks in the world frame (as the trackers report them,
    // without the fuser's correction of their biases), at their own scan times; those heard
    // within the fuser's source_timeout_s, as Fuser::WorldTracks lists them.
    std::vector<fusion::WorldTrack> world_tracks;
    for (std::size_t s = 0; s < sensors.size(); ++s) {
      for (auto it = latest_tracks[s].begin(); it != latest_tracks[s].end();) {
        if (common::NsToSeconds(now - it->second.stamp_ns) > options.source_timeout_s) {
          it = latest_tracks[s].erase(it);
          continue;
        }
        world_tracks.push_back(it->second);
        ++it;
      }
    }
    std::vector<std::size_t> views(config.people, 0);
    for (std::size_t s = 0; s < sensors.size(); ++s) {
      std::vector<Vector2d> raw;
      std::vector<Eigen::Matrix2d> raw_cov;
      double stamp_s = t;
      for (const auto& w : world_tracks) {
        if (sensor_index[w.sensor_id] != s || w.state != daemon::TrackState::kConfirmed) continue;
        raw.emplace_back(w.x_m, w.y_m);
        raw_cov.push_back(w.position_covariance);
        stamp_s = common::NsToSeconds(w.stamp_ns - kT0);
      }
      if (raw.empty()) continue;
      std::vector<Vector2d> truth;
      for (std::size_t p = 0; p < config.people; ++p) truth.push_back(traj.At(p, stamp_s));
      const std::vector<int> m = Match(truth, raw);
      for (std::size_t p = 0; p < config.people; ++p) {
        if (m[p] < 0) continue;
        const auto k = static_cast<std::size_t>(m[p]);
        const Vector2d error = raw[k] - truth[p];
        ++views[p];
        totals.sensor_errors[s].push_back(error.norm());
        if (match[p] >= 0) {
          totals.paired_sensor[s].push_back(error.norm());
          totals.paired_fused[s].push_back(
              (fused_pos[static_cast<std::size_t>(match[p])] - people[p]).norm());
        }
        totals.sensor_nees_sum += std::min(Nees2(error, raw_cov[k]), 1e4);
        ++totals.sensor_nees_n;
      }
    }
    for (std::size_t p = 0; p < config.people; ++p) {
      if (fused_error[p] >= 0.0) {
        totals.fused_errors_by_views[std::min<std::size_t>(views[p], 3)].push_back(fused_error[p]);
      }
    }
  };

  double next_sample = 0.0;
  for (const auto& [t, s] : events) {
    while (next_sample <= t) {
      evaluate(next_sample);
      next_sample += kSample;
    }
    const auto frame = trackers[s].Frame(sensors[s], traj, t);
    for (const auto& o : frame.tracks) {
      latest_tracks[s][o.track_id] =
          fusion::ToWorld(sensors[s].placement, sensors[s].id, frame.scan_start_ns, o);
    }
    const auto t0 = Clock::now();
    fuser.AddFrame(sensors[s].id, frame);
    totals.update_us.push_back(
        std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
    ++totals.frames;
    // A person is visible while some sensor reports a confirmed track on them.
    const common::Pose2 world_from_sensor = sensors[s].truth;
    for (const auto& o : frame.tracks) {
      if (o.state != daemon::TrackState::kConfirmed) continue;
      const Vector2d w = world_from_sensor * Vector2d(o.x_m, o.y_m);
      for (std::size_t p = 0; p < config.people; ++p) {
        if ((traj.At(p, t) - w).norm() < 0.5) last_visible[p] = t;
      }
    }
  }
  totals.Add(fuser.counters());
  for (const fusion::SensorBias& b : fuser.sensor_biases()) {
    if (!b.applied) continue;
    const std::size_t k = sensor_index[b.sensor_id];
    const double error = b.radial_m - trackers[k].sensor_offset_m();
    totals.bias_errors.push_back(error);
    totals.bias_inside_2sigma += std::abs(error) <= 2.0 * b.sigma_m ? 1 : 0;
    const common::Pose2& given = sensors[k].placement.world_from_sensor;
    const common::Pose2& truth = sensors[k].truth;
    const Vector2d before(given.x_m - truth.x_m, given.y_m - truth.y_m);
    const Vector2d after = before - Vector2d(b.dx_m, b.dy_m);
    const double yaw_before = common::AngleDiff(given.yaw_rad, truth.yaw_rad);
    totals.pose_before_m2 += before.squaredNorm();
    totals.pose_after_m2 += after.squaredNorm();
    totals.yaw_before_rad2 += yaw_before * yaw_before;
    totals.yaw_after_rad2 += (yaw_before - b.dyaw_rad) * (yaw_before - b.dyaw_rad);
  }
  // Group the sensors' encounters of the same two people (within 0.5 s): a swap is correctable
  // when another sensor measured both and did not swap them.
  struct Group {
    double last_s = -1e9;
    std::size_t seen = 0, swapped = 0;
  };
  std::vector<LocalTracker::Encounter> all;
  for (const auto& tr : trackers)
    all.insert(all.end(), tr.encounters().begin(), tr.encounters().end());
  std::sort(all.begin(), all.end(), [](const auto& a, const auto& b) { return a.t_s < b.t_s; });
  std::map<std::pair<std::size_t, std::size_t>, Group> open;
  auto close_group = [&](const Group& g) {
    if (g.swapped == 0) return;
    ++totals.swap_events;
    if (g.seen > g.swapped) ++totals.correctable_swap_events;
  };
  for (const auto& e : all) {
    totals.tracker_swaps += e.swapped ? 1 : 0;
    Group& g = open[{e.p, e.q}];
    if (e.t_s - g.last_s > 0.5) {
      close_group(g);
      g = Group{};
    }
    g.last_s = e.t_s;
    g.seen += e.seen ? 1 : 0;
    g.swapped += e.swapped ? 1 : 0;
  }
  for (const auto& [key, g] : open) close_group(g);
}

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1))];
}

double Rms(const std::vector<double>& v) {
  double sum = 0.0;
  for (double e : v) sum += e * e;
  return std::sqrt(sum / static_cast<double>(std::max<std::size_t>(v.size(), 1)));
}

}  // namespace

int main(int argc, char** argv) {
  std::string out = "results/fusion_benchmark.md";
  double seconds = 120.0;
  int seeds = 3;
  std::string only;  // rows whose scene and people are "NAME/PEOPLE", or all
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--out" && i + 1 < argc) {
      out = argv[++i];
    } else if (a == "--seconds" && i + 1 < argc) {
      seconds = std::stod(argv[++i]);
    } else if (a == "--seeds" && i + 1 < argc) {
      seeds = std::stoi(argv[++i]);
    } else if (a == "--scene" && i + 1 < argc) {
      only = argv[++i];
    } else {
      std::fprintf(
          stderr,
          "usage: fusion_benchmark [--out FILE] [--seconds S] [--seeds N] [--scene NAME/PEOPLE]\n");
      return 2;
    }
  }
  if (!(seconds >= 10.0 && seconds <= 3600.0) || seeds < 1 || seeds > 100) {
    std::fprintf(stderr, "fusion_benchmark: --seconds must be 10..3600, --seeds 1..100\n");
    return 2;
  }

  TrackerErrors ideal;
  ideal.swap_probability = 0.0;
  ideal.loss_rate_hz = 0.0;
  ideal.false_rate_hz = 0.0;
  const TrackerErrors errors;
  TrackerErrors legacy;
  legacy.legacy = true;
  std::vector<Config> scenes;
  scenes.push_back({"ideal trackers", 25, ideal, 1.0});
  for (std::size_t n : {10u, 25u, 50u}) scenes.push_back({"tracker errors", n, errors, 1.0});
  scenes.push_back({"tracker errors, poses 3 sigma off", 25, errors, 3.0});
  scenes.push_back({"tracker errors, exact poses", 25, errors, 0.0});
  scenes.push_back({"legacy trackers (centre of mass), tracker errors", 25, legacy, 1.0});

  const TrackerErrors& e = errors;
  char header[8192];
  std::snprintf(
      header, sizeof(header),
      "# Track fusion\n\n"
      "Synthetic scenes: six sensors (range 14 m, 190° field of view, 25 Hz, random phases) around "
      "a 30 m x 20 m hall; poses given to the fuser drawn from the reported covariance (0.03 m, "
      "0.3° per axis; the reference sensor s1 exact) or, where noted, from 3x it, or exact; "
      "people walking "
      "between random waypoints at 0.8-1.5 m/s with pauses. Every sensor has an emulated "
      "tracker: a constant-velocity Kalman filter (process noise %.1f m²/s³) on measurements of "
      "the body centre z = c + (o_sensor + o_track + o_turn) u + o_lateral l + n (u towards the "
      "sensor, l across): o_sensor uniform in [%.2f, %.2f] m per sensor, o_track N(0, %.2f m) "
      "per local track, o_turn and o_lateral AR(1) per person and sensor (%.3f m with %.1f s, "
      "%.3f m with %.1f s correlation), n white with %.3f m + %.3f m per metre of range. Its "
      "measurement covariance is honest about the spread of these errors, not about their "
      "correlation in time; shape-fit kind. Occlusion by nearer people, coasting for %.1f s, then "
      "a new id; %u tentative frames. With tracker errors also random losses (%.2f per "
      "track-second, %.1f s until a new id), id swaps (p = %.1f per sensor when two people it "
      "tracks come within %.1f m: each filter goes on with the other person's measurements) and "
      "false tracks (%.2f per sensor-second, 0.5-4 s, static or 0.3 m/s). Legacy trackers: the "
      "centre of the visible side, 0.08-0.20 m towards the sensor, claiming 0.11 m per axis, "
      "centre-of-mass kind. %d runs of %.0f s per row, default FusionOptions except the method "
      "(latest states with the earlier releases' max_coast_s 1.0 s and accel_psd 1.0 m²/s³), "
      "evaluated every 0.1 s after 2 s. Rows of a scene share their seeds (the same walks, "
      "poses and tracker errors).\n\n"
      "Fusion: *fused filter* (the default; one Kalman filter per fused track on every sensor's "
      "new information, with each sensor's centre offset as a state, and each sensor's constant "
      "centre offset and placement error learnt across its tracks, the placement error taken out "
      "of its frames and the offset where its sigma is at most a third of its kind's), *fused "
      "filter, earlier merge and reporting* (the same leaving fused tracks without sources "
      "beside the track that took their object, merge_sourceless off, and reporting them as "
      "coasting, report_sourceless on: the earlier release), *fused "
      "filter, every learnt offset taken out* (the same taking out every learnt offset, "
      "sensor_bias_offset_sigma_fraction 10: the earlier release), "
      "*fused filter, no sensor bias* (the same without that learning, learn_sensor_bias off: "
      "the earlier release) or *latest states* (the information-weighted combination of the "
      "sources' latest states, earlier releases). Fused ÷ best single: fused RMS divided by "
      "the best single sensor's. Learnt: at the end of each run, for the sensors whose bias "
      "is applied, the RMS of learnt minus true o_sensor (and the share within 2 of its "
      "reported sigma), and the RMS of the placements' translation and yaw errors before and "
      "after the learnt correction (s1, the exact reference, included when its bias applies). "
      "Tracker swaps: swaps summed over the sensors / encounters with a swap / of those, the "
      "ones in which another sensor measured both people and did not swap them. Fused RMS and "
      "p95: position error of confirmed and coasting fused tracks matched to people (CLEAR MOT "
      "style: a person keeps the track matched before while it stays within 1 m, the rest "
      "greedily by distance within 1 m); single sensor: each sensor's confirmed raw tracks in "
      "the world frame (the same poses) matched to people at their scan time, best and mean of "
      "the six sensors' RMS. By views: the fused RMS split by how many sensors had a confirmed "
      "track on the person at the sample (0: the fused track coasts or only tentative or "
      "coasting local tracks see the person). Fused ÷ sensor, same samples: for each sensor, the "
      "fused tracks' RMS on the samples where that sensor has a confirmed track on a person, "
      "divided by that "
      "sensor's RMS on them; the largest of the six (below 1: fusion beats every sensor where it "
      "sees). NEES: mean of e^T P^-1 e over matched confirmed fused tracks with "
      "their position covariance (2 for a covariance that fits the error; fraction inside the "
      "95 %% ellipse), and over the single sensors' tracks with their covariance in the world "
      "frame (pose included). Id switches: changes of a person's matched fused id, per minute "
      "the person is measured by some sensor. Exactly one: fraction of those samples in which "
      "the person has exactly one fused track within 1 m that is nearer to them than to anybody "
      "else. False tracks: fused tracks matched to nobody, per sample. Update: Fuser::AddFrame "
      "wall time per frame on one core. Rebinds / drifted / merged / hand-overs: the Fuser's "
      "counters source_rebinds, sources_drifted, fused_merged, handovers.\n\n"
      "| scene | fusion | people | tracker swaps | fused RMS m | fused p95 m "
      "| fused RMS m by views 0 / 1 / 2 / 3+ (share of samples) "
      "| best / mean single-sensor RMS m | fused ÷ best single | fused ÷ sensor RMS, same samples, "
      "worst sensor "
      "| fused NEES / inside 95 %% | single NEES "
      "| id switches / person-min | exactly one | false tracks / sample | update µs mean / p99 "
      "| rebinds / drifted / merged / hand-overs "
      "| learnt offset error RMS m (inside 2σ) / placement error before → after |\n"
      "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
      e.accel_psd, e.sensor_offset_min_m, e.sensor_offset_max_m, e.track_offset_sigma_m,
      e.turn_sigma_m, e.turn_tau_s, e.lateral_sigma_m, e.lateral_tau_s, e.noise_m, e.noise_per_m,
      e.coast_s, e.tentative_frames, e.loss_rate_hz, e.loss_gap_s, e.swap_probability,
      e.swap_distance_m, e.false_rate_hz, seeds, seconds);
  std::string table = header;
  std::printf("%s", table.c_str());
  std::fflush(stdout);
  for (const Config& scene : scenes) {
    if (!only.empty() && only != scene.name + "/" + std::to_string(scene.people)) continue;
    // The fused filter with the sensors' biases learnt (default), with every learnt offset taken
    // out (3), without learning (the earlier releases), and the latest states.
    for (const int variant : {0, 4, 3, 1, 2}) {
      const fusion::FusionMethod method =
          variant != 2 ? fusion::FusionMethod::kFusedFilter : fusion::FusionMethod::kLatestStates;
      Config config = scene;
      config.method = method;
      config.learn_sensor_bias = variant == 0 || variant == 3 || variant == 4;
      config.earlier_merge = variant == 4;
      if (variant == 3) config.offset_sigma_fraction = 10.0;
      Totals totals;
      for (int k = 0; k < seeds; ++k)
        Run(config, seconds, 1000u + static_cast<std::uint32_t>(k), totals);
      double best = 1e9, mean = 0.0, worst_paired = 0.0;
      int n = 0;
      for (std::size_t s = 0; s < 6; ++s) {
        if (totals.sensor_errors[s].empty()) continue;
        const double rms = Rms(totals.sensor_errors[s]);
        best = std::min(best, rms);
        mean += rms;
        ++n;
        if (!totals.paired_sensor[s].empty()) {
          worst_paired =
              std::max(worst_paired, Rms(totals.paired_fused[s]) / Rms(totals.paired_sensor[s]));
        }
      }
      mean /= std::max(n, 1);
      double sum_us = 0.0;
      for (double us : totals.update_us) sum_us += us;
      const auto ratio = [](double a, std::size_t b) {
        return a / static_cast<double>(std::max<std::size_t>(b, 1));
      };
      std::string by_views;
      for (std::size_t v = 0; v < 4; ++v) {
        char cell[64];
        std::snprintf(
            cell, sizeof(cell), "%s%.3f (%.0f %%)", v == 0 ? "" : " / ",
            Rms(totals.fused_errors_by_views[v]),
            100.0 * static_cast<double>(totals.fused_errors_by_views[v].size()) /
                static_cast<double>(std::max<std::size_t>(totals.fused_errors.size(), 1)));
        by_views += cell;
      }
      std::string learnt = "-";
      if (!totals.bias_errors.empty()) {
        const double n_bias = static_cast<double>(totals.bias_errors.size());
        char cell[160];
        std::snprintf(cell, sizeof(cell), "%.3f (%.0f %%) / %.3f → %.3f m, %.2f → %.2f°",
                      Rms(totals.bias_errors),
                      100.0 * static_cast<double>(totals.bias_inside_2sigma) / n_bias,
                      std::sqrt(totals.pose_before_m2 / n_bias),
                      std::sqrt(totals.pose_after_m2 / n_bias),
                      common::RadToDeg(std::sqrt(totals.yaw_before_rad2 / n_bias)),
                      common::RadToDeg(std::sqrt(totals.yaw_after_rad2 / n_bias)));
        learnt = cell;
      }
      char row[1280];
      std::snprintf(
          row, sizeof(row),
          "| %s | %s | %zu | %zu / %zu / %zu | %.3f | %.3f | %s | %.3f / %.3f | %.2f | %.2f "
          "| %.2f / %.1f %% | %.1f | %.2f | %.1f %% | %.2f | %.1f / %.1f | %llu / %llu / %llu / "
          "%llu | %s |\n",
          config.name.c_str(),
          variant == 0   ? "fused filter"
          : variant == 4 ? "fused filter, earlier merge and reporting"
          : variant == 3 ? "fused filter, every learnt offset taken out"
          : variant == 1 ? "fused filter, no sensor bias"
                         : "latest states",
          config.people, totals.tracker_swaps, totals.swap_events, totals.correctable_swap_events,
          Rms(totals.fused_errors), Percentile(totals.fused_errors, 0.95), by_views.c_str(), best,
          mean, Rms(totals.fused_errors) / best, worst_paired,
          ratio(totals.fused_nees_sum, totals.fused_nees_n),
          100.0 * ratio(static_cast<double>(totals.fused_nees_inside), totals.fused_nees_n),
          ratio(totals.sensor_nees_sum, totals.sensor_nees_n),
          static_cast<double>(totals.switches) / std::max(totals.person_seconds / 60.0, 1e-9),
          100.0 * ratio(static_cast<double>(totals.exactly_one), totals.visible_samples),
          ratio(static_cast<double>(totals.unmatched_fused), totals.samples),
          ratio(sum_us, totals.update_us.size()), Percentile(totals.update_us, 0.99),
          static_cast<unsigned long long>(totals.counters.source_rebinds),
          static_cast<unsigned long long>(totals.counters.sources_drifted),
          static_cast<unsigned long long>(totals.counters.fused_merged),
          static_cast<unsigned long long>(totals.counters.handovers), learnt.c_str());
      std::printf("%s", row);
      std::fflush(stdout);
      table += row;
    }
  }
  const std::filesystem::path path(out);
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
  std::ofstream file(out);
  file << table;
  if (!file) {
    std::fprintf(stderr, "fusion_benchmark: cannot write %s\n", out.c_str());
    return 1;
  }
  return 0;
}
