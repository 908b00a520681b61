#include "tools/sim/targets.h"

#include <algorithm>
#include <cmath>

#include "tools/sim/rng.h"

namespace lrfnet::sim {

namespace {

constexpr double kPi = 3.14159265358979323846;
// Shoulder rotation while walking (one cycle per stride), amplitude at walking speed.
constexpr double kTorsoTwistRad = 4.0 * kPi / 180.0;
// Sway and twist grow with speed up to this one (a person who shuffles barely sways).
constexpr double kFullSwaySpeedMps = 0.8;
// A trolley's pusher: the handle is this far behind the trolley's back, the pusher's centre one
// body depth further.
constexpr double kHandleGapM = 0.25;
// Half-window for the facing direction: a person turns over about half a second at a corner.
constexpr double kHeadingWindowS = 0.25;
// Speed-variation paths are sampled this densely (corners are added exactly).
constexpr double kVariationSampleS = 0.05;
// Random walks keep this much more than the body radius from walls and sensors.
constexpr double kWalkMarginM = 0.1;
constexpr double kWalkMinLegM = 1.0;
constexpr int kWalkGoalTries = 200;
constexpr int kWalkStartTries = 20000;

double Wrap(double a) { return std::remainder(a, 2.0 * kPi); }

// ---- paths

struct Polyline {
  std::vector<Vec2> points;
  std::vector<double> cumulative_m;  // arc length at each point
  double length_m = 0;
  bool loop = false;

  explicit Polyline(const TargetSpec& t) : loop(t.loop) {
    points = t.path;
    if (loop) points.push_back(points.front());
    cumulative_m.push_back(0.0);
    for (std::size_t i = 1; i < points.size(); ++i) {
      cumulative_m.push_back(cumulative_m.back() + Norm(points[i] - points[i - 1]));
    }
    length_m = cumulative_m.back();
  }

  Vec2 At(double s) const {
    if (loop) {
      s = std::fmod(s, length_m);
      if (s < 0) s += length_m;
    } else {
      s = std::clamp(s, 0.0, length_m);
    }
    auto it = std::upper_bound(cumulative_m.begin(), cumulative_m.end(), s);
    std::size_t i =
        it == cumulative_m.begin() ? 0 : static_cast<std::size_t>(it - cumulative_m.begin()) - 1;
    if (i + 1 >= points.size()) return points.back();
    const double seg = cumulative_m[i + 1] - cumulative_m[i];
    const double u = seg > 0 ? (s - cumulative_m[i]) / seg : 0.0;
    return points[i] + u * (points[i + 1] - points[i]);
  }
};

// Arc length walked after tau seconds: speed v with a sinusoidal variation (amplitude A,
// period P).
struct SpeedProfile {
  double v = 0;
  double amplitude = 0;
  double period = 1;

  double S(double tau) const {
    if (amplitude == 0.0) return v * tau;
    const double w = 2.0 * kPi / period;
    return v * tau - amplitude / w * (std::cos(w * tau) - 1.0);
  }
  // Inverse of S (monotonic because amplitude < v).
  double Tau(double s) const {
    if (amplitude == 0.0) return s / v;
    const double slack = amplitude * period / kPi;
    double lo = std::max(0.0, (s - slack) / v - 1e-6), hi = (s + slack) / v + 1e-6;
    for (int i = 0; i < 80; ++i) {
      const double mid = 0.5 * (lo + hi);
      (S(mid) < s ? lo : hi) = mid;
    }
    return 0.5 * (lo + hi);
  }
};

// The knots with t < limit, and one at limit on the way to the next (a trajectory that ends before
// limit is kept whole).
std::vector<Knot> CutAt(std::vector<Knot> knots, double limit) {
  std::vector<Knot> cut;
  for (std::size_t i = 0; i < knots.size(); ++i) {
    if (knots[i].t_s < limit) {
      cut.push_back(knots[i]);
      continue;
    }
    if (!cut.empty()) {
      const Knot& a = cut.back();
      const Knot& b = knots[i];
      const double dt = b.t_s - a.t_s;
      const double u = dt > 0 ? (limit - a.t_s) / dt : 1.0;
      cut.push_back(
          {limit, a.p + u * (b.p - a.p), a.distance_m + u * (b.distance_m - a.distance_m)});
    }
    return cut;
  }
  return cut;
}

Trajectory PathTrajectory(const TargetSpec& t, double horizon_s) {
  const double t0 = t.enter_s;
  const double limit = std::min(t.leave_s.value_or(horizon_s), horizon_s);
  if (limit <= t0) return Trajectory();
  const bool stay = t.stay.value_or(t.shape == TargetShape::kChair);
  if (t.path.size() == 1 || t.speed_mps == 0.0) {
    return Trajectory({{t0, t.path.front(), 0.0}, {limit, t.path.front(), 0.0}});
  }
  const Polyline line(t);
  SpeedProfile profile{t.speed_mps, 0.0, 1.0};
  if (t.speed_variation) {
    profile.amplitude = t.speed_variation->amplitude_mps;
    profile.period = t.speed_variation->period_s;
  }
  // Moving time: waits and stops only use up time, so limit - t0 of it always suffices.
  double stop = limit - t0;
  if (!t.loop) stop = std::min(stop, profile.Tau(line.length_m));

  struct Tagged {
    double tau;
    int waypoint;  // -1: not a waypoint
  };
  std::vector<Tagged> taus;
  const int n = static_cast<int>(t.path.size());
  // Corners exactly, lap after lap.
  for (double lap_start = 0.0;; lap_start += line.length_m) {
    bool beyond = false;
    for (std::size_t k = 0; k < line.cumulative_m.size(); ++k) {
      const double tau = profile.Tau(lap_start + line.cumulative_m[k]);
      if (tau > stop) {
        beyond = true;
        break;
      }
      taus.push_back({tau, static_cast<int>(k) % n});
    }
    if (beyond || !t.loop) break;
  }
  if (profile.amplitude > 0.0) {
    for (double tau = 0.0; tau < stop; tau += kVariationSampleS) taus.push_back({tau, -1});
  }
  taus.push_back({stop, -1});
  std::stable_sort(taus.begin(), taus.end(),
                   [](const Tagged& a, const Tagged& b) { return a.tau < b.tau; });
  std::vector<double> stop_s(static_cast<std::size_t>(n), 0.0);
  for (const PathStop& s : t.stops) stop_s[s.waypoint] += s.seconds;

  std::vector<Knot> knots;
  if (t.wait_s > 0.0) knots.push_back({t0, line.At(0.0), 0.0});
  double paused = t.wait_s;
  double last_tau = -1.0;
  for (const Tagged& tag : taus) {
    if (tag.tau - last_tau < 1e-9) continue;  // a corner first (stable sort), duplicates dropped
    last_tau = tag.tau;
    const double s = profile.S(tag.tau);
    knots.push_back({t0 + paused + tag.tau, line.At(s), s});
    if (tag.waypoint >= 0 && stop_s[static_cast<std::size_t>(tag.waypoint)] > 0.0) {
      paused += stop_s[static_cast<std::size_t>(tag.waypoint)];
      knots.push_back({t0 + paused + tag.tau, line.At(s), s});
    }
  }
  if (stay && !t.loop && knots.back().t_s < limit) {
    knots.push_back({limit, knots.back().p, knots.back().distance_m});
  }
  knots = CutAt(std::move(knots), limit);
  if (knots.size() == 1) knots.push_back(knots.front());
  return Trajectory(std::move(knots));
}

// ---- random walks

class WalkPlanner {
 public:
  WalkPlanner(const RandomWalkSpec& spec, const Clearance& clearance, double radius)
      : spec_(spec), clearance_(clearance), margin_(radius + kWalkMarginM) {
    area_edges_ = PolygonEdges(spec.area);
    lo_ = hi_ = spec.area.front();
    for (const Vec2& p : spec.area) {
      lo_ = {std::min(lo_.x, p.x), std::min(lo_.y, p.y)};
      hi_ = {std::max(hi_.x, p.x), std::max(hi_.y, p.y)};
    }
  }

  bool FreeSpot(Vec2 p) const {
    if (!PointInPolygon(p, spec_.area)) return false;
    for (const auto& o : clearance_.obstacles) {
      if (PointInPolygon(p, o)) return false;
    }
    for (const Segment& w : clearance_.walls) {
      if (PointSegmentDistance(p, w) < margin_) return false;
    }
    for (const Vec2& s : clearance_.sensors) {
      if (Norm(p - s) < margin_) return false;
    }
    return true;
  }

  bool FreeLeg(Vec2 a, Vec2 b) const {
    const Segment leg{a, b};
    for (const Segment& e : area_edges_) {
      if (SegmentsIntersect(leg, e)) return false;
    }
    for (const Segment& w : clearance_.walls) {
      if (SegmentSegmentDistance(leg, w) < margin_) return false;
    }
    for (const Vec2& s : clearance_.sensors) {
      if (PointSegmentDistance(s, leg) < margin_) return false;
    }
    return true;
  }

  Vec2 Sample(Rng& rng) const { return {rng.Uniform(lo_.x, hi_.x), rng.Uniform(lo_.y, hi_.y)}; }

 private:
  const RandomWalkSpec& spec_;
  const Clearance& clearance_;
  double margin_;
  std::vector<Segment> area_edges_;
  Vec2 lo_, hi_;
};

bool WalkTrajectory(const TargetSpec& t, std::size_t index, const Scenario& s,
                    const Clearance& clearance, Trajectory* out, std::string* error) {
  const RandomWalkSpec& spec = *t.random_walk;
  const double t0 = t.enter_s;
  const double limit = std::min(t.leave_s.value_or(s.duration_s), s.duration_s);
  if (limit <= t0) {
    *out = Trajectory();
    return true;
  }
  Rng rng(MixSeed({s.seed, static_cast<std::uint64_t>(RngStream::kRandomWalk), index}));
  const WalkPlanner planner(spec, clearance, TargetRadius(t));
  Vec2 p;
  bool found = false;
  for (int i = 0; i < kWalkStartTries && !found; ++i) {
    p = planner.Sample(rng);
    found = planner.FreeSpot(p);
  }
  if (!found) {
    *error = (s.source.empty() ? "" : s.source + ": ") + "targets[" + std::to_string(index) +
             "].random_walk.area: no free spot for a target of radius " +
             std::to_string(TargetRadius(t)) + " m (walls, obstacles or sensors cover the area)";
    return false;
  }
  std::vector<Knot> knots{{t0, p, 0.0}};
  double now = t0, walked = 0.0;
  while (now < limit) {
    bool moved = false;
    for (int i = 0; i < kWalkGoalTries; ++i) {
      const Vec2 goal = planner.Sample(rng);
      const double len = Norm(goal - p);
      if (len < kWalkMinLegM || !planner.FreeSpot(goal) || !planner.FreeLeg(p, goal)) continue;
      const double speed =
          spec.speed_mps * rng.Uniform(1.0 - spec.speed_spread, 1.0 + spec.speed_spread);
      now += len / speed;
      walked += len;
      p = goal;
      knots.push_back({now, p, walked});
      moved = true;
      break;
    }
    // Nowhere to go from here (a tight corner): stand for a moment and draw again.
    const double pause = moved ? rng.Uniform(0.0, spec.pause_s) : 0.5;
    if (pause > 0.0) {
      now += pause;
      knots.push_back({now, p, walked});
    }
  }
  // Cut at the limit.
  Trajectory full(std::move(knots));
  std::vector<Knot> cut;
  for (const Knot& k : full.knots()) {
    if (k.t_s >= limit) break;
    cut.push_back(k);
  }
  cut.push_back({limit, full.Position(limit), full.Distance(limit)});
  *out = Trajectory(std::move(cut));
  return true;
}

}  // namespace

// ---- Trajectory

Trajectory::Trajectory(std::vector<Knot> knots) : knots_(std::move(knots)) {
  if (knots_.size() == 1) knots_.push_back(knots_.front());
  const std::size_t legs = knots_.size() < 2 ? 0 : knots_.size() - 1;
  leg_heading_rad_.assign(legs, 0.0);
  std::optional<double> last;
  for (std::size_t i = 0; i < legs; ++i) {
    const Vec2 d = knots_[i + 1].p - knots_[i].p;
    const double dt = knots_[i + 1].t_s - knots_[i].t_s;
    if (Norm(d) > 1e-9) {
      last = std::atan2(d.y, d.x);
      if (dt > 0) max_speed_mps_ = std::max(max_speed_mps_, Norm(d) / dt);
    }
    leg_heading_rad_[i] = last.value_or(kNoHit);
  }
  // Pauses before the first move face the way the target will walk.
  double next = 0.0;
  for (std::size_t i = legs; i-- > 0;) {
    if (leg_heading_rad_[i] == kNoHit) {
      leg_heading_rad_[i] = next;
    } else {
      next = leg_heading_rad_[i];
    }
  }
}

std::size_t Trajectory::LegIndex(double t_s) const {
  auto it = std::upper_bound(knots_.begin(), knots_.end(), t_s,
                             [](double t, const Knot& k) { return t < k.t_s; });
  std::size_t i = it == knots_.begin() ? 0 : static_cast<std::size_t>(it - knots_.begin()) - 1;
  return std::min(i, knots_.size() - 2);
}

std::pair<std::size_t, double> Trajectory::LegFraction(double t_s) const {
  t_s = std::clamp(t_s, start_s(), end_s());
  const std::size_t i = LegIndex(t_s);
  const double dt = knots_[i + 1].t_s - knots_[i].t_s;
  return {i, dt > 0 ? (t_s - knots_[i].t_s) / dt : 1.0};
}

Vec2 Trajectory::Position(double t_s) const {
  if (knots_.empty()) return {};
  const auto [i, u] = LegFraction(t_s);
  return knots_[i].p + u * (knots_[i + 1].p - knots_[i].p);
}

double Trajectory::Distance(double t_s) const {
  if (knots_.empty()) return 0.0;
  const auto [i, u] = LegFraction(t_s);
  return knots_[i].distance_m + u * (knots_[i + 1].distance_m - knots_[i].distance_m);
}

double Trajectory::LegHeading(double t_s) const {
  if (leg_heading_rad_.empty()) return 0.0;
  return leg_heading_rad_[LegIndex(std::clamp(t_s, start_s(), end_s()))];
}

double Trajectory::LegSpeed(std::size_t leg) const {
  if (leg + 1 >= knots_.size()) return 0.0;
  const double dt = knots_[leg + 1].t_s - knots_[leg].t_s;
  return dt > 0 ? Norm(knots_[leg + 1].p - knots_[leg].p) / dt : 0.0;
}

// ---- People

PersonBody ResolvePerson(const PersonSpec& spec, Rng& rng) {
  const auto normal = [&](double mean, double sigma, double lo, double hi) {
    return std::clamp(mean + sigma * rng.Normal(), lo, hi);
  };
  // Every value drawn, in this order, whether or not the scenario fixes it.
  const double a = normal(0.23, 0.02, 0.18, 0.30);
  const double b = normal(0.14, 0.015, 0.10, 0.20);
  const double exponent = rng.Uniform(2.0, 3.0);
  const double sway = rng.Uniform(0.015, 0.035);
  const double leg = rng.Uniform(0.05, 0.07);
  const double hip = rng.Uniform(0.08, 0.11);
  PersonBody body;
  body.a_m = spec.a_m.value_or(a);
  body.b_m = spec.b_m.value_or(b);
  // DESIGN.md: a person given a_m and b_m is that ellipse.
  body.exponent = spec.torso_exponent.value_or(spec.a_m && spec.b_m ? 2.0 : exponent);
  body.sway_m = spec.sway_m.value_or(sway);
  body.leg_radius_m = spec.leg_radius_m.value_or(leg);
  body.hip_half_width_m = spec.hip_half_width_m.value_or(hip);
  return body;
}

double StrideM(double speed_mps) {
  if (!(speed_mps > 0.0)) return 0.0;
  return std::min(2.0, 1.4 * std::pow(speed_mps / 1.3, 0.6));
}

double FootOffsetStrides(double phase) {
  const double u = phase - std::floor(phase);
  if (u < kStanceFraction) return 0.3 - 0.6 * u / kStanceFraction;
  const double s = (u - kStanceFraction) / (1.0 - kStanceFraction);
  return -0.3 + 0.6 * 0.5 * (1.0 - std::cos(kPi * s));
}

// ---- Target

namespace {

// Farthest any part of the body can be from its centre, over all mounts.
double BodyReach(TargetShape shape, const TargetSpec& spec, const PersonBody& body) {
  switch (shape) {
    case TargetShape::kCylinder:
      return spec.radius_m;
    case TargetShape::kPerson: {
      // The superellipse lies in its box; legs reach 0.3 of the longest stride at knee height.
      const double torso = std::hypot(body.a_m, body.b_m) + body.sway_m;
      const double legs = std::hypot(body.hip_half_width_m, kKneeFraction * 0.3 * StrideM(10.0)) +
                          body.leg_radius_m + body.sway_m;
      return std::max(torso, legs);
    }
    case TargetShape::kTrolley:
      return 0.5 * std::hypot(spec.length_m, spec.width_m);
    case TargetShape::kChair:
      return spec.size_m / std::sqrt(2.0);
    case TargetShape::kDoor:
      return spec.door ? spec.door->width_m + spec.door->thickness_m : 1.0;
  }
  return 1.0;
}

}  // namespace

Target::Target(std::string id, TargetShape shape, std::size_t spec_index, const TargetSpec& spec,
               const PersonBody& body, Trajectory trajectory, double behind_m)
    : id_(std::move(id)),
      shape_(shape),
      spec_index_(spec_index),
      spec_(spec),
      body_(body),
      trajectory_(std::move(trajectory)),
      behind_m_(behind_m),
      bound_radius_m_(BodyReach(shape, spec, body) + behind_m) {
  // Gait phase at every knot: cycles = integral of distance over stride length.
  const auto& knots = trajectory_.knots();
  knot_phase_.assign(knots.size(), 0.0);
  for (std::size_t i = 1; i < knots.size(); ++i) {
    const double stride = StrideM(trajectory_.LegSpeed(i - 1));
    const double walked = knots[i].distance_m - knots[i - 1].distance_m;
    knot_phase_[i] = knot_phase_[i - 1] + (stride > 0 ? walked / stride : 0.0);
  }
}

double Target::GaitPhase(double t_s) const {
  const auto& knots = trajectory_.knots();
  if (knots.size() < 2) return 0.0;
  const std::size_t i = trajectory_.LegAt(t_s);
  const double stride = StrideM(trajectory_.LegSpeed(i));
  const double walked = trajectory_.Distance(t_s) - knots[i].distance_m;
  return knot_phase_[i] + (stride > 0 ? walked / stride : 0.0);
}

TargetState Target::StateAt(double t_s) const {
  TargetState s;
  if (trajectory_.knots().empty() || !trajectory_.Present(t_s)) return s;
  s.present = true;
  const Vec2 p = trajectory_.Position(t_s);
  const Vec2 ahead = trajectory_.Position(t_s + kHeadingWindowS);
  const Vec2 behind = trajectory_.Position(t_s - kHeadingWindowS);
  const Vec2 d = ahead - behind;
  s.heading_rad = Norm(d) > 0.05 ? std::atan2(d.y, d.x) : trajectory_.LegHeading(t_s);
  constexpr double kH = 0.01;
  const double t_lo = std::max(trajectory_.start_s(), t_s - kH);
  const double t_hi = std::min(trajectory_.end_s(), t_s + kH);
  if (t_hi > t_lo) {
    s.velocity_mps =
        (1.0 / (t_hi - t_lo)) * (trajectory_.Position(t_hi) - trajectory_.Position(t_lo));
  }
  s.speed_mps = trajectory_.LegSpeed(trajectory_.LegAt(t_s));
  const Vec2 forward{std::cos(s.heading_rad), std::sin(s.heading_rad)};
  const Vec2 left{-forward.y, forward.x};
  s.center = p - behind_m_ * forward;
  switch (shape_) {
    case TargetShape::kPerson: {
      s.gait_phase = GaitPhase(t_s);
      const double walking = std::min(1.0, s.speed_mps / kFullSwaySpeedMps);
      // The body shifts over the standing foot: one sway cycle per stride, and the shoulders turn
      // against the hips.
      const double angle = 2.0 * kPi * s.gait_phase;
      const Vec2 hips = s.center;
      s.center = s.center + (walking * body_.sway_m * std::sin(angle)) * left;
      const double twist = walking * kTorsoTwistRad * std::cos(angle);
      // Axis a runs across the shoulders, perpendicular to the facing direction.
      s.body_yaw_rad = Wrap(s.heading_rad + kPi / 2.0 + twist);
      // Legs at knee height: from the hip towards the foot, which stands while the body passes.
      const double stride = StrideM(s.speed_mps);
      for (int leg = 0; leg < 2; ++leg) {
        const double side = leg == 0 ? 1.0 : -1.0;
        const double foot = FootOffsetStrides(s.gait_phase + 0.5 * leg) * stride;
        s.legs[leg] = hips + (side * body_.hip_half_width_m) * left +
                      (kKneeFraction * foot) * forward +
                      (0.5 * walking * body_.sway_m * std::sin(angle)) * left;
      }
      break;
    }
    case TargetShape::kTrolley:
      s.body_yaw_rad = s.heading_rad;
      break;
    case TargetShape::kChair:
      s.body_yaw_rad = Wrap(spec_.yaw_deg * kPi / 180.0);
      break;
    case TargetShape::kDoor: {
      const DoorSpec& door = *spec_.door;
      const auto angle_at = [&](double t) {
        const auto& k = door.swing;
        if (t <= k.front().first) return k.front().second;
        for (std::size_t i = 1; i < k.size(); ++i) {
          if (t <= k[i].first) {
            const double u = (t - k[i - 1].first) / (k[i].first - k[i - 1].first);
            return k[i - 1].second + u * (k[i].second - k[i - 1].second);
          }
        }
        return k.back().second;
      };
      const auto centre_at = [&](double t) {
        const double a = angle_at(t) * kPi / 180.0;
        return door.hinge + (0.5 * door.width_m) * Vec2{std::cos(a), std::sin(a)};
      };
      s.body_yaw_rad = Wrap(angle_at(t_s) * kPi / 180.0);
      s.heading_rad = s.body_yaw_rad;
      s.center = centre_at(t_s);
      s.velocity_mps = (1.0 / (2.0 * kH)) * (centre_at(t_s + kH) - centre_at(t_s - kH));
      s.speed_mps = Norm(s.velocity_mps);
      break;
    }
    case TargetShape::kCylinder:
      s.body_yaw_rad = s.heading_rad;
      break;
  }
  return s;
}

double Target::Intersect(const Ray& ray, const TargetState& state, Mount mount) const {
  if (!state.present) return kNoHit;
  switch (shape_) {
    case TargetShape::kCylinder:
      return RayCircle(ray, state.center, spec_.radius_m);
    case TargetShape::kPerson:
      if (mount == Mount::kLegs) {
        return std::min(RayCircle(ray, state.legs[0], body_.leg_radius_m),
                        RayCircle(ray, state.legs[1], body_.leg_radius_m));
      }
      return RaySuperellipse(ray, state.center, body_.a_m, body_.b_m, body_.exponent,
                             state.body_yaw_rad);
    case TargetShape::kTrolley:
      return RayBox(ray, state.center, 0.5 * spec_.length_m, 0.5 * spec_.width_m,
                    state.body_yaw_rad);
    case TargetShape::kChair: {
      const Vec2 facing{std::cos(state.body_yaw_rad), std::sin(state.body_yaw_rad)};
      const Vec2 side{-facing.y, facing.x};
      const double half = 0.5 * spec_.size_m;
      if (mount == Mount::kLegs) {
        // Four legs at the seat's corners.
        constexpr double kLegRadiusM = 0.015;
        double best = kNoHit;
        for (const double f : {-1.0, 1.0}) {
          for (const double l : {-1.0, 1.0}) {
            const Vec2 c = state.center + (f * (half - 0.03)) * facing + (l * (half - 0.03)) * side;
            best = std::min(best, RayCircle(ray, c, kLegRadiusM));
          }
        }
        return best;
      }
      // The backrest: a board along the seat's back edge.
      constexpr double kBackrestHalfDepthM = 0.025;
      return RayBox(ray, state.center - (half - kBackrestHalfDepthM) * facing, kBackrestHalfDepthM,
                    half, state.body_yaw_rad);
    }
    case TargetShape::kDoor:
      return RayBox(ray, state.center, 0.5 * spec_.door->width_m, 0.5 * spec_.door->thickness_m,
                    state.body_yaw_rad);
  }
  return kNoHit;
}

bool BuildTargets(const Scenario& scenario, std::vector<Target>* out, std::string* error) {
  Clearance clearance;
  for (const auto& wall : scenario.world.walls) {
    for (std::size_t k = 0; k + 1 < wall.size(); ++k)
      clearance.walls.push_back({wall[k], wall[k + 1]});
  }
  for (const auto* polygons : {&scenario.world.obstacles, &scenario.world.low_obstacles}) {
    for (const auto& o : *polygons) {
      for (const Segment& e : PolygonEdges(o)) clearance.walls.push_back(e);
      clearance.obstacles.push_back(o);
    }
  }
  for (const SensorSpec& s : scenario.sensors) clearance.sensors.push_back({s.x_m, s.y_m});
  out->clear();
  for (std::size_t i = 0; i < scenario.targets.size(); ++i) {
    const TargetSpec& spec = scenario.targets[i];
    Trajectory trajectory;
    if (spec.shape == TargetShape::kDoor) {
      // The hinge stays; the leaf turns (Target::StateAt).
      const double limit =
          std::min(spec.leave_s.value_or(scenario.duration_s), scenario.duration_s);
      if (limit > spec.enter_s) {
        trajectory =
            Trajectory({{spec.enter_s, spec.door->hinge, 0.0}, {limit, spec.door->hinge, 0.0}});
      }
    } else if (spec.random_walk) {
      if (!WalkTrajectory(spec, i, scenario, clearance, &trajectory, error)) return false;
    } else {
      trajectory = PathTrajectory(spec, scenario.duration_s);
    }
    Rng body_rng(MixSeed({scenario.seed, static_cast<std::uint64_t>(RngStream::kBody), i}));
    const PersonBody body = ResolvePerson(spec.person, body_rng);
    out->emplace_back(spec.id, spec.shape, i, spec, body, trajectory);
    if (spec.shape == TargetShape::kTrolley) {
      out->emplace_back(spec.id + ".pusher", TargetShape::kPerson, i, spec, body,
                        std::move(trajectory), 0.5 * spec.length_m + kHandleGapM + body.b_m);
    }
  }
  return true;
}

}  // namespace lrfnet::sim
