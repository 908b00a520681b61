#include "firmware_tracker/tracking/measurement.h"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <cmath>
#include <limits>
#include <vector>

#include "common/geometry.h"
#include "firmware_tracker/tracking/segmentation.h"
#include "firmware_tracker/tracking/tracking_test_util.h"

namespace lrfnet::tracking {
namespace {

using testing::Body;
using testing::SyntheticScanner;

// The visible points of one body (its near side), as the scanner sees it.
std::vector<Eigen::Vector2d> VisiblePoints(const Body& body, double noise_sigma_m,
                                           std::uint32_t seed, double step_deg = 0.25) {
  testing::ScannerConfig config;
  config.first_angle_rad = common::DegToRad(-90.0);
  config.angle_step_rad = common::DegToRad(step_deg);
  config.beams = static_cast<std::size_t>(180.0 / step_deg) + 1;
  config.noise_sigma_m = noise_sigma_m;
  config.seed = seed;
  SyntheticScanner scanner(config);
  const std::vector<Body> bodies = {body};
  const ScanView scan = scanner.Render(0, {}, bodies);
  std::vector<Eigen::Vector2d> pts;
  for (std::size_t i = 0; i < scan.range_m.size(); ++i) {
    if (scan.range_m[i] <= 0.0f) continue;
    const double a = scan.BeamAngleRad(i);
    pts.emplace_back(scan.range_m[i] * std::cos(a), scan.range_m[i] * std::sin(a));
  }
  return pts;
}

bool SymmetricPositiveDefinite(const Eigen::Matrix2d& m) {
  return m.allFinite() && (m - m.transpose()).cwiseAbs().maxCoeff() < 1e-12 &&
         Eigen::LLT<Eigen::Matrix2d>(m).info() == Eigen::Success;
}

TEST(MeasurementOptionsTest, DefaultsValidAndBadValuesRejected) {
  EXPECT_EQ(Validate(MeasurementOptions{}), std::nullopt);
  MeasurementOptions o;
  o.ellipse_minor_m = 0.3;  // larger than the major axis
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.min_ellipse_points = 3;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.max_position_sigma_m = 0.001;
  EXPECT_NE(Validate(o), std::nullopt);
}

TEST(ConicEllipseTest, RecoversAFullEllipse) {
  std::vector<Eigen::Vector2d> pts;
  const Eigen::Vector2d c(4.0, -2.0);
  const double a = 0.6, b = 0.3, yaw = 0.4;
  for (int i = 0; i < 40; ++i) {
    const double t = 2.0 * common::kPi * i / 40.0;
    const Eigen::Vector2d e(a * std::cos(t), b * std::sin(t));
    pts.push_back(c + Eigen::Vector2d(std::cos(yaw) * e.x() - std::sin(yaw) * e.y(),
                                      std::sin(yaw) * e.x() + std::cos(yaw) * e.y()));
  }
  const auto fit = FitConicEllipse(pts);
  ASSERT_TRUE(fit.has_value());
  EXPECT_NEAR(fit->center_m.x(), c.x(), 1e-6);
  EXPECT_NEAR(fit->center_m.y(), c.y(), 1e-6);
  EXPECT_NEAR(fit->semi_major_m, a, 1e-6);
  EXPECT_NEAR(fit->semi_minor_m, b, 1e-6);
  EXPECT_NEAR(fit->orientation_rad, yaw, 1e-6);
}

TEST(ConicEllipseTest, DegenerateInputsGiveNoEllipse) {
  EXPECT_FALSE(FitConicEllipse(std::vector<Eigen::Vector2d>{{1, 1}, {2, 2}, {3, 1}, {2, 0}}));
  std::vector<Eigen::Vector2d> line;
  for (int i = 0; i < 10; ++i) line.emplace_back(2.0 + 0.1 * i, 1.0 + 0.05 * i);
  EXPECT_FALSE(FitConicEllipse(line));
  std::vector<Eigen::Vector2d> same(10, Eigen::Vector2d(3.0, 1.0));
  EXPECT_FALSE(FitConicEllipse(same));
  line[3].x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(FitConicEllipse(line));
}

TEST(MeasurementTest, CenterOfMassIsTheMean) {
  const std::vector<Eigen::Vector2d> pts = {{1, 0}, {3, 0}, {2, 3}};
  const Eigen::Vector2d c = CenterOfMass(pts);
  EXPECT_DOUBLE_EQ(c.x(), 2.0);
  EXPECT_DOUBLE_EQ(c.y(), 1.0);
}

TEST(MeasurementTest, FixedAxesEllipseFindsThePersonCentreFromTheVisibleArc) {
  const MeasurementOptions o;
  // Several people at different distances and orientations, noisy ranges.
  const std::vector<Body> people = {{{5.0, 1.0}, 0.25, 0.15, 0.3},
                                    {{3.0, -1.5}, 0.25, 0.15, 1.2},
                                    {{7.0, 0.0}, 0.25, 0.15, -0.7},
                                    {{2.0, 2.0}, 0.25, 0.15, 0.0}};
  std::uint32_t seed = 3;
  double sum_error_m = 0.0;
  int fits = 0;
  for (const Body& person : people) {
    for (int trial = 0; trial < 5; ++trial) {
      const auto pts = VisiblePoints(person, 0.01, seed++);
      ASSERT_GE(pts.size(), 10u);
      const Measurement m = MeasureSegment(pts, o);
      ASSERT_EQ(m.kind, MeasurementKind::kEllipse) << "person at " << person.centre_m.transpose();
      EXPECT_LT((m.position_m - person.centre_m).norm(), 0.03)
          << "person at " << person.centre_m.transpose() << " fitted " << m.position_m.transpose();
      sum_error_m += (m.position_m - person.centre_m).norm();
      ++fits;
      const Eigen::Vector2d com = CenterOfMass(pts);
      EXPECT_GT(m.position_m.norm(), com.norm()) << "centre lies behind the visible points";
      EXPECT_LT((m.position_m - person.centre_m).norm(), (com - person.centre_m).norm());
      EXPECT_TRUE(SymmetricPositiveDefinite(m.covariance_m2));
      EXPECT_GE(m.covariance_m2.eigenvalues().real().minCoeff(),
                o.min_position_sigma_m * o.min_position_sigma_m * (1 - 1e-9));
      EXPECT_LT(m.rms_residual_m, 0.03);
      EXPECT_EQ(m.point_count, pts.size());
    }
  }
  // Millimetre-level on average: pushing the CoM back by b along the line of sight would be off by
  // several centimetres for most orientations.
  EXPECT_LT(sum_error_m / fits, 0.012);
}

TEST(MeasurementTest, CylinderCentreLiesBehindTheCenterOfMass) {
  const Body cylinder = testing::Cylinder({4.0, 0.5}, 0.25);
  const auto pts = VisiblePoints(cylinder, 0.005, 11);
  const Measurement m = MeasureSegment(pts, MeasurementOptions{});
  ASSERT_EQ(m.kind, MeasurementKind::kEllipse);
  const Eigen::Vector2d com = CenterOfMass(pts);
  const Eigen::Vector2d ray = com.normalized();
  EXPECT_GT((m.position_m - com).dot(ray), 0.08) << "pushed back along the line of sight";
  EXPECT_LT((m.position_m - cylinder.centre_m).norm(), (com - cylinder.centre_m).norm());
  EXPECT_LT((m.position_m - cylinder.centre_m).norm(), 0.12);
}

TEST(MeasurementTest, CenterOfMassWhenEllipseDisabledOrTooFewPoints) {
  const auto pts = VisiblePoints({{5.0, 1.0}, 0.25, 0.15, 0.3}, 0.01, 5);
  MeasurementOptions o;
  o.fit_ellipse = false;
  Measurement m = MeasureSegment(pts, o);
  EXPECT_EQ(m.kind, MeasurementKind::kCenterOfMass);
  EXPECT_TRUE(m.position_m.isApprox(CenterOfMass(pts)));
  EXPECT_NEAR(m.covariance_m2(0, 0), o.com_sigma_m * o.com_sigma_m, 1e-12);

  const std::vector<Eigen::Vector2d> three = {pts[0], pts[1], pts[2]};
  m = MeasureSegment(three, MeasurementOptions{});
  EXPECT_EQ(m.kind, MeasurementKind::kCenterOfMass);
}

TEST(MeasurementTest, DegenerateSegmentsNeverCrashAndGiveFiniteResults) {
  std::vector<std::vector<Eigen::Vector2d>> cases;
  cases.push_back({{2.0, 0.0}});
  cases.push_back({{2.0, 0.0}, {2.0, 0.0}});
  cases.push_back(std::vector<Eigen::Vector2d>(20, Eigen::Vector2d(3.0, 1.0)));
  std::vector<Eigen::Vector2d> line;  // a straight piece of wall
  for (int i = 0; i < 30; ++i) line.emplace_back(4.0, -0.3 + 0.02 * i);
  cases.push_back(line);
  std::vector<Eigen::Vector2d> at_origin(8, Eigen::Vector2d::Zero());
  cases.push_back(at_origin);
  std::vector<Eigen::Vector2d> huge;  // a far, wide arc
  for (int i = 0; i < 50; ++i)
    huge.emplace_back(1e3 * std::cos(0.01 * i), 1e3 * std::sin(0.01 * i));
  cases.push_back(huge);
  std::vector<Eigen::Vector2d> many;  // more points than the ellipse scratch holds
  for (std::size_t i = 0; i < kMaxSegmentPoints + 100; ++i) {
    many.emplace_back(1.0 + 1e-4 * static_cast<double>(i),
                      0.3 * std::sin(1e-3 * static_cast<double>(i)));
  }
  cases.push_back(many);
  for (const auto& pts : cases) {
    const Measurement m = MeasureSegment(pts, MeasurementOptions{});
    EXPECT_TRUE(m.position_m.allFinite());
    EXPECT_TRUE(SymmetricPositiveDefinite(m.covariance_m2));
    EXPECT_EQ(m.point_count, pts.size());
  }
}

}  // namespace
}  // namespace lrfnet::tracking
