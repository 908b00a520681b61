// The parts of lrfnetd's runs that need no process: the config with the flags over it, a
// calibration to start from, the recording, the stats file and the summary line.

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "central_daemon/app/monitoring_service.h"
#include "central_daemon/app/recorder.h"
#include "central_daemon/app/run_report.h"
#include "central_daemon/app/run_setup.h"
#include "central_daemon/calibration/calibration_yaml.h"
#include "central_daemon/io/datagram_source.h"

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
