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
//   error), mount (torso | legs: the scan plane at upper-body height, default, or at knee height,
//   where a person shows two legs), clock {offset_s (tick at time 0, s since power-up),
//   drift_ppm}, network {latency_ms (minimum), jitter_ms (mean of the exponential extra delay),
//   gateway_offset_ms (the gateway clock minus UTC)}, moves [{at_s, x_m, y_m, yaw_deg}, ...] (the
//   sensor is bumped or remounted: from at_s on it scans from this pose; times increasing, inside
//   the run; the scan that starts at or after at_s is the first from the new pose).
// - world.changes [{at_s, remove: obstacle index} | {at_s, add: polygon}, ...]: furniture moved
//   during the run (times not decreasing, inside the run). `remove` names an index of
//   world.obstacles (each at most once); `add` puts a new obstacle polygon in the scan plane. The
//   targets' paths are checked against the initial world only: a scenario keeps added furniture
//   off the paths.
// - targets: id, shape, enter_s, leave_s, and a motion:
//   shapes: cylinder {radius_m}; person {a_m across the shoulders, b_m front to back,
//     torso_exponent (the upper body's cross-section is the superellipse |u/a|^p + |v/b|^p = 1:
//     2 an ellipse, larger boxier), sway_m (lateral sway amplitude while walking), leg_radius_m,
//     hip_half_width_m (the legs' cross-sections at knee height and their lateral offset)}: what
//     a scenario leaves out is drawn per person from the seed (a_m 0.23 ± 0.02, b_m 0.14 ± 0.015,
//     torso_exponent 2 ... 3, sway_m 0.015 ... 0.035, leg_radius_m 0.05 ... 0.07,
//     hip_half_width_m 0.08 ... 0.11), except that a person given a_m and b_m without
//     torso_exponent is the ellipse a_m, b_m (DESIGN.md); trolley {length_m, width_m: a rectangle
//     pushed ahead by a person, whose sizes are drawn as a person's; it appears in the truth as
//     "<id>.pusher"}; chair {size_m: seat width; at torso height the scan sees its backrest, at
//     knee height its four legs; yaw_deg}; door {hinge [x, y], width_m, swing [[t_s, angle_deg],
//     ...]: the leaf's world angle, linear between the keyframes and held before and after;
//     no motion keys}.
//   motion: either path [[x, y], ...] + speed_mps + loop + speed_variation {amplitude_mps,
//   period_s} (a path of one point: standing still; a path without loop ends where the target
//   leaves the scene, or, with stay: true, stays at its last point until leave_s; chairs stay by
//   default), with wait_s (stands at the first point that long after enter_s) and stops [[k, s],
//   ...] (stands s seconds at waypoint k, every lap); or random_walk {area polygon, speed_mps,
//   pause_s (longest pause at a goal), speed_spread (fraction by which a leg's speed varies)}.
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

// Height of a sensor's scan plane: what it sees of a person.
enum class Mount { kTorso, kLegs };
const char* ToString(Mount mount);

// A sensor bumped or remounted during the run: its pose from at_s on.
struct SensorMove {
  double at_s = 0;
  double x_m = 0;
  double y_m = 0;
  double yaw_deg = 0;
};

struct SensorSpec {
  std::string id;
  std::string model;
  double x_m = 0;
  double y_m = 0;
  double yaw_deg = 0;
  DeviceOverrides overrides;
  std::optional<double> bias_m;
  Mount mount = Mount::kTorso;
  ClockSpec clock;
  NetworkSpec network;
  std::vector<SensorMove> moves;  // times increasing
  int line = 0;                   // in the scenario file, 1-based; 0 unknown
};

enum class TargetShape { kCylinder, kPerson, kTrolley, kChair, kDoor };
// "cylinder", "person", "trolley", "chair", "door".
const char* ToString(TargetShape shape);

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

// A person's body; unset values are drawn per person (see the header comment).
struct PersonSpec {
  std::optional<double> a_m;               // upper body: semi-axis across the shoulders
  std::optional<double> b_m;               // upper body: semi-axis front to back
  std::optional<double> torso_exponent;    // superellipse exponent, >= 2 (2: ellipse)
  std::optional<double> sway_m;            // lateral sway amplitude while walking
  std::optional<double> leg_radius_m;      // leg cross-section at knee height
  std::optional<double> hip_half_width_m;  // lateral offset of each leg from the body centre
};

struct DoorSpec {
  Vec2 hinge;
  double width_m = 0.9;
  double thickness_m = 0.04;
  std::vector<std::pair<double, double>> swing;  // (t_s, angle_deg), times increasing
};

// A stop on a path: the target stands `seconds` at waypoint `waypoint` (every lap of a loop).
struct PathStop {
  std::size_t waypoint = 0;
  double seconds = 0;
};

struct TargetSpec {
  std::string id;
  TargetShape shape = TargetShape::kPerson;
  double radius_m = 0.25;  // cylinder
  PersonSpec person;       // person, and a trolley's pusher
  double length_m = 0.9;   // trolley: along the direction it is pushed
  double width_m = 0.6;    // trolley
  double size_m = 0.45;    // chair: seat width and depth
  double yaw_deg = 0;      // chair: the direction its seat faces
  std::optional<DoorSpec> door;
  std::vector<Vec2> path;
  double speed_mps = 0;
  bool loop = false;
  std::optional<SpeedVariation> speed_variation;
  std::optional<RandomWalkSpec> random_walk;
  double wait_s = 0;
  std::optional<bool> stay;  // default: true for chairs, false otherwise
  std::vector<PathStop> stops;
  double enter_s = 0;
  std::optional<double> leave_s;  // default: the end of the scenario
  int line = 0;
};

// Furniture moved during the run: at at_s, obstacle `remove` (an index of WorldSpec::obstacles)
// disappears, or the polygon `add` appears (exactly one of the two).
struct WorldChange {
  double at_s = 0;
  std::optional<std::size_t> remove;
  std::vector<Vec2> add;  // open polygon; empty when `remove` is set
  int line = 0;
};

struct WorldSpec {
  std::vector<std::vector<Vec2>> walls;      // polylines
  std::vector<std::vector<Vec2>> obstacles;  // open polygons
  // Furniture below the scan plane (desks, tables): targets walk around it, beams pass over it.
  std::vector<std::vector<Vec2>> low_obstacles;
  std::optional<std::pair<Vec2, Vec2>> bounds;
  std::vector<WorldChange> changes;  // times not decreasing
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

// A sensor's pose over the run: one entry per pose, from_s = 0 for the scenario's pose, then one
// per move; to_s is the next entry's from_s, or duration_s for the last.
struct SensorPoseSpan {
  double from_s = 0;
  double to_s = 0;
  double x_m = 0;
  double y_m = 0;
  double yaw_deg = 0;
};
std::vector<SensorPoseSpan> PoseSpans(const SensorSpec& sensor, double duration_s);

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
