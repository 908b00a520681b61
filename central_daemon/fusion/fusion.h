#pragma once
// Track fusion (pure): after calibration, every sensor's tracks are brought into the world frame
// and the same object seen by several sensors becomes one fused track.
//
// What a local track carries. A tracker's track is the state of its own constant-velocity Kalman
// filter: each frame's estimate holds all its earlier measurements (its errors are correlated in
// time), the error of its sensor's pose is common to all its tracks and constant, and the centre it
// reports is offset from the body's centre by what the sensor's view leaves (more along the line
// of sight than across it), changing slowly. Combining successive states as if they were new
// measurements counts the same information many times; combining the latest states of several
// sensors as independent estimates ignores that neither their pose errors nor their centre offsets
// average out over time. The two methods (FusionOptions::method):
//
// kFusedFilter (default). One Kalman filter per fused track, state (x, y, vx, vy) in the world
// frame plus, for every sensor that measured it recently, that sensor's offset b_s (2-d, world):
// the pose error carried to this place plus the centre offset. b_s is a first-order Gauss-Markov
// process with the covariance B_s = J C_pose J^T + sigma_r^2 u u^T + sigma_l^2 (I - u u^T)
// (J = d p_w / d pose as in ToWorld, C_pose the placement's covariance, u the direction from the
// sensor, sigma_r = centre_sigma_<kind>_m, sigma_l = centre_lateral_fraction sigma_r) and the
// correlation time centre_correlation_s; the kinematic part is the constant-velocity model of
// common/cv_model.h with accel_psd. A sensor's frame z_s = p + b_s + v_s updates the track
// (Kalman update, Joseph form) with only the *new* information of the frame: the measurement the
// tracker's filter took, recovered from its consecutive states (the "tracklet" or
// equivalent-measurement idea, Drummond, Proc. SPIE 3163, 1997): with the previous measured state
// predicted by the tracker's model to xb, Pb,
//   R^-1 = P_pp^-1 - Pb_pp^-1,      z = xb_p + R P_pp^-1 (x_p - xb_p) (fusion_filter.cc)
// (position blocks; the tracker's process noise from SetTrackerModel, else tracker_accel_psd). The
// first time a local track contributes, its whole state (position and velocity, with its
// covariance) is the measurement: all of it is new to the fused tracks. So a fused track counts
// every measurement once, knows that repeated frames of one sensor do not remove that sensor's
// offset while other sensors' frames do, and its covariance contains the pose and centre errors.
// States that are not a filter's (a client sending raw detections: the covariance does not shrink
// while the position moves) are recognised and each frame is used as a measurement of its own
// (sources_unfiltered).
//   Association, every frame: global nearest neighbour (Hungarian method) of the frame's
// measurements against the fused tracks predicted to the frame time, cost d^2 + ln det S of the
// position innovation (S including the sensor's offset), gated by gate_mahalanobis2 and
// gate_max_distance_m; the fused track a local track is bound to gets binding_bonus. A tracker's
// id swap therefore moves its sources to the fused tracks they now fit (source_rebinds) in the
// frame the measurements jump, also when it is the only sensor. A bound measurement that no
// fused track took but lies within manoeuvre_max_distance_m of its own is a manoeuvre (a stop, a
// sharp turn): its track's kinematic covariance is widened until it fits (manoeuvres). Otherwise
// it is struck, and unbound after drift_updates consecutive strikes. An unbound measurement that
// nothing took starts a fused track (after 2 x drift_updates frames when it was just unbound).
// A local track forgotten after source_timeout_s that its tracker sends again with the same id
// within max_coast_s is bound again to the fused track it fed (sources_returned), rather than
// starting a second one that would coast on without sources once it is bound back.
//   Covariances that claim too much are scaled (adapt_covariances, covariance matching): the
// placements' covariances by how well sensors' tracks fit the others' fused tracks when they join
// them, each sensor's track covariances by how well its frames fit. Never below what was reported.
//   When the placements change, every fused track restarts from its sources' latest states.
//
// kLatestStates (earlier releases). Track-to-track fusion without memory: every fused track holding
// a source of the frame's sensor is re-estimated as the information-weighted combination of its
// bound sources' latest states, each predicted to the update time:
//   P_f = (sum_i P_i^-1)^-1,   x_f = P_f sum_i P_i^-1 x_i
// where P_i is the local covariance in the world frame (ToWorld) plus position_noise_floor_m2 and
// velocity_noise_floor_m2ps2. Unbound local tracks are associated (Hungarian method, d^2 + ln det
// S) only against fused tracks that hold no local track of that sensor in the frame. Drift: every
// fused track keeps a reference estimate, the fused state of the last update in which the sources
// it used agreed with it (position and velocity within agree_mahalanobis2), predicted from there;
// sources that disagree with it while another agrees are left out (source_exclusions); a measured
// source outside the gate around the reference is struck when the other sensors' sources agree
// with the reference (or, alone, when the reference is younger than drift_reference_max_age_s),
// and unbound after drift_updates strikes; a swap seen by one sensor only cannot be told from a
// person's motion. A tracker's coasting track is used only while no measured source is left.
//
// Both methods. A sensor's local track is bound to at most one fused track, a fused track holds
// at most one local track per sensor; a newer local track of the same sensor (the tracker started
// a new id for the person) replaces the old one. Fused ids survive a hand-over between sensors and
// gaps in every sensor's view shorter than max_coast_s (the fused track coasts and is picked up).
// Merge: two fused tracks with disjoint sensors that stay within the gate of each other (position,
// also under merge_max_distance_m, and velocity under merge_max_speed_difference_mps) for
// merge_updates consecutive checks are one object: the younger is merged into the older id.
// kFusedFilter: a fused track left without sources that coasts within the gates of a measured
// one is merged into it too (merge_sourceless), unless it stands in that track's shadow from the
// sensors that saw it last (hidden by it: merge_sourceless_shadow_m); the position gate may add
// merge_centre_spread_m to both covariances (two sensors see different sides of one body; off by
// default). A fused track no sensor's track is bound to any more is kept for its id but not
// reported (report_sourceless).
//   What the fuser reports (Output): the fused tracks (Snapshot), the confirmed ids it keeps
// without reporting them (hidden, with when and where they were last measured), and the ids that
// ended with why (timed out after max_coast_s, merged into id N), for ended_report_s of outputs
// after the first that listed the end. Every id is in at most one of the three, so a consumer that
// follows ids over time holds exactly the hidden ones and ends the others at once; the estimates
// are the same with or without it. IdFollower (id_follower.h) does that following for a consumer:
// per period and id, present, held, merged into its survivor (chains resolved) or ended. A tracker
// restart (TrackFrameData.session_id changes) unbinds every local track of the old session; the new
// session's tracks (whose ids restart) are associated afresh.
//
// Where a bias model of the trackers' centres is applied to each sample: CentreCorrected in
// fusion_internal.h, for both methods (DESIGN.md, "Measurement model").
//
// Sensor bias (kFusedFilter, learn_sensor_bias). What a sensor sees of a body leaves its centres
// offset towards it by an amount that is the same for all its tracks (its mounting height, its
// beam width, the tracker's model of a body), on top of each track's own offset; and its
// placement's error moves all its tracks alike. A fused track's offset state b_s holds these only
// for centre_correlation_s and relaxes to zero, so the constant part would stay in every frame.
// They are learnt across tracks: where other sensors measured the fused track too, the posterior
// of b_s (mean m, covariance V, prior B) is the shrunk estimate of the offset there; undoing the
// prior's shrinkage gives the estimate from the data alone,
//   y = B (B - V)^-1 m     (used where V <= B / 2: the data says at least as much as the prior),
// the offset left after the correction c applied to the frame, so c + y samples the sensor's
// offset at that place. A local track's updates are averaged into one sample per
// sensor_bias_sample_s (its own offset and the turning average in it). The model of a sample is
// linear, y = J theta + e, with theta = (dx, dy, dyaw) of the placement's error and the offset
// towards the sensor per measurement kind, J = [d p_w / d pose, -n e_kind] (n the line of sight);
// e has its own variance along n and across it, each estimated from the residuals. theta is the
// Bayesian least-squares estimate with the calibration's pose covariance (times
// sensor_bias_pose_prior_scale, and widened further when the estimate lies outside it) and the
// kind's centre_sigma as prior, forgetting beyond sensor_bias_memory samples. It is observable
// where views differ in direction: two sensors' offsets u1 b1 - u2 b2 separate unless u1 = +-u2,
// and the calibration's reference sensor (zero covariance) is never moved. Once
// sensor_bias_min_samples are in, frames are corrected by it (the placement by the error,
// CentreCorrected by the offset where its sigma is at most sensor_bias_offset_sigma_fraction of
// its kind's centre sigma: an offset known less well is left to the fused tracks' offset
// states), its covariance (times sensor_bias_covariance_scale) replaces
// the calibration's and its offset's variance is added to the offset prior along the line of
// sight. A sensor that sees people only alone learns nothing and is not corrected. A new
// placement of a sensor starts its model again. Fuser::sensor_biases() reports them.
//
// Time: frames carry the gateway's UTC scan time (scan_start_ns). A frame not newer than the
// previous frame of its sensor (and not another part of it) is dropped (frames_stale); a frame
// older than the newest frame of any sensor by more than max_out_of_order_s is dropped
// (frames_out_of_order); within that window its tracks are fused at the fused track's (newer) time.
// Gateway clocks are NTP-disciplined: a sensor whose clock runs ahead by more than
// max_out_of_order_s makes the others' frames look late. Nothing here reads a clock: Tick(now) ages
// and deletes tracks.
//
// Bad data: non-finite or implausible local tracks (see the bounds in FusionOptions), duplicate
// track ids in a frame, invalid placements are skipped and counted; the output never holds NaN.
// Memory is bounded: max_tracks_per_frame, max_fused_tracks, max_offset_sensors per fused track,
// local tracks forgotten after source_timeout_s, sensors only with a placement.
// Not thread-safe.

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "central_daemon/ingest/sensor_data.h"
#include "common/geometry.h"
#include "common/time.h"

namespace lrfnet::fusion {

namespace internal {
class Engine;
}  // namespace internal

// How the sources of a fused track are combined (see the header comment).
enum class FusionMethod : std::uint8_t {
  kFusedFilter,   // one filter per fused track on each sensor's new information (default)
  kLatestStates,  // the latest states of the bound sources combined (earlier releases)
};
const char* ToString(FusionMethod method);

struct FusionOptions {
  FusionMethod method = FusionMethod::kFusedFilter;

  // Association gate: squared Mahalanobis distance of positions (2 dof; 13.8 = 99.9 %). Also the
  // drift gate around the reference and the merge gate.
  double gate_mahalanobis2 = 13.8;
  // Hard gate in metres on top of the Mahalanobis one (large covariances never join far tracks).
  double gate_max_distance_m = 1.5;
  // Process noise of the constant-velocity model of the fused tracks (and, kLatestStates, of the
  // sources' prediction), white acceleration PSD [m^2/s^3]. 0.5, as the trackers' model: people
  // change speed by ~0.7 m/s within a second.
  double accel_psd = 0.5;

  // kFusedFilter: the trackers' own process noise [m^2/s^3], with which each frame's measurement
  // is recovered from a local track's consecutive states, for sensors that do not say theirs
  // (SetTrackerModel). Too low is safe (the measurements count less than they could); too high
  // makes the fused tracks over-confident. 0.5 is the tracker's default.
  double tracker_accel_psd = 0.5;
  // kFusedFilter: standard deviation [m] of the offset between the centre a tracker reports and
  // the body's centre along the line of sight, per measurement kind (shape fit, ellipse, centre of
  // mass or unspecified); across the line of sight centre_lateral_fraction of it. It changes
  // slowly (correlation time centre_correlation_s), so repeated frames of one sensor do not
  // average it away; other sensors' views do. Added to the pose uncertainty of the calibration.
  // (Shape fit: a few cm from the fit and the torso's turning plus the unknown mean offset of
  // what a sensor sees of a body, ~0.045 m in all. On fusion_benchmark's 25-people row, accel_psd
  // 1.0 and 0.03 here gave a fused RMS of 0.064 m and NEES 1.49; 0.5 and 0.045 give 0.063 m and
  // 1.35.)
  double centre_sigma_shape_fit_m = 0.045;
  double centre_sigma_ellipse_m = 0.08;
  double centre_sigma_com_m = 0.12;
  double centre_lateral_fraction = 0.5;
  double centre_correlation_s = 2.0;
  // kFusedFilter: scale the calibration's pose covariances up when sensors joining a fused track
  // disagree with it more than those covariances allow (a calibration that claims too much), and
  // a sensor's track covariances when its frames fit its fused tracks worse than they claim (a
  // tracker that claims too much). Never scaled below what was reported.
  bool adapt_covariances = true;
  // kFusedFilter: a source's frame is assigned to the fused track it is bound to unless another
  // fits better by this much (cost: squared Mahalanobis distance + ln det S). Larger values trust
  // the trackers' ids more; 0 re-associates every frame from scratch.
  double binding_bonus = 4.0;
  // kFusedFilter: a frame of a source its fused track's gate refused, that no other fused track
  // took, within this distance [m] of the predicted position: the person turned or stopped faster
  // than the motion model (accel_psd) expects; the track's covariance is widened to take it.
  double manoeuvre_max_distance_m = 0.5;
  // kFusedFilter: most sensors whose centre offset a fused track keeps as a state; the sensor
  // that measured it longest ago is forgotten first.
  std::size_t max_offset_sensors = 8;
  // kFusedFilter: learn each sensor's constant centre offset along the line of sight (per
  // measurement kind) across all its tracks, and take it out of its frames (see "Sensor bias" in
  // the header comment). Off: the offset is left to each fused track's offset state, which
  // relaxes to zero within centre_correlation_s (earlier releases).
  bool learn_sensor_bias = true;
  // A local track gives one sample of its sensor's offset per this many seconds of updates
  // shared with other sensors (its own offset and the torso's turning average within it).
  double sensor_bias_sample_s = 5.0;
  // Samples before the learnt offset is applied, and the most samples the estimate remembers
  // (older ones fade: a tracker updated or a sensor moved is followed).
  std::uint32_t sensor_bias_min_samples = 8;
  std::uint32_t sensor_bias_memory = 200;
  // The calibration's pose covariance is widened by this factor for the prior of the learnt
  // placement error: where the tracks and the calibration disagree the tracks should decide
  // (4: its sigma doubled; on fusion_benchmark's rows with poses 3 sigma off, 1 left 8 % of the
  // fused errors outside their 95 % ellipse).
  double sensor_bias_pose_prior_scale = 4.0;
  // The learnt estimate's covariance is widened by this factor where it is used (the fused
  // tracks' offset prior, the corrected placement, SensorBias): successive samples of one local
  // track share that track's own offset, while the regression takes them as independent. (On
  // fusion_benchmark with poses 3 sigma off, 1 left 6 % of the fused errors outside their 95 %
  // ellipse, 2 5.2 %, 3 4.5 %; on the 25-people row the fused RMS is 0.054 m with each.)
  double sensor_bias_covariance_scale = 3.0;
  // A learnt offset is taken out of the frames only when its sigma (as used, see above) is at
  // most this fraction of its kind's centre sigma; the placement's error is corrected
  // regardless. (On fusion_benchmark's rows the learnt offsets' sigmas are 0.4-1.3 of the
  // kind's: taking them out made every row but the ideal trackers' as bad or worse, the legacy
  // trackers' id switches 0.19 -> 0.34 per person-minute and their 2-view RMS 0.065 -> 0.085 m;
  // 0 never takes one out.)
  double sensor_bias_offset_sigma_fraction = 0.33;
  // Learnt offsets are clamped to +-this [m] (a shape fit's is a few cm, a centre of mass's of a
  // person ~0.2 m).
  double max_sensor_bias_m = 0.3;

  // kLatestStates: added to every source position variance [m^2] (residual calibration and
  // object-centre errors). Must be > 0.
  double position_noise_floor_m2 = 0.01;
  // kLatestStates: added to every source velocity variance [m^2/s^2] (gait and the different lags
  // of the trackers' filters). Must be > 0.
  double velocity_noise_floor_m2ps2 = 0.04;
  // A confirmed fused track without any update for this long is deleted [s]; until then it coasts
  // and can be re-bound (a person hidden from every sensor keeps the id). Longer keeps more ids
  // in crowds and leaves ghosts longer where people leave the view. A tentative fused track is
  // deleted as soon as it has no source left. (Earlier releases: 1.0.)
  double max_coast_s = 1.5;
  // A confirmed fused track without an update for this long is reported as coasting [s].
  double coast_after_s = 0.2;
  // A local track of a sensor without a frame for this long is unbound and forgotten [s].
  double source_timeout_s = 0.5;
  // Frames older than the newest frame by more than this are dropped (counted) [s].
  double max_out_of_order_s = 0.5;
  // A fused track is confirmed after this many updates (tentative before).
  std::uint32_t confirm_updates = 3;
  // Tentative local tracks are ignored unless this is set.
  bool use_tentative_sources = false;

  // Drift (see the header comment). Agreement with the reference that lets it move on (squared
  // Mahalanobis, 2 dof; 4.0 = 86 %).
  double agree_mahalanobis2 = 4.0;
  // Consecutive inconsistent frames of its sensor after which a source is unbound.
  std::uint32_t drift_updates = 3;
  // A lone source is judged against a reference at most this old [s]; an older reference is
  // re-anchored on the source instead (the track coasted, the reference no longer says much).
  double drift_reference_max_age_s = 0.5;

  // Merge (see the header comment): consecutive consistent checks (one per update of either
  // track), and the distance [m] and speed difference [m/s] the two may have at most.
  std::uint32_t merge_updates = 5;
  double merge_max_distance_m = 0.6;
  double merge_max_speed_difference_mps = 0.5;
  // kFusedFilter: the merge test's spread [m, per axis] of two sensors' centres of one body that
  // their tracks' covariances leave out: each sensor sees another side of the body (its size,
  // up to a torso's half depth), and the placements and the sensors' clocks are off a little.
  // Added to both tracks' position covariances in the merge test only (s^2 I each), so narrow
  // covariances across the line of sight do not keep one person's two fused tracks apart.
  // 0 (default): the tracks' covariances alone. (On fusion_benchmark's 25-people row with
  // tracker errors, 0.1 merged people walking close together: fused RMS 0.052 -> 0.058 m, id
  // switches 0.14 -> 0.23 per person-minute; 0.05: 0.054 m, 0.19. The fused tracks' covariances
  // already hold each sensor's centre offset and pose error.)
  double merge_centre_spread_m = 0.0;
  // kFusedFilter: a fused track that no local track feeds any more (its sources timed out or
  // moved to another fused track), coasting within the merge gates of a measured fused track of
  // other or the same sensors, is that track's object left behind: it is merged into it after
  // merge_updates checks (the older id kept, the measured track's estimate). Off: it coasts on
  // beside it until max_coast_s (earlier releases).
  bool merge_sourceless = true;
  // kFusedFilter: a person's radius [m] for the shadow test of merge_sourceless. A fused track
  // without sources that stands in the shadow of the measured track from every sensor that saw it
  // last (farther along that sensor's line of sight through the measured track by more than this,
  // and across it by less than the shadow's half-width at its range plus this, the shadow being a
  // body of this radius seen from the sensor) was hidden by that track's object, not left behind
  // by its own sources: it is not merged into it and keeps its id for when it is seen again. Two
  // bodies cannot overlap, so a person hidden behind another stands at least about a body's depth
  // behind them, while a track left behind by its own object coasts where that object is.
  // 0: no shadow test (earlier releases).
  double merge_sourceless_shadow_m = 0.25;
  // kFusedFilter: a confirmed fused track that no sensor's local track is bound to any more (its
  // last source timed out: every tracker that followed it dropped it, after coasting through
  // what hid it) is kept for max_coast_s to be picked up with its id but not reported (off, the
  // default: no sensor claims the object is there), or reported by Snapshot as coasting until
  // max_coast_s deletes it (on, earlier releases). Off, an id can leave Snapshot and come back
  // within max_coast_s: Output lists it as hidden meanwhile, so lrfnetd's zones and MQTT output
  // hold it exactly while the fuser keeps it (a hidden person who reappears is neither an exit
  // nor a new entry there) and end it as soon as Output reports it ended.
  bool report_sourceless = false;
  // How long [s] Output keeps reporting an id that ended (timed out, merged into another id),
  // with why, in the time of the outputs read by consumers that follow ids (Output with
  // EndsRead::kMark): from the first such Output that listed the end until the ones since span
  // more than ended_report_s (it is forgotten at the next Tick), so a gap in the data does not
  // take an end away before a consumer read it; outputs only looked at (kPeek) do not count.
  // Consumers that take an output at least every ended_report_s / 2 (two of their periods fit in
  // it) learn of every end (lrfnetd's zones and MQTT objects: at least every 10 s). At most
  // max_fused_tracks ends are kept: beyond that the oldest is forgotten earlier
  // (FusionCounters::ended_evicted); ends no consumer reads are kept until then.
  double ended_report_s = 30.0;

  // Plausibility of a local track (sensor frame); anything outside is skipped and counted.
  double max_local_range_m = 500.0;
  double max_speed_mps = 20.0;
  double max_position_variance_m2 = 25.0;
  double max_velocity_variance_m2ps2 = 100.0;
  // Tracks beyond this many in one frame are skipped and counted.
  std::size_t max_tracks_per_frame = 256;
  // Local tracks that would start a fused track beyond this many are skipped and counted.
  std::size_t max_fused_tracks = 4096;

  bool operator==(const FusionOptions&) const = default;
};
std::optional<std::string> Validate(const FusionOptions& options);

// A sensor's place in the world (calibration.yaml). Frames of sensors without a placement are
// counted (frames_unplaced) and ignored.
struct SensorPlacement {
  std::string id;
  common::Pose2 world_from_sensor;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // (x, y, yaw), m and rad
};

enum class FusedState : std::uint8_t { kTentative, kConfirmed, kCoasting };
const char* ToString(FusedState state);

struct FusedSource {
  std::string sensor_id;
  std::uint32_t track_id = 0;  // the tracker's id
  common::UtcNs last_ns = 0;   // scan time of the latest frame that carried it
};

struct FusedTrack {
  std::uint64_t id = 0;  // never reused (lrfnetd: not across fuser restarts either)
  FusedState state = FusedState::kTentative;
  common::UtcNs stamp_ns = 0;  // time of the estimate (the latest update, or the snapshot time)
  common::UtcNs first_ns = 0;  // first update
  double x_m = 0.0, y_m = 0.0, vx_mps = 0.0, vy_mps = 0.0;  // world frame
  Eigen::Matrix4d covariance = Eigen::Matrix4d::Identity();
  std::uint64_t updates = 0;
  std::vector<FusedSource> sources;  // bound local tracks, sorted by sensor id
};

// Why a fused id ended (FusionOutput::ended).
enum class FusedEndReason : std::uint8_t {
  kTimedOut,  // no update for max_coast_s (every sensor lost the object)
  kMerged,    // merged into another (older) fused id: the same object (merged_into)
};
const char* ToString(FusedEndReason reason);

// A fused track the fuser keeps but does not report in FusionOutput::tracks (report_sourceless
// off and no tracker holds it): its id may be reported again when a sensor sees the object
// again. A track older than max_coast_s at the output's time is not hidden (it ends at the next
// Tick; without Ticks, a consumer bounds it by its own hold).
struct HiddenFusedTrack {
  std::uint64_t id = 0;
  common::UtcNs last_ns = 0;    // time of its last update (the last measurement it took)
  double x_m = 0.0, y_m = 0.0;  // its estimate then, world frame
  std::string last_sensor;      // the sensor whose track fed it last, if known
};

// A fused id that ended: it is never reported again (ids are never reused).
struct EndedFusedTrack {
  std::uint64_t id = 0;
  common::UtcNs ended_ns = 0;  // when it ended (the merging frame's time, or Tick's)
  FusedEndReason reason = FusedEndReason::kTimedOut;
  // kMerged: the id it was merged into, else 0. That id may itself be merged later (its own
  // entry then follows): the id that continues the object is the last of the chain.
  std::uint64_t merged_into = 0;
};

// What the fuser holds at a time: its reported tracks and what it knows of the ids that are not
// among them. Every id a consumer has seen in `tracks` is, at any later output, in exactly one
// of: `tracks`, `hidden`, `ended` (for ended_report_s of outputs, see FusionOptions, as long as
// no more than max_fused_tracks ends are kept: beyond that the oldest is forgotten earlier,
// FusionCounters::ended_evicted), or none once that is over. A kept track older than
// max_coast_s whose end awaits Tick is in none either.
struct FusionOutput {
  common::UtcNs stamp_ns = 0;
  std::vector<FusedTrack> tracks;        // as Snapshot
  std::vector<HiddenFusedTrack> hidden;  // confirmed, kept, not in tracks, not older than
                                         // max_coast_s; ordered by id
  std::vector<EndedFusedTrack> ended;    // kept ends (ended_report_s), in the order recorded
};

// A local track in the world frame (what the live view draws as a "raw" track).
struct WorldTrack {
  std::string sensor_id;
  std::uint32_t track_id = 0;
  daemon::TrackState state = daemon::TrackState::kTentative;
  common::UtcNs stamp_ns = 0;
  double x_m = 0.0, y_m = 0.0, vx_mps = 0.0, vy_mps = 0.0;
  Eigen::Matrix2d position_covariance = Eigen::Matrix2d::Zero();  // incl. pose uncertainty
  // (x, y, vx, vy) covariance in the world frame, incl. pose uncertainty (position_covariance is
  // its upper left block).
  Eigen::Matrix4d covariance = Eigen::Matrix4d::Zero();
  std::optional<std::uint64_t> fused_id;  // the fused track it is bound to
};

// Transforms a local track into the world frame: p_w = R(yaw) p_s + t, v_w = R(yaw) v_s, and the
// covariance to first order (the compounding of uncertain transforms, Smith, Self & Cheeseman
// 1990), pose and local track independent:
//   P_w = J_s P_s J_s^T + J_pose C_pose J_pose^T,   J_s = diag(R, R),
//   J_pose = d(p_w, v_w)/d(x, y, yaw) = [I, R' p_s; 0, R' v_s],   R' = dR/dyaw.
// No validation (the Fuser checks the inputs first).
WorldTrack ToWorld(const SensorPlacement& placement, const std::string& sensor_id,
                   common::UtcNs stamp_ns, const daemon::TrackObservation& track);

struct FusionCounters {
  std::uint64_t frames = 0;
  std::uint64_t frames_unplaced = 0;       // sensor without a placement
  std::uint64_t frames_out_of_order = 0;   // older than the newest frame by > max_out_of_order_s
  std::uint64_t frames_stale = 0;          // not newer than the sensor's previous frame
  std::uint64_t frames_invalid = 0;        // scan time <= 0
  std::uint64_t session_changes = 0;       // tracker restarts (new session_id of a sensor)
  std::uint64_t placements_invalid = 0;    // non-finite or not positive semi-definite, ignored
  std::uint64_t observations = 0;          // local tracks used
  std::uint64_t observations_ignored = 0;  // tentative (use_tentative_sources off)
  std::uint64_t observations_invalid = 0;  // non-finite, implausible, or duplicate id
  std::uint64_t observations_over_capacity = 0;  // beyond max_tracks_per_frame
  std::uint64_t bindings = 0;                    // a local track bound to an existing fused track
  std::uint64_t handovers = 0;          // a sensor's source timed out, other sensors continue
                                        // the fused track (or pick it up while it coasts)
  std::uint64_t source_exclusions = 0;  // a source left out of an update (see Drift)
  std::uint64_t source_strikes = 0;     // a frame in which a source disagreed with its track
  std::uint64_t sources_drifted = 0;    // sources unbound for drifting away
  std::uint64_t sources_timed_out = 0;  // sources unbound after source_timeout_s
  // kFusedFilter: a timed-out local track sent again with its id (its tracker resumed it),
  // bound again to the fused track it fed.
  std::uint64_t sources_returned = 0;
  std::uint64_t fused_created = 0;
  std::uint64_t fused_deleted = 0;  // timed out (merged ones are not counted here)
  std::uint64_t fused_merged = 0;   // merged into an older fused track
  // Ends of confirmed ids forgotten before their ended_report_s was over: more than
  // max_fused_tracks ends kept (a consumer may have missed them; it bounds them by its own hold).
  std::uint64_t ended_evicted = 0;
  // kFusedFilter: of fused_merged, a track without sources merged with the measured track it
  // coasted on (merge_sourceless).
  std::uint64_t fused_merged_sourceless = 0;
  // kFusedFilter: merge checks of a track without sources refused because it stands in the
  // measured track's shadow (merge_sourceless_shadow_m).
  std::uint64_t merge_sourceless_shadowed = 0;
  // kFusedFilter: merge checks passed only with merge_centre_spread_m.
  std::uint64_t merge_checks_spread = 0;
  // kFusedFilter: confirmed fused tracks whose last source timed out, no longer reported from
  // then on unless a source binds again (report_sourceless off). Counted at the timeout only: a
  // track whose last source moved to another fused track, drifted off or whose tracker restarted
  // is hidden too but not counted here.
  std::uint64_t fused_unreported_sourceless = 0;
  std::uint64_t fused_over_capacity = 0;  // not created: max_fused_tracks reached
  std::uint64_t numerical_failures = 0;   // a covariance that could not be factorised (skipped)
  // kFusedFilter: a source's frame went to another fused track than the one it was bound to (its
  // tracker exchanged two people's ids, or it took over a person another fused track followed).
  std::uint64_t source_rebinds = 0;
  // kFusedFilter: frames of a local track that carried no new information the fused filter could
  // recover (its tracker's covariance grew where a measurement should have shrunk it: a tracker
  // model other than the one assumed, see tracker_accel_psd); directions without information
  // are left out.
  std::uint64_t recovery_clamped = 0;
  // kFusedFilter: local tracks whose states do not behave like a Kalman filter's (their covariance
  // hardly shrinks while their position moves: e.g. raw detections sent with their covariance);
  // each of their frames is then used as a measurement of its own.
  std::uint64_t sources_unfiltered = 0;
  // kFusedFilter: frames taken by their fused track with its covariance widened (a person who
  // turned or stopped faster than the motion model expects).
  std::uint64_t manoeuvres = 0;
};

// What the fuser learnt about the covariances it is given (kFusedFilter, adapt_covariances):
// factors >= 1 by which they had to be scaled to fit the errors seen.
struct CovarianceScales {
  double pose = 1.0;                       // of every placement's covariance
  std::map<std::string, double> trackers;  // of each sensor's track covariances
};

// A sensor's learnt centre offset (FusionOptions::learn_sensor_bias): along the line of sight,
// positive towards the sensor, per measurement kind.
struct SensorBias {
  std::string sensor_id;
  daemon::MeasurementKind kind = daemon::MeasurementKind::kUnspecified;
  double radial_m = 0.0;  // the estimate (applied once samples >= sensor_bias_min_samples)
  double sigma_m = 0.0;   // its standard deviation
  // The error of the sensor's placement estimated with it (the placement minus the truth; taken
  // off the placement once applied) and its covariance (x, y, yaw).
  double dx_m = 0.0, dy_m = 0.0, dyaw_rad = 0.0;
  Eigen::Matrix3d pose_covariance = Eigen::Matrix3d::Zero();
  std::uint64_t samples = 0;  // of the sensor (all kinds)
  // The scatter of its samples about the estimate (standard deviations along the line of sight
  // and across it), as estimated from the residuals.
  double residual_radial_m = 0.0, residual_lateral_m = 0.0;
  bool applied = false;         // the placement corrected by it
  bool offset_applied = false;  // radial_m taken out of the frames of this kind
};

class Fuser {
 public:
  // Precondition: Validate(options) (checked; aborts otherwise).
  explicit Fuser(const FusionOptions& options = {});
  ~Fuser();
  Fuser(Fuser&&) noexcept;
  Fuser& operator=(Fuser&&) noexcept;

  // Replaces the placements (a new calibration). Fused tracks are kept; the latest states of
  // their sources are transformed again with the new poses and their next frames too. Invalid
  // placements are ignored and counted; sensors without a placement any more lose their bindings.
  void SetPlacements(const std::vector<SensorPlacement>& placements);
  bool HasPlacement(const std::string& sensor_id) const;
  // The process noise of a sensor's tracker (SensorInfo.accel_psd_m2ps3), for kFusedFilter; 0 or
  // invalid: FusionOptions::tracker_accel_psd.
  void SetTrackerModel(const std::string& sensor_id, double accel_psd_m2ps3);

  // A frame of a sensor: all its tracks of one scan, or one part of them (the other parts of the
  // latest scan, same session_id, scan_counter and scan time, different part < 64, are added
  // when they come; a part seen before is stale).
  void AddFrame(const std::string& sensor_id, const daemon::TrackFrameData& frame);
  // Deletes fused tracks without updates for max_coast_s and unbinds timed-out sources, as of
  // now_ns (gateway UTC, the same time base as the frames).
  void Tick(common::UtcNs now_ns);

  // Fused tracks predicted to now_ns (not modified), ordered by id. Tentative ones only when
  // include_tentative. Tracks older than max_coast_s at now_ns (awaiting Tick) are left out.
  std::vector<FusedTrack> Snapshot(common::UtcNs now_ns, bool include_tentative = false) const;
  // Snapshot's tracks and, besides them, the confirmed fused ids the fuser keeps without
  // reporting them (hidden) and the ids that ended and are still kept (ended_report_s),
  // with why (FusionOutput). Consumers that follow ids over time (zones, MQTT objects) hold a
  // hidden id and end an ended one at once (IdFollower). An output read by such a consumer
  // (EndsRead::kMark) marks the ends it lists as read (ended_report_s runs from then, in the time
  // of the marked outputs); one that is only looked at (kPeek: the fused tracks' publish, a live
  // view, a status line) changes nothing, so it cannot take an end away before the consumers read
  // it. lrfnetd computes one per output time and shares it.
  enum class EndsRead : std::uint8_t { kMark, kPeek };
  FusionOutput Output(common::UtcNs now_ns, bool include_tentative = false,
                      EndsRead ends_read = EndsRead::kMark) const;
  // Marks the ends kept as read at now_ns, as Output with kMark does (for a consumer that reads an
  // output computed earlier with kPeek at the same now_ns and fuser state).
  void MarkEndsRead(common::UtcNs now_ns) const;
  // The id the next fused track gets (ids grow by one from 1).
  std::uint64_t next_id() const;
  // Makes the next fused ids start at next_id at least (a fuser that replaces another passes
  // the other's next_id(), so ids stay unique across both).
  void ContinueIdsFrom(std::uint64_t next_id);
  // Changes ended_report_s alone, keeping the tracks (the other options need a new fuser).
  // Precondition: valid as in Validate (checked; aborts otherwise).
  void SetEndedReportS(double ended_report_s);
  // Each sensor's latest local tracks in the world frame (those seen within source_timeout_s of
  // now_ns), with their fused ids, ordered by sensor id and track id.
  std::vector<WorldTrack> WorldTracks(common::UtcNs now_ns) const;

  const FusionCounters& counters() const;
  CovarianceScales covariance_scales() const;
  // The centre offsets learnt per sensor and kind (kFusedFilter), ordered by sensor and kind.
  std::vector<SensorBias> sensor_biases() const;
  const FusionOptions& options() const { return options_; }

 private:
  FusionOptions options_;
  std::map<std::string, SensorPlacement, std::less<>> placements_;
  // The method's state (fused tracks, bindings, latest world tracks): fusion_filter.cc,
  // fusion_latest.cc.
  std::unique_ptr<internal::Engine> engine_;
};

// One JSON object (a single line, no newline) for the fused-track stream and recording:
// {"type":"fused","stamp_ns":..,"tracks":[{"id":..,"state":"confirmed","x_m":..,"y_m":..,
//  "vx_mps":..,"vy_mps":..,"cov_xy":[xx,xy,yy],"sources":[{"sensor":"s1","track":3}]},...]}
// Positions in metres with millimetre precision, velocities mm/s, covariances 1e-6 m^2; always
// valid JSON for any input (non-finite numbers are null, invalid UTF-8 in ids is replaced).
std::string FusedTracksJson(const std::vector<FusedTrack>& tracks, common::UtcNs stamp_ns);

// Splits the tracks into JSON datagrams of at most max_bytes each: every datagram a complete
// object as above with "part" (0-based) and "parts" after "stamp_ns", split on track boundaries,
// tracks in order. No tracks: one datagram with an empty list. A track too big for a datagram of
// its own is sent without its sources ("sources_truncated":true), or left out if even that does
// not fit; max_bytes too small for an empty datagram gives no datagrams.
std::vector<std::string> FusedTrackDatagrams(const std::vector<FusedTrack>& tracks,
                                             common::UtcNs stamp_ns, std::size_t max_bytes = 1400);

}  // namespace lrfnet::fusion
