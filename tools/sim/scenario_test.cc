#include "tools/sim/scenario.h"

#include <gtest/gtest.h>

#include <string>

namespace lrfnet::sim {
namespace {

// The example of DESIGN.md's scenario contract.
const char* const kDesignExample = R"(name: two_rooms
seed: 7
duration_s: 60
world:
  walls: [[[0, 0], [20, 0], [20, 10], [0, 10], [0, 0]], [[10, 0], [10, 4]]]
  obstacles: [[[4, 4], [6, 4], [6, 6], [4, 6]]]
sensors:
  - {id: s1, model: lms111, x_m: 0.5, y_m: 0.5, yaw_deg: 45}
  - {id: s2, model: tim561, x_m: 19.5, y_m: 9.5, yaw_deg: -135, clock: {offset_s: 812.3, drift_ppm: 15}}
targets:
  - {shape: person, a_m: 0.25, b_m: 0.15, path: [[2, 2], [18, 8], [2, 8]], speed_mps: 1.2, loop: true}
  - {shape: cylinder, radius_m: 0.25, random_walk: {area: [[1, 1], [19, 1], [19, 9], [1, 9]], speed_mps: 0.8}}
)";

std::string Replace(std::string text, const std::string& from, const std::string& to) {
  const std::size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << "test bug: '" << from << "' not in the scenario";
  if (at != std::string::npos) text.replace(at, from.size(), to);
  return text;
}

// Parses `text` expecting failure; returns the error (one line).
std::string ErrorOf(const std::string& text) {
  Scenario s;
  std::string error;
  EXPECT_FALSE(ParseScenario(text, "bad.yaml", &s, &error)) << "accepted:\n" << text;
  EXPECT_EQ(error.find('\n'), std::string::npos) << "not one line: " << error;
  EXPECT_EQ(error.rfind("bad.yaml", 0), 0u) << "does not name the file: " << error;
  return error;
}

TEST(Scenario, TheDesignExampleParsesWithItsValues) {
  Scenario s;
  std::string error;
  ASSERT_TRUE(ParseScenario(kDesignExample, "example.yaml", &s, &error)) << error;
  EXPECT_EQ(s.name, "two_rooms");
  EXPECT_EQ(s.seed, 7u);
  EXPECT_EQ(s.duration_s, 60.0);
  ASSERT_EQ(s.world.walls.size(), 2u);
  EXPECT_EQ(s.world.walls[0].size(), 5u);  // a polyline keeps its closing point
  ASSERT_EQ(s.world.obstacles.size(), 1u);
  EXPECT_EQ(s.world.obstacles[0].size(), 4u);
  ASSERT_EQ(s.sensors.size(), 2u);
  EXPECT_EQ(s.sensors[1].id, "s2");
  EXPECT_EQ(s.sensors[1].model, "tim561");
  EXPECT_EQ(s.sensors[1].yaw_deg, -135.0);
  EXPECT_EQ(s.sensors[1].clock.offset_s, 812.3);
  EXPECT_EQ(s.sensors[1].clock.drift_ppm, 15.0);
  EXPECT_FALSE(s.sensors[0].clock.offset_s.has_value());
  ASSERT_EQ(s.targets.size(), 2u);
  EXPECT_EQ(s.targets[0].shape, TargetShape::kPerson);
  EXPECT_TRUE(s.targets[0].loop);
  EXPECT_EQ(s.targets[0].path.size(), 3u);
  EXPECT_EQ(s.targets[1].shape, TargetShape::kCylinder);
  ASSERT_TRUE(s.targets[1].random_walk.has_value());
  EXPECT_EQ(s.targets[1].random_walk->speed_mps, 0.8);
  EXPECT_EQ(s.targets[0].id, "target1");
}

TEST(Scenario, ClosedObstacleWithRepeatedFirstVertexIsTheSamePolygon) {
  Scenario s;
  std::string error;
  ASSERT_TRUE(ParseScenario(Replace(kDesignExample, "[[[4, 4], [6, 4], [6, 6], [4, 6]]]",
                                    "[[[4, 4], [6, 4], [6, 6], [4, 6], [4, 4]]]"),
                            "x.yaml", &s, &error))
      << error;
  EXPECT_EQ(s.world.obstacles[0].size(), 4u);
}

TEST(ScenarioErrors, UnknownKeysNameTheirPathAndTheKnownKeys) {
  std::string e = ErrorOf(Replace(kDesignExample, "seed: 7", "seed: 7\nsed: 8"));
  EXPECT_NE(e.find("sed: unknown key"), std::string::npos) << e;
  EXPECT_NE(e.find("duration_s"), std::string::npos) << e;  // lists the known keys

  e = ErrorOf(Replace(kDesignExample, "drift_ppm: 15", "drift_pmm: 15"));
  EXPECT_NE(e.find("sensors[1].clock.drift_pmm: unknown key (known: offset_s, drift_ppm)"),
            std::string::npos)
      << e;
  EXPECT_NE(e.find("bad.yaml:9:"), std::string::npos) << "line of the key: " << e;

  e = ErrorOf(Replace(kDesignExample, "speed_mps: 0.8}", "speed_mps: 0.8, sped: 1}"));
  EXPECT_NE(e.find("targets[1].random_walk.sped: unknown key"), std::string::npos) << e;
}

TEST(ScenarioErrors, MalformedPolygons) {
  std::string e = ErrorOf(Replace(kDesignExample, "[[[4, 4], [6, 4], [6, 6], [4, 6]]]",
                                  "[[[4, 4], [6, 6], [6, 4], [4, 6]]]"));
  EXPECT_NE(e.find("world.obstacles[0]: edges"), std::string::npos) << e;
  EXPECT_NE(e.find("cross"), std::string::npos) << e;

  e = ErrorOf(Replace(kDesignExample, "[[[4, 4], [6, 4], [6, 6], [4, 6]]]", "[[[4, 4], [6, 4]]]"));
  EXPECT_NE(e.find("world.obstacles[0]: a polygon needs at least 3 vertices"), std::string::npos)
      << e;

  e = ErrorOf(Replace(kDesignExample, "[[10, 0], [10, 4]]", "[[10, 0], [10, 0]]"));
  EXPECT_NE(e.find("world.walls[1]: points 0 and 1 are the same"), std::string::npos) << e;

  e = ErrorOf(Replace(kDesignExample, "[[10, 0], [10, 4]]", "[[10, 0], [10]]"));
  EXPECT_NE(e.find("world.walls[1][1]: expected a point [x, y]"), std::string::npos) << e;

  e = ErrorOf(Replace(kDesignExample, "area: [[1, 1], [19, 1], [19, 9], [1, 9]]",
                      "area: [[1, 1], [19, 9], [19, 1], [1, 9]]"));
  EXPECT_NE(e.find("targets[1].random_walk.area: edges"), std::string::npos) << e;
}

TEST(ScenarioErrors, SensorsOutsideTheWorldOrInsideObstacles) {
  std::string e = ErrorOf(Replace(kDesignExample, "x_m: 19.5, y_m: 9.5", "x_m: 25, y_m: 9.5"));
  EXPECT_NE(
      e.find("sensors[1]: sensor 's2' at [25, 9.5] is outside the world ([0, 0] .. [20, 10])"),
      std::string::npos)
      << e;
  e = ErrorOf(Replace(kDesignExample, "x_m: 19.5, y_m: 9.5", "x_m: 5, y_m: 5"));
  EXPECT_NE(e.find("sensors[1]: sensor 's2' stands inside world.obstacles[0]"), std::string::npos)
      << e;
  e = ErrorOf(Replace(kDesignExample, "x_m: 19.5, y_m: 9.5", "x_m: 10.01, y_m: 2"));
  EXPECT_NE(e.find("from world.walls[1]"), std::string::npos) << e;
}

TEST(ScenarioErrors, UnknownModelListsTheKnownOnes) {
  const std::string e = ErrorOf(Replace(kDesignExample, "model: tim561", "model: lms999"));
  EXPECT_NE(e.find("sensors[1].model: unknown model 'lms999' (known: lms111, lms151, lms511, "
                   "tim561, tim781)"),
            std::string::npos)
      << e;
}

TEST(ScenarioErrors, BadNumbers) {
  std::string e = ErrorOf(Replace(kDesignExample, "duration_s: 60", "duration_s: -5"));
  EXPECT_NE(e.find("duration_s: must be in (0,"), std::string::npos) << e;
  e = ErrorOf(Replace(kDesignExample, "duration_s: 60", "duration_s: sixty"));
  EXPECT_NE(e.find("duration_s: expected a finite number, got 'sixty'"), std::string::npos) << e;
  e = ErrorOf(Replace(kDesignExample, "duration_s: 60", "duration_s: .nan"));
  EXPECT_NE(e.find("duration_s: expected a finite number"), std::string::npos) << e;
  e = ErrorOf(Replace(kDesignExample, "seed: 7", "seed: -7"));
  EXPECT_NE(e.find("seed: expected an unsigned integer"), std::string::npos) << e;
  e = ErrorOf(Replace(kDesignExample, "drift_ppm: 15", "drift_ppm: 5000"));
  EXPECT_NE(e.find("sensors[1].clock.drift_ppm: must be in [-1000, 1000], got 5000"),
            std::string::npos)
      << e;
  e = ErrorOf(Replace(kDesignExample, "yaw_deg: 45}", "yaw_deg: 45, resolution_deg: 0.7}"));
  EXPECT_NE(e.find("sensors[0].resolution_deg: the field of view"), std::string::npos) << e;
  e = ErrorOf(Replace(kDesignExample, "yaw_deg: 45}", "yaw_deg: 45, range_m: 0}"));
  EXPECT_NE(e.find("sensors[0].range_m: must be in"), std::string::npos) << e;
  e = ErrorOf(Replace(kDesignExample, "speed_mps: 1.2", "speed_mps: 0"));
  EXPECT_NE(e.find("targets[0].speed_mps: must be in (0, 10]"), std::string::npos) << e;
  e = ErrorOf(Replace(kDesignExample, "loop: true}", "loop: maybe}"));
  EXPECT_NE(e.find("targets[0].loop: expected true or false"), std::string::npos) << e;
}

TEST(ScenarioErrors, TargetsAndIds) {
  std::string e = ErrorOf(Replace(kDesignExample, "id: s2", "id: s1"));
  EXPECT_NE(e.find("sensors[1].id: duplicate sensor id 's1'"), std::string::npos) << e;
  e = ErrorOf(Replace(kDesignExample, "id: s2", "id: \"../s2\""));
  EXPECT_NE(e.find("sensors[1].id: '../s2' is not a valid id"), std::string::npos) << e;
  e = ErrorOf(
      Replace(kDesignExample, "path: [[2, 2], [18, 8], [2, 8]]", "path: [[2, 2], [18, 2]]"));
  EXPECT_NE(e.find("targets[0].path: leg [2, 2] -> [18, 2] crosses world.walls[1]"),
            std::string::npos)
      << e;
  e = ErrorOf(Replace(kDesignExample, "path: [[2, 2], [18, 8], [2, 8]]", "path: [[2, 2], [5, 5]]"));
  EXPECT_NE(e.find("inside world.obstacles[0]"), std::string::npos) << e;
  e = ErrorOf(
      Replace(kDesignExample, "shape: cylinder, radius_m: 0.25", "shape: cylinder, a_m: 0.25"));
  EXPECT_NE(e.find("targets[1].a_m: not a key of shape cylinder"), std::string::npos) << e;
  e = ErrorOf(Replace(kDesignExample, "shape: cylinder", "shape: cube"));
  EXPECT_NE(e.find("targets[1].shape: unknown shape 'cube'"), std::string::npos) << e;
  e = ErrorOf(Replace(kDesignExample, "loop: true}",
                      "loop: true, random_walk: {area: [[1, 1], [2, 1], [2, 2]], speed_mps: 1}}"));
  EXPECT_NE(e.find("targets[0]: give either path"), std::string::npos) << e;
  e = ErrorOf(Replace(kDesignExample, "loop: true}", "loop: true, enter_s: 10, leave_s: 5}"));
  EXPECT_NE(e.find("targets[0].leave_s: must be after enter_s"), std::string::npos) << e;
  e = ErrorOf(
      Replace(kDesignExample, "path: [[2, 2], [18, 8], [2, 8]]", "path: [[2, 2], [19.5, 9.5]]"));
  EXPECT_NE(e.find("walks through sensor 's2'"), std::string::npos) << e;
}

TEST(ScenarioErrors, MissingKeysAndBrokenYaml) {
  std::string e = ErrorOf(Replace(kDesignExample, "x_m: 0.5, ", ""));
  EXPECT_NE(e.find("sensors[0]: missing key 'x_m'"), std::string::npos) << e;
  e = ErrorOf(Replace(kDesignExample, "sensors:\n", "sensorz:\n"));
  EXPECT_NE(e.find("sensorz: unknown key"), std::string::npos) << e;
  e = ErrorOf(Replace(kDesignExample, "world:\n", "world: [\n"));
  EXPECT_NE(e.find("not valid YAML"), std::string::npos) << e;
  e = ErrorOf("");
  EXPECT_NE(e.find("empty"), std::string::npos) << e;
  e = ErrorOf("- just\n- a list\n");
  EXPECT_NE(e.find("expected a map"), std::string::npos) << e;
}

// Every key the people, trolleys, chairs and doors take, and mounts.
const char* const kPeopleAndThings = R"(name: shop
seed: 3
duration_s: 60
world:
  walls: [[[0, 0], [20, 0], [20, 10], [0, 10], [0, 0]]]
sensors:
  - {id: knee, model: lms111, x_m: 0.5, y_m: 0.5, yaw_deg: 45, mount: legs}
  - {id: chest, model: tim781, x_m: 19.5, y_m: 9.5, yaw_deg: -135, mount: torso}
targets:
  - {id: anna, shape: person, a_m: 0.22, b_m: 0.13, torso_exponent: 2.5, sway_m: 0.02,
     leg_radius_m: 0.055, hip_half_width_m: 0.1, path: [[2, 2], [8, 2], [8, 6]], speed_mps: 1.1,
     wait_s: 2, stops: [[1, 4]], stay: true}
  - {id: cart, shape: trolley, length_m: 1.0, width_m: 0.55, path: [[3, 8], [15, 8]], speed_mps: 0.9}
  - {id: seat, shape: chair, size_m: 0.5, yaw_deg: 90, path: [[12, 3], [13, 4]], speed_mps: 0.4,
     wait_s: 20}
  - {id: door, shape: door, hinge: [10, 0.2], width_m: 0.9, swing: [[0, 90], [5, 90], [6.5, 160]]}
)";

TEST(Scenario, PeopleTrolleysChairsDoorsAndMountsParse) {
  Scenario s;
  std::string error;
  ASSERT_TRUE(ParseScenario(kPeopleAndThings, "shop.yaml", &s, &error)) << error;
  EXPECT_EQ(s.sensors[0].mount, Mount::kLegs);
  EXPECT_EQ(s.sensors[1].mount, Mount::kTorso);
  ASSERT_EQ(s.targets.size(), 4u);
  const TargetSpec& anna = s.targets[0];
  EXPECT_EQ(anna.person.a_m, 0.22);
  EXPECT_EQ(anna.person.torso_exponent, 2.5);
  EXPECT_EQ(anna.person.hip_half_width_m, 0.1);
  EXPECT_EQ(anna.wait_s, 2.0);
  ASSERT_EQ(anna.stops.size(), 1u);
  EXPECT_EQ(anna.stops[0].waypoint, 1u);
  EXPECT_EQ(anna.stops[0].seconds, 4.0);
  EXPECT_EQ(anna.stay, true);
  EXPECT_EQ(s.targets[1].shape, TargetShape::kTrolley);
  EXPECT_EQ(s.targets[1].length_m, 1.0);
  EXPECT_EQ(s.targets[1].width_m, 0.55);
  EXPECT_EQ(s.targets[2].shape, TargetShape::kChair);
  EXPECT_EQ(s.targets[2].yaw_deg, 90.0);
  EXPECT_FALSE(s.targets[2].stay.has_value());  // chairs stay by default
  ASSERT_TRUE(s.targets[3].door.has_value());
  EXPECT_EQ(s.targets[3].door->swing.size(), 3u);
  EXPECT_EQ(s.targets[3].door->swing[2].second, 160.0);
}

TEST(ScenarioErrors, PeopleTrolleysChairsDoorsAndMounts) {
  std::string e = ErrorOf(Replace(kPeopleAndThings, "mount: legs", "mount: ankle"));
  EXPECT_NE(e.find("sensors[0].mount: unknown mount 'ankle' (known: torso, legs)"),
            std::string::npos)
      << e;
  e = ErrorOf(Replace(kPeopleAndThings, "stops: [[1, 4]]", "stops: [[3, 4]]"));
  EXPECT_NE(e.find("targets[0].stops[0]: waypoint 3 does not exist"), std::string::npos) << e;
  e = ErrorOf(Replace(kPeopleAndThings, "stops: [[1, 4]]", "stops: [[1.5, 4]]"));
  EXPECT_NE(e.find("targets[0].stops[0]: expected [waypoint index, seconds]"), std::string::npos)
      << e;
  e = ErrorOf(Replace(kPeopleAndThings, "torso_exponent: 2.5", "torso_exponent: 1.5"));
  EXPECT_NE(e.find("targets[0].torso_exponent: must be in [2, 20]"), std::string::npos) << e;
  e = ErrorOf(Replace(kPeopleAndThings, "shape: trolley,", "shape: trolley, radius_m: 1,"));
  EXPECT_NE(e.find("targets[1].radius_m: not a key of shape trolley"), std::string::npos) << e;
  e = ErrorOf(Replace(kPeopleAndThings, "swing: [[0, 90], [5, 90]",
                      "path: [[1, 1]], speed_mps: 0, swing: [[0, 90], [5, 90]"));
  EXPECT_NE(e.find("targets[3]: a door swings on its hinge"), std::string::npos) << e;
  e = ErrorOf(Replace(kPeopleAndThings, "[5, 90], [6.5, 160]", "[5, 90], [4, 160]"));
  EXPECT_NE(e.find("targets[3].swing[2]: keyframe times must increase"), std::string::npos) << e;
  e = ErrorOf(Replace(kPeopleAndThings, ", swing: [[0, 90], [5, 90], [6.5, 160]]", ""));
  EXPECT_NE(e.find("targets[3]: missing key 'swing'"), std::string::npos) << e;
  e = ErrorOf(Replace(kPeopleAndThings, "shape: trolley,",
                      "shape: trolley, random_walk: {area: [[1, 1], [2, 1], [2, 2]], "
                      "speed_mps: 1}, wait_s: 3,"));
  EXPECT_NE(e.find("targets[1]: give either path"), std::string::npos) << e;
}

// Sensors bumped and furniture moved during the run.
TEST(Scenario, SensorMovesAndWorldChangesParse) {
  std::string text = Replace(kDesignExample, "clock: {offset_s: 812.3, drift_ppm: 15}}",
                             "clock: {offset_s: 812.3, drift_ppm: 15},\n"
                             "     moves: [{at_s: 20, x_m: 19.4, y_m: 9.5, yaw_deg: -133},\n"
                             "             {at_s: 40.5, x_m: 19.5, y_m: 9.4, yaw_deg: -140}]}");
  text =
      Replace(text, "obstacles: [[[4, 4], [6, 4], [6, 6], [4, 6]]]",
              "obstacles: [[[4, 4], [6, 4], [6, 6], [4, 6]]]\n"
              "  changes: [{at_s: 10, remove: 0}, {at_s: 10, add: [[12, 6], [13, 6], [13, 7]]}]");
  Scenario s;
  std::string error;
  ASSERT_TRUE(ParseScenario(text, "moves.yaml", &s, &error)) << error;
  ASSERT_EQ(s.sensors[1].moves.size(), 2u);
  EXPECT_DOUBLE_EQ(s.sensors[1].moves[1].at_s, 40.5);
  EXPECT_DOUBLE_EQ(s.sensors[1].moves[1].yaw_deg, -140.0);
  ASSERT_EQ(s.world.changes.size(), 2u);
  EXPECT_EQ(s.world.changes[0].remove, std::optional<std::size_t>(0));
  EXPECT_EQ(s.world.changes[1].add.size(), 3u);

  const std::vector<SensorPoseSpan> spans = PoseSpans(s.sensors[1], s.duration_s);
  ASSERT_EQ(spans.size(), 3u);
  EXPECT_DOUBLE_EQ(spans[0].to_s, 20.0);
  EXPECT_DOUBLE_EQ(spans[0].yaw_deg, -135.0);
  EXPECT_DOUBLE_EQ(spans[1].from_s, 20.0);
  EXPECT_DOUBLE_EQ(spans[1].x_m, 19.4);
  EXPECT_DOUBLE_EQ(spans[2].to_s, 60.0);
  EXPECT_EQ(PoseSpans(s.sensors[0], s.duration_s).size(), 1u);
}

TEST(ScenarioErrors, SensorMovesAndWorldChanges) {
  const auto with_moves = [](const std::string& moves) {
    return Replace(kDesignExample, "clock: {offset_s: 812.3, drift_ppm: 15}}",
                   "clock: {offset_s: 812.3, drift_ppm: 15}, moves: " + moves + "}");
  };
  std::string e = ErrorOf(with_moves("[{at_s: 20, x_m: 25, y_m: 9.5, yaw_deg: 0}]"));
  EXPECT_NE(e.find("sensors[1].moves[0]: sensor 's2' moves to [25, 9.5], outside the world"),
            std::string::npos)
      << e;
  e = ErrorOf(with_moves("[{at_s: 20, x_m: 5, y_m: 5, yaw_deg: 0}]"));
  EXPECT_NE(e.find("moves inside world.obstacles[0]"), std::string::npos) << e;
  e =
      ErrorOf(with_moves("[{at_s: 30, x_m: 19, y_m: 9, yaw_deg: 0}, "
                         "{at_s: 30, x_m: 19, y_m: 9, yaw_deg: 1}]"));
  EXPECT_NE(e.find("sensors[1].moves[1].at_s: must lie after 30 s"), std::string::npos) << e;
  e = ErrorOf(with_moves("[{at_s: 60, x_m: 19, y_m: 9, yaw_deg: 0}]"));
  EXPECT_NE(e.find("moves[0].at_s"), std::string::npos) << e;
  e = ErrorOf(with_moves("[{at_s: 10, x_m: 19, y_m: 9}]"));
  EXPECT_NE(e.find("sensors[1].moves[0]: missing key 'yaw_deg'"), std::string::npos) << e;
  e = ErrorOf(with_moves("[{at_s: 10, x_m: 19, y_m: 9, yaw_deg: 0, z_m: 1}]"));
  EXPECT_NE(e.find("sensors[1].moves[0].z_m: unknown key"), std::string::npos) << e;

  const auto with_changes = [](const std::string& changes) {
    return Replace(kDesignExample, "obstacles: [[[4, 4], [6, 4], [6, 6], [4, 6]]]",
                   "obstacles: [[[4, 4], [6, 4], [6, 6], [4, 6]]]\n  changes: " + changes);
  };
  e = ErrorOf(with_changes("[{at_s: 10, remove: 1}]"));
  EXPECT_NE(e.find("world.changes[0].remove: no obstacle 1 (world.obstacles has 1)"),
            std::string::npos)
      << e;
  e = ErrorOf(with_changes("[{at_s: 10, remove: 0}, {at_s: 12, remove: 0}]"));
  EXPECT_NE(e.find("world.changes[1].remove: obstacle 0 is already removed"), std::string::npos)
      << e;
  e = ErrorOf(with_changes("[{at_s: 10, remove: 0, add: [[1, 1], [2, 1], [2, 2]]}]"));
  EXPECT_NE(e.find("world.changes[0]: give exactly one of remove"), std::string::npos) << e;
  e = ErrorOf(with_changes("[{at_s: 10}]"));
  EXPECT_NE(e.find("world.changes[0]: give exactly one of remove"), std::string::npos) << e;
  e = ErrorOf(with_changes("[{at_s: 20, remove: 0}, {at_s: 10, add: [[1, 1], [2, 1], [2, 2]]}]"));
  EXPECT_NE(e.find("world.changes[1].at_s"), std::string::npos) << e;
  e = ErrorOf(with_changes("[{at_s: 10, remove: -1}]"));
  EXPECT_NE(e.find("world.changes[0].remove: expected an obstacle index"), std::string::npos) << e;
  e = ErrorOf(with_changes("[{at_s: 10, add: [[0.2, 0.2], [1, 0.2], [1, 1], [0.2, 1]]}]"));
  EXPECT_NE(e.find("world.changes[0].add: the polygon covers sensor 's1'"), std::string::npos) << e;
}

TEST(ScenarioErrors, MissingFile) {
  Scenario s;
  std::string error;
  EXPECT_FALSE(LoadScenarioFile("no/such/scenario.yaml", &s, &error));
  EXPECT_NE(error.find("no/such/scenario.yaml: cannot open"), std::string::npos) << error;
}

TEST(Scenario, ValidateCatchesScenariosBuiltInCode) {
  Scenario s;
  s.name = "coded";
  s.world.bounds = std::make_pair(Vec2{0, 0}, Vec2{10, 10});
  SensorSpec sensor;
  sensor.id = "a";
  sensor.model = "tim781";
  sensor.x_m = 5;
  sensor.y_m = 5;
  s.sensors.push_back(sensor);
  EXPECT_FALSE(Validate(s).has_value());
  s.sensors[0].overrides.rate_hz = 0.0;
  const auto e = Validate(s);
  ASSERT_TRUE(e.has_value());
  EXPECT_EQ(*e, "sensors[0].rate_hz: must be in [1, 200]");
}

TEST(Utc, ParsesAndFormatsIsoTimes) {
  EXPECT_EQ(ParseUtc("2021-01-01T12:00:00Z"), 1609502400LL * 1000000000LL);
  EXPECT_EQ(ParseUtc("1970-01-01T00:00:00.5Z"), 500000000LL);
  EXPECT_FALSE(ParseUtc("2021-01-01 12:00:00").has_value());
  EXPECT_FALSE(ParseUtc("2021-13-01T12:00:00Z").has_value());
  EXPECT_EQ(FormatUtc(1609502400LL * 1000000000LL), "2021-01-01T12:00:00Z");
  EXPECT_EQ(FormatUtc(1609502400LL * 1000000000LL + 250000000), "2021-01-01T12:00:00.250000000Z");
}

}  // namespace
}  // namespace lrfnet::sim
