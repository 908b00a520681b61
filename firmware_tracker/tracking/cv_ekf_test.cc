#include "firmware_tracker/tracking/cv_ekf.h"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <cmath>
#include <limits>
#include <random>

#include "common/cv_model.h"

namespace lrfnet::tracking {
namespace {

bool SymmetricPositiveDefinite(const Eigen::Matrix4d& p) {
  return p.allFinite() && p == p.transpose() &&
         Eigen::LLT<Eigen::Matrix4d>(p).info() == Eigen::Success;
}

TEST(CvEkfOptionsTest, DefaultsValidAndBadValuesRejected) {
  EXPECT_EQ(Validate(CvEkfOptions{}), std::nullopt);
  EXPECT_NE(Validate(CvEkfOptions{.accel_psd_m2ps3 = 0.0}), std::nullopt);
  EXPECT_NE(Validate(CvEkfOptions{.initial_velocity_sigma_mps = -1.0}), std::nullopt);
}

TEST(CvEkfTest, StraightWalkConvergesToTheVelocity) {
  const Eigen::Vector2d start(1.0, -3.0);
  const Eigen::Vector2d velocity(1.2 * std::cos(0.6), 1.2 * std::sin(0.6));  // 1.2 m/s
  const double dt = 0.04, sigma = 0.03;
  const Eigen::Matrix2d r = sigma * sigma * Eigen::Matrix2d::Identity();
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0.0, sigma);
  // A steady walker: low acceleration noise (the default suits people who stop and turn).
  CvEkf ekf{CvEkfOptions{.accel_psd_m2ps3 = 0.05}};
  ekf.Init(start, r);
  for (int k = 1; k <= 250; ++k) {  // 10 s at 25 Hz
    ekf.Predict(dt);
    const Eigen::Vector2d truth = start + velocity * (k * dt);
    ASSERT_TRUE(ekf.Update(truth + Eigen::Vector2d(noise(rng), noise(rng)), r));
    ASSERT_TRUE(SymmetricPositiveDefinite(ekf.covariance())) << "step " << k;
  }
  EXPECT_LT((ekf.velocity_mps() - velocity).norm(), 0.15);
  EXPECT_LT((ekf.position_m() - (start + velocity * 10.0)).norm(), 0.05);
  // The filter's velocity uncertainty shrank far below the 1.5 m/s prior and is consistent with the
  // error.
  const double velocity_sigma = std::sqrt(ekf.covariance()(2, 2));
  EXPECT_LT(velocity_sigma, 0.15);
  EXPECT_LT(std::abs(ekf.velocity_mps().x() - velocity.x()), 3.0 * velocity_sigma);
}

TEST(CvEkfTest, PredictGrowsUncertaintyAndMovesWithVelocity) {
  CvEkf ekf{CvEkfOptions{}};
  ekf.Init({0.0, 0.0}, 0.01 * Eigen::Matrix2d::Identity());
  const Eigen::Matrix2d r = 0.0001 * Eigen::Matrix2d::Identity();
  for (int k = 1; k <= 50; ++k) {
    ekf.Predict(0.1);
    ASSERT_TRUE(ekf.Update({0.5 * k * 0.1, 0.0}, r));
  }
  const double p_before = ekf.covariance()(0, 0);
  const double x_before = ekf.position_m().x();
  ekf.Predict(1.0);
  EXPECT_GT(ekf.covariance()(0, 0), p_before);
  EXPECT_NEAR(ekf.position_m().x() - x_before, 0.5, 0.05);
  EXPECT_TRUE(SymmetricPositiveDefinite(ekf.covariance()));

  const auto frozen = ekf.state();
  ekf.Predict(0.0);
  ekf.Predict(-1.0);
  ekf.Predict(std::nan(""));
  EXPECT_EQ(ekf.state(), frozen);
}

TEST(CvEkfTest, MahalanobisDistanceGatesFarMeasurements) {
  CvEkf ekf{CvEkfOptions{}};
  const Eigen::Matrix2d r = 0.01 * Eigen::Matrix2d::Identity();
  ekf.Init({2.0, 1.0}, r);
  EXPECT_NEAR(ekf.MahalanobisSq({2.0, 1.0}, r), 0.0, 1e-12);
  // One sigma of the innovation (P + R = 0.02) along x.
  EXPECT_NEAR(ekf.MahalanobisSq({2.0 + std::sqrt(0.02), 1.0}, r), 1.0, 1e-9);
  EXPECT_GT(ekf.MahalanobisSq({4.0, 1.0}, r), 100.0);
  EXPECT_TRUE(std::isinf(ekf.MahalanobisSq({2.0, 1.0}, -Eigen::Matrix2d::Identity())));
}

// The update with H's structure spelt out against the textbook matrices (H = [I 0], the gain from
// an explicit inverse, Joseph form), on random states and measurement covariances: equal up to
// rounding.
TEST(CvEkfTest, UpdateIsTheTextbookJosephFormUpdate) {
  std::mt19937 rng(14);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k < 200; ++k) {
    CvEkf ekf{CvEkfOptions{}};
    Eigen::Matrix2d a;
    a << u(rng), u(rng), u(rng), u(rng);
    const Eigen::Matrix2d r0 = 0.01 * (a * a.transpose() + 0.1 * Eigen::Matrix2d::Identity());
    ekf.Init({5.0 * u(rng), 5.0 * u(rng)}, r0);
    ekf.Predict(0.04 + 0.2 * (u(rng) + 1.0));
    a << u(rng), u(rng), u(rng), u(rng);
    const Eigen::Matrix2d r = 0.005 * (a * a.transpose() + 0.05 * Eigen::Matrix2d::Identity());
    const Eigen::Vector2d z = ekf.state().head<2>() + Eigen::Vector2d(0.3 * u(rng), 0.3 * u(rng));
    const CvEkf::State x = ekf.state();
    const CvEkf::Covariance p = ekf.covariance();
    Eigen::Matrix<double, 2, 4> h = Eigen::Matrix<double, 2, 4>::Zero();
    h(0, 0) = h(1, 1) = 1.0;
    const Eigen::Matrix<double, 4, 2> gain =
        p * h.transpose() * (h * p * h.transpose() + r).inverse();
    const CvEkf::State x_expected = x + gain * (z - h * x);
    const Eigen::Matrix4d i_kh = Eigen::Matrix4d::Identity() - gain * h;
    const Eigen::Matrix4d p_expected = i_kh * p * i_kh.transpose() + gain * r * gain.transpose();
    ASSERT_TRUE(ekf.Update(z, r));
    EXPECT_LT((ekf.state() - x_expected).norm(), 1e-12 * (1.0 + x_expected.norm())) << k;
    EXPECT_LT((ekf.covariance() - p_expected).norm(), 1e-12 * p_expected.norm()) << k;
    EXPECT_TRUE(SymmetricPositiveDefinite(ekf.covariance())) << k;
  }
}

// Predict forms the covariance from its upper triangle (common::CvPredictSymmetricCovariance):
// the same as common::CvPredict's two passes and 4 x 4 average, bit for bit where multiply-adds
// are not fused (else to a few units in the last place), the gain covariance's too; and the gain
// covariance's multiplied-out Joseph update is the textbook one with the other noise.
TEST(CvEkfTest, PredictAndGainCovarianceAreTheTextbookSteps) {
  std::mt19937 rng(21);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::Matrix<double, 2, 4> h = Eigen::Matrix<double, 2, 4>::Zero();
  h(0, 0) = h(1, 1) = 1.0;
  const auto random_noise = [&](double scale) {
    Eigen::Matrix2d a;
    a << u(rng), u(rng), u(rng), u(rng);
    return Eigen::Matrix2d(scale * (a * a.transpose() + 0.05 * Eigen::Matrix2d::Identity()));
  };
  int predictions_checked = 0;
  for (int k = 0; k < 100; ++k) {
    const CvEkfOptions options{.accel_psd_m2ps3 = 0.2 + (u(rng) + 1.0)};
    CvEkf ekf{options};
    ekf.Init({5.0 * u(rng), 5.0 * u(rng)}, random_noise(0.01));
    ekf.StartGainCovariance();
    for (int step = 0; step < 6; ++step) {
      const double dt_s = 0.04 + 0.2 * (u(rng) + 1.0);
      common::CvState x = ekf.state();
      common::CvCovariance p = ekf.covariance();
      common::CvCovariance pg = ekf.gain_covariance();
      common::CvPredict(dt_s, options.accel_psd_m2ps3, x, p);
      common::CvPredictCovariance(dt_s, options.accel_psd_m2ps3, pg);
      ekf.Predict(dt_s);
#ifdef __FP_FAST_FMA
      const double tol = 16.0 * std::numeric_limits<double>::epsilon();
      EXPECT_LT((ekf.state() - x).norm(), tol * x.norm()) << k;
      EXPECT_LT((ekf.covariance() - p).norm(), tol * p.norm()) << k;
      EXPECT_LT((ekf.gain_covariance() - pg).norm(), tol * pg.norm()) << k;
#else
      EXPECT_EQ(ekf.state(), x) << k;
      EXPECT_EQ(ekf.covariance(), p) << k;
      EXPECT_EQ(ekf.gain_covariance(), pg) << k;
#endif
      ++predictions_checked;
      const Eigen::Matrix2d r = random_noise(0.005);
      const Eigen::Matrix2d r_gain = random_noise(0.002);
      const Eigen::Vector2d z = ekf.state().head<2>() + Eigen::Vector2d(0.3 * u(rng), 0.3 * u(rng));
      const Eigen::Matrix<double, 4, 2> gain =
          p * h.transpose() * (h * p * h.transpose() + r).inverse();
      const Eigen::Matrix4d i_kh = Eigen::Matrix4d::Identity() - gain * h;
      const Eigen::Matrix4d pg_expected =
          i_kh * pg * i_kh.transpose() + gain * r_gain * gain.transpose();
      ASSERT_TRUE(ekf.Update(z, r, &r_gain));
      EXPECT_LT((ekf.gain_covariance() - pg_expected).norm(), 1e-12 * pg_expected.norm()) << k;
      EXPECT_GT((ekf.gain_covariance() - ekf.covariance()).norm(), 1e-6 * pg_expected.norm()) << k;
      EXPECT_TRUE(SymmetricPositiveDefinite(ekf.gain_covariance())) << k;
    }
  }
  EXPECT_EQ(predictions_checked, 600);
}

// The gain covariance is formed apart from the filter's own only from the first update whose
// noise is not R: until then it is covariance() itself; from then on it is the textbook recursion
// started at StartGainCovariance (predictions, inflations and Joseph updates with the other noise);
// a restart or a new Init makes it the filter's covariance again.
TEST(CvEkfTest, GainCovarianceGoesApartAtTheFirstOtherNoiseAndRestarts) {
  const CvEkfOptions options{};
  CvEkf ekf{options};
  const Eigen::Matrix2d r = 0.015 * 0.015 * Eigen::Matrix2d::Identity();
  Eigen::Matrix2d r_other;
  r_other << 0.004 * 0.004, 0.000002, 0.000002, 0.006 * 0.006;
  Eigen::Matrix<double, 2, 4> h = Eigen::Matrix<double, 2, 4>::Zero();
  h(0, 0) = h(1, 1) = 1.0;
  ekf.Init({1.0, 2.0}, r);
  ekf.StartGainCovariance();
  common::CvCovariance pg = ekf.covariance();  // the textbook recursion, by hand
  const auto step = [&](int k, const Eigen::Matrix2d& gain_r) {
    const double dt_s = 0.04;
    common::CvPredictCovariance(dt_s, options.accel_psd_m2ps3, pg);
    ekf.Predict(dt_s);
    if (k == 3) {
      ekf.InflateCovariance(2.5);
      pg *= 2.5;
    }
    const common::CvCovariance p = ekf.covariance();
    const Eigen::Matrix<double, 4, 2> gain =
        p * h.transpose() * (h * p * h.transpose() + r).inverse();
    const Eigen::Matrix4d i_kh = Eigen::Matrix4d::Identity() - gain * h;
    pg = (i_kh * pg * i_kh.transpose() + gain * gain_r * gain.transpose()).eval();
    const Eigen::Vector2d z(1.0 + 0.04 * k, 2.0 + 0.01 * (k % 3));
    ASSERT_TRUE(ekf.Update(z, r, &gain_r));
  };
  for (int k = 1; k <= 5; ++k) {
    step(k, r);  // told R as the gain's noise too: not formed apart
    EXPECT_EQ(&ekf.gain_covariance(), &ekf.covariance()) << k;
    EXPECT_LT((ekf.gain_covariance() - pg).norm(), 1e-12 * pg.norm()) << k;
  }
  for (int k = 6; k <= 12; ++k) {
    step(k, r_other);
    EXPECT_NE(&ekf.gain_covariance(), &ekf.covariance()) << k;
    EXPECT_LT((ekf.gain_covariance() - pg).norm(), 1e-12 * pg.norm()) << k;
    EXPECT_EQ(ekf.gain_covariance(), ekf.gain_covariance().transpose()) << k;
  }
  // Apart, the gain covariance is the smaller: the other noise is below R.
  const double apart_trace = ekf.gain_covariance().topLeftCorner<2, 2>().trace();
  const double filter_trace = ekf.covariance().topLeftCorner<2, 2>().trace();
  EXPECT_LT(apart_trace, 0.5 * filter_trace);
  ekf.StartGainCovariance();  // e.g. a resumed track confirmed again
  EXPECT_EQ(ekf.gain_covariance(), ekf.covariance());
  pg = ekf.covariance();
  step(13, r_other);  // apart again from here, started from the filter's covariance
  EXPECT_NE(ekf.gain_covariance(), ekf.covariance());
  EXPECT_LT((ekf.gain_covariance() - pg).norm(), 1e-12 * pg.norm());
  ekf.Init({0.0, 0.0}, r);
  EXPECT_EQ(ekf.gain_covariance(), ekf.covariance());
  ASSERT_TRUE(ekf.Update({0.01, 0.0}, r, &r_other));
  EXPECT_EQ(ekf.gain_covariance(), ekf.covariance());  // Init stops it until started again
}

TEST(CvEkfTest, BadMeasurementsLeaveTheFilterUnchanged) {
  CvEkf ekf{CvEkfOptions{}};
  const Eigen::Matrix2d r = 0.01 * Eigen::Matrix2d::Identity();
  ekf.Init({2.0, 1.0}, r);
  const auto x = ekf.state();
  const auto p = ekf.covariance();
  EXPECT_FALSE(ekf.Update({std::nan(""), 1.0}, r));
  EXPECT_FALSE(ekf.Update({2.0, 1.0}, -Eigen::Matrix2d::Identity()));
  EXPECT_EQ(ekf.state(), x);
  EXPECT_EQ(ekf.covariance(), p);
}

// CvEkf::gain_covariance: the same gains with the true noise. Told 1.5 cm per scan while the
// measurements scatter by 3 mm, the filter's state scatters by what the gains make of 3 mm, which
// the gain covariance says and the filter's own does not; the state is the same either way.
TEST(CvEkfTest, GainCovarianceIsTheErrorTheGainsLeaveWithTheTrueNoise) {
  const Eigen::Matrix2d told = 0.015 * 0.015 * Eigen::Matrix2d::Identity();
  const Eigen::Matrix2d actual = 0.003 * 0.003 * Eigen::Matrix2d::Identity();
  CvEkf a{CvEkfOptions{}}, b{CvEkfOptions{}};
  a.Init({0.0, 0.0}, told);
  b.Init({0.0, 0.0}, told);
  a.StartGainCovariance();
  b.StartGainCovariance();
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 0.003);
  double err2 = 0.0;
  int n = 0;
  for (int k = 1; k <= 2000; ++k) {
    a.Predict(0.04);
    b.Predict(0.04);
    if (k % 50 == 0) {
      a.InflateCovariance(3.0);
      b.InflateCovariance(3.0);
    }
    const Eigen::Vector2d truth(0.04 * k, 0.0);
    const Eigen::Vector2d z = truth + Eigen::Vector2d(noise(rng), noise(rng));
    ASSERT_TRUE(a.Update(z, told));
    ASSERT_TRUE(b.Update(z, told, &actual));
    EXPECT_EQ(a.state(), b.state());
    EXPECT_EQ(a.gain_covariance(), a.covariance());  // told R each time: the filter's own
    if (k > 100) {
      err2 += (b.position_m() - truth).squaredNorm();
      ++n;
    }
  }
  const double claimed = b.gain_covariance().topLeftCorner<2, 2>().trace();
  const double filters = b.covariance().topLeftCorner<2, 2>().trace();
  EXPECT_LT(claimed, 0.25 * filters);
  // The mean squared error against each trace: the gain covariance is nearer (what is left is the
  // process noise, for accelerations this straight walk does not make) and not below it.
  const double mse = err2 / n;
  EXPECT_GT(mse / claimed, 3.0 * mse / filters);
  EXPECT_LT(mse / claimed, 1.0);
}

}  // namespace
// RelieveGainProcessNoise: a prediction of dt_s followed by it leaves the gain covariance at
// F P F^T (no acceleration realised; per axis F = [1 dt; 0 1]), the filter's own at F P F^T + Q.
// Known answer, one axis: P = diag(0.01, 0.25), dt 0.1 s, q 0.5: position 0.01 + 0.01 * 0.25 =
// 0.0125 (the filter's 0.0125 + 0.5 * 0.001 / 3), position-velocity 0.025 (+ 0.0025), velocity
// 0.25 (+ 0.05).
TEST(CvEkfTest, RelievedProcessNoiseLeavesTheGainCovarianceWithoutTheLastPredictionsQ) {
  CvEkf ekf{CvEkfOptions{.accel_psd_m2ps3 = 0.5, .initial_velocity_sigma_mps = 0.5}};
  ekf.Init({2.0, 1.0}, 0.01 * Eigen::Matrix2d::Identity());
  ekf.RelieveGainProcessNoise(0.1);  // before StartGainCovariance: nothing
  EXPECT_EQ(ekf.gain_covariance(), ekf.covariance());
  ekf.StartGainCovariance();
  ekf.Predict(0.1);
  const Eigen::Matrix4d filter = ekf.covariance();
  ekf.RelieveGainProcessNoise(0.1);
  EXPECT_EQ(ekf.covariance(), filter);
  const Eigen::Matrix4d& g = ekf.gain_covariance();
  for (int a = 0; a < 2; ++a) {
    EXPECT_NEAR(g(a, a), 0.0125, 1e-15) << a;
    EXPECT_NEAR(g(a, a + 2), 0.025, 1e-15) << a;
    EXPECT_NEAR(g(a + 2, a + 2), 0.25, 1e-15) << a;
    EXPECT_NEAR(filter(a, a), 0.0125 + 0.5 * 0.001 / 3.0, 1e-15) << a;
    EXPECT_NEAR(filter(a, a + 2), 0.025 + 0.0025, 1e-15) << a;
    EXPECT_NEAR(filter(a + 2, a + 2), 0.25 + 0.05, 1e-15) << a;
  }
  EXPECT_TRUE(SymmetricPositiveDefinite(g));
  // Updated with the same noise afterwards, the gain covariance stays the smaller one.
  ASSERT_TRUE(ekf.Update({2.0, 1.0}, 0.01 * Eigen::Matrix2d::Identity()));
  EXPECT_LT(ekf.gain_covariance()(0, 0), ekf.covariance()(0, 0));
}

}  // namespace lrfnet::tracking
