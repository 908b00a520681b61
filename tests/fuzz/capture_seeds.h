#pragma once
// Seeds for the capture fuzz targets, made from a real capture, and the input formats those targets
// share with the seed writer.
//
// packet_fuzz input: [selector u8][frame bytes...]
//   The selector picks the link type: kFuzzLinkTypes[selector % kFuzzLinkTypes.size()].
//
// reassembler_fuzz input: [options u8] then records [seq u32 BE][flags u8][length u16 BE][payload]
//   options bits 0-2: max_pending_bytes = 16 << value (16 .. 2048)
//           bits 3-6: max_pending_ranges = 1 + value (1 .. 16)
//           bit 7:    synthetic payload: records carry no payload bytes and the length is taken
//                     modulo kSyntheticMaxLength; the byte at sequence number s is
//                     SyntheticByte(s), so the target can check every delivered byte.
//   flags are TCP header flags (kTcp* of packet_parser.h). A final record cut short is fed with
//   the payload bytes present. Segment i is stamped i microseconds. Feeding stops after
//   kFuzzMaxFedBytes of payload (keeps a run fast whatever the lengths say).

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "common/capture/packet_parser.h"

namespace lrfnet::fuzz {

// The last entry is deliberately unsupported (IEEE 802.11) so the fuzzer covers that path too.
inline constexpr std::array<std::uint32_t, 9> kFuzzLinkTypes = {
    capture::kLinkTypeEthernet, capture::kLinkTypeLinuxSll, capture::kLinkTypeLinuxSll2,
    capture::kLinkTypeRaw,      capture::kLinkTypeIpv4,     capture::kLinkTypeIpv6,
    capture::kLinkTypeNull,     capture::kLinkTypeLoop,     105};

inline std::uint32_t FuzzLinkType(std::uint8_t selector) {
  return kFuzzLinkTypes[selector % kFuzzLinkTypes.size()];
}

inline std::optional<std::uint8_t> FuzzLinkTypeSelector(std::uint32_t link_type) {
  for (std::size_t i = 0; i < kFuzzLinkTypes.size(); ++i) {
    if (kFuzzLinkTypes[i] == link_type) return static_cast<std::uint8_t>(i);
  }
  return std::nullopt;
}

inline constexpr std::size_t kSegmentRecordHeaderBytes = 7;
inline constexpr std::uint8_t kSyntheticPayloadBit = 0x80;
inline constexpr std::size_t kSyntheticMaxLength = 4096;
inline constexpr std::size_t kFuzzMaxFedBytes = std::size_t{64} * 1024;

inline std::size_t FuzzMaxPendingBytes(std::uint8_t options) {
  return std::size_t{16} << (options & 7);
}
inline std::size_t FuzzMaxPendingRanges(std::uint8_t options) { return 1 + ((options >> 3) & 15); }

inline std::uint8_t SyntheticByte(std::uint32_t seq) {
  return static_cast<std::uint8_t>((seq * 2654435761u) >> 24);
}

// Appends one record; in synthetic mode pass an empty payload and the length separately.
inline void AppendSegmentRecord(std::vector<std::uint8_t>* out, std::uint32_t seq,
                                std::uint8_t flags, std::uint16_t length,
                                std::span<const std::uint8_t> payload) {
  for (int shift = 24; shift >= 0; shift -= 8)
    out->push_back(static_cast<std::uint8_t>(seq >> shift));
  out->push_back(flags);
  out->push_back(static_cast<std::uint8_t>(length >> 8));
  out->push_back(static_cast<std::uint8_t>(length));
  out->insert(out->end(), payload.begin(), payload.end());
}

// Writes seed files for packet_fuzz (up to 50 frames sampled across the capture) into packet_dir
// and for reassembler_fuzz (up to 10 runs of the sensor -> client segments, each file at most 64
// KiB, some reordered or duplicated, some in synthetic mode) into reassembler_dir. Directories are
// created; a capture that cannot be read writes nothing.
void WriteCaptureSeeds(const std::string& capture_path, const std::string& reassembler_dir,
                       const std::string& packet_dir);

// The whole reassembled sensor -> client byte stream of a capture (TCP port 2112); empty when the
// file cannot be opened, the bytes before the error when it ends in one.
std::vector<std::uint8_t> ReadSensorStream(const std::string& capture_path);

}  // namespace lrfnet::fuzz
