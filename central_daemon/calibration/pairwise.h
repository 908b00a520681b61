#pragma once
// Pairwise calibration of two sensors from simultaneous tracks (Quenzel et al., section III-D).
//
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
//      view-dependent offsets of CoM and ellipse centres (estimate_view_offset);
//   5. the pair is accepted only with enough, spread-out matches, a small residual, matches
//      wherever s demonstrably sees people, and no clearly different hypothesis that explains a
//      comparable share of the data by associations of its own.
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
// finite, positive definite and below 1e8 m^2, are ignored (counted in
// PairDiagnostics::unusable_samples).

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
  // Isotropic standard deviation (metres) added to the summed covariance of eq. 6. The bare
  // track covariances (a few cm) describe the filter's noise, not that r and s see different
  // sides of a person: their CoMs differ by up to ~0.4 m, which would otherwise be >10 sigma.
  double model_sigma_m = 0.2;
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
  // Huber threshold on the Mahalanobis residual of a match (with model_sigma_m): a swapped
  // association of two people walking close together must not pull the estimate.
  double huber_k = 2.0;
  // Estimate, with the pose, the view offsets of the tracks: the CoM of the side of a person a
  // sensor sees lies nearer that sensor than the person's centre (pi/4 of the radius for a round
  // body: ~0.15 m for a person, ~0.2 m for a 0.25 m cylinder), so two facing sensors see one
  // person ~0.3-0.4 m apart along their baseline; an ellipse of fixed size (a = 0.25 m,
  // b = 0.15 m) fitted to a body of another shape is displaced along the line of sight too (by
  // ~0.13 m towards the sensor for a 0.25 m cylinder, ~0 for a person). Left unmodelled, such
  // offsets go straight into the translation. The refit models each observation as
  // centre - b * (unit vector from its sensor), with one b per measurement kind
  // (GridTrack::kind: kCenterOfMass, kEllipse; kUnspecified tracks are taken as unbiased) and a
  // Gaussian prior per kind: b is well observed when people are seen from varied directions and
  // only weakly (then the prior decides) when they stay on the line between the sensors.
  bool estimate_view_offset = true;
  double com_view_offset_prior_m = 0.15;
  double com_view_offset_prior_sigma_m = 0.05;
  double ellipse_view_offset_prior_m = 0.0;
  double ellipse_view_offset_prior_sigma_m = 0.1;
  // Smoothed tracks on a 0.05 s grid are strongly correlated in time; the covariance from the
  // normal equations is inflated as if only every covariance_correlation_steps-th match were
  // independent.
  double covariance_correlation_steps = 20.0;

  // --- decision ---
  std::size_t min_matches = 100;  // associated observations (5 s of one person at 0.05 s)
  double max_rms_m = 0.35;        // Euclidean residual of the refit
  // Matched r positions must span at least this much (square root of the largest eigenvalue of
  // their scatter, metres).
  double min_match_spread_m = 0.5;
  // Ambiguity: of the clearly different hypotheses (distinct_*) with the lowest E, none may draw
  // more than this fraction of the refitted estimate's evidence from associations of its own.
  // Evidence of a hypothesis = sum over r observations of (verify_gate - d_S) where d_S < gate;
  // "of its own" = where its nearest s observation differs from the estimate's. A hypothesis a
  // few degrees off the right one re-uses the right associations and is no alternative.
  double max_ambiguity_ratio = 0.5;
  // Of the r observations that the estimate maps into the area where s ever saw a track, at
  // least this fraction must be matched by a track of s at that time. A correct estimate
  // matches most of them (0.47-1.0 on the simulated scenarios; less where people occlude each
  // other or at the edge of s's view); a coincidental alignment of independent motions matches
  // only by chance (0.13-0.28). This is the check that rejects pairs without a true overlap.
  double min_visible_match_fraction = 0.35;
  double coverage_cell_m = 0.5;  // cell size of s's coverage map for that check

  std::uint64_t seed = 1;
};

// nullopt when valid, else the reason naming the field. The functions below take valid options
// (checked; they abort otherwise).
std::optional<std::string> Validate(const PairwiseOptions& options);

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
  double match_spread_m = 0.0;
  double com_view_offset_m = 0.0;  // of the refit (see RigidFit)
  double ellipse_view_offset_m = 0.0;
  std::size_t visible_observations = 0;  // see PairwiseOptions::min_visible_match_fraction
  double visible_match_fraction = 0.0;
};

// The estimate for one pair (r != s; EstimateAllPairs uses r < s). Every field of PairEstimate
// except the ICP ones is filled (PairEstimate::intervals counts every dynamic interval of the
// pair, whatever its length); when accepted is false, reason says why and s_from_r holds the
// best hypothesis found (if any) for inspection only.
PairEstimate EstimatePair(const AlignedTracks& aligned, std::size_t r, std::size_t s,
                          const PairwiseOptions& options, PairDiagnostics* diagnostics = nullptr);

// All pairs r < s with a pair of tracks visible together for at least intervals.min_steps
// (others are not listed), ordered by (r, s).
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
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Identity();  // (x, y, yaw); see options
  double rms_m = 0.0;                  // Euclidean residual RMS over the matches
  double mean_residual_m = 0.0;        // mean Euclidean residual
  double com_view_offset_m = 0.0;      // see PairwiseOptions::estimate_view_offset
  double ellipse_view_offset_m = 0.0;  // (an offset without observations of its kind: its prior)
};

// Weighted least squares over matches (Gauss-Newton on eq. 5 without truncation, each residual
// weighted by the inverse of R*Sigma_p*R^T + Sigma_q + model_sigma_m^2*I, Huber loss with
// huber_k, and the view offset when estimate_view_offset), started from the closed-form weighted
// 2D Procrustes solution. The covariance is the inverse of the normal equations scaled by the
// residual variance and covariance_correlation_steps (marginal over the view offsets).
RigidFit FitMatches(const AlignedTracks& aligned, std::size_t r, std::size_t s,
                    const std::vector<Match>& matches, const PairwiseOptions& options);

}  // namespace lrfnet::calib
