#include "central_daemon/monitoring/monitor.h"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace lrfnet::monitoring {

namespace {

// Two estimates of a pose this close agree (a settled background).
constexpr double kAgreeYawDeg = 0.05;
constexpr double kAgreeTranslationM = 0.005;

common::UtcNs SecondsToNs(double s) { return static_cast<common::UtcNs>(std::llround(s * 1e9)); }

std::string MotionText(const Pose2& m) {
  return fmt::format("{:+.2f} deg, {:.3f} m", common::RadToDeg(m.yaw_rad),
                     std::hypot(m.x_m, m.y_m));
}

std::string PoseText(const Pose2& p) {
  return fmt::format("x {:.3f} m, y {:.3f} m, yaw {:.2f} deg", p.x_m, p.y_m,
                     common::RadToDeg(p.yaw_rad));
}

Eigen::Matrix3d Symmetric(const Eigen::Matrix3d& m) { return 0.5 * (m + m.transpose()); }

}  // namespace

const char* ToString(WatchState state) {
  switch (state) {
    case WatchState::kWatched:
      return "ok";
    case WatchState::kMoved:
      return "moved";
    case WatchState::kSettling:
      return "settling";
  }
  return "?";
}

const char* ToString(MonitorEventKind kind) {
  switch (kind) {
    case MonitorEventKind::kMoved:
      return "moved";
    case MonitorEventKind::kCorrected:
      return "corrected";
    case MonitorEventKind::kBackgroundRelearned:
      return "background_relearned";
  }
  return "?";
}

std::optional<std::string> Validate(const MonitorOptions& o) {
  if (auto e = Validate(o.background)) return "background." + *e;
  if (auto e = Validate(o.tracks)) return "tracks." + *e;
  const auto positive = [](double v, double hi) { return std::isfinite(v) && v > 0.0 && v <= hi; };
  if (!positive(o.track_window_s, 3600.0)) return "track_window_s must be in (0, 3600]";
  if (!positive(o.track_period_s, 3600.0)) return "track_period_s must be in (0, 3600]";
  if (o.track_confirmations < 1 || o.track_confirmations > 100) {
    return "track_confirmations must be in [1, 100]";
  }
  if (o.track_baseline_checks < 1 || o.track_baseline_checks > 1000) {
    return "track_baseline_checks must be in [1, 1000]";
  }
  if (!(o.correct_min_inliers >= 0.0 && o.correct_min_inliers <= 1.0)) {
    return "correct_min_inliers must be in [0, 1]";
  }
  if (!positive(o.check_max_yaw_sigma_deg, 180.0)) {
    return "check_max_yaw_sigma_deg must be in (0, 180]";
  }
  if (!positive(o.check_max_translation_sigma_m, 1000.0)) {
    return "check_max_translation_sigma_m must be in (0, 1000]";
  }
  if (!positive(o.correction_min_tracks_s, 3600.0)) {
    return "correction_min_tracks_s must be in (0, 3600]";
  }
  if (!(o.correction_max_tracks_s >= o.correction_min_tracks_s &&
        o.correction_max_tracks_s <= 3600)) {
    return "correction_max_tracks_s must be in [correction_min_tracks_s, 3600]";
  }
  if (!positive(o.correction_max_rms_m, 10.0)) return "correction_max_rms_m must be in (0, 10]";
  if (!(o.refine_max_yaw_deg >= 0.0 && o.refine_max_yaw_deg <= 180.0)) {
    return "refine_max_yaw_deg must be in [0, 180]";
  }
  if (!(o.refine_max_translation_m >= 0.0 && o.refine_max_translation_m <= 100.0)) {
    return "refine_max_translation_m must be in [0, 100]";
  }
  if (!(o.settled_min_inliers >= 0.0 && o.settled_min_inliers <= 1.0)) {
    return "settled_min_inliers must be in [0, 1]";
  }
  if (!positive(o.background_time_constant_s, 3600.0)) {
    return "background_time_constant_s must be in (0, 3600]";
  }
  if (!(o.background_absorb_after_s >= 0.0 && o.background_absorb_after_s <= 3600.0)) {
    return "background_absorb_after_s must be in [0, 3600]";
  }
  if (!positive(o.combine_max_chi2, 1e12)) return "combine_max_chi2 must be in (0, 1e12]";
  if (!(o.tracks_bias_sigma_m >= 0.0 && o.tracks_bias_sigma_m <= 10.0)) {
    return "tracks_bias_sigma_m must be in [0, 10]";
  }
  if (!(o.tracks_bias_sigma_deg >= 0.0 && o.tracks_bias_sigma_deg <= 180.0)) {
    return "tracks_bias_sigma_deg must be in [0, 180]";
  }
  if (!(o.relearn_hold_s >= 0.0 && o.relearn_hold_s <= 86400.0)) {
    return "relearn_hold_s must be in [0, 86400]";
  }
  return std::nullopt;
}

Monitor::Monitor(const MonitorOptions& options) : options_(options) {
  if (auto e = Validate(options)) {
    std::fprintf(stderr, "Monitor: invalid options: %s\n", e->c_str());
    std::abort();
  }
}

void Monitor::SetOptions(const MonitorOptions& options) {
  if (auto e = Validate(options)) {
    std::fprintf(stderr, "Monitor: invalid options: %s\n", e->c_str());
    std::abort();
  }
  options_ = options;
}

void Monitor::SetPoses(const std::vector<SensorPose>& poses,
                       const std::map<std::string, daemon::BackgroundScan>& backgrounds) {
  std::map<std::string, SensorWatch> next;
  for (const SensorPose& p : poses) {
    SensorWatch watch;
    const auto old = sensors_.find(p.id);
    const bool same_pose =
        old != sensors_.end() &&
        common::TranslationDistanceM(old->second.world_from_sensor, p.world_from_sensor) < 1e-9 &&
        common::RotationDistanceRad(old->second.world_from_sensor, p.world_from_sensor) < 1e-12;
    if (old != sensors_.end()) {
      // Counters go on; the decision state starts again from the new pose.
      watch.snapshots_checked = old->second.snapshots_checked;
      watch.track_checks = old->second.track_checks;
      watch.moves = old->second.moves;
      watch.corrections = old->second.corrections;
      watch.relearns = old->second.relearns;
      watch.max_track_chi2 = old->second.max_track_chi2;
      if (same_pose && old->second.state == WatchState::kWatched) {
        watch.reference = old->second.reference;
        watch.reference_from_sensor = old->second.reference_from_sensor;
      }
    }
    watch.id = p.id;
    watch.world_from_sensor = p.world_from_sensor;
    watch.covariance = p.covariance;
    if (const auto b = backgrounds.find(p.id); b != backgrounds.end()) {
      watch.reference = b->second;
      watch.reference_from_sensor = Pose2::Identity();
    }
    next.emplace(p.id, std::move(watch));
  }
  sensors_ = std::move(next);
}

void Monitor::OnBackground(const std::string& sensor_id, const daemon::BackgroundScan& snapshot,
                           common::UtcNs now_ns) {
  const auto it = sensors_.find(sensor_id);
  if (it == sensors_.end()) return;
  SensorWatch& watch = it->second;
  if (!watch.reference) {
    // The first snapshot since the pose was set: the reference, unless it cannot be used.
    if (!calib::CheckBackground(snapshot)) {
      watch.reference = snapshot;
      watch.reference_from_sensor = Pose2::Identity();
      watch.detail = "reference background taken";
    }
    return;
  }
  ++watch.snapshots_checked;
  const BackgroundVerdict v = CheckBackgrounds(
      *watch.reference, snapshot, options_.background,
      watch.state == WatchState::kMoved ? watch.reference_from_sensor * watch.estimated_motion
                                        : watch.reference_from_sensor);
  watch.detail = std::string("background: ") + ToString(v.kind) + ": " + v.reason;
  if (v.kind == BackgroundVerdictKind::kUnusable) return;

  if (watch.state == WatchState::kMoved) {
    // A snapshot that aligns with the reference as a whole gives the pose (checked against the
    // tracks in Update); a partial one refines the estimate only.
    const Pose2 motion = watch.reference_from_sensor.inverse() * v.reference_from_current;
    // Short of settled_min_inliers the snapshot mixes the old scene (the nearer returns the
    // tracker keeps as foreground until absorb_after_s) with the new one, and the whole-scene
    // motion falls between the two: a candidate only when the tracks can check it to within the
    // correction's bounds (Update), a changed-part estimate otherwise.
    const bool whole = v.inliers_after >= options_.settled_min_inliers;
    if (v.inliers_after >= options_.correct_min_inliers && !v.partial &&
        v.kind != BackgroundVerdictKind::kSceneChanged) {
      watch.background_candidate = motion;
      watch.background_candidate_inliers = v.inliers_after;
      watch.background_candidate_covariance = v.covariance;
      watch.background_candidate_detail = v.reason;
    } else if (v.kind == BackgroundVerdictKind::kMoved && (v.partial || whole)) {
      watch.estimated_motion = motion;
    }
    return;
  }

  // After a move the tracker re-learns its background beam by beam (see background_check.h):
  // until a snapshot holds the whole new scene, its verdicts are about the tracker, not the
  // sensor. Such a settled snapshot refines a pose that came from tracks.
  const bool settling = watch.tracks_valid_from_ns != 0 &&
                        now_ns - watch.tracks_valid_from_ns < SecondsToNs(options_.relearn_hold_s);
  const bool settled = !v.partial && v.kind != BackgroundVerdictKind::kSceneChanged &&
                       v.inliers_after >= options_.settled_min_inliers &&
                       v.inliers_after >= v.inliers_before;
  // Where the sensor is: the whole scene's ICP pose, also where the expectation kept a few more
  // points within inlier_distance_m (see BackgroundVerdict::fit_share; the expectation is often
  // the tracks' pose, and a count of points cannot tell it from one a few tenths of a degree off).
  const bool use_fit = v.fit_found && !v.partial && v.fit_share >= options_.correct_min_inliers;
  const Pose2 refinement = watch.reference_from_sensor.inverse() *
                           (use_fit ? v.fit_reference_from_current : v.reference_from_current);
  const bool within_refinement =
      std::abs(common::RadToDeg(refinement.yaw_rad)) <= options_.refine_max_yaw_deg &&
      std::hypot(refinement.x_m, refinement.y_m) <= options_.refine_max_translation_m;
  // After a move every snapshot that aligns with the reference scene as a whole refines the pose,
  // whatever the verdict says of the motion's significance (the question here is where the sensor
  // is, not whether it moved): within relearn_hold_s of the move (a settled snapshot may still
  // hold a few old returns, or lag the move: see background_time_constant_s) and, for a pose from
  // tracks, until one agrees with it. Each refinement takes the newest snapshot, combined with the
  // tracks' estimate since the flag by covariance; a snapshot short of settled_min_inliers counts
  // only that way (its unabsorbed old returns are in its covariance). A motion beyond the
  // refinement bounds is a new move, judged below.
  const bool aligned_whole = !v.partial && v.inliers_after >= v.inliers_before &&
                             v.inliers_after >= options_.correct_min_inliers;
  const bool whole_settled = aligned_whole && v.inliers_after >= options_.settled_min_inliers;
  const bool usable = whole_settled || (aligned_whole && watch.tracks_estimate.has_value());
  if ((settling || watch.provisional) && usable && (watch.provisional || within_refinement)) {
    const bool was_provisional = watch.provisional;
    Refined refined =
        RefineAfterMove(watch, refinement, use_fit ? v.fit_covariance : v.covariance, v, now_ns);
    if (use_fit && v.fit_share < v.inliers_after) {
      refined.detail += fmt::format(
          " (the ICP's pose, {:.1f}% of the points on the scene there; {:.1f}% at the expected "
          "one)",
          100.0 * v.fit_share, 100.0 * v.inliers_after);
    }
    const Pose2 change = watch.world_from_sensor.inverse() * refined.world_from_sensor;
    const bool agrees = std::abs(common::RadToDeg(change.yaw_rad)) <= kAgreeYawDeg &&
                        std::hypot(change.x_m, change.y_m) <= kAgreeTranslationM;
    // Agreement says the tracker's background stopped changing only once it can no longer lag
    // the move by more than agreement (a lagging background changes by little per snapshot):
    // until then each snapshot refines a pose from tracks.
    const bool lag_small =
        common::RadToDeg(refined.lag_rad) <= kAgreeYawDeg && refined.lag_m <= kAgreeTranslationM;
    if (refined.tracks_left_out) watch.tracks_estimate.reset();
    if (!agrees || (was_provisional && !lag_small)) {
      Correct(watch, now_ns, "background", refined.world_from_sensor, refined.covariance,
              "refined by the background: " + refined.detail, whole_settled);
      // A pose from tracks is refined until a snapshot agrees with it: the tracker's background
      // has then stopped changing.
      watch.provisional = was_provisional;
    } else {
      if (lag_small) watch.provisional = false;
      if (watch.state == WatchState::kSettling && whole_settled) {
        watch.state = WatchState::kWatched;
      }
    }
    watch.background_refined = true;
    return;
  }
  if (watch.state == WatchState::kSettling && settled) {
    watch.state = WatchState::kWatched;
  }
  if (settling && !settled) return;

  switch (v.kind) {
    case BackgroundVerdictKind::kMoved: {
      const Pose2 motion = v.motion;
      Flag(watch, now_ns, v.partial ? "background (changed part)" : "background", motion, v.reason);
      // A snapshot that already holds the whole new scene is the correction too (checked by the
      // tracks in Update when it holds less than settled_min_inliers of it).
      if (!v.partial && v.inliers_after >= options_.correct_min_inliers) {
        watch.background_candidate = motion;
        watch.background_candidate_inliers = v.inliers_after;
        watch.background_candidate_covariance = v.covariance;
        watch.background_candidate_detail = v.reason;
      }
      break;
    }
    case BackgroundVerdictKind::kSceneChanged:
      if (options_.relearn_background) {
        watch.pending_relearn = snapshot;
        watch.pending_relearn_ns = now_ns;
      }
      break;
    case BackgroundVerdictKind::kUnchanged:
      watch.pending_relearn.reset();
      // After a correction the reference is still the old snapshot with the motion expected; a
      // settled snapshot that agrees with that replaces it. So does one that follows a tracker's
      // first snapshot of a session, which it sends as soon as it has learned (from the farthest
      // stable returns: a few centimetres too far until its background has settled).
      if (settled &&
          (watch.reference->snapshot_id == 0 ||
           !(watch.reference_from_sensor.x_m == 0.0 && watch.reference_from_sensor.y_m == 0.0 &&
             watch.reference_from_sensor.yaw_rad == 0.0))) {
        watch.reference = snapshot;
        watch.reference_from_sensor = Pose2::Identity();
      }
      break;
    case BackgroundVerdictKind::kUnusable:
      break;
  }
}

std::vector<PlacedFrames> Monitor::Others(
    const std::string& sensor_id,
    const std::map<std::string, std::vector<daemon::TrackFrameData>>& frames) const {
  std::vector<PlacedFrames> out;
  for (const auto& [id, watch] : sensors_) {
    if (id == sensor_id || watch.state != WatchState::kWatched) continue;
    const auto f = frames.find(id);
    if (f == frames.end() || f->second.empty()) continue;
    out.push_back({id, watch.world_from_sensor, &f->second});
  }
  return out;
}

void Monitor::Update(common::UtcNs now_ns, const FrameSource& source) {
  if (sensors_.empty()) return;
  const common::UtcNs period_ns = SecondsToNs(options_.track_period_s);
  if (last_track_check_ns_ != 0 && now_ns >= last_track_check_ns_ &&
      now_ns - last_track_check_ns_ < period_ns) {
    return;
  }
  last_track_check_ns_ = now_ns;
  const common::UtcNs window_ns = SecondsToNs(options_.track_window_s);
  const common::UtcNs from_ns = now_ns > window_ns ? now_ns - window_ns : 0;
  std::map<std::string, std::vector<daemon::TrackFrameData>> window;
  for (auto& [id, watch] : sensors_) {
    // A corrected sensor whose tracker has had relearn_hold_s to re-learn is fused again.
    if (watch.state == WatchState::kSettling &&
        now_ns - watch.flagged_ns >= SecondsToNs(options_.relearn_hold_s)) {
      watch.state = WatchState::kWatched;
    }
    if (watch.state != WatchState::kMoved) {
      window[id] = source.Frames(id, std::max(from_ns, watch.tracks_valid_from_ns), now_ns + 1);
    }
  }

  // The sensor to flag by its tracks this round: the most significant of those confirmed.
  SensorWatch* to_flag = nullptr;
  TrackFit flag_fit;
  for (auto& [id, watch] : sensors_) {
    if (watch.state != WatchState::kMoved) {
      const std::vector<PlacedFrames> others = Others(id, window);
      if (others.empty()) continue;
      ++watch.track_checks;
      TrackFit fit = CheckTracks(window[id], watch.world_from_sensor, others, options_.tracks,
                                 watch.track_baseline);
      if (watch.baseline_checks < options_.track_baseline_checks) {
        // Learning what "nothing moved" looks like to the tracks.
        if (fit.enough && fit.rms_m <= options_.tracks.max_fit_rms_m &&
            fit.matches >= 2 * options_.tracks.min_matches) {
          watch.baseline_sum +=
              Eigen::Vector3d(fit.correction.x_m, fit.correction.y_m, fit.correction.yaw_rad);
          ++watch.baseline_checks;
          const Eigen::Vector3d mean = watch.baseline_sum / watch.baseline_checks;
          watch.track_baseline = Pose2{mean.x(), mean.y(), mean.z()};
        }
        continue;
      }
      if (fit.enough && !fit.moved && fit.rms_m > options_.tracks.max_fit_rms_m) {
        // The residuals disagree within the window: a move inside it leaves the tracks before it
        // and after it at two poses (after 5 degrees, half a metre apart at 6 m), which no rigid
        // correction fits. The newest half of the window alone, tested against its own (larger)
        // covariance.
        const common::UtcNs half_from_ns = now_ns - window_ns / 2;
        std::map<std::string, std::vector<daemon::TrackFrameData>> recent;
        for (const auto& [other_id, frames] : window) {
          auto& kept = recent[other_id];
          for (const daemon::TrackFrameData& f : frames) {
            if (f.scan_start_ns >= half_from_ns) kept.push_back(f);
          }
        }
        const std::vector<PlacedFrames> recent_others = Others(id, recent);
        if (recent_others.size() >= 2) {
          TrackFit tail = CheckTracks(recent[id], watch.world_from_sensor, recent_others,
                                      options_.tracks, watch.track_baseline);
          if (tail.moved) {
            tail.reason += " (the newest half of the window)";
            fit = tail;
          }
        }
      }
      if (fit.moved && watch.provisional && !watch.background_refined &&
          fit.rms_m <= options_.correction_max_rms_m &&
          std::abs(common::RadToDeg(fit.correction.yaw_rad)) <= options_.refine_max_yaw_deg &&
          std::hypot(fit.correction.x_m, fit.correction.y_m) <= options_.refine_max_translation_m) {
        // The same move, estimated better from more (and cleaner) tracks.
        Correct(watch, now_ns, "tracks", fit.world_from_sensor * watch.track_baseline.inverse(),
                Symmetric(fit.covariance), "refined: " + fit.reason, false);
        watch.provisional = true;
        continue;
      }
      // Within relearn_hold_s of its last move the sensor's tracker is still re-learning its
      // background (wall pieces merge with people near them): only a new bump beyond the
      // refinement bounds counts then; the background watches the rest.
      const bool settling =
          watch.tracks_valid_from_ns != 0 &&
          now_ns - watch.tracks_valid_from_ns < SecondsToNs(options_.relearn_hold_s);
      const Pose2 motion = watch.track_baseline.inverse() * fit.correction;
      const bool beyond_refinement =
          std::abs(common::RadToDeg(motion.yaw_rad)) > options_.refine_max_yaw_deg ||
          std::hypot(motion.x_m, motion.y_m) > options_.refine_max_translation_m;
      if (fit.enough && others.size() >= 2 && !settling) {
        watch.max_track_chi2 = std::max(watch.max_track_chi2, fit.chi2);
      }
      // With one other sensor, a disagreement does not say which of the two moved.
      if (fit.moved && others.size() >= 2 && (!settling || beyond_refinement)) {
        if (++watch.track_strikes >= options_.track_confirmations &&
            (to_flag == nullptr || fit.chi2 > flag_fit.chi2)) {
          to_flag = &watch;
          flag_fit = fit;
          // The motion since "nothing moved".
          flag_fit.correction = watch.track_baseline.inverse() * fit.correction;
        }
      } else if (fit.enough) {
        watch.track_strikes = 0;
        // The tracks agree (a clean fit, no motion to speak of): a changed scene is furniture,
        // not a move.
        const bool agree =
            fit.rms_m <= options_.tracks.max_fit_rms_m && fit.chi2 < options_.tracks.min_chi2 &&
            std::abs(common::RadToDeg(motion.yaw_rad)) < options_.tracks.min_yaw_deg &&
            std::hypot(motion.x_m, motion.y_m) < options_.tracks.min_translation_m;
        if (agree && watch.pending_relearn && watch.pending_relearn_ns <= now_ns) {
          watch.reference = *watch.pending_relearn;
          watch.reference_from_sensor = Pose2::Identity();
          watch.pending_relearn.reset();
          ++watch.relearns;
          Emit(MonitorEventKind::kBackgroundRelearned, watch, now_ns, "tracks",
               "the scene changed, the tracks agree with the pose (" + fit.reason +
                   "): the reference background is re-learned",
               std::nullopt, std::nullopt);
        }
      }
      continue;
    }

    // kMoved: correct from the background, checked by the tracks when they can; else from the
    // tracks since the flag (the sensor's and the others', each from when its pose holds).
    const common::UtcNs max_ns = SecondsToNs(options_.correction_max_tracks_s);
    const common::UtcNs since_ns =
        std::max(watch.flagged_ns, now_ns > max_ns ? now_ns - max_ns : 0);
    const std::vector<daemon::TrackFrameData> own = source.Frames(id, since_ns, now_ns + 1);
    std::map<std::string, std::vector<daemon::TrackFrameData>> fresh;
    for (const auto& [other_id, other] : sensors_) {
      if (other_id != id && other.state == WatchState::kWatched) {
        fresh[other_id] =
            source.Frames(other_id, std::max(since_ns, other.tracks_valid_from_ns), now_ns + 1);
      }
    }
    const std::vector<PlacedFrames> others = Others(id, fresh);
    if (watch.background_candidate) {
      const Pose2 candidate = watch.world_from_sensor * *watch.background_candidate;
      const TrackFit check = others.empty() ? TrackFit{}
                                            : CheckTracks(own, candidate, others, options_.tracks,
                                                          watch.track_baseline);
      // Only a snapshot that holds the whole new scene gives the pose on its own: one taken while
      // the tracker re-learns its background mixes the old scene and the new, and its motion falls
      // between the two (by a degree after a 2 degree turn, which a few seconds of tracks cannot
      // tell from nothing at chi^2 < min_chi2). Such a snapshot counts only when the tracks place
      // the sensor to within check_max_yaw_sigma_deg / check_max_translation_sigma_m (one
      // standard deviation) and put it within twice that of the snapshot's pose.
      const bool mixed = watch.background_candidate_inliers < options_.settled_min_inliers;
      bool confirmed = false;
      if (check.enough) {
        const double yaw_bound_rad = common::DegToRad(options_.check_max_yaw_sigma_deg);
        const double shift_bound_m = options_.check_max_translation_sigma_m;
        const Pose2 off =
            candidate.inverse() * check.world_from_sensor * watch.track_baseline.inverse();
        confirmed =
            std::sqrt(std::max(0.0, check.covariance(2, 2))) <= yaw_bound_rad &&
            std::sqrt(std::max(0.0, std::max(check.covariance(0, 0), check.covariance(1, 1)))) <=
                shift_bound_m &&
            std::abs(off.yaw_rad) <= 2.0 * yaw_bound_rad &&
            std::hypot(off.x_m, off.y_m) <= 2.0 * shift_bound_m;
      }
      if (!check.moved && (!mixed || confirmed)) {
        Correct(watch, now_ns, "background", candidate,
                MovedCovariance(watch, watch.background_candidate_covariance),
                watch.background_candidate_detail +
                    (check.enough ? "; the tracks agree (" + check.reason + ")"
                                  : "; too few tracks since the move to check it"),
                watch.background_candidate_inliers >= options_.settled_min_inliers);
        continue;
      }
      if (check.moved) {
        watch.detail = "the background suggests " + MotionText(*watch.background_candidate) +
                       ", the tracks disagree: " + check.reason;
        watch.background_candidate.reset();
      } else {
        watch.detail = "the background suggests " + MotionText(*watch.background_candidate) +
                       " from a snapshot that still mixes the old scene with the new, waiting "
                       "for a settled snapshot or the tracks" +
                       (check.enough ? " (" + check.reason + ")" : "");
      }
    }
    if (others.empty() || own.empty()) continue;
    const double tracked_s =
        static_cast<double>(own.back().scan_start_ns - own.front().scan_start_ns) * 1e-9;
    if (tracked_s < options_.correction_min_tracks_s) continue;
    const TrackFit fit = EstimateFromTracks(
        own, watch.world_from_sensor * watch.estimated_motion * watch.track_baseline, others,
        options_.tracks, watch.track_baseline);
    if (!fit.enough || fit.rms_m > options_.correction_max_rms_m) {
      watch.detail = "waiting for tracks to correct the pose: " + fit.reason;
      continue;
    }
    Correct(watch, now_ns, "tracks", fit.world_from_sensor * watch.track_baseline.inverse(),
            Symmetric(fit.covariance),
            fit.reason + (fit.from_search ? " (searched from scratch)" : ""), false);
    watch.provisional = true;
  }
  if (to_flag != nullptr) {
    Flag(*to_flag, now_ns, "tracks", flag_fit.correction, flag_fit.reason);
  }
  for (auto& [id, watch] : sensors_) {
    if (watch.state == WatchState::kWatched && &watch != to_flag && watch.track_strikes > 0 &&
        to_flag != nullptr) {
      // Their strikes may come from the flagged sensor's tracks; count again without them.
      watch.track_strikes = 0;
    }
  }
}

Monitor::Refined Monitor::RefineAfterMove(const SensorWatch& watch, const Pose2& refinement,
                                          const Eigen::Matrix3d& refinement_covariance,
                                          const BackgroundVerdict& v, common::UtcNs now_ns) const {
  const Pose2 snapshot_pose = watch.world_from_sensor * refinement;
  // The lag: beams whose range changed by less than the tracker's margin follow the change with
  // its time constant (a share exp(-t / tau) of the move left after t seconds; the flag comes
  // after the move, so t from the flag bounds it from below), and until the tracker absorbs
  // nearer returns the points off the scene may be old ones, each pulling the motion towards the
  // old pose (at most their share of it).
  const double since_flag_s = std::max(0.0, static_cast<double>(now_ns - watch.flagged_ns) * 1e-9);
  const double lag = std::exp(-since_flag_s / options_.background_time_constant_s) +
                     (since_flag_s < options_.background_absorb_after_s
                          ? std::clamp(1.0 - v.inliers_after, 0.0, 1.0)
                          : 0.0);
  const Pose2 move = watch.pose_before_move.inverse() * snapshot_pose;
  const double lag_m = lag * std::hypot(move.x_m, move.y_m);
  const double lag_rad = lag * std::abs(move.yaw_rad);
  Eigen::Matrix3d motion_covariance = refinement_covariance;
  motion_covariance(0, 0) += lag_m * lag_m;
  motion_covariance(1, 1) += lag_m * lag_m;
  motion_covariance(2, 2) += lag_rad * lag_rad;
  Eigen::Matrix3d j = Eigen::Matrix3d::Identity();
  j.topLeftCorner<2, 2>() = watch.world_from_sensor.rotation();
  const Eigen::Matrix3d snapshot_covariance = Symmetric(j * motion_covariance * j.transpose());
  Refined out{snapshot_pose, MovedCovariance(watch, refinement_covariance),
              fmt::format("{:.0f}% of {} points on the reference scene after a motion of {} "
                          "({:.1f} s after the flag, lag up to {:.0f}% of the move)",
                          100.0 * v.inliers_after, v.points, MotionText(refinement), since_flag_s,
                          100.0 * lag)};
  out.lag_m = lag_m;
  out.lag_rad = lag_rad;
  if (!watch.tracks_estimate) return out;
  // The information-weighted mean of the snapshot's pose and the tracks' (independent errors).
  const Pose2& tracks = *watch.tracks_estimate;
  const Eigen::Matrix3d sum = snapshot_covariance + watch.tracks_estimate_covariance;
  const Eigen::Vector3d difference(tracks.x_m - snapshot_pose.x_m, tracks.y_m - snapshot_pose.y_m,
                                   common::AngleDiff(tracks.yaw_rad, snapshot_pose.yaw_rad));
  const Eigen::LDLT<Eigen::Matrix3d> ldlt(sum);
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0.0)) {
    return out;
  }
  const double chi2 = difference.dot(ldlt.solve(difference));
  if (!(chi2 <= options_.combine_max_chi2)) {
    // They disagree beyond both covariances: the tracks are bent (a tracker re-learning its
    // background merges wall pieces with people), the scene as a whole is not.
    out.detail += fmt::format(
        ", the tracks' estimate {:+.2f} deg, {:.3f} m from it left out (chi2 {:.0f})",
        common::RadToDeg(difference.z()), std::hypot(difference.x(), difference.y()), chi2);
    out.tracks_left_out = true;
    return out;
  }
  const Eigen::Matrix3d gain = snapshot_covariance * ldlt.solve(Eigen::Matrix3d::Identity());
  const Eigen::Vector3d step = gain * difference;
  out.world_from_sensor = Pose2{snapshot_pose.x_m + step.x(), snapshot_pose.y_m + step.y(),
                                common::NormalizeAngle(snapshot_pose.yaw_rad + step.z())};
  // The combination's covariance only weighs and judges; the pose keeps the one any snapshot's
  // correction gives (the fused filter takes it as the prior of what it learns of the sensor).
  out.covariance = MovedCovariance(watch, refinement_covariance);
  out.detail +=
      fmt::format(", combined with the tracks' estimate {:+.2f} deg, {:.3f} m from it",
                  common::RadToDeg(difference.z()), std::hypot(difference.x(), difference.y()));
  return out;
}

Eigen::Matrix3d Monitor::MovedCovariance(const SensorWatch& watch,
                                         const Eigen::Matrix3d& motion_covariance) {
  Eigen::Matrix3d j = Eigen::Matrix3d::Identity();
  j.topLeftCorner<2, 2>() = watch.world_from_sensor.rotation();
  return Symmetric(watch.covariance + j * motion_covariance * j.transpose());
}

void Monitor::Flag(SensorWatch& watch, common::UtcNs now_ns, const std::string& method,
                   const Pose2& motion, const std::string& detail) {
  watch.state = WatchState::kMoved;
  watch.flagged_ns = now_ns;
  watch.flag_method = method;
  watch.estimated_motion = motion;
  watch.track_strikes = 0;
  watch.pending_relearn.reset();
  watch.background_candidate.reset();
  watch.background_refined = false;
  watch.pose_before_move = watch.world_from_sensor;
  watch.tracks_estimate.reset();
  watch.detail = detail;
  ++watch.moves;
  // The others' track checks compared them with this sensor's tracks too: count again without.
  for (auto& [id, other] : sensors_) other.track_strikes = 0;
  Emit(MonitorEventKind::kMoved, watch, now_ns, method,
       "moved by about " + MotionText(motion) + ": " + detail, watch.world_from_sensor,
       watch.world_from_sensor * motion);
}

void Monitor::Correct(SensorWatch& watch, common::UtcNs now_ns, const std::string& method,
                      const Pose2& world_from_sensor, const Eigen::Matrix3d& covariance,
                      const std::string& detail, bool settled) {
  const Pose2 before = watch.world_from_sensor;
  // The reference snapshot stays, with the motion since it expected (see the header comment).
  watch.reference_from_sensor =
      watch.reference_from_sensor * (before.inverse() * world_from_sensor);
  if (watch.state == WatchState::kMoved) watch.tracks_valid_from_ns = watch.flagged_ns;
  watch.world_from_sensor = world_from_sensor;
  watch.covariance = covariance;
  if (method == "tracks") {
    // Tracks since a flag come from a tracker that re-learns its background: besides their
    // noise they share a bend of unknown size (see tracks_bias_sigma_m).
    watch.tracks_estimate = world_from_sensor;
    watch.tracks_estimate_covariance = covariance;
    const double bias_rad = common::DegToRad(options_.tracks_bias_sigma_deg);
    watch.tracks_estimate_covariance(0, 0) +=
        options_.tracks_bias_sigma_m * options_.tracks_bias_sigma_m;
    watch.tracks_estimate_covariance(1, 1) +=
        options_.tracks_bias_sigma_m * options_.tracks_bias_sigma_m;
    watch.tracks_estimate_covariance(2, 2) += bias_rad * bias_rad;
  }
  // Fused again once its tracker has re-learned its background (see kSettling).
  if (settled) {
    watch.state = WatchState::kWatched;
  } else if (watch.state == WatchState::kMoved) {
    watch.state = WatchState::kSettling;
  }
  watch.provisional = false;
  watch.background_candidate.reset();
  watch.estimated_motion = Pose2::Identity();
  watch.track_strikes = 0;
  watch.detail = "corrected (" + method + ")";
  ++watch.corrections;
  Emit(MonitorEventKind::kCorrected, watch, now_ns, method,
       "pose corrected by " + MotionText(before.inverse() * world_from_sensor) + " to " +
           PoseText(world_from_sensor) + ": " + detail,
       before, world_from_sensor);
}

void Monitor::Emit(MonitorEventKind kind, const SensorWatch& watch, common::UtcNs stamp_ns,
                   const std::string& method, const std::string& detail,
                   std::optional<Pose2> before, std::optional<Pose2> after) {
  MonitorEvent e;
  e.kind = kind;
  e.sensor_id = watch.id;
  e.stamp_ns = stamp_ns;
  e.method = method;
  e.detail = detail;
  e.before = before;
  e.after = after;
  events_.push_back(std::move(e));
  // Bounded: a caller that never takes them loses the oldest.
  if (events_.size() > 1000) events_.erase(events_.begin());
}

std::vector<MonitorEvent> Monitor::TakeEvents() {
  std::vector<MonitorEvent> out;
  out.swap(events_);
  return out;
}

bool Monitor::Excluded(const std::string& sensor_id) const {
  const auto it = sensors_.find(sensor_id);
  return it != sensors_.end() && it->second.state != WatchState::kWatched;
}

std::vector<SensorPose> Monitor::Poses() const {
  std::vector<SensorPose> out;
  for (const auto& [id, watch] : sensors_) {
    out.push_back({id, watch.world_from_sensor, watch.covariance});
  }
  return out;
}

}  // namespace lrfnet::monitoring
