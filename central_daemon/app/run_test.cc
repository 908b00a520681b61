// The parts of lrfnetd's runs that need no process: the config with the flags over it, a
// calibration to start from, the recording, the stats file and the summary line.

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "central_daemon/app/calibration_input.h"
#include "central_daemon/app/calibration_service.h"
#include "central_daemon/app/fusion_service.h"
#include "central_daemon/app/live_feed.h"
#include "central_daemon/app/monitoring_service.h"
#include "central_daemon/app/mqtt_messages.h"
#include "central_daemon/app/recorder.h"
#include "central_daemon/app/run_report.h"
#include "central_daemon/app/run_setup.h"
#include "central_daemon/calibration/calibration_yaml.h"
#include "central_daemon/io/datagram_source.h"
#include "firmware_tracker/io/datagram_encoder.h"

namespace lrfnet::daemon {
namespace {

namespace fs = std::filesystem;

constexpr common::UtcNs kRunT0 = 1'700'000'000'000'000'000;

class RunTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("lrfnetd_run_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string Write(const std::string& name, const std::string& text) {
    const std::string path = (dir_ / name).string();
    std::ofstream(path, std::ios::binary) << text;
    return path;
  }
  static std::string Read(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  }

  fs::path dir_;
};

TEST_F(RunTest, FlagsOverTheConfigFileOverTheDefaults) {
  DaemonConfig in_file;
  in_file.listen = "127.0.0.1:6100";
  in_file.status_interval_s = 7.0;
  in_file.calibration_output = "from_file.yaml";
  RunOptions run;
  run.config_path = Write("lrfnetd.yaml", PrintDaemonConfig(in_file));
  run.listen_flag = "127.0.0.1:6200";
  run.calibration_out_flag = "from_flag.yaml";

  DaemonConfig c;
  ASSERT_EQ(LoadConfig(run, &c), std::nullopt);
  EXPECT_EQ(c.listen, "127.0.0.1:6200");
  EXPECT_EQ(c.calibration_output, "from_flag.yaml");
  EXPECT_EQ(c.status_interval_s, 7.0);                               // the file's
  EXPECT_EQ(c.fusion_publish_hz, DaemonConfig{}.fusion_publish_hz);  // the default

  // No file: the flags over the defaults.
  run.config_path.clear();
  ASSERT_EQ(LoadConfig(run, &c), std::nullopt);
  EXPECT_EQ(c.status_interval_s, DaemonConfig{}.status_interval_s);
  EXPECT_EQ(c.listen, "127.0.0.1:6200");
}

TEST_F(RunTest, ConfigErrorsNameTheFileAndLeaveTheConfigAlone) {
  DaemonConfig c;
  c.listen = "untouched";
  RunOptions run;
  run.config_path = (dir_ / "missing.yaml").string();
  EXPECT_EQ(LoadConfig(run, &c), "--config: cannot read '" + run.config_path + "'");

  run.config_path = Write("bad.yaml", "status:\n  interval_s: [1, 2\n");
  const auto e = LoadConfig(run, &c);
  ASSERT_TRUE(e.has_value());
  EXPECT_EQ(e->rfind("--config " + run.config_path + ": ", 0), 0u) << *e;

  run.config_path = Write("unknown.yaml", "no_such_section:\n  x: 1\n");
  ASSERT_TRUE(LoadConfig(run, &c).has_value());
  EXPECT_EQ(c.listen, "untouched");
}

TEST_F(RunTest, InitialCalibrationIsTheFilesPosesAndText) {
  const std::string text =
      "reference: \"s1\"\n"
      "sensors:\n"
      "  - {id: \"s1\", x_m: 0, y_m: 0, yaw_deg: 0}\n"
      "  - {id: \"s2\", x_m: 4.5, y_m: -1.25, yaw_deg: 90}\n"
      "  - {id: \"s3\", calibrated: false}\n";
  const std::string path = Write("calibration.yaml", text);
  calib::CalibrationOutcome outcome;
  std::string read_text;
  ASSERT_EQ(LoadInitialCalibration(path, &outcome, &read_text), std::nullopt);
  EXPECT_TRUE(outcome.ok);
  EXPECT_EQ(outcome.result.method, "file");
  EXPECT_EQ(outcome.result.reference, "s1");
  ASSERT_EQ(outcome.result.sensors.size(), 3u);
  EXPECT_EQ(outcome.result.sensors[1].id, "s2");
  EXPECT_DOUBLE_EQ(outcome.result.sensors[1].world_from_sensor.x_m, 4.5);
  EXPECT_DOUBLE_EQ(outcome.result.sensors[1].world_from_sensor.y_m, -1.25);
  EXPECT_NEAR(outcome.result.sensors[1].world_from_sensor.yaw_rad, M_PI / 2, 1e-12);
  EXPECT_TRUE(outcome.result.sensors[1].calibrated);
  EXPECT_FALSE(outcome.result.sensors[2].calibrated);
  EXPECT_EQ(read_text, text);

  calib::CalibrationOutcome untouched;
  const auto e = LoadInitialCalibration(Write("broken.yaml", "sensors: 3\n"), &untouched);
  ASSERT_TRUE(e.has_value());
  EXPECT_EQ(e->rfind("calibration.initial: ", 0), 0u) << *e;
  EXPECT_FALSE(untouched.ok);
  EXPECT_TRUE(untouched.result.sensors.empty());
}

// A calibration as the pipeline leaves it: correlated covariances, radial biases estimated and
// held, a sensor whose tracks look like legs, one not placed.
calib::CalibrationResult ComputedCalibration() {
  calib::CalibrationResult r;
  r.method = "quenzel";
  r.reference = "s1";
  r.track_residual_rms_m = 0.0283;
  const auto pose = [](const char* id, double x, double y, double yaw_deg, double sigma_m,
                       double sigma_yaw_deg) {
    calib::SensorPose p;
    p.id = id;
    p.calibrated = true;
    p.world_from_sensor = {x, y, common::DegToRad(yaw_deg)};
    // Yaw correlated with the position through the lever arm to the reference.
    Eigen::Matrix3d j = Eigen::Matrix3d::Identity();
    j(0, 2) = -y;
    j(1, 2) = x;
    const double s_yaw = common::DegToRad(sigma_yaw_deg);
    p.covariance =
        j *
        Eigen::Vector3d(sigma_m * sigma_m, 0.7 * sigma_m * sigma_m, s_yaw * s_yaw).asDiagonal() *
        j.transpose();
    return p;
  };
  r.sensors.push_back(pose("s1", 0, 0, 0, 0, 0));
  r.sensors.back().radial_bias = calib::RadialBiasEstimate{-0.0183456, 0.0061234, true};
  r.sensors.push_back(pose("s2", 11.3124, 7.4031, 179.9812, 0.0114, 0.0512));
  r.sensors.back().radial_bias = calib::RadialBiasEstimate{0.0, 0.02, false};
  r.sensors.push_back(pose("s3", -4.25, 9.5, -91.5, 0.0231, 0.1234));
  r.sensors.back().radial_bias = calib::RadialBiasEstimate{0.0, 0.1, false};
  r.sensors.back().mount_looks_like_legs = true;
  r.sensors.back().flag =
      "s3: tracks look like legs (6 of 7 people tracks leg-sized, median half-width 0.07 m) but "
      "shape.mount is torso; set shape.mount: legs on its tracker";
  calib::SensorPose lost;
  lost.id = "s4";
  lost.flag = "ambiguous: two placements explain the data equally";
  r.sensors.push_back(lost);
  return r;
}

TEST_F(RunTest, ACalibrationReadAtStartUpCarriesWhatItsCalibrationComputed) {
  const calib::CalibrationResult computed = ComputedCalibration();
  calib::CalibrationOutcome loaded;
  ASSERT_EQ(LoadInitialCalibration(Write("calibration.yaml", calib::CalibrationYaml(computed, {})),
                                   &loaded),
            std::nullopt);
  ASSERT_EQ(loaded.result.sensors.size(), computed.sensors.size());
  for (std::size_t i = 0; i < computed.sensors.size(); ++i) {
    const calib::SensorPose& want = computed.sensors[i];
    const calib::SensorPose& got = loaded.result.sensors[i];
    EXPECT_EQ(got.calibrated, want.calibrated) << want.id;
    EXPECT_EQ(got.flag, want.flag) << want.id;
    EXPECT_EQ(got.mount_looks_like_legs, want.mount_looks_like_legs) << want.id;
    ASSERT_EQ(got.radial_bias.has_value(), want.radial_bias.has_value()) << want.id;
    if (want.radial_bias) {
      EXPECT_EQ(got.radial_bias->bias_m, want.radial_bias->bias_m) << want.id;
      EXPECT_NEAR(got.radial_bias->sigma_m, want.radial_bias->sigma_m,
                  1e-6 * want.radial_bias->sigma_m);
      EXPECT_EQ(got.radial_bias->estimated, want.radial_bias->estimated) << want.id;
    }
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) {
        const double scale = std::sqrt(want.covariance(r, r) * want.covariance(c, c));
        EXPECT_NEAR(got.covariance(r, c), want.covariance(r, c), 2e-5 * scale)
            << want.id << " (" << r << ", " << c << ")";
      }
    }
  }
  // The fusion weighs each placement by that covariance, as it would the computed one's.
  const auto placed_computed = PlacementsOf(computed);
  const auto placed_loaded = PlacementsOf(loaded.result);
  ASSERT_EQ(placed_loaded.size(), 3u);
  ASSERT_EQ(placed_loaded.size(), placed_computed.size());
  for (std::size_t i = 0; i < placed_loaded.size(); ++i) {
    EXPECT_TRUE(placed_loaded[i].covariance.isApprox(placed_computed[i].covariance, 1e-4) ||
                placed_computed[i].covariance.isZero())
        << placed_loaded[i].id << "\n"
        << placed_loaded[i].covariance;
    EXPECT_GT(placed_loaded[i].covariance(2, 2), i == 0 ? -1.0 : 0.0) << placed_loaded[i].id;
  }
  EXPECT_EQ(loaded.result.track_residual_rms_m, computed.track_residual_rms_m);
  // What is published of each sensor is the same (MQTT rounds sigmas to 1e-5).
  const nlohmann::json from_computed = nlohmann::json::parse(CalibrationJson("lab", 1, computed));
  const nlohmann::json from_loaded =
      nlohmann::json::parse(CalibrationJson("lab", 1, loaded.result));
  EXPECT_EQ(from_loaded["sensors"], from_computed["sensors"]) << from_loaded["sensors"].dump(1);
  EXPECT_EQ(from_loaded["sensors"][2]["mount_looks_like_legs"], true);
  EXPECT_EQ(from_loaded["sensors"][1]["sigma_yaw_deg"], 0.0512);
  // And the live view shows each sensor's calibration as the computed one's.
  for (std::size_t i = 0; i < computed.sensors.size(); ++i) {
    const LiveSensor::Calibration want = LiveCalibrationOf(computed.sensors[i]);
    const LiveSensor::Calibration got = LiveCalibrationOf(loaded.result.sensors[i]);
    const std::string& id = computed.sensors[i].id;
    EXPECT_TRUE(got.calibrated) << id;
    EXPECT_NEAR(got.sigma_x_m, want.sigma_x_m, 1e-5 * want.sigma_x_m) << id;
    EXPECT_NEAR(got.sigma_y_m, want.sigma_y_m, 1e-5 * want.sigma_y_m) << id;
    EXPECT_NEAR(got.sigma_yaw_rad, want.sigma_yaw_rad, 1e-5 * want.sigma_yaw_rad) << id;
    EXPECT_EQ(got.has_radial_bias, want.has_radial_bias) << id;
    EXPECT_EQ(got.radial_bias_m, want.radial_bias_m) << id;
    EXPECT_NEAR(got.sigma_radial_bias_m, want.sigma_radial_bias_m, 1e-6 * want.sigma_radial_bias_m)
        << id;
    EXPECT_EQ(got.radial_bias_estimated, want.radial_bias_estimated) << id;
    EXPECT_EQ(got.mount_looks_like_legs, want.mount_looks_like_legs) << id;
    EXPECT_EQ(got.flag, want.flag) << id;
  }
  EXPECT_TRUE(LiveCalibrationOf(loaded.result.sensors[2]).mount_looks_like_legs);
  EXPECT_GT(LiveCalibrationOf(loaded.result.sensors[1]).sigma_x_m, 0.01);
  EXPECT_FALSE(LiveCalibrationOf(loaded.result.sensors[3]).has_radial_bias);
}

TEST_F(RunTest, RecorderWritesWhatTheCoreRecordsAndItReadsBack) {
  DaemonConfig config;
  config.record_path = (dir_ / "rec.lrfrec").string();
  Recorder recorder(RecordingOptions(config, Writer()));
  ASSERT_EQ(recorder.Open(kRunT0), std::nullopt);
  const std::vector<std::vector<std::uint8_t>> sent = {{1, 2, 3}, {}, {0xff, 0x00, 0x7f, 0x80}};
  for (std::size_t i = 0; i < sent.size(); ++i) {
    recorder.Record(sent[i], "192.0.2.7:4000", kRunT0 + static_cast<common::UtcNs>(i) * 1'000'000);
  }
  recorder.FlushIfDue(kRunT0 + 10'000'000'000);
  ASSERT_EQ(recorder.Close(), std::nullopt);
  EXPECT_EQ(recorder.writer().counters().entries_written, sent.size());
  EXPECT_EQ(recorder.writer().counters().write_errors, 0u);

  std::string error;
  auto source = OpenDatagramFile(recorder.writer().current_path(), {}, &error);
  ASSERT_NE(source, nullptr) << error;
  ReceivedDatagram d;
  for (std::size_t i = 0; i < sent.size(); ++i) {
    ASSERT_EQ(source->Next(&d), SourceStatus::kDatagram) << i;
    EXPECT_EQ(d.bytes, sent[i]);
    EXPECT_EQ(d.source, "192.0.2.7:4000");
    EXPECT_EQ(d.receive_ns, kRunT0 + static_cast<common::UtcNs>(i) * 1'000'000);
  }
  EXPECT_EQ(source->Next(&d), SourceStatus::kEnd);
}

// What a tracker's encoder sends, with the time it sends it.
struct Sent final : io::DatagramSink {
  std::vector<std::pair<std::vector<std::uint8_t>, common::UtcNs>> out;
  void Send(std::span<const std::uint8_t> d, common::UtcNs t) override {
    out.emplace_back(std::vector<std::uint8_t>(d.begin(), d.end()), t);
  }
};

// A live calibration takes what the store holds when it starts, so the same sources calibrate
// differently with the moment it starts; its window (calibration.yaml `input_window`) gives that
// same input again from the daemon's recording, whatever arrived after it.
TEST_F(RunTest, ALiveCalibrationsInputComesBackFromTheRecordingThroughItsWindow) {
  DaemonConfig config;
  config.record_path = (dir_ / "rec.lrfrec").string();
  Recorder recorder(RecordingOptions(config, Writer()));
  ASSERT_EQ(recorder.Open(kRunT0), std::nullopt);
  Daemon daemon(CoreOptions(config), &recorder, nullptr, 1);
  constexpr common::DurationNs kPeriodNs = 40'000'000;
  // Two sensors, 25 Hz for 4 s, their datagrams arriving 2 and 7 ms after they were sent.
  std::vector<std::tuple<common::UtcNs, std::vector<std::uint8_t>>> arrivals;
  int sensor = 0;
  for (const char* id : {"a", "b"}) {
    io::DatagramEncoder encoder({id, static_cast<std::uint64_t>(++sensor)});
    Sent sent;
    for (std::uint32_t i = 0; i < 100; ++i) {
      tracking::ScanTracks scan;
      scan.scan_start_ns = kRunT0 + i * kPeriodNs;
      scan.scan_period_s = 0.04;
      scan.scan_counter = i;
      tracking::TrackReport* t = scan.tracks.emplace_slot();
      t->track_id = 1;
      t->state = tracking::TrackState::kConfirmed;
      t->x_m = 1.0 + 0.01 * i;
      t->y_m = sensor;
      t->covariance = Eigen::Matrix4d::Identity() * 0.01;
      encoder.EncodeTracks(scan, scan.scan_start_ns + kPeriodNs, sent);
    }
    for (auto& [bytes, sent_ns] : sent.out) {
      arrivals.emplace_back(sent_ns + (sensor == 1 ? 2 : 7) * 1'000'000, std::move(bytes));
    }
  }
  std::sort(arrivals.begin(), arrivals.end());
  calib::CalibrationInput live;
  InputWindow window;
  for (std::size_t i = 0; i < arrivals.size(); ++i) {
    const auto& [receive_ns, bytes] = arrivals[i];
    daemon.OnDatagram(bytes, "192.0.2.1:4000", receive_ns);
    if (i == 130) live = WindowInput(daemon, 1.5, &window);  // the attempt, 2.6 s in
  }
  ASSERT_EQ(recorder.Close(), std::nullopt);
  EXPECT_EQ(window.received_until_ns, std::get<0>(arrivals[130]));
  const std::string path = recorder.writer().current_path();

  const auto frames_of = [](const calib::CalibrationInput& input) {
    std::vector<std::tuple<std::string, common::UtcNs, float>> out;
    for (const calib::SensorRecording& s : input.sensors) {
      for (const TrackFrameData& f : s.frames) {
        out.emplace_back(s.id, f.scan_start_ns, f.tracks.empty() ? 0.0f : f.tracks[0].x_m);
      }
    }
    return out;
  };
  calib::CalibrationInput again;
  std::string error;
  ASSERT_TRUE(LoadCalibrationInput({path}, 0, &again, nullptr, &error, {}, window)) << error;
  ASSERT_EQ(again.sensors.size(), 2u);
  EXPECT_EQ(frames_of(again), frames_of(live));
  const std::size_t live_frames = frames_of(live).size();
  EXPECT_GT(live_frames, 60u);   // 1.5 s of two sensors at 25 Hz
  EXPECT_LT(live_frames, 100u);  // not the 2.6 s received by then
  // The whole recording is another input (later frames), as is the store with any other window.
  calib::CalibrationInput all;
  ASSERT_TRUE(LoadCalibrationInput({path}, 0, &all, nullptr, &error)) << error;
  EXPECT_EQ(frames_of(all).size(), 200u);
  InputWindow received_only = window;
  received_only.scan_from_ns = 0;
  ASSERT_TRUE(LoadCalibrationInput({path}, 0, &all, nullptr, &error, {}, received_only)) << error;
  EXPECT_GT(frames_of(all).size(), live_frames);
}

TEST_F(RunTest, SummaryAndStatsCountWhatArrived) {
  DaemonConfig config;
  Daemon daemon(CoreOptions(config), nullptr, nullptr, 42);
  EXPECT_EQ(Summary(daemon),
            "summary: sensors=0 datagrams=0 accepted=0 rejected=0 lost=0 frames=0");
  const std::vector<std::uint8_t> garbage = {0xde, 0xad, 0xbe, 0xef};
  daemon.OnDatagram(garbage, "192.0.2.1:5000", kRunT0);
  daemon.OnDatagram({}, "192.0.2.1:5000", kRunT0 + 1);
  EXPECT_EQ(Summary(daemon),
            "summary: sensors=0 datagrams=2 accepted=0 rejected=2 lost=0 frames=0");

  MonitoringService monitoring(config);
  const std::string path = (dir_ / "stats.json").string();
  ASSERT_TRUE(WriteStats(path, daemon, nullptr, nullptr, monitoring));
  const nlohmann::json j = nlohmann::json::parse(Read(path));
  EXPECT_EQ(j.at("datagrams"), 2);
  EXPECT_EQ(j.at("rejected"), 2);
  EXPECT_EQ(j.at("requests_sent"), 0);
  EXPECT_TRUE(j.contains("monitoring"));
  EXPECT_FALSE(j.contains("receiver"));
  EXPECT_FALSE(j.contains("recording"));
  EXPECT_FALSE(j.contains("mqtt"));

  // With the recording: its counters too.
  config.record_path = (dir_ / "rec.lrfrec").string();
  Recorder recorder(RecordingOptions(config, Writer()));
  ASSERT_EQ(recorder.Open(kRunT0), std::nullopt);
  recorder.Record(garbage, "192.0.2.1:5000", kRunT0);
  ASSERT_TRUE(WriteStats(path, daemon, nullptr, &recorder, monitoring));
  EXPECT_TRUE(nlohmann::json::parse(Read(path)).contains("recording"));

  EXPECT_TRUE(WriteStats("", daemon, nullptr, nullptr, monitoring));  // no --stats-out
  EXPECT_FALSE(WriteStats((dir_ / "no_such_dir" / "stats.json").string(), daemon, nullptr, nullptr,
                          monitoring));
}

}  // namespace
}  // namespace lrfnet::daemon
