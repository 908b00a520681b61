#include "common/capture/capture_stream.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "common/capture/capture_test_util.h"
#include "common/capture/packet_parser.h"
#include "common/capture/pcap_reader.h"
#include "tests/support/test_data.h"

namespace lrfnet::capture {
namespace {

using Bytes = std::vector<std::uint8_t>;

// ------------------------------------------------------------------------------------------------
// Writing small captures.

using test::Put16;
using test::Put32;
void AppendLe32(Bytes* b, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b->push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
using test::Cat;
using test::Text;

Bytes TcpHeader(std::uint16_t src_port, std::uint16_t dst_port, std::uint32_t seq,
                std::uint8_t flags, const Bytes& payload) {
  Bytes h(20, 0);
  Put16(&h, 0, src_port);
  Put16(&h, 2, dst_port);
  Put32(&h, 4, seq);
  h[12] = 5 << 4;
  h[13] = flags;
  Put16(&h, 14, 65535);
  return Cat(h, payload);
}

Bytes Ipv4Packet(std::uint32_t src, std::uint32_t dst, std::uint8_t protocol, const Bytes& l4) {
  Bytes h(20, 0);
  h[0] = 0x45;
  Put16(&h, 2, static_cast<std::uint32_t>(20 + l4.size()));
  h[8] = 64;
  h[9] = protocol;
  Put32(&h, 12, src);
  Put32(&h, 16, dst);
  return Cat(h, l4);
}

Bytes Ipv6Packet(std::uint8_t src_last, std::uint8_t dst_last, std::uint8_t protocol,
                 const Bytes& l4) {
  Bytes h(40, 0);
  h[0] = 0x60;
  Put16(&h, 4, static_cast<std::uint32_t>(l4.size()));
  h[6] = protocol;
  h[7] = 64;
  h[8] = 0x20;
  h[9] = 0x01;
  h[23] = src_last;
  h[24] = 0x20;
  h[25] = 0x01;
  h[39] = dst_last;
  return Cat(h, l4);
}

Bytes EthernetFrame(std::uint16_t ether_type, const Bytes& payload) {
  Bytes h(14, 0);
  Put16(&h, 12, ether_type);
  Bytes f = Cat(h, payload);
  if (f.size() < 60) f.resize(60, 0);
  return f;
}

Bytes SllFrame(std::uint16_t protocol, const Bytes& payload) {
  Bytes h(16, 0);
  Put16(&h, 2, 1);
  Put16(&h, 4, 6);
  Put16(&h, 14, protocol);
  return Cat(h, payload);
}

struct Packet {
  common::UtcNs time_ns;
  Bytes frame;
};

// Classic pcap, little-endian, nanosecond timestamps.
void WritePcap(const std::string& path, std::uint32_t link_type,
               const std::vector<Packet>& packets) {
  Bytes out;
  AppendLe32(&out, 0xA1B23C4D);
  AppendLe32(&out, 2 | (4u << 16));  // version 2.4
  AppendLe32(&out, 0);
  AppendLe32(&out, 0);
  AppendLe32(&out, 262144);
  AppendLe32(&out, link_type);
  for (const Packet& p : packets) {
    AppendLe32(&out, static_cast<std::uint32_t>(p.time_ns / common::kNsPerS));
    AppendLe32(&out, static_cast<std::uint32_t>(p.time_ns % common::kNsPerS));
    AppendLe32(&out, static_cast<std::uint32_t>(p.frame.size()));
    AppendLe32(&out, static_cast<std::uint32_t>(p.frame.size()));
    out.insert(out.end(), p.frame.begin(), p.frame.end());
  }
  std::ofstream f(path, std::ios::binary);
  f.write(reinterpret_cast<const char*>(out.data()), static_cast<std::streamsize>(out.size()));
  ASSERT_TRUE(f.good()) << path;
}

void WriteBytes(const std::string& path, const Bytes& bytes) {
  std::ofstream f(path, std::ios::binary);
  f.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(f.good()) << path;
}

// ------------------------------------------------------------------------------------------------
// Reading a whole stream.

struct StreamResult {
  Bytes bytes;
  // Spans dangle after the read; only times and flags are used.
  std::vector<StreamChunk> chunks;
  CaptureCounters counters;
  std::string error;
};

StreamResult ReadAll(const std::string& path, const CaptureStreamOptions& options = {}) {
  StreamResult r;
  std::string error;
  auto stream = CaptureStream::Open(path, options, &error);
  EXPECT_NE(stream, nullptr) << error;
  if (stream == nullptr) return r;
  StreamChunk chunk;
  while (stream->Next(&chunk)) {
    EXPECT_FALSE(chunk.bytes.empty());
    r.bytes.insert(r.bytes.end(), chunk.bytes.begin(), chunk.bytes.end());
    r.chunks.push_back(chunk);
  }
  EXPECT_FALSE(stream->Next(&chunk)) << "Next() after the end";
  r.counters = stream->counters();
  r.error = stream->error();
  return r;
}

// A tiny CoLa-B frame counter, independent of the codec library: 02 02 02 02, uint32 BE length,
// payload, XOR of the payload.
struct ColaScan {
  int frames = 0;
  int bad_checksums = 0;
  int scans = 0;  // payload starts with "sSN LMDscandata "
  std::size_t unframed_bytes = 0;
  std::string first_payload_start;
};

ColaScan ScanColaB(const Bytes& s) {
  ColaScan r;
  std::size_t at = 0;
  while (at < s.size()) {
    if (s.size() - at < 8 || !(s[at] == 2 && s[at + 1] == 2 && s[at + 2] == 2 && s[at + 3] == 2)) {
      ++r.unframed_bytes;
      ++at;
      continue;
    }
    const std::size_t length = (std::size_t{s[at + 4]} << 24) | (std::size_t{s[at + 5]} << 16) |
                               (std::size_t{s[at + 6]} << 8) | s[at + 7];
    if (s.size() - at - 8 < length + 1) {
      r.unframed_bytes += s.size() - at;
      break;
    }
    const auto payload = std::span<const std::uint8_t>(s).subspan(at + 8, length);
    std::uint8_t x = 0;
    for (std::uint8_t b : payload) x ^= b;
    if (x != s[at + 8 + length]) {
      ++r.bad_checksums;
    } else {
      ++r.frames;
      const std::string start(payload.begin(), payload.begin() + std::min<std::size_t>(16, length));
      if (r.frames == 1) r.first_payload_start = start;
      if (start == "sSN LMDscandata ") ++r.scans;
    }
    at += 9 + length;
  }
  return r;
}

struct TimeRange {
  common::UtcNs first = 0;
  common::UtcNs last = 0;
  std::uint64_t packets = 0;
};

TimeRange CaptureTimeRange(const std::string& path) {
  TimeRange range;
  std::string error;
  auto reader = PcapReader::Open(path, &error);
  EXPECT_NE(reader, nullptr) << error;
  if (reader == nullptr) return range;
  RawPacket p;
  while (reader->Next(&p) == ReadStatus::kPacket) {
    if (range.packets == 0 || p.timestamp_ns < range.first) range.first = p.timestamp_ns;
    range.last = std::max(range.last, p.timestamp_ns);
    ++range.packets;
  }
  return range;
}

class TempDir : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = std::filesystem::temp_directory_path() /
           ("lrfnet_capture_" + std::string(info->name()) + "_" + std::to_string(::getpid()));
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  std::filesystem::path dir_;
};

// ------------------------------------------------------------------------------------------------
// The real SICK captures: the reassembled sensor stream holds exactly the CoLa-B frames of the
// README.

struct RealCapture {
  const char* name;
  std::uint64_t packets;
  int frames;
  int scans;
  std::uint64_t retransmitted_bytes;
  std::uint64_t connections;  // SYNs from the sensor
};

class RealCaptureTest : public ::testing::TestWithParam<RealCapture> {};

TEST_P(RealCaptureTest, SensorStreamHoldsExactlyTheFrames) {
  const RealCapture& c = GetParam();
  LRFNET_REQUIRE_SHARED_FILE(path, std::string("data/sick/") + c.name);
  const StreamResult r = ReadAll(path);
  EXPECT_EQ(r.error, "");

  const ColaScan scan = ScanColaB(r.bytes);
  EXPECT_EQ(scan.frames, c.frames);
  EXPECT_EQ(scan.scans, c.scans);
  EXPECT_EQ(scan.bad_checksums, 0);
  EXPECT_EQ(scan.unframed_bytes, 0u);

  EXPECT_EQ(r.counters.packets, c.packets);
  EXPECT_EQ(r.counters.malformed_packets, 0u);
  EXPECT_EQ(r.counters.stream_packets + r.counters.ignored_packets, r.counters.packets);
  EXPECT_EQ(r.counters.retransmitted_bytes, c.retransmitted_bytes);
  EXPECT_EQ(r.counters.connections, c.connections);
  EXPECT_EQ(r.counters.gaps, 0u);
  EXPECT_EQ(r.counters.gap_bytes, 0u);
  EXPECT_EQ(r.counters.out_of_order_segments, 0u);
  EXPECT_EQ(r.counters.delivered_bytes, r.bytes.size());

  const TimeRange range = CaptureTimeRange(path);
  ASSERT_FALSE(r.chunks.empty());
  for (std::size_t i = 0; i < r.chunks.size(); ++i) {
    EXPECT_FALSE(r.chunks[i].discontinuity) << "chunk " << i;
    EXPECT_GE(r.chunks[i].receive_time_ns, range.first) << "chunk " << i;
    EXPECT_LE(r.chunks[i].receive_time_ns, range.last) << "chunk " << i;
    if (i > 0) {
      EXPECT_GE(r.chunks[i].receive_time_ns, r.chunks[i - 1].receive_time_ns) << "chunk " << i;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(
    SickCaptures, RealCaptureTest,
    ::testing::Values(RealCapture{"test.pcapng", 50, 16, 16, 0, 0},
                      RealCapture{"lms111_20210302.pcap", 557, 222, 172, 3663, 1},
                      RealCapture{"lms511_20210301.pcap", 829, 209, 136, 117, 1},
                      RealCapture{"mrs1104_20210722.pcap", 443, 134, 96, 0, 1}),
    [](const ::testing::TestParamInfo<RealCapture>& param_info) {
      std::string name = param_info.param.name;
      std::replace_if(
          name.begin(), name.end(), [](char ch) { return !std::isalnum(ch); }, '_');
      return name;
    });

TEST(CaptureStream, TiM781sCaptureStartsMidConnectionAtAFrame) {
  LRFNET_REQUIRE_SHARED_FILE(path, "data/sick/test.pcapng");
  const StreamResult r = ReadAll(path);
  EXPECT_EQ(r.bytes.size(), 16u * 3374u);  // 16 scan telegrams, 3374 bytes each
  ASSERT_GE(r.bytes.size(), 4u);
  EXPECT_EQ(r.bytes[0], 2);
  // The client only sends ACKs: its direction carries no bytes.
  CaptureStreamOptions client;
  client.from_sensor = false;
  const StreamResult c = ReadAll(path, client);
  EXPECT_TRUE(c.bytes.empty());
  EXPECT_EQ(c.counters.packets, 50u);
}

TEST(CaptureStream, ClientDirectionHoldsTheCommands) {
  LRFNET_REQUIRE_SHARED_FILE(path, "data/sick/lms111_20210302.pcap");
  CaptureStreamOptions options;
  options.from_sensor = false;
  const StreamResult r = ReadAll(path, options);
  const ColaScan scan = ScanColaB(r.bytes);
  EXPECT_GT(scan.frames, 10);
  EXPECT_EQ(scan.unframed_bytes, 0u);
  EXPECT_EQ(scan.scans, 0);
  EXPECT_EQ(scan.first_payload_start.rfind("sMN SetAccess", 0), 0u) << scan.first_payload_start;
  EXPECT_EQ(r.counters.connections, 1u);  // the client's SYN
}

// ------------------------------------------------------------------------------------------------
// Broken and unusual files.

class CaptureFiles : public TempDir {};

// Byte offsets where the records of a classic pcap file start.
std::vector<std::size_t> PcapRecordOffsets(const Bytes& file) {
  std::vector<std::size_t> offsets;
  std::size_t at = 24;
  while (at + 16 <= file.size()) {
    offsets.push_back(at);
    const std::size_t caplen = std::size_t{file[at + 8]} | (std::size_t{file[at + 9]} << 8) |
                               (std::size_t{file[at + 10]} << 16) |
                               (std::size_t{file[at + 11]} << 24);
    at += 16 + caplen;
  }
  return offsets;
}

TEST_F(CaptureFiles, TruncatedPcapDeliversWhatPrecedesAndReportsTheError) {
  LRFNET_REQUIRE_SHARED_FILE(path, "data/sick/lms111_20210302.pcap");
  const Bytes file = testing::ReadFileBytes(path);
  const std::vector<std::size_t> records = PcapRecordOffsets(file);
  ASSERT_GT(records.size(), 400u);
  // Cut at a record boundary: a clean end. Cut in the middle of the next record: the same bytes,
  // plus an error naming the file.
  const std::size_t boundary = records[400];
  const std::size_t inside = boundary + 16 + 20;
  WriteBytes(Path("clean.pcap"),
             Bytes(file.begin(), file.begin() + static_cast<std::ptrdiff_t>(boundary)));
  WriteBytes(Path("cut.pcap"),
             Bytes(file.begin(), file.begin() + static_cast<std::ptrdiff_t>(inside)));

  const StreamResult full = ReadAll(path);
  const StreamResult clean = ReadAll(Path("clean.pcap"));
  const StreamResult cut = ReadAll(Path("cut.pcap"));
  EXPECT_EQ(clean.error, "");
  EXPECT_EQ(clean.counters.packets, 400u);
  ASSERT_GT(clean.bytes.size(), 1000u);
  EXPECT_EQ(cut.bytes, clean.bytes);
  EXPECT_EQ(cut.counters.packets, 400u);
  ASSERT_LT(clean.bytes.size(), full.bytes.size());
  EXPECT_TRUE(std::equal(clean.bytes.begin(), clean.bytes.end(), full.bytes.begin()));
  EXPECT_EQ(cut.error.rfind(Path("cut.pcap") + ": ", 0), 0u) << cut.error;
  EXPECT_NE(cut.error.find("truncated"), std::string::npos) << cut.error;
  EXPECT_EQ(cut.error.find('\n'), std::string::npos);
}

TEST_F(CaptureFiles, TruncatedPcapngDeliversAPrefix) {
  LRFNET_REQUIRE_SHARED_FILE(path, "data/sick/test.pcapng");
  const Bytes file = testing::ReadFileBytes(path);
  WriteBytes(Path("cut.pcapng"),
             Bytes(file.begin(), file.begin() + static_cast<std::ptrdiff_t>(file.size() / 2)));
  const StreamResult full = ReadAll(path);
  const StreamResult cut = ReadAll(Path("cut.pcapng"));
  EXPECT_NE(cut.error, "");
  ASSERT_GT(cut.bytes.size(), 3374u * 4);
  ASSERT_LT(cut.bytes.size(), full.bytes.size());
  EXPECT_TRUE(std::equal(cut.bytes.begin(), cut.bytes.end(), full.bytes.begin()));
}

TEST_F(CaptureFiles, MissingFileGivesOneClearLine) {
  const std::string missing = Path("no_such_capture.pcap");
  std::string error;
  EXPECT_EQ(CaptureStream::Open(missing, {}, &error), nullptr);
  EXPECT_EQ(error.rfind(missing + ": ", 0), 0u) << error;
  EXPECT_NE(error.find("No such file"), std::string::npos) << error;
  EXPECT_EQ(error.find(missing, 1), std::string::npos) << "path named twice: " << error;
  EXPECT_EQ(error.find('\n'), std::string::npos);
}

TEST_F(CaptureFiles, NonCaptureFileGivesOneClearLine) {
  WriteBytes(Path("notes.txt"), Text("these are notes, not packets; long enough for a header\n"));
  WriteBytes(Path("empty.pcap"), {});
  for (const char* name : {"notes.txt", "empty.pcap"}) {
    std::string error;
    EXPECT_EQ(CaptureStream::Open(Path(name), {}, &error), nullptr);
    EXPECT_EQ(error.rfind(Path(name) + ": cannot read as pcap or pcapng: ", 0), 0u) << error;
    EXPECT_EQ(error.find('\n'), std::string::npos);
  }
}

TEST_F(CaptureFiles, UnsupportedLinkTypeIsNamed) {
  WritePcap(Path("wifi.pcap"), 105, {{1, Bytes(40, 0)}});
  std::string error;
  EXPECT_EQ(CaptureStream::Open(Path("wifi.pcap"), {}, &error), nullptr);
  EXPECT_NE(error.find("unsupported link type 105"), std::string::npos) << error;
}

TEST_F(CaptureFiles, InvalidOptionsAreRejected) {
  WritePcap(Path("empty_ok.pcap"), kLinkTypeEthernet, {});
  CaptureStreamOptions options;
  options.sensor_port = 0;
  EXPECT_TRUE(Validate(options));
  std::string error;
  EXPECT_EQ(CaptureStream::Open(Path("empty_ok.pcap"), options, &error), nullptr);
  EXPECT_NE(error.find("sensor_port"), std::string::npos) << error;
  options = {};
  options.max_pending_bytes = 0;
  EXPECT_TRUE(Validate(options));
  EXPECT_FALSE(Validate(CaptureStreamOptions{}));
}

TEST_F(CaptureFiles, EmptyCaptureEndsCleanly) {
  WritePcap(Path("empty_ok.pcap"), kLinkTypeEthernet, {});
  const StreamResult r = ReadAll(Path("empty_ok.pcap"));
  EXPECT_TRUE(r.bytes.empty());
  EXPECT_EQ(r.error, "");
  EXPECT_EQ(r.counters.packets, 0u);
}

// A Linux cooked capture of an IPv6 session with reordering, a retransmission, other traffic and a
// broken packet.
TEST_F(CaptureFiles, LinuxCookedIpv6Session) {
  constexpr std::uint8_t kSensor = 0x01, kClient = 0x64;
  constexpr std::uint32_t kIsn = 0xFFFFFFFEu;  // the data wraps the sequence space
  constexpr std::uint32_t kClientIsn = 500;
  auto to_client = [&](std::uint32_t seq, std::uint8_t flags, const std::string& data) {
    return SllFrame(
        0x86DD, Ipv6Packet(kSensor, kClient, 6, TcpHeader(2112, 40000, seq, flags, Text(data))));
  };
  auto to_sensor = [&](std::uint32_t seq, std::uint8_t flags, const std::string& data) {
    return SllFrame(
        0x86DD, Ipv6Packet(kClient, kSensor, 6, TcpHeader(40000, 2112, seq, flags, Text(data))));
  };
  const common::UtcNs t0 = 1'700'000'000'123'456'789;
  Bytes broken = to_client(kIsn + 1, kTcpAck, "zzzz");
  broken.resize(16 + 30);  // cut inside the IPv6 header
  const std::vector<Packet> packets = {
      {t0 + 0, to_sensor(kClientIsn, kTcpSyn, "")},
      {t0 + 1, to_client(kIsn, kTcpSyn | kTcpAck, "")},
      {t0 + 2, to_sensor(kClientIsn + 1, kTcpAck, "")},
      {t0 + 3, to_sensor(kClientIsn + 1, kTcpAck | kTcpPsh, "sMN hello")},
      {t0 + 4, to_client(kIsn + 1, kTcpAck | kTcpPsh, "AAAA")},
      {t0 + 5, to_client(kIsn + 9, kTcpAck | kTcpPsh, "CCCC")},
      {t0 + 6, broken},
      {t0 + 7, SllFrame(0x0806, Bytes(28, 0))},  // ARP
      {t0 + 8,
       SllFrame(0x86DD, Ipv6Packet(kSensor, kClient, 17,
                                   Bytes{0x08, 0x40, 0x9C, 0x40, 0, 12, 0, 0, 1, 2, 3, 4}))},
      {t0 + 9, to_client(kIsn + 5, kTcpAck | kTcpPsh, "BBBB")},
      {t0 + 10, to_client(kIsn + 1, kTcpAck | kTcpPsh, "AAAA")},  // retransmission
      {t0 + 11, to_sensor(kClientIsn + 10, kTcpAck, "")},
  };
  WritePcap(Path("sll6.pcap"), kLinkTypeLinuxSll, packets);

  const StreamResult r = ReadAll(Path("sll6.pcap"));
  EXPECT_EQ(r.error, "");
  EXPECT_EQ(std::string(r.bytes.begin(), r.bytes.end()), "AAAABBBBCCCC");
  ASSERT_EQ(r.chunks.size(), 3u);
  EXPECT_EQ(r.chunks[0].receive_time_ns, t0 + 4);  // nanoseconds kept
  EXPECT_EQ(r.chunks[1].receive_time_ns, t0 + 9);
  EXPECT_EQ(r.chunks[2].receive_time_ns, t0 + 9);  // held until BBBB filled the hole
  EXPECT_EQ(r.counters.packets, 12u);
  EXPECT_EQ(r.counters.stream_packets, 5u);
  EXPECT_EQ(r.counters.malformed_packets, 1u);
  EXPECT_EQ(r.counters.ignored_packets, 6u);
  EXPECT_EQ(r.counters.retransmitted_bytes, 4u);
  EXPECT_EQ(r.counters.out_of_order_segments, 1u);
  EXPECT_EQ(r.counters.connections, 1u);
  EXPECT_EQ(r.counters.delivered_bytes, 12u);

  CaptureStreamOptions client;
  client.from_sensor = false;
  const StreamResult c = ReadAll(Path("sll6.pcap"), client);
  EXPECT_EQ(std::string(c.bytes.begin(), c.bytes.end()), "sMN hello");
}

TEST_F(CaptureFiles, ClientReconnectSwitchesToTheNewConnection) {
  auto frame = [](std::uint16_t client_port, std::uint32_t seq, std::uint8_t flags,
                  const std::string& data) {
    return EthernetFrame(0x0800, Ipv4Packet(0xC0A80001, 0xC0A80064, 6,
                                            TcpHeader(2112, client_port, seq, flags, Text(data))));
  };
  const std::vector<Packet> packets = {
      {1000, frame(49152, 7000, kTcpSyn | kTcpAck, "")},
      {2000, frame(49152, 7001, kTcpAck, "first")},
      {3000, frame(49153, 90000, kTcpSyn | kTcpAck, "")},
      {4000, frame(49152, 7006, kTcpAck, "stale")},  // the old connection: no longer followed
      {5000, frame(49153, 90001, kTcpAck, "second")},
      {6000, frame(49153, 90001, kTcpAck, "second")},
  };
  WritePcap(Path("reconnect.pcap"), kLinkTypeEthernet, packets);
  const StreamResult r = ReadAll(Path("reconnect.pcap"));
  EXPECT_EQ(std::string(r.bytes.begin(), r.bytes.end()), "firstsecond");
  ASSERT_EQ(r.chunks.size(), 2u);
  EXPECT_FALSE(r.chunks[0].discontinuity);
  EXPECT_TRUE(r.chunks[1].discontinuity);
  EXPECT_EQ(r.chunks[1].receive_time_ns, 5000);
  EXPECT_EQ(r.counters.connections, 2u);
  EXPECT_EQ(r.counters.ignored_packets, 1u);
  EXPECT_EQ(r.counters.retransmitted_bytes, 6u);
}

TEST_F(CaptureFiles, MissingSegmentAtTheEndIsCountedAsAGap) {
  auto frame = [](std::uint32_t seq, const std::string& data) {
    return EthernetFrame(0x0800, Ipv4Packet(0xC0A80001, 0xC0A80064, 6,
                                            TcpHeader(2112, 49152, seq, kTcpAck, Text(data))));
  };
  WritePcap(Path("lost.pcap"), kLinkTypeEthernet,
            {{1, frame(100, "aaaa")}, {2, frame(110, "cccc")}, {3, frame(120, "eeee")}});
  const StreamResult r = ReadAll(Path("lost.pcap"));
  EXPECT_EQ(std::string(r.bytes.begin(), r.bytes.end()), "aaaacccceeee");
  ASSERT_EQ(r.chunks.size(), 3u);
  EXPECT_TRUE(r.chunks[1].discontinuity);
  EXPECT_TRUE(r.chunks[2].discontinuity);
  EXPECT_EQ(r.counters.gaps, 2u);
  EXPECT_EQ(r.counters.gap_bytes, 12u);
}

}  // namespace
}  // namespace lrfnet::capture
