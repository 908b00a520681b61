#pragma once
// The whole calibration: from the tracks and backgrounds of N sensors to every sensor's pose
// (pure: no clock, no files, no logging; stage times are measured with a clock passed in).
//
// Methods (CalibrationOptions::method):
//   quenzel  (default) Quenzel et al. end to end: align + RTS smoothing → dynamic intervals →
//            pairwise MSAC + verification (eqs. 5-8) → point-to-line ICP on the backgrounds →
//            L1 rotation averaging (Algorithm 1, node-angle form) → least-squares translations →
//            joint refinement over all associated observations (Ceres; kept only if it lowers the
//            cost and moves no sensor placed on walls beyond refine_max_disagreement_sigma, nor,
//            if set, a pair aligned on walls beyond refine_max_wall_residual_sigma of that
//            alignment; a sensor hanging on a weak pair moves only beyond
//            weak_refine_min_move_sigma).
//   spectral the same pairwise estimates, then weighted spectral relaxation [21] and weighted
//            least-squares translations (Quenzel et al.'s non-robust comparison).
//   schenk   Schenk et al.: SVD track association, N/d weights, greedy placement, mass-spring
//            relaxation, close-points-only ICP.
//
// Robustness of the quenzel method: an edge whose rotation disagrees with the L1 solution by more
// than RotationAveragingOptions::outlier_threshold_deg, or whose translation then disagrees by more
// than max_translation_residual_m, takes no part in the translations (reported per edge).
//
// Failure is a value: CalibrationOutcome::ok = false with `error`, one line a person can act on:
// too little data says what is missing (which sensors have no tracks, which share no simultaneous
// tracks with the others, how many seconds of co-observation each link has and needs); a graph
// that stays disconnected names the sensors not connected to the reference. The poses of the
// sensors that are connected are still filled in (calibrated = true) so a caller may show them.

#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "central_daemon/calibration/align.h"
#include "central_daemon/calibration/icp.h"
#include "central_daemon/calibration/intervals.h"
#include "central_daemon/calibration/pairwise.h"
#include "central_daemon/calibration/refine.h"
#include "central_daemon/calibration/rotation_averaging.h"
#include "central_daemon/calibration/schenk.h"
#include "central_daemon/calibration/translations.h"
#include "central_daemon/calibration/types.h"
#include "common/mount_check.h"

namespace lrfnet::calib {

enum class Method { kQuenzel, kSpectral, kSchenk };
const char* ToString(Method method);
std::optional<Method> ParseMethod(const std::string& name);

struct CalibrationOptions {
  Method method = Method::kQuenzel;
  // The sensor fixed at the origin; empty: the best-connected one (most accepted edges, then
  // most matched observations, then the first id).
  std::string reference;
  // Schenk's N/d weights on the edges (rotation averaging, translations); false: uniform.
  bool weighted = false;
  bool use_icp = true;                       // step 6
  bool refine = true;                        // step 8
  // ICP is kept only if the tracks still agree: the Mahalanobis distance between the ICP's pose
  // and the tracks' estimate (both covariances summed) at most this (sigma units). The kept pair
  // is then the information-weighted fusion of both (the tracks decide where the walls leave a
  // direction open, e.g. along a corridor), strong if the fusion passes the pairwise thresholds.
  double icp_max_disagreement_sigma = 3.5;
  // In that test only, the tracks' estimate carries in addition this isotropic standard deviation
  // of its translation (metres): a bias the measurement model does not know and that does not
  // average out, e.g. a scanner at knee height whose tracker fits a torso to a pair of legs (its
  // centres lie ~0.1 m behind the body centre). Walls that agree all round (no degenerate
  // direction) then win over such tracks instead of being dropped; the tracks still decide along a
  // direction the walls leave open.
  double icp_track_bias_sigma_m = 0.1;
  // The joint refinement is kept only if no sensor with a used pair aligned on the backgrounds
  // moves farther from the weighted least squares on the pairs than this (Mahalanobis, 3 dof,
  // both covariances summed): from the tracks alone it cannot know better than the walls, so a
  // larger move means its model of the tracks is wrong (a bias it absorbs into the shared size
  // correction, a wall constraint its robust loss gave up).
  double refine_max_disagreement_sigma = 3.5;
  // And only if at the refined poses every used pair aligned on the backgrounds keeps its
  // background alignment within this (Mahalanobis, 3 dof, the alignment's own covariance): the
  // test above sums in the refinement's covariance, which is wide exactly where its robust loss
  // gave a wall constraint up, so two sensors with biased tracks (knee-height scanners whose
  // tracker fits a torso to legs) could both move within it while their walls' relative pose
  // breaks. inf (the default): not tested. Off because where the tracks carry a bias shared by
  // every pair between two rooms (office_distributed with shape-fit tracks), the pairs' least
  // squares it falls back to claims too little uncertainty (errors beyond 3 sigma) where the
  // refinement's covariance happened to cover them (results/calibration_benchmark.md,
  // --diagnostic-variants).
  double refine_max_wall_residual_sigma = std::numeric_limits<double>::infinity();
  // A sensor whose one used pair is weak (a flagged leaf) keeps the pairs' placement, carried along
  // with the sensor it hangs on, unless the joint refinement moves it relative to that sensor
  // farther than this from the weak pair's estimate (Mahalanobis, 3 dof, the pair's covariance;
  // 2.8: chi-square 95 %). The refinement's pose for such a sensor rests on the pair's few
  // observations and on associations with sensors whose pairs were rejected (nothing verified
  // them; far-range views whose systematic error the model does not carry), while its covariance
  // claims a precision those do not have; a move the pair's own uncertainty explains is no
  // evidence against the pair. 0: the refinement's pose is always taken (the method before it).
  double weak_refine_min_move_sigma = 2.8;
  // Tracks and walls that disagree beyond icp_max_disagreement_sigma leave their pair a
  // candidate with each component's variance widened by the square of its disagreement, and a
  // kept refinement reports no less uncertainty than the pairs' least squares (the refinement
  // cannot see such conflicts). false: neither (the method before them; with
  // icp_track_bias_sigma_m = 0 and refine_max_disagreement_sigma = inf it is the benchmark's
  // "before" row).
  bool conflicts_widen_covariance = true;
  // A sensor configured for upper-body height (SensorInfo mount torso, or unspecified with sizes
  // sent) whose tracks look like legs (common/mount_check.h: a knee-height scanner whose
  // tracker fits a torso to two legs, its centres ~0.1 m off the body's): flagged with what to do
  // (set shape.mount: legs on its tracker), and its samples carry a shared radial bias of this
  // standard deviation (metres; through the size correction, types.h TrackSample), so that the
  // pairs through it and its pose say how little its tracks are worth; the joint refinement, whose
  // model does not know that bias, is not run (a warning says so). check_mount false: no check.
  bool check_mount = true;
  common::MountCheckOptions mount_check;
  double mount_mismatch_bias_sigma_m = 0.1;
  double max_translation_residual_m = 0.5;   // edges beyond it are dropped from the translations
  // Minimum data: seconds of simultaneous tracks a pair needs to count as linked (assessment).
  double min_pair_overlap_s = 3.0;
  AlignOptions align;
  IntervalOptions intervals;
  PairwiseOptions pairwise;
  IcpOptions icp;
  RotationAveragingOptions rotation;
  TranslationOptions translation;
  JointRefineOptions joint;
  SchenkOptions schenk;
};
std::optional<std::string> Validate(const CalibrationOptions& options);

// What the data allows, before any estimation (cheap; the daemon shows it as progress).
struct SensorData {
  std::string id;
  double tracked_s = 0.0;       // grid time with at least one track
  std::size_t tracks = 0;
  bool has_background = false;
  bool has_description = false;
  bool clock_suspect = false;
};
struct PairData {
  std::size_t r = 0, s = 0;
  double overlap_s = 0.0;  // grid time during which both sensors have tracks
};
struct DataAssessment {
  std::vector<SensorData> sensors;
  std::vector<PairData> pairs;  // pairs with overlap_s > 0
  // Sensors not linked to the first sensor with data by pairs of at least min_pair_overlap_s
  // (empty: the data can connect every sensor).
  std::vector<std::string> unlinked;
  bool sufficient = false;
  std::string missing;  // what is missing, one line ("" when sufficient)
};
DataAssessment Assess(const AlignedTracks& tracks, double min_pair_overlap_s);

struct CalibrationOutcome {
  bool ok = false;
  std::string error;
  CalibrationResult result;
  AlignedTracks tracks;             // the aligned tracks used (for the report and fusion)
  std::vector<PairEstimate> pairs;  // every pair considered
  DataAssessment assessment;
  // Per sensor (input order): the mount check of a sensor configured for upper-body height
  // (decided false for the others and with check_mount off).
  std::vector<common::MountCheck> mount_checks;
};

// A monotonic clock in seconds for the stage times (may be empty: no timings).
using StageClock = std::function<double()>;

// The mount check of one sensor's recording (common/mount_check.h): every confirmed person track
// (not a box) of each session, its median learned half-width (the smaller semi-axis of its size
// state) over its states faster than options.min_speed_mps, if it has options.min_states of them.
// Decided false for a sensor configured at knee height (SensorInfo mount legs) or whose tracker
// sends no sizes.
common::MountCheck CheckMount(const SensorRecording& sensor,
                              const common::MountCheckOptions& options);

// The flag of a sensor whose check says legs ("" otherwise): what was seen and what to do.
std::string MountFlag(const std::string& id, const common::MountCheck& check);

// Precondition: Validate(options) is nullopt (checked: a violation gives ok = false).
CalibrationOutcome Calibrate(const CalibrationInput& input, const CalibrationOptions& options,
                             const StageClock& clock = {});

// The global step onwards (step 7 with its hypotheses, step 8) from pairwise estimates made
// already (e.g. by EstimateAllPairs and the background ICP) on `tracks` (as Align made them): for
// tools and tests that estimate or inspect the pairs themselves. Methods quenzel and spectral.
CalibrationOutcome CalibrateFromPairs(AlignedTracks tracks, std::vector<PairEstimate> pairs,
                                      const CalibrationOptions& options,
                                      const StageClock& clock = {});

}  // namespace lrfnet::calib
