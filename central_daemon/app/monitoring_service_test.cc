#include "central_daemon/app/monitoring_service.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <boost/asio/io_context.hpp>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "central_daemon/app/fusion_service.h"
#include "central_daemon/app/mqtt_service.h"
#include "central_daemon/app/zone_service.h"
#include "central_daemon/calibration/calibration_yaml.h"
#include "central_daemon/monitoring/monitoring_test_util.h"
#include "firmware_tracker/io/datagram_encoder.h"

namespace lrfnet::daemon {
namespace {

constexpr common::UtcNs kServiceT0 = 1'700'000'000'000'000'000;
constexpr common::DurationNs kServiceMs = 1'000'000;
const common::Pose2 kS1{0.3, 0.3, common::DegToRad(40.0)};
const common::Pose2 kS2{11.7, 0.3, common::DegToRad(140.0)};

struct CollectDatagrams final : io::DatagramSink {
  std::vector<std::vector<std::uint8_t>> out;
  void Send(std::span<const std::uint8_t> d, common::UtcNs) override {
    out.emplace_back(d.begin(), d.end());
  }
};

// One sensor's tracker: background snapshots and (empty) track frames, as datagrams into the core.
struct Tracker {
  std::string id;
  io::DatagramEncoder encoder;
  std::uint32_t scans = 0;
  Tracker(std::string sensor, std::uint64_t session) : id(sensor), encoder({sensor, session}) {}

  void Background(Daemon& d, const BackgroundScan& scan, common::UtcNs at_ns) {
    std::vector<float> ranges;
    for (const std::uint32_t mm : scan.ranges_mm) ranges.push_back(static_cast<float>(mm) * 1e-3f);
    CollectDatagrams c;
    encoder.EncodeBackground({at_ns, scan.first_angle_rad, scan.angle_step_rad, ranges}, at_ns, c);
    for (const auto& bytes : c.out) d.OnDatagram(bytes, id + ":1", at_ns);
  }
  void Frame(Daemon& d, common::UtcNs at_ns) {
    tracking::ScanTracks scan;
    scan.scan_start_ns = at_ns;
    scan.scan_period_s = 1.0 / 15;
    scan.scan_counter = scans++;
    CollectDatagrams c;
    encoder.EncodeTracks(scan, at_ns, c);
    for (const auto& bytes : c.out) d.OnDatagram(bytes, id + ":1", at_ns);
  }
};

calib::CalibrationResult Result() {
  calib::CalibrationResult r;
  r.method = "quenzel";
  r.reference = "s1";
  for (const auto& [id, pose] : {std::pair{"s1", kS1}, std::pair{"s2", kS2}}) {
    calib::SensorPose p;
    p.id = id;
    p.calibrated = true;
    p.world_from_sensor = pose;
    p.covariance = Eigen::Matrix3d::Identity() * 1e-6;
    r.sensors.push_back(p);
  }
  return r;
}

std::string Read(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST(MonitoringService, AMovedSensorIsExcludedFromTheFusionAndTheCalibrationKeepsItsHistory) {
  const std::string dir = (std::filesystem::temp_directory_path() /
                           ("monitoring_service_" + std::to_string(::getpid())))
                              .string();
  std::filesystem::create_directories(dir);
  DaemonConfig config;
  config.calibration_output = dir + "/calibration.yaml";
  DaemonOptions options;
  options.send_requests = false;
  Daemon daemon(options, nullptr, nullptr, 1);
  Tracker s1("s1", 11), s2("s2", 12);
  const auto room = monitoring::testing::Room();
  s1.Background(daemon, monitoring::testing::Snapshot(room, kS1, 0.005, 1), kServiceT0);
  s2.Background(daemon, monitoring::testing::Snapshot(room, kS2, 0.005, 2), kServiceT0);
  s1.Frame(daemon, kServiceT0 + 100 * kServiceMs);
  s2.Frame(daemon, kServiceT0 + 100 * kServiceMs);

  MonitoringService monitoring(config);
  EXPECT_FALSE(monitoring.active());
  EXPECT_FALSE(monitoring.OnTick(daemon));
  monitoring.SetCalibration(Result(), daemon, "calibrated");
  EXPECT_TRUE(monitoring.active());
  ASSERT_EQ(monitoring.WriteCalibration(), "");
  std::vector<calib::CalibrationEvent> history;
  std::string error;
  ASSERT_TRUE(calib::ParseHistoryYaml(Read(config.calibration_output), &history, &error)) << error;
  ASSERT_EQ(history.size(), 1u);
  EXPECT_EQ(history[0].event, "calibrated");
  EXPECT_FALSE(monitoring.OnTick(daemon));  // nothing new

  // s2 is turned by 3 degrees. Its tracker's next snapshot has taken the new returns only where
  // they are farther (the rest of its background follows later): flagged, not yet corrected.
  const common::Pose2 bumped = kS2 * common::Pose2{0.0, 0.0, common::DegToRad(3.0)};
  const BackgroundScan before = monitoring::testing::Snapshot(room, kS2, 0.005, 2);
  const BackgroundScan after = monitoring::testing::Snapshot(room, bumped, 0.005, 3);
  BackgroundScan partial = before;
  for (std::size_t i = 0; i < partial.ranges_mm.size(); ++i) {
    if (before.ranges_mm[i] != 0 &&
        (after.ranges_mm[i] == 0 || after.ranges_mm[i] > before.ranges_mm[i] + 150)) {
      partial.ranges_mm[i] = after.ranges_mm[i];
    }
  }
  s2.Background(daemon, partial, kServiceT0 + 5000 * kServiceMs);
  s1.Frame(daemon, kServiceT0 + 5100 * kServiceMs);
  EXPECT_TRUE(monitoring.OnTick(daemon));
  EXPECT_EQ(monitoring.excluded(), std::set<std::string>{"s2"});
  EXPECT_NE(monitoring.StatusText().find("MOVED, not fused: s2"), std::string::npos)
      << monitoring.StatusText();
  EXPECT_EQ(monitoring.counters().moved, 1u);

  // The file says so, and still reads as a pose file.
  const std::string text = Read(config.calibration_output);
  ASSERT_TRUE(calib::ParseHistoryYaml(text, &history, &error)) << error;
  ASSERT_GE(history.size(), 2u);
  EXPECT_EQ(history[1].event, "moved");
  EXPECT_EQ(history[1].sensor, "s2");
  EXPECT_EQ(history[1].stamp_ns, kServiceT0 + 5100 * kServiceMs);
  ASSERT_TRUE(history[1].after.has_value());
  EXPECT_NEAR(common::RadToDeg(history[1].after->yaw_rad), 143.0, 0.1);
  calib::PoseFile poses;
  ASSERT_TRUE(calib::ParsePoseYaml(text, &poses, &error)) << error;

  // The stats and the live view show it.
  const nlohmann::json stats = monitoring.StatsJson();
  EXPECT_EQ(stats["sensors"]["s2"]["state"], "moved");
  EXPECT_EQ(stats["sensors"]["s1"]["state"], "ok");
  LiveState state;
  state.sensors.resize(3);
  state.sensors[0].id = "s1";
  state.sensors[1].id = "s2";
  state.sensors[2].id = "s9";
  monitoring.Annotate(&state);
  EXPECT_EQ(state.sensors[0].monitor_state, "ok");
  EXPECT_EQ(state.sensors[1].monitor_state, "moved");
  EXPECT_FALSE(state.sensors[1].monitor_detail.empty());
  EXPECT_EQ(state.sensors[2].monitor_state, "");
  EXPECT_NE(LiveStateJson(state).find("\"monitor\":{\"state\":\"moved\""), std::string::npos);

  // The fusion leaves s2's frames out from now on.
  boost::asio::io_context io;
  FusionService fusion(io, config);
  fusion.SetCalibration(monitoring.result());
  fusion.SetExcluded(monitoring.excluded());
  TrackFrameData frame;
  frame.session_id = 1;
  frame.scan_start_ns = kServiceT0 + 6000 * kServiceMs;
  TrackObservation track;
  track.track_id = 1;
  track.state = TrackState::kConfirmed;
  track.x_m = 2.0f;
  track.covariance = {0.01f, 0, 0, 0, 0.01f, 0, 0, 0.1f, 0, 0.1f};
  frame.tracks.push_back(track);
  fusion.OnFrame("s2", frame);
  EXPECT_EQ(fusion.fuser().counters().frames, 0u);
  fusion.OnFrame("s1", frame);
  EXPECT_EQ(fusion.fuser().counters().frames, 1u);
  EXPECT_FALSE(fusion.fuser().HasPlacement("s2"));

  // MQTT: s2's health says "moved" (the others as they are), published at once.
  struct Sink : MqttSink {
    std::map<std::string, std::string> last;
    void Publish(const std::string& topic, std::string payload, int, bool) override {
      last[topic] = std::move(payload);
    }
  } sink;
  MqttService mqtt(config, &sink, "test");
  const ZoneService zones(config);
  std::map<std::string, std::string, std::less<>> states;
  for (const auto& [id, watch] : monitoring.monitor().sensors()) {
    states[id] = monitoring::ToString(watch.state);
  }
  mqtt.SetMonitorStates(states);
  mqtt.OnTick(kServiceT0 + 6000 * kServiceMs, daemon, fusion, zones);
  EXPECT_NE(sink.last[mqtt.Topic("sensors/s2/health")].find("\"state\":\"moved\""),
            std::string::npos)
      << sink.last[mqtt.Topic("sensors/s2/health")];
  EXPECT_NE(sink.last[mqtt.Topic("sensors/s1/health")].find("\"state\":\"active\""),
            std::string::npos)
      << sink.last[mqtt.Topic("sensors/s1/health")];

  fusion.SetExcluded({});
  EXPECT_TRUE(fusion.fuser().HasPlacement("s2"));

  // Its background once re-learned gives the pose: corrected, fused again, in the file.
  s2.Background(daemon, after, kServiceT0 + 35000 * kServiceMs);
  s1.Frame(daemon, kServiceT0 + 35100 * kServiceMs);
  EXPECT_TRUE(monitoring.OnTick(daemon));
  EXPECT_TRUE(monitoring.excluded().empty());
  EXPECT_EQ(monitoring.StatusText(), "");
  ASSERT_TRUE(calib::ParsePoseYaml(Read(config.calibration_output), &poses, &error)) << error;
  const auto at = poses.Find("s2");
  ASSERT_TRUE(at.has_value());
  EXPECT_NEAR(common::RadToDeg(poses.sensors[*at].second.yaw_rad), 143.0, 0.05);
  EXPECT_NEAR(poses.sensors[*at].second.x_m, bumped.x_m, 0.005);
  ASSERT_TRUE(calib::ParseHistoryYaml(Read(config.calibration_output), &history, &error)) << error;
  EXPECT_EQ(history.back().event, "corrected");
  EXPECT_EQ(history.back().method, "background");
  std::filesystem::remove_all(dir);
}

TEST(MonitoringService, ALoadedCalibrationBringsItsHistoryAndOffMeansOff) {
  DaemonOptions options;
  options.send_requests = false;
  Daemon daemon(options, nullptr, nullptr, 1);
  DaemonConfig config;
  calib::CalibrationEvent old;
  old.sensor = "s2";
  old.event = "corrected";
  MonitoringService monitoring(config);
  monitoring.SetCalibration(Result(), daemon, "loaded",
                            "sensors: []\n" + calib::HistoryYaml({old}));
  ASSERT_EQ(monitoring.history().size(), 1u);
  EXPECT_EQ(monitoring.history()[0].event, "corrected");
  // A history that does not read starts anew (the poses are still watched).
  monitoring.SetCalibration(Result(), daemon, "loaded", "history: [{sensor: [1]}]\n");
  EXPECT_TRUE(monitoring.active());
  config.monitoring_enabled = false;
  monitoring.Reconfigure(config);
  EXPECT_FALSE(monitoring.active());
  EXPECT_FALSE(monitoring.OnTick(daemon));
  EXPECT_EQ(monitoring.WriteCalibration(), "");  // no output configured
}

}  // namespace
}  // namespace lrfnet::daemon
