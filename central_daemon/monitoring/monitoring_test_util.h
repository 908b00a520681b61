#pragma once
// Scenes with known answers for the monitoring tests: background snapshots ray-cast from a pose in
// a world of wall segments, and track frames of people walking known paths, seen from a pose.

#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "central_daemon/ingest/sensor_data.h"
#include "common/geometry.h"
#include "common/time.h"

namespace lrfnet::monitoring::testing {

using common::Pose2;

struct Wall {
  Eigen::Vector2d a, b;
};

// A 12 x 8 m room with a cabinet and a pillar: structure in every direction.
inline std::vector<Wall> Room() {
  std::vector<Wall> w = {
      {{0, 0}, {12, 0}}, {{12, 0}, {12, 8}}, {{12, 8}, {0, 8}}, {{0, 8}, {0, 0}}};
  const auto box = [&](double x0, double y0, double x1, double y1) {
    w.push_back({{x0, y0}, {x1, y0}});
    w.push_back({{x1, y0}, {x1, y1}});
    w.push_back({{x1, y1}, {x0, y1}});
    w.push_back({{x0, y1}, {x0, y0}});
  };
  box(5.5, 7.0, 7.5, 7.6);  // cabinet
  box(3.0, 3.8, 3.4, 4.2);  // pillar
  return w;
}

inline void AddBox(std::vector<Wall>* w, double x0, double y0, double x1, double y1) {
  w->push_back({{x0, y0}, {x1, y0}});
  w->push_back({{x1, y0}, {x1, y1}});
  w->push_back({{x1, y1}, {x0, y1}});
  w->push_back({{x0, y1}, {x0, y0}});
}

// Range along a ray from `origin` in direction `dir` to the nearest wall (+inf: none).
inline double CastRay(const std::vector<Wall>& walls, const Eigen::Vector2d& origin,
                      const Eigen::Vector2d& dir) {
  double best = std::numeric_limits<double>::infinity();
  for (const Wall& w : walls) {
    const Eigen::Vector2d e = w.b - w.a;
    const double den = dir.x() * e.y() - dir.y() * e.x();
    if (std::abs(den) < 1e-12) continue;
    const Eigen::Vector2d d = w.a - origin;
    const double t = (d.x() * e.y() - d.y() * e.x()) / den;
    const double u = (d.x() * dir.y() - d.y() * dir.x()) / den;
    if (t > 1e-6 && u >= 0.0 && u <= 1.0) best = std::min(best, t);
  }
  return best;
}

// A TiM561-like snapshot (811 beams of 1/3 degree from -135 degrees, 10 m): what a sensor at
// world_from_sensor sees of `walls`, with Gaussian range noise of sigma_m (seeded).
inline daemon::BackgroundScan Snapshot(const std::vector<Wall>& walls,
                                       const Pose2& world_from_sensor, double sigma_m = 0.0,
                                       std::uint32_t seed = 1, std::uint32_t snapshot_id = 1) {
  daemon::BackgroundScan b;
  b.session_id = 7;
  b.snapshot_id = snapshot_id;
  b.first_angle_rad = common::DegToRad(-135.0);
  b.angle_step_rad = common::DegToRad(1.0 / 3.0);
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, 1.0);
  for (int i = 0; i < 811; ++i) {
    const double a = world_from_sensor.yaw_rad + b.first_angle_rad + i * b.angle_step_rad;
    const double r =
        CastRay(walls, world_from_sensor.translation(), Eigen::Vector2d(std::cos(a), std::sin(a))) +
        sigma_m * noise(rng);
    b.ranges_mm.push_back(r > 0.05 && r <= 10.0 ? static_cast<std::uint32_t>(std::lround(r * 1e3))
                                                : 0u);
  }
  return b;
}

// A person walking a closed loop at speed_mps (world frame), position at time t_s.
struct Walker {
  std::vector<Eigen::Vector2d> loop;
  double speed_mps = 1.2;
  double phase_s = 0.0;

  Eigen::Vector2d At(double t_s, Eigen::Vector2d* velocity = nullptr) const {
    double length = 0;
    for (std::size_t i = 0; i < loop.size(); ++i)
      length += (loop[(i + 1) % loop.size()] - loop[i]).norm();
    double s = std::fmod((t_s + phase_s) * speed_mps, length);
    for (std::size_t i = 0;; i = (i + 1) % loop.size()) {
      const Eigen::Vector2d d = loop[(i + 1) % loop.size()] - loop[i];
      if (s <= d.norm()) {
        if (velocity != nullptr) *velocity = d.normalized() * speed_mps;
        return loop[i] + d * (s / d.norm());
      }
      s -= d.norm();
    }
  }
};

inline std::vector<Walker> TwoPeople() {
  return {{{{2.5, 2}, {9.5, 2}, {9.5, 5.5}, {2.5, 5.5}}, 1.2, 0.0},
          {{{4, 3.5}, {8.5, 3.5}, {6.5, 6}}, 1.0, 3.0}};
}

// Track frames at rate_hz over [t0_s, t1_s) of `people` as a sensor at world_from_sensor reports
// them (sensor frame, confirmed, 2 cm noise, covariance to match; body centres, i.e. a shape fit
// with the person's size), scan times from start_ns.
inline std::vector<daemon::TrackFrameData> Frames(const std::vector<Walker>& people,
                                                  const Pose2& world_from_sensor, double t0_s,
                                                  double t1_s, common::UtcNs start_ns,
                                                  std::uint64_t session_id = 11,
                                                  std::uint32_t seed = 3, double rate_hz = 15.0) {
  std::vector<daemon::TrackFrameData> out;
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, 0.02);
  const Pose2 sensor_from_world = world_from_sensor.inverse();
  const Eigen::Matrix2d r = sensor_from_world.rotation();
  std::uint32_t counter = 0;
  for (double t = t0_s; t < t1_s; t += 1.0 / rate_hz) {
    daemon::TrackFrameData f;
    f.session_id = session_id;
    f.scan_start_ns = start_ns + static_cast<common::UtcNs>(std::llround(t * 1e9));
    f.scan_period_s = 1.0 / rate_hz;
    f.scan_counter = counter++;
    for (std::size_t k = 0; k < people.size(); ++k) {
      Eigen::Vector2d v;
      const Eigen::Vector2d p = sensor_from_world * people[k].At(t, &v);
      const Eigen::Vector2d vs = r * v;
      daemon::TrackObservation o;
      o.track_id = static_cast<std::uint32_t>(k + 1);
      o.state = daemon::TrackState::kConfirmed;
      // The walker's own position: a body centre, as a shape fit with the person's size reports it.
      o.kind = daemon::MeasurementKind::kShapeFit;
      o.shape = daemon::ObjectShape::kTorso;
      o.size_major_m = 0.25f;
      o.size_minor_m = 0.15f;
      o.size_sigma_m = 0.02f;
      o.ellipse_yaw_rad = static_cast<float>(std::atan2(vs.y(), vs.x()) + 0.5 * M_PI);
      o.points = 12;
      o.x_m = static_cast<float>(p.x() + noise(rng));
      o.y_m = static_cast<float>(p.y() + noise(rng));
      o.vx_mps = static_cast<float>(vs.x());
      o.vy_mps = static_cast<float>(vs.y());
      o.covariance = {4e-4f, 0, 0, 0, 4e-4f, 0, 0, 0.01f, 0, 0.01f};
      o.age_scans = counter;
      f.tracks.push_back(o);
    }
    out.push_back(std::move(f));
  }
  return out;
}

}  // namespace lrfnet::monitoring::testing
