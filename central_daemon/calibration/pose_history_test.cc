#include "central_daemon/calibration/pose_history.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace lrfnet::calib {
namespace {

CalibrationEvent Moved() {
  CalibrationEvent e;
  e.time_utc = "2024-05-01T12:00:03Z";
  e.stamp_ns = 1714564803123456789;
  e.sensor = "s \"2\"";
  e.event = "moved";
  e.method = "background";
  e.detail = "whole scene turned: 2.0 deg, 0.10 m\tnew line\n";
  e.before = Pose2{1.0, 2.0, common::DegToRad(30.0)};
  e.after = Pose2{1.1, 2.0, common::DegToRad(-179.0)};
  return e;
}

TEST(PoseHistory, EventsReadBackAsWritten) {
  CalibrationEvent relearned;
  relearned.sensor = "s1";
  relearned.event = "background_relearned";
  const std::vector<CalibrationEvent> events = {Moved(), relearned};
  const std::string yaml = "reference: \"s1\"\nsensors: []\n" + HistoryYaml(events);
  EXPECT_NE(yaml.find("motion: {dx_m: 0.10000000000000009, dy_m: 0, dyaw_deg: 151}"),
            std::string::npos)
      << yaml;
  std::vector<CalibrationEvent> back;
  std::string error;
  ASSERT_TRUE(ParseHistoryYaml(yaml, &back, &error)) << error << "\n" << yaml;
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(back[0].sensor, "s \"2\"");
  EXPECT_EQ(back[0].detail, events[0].detail);
  EXPECT_EQ(back[0].stamp_ns, events[0].stamp_ns);
  ASSERT_TRUE(back[0].after.has_value());
  EXPECT_DOUBLE_EQ(back[0].after->x_m, 1.1);
  EXPECT_NEAR(back[0].after->yaw_rad, common::DegToRad(-179.0), 1e-12);
  EXPECT_EQ(back[1].event, "background_relearned");
  EXPECT_FALSE(back[1].before.has_value());

  // No history: an empty list; an empty history section too.
  ASSERT_TRUE(ParseHistoryYaml("sensors: []\n", &back, &error)) << error;
  EXPECT_TRUE(back.empty());
  ASSERT_TRUE(ParseHistoryYaml(HistoryYaml({}), &back, &error)) << error;
  EXPECT_TRUE(back.empty());
}

TEST(PoseHistory, MalformedHistoriesAreOneLineErrors) {
  std::vector<CalibrationEvent> out = {Moved()};
  std::string error;
  for (const char* bad :
       {"history: 3\n", "history: [{event: moved}]\n",
        "history: [{sensor: a, event: moved, before: {x_m: 1, y_m: 2}}]\n",
        "history: [{sensor: a, event: moved, stamp_ns: -5}]\n",
        "history: [{sensor: a, event: moved, after: {x_m: 1e300, y_m: 0, "
        "yaw_deg: 0}}]\n",
        "history: [{sensor: [a], event: moved}]\n", "history: [\n", "history: [nan]\n"}) {
    EXPECT_FALSE(ParseHistoryYaml(bad, &out, &error)) << bad;
    EXPECT_EQ(error.find('\n'), std::string::npos) << error;
    EXPECT_FALSE(error.empty()) << bad;
    EXPECT_EQ(out.size(), 1u) << "written on failure: " << bad;
  }
  EXPECT_FALSE(ParseHistoryYaml(std::string("history: []\n\0", 13), &out, &error));
}

TEST(PoseHistory, TruthPosesAtATime) {
  const std::string truth =
      "sensors:\n"
      "  - {id: a, x_m: 5, y_m: 0, yaw_deg: 10}\n"
      "  - {id: b, x_m: 1, y_m: 1, yaw_deg: 0}\n"
      "poses:\n"
      "  - {id: a, from_s: 0, to_s: 30, from_utc_ns: 0, x_m: 4, y_m: 0, yaw_deg: 0}\n"
      "  - {id: a, from_s: 30, to_s: 60, from_utc_ns: 0, x_m: 5, y_m: 0, yaw_deg: 10}\n"
      "  - {id: b, from_s: 0, to_s: 60, from_utc_ns: 0, x_m: 1, y_m: 1, yaw_deg: 0}\n";
  PoseFile at;
  std::string error;
  ASSERT_TRUE(TruthPosesAt(truth, 29.9, &at, &error)) << error;
  ASSERT_EQ(at.sensors.size(), 2u);
  EXPECT_EQ(at.sensors[0].first, "a");
  EXPECT_DOUBLE_EQ(at.sensors[0].second.x_m, 4.0);
  ASSERT_TRUE(TruthPosesAt(truth, 30.0, &at, &error)) << error;
  EXPECT_DOUBLE_EQ(at.sensors[0].second.x_m, 5.0);
  EXPECT_NEAR(at.sensors[0].second.yaw_rad, common::DegToRad(10.0), 1e-12);
  // After the end of the run: the last pose.
  ASSERT_TRUE(TruthPosesAt(truth, 100.0, &at, &error)) << error;
  EXPECT_DOUBLE_EQ(at.sensors[0].second.x_m, 5.0);
  EXPECT_DOUBLE_EQ(at.sensors[1].second.y_m, 1.0);

  EXPECT_FALSE(TruthPosesAt("sensors: []\n", 1.0, &at, &error));
  EXPECT_NE(error.find("no `poses`"), std::string::npos) << error;
  EXPECT_FALSE(TruthPosesAt("poses: [{id: a, from_s: 0, to_s: x, x_m: 0, y_m: 0, yaw_deg: 0}]\n",
                            1.0, &at, &error));
  EXPECT_NE(error.find("poses[0].to_s"), std::string::npos) << error;
}

TEST(PoseHistory, TruncatedAndCorruptedFilesNeverCrash) {
  // Every prefix of a real file, and every byte flipped: a result or a one-line error.
  const std::string yaml = "reference: \"s1\"\nsensors: []\n" + HistoryYaml({Moved(), Moved()});
  std::size_t read = 0;
  for (std::size_t n = 0; n <= yaml.size(); ++n) {
    std::vector<CalibrationEvent> out;
    std::string error;
    if (ParseHistoryYaml(yaml.substr(0, n), &out, &error)) {
      ++read;
      EXPECT_LE(out.size(), 2u);
    } else {
      EXPECT_EQ(error.find('\n'), std::string::npos) << error;
    }
    PoseFile at;
    TruthPosesAt(yaml.substr(0, n), 1.0, &at, &error);
  }
  EXPECT_GT(read, 0u);
  for (std::size_t i = 0; i < yaml.size(); ++i) {
    std::string bad = yaml;
    bad[i] = static_cast<char>(bad[i] ^ 0x5a);
    std::vector<CalibrationEvent> out;
    std::string error;
    if (!ParseHistoryYaml(bad, &out, &error)) {
      EXPECT_EQ(error.find('\n'), std::string::npos) << error;
    }
  }
}

}  // namespace
}  // namespace lrfnet::calib
