// FusionMethod::kFusedFilter: one filter per fused track, fed with each sensor's new information
// (fusion.h, "kFusedFilter").

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <optional>
#include <tuple>
#include <utility>

#include "central_daemon/fusion/assignment.h"
#include "central_daemon/fusion/fusion_internal.h"
#include "common/cv_model.h"
#include "common/eigen_instances.h"

namespace lrfnet::fusion::internal {
namespace {

using common::CvCovariance;
using common::CvState;
using common::UtcNs;
using Mat = Eigen::MatrixXd;
using Vec = Eigen::VectorXd;

// Bounds of a recovered measurement's variance per direction [m^2]: below, float rounding of the
// wire's covariances dominates; above, the direction carries no information (kept finite so that
// the innovation covariance stays invertible).
constexpr double kMinMeasurementVariance = 1e-6;
constexpr double kMaxMeasurementVariance = 1e4;
// A local track whose recovered measurements are on average this many times less certain than
// its own position after kUnfilteredFrames frames does not come from the assumed filter (a filter
// at 25 Hz with people's process noise has a ratio of 2-5; raw detections reported with their
// own covariance have hundreds).
constexpr double kUnfilteredRatio = 30.0;
constexpr std::uint32_t kUnfilteredFrames = 5;
// Covariance matching (Mehra 1972): a covariance that fits its errors gives squared Mahalanobis
// distances (2 dof) with mean 2. The running mean of such distances (each capped at kNisCap: a
// mismatched pair must not dominate; memory ~1 / rate samples) raises the scale of the covariance
// while it is above 2 and lowers it towards 1 while it is below; never below 1 (a covariance
// claimed larger than needed is kept).
struct CovarianceScale {
  static constexpr double kNisCap = 20.0;
  static constexpr double kStep = 0.05;
  double mean = 2.0;
  double scale = 1.0;
  void Add(double d2, double rate, double max_scale) {
    if (!std::isfinite(d2)) return;
    mean += rate * (std::min(d2, kNisCap) - mean);
    scale = std::clamp(scale * std::exp(kStep * (mean / 2.0 - 1.0)), 1.0, max_scale);
  }
};
// Pose covariances: tested whenever a sensor's whole track joins a fused track of other sensors.
constexpr double kPoseNisRate = 0.02;
constexpr double kMaxPoseScale = 100.0;
// A sensor's measurement covariances: tested by every frame's update of its own fused track.
constexpr double kNoiseNisRate = 0.002;
constexpr double kMaxNoiseScale = 1e4;

// Squared Mahalanobis distance of the first two components of nu with the upper left of s.
double PositionNis(const Vec& nu, const Mat& s) {
  const Eigen::Matrix2d spp = s.topLeftCorner<2, 2>();
  const Eigen::LLT<Eigen::Matrix2d> llt(spp);
  if (llt.info() != Eigen::Success) return std::numeric_limits<double>::quiet_NaN();
  const Eigen::Vector2d np = nu.head<2>();
  return np.dot(llt.solve(np));
}

// The new information a local track's frame carries, in the world frame, and the covariance of
// its sensor's centre offset at that place.
struct Measurement {
  bool valid = false;
  // The whole tracker state (position and velocity): the first time the local track contributes,
  // everything it learnt is new to the fused tracks. Afterwards only the frame's measurement.
  bool full_state = false;
  Eigen::Vector4d z = Eigen::Vector4d::Zero();  // position, and velocity when full_state
  Eigen::Matrix4d r = Eigen::Matrix4d::Zero();  // its noise (upper left 2x2 when !full_state)
  Eigen::Matrix2d offset_prior = Eigen::Matrix2d::Zero();
};

constexpr std::size_t kKinds = 4;  // daemon::MeasurementKind
std::size_t KindIndex(daemon::MeasurementKind kind) {
  return std::min(static_cast<std::size_t>(kind), kKinds - 1);
}
// A sensor's bias model ("Sensor bias" in fusion.h): theta = (dx, dy, dyaw) of its placement's
// error and its centre offset towards itself per measurement kind; at a place p_s (sensor frame)
// its frames are off by J(p_s) theta, J = [I, R' p_s, -n e_kind] (n = R p_s / |p_s|).
constexpr int kBiasParams = 3 + static_cast<int>(kKinds);
using BiasVec = Eigen::Matrix<double, kBiasParams, 1>;
using BiasMat = Eigen::Matrix<double, kBiasParams, kBiasParams>;
using BiasRows = Eigen::Matrix<double, 2, kBiasParams>;

BiasRows BiasJacobian(const common::Pose2& world_from_sensor, const Eigen::Vector2d& p_s,
                      daemon::MeasurementKind kind) {
  BiasRows j = BiasRows::Zero();
  j.leftCols<3>() = PoseJacobian(world_from_sensor, p_s, Eigen::Vector2d::Zero()).topRows<2>();
  const double range = p_s.norm();
  if (range > 1e-6) {
    j.col(3 + static_cast<Eigen::Index>(KindIndex(kind))) =
        -(world_from_sensor.rotation() * p_s) / range;
  }
  return j;
}

// The Bayesian linear regression of a sensor's samples y = J theta + e with the prior
// theta ~ N(0, prior), each sample split along its line of sight n and across it l (a track's
// own offset and the turning are larger along it): e.n ~ N(0, noise_n), e.l ~ N(0, noise_l).
// Normal equations per direction with exponential forgetting (memory samples), the noise
// variances from the residuals of the samples against the estimate before them.
struct BiasModel {
  std::array<BiasMat, 2> a = {BiasMat::Zero(), BiasMat::Zero()};  // sum J^T J (n, l)
  std::array<BiasVec, 2> c = {BiasVec::Zero(), BiasVec::Zero()};  // sum J^T y
  std::array<double, 2> noise_m2 = {0.0, 0.0};                    // 0: not yet set
  double noise_count = 0.0;
  std::uint64_t samples = 0;
  BiasVec estimate = BiasVec::Zero();
  BiasMat covariance = BiasMat::Zero();
  bool solved = false;
};
constexpr std::uint32_t kMinBiasUpdates = 5;

struct SourceKey {
  std::string sensor_id;
  std::uint32_t track_id = 0;
  bool operator<(const SourceKey& o) const {
    return std::tie(sensor_id, track_id) < std::tie(o.sensor_id, o.track_id);
  }
  bool operator==(const SourceKey& o) const {
    return sensor_id == o.sensor_id && track_id == o.track_id;
  }
};

struct LocalTrack {
  daemon::TrackObservation observation;  // as received (centre corrected), sensor frame
  daemon::TrackObservation received;     // as received
  double applied_bias_m = 0.0;           // the centre correction of `observation`
  // The correction of this frame's world position by the sensor's bias model (J theta).
  Eigen::Vector2d applied_world = Eigen::Vector2d::Zero();
  BiasRows jacobian = BiasRows::Zero();  // J at this frame's place
  WorldTrack world;
  bool usable = false;  // not tentative, or tentative sources allowed
  // The latest state its tracker measured (sensor frame) and its time: the next frame's
  // measurement is recovered against it.
  bool has_reference = false;
  daemon::TrackObservation reference;  // as received (corrected with the current offset when used)
  CvCovariance reference_p = CvCovariance::Identity();
  UtcNs reference_ns = 0;
  // Its information entered a fused track: from now on only each frame's new information counts.
  bool contributed = false;
  // Recovery statistics: frames recovered and the sum of tr(R) / tr(P_pp) over them. A tracker's
  // filter has a ratio of a few; states that are not a filter's (raw detections with their
  // covariance) give hundreds, and then every frame is used as a measurement of its own.
  std::uint32_t recovered_frames = 0;
  double ratio_sum = 0.0;
  bool unfiltered = false;
  Measurement measurement;  // of the latest frame
  // Its sensor's bias: the sums of J and of (applied correction + de-shrunk offset) over its
  // updates shared with other sensors since bias_first_ns ("Sensor bias" in fusion.h).
  BiasRows bias_j_sum = BiasRows::Zero();
  Eigen::Vector2d bias_y_sum = Eigen::Vector2d::Zero();
  std::uint32_t bias_updates = 0;
  UtcNs bias_first_ns = 0;
  std::optional<std::uint64_t> fused_id;
  std::uint32_t misses = 0;       // consecutive measured frames not assigned to its fused track
  std::uint32_t hold_frames = 0;  // after unbinding: frames before it may start a fused track
  UtcNs stamp() const { return world.stamp_ns; }
};

struct SensorState {
  FrameClock clock;
  // Scale of its tracker's covariances, learnt from its frames' fit (adapt_covariances).
  CovarianceScale noise_scale;
  // Its placement's error and centre offsets (learn_sensor_bias).
  BiasModel bias;
  std::map<std::uint32_t, LocalTrack> tracks;
  // Local tracks forgotten after source_timeout_s while bound: the fused track each fed and the
  // time of its last frame, kept for max_coast_s (see ReturningSource).
  struct Forgotten {
    std::uint64_t fused_id = 0;
    UtcNs last_ns = 0;
  };
  std::map<std::uint32_t, Forgotten> forgotten;
};

// A sensor's centre offset kept as a state of a fused track.
struct Offset {
  std::string sensor_id;
  UtcNs last_ns = 0;                                // its latest measurement
  Eigen::Matrix2d prior = Eigen::Matrix2d::Zero();  // stationary covariance there
};

struct Track {
  std::uint64_t id = 0;
  UtcNs first_ns = 0;
  UtcNs stamp_ns = 0;  // time of x, p
  // (x, y, vx, vy, then the 2-d offset of every sensor in `offsets`), world frame.
  Vec x = Vec::Zero(4);
  Mat p = Mat::Identity(4, 4);
  std::vector<Offset> offsets;
  std::uint64_t updates = 0;
  bool confirmed = false;
  std::vector<SourceKey> sources;  // sorted; at most one per sensor
  // The sensor whose source timed out last, leaving the track without sources: a source of
  // another sensor binding later is a hand-over.
  std::string last_sensor;
  std::uint64_t merge_into = 0;
  std::uint32_t merge_count = 0;

  int OffsetIndex(const std::string& sensor_id) const {
    for (std::size_t i = 0; i < offsets.size(); ++i) {
      if (offsets[i].sensor_id == sensor_id) return static_cast<int>(i);
    }
    return -1;
  }
};

Eigen::Index Dim(const Track& f) { return 4 + 2 * static_cast<Eigen::Index>(f.offsets.size()); }

void Symmetrize(Mat& p) { p = (0.5 * (p + p.transpose())).eval(); }

// Predicts f's state over dt_s >= 0: constant velocity for (x, y, vx, vy), first-order
// Gauss-Markov for every offset (b <- a b, a = exp(-dt / tau), process noise (1 - a^2) prior, so
// that its covariance relaxes to the prior).
void PredictState(const FusionOptions& o, double dt_s, Vec& x, Mat& p,
                  const std::vector<Offset>& offsets) {
  if (!(dt_s > 0.0) || !std::isfinite(dt_s)) return;
  const Eigen::Index n = x.size();
  const double a = std::exp(-dt_s / o.centre_correlation_s);
  x(0) += dt_s * x(2);
  x(1) += dt_s * x(3);
  x.tail(n - 4) *= a;
  p.row(0) += dt_s * p.row(2);
  p.row(1) += dt_s * p.row(3);
  p.bottomRows(n - 4) *= a;
  p.col(0) += dt_s * p.col(2);
  p.col(1) += dt_s * p.col(3);
  p.rightCols(n - 4) *= a;
  p.topLeftCorner<4, 4>() += common::CvProcessNoise(dt_s, o.accel_psd);
  for (std::size_t i = 0; i < offsets.size(); ++i) {
    const auto k = 4 + 2 * static_cast<Eigen::Index>(i);
    p.block<2, 2>(k, k) += (1.0 - a * a) * offsets[i].prior;
  }
  Symmetrize(p);
}

// Adds a state for the offset of `sensor_id` (zero, its prior, uncorrelated); forgets the offset
// measured longest ago when max_offset_sensors are kept.
int AddOffset(const FusionOptions& o, Track& f, const std::string& sensor_id,
              const Eigen::Matrix2d& prior, UtcNs t) {
  if (f.offsets.size() >= o.max_offset_sensors) {
    std::size_t oldest = 0;
    for (std::size_t i = 1; i < f.offsets.size(); ++i) {
      if (f.offsets[i].last_ns < f.offsets[oldest].last_ns) oldest = i;
    }
    // Marginalising a Gaussian: drop its rows and columns.
    const auto k = 4 + 2 * static_cast<Eigen::Index>(oldest);
    const Eigen::Index n = Dim(f);
    std::vector<Eigen::Index> keep;
    for (Eigen::Index i = 0; i < n; ++i) {
      if (i != k && i != k + 1) keep.push_back(i);
    }
    Vec x(n - 2);
    Mat p(n - 2, n - 2);
    for (std::size_t i = 0; i < keep.size(); ++i) {
      x(static_cast<Eigen::Index>(i)) = f.x(keep[i]);
      for (std::size_t j = 0; j < keep.size(); ++j) {
        p(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) = f.p(keep[i], keep[j]);
      }
    }
    f.x = std::move(x);
    f.p = std::move(p);
    f.offsets.erase(f.offsets.begin() + static_cast<std::ptrdiff_t>(oldest));
  }
  const Eigen::Index n = Dim(f);
  f.x.conservativeResize(n + 2);
  f.x.tail<2>().setZero();
  Mat p = Mat::Zero(n + 2, n + 2);
  p.topLeftCorner(n, n) = f.p;
  p.bottomRightCorner<2, 2>() = prior;
  f.p = std::move(p);
  f.offsets.push_back(Offset{sensor_id, t, prior});
  return static_cast<int>(f.offsets.size()) - 1;
}

// Forgets the offsets not measured for `max_age_s` (their correlation with anything has decayed).
void ForgetOffsets(Track& f, UtcNs now, double max_age_s) {
  std::vector<Eigen::Index> keep = {0, 1, 2, 3};
  std::vector<Offset> kept;
  for (std::size_t i = 0; i < f.offsets.size(); ++i) {
    if (Seconds(now, f.offsets[i].last_ns) > max_age_s) continue;
    const auto k = 4 + 2 * static_cast<Eigen::Index>(i);
    keep.push_back(k);
    keep.push_back(k + 1);
    kept.push_back(f.offsets[i]);
  }
  if (kept.size() == f.offsets.size()) return;
  const auto n = static_cast<Eigen::Index>(keep.size());
  Vec x(n);
  Mat p(n, n);
  for (Eigen::Index i = 0; i < n; ++i) {
    x(i) = f.x(keep[static_cast<std::size_t>(i)]);
    for (Eigen::Index j = 0; j < n; ++j) {
      p(i, j) = f.p(keep[static_cast<std::size_t>(i)], keep[static_cast<std::size_t>(j)]);
    }
  }
  f.x = std::move(x);
  f.p = std::move(p);
  f.offsets = std::move(kept);
}

// The rows of the measurement matrix: position = (x, y) + the sensor's offset (when it has a
// state), velocity = (vx, vy).
Mat MeasurementMatrix(Eigen::Index n, int offset_index, bool full_state) {
  Mat h = Mat::Zero(full_state ? 4 : 2, n);
  h(0, 0) = 1.0;
  h(1, 1) = 1.0;
  if (offset_index >= 0) {
    const auto k = 4 + 2 * static_cast<Eigen::Index>(offset_index);
    h(0, k) = 1.0;
    h(1, k + 1) = 1.0;
  }
  if (full_state) {
    h(2, 2) = 1.0;
    h(3, 3) = 1.0;
  }
  return h;
}

// A measurement made late_s before the state's time, moved to it with the state's velocity:
// z_p += late v, its noise grows by what that prediction does not know.
Measurement MovedForward(const Measurement& m, double late_s, const Vec& x, const Mat& p,
                         double accel_psd) {
  if (!(late_s > 0.0)) return m;
  Measurement out = m;
  const Eigen::Matrix4d q = common::CvProcessNoise(late_s, accel_psd);
  if (m.full_state) {
    out.z.head<2>() += late_s * m.z.tail<2>();
    common::CvApplyTransition(late_s, out.r);
    common::CvApplyTransitionTransposed(late_s, out.r);
    out.r += q;
  } else {
    out.z.head<2>() += late_s * x.segment<2>(2);
    out.r.topLeftCorner<2, 2>() += late_s * late_s * p.block<2, 2>(2, 2) + q.topLeftCorner<2, 2>();
  }
  return out;
}

class FusedFilterEngine final : public Engine {
 public:
  explicit FusedFilterEngine(const FusionOptions& options) : Engine(options) {}

  void SetPlacements(const PlacementMap& next, const PlacementMap& previous) override {
    for (auto it = sensors_.begin(); it != sensors_.end();) {
      const auto placement = next.find(it->first);
      if (placement == next.end()) {
        DropSensorTracks(it->first, it->second);
        it = sensors_.erase(it);
        continue;
      }
      const auto old = previous.find(it->first);
      if (old == previous.end() || !SamePlacement(old->second, placement->second)) {
        // A new calibration: what was learnt of the old placement's error does not hold.
        it->second.bias = BiasModel{};
        for (auto& [tid, lt] : it->second.tracks) {
          lt.observation = lt.received;
          lt.applied_bias_m = 0.0;
          lt.applied_world.setZero();
          lt.bias_j_sum.setZero();
          lt.bias_y_sum.setZero();
          lt.bias_updates = 0;
          lt.world = ToWorld(placement->second, it->first, lt.world.stamp_ns, lt.observation);
        }
      }
      ++it;
    }
    placements_ = next;
    // Estimates made with the old poses do not fit the new ones: every fused track starts again
    // from its sources' latest states, combined as independent estimates (their sensors differ).
    for (auto& [id, f] : tracks_) {
      Restart(f);
      f.merge_into = 0;
      f.merge_count = 0;
    }
  }

  void SetTrackerModel(const std::string& sensor_id, double accel_psd) override {
    if (std::isfinite(accel_psd) && accel_psd > 0.0 && accel_psd < 1e4) {
      tracker_psd_[sensor_id] = accel_psd;
    } else {
      tracker_psd_.erase(sensor_id);
    }
  }

  void AddFrame(const SensorPlacement& placement, const std::string& sensor_id,
                const daemon::TrackFrameData& frame) override;
  void Tick(UtcNs now_ns) override;
  std::vector<FusedTrack> Snapshot(UtcNs now_ns, bool include_tentative) const override;
  std::vector<WorldTrack> WorldTracks(UtcNs now_ns) const override;
  std::vector<HiddenFusedTrack> Hidden(const std::vector<FusedTrack>& reported,
                                       UtcNs now_ns) const override {
    return HiddenTracks(tracks_, reported, now_ns, options_.max_coast_s);
  }
  CovarianceScales covariance_scales() const override {
    CovarianceScales out;
    out.pose = pose_scale_.scale;
    for (const auto& [id, ss] : sensors_) out.trackers[id] = ss.noise_scale.scale;
    return out;
  }
  std::vector<SensorBias> sensor_biases() const override {
    std::vector<SensorBias> out;
    for (const auto& [id, ss] : sensors_) {
      const BiasModel& b = ss.bias;
      if (!b.solved) continue;
      for (std::size_t k = 0; k < kKinds; ++k) {
        const auto i = 3 + static_cast<Eigen::Index>(k);
        if (b.a[0](i, i) <= 0.0) continue;  // no sample of this kind
        SensorBias sb;
        sb.sensor_id = id;
        sb.kind = static_cast<daemon::MeasurementKind>(k);
        const BiasVec theta = Applicable(b);
        sb.radial_m = theta(i);
        const BiasMat covariance = Covariance(b);
        sb.sigma_m = std::sqrt(std::max(covariance(i, i), 0.0));
        sb.dx_m = theta(0);
        sb.dy_m = theta(1);
        sb.dyaw_rad = theta(2);
        sb.pose_covariance = covariance.topLeftCorner<3, 3>();
        sb.samples = b.samples;
        sb.residual_radial_m = std::sqrt(std::max(b.noise_m2[0], 0.0));
        sb.residual_lateral_m = std::sqrt(std::max(b.noise_m2[1], 0.0));
        sb.applied = Learnt(b);
        sb.offset_applied = OffsetApplied(b, sb.kind);
        out.push_back(std::move(sb));
      }
    }
    return out;
  }

 private:
  bool Learnt(const BiasModel& b) const {
    return options_.learn_sensor_bias && b.solved && b.samples >= options_.sensor_bias_min_samples;
  }
  // The estimate with its offsets clamped to max_sensor_bias_m.
  BiasVec Applicable(const BiasModel& b) const {
    BiasVec theta = b.estimate;
    for (Eigen::Index i = 3; i < kBiasParams; ++i) {
      theta(i) = std::clamp(theta(i), -options_.max_sensor_bias_m, options_.max_sensor_bias_m);
    }
    return theta;
  }
  // The covariance of the estimate, widened by sensor_bias_covariance_scale (successive samples
  // of one local track share its own offset; the regression takes them as independent).
  BiasMat Covariance(const BiasModel& b) const {
    return options_.sensor_bias_covariance_scale * b.covariance;
  }
  // The placement corrected by the sensor's learnt error, with the estimate's covariance (in
  // place of the calibration's) once it is learnt; else `placement`.
  SensorPlacement CorrectedPlacement(const SensorPlacement& placement, const BiasModel& b) const {
    if (!Learnt(b)) return placement;
    const BiasVec theta = Applicable(b);
    SensorPlacement out = placement;
    out.world_from_sensor.x_m -= theta(0);
    out.world_from_sensor.y_m -= theta(1);
    out.world_from_sensor.yaw_rad -= theta(2);
    out.covariance = Covariance(b).topLeftCorner<3, 3>();
    return out;
  }
  // Whether the learnt offset of a kind is taken out of the frames: only where it is known to
  // within sensor_bias_offset_sigma_fraction of the kind's centre sigma (a less precise one
  // would add an error common to all the sensor's frames for minutes, which the fused tracks'
  // offset states, relaxing within centre_correlation_s, do better without).
  bool OffsetApplied(const BiasModel& b, daemon::MeasurementKind kind) const {
    if (!Learnt(b)) return false;
    const auto i = 3 + static_cast<Eigen::Index>(KindIndex(kind));
    const double limit = options_.sensor_bias_offset_sigma_fraction * CentreSigma(kind);
    return Covariance(b)(i, i) <= limit * limit;
  }
  double AppliedBias(const SensorState& ss, daemon::MeasurementKind kind) const {
    if (!OffsetApplied(ss.bias, kind)) return 0.0;
    return Applicable(ss.bias)(3 + static_cast<Eigen::Index>(KindIndex(kind)));
  }
  double AppliedBiasSigma(const SensorState& ss, daemon::MeasurementKind kind) const {
    if (!OffsetApplied(ss.bias, kind)) return 0.0;
    const auto i = 3 + static_cast<Eigen::Index>(KindIndex(kind));
    return std::sqrt(std::max(Covariance(ss.bias)(i, i), 0.0));
  }
  // The prior of a sensor's bias model: its placement's covariance (pose_scale_ and
  // sensor_bias_pose_prior_scale included) and the centre sigma of each kind.
  BiasMat BiasPrior(const SensorPlacement& placement) const {
    BiasMat prior = BiasMat::Zero();
    prior.topLeftCorner<3, 3>() =
        options_.sensor_bias_pose_prior_scale * pose_scale_.scale * placement.covariance;
    for (std::size_t k = 0; k < kKinds; ++k) {
      const double sigma = CentreSigma(static_cast<daemon::MeasurementKind>(k));
      prior(3 + static_cast<Eigen::Index>(k), 3 + static_cast<Eigen::Index>(k)) = sigma * sigma;
    }
    return prior;
  }
  // The local track's sample of its sensor's bias, when it has enough updates; the model solved
  // again.
  void SubmitBiasSample(SensorState& ss, LocalTrack& lt, const SensorPlacement* placement) {
    if (lt.bias_updates >= kMinBiasUpdates && placement != nullptr) {
      const double n = lt.bias_updates;
      const BiasRows j = lt.bias_j_sum / n;
      const Eigen::Vector2d y = lt.bias_y_sum / n;
      AddBiasSample(ss.bias, j, y, BiasPrior(*placement));
    }
    lt.bias_j_sum.setZero();
    lt.bias_y_sum.setZero();
    lt.bias_updates = 0;
  }
  void AddBiasSample(BiasModel& b, const BiasRows& j, const Eigen::Vector2d& y,
                     const BiasMat& prior) {
    if (!AllFinite(j) || !AllFinite(y)) return;
    const double memory = options_.sensor_bias_memory;
    // The line of sight: the offset's column of J is -n.
    Eigen::Vector2d n = -j.rightCols<kKinds>().rowwise().sum();
    if (!(n.norm() > 0.5)) return;
    n.normalize();
    const Eigen::Vector2d l(-n.y(), n.x());
    // The noise: residuals against the estimate so far (the first samples: the largest centre
    // sigma).
    const double first = prior.diagonal().tail<kKinds>().maxCoeff();
    const Eigen::Vector2d r = y - j * b.estimate;
    b.noise_count = std::min(b.noise_count + 1.0, memory);
    const double forget = 1.0 - 1.0 / memory;
    for (int k = 0; k < 2; ++k) {
      const Eigen::Vector2d& dir = k == 0 ? n : l;
      if (b.noise_m2[k] <= 0.0) b.noise_m2[k] = first;
      const double rk = dir.dot(r);
      b.noise_m2[k] += (rk * rk - b.noise_m2[k]) / (b.noise_count + 1.0);
      const BiasVec jk = (dir.transpose() * j).transpose();
      b.a[k] = forget * b.a[k] + jk * jk.transpose();
      b.c[k] = forget * b.c[k] + jk * dir.dot(y);
    }
    ++b.samples;
    // Information form: (sum_k A_k / noise_k + prior^-1) theta = sum_k c_k / noise_k. A prior
    // variance of zero (the calibration's reference sensor) fixes that parameter at zero.
    const BiasMat data_info = b.a[0] / b.noise_m2[0] + b.a[1] / b.noise_m2[1];
    const BiasVec rhs = b.c[0] / b.noise_m2[0] + b.c[1] / b.noise_m2[1];
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> pose_eig(
        Eigen::Matrix3d(prior.topLeftCorner<3, 3>()));
    if (pose_eig.info() != Eigen::Success) return;
    constexpr double kFixed = 1e-12;  // variance below which a direction is fixed
    Eigen::Matrix3d pose_info = Eigen::Matrix3d::Zero();
    for (int i = 0; i < 3; ++i) {
      const double lambda = pose_eig.eigenvalues()(i);
      const Eigen::Vector3d v = pose_eig.eigenvectors().col(i);
      pose_info += (lambda > kFixed ? 1.0 / lambda : 1.0 / kFixed) * v * v.transpose();
    }
    // Solved with the pose prior's information scaled by 1 / widen.
    const auto solve = [&](double widen, BiasVec& estimate, BiasMat& covariance) {
      BiasMat info = data_info;
      info.topLeftCorner<3, 3>() += pose_info / widen;
      for (Eigen::Index i = 3; i < kBiasParams; ++i) info(i, i) += 1.0 / prior(i, i);
      const Eigen::LDLT<BiasMat> ldlt(info);
      if (ldlt.info() != Eigen::Success) return false;
      estimate = ldlt.solve(rhs);
      covariance = ldlt.solve(BiasMat::Identity());
      covariance = (0.5 * (covariance + covariance.transpose())).eval();
      return AllFinite(estimate) && AllFinite(covariance);
    };
    BiasVec estimate;
    BiasMat covariance;
    if (!solve(1.0, estimate, covariance)) return;
    // A placement error the prior finds unlikely (squared Mahalanobis distance above its 3
    // degrees of freedom): the calibration claims too much; its prior is widened by that ratio
    // and the regression solved again (an empirical Bayes step), so that the estimate is not
    // held back, nor its covariance too small.
    const Eigen::Vector3d pose = estimate.head<3>();
    const double d2 = pose.dot(pose_info * pose);
    if (std::isfinite(d2) && d2 > 3.0) {
      BiasVec wider_estimate;
      BiasMat wider_covariance;
      if (solve(d2 / 3.0, wider_estimate, wider_covariance)) {
        estimate = wider_estimate;
        covariance = wider_covariance;
      }
    }
    b.estimate = estimate;
    b.covariance = covariance;
    b.solved = true;
  }

  LocalTrack* Find(const SourceKey& key) {
    const auto s = sensors_.find(key.sensor_id);
    if (s == sensors_.end()) return nullptr;
    const auto t = s->second.tracks.find(key.track_id);
    return t == s->second.tracks.end() ? nullptr : &t->second;
  }
  const LocalTrack* Find(const SourceKey& key) const {
    const auto s = sensors_.find(key.sensor_id);
    if (s == sensors_.end()) return nullptr;
    const auto t = s->second.tracks.find(key.track_id);
    return t == s->second.tracks.end() ? nullptr : &t->second;
  }

  double TrackerPsd(const std::string& sensor_id) const {
    const auto it = tracker_psd_.find(sensor_id);
    return it == tracker_psd_.end() ? options_.tracker_accel_psd : it->second;
  }

  double CentreSigma(daemon::MeasurementKind kind) const {
    switch (kind) {
      case daemon::MeasurementKind::kShapeFit:
        return options_.centre_sigma_shape_fit_m;
      case daemon::MeasurementKind::kEllipse:
        return options_.centre_sigma_ellipse_m;
      case daemon::MeasurementKind::kCenterOfMass:
      case daemon::MeasurementKind::kUnspecified:
        break;
    }
    return options_.centre_sigma_com_m;
  }

  Measurement Measure(const SensorPlacement& placement, const std::string& sensor_id,
                      LocalTrack& lt, UtcNs t);

  void Unbind(Track& f, const SourceKey& key) {
    f.sources.erase(std::remove(f.sources.begin(), f.sources.end(), key), f.sources.end());
    if (LocalTrack* lt = Find(key); lt != nullptr && lt->fused_id == f.id) {
      lt->fused_id.reset();
      lt->misses = 0;
    }
  }

  // Binds the local track to f: away from its previous fused track, and in place of any other
  // source of the same sensor in f.
  void Bind(Track& f, const SourceKey& key, LocalTrack& lt) {
    if (lt.fused_id && *lt.fused_id != f.id) {
      auto g = tracks_.find(*lt.fused_id);
      if (g != tracks_.end()) Unbind(g->second, key);
    }
    const std::vector<SourceKey> current = f.sources;
    for (const SourceKey& k : current) {
      if (k.sensor_id == key.sensor_id && k.track_id != key.track_id) Unbind(f, k);
    }
    if (std::find(f.sources.begin(), f.sources.end(), key) == f.sources.end()) {
      f.sources.insert(std::upper_bound(f.sources.begin(), f.sources.end(), key), key);
    }
    lt.fused_id = f.id;
    lt.misses = 0;
    lt.hold_frames = 0;
  }

  void DeleteTrack(std::map<std::uint64_t, Track>::iterator it) {
    const std::vector<SourceKey> keys = it->second.sources;
    for (const SourceKey& k : keys) Unbind(it->second, k);
    tracks_.erase(it);
  }

  const SensorPlacement* PlacementOf(const std::string& sensor_id) const {
    const auto it = placements_.find(sensor_id);
    return it == placements_.end() ? nullptr : &it->second;
  }

  void DropSensorTracks(const std::string& sensor_id, SensorState& ss) {
    for (auto& [tid, lt] : ss.tracks) {
      SubmitBiasSample(ss, lt, PlacementOf(sensor_id));
      if (!lt.fused_id) continue;
      auto f = tracks_.find(*lt.fused_id);
      if (f != tracks_.end()) Unbind(f->second, SourceKey{sensor_id, tid});
    }
    ss.tracks.clear();
    ss.forgotten.clear();  // a new session's ids are other tracks
  }

  // A local track that returns after it was forgotten. A tracker may hold a coasting track
  // unsent for longer than source_timeout_s and send it again with the same id (it resumed the
  // track: the same person, as far as it knows). Started as a new source, it would start a
  // second fused track beside the one it fed, be bound back to that one a frame later, and leave
  // the new one without sources to coast on as a false track. So it is bound again to the fused
  // track it fed, if that still lives and holds no other track of the sensor; the association
  // then treats it as any bound source (binding_bonus; unbound after drift_updates strikes if
  // it no longer fits). Kept for max_coast_s after the last frame: the fused track it fed
  // coasts no longer than that without other sources.
  void ReturningSource(const std::string& sensor_id, SensorState& ss, std::uint32_t track_id,
                       LocalTrack& lt, UtcNs t) {
    const auto it = ss.forgotten.find(track_id);
    if (it == ss.forgotten.end()) return;
    const SensorState::Forgotten forgotten = it->second;
    ss.forgotten.erase(it);
    if (Seconds(t, forgotten.last_ns) > options_.max_coast_s) return;
    const auto f = tracks_.find(forgotten.fused_id);
    if (f == tracks_.end()) return;
    for (const SourceKey& k : f->second.sources) {
      if (k.sensor_id == sensor_id) return;
    }
    Bind(f->second, SourceKey{sensor_id, track_id}, lt);
    ++counters_.sources_returned;
  }

  void ExpireSources(const std::string& sensor_id, SensorState& ss, UtcNs now) {
    for (auto it = ss.forgotten.begin(); it != ss.forgotten.end();) {
      it = Seconds(now, it->second.last_ns) > options_.max_coast_s ? ss.forgotten.erase(it)
                                                                   : std::next(it);
    }
    for (auto it = ss.tracks.begin(); it != ss.tracks.end();) {
      LocalTrack& lt = it->second;
      if (Seconds(now, lt.stamp()) <= options_.source_timeout_s) {
        ++it;
        continue;
      }
      SubmitBiasSample(ss, lt, PlacementOf(sensor_id));
      if (lt.fused_id) {
        auto f = tracks_.find(*lt.fused_id);
        if (f != tracks_.end()) {
          Unbind(f->second, SourceKey{sensor_id, it->first});
          if (!f->second.sources.empty()) {
            ++counters_.handovers;  // other sensors continue the track
          } else {
            f->second.last_sensor = sensor_id;
            if (!options_.report_sourceless && f->second.confirmed) {
              ++counters_.fused_unreported_sourceless;
            }
          }
          ss.forgotten[it->first] = SensorState::Forgotten{f->first, lt.stamp()};
        }
        ++counters_.sources_timed_out;
      }
      it = ss.tracks.erase(it);
    }
  }

  // f's state predicted to t (not before its own time).
  void Predicted(const Track& f, UtcNs t, Vec& x, Mat& p) const {
    x = f.x;
    p = f.p;
    PredictState(options_, Seconds(t, f.stamp_ns), x, p, f.offsets);
  }

  // The association cost of measurement m of `sensor_id` with f predicted to t (x, p): squared
  // Mahalanobis distance of the positions plus ln det S; nullopt outside the gates.
  std::optional<double> Cost(const Track& f, const Vec& x, const Mat& p, const Measurement& m,
                             const std::string& sensor_id, double late_s) const;

  // For a bound measurement its fused track (fused_id, untaken in this frame) did not accept:
  // the factor by which that track's kinematic covariance must grow for the measurement to lie
  // at half the gate, when it is within manoeuvre_max_distance_m; else 1 (no manoeuvre).
  template <typename Candidates>
  double ManoeuvreWidening(Candidates& candidates, const std::vector<char>& taken,
                           std::uint64_t fused_id, const Measurement& m,
                           const std::string& sensor_id) {
    for (std::size_t j = 0; j < candidates.size(); ++j) {
      auto& c = candidates[j];
      if (c.track->id != fused_id) continue;
      if (taken[j] || !c.predicted) return 1.0;
      const Measurement moved = MovedForward(m, c.late_s, c.x, c.p, options_.accel_psd);
      const int k = c.track->OffsetIndex(sensor_id);
      Eigen::Vector2d predicted = c.x.template head<2>();
      Eigen::Matrix2d kinematic = c.p.template topLeftCorner<2, 2>();
      Eigen::Matrix2d rest = moved.r.topLeftCorner<2, 2>();
      if (k >= 0) {
        const auto i = 4 + 2 * static_cast<Eigen::Index>(k);
        predicted += c.x.template segment<2>(i);
        rest += c.p.template block<2, 2>(i, i);
        kinematic += c.p.template block<2, 2>(0, i) + c.p.template block<2, 2>(i, 0);
      } else {
        rest += moved.offset_prior;
      }
      const Eigen::Vector2d nu = moved.z.head<2>() - predicted;
      if (nu.norm() > options_.manoeuvre_max_distance_m) return 1.0;
      // Smallest widening w (doubling) with nu^T (w kinematic + rest)^-1 nu <= gate / 2.
      for (double w = 2.0; w <= 1024.0; w *= 2.0) {
        if (Mahalanobis2(nu, w * kinematic + rest, Eigen::Vector2d::Zero(),
                         Eigen::Matrix2d::Zero()) <= 0.5 * options_.gate_mahalanobis2) {
          return w;
        }
      }
      return 1.0;
    }
    return 1.0;
  }

  // The Kalman update of f with m of `sensor_id` made at t. False (f unchanged) on a numerical
  // failure.
  // widen > 1 scales the covariance of (x, y, vx, vy) (and its correlation with the offsets by
  // the square root) before the update: a manoeuvre the motion model did not expect.
  // bias_sample (optional): set to the sensor's offset there with the prior's shrinkage undone,
  // when the update tells something about it ("Sensor bias" in fusion.h).
  bool Update(Track& f, const Measurement& m, const std::string& sensor_id, UtcNs t,
              double widen = 1.0, std::optional<Eigen::Vector2d>* bias_sample = nullptr);

  Track& NewTrack(const Measurement& m, const std::string& sensor_id, UtcNs t);

  // Whether another sensor than `sensor_id` measured f within source_timeout_s of t.
  bool OthersMeasured(const Track& f, const std::string& sensor_id, UtcNs t) const {
    for (const Offset& off : f.offsets) {
      if (off.sensor_id != sensor_id && Seconds(t, off.last_ns) <= options_.source_timeout_s) {
        return true;
      }
    }
    return false;
  }

  // Whether g (at g_pos) stands in the shadow of a body of radius merge_sourceless_shadow_m at
  // f_pos from every sensor that measured g within source_timeout_s of its last measurement:
  // along each sensor's line of sight u through f_pos, at least that radius behind f
  // (d.u - |f_pos - s| >= r) and across it within the shadow's half-width at that range plus a
  // body's radius (|d x u| <= r (d.u) / |f_pos - s| + r), d = g_pos - s.
  bool InShadowOf(const Track& g, const Eigen::Vector2d& g_pos,
                  const Eigen::Vector2d& f_pos) const {
    const double r = options_.merge_sourceless_shadow_m;
    if (!(r > 0.0)) return false;
    UtcNs last_ns = 0;
    for (const Offset& off : g.offsets) last_ns = std::max(last_ns, off.last_ns);
    bool any = false;
    for (const Offset& off : g.offsets) {
      if (off.last_ns == 0 || Seconds(last_ns, off.last_ns) > options_.source_timeout_s) continue;
      const SensorPlacement* placement = PlacementOf(off.sensor_id);
      if (placement == nullptr) continue;
      const Eigen::Vector2d s = placement->world_from_sensor.translation();
      const Eigen::Vector2d to_f = f_pos - s, to_g = g_pos - s;
      const double range_f = to_f.norm();
      if (!(range_f > r)) return false;
      const Eigen::Vector2d u = to_f / range_f;
      const double range_g = to_g.dot(u);
      const double across = std::abs(u.x() * to_g.y() - u.y() * to_g.x());
      if (!(range_g - range_f >= r) || !(across <= r * range_g / range_f + r)) return false;
      any = true;
    }
    return any;
  }

  std::vector<std::string> ActiveSensors(const Track& f) const {
    std::vector<std::string> out;
    for (const SourceKey& k : f.sources) {
      const LocalTrack* lt = Find(k);
      const auto s = sensors_.find(k.sensor_id);
      if (lt == nullptr || s == sensors_.end() || !lt->usable || lt->misses != 0 ||
          lt->stamp() != s->second.clock.latest_ns ||
          Seconds(f.stamp_ns, lt->stamp()) > options_.source_timeout_s) {
        continue;
      }
      out.push_back(k.sensor_id);
    }
    return out;
  }

  // Replaces f's estimate by the information-weighted combination of its sources' latest world
  // states (pose uncertainty included) predicted to f's time, its offsets forgotten. Unchanged
  // when no source is left.
  void Restart(Track& f) {
    Eigen::Matrix4d info = Eigen::Matrix4d::Zero();
    Eigen::Vector4d info_x = Eigen::Vector4d::Zero();
    int count = 0;
    for (const SourceKey& k : f.sources) {
      const LocalTrack* lt = Find(k);
      if (lt == nullptr) continue;
      CvState x(lt->world.x_m, lt->world.y_m, lt->world.vx_mps, lt->world.vy_mps);
      CvCovariance p = lt->world.covariance;
      const double sigma = CentreSigma(lt->observation.kind);
      p.topLeftCorner<2, 2>() += sigma * sigma * Eigen::Matrix2d::Identity();
      internal::Predict(Seconds(f.stamp_ns, lt->stamp()), options_.accel_psd, x, p);
      const Eigen::LLT<Eigen::Matrix4d> llt(p);
      if (llt.info() != Eigen::Success) continue;
      const Eigen::Matrix4d i = llt.solve(Eigen::Matrix4d::Identity());
      info += i;
      info_x += i * x;
      ++count;
    }
    if (count == 0) return;
    const Eigen::LLT<Eigen::Matrix4d> llt(info);
    if (llt.info() != Eigen::Success) return;
    Eigen::Matrix4d p = llt.solve(Eigen::Matrix4d::Identity());
    p = (0.5 * (p + p.transpose())).eval();
    const Eigen::Vector4d x = p * info_x;
    if (!AllFinite(x) || !AllFinite(p)) return;
    f.x = x;
    f.p = p;
    f.offsets.clear();
  }

  std::uint64_t MergeCheck(std::uint64_t f_id);
  // estimate_of: 0, or the one of the two whose estimate alone is kept (the other is a track
  // without sources whose information is older and shares its sensors).
  void Merge(std::uint64_t older_id, std::uint64_t younger_id, std::uint64_t estimate_of = 0);

  std::map<std::string, SensorState, std::less<>> sensors_;
  std::map<std::string, double, std::less<>> tracker_psd_;
  PlacementMap placements_;  // as the Fuser was given them
  std::map<std::uint64_t, Track> tracks_;
  // Scale of the calibration's pose covariances, learnt from how well sensors' tracks fit the
  // fused tracks of other sensors when they join them (adapt_covariances).
  CovarianceScale pose_scale_;
  bool have_newest_ = false;
  UtcNs newest_ns_ = 0;
};

// Recovers the information of this frame (fusion.h, "kFusedFilter"). The tracker's filter turned
// its prediction xb, Pb (from the previous measured state, with its own process noise) into x, P
// with a position measurement z ~ N(H x_true, R). For the position marginals of a Kalman update
// with H = [I 0] (its information form; e.g. Bar-Shalom, Li & Kirubarajan, "Estimation with
// Applications to Tracking and Navigation", 2001):
//   P_pp^-1 = Pb_pp^-1 + R^-1,        x_p = xb_p + Pb_pp (Pb_pp + R)^-1 (z - xb_p)
// so  R^-1 = P_pp^-1 - Pb_pp^-1   and   z = xb_p + R P_pp^-1 (x_p - xb_p)
// (using (Pb_pp + R) Pb_pp^-1 = R P_pp^-1). Directions in which the covariance did not shrink
// carry no information; if the tracker's model is not the one assumed, R is what it would have
// had to be under the assumed one (a process noise assumed too low gives a larger R).
Measurement FusedFilterEngine::Measure(const SensorPlacement& placement,
                                       const std::string& sensor_id, LocalTrack& lt, UtcNs t) {
  Measurement m;
  const daemon::TrackObservation& obs = lt.observation;
  if (obs.state == daemon::TrackState::kCoasting) return m;  // a prediction: nothing new
  const CvState x(obs.x_m, obs.y_m, obs.vx_mps, obs.vy_mps);
  const CvCovariance p = UnpackCovariance(obs.covariance);
  const common::Pose2& pose = placement.world_from_sensor;
  const Eigen::Matrix2d rot = pose.rotation();

  Eigen::Vector2d z_s = x.head<2>();
  Eigen::Matrix2d r_s = p.topLeftCorner<2, 2>();
  bool usable_measurement = true;
  if (lt.contributed && !lt.unfiltered) {
    const double dt = Seconds(t, lt.reference_ns);
    if (!lt.has_reference || !(dt > 0.0) || !std::isfinite(dt)) {
      usable_measurement = false;
    } else {
      // The previous state corrected with the same offset as this one (a change of the learnt
      // offset is no motion).
      const daemon::TrackObservation ref = CentreCorrected(lt.reference, lt.applied_bias_m);
      CvState xb(ref.x_m, ref.y_m, ref.vx_mps, ref.vy_mps);
      CvCovariance pb = lt.reference_p;
      common::CvPredict(dt, TrackerPsd(sensor_id), xb, pb);
      const Eigen::Matrix2d pp = p.topLeftCorner<2, 2>(), pbp = pb.topLeftCorner<2, 2>();
      const Eigen::LLT<Eigen::Matrix2d> llt_p(pp), llt_pb(pbp);
      if (llt_p.info() != Eigen::Success || llt_pb.info() != Eigen::Success) {
        usable_measurement = false;
      } else {
        const Eigen::Matrix2d pp_inv = llt_p.solve(Eigen::Matrix2d::Identity());
        Eigen::Matrix2d info = pp_inv - llt_pb.solve(Eigen::Matrix2d::Identity());
        info = (0.5 * (info + info.transpose())).eval();
        const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(info);
        const Eigen::Vector2d lambda = eig.eigenvalues();
        const double scale = pp_inv.trace();
        if (eig.info() != Eigen::Success || !AllFinite(lambda)) {
          usable_measurement = false;
        } else {
          if (lambda.minCoeff() < -1e-3 * scale) ++counters_.recovery_clamped;
          Eigen::Vector2d variance;
          for (int i = 0; i < 2; ++i) {
            variance(i) = lambda(i) > 1.0 / kMaxMeasurementVariance
                              ? std::max(1.0 / lambda(i), kMinMeasurementVariance)
                              : kMaxMeasurementVariance;
          }
          r_s = eig.eigenvectors() * variance.asDiagonal() * eig.eigenvectors().transpose();
          z_s = xb.head<2>() + r_s * pp_inv * (x.head<2>() - xb.head<2>());
          const double ratio = std::min(r_s.trace() / pp.trace(), 1e3);
          ++lt.recovered_frames;
          lt.ratio_sum += ratio;
          if (lt.recovered_frames >= kUnfilteredFrames &&
              lt.ratio_sum > kUnfilteredRatio * lt.recovered_frames) {
            lt.unfiltered = true;
            ++counters_.sources_unfiltered;
          }
          // A frame that added (almost) nothing to what a filter would have known: a state that
          // is not a filter's (what was recovered is nonsense far away with a huge covariance).
          // The state itself is the measurement then.
          if (ratio > kUnfilteredRatio) {
            z_s = x.head<2>();
            r_s = pp;
          }
        }
      }
    }
  }
  // The next frame's reference.
  lt.has_reference = true;
  lt.reference = lt.received;
  lt.reference_p = p;
  lt.reference_ns = t;
  if (!usable_measurement || !AllFinite(z_s) || !AllFinite(r_s)) return m;

  m.valid = true;
  m.full_state = !lt.contributed;
  m.z.head<2>() = rot * z_s + pose.translation();
  const auto ss = sensors_.find(sensor_id);
  const double noise_scale = ss == sensors_.end() ? 1.0 : ss->second.noise_scale.scale;
  if (m.full_state) {
    Eigen::Matrix4d j = Eigen::Matrix4d::Zero();
    j.topLeftCorner<2, 2>() = rot;
    j.bottomRightCorner<2, 2>() = rot;
    m.z.tail<2>() = rot * x.tail<2>();
    m.r = noise_scale * j * p * j.transpose();
    // The yaw uncertainty turns the velocity too; the position part is in the offset.
    const Eigen::Matrix<double, 4, 3> jp = PoseJacobian(pose, x.head<2>(), x.tail<2>());
    m.r.bottomRightCorner<2, 2>() +=
        jp.bottomRows<2>() * placement.covariance * jp.bottomRows<2>().transpose();
  } else {
    m.r.topLeftCorner<2, 2>() = noise_scale * rot * r_s * rot.transpose();
  }
  m.r = (0.5 * (m.r + m.r.transpose())).eval();
  // The offset of this sensor's centre at this place: the pose's uncertainty carried to the
  // position (first order, as in ToWorld) plus the centre's own offset, larger along the line
  // of sight (the side a sensor sees) than across it.
  const Eigen::Matrix<double, 4, 3> jp = PoseJacobian(pose, x.head<2>(), x.tail<2>());
  m.offset_prior =
      pose_scale_.scale * jp.topRows<2>() * placement.covariance * jp.topRows<2>().transpose();
  const double sigma = CentreSigma(obs.kind);
  const double lateral = options_.centre_lateral_fraction * sigma;
  Eigen::Vector2d u = rot * x.head<2>();
  const double range = u.norm();
  u = range > 1e-6 ? Eigen::Vector2d(u / range) : Eigen::Vector2d(1.0, 0.0);
  // The learnt offset's own error is common to the sensor's frames, as the pose's.
  const auto ss_it = sensors_.find(sensor_id);
  const double bias_sigma =
      ss_it == sensors_.end() ? 0.0 : AppliedBiasSigma(ss_it->second, obs.kind);
  m.offset_prior += (sigma * sigma + bias_sigma * bias_sigma) * u * u.transpose() +
                    lateral * lateral * (Eigen::Matrix2d::Identity() - u * u.transpose());
  m.offset_prior = (0.5 * (m.offset_prior + m.offset_prior.transpose())).eval();
  if (!AllFinite(m.z) || !AllFinite(m.r) || !AllFinite(m.offset_prior)) m.valid = false;
  return m;
}

std::optional<double> FusedFilterEngine::Cost(const Track& f, const Vec& x, const Mat& p,
                                              const Measurement& m0, const std::string& sensor_id,
                                              double late_s) const {
  const Measurement m = MovedForward(m0, late_s, x, p, options_.accel_psd);
  const int k = f.OffsetIndex(sensor_id);
  Eigen::Vector2d predicted = x.head<2>();
  Eigen::Matrix2d s = p.topLeftCorner<2, 2>() + m.r.topLeftCorner<2, 2>();
  if (k >= 0) {
    const auto i = 4 + 2 * static_cast<Eigen::Index>(k);
    predicted += x.segment<2>(i);
    s += p.block<2, 2>(i, i) + p.block<2, 2>(0, i) + p.block<2, 2>(i, 0);
  } else {
    s += m.offset_prior;
  }
  const Eigen::Vector2d nu = m.z.head<2>() - predicted;
  if (nu.norm() > options_.gate_max_distance_m) return std::nullopt;
  double log_det = 0.0;
  const double d2 = Mahalanobis2(m.z.head<2>(), Eigen::Matrix2d::Zero(), predicted, s, &log_det);
  if (!(d2 <= options_.gate_mahalanobis2)) return std::nullopt;
  return d2 + log_det;
}

bool FusedFilterEngine::Update(Track& f, const Measurement& m0, const std::string& sensor_id,
                               UtcNs t, double widen, std::optional<Eigen::Vector2d>* bias_sample) {
  const UtcNs t_est = std::max(t, f.stamp_ns);
  Vec x;
  Mat p;
  Predicted(f, t_est, x, p);
  if (widen > 1.0) {
    const double w = std::sqrt(widen);
    p.topRows<4>() *= w;
    p.leftCols<4>() *= w;
  }
  const Measurement m = MovedForward(m0, Seconds(t_est, t), x, p, options_.accel_psd);
  // The update works on a copy of the filter state: f stays as it was if it fails.
  Track candidate;
  candidate.x = std::move(x);
  candidate.p = std::move(p);
  candidate.offsets = f.offsets;
  int k = candidate.OffsetIndex(sensor_id);
  if (k < 0) k = AddOffset(options_, candidate, sensor_id, m.offset_prior, t_est);
  const Eigen::Index n = Dim(candidate);
  const Mat h = MeasurementMatrix(n, k, m.full_state);
  const Eigen::Index d = h.rows();
  const Mat r = m.r.topLeftCorner(d, d);
  const Vec nu = m.z.head(d) - h * candidate.x;
  const Mat pht = candidate.p * h.transpose();
  const Mat s = (h * pht + r).eval();
  const Eigen::LLT<Mat> llt(s);
  if (llt.info() != Eigen::Success) {
    ++counters_.numerical_failures;
    return false;
  }
  if (options_.adapt_covariances) {
    // Covariance matching of the poses (a whole track joining others) and of the sensor's
    // measurements (its frames in its own fused track).
    if (m.full_state) {
      if (OthersMeasured(candidate, sensor_id, t_est)) {
        pose_scale_.Add(PositionNis(nu, s), kPoseNisRate, kMaxPoseScale);
      }
    } else if (const auto ss = sensors_.find(sensor_id); ss != sensors_.end()) {
      ss->second.noise_scale.Add(PositionNis(nu, s), kNoiseNisRate, kMaxNoiseScale);
    }
  }
  const Mat gain = llt.solve(pht.transpose()).transpose();
  candidate.x += gain * nu;
  // Joseph form: stays positive semi-definite in floating point.
  const Mat i_kh = Mat::Identity(n, n) - gain * h;
  candidate.p = i_kh * candidate.p * i_kh.transpose() + gain * r * gain.transpose();
  Symmetrize(candidate.p);
  if (!AllFinite(candidate.x) || !AllFinite(candidate.p)) {
    ++counters_.numerical_failures;
    return false;
  }
  if (bias_sample != nullptr && !m.full_state && OthersMeasured(candidate, sensor_id, t_est)) {
    // The offset's posterior N(mean, V) with its prior N(0, B)'s shrinkage undone: the
    // likelihood's mean B (B - V)^-1 mean (fusion.h, "Sensor bias"), where the data says at least
    // as much as the prior in every direction (V <= B / 2).
    const auto i = 4 + 2 * static_cast<Eigen::Index>(k);
    const Eigen::Vector2d mean = candidate.x.segment<2>(i);
    const Eigen::Matrix2d v = candidate.p.block<2, 2>(i, i);
    const Eigen::Matrix2d& b = m.offset_prior;
    const Eigen::LLT<Eigen::Matrix2d> llt_b(b);
    if (llt_b.info() == Eigen::Success) {
      const Eigen::Matrix2d l_inv = llt_b.matrixL().solve(Eigen::Matrix2d::Identity());
      const Eigen::Matrix2d w = l_inv * v * l_inv.transpose();
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(
          Eigen::Matrix2d(0.5 * (w + w.transpose())), Eigen::EigenvaluesOnly);
      if (eig.info() == Eigen::Success && eig.eigenvalues().maxCoeff() <= 0.5) {
        const Eigen::Vector2d y = b * (b - v).ldlt().solve(mean);
        if (AllFinite(y)) *bias_sample = y;
      }
    }
  }
  Offset& offset = candidate.offsets[static_cast<std::size_t>(k)];
  offset.last_ns = t_est;
  offset.prior = m.offset_prior;
  f.x = std::move(candidate.x);
  f.p = std::move(candidate.p);
  f.offsets = std::move(candidate.offsets);
  f.stamp_ns = t_est;
  if (f.updates == 0) f.first_ns = t_est;
  ++f.updates;
  if (f.updates >= options_.confirm_updates) f.confirmed = true;
  return true;
}

// A new fused track from a local track's state z (with the tracker's covariance R, velocity
// included) and its sensor's offset b ~ N(0, B): z = p + b + e, so p = z - b - e, and
//   x = (z, 0),  P = [R + B_pp, -B; -B, B]   (B on the position rows only).
Track& FusedFilterEngine::NewTrack(const Measurement& m, const std::string& sensor_id, UtcNs t) {
  Track f;
  f.id = next_id_++;
  f.first_ns = t;
  f.stamp_ns = t;
  f.x = Vec::Zero(6);
  f.x.head<4>() = m.z;
  f.p = Mat::Zero(6, 6);
  f.p.topLeftCorner<4, 4>() = m.r;
  if (!m.full_state) {
    // Only a position measurement (the local track contributed elsewhere before): the velocity
    // is unknown within walking speeds.
    f.x.segment<2>(2).setZero();
    f.p.block<2, 2>(2, 2) = Eigen::Matrix2d::Identity() * 2.25;
    f.p.block<2, 2>(0, 2).setZero();
    f.p.block<2, 2>(2, 0).setZero();
  }
  f.p.topLeftCorner<2, 2>() += m.offset_prior;
  f.p.block<2, 2>(0, 4) = -m.offset_prior;
  f.p.block<2, 2>(4, 0) = -m.offset_prior;
  f.p.block<2, 2>(4, 4) = m.offset_prior;
  Symmetrize(f.p);
  f.offsets.push_back(Offset{sensor_id, t, m.offset_prior});
  f.updates = 1;
  f.confirmed = f.updates >= options_.confirm_updates;
  const std::uint64_t id = f.id;
  ++counters_.fused_created;
  return tracks_.emplace(id, std::move(f)).first->second;
}

void FusedFilterEngine::AddFrame(const SensorPlacement& placement, const std::string& sensor_id,
                                 const daemon::TrackFrameData& frame) {
  const FusionOptions& o = options_;
  const UtcNs t = frame.scan_start_ns;
  if (t <= 0) {
    ++counters_.frames_invalid;
    return;
  }
  SensorState& ss = sensors_[sensor_id];
  const FrameAdmission admission =
      AdmitFrame(frame, o.max_out_of_order_s, ss.clock, have_newest_, newest_ns_);
  if (admission == FrameAdmission::kNewSession) DropSensorTracks(sensor_id, ss);
  if (!CountAdmission(admission, counters_)) return;
  // The placement with the error learnt of it taken off ("Sensor bias" in fusion.h).
  const SensorPlacement corrected = CorrectedPlacement(placement, ss.bias);

  // 1. The frame's tracks: world frame, and the new information of each.
  std::vector<std::uint32_t> rows;  // local tracks with a measurement to associate
  std::size_t accepted = 0;
  for (const daemon::TrackObservation& received : frame.tracks) {
    if (accepted >= o.max_tracks_per_frame) {
      ++counters_.observations_over_capacity;
      continue;
    }
    const double bias_m = AppliedBias(ss, received.kind);
    const daemon::TrackObservation obs = CentreCorrected(received, bias_m);
    if (!PlausibleObservation(o, obs)) {
      ++counters_.observations_invalid;
      continue;
    }
    const auto [it, inserted] = ss.tracks.try_emplace(obs.track_id);
    LocalTrack& lt = it->second;
    if (!inserted && lt.stamp() == t) {
      ++counters_.observations_invalid;  // the same id twice in one frame
      continue;
    }
    WorldTrack world = ToWorld(corrected, sensor_id, t, obs);
    if (!AllFinite(world.covariance) || !std::isfinite(world.x_m) || !std::isfinite(world.y_m) ||
        !std::isfinite(world.vx_mps) || !std::isfinite(world.vy_mps)) {
      ++counters_.observations_invalid;
      if (inserted) ss.tracks.erase(it);
      continue;
    }
    ++accepted;
    if (!inserted && lt.observation.kind != obs.kind) SubmitBiasSample(ss, lt, &placement);
    lt.observation = obs;
    lt.received = received;
    lt.applied_bias_m = bias_m;
    const Eigen::Vector2d p_raw(received.x_m, received.y_m);
    lt.jacobian = BiasJacobian(placement.world_from_sensor, p_raw, received.kind);
    lt.applied_world = placement.world_from_sensor * p_raw -
                       corrected.world_from_sensor * Eigen::Vector2d(obs.x_m, obs.y_m);
    lt.world = std::move(world);
    lt.usable = obs.state != daemon::TrackState::kTentative || o.use_tentative_sources;
    lt.measurement = Measure(corrected, sensor_id, lt, t);
    if (inserted && lt.usable && lt.measurement.valid) {
      ReturningSource(sensor_id, ss, obs.track_id, lt, t);
    }
    if (lt.usable) {
      ++counters_.observations;
      if (lt.measurement.valid) rows.push_back(obs.track_id);
    } else {
      ++counters_.observations_ignored;
    }
  }

  // 2. Global nearest neighbour between the frame's measurements and the fused tracks alive at t
  // (each fused track takes at most one measurement of a frame). A local track's own fused track
  // gets binding_bonus: the trackers' ids are right most of the time.
  struct Candidate {
    Track* track;
    Eigen::Vector2d position;  // predicted to t (cheap, for the distance pre-gate)
    bool predicted = false;    // x, p below are valid
    Vec x;
    Mat p;
    double late_s;  // the frame is this much older than the track's estimate
  };
  std::vector<Candidate> candidates;
  if (!rows.empty()) {
    for (auto& [id, f] : tracks_) {
      const double age = Seconds(t, f.stamp_ns);
      if (age > o.max_coast_s || -age > o.max_out_of_order_s || f.updates == 0) continue;
      const Eigen::Vector2d position = f.x.head<2>() + std::max(0.0, age) * f.x.segment<2>(2);
      candidates.push_back(Candidate{&f, position, false, Vec(), Mat(), std::max(0.0, -age)});
    }
  }
  Eigen::MatrixXd cost =
      Eigen::MatrixXd::Constant(static_cast<Eigen::Index>(rows.size()),
                                static_cast<Eigen::Index>(candidates.size()), kForbiddenCost);
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const LocalTrack& lt = ss.tracks.at(rows[i]);
    const Eigen::Vector2d z = lt.measurement.z.head<2>();
    for (std::size_t j = 0; j < candidates.size(); ++j) {
      Candidate& c = candidates[j];
      // The measurement moved forward for a late frame moves by less than a metre.
      if ((z - c.position).norm() > o.gate_max_distance_m + 1.0) continue;
      if (!c.predicted) {
        Predicted(*c.track, t, c.x, c.p);
        c.predicted = true;
      }
      const std::optional<double> pair_cost =
          Cost(*c.track, c.x, c.p, lt.measurement, sensor_id, c.late_s);
      if (!pair_cost) continue;
      const bool bound = lt.fused_id == c.track->id;
      cost(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) =
          *pair_cost - (bound ? o.binding_bonus : 0.0);
    }
  }
  const std::vector<int> assignment = rows.empty() ? std::vector<int>() : SolveAssignment(cost);

  // 3. Updates, re-bindings, misses, new fused tracks.
  std::vector<std::uint64_t> updated;
  std::vector<char> taken(candidates.size(), 0);
  for (const int j : assignment) {
    if (j >= 0) taken[static_cast<std::size_t>(j)] = 1;
  }
  // The bindings before this frame (a re-binding below may unbind a later row's source).
  std::vector<std::optional<std::uint64_t>> bound_before;
  for (const std::uint32_t tid : rows) bound_before.push_back(ss.tracks.at(tid).fused_id);
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const SourceKey key{sensor_id, rows[i]};
    LocalTrack& lt = ss.tracks.at(rows[i]);
    if (assignment[i] >= 0) {
      Track& f = *candidates[static_cast<std::size_t>(assignment[i])].track;
      if (lt.fused_id != f.id) {
        if (bound_before[i] && *bound_before[i] != f.id) {
          ++counters_.source_rebinds;
        } else {
          ++counters_.bindings;
          if (f.sources.empty() && !f.last_sensor.empty() && f.last_sensor != sensor_id) {
            ++counters_.handovers;  // picked up by another sensor while coasting
          }
        }
        Bind(f, key, lt);
      }
      lt.misses = 0;
      std::optional<Eigen::Vector2d> bias_sample;
      if (Update(f, lt.measurement, sensor_id, t, 1.0,
                 o.learn_sensor_bias ? &bias_sample : nullptr)) {
        lt.contributed = true;
        updated.push_back(f.id);
        if (bias_sample) {
          if (lt.bias_updates == 0) lt.bias_first_ns = t;
          lt.bias_j_sum += lt.jacobian;
          lt.bias_y_sum += lt.applied_world + *bias_sample;
          ++lt.bias_updates;
          if (Seconds(t, lt.bias_first_ns) >= o.sensor_bias_sample_s) {
            SubmitBiasSample(ss, lt, &placement);
          }
        }
      }
      continue;
    }
    if (lt.fused_id) {
      // Its fused track did not take it, and no other did. When the fused track had no other
      // measurement of this frame and the measurement is near, the person turned or stopped
      // faster than the motion model expects: the track's covariance is widened until it fits.
      if (const double widen =
              ManoeuvreWidening(candidates, taken, *lt.fused_id, lt.measurement, sensor_id);
          widen > 1.0) {
        Track& f = tracks_.at(*lt.fused_id);
        if (Update(f, lt.measurement, sensor_id, t, widen)) {
          ++counters_.manoeuvres;
          lt.misses = 0;
          updated.push_back(f.id);
          continue;
        }
      }
      // Otherwise the tracker may have swapped ids or jumped.
      ++counters_.source_strikes;
      if (++lt.misses >= o.drift_updates) {
        auto f = tracks_.find(*lt.fused_id);
        if (f != tracks_.end()) Unbind(f->second, key);
        lt.fused_id.reset();
        lt.hold_frames = 2 * o.drift_updates;
        ++counters_.sources_drifted;
      }
      continue;
    }
    // Unbound and unassociated: a person no fused track follows yet. After unbinding, wait a
    // few frames: the track it belongs to is often freed by its own swapped source.
    if (lt.hold_frames > 0) {
      --lt.hold_frames;
      continue;
    }
    if (tracks_.size() >= o.max_fused_tracks) {
      ++counters_.fused_over_capacity;
      continue;
    }
    Track& f = NewTrack(lt.measurement, sensor_id, t);
    Bind(f, key, lt);
    lt.contributed = true;
    updated.push_back(f.id);
  }

  // 4. Duplicates, then sources that left.
  std::sort(updated.begin(), updated.end());
  updated.erase(std::unique(updated.begin(), updated.end()), updated.end());
  for (const std::uint64_t id : updated) MergeCheck(id);
  ExpireSources(sensor_id, ss, t);
}

std::uint64_t FusedFilterEngine::MergeCheck(std::uint64_t f_id) {
  const FusionOptions& o = options_;
  auto fit = tracks_.find(f_id);
  if (fit == tracks_.end()) return f_id;
  Track& f = fit->second;
  const UtcNs t = f.stamp_ns;
  const std::vector<std::string> f_sensors = ActiveSensors(f);
  if (f_sensors.empty()) return f_id;
  const Eigen::Vector2d f_pos = f.x.head<2>(), f_vel = f.x.segment<2>(2);
  for (auto& [g_id, g] : tracks_) {
    if (g_id == f_id) continue;
    Track& younger = g_id > f_id ? g : f;
    const std::uint64_t older_id = std::min(g_id, f_id);
    auto reset = [&] {
      if (younger.merge_into == older_id) {
        younger.merge_into = 0;
        younger.merge_count = 0;
      }
    };
    const double dt = Seconds(t, g.stamp_ns);
    // A track no local track feeds any more (none of its sources was in its sensor's latest
    // frame), coasting while f is measured: its object's sources may have moved on to f
    // (merge_sourceless).
    const bool g_sourceless = o.merge_sourceless && g.updates > 0 && dt > o.coast_after_s &&
                              dt <= o.max_coast_s && ActiveSensors(g).empty();
    if (std::abs(dt) > o.coast_after_s && !g_sourceless) {
      reset();
      continue;
    }
    const Eigen::Vector2d g_pos = g.x.head<2>() + dt * g.x.segment<2>(2);
    if ((g_pos - f_pos).norm() > o.merge_max_distance_m ||
        (g.x.segment<2>(2) - f_vel).norm() > o.merge_max_speed_difference_mps) {
      reset();
      continue;
    }
    // Without sources in f's shadow: hidden by f's object, not left behind by its own.
    if (g_sourceless && InShadowOf(g, g_pos, f_pos)) {
      ++counters_.merge_sourceless_shadowed;
      reset();
      continue;
    }
    const std::vector<std::string> g_sensors = ActiveSensors(g);
    bool disjoint = !g_sensors.empty() || g_sourceless;
    for (const std::string& s : f_sensors) {
      if (std::find(g_sensors.begin(), g_sensors.end(), s) != g_sensors.end()) disjoint = false;
    }
    CvState gx = g.x.head<4>();
    CvCovariance gp = g.p.topLeftCorner<4, 4>();
    internal::Predict(dt, o.accel_psd, gx, gp);
    // Two sensors' centres of one body differ by what each sees of it: s^2 I on both sides
    // (not for a coasting track, whose covariance grew with its coasting).
    const double spread_m = g_sourceless ? 0.0 : o.merge_centre_spread_m;
    const Eigen::Matrix2d spread = spread_m * spread_m * Eigen::Matrix2d::Identity();
    const Eigen::Matrix2d fp = f.p.topLeftCorner<2, 2>(), gpp = gp.topLeftCorner<2, 2>();
    if (!disjoint ||
        !(Mahalanobis2(f_pos, fp + spread, gx.head<2>(), gpp + spread) <= o.gate_mahalanobis2)) {
      reset();
      continue;
    }
    if (spread_m > 0.0 &&
        !(Mahalanobis2(f_pos, fp, gx.head<2>(), gpp) <= o.gate_mahalanobis2)) {
      ++counters_.merge_checks_spread;
    }
    if (younger.merge_into == older_id) {
      ++younger.merge_count;
    } else {
      younger.merge_into = older_id;
      younger.merge_count = 1;
    }
    if (younger.merge_count >= o.merge_updates) {
      if (g_sourceless) ++counters_.fused_merged_sourceless;
      Merge(older_id, std::max(g_id, f_id), g_sourceless ? f_id : 0);
      return older_id;
    }
  }
  return f_id;
}

// The younger track's estimate and sources go into the older one. Their sensors were disjoint,
// so their estimates are independent: information-weighted sum of the two (x, y, vx, vy); the
// older track's offsets are kept with their covariance, the younger's others start from their
// priors.
void FusedFilterEngine::Merge(std::uint64_t older_id, std::uint64_t younger_id,
                              std::uint64_t estimate_of) {
  Track& older = tracks_.at(older_id);
  auto yit = tracks_.find(younger_id);
  Track& younger = yit->second;
  const UtcNs t = std::max(older.stamp_ns, younger.stamp_ns);
  Vec xo, xy;
  Mat po, py;
  Predicted(older, t, xo, po);
  Predicted(younger, t, xy, py);
  if (estimate_of != 0) {
    // The track without sources keeps none: its local tracks were not in their sensors' latest
    // frames (the trackers dropped them or moved them on).
    Track& stale = estimate_of == younger_id ? older : younger;
    const std::vector<SourceKey> keys = stale.sources;
    for (const SourceKey& k : keys) Unbind(stale, k);
  }
  if (estimate_of == younger_id) {
    // The younger (measured) track's estimate and offsets replace the older's.
    xo = xy;
    po = py;
    older.offsets = younger.offsets;
  }
  const Eigen::Matrix4d a = po.topLeftCorner<4, 4>(), b = py.topLeftCorner<4, 4>();
  const Eigen::LLT<Eigen::Matrix4d> lla(a), llb(b);
  if (estimate_of == 0 && lla.info() == Eigen::Success && llb.info() == Eigen::Success) {
    const Eigen::Matrix4d ia = lla.solve(Eigen::Matrix4d::Identity());
    const Eigen::Matrix4d ib = llb.solve(Eigen::Matrix4d::Identity());
    const Eigen::LLT<Eigen::Matrix4d> llm(ia + ib);
    if (llm.info() == Eigen::Success) {
      Eigen::Matrix4d pm = llm.solve(Eigen::Matrix4d::Identity());
      pm = (0.5 * (pm + pm.transpose())).eval();
      const Eigen::Vector4d xm = pm * (ia * xo.head<4>() + ib * xy.head<4>());
      if (AllFinite(xm) && AllFinite(pm)) {
        xo.head<4>() = xm;
        po.topLeftCorner<4, 4>() = pm;
        po.topRightCorner(4, po.cols() - 4).setZero();
        po.bottomLeftCorner(po.rows() - 4, 4).setZero();
      }
    }
  }
  older.x = std::move(xo);
  older.p = std::move(po);
  older.stamp_ns = t;
  for (const Offset& off : younger.offsets) {
    if (estimate_of != 0) break;  // the measured track's offsets only
    if (older.OffsetIndex(off.sensor_id) < 0) {
      const int k = AddOffset(options_, older, off.sensor_id, off.prior, off.last_ns);
      (void)k;
    }
  }
  const std::vector<SourceKey> moving = younger.sources;
  for (const SourceKey& k : moving) {
    LocalTrack* lt = Find(k);
    Unbind(younger, k);
    if (lt == nullptr) continue;
    bool keep_new = true;  // one source per sensor: keep the fresher one
    for (const SourceKey& ok : older.sources) {
      if (ok.sensor_id != k.sensor_id) continue;
      const LocalTrack* olt = Find(ok);
      if (olt != nullptr && olt->stamp() >= lt->stamp()) keep_new = false;
    }
    if (keep_new) Bind(older, k, *lt);
  }
  older.first_ns = std::min(older.first_ns, younger.first_ns);
  older.updates += younger.updates;
  older.confirmed = older.confirmed || younger.confirmed;
  older.merge_into = 0;
  older.merge_count = 0;
  const bool younger_confirmed = younger.confirmed;
  tracks_.erase(yit);
  for (auto& [id, tr] : tracks_) {
    if (tr.merge_into == younger_id) {
      tr.merge_into = 0;
      tr.merge_count = 0;
    }
  }
  ++counters_.fused_merged;
  if (younger_confirmed) RecordEnded(younger_id, t, FusedEndReason::kMerged, older_id);
}

void FusedFilterEngine::Tick(UtcNs now_ns) {
  for (auto& [sensor_id, ss] : sensors_) ExpireSources(sensor_id, ss, now_ns);
  const double offset_age_s =
      std::max(options_.source_timeout_s, 3.0 * options_.centre_correlation_s);
  for (auto it = tracks_.begin(); it != tracks_.end();) {
    Track& f = it->second;
    const double age = Seconds(now_ns, f.stamp_ns);
    const bool dead = age > options_.max_coast_s || (!f.confirmed && f.sources.empty());
    if (!dead) {
      ForgetOffsets(f, now_ns, offset_age_s);
      ++it;
      continue;
    }
    ++counters_.fused_deleted;
    // A confirmed track ends only by timing out (a tentative one is never reported).
    if (f.updates > 0 && f.confirmed) RecordEnded(it->first, now_ns, FusedEndReason::kTimedOut);
    auto next = std::next(it);
    DeleteTrack(it);
    it = next;
  }
  ForgetEnded();
}

std::vector<FusedTrack> FusedFilterEngine::Snapshot(UtcNs now_ns, bool include_tentative) const {
  std::vector<FusedTrack> out;
  for (const auto& [id, f] : tracks_) {
    if (f.updates == 0 || (!f.confirmed && !include_tentative)) continue;
    if (!options_.report_sourceless && f.sources.empty()) continue;  // no tracker claims it
    std::optional<FusedTrack> t =
        PredictedFusedTrack(id, f.confirmed, f.first_ns, f.stamp_ns, f.updates, f.x.head<4>(),
                            f.p.topLeftCorner<4, 4>(), options_, now_ns);
    if (!t) continue;
    for (const SourceKey& k : f.sources) {
      const LocalTrack* lt = Find(k);
      t->sources.push_back(FusedSource{k.sensor_id, k.track_id, lt != nullptr ? lt->stamp() : 0});
    }
    out.push_back(std::move(*t));
  }
  return out;
}

std::vector<WorldTrack> FusedFilterEngine::WorldTracks(UtcNs now_ns) const {
  return RecentWorldTracks(sensors_, options_.source_timeout_s, now_ns);
}

}  // namespace

std::unique_ptr<Engine> MakeFusedFilterEngine(const FusionOptions& options) {
  return std::make_unique<FusedFilterEngine>(options);
}

}  // namespace lrfnet::fusion::internal
