#include "tools/sim/simulator.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "common/time.h"
#include "tools/sim/device_model.h"
#include "tools/sim/sim_output.h"

namespace lrfnet::sim {
namespace {

constexpr double kPi = 3.14159265358979323846;

// One LMS111 at the origin looking along +x at a wall x = 10.
Scenario WallScenario() {
  Scenario s;
  s.name = "wall";
  s.seed = 5;
  s.duration_s = 1.0;
  s.world.walls = {{{10, -20}, {10, 20}}};
  s.world.bounds = std::make_pair(Vec2{-1, -21}, Vec2{11, 21});
  SensorSpec sensor;
  sensor.id = "s";
  sensor.model = "lms111";
  s.sensors.push_back(sensor);
  return s;
}

std::unique_ptr<Simulator> Make(const Scenario& s) {
  const auto invalid = Validate(s);
  EXPECT_FALSE(invalid.has_value()) << *invalid;
  std::string error;
  auto sim = Simulator::Create(s, &error);
  EXPECT_NE(sim, nullptr) << error;
  return sim;
}

// LMS111: 541 beams from −135° at 0.5°; beam 270 points straight ahead.
std::size_t BeamAt(double angle_deg) {
  return static_cast<std::size_t>(std::lround(270 + angle_deg / 0.5));
}

TEST(Simulator, BeamRangesMatchHandComputedGeometry) {
  Scenario s = WallScenario();
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  // Straight ahead: 10 m. At 30°: 10 / cos 30° = 11.547 m. (The five rays across the beam's width
  // average to a little more on a flat wall: 0.08 mm straight ahead, 0.16 mm at 30°.)
  EXPECT_NEAR(sim->NoiselessRange(0, BeamAt(0), 0.0), 10.0, 2e-4);
  EXPECT_NEAR(sim->NoiselessRange(0, BeamAt(30), 0.0), 10.0 / std::cos(30 * kPi / 180), 5e-4);
  // Beyond ±63.4° the wall ends (y = ±20): no echo; behind the sensor: nothing either.
  EXPECT_EQ(sim->NoiselessRange(0, BeamAt(70), 0.0), kNoHit);
  EXPECT_EQ(sim->NoiselessRange(0, BeamAt(-120), 0.0), kNoHit);

  // The telegram carries the same: with noise off, whole millimetres of the geometry.
  s.sensors[0].overrides.noise_m = 0.0;
  sim = Make(s);
  auto scan = std::make_unique<cola::ScanTelegram>();
  sim->SimulateScan(0, 0, scan.get());
  const cola::ScanChannel* dist = scan->FindChannel("DIST1");
  ASSERT_NE(dist, nullptr);
  ASSERT_EQ(dist->count, 541);
  EXPECT_EQ(dist->start_angle_raw, -450000);
  EXPECT_EQ(dist->angle_step_raw, 5000);
  EXPECT_EQ(dist->raw[BeamAt(0)], 10000);
  EXPECT_NEAR(dist->raw[BeamAt(30)], 11547, 1);
  EXPECT_NEAR(dist->raw[BeamAt(-40)], 13054, 1);
  EXPECT_EQ(dist->raw[BeamAt(70)], 0);
  EXPECT_EQ(scan->FindChannel("RSSI1"), nullptr);  // the LMS111 sends DIST1 only
}

TEST(Simulator, PoseRotatesTheScan) {
  // The same wall seen from (0, 0) with yaw 90° is straight ahead only for a wall at y = 10; with
  // this one (x = 10) it is 90° to the right: beam −90°.
  Scenario s = WallScenario();
  s.sensors[0].yaw_deg = 90;
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  EXPECT_NEAR(sim->NoiselessRange(0, BeamAt(-90), 0.0), 10.0, 2e-4);
  EXPECT_EQ(sim->NoiselessRange(0, BeamAt(0), 0.0), kNoHit);
}

TEST(Simulator, TargetsAreHitWhereTheyStand) {
  Scenario s = WallScenario();
  TargetSpec cylinder;
  cylinder.id = "cyl";
  cylinder.shape = TargetShape::kCylinder;
  cylinder.radius_m = 0.5;
  cylinder.path = {{5, 0}};
  s.targets.push_back(cylinder);
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  EXPECT_NEAR(sim->NoiselessRange(0, BeamAt(0), 0.5), 4.5, 1e-3);
  const double a = kPi / 180;
  EXPECT_NEAR(sim->NoiselessRange(0, BeamAt(1), 0.5),
              5 * std::cos(a) - std::sqrt(0.25 - 25 * std::sin(a) * std::sin(a)), 1e-3);
  // Outside [enter_s, leave_s] the target is gone.
  s.targets[0].enter_s = 0.8;
  sim = Make(s);
  EXPECT_NEAR(sim->NoiselessRange(0, BeamAt(0), 0.5), 10.0, 2e-4);
  EXPECT_NEAR(sim->NoiselessRange(0, BeamAt(0), 0.9), 4.5, 1e-3);
}

TEST(Simulator, APersonShowsTheShouldersAcrossItsWalkingDirection) {
  // The upper body is an ellipse with a = 0.25 m across the shoulders and b = 0.15 m front to
  // back. A person standing 4 m ahead facing the sensor's x axis shows its back: 4 − b; walking
  // across the beam (along +y) it shows a shoulder side: 4 − a.
  Scenario s = WallScenario();
  s.duration_s = 10;
  TargetSpec standing;
  standing.id = "standing";
  standing.path = {{4, 0}};
  standing.person.a_m = 0.25;
  standing.person.b_m = 0.15;
  standing.person.sway_m = 0.0;
  s.targets.push_back(standing);
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  EXPECT_NEAR(sim->NoiselessRange(0, BeamAt(0), 1.0), 3.85, 1e-3);

  TargetSpec walking = standing;
  walking.id = "walking";
  walking.path = {{4, -3}, {4, 3}};
  walking.speed_mps = 1.0;
  s.targets = {walking};
  sim = Make(s);
  // The beam's width on the curved side adds 1.4 mm, the torso's turn with the gait (4 degrees at
  // most) up to 1.2 mm.
  EXPECT_NEAR(sim->NoiselessRange(0, BeamAt(0), 3.0), 3.75, 3e-3);
  // With sway the body centre leaves the path by up to sway_m sideways (here: along x).
  s.targets[0].person.sway_m = 0.05;
  sim = Make(s);
  double lo = 10, hi = 0;
  for (double t = 2.0; t < 4.0; t += 0.05) {
    const TargetState st = sim->targets()[0].StateAt(t);
    lo = std::min(lo, st.center.x);
    hi = std::max(hi, st.center.x);
  }
  EXPECT_NEAR(lo, 3.95, 0.005);
  EXPECT_NEAR(hi, 4.05, 0.005);
}

TEST(Simulator, MixedPixelsAtAnEdgeLieBetweenForegroundAndBackground) {
  // A plate from (5, 0.5) to (5, 3) in front of the wall x = 10: its edge is at atan(0.1) = 5.71°.
  // The beam at 5.5° has 30 % of its energy on the plate (rays at 5.72° and 5.93°): a mixed pixel;
  // the beam at 6.0° has 90 %: the plate.
  Scenario s = WallScenario();
  s.world.walls.push_back({{5, 0.5}, {5, 3}});
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  const double mixed = sim->NoiselessRange(0, BeamAt(5.5), 0.0);
  EXPECT_GT(mixed, 5.5);
  EXPECT_LT(mixed, 9.5);
  EXPECT_NEAR(sim->NoiselessRange(0, BeamAt(6.0), 0.0), 5.0 / std::cos(6 * kPi / 180), 0.02);
  EXPECT_NEAR(sim->NoiselessRange(0, BeamAt(5.0), 0.0), 10.0 / std::cos(5 * kPi / 180), 0.01);
}

TEST(Simulator, AnLms511ResolvesAnEdgesEchoesFartherApartThanHalfAMetre) {
  // The plate of the test above, 5 m in front of the wall, seen by an LMS511 (1141 beams from
  // −95° at 1/6°, beam 570 straight ahead; 11 mrad: rays 0.1575° apart). The beam at 5.667°
  // (rays from 5.352° to 5.982°) has 30 % of its energy on the plate: the wall's echo, not a
  // range between; the beam at 5.833° has 70 %: the plate's (a merged echo would lie between).
  Scenario s = WallScenario();
  s.sensors[0].model = "lms511";
  s.world.walls.push_back({{5, 0.5}, {5, 3}});
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  const auto beam_at = [](int sixths) { return static_cast<std::size_t>(570 + sixths); };
  const double deg = kPi / 180;
  EXPECT_NEAR(sim->NoiselessRange(0, beam_at(34), 0.0), 10.0 / std::cos(34.0 / 6 * deg), 0.02);
  EXPECT_NEAR(sim->NoiselessRange(0, beam_at(35), 0.0), 5.0 / std::cos(35.0 / 6 * deg), 0.02);
  // The LMS111 merges them (DeviceModel::resolved_echo_m 0): the test above.
  ASSERT_EQ(FindDeviceModel("lms111")->resolved_echo_m, 0.0);
  ASSERT_EQ(FindDeviceModel("lms511")->resolved_echo_m, 0.5);
}

TEST(Simulator, RangeLimitAndNoise) {
  Scenario s = WallScenario();
  s.sensors[0].overrides.range_m = 9.0;  // the wall at 10 m is out of range
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  auto scan = std::make_unique<cola::ScanTelegram>();
  sim->SimulateScan(0, 0, scan.get());
  for (std::size_t i = 0; i < 541; ++i) EXPECT_EQ(scan->channels16[0].raw[i], 0) << i;

  // Noise: σ = 12 mm (LMS111) around 10 m on the straight-ahead beam, over many scans.
  s = WallScenario();
  s.duration_s = 4;
  sim = Make(s);
  double sum = 0, sum2 = 0;
  int n = 0;
  for (std::uint64_t k = 0; k < sim->sensor(0).scan_count; ++k) {
    sim->SimulateScan(0, k, scan.get());
    const double r = scan->channels16[0].raw[BeamAt(0)] / 1000.0;
    if (r == 0) continue;  // a drop-out
    sum += r;
    sum2 += r * r;
    ++n;
  }
  ASSERT_GT(n, 150);
  const double mean = sum / n;
  const double sd = std::sqrt(sum2 / n - mean * mean);
  EXPECT_NEAR(mean, 10.0, 0.004);
  EXPECT_GT(sd, 0.008);
  EXPECT_LT(sd, 0.016);
}

TEST(Simulator, SameSeedSameScansOtherSeedOtherNoise) {
  Scenario s = WallScenario();
  auto a = Make(s);
  auto b = Make(s);
  s.seed = 6;
  auto c = Make(s);
  auto sa = std::make_unique<cola::ScanTelegram>();
  auto sb = std::make_unique<cola::ScanTelegram>();
  auto sc = std::make_unique<cola::ScanTelegram>();
  // Scan 7 is the same whether or not scans 0..6 were simulated first.
  for (std::uint64_t k = 0; k < 7; ++k) a->SimulateScan(0, k, sa.get());
  a->SimulateScan(0, 7, sa.get());
  b->SimulateScan(0, 7, sb.get());
  c->SimulateScan(0, 7, sc.get());
  const auto& da = sa->channels16[0];
  EXPECT_TRUE(std::equal(da.raw.begin(), da.raw.begin() + da.count, sb->channels16[0].raw.begin()));
  EXPECT_EQ(sa->time_since_startup_us, sb->time_since_startup_us);
  EXPECT_FALSE(
      std::equal(da.raw.begin(), da.raw.begin() + da.count, sc->channels16[0].raw.begin()));
}

TEST(SensorClock, DriftAndTickWrap) {
  Scenario s = WallScenario();
  s.duration_s = 2.0;
  s.sensors[0].clock.offset_s = 4294.9;  // the uint32 µs tick wraps at 4294.967296 s
  s.sensors[0].clock.drift_ppm = 200;
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  const SensorSetup& setup = sim->sensor(0);
  EXPECT_EQ(setup.clock_offset_s, 4294.9);
  EXPECT_EQ(setup.drift_ppm, 200.0);
  // 50 Hz for 2 s (a scan starts in the first 20 ms).
  EXPECT_GE(setup.scan_count, 100u);
  EXPECT_LE(setup.scan_count, 101u);
  auto scan = std::make_unique<cola::ScanTelegram>();
  common::TickUnwrapper unwrap;
  int wraps = 0;
  std::uint32_t last = 0;
  std::int64_t first_unwrapped = 0, last_unwrapped = 0;
  for (std::uint64_t k = 0; k < setup.scan_count; ++k) {
    sim->SimulateScan(0, k, scan.get());
    if (k > 0 && scan->time_since_startup_us < last) ++wraps;
    last = scan->time_since_startup_us;
    const auto u = unwrap.Unwrap(scan->time_since_startup_us);
    EXPECT_FALSE(u.restarted);
    if (k == 0) first_unwrapped = u.ticks_us;
    last_unwrapped = u.ticks_us;
    // Counters advance by one per scan (uint16).
    EXPECT_EQ(scan->telegram_counter, static_cast<std::uint16_t>(setup.first_telegram_counter + k));
  }
  EXPECT_EQ(wraps, 1);
  // The device's own clock runs the scan period exactly (20 000 µs), give or take the jitter...
  const double ticks_per_scan = static_cast<double>(last_unwrapped - first_unwrapped) /
                                static_cast<double>(setup.scan_count - 1);
  EXPECT_NEAR(ticks_per_scan, 20000.0, 3.5);
  // ...and that clock runs 200 ppm fast against scenario time.
  const ScanTiming first = sim->Timing(0, 0);
  const ScanTiming final = sim->Timing(0, setup.scan_count - 1);
  EXPECT_NEAR(static_cast<double>(final.start_tick_us - first.start_tick_us) /
                  ((final.start_s - first.start_s) * 1e6),
              1.0002, 1e-6);
  // Transmission: LMS111, 3.05-3.3 ms after the scan started.
  for (std::uint64_t k = 0; k < 5; ++k) {
    const ScanTiming t = sim->Timing(0, k);
    EXPECT_GE(t.transmit_tick_us - t.start_tick_us, 3050);
    EXPECT_LE(t.transmit_tick_us - t.start_tick_us, 3300);
  }
}

TEST(Targets, PathsTimesAndTruth) {
  Scenario s = WallScenario();
  s.duration_s = 20;
  TargetSpec walker;
  walker.id = "w";
  walker.path = {{1, 1}, {9, 1}};
  walker.speed_mps = 2.0;
  walker.enter_s = 1.0;
  walker.person.sway_m = 0.0;
  s.targets.push_back(walker);
  TargetSpec looper = walker;
  looper.id = "l";
  looper.path = {{1, -5}, {5, -5}, {5, -1}};
  looper.loop = true;
  looper.enter_s = 0.0;
  s.targets.push_back(looper);
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  // Walker: enters at 1 s at (1, 1), 2 m/s east, reaches (9, 1) at 5 s and leaves.
  EXPECT_FALSE(sim->targets()[0].StateAt(0.5).present);
  TargetState st = sim->targets()[0].StateAt(3.0);
  ASSERT_TRUE(st.present);
  EXPECT_NEAR(st.center.x, 5.0, 1e-9);
  EXPECT_NEAR(st.center.y, 1.0, 1e-9);
  EXPECT_NEAR(st.velocity_mps.x, 2.0, 1e-6);
  EXPECT_NEAR(st.heading_rad, 0.0, 1e-9);
  EXPECT_FALSE(sim->targets()[0].StateAt(5.5).present);
  // Looper: the lap is 4 + 4 + 5.657 m; after 6 s (12 m) it is on the diagonal back to the start.
  st = sim->targets()[1].StateAt(6.0);
  ASSERT_TRUE(st.present);
  const double lap = 8 + std::sqrt(32.0);
  EXPECT_NEAR(st.center.x, 5 - 4 / std::sqrt(32.0) * 4, 1e-9);
  st = sim->targets()[1].StateAt(lap / 2.0 + 1.0);  // one lap and 2 m later
  EXPECT_NEAR(st.center.x, 3.0, 1e-9);
  EXPECT_NEAR(st.center.y, -5.0, 1e-9);
  const auto truth = sim->TruthAt(3.0);
  EXPECT_EQ(truth.size(), 2u);
}

TEST(Targets, SpeedVariationKeepsTheMeanSpeedAndSwayStaysSmall) {
  Scenario s = WallScenario();
  s.duration_s = 30;
  TargetSpec walker;
  walker.id = "w";
  walker.path = {{1, -15}, {1, 15}};
  walker.speed_mps = 1.0;
  walker.speed_variation = SpeedVariation{0.5, 4.0};
  s.targets.push_back(walker);
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  const Target& t = sim->targets()[0];
  // Over whole periods the variation averages out: 8 s -> 8 m.
  EXPECT_NEAR(t.trajectory().Distance(8.0), 8.0, 1e-4);
  // ...but not within one: after 1 s (a quarter period) it walked 1 + 0.5·4/(2π) m.
  EXPECT_NEAR(t.trajectory().Distance(1.0), 1.0 + 0.5 * 4.0 / (2 * kPi), 1e-3);
  // A person sways sideways by sway_m at most, around the path.
  for (double time = 0; time < 20; time += 0.1) {
    const TargetState st = t.StateAt(time);
    EXPECT_LE(std::abs(st.center.x - 1.0), t.body().sway_m + 1e-9);
  }
}

TEST(Targets, RandomWalksStayInTheirAreaAndOutOfObstacles) {
  Scenario s;
  s.name = "walk";
  s.seed = 9;
  s.duration_s = 120;
  s.world.walls = {{{0, 0}, {8, 0}, {8, 3.5}, {4, 3.5}, {4, 7}, {0, 7}, {0, 0}}};
  s.world.obstacles = {{{1, 1}, {3, 1}, {3, 2}, {1, 2}}};
  s.world.low_obstacles = {{{5, 1}, {7, 1}, {7, 2}, {5, 2}}};
  SensorSpec sensor;
  sensor.id = "s";
  sensor.model = "tim561";
  sensor.x_m = 0.3;
  sensor.y_m = 0.3;
  s.sensors.push_back(sensor);
  TargetSpec walker;
  walker.id = "w";
  RandomWalkSpec walk;
  walk.area = {{0.2, 0.2}, {7.8, 0.2}, {7.8, 3.3}, {3.8, 3.3}, {3.8, 6.8}, {0.2, 6.8}};
  walk.speed_mps = 1.0;
  walk.pause_s = 1.0;
  walker.random_walk = walk;
  s.targets.push_back(walker);
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  const Target& t = sim->targets()[0];
  double walked = 0;
  for (double time = 0; time <= 120; time += 0.05) {
    const Vec2 p = t.trajectory().Position(time);
    ASSERT_TRUE(PointInPolygon(p, walk.area)) << time;
    ASSERT_FALSE(PointInPolygon(p, s.world.obstacles[0])) << time;
    ASSERT_FALSE(PointInPolygon(p, s.world.low_obstacles[0])) << time;
    ASSERT_GT(Norm(p - Vec2{0.3, 0.3}), 0.3) << "walked into the sensor at " << time;
  }
  walked = t.trajectory().Distance(120);
  EXPECT_GT(walked, 40.0);  // it does walk (pauses included)
  // The same seed draws the same walk.
  auto again = Make(s);
  EXPECT_EQ(again->targets()[0].trajectory().knots().size(), t.trajectory().knots().size());
  EXPECT_EQ(again->targets()[0].trajectory().Position(77.7).x, t.trajectory().Position(77.7).x);
}

TEST(Targets, RandomWalkWithoutRoomIsAnError) {
  Scenario s = WallScenario();
  s.world.obstacles = {{{1, -1}, {3, -1}, {3, 1}, {1, 1}}};
  TargetSpec walker;
  walker.id = "w";
  RandomWalkSpec walk;
  walk.area = {{1.1, -0.9}, {2.9, -0.9}, {2.9, 0.9}, {1.1, 0.9}};  // entirely inside the obstacle
  walker.random_walk = walk;
  s.targets.push_back(walker);
  ASSERT_FALSE(Validate(s).has_value());
  std::string error;
  EXPECT_EQ(Simulator::Create(s, &error), nullptr);
  EXPECT_NE(error.find("targets[0].random_walk.area: no free spot"), std::string::npos) << error;
}

}  // namespace
}  // namespace lrfnet::sim

namespace lrfnet::sim {
namespace {

// Beams of sensor 0 (in WallScenario) at t_s that hit something in front of the wall at x = 10, as
// runs [begin, end) of consecutive beams.
std::vector<std::pair<std::size_t, std::size_t>> HitRuns(const Simulator& sim, double t_s) {
  std::vector<std::pair<std::size_t, std::size_t>> runs;
  const std::size_t beams = sim.sensor(0).device.count;
  bool open = false;
  for (std::size_t b = 0; b < beams; ++b) {
    const bool hit = sim.NoiselessRange(0, b, t_s) < 9.0;
    if (hit && !open) runs.emplace_back(b, b + 1);
    if (hit) runs.back().second = b + 1;
    open = hit;
  }
  return runs;
}

TEST(Targets, PeopleDifferInSizeUnlessTheScenarioFixesThem) {
  Scenario s = WallScenario();
  s.duration_s = 5;
  for (int i = 0; i < 6; ++i) {
    TargetSpec p;
    p.id = "p" + std::to_string(i);
    p.path = {{2.0 + i, 3.0}};
    s.targets.push_back(p);
  }
  s.targets[5].person.a_m = 0.21;
  s.targets[5].person.b_m = 0.12;
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  std::set<double> widths, exponents;
  for (std::size_t i = 0; i < 5; ++i) {
    const PersonBody& b = sim->targets()[i].body();
    EXPECT_GE(b.a_m, 0.18);
    EXPECT_LE(b.a_m, 0.30);
    EXPECT_GE(b.b_m, 0.10);
    EXPECT_LE(b.b_m, 0.20);
    EXPECT_GE(b.exponent, 2.0);
    EXPECT_LE(b.exponent, 3.0);
    EXPECT_GE(b.leg_radius_m, 0.05);
    EXPECT_LE(b.leg_radius_m, 0.07);
    widths.insert(b.a_m);
    exponents.insert(b.exponent);
  }
  EXPECT_EQ(widths.size(), 5u);
  EXPECT_EQ(exponents.size(), 5u);
  // Fixed sizes are that ellipse (DESIGN.md); the person's other values are still drawn.
  const PersonBody& fixed = sim->targets()[5].body();
  EXPECT_EQ(fixed.a_m, 0.21);
  EXPECT_EQ(fixed.b_m, 0.12);
  EXPECT_EQ(fixed.exponent, 2.0);
  // Fixing one person does not change the others' draws, and the seed decides them.
  s.targets[5].person = {};
  auto again = Make(s);
  for (std::size_t i = 0; i < 5; ++i) {
    EXPECT_EQ(again->targets()[i].body().a_m, sim->targets()[i].body().a_m);
  }
  EXPECT_EQ(again->targets()[5].body().sway_m, fixed.sway_m);
  s.seed = 6;
  auto other = Make(s);
  EXPECT_NE(other->targets()[0].body().a_m, sim->targets()[0].body().a_m);
}

TEST(Targets, LegsStepWithTheGaitAndStandSideBySide) {
  Scenario s = WallScenario();
  s.duration_s = 30;
  TargetSpec slow;
  slow.id = "slow";
  slow.path = {{1, -8}, {1, 8}};
  slow.speed_mps = 0.6;
  TargetSpec fast = slow;
  fast.id = "fast";
  fast.path = {{3, -8}, {3, 8}};
  fast.speed_mps = 1.5;
  TargetSpec standing;
  standing.id = "standing";
  standing.path = {{5, 0}};
  s.targets = {slow, fast, standing};
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  // Walking along +y: the legs' offsets along y alternate; the largest gap between the legs grows
  // with the stride, which grows with speed.
  const auto largest_gap = [&](std::size_t j, double from_s, double to_s) {
    double gap = 0;
    for (double t = from_s; t < to_s; t += 0.01) {
      const TargetState st = sim->targets()[j].StateAt(t);
      gap = std::max(gap, std::abs(st.legs[0].y - st.legs[1].y));
      // Left leg on the left of the walking direction (+y: left is -x).
      EXPECT_LT(st.legs[0].x, st.legs[1].x) << t;
    }
    return gap;
  };
  const double slow_gap = largest_gap(0, 2.0, 6.0);
  const double fast_gap = largest_gap(1, 2.0, 6.0);
  EXPECT_NEAR(fast_gap, 0.5 * kKneeFraction * StrideM(1.5), 0.02);
  EXPECT_NEAR(slow_gap, 0.5 * kKneeFraction * StrideM(0.6), 0.02);
  EXPECT_GT(fast_gap, slow_gap + 0.05);
  // A leg in stance moves at (1 - kKneeFraction) of the body's speed at knee height, one in swing
  // faster than the body.
  double min_speed = 10, max_speed = 0;
  for (double t = 2.0; t < 4.0; t += 0.01) {
    const double v = Norm(sim->targets()[1].StateAt(t + 0.005).legs[0] -
                          sim->targets()[1].StateAt(t - 0.005).legs[0]) /
                     0.01;
    min_speed = std::min(min_speed, v);
    max_speed = std::max(max_speed, v);
  }
  EXPECT_NEAR(min_speed, (1.0 - kKneeFraction) * 1.5, 0.05);
  EXPECT_GT(max_speed, 2.0 * 1.5);
  // Standing: both legs down, side by side under the hips.
  const Target& st = sim->targets()[2];
  const TargetState still = st.StateAt(10.0);
  EXPECT_NEAR(Norm(still.legs[0] - still.legs[1]), 2.0 * st.body().hip_half_width_m, 1e-9);
  EXPECT_NEAR(Norm(0.5 * (still.legs[0] + still.legs[1]) - still.center), 0.0, 1e-9);
}

TEST(Simulator, ASensorAtKneeHeightSeesTwoLegsAndAtTorsoHeightOneBody) {
  Scenario s = WallScenario();
  s.duration_s = 5;
  TargetSpec standing;
  standing.id = "p";
  standing.path = {{4, 0}};
  standing.person.hip_half_width_m = 0.15;
  s.targets = {standing};
  // Facing +x (a path of one point faces heading 0): the legs stand at y = ±hip_half_width, 0.18 m
  // apart at 4 m, wider than a beam there.
  auto torso = Make(s);
  ASSERT_NE(torso, nullptr);
  EXPECT_EQ(HitRuns(*torso, 1.0).size(), 1u);
  s.sensors[0].mount = Mount::kLegs;
  auto legs = Make(s);
  ASSERT_NE(legs, nullptr);
  const auto runs = HitRuns(*legs, 1.0);
  ASSERT_EQ(runs.size(), 2u);
  const PersonBody& body = legs->targets()[0].body();
  for (const auto& [begin, end] : runs) {
    double nearest = kNoHit;
    for (std::size_t b = begin; b < end; ++b) {
      nearest = std::min(nearest, legs->NoiselessRange(0, b, 1.0));
    }
    EXPECT_NEAR(nearest, std::hypot(4.0, body.hip_half_width_m) - body.leg_radius_m, 0.005);
  }
  // The truth is the body centre whatever the mount.
  EXPECT_NEAR(legs->TruthAt(1.0)[0].state.center.x, 4.0, 1e-9);
  // A scan counts the beams each target returned.
  auto scan = std::make_unique<cola::ScanTelegram>();
  std::vector<std::uint32_t> hits;
  legs->SimulateScan(0, 10, scan.get(), &hits);
  ASSERT_EQ(hits.size(), 1u);
  EXPECT_GE(hits[0], 2u * 2u);
  EXPECT_LE(hits[0], static_cast<std::uint32_t>((runs[0].second - runs[0].first) +
                                                (runs[1].second - runs[1].first) + 2));
}

TEST(Targets, ATrolleyIsPushedByAPersonBehindIt) {
  Scenario s = WallScenario();
  s.duration_s = 10;
  TargetSpec trolley;
  trolley.id = "cart";
  trolley.shape = TargetShape::kTrolley;
  trolley.path = {{3, -6}, {3, 6}};
  trolley.speed_mps = 1.0;
  s.targets = {trolley};
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  ASSERT_EQ(sim->targets().size(), 2u);
  EXPECT_EQ(sim->targets()[1].id(), "cart.pusher");
  EXPECT_EQ(sim->targets()[1].shape(), TargetShape::kPerson);
  const auto truth = sim->TruthAt(5.0);
  ASSERT_EQ(truth.size(), 2u);
  const Vec2 cart = truth[0].state.center, pusher = truth[1].state.center;
  EXPECT_NEAR(cart.y, -1.0, 1e-6);
  // Behind the trolley (walking +y), by half its length, the handle and the pusher's depth.
  EXPECT_NEAR(cart.y - pusher.y, 0.45 + 0.25 + sim->targets()[1].body().b_m, 1e-6);
  EXPECT_LT(std::abs(pusher.x - 3.0), 0.04);  // sway
  // The sensor sees the trolley's side at x = 3 - width / 2.
  EXPECT_NEAR(sim->NoiselessRange(0, BeamAt(std::atan2(-1.0, 3.0) * 180 / kPi), 5.0),
              std::hypot(2.7, 2.7 / 3.0), 0.01);
}

TEST(Targets, ADoorSwingsBetweenItsKeyframesAndAChairIsMovedAndLeft) {
  Scenario s = WallScenario();
  s.duration_s = 30;
  TargetSpec door;
  door.id = "door";
  door.shape = TargetShape::kDoor;
  door.door = DoorSpec{{5, 1}, 1.0, 0.04, {{2, 90}, {4, 180}}};
  TargetSpec chair;
  chair.id = "chair";
  chair.shape = TargetShape::kChair;
  chair.path = {{2, -1.5}, {2, -2.5}};
  chair.speed_mps = 0.25;
  chair.wait_s = 10;
  s.targets = {door, chair};
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  TargetState d = sim->targets()[0].StateAt(1.0);
  ASSERT_TRUE(d.present);
  EXPECT_NEAR(d.center.x, 5.0, 1e-9);
  EXPECT_NEAR(d.center.y, 1.5, 1e-9);
  d = sim->targets()[0].StateAt(3.0);  // half-way: 135 degrees
  EXPECT_NEAR(d.center.x, 5.0 - 0.5 * std::sqrt(0.5), 1e-9);
  EXPECT_GT(d.speed_mps, 0.3);
  d = sim->targets()[0].StateAt(29.0);
  EXPECT_NEAR(d.center.x, 4.5, 1e-9);
  EXPECT_NEAR(d.speed_mps, 0.0, 1e-9);
  // Open towards the sensor, the leaf (its near face at y = 0.98) blocks the beams over x in
  // [4, 5].
  const double beam_deg = 12.5;
  EXPECT_NEAR(sim->NoiselessRange(0, BeamAt(beam_deg), 29.0), 0.98 / std::sin(beam_deg * kPi / 180),
              0.002);
  // The chair stands, is moved 1 m in 4 s, and stays there.
  EXPECT_NEAR(sim->targets()[1].StateAt(5.0).center.y, -1.5, 1e-9);
  EXPECT_NEAR(sim->targets()[1].StateAt(12.0).center.y, -2.0, 1e-9);
  const TargetState left = sim->targets()[1].StateAt(29.9);
  ASSERT_TRUE(left.present);
  EXPECT_NEAR(left.center.y, -2.5, 1e-9);
  const auto truth = sim->TruthAt(20.0);
  ASSERT_EQ(truth.size(), 2u);
  EXPECT_EQ(sim->targets()[truth[0].target].shape(), TargetShape::kDoor);
  EXPECT_EQ(sim->targets()[truth[1].target].shape(), TargetShape::kChair);
  // At torso height the chair is its backrest; at knee height four thin legs.
  EXPECT_EQ(HitRuns(*sim, 29.0).size(), 2u);  // the door leaf and the backrest
  s.sensors[0].mount = Mount::kLegs;
  auto legs = Make(s);
  EXPECT_EQ(HitRuns(*legs, 29.0).size(), 1u + 4u);
}

TEST(Targets, StopsWaitsAndStayShapeAPath) {
  Scenario s = WallScenario();
  s.duration_s = 30;
  TargetSpec walker;
  walker.id = "w";
  walker.path = {{1, 0}, {3, 0}, {3, 2}};
  walker.speed_mps = 1.0;
  walker.wait_s = 1.0;
  walker.stops = {{1, 3.0}};
  walker.stay = true;
  s.targets = {walker};
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  const Target& t = sim->targets()[0];
  EXPECT_NEAR(t.StateAt(0.5).center.x, 1.0, 1e-9);  // waiting
  EXPECT_NEAR(t.StateAt(2.0).center.x, 2.0, 1e-9);
  for (const double at : {3.2, 4.5, 5.8}) {  // the stop at waypoint 1, 3 ... 6 s
    EXPECT_NEAR(t.StateAt(at).center.x, 3.0, 1e-9) << at;
    EXPECT_NEAR(t.StateAt(at).center.y, 0.0, 1e-9) << at;
    EXPECT_EQ(t.StateAt(at).speed_mps, 0.0) << at;
  }
  EXPECT_NEAR(t.StateAt(7.0).center.y, 1.0, 1e-9);
  ASSERT_TRUE(t.StateAt(29.0).present);  // stays at the end
  EXPECT_NEAR(t.StateAt(29.0).center.y, 2.0, 1e-9);
}

TEST(Simulator, AMovedSensorScansFromItsNewPoseFromTheMoveOn) {
  // Before 0.5 s straight ahead at the wall x = 10; then turned 90° left and 2 m back: the wall is
  // 12 m away at beam −90°.
  Scenario s = WallScenario();
  s.sensors[0].moves.push_back({0.5, -0.5, 0.0, 90.0});
  s.world.bounds = std::make_pair(Vec2{-3, -21}, Vec2{11, 21});
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  EXPECT_NEAR(sim->NoiselessRange(0, BeamAt(0), 0.2), 10.0, 2e-4);
  EXPECT_NEAR(sim->NoiselessRange(0, BeamAt(-90), 0.7), 10.5, 2e-4);
  EXPECT_EQ(sim->NoiselessRange(0, BeamAt(0), 0.7), kNoHit);
  // The scans: every scan that starts before the move sees the wall ahead, every later one not.
  cola::ScanTelegram scan;
  std::size_t before = 0, after = 0;
  for (std::uint64_t k = 0; k < sim->sensor(0).scan_count; ++k) {
    sim->SimulateScan(0, k, &scan);
    const std::uint16_t ahead = scan.channels16[0].raw[BeamAt(0)];
    if (sim->Timing(0, k).start_s < 0.5) {
      ++before;
      EXPECT_NEAR(ahead, 10000, 60) << k;
    } else {
      ++after;
      EXPECT_EQ(ahead, 0) << k;
    }
  }
  EXPECT_GT(before, 5u);
  EXPECT_GT(after, 5u);
}

TEST(Simulator, TruthListsEveryPoseWithItsTimeRange) {
  Scenario s = WallScenario();
  s.sensors[0].moves.push_back({0.5, -0.5, 0.25, 90.0});
  s.world.bounds = std::make_pair(Vec2{-3, -21}, Vec2{11, 21});
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  const std::string truth = TruthYaml(*sim, s.start_utc_ns, false);
  // `sensors` holds the pose at the end; `poses` both with their time ranges.
  EXPECT_NE(truth.find("sensors:\n  - {id: \"s\", x_m: -0.5, y_m: 0.25, yaw_deg: 90}"),
            std::string::npos)
      << truth;
  EXPECT_NE(truth.find("  - {id: \"s\", from_s: 0, to_s: 0.5, from_utc_ns: 1609502400000000000, "
                       "x_m: 0, y_m: 0, yaw_deg: 0}"),
            std::string::npos)
      << truth;
  EXPECT_NE(truth.find("  - {id: \"s\", from_s: 0.5, to_s: 1, from_utc_ns: 1609502400500000000, "
                       "x_m: -0.5, y_m: 0.25, yaw_deg: 90}"),
            std::string::npos)
      << truth;
}

TEST(Simulator, FurnitureRemovedAndAddedChangesTheStaticScene) {
  // A box 5 m ahead, removed at 0.3 s; a new one at 3 m appears at 0.6 s.
  Scenario s = WallScenario();
  s.world.obstacles = {{{5, -0.5}, {6, -0.5}, {6, 0.5}, {5, 0.5}}};
  WorldChange remove;
  remove.at_s = 0.3;
  remove.remove = 0;
  WorldChange add;
  add.at_s = 0.6;
  add.add = {{3, -0.5}, {3.5, -0.5}, {3.5, 0.5}, {3, 0.5}};
  s.world.changes = {remove, add};
  auto sim = Make(s);
  ASSERT_NE(sim, nullptr);
  EXPECT_NEAR(sim->NoiselessRange(0, BeamAt(0), 0.1), 5.0, 2e-4);
  EXPECT_NEAR(sim->NoiselessRange(0, BeamAt(0), 0.4), 10.0, 2e-4);
  EXPECT_NEAR(sim->NoiselessRange(0, BeamAt(0), 0.8), 3.0, 2e-4);
  // Sees() keeps to the world at the start.
  EXPECT_FALSE(sim->Sees(0, {8, 0}));
}

}  // namespace
}  // namespace lrfnet::sim
