#include "central_daemon/calibration/rts.h"

#include <algorithm>
#include <cmath>
#include <cstddef>

#include "common/cv_model.h"

namespace lrfnet::calib {
namespace {

// Symmetrises p and makes it positive definite. Rounding can leave a smoothed covariance of a
// nearly singular track (float covariances from the wire, a state pinned by many scans) with a
// negative eigenvalue of the order of 1e-16 times its scale; a jitter of that order on the diagonal
// fixes it without changing anything measurable.
void MakeSymmetricPositiveDefinite(Eigen::Matrix4d& p) {
  p = 0.5 * (p + p.transpose()).eval();
  if (Ldlt4(p).ok()) return;
  const double scale = std::max(p.diagonal().cwiseAbs().maxCoeff(), 1e-12);
  double jitter = 1e-12 * scale;
  for (int attempt = 0; attempt < 4; ++attempt, jitter *= 100.0) {
    const Eigen::Matrix4d candidate = p + jitter * Eigen::Matrix4d::Identity();
    if (Ldlt4(candidate).ok()) {
      p = candidate;
      return;
    }
  }
  // Not nearly PSD at all (cannot come from a consistent filter): keep the variances only.
  p = p.diagonal().cwiseMax(1e-12).asDiagonal();
}

}  // namespace

RtsInterval RtsIntervalWithoutSmoothing(const FilteredState& filtered, double dt_s) {
  RtsInterval interval;
  interval.filtered = filtered;
  interval.dt_s = dt_s;
  return interval;
}

void RtsSmoothWithSink(std::vector<FilteredState>* states, double accel_psd_m2ps3,
                       RtsIntervalSink& sink) {
  std::vector<FilteredState>& s = *states;
  const std::size_t n = s.size();
  if (n < 2) return;
  // Backward pass of the RTS smoother [23] (Quenzel et al. III-C). s[k + 1] already holds the
  // smoothed x_s(k+1), P_s(k+1); s[k] still holds the filtered x_f(k), P_f(k).
  for (std::size_t k = n - 1; k-- > 0;) {
    FilteredState& cur = s[k];
    const FilteredState& next = s[k + 1];
    const double dt_s = next.t_s - cur.t_s;
    const bool wanted = sink.Wants(k);
    if (!(dt_s > 0.0) || !std::isfinite(dt_s)) {
      if (wanted) sink.Take(k, RtsIntervalWithoutSmoothing(cur, dt_s));
      continue;
    }

    // Prediction x_p(k+1) = F x_f(k), P_p(k+1) = F P_f(k) F^T + Q.
    Eigen::Vector4d x_p = cur.x;
    Eigen::Matrix4d p_p = cur.p;
    common::CvPredict(dt_s, accel_psd_m2ps3, x_p, p_p);
    const Ldlt4 ldlt(p_p);
    if (!ldlt.ok()) {
      if (wanted) sink.Take(k, RtsIntervalWithoutSmoothing(cur, dt_s));
      continue;
    }

    // Gain C_k = P_f(k) F^T P_p(k+1)^-1, as C_k^T = P_p^-1 (F P_f(k)) (P_p and P_f symmetric).
    Eigen::Matrix4d f_p = cur.p;
    common::CvApplyTransition(dt_s, f_p);
    const Eigen::Matrix4d gain = ldlt.Solve(f_p).transpose();
    const Eigen::Vector4d e = next.x - x_p;  // x_s(k+1) - x_p(k+1)
    const Eigen::Matrix4d d = next.p - p_p;  // P_s(k+1) - P_p(k+1)
    const Eigen::Vector4d x_s = cur.x + gain * e;
    Eigen::Matrix4d p_s = cur.p + gain * d * gain.transpose();
    const bool finite = x_s.allFinite() && p_s.allFinite();

    if (wanted) {
      RtsInterval interval = RtsIntervalWithoutSmoothing(cur, dt_s);
      if (finite) {
        const Eigen::Vector4d g = ldlt.Solve(e);
        Eigen::Matrix4d m = ldlt.Solve(Eigen::Matrix4d(ldlt.Solve(d).transpose()));
        m = 0.5 * (m + m.transpose()).eval();
        if (g.allFinite() && m.allFinite()) {
          interval.gain_residual = g;
          interval.gain_covariance = m;
        }
      }
      sink.Take(k, interval);
    }
    if (!finite) continue;
    MakeSymmetricPositiveDefinite(p_s);
    cur.x = x_s;
    cur.p = p_s;
  }
}

void RtsSmooth(std::vector<FilteredState>* states, double accel_psd_m2ps3,
               std::vector<RtsInterval>* intervals) {
  class Store final : public RtsIntervalSink {
   public:
    explicit Store(std::vector<RtsInterval>* out) : out_(out) {}
    bool Wants(std::size_t /*k*/) override { return out_ != nullptr; }
    void Take(std::size_t k, const RtsInterval& interval) override { (*out_)[k] = interval; }

   private:
    std::vector<RtsInterval>* out_;
  };
  if (intervals != nullptr) {
    intervals->clear();
    if (states->size() >= 2) intervals->resize(states->size() - 1);
  }
  Store store(intervals);
  RtsSmoothWithSink(states, accel_psd_m2ps3, store);
}

FilteredState RtsInterpolate(const RtsInterval& interval, double tau_s, double accel_psd_m2ps3) {
  const double dt_s = std::isfinite(interval.dt_s) && interval.dt_s > 0.0 ? interval.dt_s : 0.0;
  const double tau = std::isfinite(tau_s) ? std::clamp(tau_s, 0.0, dt_s) : 0.0;
  FilteredState out;
  out.t_s = interval.filtered.t_s + tau;
  out.x = interval.filtered.x;
  out.p = interval.filtered.p;
  // Filtered estimate at t: x_p(t) = F(tau) x_f(k), P_p(t) = F(tau) P_f(k) F(tau)^T + Q(tau).
  common::CvPredict(tau, accel_psd_m2ps3, out.x, out.p);
  // One backward step from t against k+1: A = P_p(t) F(dt - tau)^T, C_t = A P_p(k+1)^-1, so
  // x_s(t) = x_p(t) + C_t e = x_p(t) + A g and P_s(t) = P_p(t) + C_t D C_t^T = P_p(t) + A M A^T.
  Eigen::Matrix4d a = out.p;
  common::CvApplyTransitionTransposed(dt_s - tau, a);
  out.x += a * interval.gain_residual;
  out.p += a * interval.gain_covariance * a.transpose();
  out.p = 0.5 * (out.p + out.p.transpose()).eval();
  return out;
}

}  // namespace lrfnet::calib
