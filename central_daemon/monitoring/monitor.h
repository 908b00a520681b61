#pragma once
// Keeping a calibrated site calibrated (pure): watches every placed sensor with the background
// signal (background_check.h) and the track signal (track_check.h), flags a sensor that moved,
// estimates its pose again with every other pose held fixed, and re-learns the reference
// background of a sensor whose scene changed while the sensor did not.
//
// Per sensor (SensorWatch::state):
//   kWatched   placed, fused. Every new background snapshot is checked against the reference (the
//              snapshot in place when the pose was set; without one, the first snapshot after it);
//              every track_period_s its tracks of the last track_window_s are checked against the
//              other watched sensors' tracks (and those of the newest half of the window alone
//              when the whole window fits no rigid correction: a move inside it).
//   kMoved     flagged: its tracks must not feed the fused output (Excluded() is true from the
//              moment of the flag). Flagged when a snapshot says the whole scene moved (or its
//              changed part, see background_check.h), or when track_confirmations consecutive track
//              checks say so. The flag names the sensor, the time (the gateway time of the data
//              that showed it) and the estimated motion.
//   kSettling  its pose is corrected, but its tracker is still re-learning its background after
//              the move (wall pieces it takes for people, tracks bent by them): still left out of
//              the fusion and of the other sensors' track checks, until a snapshot holds the whole
//              new scene (settled_min_inliers of it on the reference scene at the corrected pose)
//              or relearn_hold_s have passed since the flag; then kWatched again.
//   The pose is corrected (event kCorrected) from
//     - the background, when a snapshot taken after the flag aligns with the reference as a whole
//       (stage 1 with at least correct_min_inliers of its points on the reference scene): the
//       pose is the old one times the ICP's motion (exact where the scene has structure). When
//       the tracks since the flag associate enough, they must agree with it (CheckTracks not
//       "moved" under the corrected pose); otherwise the next snapshot is tried. A snapshot with
//       less than settled_min_inliers on the reference scene may mix the old scene (nearer
//       returns the tracker keeps as foreground until it absorbs them) with the new, and its
//       motion falls between the two: it gives the pose only when the tracks since the flag place
//       the sensor to within check_max_yaw_sigma_deg / check_max_translation_sigma_m and within
//       twice that of it;
//     - else the tracks since the flag (from correction_min_tracks_s of them on, every
//       track_period_s): EstimateFromTracks started from the pose the detection suggested, with
//       every other pose fixed (the calibration's pairwise association, refit and MSAC search).
//   After a correction, every snapshot that aligns with the reference as a whole refines the
//   pose (event kCorrected again, method "background"), whatever its verdict on the motion's
//   significance: within relearn_hold_s of the move (within the refinement bounds) and, for a
//   pose from tracks, until one agrees with it. The snapshot's pose carries the covariance of its
//   lag (its tracker's background follows a small range change with a time constant and absorbs
//   nearer returns only after a while: background_time_constant_s, background_absorb_after_s)
//   and is combined with the tracks' estimate since the flag, if any, by covariance (their bend
//   while the tracker re-learns: tracks_bias_sigma_*); when the two disagree beyond both
//   covariances (combine_max_chi2) the snapshot alone counts. A snapshot with fewer than
//   settled_min_inliers on the scene (a viewpoint moved by half a metre sees parts the reference
//   does not) counts only against such a tracks' estimate. The snapshot's pose is the ICP's fit
//   of the whole scene, also where the pose in use keeps a few more points within
//   inlier_distance_m (BackgroundVerdict::fit_share): that count cannot tell poses a few tenths
//   of a degree apart, and the beams the tracker has not yet re-learned favour the pose in use.
//   Only one sensor is flagged by tracks per check, and only against at least two other watched
//   sensors: when one sensor moved, the others' tracks are compared with its tracks too and look a
//   little off; once it is flagged and left out, they agree again (every sensor's strikes start
//   over at any flag). With one other sensor the tracks cannot tell which of the two moved; the
//   background can.
//   A sensor whose scene changed by itself (kSceneChanged: furniture, a parked cart) is not
//   flagged; once a track check after that snapshot finds enough data and no motion, the snapshot
//   becomes the reference (event kBackgroundRelearned). Without people to check against, the
//   reference is kept (the snapshot is checked again at the next one).
//
// After a correction the reference snapshot stays (in the sensor's old frame) with the motion as
// its expected pose, so the snapshots the tracker sends while it re-learns its background are
// compared with the right expectation; the first snapshot that agrees with it as a whole (stage 1,
// correct_min_inliers) becomes the new reference.
//
// Time: every call takes the gateway UTC of the newest data (the daemon's "now"); nothing reads a
// clock. Frames come through FrameSource (the track store in lrfnetd, a fake in tests).
// Not thread-safe.

#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "central_daemon/ingest/sensor_data.h"
#include "central_daemon/monitoring/background_check.h"
#include "central_daemon/monitoring/track_check.h"
#include "common/geometry.h"
#include "common/time.h"

namespace lrfnet::monitoring {

struct MonitorOptions {
  BackgroundCheckOptions background;
  TrackCheckOptions tracks;
  double track_window_s = 10.0;  // the sliding window of the track check
  double track_period_s = 1.0;   // how often the tracks are checked
  int track_confirmations = 2;   // consecutive "moved" track checks that flag a sensor
  // After a pose is set, the mean correction of this many track checks with twice the matches
  // they need is what "nothing moved" looks like to the tracks (track_check.h, baseline); tracks
  // flag nothing before.
  int track_baseline_checks = 10;
  // A background correction needs this share of the snapshot's points on the reference scene;
  // short of settled_min_inliers (a snapshot that may mix the old scene and the new) also the
  // tracks since the flag placing the sensor to within these standard deviations, and within
  // twice them of the snapshot's pose.
  double correct_min_inliers = 0.9;
  double check_max_yaw_sigma_deg = 0.1;
  double check_max_translation_sigma_m = 0.025;
  // A snapshot holds the whole new scene (the tracker has re-learned its background after a
  // move) when this share of its points lies on the reference scene under the ICP's motion; such
  // a snapshot refines a pose that came from tracks.
  double settled_min_inliers = 0.97;
  // The tracker's background follows a range change within its margin with this time constant
  // (the tracker's background.track_time_constant_s): a snapshot t seconds after a move still
  // lags it by up to exp(-t / this) of the move ...
  double background_time_constant_s = 10.0;
  // ... and until the tracker absorbs nearer returns (its absorb_after_s) the snapshot's points
  // off the scene may be old returns, each pulling its motion towards the old pose. Both are part
  // of the covariance of the pose a snapshot gives after a move (t from the flag, which comes
  // after the move).
  double background_absorb_after_s = 30.0;
  // The tracks since a flag come from a tracker that is re-learning its background (wall pieces
  // merge with people near it): a bend they share, of up to correction_max_rms_m, is part of the
  // covariance of a pose from them when it is combined with a snapshot's (the benchmark's track
  // corrections were 0.2-0.7 degrees / up to 0.1 m off).
  double tracks_bias_sigma_m = 0.05;
  double tracks_bias_sigma_deg = 0.5;
  // A snapshot's pose and the tracks' that disagree beyond both covariances (chi^2 of the
  // difference against their sum above this): the tracks are bent, the snapshot alone counts.
  double combine_max_chi2 = 16.0;
  // A track correction uses the tracks since the flag, once there are this many seconds of them.
  double correction_min_tracks_s = 8.0;
  // ... and at most this many (the newest).
  double correction_max_tracks_s = 30.0;
  // A track correction needs its fit's residual at most this (metres): while a tracker re-learns
  // its background after a move, wall pieces merge with people near them and bend their tracks.
  double correction_max_rms_m = 0.05;
  // A pose corrected from tracks is refined by later track checks (without a new flag) while
  // their correction stays within these bounds; beyond them it is a new move.
  double refine_max_yaw_deg = 2.0;
  double refine_max_translation_m = 0.2;
  // Re-learn the reference background when the scene changed and the tracks agree ...
  bool relearn_background = true;
  // ... but not within this many seconds of a move: the tracker re-learns its own background then
  // (a farther return within seconds, a nearer one after absorb_after_s, 30 s by default), and
  // only a settled snapshot (settled_min_inliers) counts.
  double relearn_hold_s = 60.0;
};
std::optional<std::string> Validate(const MonitorOptions& options);

// A sensor's pose in the world (calibration.yaml), with its covariance (x_m, y_m, yaw_rad).
struct SensorPose {
  std::string id;
  Pose2 world_from_sensor;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
};

// The frames the monitor reads (in lrfnetd: the track store).
class FrameSource {
 public:
  virtual ~FrameSource() = default;
  // The sensor's frames with scan time in [from_ns, to_ns), in scan order.
  virtual std::vector<daemon::TrackFrameData> Frames(const std::string& sensor_id,
                                                     common::UtcNs from_ns,
                                                     common::UtcNs to_ns) const = 0;
};

enum class WatchState { kWatched, kMoved, kSettling };
const char* ToString(WatchState state);

enum class MonitorEventKind { kMoved, kCorrected, kBackgroundRelearned };
const char* ToString(MonitorEventKind kind);

struct MonitorEvent {
  MonitorEventKind kind = MonitorEventKind::kMoved;
  std::string sensor_id;
  common::UtcNs stamp_ns = 0;  // gateway UTC of the data that showed it
  std::string method;          // "background", "background (changed part)", "tracks"
  std::string detail;          // one line for a person
  // kMoved: the pose in use and the pose the detection suggests; kCorrected: the old and the new
  // pose. Absent for kBackgroundRelearned.
  std::optional<Pose2> before;
  std::optional<Pose2> after;
};

struct SensorWatch {
  std::string id;
  WatchState state = WatchState::kWatched;
  Pose2 world_from_sensor;  // the pose in use (the last good one while kMoved)
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  // While kMoved: when, how (method), and the motion estimated (sensor frame, old from new).
  common::UtcNs flagged_ns = 0;
  std::string flag_method;
  Pose2 estimated_motion;
  std::string detail;  // the last verdict, for the live view and logs
  // Reference background and the sensor's expected pose relative to it.
  std::optional<daemon::BackgroundScan> reference;
  Pose2 reference_from_sensor;
  // Counters.
  std::uint64_t snapshots_checked = 0;
  std::uint64_t track_checks = 0;
  std::uint64_t moves = 0;
  std::uint64_t corrections = 0;
  std::uint64_t relearns = 0;
  // The largest chi^2 of a track check that could flag (after the baseline, against two or more
  // other sensors, not while re-learning after a move): how close the tracks of a sensor that
  // stays put come to tracks.min_chi2.
  double max_track_chi2 = 0.0;
  // Internal decision state.
  int track_strikes = 0;
  std::optional<daemon::BackgroundScan> pending_relearn;  // a changed scene awaiting the tracks
  common::UtcNs pending_relearn_ns = 0;
  std::optional<Pose2> background_candidate;  // a correction from a snapshot, awaiting checks
  double background_candidate_inliers = 0.0;
  Eigen::Matrix3d background_candidate_covariance = Eigen::Matrix3d::Zero();
  std::string background_candidate_detail;
  // The pose came from tracks: the first snapshot that aligns as a whole refines it.
  bool provisional = false;
  // Tracks before this time were taken at another pose (before the last move).
  common::UtcNs tracks_valid_from_ns = 0;
  // The tracks' own correction with the calibration's pose (see track_baseline_checks).
  Pose2 track_baseline;
  int baseline_checks = 0;
  Eigen::Vector3d baseline_sum = Eigen::Vector3d::Zero();
  // A settled snapshot refined the pose since the last flag: the tracks no longer refine it.
  bool background_refined = false;
  // Since the last flag: the pose in use when it was flagged, and the tracks'
  // own estimate of the new pose (kept apart from the snapshots': their errors are independent,
  // and each snapshot after a move is combined with it by covariance).
  Pose2 pose_before_move;
  std::optional<Pose2> tracks_estimate;
  Eigen::Matrix3d tracks_estimate_covariance = Eigen::Matrix3d::Zero();
};

class Monitor {
 public:
  // Precondition: Validate(options) (checked; aborts otherwise).
  explicit Monitor(const MonitorOptions& options);

  // New thresholds; the sensors' state is kept. Precondition: Validate(options) (checked).
  void SetOptions(const MonitorOptions& options);
  // A calibration: every sensor's pose. Sensors not listed are no longer watched. A sensor keeps
  // its reference background when `backgrounds` has none for it and its pose did not change; else
  // the given snapshot (or the next one received) becomes the reference.
  void SetPoses(const std::vector<SensorPose>& poses,
                const std::map<std::string, daemon::BackgroundScan>& backgrounds);
  // A new background snapshot of a watched sensor (call once per snapshot).
  void OnBackground(const std::string& sensor_id, const daemon::BackgroundScan& snapshot,
                    common::UtcNs now_ns);
  // Track checks and corrections when due.
  void Update(common::UtcNs now_ns, const FrameSource& frames);

  std::vector<MonitorEvent> TakeEvents();
  bool Excluded(const std::string& sensor_id) const;
  // The poses in use (flagged sensors included, at their last good pose), sorted by id.
  std::vector<SensorPose> Poses() const;
  const std::map<std::string, SensorWatch>& sensors() const { return sensors_; }
  const MonitorOptions& options() const { return options_; }

 private:
  void Flag(SensorWatch& watch, common::UtcNs now_ns, const std::string& method,
            const Pose2& motion, const std::string& detail);
  // `settled`: the sensor's background holds the whole new scene (fused again at once).
  void Correct(SensorWatch& watch, common::UtcNs now_ns, const std::string& method,
               const Pose2& world_from_sensor, const Eigen::Matrix3d& covariance,
               const std::string& detail, bool settled);
  // The pose after a motion (sensor frame) and its covariance: the old pose's plus the motion's,
  // rotated into the world.
  static Eigen::Matrix3d MovedCovariance(const SensorWatch& watch,
                                         const Eigen::Matrix3d& motion_covariance);
  // The pose a snapshot taken after the last move gives (`refinement` from the pose in use), with
  // the covariance of its lag (see background_time_constant_s), combined with the tracks'
  // estimate since the flag when there is one (an information-weighted mean).
  struct Refined {
    Pose2 world_from_sensor;
    Eigen::Matrix3d covariance;
    std::string detail;
    bool tracks_left_out = false;  // they disagreed (combine_max_chi2)
    double lag_m = 0.0;            // how far the snapshot may still lag the move
    double lag_rad = 0.0;
  };
  Refined RefineAfterMove(const SensorWatch& watch, const Pose2& refinement,
                          const Eigen::Matrix3d& refinement_covariance,
                          const BackgroundVerdict& verdict, common::UtcNs now_ns) const;
  std::vector<PlacedFrames> Others(
      const std::string& sensor_id,
      const std::map<std::string, std::vector<daemon::TrackFrameData>>& frames) const;
  void Emit(MonitorEventKind kind, const SensorWatch& watch, common::UtcNs stamp_ns,
            const std::string& method, const std::string& detail, std::optional<Pose2> before,
            std::optional<Pose2> after);

  MonitorOptions options_;
  std::map<std::string, SensorWatch> sensors_;
  std::vector<MonitorEvent> events_;
  common::UtcNs last_track_check_ns_ = 0;
};

}  // namespace lrfnet::monitoring
