#pragma once
// Pairwise calibration of two sensors from simultaneous tracks (Quenzel et al., section III-D).
//
// Every sample is taken as the body centre its measurement model implies (TrackSample, CentreOf:
// the tracker's point moved out along the line of sight by what is left of its bias; the shared
// correction of the prior body size is 0 except in the refit, which estimates it with its prior).
// For a sensor pair (r, s):
//   1. dynamic intervals (intervals.h, III-C);
//   2. per pair of simultaneous tracks (p of r, q of s), over the union of the consecutive
//      intervals in which both are visible: an MSAC hypothesis of eq. 5 (random 2-point minimal
//      samples, closed-form rigid transform, truncated-quadratic score) refined by least squares
//      on its inliers;
//   3. near-identical hypotheses are merged and the best-supported ones are verified over all
//      grid steps of the pair with the Mahalanobis error of eqs. 6-8 (nearest-neighbour
//      re-association per step); the lowest E wins;
//   4. the winner is refitted by weighted least squares over every associated simultaneous
//      observation of the pair (re-associated until the association stops changing), with the
//      shared size correction of the measurement model and its prior;
//   5. the decision, by information rather than counts: a pair is rejected when its residual is
//      too large, when a clearly different hypothesis explains a comparable share of the data by
//      associations of its own (ambiguous), or when, under the estimate, the people one sensor
//      sees where the other demonstrably sees people are matched far less often than the other
//      sensor detects people at that range (inconsistent); it is weak (a candidate: usable where
//      the rest of the graph confirms it, or for a sensor nothing else places, flagged) when its
//      honest covariance (below) leaves the yaw or the translation too uncertain; else strong.
//
// Honest covariance of the refit (x, y, yaw of s_from_r): the normal equations' inverse times
// max(1, residual variance of unit weight) (the model's sigmas are a floor, never shrunk by a good
// fit) times covariance_correlation_steps (smoothed samples are correlated in time), marginal over
// the size correction (whose prior uncertainty is thus included), plus a systematic floor: each
// matched track pair (one person seen by both sensors for a while) carries an error of its own
// that does not average out over its samples (its size differs from the model's, a view-dependent
// offset), modelled as a constant 2D offset per track pair (segment_sigma_*) and propagated
// through the fit. One short straight walk therefore leaves the yaw uncertain however many
// samples it has, and an L-shaped path or several people fix it.
//
// Sensor bias: what is left of each sensor's measurement bias after the model, shared by all its
// samples (TrackSample::shared_bias_sigma_m, radial), is carried as a consider parameter at its
// prior (refine.h "Sensor bias"; Bierman 1977 ch. VII): the fit's response to one standard
// deviation of r's and of s's, S = -H^-1 H_x_b, adds S S^T to the covariance. It does not average
// out over the pair's samples: two sensors facing each other across a small overlap (a doorway)
// see one person's centre shifted in opposite directions, which is a translation along the line
// between them.
//
// Frames: s_from_r maps r's coordinates into s's frame (eq. 5: R * t_p + t ≈ t_q). Metres and
// radians. Track identities are never compared across sensors: one person may carry unrelated
// ids in r and s, and a track may split or merge.
//
// Pure and deterministic: the MSAC samples come from a counter-based generator seeded by
// PairwiseOptions::seed and the sensor and track indices, so results do not depend on the
// order in which pairs are processed. Thread-safe for concurrent calls on const inputs.
//
// Input samples with a non-finite or absurd position (beyond 1e5 m), or a covariance that is not
// finite, positive definite and below 1e8 m^2, or a non-finite model, are ignored (counted in
// PairDiagnostics::unusable_samples).

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "central_daemon/calibration/intervals.h"
#include "central_daemon/calibration/types.h"

namespace lrfnet::calib {

struct PairwiseOptions {
  // A track pair yields a hypothesis only when both tracks are visible together for at least
  // intervals.min_steps grid steps.
  IntervalOptions intervals;

  // --- MSAC hypotheses (eq. 5) ---
  // Minimal samples drawn per track pair.
  std::size_t msac_iterations = 48;
  // The MSAC score of a track pair is evaluated on at most this many evenly spaced steps (the
  // least-squares refinement then uses every common step).
  std::size_t msac_max_points = 60;
  // Truncation of eq. 5 (metres). The paper truncates at r_max, the sensor range (20 m); that
  // bounds nothing within one track pair's span, where every residual of even a wrong pairing
  // is below the range. The truncation that makes eq. 5 robust is MSAC's inlier threshold: larger
  // than the view-dependent CoM difference between two sensors (up to ~0.4 m) plus noise.
  double msac_threshold_m = 0.5;
  // A minimal sample is two steps whose r positions are at least this far apart; shorter
  // baselines give a poorly conditioned rotation.
  double min_sample_separation_m = 0.5;
  // A track pair is skipped when r's track spans less than this in their common span (square root
  // of the largest eigenvalue of the positions' scatter, i.e. the standard deviation along the
  // main direction of motion, metres): a standing person carries no rotation information. A
  // 1 m straight walk has 0.29 m.
  double min_track_spread_m = 0.25;
  // A hypothesis is kept when at least this fraction of the common steps (and at least
  // min_hypothesis_inliers steps) are inliers of the refined transform.
  double min_hypothesis_inlier_fraction = 0.6;
  std::size_t min_hypothesis_inliers = 10;

  // --- merging and capping before verification ---
  // Two hypotheses are merged when their yaws differ by less than cluster_yaw_deg and they map
  // the centroid of r's observations within cluster_distance_m of each other (distances are
  // measured where the data are, so they do not grow with the sensors' lever arm).
  double cluster_yaw_deg = 2.0;
  double cluster_distance_m = 0.25;
  // At most this many merged hypotheses are verified, those with the most inlier steps (summed
  // over the merged members, so hypotheses supported by several or long track pairs come first).
  std::size_t max_verified_hypotheses = 40;

  // --- verification (eqs. 6-8) ---
  // Isotropic standard deviation (metres) added to the summed covariance of eq. 6, beyond each
  // sample's own (CentreCovariance) and the prior size's: the centres of one person seen from two
  // sides still differ by what the model misses, and the truncation at verify_gate should not
  // count those as misses.
  double model_sigma_m = 0.05;
  // Truncation of eqs. 7-8, applied per observation to the Mahalanobis distance d_S (unitless).
  // The paper sums d_S over an interval and truncates the sum at r_max (metres); that mixes
  // units and lets long intervals dominate. Truncating each observation's d_S at a gate keeps the
  // role r_max has in the paper (an r track that s does not see, or sees elsewhere, costs a
  // bounded amount, whatever the hypothesis) with a unit-consistent bound: E is then an MSAC
  // score in sigma units over every r observation of the pair.
  double verify_gate = 3.0;
  // Verify on every verify_stride-th grid step of the pair (1 = all steps).
  std::size_t verify_stride = 1;
  // Hypotheses at least this different from the best (yaw, or distance at r's data centroid)
  // compete with it for second_error.
  double distinct_yaw_deg = 10.0;
  double distinct_distance_m = 1.0;

  // --- least-squares refit over all associated observations ---
  // Euclidean gate (metres) of the nearest-neighbour association (AssociatePair) of the refit.
  double refit_gate_m = 0.7;
  // Re-association rounds; the refit stops earlier when the association no longer changes.
  std::size_t refit_rounds = 6;
  // Huber threshold on the Mahalanobis residual of a match: a swapped association of two people
  // walking close together must not pull the estimate.
  double huber_k = 2.0;
  // Estimate the shared correction of the prior body size (TrackSample) with the pose, under its
  // prior (AlignedTracks::size_prior_sigma_m): the prior decides where the geometry cannot tell a
  // size from a translation (people always on the line between the sensors), and its uncertainty
  // is then in the pose covariance. false: the correction is held at 0 and its uncertainty is
  // still carried.
  bool estimate_size_correction = true;
  // Smoothed tracks on a 0.05 s grid are strongly correlated in time; the covariance from the
  // normal equations is inflated as if only every covariance_correlation_steps-th match were
  // independent.
  double covariance_correlation_steps = 20.0;
  // The systematic floor of the covariance (see the header comment): the constant 2D offset of
  // each matched track pair has one standard deviation per side of segment_sigma_m plus
  // segment_sigma_per_m times that side's mean range (far away a person is a few beams, and a
  // track's start and end there are often a person half hidden), both sides in quadrature.
  double segment_sigma_m = 0.015;
  double segment_sigma_per_m = 0.003;
  // Carry both sensors' shared radial bias in the covariance (see "Sensor bias" above).
  bool sensor_bias = true;

  // --- decision ---
  // Fewer associated observations than this: rejected (too little to judge).
  std::size_t min_matches = 20;
  double max_rms_m = 0.35;  // Euclidean residual of the refit
  // Strong when the honest covariance leaves at most these standard deviations (yaw; the larger
  // axis of the translation's ellipse); else weak.
  double max_yaw_sigma_deg = 1.0;
  double max_translation_sigma_m = 0.15;
  // Ambiguity: of the clearly different hypotheses (distinct_*) with the lowest E, none may draw
  // more than this fraction of the refitted estimate's evidence from associations of its own.
  // Evidence of a hypothesis = sum over r observations of (verify_gate - d_S) where d_S < gate;
  // "of its own" = where its nearest s observation differs from the estimate's. A hypothesis a
  // few degrees off the right one re-uses the right associations and is no alternative.
  double max_ambiguity_ratio = 0.5;
  // Negative evidence, both ways: the observations of one sensor that the estimate maps into the
  // area where the other ever saw a track must be matched at least min_match_fraction_ratio times
  // as often as the other sensor detects people at that range. EstimateAllPairs measures each
  // sensor's detection probability per range band from its pairs (the best of its partners:
  // a wrong pair only lowers its own); where no pair measured a band, and in EstimatePair,
  // default_detection_probability. A correct estimate matches about what the sensor detects; a
  // coincidental alignment of independent motions matches only by chance (0.13-0.28 on the
  // simulated scenarios). This is the check that rejects pairs without a true overlap.
  double min_match_fraction_ratio = 0.5;
  double default_detection_probability = 0.7;
  double coverage_cell_m = 0.5;  // cell size of a sensor's coverage map for that check

  std::uint64_t seed = 1;
};

// nullopt when valid, else the reason naming the field. The functions below take valid options
// (checked; they abort otherwise).
std::optional<std::string> Validate(const PairwiseOptions& options);

// Cells (coverage_cell_m, dilated by one) where a sensor ever had a track: the area in which it
// demonstrably sees people (its own frame). Memory is bounded whatever the data (coarser cells
// for a huge extent).
class Coverage {
 public:
  Coverage(const SensorTracks& sensor, double cell_m);
  bool Covered(const Eigen::Vector2d& p) const;

 private:
  double cell_m_;
  Eigen::Vector2d origin_ = Eigen::Vector2d::Zero();
  long nx_ = 0, ny_ = 0;
  std::vector<std::uint8_t> cells_;
};

// Range bands (metres from the detecting sensor) of the detection probability: [0, 5), [5, 10),
// [10, 15), [15, 20), [20, 30), [30, 50), [50, inf).
inline constexpr std::size_t kRangeBands = 7;
std::size_t RangeBandOf(double range_m);

// One direction of the negative-evidence check: observations of one sensor mapped into the
// coverage of the other ("visible"), and how many of them the other matched, per range band of
// the other sensor.
struct VisibilityCounts {
  std::array<std::size_t, kRangeBands> visible{};
  std::array<std::size_t, kRangeBands> matched{};
};

// Figures behind a PairEstimate's decision, for reports and tuning.
struct PairDiagnostics {
  std::size_t unusable_samples = 0;      // samples ignored (non-finite, bad covariance)
  std::size_t degenerate_pairs = 0;      // (interval, p, q) skipped for too little motion
  std::size_t clusters = 0;              // hypotheses after merging
  std::size_t verified = 0;              // hypotheses verified
  std::size_t r_observations = 0;        // r observations on verified steps
  double best_gain = 0.0;                // evidence of the estimate (see max_ambiguity_ratio)
  double second_gain = 0.0;              // largest evidence of a competitor's own associations
  Pose2 best_hypothesis;                 // s_from_r of the best hypothesis before the refit
  std::optional<Pose2> second_s_from_r;  // the best clearly different one, if any
  double match_spread_m = 0.0;           // largest standard deviation of the matched r positions
  Eigen::Vector2d size_correction_m = Eigen::Vector2d::Zero();  // of the refit (see RigidFit)
  std::size_t segments = 0;                                     // matched track pairs
  VisibilityCounts r_in_s, s_in_r;                              // see min_match_fraction_ratio
};

// The estimate for one pair (r != s; EstimateAllPairs uses r < s). Every field of PairEstimate
// except the ICP ones is filled (PairEstimate::intervals counts every dynamic interval of the
// pair, whatever its length); when accepted is false, reason says why and s_from_r holds the
// best hypothesis found (if any) for inspection only. The negative evidence is judged against
// default_detection_probability.
PairEstimate EstimatePair(const AlignedTracks& aligned, std::size_t r, std::size_t s,
                          const PairwiseOptions& options, PairDiagnostics* diagnostics = nullptr);

// All pairs r < s with a pair of tracks visible together for at least intervals.min_steps
// (others are not listed), ordered by (r, s); the negative evidence judged against each sensor's
// measured detection probability (see min_match_fraction_ratio).
std::vector<PairEstimate> EstimateAllPairs(const AlignedTracks& aligned,
                                           const PairwiseOptions& options);

// Simultaneous observations of the pair associated under s_from_r: on every grid step where both
// sensors have tracks, r's positions mapped into s are paired with s's positions by increasing
// Euclidean distance, one-to-one, up to gate_m. Ordered by step, then by track_r.
struct Match {
  std::size_t step;
  std::size_t track_r, track_s;  // indices into SensorTracks::tracks
};
std::vector<Match> AssociatePair(const AlignedTracks& aligned, std::size_t r, std::size_t s,
                                 const Pose2& s_from_r, double gate_m);

struct RigidFit {
  bool ok = false;  // false: fewer than 3 usable matches or no rotation information
  Pose2 s_from_r;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Identity();  // (x, y, yaw); honest (see above)
  Eigen::Matrix3d covariance_systematic = Eigen::Matrix3d::Zero();  // its per-track-pair part
  // The part of covariance_systematic from the sensors' shared radial biases (options.sensor_bias;
  // zero without): a constant of the sensors, which a comparison with an earlier fit of the same
  // sensors cancels (monitoring/track_check.h).
  Eigen::Matrix3d covariance_sensor_bias = Eigen::Matrix3d::Zero();
  double rms_m = 0.0;            // Euclidean residual RMS over the matches
  double mean_residual_m = 0.0;  // mean Euclidean residual
  double variance_factor = 0.0;  // residual variance of unit weight (before the floor at 1)
  Eigen::Vector2d size_correction_m = Eigen::Vector2d::Zero();  // (d_major, d_minor)
  std::size_t segments = 0;                                     // matched track pairs
};

// Weighted least squares over matches (Gauss-Newton on eq. 5 without truncation, on the samples'
// body centres, each residual weighted by the inverse of R*C_p*R^T + C_q (CentreCovariance), Huber
// loss with huber_k, the size correction with its prior when estimate_size_correction), started
// from the closed-form weighted 2D Procrustes solution. The covariance is the honest one of the
// header comment.
RigidFit FitMatches(const AlignedTracks& aligned, std::size_t r, std::size_t s,
                    const std::vector<Match>& matches, const PairwiseOptions& options);

}  // namespace lrfnet::calib
