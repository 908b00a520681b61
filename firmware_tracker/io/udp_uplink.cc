#include "firmware_tracker/io/udp_uplink.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/uio.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace lrfnet::io {
namespace {

std::string AddressText(const sockaddr* addr) {
  char host[INET6_ADDRSTRLEN] = {};
  if (addr->sa_family == AF_INET) {
    const auto* a = reinterpret_cast<const sockaddr_in*>(addr);
    inet_ntop(AF_INET, &a->sin_addr, host, sizeof(host));
    return std::string(host) + ":" + std::to_string(ntohs(a->sin_port));
  }
  if (addr->sa_family == AF_INET6) {
    const auto* a = reinterpret_cast<const sockaddr_in6*>(addr);
    inet_ntop(AF_INET6, &a->sin6_addr, host, sizeof(host));
    return "[" + std::string(host) + "]:" + std::to_string(ntohs(a->sin6_port));
  }
  return "?";
}

}  // namespace

std::optional<std::string> Validate(const UdpUplinkOptions& options) {
  if (options.host.empty()) return "uplink: empty host";
  if (options.port == 0) return "uplink: port must be 1..65535";
  if (!IsValidSensorId(options.sensor_id))
    return "uplink: sensor id '" + options.sensor_id + "' must match [A-Za-z0-9_.-]{1,32}";
  if (options.send_buffer_bytes < 0) return "uplink: send_buffer_bytes must be >= 0";
  if (options.max_datagrams_per_poll == 0) return "uplink: max_datagrams_per_poll must be >= 1";
  return std::nullopt;
}

UdpUplink::UdpUplink(const UdpUplinkOptions& options)
    : options_(options), decoder_(options.sensor_id, options.keys) {
  if (const auto error = Validate(options)) {
    std::fprintf(stderr, "UdpUplink: invalid options: %s\n", error->c_str());
    std::abort();
  }
}

UdpUplink::~UdpUplink() { Close(); }

void UdpUplink::Close() {
  if (fd_ >= 0) {
    SendHeld();  // also empties the held datagrams
    ::close(fd_);
  }
  batching_ = false;
  fd_ = -1;
}

std::optional<std::string> UdpUplink::Open() {
  Close();
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_DGRAM;
  hints.ai_flags = AI_NUMERICSERV | AI_ADDRCONFIG;
  addrinfo* found = nullptr;
  const std::string port = std::to_string(options_.port);
  int rc = getaddrinfo(options_.host.c_str(), port.c_str(), &hints, &found);
  if (rc != 0 && (hints.ai_flags & AI_ADDRCONFIG) != 0) {
    // AI_ADDRCONFIG hides loopback-only families on hosts without a configured address of that
    // family.
    hints.ai_flags = AI_NUMERICSERV;
    rc = getaddrinfo(options_.host.c_str(), port.c_str(), &hints, &found);
  }
  if (rc != 0) {
    return "uplink: cannot resolve '" + options_.host + "': " + gai_strerror(rc);
  }
  std::string error = "uplink: no address for '" + options_.host + "'";
  for (const addrinfo* a = found; a != nullptr; a = a->ai_next) {
    const int fd =
        ::socket(a->ai_family, a->ai_socktype | SOCK_NONBLOCK | SOCK_CLOEXEC, a->ai_protocol);
    if (fd < 0) {
      error = std::string("uplink: socket: ") + std::strerror(errno);
      continue;
    }
    if (options_.send_buffer_bytes > 0) {
      // Best effort: the kernel caps it at net.core.wmem_max.
      ::setsockopt(fd, SOL_SOCKET, SO_SNDBUF, &options_.send_buffer_bytes,
                   sizeof(options_.send_buffer_bytes));
    }
    if (::connect(fd, a->ai_addr, a->ai_addrlen) != 0) {
      error = "uplink: connect to " + AddressText(a->ai_addr) + ": " + std::strerror(errno);
      ::close(fd);
      continue;
    }
    fd_ = fd;
    peer_ = AddressText(a->ai_addr);
    break;
  }
  freeaddrinfo(found);
  if (fd_ < 0) return error;
  return std::nullopt;
}

std::uint16_t UdpUplink::local_port() const {
  if (fd_ < 0) return 0;
  sockaddr_storage addr{};
  socklen_t len = sizeof(addr);
  if (::getsockname(fd_, reinterpret_cast<sockaddr*>(&addr), &len) != 0) return 0;
  if (addr.ss_family == AF_INET)
    return ntohs(reinterpret_cast<const sockaddr_in*>(&addr)->sin_port);
  if (addr.ss_family == AF_INET6)
    return ntohs(reinterpret_cast<const sockaddr_in6*>(&addr)->sin6_port);
  return 0;
}

void UdpUplink::Send(std::span<const std::uint8_t> datagram, common::UtcNs /*sent_ns*/) {
  if (fd_ < 0) {
    ++counters_.not_open;
    return;
  }
  if (datagram.size() > kMaxDatagramBytes) {
    ++counters_.oversize;
    return;
  }
  if (batching_) {
    if (held_count_ == kMaxHeldDatagrams) SendHeld();
    std::memcpy(held_[held_count_].data(), datagram.data(), datagram.size());
    held_bytes_[held_count_] = datagram.size();
    ++held_count_;
    return;
  }
  SendNow(datagram);
}

void UdpUplink::SendNow(std::span<const std::uint8_t> datagram) {
  ssize_t n;
  do {
    n = ::send(fd_, datagram.data(), datagram.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
  } while (n < 0 && errno == EINTR);
  if (n < 0) {
    CountSendError(errno);
    return;
  }
  ++counters_.datagrams_sent;
  counters_.bytes_sent += static_cast<std::uint64_t>(n);
}

void UdpUplink::CountSendError(int error) {
  ++counters_.send_errors;
  if (error == EAGAIN || error == EWOULDBLOCK) ++counters_.would_block;
  counters_.last_errno = error;
}

void UdpUplink::BeginBatch() { batching_ = options_.batch_sends && fd_ >= 0; }

void UdpUplink::EndBatch() {
  SendHeld();
  batching_ = false;
}

void UdpUplink::SendHeld() {
  const std::size_t count = held_count_;
  held_count_ = 0;
  if (count == 0 || fd_ < 0) return;
  if (count == 1) {
    // One send(2): sendmmsg's message headers would cost more than they save.
    SendNow(std::span<const std::uint8_t>(held_[0].data(), held_bytes_[0]));
    return;
  }
  std::array<iovec, kMaxHeldDatagrams> parts{};
  std::array<mmsghdr, kMaxHeldDatagrams> messages{};
  for (std::size_t i = 0; i < count; ++i) {
    parts[i].iov_base = held_[i].data();
    parts[i].iov_len = held_bytes_[i];
    messages[i].msg_hdr.msg_iov = &parts[i];
    messages[i].msg_hdr.msg_iovlen = 1;
  }
  // sendmmsg stops at the first datagram the kernel refuses: with none sent before it that one's
  // error is returned, else the count sent so far and the next call starts at it. A refused
  // datagram is dropped and counted, and the rest go on, as with one send(2) each.
  std::size_t next = 0;
  while (next < count) {
    const int n = ::sendmmsg(fd_, messages.data() + next, static_cast<unsigned>(count - next),
                             MSG_DONTWAIT | MSG_NOSIGNAL);
    if (n < 0 && errno == EINTR) continue;
    ++counters_.batches;
    if (n <= 0) {
      CountSendError(n < 0 ? errno : 0);
      ++next;
      continue;
    }
    for (std::size_t i = next; i < next + static_cast<std::size_t>(n); ++i) {
      ++counters_.datagrams_sent;
      ++counters_.batched;
      counters_.bytes_sent += messages[i].msg_len;
    }
    next += static_cast<std::size_t>(n);
  }
}

std::size_t UdpUplink::Poll() {
  if (fd_ < 0) return 0;
  std::size_t read = 0;
  while (read < options_.max_datagrams_per_poll) {
    // MSG_TRUNC: the return value is the datagram's real length, so an oversized one is recognised.
    const ssize_t n =
        ::recv(fd_, receive_buffer_.data(), receive_buffer_.size(), MSG_DONTWAIT | MSG_TRUNC);
    if (n < 0) {
      if (errno == EINTR) continue;
      if (errno != EAGAIN && errno != EWOULDBLOCK) {
        // ECONNREFUSED from an earlier send's ICMP error is reported here too; not fatal.
        ++counters_.receive_errors;
        counters_.last_errno = errno;
      }
      break;
    }
    ++read;
    ++counters_.received;
    const auto size = static_cast<std::size_t>(n);
    const DecodedRequest request =
        size > kMaxDatagramBytes
            ? decoder_.Decode(
                  std::span<const std::uint8_t>(receive_buffer_.data(), receive_buffer_.size()))
            : decoder_.Decode(std::span<const std::uint8_t>(receive_buffer_.data(), size));
    if (request.reject == RequestReject::kNone) {
      pending_.send_sensor_info |= request.send_sensor_info;
      pending_.send_background |= request.send_background;
    }
  }
  return read;
}

PendingRequests UdpUplink::TakeRequests() {
  const PendingRequests r = pending_;
  pending_ = {};
  return r;
}

}  // namespace lrfnet::io
