#include "tools/sim/pcap_writer.h"

#include <cerrno>
#include <cstring>

#include "common/byte_order.h"

namespace lrfnet::sim {

namespace {

constexpr std::uint32_t kPcapMagicNs = 0xA1B23C4D;
constexpr std::uint32_t kLinkTypeEthernet = 1;
constexpr std::uint32_t kSnapLen = 262144;
constexpr std::size_t kEthernetHeader = 14;
constexpr std::size_t kIpv4Header = 20;
constexpr std::size_t kTcpHeaderWithTimestamps = 32;  // 20 + NOP NOP TS(10)
constexpr std::size_t kTcpHeaderSyn = 40;             // 20 + MSS(4) SACK_PERM(2) TS(10) NOP WS(3)
constexpr std::size_t kEthernetMinimumFrame = 60;
constexpr std::uint16_t kClientWindow = 64240;
constexpr std::uint16_t kDeviceWindow = 8192;

constexpr auto PutLe32 = common::StoreLe32;
constexpr auto PutLe16 = common::StoreLe16;
constexpr auto PutBe16 = common::StoreBe16;
constexpr auto PutBe32 = common::StoreBe32;

// RFC 1071 one's-complement sum.
std::uint32_t SumWords(const std::uint8_t* p, std::size_t n, std::uint32_t sum) {
  for (; n >= 2; p += 2, n -= 2) sum += static_cast<std::uint32_t>(p[0] << 8 | p[1]);
  if (n == 1) sum += static_cast<std::uint32_t>(p[0] << 8);
  return sum;
}
std::uint16_t FoldChecksum(std::uint32_t sum) {
  while (sum >> 16) sum = (sum & 0xFFFF) + (sum >> 16);
  return static_cast<std::uint16_t>(~sum & 0xFFFF);
}

}  // namespace

std::unique_ptr<PcapWriter> PcapWriter::Create(const std::string& path, std::string* error) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) {
    *error = path + ": cannot create: " + std::strerror(errno);
    return nullptr;
  }
  std::unique_ptr<PcapWriter> w(new PcapWriter(f, path));
  std::uint8_t header[24];
  PutLe32(header, kPcapMagicNs);
  PutLe16(header + 4, 2);
  PutLe16(header + 6, 4);
  PutLe32(header + 8, 0);   // thiszone
  PutLe32(header + 12, 0);  // sigfigs
  PutLe32(header + 16, kSnapLen);
  PutLe32(header + 20, kLinkTypeEthernet);
  if (std::fwrite(header, 1, sizeof header, f) != sizeof header) w->failed_ = true;
  return w;
}

PcapWriter::~PcapWriter() {
  if (file_ != nullptr) std::fclose(file_);
}

void PcapWriter::WritePacket(std::int64_t utc_ns, std::span<const std::uint8_t> frame) {
  if (failed_ || file_ == nullptr) return;
  std::uint8_t record[16];
  PutLe32(record, static_cast<std::uint32_t>(utc_ns / 1000000000LL));
  PutLe32(record + 4, static_cast<std::uint32_t>(utc_ns % 1000000000LL));
  PutLe32(record + 8, static_cast<std::uint32_t>(frame.size()));
  PutLe32(record + 12, static_cast<std::uint32_t>(frame.size()));
  if (std::fwrite(record, 1, sizeof record, file_) != sizeof record ||
      std::fwrite(frame.data(), 1, frame.size(), file_) != frame.size()) {
    failed_ = true;
  }
  ++packets_;
}

bool PcapWriter::Close(std::string* error) {
  if (file_ == nullptr) return !failed_;
  const bool flushed = std::fflush(file_) == 0;
  const bool closed = std::fclose(file_) == 0;
  file_ = nullptr;
  if (failed_ || !flushed || !closed) {
    *error = path_ + ": write error (disk full?)";
    return false;
  }
  return true;
}

TcpSessionWriter::TcpSessionWriter(PcapWriter* out, const TcpEndpoint& client,
                                   const TcpEndpoint& device, std::uint32_t client_isn,
                                   std::uint32_t device_isn)
    : out_(out),
      client_(client),
      device_(device),
      client_seq_(client_isn),
      device_seq_(device_isn) {
  frame_.reserve(kEthernetHeader + kIpv4Header + kTcpHeaderSyn + kMaxSegmentPayload);
}

void TcpSessionWriter::Handshake(std::int64_t syn_ns, std::int64_t syn_ack_ns, std::int64_t ack_ns,
                                 std::uint32_t client_ts_ms, std::uint32_t device_ts_ms) {
  Emit(syn_ns, true, kSyn, client_seq_, 0, {}, client_ts_ms, true);
  ++client_seq_;
  last_client_ts_ = client_ts_ms;
  Emit(syn_ack_ns, false, kSyn | kAck, device_seq_, client_seq_, {}, device_ts_ms, true);
  ++device_seq_;
  last_device_ts_ = device_ts_ms;
  Emit(ack_ns, true, kAck, client_seq_, device_seq_, {}, client_ts_ms, false);
}

void TcpSessionWriter::ClientData(std::int64_t utc_ns, std::span<const std::uint8_t> payload,
                                  std::uint32_t ts_ms) {
  Emit(utc_ns, true, kPsh | kAck, client_seq_, device_seq_, payload, ts_ms, false);
  client_seq_ += static_cast<std::uint32_t>(payload.size());
  last_client_ts_ = ts_ms;
}

void TcpSessionWriter::ClientAck(std::int64_t utc_ns, std::uint32_t ts_ms) {
  Emit(utc_ns, true, kAck, client_seq_, device_seq_, {}, ts_ms, false);
  last_client_ts_ = ts_ms;
}

void TcpSessionWriter::DeviceData(std::span<const std::uint8_t> payload,
                                  std::span<const std::int64_t> segment_ns, std::uint32_t ts_ms) {
  std::size_t offset = 0;
  for (std::size_t i = 0; offset < payload.size(); ++i) {
    const std::size_t n = std::min(kMaxSegmentPayload, payload.size() - offset);
    const bool last = offset + n == payload.size();
    // PSH on the segment that completes the application write, as a device's stack sets it.
    Emit(segment_ns[std::min(i, segment_ns.size() - 1)], false,
         static_cast<std::uint8_t>(kAck | (last ? kPsh : 0)), device_seq_, client_seq_,
         payload.subspan(offset, n), ts_ms, false);
    device_seq_ += static_cast<std::uint32_t>(n);
    offset += n;
  }
  last_device_ts_ = ts_ms;
}

void TcpSessionWriter::Emit(std::int64_t utc_ns, bool from_client, std::uint8_t flags,
                            std::uint32_t seq, std::uint32_t ack,
                            std::span<const std::uint8_t> payload, std::uint32_t ts_val,
                            bool syn_options) {
  const TcpEndpoint& src = from_client ? client_ : device_;
  const TcpEndpoint& dst = from_client ? device_ : client_;
  const std::size_t tcp_header = syn_options ? kTcpHeaderSyn : kTcpHeaderWithTimestamps;
  const std::size_t ip_total = kIpv4Header + tcp_header + payload.size();
  std::size_t frame_size = kEthernetHeader + ip_total;
  // Received frames carry the sender's padding up to the Ethernet minimum; the capturing host's own
  // frames are captured before the NIC pads them.
  if (!from_client) frame_size = std::max(frame_size, kEthernetMinimumFrame);
  frame_.assign(frame_size, 0);
  std::uint8_t* eth = frame_.data();
  std::memcpy(eth, dst.mac.data(), 6);
  std::memcpy(eth + 6, src.mac.data(), 6);
  PutBe16(eth + 12, 0x0800);

  std::uint8_t* ip = eth + kEthernetHeader;
  ip[0] = 0x45;
  ip[1] = 0;
  PutBe16(ip + 2, static_cast<std::uint16_t>(ip_total));
  std::uint16_t& ip_id = from_client ? client_ip_id_ : device_ip_id_;
  PutBe16(ip + 4, ip_id++);
  PutBe16(ip + 6, 0x4000);  // don't fragment
  ip[8] = 64;
  ip[9] = 6;  // TCP
  std::memcpy(ip + 12, src.ip.data(), 4);
  std::memcpy(ip + 16, dst.ip.data(), 4);
  PutBe16(ip + 10, FoldChecksum(SumWords(ip, kIpv4Header, 0)));

  std::uint8_t* tcp = ip + kIpv4Header;
  PutBe16(tcp, src.port);
  PutBe16(tcp + 2, dst.port);
  PutBe32(tcp + 4, seq);
  PutBe32(tcp + 8, ack);
  tcp[12] = static_cast<std::uint8_t>((tcp_header / 4) << 4);
  tcp[13] = flags;
  PutBe16(tcp + 14, from_client ? kClientWindow : kDeviceWindow);
  std::uint8_t* opt = tcp + 20;
  const std::uint32_t ts_ecr =
      (flags & kSyn) != 0 && from_client ? 0 : (from_client ? last_device_ts_ : last_client_ts_);
  if (syn_options) {
    opt[0] = 2;  // MSS 1460
    opt[1] = 4;
    PutBe16(opt + 2, 1460);
    opt[4] = 4;  // SACK permitted
    opt[5] = 2;
    opt[6] = 8;  // timestamps
    opt[7] = 10;
    PutBe32(opt + 8, ts_val);
    PutBe32(opt + 12, ts_ecr);
    opt[16] = 1;  // NOP
    opt[17] = 3;  // window scale 0
    opt[18] = 3;
    opt[19] = 0;
  } else {
    opt[0] = 1;
    opt[1] = 1;
    opt[2] = 8;
    opt[3] = 10;
    PutBe32(opt + 4, ts_val);
    PutBe32(opt + 8, ts_ecr);
  }
  if (!payload.empty()) std::memcpy(tcp + tcp_header, payload.data(), payload.size());
  const std::size_t tcp_len = tcp_header + payload.size();
  std::uint32_t sum = SumWords(ip + 12, 8, 0);  // pseudo header: addresses
  sum += 6;
  sum += static_cast<std::uint32_t>(tcp_len);
  sum = SumWords(tcp, tcp_len, sum);
  PutBe16(tcp + 16, FoldChecksum(sum));
  out_->WritePacket(utc_ns, frame_);
}

}  // namespace lrfnet::sim
