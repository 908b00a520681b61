#include "central_daemon/calibration/schenk.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace lrfnet::calib {
namespace {

using common::DegToRad;
using common::kPi;
using common::RadToDeg;

constexpr double kStepS = 0.05;

// ---------------------------------------------------------------------------------------------
// A small synthetic world: a walled room, sensors at known poses, objects on known paths.

struct Segment {
  Eigen::Vector2d a, b;
};

struct SimSensor {
  std::string id;
  Pose2 world_from_sensor;
  double range_m = 30.0;
  double fov_rad = DegToRad(270.0);
};

struct SimObject {
  std::function<Eigen::Vector2d(double)> world_at;  // time in seconds → world position
  double enter_s = 0.0;
  double leave_s = 1e9;
  std::vector<bool> seen_by;  // empty: every sensor that covers it
};

struct World {
  std::vector<Segment> walls;
  std::vector<SimSensor> sensors;
  std::vector<SimObject> objects;
  double duration_s = 40.0;
  double track_noise_m = 0.02;
  double com_bias_m = 0.0;  // observed position pulled towards the sensor (one-sided view)
  double background_noise_m = 0.003;
  bool backgrounds = true;
  std::uint32_t seed = 1;
};

void AddBox(std::vector<Segment>& walls, double x0, double y0, double x1, double y1) {
  walls.push_back({{x0, y0}, {x1, y0}});
  walls.push_back({{x1, y0}, {x1, y1}});
  walls.push_back({{x1, y1}, {x0, y1}});
  walls.push_back({{x0, y1}, {x0, y0}});
}

// Nearest hit of the ray o + t d (|d| = 1, t > 0) with the walls, or +inf.
double CastRay(const std::vector<Segment>& walls, const Eigen::Vector2d& o,
               const Eigen::Vector2d& d) {
  double best = std::numeric_limits<double>::infinity();
  for (const Segment& w : walls) {
    const Eigen::Vector2d e = w.b - w.a;
    const double den = d.x() * (-e.y()) - d.y() * (-e.x());
    if (std::abs(den) < 1e-12) continue;
    const Eigen::Vector2d rhs = w.a - o;
    const double t = (rhs.x() * (-e.y()) - rhs.y() * (-e.x())) / den;
    const double u = (d.x() * rhs.y() - d.y() * rhs.x()) / den;
    if (t > 1e-9 && u >= 0.0 && u <= 1.0) best = std::min(best, t);
  }
  return best;
}

BackgroundScan RayCastBackground(const World& world, const SimSensor& sensor, std::mt19937& rng) {
  std::normal_distribution<double> noise(0.0, world.background_noise_m);
  BackgroundScan scan;
  scan.angle_step_rad = DegToRad(0.5);
  scan.first_angle_rad = -sensor.fov_rad / 2.0;
  const auto beams =
      static_cast<std::size_t>(std::lround(sensor.fov_rad / scan.angle_step_rad)) + 1;
  for (std::size_t i = 0; i < beams; ++i) {
    const double angle = scan.first_angle_rad + static_cast<double>(i) * scan.angle_step_rad;
    const double yaw = sensor.world_from_sensor.yaw_rad + angle;
    const double range = CastRay(world.walls, sensor.world_from_sensor.translation(),
                                 {std::cos(yaw), std::sin(yaw)});
    if (!(range < sensor.range_m)) {
      scan.ranges_mm.push_back(0);
      continue;
    }
    scan.ranges_mm.push_back(
        static_cast<std::uint32_t>(std::lround((range + noise(rng)) * 1000.0)));
  }
  return scan;
}

bool Covers(const SimSensor& sensor, const Eigen::Vector2d& world_p) {
  const Eigen::Vector2d p = sensor.world_from_sensor.inverse() * world_p;
  return p.norm() < sensor.range_m && std::abs(std::atan2(p.y(), p.x())) < sensor.fov_rad / 2.0;
}

AlignedTracks Simulate(const World& world) {
  std::mt19937 rng(world.seed);
  std::normal_distribution<double> noise(0.0, world.track_noise_m);
  AlignedTracks out;
  out.step_s = kStepS;
  out.steps = static_cast<std::size_t>(world.duration_s / kStepS);
  for (const SimSensor& sensor : world.sensors) {
    SensorTracks st;
    st.id = sensor.id;
    if (world.backgrounds) st.background = RayCastBackground(world, sensor, rng);
    std::uint32_t next_id = 1;
    for (std::size_t o = 0; o < world.objects.size(); ++o) {
      const SimObject& obj = world.objects[o];
      const std::size_t sensor_index = out.sensors.size();
      if (!obj.seen_by.empty() && !obj.seen_by[sensor_index]) continue;
      GridTrack current;
      bool open = false;
      for (std::size_t k = 0; k <= out.steps; ++k) {
        const double t = static_cast<double>(k) * kStepS;
        const bool visible =
            k < out.steps && t >= obj.enter_s && t < obj.leave_s && Covers(sensor, obj.world_at(t));
        if (visible) {
          if (!open) {
            current = GridTrack{};
            current.track_id = next_id++;
            current.first_step = k;
            open = true;
          }
          Eigen::Vector2d p = sensor.world_from_sensor.inverse() * obj.world_at(t);
          p -= world.com_bias_m * p.normalized();
          TrackSample sample;
          sample.position_m = p + Eigen::Vector2d(noise(rng), noise(rng));
          current.samples.push_back(sample);
        } else if (open) {
          st.tracks.push_back(std::move(current));
          open = false;
        }
      }
    }
    std::sort(st.tracks.begin(), st.tracks.end(),
              [](const GridTrack& a, const GridTrack& b) { return a.first_step < b.first_step; });
    out.sensors.push_back(std::move(st));
  }
  return out;
}

// Lissajous paths: curved everywhere, so every track segment fixes a rotation.
std::function<Eigen::Vector2d(double)> Circle(double cx, double cy, double radius_m,
                                              double rate_rad_s) {
  return [=](double t) -> Eigen::Vector2d {
    return {cx + radius_m * std::cos(rate_rad_s * t), cy + radius_m * std::sin(rate_rad_s * t)};
  };
}

std::function<Eigen::Vector2d(double)> Lissajous(double cx, double cy, double ax, double ay,
                                                 double wx, double wy, double phase) {
  return [=](double t) -> Eigen::Vector2d {
    return {cx + ax * std::sin(wx * t + phase), cy + ay * std::sin(wy * t)};
  };
}

// A 19 m x 10 m hall with a few objects along the walls (like setup A of the paper), sensors in
// the corners looking at the walking area (x 2..17, y 2..8).
World Hall(std::size_t sensor_count) {
  World w;
  AddBox(w.walls, 0.0, 0.0, 19.0, 10.0);
  AddBox(w.walls, 4.0, 9.4, 8.0, 9.9);    // cabinets
  AddBox(w.walls, 12.0, 0.2, 14.0, 0.8);  // table
  AddBox(w.walls, 9.3, 9.3, 9.7, 9.7);    // pillar
  AddBox(w.walls, 0.2, 4.5, 0.7, 5.5);    // box
  const std::vector<SimSensor> all = {
      {"a", {1.0, 1.0, DegToRad(20.0)}},
      {"b", {18.0, 1.0, DegToRad(160.0)}},
      {"c", {18.0, 9.0, DegToRad(-160.0)}},
      {"d", {1.0, 9.0, DegToRad(-20.0)}},
  };
  w.sensors.assign(all.begin(), all.begin() + static_cast<std::ptrdiff_t>(sensor_count));
  // One person at a time, as in most of the paper's scenes (smooth paths of two simultaneous
  // people can be locally congruent, which the shape-based association cannot tell apart).
  w.duration_s = 50.0;
  w.objects.push_back(SimObject{Lissajous(9.5, 5.0, 6.5, 2.8, 0.21, 0.33, 0.3), 0.0, 25.0, {}});
  w.objects.push_back(SimObject{Lissajous(9.0, 5.2, 5.0, 2.5, 0.37, 0.23, 1.9), 25.0, 50.0, {}});
  return w;
}

// The truth expressed with `reference` at the origin, as the calibration reports it.
Pose2 TruthInReference(const World& w, std::size_t reference, std::size_t i) {
  return w.sensors[reference].world_from_sensor.inverse() * w.sensors[i].world_from_sensor;
}

struct Errors {
  double max_rot_deg = 0.0;
  double max_trans_m = 0.0;
};

Errors ErrorsOf(const World& w, const SchenkResult& result, std::size_t reference) {
  Errors e;
  for (std::size_t i = 0; i < w.sensors.size(); ++i) {
    const Pose2 truth = TruthInReference(w, reference, i);
    e.max_rot_deg = std::max(
        e.max_rot_deg, RadToDeg(common::RotationDistanceRad(truth, result.world_from_sensor[i])));
    e.max_trans_m =
        std::max(e.max_trans_m, common::TranslationDistanceM(truth, result.world_from_sensor[i]));
  }
  return e;
}

const SchenkEdge* FindEdge(const SchenkResult& result, std::size_t r, std::size_t s) {
  for (const SchenkEdge& e : result.edges) {
    if (e.r == r && e.s == s) return &e;
  }
  return nullptr;
}

// An edge from known poses, optionally disturbed.
SchenkEdge MakeEdge(const std::vector<Pose2>& world_from, std::size_t r, std::size_t s,
                    double weight, Pose2 disturbance = {}) {
  SchenkEdge e;
  e.r = r;
  e.s = s;
  e.s_from_r = disturbance * (world_from[s].inverse() * world_from[r]);
  e.n = 100;
  e.d_m = 100.0 / weight;
  e.weight = weight;
  return e;
}

// ---------------------------------------------------------------------------------------------

TEST(SchenkOptionsTest, DefaultsAreValidAndFollowThePaper) {
  const SchenkOptions o;
  EXPECT_FALSE(Validate(o).has_value());
  EXPECT_DOUBLE_EQ(o.association_threshold_m, 0.2);
  EXPECT_TRUE(o.use_icp);
}

TEST(SchenkOptionsTest, RejectsNonsense) {
  auto bad = [](auto mutate) {
    SchenkOptions o;
    mutate(o);
    return Validate(o).has_value();
  };
  EXPECT_TRUE(bad([](SchenkOptions& o) { o.association_threshold_m = 0.0; }));
  EXPECT_TRUE(bad([](SchenkOptions& o) { o.association_threshold_m = std::nan(""); }));
  EXPECT_TRUE(bad([](SchenkOptions& o) { o.min_common_samples = 2; }));
  EXPECT_TRUE(bad([](SchenkOptions& o) { o.relaxation_iterations = -1; }));
  EXPECT_TRUE(bad([](SchenkOptions& o) { o.relaxation_step = 1.5; }));
  EXPECT_TRUE(bad([](SchenkOptions& o) { o.icp_max_correspondence_m = -0.1; }));
  EXPECT_TRUE(bad([](SchenkOptions& o) { o.icp_iterations = 0; }));
  SchenkOptions o;
  o.min_common_samples = 2;
  const SchenkResult r = CalibrateSchenk(AlignedTracks{}, 0, o);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.message.find("min_common_samples"), std::string::npos);
}

TEST(SchenkAlignTest, RecoversAKnownTransformAndMeasuresMeanDistance) {
  const Pose2 s_from_r{1.5, -2.0, DegToRad(123.0)};
  std::vector<Eigen::Vector2d> r_points, s_points;
  for (int i = 0; i < 50; ++i) {
    const double t = 0.1 * i;
    r_points.emplace_back(3.0 * std::cos(t), 2.0 * std::sin(1.3 * t));
    s_points.push_back(s_from_r * r_points.back());
  }
  PointSetAlignment fit = AlignPointSets(r_points, s_points);
  ASSERT_TRUE(fit.ok);
  EXPECT_NEAR(fit.s_from_r.x_m, 1.5, 1e-9);
  EXPECT_NEAR(fit.s_from_r.y_m, -2.0, 1e-9);
  EXPECT_NEAR(fit.s_from_r.yaw_rad, DegToRad(123.0), 1e-9);
  EXPECT_NEAR(fit.mean_distance_m, 0.0, 1e-9);

  // Eq. 2 is the mean of the Euclidean distances: alternate ±0.1 m offsets perpendicular to a
  // symmetric set leave the optimum in place and give exactly 0.1 m.
  std::vector<Eigen::Vector2d> line_r, line_s;
  for (int i = -10; i <= 10; ++i) {
    line_r.emplace_back(static_cast<double>(i), 0.0);
    line_r.emplace_back(static_cast<double>(i), 1.0);
    line_s.emplace_back(static_cast<double>(i), 0.1 * ((i % 2 == 0) ? 1.0 : -1.0));
    line_s.emplace_back(static_cast<double>(i), 1.0 - 0.1 * ((i % 2 == 0) ? 1.0 : -1.0));
  }
  fit = AlignPointSets(line_r, line_s);
  ASSERT_TRUE(fit.ok);
  EXPECT_NEAR(fit.mean_distance_m, 0.1, 1e-3);

  EXPECT_FALSE(AlignPointSets(std::vector<Eigen::Vector2d>{{0.0, 0.0}},
                              std::vector<Eigen::Vector2d>{{0.0, 0.0}})
                   .ok);
  EXPECT_FALSE(AlignPointSets(r_points, line_s).ok);
}

TEST(SchenkTest, RecoversFourSensorsWithinNoise) {
  World w = Hall(4);
  w.seed = 11;
  const AlignedTracks tracks = Simulate(w);
  for (std::size_t reference : {std::size_t{0}, std::size_t{2}}) {
    const SchenkResult result = CalibrateSchenk(tracks, reference, SchenkOptions{});
    ASSERT_TRUE(result.ok) << result.message;
    EXPECT_EQ(result.world_from_sensor[reference].x_m, 0.0);
    EXPECT_EQ(result.world_from_sensor[reference].yaw_rad, 0.0);
    const Errors e = ErrorsOf(w, result, reference);
    EXPECT_LT(e.max_rot_deg, 0.3) << "reference " << reference;
    EXPECT_LT(e.max_trans_m, 0.04) << "reference " << reference;
    // Six pairs, all with constraints from the two objects (the correct pairs only).
    ASSERT_EQ(result.edges.size(), 6u);
    for (const SchenkEdge& edge : result.edges) {
      EXPECT_GT(edge.n, 0u);
      EXPECT_TRUE(edge.used);
      EXPECT_LT(edge.d_m, 0.05);
      EXPECT_NEAR(edge.weight, static_cast<double>(edge.n) / edge.d_m, 1e-9 * edge.weight);
    }
  }
}

TEST(SchenkTest, ThreeSensorsWithoutBackgroundsStillCalibrate) {
  World w = Hall(3);
  w.backgrounds = false;
  w.seed = 5;
  const SchenkResult result = CalibrateSchenk(Simulate(w), 1, SchenkOptions{});
  ASSERT_TRUE(result.ok) << result.message;
  const Errors e = ErrorsOf(w, result, 1);
  EXPECT_LT(e.max_rot_deg, 0.3);
  EXPECT_LT(e.max_trans_m, 0.04);
  for (const SchenkIcpReport& icp : result.icp) EXPECT_FALSE(icp.applied);
}

TEST(SchenkTest, AssociationThresholdRejectsADifferentObject) {
  // Sensor a sees only object 0; sensor b sees it and, at the same time, a person walking in a
  // tight circle.
  World w = Hall(2);
  w.objects[0].leave_s = 50.0;
  w.objects[0].seen_by = {true, true};
  w.objects[1] = SimObject{Circle(12.0, 5.0, 1.2, 1.0), 0.0, 50.0, {false, true}};
  w.seed = 3;
  const AlignedTracks tracks = Simulate(w);
  const SchenkResult result = CalibrateSchenk(tracks, 0, SchenkOptions{});
  ASSERT_TRUE(result.ok) << result.message;
  const SchenkEdge* edge = FindEdge(result, 0, 1);
  ASSERT_NE(edge, nullptr);
  ASSERT_GT(edge->associations.size(), 0u);
  EXPECT_GT(edge->compared, edge->associations.size());  // the wrong pairs were compared ...
  std::size_t wrong_pairs = 0;
  for (const SchenkAssociation& a : edge->associations) {
    const GridTrack& ta = tracks.sensors[0].tracks[a.track_r];
    const GridTrack& tb = tracks.sensors[1].tracks[a.track_s];
    // ... and only pairs of the same object survive: after the true transform they coincide.
    const Pose2 s_from_r =
        w.sensors[1].world_from_sensor.inverse() * w.sensors[0].world_from_sensor;
    const std::size_t k = std::max(ta.first_step, tb.first_step);
    if ((s_from_r * ta.At(k).position_m - tb.At(k).position_m).norm() > 0.5) ++wrong_pairs;
    EXPECT_LT(a.d_m, 0.2);
  }
  EXPECT_EQ(wrong_pairs, 0u);
  const Errors e = ErrorsOf(w, result, 0);
  EXPECT_LT(e.max_rot_deg, 0.3);
  EXPECT_LT(e.max_trans_m, 0.05);

  // The same wrong pairs pass when the threshold is raised far enough: it is the threshold that
  // keeps them out, and letting them in spoils the constraint.
  SchenkOptions loose;
  loose.association_threshold_m = 50.0;
  const SchenkResult polluted = CalibrateSchenk(tracks, 0, loose);
  const SchenkEdge* loose_edge = FindEdge(polluted, 0, 1);
  ASSERT_NE(loose_edge, nullptr);
  EXPECT_EQ(loose_edge->associations.size(), loose_edge->compared);
  EXPECT_GT(loose_edge->associations.size(), edge->associations.size());
  EXPECT_GT(ErrorsOf(w, polluted, 0).max_trans_m, 0.3);
}

TEST(SchenkTest, GreedyPlacementFollowsDescendingWeight) {
  const std::vector<Pose2> truth = {
      {0.0, 0.0, 0.0}, {5.0, 0.0, 0.5}, {5.0, 5.0, 1.5}, {0.0, 6.0, -2.0}};
  // The direct edges to 2 and 3 are wrong and light; the heavy chain 0-1-2-3 is right.
  const Pose2 wrong{0.7, -0.4, 0.2};
  std::vector<SchenkEdge> edges = {MakeEdge(truth, 0, 1, 10.0), MakeEdge(truth, 0, 2, 3.0, wrong),
                                   MakeEdge(truth, 1, 2, 8.0), MakeEdge(truth, 2, 3, 5.0),
                                   MakeEdge(truth, 0, 3, 1.0, wrong)};
  SchenkPlacement p = PlaceGreedy(4, edges, 0);
  EXPECT_EQ(p.order, (std::vector<std::size_t>{0, 1, 2, 3}));
  EXPECT_TRUE(edges[0].placement);
  EXPECT_FALSE(edges[1].placement);
  EXPECT_TRUE(edges[2].placement);
  EXPECT_TRUE(edges[3].placement);
  EXPECT_FALSE(edges[4].placement);
  for (std::size_t i = 0; i < 4; ++i) {
    EXPECT_TRUE(p.placed[i]);
    EXPECT_LT(common::TranslationDistanceM(p.world_from_sensor[i], truth[i]), 1e-9) << i;
    EXPECT_LT(common::RotationDistanceRad(p.world_from_sensor[i], truth[i]), 1e-9) << i;
  }
  // Eq. 7 along the placement path, the reference infinitely heavy.
  EXPECT_TRUE(std::isinf(p.node_weight[0]));
  EXPECT_DOUBLE_EQ(p.node_weight[1], 10.0);
  EXPECT_DOUBLE_EQ(p.node_weight[2], 10.0 * 8.0 / 18.0);

  // Another root gives the same spanning tree (the maximum-weight one).
  p = PlaceGreedy(4, edges, 3);
  EXPECT_EQ(p.order, (std::vector<std::size_t>{3, 2, 1, 0}));
  EXPECT_TRUE(edges[0].placement && edges[2].placement && edges[3].placement);
  EXPECT_FALSE(edges[1].placement || edges[4].placement);

  // Edges without constraint (n = 0) never place anything.
  std::vector<SchenkEdge> none = {MakeEdge(truth, 0, 1, 10.0)};
  none[0].n = 0;
  p = PlaceGreedy(2, none, 0);
  EXPECT_FALSE(p.placed[1]);
}

// How far the poses are from satisfying the constraints: the weighted sum and the maximum of the
// translation residuals (what eqs. 6-9 relax), and the largest rotation residual.
struct Inconsistency {
  double weighted_translation = 0.0;
  double max_translation_m = 0.0;
  double max_rotation_rad = 0.0;
};
Inconsistency InconsistencyOf(const std::vector<SchenkEdge>& edges,
                              const std::vector<Pose2>& poses) {
  Inconsistency out;
  for (const SchenkEdge& e : edges) {
    const Pose2 predicted = poses[e.s].inverse() * poses[e.r];
    const double dt = common::TranslationDistanceM(predicted, e.s_from_r);
    out.weighted_translation += e.weight * dt;
    out.max_translation_m = std::max(out.max_translation_m, dt);
    out.max_rotation_rad =
        std::max(out.max_rotation_rad, common::RotationDistanceRad(predicted, e.s_from_r));
  }
  return out;
}

TEST(SchenkTest, RelaxationKeepsConsistentPosesAndSpreadsALoopError) {
  const std::vector<Pose2> truth = {
      {0.0, 0.0, 0.0}, {8.0, 0.0, 0.5}, {8.0, 6.0, 2.0}, {0.0, 6.0, -1.0}};
  std::vector<SchenkEdge> edges = {MakeEdge(truth, 0, 1, 10.0), MakeEdge(truth, 1, 2, 9.0),
                                   MakeEdge(truth, 2, 3, 8.0), MakeEdge(truth, 0, 3, 7.0)};
  const std::vector<bool> placed(4, true);
  SchenkOptions options;

  // Consistent constraints are a fixed point (this pins our reading of eq. 10).
  {
    std::vector<SchenkEdge> copy = edges;
    SchenkPlacement p = PlaceGreedy(4, copy, 0);
    std::vector<Pose2> poses = p.world_from_sensor;
    RelaxSchenk(copy, 0, placed, options, poses, p.node_weight);
    for (std::size_t i = 0; i < 4; ++i) {
      EXPECT_LT(common::TranslationDistanceM(poses[i], truth[i]), 1e-6) << i;
      EXPECT_LT(common::RotationDistanceRad(poses[i], truth[i]), 1e-6) << i;
    }
  }

  // Disturb the edge 2-3 of the loop: placement puts all the error on the closing edge 0-3.
  edges[2] = MakeEdge(truth, 2, 3, 8.0, Pose2{0.3, -0.2, DegToRad(1.5)});
  SchenkPlacement p = PlaceGreedy(4, edges, 0);
  ASSERT_FALSE(edges[3].placement);
  std::vector<Pose2> poses = p.world_from_sensor;
  const Inconsistency before = InconsistencyOf(edges, poses);
  const int iterations = RelaxSchenk(edges, 0, placed, options, poses, p.node_weight);
  const Inconsistency after = InconsistencyOf(edges, poses);
  EXPECT_GT(iterations, 1);
  EXPECT_LT(iterations, options.relaxation_iterations);  // converged
  // Placement leaves 0.39 m and 1.5 deg on the closing edge; relaxation spreads them over the loop.
  EXPECT_GT(before.max_translation_m, 0.35);
  EXPECT_LT(after.max_translation_m, 0.5 * before.max_translation_m);
  EXPECT_LT(after.weighted_translation, 0.8 * before.weighted_translation);
  EXPECT_LT(after.max_rotation_rad, 0.8 * before.max_rotation_rad);
  // The reference did not move.
  EXPECT_EQ(poses[0].x_m, 0.0);
  EXPECT_EQ(poses[0].yaw_rad, 0.0);

  // No iterations: placement only.
  options.relaxation_iterations = 0;
  std::vector<Pose2> unrelaxed = p.world_from_sensor;
  EXPECT_EQ(RelaxSchenk(edges, 0, placed, options, unrelaxed, p.node_weight), 0);
  EXPECT_EQ(unrelaxed[3].x_m, p.world_from_sensor[3].x_m);
}

TEST(SchenkTest, SensorWithoutAssociatedTrackIsNotPlacedAndNamed) {
  World w = Hall(4);
  w.sensors[3].id = "lonely";
  // Object 2 is seen by "lonely" alone; it does not see the others.
  w.objects[0].seen_by = {true, true, true, false};
  w.objects[1].seen_by = {true, true, true, false};
  w.objects.push_back(SimObject{Circle(4.0, 7.0, 1.2, 0.8), 0.0, 1e9, {false, false, false, true}});
  const SchenkResult result = CalibrateSchenk(Simulate(w), 0, SchenkOptions{});
  EXPECT_FALSE(result.ok);
  EXPECT_TRUE(result.placed[0] && result.placed[1] && result.placed[2]);
  EXPECT_FALSE(result.placed[3]);
  EXPECT_NE(result.message.find("lonely"), std::string::npos) << result.message;
  EXPECT_NE(result.message.find("no track associated"), std::string::npos) << result.message;
  for (const SchenkEdge& e : result.edges) {
    if (e.s == 3) {
      EXPECT_FALSE(e.used);
    }
  }
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_LT(common::TranslationDistanceM(result.world_from_sensor[i], TruthInReference(w, 0, i)),
              0.05);
  }
}

TEST(SchenkTest, SensorsOnlyConnectedToEachOtherAreNamedAsUnconnected) {
  World w = Hall(4);
  w.objects[0].seen_by = {true, true, false, false};
  w.objects[1].seen_by = {false, false, true, true};
  const SchenkResult result = CalibrateSchenk(Simulate(w), 0, SchenkOptions{});
  EXPECT_FALSE(result.ok);
  EXPECT_TRUE(result.placed[1]);
  EXPECT_FALSE(result.placed[2]);
  EXPECT_FALSE(result.placed[3]);
  EXPECT_NE(result.message.find("'c' (not connected to the reference 'a')"), std::string::npos)
      << result.message;
  EXPECT_NE(result.message.find("'d'"), std::string::npos) << result.message;
}

TEST(SchenkTest, BadReferenceAndBadSamplesGiveStatusNotCrash) {
  World w = Hall(2);
  AlignedTracks tracks = Simulate(w);
  SchenkResult result = CalibrateSchenk(tracks, 7, SchenkOptions{});
  EXPECT_FALSE(result.ok);
  EXPECT_NE(result.message.find("out of range"), std::string::npos);
  EXPECT_FALSE(CalibrateSchenk(AlignedTracks{}, 0, SchenkOptions{}).ok);

  // Non-finite samples are skipped; the rest still calibrates.
  for (GridTrack& t : tracks.sensors[1].tracks) {
    for (std::size_t k = 0; k < t.samples.size(); k += 7) {
      t.samples[k].position_m.x() = std::numeric_limits<double>::quiet_NaN();
    }
  }
  tracks.sensors[0].background->angle_step_rad = std::numeric_limits<double>::infinity();
  result = CalibrateSchenk(tracks, 0, SchenkOptions{});
  ASSERT_TRUE(result.ok) << result.message;
  EXPECT_LT(ErrorsOf(w, result, 0).max_trans_m, 0.05);
}

TEST(SchenkIcpTest, BackgroundPointsFollowTheBeamConvention) {
  BackgroundScan scan;
  scan.first_angle_rad = -kPi / 2.0;
  scan.angle_step_rad = kPi / 2.0;
  scan.ranges_mm = {1000, 0, 2500};  // right, (forward: no return), left
  const auto points = BackgroundPoints(scan);
  ASSERT_EQ(points.size(), 2u);
  EXPECT_NEAR(points[0].x(), 0.0, 1e-12);
  EXPECT_NEAR(points[0].y(), -1.0, 1e-12);
  EXPECT_NEAR(points[1].y(), 2.5, 1e-12);
}

TEST(SchenkIcpTest, CloseRangeIcpImprovesAPerturbedPoseInARayCastRoom) {
  World w = Hall(3);
  w.objects.clear();
  w.seed = 21;
  const AlignedTracks tracks = Simulate(w);
  std::vector<Pose2> poses;
  for (std::size_t i = 0; i < 3; ++i) poses.push_back(TruthInReference(w, 0, i));
  const Pose2 truth2 = poses[2];
  poses[2] = Pose2{0.08, -0.06, DegToRad(0.8)} * poses[2];
  const double rot_before = common::RotationDistanceRad(poses[2], truth2);
  const double trans_before = common::TranslationDistanceM(poses[2], truth2);

  const std::vector<bool> placed(3, true);
  const auto reports = RefineSchenkIcp(tracks, 0, placed, {0, 1, 2}, SchenkOptions{}, poses);
  ASSERT_EQ(reports.size(), 3u);
  EXPECT_FALSE(reports[0].applied);  // the reference stays
  EXPECT_TRUE(reports[2].applied);
  EXPECT_LT(reports[2].mean_distance_after_m, reports[2].mean_distance_before_m);
  EXPECT_GE(reports[2].correspondences, SchenkOptions{}.icp_min_correspondences);
  EXPECT_LT(common::TranslationDistanceM(poses[2], truth2), 0.2 * trans_before);
  EXPECT_LT(common::RotationDistanceRad(poses[2], truth2), 0.2 * rot_before);
  EXPECT_EQ(poses[0].x_m, 0.0);

  // Too far off for close points: nothing pairs up, so the pose stays where it was.
  poses[2] = Pose2{3.0, 2.0, 0.0} * truth2;
  SchenkOptions tight;
  tight.icp_max_correspondence_m = 0.05;
  const Pose2 far = poses[2];
  const auto far_reports = RefineSchenkIcp(tracks, 0, placed, {0, 1, 2}, tight, poses);
  EXPECT_LT(far_reports[2].correspondences, tight.icp_min_correspondences);
  EXPECT_FALSE(far_reports[2].applied);
  EXPECT_EQ(poses[2].x_m, far.x_m);
}

TEST(SchenkIcpTest, IcpRemovesTheOneSidedTrackingOffset) {
  // Each sensor sees the near side of the object: positions pulled 15 cm towards the sensor, an
  // offset of the track-based calibration that the background ICP corrects (III-F).
  World w = Hall(4);
  w.com_bias_m = 0.15;
  w.track_noise_m = 0.01;
  w.seed = 8;
  const AlignedTracks tracks = Simulate(w);
  SchenkOptions no_icp;
  no_icp.use_icp = false;
  const SchenkResult without = CalibrateSchenk(tracks, 0, no_icp);
  const SchenkResult with = CalibrateSchenk(tracks, 0, SchenkOptions{});
  ASSERT_TRUE(without.ok && with.ok);
  const Errors e_without = ErrorsOf(w, without, 0);
  const Errors e_with = ErrorsOf(w, with, 0);
  EXPECT_GT(e_without.max_trans_m, 0.08);
  EXPECT_LT(e_with.max_trans_m, 0.5 * e_without.max_trans_m);
  EXPECT_LT(e_with.max_trans_m, 0.03);
  EXPECT_LT(e_with.max_rot_deg, 0.3);
}

}  // namespace
}  // namespace lrfnet::calib
