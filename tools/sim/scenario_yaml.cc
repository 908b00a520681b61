// Scenario YAML -> Scenario (the adapter between yaml-cpp and the pure checks in scenario.cc).
//
// yaml-cpp reports malformed YAML by throwing; this file is the one place that catches it and turns
// it into the one-line error the rest of the program expects.

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <set>
#include <sstream>
#include <vector>

#include "common/one_line.h"
#include "tools/sim/scenario.h"

namespace lrfnet::sim {

namespace {

class Parser {
 public:
  explicit Parser(std::string source) : source_(std::move(source)) {}

  std::optional<std::string> error;

  bool Fail(const YAML::Node& near, const std::string& path, const std::string& message) {
    if (error) return false;
    std::string where = source_;
    const int line = LineOf(near);
    if (line > 0) where += (where.empty() ? "line " : ":") + std::to_string(line);
    // Keys and values come from the file: one line, a hostile one cut short.
    error = (where.empty() ? "" : where + ": ") + common::OneLine(path, 120) + ": " +
            common::OneLine(message, 600);
    return false;
  }

  static int LineOf(const YAML::Node& node) {
    if (!node.IsDefined()) return 0;
    const YAML::Mark m = node.Mark();
    return m.is_null() ? 0 : m.line + 1;
  }

  // A map whose keys are all in `known` (each at most once).
  bool Map(const YAML::Node& node, const std::string& path,
           std::initializer_list<const char*> known) {
    if (!node.IsMap()) return Fail(node, path, "expected a map of keys");
    std::set<std::string> seen;
    for (auto it = node.begin(); it != node.end(); ++it) {
      if (!it->first.IsScalar()) return Fail(it->first, path, "keys must be plain names");
      const std::string key = it->first.Scalar();
      bool ok = false;
      for (const char* k : known) ok = ok || key == k;
      if (!ok) {
        std::string list;
        for (const char* k : known) list += std::string(list.empty() ? "" : ", ") + k;
        return Fail(it->first, Join(path, key), "unknown key (known: " + list + ")");
      }
      if (!seen.insert(key).second) return Fail(it->first, Join(path, key), "key given twice");
    }
    return true;
  }

  static std::string Join(const std::string& path, const std::string& key) {
    return path.empty() ? key : path + "." + key;
  }

  bool Has(const YAML::Node& map, const char* key) {
    return map[key].IsDefined() && !map[key].IsNull();
  }

  bool Require(const YAML::Node& map, const std::string& path, const char* key) {
    if (Has(map, key)) return true;
    return Fail(map, path.empty() ? std::string(key) : path,
                "missing key '" + std::string(key) + "'");
  }

  bool ParseNumber(const YAML::Node& node, const std::string& path, double* out) {
    if (!node.IsScalar()) return Fail(node, path, "expected a number");
    const std::string& text = node.Scalar();
    errno = 0;
    char* end = nullptr;
    const double v = std::strtod(text.c_str(), &end);
    if (text.empty() || end != text.c_str() + text.size() || errno == ERANGE || !std::isfinite(v)) {
      return Fail(node, path, "expected a finite number, got '" + text + "'");
    }
    *out = v;
    return true;
  }

  bool Number(const YAML::Node& map, const std::string& path, const char* key, double* out) {
    if (!Require(map, path, key)) return false;
    return ParseNumber(map[key], Join(path, key), out);
  }
  bool OptNumber(const YAML::Node& map, const std::string& path, const char* key, double* out) {
    if (!Has(map, key)) return true;
    return ParseNumber(map[key], Join(path, key), out);
  }
  bool OptNumber(const YAML::Node& map, const std::string& path, const char* key,
                 std::optional<double>* out) {
    if (!Has(map, key)) return true;
    double v = 0;
    if (!ParseNumber(map[key], Join(path, key), &v)) return false;
    *out = v;
    return true;
  }

  bool String(const YAML::Node& map, const std::string& path, const char* key, std::string* out,
              bool required) {
    if (!Has(map, key)) return required ? Require(map, path, key) : true;
    const YAML::Node node = map[key];
    if (!node.IsScalar()) return Fail(node, Join(path, key), "expected a string");
    *out = node.Scalar();
    return true;
  }

  bool Bool(const YAML::Node& map, const std::string& path, const char* key, bool* out) {
    if (!Has(map, key)) return true;
    const YAML::Node node = map[key];
    const std::string text = node.IsScalar() ? node.Scalar() : "";
    if (text == "true" || text == "True" || text == "TRUE") {
      *out = true;
    } else if (text == "false" || text == "False" || text == "FALSE") {
      *out = false;
    } else {
      return Fail(node, Join(path, key), "expected true or false");
    }
    return true;
  }

  bool Seed(const YAML::Node& map, std::uint64_t* out) {
    if (!Require(map, "", "seed")) return false;
    const YAML::Node node = map["seed"];
    const std::string text = node.IsScalar() ? node.Scalar() : "";
    errno = 0;
    char* end = nullptr;
    const unsigned long long v = std::strtoull(text.c_str(), &end, 10);
    if (text.empty() || text[0] == '-' || end != text.c_str() + text.size() || errno == ERANGE) {
      return Fail(node, "seed", "expected an unsigned integer, got '" + text + "'");
    }
    *out = v;
    return true;
  }

  bool Point(const YAML::Node& node, const std::string& path, Vec2* out) {
    if (!node.IsSequence() || node.size() != 2) return Fail(node, path, "expected a point [x, y]");
    return ParseNumber(node[0], path, &out->x) && ParseNumber(node[1], path, &out->y);
  }

  bool Points(const YAML::Node& node, const std::string& path, std::vector<Vec2>* out) {
    if (!node.IsSequence()) return Fail(node, path, "expected a list of points [[x, y], ...]");
    out->clear();
    for (std::size_t i = 0; i < node.size(); ++i) {
      Vec2 p;
      if (!Point(node[i], path + "[" + std::to_string(i) + "]", &p)) return false;
      out->push_back(p);
    }
    return true;
  }

  // A closed polygon; a repeated first vertex at the end is dropped.
  bool Polygon(const YAML::Node& node, const std::string& path, std::vector<Vec2>* out) {
    if (!Points(node, path, out)) return false;
    if (out->size() >= 2 && Norm(out->front() - out->back()) < 1e-12) out->pop_back();
    return true;
  }

  bool World(const YAML::Node& node, WorldSpec* w) {
    if (!Map(node, "world", {"walls", "obstacles", "low_obstacles", "bounds", "changes"}))
      return false;
    if (Has(node, "walls")) {
      const YAML::Node walls = node["walls"];
      if (!walls.IsSequence()) return Fail(walls, "world.walls", "expected a list of polylines");
      for (std::size_t i = 0; i < walls.size(); ++i) {
        std::vector<Vec2> wall;
        if (!Points(walls[i], "world.walls[" + std::to_string(i) + "]", &wall)) return false;
        w->walls.push_back(std::move(wall));
        w->wall_lines.push_back(LineOf(walls[i]));
      }
    }
    if (Has(node, "obstacles")) {
      const YAML::Node obstacles = node["obstacles"];
      if (!obstacles.IsSequence())
        return Fail(obstacles, "world.obstacles", "expected a list of polygons");
      for (std::size_t i = 0; i < obstacles.size(); ++i) {
        std::vector<Vec2> polygon;
        if (!Polygon(obstacles[i], "world.obstacles[" + std::to_string(i) + "]", &polygon))
          return false;
        w->obstacles.push_back(std::move(polygon));
        w->obstacle_lines.push_back(LineOf(obstacles[i]));
      }
    }
    if (Has(node, "low_obstacles")) {
      const YAML::Node low = node["low_obstacles"];
      if (!low.IsSequence()) return Fail(low, "world.low_obstacles", "expected a list of polygons");
      for (std::size_t i = 0; i < low.size(); ++i) {
        std::vector<Vec2> polygon;
        if (!Polygon(low[i], "world.low_obstacles[" + std::to_string(i) + "]", &polygon))
          return false;
        w->low_obstacles.push_back(std::move(polygon));
        w->low_obstacle_lines.push_back(LineOf(low[i]));
      }
    }
    if (Has(node, "bounds")) {
      std::vector<Vec2> corners;
      if (!Points(node["bounds"], "world.bounds", &corners)) return false;
      if (corners.size() != 2) {
        return Fail(node["bounds"], "world.bounds", "expected [[x_min, y_min], [x_max, y_max]]");
      }
      w->bounds = std::make_pair(corners[0], corners[1]);
    }
    return Has(node, "changes") ? WorldChanges(node["changes"], w) : true;
  }

  // world.changes: [{at_s, remove: index} | {at_s, add: polygon}, ...]
  bool WorldChanges(const YAML::Node& node, WorldSpec* w) {
    if (!node.IsSequence()) return Fail(node, "world.changes", "expected a list of changes");
    for (std::size_t i = 0; i < node.size(); ++i) {
      const std::string path = "world.changes[" + std::to_string(i) + "]";
      const YAML::Node c = node[i];
      WorldChange change;
      change.line = LineOf(c);
      if (!Map(c, path, {"at_s", "remove", "add"}) || !Number(c, path, "at_s", &change.at_s))
        return false;
      if (Has(c, "remove")) {
        double index = 0;
        if (!ParseNumber(c["remove"], path + ".remove", &index)) return false;
        if (index < 0 || index > 1e6 || index != std::floor(index))
          return Fail(c["remove"], path + ".remove", "expected an obstacle index (0, 1, ...)");
        change.remove = static_cast<std::size_t>(index);
      }
      if (Has(c, "add") && !Polygon(c["add"], path + ".add", &change.add)) return false;
      if (Has(c, "add") && change.add.empty())
        return Fail(c["add"], path + ".add", "expected a polygon");
      w->changes.push_back(std::move(change));
    }
    return true;
  }

  // sensors[i].moves: [{at_s, x_m, y_m, yaw_deg}, ...]
  bool SensorMoves(const YAML::Node& node, const std::string& path, SensorSpec* s) {
    if (!node.IsSequence()) return Fail(node, path, "expected a list of moves");
    for (std::size_t i = 0; i < node.size(); ++i) {
      const std::string mpath = path + "[" + std::to_string(i) + "]";
      SensorMove m;
      if (!Map(node[i], mpath, {"at_s", "x_m", "y_m", "yaw_deg"}) ||
          !Number(node[i], mpath, "at_s", &m.at_s) || !Number(node[i], mpath, "x_m", &m.x_m) ||
          !Number(node[i], mpath, "y_m", &m.y_m) || !Number(node[i], mpath, "yaw_deg", &m.yaw_deg))
        return false;
      s->moves.push_back(m);
    }
    return true;
  }

  bool Sensor(const YAML::Node& node, const std::string& path, SensorSpec* s) {
    if (!Map(node, path,
             {"id", "model", "x_m", "y_m", "yaw_deg", "range_m", "fov_deg", "resolution_deg",
              "rate_hz", "noise_m", "noise_per_m", "bias_m", "mount", "clock", "network",
              "moves"})) {
      return false;
    }
    s->line = LineOf(node);
    if (!String(node, path, "id", &s->id, true) || !String(node, path, "model", &s->model, true) ||
        !Number(node, path, "x_m", &s->x_m) || !Number(node, path, "y_m", &s->y_m) ||
        !Number(node, path, "yaw_deg", &s->yaw_deg) ||
        !OptNumber(node, path, "range_m", &s->overrides.range_m) ||
        !OptNumber(node, path, "fov_deg", &s->overrides.fov_deg) ||
        !OptNumber(node, path, "resolution_deg", &s->overrides.resolution_deg) ||
        !OptNumber(node, path, "rate_hz", &s->overrides.rate_hz) ||
        !OptNumber(node, path, "noise_m", &s->overrides.noise_m) ||
        !OptNumber(node, path, "noise_per_m", &s->overrides.noise_per_m) ||
        !OptNumber(node, path, "bias_m", &s->bias_m)) {
      return false;
    }
    if (Has(node, "mount")) {
      std::string mount;
      if (!String(node, path, "mount", &mount, true)) return false;
      if (mount == "torso") {
        s->mount = Mount::kTorso;
      } else if (mount == "legs") {
        s->mount = Mount::kLegs;
      } else {
        return Fail(node["mount"], path + ".mount",
                    "unknown mount '" + mount + "' (known: torso, legs)");
      }
    }
    if (Has(node, "moves") && !SensorMoves(node["moves"], path + ".moves", s)) return false;
    if (Has(node, "clock")) {
      const YAML::Node clock = node["clock"];
      const std::string cpath = path + ".clock";
      if (!Map(clock, cpath, {"offset_s", "drift_ppm"}) ||
          !OptNumber(clock, cpath, "offset_s", &s->clock.offset_s) ||
          !OptNumber(clock, cpath, "drift_ppm", &s->clock.drift_ppm)) {
        return false;
      }
    }
    if (Has(node, "network")) {
      const YAML::Node net = node["network"];
      const std::string npath = path + ".network";
      if (!Map(net, npath, {"latency_ms", "jitter_ms", "gateway_offset_ms"}) ||
          !OptNumber(net, npath, "latency_ms", &s->network.latency_ms) ||
          !OptNumber(net, npath, "jitter_ms", &s->network.jitter_ms) ||
          !OptNumber(net, npath, "gateway_offset_ms", &s->network.gateway_offset_ms)) {
        return false;
      }
    }
    return true;
  }

  bool Target(const YAML::Node& node, const std::string& path, std::size_t index, TargetSpec* t) {
    // clang-format off
    if (!Map(node, path,
             {"id", "shape", "radius_m", "a_m", "b_m", "torso_exponent", "sway_m", "leg_radius_m",
              "hip_half_width_m", "length_m", "width_m", "size_m", "yaw_deg", "hinge",
              "thickness_m", "swing", "path", "speed_mps", "loop", "speed_variation", "random_walk",
              "wait_s", "stay", "stops", "enter_s", "leave_s"})) {
      // clang-format on
      return false;
    }
    t->line = LineOf(node);
    t->id = "target" + std::to_string(index + 1);
    std::string shape;
    if (!String(node, path, "id", &t->id, false) || !String(node, path, "shape", &shape, true))
      return false;
    // The keys each shape takes (besides id, shape, the motion and enter_s / leave_s).
    const std::vector<const char*> person_keys = {"a_m",    "b_m",          "torso_exponent",
                                                  "sway_m", "leg_radius_m", "hip_half_width_m"};
    std::vector<const char*> allowed;
    if (shape == "cylinder") {
      t->shape = TargetShape::kCylinder;
      allowed = {"radius_m"};
    } else if (shape == "person") {
      t->shape = TargetShape::kPerson;
      allowed = person_keys;
    } else if (shape == "trolley") {
      t->shape = TargetShape::kTrolley;
      allowed = person_keys;
      allowed.push_back("length_m");
      allowed.push_back("width_m");
    } else if (shape == "chair") {
      t->shape = TargetShape::kChair;
      allowed = {"size_m", "yaw_deg"};
    } else if (shape == "door") {
      t->shape = TargetShape::kDoor;
      allowed = {"hinge", "width_m", "thickness_m", "swing"};
    } else {
      return Fail(node["shape"], path + ".shape",
                  "unknown shape '" + shape + "' (known: cylinder, person, trolley, chair, door)");
    }
    for (const char* key :
         {"radius_m", "a_m", "b_m", "torso_exponent", "sway_m", "leg_radius_m", "hip_half_width_m",
          "length_m", "width_m", "size_m", "yaw_deg", "hinge", "thickness_m", "swing"}) {
      if (!Has(node, key)) continue;
      if (std::find_if(allowed.begin(), allowed.end(),
                       [&](const char* k) { return std::string(k) == key; }) == allowed.end()) {
        return Fail(node[key], Join(path, key), "not a key of shape " + shape);
      }
    }
    PersonSpec& p = t->person;
    if (!OptNumber(node, path, "a_m", &p.a_m) || !OptNumber(node, path, "b_m", &p.b_m) ||
        !OptNumber(node, path, "torso_exponent", &p.torso_exponent) ||
        !OptNumber(node, path, "sway_m", &p.sway_m) ||
        !OptNumber(node, path, "leg_radius_m", &p.leg_radius_m) ||
        !OptNumber(node, path, "hip_half_width_m", &p.hip_half_width_m) ||
        !OptNumber(node, path, "length_m", &t->length_m) ||
        !OptNumber(node, path, "size_m", &t->size_m) ||
        !OptNumber(node, path, "yaw_deg", &t->yaw_deg)) {
      return false;
    }
    if (t->shape == TargetShape::kCylinder && !Number(node, path, "radius_m", &t->radius_m)) {
      return false;
    }
    if (t->shape == TargetShape::kDoor) {
      DoorSpec door;
      if (!Require(node, path, "hinge") || !Point(node["hinge"], path + ".hinge", &door.hinge) ||
          !OptNumber(node, path, "width_m", &door.width_m) ||
          !OptNumber(node, path, "thickness_m", &door.thickness_m) ||
          !Require(node, path, "swing")) {
        return false;
      }
      std::vector<Vec2> keys;
      if (!Points(node["swing"], path + ".swing", &keys)) return false;
      for (const Vec2& k : keys) door.swing.emplace_back(k.x, k.y);
      t->door = std::move(door);
    } else if (!OptNumber(node, path, "width_m", &t->width_m)) {
      return false;
    }
    if (!OptNumber(node, path, "wait_s", &t->wait_s)) return false;
    if (Has(node, "stay")) {
      bool stay = false;
      if (!Bool(node, path, "stay", &stay)) return false;
      t->stay = stay;
    }
    if (Has(node, "stops")) {
      std::vector<Vec2> stops;
      if (!Points(node["stops"], path + ".stops", &stops)) return false;
      for (std::size_t k = 0; k < stops.size(); ++k) {
        const double w = stops[k].x;
        if (!(w >= 0.0 && w < 1e6) || w != std::floor(w)) {
          return Fail(node["stops"], path + ".stops[" + std::to_string(k) + "]",
                      "expected [waypoint index, seconds]");
        }
        t->stops.push_back({static_cast<std::size_t>(w), stops[k].y});
      }
    }
    if (!OptNumber(node, path, "enter_s", &t->enter_s) ||
        !OptNumber(node, path, "leave_s", &t->leave_s)) {
      return false;
    }
    if (Has(node, "path")) {
      if (!Points(node["path"], path + ".path", &t->path)) return false;
      if (t->path.empty()) return Fail(node["path"], path + ".path", "needs at least one waypoint");
      if (t->path.size() >= 2 && !Require(node, path, "speed_mps")) return false;
      if (!OptNumber(node, path, "speed_mps", &t->speed_mps) ||
          !Bool(node, path, "loop", &t->loop)) {
        return false;
      }
      if (Has(node, "speed_variation")) {
        const YAML::Node v = node["speed_variation"];
        const std::string vpath = path + ".speed_variation";
        SpeedVariation sv;
        if (!Map(v, vpath, {"amplitude_mps", "period_s"}) ||
            !Number(v, vpath, "amplitude_mps", &sv.amplitude_mps) ||
            !Number(v, vpath, "period_s", &sv.period_s)) {
          return false;
        }
        t->speed_variation = sv;
      }
    } else {
      for (const char* key : {"speed_mps", "loop", "speed_variation"}) {
        if (Has(node, key)) {
          return Fail(node[key], Join(path, key),
                      Has(node, "random_walk")
                          ? "belongs to a path (random_walk has its own speed_mps)"
                          : "needs a path");
        }
      }
    }
    if (Has(node, "random_walk")) {
      const YAML::Node w = node["random_walk"];
      const std::string wpath = path + ".random_walk";
      RandomWalkSpec spec;
      if (!Map(w, wpath, {"area", "speed_mps", "pause_s", "speed_spread"})) return false;
      if (!Require(w, wpath, "area") || !Polygon(w["area"], wpath + ".area", &spec.area) ||
          !Number(w, wpath, "speed_mps", &spec.speed_mps) ||
          !OptNumber(w, wpath, "pause_s", &spec.pause_s) ||
          !OptNumber(w, wpath, "speed_spread", &spec.speed_spread)) {
        return false;
      }
      t->random_walk = std::move(spec);
    }
    return true;
  }

  bool Root(const YAML::Node& root, Scenario* s) {
    if (!root.IsDefined() || root.IsNull()) return Fail(root, "scenario", "the file is empty");
    if (!Map(root, "",
             {"name", "seed", "duration_s", "description", "start_utc", "truth_rate_hz", "world",
              "sensors", "targets"})) {
      return false;
    }
    if (!String(root, "", "name", &s->name, true) || !Seed(root, &s->seed) ||
        !Number(root, "", "duration_s", &s->duration_s) ||
        !String(root, "", "description", &s->description, false) ||
        !OptNumber(root, "", "truth_rate_hz", &s->truth_rate_hz)) {
      return false;
    }
    if (Has(root, "start_utc")) {
      std::string text;
      if (!String(root, "", "start_utc", &text, true)) return false;
      const auto ns = ParseUtc(text);
      if (!ns)
        return Fail(root["start_utc"], "start_utc",
                    "expected UTC like 2021-01-01T12:00:00Z, got '" + text + "'");
      s->start_utc_ns = *ns;
    }
    if (!Require(root, "", "world") || !World(root["world"], &s->world)) return false;
    if (!Require(root, "", "sensors")) return false;
    const YAML::Node sensors = root["sensors"];
    if (!sensors.IsSequence()) return Fail(sensors, "sensors", "expected a list of sensors");
    for (std::size_t i = 0; i < sensors.size(); ++i) {
      SensorSpec sensor;
      if (!Sensor(sensors[i], "sensors[" + std::to_string(i) + "]", &sensor)) return false;
      s->sensors.push_back(std::move(sensor));
    }
    if (Has(root, "targets")) {
      const YAML::Node targets = root["targets"];
      if (!targets.IsSequence()) return Fail(targets, "targets", "expected a list of targets");
      for (std::size_t i = 0; i < targets.size(); ++i) {
        TargetSpec target;
        if (!Target(targets[i], "targets[" + std::to_string(i) + "]", i, &target)) return false;
        s->targets.push_back(std::move(target));
      }
    }
    return true;
  }

 private:
  std::string source_;
};

}  // namespace

bool ParseScenario(const std::string& yaml_text, const std::string& source, Scenario* out,
                   std::string* error) {
  Scenario s;
  s.source = source;
  Parser parser(source);
  try {
    const YAML::Node root = YAML::Load(yaml_text);
    parser.Root(root, &s);
  } catch (const YAML::Exception& e) {
    // Syntax errors (ParserException) and anything yaml-cpp rejects while walking the tree.
    std::string where = source;
    if (!e.mark.is_null())
      where += (where.empty() ? "line " : ":") + std::to_string(e.mark.line + 1);
    *error = (where.empty() ? "" : where + ": ") + "not valid YAML: " + common::OneLine(e.msg);
    return false;
  }
  if (parser.error) {
    *error = *parser.error;
    return false;
  }
  if (auto e = Validate(s)) {
    *error = *e;
    return false;
  }
  *out = std::move(s);
  return true;
}

bool LoadScenarioFile(const std::string& path, Scenario* out, std::string* error) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    *error = path + ": cannot open the scenario file";
    return false;
  }
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) {
    *error = path + ": read error";
    return false;
  }
  return ParseScenario(text.str(), path, out, error);
}

std::optional<std::string> FindScenarioFile(const std::string& argument) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::is_regular_file(argument, ec)) return argument;
  if (argument.empty() || argument.find('/') != std::string::npos) return std::nullopt;
  // An installed lrfnet (a package, or any prefix) finds its scenarios beside it in
  // ../share/lrfnet/scenarios; a built one in the source tree; then the configured install prefix.
  std::vector<std::string> dirs;
  const fs::path executable = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    dirs.push_back((executable.parent_path().parent_path() / "share/lrfnet/scenarios").string());
  }
  // Build-time locations (compile definitions of this library), not paths written in the sources.
#ifdef LRFNET_SCENARIO_SOURCE_DIR
  dirs.push_back(LRFNET_SCENARIO_SOURCE_DIR);
#endif
#ifdef LRFNET_SCENARIO_INSTALL_DIR
  dirs.push_back(LRFNET_SCENARIO_INSTALL_DIR);
#endif
  for (const std::string& dir : dirs) {
    for (const std::string& name : {argument, argument + ".yaml"}) {
      const fs::path candidate = fs::path(dir) / name;
      if (fs::is_regular_file(candidate, ec)) return candidate.string();
    }
  }
  return std::nullopt;
}

}  // namespace lrfnet::sim
