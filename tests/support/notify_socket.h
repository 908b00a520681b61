#pragma once
// Test-only: the service manager's end of sd_notify(3), an AF_UNIX datagram socket bound to a path
// (or '@' + name: the abstract namespace) that collects what a process sends to $NOTIFY_SOCKET.

#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstddef>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

namespace lrfnet::testing {

class FakeNotifySocket {
 public:
  explicit FakeNotifySocket(const std::string& name) : name_(name) {
    fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un address{};
    address.sun_family = AF_UNIX;
    std::memcpy(address.sun_path, name.data(), std::min(name.size(), sizeof(address.sun_path)));
    if (!name.empty() && name[0] == '@') address.sun_path[0] = '\0';
    const auto length = static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + name.size());
    if (::bind(fd_, reinterpret_cast<const sockaddr*>(&address), length) != 0) {
      error_ = std::strerror(errno);
    }
  }
  ~FakeNotifySocket() {
    ::close(fd_);
    if (!name_.empty() && name_[0] == '/') {
      std::error_code ec;
      std::filesystem::remove(name_, ec);
    }
  }
  FakeNotifySocket(const FakeNotifySocket&) = delete;
  FakeNotifySocket& operator=(const FakeNotifySocket&) = delete;

  const std::string& name() const { return name_; }
  // Empty when the socket is bound.
  const std::string& error() const { return error_; }

  // The messages that arrive within `wait` of the call (the first one waited for, the rest taken
  // as long as more arrive within `wait` each).
  std::vector<std::string> Receive(std::chrono::milliseconds wait) {
    std::vector<std::string> out;
    pollfd p{fd_, POLLIN, 0};
    while (::poll(&p, 1, static_cast<int>(wait.count())) == 1) {
      char buf[4096];
      const ssize_t n = ::recv(fd_, buf, sizeof(buf), 0);
      if (n < 0) break;
      out.emplace_back(buf, static_cast<std::size_t>(n));
    }
    return out;
  }

  // Every message that arrives until `duration` has passed.
  std::vector<std::string> ReceiveFor(std::chrono::milliseconds duration) {
    std::vector<std::string> out;
    const auto end = std::chrono::steady_clock::now() + duration;
    while (true) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          end - std::chrono::steady_clock::now());
      if (left.count() <= 0) break;
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, static_cast<int>(left.count())) != 1) break;
      char buf[4096];
      const ssize_t n = ::recv(fd_, buf, sizeof(buf), 0);
      if (n < 0) break;
      out.emplace_back(buf, static_cast<std::size_t>(n));
    }
    return out;
  }

  // Waits up to `timeout` for a message that starts with `prefix`; the messages before it are
  // appended to *before (when given).
  bool WaitFor(const std::string& prefix, std::chrono::milliseconds timeout,
               std::vector<std::string>* before = nullptr, std::string* found = nullptr) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < end) {
      for (std::string& m : ReceiveFor(std::chrono::milliseconds(50))) {
        if (m.rfind(prefix, 0) == 0) {
          if (found != nullptr) *found = m;
          return true;
        }
        if (before != nullptr) before->push_back(std::move(m));
      }
    }
    return false;
  }

 private:
  std::string name_;
  std::string error_;
  int fd_ = -1;
};

}  // namespace lrfnet::testing
