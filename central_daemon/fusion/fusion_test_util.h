#pragma once
// For the tests: a synthetic scene of sensors and walking people whose local tracks (tracker-like:
// new ids on (re)appearance, tentative for the first frames, noisy measurements biased towards
// the sensor, filtered by a constant-velocity Kalman filter like lrfnet-tracker's, or reported
// raw) are fed to a Fuser in time order. Deterministic for a given seed.

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "central_daemon/fusion/fusion.h"
#include "common/cv_model.h"
#include "common/geometry.h"
#include "common/time.h"

namespace lrfnet::fusion::testing {

inline constexpr common::UtcNs kT0 = 1'700'000'000LL * common::kNsPerS;

inline common::UtcNs AtSeconds(double t_s) { return kT0 + common::SecondsToNs(t_s); }

struct SimSensor {
  std::string id;
  common::Pose2 truth;                  // world_from_sensor
  std::optional<common::Pose2> placed;  // what the Fuser is told; the truth when unset
  Eigen::Matrix3d pose_covariance = Eigen::Vector3d(1e-4, 1e-4, 1e-6).asDiagonal();
  double range_m = 30.0;
  // World region the sensor sees (on top of range_m); everything when unset.
  std::function<bool(const Eigen::Vector2d&)> sees;
  double period_s = 0.04;
  double phase_s = 0.0;
  // Scene times at which the sensor sends no frames; never when unset.
  std::function<bool(double)> silent;
  double noise_m = 0.03;  // white noise of each measurement (per axis)
  double bias_m = 0.0;    // offset of the measured position towards the sensor
  // The measurement's standard deviation the tracker assumes (and, unfiltered, reports).
  double reported_sigma_m = 0.05;
  // Tracks are the states of a constant-velocity Kalman filter (process noise
  // tracker_accel_psd) fed with the measurements; unset: every frame reports the raw measurement
  // with reported_sigma_m and a velocity with 0.1 m/s noise.
  bool filtered = true;
  double tracker_accel_psd = 0.5;
  std::uint64_t session_id = 1;
};

struct SimPerson {
  std::function<Eigen::Vector2d(double)> position;  // world, at scene time t_s
  // Whether sensor index s sees the object at scene time t_s (on top of its range and `sees`);
  // always when unset. E.g. a false object only one sensor reports for a while.
  std::function<bool(std::size_t, double)> seen_by;
  Eigen::Vector2d Velocity(double t_s) const {
    const double h = 1e-3;
    return (position(t_s + h) - position(t_s - h)) / (2.0 * h);
  }
};

// A person walking from a to b at speed_mps starting at start_s (standing at a before, at b after).
inline SimPerson Walker(Eigen::Vector2d a, Eigen::Vector2d b, double speed_mps,
                        double start_s = 0.0) {
  SimPerson person;
  person.position = [=](double t) {
    const double len = (b - a).norm();
    const double s = std::clamp((t - start_s) * speed_mps, 0.0, len);
    return Eigen::Vector2d(a + (b - a) * (len > 0.0 ? s / len : 0.0));
  };
  return person;
}

inline SensorPlacement PlacementOf(const SimSensor& s) {
  return SensorPlacement{s.id, s.placed.value_or(s.truth), s.pose_covariance};
}

class Scene {
 public:
  std::vector<SimSensor> sensors;
  std::vector<SimPerson> people;
  std::uint32_t seed = 1;
  std::uint32_t tentative_frames = 2;
  // Remaps a local id just before it is reported: (sensor index, t_s, person index, id) -> id.
  std::function<std::uint32_t(std::size_t, double, std::size_t, std::uint32_t)> remap;
  // Called before every frame of a sensor at scene time t_s (e.g. to restart a tracker).
  std::function<void(Scene&, std::size_t, double)> before_frame;
  // Called with every measurement a tracker gets: (sensor index, t_s, person index, position in
  // the world frame (true pose), its standard deviation per axis as the tracker assumes it).
  std::function<void(std::size_t, double, std::size_t, const Eigen::Vector2d&, double)>
      on_measurement;

  std::vector<SensorPlacement> Placements() const {
    std::vector<SensorPlacement> out;
    for (const SimSensor& s : sensors) out.push_back(PlacementOf(s));
    return out;
  }

  // Sensor s's tracker exchanges the local tracks (ids and filters) of persons p and q: from now
  // on each goes on with the other person's measurements (an association error).
  void ExchangeLocalTracks(std::size_t s, std::size_t p, std::size_t q) {
    local_.resize(sensors.size());
    auto& ids = local_[s].ids;
    const auto ip = ids.find(p), iq = ids.find(q);
    if (ip != ids.end() && iq != ids.end()) std::swap(ip->second, iq->second);
  }

  // Forgets the local tracks of a sensor (its tracker restarted): ids start again at 1.
  void RestartTracker(std::size_t sensor) {
    local_[sensor] = {};
    ++sensors[sensor].session_id;
  }

  // Feeds every sensor's frames of [0, duration_s) into the fuser in time order; every sample_s it
  // calls fuser.Tick(now) and then observe(t_s, now).
  void Run(Fuser& fuser, double duration_s, double sample_s,
           const std::function<void(double, common::UtcNs)>& observe) {
    local_.resize(sensors.size());
    std::vector<std::pair<double, std::size_t>> events;
    for (std::size_t s = 0; s < sensors.size(); ++s) {
      for (double t = sensors[s].phase_s; t < duration_s; t += sensors[s].period_s) {
        if (!sensors[s].silent || !sensors[s].silent(t)) events.emplace_back(t, s);
      }
    }
    std::sort(events.begin(), events.end());
    double next_sample = 0.0;
    for (const auto& [t, s] : events) {
      while (next_sample <= t) {
        fuser.Tick(AtSeconds(next_sample));
        if (observe) observe(next_sample, AtSeconds(next_sample));
        next_sample += sample_s;
      }
      if (before_frame) before_frame(*this, s, t);
      fuser.AddFrame(sensors[s].id, Frame(s, t));
    }
  }

  // The frame sensor s reports at scene time t_s (advances its local tracker).
  daemon::TrackFrameData Frame(std::size_t s, double t_s) {
    local_.resize(sensors.size());
    if (!seeded_) {
      rng_.seed(seed);
      seeded_ = true;
    }
    const SimSensor& sensor = sensors[s];
    Local& local = local_[s];
    daemon::TrackFrameData frame;
    frame.session_id = sensor.session_id;
    frame.scan_start_ns = AtSeconds(t_s);
    frame.scan_period_s = sensor.period_s;
    frame.scan_counter = local.frames++;
    std::normal_distribution<double> n01(0.0, 1.0);
    const common::Pose2 sensor_from_world = sensor.truth.inverse();
    for (std::size_t p = 0; p < people.size(); ++p) {
      const Eigen::Vector2d pos = people[p].position(t_s);
      const bool visible = (pos - sensor.truth.translation()).norm() <= sensor.range_m &&
                           (!sensor.sees || sensor.sees(pos)) &&
                           (!people[p].seen_by || people[p].seen_by(s, t_s));
      if (!visible) {
        local.ids.erase(p);
        continue;
      }
      auto [it, inserted] = local.ids.try_emplace(p, LocalTrack{local.next_id});
      if (inserted) ++local.next_id;
      LocalTrack& track = it->second;
      const std::uint32_t age = track.age++;
      std::uint32_t id = track.id;
      if (remap) id = remap(s, t_s, p, id);

      Eigen::Vector2d observed = pos;
      const Eigen::Vector2d to_sensor = sensor.truth.translation() - pos;
      if (to_sensor.norm() > 1e-9) observed += sensor.bias_m * to_sensor.normalized();
      observed += sensor.noise_m * Eigen::Vector2d(n01(rng_), n01(rng_));
      const Eigen::Vector2d z_s = sensor_from_world * observed;
      const double r = sensor.reported_sigma_m * sensor.reported_sigma_m;
      if (on_measurement) on_measurement(s, t_s, p, observed, sensor.reported_sigma_m);
      common::CvState x;
      common::CvCovariance cov;
      if (sensor.filtered) {
        if (age == 0) {
          track.x << z_s, 0.0, 0.0;
          track.p = Eigen::Vector4d(r, r, 2.25, 2.25).asDiagonal();
        } else {
          common::CvPredict(t_s - track.t_s, sensor.tracker_accel_psd, track.x, track.p);
          const Eigen::Matrix2d s_inv =
              (track.p.topLeftCorner<2, 2>() + r * Eigen::Matrix2d::Identity())
                  .llt()
                  .solve(Eigen::Matrix2d::Identity());
          const Eigen::Matrix<double, 4, 2> gain = track.p.leftCols<2>() * s_inv;
          track.x += gain * (z_s - track.x.head<2>());
          track.p -= gain * track.p.topRows<2>();
          track.p = (0.5 * (track.p + track.p.transpose())).eval();
        }
        track.t_s = t_s;
        x = track.x;
        cov = track.p;
      } else {
        const Eigen::Vector2d v_s =
            sensor.truth.rotation().transpose() *
            (people[p].Velocity(t_s) + 0.1 * Eigen::Vector2d(n01(rng_), n01(rng_)));
        x << z_s, v_s;
        cov = Eigen::Vector4d(r, r, 0.01, 0.01).asDiagonal();
      }
      daemon::TrackObservation o;
      o.track_id = id;
      o.state =
          age < tentative_frames ? daemon::TrackState::kTentative : daemon::TrackState::kConfirmed;
      o.kind = daemon::MeasurementKind::kCenterOfMass;
      o.x_m = static_cast<float>(x(0));
      o.y_m = static_cast<float>(x(1));
      o.vx_mps = static_cast<float>(x(2));
      o.vy_mps = static_cast<float>(x(3));
      std::size_t k = 0;
      for (int row = 0; row < 4; ++row) {
        for (int col = row; col < 4; ++col) o.covariance[k++] = static_cast<float>(cov(row, col));
      }
      o.age_scans = age;
      frame.tracks.push_back(o);
    }
    std::sort(frame.tracks.begin(), frame.tracks.end(),
              [](const auto& a, const auto& b) { return a.track_id < b.track_id; });
    return frame;
  }

 private:
  struct LocalTrack {
    std::uint32_t id = 0;
    std::uint32_t age = 0;
    double t_s = 0.0;  // of the filter's state
    common::CvState x = common::CvState::Zero();
    common::CvCovariance p = common::CvCovariance::Identity();
  };
  struct Local {
    std::map<std::size_t, LocalTrack> ids;  // person -> its local track
    std::uint32_t next_id = 1;
    std::uint32_t frames = 0;
  };
  std::vector<Local> local_;
  std::mt19937 rng_;
  bool seeded_ = false;
};

// The fused track nearest to pos within radius_m (nullptr when none).
inline const FusedTrack* Nearest(const std::vector<FusedTrack>& tracks, const Eigen::Vector2d& pos,
                                 double radius_m) {
  const FusedTrack* best = nullptr;
  double best_d = radius_m;
  for (const FusedTrack& t : tracks) {
    const double d = std::hypot(t.x_m - pos.x(), t.y_m - pos.y());
    if (d <= best_d) {
      best_d = d;
      best = &t;
    }
  }
  return best;
}

// The number of fused tracks within radius_m of pos.
inline std::size_t CountNear(const std::vector<FusedTrack>& tracks, const Eigen::Vector2d& pos,
                             double radius_m) {
  return static_cast<std::size_t>(std::count_if(tracks.begin(), tracks.end(), [&](const auto& t) {
    return std::hypot(t.x_m - pos.x(), t.y_m - pos.y()) <= radius_m;
  }));
}

}  // namespace lrfnet::fusion::testing
