#pragma once
// The tracker's UDP link to the daemon: datagrams out, the daemon's Requests in, on one socket.
//
// - Open() resolves HOST:PORT once (getaddrinfo, IPv4 or IPv6, the first address a socket can be
//   connected to), opens a non-blocking datagram socket and connect()s it to the daemon. Only Open
//   allocates (the resolver); Send and Poll never do.
// - Send() is one non-blocking send(2) per datagram. A full socket buffer (EAGAIN) or any other
//   error (e.g. ECONNREFUSED after an ICMP port-unreachable while the daemon is down) drops that
//   datagram and is counted; nothing is ever fatal or retried.
// - Between BeginBatch() and EndBatch() (UdpUplinkOptions::batch_sends) Send() copies the datagram
//   into one of kMaxHeldDatagrams fixed buffers instead, and EndBatch() sends the held ones, in
//   order, with one sendmmsg(2) (the system call's entry and exit once per scan, not once per
//   datagram: a scan of many tracks and a background snapshot send several; a lone datagram goes
//   with send(2), which costs less than sendmmsg's message headers). The same datagrams in
//   the same order; each one the kernel refuses is dropped and counted as a failed send(2) would
//   be. With every buffer full the held datagrams are sent at once. Close() sends what is held
//   first.
// - Poll() reads the datagrams queued on the socket (at most max_datagrams_per_poll per call) and
//   decodes Requests (RequestDecoder). Because the socket is connected, the kernel delivers only
//   datagrams from the daemon's address: the daemon answers from the socket the tracker sends to,
//   to the tracker's source address. With keys, only sealed Requests count (see RequestDecoder).
//   The pending flags accumulate until TakeRequests().
// Not thread-safe: one thread sends and polls (or the caller serialises).

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>

#include "common/time.h"
#include "firmware_tracker/io/datagram_encoder.h"
#include "firmware_tracker/io/request_decoder.h"

namespace lrfnet::io {

struct UdpUplinkOptions {
  std::string host;           // name or address of the daemon (IPv6 without brackets)
  std::uint16_t port = 0;     // daemon's UDP port
  std::string sensor_id;      // this tracker's id: Requests for other ids are ignored
  int send_buffer_bytes = 0;  // SO_SNDBUF; 0 keeps the system default
  std::size_t max_datagrams_per_poll = 16;
  // This sensor's keys when the uplink is authenticated: Requests must then be sealed for it
  // (RequestDecoder). The datagrams sent are sealed before they reach Send (SealingSink).
  std::optional<auth::SensorKeys> keys;
  // Datagrams sent between BeginBatch() and EndBatch() go out together, in one sendmmsg(2); false:
  // one send(2) each, as at any other time.
  bool batch_sends = true;
};
std::optional<std::string> Validate(const UdpUplinkOptions& options);

struct UdpUplinkCounters {
  std::uint64_t datagrams_sent = 0;
  std::uint64_t bytes_sent = 0;
  std::uint64_t send_errors = 0;  // every failed send, EAGAIN included
  std::uint64_t would_block = 0;  // of which: socket buffer full
  std::uint64_t oversize = 0;     // refused: larger than kMaxDatagramBytes (never from the encoder)
  std::uint64_t not_open = 0;     // Send before Open or after a failed Open
  std::uint64_t batches = 0;      // sendmmsg(2) calls (UdpUplinkOptions::batch_sends)
  std::uint64_t batched = 0;      // of the datagrams sent, those sent by sendmmsg(2)
  std::uint64_t received = 0;     // datagrams read by Poll
  std::uint64_t receive_errors = 0;
  int last_errno = 0;
};

struct PendingRequests {
  bool send_sensor_info = false;
  bool send_background = false;
  bool any() const { return send_sensor_info || send_background; }
};

class UdpUplink final : public DatagramSink {
 public:
  // Precondition: Validate(options) is nullopt (checked; aborts otherwise).
  explicit UdpUplink(const UdpUplinkOptions& options);
  ~UdpUplink() override;
  UdpUplink(const UdpUplink&) = delete;
  UdpUplink& operator=(const UdpUplink&) = delete;

  // nullopt on success, else one line saying what failed (resolution, socket, connect).
  std::optional<std::string> Open();
  void Close();
  bool is_open() const { return fd_ >= 0; }

  void Send(std::span<const std::uint8_t> datagram, common::UtcNs sent_ns) override;
  void BeginBatch() override;
  void EndBatch() override;

  // Returns the number of datagrams read.
  std::size_t Poll();
  // The flags requested since the last call; clears them.
  PendingRequests TakeRequests();

  // After Open: the daemon's address as resolved ("1.2.3.4:5000" / "[::1]:5000") and our local
  // port.
  const std::string& peer() const { return peer_; }
  std::uint16_t local_port() const;
  // The socket, for an event loop that waits for it to become readable (then calls Poll); -1 if
  // closed.
  int native_handle() const { return fd_; }

  const UdpUplinkCounters& counters() const { return counters_; }
  const RequestDecoderCounters& request_counters() const { return decoder_.counters(); }

 private:
  // One send(2).
  void SendNow(std::span<const std::uint8_t> datagram);
  // Sends the datagrams held since BeginBatch() (batch_sends): two or more in one sendmmsg(2).
  void SendHeld();
  void CountSendError(int error);

  UdpUplinkOptions options_;
  int fd_ = -1;
  std::string peer_;
  UdpUplinkCounters counters_;
  RequestDecoder decoder_;
  PendingRequests pending_;
  // One byte more than the largest acceptable datagram: with MSG_TRUNC the true size is reported.
  std::array<std::uint8_t, kMaxDatagramBytes + 1> receive_buffer_{};
  // The datagrams held since BeginBatch() (batch_sends), sent by SendHeld().
  static constexpr std::size_t kMaxHeldDatagrams = 8;
  bool batching_ = false;
  std::size_t held_count_ = 0;
  std::array<std::size_t, kMaxHeldDatagrams> held_bytes_{};
  std::array<std::array<std::uint8_t, kMaxDatagramBytes>, kMaxHeldDatagrams> held_{};
};

}  // namespace lrfnet::io
