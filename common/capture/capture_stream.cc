#include "common/capture/capture_stream.h"

#include <utility>

#include "common/capture/packet_parser.h"
#include "common/capture/pcap_reader.h"
#include "common/capture/tcp_reassembler.h"

namespace lrfnet::capture {
namespace {

TcpReassemblerOptions ReassemblerOptions(const CaptureStreamOptions& options) {
  TcpReassemblerOptions r;
  r.max_pending_bytes = options.max_pending_bytes;
  return r;
}

// Source and destination as seen in the selected direction.
struct ConnectionKey {
  IpAddress src_address;
  IpAddress dst_address;
  std::uint16_t src_port = 0;
  std::uint16_t dst_port = 0;

  bool operator==(const ConnectionKey&) const = default;
};

class PcapCaptureStream final : public CaptureStream {
 public:
  PcapCaptureStream(std::string path, std::unique_ptr<PcapReader> reader,
                    const CaptureStreamOptions& options)
      : path_(std::move(path)),
        reader_(std::move(reader)),
        options_(options),
        reassembler_(ReassemblerOptions(options)) {}

  bool Next(StreamChunk* chunk) override {
    while (true) {
      ReassembledChunk piece;
      if (reassembler_.Pop(&piece)) {
        chunk->bytes = piece.bytes;
        chunk->receive_time_ns = piece.time_ns;
        chunk->discontinuity = piece.discontinuity;
        SyncCounters();
        return true;
      }
      if (finished_) return false;
      ReadPacket();
      SyncCounters();
    }
  }

  const CaptureCounters& counters() const override { return counters_; }
  const std::string& error() const override { return error_; }

 private:
  void ReadPacket() {
    RawPacket packet;
    switch (reader_->Next(&packet)) {
      case ReadStatus::kPacket:
        HandlePacket(packet);
        return;
      case ReadStatus::kError:
        error_ = path_ + ": " + reader_->error();
        [[fallthrough]];
      case ReadStatus::kEnd:
        finished_ = true;
        reassembler_.Finish();
        return;
    }
  }

  void HandlePacket(const RawPacket& packet) {
    ++counters_.packets;
    const ParseResult parsed = ParsePacket(packet.link_type, packet.bytes);
    if (parsed.status == ParseStatus::kMalformed) {
      ++counters_.malformed_packets;
      return;
    }
    const ParsedPacket& p = parsed.packet;
    if (parsed.status != ParseStatus::kOk || p.protocol != TransportProtocol::kTcp) {
      ++counters_.ignored_packets;
      return;
    }
    const bool selected = options_.from_sensor ? p.src_port == options_.sensor_port
                                               : p.dst_port == options_.sensor_port;
    if (!selected) {
      ++counters_.ignored_packets;
      return;
    }
    const ConnectionKey key{p.src_address, p.dst_address, p.src_port, p.dst_port};
    const bool syn = (p.tcp_flags & kTcpSyn) != 0;
    if (!following_) {
      // Pure ACKs cannot start a stream: without data or a SYN there is no sequence number to
      // anchor.
      if (!syn && p.payload.empty()) {
        ++counters_.ignored_packets;
        return;
      }
      following_ = true;
      key_ = key;
    } else if (!(key == key_)) {
      // Another connection on the sensor port: follow it only from its SYN (a client reconnect).
      // The reassembler treats that SYN as a new stream and marks the next chunk as a
      // discontinuity.
      if (!syn) {
        ++counters_.ignored_packets;
        return;
      }
      key_ = key;
    }
    ++counters_.stream_packets;
    reassembler_.Push({p.tcp_seq, p.tcp_flags, p.payload, packet.timestamp_ns});
  }

  void SyncCounters() {
    const TcpReassemblerCounters& r = reassembler_.counters();
    counters_.retransmitted_bytes = r.retransmitted_bytes;
    counters_.out_of_order_segments = r.out_of_order_segments;
    counters_.gaps = r.gaps;
    counters_.gap_bytes = r.gap_bytes;
    counters_.out_of_window_segments = r.out_of_window_segments;
    counters_.connections = r.connections;
    counters_.delivered_bytes = r.delivered_bytes;
  }

  std::string path_;
  std::unique_ptr<PcapReader> reader_;
  CaptureStreamOptions options_;
  TcpReassembler reassembler_;
  bool following_ = false;
  ConnectionKey key_;
  bool finished_ = false;
  CaptureCounters counters_;
  std::string error_;
};

}  // namespace

std::optional<std::string> Validate(const CaptureStreamOptions& options) {
  if (options.sensor_port == 0) return "sensor_port must be between 1 and 65535";
  if (auto reason = Validate(ReassemblerOptions(options))) return reason;
  return std::nullopt;
}

std::unique_ptr<CaptureStream> CaptureStream::Open(const std::string& path,
                                                   const CaptureStreamOptions& options,
                                                   std::string* error) {
  std::string ignored;
  if (error == nullptr) error = &ignored;
  if (auto reason = Validate(options)) {
    *error = path + ": invalid capture options: " + *reason;
    return nullptr;
  }
  std::string reason;
  auto reader = PcapReader::Open(path, &reason);
  if (reader == nullptr) {
    // libpcap prefixes errno messages with the path; name it once.
    if (reason.rfind(path + ": ", 0) == 0) reason.erase(0, path.size() + 2);
    *error = path + ": cannot read as pcap or pcapng: " + reason;
    return nullptr;
  }
  if (!IsSupportedLinkType(reader->link_type())) {
    *error = path + ": unsupported link type " + std::to_string(reader->link_type()) + " (" +
             reader->link_type_name() +
             "); expected Ethernet, Linux cooked capture, raw IP or BSD loopback";
    return nullptr;
  }
  return std::make_unique<PcapCaptureStream>(path, std::move(reader), options);
}

}  // namespace lrfnet::capture
