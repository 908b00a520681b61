// Emulator -> TCP loopback -> SickClient: the client receives exactly the scans `lrfnet dump` finds
// in the capture, in order, none lost, none duplicated; the same for the synthetic source and for a
// looping capture.

#include <gtest/gtest.h>

#include <memory>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "tests/link_harness.h"
#include "tests/support/test_data.h"
#include "tools/dump.h"

namespace lrfnet {
namespace {

using std::chrono::milliseconds;
using std::chrono::seconds;

// The dump line without the receive time (capture time there, loopback time here).
std::string WithoutReceiveTime(const std::string& line) {
  static const std::regex kReceiveTime(R"(, "receive_time_ns": -?[0-9]+)");
  return std::regex_replace(line, kReceiveTime, "");
}

std::vector<std::string> DumpLines(const std::string& capture) {
  std::ostringstream out;
  std::string error;
  tools::DumpSummary summary;
  EXPECT_TRUE(tools::DumpCapture(capture, tools::DumpOptions{}, &out, &summary, &error)) << error;
  std::vector<std::string> lines;
  std::istringstream in(out.str());
  for (std::string line; std::getline(in, line);) lines.push_back(WithoutReceiveTime(line));
  return lines;
}

class CaptureLoopbackTest : public ::testing::TestWithParam<std::string> {};

TEST_P(CaptureLoopbackTest, ClientReceivesExactlyTheDumpedScans) {
  LRFNET_REQUIRE_SHARED_FILE(capture, "data/sick/" + GetParam());
  const std::vector<std::string> expected = DumpLines(capture);
  ASSERT_FALSE(expected.empty());

  std::string error;
  std::unique_ptr<tools::ScanSource> source = tools::OpenCaptureScanSource(capture, {}, &error);
  ASSERT_NE(source, nullptr) << error;
  tools::EmulatorOptions emulator_options;
  emulator_options.speed = 20;
  emulator_options.ready_after_run_s = 0.2;  // the MRS1104 takes 15 s; the dialogue test has it
  std::vector<std::string> received_lines;
  testing::LinkHarness link(
      emulator_options, std::move(source), testing::TestClientOptions(),
      [&](const cola::ScanTelegram& scan) {
        received_lines.push_back(WithoutReceiveTime(tools::ScanJsonLine(scan, 0)));
      });
  ASSERT_TRUE(link.started());
  ASSERT_TRUE(link.RunUntil(
      [&] { return link.emulator().exhausted() && received_lines.size() >= expected.size(); },
      seconds(20)))
      << "received " << received_lines.size() << " of " << expected.size();
  // Nothing more may arrive (no duplicates): give the stream a moment.
  link.RunUntil([] { return false; }, milliseconds(100));

  ASSERT_EQ(received_lines.size(), expected.size());
  for (std::size_t i = 0; i < expected.size(); ++i) {
    ASSERT_EQ(received_lines[i], expected[i]) << "scan " << i;
  }
  const io::SickClientCounters& c = link.client().counters();
  EXPECT_EQ(c.connects, 1u);
  EXPECT_EQ(c.reconnects, 0u);
  EXPECT_EQ(c.read_timeouts, 0u);
  EXPECT_EQ(c.bad_frames, 0u);
  EXPECT_EQ(c.scans, expected.size());
  EXPECT_FALSE(link.client().device_info().ident_name.empty());
  EXPECT_FALSE(link.client().device_info().serial_number.empty());
}

INSTANTIATE_TEST_SUITE_P(SharedCaptures, CaptureLoopbackTest,
                         ::testing::ValuesIn(testing::SickCaptureNames()),
                         [](const ::testing::TestParamInfo<std::string>& param_info) {
                           return param_info.param.substr(0, param_info.param.find('.'));
                         });

TEST(SyntheticLoopbackTest, ClientReceivesTheGeneratedScansInOrder) {
  tools::SyntheticScanOptions synthetic;
  synthetic.model = "lms511";
  tools::EmulatorOptions emulator_options;
  emulator_options.speed = 10;
  std::vector<std::string> received_lines;
  testing::LinkHarness link(emulator_options, tools::MakeSyntheticScanSource(synthetic),
                            testing::TestClientOptions(), [&](const cola::ScanTelegram& scan) {
                              received_lines.push_back(tools::ScanJsonLine(scan, 0));
                            });
  ASSERT_TRUE(link.started());
  ASSERT_TRUE(link.RunUntilScans(60, seconds(10)));

  // The same source, read directly: the client must have seen these very scans.
  auto reference = tools::MakeSyntheticScanSource(synthetic);
  auto scan = std::make_unique<cola::ScanTelegram>();
  common::DurationNs gap = 0;
  for (std::size_t i = 0; i < 60; ++i) {
    ASSERT_TRUE(reference->Next(scan.get(), &gap));
    ASSERT_EQ(received_lines[i], tools::ScanJsonLine(*scan, 0)) << "scan " << i;
  }
  EXPECT_EQ(link.client().device_info().ident_name, "LMS511-10100");
  EXPECT_EQ(link.client().counters().connects, 1u);
  EXPECT_EQ(link.client().counters().bad_frames, 0u);
  link.Shutdown();
  testing::ExpectNoLossNoDuplicates(link.emulator().sent_telegram_counters(),
                                    link.received_counters());
}

TEST(LoopingLoopbackTest, CountersAndTicksKeepIncreasingAcrossPasses) {
  LRFNET_REQUIRE_SHARED_FILE(capture, "data/sick/test.pcapng");
  std::string error;
  std::unique_ptr<tools::ScanSource> source = tools::OpenCaptureScanSource(capture, {}, &error);
  ASSERT_NE(source, nullptr) << error;
  tools::EmulatorOptions emulator_options;
  emulator_options.speed = 20;
  emulator_options.loop = true;
  testing::LinkHarness link(emulator_options, std::move(source));
  ASSERT_TRUE(link.RunUntilScans(40, seconds(20)));  // 16 scans per pass: two and a half passes
  const std::vector<testing::ReceivedScan>& r = link.received();
  for (std::size_t i = 1; i < 40; ++i) {
    EXPECT_EQ(static_cast<std::uint16_t>(r[i].telegram_counter - r[i - 1].telegram_counter), 1)
        << i;
    EXPECT_EQ(static_cast<std::uint16_t>(r[i].scan_counter - r[i - 1].scan_counter), 1) << i;
    const std::uint32_t tick_step = r[i].time_since_startup_us - r[i - 1].time_since_startup_us;
    EXPECT_GT(tick_step, 0u) << i;
    EXPECT_LT(tick_step, 200'000u) << i;  // 15 Hz device: ~66 ms
    // The ranges repeat with the capture's period.
    if (i >= 16) {
      EXPECT_EQ(r[i].dist1_raw_sum, r[i - 16].dist1_raw_sum) << i;
    }
  }
  EXPECT_GE(link.emulator().counters().passes, 2u);
  EXPECT_EQ(link.client().counters().connects, 1u);
}

}  // namespace
}  // namespace lrfnet
