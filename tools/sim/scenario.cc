#include "tools/sim/scenario.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>

#include "common/one_line.h"

namespace lrfnet::sim {

namespace {

// Sensors stand at least this far from any wall (a sensor inside a wall sees nothing).
constexpr double kSensorWallClearanceM = 0.05;
constexpr double kMaxDurationS = 24.0 * 3600.0;

std::string Fmt(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

std::string FmtPoint(Vec2 p) { return "[" + Fmt(p.x) + ", " + Fmt(p.y) + "]"; }

bool ValidId(const std::string& id) {
  if (id.empty() || id.size() > 64) return false;
  return std::all_of(id.begin(), id.end(),
                     [](char c) {
                       return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') ||
                              (c >= '0' && c <= '9') || c == '_' || c == '-' || c == '.';
                     }) &&
         id != "." && id != "..";
}

class Checker {
 public:
  explicit Checker(const Scenario& s) : s_(s) {}

  std::optional<std::string> error;

  bool Fail(int line, const std::string& path, const std::string& message) {
    if (error) return false;
    std::string prefix;
    if (!s_.source.empty())
      prefix = s_.source + (line > 0 ? ":" + std::to_string(line) : "") + ": ";
    // Ids and names come from the file: one line, a hostile one cut short.
    error = prefix + common::OneLine(path, 120) + ": " + common::OneLine(message, 600);
    return false;
  }

  bool Range(int line, const std::string& path, double v, double lo, double hi) {
    if (std::isfinite(v) && v >= lo && v <= hi) return true;
    return Fail(line, path, "must be in [" + Fmt(lo) + ", " + Fmt(hi) + "], got " + Fmt(v));
  }
  bool Positive(int line, const std::string& path, double v, double hi) {
    if (std::isfinite(v) && v > 0.0 && v <= hi) return true;
    return Fail(line, path, "must be in (0, " + Fmt(hi) + "], got " + Fmt(v));
  }
  bool Finite(int line, const std::string& path, Vec2 p) {
    if (std::isfinite(p.x) && std::isfinite(p.y) && std::abs(p.x) < 1e6 && std::abs(p.y) < 1e6) {
      return true;
    }
    return Fail(line, path, "coordinates must be finite and within ±1e6 m");
  }

 private:
  const Scenario& s_;
};

bool InBounds(Vec2 p, const std::pair<Vec2, Vec2>& b) {
  return p.x > b.first.x && p.x < b.second.x && p.y > b.first.y && p.y < b.second.y;
}

std::string BoundsText(const std::pair<Vec2, Vec2>& b) {
  return FmtPoint(b.first) + " .. " + FmtPoint(b.second);
}

struct NamedSegment {
  Segment segment;
  std::string name;  // "world.walls[2]"
};

std::vector<NamedSegment> StaticSegments(const WorldSpec& w) {
  std::vector<NamedSegment> out;
  for (std::size_t i = 0; i < w.walls.size(); ++i) {
    for (std::size_t k = 0; k + 1 < w.walls[i].size(); ++k) {
      out.push_back({{w.walls[i][k], w.walls[i][k + 1]}, "world.walls[" + std::to_string(i) + "]"});
    }
  }
  for (std::size_t i = 0; i < w.obstacles.size(); ++i) {
    for (const Segment& e : PolygonEdges(w.obstacles[i])) {
      out.push_back({e, "world.obstacles[" + std::to_string(i) + "]"});
    }
  }
  return out;
}

std::vector<NamedSegment> LowSegments(const WorldSpec& w) {
  std::vector<NamedSegment> out;
  for (std::size_t i = 0; i < w.low_obstacles.size(); ++i) {
    for (const Segment& e : PolygonEdges(w.low_obstacles[i])) {
      out.push_back({e, "world.low_obstacles[" + std::to_string(i) + "]"});
    }
  }
  return out;
}

bool CheckWorld(const WorldSpec& w, Checker& c) {
  for (std::size_t i = 0; i < w.walls.size(); ++i) {
    const std::string path = "world.walls[" + std::to_string(i) + "]";
    const int line = i < w.wall_lines.size() ? w.wall_lines[i] : 0;
    const auto& wall = w.walls[i];
    if (wall.size() < 2) return c.Fail(line, path, "a wall needs at least 2 points");
    for (std::size_t k = 0; k < wall.size(); ++k) {
      if (!c.Finite(line, path, wall[k])) return false;
      if (k > 0 && Norm(wall[k] - wall[k - 1]) < 1e-9) {
        return c.Fail(line, path,
                      "points " + std::to_string(k - 1) + " and " + std::to_string(k) +
                          " are the same (zero-length segment)");
      }
    }
  }
  for (std::size_t i = 0; i < w.obstacles.size(); ++i) {
    const std::string path = "world.obstacles[" + std::to_string(i) + "]";
    const int line = i < w.obstacle_lines.size() ? w.obstacle_lines[i] : 0;
    for (const Vec2& p : w.obstacles[i]) {
      if (!c.Finite(line, path, p)) return false;
    }
    if (auto e = CheckSimplePolygon(w.obstacles[i])) return c.Fail(line, path, *e);
  }
  for (std::size_t i = 0; i < w.low_obstacles.size(); ++i) {
    const std::string path = "world.low_obstacles[" + std::to_string(i) + "]";
    const int line = i < w.low_obstacle_lines.size() ? w.low_obstacle_lines[i] : 0;
    for (const Vec2& p : w.low_obstacles[i]) {
      if (!c.Finite(line, path, p)) return false;
    }
    if (auto e = CheckSimplePolygon(w.low_obstacles[i])) return c.Fail(line, path, *e);
  }
  if (w.bounds) {
    const auto& b = *w.bounds;
    if (!c.Finite(0, "world.bounds", b.first) || !c.Finite(0, "world.bounds", b.second))
      return false;
    if (!(b.first.x < b.second.x && b.first.y < b.second.y)) {
      return c.Fail(0, "world.bounds", "must be [[x_min, y_min], [x_max, y_max]] with min < max");
    }
  }
  if (w.walls.empty() && w.obstacles.empty() && !w.bounds) {
    return c.Fail(0, "world", "give walls, obstacles or bounds (the extent of the world)");
  }
  return true;
}

bool CheckSensor(const Scenario& s, std::size_t i, const std::vector<NamedSegment>& segments,
                 const std::pair<Vec2, Vec2>& bounds, std::set<std::string>* ids, Checker& c) {
  const SensorSpec& sensor = s.sensors[i];
  const std::string path = "sensors[" + std::to_string(i) + "]";
  const int line = sensor.line;
  if (!ValidId(sensor.id)) {
    return c.Fail(
        line, path + ".id",
        "'" + sensor.id + "' is not a valid id (1-64 of A-Z a-z 0-9 _ - .; it names a file)");
  }
  if (!ids->insert(sensor.id).second) {
    return c.Fail(line, path + ".id", "duplicate sensor id '" + sensor.id + "'");
  }
  const DeviceModel* model = FindDeviceModel(sensor.model);
  if (model == nullptr) {
    return c.Fail(line, path + ".model",
                  "unknown model '" + sensor.model + "' (known: " + DeviceModelKeys() + ")");
  }
  DeviceConfig device;
  if (auto e = ResolveDevice(*model, sensor.overrides, &device)) {
    // ResolveDevice says "<override key>: <problem>".
    const std::size_t colon = e->find(": ");
    return c.Fail(line, path + "." + e->substr(0, colon),
                  colon == std::string::npos ? "invalid" : e->substr(colon + 2));
  }
  const Vec2 p{sensor.x_m, sensor.y_m};
  if (!c.Finite(line, path, p)) return false;
  if (!c.Range(line, path + ".yaw_deg", sensor.yaw_deg, -3600.0, 3600.0)) return false;
  if (!InBounds(p, bounds)) {
    return c.Fail(line, path,
                  "sensor '" + sensor.id + "' at " + FmtPoint(p) + " is outside the world (" +
                      BoundsText(bounds) + ")");
  }
  for (std::size_t k = 0; k < s.world.obstacles.size(); ++k) {
    if (PointInPolygon(p, s.world.obstacles[k])) {
      return c.Fail(
          line, path,
          "sensor '" + sensor.id + "' stands inside world.obstacles[" + std::to_string(k) + "]");
    }
  }
  for (const NamedSegment& seg : segments) {
    const double d = PointSegmentDistance(p, seg.segment);
    if (d < kSensorWallClearanceM) {
      return c.Fail(line, path,
                    "sensor '" + sensor.id + "' is " + Fmt(d) + " m from " + seg.name +
                        " (keep >= " + Fmt(kSensorWallClearanceM) + " m)");
    }
  }
  if (sensor.bias_m && !c.Range(line, path + ".bias_m", *sensor.bias_m, -1.0, 1.0)) return false;
  if (sensor.clock.offset_s &&
      !c.Range(line, path + ".clock.offset_s", *sensor.clock.offset_s, 0.0, 1e7)) {
    return false;
  }
  if (sensor.clock.drift_ppm &&
      !c.Range(line, path + ".clock.drift_ppm", *sensor.clock.drift_ppm, -1000.0, 1000.0)) {
    return false;
  }
  const NetworkSpec& n = sensor.network;
  if (n.latency_ms && !c.Range(line, path + ".network.latency_ms", *n.latency_ms, 0.0, 10000.0))
    return false;
  if (n.jitter_ms && !c.Range(line, path + ".network.jitter_ms", *n.jitter_ms, 0.0, 10000.0))
    return false;
  if (n.gateway_offset_ms &&
      !c.Range(line, path + ".network.gateway_offset_ms", *n.gateway_offset_ms, -1e6, 1e6)) {
    return false;
  }
  return true;
}

// Where a sensor stands after a move: the checks of CheckSensor's pose.
bool CheckMovedPlace(const Scenario& s, const std::string& path, int line, const std::string& id,
                     const SensorMove& move, const std::vector<NamedSegment>& segments,
                     const std::pair<Vec2, Vec2>& bounds, Checker& c) {
  const Vec2 p{move.x_m, move.y_m};
  if (!c.Finite(line, path, p)) return false;
  if (!c.Range(line, path + ".yaw_deg", move.yaw_deg, -3600.0, 3600.0)) return false;
  if (!InBounds(p, bounds)) {
    return c.Fail(line, path,
                  "sensor '" + id + "' moves to " + FmtPoint(p) + ", outside the world (" +
                      BoundsText(bounds) + ")");
  }
  for (std::size_t k = 0; k < s.world.obstacles.size(); ++k) {
    if (PointInPolygon(p, s.world.obstacles[k])) {
      return c.Fail(line, path,
                    "sensor '" + id + "' moves inside world.obstacles[" + std::to_string(k) + "]");
    }
  }
  for (const NamedSegment& seg : segments) {
    const double d = PointSegmentDistance(p, seg.segment);
    if (d < kSensorWallClearanceM) {
      return c.Fail(line, path,
                    "sensor '" + id + "' moves to " + Fmt(d) + " m from " + seg.name +
                        " (keep >= " + Fmt(kSensorWallClearanceM) + " m)");
    }
  }
  return true;
}

bool CheckSensorMoves(const Scenario& s, std::size_t i, const std::vector<NamedSegment>& segments,
                      const std::pair<Vec2, Vec2>& bounds, Checker& c) {
  const SensorSpec& sensor = s.sensors[i];
  double previous_s = 0.0;
  for (std::size_t k = 0; k < sensor.moves.size(); ++k) {
    const SensorMove& m = sensor.moves[k];
    const std::string path = "sensors[" + std::to_string(i) + "].moves[" + std::to_string(k) + "]";
    if (!(std::isfinite(m.at_s) && m.at_s > previous_s && m.at_s < s.duration_s)) {
      return c.Fail(sensor.line, path + ".at_s",
                    "must lie after " + Fmt(previous_s) +
                        " s (the pose before) and before duration_s " + Fmt(s.duration_s) +
                        ", got " + Fmt(m.at_s));
    }
    previous_s = m.at_s;
    if (!CheckMovedPlace(s, path, sensor.line, sensor.id, m, segments, bounds, c)) return false;
  }
  return true;
}

bool CheckWorldChanges(const Scenario& s, Checker& c) {
  const WorldSpec& w = s.world;
  std::set<std::size_t> removed;
  double previous_s = 0.0;
  for (std::size_t k = 0; k < w.changes.size(); ++k) {
    const WorldChange& change = w.changes[k];
    const std::string path = "world.changes[" + std::to_string(k) + "]";
    if (!(std::isfinite(change.at_s) && change.at_s >= previous_s && change.at_s > 0.0 &&
          change.at_s < s.duration_s)) {
      return c.Fail(change.line, path + ".at_s",
                    "must lie in (0, duration_s " + Fmt(s.duration_s) +
                        ") and not before the change before, got " + Fmt(change.at_s));
    }
    previous_s = change.at_s;
    if (change.remove.has_value() == !change.add.empty()) {
      return c.Fail(change.line, path, "give exactly one of remove (an obstacle index) and add");
    }
    if (change.remove) {
      if (*change.remove >= w.obstacles.size()) {
        return c.Fail(change.line, path + ".remove",
                      "no obstacle " + std::to_string(*change.remove) + " (world.obstacles has " +
                          std::to_string(w.obstacles.size()) + ")");
      }
      if (!removed.insert(*change.remove).second) {
        return c.Fail(change.line, path + ".remove",
                      "obstacle " + std::to_string(*change.remove) + " is already removed");
      }
      continue;
    }
    for (const Vec2& p : change.add) {
      if (!c.Finite(change.line, path + ".add", p)) return false;
    }
    if (auto e = CheckSimplePolygon(change.add)) return c.Fail(change.line, path + ".add", *e);
    for (const SensorSpec& sensor : s.sensors) {
      for (const SensorPoseSpan& span : PoseSpans(sensor, s.duration_s)) {
        if (PointInPolygon({span.x_m, span.y_m}, change.add)) {
          return c.Fail(change.line, path + ".add",
                        "the polygon covers sensor '" + sensor.id + "'");
        }
      }
    }
  }
  return true;
}

bool CheckPathGeometry(const Scenario& s, const TargetSpec& t, const std::string& path, int line,
                       const std::vector<NamedSegment>& segments,
                       const std::pair<Vec2, Vec2>& bounds, Checker& c) {
  const double radius = TargetRadius(t);
  for (std::size_t k = 0; k < t.path.size(); ++k) {
    const Vec2 p = t.path[k];
    if (!c.Finite(line, path + ".path", p)) return false;
    if (!InBounds(p, bounds)) {
      return c.Fail(line, path + ".path",
                    "waypoint " + std::to_string(k) + " " + FmtPoint(p) +
                        " is outside the world (" + BoundsText(bounds) + ")");
    }
    for (std::size_t o = 0; o < s.world.obstacles.size(); ++o) {
      if (PointInPolygon(p, s.world.obstacles[o])) {
        return c.Fail(line, path + ".path",
                      "waypoint " + std::to_string(k) + " " + FmtPoint(p) +
                          " is inside world.obstacles[" + std::to_string(o) + "]");
      }
    }
    for (std::size_t o = 0; o < s.world.low_obstacles.size(); ++o) {
      if (PointInPolygon(p, s.world.low_obstacles[o])) {
        return c.Fail(line, path + ".path",
                      "waypoint " + std::to_string(k) + " " + FmtPoint(p) +
                          " is inside world.low_obstacles[" + std::to_string(o) + "]");
      }
    }
  }
  const std::size_t n = t.path.size();
  const std::size_t legs = n < 2 ? 0 : (t.loop ? n : n - 1);
  for (std::size_t k = 0; k < legs; ++k) {
    const Segment leg{t.path[k], t.path[(k + 1) % n]};
    if (Norm(leg.b - leg.a) < 1e-9) {
      return c.Fail(line, path + ".path",
                    "waypoints " + std::to_string(k) + " and " + std::to_string((k + 1) % n) +
                        " are the same");
    }
    for (const NamedSegment& seg : segments) {
      if (SegmentsIntersect(leg, seg.segment)) {
        return c.Fail(line, path + ".path",
                      "leg " + FmtPoint(leg.a) + " -> " + FmtPoint(leg.b) + " crosses " + seg.name);
      }
    }
    for (const SensorSpec& sensor : s.sensors) {
      if (PointSegmentDistance({sensor.x_m, sensor.y_m}, leg) < radius) {
        return c.Fail(line, path + ".path",
                      "leg " + FmtPoint(leg.a) + " -> " + FmtPoint(leg.b) +
                          " walks through sensor '" + sensor.id + "'");
      }
    }
  }
  return true;
}

bool CheckTarget(const Scenario& s, std::size_t i, const std::vector<NamedSegment>& segments,
                 const std::pair<Vec2, Vec2>& bounds, std::set<std::string>* ids, Checker& c) {
  const TargetSpec& t = s.targets[i];
  const std::string path = "targets[" + std::to_string(i) + "]";
  const int line = t.line;
  if (!ValidId(t.id)) return c.Fail(line, path + ".id", "'" + t.id + "' is not a valid id");
  if (!ids->insert(t.id).second)
    return c.Fail(line, path + ".id", "duplicate target id '" + t.id + "'");
  const auto check_person = [&](const PersonSpec& p, const std::string& where) {
    const auto opt = [&](const std::optional<double>& v, const char* key, double lo, double hi) {
      return !v || c.Range(line, where + "." + key, *v, lo, hi);
    };
    return opt(p.a_m, "a_m", 0.01, 5.0) && opt(p.b_m, "b_m", 0.01, 5.0) &&
           opt(p.torso_exponent, "torso_exponent", 2.0, 20.0) &&
           opt(p.sway_m, "sway_m", 0.0, 0.5) && opt(p.leg_radius_m, "leg_radius_m", 0.01, 0.3) &&
           opt(p.hip_half_width_m, "hip_half_width_m", 0.0, 0.5);
  };
  switch (t.shape) {
    case TargetShape::kCylinder:
      if (!c.Positive(line, path + ".radius_m", t.radius_m, 5.0)) return false;
      break;
    case TargetShape::kPerson:
      if (!check_person(t.person, path)) return false;
      break;
    case TargetShape::kTrolley:
      if (!check_person(t.person, path) ||
          !c.Positive(line, path + ".length_m", t.length_m, 10.0) ||
          !c.Positive(line, path + ".width_m", t.width_m, 10.0)) {
        return false;
      }
      break;
    case TargetShape::kChair:
      if (!c.Range(line, path + ".size_m", t.size_m, 0.1, 2.0) ||
          !c.Range(line, path + ".yaw_deg", t.yaw_deg, -3600.0, 3600.0)) {
        return false;
      }
      break;
    case TargetShape::kDoor: {
      if (!t.door) return c.Fail(line, path, "a door needs hinge, width_m and swing");
      const DoorSpec& d = *t.door;
      if (!c.Finite(line, path + ".hinge", d.hinge)) return false;
      if (!InBounds(d.hinge, bounds)) {
        return c.Fail(line, path + ".hinge",
                      FmtPoint(d.hinge) + " is outside the world (" + BoundsText(bounds) + ")");
      }
      if (!c.Range(line, path + ".width_m", d.width_m, 0.1, 10.0) ||
          !c.Range(line, path + ".thickness_m", d.thickness_m, 0.005, 0.5)) {
        return false;
      }
      if (d.swing.empty()) return c.Fail(line, path + ".swing", "needs at least one keyframe");
      for (std::size_t k = 0; k < d.swing.size(); ++k) {
        const std::string key = path + ".swing[" + std::to_string(k) + "]";
        if (!c.Range(line, key, d.swing[k].first, 0.0, kMaxDurationS) ||
            !c.Range(line, key, d.swing[k].second, -3600.0, 3600.0)) {
          return false;
        }
        if (k > 0 && !(d.swing[k].first > d.swing[k - 1].first)) {
          return c.Fail(line, key, "keyframe times must increase");
        }
      }
      if (!t.path.empty() || t.random_walk) {
        return c.Fail(line, path, "a door swings on its hinge: no path or random_walk");
      }
      break;
    }
  }
  if (!c.Range(line, path + ".enter_s", t.enter_s, 0.0, kMaxDurationS)) return false;
  if (t.leave_s) {
    if (!c.Range(line, path + ".leave_s", *t.leave_s, 0.0, kMaxDurationS)) return false;
    if (*t.leave_s <= t.enter_s) return c.Fail(line, path + ".leave_s", "must be after enter_s");
  }
  const bool has_path = !t.path.empty();
  if (t.shape == TargetShape::kDoor) return true;
  if (has_path == t.random_walk.has_value()) {
    return c.Fail(line, path, "give either path (with speed_mps) or random_walk");
  }
  if (!has_path && (t.wait_s != 0.0 || t.stay || !t.stops.empty())) {
    return c.Fail(line, path, "wait_s, stay and stops belong to a path");
  }
  if (has_path) {
    if (!c.Range(line, path + ".wait_s", t.wait_s, 0.0, kMaxDurationS)) return false;
    for (std::size_t k = 0; k < t.stops.size(); ++k) {
      const std::string key = path + ".stops[" + std::to_string(k) + "]";
      if (t.stops[k].waypoint >= t.path.size()) {
        return c.Fail(line, key,
                      "waypoint " + std::to_string(t.stops[k].waypoint) +
                          " does not exist (the path has " + std::to_string(t.path.size()) + ")");
      }
      if (!c.Range(line, key, t.stops[k].seconds, 0.0, kMaxDurationS)) return false;
    }
    if (t.path.size() >= 2 && !c.Positive(line, path + ".speed_mps", t.speed_mps, 10.0))
      return false;
    if (t.path.size() == 1 && !c.Range(line, path + ".speed_mps", t.speed_mps, 0.0, 10.0))
      return false;
    if (t.speed_variation) {
      if (!c.Range(line, path + ".speed_variation.amplitude_mps", t.speed_variation->amplitude_mps,
                   0.0, 0.95 * t.speed_mps) ||
          !c.Positive(line, path + ".speed_variation.period_s", t.speed_variation->period_s,
                      3600.0)) {
        return false;
      }
    }
    if (!CheckPathGeometry(s, t, path, line, segments, bounds, c)) return false;
  } else {
    const RandomWalkSpec& w = *t.random_walk;
    const std::string wpath = path + ".random_walk";
    for (const Vec2& p : w.area) {
      if (!c.Finite(line, wpath + ".area", p)) return false;
      if (!InBounds(p, bounds)) {
        return c.Fail(
            line, wpath + ".area",
            "vertex " + FmtPoint(p) + " is outside the world (" + BoundsText(bounds) + ")");
      }
    }
    if (auto e = CheckSimplePolygon(w.area)) return c.Fail(line, wpath + ".area", *e);
    if (!c.Positive(line, wpath + ".speed_mps", w.speed_mps, 10.0) ||
        !c.Range(line, wpath + ".pause_s", w.pause_s, 0.0, 600.0) ||
        !c.Range(line, wpath + ".speed_spread", w.speed_spread, 0.0, 0.9)) {
      return false;
    }
  }
  return true;
}

}  // namespace

double TargetRadius(const TargetSpec& target) {
  switch (target.shape) {
    case TargetShape::kCylinder:
      return target.radius_m;
    case TargetShape::kPerson: {
      // The nominal person (0.25 x 0.15 m, 3 cm sway) where the sizes are drawn: clearances and
      // random walks do not depend on the draw.
      const PersonSpec& p = target.person;
      return std::max(p.a_m.value_or(0.25), p.b_m.value_or(0.15)) + p.sway_m.value_or(0.03);
    }
    case TargetShape::kTrolley:
      return 0.5 * std::hypot(target.length_m, target.width_m);
    case TargetShape::kChair:
      return target.size_m / std::sqrt(2.0);
    case TargetShape::kDoor:
      return target.door ? target.door->width_m : 0.9;
  }
  return 0.0;
}

const char* ToString(Mount mount) { return mount == Mount::kLegs ? "legs" : "torso"; }

const char* ToString(TargetShape shape) {
  switch (shape) {
    case TargetShape::kCylinder:
      return "cylinder";
    case TargetShape::kPerson:
      return "person";
    case TargetShape::kTrolley:
      return "trolley";
    case TargetShape::kChair:
      return "chair";
    case TargetShape::kDoor:
      return "door";
  }
  return "?";
}

std::pair<Vec2, Vec2> WorldBounds(const WorldSpec& world) {
  if (world.bounds) return *world.bounds;
  Vec2 lo{kNoHit, kNoHit}, hi{-kNoHit, -kNoHit};
  const auto grow = [&](const std::vector<Vec2>& points) {
    for (const Vec2& p : points) {
      lo = {std::min(lo.x, p.x), std::min(lo.y, p.y)};
      hi = {std::max(hi.x, p.x), std::max(hi.y, p.y)};
    }
  };
  for (const auto& w : world.walls) grow(w);
  for (const auto& o : world.obstacles) grow(o);
  for (const auto& o : world.low_obstacles) grow(o);
  if (!(lo.x <= hi.x)) return {{0, 0}, {0, 0}};
  return {lo, hi};
}

std::vector<SensorPoseSpan> PoseSpans(const SensorSpec& sensor, double duration_s) {
  std::vector<SensorPoseSpan> out;
  out.push_back({0.0, duration_s, sensor.x_m, sensor.y_m, sensor.yaw_deg});
  for (const SensorMove& m : sensor.moves) {
    out.back().to_s = m.at_s;
    out.push_back({m.at_s, duration_s, m.x_m, m.y_m, m.yaw_deg});
  }
  return out;
}

std::optional<std::string> Validate(const Scenario& s) {
  Checker c(s);
  const auto done = [&]() { return c.error; };
  if (!ValidId(s.name)) {
    c.Fail(0, "name", "'" + s.name + "' is not a valid scenario name (1-64 of A-Z a-z 0-9 _ - .)");
    return done();
  }
  if (!c.Positive(0, "duration_s", s.duration_s, kMaxDurationS)) return done();
  if (!c.Positive(0, "truth_rate_hz", s.truth_rate_hz, 1000.0)) return done();
  // Capture files keep seconds since 1970 in 32 bits; the session starts a moment before time 0.
  constexpr std::int64_t kDayNs = 86400LL * 1000000000LL;
  constexpr std::int64_t kLastPcapNs = 4294967295LL * 1000000000LL;
  if (s.start_utc_ns < kDayNs || static_cast<double>(s.start_utc_ns) + (s.duration_s + 1.0) * 1e9 >
                                     static_cast<double>(kLastPcapNs)) {
    c.Fail(0, "start_utc", "must lie between 1970-01-02 and 2106-02-07 (pcap time stamps)");
    return done();
  }
  if (s.targets.size() > kMaxTargets) {
    c.Fail(0, "targets", "at most " + std::to_string(kMaxTargets) + " targets");
    return done();
  }
  if (!CheckWorld(s.world, c)) return done();
  const auto bounds = WorldBounds(s.world);
  const std::vector<NamedSegment> segments = StaticSegments(s.world);
  std::vector<NamedSegment> walkable_limits = segments;
  for (NamedSegment& low : LowSegments(s.world)) walkable_limits.push_back(std::move(low));
  if (s.sensors.empty()) {
    c.Fail(0, "sensors", "at least one sensor is needed");
    return done();
  }
  std::set<std::string> ids;
  for (std::size_t i = 0; i < s.sensors.size(); ++i) {
    if (!CheckSensor(s, i, segments, bounds, &ids, c)) return done();
    if (!CheckSensorMoves(s, i, segments, bounds, c)) return done();
  }
  if (!CheckWorldChanges(s, c)) return done();
  std::set<std::string> target_ids;
  for (std::size_t i = 0; i < s.targets.size(); ++i) {
    if (!CheckTarget(s, i, walkable_limits, bounds, &target_ids, c)) return done();
  }
  return std::nullopt;
}

// ---- UTC text

namespace {
// Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant's days_from_civil).
std::int64_t DaysFromCivil(std::int64_t y, unsigned m, unsigned d) {
  y -= m <= 2 ? 1 : 0;
  const std::int64_t era = (y >= 0 ? y : y - 399) / 400;
  const auto yoe = static_cast<unsigned>(y - era * 400);
  const unsigned doy = (153 * (m + (m > 2 ? -3 : 9)) + 2) / 5 + d - 1;
  const unsigned doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  return era * 146097 + static_cast<std::int64_t>(doe) - 719468;
}
}  // namespace

std::optional<std::int64_t> ParseUtc(const std::string& text) {
  int y = 0, mo = 0, d = 0, h = 0, mi = 0, consumed = 0;
  double sec = 0;
  if (std::sscanf(text.c_str(), "%4d-%2d-%2dT%2d:%2d:%lf%n", &y, &mo, &d, &h, &mi, &sec,
                  &consumed) != 6) {
    return std::nullopt;
  }
  if (static_cast<std::size_t>(consumed) + 1 != text.size() || text.back() != 'Z')
    return std::nullopt;
  if (y < 1970 || y > 2200 || mo < 1 || mo > 12 || d < 1 || d > 31 || h > 23 || mi > 59 ||
      !(sec >= 0.0 && sec < 61.0)) {
    return std::nullopt;
  }
  const std::int64_t days = DaysFromCivil(y, static_cast<unsigned>(mo), static_cast<unsigned>(d));
  const std::int64_t whole = ((days * 24 + h) * 60 + mi) * 60;
  return whole * 1000000000LL + static_cast<std::int64_t>(std::llround(sec * 1e9));
}

std::string FormatUtc(std::int64_t utc_ns) {
  const std::int64_t secs = utc_ns / 1000000000LL;
  const std::int64_t frac_ns = utc_ns % 1000000000LL;
  std::int64_t days = secs / 86400;
  const std::int64_t rem = secs % 86400;
  // civil_from_days
  days += 719468;
  const std::int64_t era = (days >= 0 ? days : days - 146096) / 146097;
  const auto doe = static_cast<unsigned>(days - era * 146097);
  const unsigned yoe = (doe - doe / 1460 + doe / 36524 - doe / 146096) / 365;
  std::int64_t y = static_cast<std::int64_t>(yoe) + era * 400;
  const unsigned doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
  const unsigned mp = (5 * doy + 2) / 153;
  const unsigned d = doy - (153 * mp + 2) / 5 + 1;
  const unsigned m = mp < 10 ? mp + 3 : mp - 9;
  y += m <= 2 ? 1 : 0;
  char buf[64];
  if (frac_ns == 0) {
    std::snprintf(buf, sizeof buf, "%04lld-%02u-%02uT%02lld:%02lld:%02lldZ",
                  static_cast<long long>(y), m, d, static_cast<long long>(rem / 3600),
                  static_cast<long long>(rem / 60 % 60), static_cast<long long>(rem % 60));
  } else {
    std::snprintf(buf, sizeof buf, "%04lld-%02u-%02uT%02lld:%02lld:%02lld.%09lldZ",
                  static_cast<long long>(y), m, d, static_cast<long long>(rem / 3600),
                  static_cast<long long>(rem / 60 % 60), static_cast<long long>(rem % 60),
                  static_cast<long long>(frac_ns));
  }
  return buf;
}

}  // namespace lrfnet::sim
