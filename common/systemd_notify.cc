#include "common/systemd_notify.h"

#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <chrono>
#include <cstddef>
#include <cstdlib>
#include <cstring>

namespace lrfnet::common {
namespace {

// A decimal without sign or trailing characters, as systemd writes them.
std::optional<std::uint64_t> ParseUnsigned(const char* text) {
  if (text == nullptr || *text == '\0') return std::nullopt;
  const char* end = text + std::strlen(text);
  std::uint64_t value = 0;
  const auto [ptr, ec] = std::from_chars(text, end, value);
  if (ec != std::errc() || ptr != end) return std::nullopt;
  return value;
}

}  // namespace

NotifyEnvironment ParseNotifyEnvironment(const char* notify_socket, const char* watchdog_usec,
                                         const char* watchdog_pid, long pid) {
  NotifyEnvironment env;
  if (notify_socket != nullptr) env.socket = notify_socket;
  const std::optional<std::uint64_t> usec = ParseUnsigned(watchdog_usec);
  // sd_watchdog_enabled(3): WATCHDOG_PID, when set, names the process the watchdog is for.
  if (watchdog_pid != nullptr) {
    const std::optional<std::uint64_t> for_pid = ParseUnsigned(watchdog_pid);
    if (!for_pid || *for_pid != static_cast<std::uint64_t>(pid)) return env;
  }
  // Bounded so that the conversion to ns cannot overflow (a year is far beyond any WatchdogSec).
  constexpr std::uint64_t kMaxUsec = std::uint64_t{366} * 24 * 3600 * 1'000'000;
  if (usec && *usec > 0 && *usec <= kMaxUsec)
    env.watchdog_timeout_ns = static_cast<DurationNs>(*usec) * kNsPerUs;
  return env;
}

NotifyEnvironment SystemdNotifier::ProcessEnvironment() {
  return ParseNotifyEnvironment(std::getenv("NOTIFY_SOCKET"), std::getenv("WATCHDOG_USEC"),
                                std::getenv("WATCHDOG_PID"), static_cast<long>(::getpid()));
}

SystemdNotifier::SystemdNotifier(const NotifyEnvironment& env)
    : socket_(env.socket), watchdog_timeout_ns_(env.watchdog_timeout_ns) {
  if (socket_.empty()) return;
  if (socket_[0] != '/' && socket_[0] != '@') {
    error_ = "NOTIFY_SOCKET '" + socket_ + "' is neither a path nor an abstract socket (@name)";
    return;
  }
  if (socket_.size() >= sizeof(sockaddr_un::sun_path)) {
    error_ = "NOTIFY_SOCKET is longer than a socket address";
    return;
  }
  valid_ = true;
  if (!Connect()) error_ = "NOTIFY_SOCKET " + socket_ + ": " + std::strerror(errno);
}

SystemdNotifier::~SystemdNotifier() {
  if (fd_ >= 0) ::close(fd_);
}

bool SystemdNotifier::Connect() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
  if (fd_ < 0) return false;
  sockaddr_un address{};
  address.sun_family = AF_UNIX;
  std::memcpy(address.sun_path, socket_.data(), socket_.size());
  if (socket_[0] == '@') address.sun_path[0] = '\0';  // abstract namespace: no trailing NUL
  const auto length = static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + socket_.size());
  if (::connect(fd_, reinterpret_cast<const sockaddr*>(&address), length) != 0) {
    const int saved = errno;
    ::close(fd_);
    fd_ = -1;
    errno = saved;
    return false;
  }
  return true;
}

bool SystemdNotifier::Send(const char* bytes, std::size_t size) {
  if (!valid_) return false;
  // Non-blocking: the scan path never waits for the service manager. A manager that re-executed
  // itself has a new socket under the same name: connect again once.
  int error_number = 0;
  for (int attempt = 0; attempt < 2; ++attempt) {
    if (fd_ < 0 && !Connect()) {
      error_number = errno;
      break;
    }
    if (::send(fd_, bytes, size, MSG_NOSIGNAL) == static_cast<ssize_t>(size)) {
      ++counters_.sent;
      return true;
    }
    error_number = errno;
    if (error_number != ECONNREFUSED && error_number != ENOTCONN) break;
    ::close(fd_);
    fd_ = -1;
  }
  error_ = "NOTIFY_SOCKET " + socket_ + ": " + std::strerror(error_number);
  ++counters_.send_errors;
  return false;
}

bool SystemdNotifier::Notify(std::string_view state) { return Send(state.data(), state.size()); }

bool SystemdNotifier::Ready(std::string_view status) {
  if (status.empty()) return Notify("READY=1");
  return Notify("READY=1\nSTATUS=" + std::string(status));
}

bool SystemdNotifier::Status(std::string_view status) {
  return Notify("STATUS=" + std::string(status));
}

bool SystemdNotifier::Stopping() { return Notify("STOPPING=1"); }

void SystemdNotifier::Watchdog(DurationNs steady_now_ns) {
  if (!watchdog_enabled()) return;
  if (watchdog_sent_ && steady_now_ns - last_watchdog_ns_ < watchdog_timeout_ns_ / 4) return;
  static constexpr char kWatchdog[] = "WATCHDOG=1";
  if (Send(kWatchdog, sizeof(kWatchdog) - 1)) ++counters_.watchdogs;
  // Also after a failed send: retried at the same pace, not on every scan.
  watchdog_sent_ = true;
  last_watchdog_ns_ = steady_now_ns;
}

DurationNs SteadyNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace lrfnet::common
