#pragma once
// Moving targets: a trajectory (timed knots, linear between them) and a body: a cylinder; a person
// (upper body a superellipse that sways and turns with the gait, legs at knee height that step);
// a trolley pushed by a person; a chair; a door leaf swinging on its hinge. Pure; world frame,
// metres, seconds of scenario time.

#include <algorithm>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "tools/sim/geometry2d.h"
#include "tools/sim/rng.h"
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
  // The leg (knot index i, knots_[i] .. knots_[i + 1]) in use at t_s (clamped), and its speed.
  std::size_t LegAt(double t_s) const { return LegIndex(std::clamp(t_s, start_s(), end_s())); }
  double LegSpeed(std::size_t leg) const;
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

// A person's body, resolved: what the scenario gave, the rest drawn from the seed.
struct PersonBody {
  double a_m = 0.25;               // upper body, semi-axis across the shoulders
  double b_m = 0.15;               // upper body, semi-axis front to back
  double exponent = 2.0;           // superellipse exponent of the upper body (2: ellipse)
  double sway_m = 0.03;            // lateral sway amplitude at walking speed
  double leg_radius_m = 0.06;      // leg cross-section at knee height
  double hip_half_width_m = 0.09;  // lateral offset of each leg from the body centre
};

// The person's sizes: `spec`'s values, the others drawn from `rng` (every value is drawn, in a
// fixed order, so fixing one does not change the others).
PersonBody ResolvePerson(const PersonSpec& spec, Rng& rng);

// Gait of a walking person (pure): stride length (two steps) over speed, L(v) = 1.4 m (v /
// 1.3 m/s)^0.6, 0 when standing; each leg is on the ground for kStanceFraction of a cycle.
double StrideM(double speed_mps);
inline constexpr double kStanceFraction = 0.6;
// Offset of a foot from the hip along the walking direction, in strides, at gait phase `phase`
// (cycles; 0 = heel strike): stance moves it back linearly from +0.3 to -0.3 (the foot stands while
// the body passes over it), swing brings it forward again on a smooth (cosine) profile.
double FootOffsetStrides(double phase);
// At knee height a leg is this fraction of the way from the hip to the foot (knee 0.5 m, hip
// 0.9 m above the floor).
inline constexpr double kKneeFraction = 0.45;

struct TargetState {
  bool present = false;
  Vec2 center;             // body centre (with sway): the truth of every shape
  double heading_rad = 0;  // direction the target faces (smoothed direction of travel)
  // Person: direction of the upper body's a axis (shoulders, with twist). Trolley: its length
  // axis. Chair: the direction its seat faces. Door: the leaf, from the hinge.
  double body_yaw_rad = 0;
  Vec2 velocity_mps;  // of the path point (without sway)
  double speed_mps = 0;
  double gait_phase = 0;  // person: cycles walked (left heel strike at whole numbers)
  Vec2 legs[2];           // person: centres of the left and right leg at knee height
};

class Target {
 public:
  // `spec_index`: the scenario target it belongs to. `behind_m` (a trolley's pusher): the body
  // centre lies this far behind the trajectory point along the facing direction.
  Target(std::string id, TargetShape shape, std::size_t spec_index, const TargetSpec& spec,
         const PersonBody& body, Trajectory trajectory, double behind_m = 0.0);

  const std::string& id() const { return id_; }
  TargetShape shape() const { return shape_; }
  std::size_t spec_index() const { return spec_index_; }
  const PersonBody& body() const { return body_; }
  const Trajectory& trajectory() const { return trajectory_; }
  // Upper bound of the distance from the trajectory point to any point of the body (every mount).
  double bound_radius_m() const { return bound_radius_m_; }
  double remission() const { return shape_ == TargetShape::kPerson ? 0.3 : 0.6; }

  TargetState StateAt(double t_s) const;
  // Distance along the ray to the body in `state` as a sensor mounted at `mount` sees it, kNoHit
  // if it misses (or the target is absent).
  double Intersect(const Ray& ray, const TargetState& state, Mount mount = Mount::kTorso) const;

 private:
  double GaitPhase(double t_s) const;

  std::string id_;
  TargetShape shape_;
  std::size_t spec_index_;
  TargetSpec spec_;  // shape parameters (door, chair, trolley)
  PersonBody body_;
  Trajectory trajectory_;
  double behind_m_;
  std::vector<double> knot_phase_;  // gait phase at every knot
  double bound_radius_m_;
};

// What random walks keep clear of.
struct Clearance {
  std::vector<Segment> walls;  // walls, obstacle and low-obstacle edges
  std::vector<std::vector<Vec2>> obstacles;
  std::vector<Vec2> sensors;
};

// Builds every target's trajectory over [0, duration_s] (random walks drawn from the scenario seed
// and the target's index, person sizes from the seed and the index too). One Target per scenario
// target, in the scenario's order, then a trolley's pusher ("<id>.pusher") after its trolley.
// False with *error (one line naming the target) when a random walk finds no free spot in its
// area.
bool BuildTargets(const Scenario& scenario, std::vector<Target>* out, std::string* error);

}  // namespace lrfnet::sim
