#include "central_daemon/monitoring/monitor.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>

#include "central_daemon/monitoring/monitoring_test_util.h"

namespace lrfnet::monitoring {
namespace {

using testing::Room;
using testing::Snapshot;
using testing::TwoPeople;

constexpr common::UtcNs kStart = 1'700'000'000'000'000'000;
const Pose2 kS1{0.3, 0.3, common::DegToRad(40.0)};
const Pose2 kS2{11.7, 0.3, common::DegToRad(140.0)};
const Pose2 kS3{11.7, 7.7, common::DegToRad(-140.0)};

common::UtcNs At(double t_s) {
  return kStart + static_cast<common::UtcNs>(std::llround(t_s * 1e9));
}

// The frames of three sensors watching two people for `duration_s`; s2 stands at its pose of the
// time (poses_s2: (from_s, pose), increasing).
class FakeFrames final : public FrameSource {
 public:
  FakeFrames(double duration_s, const std::vector<std::pair<double, Pose2>>& poses_s2) {
    frames_["s1"] = testing::Frames(TwoPeople(), kS1, 0, duration_s, kStart, 11, 1);
    frames_["s3"] = testing::Frames(TwoPeople(), kS3, 0, duration_s, kStart, 13, 3);
    auto& s2 = frames_["s2"];
    for (std::size_t i = 0; i < poses_s2.size(); ++i) {
      const double to = i + 1 < poses_s2.size() ? poses_s2[i + 1].first : duration_s;
      for (auto& f : testing::Frames(TwoPeople(), poses_s2[i].second, poses_s2[i].first, to, kStart,
                                     12, static_cast<std::uint32_t>(2 + i))) {
        s2.push_back(std::move(f));
      }
    }
  }
  std::vector<daemon::TrackFrameData> Frames(const std::string& id, common::UtcNs from_ns,
                                             common::UtcNs to_ns) const override {
    std::vector<daemon::TrackFrameData> out;
    const auto it = frames_.find(id);
    if (it == frames_.end()) return out;
    for (const auto& f : it->second) {
      if (f.scan_start_ns >= from_ns && f.scan_start_ns < to_ns) out.push_back(f);
    }
    return out;
  }

 private:
  std::map<std::string, std::vector<daemon::TrackFrameData>> frames_;
};

std::vector<SensorPose> Calibrated() {
  return {{"s1", kS1, Eigen::Matrix3d::Identity() * 1e-6},
          {"s2", kS2, Eigen::Matrix3d::Identity() * 1e-6},
          {"s3", kS3, Eigen::Matrix3d::Identity() * 1e-6}};
}

std::map<std::string, daemon::BackgroundScan> References() {
  return {{"s1", Snapshot(Room(), kS1, 0.005, 1)},
          {"s2", Snapshot(Room(), kS2, 0.005, 2)},
          {"s3", Snapshot(Room(), kS3, 0.005, 3)}};
}

const SensorWatch& Watch(const Monitor& m, const std::string& id) { return m.sensors().at(id); }

TEST(Monitor, ABumpedSensorIsFlaggedExcludedAndCorrectedFromItsBackground) {
  Monitor monitor(MonitorOptions{});
  monitor.SetPoses(Calibrated(), References());
  const Pose2 bumped = kS2 * Pose2{0.05, 0.1, common::DegToRad(2.0)};
  const FakeFrames frames(40.0, {{0.0, kS2}, {20.0, bumped}});
  for (double t = 1.0; t <= 20.0; t += 1.0) monitor.Update(At(t), frames);
  EXPECT_TRUE(monitor.TakeEvents().empty()) << "a false flag before the bump";
  EXPECT_FALSE(monitor.Excluded("s2"));

  // The first snapshot after the bump: flagged at once, with the motion, left out.
  monitor.OnBackground("s2", Snapshot(Room(), bumped, 0.005, 9, 2), At(21.0));
  EXPECT_TRUE(monitor.Excluded("s2"));
  std::vector<MonitorEvent> events = monitor.TakeEvents();
  ASSERT_GE(events.size(), 1u);
  EXPECT_EQ(events[0].kind, MonitorEventKind::kMoved);
  EXPECT_EQ(events[0].sensor_id, "s2");
  EXPECT_EQ(events[0].stamp_ns, At(21.0));
  EXPECT_EQ(events[0].method, "background");
  ASSERT_TRUE(events[0].after.has_value());
  EXPECT_LT(common::TranslationDistanceM(*events[0].after, bumped), 0.01);
  // The whole new scene was in it: corrected at the next update, and fused again.
  monitor.Update(At(22.0), frames);
  events = monitor.TakeEvents();
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].kind, MonitorEventKind::kCorrected);
  EXPECT_EQ(events[0].method, "background");
  EXPECT_FALSE(monitor.Excluded("s2"));
  const Pose2 corrected = Watch(monitor, "s2").world_from_sensor;
  EXPECT_LT(common::TranslationDistanceM(corrected, bumped), 0.01);
  EXPECT_LT(common::RadToDeg(common::RotationDistanceRad(corrected, bumped)), 0.05);
  // The others never moved, and s2 at its new pose agrees with them from now on.
  for (double t = 23.0; t <= 40.0; t += 1.0) monitor.Update(At(t), frames);
  monitor.OnBackground("s2", Snapshot(Room(), bumped, 0.005, 10, 3), At(40.0));
  EXPECT_TRUE(monitor.TakeEvents().empty());
  EXPECT_EQ(Watch(monitor, "s1").world_from_sensor.x_m, kS1.x_m);
  EXPECT_EQ(Watch(monitor, "s2").moves, 1u);
}

// What a tracker sends while it re-learns its background after a move: the new scene where it is
// farther than the old one (re-learned within seconds), the old one where it is nearer (taken for
// foreground until absorbed).
daemon::BackgroundScan Mixed(const daemon::BackgroundScan& old_scene,
                             const daemon::BackgroundScan& new_scene) {
  daemon::BackgroundScan b = new_scene;
  for (std::size_t i = 0; i < b.ranges_mm.size(); ++i) {
    b.ranges_mm[i] = std::max(old_scene.ranges_mm[i], new_scene.ranges_mm[i]);
  }
  return b;
}

TEST(Monitor, SnapshotsThatMixTheOldSceneWithTheNewNeverSetAWrongPose) {
  Monitor monitor(MonitorOptions{});
  monitor.SetPoses(Calibrated(), References());
  const Pose2 bumped = kS2 * Pose2{0.0, 0.0, common::DegToRad(2.0)};
  const FakeFrames frames(120.0, {{0.0, kS2}, {20.0, bumped}});
  for (double t = 1.0; t <= 20.0; t += 1.0) monitor.Update(At(t), frames);
  ASSERT_TRUE(monitor.TakeEvents().empty());
  const daemon::BackgroundScan old_scene = Snapshot(Room(), kS2, 0.005, 20, 2);
  // Mixed snapshots every 2 s for 30 s (the tracker's absorb_after_s), then the settled scene.
  std::uint32_t id = 2;
  bool flagged = false;
  for (double t = 21.0; t <= 80.0; t += 1.0) {
    if (static_cast<int>(t) % 2 == 1) {
      const daemon::BackgroundScan new_scene = Snapshot(Room(), bumped, 0.005, 30 + id, id);
      monitor.OnBackground("s2", t < 51.0 ? Mixed(old_scene, new_scene) : new_scene, At(t));
      ++id;
    }
    monitor.Update(At(t), frames);
    for (const MonitorEvent& e : monitor.TakeEvents()) {
      ASSERT_EQ(e.sensor_id, "s2") << e.detail;
      if (e.kind == MonitorEventKind::kMoved) flagged = true;
      if (e.kind != MonitorEventKind::kCorrected) continue;
      ASSERT_TRUE(e.after.has_value());
      // Every pose it sets holds (none of a mixed snapshot's compromises, which fall a degree
      // short here; the tracks' estimate is within 0.25 degrees).
      EXPECT_LT(common::RadToDeg(common::RotationDistanceRad(*e.after, bumped)), 0.3)
          << "at " << t << " s: " << e.detail;
      EXPECT_LT(common::TranslationDistanceM(*e.after, bumped), 0.05)
          << "at " << t << " s: " << e.detail;
    }
  }
  EXPECT_TRUE(flagged);
  // The settled scene ends it within the background's precision, fused again.
  const Pose2 final_pose = Watch(monitor, "s2").world_from_sensor;
  EXPECT_LT(common::RadToDeg(common::RotationDistanceRad(final_pose, bumped)), 0.05);
  EXPECT_LT(common::TranslationDistanceM(final_pose, bumped), 0.01);
  EXPECT_FALSE(monitor.Excluded("s2"));
}

// s2 turned 2 degrees; its frames from 20 s on as its tracker gives them while it re-learns the
// background: bent 0.6 degrees further.
const Pose2 kS2Turned2Deg = kS2 * Pose2{0.0, 0.0, common::DegToRad(2.0)};
FakeFrames BentTracksOfTurnedS2() {
  return FakeFrames(100.0,
                    {{0.0, kS2}, {20.0, kS2Turned2Deg * Pose2{0.0, 0.0, common::DegToRad(0.6)}}});
}

TEST(Monitor, APoseFromBentTracksIsRefinedBySnapshotsShortOfSettled) {
  // Where the background cannot flag (no significant motion: background min_chi2 1e12), the
  // tracks flag a 2 degree turn and correct it from the tracks since the flag, which the moved
  // sensor's tracker bends while it re-learns its background: here they place it 0.6 degrees
  // off. The snapshots that follow hold the new scene with a few old returns (short of
  // settled_min_inliers), and their verdict is "scene changed" (the motion is never
  // significant). They must still set the pose where the scene as a whole puts it.
  MonitorOptions options;
  options.background.min_chi2 = 1e12;
  Monitor monitor(options);
  monitor.SetPoses(Calibrated(), References());
  const Pose2 bumped = kS2Turned2Deg;
  const FakeFrames frames = BentTracksOfTurnedS2();
  std::uint32_t id = 2;
  common::UtcNs flagged = 0, corrected_by_tracks = 0;
  double inliers = 0.0;
  for (double t = 1.0; t <= 90.0; t += 1.0) {
    if (t >= 50.0 && static_cast<int>(t) % 4 == 2) {
      // Every 16th beam still holds a nearer return of the old scene, not yet absorbed.
      daemon::BackgroundScan scene = Snapshot(Room(), bumped, 0.005, 30 + id, id);
      for (std::size_t i = 0; i < scene.ranges_mm.size(); i += 16) {
        scene.ranges_mm[i] = scene.ranges_mm[i] * 7 / 10;
      }
      monitor.OnBackground("s2", scene, At(t));
      ++id;
      // What the check makes of it at the expected pose (for the message below).
      inliers =
          CheckBackgrounds(References().at("s2"), scene, options.background, kS2.inverse() * bumped)
              .inliers_after;
    }
    monitor.Update(At(t), frames);
    for (const MonitorEvent& e : monitor.TakeEvents()) {
      ASSERT_EQ(e.sensor_id, "s2") << e.detail;
      if (e.kind == MonitorEventKind::kMoved) flagged = e.stamp_ns;
      if (e.kind == MonitorEventKind::kCorrected && e.method == "tracks" && !corrected_by_tracks) {
        corrected_by_tracks = e.stamp_ns;
        ASSERT_TRUE(e.after.has_value());
        // The failure mode: the tracks' pose is the bent one.
        EXPECT_GT(common::RadToDeg(common::RotationDistanceRad(*e.after, bumped)), 0.4) << e.detail;
      }
    }
  }
  ASSERT_NE(flagged, 0);
  ASSERT_NE(corrected_by_tracks, 0);
  EXPECT_LT(corrected_by_tracks, At(50.0));
  EXPECT_GT(inliers, options.correct_min_inliers);
  EXPECT_LT(inliers, options.settled_min_inliers) << "the snapshots were meant to be unsettled";
  const Pose2 final_pose = Watch(monitor, "s2").world_from_sensor;
  EXPECT_LT(common::RadToDeg(common::RotationDistanceRad(final_pose, bumped)), 0.1)
      << Watch(monitor, "s2").detail;
  EXPECT_LT(common::TranslationDistanceM(final_pose, bumped), 0.02);
  EXPECT_EQ(Watch(monitor, "s2").moves, 1u);
}

TEST(Monitor, SnapshotsWhoseStaleBeamsFavourThePoseInUseStillCorrectIt) {
  // The tracks flag a 2 degree turn and place it off (bent tracks, as in the test above). In the
  // snapshots that follow, the beams on which a sensor at the pose in use would see more than 6 cm
  // farther or nearer still hold what it saw from there: at that pose (the check's expectation)
  // they lie on the scene and every other point within inlier_distance_m, so the expectation keeps
  // more points on the scene than the ICP's pose does. The refinement must take the ICP's pose:
  // the expectation would keep the pose in use as it is.
  MonitorOptions options;
  options.background.min_chi2 = 1e12;
  Monitor monitor(options);
  monitor.SetPoses(Calibrated(), References());
  const Pose2 bumped = kS2Turned2Deg;
  const FakeFrames frames = BentTracksOfTurnedS2();
  std::uint32_t id = 2;
  common::UtcNs corrected_by_tracks = 0;
  int expectation_kept = 0;
  for (double t = 1.0; t <= 90.0; t += 1.0) {
    if (t >= 50.0 && static_cast<int>(t) % 4 == 2) {
      const Pose2 in_use = Watch(monitor, "s2").world_from_sensor;
      daemon::BackgroundScan scene = Snapshot(Room(), bumped, 0.005, 30 + id, id);
      const daemon::BackgroundScan stale = Snapshot(Room(), in_use, 0.005, 60 + id, id);
      for (std::size_t i = 0; i < scene.ranges_mm.size(); ++i) {
        if (std::abs(static_cast<double>(scene.ranges_mm[i]) -
                     static_cast<double>(stale.ranges_mm[i])) > 60.0) {
          scene.ranges_mm[i] = stale.ranges_mm[i];
        }
      }
      const BackgroundVerdict v = CheckBackgrounds(References().at("s2"), scene, options.background,
                                                   kS2.inverse() * in_use);
      if (v.fit_found && v.fit_share < v.inliers_before) ++expectation_kept;
      monitor.OnBackground("s2", scene, At(t));
      ++id;
    }
    monitor.Update(At(t), frames);
    for (const MonitorEvent& e : monitor.TakeEvents()) {
      ASSERT_EQ(e.sensor_id, "s2") << e.detail;
      if (e.kind == MonitorEventKind::kCorrected && e.method == "tracks" && !corrected_by_tracks) {
        corrected_by_tracks = e.stamp_ns;
        ASSERT_TRUE(e.after.has_value());
        EXPECT_GT(common::RadToDeg(common::RotationDistanceRad(*e.after, bumped)), 0.4) << e.detail;
      }
    }
  }
  ASSERT_NE(corrected_by_tracks, 0);
  EXPECT_LT(corrected_by_tracks, At(50.0));
  EXPECT_GE(expectation_kept, 1) << "the snapshots were meant to favour the pose in use";
  const Pose2 final_pose = Watch(monitor, "s2").world_from_sensor;
  EXPECT_LT(common::RadToDeg(common::RotationDistanceRad(final_pose, bumped)), 0.1)
      << Watch(monitor, "s2").detail;
  EXPECT_LT(common::TranslationDistanceM(final_pose, bumped), 0.02);
  EXPECT_EQ(Watch(monitor, "s2").moves, 1u);
}

TEST(Monitor, WithoutBackgroundsTheTracksFlagAndCorrect) {
  MonitorOptions options;
  Monitor monitor(options);
  monitor.SetPoses(Calibrated(), {});
  const Pose2 bumped = kS2 * Pose2{0.0, 0.0, common::DegToRad(3.0)};
  const FakeFrames frames(90.0, {{0.0, kS2}, {20.0, bumped}});
  common::UtcNs flagged = 0;
  for (double t = 1.0; t <= 60.0 && !flagged; t += 1.0) {
    monitor.Update(At(t), frames);
    for (const MonitorEvent& e : monitor.TakeEvents()) {
      ASSERT_EQ(e.kind, MonitorEventKind::kMoved) << e.detail;
      EXPECT_EQ(e.sensor_id, "s2") << e.detail;
      EXPECT_EQ(e.method, "tracks");
      flagged = e.stamp_ns;
    }
  }
  ASSERT_NE(flagged, 0);
  EXPECT_GT(flagged, At(20.0));
  EXPECT_LE(flagged, At(20.0 + options.track_window_s)) << "flagged late";
  EXPECT_TRUE(monitor.Excluded("s2"));
  // Corrected from the tracks since the flag, once there are enough of them.
  common::UtcNs corrected_at = 0;
  for (double t = 1.0; corrected_at == 0 && At(t) <= At(60.0); t += 1.0) {
    if (At(t) <= flagged) continue;
    monitor.Update(At(t), frames);
    for (const MonitorEvent& e : monitor.TakeEvents()) {
      if (e.kind == MonitorEventKind::kCorrected) corrected_at = e.stamp_ns;
    }
  }
  ASSERT_NE(corrected_at, 0);
  EXPECT_GE(corrected_at - flagged,
            static_cast<common::UtcNs>(options.correction_min_tracks_s * 1e9) - 1'000'000'000);
  const Pose2 corrected = Watch(monitor, "s2").world_from_sensor;
  EXPECT_LT(common::TranslationDistanceM(corrected, bumped), 0.05);
  EXPECT_LT(common::RadToDeg(common::RotationDistanceRad(corrected, bumped)), 0.2);
  // Without a snapshot to show that its tracker has re-learned its background, it is fused again
  // only relearn_hold_s after the flag.
  EXPECT_EQ(Watch(monitor, "s2").state, WatchState::kSettling);
  EXPECT_TRUE(monitor.Excluded("s2"));
  const double flagged_s = static_cast<double>(flagged - kStart) * 1e-9;
  for (double t = flagged_s + 10.0; t < flagged_s + options.relearn_hold_s - 1.0; t += 1.0) {
    monitor.Update(At(t), frames);
  }
  EXPECT_TRUE(monitor.Excluded("s2"));
  monitor.Update(At(flagged_s + options.relearn_hold_s + 1.0), frames);
  EXPECT_FALSE(monitor.Excluded("s2"));
  for (const MonitorEvent& e : monitor.TakeEvents()) {
    EXPECT_NE(e.kind, MonitorEventKind::kMoved) << "flagged again: " << e.detail;
  }
}

TEST(Monitor, ALargeTurnIsFlaggedByTheTracksBeforeTheirWindowHasPassed) {
  // Tracks before and after a 6 degree turn lie at two poses that no rigid correction of the
  // whole window fits; the newest half of it shows the move.
  MonitorOptions options;
  Monitor monitor(options);
  monitor.SetPoses(Calibrated(), {});
  const Pose2 bumped = kS2 * Pose2{0.0, 0.0, common::DegToRad(6.0)};
  const FakeFrames frames(40.0, {{0.0, kS2}, {20.0, bumped}});
  common::UtcNs flagged = 0;
  std::string detail;
  for (double t = 1.0; t <= 40.0 && !flagged; t += 1.0) {
    monitor.Update(At(t), frames);
    for (const MonitorEvent& e : monitor.TakeEvents()) {
      ASSERT_EQ(e.kind, MonitorEventKind::kMoved) << e.detail;
      EXPECT_EQ(e.sensor_id, "s2") << e.detail;
      flagged = e.stamp_ns;
      detail = e.detail;
    }
  }
  ASSERT_NE(flagged, 0);
  EXPECT_LE(flagged, At(20.0 + 0.75 * options.track_window_s)) << detail;
  ASSERT_TRUE(Watch(monitor, "s2").estimated_motion.yaw_rad != 0.0);
  EXPECT_NEAR(common::RadToDeg(Watch(monitor, "s2").estimated_motion.yaw_rad), 6.0, 1.0) << detail;
}

TEST(Monitor, FurnitureMovedWhileTheTracksAgreeReLearnsTheBackground) {
  Monitor monitor(MonitorOptions{});
  monitor.SetPoses(Calibrated(), References());
  const FakeFrames frames(40.0, {{0.0, kS2}});
  // The tracks first learn what "nothing moved" looks like.
  for (double t = 1.0; t <= 20.0; t += 1.0) monitor.Update(At(t), frames);
  std::vector<testing::Wall> changed = Room();
  testing::AddBox(&changed, 8.6, 1.4, 9.6, 2.6);
  const daemon::BackgroundScan with_cupboard = Snapshot(changed, kS2, 0.005, 4, 2);
  monitor.OnBackground("s2", with_cupboard, At(21.0));
  EXPECT_FALSE(monitor.Excluded("s2"));
  for (double t = 21.0; t <= 23.0; t += 1.0) monitor.Update(At(t), frames);
  const std::vector<MonitorEvent> events = monitor.TakeEvents();
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].kind, MonitorEventKind::kBackgroundRelearned);
  EXPECT_EQ(events[0].sensor_id, "s2");
  EXPECT_EQ(Watch(monitor, "s2").relearns, 1u);
  EXPECT_EQ(Watch(monitor, "s2").reference->ranges_mm, with_cupboard.ranges_mm);
  // The next snapshot of the new scene is unchanged against the new reference.
  monitor.OnBackground("s2", Snapshot(changed, kS2, 0.005, 5, 3), At(30.0));
  EXPECT_TRUE(monitor.TakeEvents().empty());
  EXPECT_EQ(Watch(monitor, "s2").state, WatchState::kWatched);
}

TEST(Monitor, ANewCalibrationReplacesThePosesAndAReferenceIsTakenWhenMissing) {
  Monitor monitor(MonitorOptions{});
  monitor.SetPoses(Calibrated(), {});
  EXPECT_FALSE(Watch(monitor, "s2").reference.has_value());
  monitor.OnBackground("s2", Snapshot(Room(), kS2, 0.005, 1, 0), At(1.0));
  EXPECT_TRUE(Watch(monitor, "s2").reference.has_value());
  EXPECT_TRUE(monitor.TakeEvents().empty());
  // Sensors not in a new calibration are no longer watched.
  monitor.SetPoses({{"s1", kS1, Eigen::Matrix3d::Zero()}}, {});
  EXPECT_EQ(monitor.sensors().size(), 1u);
  monitor.OnBackground("s2", Snapshot(Room(), kS2 * Pose2{0, 0, 0.1}, 0.005, 2), At(2.0));
  EXPECT_TRUE(monitor.TakeEvents().empty());
  EXPECT_FALSE(monitor.Excluded("s2"));
  ASSERT_EQ(monitor.Poses().size(), 1u);
  EXPECT_EQ(monitor.Poses()[0].id, "s1");
}

TEST(Monitor, OptionsAreValidated) {
  EXPECT_FALSE(Validate(MonitorOptions{}).has_value());
  MonitorOptions o;
  o.track_window_s = 0;
  EXPECT_NE(Validate(o).value_or("").find("track_window_s"), std::string::npos);
  o = {};
  o.track_confirmations = 0;
  EXPECT_NE(Validate(o).value_or("").find("track_confirmations"), std::string::npos);
  o = {};
  o.correction_max_tracks_s = 1.0;
  EXPECT_NE(Validate(o).value_or("").find("correction_max_tracks_s"), std::string::npos);
  o = {};
  o.check_max_yaw_sigma_deg = 0.0;
  EXPECT_NE(Validate(o).value_or("").find("check_max_yaw_sigma_deg"), std::string::npos);
  o = {};
  o.check_max_translation_sigma_m = std::nan("");
  EXPECT_NE(Validate(o).value_or("").find("check_max_translation_sigma_m"), std::string::npos);
  o = {};
  o.tracks.min_matches = 1;
  EXPECT_NE(Validate(o).value_or("").find("tracks.min_matches"), std::string::npos);
  o = {};
  o.background.min_yaw_deg = -1;
  EXPECT_NE(Validate(o).value_or("").find("background.min_yaw_deg"), std::string::npos);
  o = {};
  o.background_time_constant_s = 0.0;
  EXPECT_NE(Validate(o).value_or("").find("background_time_constant_s"), std::string::npos);
  o = {};
  o.combine_max_chi2 = std::nan("");
  EXPECT_NE(Validate(o).value_or("").find("combine_max_chi2"), std::string::npos);
  o = {};
  o.tracks_bias_sigma_deg = -1.0;
  EXPECT_NE(Validate(o).value_or("").find("tracks_bias_sigma_deg"), std::string::npos);
}

}  // namespace
}  // namespace lrfnet::monitoring
