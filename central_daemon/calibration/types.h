#pragma once
// Value types shared by the stages of the calibration (pure library, namespace lrfnet::calib).
//
// Poses follow common/geometry.h: `a_from_b` maps coordinates in frame b to frame a. A sensor's
// calibrated pose is world_from_sensor; a pairwise estimate between sensors r and s is s_from_r
// (Quenzel et al. eq. 5: R * t_p + t = t_q maps r's observation t_p onto s's observation t_q, so
// (R, t) = s_from_r). Times on the common grid are seconds since AlignedTracks::t0_ns.
//
// Stages (equation numbers of Quenzel et al., papers/000):
//   input (CalibrationInput) → alignment + RTS smoothing (AlignedTracks)
//   → per pair: dynamic intervals (III-C) → MSAC hypotheses (eq. 5) → verification (eqs. 6-8)
//     → PairEstimate → point-to-line ICP on the backgrounds
//   → L1 rotation averaging (Algorithm 1) + least-squares translations → joint refinement
//   → CalibrationResult (calibration.yaml, report).

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "central_daemon/ingest/sensor_data.h"
#include "common/geometry.h"
#include "common/time.h"

namespace lrfnet::calib {

using common::Pose2;
using daemon::BackgroundScan;
using daemon::ClockSync;
using daemon::MeasurementKind;
using daemon::SensorDescription;
using daemon::TrackFrameData;
using daemon::TrackObservation;

// ---------------------------------------------------------------------------------------------
// Input: what the daemon holds per sensor (from its TrackStore, a recording or a UDP capture).

struct SensorRecording {
  std::string id;
  std::optional<SensorDescription> description;  // SensorInfo, when received
  ClockSync clock_sync = ClockSync::kUnknown;      // latest Health, when received
  std::vector<TrackFrameData> frames;             // in scan order (scan_start_ns)
  std::optional<BackgroundScan> background;       // the newest complete snapshot
};

struct CalibrationInput {
  std::vector<SensorRecording> sensors;  // any order; ids unique
};

// ---------------------------------------------------------------------------------------------
// Aligned tracks: every sensor's smoothed tracks sampled on one common UTC time grid.

// One smoothed track state on the grid, with what the tracker measured it with and what the
// measurement model (central_daemon/ingest/measurement_model.h) says is left of its bias. The body
// centre it implies, for a correction d = (d_major, d_minor) of the prior body size shared by all
// samples of that prior (AlignedTracks::size_prior_sigma_m), is
//
//   centre = position_m + (bias_m + bias_per_major * d_major + bias_per_minor * d_minor) u,
//
// u the unit vector from the sensor to position_m; CentreCovariance says how well it is known.
struct TrackSample {
  Eigen::Vector2d position_m = Eigen::Vector2d::Zero();  // sensor frame
  Eigen::Vector2d velocity_mps = Eigen::Vector2d::Zero();
  Eigen::Matrix2d position_cov_m2 = Eigen::Matrix2d::Identity();  // symmetric positive definite
  // The measurement kind of the tracker's states around this time (the one with the most weight)
  // and their mean point count (0: coasting only).
  MeasurementKind kind = MeasurementKind::kUnspecified;
  std::uint16_t points = 0;
  // The model, mixed over the kinds of the states around this time (a track whose estimator flips
  // between two kinds from scan to scan is smoothed into a mixture of both biases).
  float bias_m = 0.0f;          // expected offset towards the sensor at the prior size
  float bias_per_major = 0.0f;  // d bias / d d_major (unitless)
  float bias_per_minor = 0.0f;  // d bias / d d_minor
  float bias_sigma_m = 0.0f;    // radial, 1 sigma, not shared with other samples
  float model_sigma_m = 0.0f;   // isotropic, 1 sigma, beyond position_cov_m2
  // Radial, 1 sigma: the part of the bias shared by all samples of this sensor (CentreBias::
  // shared_sigma_m), not in CentreCovariance: the joint refinement and the pairwise covariance
  // carry it as one unknown per sensor (refine.h, pairwise.h "sensor bias").
  float shared_bias_sigma_m = 0.0f;
};

// Unit vector from the sensor to p (zero at the sensor itself).
inline Eigen::Vector2d LineOfSight(const Eigen::Vector2d& p) {
  const double n = p.norm();
  return n > 1e-3 ? Eigen::Vector2d(p / n) : Eigen::Vector2d::Zero();
}

// The body centre of a sample (sensor frame) for the size correction d (see TrackSample).
inline Eigen::Vector2d CentreOf(const TrackSample& x,
                                const Eigen::Vector2d& size_correction_m = Eigen::Vector2d::Zero()) {
  const double b = static_cast<double>(x.bias_m) +
                   static_cast<double>(x.bias_per_major) * size_correction_m.x() +
                   static_cast<double>(x.bias_per_minor) * size_correction_m.y();
  return x.position_m + b * LineOfSight(x.position_m);
}

// The covariance of CentreOf(x) for a known size correction: the track's own covariance, the
// model's isotropic sigma and its radial sigma.
inline Eigen::Matrix2d CentreCovariance(const TrackSample& x) {
  const Eigen::Vector2d u = LineOfSight(x.position_m);
  const double m = static_cast<double>(x.model_sigma_m), b = static_cast<double>(x.bias_sigma_m);
  Eigen::Matrix2d c = 0.5 * (x.position_cov_m2 + x.position_cov_m2.transpose());
  c.diagonal().array() += m * m;
  c += (b * b) * (u * u.transpose());
  return c;
}

// d CentreOf / d (d_major, d_minor): 2x2, columns per correction.
inline Eigen::Matrix2d CentrePerSizeCorrection(const TrackSample& x) {
  const Eigen::Vector2d u = LineOfSight(x.position_m);
  Eigen::Matrix2d j;
  j.col(0) = static_cast<double>(x.bias_per_major) * u;
  j.col(1) = static_cast<double>(x.bias_per_minor) * u;
  return j;
}

// One track of one sensor, present on grid steps [first_step, first_step + samples.size()).
struct GridTrack {
  std::uint32_t track_id = 0;        // the tracker's id (unique within the sensor's session)
  std::uint64_t session_id = 0;      // the tracker's session
  MeasurementKind kind = MeasurementKind::kUnspecified;  // the kind most of its states report
  std::size_t first_step = 0;
  std::vector<TrackSample> samples;  // one per grid step, contiguous

  std::size_t end_step() const { return first_step + samples.size(); }
  bool Covers(std::size_t step) const { return step >= first_step && step < end_step(); }
  const TrackSample& At(std::size_t step) const { return samples[step - first_step]; }
};

struct SensorTracks {
  std::string id;
  std::optional<SensorDescription> description;
  std::optional<BackgroundScan> background;
  bool clock_suspect = false;          // clock sync reported bad (see AlignOptions)
  std::vector<GridTrack> tracks;       // ordered by first_step
  std::size_t frames_used = 0;         // input frames that contributed
  std::size_t observations_used = 0;   // input track observations that contributed
};

struct AlignedTracks {
  common::UtcNs t0_ns = 0;  // UTC of grid step 0
  double step_s = 0.05;     // grid spacing
  std::size_t steps = 0;
  // One standard deviation of each component of the shared size correction of the samples'
  // measurement model (TrackSample; MeasurementModelOptions::prior_size_sigma_m).
  double size_prior_sigma_m = 0.05;
  std::vector<SensorTracks> sensors;  // same order as CalibrationInput::sensors

  double TimeOf(std::size_t step) const { return static_cast<double>(step) * step_s; }
};

// ---------------------------------------------------------------------------------------------
// Pairwise estimates (one per unordered sensor pair that has simultaneous tracks).

struct PairEstimate {
  std::size_t r = 0;  // sensor indices into AlignedTracks::sensors, r < s
  std::size_t s = 0;
  bool accepted = false;        // a convincing hypothesis was found (an edge of the pose graph)
  std::string reason;           // why not accepted ("" when accepted)
  // Accepted, but its covariance leaves the pose too uncertain to trust alone (pairwise.h): a
  // candidate, used where the rest of the graph confirms it or where nothing else places a sensor
  // (which is then flagged). weak_reason says why.
  bool weak = false;
  std::string weak_reason;
  Pose2 s_from_r;               // the estimate g_rs (valid when accepted)
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Identity();  // of (x, y, yaw) of s_from_r
  std::size_t intervals = 0;     // dynamic intervals with tracks on both sides
  std::size_t hypotheses = 0;    // MSAC hypotheses generated (eq. 5)
  double best_error = 0.0;       // E of the best hypothesis (eq. 8)
  double second_error = 0.0;     // E of the best clearly different hypothesis (or +inf)
  std::size_t matches = 0;       // associated simultaneous observations used in the refit (N)
  double rms_m = 0.0;            // residual of the refit over the matches
  double mean_residual_m = 0.0;  // d of Schenk's weight N/d
  // Negative evidence (pairwise.h), the weaker of the two directions: the fraction of one
  // sensor's observations in the other's coverage that were matched, and what the other's
  // detection probability at those ranges leads to expect.
  double match_fraction = 0.0;
  double expected_match_fraction = 0.0;
  bool icp_applied = false;      // the background ICP changed the estimate
  // When applied: the ICP's own pose and covariance (s_from_r and covariance are then the
  // information-weighted fusion of it with the tracks' estimate).
  Pose2 icp_s_from_r;
  Eigen::Matrix3d icp_covariance = Eigen::Matrix3d::Zero();
  double icp_score_before = 0.0; // consistency of the backgrounds before/after ICP (see icp.h)
  double icp_score_after = 0.0;
};

// ---------------------------------------------------------------------------------------------
// Global result.

// A sensor's shared radial bias from the joint refinement (refine.h "Sensor bias"): how far its
// people's centres lie towards it, along its line of sight, beyond the measurement model.
struct RadialBiasEstimate {
  double bias_m = 0.0;     // 0 where held at its prior
  double sigma_m = 0.0;    // after the refinement; a held one's prior
  bool estimated = false;  // false: the data do not observe it, held at its prior N(0, sigma^2)
};

struct SensorPose {
  std::string id;
  bool calibrated = false;       // false: not placed (not connected to the reference, or refused)
  // What a person should know about this sensor's pose ("" when nothing): it hangs on weak pairs
  // only (calibrated, with their large covariance), or it was refused because placements that
  // differ explain the data equally well (calibrated false).
  std::string flag;
  Pose2 world_from_sensor;       // the reference sensor is the identity
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // (x, y, yaw), metres and radians
  // Only where the joint refinement was applied and placed this sensor.
  std::optional<RadialBiasEstimate> radial_bias;
  // The mount check (common/mount_check.h) found this sensor's tracks leg-sized while its tracker
  // is configured for upper-body height (shape.mount: torso); `flag` says what to do.
  bool mount_looks_like_legs = false;
};

struct EdgeReport {
  std::string r, s;               // sensor ids
  bool used = false;              // used by the global solution
  std::string status;             // "used", or why not (no hypothesis, rotation outlier, ...)
  std::size_t matches = 0;
  double rms_m = 0.0;
  double rotation_residual_deg = 0.0;     // |yaw(s_from_r measured) - yaw(from poses)|
  double translation_residual_m = 0.0;    // |t(s_from_r measured) - t(from poses)|
  double track_residual_rms_m = 0.0;      // matched observations under the final poses
  bool icp_applied = false;
};

// One placement tried where the pose graph's cycles could not tell which pair is wrong
// (pipeline.h "Hypotheses").
struct HypothesisReport {
  std::string description;  // which pair it leaves out ("all pairs" for none)
  double cost = 0.0;        // robust cost over all raw observations (placement.h), lower is better
  bool chosen = false;
};

struct StageTime {
  std::string stage;
  double seconds = 0.0;
};

struct CalibrationResult {
  std::string method;     // "quenzel", "schenk", "spectral"
  std::string reference;  // the sensor at the origin
  std::vector<SensorPose> sensors;  // same order as the input
  std::vector<EdgeReport> edges;
  std::vector<StageTime> timings;
  // Joint refinement (Quenzel method only).
  bool refined = false;
  double refine_cost_before = 0.0;  // robust cost over all associated observations
  double refine_cost_after = 0.0;
  std::size_t refine_observations = 0;
  double track_residual_rms_m = 0.0;  // all matched observations under the final poses
  // The shared correction of the measurement model's prior body size (types.h TrackSample) and
  // whether each component was estimated (else not observable apart from the layout's scale: its
  // prior's uncertainty is in the covariances).
  Eigen::Vector2d size_correction_m = Eigen::Vector2d::Zero();
  std::array<bool, 2> size_estimated{};
  std::array<double, 2> size_scale_correlation{};  // refine.h JointRefineResult
  std::array<double, 2> size_data_sigma_m{};
  // Hypotheses tested (empty when the cycles decided) and, when they did not separate, what the
  // data cannot decide and what walk would ("" otherwise).
  std::vector<HypothesisReport> hypotheses;
  std::string ambiguity;
  // When the layout's scale cannot be told apart from the people's size (a size component held at
  // its prior because it correlates with the scale beyond JointRefineOptions::
  // max_size_scale_correlation): what that means for the poses and what data would fix it ("" when
  // the scale is observable, or without the joint refinement). The covariances carry the size
  // prior's uncertainty either way.
  std::string scale_note;
  std::vector<std::string> warnings;
};

}  // namespace lrfnet::calib
