#pragma once
// Constant-velocity Kalman filter for one track (Quenzel et al., section III-B: "the center of mass
// (CoM) is tracked over time by an Extended Kalman Filter under the assumption of a constant
// velocity"). With a linear position measurement the EKF reduces to the linear filter implemented
// here.
//
// State x = (x_m, y_m, vx_mps, vy_mps) in the sensor frame. Process noise: continuous white
// acceleration with spectral density q = accel_psd_m2ps3 per axis, discretised exactly:
//   Q_axis = q * [dt^3/3, dt^2/2; dt^2/2, dt].
// Update uses the Joseph form; the covariances are kept exactly symmetric (the prediction from the
// upper triangle, the Joseph updates symmetric by construction), so P stays symmetric positive
// definite in floating point. Pure, fixed-size, never allocates.

#include <Eigen/Core>
#include <cmath>
#include <optional>
#include <string>

namespace lrfnet::tracking {

struct CvEkfOptions {
  double accel_psd_m2ps3 = 0.5;             // q: people change speed by ~0.7 m/s within a second
  double initial_velocity_sigma_mps = 1.5;  // velocity prior of a new track (walking speed range)
};

std::optional<std::string> Validate(const CvEkfOptions& options);

class CvEkf {
 public:
  using State = Eigen::Vector4d;
  using Covariance = Eigen::Matrix4d;

  CvEkf() = default;
  explicit CvEkf(const CvEkfOptions& options) : options_(options) {}

  // Starts at position z with covariance r, zero velocity with the velocity prior.
  void Init(const Eigen::Vector2d& z_m, const Eigen::Matrix2d& r_m2);

  // Propagates by dt_s seconds (dt_s <= 0 leaves the filter unchanged).
  void Predict(double dt_s);

  // Squared Mahalanobis distance of a position measurement from the predicted position,
  // (z - Hx)^T (H P H^T + R)^-1 (z - Hx); +infinity when the innovation covariance is not
  // invertible.
  double MahalanobisSq(const Eigen::Vector2d& z_m, const Eigen::Matrix2d& r_m2) const;

  // Position update. Returns false (filter unchanged) when the innovation covariance is not
  // positive definite or the input is not finite.
  // gain_r_m2: the measurement noise gain_covariance() takes (else r_m2).
  bool Update(const Eigen::Vector2d& z_m, const Eigen::Matrix2d& r_m2,
              const Eigen::Matrix2d* gain_r_m2 = nullptr);

  // Multiplies the covariance by factor (> 0 and finite, else nothing): a state that proved less
  // certain than it claimed (a manoeuvre the constant-velocity model did not predict); the gain
  // covariance too (the state's error is as much larger).
  void InflateCovariance(double factor) {
    if (!(std::isfinite(factor) && factor > 0.0)) return;
    p_ *= factor;
    if (gain_apart_) p_gain_ *= factor;
  }

  // Replaces the state (e.g. a velocity limited to the possible), keeping the covariance.
  void SetState(const State& x) { x_ = x; }

  const State& state() const { return x_; }
  const Covariance& covariance() const { return p_; }
  // The covariance of the state's error given the gains the filter applied and the measurement
  // noise gain_r_m2 of each Update (Gelb, Applied Optimal Estimation, 1974, sec. 7.2: the error
  // covariance of a filter whose gains were computed from other noise statistics than the true
  // ones): propagated with the same process noise and inflations, updated in Joseph form with the
  // gain K = P H^T S^-1 computed from covariance() and R. Equal to covariance() where every
  // gain_r_m2 was R.
  // Kept from StartGainCovariance() on (before that, the filter's own covariance()): the recursion
  // costs a second covariance per prediction and update, paid only by the tracks whose covariance
  // is reported, and only from their first update whose gain_r_m2 is not R on (until then it is
  // covariance() itself, which the recursion would give bit for bit).
  const Covariance& gain_covariance() const { return gain_apart_ ? p_gain_ : p_; }
  // Takes the process noise of the last dt_s of prediction out of gain_covariance() (not out of
  // covariance(): the gains stay): where a measurement shows that the object did not move in that
  // time, the acceleration the filter allows for was not realised, and gain_covariance() is the
  // state's error given the noise that was. Only while the gain covariance is kept; dt_s must be
  // at most the time predicted since the last update (else the result may not be a covariance).
  void RelieveGainProcessNoise(double dt_s);
  // Starts gain_covariance() from covariance() (the filter's R: the larger, so never too small).
  void StartGainCovariance() {
    gain_ = true;
    gain_apart_ = false;
  }
  // The state and covariance() predicted by dt_s, without the gain covariance (for a gate or a
  // look ahead; Predict's arguments and arithmetic), as a plain pair instead of a filter.
  struct Prediction {
    State x;
    Covariance p;
    const State& state() const { return x; }
    const Covariance& covariance() const { return p; }
    Eigen::Vector2d position_m() const { return x.head<2>(); }
  };
  Prediction Predicted(double dt_s) const;
  Eigen::Vector2d position_m() const { return x_.head<2>(); }
  Eigen::Vector2d velocity_mps() const { return x_.tail<2>(); }

 private:
  CvEkfOptions options_;
  State x_ = State::Zero();
  Covariance p_ = Covariance::Identity();
  Covariance p_gain_ = Covariance::Identity();
  bool gain_ = false;        // StartGainCovariance() was called
  bool gain_apart_ = false;  // p_gain_ holds gain_covariance() (else it equals p_)
};

}  // namespace lrfnet::tracking
