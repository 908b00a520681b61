#pragma once
// Rauch-Tung-Striebel smoother (the "RTS smoother [23]" of Quenzel et al., section III-C; [23] is
// Särkkä, Bayesian filtering and smoothing, 2013, chapter 8) over the filtered states of one track,
// for the trackers' constant-velocity model (common/cv_model.h).
//
// The daemon receives the trackers' filtered estimates x_f(k), P_f(k), not their measurements. The
// backward pass needs nothing else: with F_k = F(t_{k+1} - t_k), Q_k = Q(t_{k+1} - t_k, q),
//   x_p(k+1) = F_k x_f(k),              P_p(k+1) = F_k P_f(k) F_k^T + Q_k        (prediction)
//   C_k      = P_f(k) F_k^T P_p(k+1)^-1                                          (gain)
//   x_s(k)   = x_f(k) + C_k (x_s(k+1) - x_p(k+1))
//   P_s(k)   = P_f(k) + C_k (P_s(k+1) - P_p(k+1)) C_k^T
// starting from x_s(n-1) = x_f(n-1), P_s(n-1) = P_f(n-1). The smoother is exactly the one of the
// filter only when q is the filter's own process noise (CvEkfOptions::accel_psd_m2ps3).
//
// Numerics: the gain is computed with an LDL^T solve against P_p(k+1) (never an explicit inverse);
// every smoothed covariance is symmetrised and kept symmetric positive definite (a tiny diagonal
// jitter is added when its LDL^T factorisation has a pivot <= 0, which only rounding of nearly
// singular input can cause). An interval whose time step is not > 0 or whose P_p(k+1) is not
// positive definite is not smoothed across: state k keeps its filtered value (gain 0).
//
// Times t_s are seconds on any common origin, strictly increasing within one call. Units of the
// state as in common/cv_model.h. Pure; thread-compatible.

#include <Eigen/Core>
#include <cstddef>
#include <vector>

namespace lrfnet::calib {

// LDL^T factorisation P = L D L^T (L unit lower triangular, D diagonal, no pivoting) of a
// symmetric 4x4 matrix (only its lower triangle is read) and solves with it, written out for the
// fixed size: Eigen's LLT/LDLT with a matrix right-hand side goes through its blocked
// dynamic-size kernels, several times slower for 4x4, and the smoother does a few of these per
// state. Without square roots (only the four pivot divisions), and for a symmetric positive
// definite P as stable as Cholesky. ok() is false (and Solve must not be called) unless every
// pivot is > 0, i.e. P is positive definite to working precision; NaN fails too.
class Ldlt4 {
 public:
  explicit Ldlt4(const Eigen::Matrix4d& p) {
    // Column j: d_j = p_jj - sum_k l_jk^2 d_k, l_ij = (p_ij - sum_k l_ik l_jk d_k) / d_j, with
    // w_ik = l_ik d_k kept to save multiplications (w_i0 = p_i0).
    const double d0 = p(0, 0);
    if (!(d0 > 0.0)) return;
    inv_d0_ = 1.0 / d0;
    l10_ = p(1, 0) * inv_d0_;
    l20_ = p(2, 0) * inv_d0_;
    l30_ = p(3, 0) * inv_d0_;
    const double d1 = p(1, 1) - l10_ * p(1, 0);
    if (!(d1 > 0.0)) return;
    inv_d1_ = 1.0 / d1;
    const double w21 = p(2, 1) - l20_ * p(1, 0);
    const double w31 = p(3, 1) - l30_ * p(1, 0);
    l21_ = w21 * inv_d1_;
    l31_ = w31 * inv_d1_;
    const double d2 = p(2, 2) - l20_ * p(2, 0) - l21_ * w21;
    if (!(d2 > 0.0)) return;
    inv_d2_ = 1.0 / d2;
    const double w32 = p(3, 2) - l30_ * p(2, 0) - l31_ * w21;
    l32_ = w32 * inv_d2_;
    const double d3 = p(3, 3) - l30_ * p(3, 0) - l31_ * w31 - l32_ * w32;
    if (!(d3 > 0.0)) return;
    inv_d3_ = 1.0 / d3;
    ok_ = true;
  }

  bool ok() const { return ok_; }

  // P^-1 B: L Y = B, Z = D^-1 Y, L^T X = Z, on whole rows (B: Vector4d or Matrix4d).
  template <typename Rows>
  Rows Solve(const Rows& b) const {
    using Row = decltype(b.row(0).eval());
    const Row y0 = b.row(0);
    const Row y1 = b.row(1) - l10_ * y0;
    const Row y2 = b.row(2) - l20_ * y0 - l21_ * y1;
    const Row y3 = b.row(3) - l30_ * y0 - l31_ * y1 - l32_ * y2;
    Rows x;
    x.row(3) = y3 * inv_d3_;
    x.row(2) = y2 * inv_d2_ - l32_ * x.row(3);
    x.row(1) = y1 * inv_d1_ - l21_ * x.row(2) - l31_ * x.row(3);
    x.row(0) = y0 * inv_d0_ - l10_ * x.row(1) - l20_ * x.row(2) - l30_ * x.row(3);
    return x;
  }

 private:
  // L below its unit diagonal, and the reciprocals of D.
  double l10_ = 0.0, l20_ = 0.0, l30_ = 0.0, l21_ = 0.0, l31_ = 0.0, l32_ = 0.0;
  double inv_d0_ = 0.0, inv_d1_ = 0.0, inv_d2_ = 0.0, inv_d3_ = 0.0;
  bool ok_ = false;
};

struct FilteredState {
  double t_s = 0.0;
  Eigen::Vector4d x = Eigen::Vector4d::Zero();      // (x_m, y_m, vx_mps, vy_mps)
  Eigen::Matrix4d p = Eigen::Matrix4d::Identity();  // covariance of x, symmetric PSD
};

// What the exact smoothed state strictly between states k and k+1 needs, kept by the backward
// pass. With e = x_s(k+1) - x_p(k+1) and D = P_s(k+1) - P_p(k+1):
struct RtsInterval {
  FilteredState filtered;                                     // x_f(k), P_f(k), t_k
  double dt_s = 0.0;                                          // t_{k+1} - t_k
  Eigen::Vector4d gain_residual = Eigen::Vector4d::Zero();    // P_p(k+1)^-1 e
  Eigen::Matrix4d gain_covariance = Eigen::Matrix4d::Zero();  // P_p(k+1)^-1 D P_p(k+1)^-1
};

// Smooths `states` in place (x and p become x_s and P_s), q = accel_psd_m2ps3 > 0. When
// `intervals` is given it is overwritten with states->size() - 1 entries (interval k between
// states k and k+1; empty for fewer than two states) for RtsInterpolate. Reuses the capacity of
// `intervals`; allocates nothing else.
void RtsSmooth(std::vector<FilteredState>* states, double accel_psd_m2ps3,
               std::vector<RtsInterval>* intervals = nullptr);

// Receives the intervals a caller wants during the backward pass, so that it can sample them
// without keeping one RtsInterval (over 300 bytes) per state.
class RtsIntervalSink {
 public:
  virtual ~RtsIntervalSink() = default;
  // Whether interval k (between states k and k+1) is wanted; asked once per interval.
  virtual bool Wants(std::size_t k) = 0;
  // Called once for every wanted interval, for k from the last to the first, when states[k+1]
  // holds its smoothed value and states[k] still its filtered one. `interval` is valid during the
  // call only.
  virtual void Take(std::size_t k, const RtsInterval& interval) = 0;
};

// As RtsSmooth, handing the wanted intervals to `sink` instead of storing them. Allocates nothing.
void RtsSmoothWithSink(std::vector<FilteredState>* states, double accel_psd_m2ps3,
                       RtsIntervalSink& sink);

// The smoothed state at t_k + tau_s, 0 <= tau_s <= dt_s. Exact for the CV model, no approximation:
// the filtered state at t (no measurement there) is the prediction from k,
//   x_p(t) = F(tau) x_f(k),  P_p(t) = F(tau) P_f(k) F(tau)^T + Q(tau),
// and one backward step from t against k+1 (whose prediction from t is the same x_p(k+1),
// P_p(k+1), because F and Q of the exact discretisation compose) gives, with
// A = P_p(t) F(dt - tau)^T (so C_t = A P_p(k+1)^-1),
//   x_s(t) = x_p(t) + A gain_residual,   P_s(t) = P_p(t) + A gain_covariance A^T.
// At tau = 0 this is x_s(k), P_s(k); at tau = dt it is x_s(k+1), P_s(k+1). An interval with zero
// gains (RtsIntervalWithoutSmoothing, or one not smoothed across) gives the filter's prediction.
// The result's covariance is symmetric.
FilteredState RtsInterpolate(const RtsInterval& interval, double tau_s, double accel_psd_m2ps3);

// The interval from `filtered` over dt_s with zero gains: RtsInterpolate then returns the filtered
// estimate (prediction from state k) at any time of the interval.
RtsInterval RtsIntervalWithoutSmoothing(const FilteredState& filtered, double dt_s);

}  // namespace lrfnet::calib
