#pragma once
// Track fusion (pure): after calibration, every sensor's tracks are brought into the world frame
// and the same object seen by several sensors becomes one fused track.
//
// Model: centralised track-to-track fusion *without memory* (Bar-Shalom, Willett & Tian, "Tracking
// and Data Fusion", 2011: the latest local estimates are combined, no fused filter in the loop). A
// sensor's local track is *bound* to at most one fused track, and a fused track holds at most one
// local track per sensor. When a frame of sensor S arrives, every fused track that holds a local
// track of S in that frame is re-estimated as the information-weighted combination of the latest
// states of all its bound sources, each predicted to the update time with the constant-velocity
// model of common/cv_model.h (x' = F x, P' = F P F^T + Q):
//   P_f = (sum_i P_i^-1)^-1,   x_f = P_f sum_i P_i^-1 x_i          (x = (x, y, vx, vy), world)
// where P_i is the local covariance propagated into the world frame (ToWorld) plus
// position_noise_floor_m2 on the position (residual calibration error, and the object-centre
// offset: different sensors see different sides of a person) and velocity_noise_floor_m2ps2 on
// the velocity. A local track's successive states
// are strongly correlated (its filter's memory), so feeding them into a second filter as if they
// were independent measurements would count the same information many times and make the fused
// track lag; combining only the *latest* states avoids both. Local tracks of different sensors are
// treated as independent (their measurement noise, pose errors and viewpoints are); the small
// correlation through the common process noise (Bar-Shalom & Campo, IEEE TAES 22(6), 1986) is
// neglected and covered by the noise floors. The fused track's own CV prediction is used for
// coasting, for gating and as the drift reference below, never as a prior of the combination.
//
// Association: a usable local track that is not bound is associated by global nearest neighbour
// (an optimal assignment, Hungarian method, over the gated costs d^2 + ln det S) against the fused
// tracks predicted to the frame time that hold no local track of that sensor in the frame;
// d^2 = r^T S^-1 r of the positions with S = P_local + P_fused, gated by gate_mahalanobis2 and
// gate_max_distance_m. What stays unassociated starts a new fused track. A fused track's stale
// local track of the same sensor (the tracker dropped it and started a new id for the same
// person) is replaced by the new one. Fused ids therefore survive a hand-over between sensors
// (B binds while A still sees the person, A drops, B continues) and short gaps (a coasting fused
// track is predicted and re-bound within max_coast_s).
//
// Coasting: a local track its tracker reports as coasting (predicted, not measured) is used only
// while the fused track has no measured source: it is a constant-velocity prediction like the
// fused track's own, and it lags when the person turns or stops.
//
// Drift: every fused track keeps a reference estimate, the fused state of the last update in
// which the sources it used agreed with the reference (position and velocity each within
// agree_mahalanobis2), predicted from there. Sources that disagree with it while another source
// agrees are left out of the combination (source_exclusions), so a source that starts to drift
// cannot drag the track. A measured source outside the gate around the reference is struck when
// the other sensors' measured sources agree with the reference and not with it (or, when it is
// the only one, when the reference is younger than drift_reference_max_age_s: a jump); when it
// agrees with the others instead, everybody saw the same turn and the reference is re-anchored.
// After drift_updates consecutive strikes (frames of its sensor) the source is unbound, may not
// re-bind to that fused track, and is associated afresh (for 2 x drift_updates frames only with
// existing fused tracks: the one it belongs to is often freed a frame later, by the other swapped
// source); a new local track of the same sensor may replace a struck one. This follows people
// through a tracker's id swap as long as another sensor saw them right; a swap seen by one sensor
// only cannot be told from a person's motion.
//
// Merge: two fused tracks with disjoint sensors that stay within the gate of each other (position,
// also under merge_max_distance_m, and velocity under merge_max_speed_difference_mps) for
// merge_updates consecutive checks are one object (e.g. seen by A and B before they could be
// associated, or after a better calibration): the younger one is merged into the older id.
//
// Sessions: a tracker restart (TrackFrameData.session_id changes) unbinds every local track of the
// old session; the new session's tracks (whose ids restart) are associated afresh.
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
// Memory is bounded: max_tracks_per_frame, max_fused_tracks, local tracks forgotten after
// source_timeout_s, sensors only with a placement.
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

struct FusionOptions {
  // Association gate: squared Mahalanobis distance of positions (2 dof; 13.8 = 99.9 %). Also the
  // drift gate around the reference and the merge gate.
  double gate_mahalanobis2 = 13.8;
  // Hard gate in metres on top of the Mahalanobis one (large covariances never join far tracks).
  double gate_max_distance_m = 1.5;
  // Process noise of the constant-velocity model used to predict sources and fused tracks, white
  // acceleration PSD [m^2/s^3].
  double accel_psd = 1.0;
  // Added to every source position variance [m^2]: residual calibration and object-centre errors
  // (different sensors see different sides of a person). Must be > 0.
  double position_noise_floor_m2 = 0.01;
  // Added to every source velocity variance [m^2/s^2]: gait and the different lags of the
  // trackers' filters (a tracker's own velocity covariance does not cover them). Must be > 0.
  double velocity_noise_floor_m2ps2 = 0.04;
  // A confirmed fused track without any update for this long is deleted [s]; until then it coasts
  // and can be re-bound. A tentative fused track is deleted as soon as it has no source left.
  double max_coast_s = 1.0;
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

  // Plausibility of a local track (sensor frame); anything outside is skipped and counted.
  double max_local_range_m = 500.0;
  double max_speed_mps = 20.0;
  double max_position_variance_m2 = 25.0;
  double max_velocity_variance_m2ps2 = 100.0;
  // Tracks beyond this many in one frame are skipped and counted.
  std::size_t max_tracks_per_frame = 256;
  // Local tracks that would start a fused track beyond this many are skipped and counted.
  std::size_t max_fused_tracks = 4096;
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
  std::uint64_t id = 0;  // unique for the Fuser's life, never reused
  FusedState state = FusedState::kTentative;
  common::UtcNs stamp_ns = 0;  // time of the estimate (the latest update, or the snapshot time)
  common::UtcNs first_ns = 0;  // first update
  double x_m = 0.0, y_m = 0.0, vx_mps = 0.0, vy_mps = 0.0;  // world frame
  Eigen::Matrix4d covariance = Eigen::Matrix4d::Identity();
  std::uint64_t updates = 0;
  std::vector<FusedSource> sources;  // bound local tracks, sorted by sensor id
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
  std::uint64_t fused_created = 0;
  std::uint64_t fused_deleted = 0;        // timed out (merged ones are not counted here)
  std::uint64_t fused_merged = 0;         // merged into an older fused track
  std::uint64_t fused_over_capacity = 0;  // not created: max_fused_tracks reached
  std::uint64_t numerical_failures = 0;   // a covariance that could not be factorised (skipped)
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
  // Each sensor's latest local tracks in the world frame (those seen within source_timeout_s of
  // now_ns), with their fused ids, ordered by sensor id and track id.
  std::vector<WorldTrack> WorldTracks(common::UtcNs now_ns) const;

  const FusionCounters& counters() const { return counters_; }
  const FusionOptions& options() const { return options_; }

 private:
  FusionOptions options_;
  FusionCounters counters_;
  std::map<std::string, SensorPlacement, std::less<>> placements_;
  // Implementation state (fused tracks, bindings, latest world tracks) is defined in fusion.cc.
  struct State;
  std::unique_ptr<State> state_;
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
