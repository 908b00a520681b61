#pragma once
// A simulation scenario (DESIGN.md "Scenario"): the world (walls, obstacles), the sensors with
// their device model, pose, clock and network, and the moving targets. World frame, metres,
// degrees for yaw (counter-clockwise; a sensor's x axis is its telegram's 90° beam), seconds from
// the start of the scenario.
//
// YAML (see the shipped tools/scenarios/*.yaml for complete examples):
// - name, seed, duration_s, description (free text), start_utc ("2021-01-01T12:00:00Z": the UTC
//   of scenario time 0), truth_rate_hz (rows per second and target in truth_tracks.csv).
// - world: walls (polylines); obstacles (closed polygons, repeating the first vertex at the end is
//   optional); low_obstacles (polygons below the scan plane, such as desks: targets keep off them,
//   the sensors do not see them); bounds [[x_min, y_min], [x_max, y_max]] (default: the bounding
//   box of walls and obstacles; sensors and targets must lie inside).
// - sensors: id, model, x_m, y_m, yaw_deg, and optional range_m, fov_deg, resolution_deg,
//   rate_hz, noise_m (σ at 0 m), noise_per_m (σ growth per metre), bias_m (systematic range
//   error), clock {offset_s (tick at time 0, s since power-up), drift_ppm}, network {latency_ms
//   (minimum), jitter_ms (mean of the exponential extra delay), gateway_offset_ms (the gateway
//   clock minus UTC)}.
// - targets: id, shape (cylinder {radius_m} | person {a_m across the shoulders, b_m front to
//   back, sway_m lateral sway amplitude}), enter_s, leave_s, and either path [[x, y], ...] +
//   speed_mps + loop + speed_variation {amplitude_mps, period_s} (a path of one point: standing
//   still; a path without loop ends where the target leaves the scene), or random_walk {area
//   polygon, speed_mps, pause_s (longest pause at a goal), speed_spread (fraction by which a
//   leg's speed varies)}.
// Unknown keys are errors.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "tools/sim/device_model.h"
#include "tools/sim/geometry2d.h"

namespace lrfnet::sim {

struct ClockSpec {
  std::optional<double> offset_s;   // default: drawn from the seed, 60 ... 4000 s
  std::optional<double> drift_ppm;  // default: drawn from the seed, ±30 ppm
};

struct NetworkSpec {
  std::optional<double> latency_ms;         // default 0.3 ms (wired LAN)
  std::optional<double> jitter_ms;          // default 0.1 ms
  std::optional<double> gateway_offset_ms;  // default 0
};

struct SensorSpec {
  std::string id;
  std::string model;
  double x_m = 0;
  double y_m = 0;
  double yaw_deg = 0;
  DeviceOverrides overrides;
  std::optional<double> bias_m;
  ClockSpec clock;
  NetworkSpec network;
  int line = 0;  // in the scenario file, 1-based; 0 unknown
};

enum class TargetShape { kCylinder, kPerson };

struct SpeedVariation {
  double amplitude_mps = 0;
  double period_s = 10;
};

struct RandomWalkSpec {
  std::vector<Vec2> area;  // open polygon
  double speed_mps = 1.0;
  double pause_s = 0.0;
  double speed_spread = 0.2;
};

struct TargetSpec {
  std::string id;
  TargetShape shape = TargetShape::kPerson;
  double radius_m = 0.25;  // cylinder
  double a_m = 0.25;       // person: semi-axis across the shoulders
  double b_m = 0.15;       // person: semi-axis front to back
  double sway_m = 0.03;    // person: lateral sway amplitude while walking
  std::vector<Vec2> path;
  double speed_mps = 0;
  bool loop = false;
  std::optional<SpeedVariation> speed_variation;
  std::optional<RandomWalkSpec> random_walk;
  double enter_s = 0;
  std::optional<double> leave_s;  // default: the end of the scenario
  int line = 0;
};

struct WorldSpec {
  std::vector<std::vector<Vec2>> walls;      // polylines
  std::vector<std::vector<Vec2>> obstacles;  // open polygons
  // Furniture below the scan plane (desks, tables): targets walk around it, beams pass over it.
  std::vector<std::vector<Vec2>> low_obstacles;
  std::optional<std::pair<Vec2, Vec2>> bounds;
  std::vector<int> wall_lines;
  std::vector<int> obstacle_lines;
  std::vector<int> low_obstacle_lines;
};

struct Scenario {
  std::string source;  // file name for error messages ("" for scenarios built in code)
  std::string name;
  std::string description;
  std::uint64_t seed = 1;
  double duration_s = 60;
  std::int64_t start_utc_ns = 1609502400LL * 1000000000LL;  // 2021-01-01T12:00:00Z
  double truth_rate_hz = 50;
  WorldSpec world;
  std::vector<SensorSpec> sensors;
  std::vector<TargetSpec> targets;
};

inline constexpr std::size_t kMaxTargets = 64;

// Geometry the targets must keep clear of (radius of a target's footprint).
double TargetRadius(const TargetSpec& target);

// The rectangle sensors and targets must lie in: world.bounds, else the bounding box of walls and
// obstacles.
std::pair<Vec2, Vec2> WorldBounds(const WorldSpec& world);

// Every check of the scenario contract that does not need the YAML text: ranges of numbers,
// polygons, unique ids, known models, sensors inside the world and clear of walls, paths that do
// not cross walls. The error is one line, "<source>:<line>: <key path>: <problem>" (source and
// line when known), e.g. "office.yaml:14: sensors[2].model: unknown model 'lms999' (known: ...)".
std::optional<std::string> Validate(const Scenario& scenario);

// Reads and validates a scenario. False with *error set (one line, as Validate) when the text is
// not YAML, has unknown keys, wrong types or fails Validate. `source` names the text in messages.
bool ParseScenario(const std::string& yaml_text, const std::string& source, Scenario* out,
                   std::string* error);
bool LoadScenarioFile(const std::string& path, Scenario* out, std::string* error);

// The file a `lrfnet sim SCENARIO` argument names: SCENARIO itself when it is a file, else a
// shipped scenario of that name (SCENARIO or SCENARIO.yaml in the source tree's tools/scenarios,
// then in the installed share/lrfnet/scenarios). nullopt when none exists.
std::optional<std::string> FindScenarioFile(const std::string& argument);

// "2021-01-01T12:00:00Z" or with fractional seconds -> ns since the epoch; nullopt if malformed.
std::optional<std::int64_t> ParseUtc(const std::string& text);
std::string FormatUtc(std::int64_t utc_ns);

}  // namespace lrfnet::sim
