// Every shipped scenario (tools/scenarios/*.yaml) loads, has the setup its paper describes, and
// simulates: a couple of seconds through the capture writer and back through the capture reader.

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "common/capture/capture_stream.h"
#include "firmware_tracker/cola/stream_decoder.h"
#include "tools/sim/sim_output.h"
#include "tools/sim/simulator.h"

#ifndef LRFNET_SCENARIO_DIR
#error "LRFNET_SCENARIO_DIR must name the shipped scenarios' folder"
#endif

namespace lrfnet::sim {
namespace {

namespace fs = std::filesystem;

std::vector<std::string> ScenarioFiles() {
  std::vector<std::string> files;
  for (const auto& entry : fs::directory_iterator(LRFNET_SCENARIO_DIR)) {
    if (entry.path().extension() == ".yaml") files.push_back(entry.path().string());
  }
  std::sort(files.begin(), files.end());
  return files;
}

// What the papers (and the issue) fix about each scenario.
struct Expected {
  std::size_t sensors;
  std::multiset<std::string> models;
  double rate_hz;         // every sensor; 0: not checked
  double resolution_deg;  // every sensor; 0: not checked
  double fov_deg;         // every sensor; 0: not checked
  std::size_t max_targets_at_once;
};

const std::map<std::string, Expected>& ExpectedScenarios() {
  static const std::map<std::string, Expected> kExpected = {
      {"quenzel_sim",
       {6, {"lms111", "lms111", "lms111", "lms111", "lms111", "lms111"}, 50, 0.5, 270, 1}},
      {"quenzel_sim_far",
       {6, {"lms111", "lms111", "lms111", "lms111", "lms111", "lms111"}, 50, 0.5, 270, 1}},
      {"office_semicircle",
       {6, {"tim561", "tim561", "tim561", "tim561", "tim561", "tim561"}, 15, 0, 270, 1}},
      {"office_distributed",
       {6, {"tim561", "tim561", "tim561", "tim561", "tim561", "tim561"}, 15, 0, 270, 4}},
      {"industrial", {4, {"lms111", "lms111", "lms111", "lms511"}, 25, 0.5, 0, 2}},
      {"computer_lab", {5, {"lms111", "lms111", "lms111", "lms111", "lms111"}, 12.5, 0, 270, 4}},
      {"schenk_A", {5, {"lms151", "lms151", "lms151", "lms151", "lms151"}, 50, 0.5, 270, 1}},
      {"schenk_B", {5, {"lms151", "lms151", "lms151", "lms151", "lms151"}, 50, 0.5, 270, 1}},
      {"schenk_C", {5, {"lms151", "lms151", "lms151", "lms151", "lms151"}, 50, 0.5, 270, 2}},
      {"schenk_D", {5, {"lms151", "lms151", "lms151", "lms151", "lms151"}, 50, 0.5, 270, 2}},
  };
  return kExpected;
}

TEST(ShippedScenarios, AllOfTheIssuesScenariosAreThere) {
  std::set<std::string> names;
  for (const std::string& f : ScenarioFiles()) names.insert(fs::path(f).stem().string());
  for (const auto& [name, expected] : ExpectedScenarios()) {
    EXPECT_TRUE(names.count(name)) << name << ".yaml is missing";
  }
}

class ShippedScenario : public ::testing::TestWithParam<std::string> {};

TEST_P(ShippedScenario, LoadsHasThePapersSetupAndSimulates) {
  const std::string path = GetParam();
  Scenario scenario;
  std::string error;
  ASSERT_TRUE(LoadScenarioFile(path, &scenario, &error)) << error;
  EXPECT_EQ(scenario.name, fs::path(path).stem().string()) << "name and file name differ";
  EXPECT_FALSE(scenario.description.empty());
  ASSERT_FALSE(scenario.targets.empty());

  const double full_duration = scenario.duration_s;
  std::unique_ptr<Simulator> full = Simulator::Create(scenario, &error);
  ASSERT_NE(full, nullptr) << error;
  const auto it = ExpectedScenarios().find(scenario.name);
  if (it != ExpectedScenarios().end()) {
    const Expected& e = it->second;
    ASSERT_EQ(full->sensor_count(), e.sensors);
    std::multiset<std::string> models;
    for (std::size_t i = 0; i < full->sensor_count(); ++i) {
      const DeviceConfig& d = full->sensor(i).device;
      models.insert(std::string(d.model->key));
      if (e.rate_hz > 0) {
        EXPECT_EQ(d.rate_hz, e.rate_hz) << full->sensor(i).id;
      }
      if (e.resolution_deg > 0) {
        EXPECT_EQ(d.resolution_deg, e.resolution_deg) << full->sensor(i).id;
      }
      if (e.fov_deg > 0) {
        EXPECT_EQ(d.fov_deg, e.fov_deg) << full->sensor(i).id;
      }
    }
    EXPECT_EQ(models, e.models);
    std::size_t most = 0;
    for (double t = 0; t < full_duration; t += 0.5) most = std::max(most, full->TruthAt(t).size());
    EXPECT_EQ(most, e.max_targets_at_once);
  }
  // Every target, while in the scene, is in some sensor's view most of the time.
  for (std::size_t j = 0; j < full->targets().size(); ++j) {
    int present = 0, seen = 0;
    for (double t = 0; t < full_duration; t += 0.5) {
      const TargetState st = full->targets()[j].StateAt(t);
      if (!st.present) continue;
      ++present;
      for (std::size_t i = 0; i < full->sensor_count(); ++i) {
        if (full->Sees(i, st.center)) {
          ++seen;
          break;
        }
      }
    }
    EXPECT_GT(present, 0) << full->targets()[j].id() << " never enters";
    EXPECT_GE(seen, present * 8 / 10) << full->targets()[j].id() << " is out of view too often";
  }

  // A couple of seconds through the capture writer and back.
  scenario.duration_s = 2.0;
  std::unique_ptr<Simulator> sim = Simulator::Create(scenario, &error);
  ASSERT_NE(sim, nullptr) << error;
  const fs::path dir =
      fs::temp_directory_path() /
      ("lrfnet_scenarios_test_" + std::to_string(::getpid()) + "_" + scenario.name);
  ASSERT_TRUE(WriteSimulation(*sim, dir.string(), {}, nullptr, &error)) << error;
  for (std::size_t i = 0; i < sim->sensor_count(); ++i) {
    const SensorSetup& sensor = sim->sensor(i);
    auto capture = capture::CaptureStream::Open((dir / (sensor.id + ".pcap")).string(), {}, &error);
    ASSERT_NE(capture, nullptr) << error;
    cola::StreamDecoder decoder;
    struct Counter : cola::TelegramListener {
      std::uint64_t scans = 0, echoes = 0, beams = 0;
      void OnScan(const cola::ScanTelegram& scan, common::UtcNs) override {
        ++scans;
        const cola::ScanChannel* d = scan.FindChannel("DIST1");
        for (std::size_t b = 0; d != nullptr && b < d->count; ++b) echoes += d->raw[b] != 0 ? 1 : 0;
        beams += d != nullptr ? d->count : 0;
      }
    } counter;
    capture::StreamChunk chunk;
    while (capture->Next(&chunk)) decoder.Feed(chunk.bytes, chunk.receive_time_ns, counter);
    EXPECT_EQ(counter.scans, sensor.scan_count) << sensor.id;
    EXPECT_GE(sensor.scan_count, static_cast<std::uint64_t>(2.0 * sensor.device.rate_hz) - 1)
        << sensor.id;
    // Every sensor sees its surroundings (the open Quenzel rings excepted: a cuboid that fills a
    // small part of the view, or nothing static in range).
    if (scenario.name.rfind("quenzel_sim", 0) != 0) {
      EXPECT_GT(counter.echoes, counter.beams / 4) << sensor.id << " sees almost nothing";
    }
  }
  std::error_code ec;
  fs::remove_all(dir, ec);
}

INSTANTIATE_TEST_SUITE_P(Files, ShippedScenario, ::testing::ValuesIn(ScenarioFiles()),
                         [](const ::testing::TestParamInfo<std::string>& param_info) {
                           return fs::path(param_info.param).stem().string();
                         });

}  // namespace
}  // namespace lrfnet::sim
