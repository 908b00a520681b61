// The calibration chain as a user runs it: `lrfnet sim` → `lrfnet-tracker --replay --out` per
// sensor → `lrfnet calibrate` (and `lrfnetd --input ... --calibration-out`) → `lrfnet eval`.

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tests/process_harness.h"

namespace lrfnet {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;
using testing::Process;
using testing::ReadText;

using TempDir = testing::ScratchDir;

// The simulated setup of Quenzel et al. (six sensors on a 60 m circle, 120 s: the cylinder goes
// round once, so every neighbouring pair sees it together) and each sensor's tracks as its tracker
// sends them. Made once for all tests of this file.
class CalibrationChain : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    Process sim(LRFNET_TOOL_BINARY,
                {"sim", "quenzel_sim", "--out", *dir_ / "sim", "--jobs", "2"});
    ASSERT_EQ(sim.Wait(milliseconds(120'000)), 0) << sim.err();
    for (const char* id : {"s1", "s2", "s3", "s4", "s5", "s6"}) {
      Process tracker(LRFNET_TRACKER_BINARY,
                      {"--replay", *dir_ / ("sim/" + std::string(id) + ".pcap"), "--sensor-id", id,
                       "--out", *dir_ / (std::string(id) + ".rec"), "--log-level", "warn"});
      ASSERT_EQ(tracker.Wait(milliseconds(60'000)), 0) << tracker.err();
    }
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  static std::vector<std::string> Recordings() {
    std::vector<std::string> out;
    for (const char* id : {"s1", "s2", "s3", "s4", "s5", "s6"}) {
      out.push_back(*dir_ / (std::string(id) + ".rec"));
    }
    return out;
  }
  static TempDir* dir_;
};
TempDir* CalibrationChain::dir_ = nullptr;

nlohmann::json ReadJson(const std::string& path) {
  const std::string text = ReadText(path);
  return nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
}

TEST_F(CalibrationChain, CalibratesTheSimulatedSetupWithinTheBoundsAndWritesTheReport) {
  TempDir out;
  std::vector<std::string> args = {"calibrate"};
  for (const std::string& r : Recordings()) args.push_back(r);
  for (const std::string& a : {std::string("--out"), out / "calibration.yaml",
                               std::string("--report"), out / "report", std::string("--truth"),
                               *dir_ / "sim/truth.yaml", std::string("--stats-out"),
                               out / "stats.json"}) {
    args.push_back(a);
  }
  Process calibrate(LRFNET_TOOL_BINARY, args);
  ASSERT_EQ(calibrate.Wait(milliseconds(120'000)), 0) << calibrate.out() << calibrate.err();

  const nlohmann::json stats = ReadJson(out / "stats.json");
  ASSERT_TRUE(stats.is_object()) << calibrate.out();
  EXPECT_TRUE(stats["ok"].get<bool>());
  EXPECT_EQ(stats["invalid_datagrams"], 0);
  ASSERT_TRUE(stats.contains("eval")) << stats.dump(2);
  // The paper's own result on this setup: mean d_R 0.11 deg, d_t 0.062 m (Table III). With the
  // cuboid in range and the measurement model we reach ~0.01 deg and ~0.015 m with the tracker's
  // centre-of-mass or ellipse measurement (results/calibration_benchmark.md). The tracker's default
  // shape fit leaves a few centimetres of bias towards each sensor on this cylinder that the model
  // does not remove: the ring comes out ~0.4 % small (d_t ~0.12 m, within the reported sigma). The
  // bounds catch a broken chain; the 3-sigma check below that the uncertainty says so.
  EXPECT_LT(stats["eval"]["mean_d_r_deg"].get<double>(), 0.1) << calibrate.out();
  EXPECT_LT(stats["eval"]["mean_d_t_m"].get<double>(), 0.2) << calibrate.out();
  // Every sensor's error lies within 3 times the uncertainty calibration.yaml reports for it.
  const YAML::Node written = YAML::LoadFile(out / "calibration.yaml");
  std::size_t judged = 0;
  for (const auto& e : stats["eval"]["sensors"]) {
    for (const YAML::Node& s : written["sensors"]) {
      if (s["id"].as<std::string>() != e["id"].get<std::string>()) continue;
      const double sigma_t_m = std::hypot(s["sigma_x_m"].as<double>(), s["sigma_y_m"].as<double>());
      EXPECT_LE(e["d_t_m"].get<double>(), 3.0 * sigma_t_m) << s["id"].as<std::string>();
      EXPECT_LE(e["d_r_deg"].get<double>(), 3.0 * s["sigma_yaw_deg"].as<double>())
          << s["id"].as<std::string>();
      ++judged;
    }
  }
  EXPECT_EQ(judged, 5u);  // every sensor but the reference
  std::size_t used = 0;
  for (const auto& e : stats["edges"]) used += e["used"].get<bool>() ? 1 : 0;
  EXPECT_GE(used, 5u) << stats["edges"].dump(2);  // a ring of six needs at least five

  for (const char* file : {"calibration.svg", "calibration.png", "graph.svg", "graph.png",
                           "edges.csv", "summary.md"}) {
    EXPECT_TRUE(fs::exists(out / ("report/" + std::string(file)))) << file;
  }

  // `lrfnet eval` reads the file back and agrees.
  Process eval(LRFNET_TOOL_BINARY,
               {"eval", out / "calibration.yaml", *dir_ / "sim/truth.yaml", "--json"});
  ASSERT_EQ(eval.Wait(), 0) << eval.err();
  const nlohmann::json e = nlohmann::json::parse(eval.out(), nullptr, false);
  ASSERT_TRUE(e.is_object()) << eval.out();
  EXPECT_NEAR(e["mean_d_t_m"].get<double>(), stats["eval"]["mean_d_t_m"].get<double>(), 1e-3);
  EXPECT_NEAR(e["mean_d_r_deg"].get<double>(), stats["eval"]["mean_d_r_deg"].get<double>(), 1e-2);
}

TEST_F(CalibrationChain, TheDaemonCalibratesItsInputTheSameWay) {
  TempDir out;
  std::vector<std::string> calibrate_args = {"calibrate"};
  std::vector<std::string> daemon_args = {"--input"};
  for (const std::string& r : Recordings()) {
    calibrate_args.push_back(r);
    daemon_args.push_back(r);
  }
  calibrate_args.insert(calibrate_args.end(), {"--out", out / "tool.yaml"});
  daemon_args.insert(daemon_args.end(), {"--calibration-out", out / "daemon.yaml"});
  Process tool(LRFNET_TOOL_BINARY, calibrate_args);
  Process daemon(LRFNET_DAEMON_BINARY, daemon_args);
  ASSERT_EQ(tool.Wait(milliseconds(120'000)), 0) << tool.err();
  ASSERT_EQ(daemon.Wait(milliseconds(120'000)), 0) << daemon.err();
  EXPECT_NE(daemon.err().find("calibration: wrote"), std::string::npos) << daemon.err();
  // Same data, same code: the same poses (eval of one against the other is zero).
  Process eval(LRFNET_TOOL_BINARY, {"eval", out / "daemon.yaml", out / "tool.yaml", "--json"});
  ASSERT_EQ(eval.Wait(), 0) << eval.err();
  const nlohmann::json e = nlohmann::json::parse(eval.out(), nullptr, false);
  ASSERT_TRUE(e.is_object()) << eval.out();
  EXPECT_LT(e["mean_d_t_m"].get<double>(), 1e-6);
  EXPECT_LT(e["mean_d_r_deg"].get<double>(), 1e-6);
}

TEST_F(CalibrationChain, TooLittleDataAndBadInputAreOneLineErrors) {
  TempDir out;
  {
    Process one(LRFNET_TOOL_BINARY,
                {"calibrate", Recordings()[0], "--out", out / "one.yaml"});
    EXPECT_EQ(one.Wait(), 1);
    EXPECT_NE(one.err().find("too little data: only one sensor (s1)"), std::string::npos)
        << one.err();
    EXPECT_FALSE(fs::exists(out / "one.yaml"));
  }
  {
    // Two sensors on opposite sides of the circle never see the cylinder at the same time.
    Process apart(LRFNET_TOOL_BINARY, {"calibrate", Recordings()[0], Recordings()[3], "--out",
                                       out / "apart.yaml"});
    EXPECT_EQ(apart.Wait(milliseconds(60'000)), 1);
    EXPECT_NE(apart.err().find("too little data"), std::string::npos) << apart.err();
    EXPECT_NE(apart.err().find("simultaneous tracks"), std::string::npos) << apart.err();
  }
  {
    std::ofstream(out / "garbage.rec") << "this is not a recording";
    Process garbage(LRFNET_TOOL_BINARY, {"calibrate", out / "garbage.rec", "--out", out / "g.yaml"});
    EXPECT_EQ(garbage.Wait(), 1);
    EXPECT_NE(garbage.err().find("garbage.rec"), std::string::npos) << garbage.err();
  }
  {
    Process missing(LRFNET_TOOL_BINARY, {"calibrate", out / "nope.rec", "--out", out / "n.yaml"});
    EXPECT_EQ(missing.Wait(), 1);
    EXPECT_NE(missing.err().find("nope.rec"), std::string::npos) << missing.err();
  }
  {
    Process no_out(LRFNET_TOOL_BINARY, {"calibrate", Recordings()[0]});
    EXPECT_EQ(no_out.Wait(), 2);
    EXPECT_NE(no_out.err().find("--out"), std::string::npos) << no_out.err();
  }
  {
    Process bad_method(LRFNET_TOOL_BINARY,
                       {"calibrate", Recordings()[0], "--out", out / "x.yaml", "--method", "magic"});
    EXPECT_EQ(bad_method.Wait(), 2);
  }
  {
    std::ofstream(out / "broken.yaml") << "sensors: [{id: s1, x_m: one}]\n";
    Process eval(LRFNET_TOOL_BINARY, {"eval", out / "broken.yaml", *dir_ / "sim/truth.yaml"});
    EXPECT_EQ(eval.Wait(), 1);
    EXPECT_NE(eval.err().find("broken.yaml"), std::string::npos) << eval.err();
  }
}

TEST_F(CalibrationChain, BaselinesRunThroughTheCommandLine) {
  for (const char* method : {"spectral", "schenk"}) {
    TempDir out;
    std::vector<std::string> args = {"calibrate"};
    for (const std::string& r : Recordings()) args.push_back(r);
    args.insert(args.end(), {"--out", out / "c.yaml", "--method", method, "--weights", "schenk",
                             "--truth", *dir_ / "sim/truth.yaml", "--stats-out", out / "s.json"});
    Process calibrate(LRFNET_TOOL_BINARY, args);
    const int code = calibrate.Wait(milliseconds(120'000));
    // A baseline may fail to connect every sensor; it must say so and never crash.
    ASSERT_TRUE(code == 0 || code == 1) << method << ": " << calibrate.err();
    const nlohmann::json stats = ReadJson(out / "s.json");
    ASSERT_TRUE(stats.is_object()) << method;
    EXPECT_EQ(stats["method"], method);
    if (code == 1) {
      EXPECT_FALSE(stats["error"].get<std::string>().empty());
    }
  }
}

}  // namespace
}  // namespace lrfnet
