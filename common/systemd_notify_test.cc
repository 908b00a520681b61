#include "common/systemd_notify.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "tests/support/notify_socket.h"

namespace lrfnet::common {
namespace {

using testing::FakeNotifySocket;

// Every message waiting now (the first waited for up to wait_ms).
std::vector<std::string> Drain(FakeNotifySocket& manager, int wait_ms = 200) {
  return manager.Receive(std::chrono::milliseconds(wait_ms));
}

std::string TempSocketPath(const char* name) {
  return (std::filesystem::path(::testing::TempDir()) /
          (std::string(name) + "_" + std::to_string(::getpid())))
      .string();
}

TEST(NotifyEnvironmentTest, ReadsSocketAndWatchdogForThisProcess) {
  NotifyEnvironment env = ParseNotifyEnvironment("/run/systemd/notify", "30000000", nullptr, 42);
  EXPECT_EQ(env.socket, "/run/systemd/notify");
  EXPECT_EQ(env.watchdog_timeout_ns, 30 * kNsPerS);
  env = ParseNotifyEnvironment("@notify", "2000000", "42", 42);
  EXPECT_EQ(env.socket, "@notify");
  EXPECT_EQ(env.watchdog_timeout_ns, 2 * kNsPerS);
}

TEST(NotifyEnvironmentTest, NoWatchdogForAnotherProcessOrBadValues) {
  EXPECT_EQ(ParseNotifyEnvironment("/n", "2000000", "41", 42).watchdog_timeout_ns, 0);
  EXPECT_EQ(ParseNotifyEnvironment("/n", "2000000", "x", 42).watchdog_timeout_ns, 0);
  EXPECT_EQ(ParseNotifyEnvironment("/n", "0", nullptr, 42).watchdog_timeout_ns, 0);
  EXPECT_EQ(ParseNotifyEnvironment("/n", "-5", nullptr, 42).watchdog_timeout_ns, 0);
  EXPECT_EQ(ParseNotifyEnvironment("/n", "12abc", nullptr, 42).watchdog_timeout_ns, 0);
  EXPECT_EQ(ParseNotifyEnvironment("/n", "", nullptr, 42).watchdog_timeout_ns, 0);
  EXPECT_EQ(
      ParseNotifyEnvironment("/n", "99999999999999999999999", nullptr, 42).watchdog_timeout_ns, 0);
  const NotifyEnvironment none = ParseNotifyEnvironment(nullptr, nullptr, nullptr, 42);
  EXPECT_TRUE(none.socket.empty());
  EXPECT_EQ(none.watchdog_timeout_ns, 0);
}

TEST(SystemdNotifierTest, UnsupervisedDoesNothing) {
  SystemdNotifier notifier(NotifyEnvironment{});
  EXPECT_FALSE(notifier.enabled());
  EXPECT_FALSE(notifier.watchdog_enabled());
  EXPECT_FALSE(notifier.Ready());
  notifier.Watchdog(0);
  EXPECT_EQ(notifier.counters().sent, 0u);
  EXPECT_EQ(notifier.counters().send_errors, 0u);
  EXPECT_TRUE(notifier.error().empty());
}

TEST(SystemdNotifierTest, SendsReadyStatusAndStoppingToAPathSocket) {
  const std::string path = TempSocketPath("notify");
  FakeNotifySocket manager(path);
  SystemdNotifier notifier({path, 0});
  ASSERT_TRUE(notifier.enabled()) << notifier.error();
  EXPECT_TRUE(notifier.Ready("streaming from 10.0.0.5:2112"));
  EXPECT_TRUE(notifier.Status("3 sensors"));
  EXPECT_TRUE(notifier.Stopping());
  EXPECT_EQ(Drain(manager),
            (std::vector<std::string>{"READY=1\nSTATUS=streaming from 10.0.0.5:2112",
                                      "STATUS=3 sensors", "STOPPING=1"}));
  EXPECT_EQ(notifier.counters().sent, 3u);
}

TEST(SystemdNotifierTest, AbstractSocket) {
  const std::string name = "@lrfnet_notify_test_" + std::to_string(::getpid());
  FakeNotifySocket manager(name);
  SystemdNotifier notifier({name, 0});
  ASSERT_TRUE(notifier.enabled()) << notifier.error();
  EXPECT_TRUE(notifier.Ready());
  EXPECT_EQ(Drain(manager), std::vector<std::string>{"READY=1"});
}

TEST(SystemdNotifierTest, WatchdogAtAQuarterOfTheTimeoutOnly) {
  const std::string path = TempSocketPath("watchdog");
  FakeNotifySocket manager(path);
  SystemdNotifier notifier({path, 4 * kNsPerS});
  ASSERT_TRUE(notifier.watchdog_enabled());
  // Scans every 40 ms over 5 s: the first at once, then one per second.
  for (DurationNs t = 0; t <= 5 * kNsPerS; t += 40 * kNsPerMs) notifier.Watchdog(t);
  const std::vector<std::string> got = Drain(manager);
  EXPECT_EQ(got.size(), 6u);
  for (const std::string& m : got) EXPECT_EQ(m, "WATCHDOG=1");
  EXPECT_EQ(notifier.counters().watchdogs, 6u);
}

TEST(SystemdNotifierTest, NoWatchdogWithoutTimeout) {
  const std::string path = TempSocketPath("nowatchdog");
  FakeNotifySocket manager(path);
  SystemdNotifier notifier({path, 0});
  for (DurationNs t = 0; t < 10 * kNsPerS; t += kNsPerS) notifier.Watchdog(t);
  EXPECT_TRUE(Drain(manager, 50).empty());
}

TEST(SystemdNotifierTest, BadOrMissingSocketIsAnErrorNotACrash) {
  SystemdNotifier relative({"notify", 0});
  EXPECT_FALSE(relative.enabled());
  EXPECT_NE(relative.error().find("neither a path"), std::string::npos) << relative.error();
  SystemdNotifier missing({TempSocketPath("absent"), kNsPerS});
  EXPECT_NE(missing.error().find("No such file"), std::string::npos) << missing.error();
  missing.Watchdog(0);
  EXPECT_FALSE(missing.Ready());
  EXPECT_EQ(missing.counters().send_errors, 2u);
  EXPECT_EQ(missing.counters().sent, 0u);
  SystemdNotifier too_long({"/" + std::string(200, 'x'), 0});
  EXPECT_FALSE(too_long.enabled());
  EXPECT_FALSE(too_long.error().empty());
}

TEST(SystemdNotifierTest, ManagerGoneIsCountedAndARestartedOneIsFoundAgain) {
  const std::string path = TempSocketPath("restart");
  auto manager = std::make_unique<FakeNotifySocket>(path);
  SystemdNotifier notifier({path, kNsPerS});
  ASSERT_TRUE(notifier.enabled());
  manager.reset();
  EXPECT_FALSE(notifier.Status("nobody listens"));
  EXPECT_EQ(notifier.counters().send_errors, 1u);
  manager =
      std::make_unique<FakeNotifySocket>(path);  // the manager re-executed: same name, new socket
  EXPECT_TRUE(notifier.Status("back"));
  EXPECT_EQ(Drain(*manager), std::vector<std::string>{"STATUS=back"});
}

}  // namespace
}  // namespace lrfnet::common
