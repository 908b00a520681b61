#pragma once
// systemd's service notification protocol (sd_notify(3)), spoken without libsystemd: newline-
// separated "KEY=VALUE" assignments in one datagram to the AF_UNIX socket named by $NOTIFY_SOCKET.
// A unit with Type=notify waits for "READY=1"; with WatchdogSec= it expects "WATCHDOG=1" at least
// every $WATCHDOG_USEC and restarts the service when one is missing. Outside such a unit
// ($NOTIFY_SOCKET unset) every call does nothing.
//
// The binaries send READY=1 once their input is up (the tracker: the first scan from the scanner;
// lrfnetd: the UDP socket bound) and WATCHDOG=1 from the path that must not hang (the tracker:
// after each processed scan; lrfnetd: the io thread's tick, which also runs ingest), so a hung
// scanner link or io loop is what the watchdog catches.
//
// Thread-safety: none; one notifier per process, used from one thread.

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "common/time.h"

namespace lrfnet::common {

// What the service manager asked of this process, from its environment.
struct NotifyEnvironment {
  // $NOTIFY_SOCKET: a path, or '@' + name for the abstract namespace; empty: not supervised.
  std::string socket;
  // $WATCHDOG_USEC in ns when the watchdog applies to this process; 0: no watchdog.
  DurationNs watchdog_timeout_ns = 0;
};

// Pure: the environment's values (nullptr when unset) for process `pid`. A $WATCHDOG_PID naming
// another process (the watchdog is meant for it), or an unparsable or zero $WATCHDOG_USEC, gives no
// watchdog.
NotifyEnvironment ParseNotifyEnvironment(const char* notify_socket, const char* watchdog_usec,
                                         const char* watchdog_pid, long pid);

struct NotifyCounters {
  std::uint64_t sent = 0;         // datagrams delivered to the socket
  std::uint64_t send_errors = 0;  // datagrams the socket refused (manager gone, buffer full)
  std::uint64_t watchdogs = 0;    // of them WATCHDOG=1
};

class SystemdNotifier {
 public:
  // Connects to env.socket (nothing to do when it is empty). A name that is not a socket address
  // leaves the notifier disabled; a socket that refuses (not there yet, manager gone) is tried
  // again on the next message. error() says why; the program runs on either way.
  explicit SystemdNotifier(const NotifyEnvironment& env);
  // From this process's environment (getenv, getpid).
  static NotifyEnvironment ProcessEnvironment();
  ~SystemdNotifier();
  SystemdNotifier(const SystemdNotifier&) = delete;
  SystemdNotifier& operator=(const SystemdNotifier&) = delete;

  bool enabled() const { return valid_; }
  bool watchdog_enabled() const { return enabled() && watchdog_timeout_ns_ > 0; }
  DurationNs watchdog_timeout_ns() const { return watchdog_timeout_ns_; }
  const std::string& error() const { return error_; }
  const NotifyCounters& counters() const { return counters_; }

  // Sends `state` ("READY=1", "STATUS=...", several joined by '\n'). False when disabled or the
  // socket refused it (counted).
  bool Notify(std::string_view state);
  // READY=1 plus a STATUS= line when `status` is not empty.
  bool Ready(std::string_view status = {});
  bool Status(std::string_view status);
  bool Stopping();

  // The keep-alive, called from the path it vouches for with the steady clock's time: sends
  // WATCHDOG=1 when a quarter of the watchdog timeout has passed since the last one (the manual
  // asks for at least every half; the margin covers a loaded machine). No allocation while the
  // socket takes the messages.
  void Watchdog(DurationNs steady_now_ns);

 private:
  bool Send(const char* bytes, std::size_t size);
  bool Connect();

  std::string socket_;
  DurationNs watchdog_timeout_ns_ = 0;
  bool valid_ = false;
  int fd_ = -1;
  std::string error_;
  bool watchdog_sent_ = false;
  DurationNs last_watchdog_ns_ = 0;
  NotifyCounters counters_;
};

// The steady (monotonic) clock in ns, for Watchdog().
DurationNs SteadyNowNs();

}  // namespace lrfnet::common
