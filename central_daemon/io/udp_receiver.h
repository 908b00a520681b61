#pragma once
// The daemon's UDP socket (Boost.Asio adapter): receives the trackers' datagrams and sends the
// daemon's Requests back to them from the same socket (a tracker's socket is connected to the
// daemon's address, so only datagrams from that address reach it).
//
// - Open() binds ADDRESS:PORT (IPv4, IPv6; "::" also accepts IPv4 unless the system forbids dual
//   stack), sets the receive buffer (SO_RCVBUFFORCE where permitted, else SO_RCVBUF capped by the
//   system's net.core.rmem_max: receive_buffer_bytes() tells what the kernel granted) and asks for
//   kernel receive timestamps (SO_TIMESTAMPNS).
// - Receiving is batched: when the socket is readable, recvmmsg(2) takes up to batch_datagrams per
//   call, repeatedly until the socket is empty or max_datagrams_per_wakeup were handled (then the
//   io_context runs other handlers — timers, signals — before it goes on). Every datagram goes to
//   the handler with its bytes (up to 64 KiB, never cut), its sender as "ip:port" / "[ipv6]:port"
//   (IPv4-mapped IPv6 senders shown as IPv4) and the kernel's receive time (UTC ns; the clock at
//   read time when the kernel gave none).
// - SendTo() is a non-blocking sendto(2); a full buffer or an error is counted and the datagram is
//   dropped.
// All buffers are allocated in Open(); receiving allocates only when a new sender appears (its
// address string is cached). Not thread-safe: one io_context thread.

#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/udp.hpp>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <memory>
#include <string_view>

#include "common/time.h"

namespace lrfnet::daemon {

struct UdpReceiverOptions {
  std::string address = "::";  // bind address (IPv4 or IPv6 literal, or a name)
  std::uint16_t port = 5800;
  int receive_buffer_bytes = 16 << 20;  // requested SO_RCVBUF (>= 64 KiB)
  std::size_t batch_datagrams = 64;     // per recvmmsg call (1..1024)
  std::size_t max_datagrams_per_wakeup = 4096;
};
std::optional<std::string> Validate(const UdpReceiverOptions& options);

struct UdpReceiverCounters {
  std::uint64_t datagrams = 0;
  std::uint64_t bytes = 0;
  std::uint64_t batches = 0;         // recvmmsg calls that returned datagrams
  std::uint64_t receive_errors = 0;  // errors other than "would block"
  std::uint64_t truncated = 0;       // larger than 64 KiB (cannot happen for UDP over IPv4/6)
  std::uint64_t kernel_drops = 0;    // SO_RXQ_OVFL: datagrams the kernel dropped (buffer full)
  std::uint64_t sent = 0;
  std::uint64_t send_errors = 0;
  std::uint64_t unknown_destinations = 0;  // SendTo with a source never seen
};

class UdpReceiver {
 public:
  using Handler = std::function<void(std::span<const std::uint8_t> bytes,
                                     const std::string& source, common::UtcNs receive_ns)>;

  UdpReceiver(boost::asio::io_context& io, const UdpReceiverOptions& options, Handler handler);
  ~UdpReceiver();
  UdpReceiver(const UdpReceiver&) = delete;
  UdpReceiver& operator=(const UdpReceiver&) = delete;

  // Resolves, binds and starts receiving. nullopt on success, else one line.
  std::optional<std::string> Open();
  void Close();

  // Sends to a sender seen before (`source` as given to the handler). False when dropped.
  bool SendTo(std::string_view source, std::span<const std::uint8_t> bytes);

  // The bound address as "ip:port" (the port the kernel chose when options.port was 0).
  std::string local_address() const;
  std::uint16_t local_port() const;
  int receive_buffer_bytes() const { return granted_buffer_bytes_; }
  const UdpReceiverCounters& counters() const { return counters_; }

 private:
  struct Slots;  // recvmmsg buffers and the sender cache
  void Wait();
  void Drain();

  boost::asio::io_context& io_;
  UdpReceiverOptions options_;
  Handler handler_;
  boost::asio::ip::udp::socket socket_;
  int granted_buffer_bytes_ = 0;
  UdpReceiverCounters counters_;
  std::unique_ptr<Slots> slots_;
};

}  // namespace lrfnet::daemon
