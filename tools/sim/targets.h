#pragma once
// Moving targets: a trajectory (timed knots, linear between them) and a body (cylinder, or a
// person's upper-body ellipse that sways while walking). Pure; world frame, metres, seconds of
// scenario time.

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "tools/sim/geometry2d.h"
#include "tools/sim/scenario.h"

namespace lrfnet::sim {

struct Knot {
  double t_s = 0;
  Vec2 p;
  double distance_m = 0;  // walked since the target entered
};

// Piecewise-linear motion between knots with non-decreasing times; the target is in the scene
// from the first knot's time up to (not including) the last's, so a target that leaves at t and
// one that enters at t are never there together.
class Trajectory {
 public:
  Trajectory() = default;
  explicit Trajectory(std::vector<Knot> knots);

  double start_s() const { return knots_.front().t_s; }
  double end_s() const { return knots_.back().t_s; }
  bool Present(double t_s) const { return t_s >= start_s() && t_s < end_s(); }
  // Clamped to [start_s, end_s].
  Vec2 Position(double t_s) const;
  double Distance(double t_s) const;
  // Direction of travel of the leg in use at t_s; while standing, the last direction walked.
  double LegHeading(double t_s) const;
  double max_speed_mps() const { return max_speed_mps_; }
  const std::vector<Knot>& knots() const { return knots_; }

 private:
  std::size_t LegIndex(double t_s) const;  // i with knots_[i].t_s <= t_s < knots_[i+1].t_s
  // For t_s clamped to the trajectory: its leg and the fraction of that leg's time passed.
  std::pair<std::size_t, double> LegFraction(double t_s) const;

  std::vector<Knot> knots_;
  std::vector<double> leg_heading_rad_;  // per leg
  double max_speed_mps_ = 0;
};

struct TargetState {
  bool present = false;
  Vec2 center;              // body centre (with sway)
  double heading_rad = 0;   // direction the target faces (smoothed direction of travel)
  double body_yaw_rad = 0;  // person: direction of the ellipse's a axis (shoulders, with twist)
  Vec2 velocity_mps;        // of the path point (without sway)
};

class Target {
 public:
  Target(const TargetSpec& spec, Trajectory trajectory);

  const std::string& id() const { return id_; }
  TargetShape shape() const { return shape_; }
  const Trajectory& trajectory() const { return trajectory_; }
  // Upper bound of the distance from the path point to any point of the body.
  double bound_radius_m() const { return bound_radius_m_; }
  double remission() const { return shape_ == TargetShape::kPerson ? 0.3 : 0.6; }

  TargetState StateAt(double t_s) const;
  // Distance along the ray to the body in `state`, kNoHit if it misses (or the target is absent).
  double Intersect(const Ray& ray, const TargetState& state) const;

 private:
  std::string id_;
  TargetShape shape_;
  double radius_m_;
  double a_m_;
  double b_m_;
  double sway_m_;
  Trajectory trajectory_;
  double bound_radius_m_;
};

// What random walks keep clear of.
struct Clearance {
  std::vector<Segment> walls;  // walls, obstacle and low-obstacle edges
  std::vector<std::vector<Vec2>> obstacles;
  std::vector<Vec2> sensors;
};

// Builds every target's trajectory over [0, duration_s] (random walks drawn from the scenario seed
// and the target's index). False with *error (one line naming the target) when a random walk finds
// no free spot in its area.
bool BuildTargets(const Scenario& scenario, std::vector<Target>* out, std::string* error);

}  // namespace lrfnet::sim
