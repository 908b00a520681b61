#pragma once
// Pure packet parser: one captured frame -> addresses, ports, TCP sequence/flags and the transport
// payload. No socket, no clock, no logging, no allocation; the result's payload is a view into the
// frame.
//
// Link types (LINKTYPE_* numbers of the pcap/pcapng formats): Ethernet (with any number of 802.1Q /
// 802.1ad VLAN tags), Linux cooked capture v1 and v2, raw IP (IPv4 or IPv6 by the version nibble),
// raw IPv4, raw IPv6, and BSD loopback (NULL and LOOP, either byte order).
//
// Network layer: IPv4 (options skipped) and IPv6 (hop-by-hop, routing and destination-options
// extension headers skipped). The IP packet ends at the IP length field, not at the frame end:
// Ethernet frames are padded to 60 bytes, so a short segment is followed by padding that is not
// payload. Fragments are reported as unsupported (no reassembly). Checksums are not verified:
// captures taken on the receiving host carry wrong TCP checksums when the card offloads them, and
// coalesced segments (frames larger than the MTU, from receive offload) are accepted as they are.
//
// Transport: TCP (options skipped) and UDP.

#include <array>
#include <cstdint>
#include <span>

namespace lrfnet::capture {

inline constexpr std::uint32_t kLinkTypeNull = 0;  // BSD loopback, host byte order family
inline constexpr std::uint32_t kLinkTypeEthernet = 1;
inline constexpr std::uint32_t kLinkTypeRaw = 101;   // raw IPv4 or IPv6
inline constexpr std::uint32_t kLinkTypeLoop = 108;  // BSD loopback, network byte order family
inline constexpr std::uint32_t kLinkTypeLinuxSll = 113;
inline constexpr std::uint32_t kLinkTypeIpv4 = 228;
inline constexpr std::uint32_t kLinkTypeIpv6 = 229;
inline constexpr std::uint32_t kLinkTypeLinuxSll2 = 276;

// True for the link types listed above.
bool IsSupportedLinkType(std::uint32_t link_type);

// TCP header flag bits (byte 13 of the TCP header).
inline constexpr std::uint8_t kTcpFin = 0x01;
inline constexpr std::uint8_t kTcpSyn = 0x02;
inline constexpr std::uint8_t kTcpRst = 0x04;
inline constexpr std::uint8_t kTcpPsh = 0x08;
inline constexpr std::uint8_t kTcpAck = 0x10;

enum class IpFamily : std::uint8_t { kNone, kIpv4, kIpv6 };
enum class TransportProtocol : std::uint8_t { kNone, kTcp, kUdp };

struct IpAddress {
  IpFamily family = IpFamily::kNone;
  // Network byte order. IPv4 uses the first 4 bytes; the rest stay zero, so == compares correctly.
  std::array<std::uint8_t, 16> bytes{};

  bool operator==(const IpAddress&) const = default;
};

struct ParsedPacket {
  IpAddress src_address;
  IpAddress dst_address;
  TransportProtocol protocol = TransportProtocol::kNone;
  std::uint16_t src_port = 0;
  std::uint16_t dst_port = 0;
  // TCP only (zero for UDP).
  std::uint32_t tcp_seq = 0;
  std::uint32_t tcp_ack = 0;
  std::uint8_t tcp_flags = 0;  // kTcp* bits
  // Transport payload: a view into the frame passed to ParsePacket, never past the IP length.
  std::span<const std::uint8_t> payload;
};

enum class ParseStatus {
  kOk,
  // Well-formed but not TCP/UDP over IP (ARP, ICMP, fragments, unknown link type): ignore.
  kUnsupported,
  kMalformed,  // truncated or inconsistent headers: drop and count
};

struct ParseResult {
  ParseStatus status = ParseStatus::kMalformed;
  const char* reason = "";  // static string, e.g. "truncated IPv4 header"; "" when kOk
  ParsedPacket packet;      // valid when status == kOk
};

// Parses one captured frame of the given link type.
ParseResult ParsePacket(std::uint32_t link_type, std::span<const std::uint8_t> frame);

}  // namespace lrfnet::capture
