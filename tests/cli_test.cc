// The built binaries as a user runs them: exit codes, one-line errors, --help, dump and replay
// output, and `lrfnet emulate` + `lrfnet-tracker` as two processes over loopback (what
// scripts/demo.sh does).

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "tests/support/test_data.h"
#include "tools/dump.h"

extern char** environ;

namespace lrfnet {
namespace {

using std::chrono::milliseconds;
using std::chrono::seconds;

const char* const kTool = LRFNET_TOOL_BINARY;
const char* const kTracker = LRFNET_TRACKER_BINARY;

std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

std::size_t CountLines(const std::string& text) {
  return static_cast<std::size_t>(std::count(text.begin(), text.end(), '\n'));
}

std::size_t CountPrefixed(const std::string& text, const std::string& prefix) {
  std::size_t n = 0;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) n += line.rfind(prefix, 0) == 0 ? 1 : 0;
  return n;
}

class Process {
 public:
  // Starts `binary args...` with stdout and stderr redirected to files in a fresh temp folder.
  Process(const std::string& binary, const std::vector<std::string>& args) {
    static int counter = 0;
    dir_ = std::filesystem::path(::testing::TempDir()) /
           ("lrfnet_cli_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
    std::filesystem::create_directories(dir_);
    out_path_ = (dir_ / "stdout").string();
    err_path_ = (dir_ / "stderr").string();
    std::vector<std::string> argv_strings = {binary};
    argv_strings.insert(argv_strings.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (std::string& s : argv_strings) argv.push_back(s.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, out_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC,
                                     0644);
    posix_spawn_file_actions_addopen(&actions, 2, err_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC,
                                     0644);
    const int rc = posix_spawn(&pid_, binary.c_str(), &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    EXPECT_EQ(rc, 0) << "cannot start " << binary;
    if (rc != 0) pid_ = -1;
  }
  ~Process() {
    if (pid_ > 0 && !exited_) {
      ::kill(pid_, SIGKILL);
      int status = 0;
      ::waitpid(pid_, &status, 0);
    }
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  // Exit code, or -1 on timeout (then the process is killed) / -2 when killed by a signal.
  int Wait(milliseconds timeout = milliseconds(20'000)) {
    if (pid_ <= 0) return -3;
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (true) {
      int status = 0;
      const pid_t r = ::waitpid(pid_, &status, WNOHANG);
      if (r == pid_) {
        exited_ = true;
        return WIFEXITED(status) ? WEXITSTATUS(status) : -2;
      }
      if (std::chrono::steady_clock::now() > deadline) {
        ::kill(pid_, SIGKILL);
        ::waitpid(pid_, &status, 0);
        exited_ = true;
        return -1;
      }
      std::this_thread::sleep_for(milliseconds(10));
    }
  }
  void Signal(int signal_number) { ::kill(pid_, signal_number); }
  std::string out() const { return ReadText(out_path_); }
  std::string err() const { return ReadText(err_path_); }
  std::string dir() const { return dir_.string(); }

  // Polls stdout until it contains `text`.
  bool WaitForOutput(const std::string& text, milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      if (out().find(text) != std::string::npos) return true;
      std::this_thread::sleep_for(milliseconds(20));
    }
    return false;
  }

 private:
  std::filesystem::path dir_;
  std::string out_path_, err_path_;
  pid_t pid_ = -1;
  bool exited_ = false;
};

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
      {{"--sensor", "127.0.0.1", "--sensor-id", "s", "--print-every", "0"}, 2},
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
  Process all(kTracker, {"--replay", capture, "--sensor-id", "r1", "--log-level", "warn"});
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
                           "--log-level", "warn"});
  ASSERT_TRUE(emulator.WaitForOutput("\n", seconds(10))) << emulator.err();
  const std::string line = emulator.out();
  const std::string prefix = "lrfnet emulate: listening on 127.0.0.1:";
  ASSERT_EQ(line.rfind(prefix, 0), 0u) << line;
  const std::string port = line.substr(prefix.size(), line.find('\n') - prefix.size());

  Process tracker(kTracker, {"--sensor", "127.0.0.1:" + port, "--sensor-id", "e2e", "--max-scans",
                             "20", "--print-every", "5", "--log-level", "warn"});
  ASSERT_EQ(tracker.Wait(seconds(20)), 0) << tracker.err();
  EXPECT_EQ(CountPrefixed(tracker.out(), "e2e tc="), 4u) << tracker.out();
  EXPECT_NE(tracker.out().find("e2e tc=1 sc=1 points=1141"), std::string::npos) << tracker.out();
  EXPECT_NE(tracker.out().find("summary: sensor=e2e mode=live scans=20 connects=1"),
            std::string::npos)
      << tracker.out();
  EXPECT_NE(tracker.out().find("ident='LMS511-10100'"), std::string::npos) << tracker.out();

  // Without --max-scans the tracker runs until a signal, then prints its counters and exits 0.
  Process endless(kTracker,
                  {"--sensor", "127.0.0.1:" + port, "--sensor-id", "sig", "--log-level", "warn"});
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
