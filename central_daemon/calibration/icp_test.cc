#include "central_daemon/calibration/icp.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <tuple>
#include <vector>

namespace lrfnet::calib {
namespace {

using common::DegToRad;
using common::RadToDeg;
using Eigen::Vector2d;

// ---------------------------------------------------------------------------------------------
// A tiny ray caster: world segments -> one sensor's background ranges.

struct Wall {
  Vector2d a, b;
};

std::vector<Wall> Polyline(std::initializer_list<Vector2d> points) {
  std::vector<Wall> walls;
  const std::vector<Vector2d> p(points);
  for (std::size_t i = 0; i + 1 < p.size(); ++i) walls.push_back({p[i], p[i + 1]});
  return walls;
}

std::vector<Wall> Box(double x0, double y0, double x1, double y1) {
  return Polyline({{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}, {x0, y0}});
}

void Append(std::vector<Wall>& to, const std::vector<Wall>& walls) {
  to.insert(to.end(), walls.begin(), walls.end());
}

double Cross(const Vector2d& a, const Vector2d& b) { return a.x() * b.y() - a.y() * b.x(); }

struct ScannerModel {
  double first_deg = -135.0;
  double step_deg = 0.5;
  int beams = 541;
  double range_m = 20.0;
};

BackgroundScan Cast(const std::vector<Wall>& world, const Pose2& world_from_sensor,
                    const ScannerModel& model, double noise_m = 0.0, unsigned seed = 1) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, noise_m);
  BackgroundScan scan;
  scan.first_angle_rad = DegToRad(model.first_deg);
  scan.angle_step_rad = DegToRad(model.step_deg);
  const Vector2d origin = world_from_sensor.translation();
  for (int i = 0; i < model.beams; ++i) {
    const double angle = world_from_sensor.yaw_rad + scan.first_angle_rad + i * scan.angle_step_rad;
    const Vector2d dir(std::cos(angle), std::sin(angle));
    double best = HUGE_VAL;
    for (const Wall& w : world) {
      const Vector2d e = w.b - w.a;
      const double denom = Cross(dir, e);
      if (std::abs(denom) < 1e-12) continue;
      const double t = Cross(w.a - origin, e) / denom;
      const double u = Cross(w.a - origin, dir) / denom;
      if (t > 1e-6 && u >= 0.0 && u <= 1.0) best = std::min(best, t);
    }
    std::uint32_t range_mm = 0;
    if (best <= model.range_m) {
      const double noisy = best + (noise_m > 0.0 ? noise(rng) : 0.0);
      range_mm = static_cast<std::uint32_t>(std::lround(std::max(noisy, 0.001) * 1000.0));
    }
    scan.ranges_mm.push_back(range_mm);
  }
  return scan;
}

// The computer-lab-like L-shaped room with a rack, monitors and a pillar.
std::vector<Wall> LabWorld() {
  std::vector<Wall> world = Polyline({{0, 0}, {8, 0}, {8, 3.5}, {4, 3.5}, {4, 7}, {0, 7}, {0, 0}});
  Append(world, Box(0.1, 2.6, 0.7, 3.4));
  Append(world, Box(1.3, 1.75, 1.85, 1.85));
  Append(world, Box(5.1, 1.75, 5.65, 1.85));
  Append(world, Box(5.8, 2.6, 6.1, 2.9));
  return world;
}

const Pose2 kWorldFromR{0.3, 0.3, DegToRad(45.0)};
const Pose2 kWorldFromS{7.7, 3.2, DegToRad(-135.0)};

Pose2 TrueSFromR(const Pose2& world_from_r, const Pose2& world_from_s) {
  return world_from_s.inverse() * world_from_r;
}

Pose2 Perturb(const Pose2& pose, double dx, double dy, double dyaw_deg) {
  return {pose.x_m + dx, pose.y_m + dy, common::NormalizeAngle(pose.yaw_rad + DegToRad(dyaw_deg))};
}

double TranslationError(const Pose2& a, const Pose2& b) {
  return common::TranslationDistanceM(a, b);
}
double YawErrorDeg(const Pose2& a, const Pose2& b) {
  return RadToDeg(common::RotationDistanceRad(a, b));
}

// ---------------------------------------------------------------------------------------------

TEST(IcpOptions, DefaultsAreValidAndBadValuesAreNamed) {
  EXPECT_EQ(Validate(IcpOptions{}), std::nullopt);
  IcpOptions o;
  o.final_correspondence_m = 0.0;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.initial_correspondence_m = 0.05;  // below the final distance
  ASSERT_TRUE(Validate(o));
  EXPECT_NE(Validate(o)->find("initial_correspondence_m"), std::string::npos);
  o = {};
  o.trim_fraction = 1.0;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.min_correspondences = 2;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.max_range_m = std::nan("");
  EXPECT_NE(Validate(o), std::nullopt);
}

TEST(BackgroundPoints, FollowTheSensorFrameConvention) {
  BackgroundScan scan;
  scan.first_angle_rad = DegToRad(-90.0);
  scan.angle_step_rad = DegToRad(90.0);
  scan.ranges_mm = {1000, 2000, 0, 3000};  // right, forward, left (no return), behind
  const auto points = BackgroundPoints(scan, 10.0);
  ASSERT_EQ(points.size(), 3u);
  EXPECT_NEAR(points[0].x(), 0.0, 1e-12);
  EXPECT_NEAR(points[0].y(), -1.0, 1e-12);
  EXPECT_NEAR(points[1].x(), 2.0, 1e-12);
  EXPECT_NEAR(points[1].y(), 0.0, 1e-12);
  EXPECT_NEAR(points[2].x(), -3.0, 1e-12);
  EXPECT_EQ(BackgroundPoints(scan, 2.5).size(), 2u);  // beyond max range: ignored
  EXPECT_EQ(BackgroundPoints(scan, 0.0).size(), 3u);  // no limit

  scan.first_angle_rad = DegToRad(180.0);  // the same beams, clockwise
  scan.angle_step_rad = DegToRad(-90.0);
  scan.ranges_mm = {3000, 0, 2000, 1000};
  const auto reversed = BackgroundPoints(scan, 10.0);
  ASSERT_EQ(reversed.size(), 3u);
  EXPECT_NEAR(reversed[2].y(), -1.0, 1e-12);
  EXPECT_NEAR(reversed[1].x(), 2.0, 1e-12);

  scan.angle_step_rad = 0.0;
  EXPECT_TRUE(BackgroundPoints(scan, 10.0).empty());
}

TEST(CheckBackground, NamesWhatIsWrong) {
  BackgroundScan scan;
  ASSERT_TRUE(CheckBackground(scan));
  EXPECT_NE(CheckBackground(scan)->find("no beams"), std::string::npos);
  scan.ranges_mm.assign(541, 5000);
  scan.first_angle_rad = DegToRad(-135.0);
  scan.angle_step_rad = DegToRad(0.5);
  EXPECT_EQ(CheckBackground(scan), std::nullopt);
  scan.angle_step_rad = -scan.angle_step_rad;
  EXPECT_EQ(CheckBackground(scan), std::nullopt);
  scan.angle_step_rad = 0.0;
  EXPECT_NE(CheckBackground(scan)->find("zero"), std::string::npos);
  scan.angle_step_rad = std::nan("");
  EXPECT_NE(CheckBackground(scan)->find("not finite"), std::string::npos);
  scan.angle_step_rad = DegToRad(0.5);
  scan.ranges_mm.assign(1000, 5000);  // 500 deg: the count does not match the step
  EXPECT_NE(CheckBackground(scan)->find("full turn"), std::string::npos);
  scan.ranges_mm.assign(kMaxIcpBeams + 1, 5000);
  scan.angle_step_rad = 1e-5;
  EXPECT_NE(CheckBackground(scan), std::nullopt);
}

TEST(SolvePointToLine, IsExactForLargeRotationsInOneSolve) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const Pose2 truth{3.0, -2.0, DegToRad(140.0)};  // far beyond any small-angle linearisation
  std::vector<internal::LineCorrespondence> cs;
  for (int i = 0; i < 40; ++i) {
    const Vector2d p_r(5.0 * uniform(rng), 5.0 * uniform(rng));
    const double normal_angle = common::kPi * uniform(rng);
    const Vector2d n(std::cos(normal_angle), std::sin(normal_angle));
    // q anywhere on the line through truth * p with normal n.
    const Vector2d q = truth * p_r + 0.7 * uniform(rng) * Vector2d(-n.y(), n.x());
    cs.push_back({p_r, q, n});
  }
  const auto pose = internal::SolvePointToLine(cs);
  ASSERT_TRUE(pose);
  EXPECT_NEAR(pose->x_m, truth.x_m, 1e-9);
  EXPECT_NEAR(pose->y_m, truth.y_m, 1e-9);
  EXPECT_NEAR(common::AngleDiff(pose->yaw_rad, truth.yaw_rad), 0.0, 1e-10);

  for (auto& c : cs) c.n_s = Vector2d::UnitY();  // all lines parallel: translation unconstrained
  EXPECT_FALSE(internal::SolvePointToLine(cs));
}

// ---------------------------------------------------------------------------------------------
// The lab: two 270 deg sensors in opposite corners share most of the room.

struct Lab {
  std::vector<Wall> world = LabWorld();
  Pose2 truth = TrueSFromR(kWorldFromR, kWorldFromS);
  BackgroundScan r, s;
  explicit Lab(double noise_m = 0.0, const ScannerModel& model = {}) {
    r = Cast(world, kWorldFromR, model, noise_m, 11);
    s = Cast(world, kWorldFromS, model, noise_m, 12);
  }
};

TEST(RefineWithBackgrounds, RecoversThePoseFromPerturbedStartsWithoutNoise) {
  const Lab lab;
  for (const auto& [dx, dy, dyaw] : {std::tuple{0.2, 0.0, 2.0}, std::tuple{0.0, -0.2, -2.0},
                                     std::tuple{-0.14, 0.14, 2.0}, std::tuple{0.14, 0.14, -2.0}}) {
    SCOPED_TRACE(::testing::Message() << "perturbation " << dx << ", " << dy << ", " << dyaw);
    const Pose2 initial = Perturb(lab.truth, dx, dy, dyaw);
    const IcpResult result = RefineWithBackgrounds(lab.r, lab.s, initial, IcpOptions{});
    ASSERT_TRUE(result.applied) << result.reason;
    EXPECT_EQ(result.reason, "");
    EXPECT_LT(TranslationError(result.s_from_r, lab.truth), 0.01);
    EXPECT_LT(YawErrorDeg(result.s_from_r, lab.truth), 0.05);
    EXPECT_LT(result.score_after, result.score_before);
    EXPECT_GT(result.inliers_after, result.inliers_before);
    EXPECT_GE(result.correspondences, 200u);
    EXPECT_EQ(result.degenerate_directions, 0);
    EXPECT_LT(result.rms_m, 0.005);

    // Swapping the sensors gives the inverse pose. (The 2 deg error of the start moves the
    // inverse's translation by another 0.3 m at the 8 m between the sensors: wider bounds.)
    IcpOptions wide;
    wide.max_translation_change_m = 1.0;
    const IcpResult swapped = RefineWithBackgrounds(lab.s, lab.r, initial.inverse(), wide);
    ASSERT_TRUE(swapped.applied) << swapped.reason;
    EXPECT_LT(TranslationError(swapped.s_from_r.inverse(), result.s_from_r), 0.002);
    EXPECT_LT(YawErrorDeg(swapped.s_from_r.inverse(), result.s_from_r), 0.02);
  }
}

TEST(RefineWithBackgrounds, StaysWithinTheNoiseAndReportsAMatchingCovariance) {
  const Lab lab(0.012);  // the simulated LMS1xx range noise
  const Pose2 initial = Perturb(lab.truth, 0.2, 0.0, 2.0);
  const IcpResult result = RefineWithBackgrounds(lab.r, lab.s, initial, IcpOptions{});
  ASSERT_TRUE(result.applied) << result.reason;
  EXPECT_LT(TranslationError(result.s_from_r, lab.truth), 0.01);
  EXPECT_LT(YawErrorDeg(result.s_from_r, lab.truth), 0.1);
  // The residual is about the range noise of r's points (s's lines average several beams).
  EXPECT_GT(result.rms_m, 0.006);
  EXPECT_LT(result.rms_m, 0.015);
  const double sigma_x = std::sqrt(result.covariance(0, 0));
  const double sigma_yaw_deg = RadToDeg(std::sqrt(result.covariance(2, 2)));
  EXPECT_GT(sigma_x, 1e-4);
  EXPECT_LT(sigma_x, 0.01);
  EXPECT_GT(sigma_yaw_deg, 1e-3);
  EXPECT_LT(sigma_yaw_deg, 0.1);
  EXPECT_NEAR(result.covariance(0, 1), result.covariance(1, 0), 1e-15);
}

TEST(RefineWithBackgrounds, WorksWithLms5xxResolutionAndClockwiseBeams) {
  const ScannerModel lms5xx{-95.0, 1.0 / 6.0, 1141, 40.0};
  const Lab lab(0.01, lms5xx);
  const Pose2 initial = Perturb(lab.truth, -0.15, 0.1, -2.0);
  const IcpResult result = RefineWithBackgrounds(lab.r, lab.s, initial, IcpOptions{});
  ASSERT_TRUE(result.applied) << result.reason;
  EXPECT_LT(TranslationError(result.s_from_r, lab.truth), 0.01);
  EXPECT_LT(YawErrorDeg(result.s_from_r, lab.truth), 0.1);

  // The same scans with the beams listed clockwise give the same answer.
  BackgroundScan r_cw = lab.r, s_cw = lab.s;
  for (BackgroundScan* scan : {&r_cw, &s_cw}) {
    scan->first_angle_rad += static_cast<double>(scan->ranges_mm.size() - 1) * scan->angle_step_rad;
    scan->angle_step_rad = -scan->angle_step_rad;
    std::reverse(scan->ranges_mm.begin(), scan->ranges_mm.end());
  }
  const IcpResult clockwise = RefineWithBackgrounds(r_cw, s_cw, initial, IcpOptions{});
  ASSERT_TRUE(clockwise.applied) << clockwise.reason;
  EXPECT_LT(TranslationError(clockwise.s_from_r, result.s_from_r), 1e-6);
  EXPECT_LT(YawErrorDeg(clockwise.s_from_r, result.s_from_r), 1e-6);
}

TEST(RefineWithBackgrounds, AGoodEstimateIsKeptWhenNothingImproves) {
  const Lab lab;
  const IcpResult result = RefineWithBackgrounds(lab.r, lab.s, lab.truth, IcpOptions{});
  EXPECT_FALSE(result.applied);
  EXPECT_NE(result.reason.find("no improvement"), std::string::npos) << result.reason;
  EXPECT_EQ(result.s_from_r.x_m, lab.truth.x_m);
  EXPECT_EQ(result.s_from_r.yaw_rad, lab.truth.yaw_rad);
  EXPECT_NEAR(result.score_after, result.score_before, 0.002);
}

TEST(RefineWithBackgrounds, DoesNotFollowTheIcpIntoAnotherBasin) {
  const Lab lab;
  // The ICP would find the truth 0.2 m away, but the bounds say the estimate is better than that.
  IcpOptions tight;
  tight.max_translation_change_m = 0.1;
  const Pose2 initial = Perturb(lab.truth, 0.2, 0.0, 0.0);
  const IcpResult bounded = RefineWithBackgrounds(lab.r, lab.s, initial, tight);
  EXPECT_FALSE(bounded.applied);
  EXPECT_NE(bounded.reason.find("moved too far"), std::string::npos) << bounded.reason;
  EXPECT_EQ(bounded.s_from_r.x_m, initial.x_m);

  // Far from the basin (1.5 m, 25 deg): whatever the ICP finds is not applied.
  const Pose2 wild = Perturb(lab.truth, 1.0, -1.1, 25.0);
  const IcpResult result = RefineWithBackgrounds(lab.r, lab.s, wild, IcpOptions{});
  EXPECT_FALSE(result.applied);
  EXPECT_FALSE(result.reason.empty());
  EXPECT_EQ(result.s_from_r.x_m, wild.x_m);
  EXPECT_EQ(result.s_from_r.y_m, wild.y_m);
  EXPECT_EQ(result.s_from_r.yaw_rad, wild.yaw_rad);
}

TEST(RefineWithBackgrounds, RefusesWithoutCommonBackground) {
  // Two closed rooms 20 m apart: each sensor sees only its own.
  std::vector<Wall> world = Box(0, 0, 5, 4);
  Append(world, Box(20, 0, 25, 4));
  const Pose2 world_from_r{1.0, 1.0, DegToRad(30.0)};
  const Pose2 world_from_s{24.0, 3.0, DegToRad(-150.0)};
  const BackgroundScan r = Cast(world, world_from_r, {});
  const BackgroundScan s = Cast(world, world_from_s, {});
  const Pose2 truth = TrueSFromR(world_from_r, world_from_s);
  for (const Pose2& initial : {truth, Perturb(truth, 0.3, 0.3, 3.0)}) {
    const IcpResult result = RefineWithBackgrounds(r, s, initial, IcpOptions{});
    EXPECT_FALSE(result.applied);
    EXPECT_NE(result.reason.find("too few common background points"), std::string::npos)
        << result.reason;
    EXPECT_EQ(result.s_from_r.x_m, initial.x_m);
    EXPECT_EQ(result.score_before, 1.0);  // nothing of either background matches the other
    EXPECT_EQ(result.inliers_before, 0u);
  }
}

TEST(RefineWithBackgrounds, DoesNotMatchTheTwoFacesOfAThinWall) {
  // A 10 cm partition between the sensors: each sees only its own face.
  const std::vector<Wall> world = Box(-5, 0, 5, 0.1);
  const Pose2 world_from_r{0.0, -2.0, DegToRad(90.0)};
  const Pose2 world_from_s{1.0, 2.1, DegToRad(-90.0)};
  const BackgroundScan r = Cast(world, world_from_r, {});
  const BackgroundScan s = Cast(world, world_from_s, {});
  const Pose2 truth = TrueSFromR(world_from_r, world_from_s);
  const IcpResult result = RefineWithBackgrounds(r, s, truth, IcpOptions{});
  EXPECT_FALSE(result.applied);
  EXPECT_NE(result.reason.find("too few common background points"), std::string::npos)
      << result.reason;
  EXPECT_EQ(result.s_from_r.y_m, truth.y_m);
}

TEST(RefineWithBackgrounds, DoesNotWanderAlongACorridor) {
  // Two long parallel walls, no end within range: the axis (world x) is unobservable.
  std::vector<Wall> world = Polyline({{-100, 0}, {100, 0}});
  Append(world, Polyline({{-100, 3}, {100, 3}}));
  const Pose2 world_from_r{0.0, 1.5, DegToRad(10.0)};
  const Pose2 world_from_s{4.0, 1.2, DegToRad(170.0)};
  const Pose2 truth = TrueSFromR(world_from_r, world_from_s);
  // The corridor's axis and normal in s's frame; start 0.3 m off along it, 0.1 m across, 1 deg.
  const Vector2d axis_s = world_from_s.rotation().transpose() * Vector2d::UnitX();
  const Vector2d normal_s = world_from_s.rotation().transpose() * Vector2d::UnitY();
  const Vector2d offset = 0.3 * axis_s + 0.1 * normal_s;
  const Pose2 initial = Perturb(truth, offset.x(), offset.y(), 1.0);
  // The raw range noise of an LMS1xx (a learned background is smoother), several draws: the
  // normals' noise must not pass for information along the axis.
  for (unsigned seed = 1; seed <= 6; ++seed) {
    SCOPED_TRACE(::testing::Message() << "seed " << seed);
    const BackgroundScan r = Cast(world, world_from_r, {}, 0.012, seed);
    const BackgroundScan s = Cast(world, world_from_s, {}, 0.012, 100 + seed);
    const IcpResult result = RefineWithBackgrounds(r, s, initial, IcpOptions{});
    ASSERT_TRUE(result.applied) << result.reason;
    EXPECT_EQ(result.degenerate_directions, 1);
    const Vector2d error = result.s_from_r.translation() - truth.translation();
    EXPECT_LT(std::abs(error.dot(normal_s)), 0.005);  // across: corrected
    EXPECT_LT(YawErrorDeg(result.s_from_r, truth), 0.1);
    EXPECT_NEAR(error.dot(axis_s), 0.3, 0.002);  // along: the initial estimate, not a wander
    // The covariance says so: along the axis it is the bound, across it is millimetres.
    const Eigen::Matrix2d cov = result.covariance.topLeftCorner<2, 2>();
    EXPECT_GT(std::sqrt(axis_s.dot(cov * axis_s)), 0.1);
    EXPECT_LT(std::sqrt(normal_s.dot(cov * normal_s)), 0.005);

    if (seed == 1) {
      // Refusing instead of keeping the initial estimate along the axis is the caller's choice.
      IcpOptions strict;
      strict.max_degenerate_directions = 0;
      const IcpResult refused = RefineWithBackgrounds(r, s, initial, strict);
      EXPECT_FALSE(refused.applied);
      EXPECT_NE(refused.reason.find("determines only 2 of the 3 directions"), std::string::npos)
          << refused.reason;
      EXPECT_EQ(refused.s_from_r.x_m, initial.x_m);
    }
  }
}

TEST(RefineWithBackgrounds, AlignsSensorsSharingOneCorridorOfAJunction) {
  // Corridors round two blocks (Schenk et al.'s setup C): the sensors in the two west corners
  // share the west corridor and see little else of each other's background; faces of the blocks
  // that only one of them sees invite wrong pairs while the correspondence distance is wide.
  std::vector<Wall> world = Box(0, 0, 30, 14);
  Append(world, Box(2, 2, 14, 12));
  Append(world, Box(16, 2, 28, 12));
  const ScannerModel lms151{-135.0, 0.5, 541, 50.0};
  const Pose2 world_from_r{0.4, 0.4, DegToRad(45.0)};
  const Pose2 world_from_s{0.4, 13.6, DegToRad(-45.0)};
  const BackgroundScan r = Cast(world, world_from_r, lms151, 0.003, 3);
  const BackgroundScan s = Cast(world, world_from_s, lms151, 0.003, 4);
  const Pose2 truth = TrueSFromR(world_from_r, world_from_s);
  for (const Pose2& initial : {truth, Perturb(truth, 0.05, -0.03, 0.5)}) {
    const IcpResult result = RefineWithBackgrounds(r, s, initial, IcpOptions{});
    EXPECT_LT(TranslationError(result.s_from_r, truth), 0.005) << result.reason;
    EXPECT_LT(YawErrorDeg(result.s_from_r, truth), 0.05);
  }
}

TEST(RefineWithBackgrounds, IgnoresBeamsBeyondRangeAndHugeRanges) {
  Lab lab(0.005);
  for (std::size_t i = 0; i < lab.r.ranges_mm.size(); i += 7) lab.r.ranges_mm[i] = 4000000000u;
  const Pose2 initial = Perturb(lab.truth, 0.1, 0.1, 1.0);
  const IcpResult result = RefineWithBackgrounds(lab.r, lab.s, initial, IcpOptions{});
  ASSERT_TRUE(result.applied) << result.reason;
  EXPECT_LT(TranslationError(result.s_from_r, lab.truth), 0.01);

  BackgroundScan far = lab.r;
  std::fill(far.ranges_mm.begin(), far.ranges_mm.end(), 4000000000u);
  const IcpResult none = RefineWithBackgrounds(far, lab.s, initial, IcpOptions{});
  EXPECT_FALSE(none.applied);
  EXPECT_NE(none.reason.find("r background has 0 points"), std::string::npos) << none.reason;
}

TEST(RefineWithBackgrounds, BadInputGivesAReasonNotAPose) {
  const Lab lab;
  const Pose2 initial = Perturb(lab.truth, 0.1, 0.0, 1.0);
  const auto reason_for = [&](const BackgroundScan& r, const BackgroundScan& s, const Pose2& pose,
                              const IcpOptions& options = {}) {
    const IcpResult result = RefineWithBackgrounds(r, s, pose, options);
    EXPECT_FALSE(result.applied);
    if (std::isfinite(pose.x_m)) {
      EXPECT_EQ(result.s_from_r.x_m, pose.x_m);
    }
    EXPECT_EQ(result.iterations, 0);
    return result.reason;
  };
  EXPECT_NE(reason_for(BackgroundScan{}, lab.s, initial).find("r: background has no beams"),
            std::string::npos);
  BackgroundScan zeros = lab.s;
  std::fill(zeros.ranges_mm.begin(), zeros.ranges_mm.end(), 0u);
  EXPECT_NE(reason_for(lab.r, zeros, initial).find("s background has 0 points"), std::string::npos);
  BackgroundScan no_step = lab.s;
  no_step.angle_step_rad = 0.0;
  EXPECT_NE(reason_for(lab.r, no_step, initial).find("s: background angle step is zero"),
            std::string::npos);
  BackgroundScan too_many = lab.r;
  too_many.ranges_mm.resize(900, 5000);  // 541 -> 900 beams of 0.5 deg: 449.5 deg
  EXPECT_NE(reason_for(too_many, lab.s, initial).find("full turn"), std::string::npos);
  EXPECT_NE(reason_for(lab.r, lab.s, Pose2{std::nan(""), 0.0, 0.0}).find("not finite"),
            std::string::npos);
  IcpOptions bad;
  bad.max_iterations = 0;
  EXPECT_NE(reason_for(lab.r, lab.s, initial, bad).find("invalid ICP options"), std::string::npos);
}

TEST(RefineWithBackgrounds, SurvivesArbitraryBackgrounds) {
  // Random beam counts, angles, ranges (zero, tiny, huge, repeated) and poses: a result, never a
  // crash; when not applied, the initial pose unchanged.
  std::mt19937 rng(17);
  std::uniform_int_distribution<int> beams(0, 1500);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const auto random_scan = [&] {
    BackgroundScan scan;
    scan.ranges_mm.resize(static_cast<std::size_t>(beams(rng)));
    scan.first_angle_rad = (unit(rng) - 0.5) * 8.0;
    scan.angle_step_rad = (unit(rng) - 0.5) * 0.01;
    const double kind = unit(rng);
    for (std::uint32_t& range : scan.ranges_mm) {
      const double u = unit(rng);
      range = kind < 0.3   ? static_cast<std::uint32_t>(u * 4.0e9)
              : kind < 0.6 ? static_cast<std::uint32_t>(1000 + u * 20000)
              : kind < 0.8 ? (u < 0.5 ? 0u : 5000u)
                           : static_cast<std::uint32_t>(u * 3.0);
    }
    return scan;
  };
  int ran = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const BackgroundScan r = random_scan();
    const BackgroundScan s = unit(rng) < 0.3 ? r : random_scan();
    const Pose2 initial{(unit(rng) - 0.5) * 20.0, (unit(rng) - 0.5) * 20.0, unit(rng) * 6.0 - 3.0};
    const IcpResult result = RefineWithBackgrounds(r, s, initial, IcpOptions{});
    if (!result.applied) {
      EXPECT_FALSE(result.reason.empty());
      EXPECT_EQ(result.s_from_r.x_m, initial.x_m);
      EXPECT_EQ(result.s_from_r.yaw_rad, initial.yaw_rad);
    }
    EXPECT_TRUE(std::isfinite(result.score_after));
    EXPECT_TRUE(result.covariance.allFinite());
    ran += result.iterations > 0 ? 1 : 0;
  }
  EXPECT_GE(ran, 40);  // the ICP itself ran often, not only the input checks
}

TEST(ScoreBackgrounds, IsLowestAtTheTruthAndOneWithoutOverlap) {
  const Lab lab(0.005);
  const auto at_truth = ScoreBackgrounds(lab.r, lab.s, lab.truth, IcpOptions{});
  const auto off = ScoreBackgrounds(lab.r, lab.s, Perturb(lab.truth, 0.05, 0.0, 0.5), IcpOptions{});
  ASSERT_TRUE(at_truth && off);
  EXPECT_LT(at_truth->score, off->score);
  EXPECT_GT(at_truth->inliers, off->inliers);
  EXPECT_EQ(at_truth->points, off->points);
  // Mapping r far away: the fixed denominator gives exactly "nothing in common".
  const auto away = ScoreBackgrounds(lab.r, lab.s, Pose2{100.0, 0.0, 0.0}, IcpOptions{});
  ASSERT_TRUE(away);
  EXPECT_EQ(away->score, 1.0);
  EXPECT_FALSE(ScoreBackgrounds(BackgroundScan{}, lab.s, lab.truth, IcpOptions{}));
}

}  // namespace
}  // namespace lrfnet::calib
