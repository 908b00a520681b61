// The built binaries as a user runs them: exit codes, one-line errors, --help, dump and replay
// output, and `lrfnet emulate` + `lrfnet-tracker` as two processes over loopback (what
// scripts/demo.sh does).

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <tuple>
#include <vector>

#include "tests/process_harness.h"
#include "tests/support/test_data.h"
#include "tools/dump.h"

namespace lrfnet {
namespace {

using std::chrono::milliseconds;
using std::chrono::seconds;
using testing::CountLines;
using testing::CountPrefixed;
using testing::Process;
using testing::ReadText;

const char* const kTool = LRFNET_TOOL_BINARY;
const char* const kTracker = LRFNET_TRACKER_BINARY;

struct BadArgs {
  std::vector<std::string> args;
  int exit_code;
};

void ExpectOneLineError(const char* binary, const BadArgs& c) {
  Process p(binary, c.args);
  EXPECT_EQ(p.Wait(), c.exit_code);
  const std::string err = p.err();
  EXPECT_EQ(CountLines(err), 1u) << "stderr: " << err;
  EXPECT_TRUE(p.out().empty()) << p.out();
}

TEST(CliTest, LrfnetBadArgumentsGiveOneLineAndExitCode2) {
  const std::vector<BadArgs> cases = {
      {{}, 2},
      {{"frobnicate"}, 2},
      {{"dump"}, 2},
      {{"dump", "--no-such-option", "x.pcap"}, 2},
      {{"dump", "--port", "70000", "x.pcap"}, 2},
      {{"dump", "--port", "abc", "x.pcap"}, 2},
      {{"dump", "a.pcap", "b.pcap"}, 2},
      {{"emulate"}, 2},
      {{"emulate", "--synthetic", "lms999"}, 2},
      {{"emulate", "--synthetic", "lms511", "--speed", "0"}, 2},
      {{"emulate", "--synthetic", "lms511", "--port", "-5"}, 2},
      {{"emulate", "--synthetic", "lms511", "--fault-stall-after", "-1"}, 2},
      {{"emulate", "x.pcap", "--synthetic", "lms511"}, 2},
  };
  for (const BadArgs& c : cases) {
    SCOPED_TRACE(::testing::PrintToString(c.args));
    ExpectOneLineError(kTool, c);
  }
}

TEST(CliTest, UnreadableCaptureExits1WithOneLineNamingTheFile) {
  Process p(kTool, {"dump", "no/such/file.pcap"});
  EXPECT_EQ(p.Wait(), 1);
  EXPECT_EQ(CountLines(p.err()), 1u) << p.err();
  EXPECT_NE(p.err().find("no/such/file.pcap"), std::string::npos) << p.err();

  Process t(kTracker, {"--replay", "no/such/file.pcap", "--sensor-id", "s"});
  EXPECT_EQ(t.Wait(), 1);
  EXPECT_NE(t.err().find("no/such/file.pcap"), std::string::npos) << t.err();
}

TEST(CliTest, TrackerBadArgumentsGiveOneLineAndExitCode2) {
  const std::vector<BadArgs> cases = {
      {{}, 2},
      {{"--sensor", "127.0.0.1"}, 2},                                            // no --sensor-id
      {{"--sensor-id", "s"}, 2},                                                 // no source
      {{"--sensor", "127.0.0.1", "--replay", "x.pcap", "--sensor-id", "s"}, 2},  // two sources
      {{"--sensor", "127.0.0.1:99999", "--sensor-id", "s"}, 2},
      {{"--sensor", "127.0.0.1:", "--sensor-id", "s"}, 2},
      {{"--sensor", "127.0.0.1", "--sensor-id", "s", "--print-every", "-1"}, 2},
      {{"--sensor", "127.0.0.1", "--sensor-id", "s", "--uplink", "127.0.0.1"}, 2},  // no port
      {{"--sensor", "127.0.0.1", "--sensor-id", "bad id"}, 2},
      {{"--sensor", "127.0.0.1", "--sensor-id", "s", "--config", "no/such/config.yaml"}, 2},
      {{"--sensor", "127.0.0.1", "--sensor-id", "s", "--bogus"}, 2},
      {{"--sensor", "127.0.0.1", "--sensor-id", "s", "--reply-timeout-ms", "0"}, 2},
      {{"--sensor", "127.0.0.1", "--sensor-id", "s", "--log-level", "loud"}, 2},
  };
  for (const BadArgs& c : cases) {
    SCOPED_TRACE(::testing::PrintToString(c.args));
    ExpectOneLineError(kTracker, c);
  }
}

TEST(CliTest, HelpExitsZeroAndDescribesTheCommand) {
  for (const auto& [binary, args, needle] :
       std::vector<std::tuple<const char*, std::vector<std::string>, std::string>>{
           {kTool, {"--help"}, "emulate"},
           {kTool, {"dump", "--help"}, "--summary"},
           {kTool, {"emulate", "--help"}, "--port-file"},
           {kTracker, {"--help"}, "--sensor-id"}}) {
    Process p(binary, args);
    EXPECT_EQ(p.Wait(), 0) << ::testing::PrintToString(args);
    EXPECT_NE(p.out().find(needle), std::string::npos) << p.out();
  }
}

TEST(CliTest, DumpBinaryPrintsTheLibraryOutputAndASummary) {
  LRFNET_REQUIRE_SHARED_FILE(capture, "data/sick/test.pcapng");
  std::ostringstream expected;
  std::string error;
  ASSERT_TRUE(tools::DumpCapture(capture, {}, &expected, nullptr, &error)) << error;
  Process dump(kTool, {"dump", capture});
  ASSERT_EQ(dump.Wait(), 0) << dump.err();
  EXPECT_EQ(dump.out(), expected.str());
  EXPECT_EQ(CountLines(dump.out()), 16u);

  Process summary(kTool, {"dump", "--summary", capture});
  ASSERT_EQ(summary.Wait(), 0) << summary.err();
  EXPECT_EQ(CountLines(summary.out()), 1u);
  EXPECT_NE(summary.out().find("\"scans\": 16"), std::string::npos) << summary.out();
  EXPECT_NE(summary.out().find("\"frames\": 16"), std::string::npos) << summary.out();
}

TEST(CliTest, TrackerReplaysACapture) {
  LRFNET_REQUIRE_SHARED_FILE(capture, "data/sick/lms111_20210302.pcap");
  Process all(kTracker, {"--replay", capture, "--sensor-id", "r1", "--print-every", "1",
                         "--log-level", "warn"});
  ASSERT_EQ(all.Wait(), 0) << all.err();
  EXPECT_EQ(CountPrefixed(all.out(), "r1 tc="), 172u);
  EXPECT_NE(all.out().find("summary: sensor=r1 mode=replay scans=172"), std::string::npos)
      << all.out();
  EXPECT_NE(all.out().find("r1 tc=63350 "), std::string::npos) << "a retransmitted scan is missing";

  Process some(kTracker, {"--replay", capture, "--sensor-id", "r1", "--max-scans", "30",
                          "--print-every", "10", "--log-level", "warn"});
  ASSERT_EQ(some.Wait(), 0) << some.err();
  EXPECT_EQ(CountPrefixed(some.out(), "r1 tc="), 3u);
  EXPECT_NE(some.out().find("scans=30"), std::string::npos) << some.out();
}

TEST(CliTest, TrackerStreamsFromTheEmulatorProcessAndStopsOnSigint) {
  Process emulator(kTool, {"emulate", "--synthetic", "lms511", "--port", "0", "--speed", "4",
                           "--log-level", "info"});
  ASSERT_TRUE(emulator.WaitForOutput("\n", seconds(10))) << emulator.err();
  const std::string line = emulator.out();
  const std::string prefix = "lrfnet emulate: listening on 127.0.0.1:";
  ASSERT_EQ(line.rfind(prefix, 0), 0u) << line;
  const std::string port = line.substr(prefix.size(), line.find('\n') - prefix.size());

  Process tracker(kTracker, {"--sensor", "127.0.0.1:" + port, "--sensor-id", "e2e", "--max-scans",
                             "20", "--print-every", "5", "--log-level", "info"});
  // 20 scans take 0.2 s; the info log (connect, dialogue, first scan) says where a slow run stood.
  ASSERT_EQ(tracker.Wait(seconds(30)), 0) << tracker.err() << "\nemulator: " << emulator.err();
  EXPECT_EQ(CountPrefixed(tracker.out(), "e2e tc="), 4u) << tracker.out();
  EXPECT_NE(tracker.out().find("e2e tc=1 sc=1 points=1141"), std::string::npos) << tracker.out();
  EXPECT_NE(tracker.out().find("summary: sensor=e2e mode=live scans=20 connects=1"),
            std::string::npos)
      << tracker.out();
  EXPECT_NE(tracker.out().find("ident='LMS511-10100'"), std::string::npos) << tracker.out();

  // Without --max-scans the tracker runs until a signal, then prints its counters and exits 0.
  Process endless(kTracker, {"--sensor", "127.0.0.1:" + port, "--sensor-id", "sig", "--print-every",
                             "1", "--log-level", "warn"});
  ASSERT_TRUE(endless.WaitForOutput("sig tc=", seconds(10))) << endless.err();
  endless.Signal(SIGINT);
  EXPECT_EQ(endless.Wait(seconds(10)), 0) << endless.err();
  EXPECT_NE(endless.out().find("summary: sensor=sig mode=live"), std::string::npos)
      << endless.out();

  emulator.Signal(SIGTERM);
  EXPECT_EQ(emulator.Wait(seconds(10)), 0) << emulator.err();
}

TEST(CliTest, EmulatorWritesThePortFile) {
  const std::string port_file =
      (std::filesystem::path(::testing::TempDir()) / ("lrfnet_port_" + std::to_string(::getpid())))
          .string();
  std::filesystem::remove(port_file);
  Process emulator(kTool, {"emulate", "--synthetic", "tim781", "--port", "0", "--port-file",
                           port_file, "--log-level", "warn"});
  ASSERT_TRUE(emulator.WaitForOutput("listening", seconds(10))) << emulator.err();
  const std::string port = ReadText(port_file);
  EXPECT_NE(emulator.out().find("127.0.0.1:" + port.substr(0, port.find('\n')) + "\n"),
            std::string::npos)
      << emulator.out() << " vs port file " << port;
  emulator.Signal(SIGTERM);
  EXPECT_EQ(emulator.Wait(seconds(10)), 0);
  std::filesystem::remove(port_file);
}

}  // namespace
}  // namespace lrfnet
