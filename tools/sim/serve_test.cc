// `lrfnet sim --serve`: the simulated sensor as a ScanSource (shared scenario clock) and, over a
// real TCP socket on loopback, the emulator serving it to the live client.

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "tests/link_harness.h"
#include "tools/sim/sim_output.h"
#include "tools/sim/sim_scan_source.h"
#include "tools/sim/simulator.h"

namespace lrfnet::sim {
namespace {

using std::chrono::seconds;

const char* const kServeScenario = R"(name: serve_test
seed: 23
duration_s: 5
world:
  walls: [[[0, 0], [20, 0], [20, 10], [0, 10], [0, 0]]]
sensors:
  - {id: a, model: lms111, x_m: 0.5, y_m: 0.5, yaw_deg: 45}
  - {id: b, model: tim781, x_m: 19.5, y_m: 9.5, yaw_deg: -135}
targets:
  - {id: walker, shape: person, path: [[2, 2], [18, 8], [2, 8]], speed_mps: 1.2, loop: true}
)";

std::shared_ptr<const Simulator> MakeServeSim() {
  Scenario s;
  std::string error;
  EXPECT_TRUE(ParseScenario(kServeScenario, "serve_test.yaml", &s, &error)) << error;
  std::shared_ptr<const Simulator> sim = Simulator::Create(s, &error);
  EXPECT_NE(sim, nullptr) << error;
  return sim;
}

std::uint64_t IndexOf(const Simulator& sim, std::size_t sensor, const cola::ScanTelegram& scan) {
  return static_cast<std::uint16_t>(scan.telegram_counter -
                                    sim.sensor(sensor).first_telegram_counter);
}

TEST(SimScanSource, ScansLeaveAtTheirScenarioTimesOnTheSharedClock) {
  auto sim = MakeServeSim();
  ASSERT_NE(sim, nullptr);
  double now = 0.5;
  auto source = MakeSimScanSource(sim, 0, [&now] { return now; });
  EXPECT_EQ(source->identity().name, "LMS111-10100");
  EXPECT_EQ(std::stoul(source->identity().serial_number), sim->sensor(0).serial_number);
  auto scan = std::make_unique<cola::ScanTelegram>();
  common::DurationNs gap = -1;

  // A client connecting at 0.5 s gets the scan sent last before then, at once...
  ASSERT_TRUE(source->Next(scan.get(), &gap));
  const std::uint64_t j = IndexOf(*sim, 0, *scan);
  EXPECT_LE(sim->Timing(0, j).transmit_s, 0.5);
  EXPECT_GT(sim->Timing(0, j + 1).transmit_s, 0.5);
  EXPECT_EQ(gap, 0);
  // ...and the next one when it is due: its transmission time minus now.
  ASSERT_TRUE(source->Next(scan.get(), &gap));
  EXPECT_EQ(IndexOf(*sim, 0, *scan), j + 1);
  EXPECT_NEAR(static_cast<double>(gap), (sim->Timing(0, j + 1).transmit_s - 0.5) * 1e9, 2.0);
  now = sim->Timing(0, j + 1).transmit_s;
  ASSERT_TRUE(source->Next(scan.get(), &gap));
  EXPECT_EQ(IndexOf(*sim, 0, *scan), j + 2);
  EXPECT_NEAR(static_cast<double>(gap),
              (sim->Timing(0, j + 2).transmit_s - sim->Timing(0, j + 1).transmit_s) * 1e9, 2.0);
  // The scan content is the simulator's scan of that index.
  auto expected = std::make_unique<cola::ScanTelegram>();
  sim->SimulateScan(0, j + 2, expected.get());
  EXPECT_EQ(scan->time_since_startup_us, expected->time_since_startup_us);
  EXPECT_TRUE(std::equal(expected->channels16[0].raw.begin(),
                         expected->channels16[0].raw.begin() + 541,
                         scan->channels16[0].raw.begin()));

  // Nobody read for a while (a reconnect): the device kept measuring; the stream resumes at now.
  now = 3.0;
  ASSERT_TRUE(source->Next(scan.get(), &gap));
  const std::uint64_t late = IndexOf(*sim, 0, *scan);
  EXPECT_LE(sim->Timing(0, late).transmit_s, 3.0);
  EXPECT_GT(sim->Timing(0, late + 1).transmit_s, 3.0);
  EXPECT_EQ(gap, 0);

  // After the scenario's end the pass is over; a rewound source plays it again, shifted by its
  // duration.
  now = 6.0;
  EXPECT_FALSE(source->Next(scan.get(), &gap));
  source->Rewind();
  ASSERT_TRUE(source->Next(scan.get(), &gap));
  const std::uint64_t again = IndexOf(*sim, 0, *scan);
  EXPECT_LE(5.0 + sim->Timing(0, again).transmit_s, 6.0);
  EXPECT_GT(5.0 + sim->Timing(0, again + 1).transmit_s, 6.0);
}

TEST(SimServe, TheLiveClientReceivesTheSimulatedScansOverTcp) {
  auto sim = MakeServeSim();
  ASSERT_NE(sim, nullptr);
  constexpr double kSpeed = 2.0;
  const auto start = std::chrono::steady_clock::now();
  auto now_s = [start] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() * kSpeed;
  };
  tools::EmulatorOptions options;
  options.speed = kSpeed;
  std::vector<std::unique_ptr<cola::ScanTelegram>> received;
  std::vector<std::chrono::steady_clock::time_point> received_at;
  testing::LinkHarness link(options, MakeSimScanSource(sim, 1, now_s), testing::TestClientOptions(),
                            [&](const cola::ScanTelegram& scan) {
                              received.push_back(std::make_unique<cola::ScanTelegram>(scan));
                              received_at.push_back(std::chrono::steady_clock::now());
                            });
  ASSERT_TRUE(link.started());
  ASSERT_TRUE(link.RunUntilScans(20, seconds(15))) << "received " << link.received().size();

  const SensorSetup& sensor = sim->sensor(1);
  EXPECT_EQ(link.client().device_info().ident_name, std::string(sensor.device.model->ident_name));
  EXPECT_EQ(std::stoul(link.client().device_info().serial_number), sensor.serial_number);
  EXPECT_EQ(link.client().counters().bad_frames, 0u);
  auto expected = std::make_unique<cola::ScanTelegram>();
  const std::uint64_t first = IndexOf(*sim, 1, *received[0]);
  for (std::size_t i = 0; i < received.size(); ++i) {
    const std::uint64_t k = IndexOf(*sim, 1, *received[i]);
    ASSERT_EQ(k, first + i) << "scans lost or repeated";
    sim->SimulateScan(1, k, expected.get());
    EXPECT_EQ(received[i]->time_since_startup_us, expected->time_since_startup_us);
    const cola::ScanChannel* dist = received[i]->FindChannel("DIST1");
    ASSERT_NE(dist, nullptr);
    ASSERT_EQ(dist->count, 811);
    EXPECT_TRUE(std::equal(dist->raw.begin(), dist->raw.begin() + 811,
                           expected->channels16[0].raw.begin()));
  }
  // Paced by the scenario clock: 19 TiM periods (66.7 ms) at twice real time take about 0.63 s.
  const double wall_s =
      std::chrono::duration<double>(received_at.back() - received_at.front()).count();
  const double scenario_s = sim->Timing(1, IndexOf(*sim, 1, *received.back())).transmit_s -
                            sim->Timing(1, first).transmit_s;
  EXPECT_NEAR(wall_s, scenario_s / kSpeed, 0.15);
}

}  // namespace
}  // namespace lrfnet::sim
