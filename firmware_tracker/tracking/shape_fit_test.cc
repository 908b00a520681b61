#include "firmware_tracker/tracking/shape_fit.h"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

#include "common/geometry.h"
#include "firmware_tracker/tracking/pipeline.h"
#include "firmware_tracker/tracking/tracking_test_util.h"

namespace lrfnet::tracking {
namespace {

using testing::Body;

struct View {
  std::vector<Eigen::Vector2d> points;
  Silhouette silhouette;
};

// What a scanner at the origin (beams step_deg apart, range noise sigma noise_m) sees of `body`:
// the points of the beams that hit it and the silhouette, as the pipeline passes them to the fit.
View Look(const Body& body, double step_deg, double noise_m = 0.0, std::uint32_t seed = 1) {
  testing::ScannerConfig config;
  config.first_angle_rad = common::DegToRad(-90.0);
  config.angle_step_rad = common::DegToRad(step_deg);
  config.beams = static_cast<std::size_t>(std::lround(180.0 / step_deg)) + 1;
  config.noise_sigma_m = noise_m;
  config.max_range_m = 40.0;
  config.seed = seed;
  testing::SyntheticScanner scanner(config);
  const std::vector<Body> bodies = {body};
  const ScanView scan = scanner.Render(0, {}, bodies);
  View v;
  std::size_t first = scan.range_m.size(), last = 0;
  for (std::size_t i = 0; i < scan.range_m.size(); ++i) {
    if (scan.range_m[i] <= 0.0f) continue;
    const double a = scan.BeamAngleRad(i);
    v.points.emplace_back(scan.range_m[i] * std::cos(a), scan.range_m[i] * std::sin(a));
    first = std::min(first, i);
    last = i;
  }
  v.silhouette.step_rad = std::abs(scan.angle_step_rad);
  v.silhouette.first_edge_rad = scan.BeamAngleRad(first) - 0.5 * scan.angle_step_rad;
  v.silhouette.last_edge_rad = scan.BeamAngleRad(last) + 0.5 * scan.angle_step_rad;
  v.silhouette.first_valid = v.silhouette.last_valid = true;
  return v;
}

// Squared Mahalanobis distance of the fit's centre from the truth.
double Nees(const ShapeFitResult& fit, const Eigen::Vector2d& truth) {
  const Eigen::Vector2d e = fit.centre_m - truth;
  return e.dot(fit.centre_cov_m2.ldlt().solve(e));
}

TEST(ShapeFitTest, OptionsValidate) {
  EXPECT_EQ(Validate(ShapeFitOptions{}), std::nullopt);
  ShapeFitOptions o;
  o.effective_points = 0.5;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.max_points = 1;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.point_sigma_m = o.model_sigma_m = 0.0;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.outside_guess_start = static_cast<OutsideGuessStart>(3);
  EXPECT_NE(Validate(o), std::nullopt);
}

TEST(ShapeFitTest, SupportFunctionsOfTheShapes) {
  const Eigen::Vector2d size(0.3, 0.1);
  EXPECT_NEAR(ShapeSupport(ShapeModel::kSuperellipse, size, 0.0, {1, 0}), 0.3, 1e-12);
  EXPECT_NEAR(ShapeSupport(ShapeModel::kSuperellipse, size, 0.0, {0, 1}), 0.1, 1e-12);
  EXPECT_NEAR(ShapeSupport(ShapeModel::kSuperellipse, size, common::kPi / 2, {1, 0}), 0.1, 1e-12);
  const Eigen::Vector2d diagonal(std::sqrt(0.5), std::sqrt(0.5));
  EXPECT_NEAR(ShapeSupport(ShapeModel::kBox, size, 0.0, diagonal), 0.4 * std::sqrt(0.5), 1e-12);
  EXPECT_NEAR(ShapeSupport(ShapeModel::kCircle, size, 1.0, diagonal), 0.3, 1e-12);
}

// The support function's derivative by the size (the centre-bias covariance's Jacobian) against
// central differences, for every model, exponents 2 and 2.5, in every direction.
TEST(ShapeFitTest, SupportFunctionSizeDerivativeMatchesDifferences) {
  const Eigen::Vector2d size(0.26, 0.15);
  const double step_m = 1e-6;
  for (const auto& [model, exponent] :
       {std::pair{ShapeModel::kSuperellipse, 2.0}, std::pair{ShapeModel::kSuperellipse, 2.5},
        std::pair{ShapeModel::kBox, 2.0}, std::pair{ShapeModel::kCircle, 2.0}}) {
    for (int k = 0; k < 24; ++k) {
      const double angle = 0.1 + 2.0 * common::kPi * k / 24.0;
      const Eigen::Vector2d n(std::cos(angle), std::sin(angle));
      Eigen::Vector2d d_size(-1.0, -1.0);
      const double h = ShapeSupport(model, size, 0.4, n, exponent, &d_size);
      EXPECT_DOUBLE_EQ(h, ShapeSupport(model, size, 0.4, n, exponent));
      for (int i = 0; i < 2; ++i) {
        Eigen::Vector2d up = size, down = size;
        up(i) += step_m;
        down(i) -= step_m;
        const double expected = (ShapeSupport(model, up, 0.4, n, exponent) -
                                 ShapeSupport(model, down, 0.4, n, exponent)) /
                                (2.0 * step_m);
        EXPECT_NEAR(d_size(i), expected, 1e-6) << static_cast<int>(model) << " " << k << " " << i;
      }
    }
  }
}

// The person model's support function (exponent 2.5: the dual norm with k = 5/3) by the fit's own
// roots against the libm powers it used before (|x|^k = x cbrt(x^2), h = pow(t, 1 / k)), over sizes
// from a micrometre to a kilometre and far beyond (1e-100..1e100 m) and every direction.
// ShapeSupportPair: the size derivatives of two directions at once, the same values as two calls
// of ShapeSupport (for every model and the exponents with and without their own path).
TEST(ShapeFitTest, SupportPairGivesTheSingleDirectionsDerivatives) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const ShapeModel models[] = {ShapeModel::kSuperellipse, ShapeModel::kBox, ShapeModel::kCircle};
  for (int k = 0; k < 2000; ++k) {
    const ShapeModel model = models[k % 3];
    const double exponent = (k / 3) % 3 == 0 ? 2.0 : ((k / 3) % 3 == 1 ? 2.5 : 3.0);
    const Eigen::Vector2d size(0.1 + 0.3 * uniform(rng), 0.05 + 0.2 * uniform(rng));
    const double yaw = 2.0 * common::kPi * uniform(rng) - common::kPi;
    const double a0 = 2.0 * common::kPi * uniform(rng), a1 = a0 + 0.5 * common::kPi;
    const Eigen::Vector2d n0(std::cos(a0), std::sin(a0)), n1(std::cos(a1), std::sin(a1));
    Eigen::Vector2d single0, single1, pair0, pair1;
    ShapeSupport(model, size, yaw, n0, exponent, &single0);
    ShapeSupport(model, size, yaw, n1, exponent, &single1);
    ShapeSupportPair(model, size, yaw, n0, n1, exponent, &pair0, &pair1);
    SCOPED_TRACE("case " + std::to_string(k));
    EXPECT_NEAR((pair0 - single0).norm(), 0.0, 1e-13 * (1.0 + single0.norm()));
    EXPECT_NEAR((pair1 - single1).norm(), 0.0, 1e-13 * (1.0 + single1.norm()));
  }
  // Known values: an ellipse (exponent 2) of semi-axes (0.3, 0.2) along x: h = (a^2 p^2 +
  // b^2 q^2)^(1/2), dh/da = a p^2 / h, dh/db = b q^2 / h; along its axes (1, 0) and (0, 1).
  Eigen::Vector2d along, across;
  ShapeSupportPair(ShapeModel::kSuperellipse, {0.3, 0.2}, 0.0, {1.0, 0.0}, {0.0, 1.0}, 2.0, &along,
                   &across);
  EXPECT_NEAR(along.x(), 1.0, 1e-15);
  EXPECT_NEAR(along.y(), 0.0, 1e-15);
  EXPECT_NEAR(across.x(), 0.0, 1e-15);
  EXPECT_NEAR(across.y(), 1.0, 1e-15);
}

// The pair's two cube roots per edge run interleaved in one sequence of Halley steps; each lane
// does the single direction's arithmetic, so on x86-64 (no fused multiply-adds) the bits are the
// same, also where one power leaves the roots' normal range (sizes down to 1e-160 m: the pair then
// takes each root alone, as the single direction does).
TEST(ShapeFitTest, SupportPairsInterleavedRootsGiveTheSingleDirectionsBits) {
#if defined(__x86_64__)
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  int out_of_range = 0;
  for (int k = 0; k < 4000; ++k) {
    const double scale = k % 4 == 3 ? std::pow(10.0, -160.0 * uniform(rng)) : 1.0;
    const Eigen::Vector2d size((0.1 + 0.3 * uniform(rng)) * scale, 0.05 + 0.2 * uniform(rng));
    const double yaw = 2.0 * common::kPi * uniform(rng) - common::kPi;
    const double a0 = 2.0 * common::kPi * uniform(rng), a1 = a0 + 0.5 * common::kPi * uniform(rng);
    const Eigen::Vector2d n0(std::cos(a0), std::sin(a0)), n1(std::cos(a1), std::sin(a1));
    Eigen::Vector2d single0, single1, pair0, pair1;
    ShapeSupport(ShapeModel::kSuperellipse, size, yaw, n0, 2.5, &single0);
    ShapeSupport(ShapeModel::kSuperellipse, size, yaw, n1, 2.5, &single1);
    ShapeSupportPair(ShapeModel::kSuperellipse, size, yaw, n0, n1, 2.5, &pair0, &pair1);
    out_of_range += size.x() < 1e-146 ? 1 : 0;  // (a p)^2 below 1e-290
    SCOPED_TRACE("case " + std::to_string(k));
    EXPECT_EQ(pair0.x(), single0.x());
    EXPECT_EQ(pair0.y(), single0.y());
    EXPECT_EQ(pair1.x(), single1.x());
    EXPECT_EQ(pair1.y(), single1.y());
  }
  EXPECT_GT(out_of_range, 50);
#else
  GTEST_SKIP() << "fused multiply-adds may round the lanes and the single path differently";
#endif
}

TEST(ShapeFitTest, PersonSupportFunctionMatchesLibmPowers) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const double k = 2.5 / 1.5;
  const auto power = [](double v) { return v * std::cbrt(v * v); };
  double worst = 0.0;
  for (int i = 0; i < 20000; ++i) {
    const double decades = i < 10000 ? 9.0 : 200.0;
    const double a = std::pow(10.0, (i < 10000 ? -6.0 : -100.0) + decades * uniform(rng));
    const double b = a * std::pow(10.0, -2.0 + 4.0 * uniform(rng));
    const double yaw = 2.0 * common::kPi * uniform(rng);
    const double angle = 2.0 * common::kPi * uniform(rng);
    const Eigen::Vector2d n(std::cos(angle), std::sin(angle));
    const double p = n.x() * std::cos(yaw) + n.y() * std::sin(yaw);
    const double q = -n.x() * std::sin(yaw) + n.y() * std::cos(yaw);
    const double expected = std::pow(power(std::abs(a * p)) + power(std::abs(b * q)), 1.0 / k);
    const double h = ShapeSupport(ShapeModel::kSuperellipse, {a, b}, yaw, n, 2.5);
    ASSERT_TRUE(std::isfinite(h)) << a << " " << b;
    worst = std::max(worst, std::abs(h - expected) / expected);
  }
  // Two Halley steps: the fifth root within 1.4e-10, cubed (a 0.3 m body: 1.3e-10 m, far below
  // any point's noise; the fits' centres move by at most 1e-10 m, CholeskySolverGivesThePivoted-
  // LdltResults).
  EXPECT_LT(worst, 1e-9);
  EXPECT_EQ(ShapeSupport(ShapeModel::kSuperellipse, {0.3, 0.1}, 0.0, {0, 0}, 2.5), 0.0);
}

// A cylinder of known radius at 5, 10 and 20 m, seen with 2 to 40 points (the beam step sets how
// many): the centre, not the visible arc's middle, within what the fit says of itself.
TEST(ShapeFitTest, CylinderOfKnownRadiusAtEveryRangeAndPointCount) {
  const double radius = 0.25;
  int cases = 0;
  double nees_sum = 0.0;
  for (const double range : {5.0, 10.0, 20.0}) {
    for (const int points : {2, 3, 4, 6, 10, 20, 40}) {
      // The arc subtends 2 asin(r / R); spread `points` beams over it.
      const double span_deg = common::RadToDeg(2.0 * std::asin(radius / range));
      const double step_deg = span_deg / (points + 0.2);
      for (const std::uint32_t seed : {1u, 2u, 3u}) {
        const double bearing = 0.2 * seed - 0.4;
        const Body body = testing::Cylinder(
            range * Eigen::Vector2d(std::cos(bearing), std::sin(bearing)), radius);
        const View v = Look(body, step_deg, 0.012, seed);
        ASSERT_GE(v.points.size(), 2u);
        ShapePrior prior;
        prior.model = ShapeModel::kCircle;
        prior.size_m = {radius, radius};
        prior.size_cov_m2 = 0.005 * 0.005 * Eigen::Matrix2d::Identity();
        const ShapeFitResult fit = FitShape(v.points, v.silhouette, prior, ShapeFitOptions{});
        ASSERT_TRUE(fit.ok);
        const double error = (fit.centre_m - body.centre_m).norm();
        SCOPED_TRACE("range " + std::to_string(range) + " points " +
                     std::to_string(v.points.size()) + " error " + std::to_string(error));
        // The centre of mass of the visible arc lies ~pi r / 4 = 0.2 m in front of the centre.
        EXPECT_LT(error, 0.05);
        EXPECT_LT(std::abs(fit.centre_m.norm() - range), 0.03);
        EXPECT_LT(Nees(fit, body.centre_m), 13.8);  // 99.9 % of chi-square, 2 dof
        EXPECT_NEAR(fit.size_m.x(), radius, 0.01);
        nees_sum += Nees(fit, body.centre_m);
        ++cases;
      }
    }
  }
  // The covariance is neither much too large nor too small on average (2 for an exact one).
  EXPECT_GT(nees_sum / cases, 0.3);
  EXPECT_LT(nees_sum / cases, 4.0);
}

// With the radius unknown (a wide prior) and many points, the fit learns it.
TEST(ShapeFitTest, CylinderRadiusIsLearnedFromAWideArc) {
  const Body body = testing::Cylinder({3.0, 0.5}, 0.25);
  const View v = Look(body, 0.25, 0.005);
  ShapePrior prior;
  prior.model = ShapeModel::kCircle;
  prior.size_m = {0.15, 0.15};
  prior.size_cov_m2 = 0.1 * 0.1 * Eigen::Matrix2d::Identity();
  const ShapeFitResult fit = FitShape(v.points, v.silhouette, prior, ShapeFitOptions{});
  ASSERT_TRUE(fit.ok);
  EXPECT_NEAR(fit.size_m.x(), 0.25, 0.02);
  EXPECT_LT((fit.centre_m - body.centre_m).norm(), 0.02);
  EXPECT_LT(std::sqrt(fit.size_cov_m2(0, 0)), 0.03);
}

// A prediction 0.45 m behind a round person (the track lagging a turn): each Gauss-Newton step
// moves the centre by at most 0.25 m (the trust region), so one iteration ends 0.25 m from the
// start, and the whole fit still reaches the person. Fails if a step beyond a bound is not cut.
TEST(ShapeFitTest, AStepBeyondTheTrustRegionIsCutAndTheFitStillConverges) {
  const Body body = testing::Cylinder({4.0, 0.0}, 0.2);
  const View v = Look(body, 0.5);
  ASSERT_GE(v.points.size(), 4u);
  ShapePrior prior;
  prior.exponent = 2.0;
  prior.size_m = {0.2, 0.2};
  prior.centre_guess_m = Eigen::Vector2d(4.45, 0.0);
  ShapeFitOptions one_step;
  one_step.max_iterations = 1;
  const ShapeFitResult first = FitShape(v.points, v.silhouette, prior, one_step);
  ASSERT_TRUE(first.ok);
  EXPECT_EQ(first.iterations, 1);
  EXPECT_NEAR((first.centre_m - *prior.centre_guess_m).norm(), 0.25, 1e-9);
  EXPECT_LT(first.centre_m.x(), 4.45);
  const ShapeFitResult fit = FitShape(v.points, v.silhouette, prior, ShapeFitOptions{});
  ASSERT_TRUE(fit.ok);
  EXPECT_GE(fit.iterations, 2);
  EXPECT_LT((fit.centre_m - body.centre_m).norm(), 0.01);
}

// A person's upper-body ellipse at every heading and 3-10 m, with the sizes known (a track that
// learned them) and the heading from the walking direction (20 degrees sigma).
TEST(ShapeFitTest, EllipseAtEveryHeading) {
  double worst = 0.0;
  for (double yaw_deg = 0; yaw_deg < 180; yaw_deg += 15) {
    for (const double range : {3.0, 6.0, 10.0}) {
      const double yaw = common::DegToRad(yaw_deg);
      const Body body{range * Eigen::Vector2d(std::cos(0.3), std::sin(0.3)), 0.23, 0.14, yaw};
      const View v = Look(body, 0.5, 0.012, static_cast<std::uint32_t>(yaw_deg + range));
      ShapePrior prior;
      prior.exponent = 2.0;  // the outline is an ellipse
      prior.size_m = {0.23, 0.14};
      prior.size_cov_m2 = 0.01 * 0.01 * Eigen::Matrix2d::Identity();
      prior.yaw_rad = yaw + 0.1;
      prior.yaw_sigma_rad = 0.35;
      const ShapeFitResult fit = FitShape(v.points, v.silhouette, prior, ShapeFitOptions{});
      ASSERT_TRUE(fit.ok);
      const double error = (fit.centre_m - body.centre_m).norm();
      SCOPED_TRACE("yaw " + std::to_string(yaw_deg) + " range " + std::to_string(range) +
                   " error " + std::to_string(error));
      EXPECT_LT(error, 0.04);
      EXPECT_LT(Nees(fit, body.centre_m), 13.8);
      worst = std::max(worst, error);
    }
  }
  EXPECT_GT(worst, 0.0);
}

// Two to four points of a person 15-25 m away: the prior size and the direction to the sensor put
// the centre behind the points, and the covariance says how little the points add.
TEST(ShapeFitTest, FewPointsStillGiveTheBodyCentreWithAnHonestCovariance) {
  for (const double range : {15.0, 20.0, 25.0}) {
    const Body body{range * Eigen::Vector2d(1.0, 0.0), 0.22, 0.15, common::kPi / 2};  // facing
    const View v = Look(body, 0.5, 0.012, static_cast<std::uint32_t>(range));
    ASSERT_GE(v.points.size(), 2u);
    ASSERT_LE(v.points.size(), 4u);
    ShapePrior prior;  // the population prior, orientation unknown
    prior.exponent = 2.0;
    const ShapeFitResult fit = FitShape(v.points, v.silhouette, prior, ShapeFitOptions{});
    ASSERT_TRUE(fit.ok);
    Eigen::Vector2d visible = Eigen::Vector2d::Zero();
    for (const auto& p : v.points) visible += p;
    visible /= static_cast<double>(v.points.size());
    SCOPED_TRACE("range " + std::to_string(range));
    // Behind the visible points, near the centre, within the covariance.
    EXPECT_GT(fit.centre_m.x(), visible.x() + 0.05);
    EXPECT_LT((fit.centre_m - body.centre_m).norm(), 0.08);
    EXPECT_LT(Nees(fit, body.centre_m), 13.8);
    // Along the ray the size and orientation are open: several centimetres.
    EXPECT_GT(std::sqrt(fit.centre_cov_m2(0, 0)), 0.02);
  }
}

// A far view (15 m, 0.5 deg beams: three points) of a person with the track's prediction 0.35 m
// to the side, outside the silhouette's wedge (the rays through its ends). With each edge turned
// away from the start, the edge the prediction lies beyond held the body beside the points, and
// the fit stayed there (the error crept from scan to scan); with the edges turned away from the
// points, and with either start the fit lands on the person.
TEST(ShapeFitTest, FewPointsWithAPredictionOutsideTheSilhouetteLandOnThePerson) {
  for (const double side : {0.35, -0.35}) {
    const Body body{15.0 * Eigen::Vector2d(1.0, 0.0), 0.22, 0.15, common::kPi / 2};
    const View v = Look(body, 0.5, 0.005, 3);
    ASSERT_EQ(v.points.size(), 3u);
    ShapePrior prior;
    prior.size_m = Eigen::Vector2d(0.22, 0.15);
    prior.size_cov_m2 = 0.03 * 0.03 * Eigen::Matrix2d::Identity();
    prior.centre_guess_m = body.centre_m + Eigen::Vector2d(0.0, side);
    // Outside the wedge by more than half a beam step.
    const double guess_angle = std::atan2(prior.centre_guess_m->y(), prior.centre_guess_m->x());
    ASSERT_TRUE(guess_angle > v.silhouette.last_edge_rad + 0.5 * v.silhouette.step_rad ||
                guess_angle < v.silhouette.first_edge_rad - 0.5 * v.silhouette.step_rad);
    SCOPED_TRACE("side " + std::to_string(side));
    const ShapeFitResult fit = FitShape(v.points, v.silhouette, prior, ShapeFitOptions{});
    ASSERT_TRUE(fit.ok);
    EXPECT_LT((fit.centre_m - body.centre_m).norm(), 0.1);
    for (const OutsideGuessStart start :
         {OutsideGuessStart::kGuess, OutsideGuessStart::kSilhouette, OutsideGuessStart::kBetter}) {
      ShapeFitOptions o;
      o.outside_guess_start = start;
      const ShapeFitResult from = FitShape(v.points, v.silhouette, prior, o);
      ASSERT_TRUE(from.ok);
      EXPECT_LT((from.centre_m - body.centre_m).norm(), 0.1) << static_cast<int>(start);
      // The cost leaves out the weak prior around the start: from the silhouette's start (no
      // guess) the same solution has the same cost.
      if (start == OutsideGuessStart::kSilhouette) {
        ShapePrior no_guess = prior;
        no_guess.centre_guess_m.reset();
        EXPECT_DOUBLE_EQ(from.cost, FitShape(v.points, v.silhouette, no_guess, o).cost);
      }
    }
    ShapeFitOptions before;
    before.edges_face_points = false;
    before.outside_guess_start = OutsideGuessStart::kGuess;
    const ShapeFitResult stuck = FitShape(v.points, v.silhouette, prior, before);
    ASSERT_TRUE(stuck.ok);
    EXPECT_GT((stuck.centre_m - body.centre_m).norm(), 0.2);
    std::printf("prediction %+.2f m to the side: off by %.3f m (before %.3f m)\n", side,
                (fit.centre_m - body.centre_m).norm(), (stuck.centre_m - body.centre_m).norm());
  }
}

// The points and silhouette a 361-beam scanner (0.5 deg from -90 deg) sees of a box with
// half-lengths a along u and b along w around centre, range noise noise_sigma_m.
View RenderBox(const Eigen::Vector2d& centre, double yaw, double a, double b, double noise_sigma_m,
               std::uint32_t seed) {
  const Eigen::Vector2d u(std::cos(yaw), std::sin(yaw)), w(-std::sin(yaw), std::cos(yaw));
  const std::vector<testing::Wall> box = {{centre + a * u + b * w, centre - a * u + b * w},
                                          {centre - a * u + b * w, centre - a * u - b * w},
                                          {centre - a * u - b * w, centre + a * u - b * w},
                                          {centre + a * u - b * w, centre + a * u + b * w}};
  testing::ScannerConfig config;
  config.first_angle_rad = common::DegToRad(-90.0);
  config.beams = 361;
  config.noise_sigma_m = noise_sigma_m;
  if (seed != 0) config.seed = seed;
  testing::SyntheticScanner scanner(config);
  const ScanView scan = scanner.Render(0, box, {});
  View v;
  std::size_t first = scan.range_m.size(), last = 0;
  for (std::size_t i = 0; i < scan.range_m.size(); ++i) {
    if (scan.range_m[i] <= 0.0f) continue;
    const double angle = scan.BeamAngleRad(i);
    v.points.emplace_back(scan.range_m[i] * std::cos(angle), scan.range_m[i] * std::sin(angle));
    first = std::min(first, i);
    last = i;
  }
  if (!v.points.empty()) {
    v.silhouette = {scan.BeamAngleRad(first) - 0.5 * scan.angle_step_rad,
                    scan.BeamAngleRad(last) + 0.5 * scan.angle_step_rad,
                    std::abs(scan.angle_step_rad), true, true};
  }
  return v;
}

TEST(ShapeFitTest, BoxOfACartAtItsCornerAndSide) {
  // A 1.0 x 0.6 m cart (half-lengths 0.5, 0.3), its length along its heading.
  for (const double yaw_deg : {0.0, 30.0, 60.0, 90.0}) {
    const double yaw = common::DegToRad(yaw_deg);
    const Eigen::Vector2d centre(4.0, 1.0);
    const View v = RenderBox(centre, yaw, 0.5, 0.3, 0.01, 0);
    ShapePrior prior;
    prior.model = ShapeModel::kBox;  // a track that learned its size, give or take 5 cm
    prior.size_m = {0.52, 0.28};
    prior.size_cov_m2 = 0.05 * 0.05 * Eigen::Matrix2d::Identity();
    prior.yaw_rad = yaw;
    prior.yaw_sigma_rad = 0.2;
    const ShapeFitResult fit = FitShape(v.points, v.silhouette, prior, ShapeFitOptions{});
    ASSERT_TRUE(fit.ok);
    SCOPED_TRACE("yaw " + std::to_string(yaw_deg));
    EXPECT_LT((fit.centre_m - centre).norm(), 0.04);
    EXPECT_LT(Nees(fit, centre), 13.8);
  }
}

TEST(ShapeFitTest, OutlierPointsOfSomethingElseAreDownWeighted) {
  const Body body = testing::Cylinder({5.0, 0.0}, 0.2);
  View v = Look(body, 0.25, 0.005);
  // Two points of a bag 15 cm in front of one side.
  v.points[1] -= Eigen::Vector2d(0.15, 0.0);
  v.points[2] -= Eigen::Vector2d(0.15, 0.0);
  ShapePrior prior;
  prior.model = ShapeModel::kCircle;
  prior.size_m = {0.2, 0.2};
  prior.size_cov_m2 = 0.01 * 0.01 * Eigen::Matrix2d::Identity();
  const ShapeFitResult fit = FitShape(v.points, v.silhouette, prior, ShapeFitOptions{});
  ASSERT_TRUE(fit.ok);
  EXPECT_LT((fit.centre_m - body.centre_m).norm(), 0.02);
}

TEST(ShapeFitTest, FlatBoardHasASmallLineResidual) {
  std::vector<Eigen::Vector2d> board, arc;
  for (int i = 0; i < 10; ++i) {
    board.emplace_back(4.0, -0.25 + 0.05 * i);
    const double a = -1.2 + 0.24 * i;
    arc.emplace_back(4.2 - 0.2 * std::cos(a), 0.2 * std::sin(a));
  }
  const Silhouette none{};
  const ShapeFitResult flat = FitShape(board, none, ShapePrior{}, ShapeFitOptions{});
  const ShapeFitResult round = FitShape(arc, none, ShapePrior{}, ShapeFitOptions{});
  EXPECT_LT(flat.line_rms_m, 1e-9);
  EXPECT_NEAR(flat.extent_m, 0.45, 1e-9);
  EXPECT_GT(round.line_rms_m, 0.03);
}

TEST(ShapeFitTest, DegenerateInputsAreRefusedOrHonest) {
  const Silhouette none{};
  const std::vector<Eigen::Vector2d> nothing = {{std::nan(""), 1.0},
                                                {std::numeric_limits<double>::infinity(), 0.0}};
  EXPECT_FALSE(FitShape(nothing, none, ShapePrior{}, ShapeFitOptions{}).ok);
  EXPECT_FALSE(FitShape({}, none, ShapePrior{}, ShapeFitOptions{}).ok);
  // One point, no silhouette: the centre is behind it, and what is open is large.
  const std::vector<Eigen::Vector2d> one = {{6.0, 0.0}};
  const ShapeFitResult fit = FitShape(one, none, ShapePrior{}, ShapeFitOptions{});
  ASSERT_TRUE(fit.ok);
  EXPECT_GT(fit.centre_m.x(), 6.05);
  EXPECT_GT(std::sqrt(fit.centre_cov_m2(1, 1)), 0.3);  // sideways: nothing known
  // Many identical points (a stuck beam) do not break it.
  const std::vector<Eigen::Vector2d> same(30, Eigen::Vector2d(3.0, 1.0));
  EXPECT_TRUE(FitShape(same, none, ShapePrior{}, ShapeFitOptions{}).ok);
}

// Beyond max_points the fit takes evenly spaced points, counted among the finite ones: a segment
// whose points are all finite (picked by index) and the same segment with non-finite points
// between them (picked on a pass over all of them) give the same fit, bit for bit, at every count.
TEST(ShapeFitTest, EvenlySubsampledPointsWithAndWithoutNonFiniteOnes) {
  const double nan = std::nan("");
  for (const std::size_t max_points : {std::size_t{2}, std::size_t{5}, std::size_t{8}}) {
    ShapeFitOptions options;
    options.max_points = max_points;
    for (std::size_t count = 1; count <= 64; ++count) {
      // An arc of a 0.2 m cylinder at 4 m, its near half, with a little unevenness.
      std::vector<Eigen::Vector2d> arc;
      for (std::size_t i = 0; i < count; ++i) {
        const double t = count == 1 ? 0.5 : static_cast<double>(i) / static_cast<double>(count - 1);
        const double angle = common::kPi * (0.5 + t) + 0.002 * std::sin(7.0 * t);
        arc.emplace_back(4.0 + 0.2 * std::cos(angle), 0.2 * std::sin(angle));
      }
      std::vector<Eigen::Vector2d> holed;
      for (std::size_t i = 0; i < count; ++i) {
        if (i % 3 == 0) holed.emplace_back(nan, 1.0);
        holed.push_back(arc[i]);
      }
      holed.emplace_back(1.0, nan);
      Silhouette edges;
      edges.first_valid = edges.last_valid = true;
      edges.step_rad = common::DegToRad(0.25);
      edges.first_edge_rad = std::atan2(arc.front().y(), arc.front().x()) - 0.5 * edges.step_rad;
      edges.last_edge_rad = std::atan2(arc.back().y(), arc.back().x()) + 0.5 * edges.step_rad;
      ShapePrior prior;
      prior.exponent = 2.0;
      prior.size_m = Eigen::Vector2d(0.2, 0.2);
      const ShapeFitResult all = FitShape(arc, edges, prior, options);
      const ShapeFitResult with_holes = FitShape(holed, edges, prior, options);
      ASSERT_TRUE(all.ok) << count;
      EXPECT_EQ(all.points_used, std::min(count, max_points)) << count;
      EXPECT_EQ(with_holes.points_used, all.points_used) << count;
      EXPECT_EQ(with_holes.iterations, all.iterations) << count;
      EXPECT_EQ(with_holes.centre_m, all.centre_m) << count << " points, max " << max_points;
      EXPECT_EQ(with_holes.centre_cov_m2, all.centre_cov_m2) << count;
      EXPECT_EQ(with_holes.extent_m, all.extent_m) << count;
      // Infinite coordinates are not finite either (one of them alone among finite points).
      std::vector<Eigen::Vector2d> infinite = arc;
      const double inf = std::numeric_limits<double>::infinity();
      infinite.insert(infinite.begin() + static_cast<std::ptrdiff_t>(count / 2), {-inf, 0.5});
      const ShapeFitResult with_infinity = FitShape(infinite, edges, prior, options);
      EXPECT_EQ(with_infinity.points_used, all.points_used) << count;
      EXPECT_EQ(with_infinity.centre_m, all.centre_m) << count;
      EXPECT_FALSE(
          FitShape(std::vector<Eigen::Vector2d>{{inf, 1.0}, {nan, nan}}, edges, prior, options).ok);
      // The first and last points are always taken.
      EXPECT_DOUBLE_EQ(all.extent_m, (arc.front() - arc.back()).norm()) << count;
      EXPECT_NEAR(all.centre_m.x(), 4.0, 0.05) << count;
    }
  }
}

// The fit with its own 5 x 5 Cholesky, roots (RootN) and start ray (the bisector) against the
// same fit with Eigen's pivoted LDLT, libm's cbrt and pow and the ray's angle by atan2 (what it
// used before): the same iterations and results up to rounding, over random people, cylinders and
// boxes at 2-25 m, with and without a track's yaw, centre guess and silhouette edges. And the fit
// with two points' and both edges' arithmetic side by side against one at a time: the same
// operations, so the same results (exactly where the compiler fuses no multiply-adds).
TEST(ShapeFitTest, CovarianceOfTheReportedEntriesOnlyHasTheFullInversesBits) {
  // Random symmetric positive definite normal matrices over many orders of magnitude: the entries
  // a fit reports are the full inverse's, bit for bit; the others are not formed (0).
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const auto reported = [](int i, int j) {
    return (i < 2 && j < 2) || (i == 2 && j == 2) || (i >= 3 && j >= 3);
  };
  for (int k = 0; k < 2000; ++k) {
    Eigen::Matrix<double, 5, 5> a;
    for (int i = 0; i < 5; ++i) {
      for (int j = 0; j < 5; ++j) a(i, j) = uniform(rng) * std::pow(10.0, 3.0 * uniform(rng));
    }
    const Eigen::Matrix<double, 5, 5> h =
        a * a.transpose() + 1e-3 * Eigen::Matrix<double, 5, 5>::Identity();
    const Eigen::Matrix<double, 5, 5> full = internal::NormalSolverInverse(h, false);
    const Eigen::Matrix<double, 5, 5> part = internal::NormalSolverInverse(h, true);
    ASSERT_TRUE(full.allFinite());
    for (int i = 0; i < 5; ++i) {
      for (int j = 0; j < 5; ++j) {
        if (reported(i, j)) {
          EXPECT_EQ(part(i, j), full(i, j)) << k << " " << i << " " << j;
        } else {
          EXPECT_EQ(part(i, j), 0.0) << k << " " << i << " " << j;
        }
      }
    }
  }
}

TEST(ShapeFitTest, NormalSolverReadsTheUpperTriangleOnly) {
  // The fit forms only the normal matrix's upper triangle: whatever lies below it, the solver's
  // inverse is the symmetric matrix's, bit for bit.
  std::mt19937 rng(6);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  for (int k = 0; k < 500; ++k) {
    Eigen::Matrix<double, 5, 5> a;
    for (int i = 0; i < 5; ++i) {
      for (int j = 0; j < 5; ++j) a(i, j) = uniform(rng) * std::pow(10.0, 3.0 * uniform(rng));
    }
    const Eigen::Matrix<double, 5, 5> h =
        a * a.transpose() + 1e-3 * Eigen::Matrix<double, 5, 5>::Identity();
    Eigen::Matrix<double, 5, 5> upper = h;
    for (int i = 1; i < 5; ++i) {
      for (int j = 0; j < i; ++j) upper(i, j) = k % 2 == 0 ? 0.0 : 1e6 * uniform(rng);
    }
    const Eigen::Matrix<double, 5, 5> expected = internal::NormalSolverInverse(h, false);
    const Eigen::Matrix<double, 5, 5> got = internal::NormalSolverInverse(upper, false);
    ASSERT_TRUE(expected.allFinite());
    for (int i = 0; i < 5; ++i) {
      for (int j = 0; j < 5; ++j) EXPECT_EQ(got(i, j), expected(i, j)) << k << " " << i << " " << j;
    }
  }
}

// A prior for the k-th random fit of `body` (exponents 2.5 and 2 by turns): its size within
// 2.5 cm of the truth (with random_size_sigma a random sigma of 1-6 cm, else the default); in
// about 7 of 10 fits a yaw prior, in about 7 of 10 a start near the centre.
ShapePrior RandomPrior(ShapeModel model, int k, const Body& body, bool random_size_sigma,
                       std::mt19937& rng) {
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  ShapePrior prior;
  prior.model = model;
  prior.exponent = k % 2 == 0 ? 2.5 : 2.0;
  prior.size_m = {body.semi_major_m + 0.05 * (uniform(rng) - 0.5),
                  body.semi_minor_m + 0.05 * (uniform(rng) - 0.5)};
  if (random_size_sigma) {
    prior.size_cov_m2 = std::pow(0.01 + 0.05 * uniform(rng), 2) * Eigen::Matrix2d::Identity();
  }
  if (uniform(rng) > 0.3) {
    prior.yaw_rad = body.yaw_rad + 0.3 * (uniform(rng) - 0.5);
    prior.yaw_sigma_rad = 0.35;
  }
  if (uniform(rng) > 0.3) {
    prior.centre_guess_m =
        body.centre_m + Eigen::Vector2d(0.2 * (uniform(rng) - 0.5), 0.2 * (uniform(rng) - 0.5));
  }
  return prior;
}

TEST(ShapeFitTest, CholeskySolverGivesThePivotedLdltResults) {
  std::mt19937 rng(14);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const double steps_deg[] = {0.1667, 0.25, 0.5, 1.0};
  const ShapeModel models[] = {ShapeModel::kSuperellipse, ShapeModel::kCircle, ShapeModel::kBox};
  int fits = 0;
  int identical = 0;  // fits whose side-by-side arithmetic gave the very same bits
  double worst_centre_m = 0.0;
  for (int k = 0; k < 600; ++k) {
    const double range = 2.0 + 23.0 * uniform(rng);
    const double bearing = -1.2 + 2.4 * uniform(rng);
    const double yaw = common::kPi * uniform(rng);
    const ShapeModel model = models[k % 3];
    const double a = 0.15 + 0.15 * uniform(rng);
    const double b = model == ShapeModel::kCircle ? a : 0.1 + 0.08 * uniform(rng);
    const Body body{range * Eigen::Vector2d(std::cos(bearing), std::sin(bearing)), a, b, yaw};
    View v = Look(body, steps_deg[(k / 3) % 4], 0.012, static_cast<std::uint32_t>(k + 1));
    if (v.points.empty()) continue;
    v.silhouette.first_valid = uniform(rng) > 0.2;
    v.silhouette.last_valid = uniform(rng) > 0.2;
    const ShapePrior prior = RandomPrior(model, k, body, /*random_size_sigma=*/true, rng);
    // The double-precision points (the single-precision ones: SinglePrecisionPoints... below).
    ShapeFitOptions exact;
    exact.single_precision_points = false;
    const ShapeFitResult fit = FitShape(v.points, v.silhouette, prior, exact);
    const ShapeFitResult ref =
        internal::FitShapeWithPivotedLdlt(v.points, v.silhouette, prior, exact);
    SCOPED_TRACE("case " + std::to_string(k) + " points " + std::to_string(v.points.size()));
    ASSERT_EQ(fit.ok, ref.ok);
    if (!fit.ok) continue;
    ++fits;
    EXPECT_EQ(fit.iterations, ref.iterations);
    EXPECT_LT((fit.centre_m - ref.centre_m).norm(), 1e-9);
    EXPECT_LT((fit.centre_cov_m2 - ref.centre_cov_m2).norm(), 1e-9 * ref.centre_cov_m2.norm());
    EXPECT_LT((fit.size_m - ref.size_m).norm(), 1e-9);
    // Up to rounding: 2e-9 relative (a size covariance of 7e-4 m^2 differed by 8e-13).
    EXPECT_LT((fit.size_cov_m2 - ref.size_cov_m2).norm(), 2e-9 * ref.size_cov_m2.norm());
    EXPECT_NEAR(fit.yaw_rad, ref.yaw_rad, 1e-9);
    // Up to rounding: 1e-8 relative (aarch64's fused multiply-adds put a poorly determined yaw's
    // sigma of 0.32 rad 1.5e-9 apart).
    EXPECT_NEAR(fit.yaw_sigma_rad, ref.yaw_sigma_rad, 1e-8 * ref.yaw_sigma_rad);
    EXPECT_NEAR(fit.rms_m, ref.rms_m, 1e-9);
    worst_centre_m = std::max(worst_centre_m, (fit.centre_m - ref.centre_m).norm());
    const ShapeFitResult unpaired =
        internal::FitShapeUnpaired(v.points, v.silhouette, prior, exact);
    ASSERT_TRUE(unpaired.ok);
    EXPECT_EQ(fit.iterations, unpaired.iterations);
    EXPECT_LE((fit.centre_m - unpaired.centre_m).norm(), 1e-12);
    EXPECT_LE((fit.centre_cov_m2 - unpaired.centre_cov_m2).norm(),
              1e-12 * unpaired.centre_cov_m2.norm());
    EXPECT_LE((fit.size_m - unpaired.size_m).norm(), 1e-12);
    EXPECT_NEAR(fit.yaw_rad, unpaired.yaw_rad, 1e-12);
    EXPECT_NEAR(fit.rms_m, unpaired.rms_m, 1e-12);
    if (fit.centre_m == unpaired.centre_m && fit.centre_cov_m2 == unpaired.centre_cov_m2 &&
        fit.size_m == unpaired.size_m && fit.yaw_rad == unpaired.yaw_rad) {
      ++identical;
    }
  }
  EXPECT_GT(fits, 500);
  std::printf("%d fits, largest centre difference %.3g m; side by side: %d identical\n", fits,
              worst_centre_m, identical);
}

// A person's points in single precision, four at a time (ShapeFitOptions::single_precision_points),
// against the same fits in double: the answers differ (the other arithmetic is taken) by
// far less than the points' noise, and both find the known body. With the default max_points (8:
// one or two groups of four, summed without a loop) and with 16 (up to four groups, the loop).
void ExpectSinglePrecisionPointsGiveTheDoubleFit(std::size_t max_points) {
  std::mt19937 rng(15);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const double steps_deg[] = {0.1667, 0.25, 0.5, 1.0};
  ShapeFitOptions single;
  single.max_points = max_points;
  ShapeFitOptions exact = single;
  exact.single_precision_points = false;
  int beyond_two_quads = 0;  // fits of more than 8 points
  int fits = 0, differing = 0, same_iterations = 0;
  std::vector<double> centre_differences;
  for (int k = 0; k < 600; ++k) {
    const double range = 2.0 + 23.0 * uniform(rng);
    const double bearing = -1.2 + 2.4 * uniform(rng);
    const double yaw = common::kPi * uniform(rng);
    const double a = 0.15 + 0.15 * uniform(rng);
    const double b = 0.1 + 0.08 * uniform(rng);
    const Body body{range * Eigen::Vector2d(std::cos(bearing), std::sin(bearing)), a, b, yaw};
    View v = Look(body, steps_deg[(k / 3) % 4], 0.012, static_cast<std::uint32_t>(k + 1));
    if (v.points.empty()) continue;
    const ShapePrior prior =
        RandomPrior(ShapeModel::kSuperellipse, k, body, /*random_size_sigma=*/false, rng);
    const ShapeFitResult fit = FitShape(v.points, v.silhouette, prior, single);
    const ShapeFitResult dbl = FitShape(v.points, v.silhouette, prior, exact);
    beyond_two_quads += fit.points_used > 8 ? 1 : 0;
    SCOPED_TRACE("case " + std::to_string(k) + " points " + std::to_string(v.points.size()));
    ASSERT_EQ(fit.ok, dbl.ok);
    if (!dbl.ok) continue;
    ++fits;
    const double dc = (fit.centre_m - dbl.centre_m).norm();
    centre_differences.push_back(dc);
    differing += fit.centre_m != dbl.centre_m ? 1 : 0;
    same_iterations += fit.iterations == dbl.iterations ? 1 : 0;
    // Within a Gauss-Newton step's stopping threshold (3 mm) always, however the rounding falls.
    EXPECT_LT(dc, 0.003);
    EXPECT_LT((fit.size_m - dbl.size_m).norm(), 0.003);
    EXPECT_NEAR(fit.rms_m, dbl.rms_m, 1e-3);
    EXPECT_LT((fit.centre_cov_m2 - dbl.centre_cov_m2).norm(), 0.05 * dbl.centre_cov_m2.norm());
    // Both as far from the body (noise 12 mm on the range).
    EXPECT_NEAR((fit.centre_m - body.centre_m).norm(), (dbl.centre_m - body.centre_m).norm(), 1e-5);
  }
  ASSERT_GT(fits, 500);
  std::sort(centre_differences.begin(), centre_differences.end());
  const double p99 = centre_differences[centre_differences.size() * 99 / 100];
  std::printf(
      "%d fits, %d with other bits, %d with the same iterations; centre difference "
      "median %.3g m, p99 %.3g m, largest %.3g m\n",
      fits, differing, same_iterations, centre_differences[centre_differences.size() / 2], p99,
      centre_differences.back());
  // The other arithmetic is taken...
  EXPECT_GT(differing, fits / 2);
  // ... and nearly every answer is the double one to within a micrometre.
  EXPECT_LT(p99, 1e-6);
  EXPECT_GT(same_iterations, fits * 98 / 100);
  if (max_points > 8) {
    EXPECT_GT(beyond_two_quads, fits / 4);
  }
}

TEST(ShapeFitTest, SinglePrecisionPointsGiveTheDoubleFitWithinItsRounding) {
  ExpectSinglePrecisionPointsGiveTheDoubleFit(8);
}

TEST(ShapeFitTest, SinglePrecisionPointsBeyondTwoQuadsGiveTheDoubleFitWithinItsRounding) {
  ExpectSinglePrecisionPointsGiveTheDoubleFit(16);
}

// The silhouette edges' directions handed in by the caller (Silhouette::first_edge_unit and
// last_edge_unit: the cosine and sine of the angles, as the pipeline's table of the scan's beams
// holds them) give the same fit, bit for bit, as the fit's own sincos of the angles.
TEST(ShapeFitTest, EdgeDirectionsFromTheCallerGiveTheSameBits) {
  std::mt19937 rng(33);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  int compared = 0;
  for (int k = 0; k < 300; ++k) {
    const double range = 2.0 + 20.0 * uniform(rng);
    const double bearing = -1.2 + 2.4 * uniform(rng);
    const double yaw = common::kPi * uniform(rng);
    const Body body{range * Eigen::Vector2d(std::cos(bearing), std::sin(bearing)),
                    0.2 + 0.05 * uniform(rng), 0.12 + 0.04 * uniform(rng), yaw};
    View v = Look(body, k % 2 == 0 ? 0.1667 : 0.5, 0.012, static_cast<std::uint32_t>(k + 7));
    if (v.points.empty()) continue;
    v.silhouette.first_valid = uniform(rng) > 0.2;
    v.silhouette.last_valid = uniform(rng) > 0.2;
    ShapePrior prior;
    prior.exponent = k % 3 == 0 ? 2.0 : 2.5;
    prior.yaw_rad = yaw + 0.3 * (uniform(rng) - 0.5);
    prior.yaw_sigma_rad = 0.35;
    const ShapeFitResult own = FitShape(v.points, v.silhouette, prior, ShapeFitOptions{});
    Silhouette given = v.silhouette;
    given.first_edge_unit = {std::cos(given.first_edge_rad), std::sin(given.first_edge_rad)};
    given.last_edge_unit = {std::cos(given.last_edge_rad), std::sin(given.last_edge_rad)};
    given.first_edge_unit_known = given.last_edge_unit_known = true;
    const ShapeFitResult fit = FitShape(v.points, given, prior, ShapeFitOptions{});
    SCOPED_TRACE("case " + std::to_string(k));
    ASSERT_EQ(fit.ok, own.ok);
    if (!fit.ok) continue;
    ++compared;
    EXPECT_EQ(fit.centre_m, own.centre_m);
    EXPECT_EQ(fit.centre_cov_m2, own.centre_cov_m2);
    EXPECT_EQ(fit.size_m, own.size_m);
    EXPECT_EQ(fit.yaw_rad, own.yaw_rad);
    EXPECT_EQ(fit.evaluations, own.evaluations);
    // A wrong direction handed in is used: the fit takes the caller's values, not the angle's.
    if (v.silhouette.first_valid && k % 10 == 0) {
      Silhouette wrong = given;
      wrong.first_edge_unit = {std::cos(given.first_edge_rad + 0.05),
                               std::sin(given.first_edge_rad + 0.05)};
      EXPECT_NE(FitShape(v.points, wrong, prior, ShapeFitOptions{}).centre_m, own.centre_m);
    }
  }
  EXPECT_GT(compared, 250);
}

// The start's guess taken without the depth (internal::GuessWithinReach) only where the full test
// takes it too: within 0.5 m of the start on the ray, (nearest_along + h) ray with h the
// superellipse's support function along the ray, whatever h is; and near the body (a track's
// prediction) it settles nearly every case.
TEST(ShapeFitTest, GuessWithinReachAgreesWithTheStartsDepth) {
  std::mt19937 rng(12);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  int settled = 0, near = 0, near_settled = 0;
  for (int k = 0; k < 20000; ++k) {
    const double bearing = -1.5 + 3.0 * uniform(rng);
    const Eigen::Vector2d ray(std::cos(bearing), std::sin(bearing));
    const double nearest = 1.0 + 20.0 * uniform(rng);
    const Eigen::Vector2d size(0.1 + 0.6 * uniform(rng), 0.05 + 0.3 * uniform(rng));
    const double yaw = 2.0 * common::kPi * uniform(rng);
    const double exponent = k % 2 == 0 ? 2.5 : 2.0;
    // Guesses from the start itself out to 0.9 m from it.
    const double reach = k % 4 < 2 ? 0.15 : 0.9;
    const double depth = ShapeSupport(ShapeModel::kSuperellipse, size, yaw, ray, exponent);
    const Eigen::Vector2d start = (nearest + depth) * ray;
    const Eigen::Vector2d guess =
        start + reach * Eigen::Vector2d(uniform(rng) - 0.5, uniform(rng) - 0.5) * 2.0;
    const bool taken = (guess - start).norm() < 0.5;
    const bool within =
        internal::GuessWithinReach(ShapeModel::kSuperellipse, size, yaw, ray, nearest, guess);
    if (within) {
      ++settled;
      EXPECT_TRUE(taken) << "case " << k;
    }
    // A person-sized body and a guess within 0.1 m of the start (a track's prediction): settled.
    if ((guess - start).norm() < 0.1 && size.maxCoeff() < 0.35) {
      ++near;
      near_settled += within ? 1 : 0;
    }
    EXPECT_FALSE(internal::GuessWithinReach(ShapeModel::kBox, size, yaw, ray, nearest, guess));
    EXPECT_FALSE(internal::GuessWithinReach(ShapeModel::kCircle, size, yaw, ray, nearest, guess));
  }
  EXPECT_GT(near, 1000);
  EXPECT_EQ(near_settled, near);
  EXPECT_GT(settled, near);
}

// The support function's two cube roots side by side in one lane pair: the same bits as the
// scalar root of each (where multiply-adds are not fused; on x86-64), over values from 1e-300 to
// 1e300 and the ones outside the iteration's range that libm's cbrt answers (0, -0, subnormal,
// below 1e-290 and above 1e290, the largest double, infinity, negative), alone and paired with
// a value inside it (then both lanes go to the scalar root).
TEST(ShapeFitTest, CubeRootsInALanePairAreTheScalarRootsBitForBit) {
#ifdef __FP_FAST_FMA
  GTEST_SKIP() << "multiply-adds are fused: lanes and scalar code may round differently";
#else
  const auto bits = [](double v) { return std::bit_cast<std::uint64_t>(v); };
  std::mt19937 rng(20261129);
  std::uniform_real_distribution<double> log10(-300.0, 300.0);
  std::vector<double> values = {0.0,
                                -0.0,
                                std::numeric_limits<double>::denorm_min(),
                                1e-310,
                                std::numeric_limits<double>::min(),
                                1e-291,
                                1e-290,
                                1.0,
                                8.0,
                                0.3,
                                1e290,
                                1e291,
                                1e300,
                                std::numeric_limits<double>::max(),
                                std::numeric_limits<double>::infinity(),
                                -8.0};
  for (int i = 0; i < 2000; ++i) values.push_back(std::pow(10.0, log10(rng)));
  for (std::size_t i = 0; i < values.size(); ++i) {
    const double a = values[i];
    const double b = values[(i * 7 + 3) % values.size()];
    const Eigen::Vector2d pair = internal::FitCubeRootPair(a, b);
    ASSERT_EQ(bits(pair(0)), bits(internal::FitCubeRoot(a))) << a << " beside " << b;
    ASSERT_EQ(bits(pair(1)), bits(internal::FitCubeRoot(b))) << b << " beside " << a;
  }
  // The roots themselves: within 1.2e-12 of libm's (kRootSteps' figure) inside the range.
  for (const double v : {1e-280, 0.3, 8.0, 1e280}) {
    EXPECT_NEAR(internal::FitCubeRoot(v) / std::cbrt(v), 1.0, 1.2e-12) << v;
  }
#endif
}

// What a scanner at the origin sees of a circle (centre c, radius r) with beams of full divergence
// div_rad: five rays across each beam (weights 0.1 0.2 0.4 0.2 0.1), the echo their weighted range
// where at least half of the weight hits (nothing behind), range noise noise_m.
View LookWithFootprint(const Eigen::Vector2d& c, double radius, double step_deg, double div_rad,
                       double noise_m, std::mt19937& rng) {
  std::normal_distribution<double> gauss(0.0, 1.0);
  constexpr std::array<double, 5> kOffset = {-1.0, -0.5, 0.0, 0.5, 1.0};
  constexpr std::array<double, 5> kWeight = {0.1, 0.2, 0.4, 0.2, 0.1};
  const double step = common::DegToRad(step_deg);
  const double bearing = std::atan2(c.y(), c.x());
  // Beams on a grid not aligned with the centre's bearing.
  const double phase = std::uniform_real_distribution<double>(-0.5, 0.5)(rng);
  View v;
  double first = 0.0, last = 0.0;
  for (int i = -60; i <= 60; ++i) {
    const double a = bearing + (i + phase) * step;
    double w = 0.0, wr = 0.0;
    for (std::size_t k = 0; k < kOffset.size(); ++k) {
      const double ak = a + kOffset[k] * 0.5 * div_rad;
      const Eigen::Vector2d d(std::cos(ak), std::sin(ak));
      const double along = d.dot(c);
      const double perp2 = c.squaredNorm() - along * along;
      if (perp2 > radius * radius) continue;
      w += kWeight[k];
      wr += kWeight[k] * (along - std::sqrt(radius * radius - perp2));
    }
    if (w < 0.5) continue;
    const double r = wr / w + noise_m * gauss(rng);
    if (v.points.empty()) first = a;
    last = a;
    v.points.emplace_back(r * std::cos(a), r * std::sin(a));
  }
  v.silhouette = {first - 0.5 * step, last + 0.5 * step, step, true, true};
  return v;
}

// Legs at knee height: radii drawn from 0.05-0.07 m, the fit with the leg prior 0.06 +- 0.015 m
// (ShapeOptions::leg_radius_m, leg_radius_sigma_m), ideal rays and beams 0.015 rad wide. The circle
// fit of a leg is not what pulls the legs' midpoint towards the sensor: its centre's radial mean
// stays within a few millimetres at 3 and 8 m, and its covariance holds the error.
TEST(ShapeFitTest, LegsOfVaryingRadiusAreNotPulledTowardsTheSensor) {
  std::mt19937 rng(14);
  std::uniform_real_distribution<double> radius_of(0.05, 0.07);
  for (const double range : {3.0, 8.0}) {
    for (const double step_deg : {0.5, 0.1667}) {
      for (const double div_rad : {0.0, 0.015}) {
        double radial_sum = 0.0, nees_sum = 0.0;
        int cases = 0;
        for (std::uint32_t draw = 1; draw <= 150; ++draw) {
          const double r = radius_of(rng);
          const double bearing = 0.01 * draw - 0.75;
          const Eigen::Vector2d c = range * Eigen::Vector2d(std::cos(bearing), std::sin(bearing));
          const View v = div_rad > 0.0 ? LookWithFootprint(c, r, step_deg, div_rad, 0.012, rng)
                                       : Look(testing::Cylinder(c, r), step_deg, 0.012, draw);
          ASSERT_FALSE(v.points.empty());
          ShapePrior prior;
          prior.model = ShapeModel::kCircle;
          prior.size_m = {0.06, 0.06};
          prior.size_cov_m2 = 0.015 * 0.015 * Eigen::Matrix2d::Identity();
          const ShapeFitResult fit = FitShape(v.points, v.silhouette, prior, ShapeFitOptions{});
          ASSERT_TRUE(fit.ok);
          radial_sum += fit.centre_m.norm() - range;
          nees_sum += Nees(fit, c);
          ++cases;
        }
        const double radial_mean = radial_sum / cases, nees = nees_sum / cases;
        SCOPED_TRACE("range " + std::to_string(range) + " step " + std::to_string(step_deg) +
                     " divergence " + std::to_string(div_rad) + ": radial mean " +
                     std::to_string(radial_mean) + " NEES " + std::to_string(nees));
        EXPECT_LT(std::abs(radial_mean), 0.006);
        EXPECT_GT(nees, 0.2);
        EXPECT_LT(nees, 3.0);
      }
    }
  }
}

// A 0.9 x 0.6 m cart seen from one corner at 4-8 m, the fit's size prior drawn from its own
// distribution (a track that learned the size to +-5 cm): over many noise draws the centre's
// NEES is about 2, neither flattering nor hiding the unseen sides' extent.
TEST(ShapeFitTest, BoxSeenFromOneCornerHasAnHonestCovariance) {
  std::mt19937 rng(7);
  std::normal_distribution<double> gauss(0.0, 1.0);
  const double size_sigma = 0.05;
  double nees_sum = 0.0;
  int cases = 0;
  for (std::uint32_t draw = 0; draw < 120; ++draw) {
    const double range = 4.0 + 4.0 * (draw % 5) / 4.0;
    const double yaw = common::DegToRad(20.0 + 50.0 * (draw % 7) / 6.0);  // a corner faces us
    const Eigen::Vector2d centre = range * Eigen::Vector2d(std::cos(0.2), std::sin(0.2));
    const double a = 0.45, b = 0.3;
    const View v = RenderBox(centre, yaw, a, b, 0.012, draw + 1);
    ASSERT_GE(v.points.size(), 4u);
    ShapePrior prior;
    prior.model = ShapeModel::kBox;
    prior.size_m = {a + size_sigma * gauss(rng), b + size_sigma * gauss(rng)};
    prior.size_cov_m2 = size_sigma * size_sigma * Eigen::Matrix2d::Identity();
    prior.yaw_rad = yaw + 0.1 * gauss(rng);
    prior.yaw_sigma_rad = 0.1;
    const ShapeFitResult fit = FitShape(v.points, v.silhouette, prior, ShapeFitOptions{});
    ASSERT_TRUE(fit.ok);
    nees_sum += Nees(fit, centre);
    ++cases;
  }
  const double nees = nees_sum / cases;
  RecordProperty("box_corner_nees", std::to_string(nees));
  EXPECT_GT(nees, 1.0) << nees;
  EXPECT_LT(nees, 3.5) << nees;
}

// The default range noise is the scanners' statistical error (1 sigma): no more than the
// largest of their datasheets' figures at any range (LMS1xx 12 mm, TiM 20 mm, LMS5xx 6 / 8 / 14
// mm at 1-10 / 10-20 / 20-30 m) plus the margin point_sigma_m leaves: 0.015 m at 0 m, 0.019 m at
// 20 m (with 0.001 per metre it was 0.035 m there, three times an LMS1xx's).
TEST(ShapeFitTest, DefaultRangeNoiseIsTheScannersStatisticalError) {
  const ShapeFitOptions o;
  EXPECT_NEAR(o.point_sigma_m + o.point_sigma_per_m * 0.0, 0.015, 1e-12);
  EXPECT_NEAR(o.point_sigma_m + o.point_sigma_per_m * 20.0, 0.019, 1e-12);
  EXPECT_LE(o.point_sigma_m + o.point_sigma_per_m * 30.0, 0.022);
}

// 2-4 points of a person of the prior's size (a = 0.23, b = 0.14 m) at 10-20 m, 0.5 deg beams,
// walking along the ray (seen from behind: the depth along the ray is the half-depth b) and
// across it (seen from the side: the depth is the shoulders' half-width a), the walking direction
// known as a track knows it: the centre lies that depth behind the points, within its covariance.
TEST(ShapeFitTest, FewPointsEndOnAndBroadsideGiveTheKnownDepth) {
  for (const bool end_on : {true, false}) {
    for (const double range : {10.0, 15.0, 20.0}) {
      const double off = 0.3 * common::DegToRad(0.5);  // not on a beam's centre
      const Eigen::Vector2d ray(std::cos(off), std::sin(off));
      // Axis a across the ray when walking along it (shoulders across), along it when across.
      const double yaw = end_on ? off + common::kPi / 2 : off;
      const Body body{range * ray, 0.23, 0.14, yaw};
      const View v = Look(body, 0.5, 0.0, 1);
      SCOPED_TRACE(std::string(end_on ? "end-on" : "broadside") + " at " + std::to_string(range) +
                   " m");
      ASSERT_GE(v.points.size(), 2u);
      ASSERT_LE(v.points.size(), 4u + (range < 12.0 ? 2u : 0u));
      ShapePrior prior;
      prior.exponent = 2.0;
      prior.yaw_rad = yaw;
      prior.yaw_sigma_rad = 0.35;
      const ShapeFitResult fit = FitShape(v.points, v.silhouette, prior, ShapeFitOptions{});
      ASSERT_TRUE(fit.ok);
      const Eigen::Vector2d e = fit.centre_m - body.centre_m;
      const double depth = end_on ? 0.14 : 0.23;
      double nearest = range;
      for (const auto& p : v.points) nearest = std::min(nearest, p.dot(ray));
      // The centre lies the depth behind the nearest point, a few centimetres at most off.
      EXPECT_NEAR(fit.centre_m.dot(ray) - nearest, depth, 0.03);
      EXPECT_LT(std::abs(e.dot(ray)), 0.03);
      EXPECT_LT(Nees(fit, body.centre_m), 9.21);
    }
  }
}

// A back seen end-on at 9 m of which the scan shows two beams, one silhouette end the body's and
// the other where its neighbouring beams were taken for the background (the segment ends there,
// the beam beyond returned from the body too): the fit's size says a sliver of a person, far below
// the truth, with a sigma a fraction of that error; a track that learns it (ShapeOptions::
// person_size_min_points 0) ends with a third of the shoulders.
TEST(ShapeFitTest, TwoPointsOfATruncatedBackDoNotShowThePersonsSize) {
  const double off = 0.3 * common::DegToRad(0.5);
  const Eigen::Vector2d ray(std::cos(off), std::sin(off));
  const Body body{9.0 * ray, 0.23, 0.14, off + common::kPi / 2};
  const View whole = Look(body, 0.5, 0.0, 1);
  ASSERT_GE(whole.points.size(), 5u);
  View v;
  v.points.assign(whole.points.begin(), whole.points.begin() + 2);
  v.silhouette = whole.silhouette;
  // The second point's beam plus half a step: where the segment ended.
  v.silhouette.last_edge_rad =
      std::atan2(v.points[1].y(), v.points[1].x()) +
      0.5 * (whole.silhouette.last_edge_rad > whole.silhouette.first_edge_rad
                 ? whole.silhouette.step_rad
                 : -whole.silhouette.step_rad);
  ShapePrior prior;
  prior.exponent = 2.0;
  prior.yaw_rad = body.yaw_rad;
  prior.yaw_sigma_rad = 0.35;
  const ShapeFitResult fit = FitShape(v.points, v.silhouette, prior, ShapeFitOptions{});
  ASSERT_TRUE(fit.ok);
  const double a_error = 0.23 - fit.size_m.x();
  std::printf("truncated back: size %.3f x %.3f (sigma %.3f), centre off %.3f m along the ray\n",
              fit.size_m.x(), fit.size_m.y(), std::sqrt(fit.size_cov_m2(0, 0)),
              (fit.centre_m - body.centre_m).dot(ray));
  EXPECT_GT(a_error, 0.05);
  EXPECT_LT(std::sqrt(fit.size_cov_m2(0, 0)), 0.5 * a_error);
  // Scan after scan of the same view (a track's size state learned as the pipeline does, a
  // quarter of each fit's information, or kept): learned, the shoulders shrink to a third.
  for (const bool learn : {true, false}) {
    TrackShape shape;
    shape.model = ShapeModel::kSuperellipse;
    shape.size_m = prior.size_m;
    shape.size_cov_m2 = prior.size_cov_m2;
    ShapeFitResult last;
    for (int k = 0; k < 30; ++k) {
      ShapePrior p = prior;
      p.size_m = shape.size_m;
      p.size_cov_m2 = shape.size_cov_m2 + 0.003 * 0.003 * 0.04 * Eigen::Matrix2d::Identity();
      last = FitShape(v.points, v.silhouette, p, ShapeFitOptions{});
      ASSERT_TRUE(last.ok);
      if (learn) internal::LearnSize(last.size_m, last.size_cov_m2, 0.25, {true, true}, shape);
    }
    const double radial = (last.centre_m - body.centre_m).dot(ray);
    std::printf("%s: size %.3f x %.3f, centre %+.3f m along the ray, NEES %.1f\n",
                learn ? "learned" : "kept", shape.size_m.x(), shape.size_m.y(), radial,
                Nees(last, body.centre_m));
    if (learn) {
      EXPECT_LT(shape.size_m.x(), 0.12);  // half the person's shoulders
    } else {
      EXPECT_NEAR(shape.size_m.x(), 0.23, 1e-12);
    }
    EXPECT_LT(std::abs(radial), 0.05);
  }
}

}  // namespace
}  // namespace lrfnet::tracking
