#pragma once
// Test-only: the daemon's end of a tracker's UDP uplink on loopback. A bound datagram socket with a
// large receive buffer that receives (remembering the sender), drains and replies to the sender,
// as lrfnetd answers a tracker's datagrams with Requests. Receive into a caller's buffer and Drain
// never allocate, so allocation-counting tests can use them.

#include <netinet/in.h>
#include <sys/socket.h>

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace lrfnet::testing {

class LoopbackUdpPeer {
 public:
  // AF_INET (127.0.0.1) or AF_INET6 (::1), port chosen by the kernel. ok() is false when the
  // family has no loopback here.
  explicit LoopbackUdpPeer(int family = AF_INET);
  ~LoopbackUdpPeer();
  LoopbackUdpPeer(const LoopbackUdpPeer&) = delete;
  LoopbackUdpPeer& operator=(const LoopbackUdpPeer&) = delete;

  bool ok() const { return fd_ >= 0; }
  std::uint16_t port() const { return port_; }

  // One datagram into `buffer` within timeout_ms (0: only what is queued). Returns its size, or -1
  // when none arrived. Remembers the sender for Reply.
  long ReceiveInto(std::span<std::uint8_t> buffer, int timeout_ms);
  // The same, as a vector (empty on timeout).
  std::vector<std::uint8_t> Receive(int timeout_ms = 2000);
  // Discards everything queued; returns how many datagrams.
  std::size_t Drain();
  // Sends `bytes` to the sender of the last received datagram.
  bool Reply(std::span<const std::uint8_t> bytes);

 private:
  int fd_ = -1;
  std::uint16_t port_ = 0;
  sockaddr_storage peer_{};
  socklen_t peer_len_ = 0;
};

}  // namespace lrfnet::testing
