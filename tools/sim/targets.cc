#include "tools/sim/targets.h"

#include <algorithm>
#include <cmath>

#include "tools/sim/rng.h"

namespace lrfnet::sim {

namespace {

constexpr double kPi = 3.14159265358979323846;
// A person's stride (two steps): one full lateral sway cycle per stride.
constexpr double kStrideM = 1.4;
// Shoulder rotation while walking, amplitude.
constexpr double kTorsoTwistRad = 4.0 * kPi / 180.0;
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

Trajectory PathTrajectory(const TargetSpec& t, double horizon_s) {
  const double t0 = t.enter_s;
  const double limit = std::min(t.leave_s.value_or(horizon_s), horizon_s);
  if (limit <= t0) return Trajectory();
  if (t.path.size() == 1 || t.speed_mps == 0.0) {
    return Trajectory({{t0, t.path.front(), 0.0}, {limit, t.path.front(), 0.0}});
  }
  const Polyline line(t);
  SpeedProfile profile{t.speed_mps, 0.0, 1.0};
  if (t.speed_variation) {
    profile.amplitude = t.speed_variation->amplitude_mps;
    profile.period = t.speed_variation->period_s;
  }
  double stop = limit;
  if (!t.loop) stop = std::min(limit, t0 + profile.Tau(line.length_m));

  std::vector<double> taus;
  // Corners exactly, lap after lap.
  for (double lap_start = 0.0;; lap_start += line.length_m) {
    bool beyond = false;
    for (std::size_t k = 0; k < line.cumulative_m.size(); ++k) {
      const double tau = profile.Tau(lap_start + line.cumulative_m[k]);
      if (t0 + tau > stop) {
        beyond = true;
        break;
      }
      taus.push_back(tau);
    }
    if (beyond || !t.loop) break;
  }
  if (profile.amplitude > 0.0) {
    for (double tau = 0.0; t0 + tau < stop; tau += kVariationSampleS) taus.push_back(tau);
  }
  taus.push_back(stop - t0);
  std::sort(taus.begin(), taus.end());
  std::vector<Knot> knots;
  for (double tau : taus) {
    if (!knots.empty() && tau - (knots.back().t_s - t0) < 1e-9) continue;
    const double s = profile.S(tau);
    knots.push_back({t0 + tau, line.At(s), s});
  }
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

// ---- Target

Target::Target(const TargetSpec& spec, Trajectory trajectory)
    : id_(spec.id),
      shape_(spec.shape),
      radius_m_(spec.radius_m),
      a_m_(spec.a_m),
      b_m_(spec.b_m),
      sway_m_(spec.sway_m),
      trajectory_(std::move(trajectory)),
      bound_radius_m_(TargetRadius(spec)) {}

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
  s.center = p;
  double twist = 0.0;
  if (shape_ == TargetShape::kPerson && sway_m_ > 0.0) {
    const double phase = 2.0 * kPi * trajectory_.Distance(t_s) / kStrideM;
    const double lateral = sway_m_ * std::sin(phase);
    s.center = p + lateral * Vec2{-std::sin(s.heading_rad), std::cos(s.heading_rad)};
    twist = kTorsoTwistRad * std::cos(phase);
  }
  // Axis a runs across the shoulders, perpendicular to the facing direction.
  s.body_yaw_rad = Wrap(s.heading_rad + kPi / 2.0 + twist);
  return s;
}

double Target::Intersect(const Ray& ray, const TargetState& state) const {
  if (!state.present) return kNoHit;
  if (shape_ == TargetShape::kCylinder) return RayCircle(ray, state.center, radius_m_);
  return RayEllipse(ray, state.center, a_m_, b_m_, state.body_yaw_rad);
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
    if (spec.random_walk) {
      if (!WalkTrajectory(spec, i, scenario, clearance, &trajectory, error)) return false;
    } else {
      trajectory = PathTrajectory(spec, scenario.duration_s);
    }
    out->emplace_back(spec, std::move(trajectory));
  }
  return true;
}

}  // namespace lrfnet::sim
