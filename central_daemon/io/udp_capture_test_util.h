#pragma once
// Hand-made UDP captures for tests and fuzz seeds: IPv4/IPv6 UDP packets, Ethernet framing, and
// classic pcap (micro- or nanosecond) and minimal pcapng files around them. Checksums are left
// zero (readers do not verify them). Not for production code.

#include <algorithm>
#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "common/byte_order.h"
#include "common/capture/packet_parser.h"
#include "common/time.h"

namespace lrfnet::daemon::test_util {

using Bytes = std::vector<std::uint8_t>;

inline Bytes Ipv4Udp(std::array<std::uint8_t, 4> src, std::uint16_t src_port,
                     std::array<std::uint8_t, 4> dst, std::uint16_t dst_port,
                     std::span<const std::uint8_t> payload) {
  Bytes p(28 + payload.size(), 0);
  p[0] = 0x45;  // version 4, 20-byte header
  common::StoreBe16(&p[2], static_cast<std::uint16_t>(p.size()));
  p[8] = 64;  // TTL
  p[9] = 17;  // UDP
  std::copy(src.begin(), src.end(), p.begin() + 12);
  std::copy(dst.begin(), dst.end(), p.begin() + 16);
  common::StoreBe16(&p[20], src_port);
  common::StoreBe16(&p[22], dst_port);
  common::StoreBe16(&p[24], static_cast<std::uint16_t>(8 + payload.size()));
  std::copy(payload.begin(), payload.end(), p.begin() + 28);
  return p;
}

inline Bytes Ipv6Udp(std::array<std::uint8_t, 16> src, std::uint16_t src_port,
                     std::array<std::uint8_t, 16> dst, std::uint16_t dst_port,
                     std::span<const std::uint8_t> payload) {
  Bytes p(48 + payload.size(), 0);
  p[0] = 0x60;  // version 6
  common::StoreBe16(&p[4], static_cast<std::uint16_t>(8 + payload.size()));
  p[6] = 17;  // next header: UDP
  p[7] = 64;  // hop limit
  std::copy(src.begin(), src.end(), p.begin() + 8);
  std::copy(dst.begin(), dst.end(), p.begin() + 24);
  common::StoreBe16(&p[40], src_port);
  common::StoreBe16(&p[42], dst_port);
  common::StoreBe16(&p[44], static_cast<std::uint16_t>(8 + payload.size()));
  std::copy(payload.begin(), payload.end(), p.begin() + 48);
  return p;
}

// Ethernet II frame around an IP packet (EtherType from the IP version nibble).
inline Bytes Ethernet(std::span<const std::uint8_t> ip) {
  Bytes f(14, 0);
  f[0] = 0x02;  // locally administered MACs
  f[6] = 0x02;
  f[11] = 1;
  const bool v6 = !ip.empty() && (ip[0] >> 4) == 6;
  common::StoreBe16(&f[12], v6 ? 0x86DD : 0x0800);
  f.insert(f.end(), ip.begin(), ip.end());
  return f;
}

// Classic pcap, little-endian. `nanosecond` selects the 0xa1b23c4d magic.
class PcapFile {
 public:
  explicit PcapFile(std::uint32_t link_type, bool nanosecond = false) : nanosecond_(nanosecond) {
    bytes_.resize(24, 0);
    common::StoreLe32(&bytes_[0], nanosecond ? 0xa1b23c4du : 0xa1b2c3d4u);
    common::StoreLe16(&bytes_[4], 2);
    common::StoreLe16(&bytes_[6], 4);
    common::StoreLe32(&bytes_[16], 65535);  // snaplen
    common::StoreLe32(&bytes_[20], link_type);
  }
  PcapFile& Add(common::UtcNs time_ns, std::span<const std::uint8_t> frame) {
    const std::size_t at = bytes_.size();
    bytes_.resize(at + 16, 0);
    const auto seconds = static_cast<std::uint32_t>(time_ns / common::kNsPerS);
    const auto fraction = static_cast<std::uint32_t>(time_ns % common::kNsPerS);
    common::StoreLe32(&bytes_[at], seconds);
    common::StoreLe32(&bytes_[at + 4], nanosecond_ ? fraction : fraction / 1000);
    common::StoreLe32(&bytes_[at + 8], static_cast<std::uint32_t>(frame.size()));
    common::StoreLe32(&bytes_[at + 12], static_cast<std::uint32_t>(frame.size()));
    bytes_.insert(bytes_.end(), frame.begin(), frame.end());
    return *this;
  }
  const Bytes& bytes() const { return bytes_; }

 private:
  bool nanosecond_;
  Bytes bytes_;
};

// Minimal pcapng: section header, one interface (nanosecond resolution), enhanced packet blocks.
class PcapngFile {
 public:
  explicit PcapngFile(std::uint32_t link_type) {
    Bytes shb(16, 0);  // byte-order magic, version 1.0, section length unknown (-1)
    common::StoreLe32(&shb[0], 0x1A2B3C4D);
    common::StoreLe16(&shb[4], 1);
    std::fill(shb.begin() + 8, shb.end(), 0xff);
    Block(0x0A0D0D0A, shb.data(), shb.size());
    Bytes idb(8 + 8, 0);  // link type, reserved, snaplen, option if_tsresol = 9, end of options
    common::StoreLe16(&idb[0], static_cast<std::uint16_t>(link_type));
    common::StoreLe32(&idb[4], 65535);
    common::StoreLe16(&idb[8], 9);   // if_tsresol
    common::StoreLe16(&idb[10], 1);  // length 1
    idb[12] = 9;                     // 10^-9 s
    Bytes idb_with_end = idb;
    idb_with_end.resize(idb.size() + 4, 0);  // opt_endofopt
    Block(0x00000001, idb_with_end.data(), idb_with_end.size());
  }
  PcapngFile& Add(common::UtcNs time_ns, std::span<const std::uint8_t> frame) {
    Bytes epb(20, 0);
    const auto t = static_cast<std::uint64_t>(time_ns);
    common::StoreLe32(&epb[4], static_cast<std::uint32_t>(t >> 32));
    common::StoreLe32(&epb[8], static_cast<std::uint32_t>(t));
    common::StoreLe32(&epb[12], static_cast<std::uint32_t>(frame.size()));
    common::StoreLe32(&epb[16], static_cast<std::uint32_t>(frame.size()));
    epb.insert(epb.end(), frame.begin(), frame.end());
    epb.resize((epb.size() + 3) / 4 * 4, 0);
    Block(0x00000006, epb.data(), epb.size());
    return *this;
  }
  const Bytes& bytes() const { return bytes_; }

 private:
  void Block(std::uint32_t type, const std::uint8_t* body, std::size_t size) {
    const auto total = static_cast<std::uint32_t>(12 + size);
    const std::size_t at = bytes_.size();
    bytes_.resize(at + 8, 0);
    common::StoreLe32(&bytes_[at], type);
    common::StoreLe32(&bytes_[at + 4], total);
    bytes_.insert(bytes_.end(), body, body + size);
    const std::size_t end = bytes_.size();
    bytes_.resize(end + 4, 0);
    common::StoreLe32(&bytes_[end], total);
  }
  Bytes bytes_;
};

}  // namespace lrfnet::daemon::test_util
