#pragma once
// One direction of one TCP connection read from a pcap / pcapng file, reassembled into the byte stream the
// application saw: the scanner -> client stream of a SICK session by default. Packet timestamps become
// receive times. Built from PcapReader (libpcap adapter), ParsePacket (pure) and TcpReassembler (pure).

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>

#include "common/time.h"

namespace lrfnet::capture {

struct CaptureStreamOptions {
  // The device's TCP port: bytes sent *from* this port are the scanner -> client stream.
  std::uint16_t sensor_port = 2112;
  // false: the client -> scanner direction instead (commands).
  bool from_sensor = true;
  // Out-of-order bytes held while waiting for a missing segment; beyond this the gap is skipped and counted.
  std::size_t max_pending_bytes = 1 << 20;
};
std::optional<std::string> Validate(const CaptureStreamOptions& options);

struct CaptureCounters {
  std::uint64_t packets = 0;              // all packets read
  std::uint64_t stream_packets = 0;       // TCP packets of the selected direction
  std::uint64_t ignored_packets = 0;      // other protocols, ports or directions (ARP, ACKs the other way…)
  std::uint64_t malformed_packets = 0;    // truncated or inconsistent headers (dropped)
  std::uint64_t retransmitted_bytes = 0;  // bytes already delivered (duplicates, overlaps): dropped
  std::uint64_t out_of_order_segments = 0;
  std::uint64_t gaps = 0;                 // holes in the stream that were given up on
  std::uint64_t gap_bytes = 0;
  std::uint64_t out_of_window_segments = 0;  // stray far-ahead segments dropped (see TcpReassembler)
  std::uint64_t connections = 0;          // SYNs of the selected direction (new streams)
  std::uint64_t delivered_bytes = 0;
};

struct StreamChunk {
  std::span<const std::uint8_t> bytes;  // valid until the next call to Next()
  common::UtcNs receive_time_ns = 0;    // capture timestamp of the packet that delivered these bytes
  bool discontinuity = false;           // a gap or a new connection precedes these bytes: reset parsers
};

class CaptureStream {
 public:
  virtual ~CaptureStream() = default;
  // Opens a pcap or pcapng file (any link type libpcap reads that carries Ethernet, Linux SLL, raw IP or
  // BSD loopback). On failure returns nullptr and sets *error to one line naming the file and the reason.
  static std::unique_ptr<CaptureStream> Open(const std::string& path, const CaptureStreamOptions& options,
                                             std::string* error);
  // Next chunk of in-order stream bytes; false at the end of the capture (after flushing what is held).
  virtual bool Next(StreamChunk* chunk) = 0;
  virtual const CaptureCounters& counters() const = 0;
  // Non-empty when the file ended in a read error (truncated file): the bytes before it were delivered.
  virtual const std::string& error() const = 0;
};

}  // namespace lrfnet::capture
