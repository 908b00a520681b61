#pragma once
// Writing a TCP session as a capture file: classic pcap with nanosecond timestamps
// (magic a1b23c4d), LINKTYPE_ETHERNET, frames built with correct IPv4 header and TCP checksums and
// TCP timestamp options, as a capture taken on the client (the gateway) would hold them.
//
// TcpSessionWriter keeps the sequence and acknowledgement numbers of one connection. Payloads the
// device sends are split into segments of at most kMaxSegmentPayload bytes (MSS 1460 minus the
// 12-byte timestamp option, as the real captures show: 1448 + 1448 + 657 for an LMS511 scan);
// frames arriving from the device are padded to the 60-byte Ethernet minimum.
//
// Thread-safety: none; one writer per file.

#include <array>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace lrfnet::sim {

inline constexpr std::size_t kMaxSegmentPayload = 1448;

class PcapWriter {
 public:
  // Creates (truncates) `path` and writes the file header. nullptr with *error on failure.
  static std::unique_ptr<PcapWriter> Create(const std::string& path, std::string* error);
  ~PcapWriter();
  PcapWriter(const PcapWriter&) = delete;
  PcapWriter& operator=(const PcapWriter&) = delete;

  // Appends one Ethernet frame captured at `utc_ns` (>= 0). Errors are sticky (see Close).
  void WritePacket(std::int64_t utc_ns, std::span<const std::uint8_t> frame);
  // Flushes and closes; false with *error when any write failed.
  bool Close(std::string* error);
  std::uint64_t packets() const { return packets_; }

 private:
  explicit PcapWriter(std::FILE* file, std::string path) : file_(file), path_(std::move(path)) {}
  std::FILE* file_;
  std::string path_;
  bool failed_ = false;
  std::uint64_t packets_ = 0;
};

struct TcpEndpoint {
  std::array<std::uint8_t, 6> mac{};
  std::array<std::uint8_t, 4> ip{};
  std::uint16_t port = 0;
};

class TcpSessionWriter {
 public:
  TcpSessionWriter(PcapWriter* out, const TcpEndpoint& client, const TcpEndpoint& device,
                   std::uint32_t client_isn, std::uint32_t device_isn);

  // SYN (client), SYN-ACK (device), ACK (client) at the given times. `*_ts_ms` are the TCP
  // timestamp values (each host's millisecond clock).
  void Handshake(std::int64_t syn_ns, std::int64_t syn_ack_ns, std::int64_t ack_ns,
                 std::uint32_t client_ts_ms, std::uint32_t device_ts_ms);
  // One segment from the client carrying `payload` (a command frame).
  void ClientData(std::int64_t utc_ns, std::span<const std::uint8_t> payload, std::uint32_t ts_ms);
  // A pure ACK from the client of everything the device sent so far.
  void ClientAck(std::int64_t utc_ns, std::uint32_t ts_ms);
  // `payload` from the device, split into segments; segment i is captured at segment_ns[i]
  // (SegmentCount(payload.size()) entries).
  void DeviceData(std::span<const std::uint8_t> payload, std::span<const std::int64_t> segment_ns,
                  std::uint32_t ts_ms);
  static std::size_t SegmentCount(std::size_t payload_bytes) {
    return (payload_bytes + kMaxSegmentPayload - 1) / kMaxSegmentPayload;
  }

 private:
  enum Flags : std::uint8_t { kFin = 0x01, kSyn = 0x02, kPsh = 0x08, kAck = 0x10 };
  void Emit(std::int64_t utc_ns, bool from_client, std::uint8_t flags, std::uint32_t seq,
            std::uint32_t ack, std::span<const std::uint8_t> payload, std::uint32_t ts_val,
            bool syn_options);

  PcapWriter* out_;
  TcpEndpoint client_;
  TcpEndpoint device_;
  std::uint32_t client_seq_;  // next sequence number the client sends
  std::uint32_t device_seq_;
  std::uint16_t client_ip_id_ = 0x1000;
  std::uint16_t device_ip_id_ = 0x2000;
  std::uint32_t last_client_ts_ = 0;
  std::uint32_t last_device_ts_ = 0;
  std::vector<std::uint8_t> frame_;  // reused
};

}  // namespace lrfnet::sim
