// lrfnet-tracker and lrfnetd as systemd would run them (Type=notify, WatchdogSec=): a fake notify
// socket in $NOTIFY_SOCKET and $WATCHDOG_USEC, the binaries as processes. The tracker is ready at
// its first scan and feeds the watchdog only while scans flow: a scanner whose link hangs (the
// emulator stopped with SIGSTOP, its TCP connection open) gets no WATCHDOG=1, so systemd would
// restart the tracker. lrfnetd is ready once its socket is bound and feeds the watchdog from its
// tick.

#include <gtest/gtest.h>
#include <signal.h>
#include <stdlib.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <string>
#include <vector>

#include "tests/process_harness.h"
#include "tests/support/notify_socket.h"

namespace lrfnet {
namespace {

using std::chrono::milliseconds;
using std::chrono::seconds;
using testing::FakeNotifySocket;
using testing::Process;
using testing::ScratchDir;

const char* const kTool = LRFNET_TOOL_BINARY;
const char* const kTracker = LRFNET_TRACKER_BINARY;
const char* const kDaemon = LRFNET_DAEMON_BINARY;

// $NOTIFY_SOCKET and $WATCHDOG_USEC for the processes started while it lives (Process passes this
// process's environment on).
class NotifyEnvironment {
 public:
  NotifyEnvironment(const std::string& socket, std::chrono::microseconds watchdog) {
    ::setenv("NOTIFY_SOCKET", socket.c_str(), 1);
    ::setenv("WATCHDOG_USEC", std::to_string(watchdog.count()).c_str(), 1);
  }
  ~NotifyEnvironment() {
    ::unsetenv("NOTIFY_SOCKET");
    ::unsetenv("WATCHDOG_USEC");
  }
};

std::size_t Count(const std::vector<std::string>& messages, const std::string& message) {
  return static_cast<std::size_t>(std::count(messages.begin(), messages.end(), message));
}

// "lrfnet emulate: listening on 127.0.0.1:PORT" -> PORT.
std::string EmulatorPort(Process& emulator) {
  if (!emulator.WaitForOutput("\n", seconds(20))) return "";
  const std::string line = emulator.out();
  const std::string prefix = "lrfnet emulate: listening on 127.0.0.1:";
  if (line.rfind(prefix, 0) != 0) return "";
  return line.substr(prefix.size(), line.find('\n') - prefix.size());
}

TEST(ServiceTest, TrackerReadyAtFirstScanWatchdogWhileScansFlowNoneWhileTheLinkHangs) {
  ScratchDir dir;
  FakeNotifySocket manager(dir / "notify");
  ASSERT_TRUE(manager.error().empty()) << manager.error();
  Process emulator(kTool,
                   {"emulate", "--synthetic", "lms511", "--port", "0", "--log-level", "warn"});
  const std::string port = EmulatorPort(emulator);
  ASSERT_FALSE(port.empty()) << emulator.out() << emulator.err();

  // Quick reconnects, so the watchdog resumes soon after the link does.
  const std::string config = dir / "tracker.yaml";
  std::ofstream(config) << "link:\n  backoff_initial_ms: 100\n  backoff_max_ms: 500\n";
  // WatchdogSec=1s: WATCHDOG=1 every 250 ms while scans flow.
  NotifyEnvironment env(manager.name(), seconds(1));
  Process tracker(kTracker, {"--config", config, "--sensor", "127.0.0.1:" + port, "--sensor-id",
                             "notify-1", "--log-level", "warn"});

  std::vector<std::string> before;
  std::string ready;
  ASSERT_TRUE(manager.WaitFor("READY=1", seconds(30), &before, &ready)) << tracker.err();
  EXPECT_EQ(ready, "READY=1\nSTATUS=streaming from 127.0.0.1:" + port);
  EXPECT_EQ(Count(before, "WATCHDOG=1"), 0u) << "no watchdog before the first scan";

  // Scans flow: the keep-alive comes at a quarter of the timeout (8 in 2 s; at least 4 on a
  // loaded machine).
  const std::vector<std::string> flowing = manager.ReceiveFor(milliseconds(2000));
  EXPECT_GE(Count(flowing, "WATCHDOG=1"), 4u);

  // The link hangs: the device stops sending, its TCP connection stays open. After what was in
  // flight, no keep-alive at all.
  emulator.Signal(SIGSTOP);
  manager.ReceiveFor(milliseconds(500));
  const std::vector<std::string> hung = manager.ReceiveFor(milliseconds(3000));
  EXPECT_EQ(Count(hung, "WATCHDOG=1"), 0u) << "the watchdog is fed only by processed scans";

  // The device is back: the tracker reconnects and the keep-alive resumes.
  emulator.Signal(SIGCONT);
  EXPECT_TRUE(manager.WaitFor("WATCHDOG=1", seconds(30))) << tracker.err();

  tracker.Signal(SIGTERM);
  EXPECT_TRUE(manager.WaitFor("STOPPING=1", seconds(10)));
  EXPECT_EQ(tracker.Wait(seconds(20)), 0) << tracker.err();
  emulator.Signal(SIGTERM);
  EXPECT_EQ(emulator.Wait(seconds(10)), 0) << emulator.err();
}

TEST(ServiceTest, DaemonReadyOnceListeningWatchdogFromItsTickStatusAndStopping) {
  ScratchDir dir;
  FakeNotifySocket manager("@lrfnet_service_test_" + std::to_string(::getpid()));
  ASSERT_TRUE(manager.error().empty()) << manager.error();
  NotifyEnvironment env(manager.name(), seconds(1));
  Process daemon(kDaemon,
                 {"--listen", "127.0.0.1:0", "--status-interval-s", "0.5", "--log-level", "warn"});
  std::string ready;
  ASSERT_TRUE(manager.WaitFor("READY=1", seconds(20), nullptr, &ready)) << daemon.err();
  ASSERT_TRUE(daemon.WaitForOutput("listening ", seconds(5)));
  const std::string out = daemon.out();
  const std::string address = out.substr(10, out.find('\n') - 10);
  EXPECT_EQ(ready, "READY=1\nSTATUS=listening on " + address);

  // No tracker sends anything: the daemon is idle but alive, and says so.
  const std::vector<std::string> idle = manager.ReceiveFor(milliseconds(2000));
  EXPECT_GE(Count(idle, "WATCHDOG=1"), 4u);
  EXPECT_TRUE(std::any_of(idle.begin(), idle.end(), [](const std::string& m) {
    return m.rfind("STATUS=0 sensors", 0) == 0;
  })) << (idle.empty() ? "" : idle.back());

  daemon.Signal(SIGTERM);
  EXPECT_TRUE(manager.WaitFor("STOPPING=1", seconds(10)));
  EXPECT_EQ(daemon.Wait(seconds(20)), 0) << daemon.err();
}

TEST(ServiceTest, AnUnusableNotifySocketIsAWarningNotAFailure) {
  ScratchDir dir;
  NotifyEnvironment env(dir / "nobody_listens", seconds(1));
  Process daemon(kDaemon, {"--listen", "127.0.0.1:0", "--duration-s", "1"});
  EXPECT_EQ(daemon.Wait(seconds(20)), 0) << daemon.err();
  EXPECT_NE(daemon.out().find("listening "), std::string::npos);
  EXPECT_NE(daemon.err().find("systemd notification: NOTIFY_SOCKET"), std::string::npos)
      << daemon.err();
}

}  // namespace
}  // namespace lrfnet
