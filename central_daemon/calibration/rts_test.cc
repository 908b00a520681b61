#include "central_daemon/calibration/rts.h"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <cmath>
#include <random>
#include <vector>

#include "common/cv_model.h"
#include "common/eigen_instances.h"
#include "firmware_tracker/tracking/cv_ekf.h"

namespace lrfnet::calib {
namespace {

constexpr double kQ = 0.5;  // the trackers' default accel_psd_m2ps3

bool SymmetricPositiveDefinite(const Eigen::Matrix4d& p) {
  return p.allFinite() && p == p.transpose() &&
         Eigen::LLT<Eigen::Matrix4d>(p).info() == Eigen::Success;
}

// Smallest eigenvalue of a symmetric matrix.
double MinEigenvalue(const Eigen::Matrix4d& m) {
  return Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d>(Eigen::Matrix4d(0.5 * (m + m.transpose())))
      .eigenvalues()
      .minCoeff();
}

// The exact interpolation relies on the discretisation composing: predicting over a then b is
// predicting over a + b.
TEST(CvModelTest, PredictionsCompose) {
  Eigen::Vector4d x1(1.0, -2.0, 0.7, 0.3), x2 = x1;
  Eigen::Matrix4d p1 = Eigen::Matrix4d::Identity() * 0.01, p2 = p1;
  p1(0, 2) = p1(2, 0) = p2(0, 2) = p2(2, 0) = 0.004;
  common::CvPredict(0.013, kQ, x1, p1);
  common::CvPredict(0.029, kQ, x1, p1);
  common::CvPredict(0.042, kQ, x2, p2);
  EXPECT_LT((x1 - x2).norm(), 1e-15);
  EXPECT_LT((p1 - p2).norm(), 1e-15);
  EXPECT_EQ(common::CvTransition(0.042) * Eigen::Vector4d(1, 2, 3, 4),
            Eigen::Vector4d(1 + 0.042 * 3, 2 + 0.042 * 4, 3, 4));
}

struct Simulation {
  std::vector<Eigen::Vector4d> truth;
  std::vector<FilteredState> filtered;
};

// A target moving with white acceleration of spectral density q (the model), observed with noise
// sigma_m at irregular times, filtered by the tracker's own CvEkf.
Simulation Simulate(std::size_t n, double q, double sigma_m, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> unit(0.0, 1.0);
  std::uniform_real_distribution<double> period(0.03, 0.07);
  const Eigen::Matrix2d r = sigma_m * sigma_m * Eigen::Matrix2d::Identity();
  Simulation sim;
  Eigen::Vector4d x(2.0, -1.0, 1.0, 0.5);
  tracking::CvEkf ekf{tracking::CvEkfOptions{.accel_psd_m2ps3 = q}};
  double t = 10.0;
  for (std::size_t k = 0; k < n; ++k) {
    if (k > 0) {
      const double dt = period(rng);
      const Eigen::LLT<Eigen::Matrix4d> chol(common::CvProcessNoise(dt, q));
      const Eigen::Vector4d w(unit(rng), unit(rng), unit(rng), unit(rng));
      x = common::CvTransition(dt) * x + chol.matrixL() * w;
      t += dt;
      ekf.Predict(dt);
    }
    const Eigen::Vector2d z = x.head<2>() + sigma_m * Eigen::Vector2d(unit(rng), unit(rng));
    if (k == 0) {
      ekf.Init(z, r);
    } else {
      EXPECT_TRUE(ekf.Update(z, r));
    }
    sim.truth.push_back(x);
    sim.filtered.push_back(FilteredState{t, ekf.state(), ekf.covariance()});
  }
  return sim;
}

double PositionRms(const std::vector<FilteredState>& states,
                   const std::vector<Eigen::Vector4d>& truth, std::size_t skip) {
  double sum = 0.0;
  for (std::size_t k = skip; k < states.size(); ++k) {
    sum += (states[k].x.head<2>() - truth[k].head<2>()).squaredNorm();
  }
  return std::sqrt(sum / static_cast<double>(states.size() - skip));
}

TEST(RtsSmoothTest, SmoothedErrorClearlyBelowFilteredAndCovariancesShrink) {
  const Simulation sim = Simulate(3000, kQ, 0.05, 11);
  std::vector<FilteredState> smoothed = sim.filtered;
  std::vector<RtsInterval> intervals;
  RtsSmooth(&smoothed, kQ, &intervals);
  ASSERT_EQ(intervals.size(), smoothed.size() - 1);

  const double filtered_rms = PositionRms(sim.filtered, sim.truth, 20);
  const double smoothed_rms = PositionRms(smoothed, sim.truth, 20);
  EXPECT_LT(smoothed_rms, 0.8 * filtered_rms)
      << "filtered " << filtered_rms << " m, smoothed " << smoothed_rms << " m";

  double mean_var_filtered = 0.0, mean_var_smoothed = 0.0;
  for (std::size_t k = 0; k < smoothed.size(); ++k) {
    ASSERT_TRUE(SymmetricPositiveDefinite(smoothed[k].p)) << "state " << k;
    // P_s <= P_f: the filtered minus the smoothed covariance is positive semi-definite.
    const Eigen::Matrix4d diff = sim.filtered[k].p - smoothed[k].p;
    ASSERT_GE(MinEigenvalue(diff), -1e-12 * sim.filtered[k].p.norm()) << "state " << k;
    mean_var_filtered += sim.filtered[k].p(0, 0);
    mean_var_smoothed += smoothed[k].p(0, 0);
  }
  EXPECT_LT(mean_var_smoothed, 0.8 * mean_var_filtered);
  // The last state has no future: unchanged.
  EXPECT_EQ(smoothed.back().x, sim.filtered.back().x);
  EXPECT_EQ(smoothed.back().p, sim.filtered.back().p);

  // The smoothed covariance is consistent with the actual error (normalised error ~ 2 dof).
  double nees = 0.0;
  for (std::size_t k = 20; k < smoothed.size(); ++k) {
    const Eigen::Vector2d e = smoothed[k].x.head<2>() - sim.truth[k].head<2>();
    nees += e.dot(smoothed[k].p.topLeftCorner<2, 2>().ldlt().solve(e));
  }
  nees /= static_cast<double>(smoothed.size() - 20);
  EXPECT_GT(nees, 1.5);
  EXPECT_LT(nees, 2.5);
}

TEST(RtsSmoothTest, InterpolationMatchesTheNodesAndTheIntermediateTruth) {
  const Simulation sim = Simulate(400, kQ, 0.05, 3);
  std::vector<FilteredState> smoothed = sim.filtered;
  std::vector<RtsInterval> intervals;
  RtsSmooth(&smoothed, kQ, &intervals);
  for (std::size_t k = 0; k + 1 < smoothed.size(); ++k) {
    const FilteredState at_k = RtsInterpolate(intervals[k], 0.0, kQ);
    const FilteredState at_next = RtsInterpolate(intervals[k], intervals[k].dt_s, kQ);
    ASSERT_LT((at_k.x - smoothed[k].x).norm(), 1e-9) << k;
    ASSERT_LT((at_k.p - smoothed[k].p).norm(), 1e-9 * smoothed[k].p.norm()) << k;
    ASSERT_LT((at_next.x - smoothed[k + 1].x).norm(), 1e-9) << k;
    ASSERT_LT((at_next.p - smoothed[k + 1].p).norm(), 1e-9 * smoothed[k + 1].p.norm()) << k;
    ASSERT_DOUBLE_EQ(at_next.t_s, intervals[k].filtered.t_s + intervals[k].dt_s);
    // In between: symmetric PD, no larger than the prediction from k (the filtered estimate).
    const FilteredState mid = RtsInterpolate(intervals[k], 0.5 * intervals[k].dt_s, kQ);
    const FilteredState predicted =
        RtsInterpolate(RtsIntervalWithoutSmoothing(sim.filtered[k], intervals[k].dt_s),
                       0.5 * intervals[k].dt_s, kQ);
    ASSERT_TRUE(SymmetricPositiveDefinite(mid.p)) << k;
    ASSERT_GE(MinEigenvalue(predicted.p - mid.p), -1e-12) << k;
  }
}

// Exactly smoothing a sequence with an extra (state-free) time inserted in each interval gives the
// same answer as the interpolation: the inserted states carry no measurement, so their filtered
// state is the prediction and the RTS pass over the refined sequence is exact.
TEST(RtsSmoothTest, InterpolationEqualsSmoothingWithInsertedPredictionSteps) {
  const Simulation sim = Simulate(200, kQ, 0.05, 8);
  std::vector<FilteredState> smoothed = sim.filtered;
  std::vector<RtsInterval> intervals;
  RtsSmooth(&smoothed, kQ, &intervals);

  std::vector<FilteredState> refined;
  for (std::size_t k = 0; k < sim.filtered.size(); ++k) {
    refined.push_back(sim.filtered[k]);
    if (k + 1 == sim.filtered.size()) break;
    FilteredState mid = sim.filtered[k];
    const double tau = 0.3 * (sim.filtered[k + 1].t_s - sim.filtered[k].t_s);
    common::CvPredict(tau, kQ, mid.x, mid.p);
    mid.t_s += tau;
    refined.push_back(mid);
  }
  RtsSmooth(&refined, kQ);
  for (std::size_t k = 0; k + 1 < sim.filtered.size(); ++k) {
    const FilteredState mid = RtsInterpolate(intervals[k], 0.3 * intervals[k].dt_s, kQ);
    const FilteredState& expected = refined[2 * k + 1];
    ASSERT_LT((mid.x - expected.x).norm(), 1e-8) << k;
    ASSERT_LT((mid.p - expected.p).norm(), 1e-8 * expected.p.norm()) << k;
    ASSERT_LT((smoothed[k].x - refined[2 * k].x).norm(), 1e-8) << k;
  }
}

// Filtered states exactly on a constant-velocity line (whatever their covariances) are a fixed
// point of the smoother, and every intermediate time lies on the line.
TEST(RtsSmoothTest, StraightConstantVelocityTrackIsReproducedExactly) {
  const Eigen::Vector4d start(1.0, 2.0, 1.3, -0.4);
  std::vector<FilteredState> states;
  tracking::CvEkf ekf{tracking::CvEkfOptions{}};
  ekf.Init(start.head<2>(), 0.01 * Eigen::Matrix2d::Identity());
  double t = 0.0;
  for (int k = 0; k < 60; ++k) {
    if (k > 0) {
      const double dt = (k % 3 == 0) ? 0.04 : 0.067;
      t += dt;
      ekf.Predict(dt);
      ekf.Update(start.head<2>() + t * start.tail<2>(), 0.0025 * Eigen::Matrix2d::Identity());
    }
    // The covariances of a real filter, the states of the exact line.
    states.push_back(FilteredState{t, common::CvTransition(t) * start, ekf.covariance()});
  }
  std::vector<FilteredState> smoothed = states;
  std::vector<RtsInterval> intervals;
  RtsSmooth(&smoothed, kQ, &intervals);
  for (std::size_t k = 0; k < states.size(); ++k) {
    ASSERT_LT((smoothed[k].x - states[k].x).norm(), 1e-12) << k;
  }
  for (std::size_t k = 0; k + 1 < states.size(); ++k) {
    for (const double fraction : {0.1, 0.5, 0.77}) {
      const double tau = fraction * intervals[k].dt_s;
      const FilteredState s = RtsInterpolate(intervals[k], tau, kQ);
      const Eigen::Vector4d expected = common::CvTransition(states[k].t_s + tau) * start;
      ASSERT_LT((s.x - expected).norm(), 1e-12) << k << " " << fraction;
    }
  }
}

TEST(RtsSmoothTest, SinkGetsExactlyTheWantedIntervalsBackwards) {
  const Simulation sim = Simulate(100, kQ, 0.05, 5);
  std::vector<FilteredState> stored = sim.filtered;
  std::vector<RtsInterval> all;
  RtsSmooth(&stored, kQ, &all);

  class EveryThird final : public RtsIntervalSink {
   public:
    bool Wants(std::size_t k) override { return k % 3 == 0; }
    void Take(std::size_t k, const RtsInterval& interval) override {
      taken.push_back(k);
      intervals.push_back(interval);
    }
    std::vector<std::size_t> taken;
    std::vector<RtsInterval> intervals;
  } sink;
  std::vector<FilteredState> streamed = sim.filtered;
  RtsSmoothWithSink(&streamed, kQ, sink);

  for (std::size_t k = 0; k < stored.size(); ++k) {
    ASSERT_EQ(streamed[k].x, stored[k].x) << k;
    ASSERT_EQ(streamed[k].p, stored[k].p) << k;
  }
  ASSERT_EQ(sink.taken.size(), 33u);  // 0, 3, ..., 96 (98 is the last interval)
  for (std::size_t i = 0; i < sink.taken.size(); ++i) {
    const std::size_t k = sink.taken[i];
    EXPECT_EQ(k, 96 - 3 * i);  // from the last to the first
    EXPECT_EQ(sink.intervals[i].filtered.x, all[k].filtered.x);
    EXPECT_EQ(sink.intervals[i].filtered.x, sim.filtered[k].x);
    EXPECT_EQ(sink.intervals[i].gain_residual, all[k].gain_residual);
    EXPECT_EQ(sink.intervals[i].gain_covariance, all[k].gain_covariance);
  }
}

TEST(RtsSmoothTest, DegenerateInputsDoNotCrashOrPoison) {
  std::vector<FilteredState> none;
  std::vector<RtsInterval> intervals(3);
  RtsSmooth(&none, kQ, &intervals);
  EXPECT_TRUE(intervals.empty());

  std::vector<FilteredState> one{
      FilteredState{1.0, Eigen::Vector4d(1, 2, 3, 4), Eigen::Matrix4d::Identity()}};
  RtsSmooth(&one, kQ, &intervals);
  EXPECT_TRUE(intervals.empty());
  EXPECT_EQ(one[0].x, Eigen::Vector4d(1, 2, 3, 4));

  // Same time twice and a zero (singular) covariance: not smoothed across, nothing non-finite.
  std::vector<FilteredState> states{
      FilteredState{0.0, Eigen::Vector4d(0, 0, 1, 0), Eigen::Matrix4d::Zero()},
      FilteredState{0.0, Eigen::Vector4d(5, 0, 1, 0), Eigen::Matrix4d::Identity()},
      FilteredState{0.1, Eigen::Vector4d(0.1, 0, 1, 0), Eigen::Matrix4d::Zero()}};
  RtsSmooth(&states, kQ, &intervals);
  ASSERT_EQ(intervals.size(), 2u);
  EXPECT_EQ(states[0].x, Eigen::Vector4d(0, 0, 1, 0));  // dt = 0: kept filtered
  for (const FilteredState& s : states) {
    EXPECT_TRUE(s.x.allFinite());
    EXPECT_TRUE(s.p.allFinite());
    EXPECT_EQ(s.p, s.p.transpose());
  }
  const FilteredState mid = RtsInterpolate(intervals[1], 0.05, kQ);
  EXPECT_TRUE(mid.x.allFinite() && mid.p.allFinite());
  // Out-of-range and non-finite tau are clamped into the interval.
  EXPECT_DOUBLE_EQ(RtsInterpolate(intervals[1], -1.0, kQ).t_s, 0.0);
  EXPECT_DOUBLE_EQ(RtsInterpolate(intervals[1], 7.0, kQ).t_s, 0.1);
  EXPECT_DOUBLE_EQ(RtsInterpolate(intervals[1], std::nan(""), kQ).t_s, 0.0);
}

}  // namespace
}  // namespace lrfnet::calib
