#include "tests/support/udp_peer.h"

#include <arpa/inet.h>
#include <poll.h>
#include <unistd.h>

#include <array>

namespace lrfnet::testing {

LoopbackUdpPeer::LoopbackUdpPeer(int family) {
  fd_ = ::socket(family, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd_ < 0) return;
  sockaddr_storage addr{};
  socklen_t len = 0;
  if (family == AF_INET) {
    auto* a = reinterpret_cast<sockaddr_in*>(&addr);
    a->sin_family = AF_INET;
    a->sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    len = sizeof(sockaddr_in);
  } else {
    auto* a = reinterpret_cast<sockaddr_in6*>(&addr);
    a->sin6_family = AF_INET6;
    a->sin6_addr = in6addr_loopback;
    len = sizeof(sockaddr_in6);
  }
  if (::bind(fd_, reinterpret_cast<sockaddr*>(&addr), len) != 0) {
    ::close(fd_);
    fd_ = -1;
    return;
  }
  // Room for a burst of a replayed capture between drains.
  const int buffer_bytes = 8 << 20;
  ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &buffer_bytes, sizeof buffer_bytes);
  len = sizeof(addr);
  ::getsockname(fd_, reinterpret_cast<sockaddr*>(&addr), &len);
  port_ = family == AF_INET ? ntohs(reinterpret_cast<sockaddr_in*>(&addr)->sin_port)
                            : ntohs(reinterpret_cast<sockaddr_in6*>(&addr)->sin6_port);
}

LoopbackUdpPeer::~LoopbackUdpPeer() {
  if (fd_ >= 0) ::close(fd_);
}

long LoopbackUdpPeer::ReceiveInto(std::span<std::uint8_t> buffer, int timeout_ms) {
  pollfd p{fd_, POLLIN, 0};
  if (::poll(&p, 1, timeout_ms) != 1) return -1;
  peer_len_ = sizeof(peer_);
  const ssize_t n = ::recvfrom(fd_, buffer.data(), buffer.size(), 0,
                               reinterpret_cast<sockaddr*>(&peer_), &peer_len_);
  return n >= 0 ? static_cast<long>(n) : -1;
}

std::vector<std::uint8_t> LoopbackUdpPeer::Receive(int timeout_ms) {
  std::vector<std::uint8_t> buffer(2048);
  const long n = ReceiveInto(buffer, timeout_ms);
  buffer.resize(n > 0 ? static_cast<std::size_t>(n) : 0);
  return buffer;
}

std::size_t LoopbackUdpPeer::Drain() {
  std::array<std::uint8_t, 2048> buffer{};
  std::size_t n = 0;
  while (::recv(fd_, buffer.data(), buffer.size(), MSG_DONTWAIT) > 0) ++n;
  return n;
}

bool LoopbackUdpPeer::Reply(std::span<const std::uint8_t> bytes) {
  return ::sendto(fd_, bytes.data(), bytes.size(), 0, reinterpret_cast<sockaddr*>(&peer_),
                  peer_len_) == static_cast<ssize_t>(bytes.size());
}

}  // namespace lrfnet::testing
