#include "common/capture/packet_parser.h"

#include <algorithm>
#include <cstddef>

#include "common/byte_order.h"

namespace lrfnet::capture {
namespace {

using Bytes = std::span<const std::uint8_t>;

constexpr std::uint16_t kEtherTypeIpv4 = 0x0800;
constexpr std::uint16_t kEtherTypeIpv6 = 0x86DD;
constexpr std::uint16_t kEtherTypeVlan = 0x8100;     // 802.1Q
constexpr std::uint16_t kEtherTypeQinQ = 0x88A8;     // 802.1ad service tag
constexpr std::uint16_t kEtherTypeQinQOld = 0x9100;  // pre-standard double tagging

constexpr std::uint8_t kIpProtoTcp = 6;
constexpr std::uint8_t kIpProtoUdp = 17;
constexpr std::uint8_t kIpv6HopByHop = 0;
constexpr std::uint8_t kIpv6Routing = 43;
constexpr std::uint8_t kIpv6Fragment = 44;
constexpr std::uint8_t kIpv6DestOptions = 60;

std::uint16_t Be16(Bytes b, std::size_t at) {
  return common::LoadBe16(b.data() + at);
}
std::uint32_t Be32(Bytes b, std::size_t at) {
  return common::LoadBe32(b.data() + at);
}
std::uint32_t Le32(Bytes b, std::size_t at) {
  return common::LoadLe32(b.data() + at);
}

ParseResult Fail(ParseStatus status, const char* reason) {
  ParseResult r;
  r.status = status;
  r.reason = reason;
  return r;
}
ParseResult Malformed(const char* reason) { return Fail(ParseStatus::kMalformed, reason); }
ParseResult Unsupported(const char* reason) { return Fail(ParseStatus::kUnsupported, reason); }

// Transport header at the start of `segment`, which ends where the IP length says.
ParseResult ParseTransport(std::uint8_t protocol, Bytes segment, ParseResult r) {
  if (protocol == kIpProtoTcp) {
    if (segment.size() < 20) return Malformed("truncated TCP header");
    const std::size_t header_bytes = static_cast<std::size_t>(segment[12] >> 4) * 4;
    if (header_bytes < 20) return Malformed("TCP data offset below 20 bytes");
    if (header_bytes > segment.size()) return Malformed("truncated TCP options");
    r.packet.protocol = TransportProtocol::kTcp;
    r.packet.src_port = Be16(segment, 0);
    r.packet.dst_port = Be16(segment, 2);
    r.packet.tcp_seq = Be32(segment, 4);
    r.packet.tcp_ack = Be32(segment, 8);
    r.packet.tcp_flags = segment[13];
    r.packet.payload = segment.subspan(header_bytes);
    r.status = ParseStatus::kOk;
    return r;
  }
  if (protocol == kIpProtoUdp) {
    if (segment.size() < 8) return Malformed("truncated UDP header");
    const std::size_t udp_length = Be16(segment, 4);
    if (udp_length < 8) return Malformed("UDP length below 8 bytes");
    if (udp_length > segment.size()) return Malformed("UDP length beyond the IP packet");
    r.packet.protocol = TransportProtocol::kUdp;
    r.packet.src_port = Be16(segment, 0);
    r.packet.dst_port = Be16(segment, 2);
    r.packet.payload = segment.subspan(8, udp_length - 8);
    r.status = ParseStatus::kOk;
    return r;
  }
  return Unsupported("neither TCP nor UDP");
}

ParseResult ParseIpv4(Bytes ip) {
  if (ip.size() < 20) return Malformed("truncated IPv4 header");
  if ((ip[0] >> 4) != 4) return Malformed("IPv4 header with a version other than 4");
  const std::size_t header_bytes = static_cast<std::size_t>(ip[0] & 0x0F) * 4;
  if (header_bytes < 20) return Malformed("IPv4 header length below 20 bytes");
  if (header_bytes > ip.size()) return Malformed("truncated IPv4 options");
  std::size_t total_length = Be16(ip, 2);
  // A total length of 0 is what a capture on the sending host shows for a segment handed to the
  // card for segmentation (TSO): the frame then holds the whole packet.
  if (total_length == 0) total_length = ip.size();
  if (total_length < header_bytes) return Malformed("IPv4 total length shorter than its header");
  if (total_length > ip.size())
    return Malformed("truncated IPv4 packet (total length beyond the frame)");
  // Flags/fragment offset: MF set or a non-zero offset means a fragment.
  if ((Be16(ip, 6) & 0x3FFF) != 0) return Unsupported("IPv4 fragment");

  ParseResult r;
  r.packet.src_address.family = IpFamily::kIpv4;
  r.packet.dst_address.family = IpFamily::kIpv4;
  std::copy_n(ip.begin() + 12, 4, r.packet.src_address.bytes.begin());
  std::copy_n(ip.begin() + 16, 4, r.packet.dst_address.bytes.begin());
  return ParseTransport(ip[9], ip.subspan(header_bytes, total_length - header_bytes), r);
}

ParseResult ParseIpv6(Bytes ip) {
  if (ip.size() < 40) return Malformed("truncated IPv6 header");
  if ((ip[0] >> 4) != 6) return Malformed("IPv6 header with a version other than 6");
  std::size_t payload_length = Be16(ip, 4);
  // 0 means a jumbogram or a TSO segment captured on the sender: the frame holds the whole packet.
  if (payload_length == 0) payload_length = ip.size() - 40;
  if (payload_length > ip.size() - 40) {
    return Malformed("truncated IPv6 packet (payload length beyond the frame)");
  }
  ParseResult r;
  r.packet.src_address.family = IpFamily::kIpv6;
  r.packet.dst_address.family = IpFamily::kIpv6;
  std::copy_n(ip.begin() + 8, 16, r.packet.src_address.bytes.begin());
  std::copy_n(ip.begin() + 24, 16, r.packet.dst_address.bytes.begin());

  std::uint8_t next_header = ip[6];
  Bytes rest = ip.subspan(40, payload_length);
  // Every extension header is at least 8 bytes, so the loop ends within rest.size() / 8 steps.
  while (next_header == kIpv6HopByHop || next_header == kIpv6Routing ||
         next_header == kIpv6DestOptions) {
    if (rest.size() < 8) return Malformed("truncated IPv6 extension header");
    const std::size_t ext_bytes = (static_cast<std::size_t>(rest[1]) + 1) * 8;
    if (ext_bytes > rest.size()) return Malformed("truncated IPv6 extension header");
    next_header = rest[0];
    rest = rest.subspan(ext_bytes);
  }
  if (next_header == kIpv6Fragment) return Unsupported("IPv6 fragment");
  return ParseTransport(next_header, rest, r);
}

ParseResult ParseByVersion(Bytes ip) {
  if (ip.empty()) return Malformed("empty raw IP packet");
  const int version = ip[0] >> 4;
  if (version == 4) return ParseIpv4(ip);
  if (version == 6) return ParseIpv6(ip);
  return Malformed("raw IP packet with a version other than 4 or 6");
}

// `ether_type` followed by `rest`, after any VLAN tags.
ParseResult ParseEtherType(std::uint16_t ether_type, Bytes rest) {
  // Each tag is 4 bytes (TCI + inner type), so the loop ends within rest.size() / 4 steps.
  while (ether_type == kEtherTypeVlan || ether_type == kEtherTypeQinQ ||
         ether_type == kEtherTypeQinQOld) {
    if (rest.size() < 4) return Malformed("truncated VLAN tag");
    ether_type = Be16(rest, 2);
    rest = rest.subspan(4);
  }
  if (ether_type == kEtherTypeIpv4) return ParseIpv4(rest);
  if (ether_type == kEtherTypeIpv6) return ParseIpv6(rest);
  return Unsupported("not an IP packet (EtherType)");
}

// BSD loopback: a 4-byte address family in the byte order of the capturing host (NULL) or in
// network order (LOOP). Family values below 0x10000 tell which order it is. AF_INET6 differs
// between systems.
ParseResult ParseLoopback(Bytes frame) {
  if (frame.size() < 4) return Malformed("truncated loopback header");
  std::uint32_t family = Le32(frame, 0);
  if (family > 0xFFFF) family = Be32(frame, 0);
  const Bytes ip = frame.subspan(4);
  if (family == 2) return ParseIpv4(ip);  // AF_INET everywhere
  // AF_INET6: Linux 10, NetBSD/OpenBSD 24, FreeBSD 28, Darwin 30.
  if (family == 10 || family == 24 || family == 28 || family == 30) return ParseIpv6(ip);
  return Unsupported("loopback packet of a family other than IP");
}

}  // namespace

bool IsSupportedLinkType(std::uint32_t link_type) {
  switch (link_type) {
    case kLinkTypeNull:
    case kLinkTypeEthernet:
    case kLinkTypeRaw:
    case kLinkTypeLoop:
    case kLinkTypeLinuxSll:
    case kLinkTypeIpv4:
    case kLinkTypeIpv6:
    case kLinkTypeLinuxSll2:
      return true;
    default:
      return false;
  }
}

ParseResult ParsePacket(std::uint32_t link_type, std::span<const std::uint8_t> frame) {
  switch (link_type) {
    case kLinkTypeEthernet:
      // destination MAC, source MAC, EtherType
      if (frame.size() < 14) return Malformed("truncated Ethernet header");
      return ParseEtherType(Be16(frame, 12), frame.subspan(14));
    case kLinkTypeLinuxSll:
      // packet type, ARPHRD type, address length, 8 address bytes, protocol (EtherType)
      if (frame.size() < 16) return Malformed("truncated Linux cooked (SLL) header");
      return ParseEtherType(Be16(frame, 14), frame.subspan(16));
    case kLinkTypeLinuxSll2:
      // protocol (EtherType), reserved, interface index, ARPHRD type, packet type, address length,
      // 8 bytes
      if (frame.size() < 20) return Malformed("truncated Linux cooked (SLL2) header");
      return ParseEtherType(Be16(frame, 0), frame.subspan(20));
    case kLinkTypeRaw:
      return ParseByVersion(frame);
    case kLinkTypeIpv4:
      return ParseIpv4(frame);
    case kLinkTypeIpv6:
      return ParseIpv6(frame);
    case kLinkTypeNull:
    case kLinkTypeLoop:
      return ParseLoopback(frame);
    default:
      return Unsupported("unsupported link type");
  }
}

}  // namespace lrfnet::capture
