#pragma once
// Test-only: a synthetic stationary scanner that ray-casts walls and elliptic bodies (people,
// cylinders, carts) and adds Gaussian range noise, producing ScanViews for the tracking tests.
// Sensor at the origin of its own frame; ranges beyond max_range_m are reported as 0 (no echo),
// like the telegram.

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <span>
#include <vector>

#include "common/geometry.h"
#include "common/time.h"
#include "firmware_tracker/tracking/scan_view.h"

namespace lrfnet::tracking::testing {

// The scan rate the tests' synthetic scanners run at.
inline constexpr double kRateHz = 25.0;

struct Wall {
  Eigen::Vector2d a_m;
  Eigen::Vector2d b_m;
};

struct Body {
  Eigen::Vector2d centre_m;
  double semi_major_m = 0.25;
  double semi_minor_m = 0.15;
  double yaw_rad = 0.0;  // major axis direction
};

inline Body Cylinder(const Eigen::Vector2d& centre_m, double radius_m) {
  return {centre_m, radius_m, radius_m, 0.0};
}

struct ScannerConfig {
  double first_angle_rad = common::DegToRad(-135.0);
  double angle_step_rad = common::DegToRad(0.5);
  std::size_t beams = 541;
  double max_range_m = 20.0;
  double noise_sigma_m = 0.01;
  double rate_hz = 25.0;
  std::uint32_t seed = 1;
  // Per beam and scan: probability of a spurious return at a uniform random range in
  // [0.2 m, true range) (dust, rain, reflections), and of a no-echo (range 0) instead of the
  // return.
  double spurious_fraction = 0.0;
  double dropout_fraction = 0.0;
};

class SyntheticScanner {
 public:
  explicit SyntheticScanner(const ScannerConfig& config = {})
      : config_(config), ranges_(config.beams, 0.0f), rng_(config.seed) {
    for (std::size_t i = 0; i < config_.beams; ++i) {
      directions_.emplace_back(std::cos(BeamAngle(i)), std::sin(BeamAngle(i)));
    }
  }

  // Scan number k (stamp k / rate_hz seconds) of the given scene. The view refers to this object's
  // buffer and is valid until the next Render.
  ScanView Render(std::int64_t k, std::span<const Wall> walls, std::span<const Body> bodies) {
    return RenderTimed(k, walls, [bodies](double) { return bodies; });
  }

  // As Render, but bodies move during the scan like in a real scanner: beam i is measured at
  // BeamTimeS(k, i) (the mirror turns once per scan period, beam 0 at the scan start), and
  // bodies_at(t_s) gives the bodies at that time (a std::span<const Body> valid until the next
  // call).
  template <typename BodiesAt>
  ScanView RenderTimed(std::int64_t k, std::span<const Wall> walls, const BodiesAt& bodies_at) {
    std::normal_distribution<double> noise(0.0, 1.0);
    std::uniform_real_distribution<double> uniform(0.0, 1.0);
    for (std::size_t i = 0; i < config_.beams; ++i) {
      const Eigen::Vector2d& d = directions_[i];
      double best = std::numeric_limits<double>::infinity();
      for (const Wall& w : walls) best = std::min(best, HitWall(d, w));
      for (const Body& b : std::span<const Body>(bodies_at(BeamTimeS(k, i)))) {
        best = std::min(best, HitBody(d, b));
      }
      double r = best + config_.noise_sigma_m * noise(rng_);
      if (!(best <= config_.max_range_m)) r = 0.0;
      if (config_.spurious_fraction > 0.0 && uniform(rng_) < config_.spurious_fraction) {
        const double far = r > 0.0 ? r : config_.max_range_m;
        r = 0.2 + (far - 0.2) * uniform(rng_);
      }
      if (config_.dropout_fraction > 0.0 && uniform(rng_) < config_.dropout_fraction) r = 0.0;
      ranges_[i] = static_cast<float>(std::max(r, 0.0));
    }
    ScanView view;
    view.first_angle_rad = config_.first_angle_rad;
    view.angle_step_rad = config_.angle_step_rad;
    view.range_m = ranges_;
    view.scan_period_s = 1.0 / config_.rate_hz;
    view.stamp_ns = StampNs(k);
    return view;
  }

  // Seconds since scan 0 at which beam i of scan k is measured.
  double BeamTimeS(std::int64_t k, std::size_t i) const {
    return (static_cast<double>(k) +
            static_cast<double>(i) * std::abs(config_.angle_step_rad) / (2.0 * common::kPi)) /
           config_.rate_hz;
  }
  double ScanTimeS(std::int64_t k) const { return static_cast<double>(k) / config_.rate_hz; }

  common::UtcNs StampNs(std::int64_t k) const {
    return 1'600'000'000 * common::kNsPerS +
           static_cast<common::UtcNs>(static_cast<double>(k) * 1e9 / config_.rate_hz);
  }
  double BeamAngle(std::size_t i) const {
    return config_.first_angle_rad + static_cast<double>(i) * config_.angle_step_rad;
  }
  std::vector<float>& ranges() { return ranges_; }
  const ScannerConfig& config() const { return config_; }

 private:
  static double Cross(const Eigen::Vector2d& u, const Eigen::Vector2d& v) {
    return u.x() * v.y() - u.y() * v.x();
  }
  static double HitWall(const Eigen::Vector2d& d, const Wall& w) {
    const Eigen::Vector2d e = w.b_m - w.a_m;
    const double denom = Cross(d, e);
    if (std::abs(denom) < 1e-12) return std::numeric_limits<double>::infinity();
    const double t = Cross(w.a_m, e) / denom;
    const double s = Cross(w.a_m, d) / denom;
    return (t > 0.0 && s >= 0.0 && s <= 1.0) ? t : std::numeric_limits<double>::infinity();
  }
  static double HitBody(const Eigen::Vector2d& d, const Body& b) {
    // Cheap rejection by the enclosing circle before the exact ellipse intersection.
    if (std::abs(Cross(d, b.centre_m)) > b.semi_major_m || d.dot(b.centre_m) < -b.semi_major_m) {
      return std::numeric_limits<double>::infinity();
    }
    const double c = std::cos(b.yaw_rad), s = std::sin(b.yaw_rad);
    const Eigen::Vector2d o(-(c * b.centre_m.x() + s * b.centre_m.y()),
                            -(-s * b.centre_m.x() + c * b.centre_m.y()));
    const Eigen::Vector2d dl(c * d.x() + s * d.y(), -s * d.x() + c * d.y());
    const Eigen::Vector2d o2(o.x() / b.semi_major_m, o.y() / b.semi_minor_m);
    const Eigen::Vector2d d2(dl.x() / b.semi_major_m, dl.y() / b.semi_minor_m);
    const double qa = d2.squaredNorm(), qb = 2.0 * o2.dot(d2), qc = o2.squaredNorm() - 1.0;
    const double disc = qb * qb - 4.0 * qa * qc;
    if (disc < 0.0) return std::numeric_limits<double>::infinity();
    const double t = (-qb - std::sqrt(disc)) / (2.0 * qa);
    return t > 0.0 ? t : std::numeric_limits<double>::infinity();
  }

  ScannerConfig config_;
  std::vector<float> ranges_;
  std::vector<Eigen::Vector2d> directions_;  // unit vector of every beam
  std::mt19937 rng_;
};

// A room around the sensor, with an opening in the upper right (beams there have no echo).
inline std::vector<Wall> Room() {
  return {
      {{8.0, -5.0}, {8.0, 1.0}},  // front wall, ends at y = 1
      {{4.0, 5.0}, {-2.0, 5.0}},  // left wall, ends at x = 4
      {{-2.0, 5.0}, {-2.0, -5.0}},
      {{-2.0, -5.0}, {8.0, -5.0}},
  };
}

}  // namespace lrfnet::tracking::testing
