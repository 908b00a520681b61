#include "tests/fuzz/capture_seeds.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "common/capture/capture_stream.h"
#include "common/capture/pcap_reader.h"

namespace lrfnet::fuzz {
namespace {

constexpr std::size_t kMaxPacketSeeds = 50;
constexpr std::size_t kMaxReassemblerSeeds = 10;
constexpr std::size_t kMaxSeedBytes = std::size_t{64} * 1024;
constexpr std::uint16_t kSensorPort = 2112;
// 2048 pending bytes, 16 ranges: room for one full-size segment held out of order.
constexpr std::uint8_t kSeedOptions = 7 | (15 << 3);

struct Segment {
  std::uint32_t seq = 0;
  std::uint8_t flags = 0;
  std::vector<std::uint8_t> payload;
};

void WriteFile(const std::filesystem::path& path, const std::vector<std::uint8_t>& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
}

std::string SeedName(const std::string& stem, const char* kind, std::size_t index) {
  char number[16];
  std::snprintf(number, sizeof(number), "%03zu", index);
  return stem + "_" + kind + "_" + number;
}

// Segment records of one run: plain, locally reordered, or with duplicates, so the seeds reach the
// reassembler's out-of-order and retransmission paths.
std::vector<std::uint8_t> EncodeRun(const std::vector<Segment>& segments, std::size_t first,
                                    std::size_t variant, bool synthetic) {
  // Synthetic records are 7 bytes but stand for up to 4 KiB of payload each: keep those runs short
  // so the target stays fast.
  const std::size_t max_records = synthetic ? 48 : 256;
  std::vector<const Segment*> order;
  for (std::size_t i = first; i < segments.size() && order.size() < max_records; ++i) {
    order.push_back(&segments[i]);
  }
  if (variant == 1) {
    for (std::size_t i = 0; i + 1 < order.size(); i += 3) std::swap(order[i], order[i + 1]);
  } else if (variant == 2) {
    std::vector<const Segment*> doubled;
    for (std::size_t i = 0; i < order.size(); ++i) {
      doubled.push_back(order[i]);
      if (i % 5 == 4) doubled.push_back(order[i - 2]);
    }
    order = std::move(doubled);
  }
  std::vector<std::uint8_t> out = {
      static_cast<std::uint8_t>(kSeedOptions | (synthetic ? kSyntheticPayloadBit : 0))};
  for (const Segment* s : order) {
    const std::size_t length = std::min<std::size_t>(s->payload.size(), 0xFFFF);
    const std::size_t record = kSegmentRecordHeaderBytes + (synthetic ? 0 : length);
    if (out.size() + record > kMaxSeedBytes) break;
    AppendSegmentRecord(&out, s->seq, s->flags, static_cast<std::uint16_t>(length),
                        synthetic ? std::span<const std::uint8_t>()
                                  : std::span<const std::uint8_t>(s->payload).first(length));
  }
  return out;
}

}  // namespace

void WriteCaptureSeeds(const std::string& capture_path, const std::string& reassembler_dir,
                       const std::string& packet_dir) {
  std::string error;
  auto reader = capture::PcapReader::Open(capture_path, &error);
  if (reader == nullptr) return;
  const std::optional<std::uint8_t> selector = FuzzLinkTypeSelector(reader->link_type());

  std::vector<std::vector<std::uint8_t>> frames;  // selector byte + frame
  std::vector<Segment> segments;
  capture::RawPacket packet;
  while (reader->Next(&packet) == capture::ReadStatus::kPacket) {
    if (selector) {
      std::vector<std::uint8_t> seed = {*selector};
      seed.insert(seed.end(), packet.bytes.begin(), packet.bytes.end());
      frames.push_back(std::move(seed));
    }
    const capture::ParseResult parsed = capture::ParsePacket(packet.link_type, packet.bytes);
    if (parsed.status == capture::ParseStatus::kOk &&
        parsed.packet.protocol == capture::TransportProtocol::kTcp &&
        parsed.packet.src_port == kSensorPort) {
      segments.push_back(
          {parsed.packet.tcp_seq, parsed.packet.tcp_flags,
           std::vector<std::uint8_t>(parsed.packet.payload.begin(), parsed.packet.payload.end())});
    }
  }

  const std::string stem = std::filesystem::path(capture_path).stem().string();
  std::error_code ec;
  if (!frames.empty()) {
    std::filesystem::create_directories(packet_dir, ec);
    const std::size_t count = std::min(frames.size(), kMaxPacketSeeds);
    for (std::size_t i = 0; i < count; ++i) {
      WriteFile(std::filesystem::path(packet_dir) / SeedName(stem, "frame", i),
                frames[i * frames.size() / count]);
    }
  }
  if (!segments.empty()) {
    std::filesystem::create_directories(reassembler_dir, ec);
    const std::size_t count = std::min(segments.size(), kMaxReassemblerSeeds);
    for (std::size_t i = 0; i < count; ++i) {
      // The first run starts at the capture's first sensor segment (its SYN when there is one).
      const std::size_t first = i * segments.size() / count;
      WriteFile(std::filesystem::path(reassembler_dir) / SeedName(stem, "segments", i),
                EncodeRun(segments, first, i % 3, /*synthetic=*/i % 4 == 3));
    }
  }
}

std::vector<std::uint8_t> ReadSensorStream(const std::string& capture_path) {
  std::vector<std::uint8_t> bytes;
  std::string error;
  capture::CaptureStreamOptions options;
  options.sensor_port = kSensorPort;
  auto stream = capture::CaptureStream::Open(capture_path, options, &error);
  if (stream == nullptr) return bytes;
  capture::StreamChunk chunk;
  while (stream->Next(&chunk)) bytes.insert(bytes.end(), chunk.bytes.begin(), chunk.bytes.end());
  return bytes;
}

}  // namespace lrfnet::fuzz
