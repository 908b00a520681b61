#include "common/capture/packet_parser.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <string>
#include <vector>

#include "common/capture/capture_test_util.h"

namespace lrfnet::capture {
namespace {

using Bytes = std::vector<std::uint8_t>;

using test::Put16;
using test::Put32;
using test::Cat;
using test::Text;

// TCP header with `option_words` 32-bit words of NOP options.
Bytes Tcp(std::uint16_t src_port, std::uint16_t dst_port, std::uint32_t seq, std::uint32_t ack,
          std::uint8_t flags, const Bytes& payload, int option_words = 0) {
  Bytes h(20 + 4 * static_cast<std::size_t>(option_words), 0x01);  // 0x01 = NOP option
  Put16(&h, 0, src_port);
  Put16(&h, 2, dst_port);
  Put32(&h, 4, seq);
  Put32(&h, 8, ack);
  h[12] = static_cast<std::uint8_t>((5 + option_words) << 4);
  h[13] = flags;
  Put16(&h, 14, 29200);  // window
  Put32(&h, 16, 0);      // checksum (deliberately wrong), urgent pointer
  return Cat(h, payload);
}

Bytes Udp(std::uint16_t src_port, std::uint16_t dst_port, const Bytes& payload) {
  Bytes h(8, 0);
  Put16(&h, 0, src_port);
  Put16(&h, 2, dst_port);
  Put16(&h, 4, static_cast<std::uint32_t>(8 + payload.size()));
  return Cat(h, payload);
}

constexpr std::uint8_t kTcp = 6;
constexpr std::uint8_t kUdp = 17;

Bytes Ipv4(std::uint8_t protocol, const Bytes& l4, int option_words = 0,
           std::uint16_t flags_fragment = 0x4000 /* DF */) {
  Bytes h(20 + 4 * static_cast<std::size_t>(option_words), 0x01);
  h[0] = static_cast<std::uint8_t>(0x40 | (5 + option_words));
  h[1] = 0;
  Put16(&h, 2, static_cast<std::uint32_t>(h.size() + l4.size()));
  Put16(&h, 4, 0x1234);
  Put16(&h, 6, flags_fragment);
  h[8] = 64;
  h[9] = protocol;
  Put16(&h, 10, 0);
  Put32(&h, 12, 0xC0A80001);  // 192.168.0.1
  Put32(&h, 16, 0xC0A80064);  // 192.168.0.100
  return Cat(h, l4);
}

// IPv6 with the given extension headers (each: {type, length in 8-byte units beyond the first 8}).
Bytes Ipv6(std::uint8_t protocol, const Bytes& l4,
           const std::vector<std::pair<std::uint8_t, std::uint8_t>>& extensions = {}) {
  Bytes ext;
  std::uint8_t first = protocol;
  for (std::size_t i = extensions.size(); i-- > 0;) {
    Bytes e((extensions[i].second + 1) * 8u, 0);
    e[0] = first;
    e[1] = extensions[i].second;
    first = extensions[i].first;
    ext = Cat(e, ext);
  }
  Bytes h(40, 0);
  h[0] = 0x60;
  Put16(&h, 4, static_cast<std::uint32_t>(ext.size() + l4.size()));
  h[6] = first;
  h[7] = 64;
  h[8] = 0xFE;
  h[9] = 0x80;
  h[23] = 0x01;  // fe80::1
  h[24] = 0xFE;
  h[25] = 0x80;
  h[39] = 0x64;  // fe80::64
  return Cat(Cat(h, ext), l4);
}

// Ethernet II with optional VLAN tags (outer first), padded to the 60-byte minimum like a real NIC.
Bytes Ethernet(std::uint16_t ether_type, const Bytes& payload,
               const std::vector<std::uint16_t>& tag_types = {}) {
  Bytes h(12, 0);
  h[5] = 0x01;
  h[11] = 0x02;
  for (std::uint16_t tag : tag_types) {
    Bytes t(4, 0);
    Put16(&t, 0, tag);
    Put16(&t, 2, 0x0005);  // VLAN id 5
    h = Cat(h, t);
  }
  Bytes type(2, 0);
  Put16(&type, 0, ether_type);
  Bytes frame = Cat(Cat(h, type), payload);
  if (frame.size() < 60) frame.resize(60, 0);
  return frame;
}

Bytes Sll(std::uint16_t protocol, const Bytes& payload) {
  Bytes h(16, 0);
  Put16(&h, 0, 0);  // packet type: to us
  Put16(&h, 2, 1);  // ARPHRD_ETHER
  Put16(&h, 4, 6);  // address length
  h[6] = 0x00;
  h[7] = 0x06;
  Put16(&h, 14, protocol);
  return Cat(h, payload);
}

Bytes Sll2(std::uint16_t protocol, const Bytes& payload) {
  Bytes h(20, 0);
  Put16(&h, 0, protocol);
  Put32(&h, 4, 2);  // interface index
  Put16(&h, 8, 1);  // ARPHRD_ETHER
  h[11] = 6;
  return Cat(h, payload);
}

Bytes Loopback(std::uint32_t family, bool big_endian, const Bytes& payload) {
  Bytes h(4, 0);
  if (big_endian) {
    Put32(&h, 0, family);
  } else {
    for (int i = 0; i < 4; ++i)
      h[static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(family >> (8 * i));
  }
  return Cat(h, payload);
}

ParseResult Parse(std::uint32_t link_type, const Bytes& frame) {
  return ParsePacket(link_type, std::span<const std::uint8_t>(frame));
}

std::string PayloadText(const ParseResult& r) {
  return std::string(r.packet.payload.begin(), r.packet.payload.end());
}

bool PayloadInside(const ParseResult& r, const Bytes& frame) {
  if (r.packet.payload.empty()) return true;
  return r.packet.payload.data() >= frame.data() &&
         r.packet.payload.data() + r.packet.payload.size() <= frame.data() + frame.size();
}

TEST(PacketParser, EthernetIpv4TcpFields) {
  const Bytes frame = Ethernet(
      0x0800, Ipv4(kTcp, Tcp(2112, 49152, 0xFFFFFFF0u, 77, kTcpAck | kTcpPsh, Text("sRA x"), 3)));
  const ParseResult r = Parse(kLinkTypeEthernet, frame);
  ASSERT_EQ(r.status, ParseStatus::kOk) << r.reason;
  EXPECT_EQ(r.packet.protocol, TransportProtocol::kTcp);
  EXPECT_EQ(r.packet.src_address.family, IpFamily::kIpv4);
  EXPECT_EQ(r.packet.src_address.bytes[0], 192);
  EXPECT_EQ(r.packet.src_address.bytes[3], 1);
  EXPECT_EQ(r.packet.src_address.bytes[4], 0);  // unused tail stays zero
  EXPECT_EQ(r.packet.dst_address.bytes[3], 100);
  EXPECT_EQ(r.packet.src_port, 2112);
  EXPECT_EQ(r.packet.dst_port, 49152);
  EXPECT_EQ(r.packet.tcp_seq, 0xFFFFFFF0u);
  EXPECT_EQ(r.packet.tcp_ack, 77u);
  EXPECT_EQ(r.packet.tcp_flags, kTcpAck | kTcpPsh);
  EXPECT_EQ(PayloadText(r), "sRA x");
}

TEST(PacketParser, PaddedPureAckHasEmptyPayload) {
  // 14 + 20 + 20 = 54 bytes, padded to 60: the 6 padding bytes are not TCP payload.
  const Bytes frame = Ethernet(0x0800, Ipv4(kTcp, Tcp(2112, 49152, 1, 2, kTcpAck, {})));
  ASSERT_EQ(frame.size(), 60u);
  const ParseResult r = Parse(kLinkTypeEthernet, frame);
  ASSERT_EQ(r.status, ParseStatus::kOk) << r.reason;
  EXPECT_TRUE(r.packet.payload.empty());
}

TEST(PacketParser, PaddedShortSegmentKeepsOnlyItsPayload) {
  const Bytes frame = Ethernet(0x0800, Ipv4(kTcp, Tcp(2112, 49152, 1, 2, kTcpAck, Text("ab"))));
  ASSERT_EQ(frame.size(), 60u);
  const ParseResult r = Parse(kLinkTypeEthernet, frame);
  ASSERT_EQ(r.status, ParseStatus::kOk) << r.reason;
  EXPECT_EQ(PayloadText(r), "ab");
}

TEST(PacketParser, CoalescedFrameLargerThanMtu) {
  // Receive offload hands over frames far above 1514 bytes (1992 in the TiM781S capture).
  const Bytes payload(1926, 0x5A);
  const Bytes frame = Ethernet(0x0800, Ipv4(kTcp, Tcp(2112, 57104, 9, 1, kTcpAck, payload, 3)));
  ASSERT_EQ(frame.size(), 1992u);
  const ParseResult r = Parse(kLinkTypeEthernet, frame);
  ASSERT_EQ(r.status, ParseStatus::kOk) << r.reason;
  EXPECT_EQ(r.packet.payload.size(), 1926u);
}

TEST(PacketParser, VlanAndQinQTags) {
  const Bytes ip = Ipv4(kTcp, Tcp(2112, 40000, 5, 0, kTcpAck, Text("vlan")));
  for (const auto& tags : std::vector<std::vector<std::uint16_t>>{
           {0x8100}, {0x88A8, 0x8100}, {0x9100, 0x8100}, {0x8100, 0x8100, 0x8100}}) {
    const Bytes frame = Ethernet(0x0800, ip, tags);
    const ParseResult r = Parse(kLinkTypeEthernet, frame);
    ASSERT_EQ(r.status, ParseStatus::kOk) << r.reason << " with " << tags.size() << " tags";
    EXPECT_EQ(PayloadText(r), "vlan");
  }
}

TEST(PacketParser, Ipv4OptionsAreSkipped) {
  const Bytes frame = Ethernet(0x0800, Ipv4(kTcp, Tcp(1, 2112, 5, 0, kTcpAck, Text("opt")), 2));
  const ParseResult r = Parse(kLinkTypeEthernet, frame);
  ASSERT_EQ(r.status, ParseStatus::kOk) << r.reason;
  EXPECT_EQ(r.packet.dst_port, 2112);
  EXPECT_EQ(PayloadText(r), "opt");
}

TEST(PacketParser, Ipv4FragmentsAreUnsupported) {
  const Bytes l4 = Tcp(1, 2112, 5, 0, kTcpAck, Text("frag"));
  const ParseResult more = Parse(kLinkTypeEthernet, Ethernet(0x0800, Ipv4(kTcp, l4, 0, 0x2000)));
  EXPECT_EQ(more.status, ParseStatus::kUnsupported);
  EXPECT_STREQ(more.reason, "IPv4 fragment");
  const ParseResult later = Parse(kLinkTypeEthernet, Ethernet(0x0800, Ipv4(kTcp, l4, 0, 0x0010)));
  EXPECT_EQ(later.status, ParseStatus::kUnsupported);
}

TEST(PacketParser, Ipv4TotalLengthZeroMeansSegmentationOffload) {
  Bytes ip = Ipv4(kTcp, Tcp(2112, 1, 5, 0, kTcpAck, Bytes(3000, 1)));
  Put16(&ip, 2, 0);
  const Bytes frame = Ethernet(0x0800, ip);
  const ParseResult r = Parse(kLinkTypeEthernet, frame);
  ASSERT_EQ(r.status, ParseStatus::kOk) << r.reason;
  EXPECT_EQ(r.packet.payload.size(), 3000u);
}

TEST(PacketParser, Ipv6TcpWithExtensionHeaders) {
  const Bytes l4 = Tcp(2112, 50000, 123, 0, kTcpSyn | kTcpAck, Text("six"));
  const Bytes frame = Ethernet(0x86DD, Ipv6(kTcp, l4, {{0, 0}, {43, 1}, {60, 2}}));
  const ParseResult r = Parse(kLinkTypeEthernet, frame);
  ASSERT_EQ(r.status, ParseStatus::kOk) << r.reason;
  EXPECT_EQ(r.packet.src_address.family, IpFamily::kIpv6);
  EXPECT_EQ(r.packet.src_address.bytes[0], 0xFE);
  EXPECT_EQ(r.packet.src_address.bytes[15], 0x01);
  EXPECT_EQ(r.packet.dst_address.bytes[15], 0x64);
  EXPECT_EQ(r.packet.tcp_flags, kTcpSyn | kTcpAck);
  EXPECT_EQ(PayloadText(r), "six");
}

TEST(PacketParser, Ipv6FragmentIsUnsupported) {
  const Bytes frame =
      Ethernet(0x86DD, Ipv6(kTcp, Tcp(2112, 50000, 1, 0, kTcpAck, Text("x")), {{0, 0}, {44, 0}}));
  const ParseResult r = Parse(kLinkTypeEthernet, frame);
  EXPECT_EQ(r.status, ParseStatus::kUnsupported);
  EXPECT_STREQ(r.reason, "IPv6 fragment");
}

TEST(PacketParser, UdpOverIpv4AndIpv6) {
  for (const Bytes& frame : {Ethernet(0x0800, Ipv4(kUdp, Udp(40001, 7000, Text("dgram")))),
                             Ethernet(0x86DD, Ipv6(kUdp, Udp(40001, 7000, Text("dgram"))))}) {
    const ParseResult r = Parse(kLinkTypeEthernet, frame);
    ASSERT_EQ(r.status, ParseStatus::kOk) << r.reason;
    EXPECT_EQ(r.packet.protocol, TransportProtocol::kUdp);
    EXPECT_EQ(r.packet.src_port, 40001);
    EXPECT_EQ(r.packet.dst_port, 7000);
    EXPECT_EQ(r.packet.tcp_seq, 0u);
    EXPECT_EQ(PayloadText(r), "dgram");
  }
}

TEST(PacketParser, UdpPayloadEndsAtUdpLength) {
  Bytes udp = Udp(1, 2, Text("abcdef"));
  Put16(&udp, 4, 8 + 3);  // the IP packet carries 3 bytes more than the datagram
  const Bytes packet = Ipv4(kUdp, udp);
  const ParseResult r = Parse(kLinkTypeIpv4, packet);
  ASSERT_EQ(r.status, ParseStatus::kOk) << r.reason;
  EXPECT_EQ(PayloadText(r), "abc");
}

TEST(PacketParser, EveryLinkType) {
  const Bytes v4 = Ipv4(kTcp, Tcp(2112, 3, 10, 0, kTcpAck, Text("v4")));
  const Bytes v6 = Ipv6(kTcp, Tcp(2112, 3, 10, 0, kTcpAck, Text("v6")));
  struct Case {
    std::uint32_t link_type;
    Bytes frame;
    const char* payload;
  };
  const std::vector<Case> cases = {
      {kLinkTypeLinuxSll, Sll(0x0800, v4), "v4"},
      {kLinkTypeLinuxSll, Sll(0x86DD, v6), "v6"},
      {kLinkTypeLinuxSll2, Sll2(0x0800, v4), "v4"},
      {kLinkTypeLinuxSll2, Sll2(0x86DD, v6), "v6"},
      {kLinkTypeRaw, v4, "v4"},
      {kLinkTypeRaw, v6, "v6"},
      {kLinkTypeIpv4, v4, "v4"},
      {kLinkTypeIpv6, v6, "v6"},
      {kLinkTypeNull, Loopback(2, false, v4), "v4"},
      {kLinkTypeNull, Loopback(2, true, v4), "v4"},
      {kLinkTypeNull, Loopback(30, false, v6), "v6"},  // Darwin AF_INET6
      {kLinkTypeNull, Loopback(24, false, v6), "v6"},  // NetBSD/OpenBSD
      {kLinkTypeNull, Loopback(28, true, v6), "v6"},   // FreeBSD
      {kLinkTypeLoop, Loopback(2, true, v4), "v4"},
      {kLinkTypeLoop, Loopback(10, true, v6), "v6"},  // Linux
  };
  for (const Case& c : cases) {
    EXPECT_TRUE(IsSupportedLinkType(c.link_type));
    const ParseResult r = Parse(c.link_type, c.frame);
    ASSERT_EQ(r.status, ParseStatus::kOk) << "link type " << c.link_type << ": " << r.reason;
    EXPECT_EQ(PayloadText(r), c.payload) << "link type " << c.link_type;
    EXPECT_EQ(r.packet.src_port, 2112);
  }
}

TEST(PacketParser, NonIpAndNonTransportAreUnsupported) {
  EXPECT_EQ(Parse(kLinkTypeEthernet, Ethernet(0x0806, Bytes(28, 0))).status,
            ParseStatus::kUnsupported);  // ARP
  EXPECT_EQ(Parse(kLinkTypeEthernet, Ethernet(0x0800, Ipv4(1, Bytes(8, 0)))).status,
            ParseStatus::kUnsupported);  // ICMP
  EXPECT_EQ(Parse(kLinkTypeNull, Loopback(7, false, Bytes(40, 0))).status,
            ParseStatus::kUnsupported);
  EXPECT_FALSE(IsSupportedLinkType(105));  // 802.11
  const ParseResult r = Parse(105, Bytes(100, 0));
  EXPECT_EQ(r.status, ParseStatus::kUnsupported);
  EXPECT_STREQ(r.reason, "unsupported link type");
}

TEST(PacketParser, WrongIpVersionIsMalformed) {
  const Bytes v6 = Ipv6(kTcp, Tcp(2112, 3, 10, 0, kTcpAck, Text("v6")));
  EXPECT_EQ(Parse(kLinkTypeIpv4, v6).status, ParseStatus::kMalformed);
  EXPECT_EQ(Parse(kLinkTypeEthernet, Ethernet(0x0800, v6)).status, ParseStatus::kMalformed);
  Bytes bogus = v6;
  bogus[0] = 0x50;
  EXPECT_EQ(Parse(kLinkTypeRaw, bogus).status, ParseStatus::kMalformed);
}

TEST(PacketParser, InconsistentLengthsAreMalformed) {
  const Bytes good = Ipv4(kTcp, Tcp(2112, 3, 10, 0, kTcpAck, Text("payload")));
  auto with = [&](std::size_t at, std::uint8_t value) {
    Bytes b = good;
    b[at] = value;
    return Parse(kLinkTypeIpv4, b);
  };
  EXPECT_STREQ(with(0, 0x44).reason, "IPv4 header length below 20 bytes");
  EXPECT_STREQ(with(0, 0x4F).reason, "truncated IPv4 options");
  EXPECT_STREQ(with(3, 10).reason, "IPv4 total length shorter than its header");  // total = 10
  EXPECT_STREQ(with(2, 0x10).reason, "truncated IPv4 packet (total length beyond the frame)");
  EXPECT_STREQ(with(20 + 12, 0x40).reason, "TCP data offset below 20 bytes");
  EXPECT_STREQ(with(20 + 12, 0xF0).reason, "truncated TCP options");

  Bytes udp = Ipv4(kUdp, Udp(1, 2, Text("abc")));
  udp[20 + 5] = 4;
  EXPECT_STREQ(Parse(kLinkTypeIpv4, udp).reason, "UDP length below 8 bytes");
  udp[20 + 5] = 200;
  EXPECT_STREQ(Parse(kLinkTypeIpv4, udp).reason, "UDP length beyond the IP packet");

  Bytes v6 = Ipv6(kTcp, Tcp(2112, 3, 10, 0, kTcpAck, Text("v6")));
  v6[4] = 0x10;
  EXPECT_STREQ(Parse(kLinkTypeIpv6, v6).reason,
               "truncated IPv6 packet (payload length beyond the frame)");
  Bytes ext = Ipv6(kTcp, Tcp(2112, 3, 10, 0, kTcpAck, Text("v6")), {{60, 0}});
  ext[40 + 1] = 200;  // extension header longer than the packet
  EXPECT_STREQ(Parse(kLinkTypeIpv6, ext).reason, "truncated IPv6 extension header");
}

TEST(PacketParser, TruncatedHeadersNameTheLayer) {
  const Bytes frame = Ethernet(0x0800, Ipv4(kTcp, Tcp(2112, 3, 10, 0, kTcpAck, Text("x"))));
  auto prefix = [&](std::size_t n) {
    return Bytes(frame.begin(), frame.begin() + static_cast<std::ptrdiff_t>(n));
  };
  EXPECT_STREQ(Parse(kLinkTypeEthernet, prefix(10)).reason, "truncated Ethernet header");
  EXPECT_STREQ(Parse(kLinkTypeEthernet, prefix(14 + 10)).reason, "truncated IPv4 header");
  Bytes vlan_cut = Ethernet(0x8100, {});
  vlan_cut.resize(16);
  EXPECT_STREQ(Parse(kLinkTypeEthernet, vlan_cut).reason, "truncated VLAN tag");
  // IP total length covers the TCP header: a cut inside it is a truncated IPv4 packet; a header
  // that claims more than its own total length is a truncated TCP header.
  Bytes short_tcp = Ipv4(kTcp, Bytes(12, 0));
  EXPECT_STREQ(Parse(kLinkTypeIpv4, short_tcp).reason, "truncated TCP header");
  Bytes short_udp = Ipv4(kUdp, Bytes(6, 0));
  EXPECT_STREQ(Parse(kLinkTypeIpv4, short_udp).reason, "truncated UDP header");
  EXPECT_STREQ(Parse(kLinkTypeLinuxSll, Bytes(15, 0)).reason,
               "truncated Linux cooked (SLL) header");
  EXPECT_STREQ(Parse(kLinkTypeLinuxSll2, Bytes(19, 0)).reason,
               "truncated Linux cooked (SLL2) header");
  EXPECT_STREQ(Parse(kLinkTypeNull, Bytes(3, 0)).reason, "truncated loopback header");
  EXPECT_STREQ(Parse(kLinkTypeRaw, Bytes()).reason, "empty raw IP packet");
  EXPECT_STREQ(Parse(kLinkTypeIpv6, Bytes(39, 0x60)).reason, "truncated IPv6 header");
}

// Every prefix of a complete frame is rejected as malformed (the IP length says more bytes are
// due), and the parser reads only the bytes it is given: each prefix lives in its own exactly-sized
// buffer, so an over-read shows up under AddressSanitizer.
TEST(PacketParser, EveryTruncationLengthIsMalformed) {
  struct Case {
    std::uint32_t link_type;
    Bytes frame;
    std::size_t unpadded_size;
  };
  const Bytes tcp4 = Ipv4(kTcp, Tcp(2112, 3, 10, 0, kTcpAck, Text("payload bytes"), 3), 1);
  const Bytes tcp6 =
      Ipv6(kTcp, Tcp(2112, 3, 10, 0, kTcpAck, Text("payload bytes"), 3), {{0, 0}, {60, 1}});
  const Bytes udp4 = Ipv4(kUdp, Udp(1, 2, Text("datagram")));
  const std::vector<Case> cases = {
      {kLinkTypeEthernet, Ethernet(0x0800, tcp4, {0x88A8, 0x8100}), 22 + tcp4.size()},
      {kLinkTypeEthernet, Ethernet(0x86DD, tcp6), 14 + tcp6.size()},
      {kLinkTypeEthernet, Ethernet(0x0800, udp4), 14 + udp4.size()},
      {kLinkTypeLinuxSll, Sll(0x86DD, tcp6), 16 + tcp6.size()},
      {kLinkTypeLinuxSll2, Sll2(0x0800, tcp4), 20 + tcp4.size()},
      {kLinkTypeRaw, tcp6, tcp6.size()},
      {kLinkTypeNull, Loopback(2, false, udp4), 4 + udp4.size()},
  };
  for (const Case& c : cases) {
    ASSERT_EQ(Parse(c.link_type, c.frame).status, ParseStatus::kOk);
    for (std::size_t n = 0; n < c.unpadded_size; ++n) {
      const Bytes cut(c.frame.begin(), c.frame.begin() + static_cast<std::ptrdiff_t>(n));
      const ParseResult r = Parse(c.link_type, cut);
      EXPECT_EQ(r.status, ParseStatus::kMalformed)
          << "link type " << c.link_type << ", " << n << " bytes";
      EXPECT_NE(std::string(r.reason), "") << n;
    }
    // Cutting only Ethernet padding loses nothing.
    for (std::size_t n = c.unpadded_size; n <= c.frame.size(); ++n) {
      const Bytes cut(c.frame.begin(), c.frame.begin() + static_cast<std::ptrdiff_t>(n));
      const ParseResult r = Parse(c.link_type, cut);
      EXPECT_EQ(r.status, ParseStatus::kOk) << n;
      EXPECT_TRUE(PayloadInside(r, cut));
    }
  }
}

}  // namespace
}  // namespace lrfnet::capture
