#include "central_daemon/ingest/measurement_model.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

namespace lrfnet::daemon {
namespace {

constexpr double kPi = std::numbers::pi;

// The centre of mass of the beams of a scanner (uniform angular steps from the origin) that hit a
// circle of radius r centred at range d on the x axis, averaged over the beam phase: what a
// centre-of-mass tracker reports on average.
double RayCastComBias(double d, double r, double step_rad) {
  const int phases = 50;
  double sum = 0.0;
  int counted = 0;
  for (int k = 0; k < phases; ++k) {
    const double phase = (k + 0.5) / phases * step_rad;
    double cx = 0.0;
    int n = 0;
    for (double a = -0.2 + phase; a < 0.2; a += step_rad) {
      // Ray (cos a, sin a) against the circle: t^2 - 2 d cos(a) t + d^2 - r^2 = 0, nearest root.
      const double b = d * std::cos(a);
      const double disc = b * b - (d * d - r * r);
      if (disc < 0.0) continue;
      const double t = b - std::sqrt(disc);
      cx += t * std::cos(a);
      ++n;
    }
    if (n == 0) continue;
    sum += d - cx / n;
    ++counted;
  }
  return sum / counted;
}

MeasurementContext At(double x, double y, MeasurementKind kind) {
  MeasurementContext c;
  c.kind = kind;
  c.x_m = x;
  c.y_m = y;
  c.points = 5;
  return c;
}

TEST(MeasurementModel, CentreOfMassOfACylinderMatchesARayCastAtEveryRangeAndPointCount) {
  const MeasurementModelOptions o;
  for (const double range : {3.0, 8.0, 15.0, 25.0}) {
    // 0.5 deg beams: from ~30 points at 3 m down to ~2 at 25 m.
    const double cast = RayCastComBias(range, 0.25, 0.5 * kPi / 180.0);
    MeasurementContext c = At(range, 0.0, MeasurementKind::kCenterOfMass);
    c.shape = ObjectShape::kCylinder;
    c.size_major_m = c.size_minor_m = 0.25;
    const CentreBias b = CentreBiasOf(c, o);
    EXPECT_NEAR(b.toward_sensor_m, kPi * 0.25 / 4.0, 1e-12);
    EXPECT_NEAR(b.toward_sensor_m, cast, 0.01) << "range " << range;
    // The tracker measured the size: nothing shared with the prior.
    EXPECT_EQ(b.per_major_m_per_m, 0.0);
    EXPECT_EQ(b.per_minor_m_per_m, 0.0);
  }
}

TEST(MeasurementModel, CentreOfMassOfAPersonDependsOnTheViewOfTheTorso) {
  const MeasurementModelOptions o;  // prior torso 0.25 x 0.15
  // Walking towards the sensor: the line of sight is along the minor axis (chest), depth 0.15.
  MeasurementContext towards = At(10.0, 0.0, MeasurementKind::kCenterOfMass);
  towards.vx_mps = -1.2;
  EXPECT_NEAR(CentreBiasOf(towards, o).toward_sensor_m, kPi / 4.0 * 0.15, 1e-9);
  // Walking across: the line of sight is along the shoulders, depth 0.25.
  MeasurementContext across = At(10.0, 0.0, MeasurementKind::kCenterOfMass);
  across.vy_mps = 1.2;
  EXPECT_NEAR(CentreBiasOf(across, o).toward_sensor_m, kPi / 4.0 * 0.25, 1e-9);
  // Standing (orientation unknown): in between, with the spread as size uncertainty.
  const CentreBias standing = CentreBiasOf(At(10.0, 0.0, MeasurementKind::kCenterOfMass), o);
  EXPECT_GT(standing.toward_sensor_m, kPi / 4.0 * 0.15);
  EXPECT_LT(standing.toward_sensor_m, kPi / 4.0 * 0.25);
  EXPECT_GT(standing.size_sigma_m, 0.01);
  EXPECT_EQ(CentreBiasOf(towards, o).size_sigma_m, 0.0);
}

TEST(MeasurementModel, FixedAxesEllipseIsUnbiasedOnItsOwnShapeAndBiasedOnOthers) {
  const MeasurementModelOptions o;
  for (double yaw = -kPi; yaw < kPi; yaw += 0.3) {
    MeasurementContext c = At(6.0, 2.0, MeasurementKind::kEllipse);
    c.has_ellipse_yaw = true;
    c.ellipse_yaw_rad = yaw;
    EXPECT_NEAR(CentreBiasOf(c, o).toward_sensor_m, 0.0, 1e-12) << yaw;
  }
  // A 0.25 m cylinder whose fit lies across the line of sight: 0.25 - 0.15 = 0.1 m.
  MeasurementContext cylinder = At(6.0, 0.0, MeasurementKind::kEllipse);
  cylinder.has_ellipse_yaw = true;
  cylinder.ellipse_yaw_rad = kPi / 2.0;
  cylinder.size_major_m = cylinder.size_minor_m = 0.25;
  EXPECT_NEAR(CentreBiasOf(cylinder, o).toward_sensor_m, 0.10, 1e-12);
}

TEST(MeasurementModel, ShapeFitIsTheBodyCentreWithItsSizeUncertainty) {
  const MeasurementModelOptions o;
  MeasurementContext c = At(12.0, -3.0, MeasurementKind::kShapeFit);
  c.size_major_m = 0.22;
  c.size_minor_m = 0.13;
  c.size_sigma_m = 0.04;
  const CentreBias b = CentreBiasOf(c, o);
  EXPECT_EQ(b.toward_sensor_m, 0.0);
  EXPECT_EQ(b.size_sigma_m, 0.04);
  c.size_sigma_m = 0.0;  // not sent: the default
  EXPECT_EQ(CentreBiasOf(c, o).size_sigma_m, o.shape_fit_size_sigma_m);
  EXPECT_EQ(CentreBiasOf(c, o).shared_sigma_m, o.shape_fit_shared_bias_sigma_m);
}

TEST(MeasurementModel, SensitivitiesAreTheDerivativesOfThePriorSize) {
  for (const MeasurementKind kind : {MeasurementKind::kCenterOfMass, MeasurementKind::kEllipse}) {
    for (double heading = 0.0; heading < kPi; heading += 0.4) {
      MeasurementContext c = At(7.0, 4.0, kind);
      c.vx_mps = std::cos(heading);
      c.vy_mps = std::sin(heading);
      c.has_ellipse_yaw = kind == MeasurementKind::kEllipse;
      c.ellipse_yaw_rad = heading + 0.3;
      MeasurementModelOptions o;
      const CentreBias b = CentreBiasOf(c, o);
      const double h = 1e-6;
      o.prior_major_m += h;
      const double d_major = (CentreBiasOf(c, o).toward_sensor_m - b.toward_sensor_m) / h;
      o.prior_major_m -= h;
      o.prior_minor_m += h;
      const double d_minor = (CentreBiasOf(c, o).toward_sensor_m - b.toward_sensor_m) / h;
      EXPECT_NEAR(b.per_major_m_per_m, d_major, 1e-5);
      EXPECT_NEAR(b.per_minor_m_per_m, d_minor, 1e-5);
    }
  }
}

TEST(MeasurementModel, LegsWithoutSizeUseTheLegPrior) {
  const MeasurementModelOptions o;
  MeasurementContext c = At(5.0, 0.0, MeasurementKind::kCenterOfMass);
  c.shape = ObjectShape::kLegs;
  EXPECT_NEAR(CentreBiasOf(c, o).toward_sensor_m, kPi / 4.0 * o.prior_leg_radius_m, 1e-12);
  EXPECT_EQ(CentreBiasOf(c, o).per_major_m_per_m, 0.0);
}

TEST(MeasurementModel, CorrectedPositionMovesAwayFromTheSensor) {
  const MeasurementModelOptions o;
  TrackObservation obs;
  obs.kind = MeasurementKind::kCenterOfMass;
  obs.x_m = 3.0f;
  obs.y_m = 4.0f;
  obs.vx_mps = -0.6f;  // towards the sensor: depth 0.15
  obs.vy_mps = -0.8f;
  const CorrectedPosition p = CorrectedPositionOf(obs, o);
  const double b = kPi / 4.0 * 0.15;
  EXPECT_NEAR(p.x_m, 3.0 + 0.6 * b, 1e-6);
  EXPECT_NEAR(p.y_m, 4.0 + 0.8 * b, 1e-6);
  // The prior's size uncertainty is in the variance (fusion does not estimate it).
  EXPECT_GT(p.extra_variance_m2, o.com_sigma_m * o.com_sigma_m);
}

TEST(MeasurementModel, HostileValuesGiveFiniteResults) {
  const MeasurementModelOptions o;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<MeasurementContext> cases;
  cases.push_back(At(nan, 1.0, MeasurementKind::kCenterOfMass));
  cases.push_back(At(inf, 1.0, MeasurementKind::kEllipse));
  cases.push_back(At(0.0, 0.0, MeasurementKind::kCenterOfMass));
  MeasurementContext c = At(5.0, 1.0, MeasurementKind::kCenterOfMass);
  c.vx_mps = inf;
  c.size_major_m = nan;
  c.size_minor_m = -1.0;
  cases.push_back(c);
  c = At(5.0, 1.0, MeasurementKind::kShapeFit);
  c.size_sigma_m = inf;
  cases.push_back(c);
  c = At(5.0, 1.0, MeasurementKind::kEllipse);
  c.has_ellipse_yaw = true;
  c.ellipse_yaw_rad = nan;
  c.size_major_m = 1e30;
  c.size_minor_m = 1e30;
  cases.push_back(c);
  c = At(5.0, 1.0, static_cast<MeasurementKind>(200));
  cases.push_back(c);
  for (const MeasurementContext& x : cases) {
    const CentreBias b = CentreBiasOf(x, o);
    EXPECT_TRUE(std::isfinite(b.toward_sensor_m));
    EXPECT_TRUE(std::isfinite(b.per_major_m_per_m) && std::isfinite(b.per_minor_m_per_m));
    EXPECT_TRUE(std::isfinite(b.size_sigma_m) && b.size_sigma_m >= 0.0);
    EXPECT_TRUE(std::isfinite(b.sigma_m) && b.sigma_m >= 0.0);
    EXPECT_LT(std::abs(b.toward_sensor_m), 5.0);
  }
}

TEST(MeasurementModel, ValidateNamesTheField) {
  MeasurementModelOptions o;
  EXPECT_FALSE(Validate(o).has_value());
  o.prior_minor_m = 0.0;
  ASSERT_TRUE(Validate(o).has_value());
  EXPECT_NE(Validate(o)->find("prior_minor_m"), std::string::npos);
  o = {};
  o.com_sigma_m = -1.0;
  EXPECT_TRUE(Validate(o).has_value());
  o = {};
  o.min_heading_speed_mps = std::numeric_limits<double>::quiet_NaN();
  EXPECT_TRUE(Validate(o).has_value());
}

}  // namespace
}  // namespace lrfnet::daemon
