#include "central_daemon/io/datagram_source.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "central_daemon/io/recording_decoder.h"
#include "central_daemon/io/recording_test_util.h"
#include "central_daemon/io/recording_writer.h"
#include "central_daemon/io/udp_capture_source.h"
#include "central_daemon/io/udp_capture_test_util.h"
#include "firmware_tracker/io/recording_writer.h"

namespace lrfnet::daemon {
namespace {

using test_util::Bytes;
using test_util::MakeDatagram;
using test_util::ReadBytes;
using test_util::ReadResult;
using test_util::ReadToEnd;
using test_util::TempPath;
using test_util::WriteBytes;

constexpr common::UtcNs kSourceT0 = 1'700'000'000'000'000'000;
constexpr common::DurationNs kSourceMs = common::kNsPerMs;

class DatagramSourceTest : public ::testing::Test {
 protected:
  static void TearDownTestSuite() { std::filesystem::remove_all(test_util::TempDir()); }
};

bool Contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// A small recording written by the daemon's writer; *boundaries gets the end offset of every
// entry (header first).
Bytes SmallRecording(const std::string& path, std::vector<std::size_t>* boundaries) {
  RecordingWriterOptions options;
  options.path = path;
  RecordingWriter writer(options);
  EXPECT_EQ(writer.Open(kSourceT0), std::nullopt);
  for (std::uint32_t i = 0; i < 4; ++i) {
    writer.Append(MakeDatagram(i * i * 20, i), "10.0.0.1:5000", kSourceT0 + i * kSourceMs);
  }
  EXPECT_EQ(writer.Close(), std::nullopt);
  Bytes bytes = ReadBytes(path);
  RecordingDecoder decoder;
  std::span<const std::uint8_t> rest(bytes);
  std::size_t consumed = 0;
  while (decoder.Feed(rest, &consumed) == RecordingDecodeStatus::kEntry) {
    rest = rest.subspan(consumed);
    boundaries->push_back(static_cast<std::size_t>(decoder.offset()));
  }
  EXPECT_EQ(boundaries->size(), 5u);
  return bytes;
}

std::unique_ptr<DatagramSource> Open(const std::string& path, std::string* error,
                                     std::uint16_t udp_port = 0) {
  DatagramSourceOptions options;
  options.udp_port = udp_port;
  return OpenDatagramFile(path, options, error);
}

TEST_F(DatagramSourceTest, RecordingCutAtEveryByteGivesTheWholeEntriesBeforeTheCut) {
  std::vector<std::size_t> boundaries;
  const Bytes whole = SmallRecording(TempPath("whole.rec"), &boundaries);
  const std::string path = TempPath("cut.rec");
  for (std::size_t cut = 0; cut <= whole.size(); ++cut) {
    WriteBytes(path, Bytes(whole.begin(), whole.begin() + static_cast<long>(cut)));
    std::string error;
    auto source = Open(path, &error);
    if (cut < boundaries[0]) {  // not even the header
      EXPECT_EQ(source, nullptr) << cut;
      EXPECT_TRUE(Contains(error, "not a recording or capture")) << error;
      EXPECT_TRUE(Contains(error, path)) << error;
      continue;
    }
    ASSERT_NE(source, nullptr) << cut << ": " << error;
    const ReadResult r = ReadToEnd(*source);
    std::size_t entries = 0;
    while (entries < boundaries.size() && boundaries[entries] <= cut) ++entries;
    ASSERT_EQ(r.datagrams.size(), entries - 1) << "cut at " << cut;
    for (std::size_t i = 0; i < r.datagrams.size(); ++i) {
      EXPECT_EQ(r.datagrams[i].bytes, MakeDatagram(i * i * 20, static_cast<std::uint32_t>(i)));
    }
    if (boundaries[entries - 1] == cut) {
      EXPECT_EQ(r.end, SourceStatus::kEnd) << "cut at " << cut;
      EXPECT_TRUE(r.error.empty());
    } else {
      EXPECT_EQ(r.end, SourceStatus::kError) << "cut at " << cut;
      EXPECT_TRUE(Contains(r.error, "'" + path + "'")) << r.error;
      EXPECT_TRUE(Contains(r.error, "at byte " + std::to_string(boundaries[entries - 1])))
          << r.error;
      EXPECT_EQ(r.error.find('\n'), std::string::npos);
    }
  }
}

TEST_F(DatagramSourceTest, CorruptedLengthEndsTheStreamAfterTheEntriesBeforeIt) {
  std::vector<std::size_t> boundaries;
  const Bytes whole = SmallRecording(TempPath("whole2.rec"), &boundaries);
  Bytes damaged(whole.begin(), whole.begin() + static_cast<long>(boundaries[2]));
  for (const int b : {0x80, 0x80, 0x40}) damaged.push_back(static_cast<std::uint8_t>(b));  // 1 MiB
  damaged.insert(damaged.end(), whole.begin() + static_cast<long>(boundaries[2]) + 1, whole.end());
  const std::string path = TempPath("bad_length.rec");
  WriteBytes(path, damaged);
  std::string error;
  auto source = Open(path, &error);
  ASSERT_NE(source, nullptr) << error;
  const ReadResult r = ReadToEnd(*source);
  EXPECT_EQ(r.datagrams.size(), 2u);
  EXPECT_EQ(r.end, SourceStatus::kError);
  EXPECT_EQ(r.error, "recording '" + path + "': length prefix 1048576 above the 65536-byte limit" +
                         " at byte " + std::to_string(boundaries[2]));
  ReceivedDatagram d;
  EXPECT_EQ(source->Next(&d), SourceStatus::kError);  // final
}

TEST_F(DatagramSourceTest, FilesThatAreNeitherGiveOneClearLine) {
  const std::string text = TempPath("notes.txt");
  const std::string prose = "these are notes, not a recording\n";
  WriteBytes(text, Bytes(prose.begin(), prose.end()));
  const std::string binary = TempPath("random.bin");
  Bytes noise(4096);
  std::uint32_t x = 12345;
  for (auto& b : noise) {
    x = x * 1103515245u + 12345u;
    b = static_cast<std::uint8_t>(x >> 24);
  }
  WriteBytes(binary, noise);
  const std::string empty = TempPath("empty.rec");
  WriteBytes(empty, {});
  for (const std::string& path : {text, binary, empty}) {
    std::string error;
    EXPECT_EQ(Open(path, &error), nullptr) << path;
    EXPECT_TRUE(Contains(error, "'" + path + "'")) << error;
    EXPECT_TRUE(Contains(error, "not a recording or capture")) << error;
    EXPECT_EQ(error.find('\n'), std::string::npos) << error;
  }
  std::string error;
  EXPECT_EQ(Open(TempPath("does_not_exist.rec"), &error), nullptr);
  EXPECT_TRUE(Contains(error, "cannot open")) << error;
  EXPECT_EQ(Open(test_util::TempDir().string(), &error), nullptr);
  EXPECT_TRUE(Contains(error, "directory")) << error;
  EXPECT_EQ(OpenDatagramFile(text, {}, nullptr), nullptr);  // error is optional
}

TEST_F(DatagramSourceTest, UnknownFormatVersionIsNamed) {
  const std::string path = TempPath("future.rec");
  // RecordEntry{header{format_version: 2}}: 0x22 len {0x08 0x02}
  WriteBytes(path, {0x04, 0x22, 0x02, 0x08, 0x02});
  std::string error;
  EXPECT_EQ(Open(path, &error), nullptr);
  EXPECT_TRUE(Contains(error, "format version 2 is not supported")) << error;
}

TEST_F(DatagramSourceTest, DamagedRotationPartIsNamed) {
  const std::string path = TempPath("parts.rec");
  RecordingWriterOptions options;
  options.path = path;
  options.max_file_bytes = 64 * 1024;
  RecordingWriter writer(options);
  ASSERT_EQ(writer.Open(kSourceT0), std::nullopt);
  for (std::uint32_t i = 0; i < 200; ++i) {
    writer.Append(MakeDatagram(1000, i), "10.0.0.1:5000", kSourceT0 + i * kSourceMs);
  }
  ASSERT_EQ(writer.Close(), std::nullopt);
  ASSERT_EQ(RecordingFiles(path).size(), 4u);
  const Bytes part2 = ReadBytes(path + ".2");
  const Bytes part1 = ReadBytes(path + ".1");

  // Torn in the middle of path.2: everything of path and path.1, then what path.2 holds whole.
  WriteBytes(path + ".2", Bytes(part2.begin(), part2.begin() + 5000));
  std::string error;
  auto source = Open(path, &error);
  ASSERT_NE(source, nullptr) << error;
  ReadResult r = ReadToEnd(*source);
  EXPECT_EQ(r.end, SourceStatus::kError);
  EXPECT_TRUE(Contains(r.error, "'" + path + ".2'")) << r.error;
  EXPECT_TRUE(Contains(r.error, "torn entry")) << r.error;
  ASSERT_GT(r.datagrams.size(), 63u * 2);
  for (std::size_t i = 0; i < r.datagrams.size(); ++i) {
    ASSERT_EQ(r.datagrams[i].bytes, MakeDatagram(1000, static_cast<std::uint32_t>(i))) << i;
  }
  EXPECT_EQ(source->counters().files, 3u);

  // path.1 without its header.
  WriteBytes(path + ".2", part2);
  Bytes headless = part1;
  RecordingDecoder decoder;
  std::size_t header_bytes = 0;
  ASSERT_EQ(decoder.Feed(part1, &header_bytes), RecordingDecodeStatus::kEntry);
  headless.erase(headless.begin(), headless.begin() + static_cast<long>(header_bytes));
  WriteBytes(path + ".1", headless);
  source = Open(path, &error);
  ASSERT_NE(source, nullptr) << error;
  r = ReadToEnd(*source);
  EXPECT_EQ(r.end, SourceStatus::kError);
  EXPECT_EQ(r.error, "recording '" + path + ".1': the first entry carries no recording header" +
                         " at byte 0");
  EXPECT_EQ(r.datagrams.size(), 63u);  // all of the first file
}

TEST_F(DatagramSourceTest, ReadsTheTrackersOwnRecordings) {
  const std::string path = TempPath("tracker.rec");
  io::RecordingWriterOptions options;
  options.path = path;
  options.writer = "lrfnet-tracker 0.1.0";
  options.source = io::TrackerRecordSource("gate-3");
  std::vector<Bytes> sent;
  {
    io::RecordingWriter writer(options);
    ASSERT_EQ(writer.Open(kSourceT0), std::nullopt);
    for (std::uint32_t i = 0; i < 100; ++i) {
      sent.push_back(MakeDatagram(i * 13 % 1400, i));
      writer.Append(sent.back(), kSourceT0 + i * 40 * kSourceMs);
    }
    ASSERT_EQ(writer.Close(), std::nullopt);
  }
  std::string error;
  auto source = Open(path, &error);
  ASSERT_NE(source, nullptr) << error;
  EXPECT_EQ(source->kind(), DatagramFileKind::kRecording);
  EXPECT_EQ(source->writer(), "lrfnet-tracker 0.1.0");
  EXPECT_EQ(source->created_ns(), kSourceT0);
  const ReadResult r = ReadToEnd(*source);
  EXPECT_EQ(r.end, SourceStatus::kEnd) << r.error;
  ASSERT_EQ(r.datagrams.size(), sent.size());
  for (std::size_t i = 0; i < sent.size(); ++i) {
    EXPECT_EQ(r.datagrams[i].bytes, sent[i]);
    EXPECT_EQ(r.datagrams[i].source, "tracker:gate-3");
    EXPECT_EQ(r.datagrams[i].receive_ns, kSourceT0 + static_cast<common::UtcNs>(i) * 40 * kSourceMs);
  }
}

// --- captures ---------------------------------------------------------------------------------

constexpr std::array<std::uint8_t, 4> kSensorA = {192, 168, 1, 10};
constexpr std::array<std::uint8_t, 4> kSensorB = {192, 168, 1, 11};
constexpr std::array<std::uint8_t, 4> kDaemon4 = {192, 168, 1, 2};
constexpr std::array<std::uint8_t, 16> kSensorC = {0xfe, 0x80, 0, 0, 0, 0, 0, 0,
                                                   0,    0,    0, 0, 0, 0, 0, 1};
constexpr std::array<std::uint8_t, 16> kDaemon6 = {0xfe, 0x80, 0, 0, 0, 0, 0, 0,
                                                   0,    0,    0, 0, 0, 0, 0, 2};

Bytes Payload(const std::string& text) { return Bytes(text.begin(), text.end()); }

// Eight Ethernet frames: UDP to ports 2222 and 3333 over IPv4 and IPv6, an empty datagram, and
// four that are no datagram (a UDP length beyond the packet, a fragment, TCP, ARP).
test_util::PcapFile EthernetCapture() {
  using test_util::Ethernet;
  using test_util::Ipv4Udp;
  using test_util::Ipv6Udp;
  Bytes bad_length = Ipv4Udp(kSensorA, 40000, kDaemon4, 2222, Payload("cut"));
  common::StoreBe16(&bad_length[24], 200);
  Bytes fragment = Ipv4Udp(kSensorA, 40000, kDaemon4, 2222, Payload("first half"));
  fragment[6] = 0x20;  // more fragments
  Bytes tcp = Ipv4Udp(kSensorA, 40000, kDaemon4, 2222, Bytes(12, 0));
  tcp[9] = 6;
  tcp[32] = 0x50;  // data offset: 20 bytes
  Bytes arp = Ethernet(Bytes(28, 0));
  arp[12] = 0x08;
  arp[13] = 0x06;

  test_util::PcapFile pcap(capture::kLinkTypeEthernet);
  pcap.Add(kSourceT0 + 1'000'000, Ethernet(Ipv4Udp(kSensorA, 40000, kDaemon4, 2222, Payload("A"))))
      .Add(kSourceT0 + 2'000'000, Ethernet(Ipv4Udp(kSensorB, 40001, kDaemon4, 3333, Payload("BB"))))
      .Add(kSourceT0 + 3'000'000, Ethernet(Ipv6Udp(kSensorC, 40002, kDaemon6, 2222, Payload("CCC"))))
      .Add(kSourceT0 + 4'000'000, Ethernet(bad_length))
      .Add(kSourceT0 + 5'000'000, Ethernet(fragment))
      .Add(kSourceT0 + 6'000'000, Ethernet(tcp))
      .Add(kSourceT0 + 7'000'000, arp)
      .Add(kSourceT0 + 8'000'000, Ethernet(Ipv4Udp(kSensorA, 40000, kDaemon4, 2222, {})));
  return pcap;
}

TEST_F(DatagramSourceTest, UdpCaptureGivesEveryDatagramWithSenderAndTime) {
  const std::string path = TempPath("udp.pcap");
  WriteBytes(path, EthernetCapture().bytes());
  std::string error;
  auto source = Open(path, &error);
  ASSERT_NE(source, nullptr) << error;
  EXPECT_EQ(source->kind(), DatagramFileKind::kCapture);
  EXPECT_EQ(source->format_version(), 0u);
  EXPECT_TRUE(source->writer().empty());
  const ReadResult r = ReadToEnd(*source);
  EXPECT_EQ(r.end, SourceStatus::kEnd) << r.error;
  ASSERT_EQ(r.datagrams.size(), 4u);
  EXPECT_EQ(r.datagrams[0].source, "192.168.1.10:40000");
  EXPECT_EQ(r.datagrams[0].bytes, Payload("A"));
  EXPECT_EQ(r.datagrams[0].receive_ns, kSourceT0 + 1'000'000);
  EXPECT_EQ(r.datagrams[1].source, "192.168.1.11:40001");
  EXPECT_EQ(r.datagrams[1].bytes, Payload("BB"));
  EXPECT_EQ(r.datagrams[2].source, "[fe80::1]:40002");
  EXPECT_EQ(r.datagrams[2].bytes, Payload("CCC"));
  EXPECT_EQ(r.datagrams[2].receive_ns, kSourceT0 + 3'000'000);
  EXPECT_TRUE(r.datagrams[3].bytes.empty());
  EXPECT_EQ(r.datagrams[3].receive_ns, kSourceT0 + 8'000'000);
  const DatagramSourceCounters& c = source->counters();
  EXPECT_EQ(c.packets, 8u);
  EXPECT_EQ(c.datagrams, 4u);
  EXPECT_EQ(c.malformed_packets, 2u);  // bad UDP length, fragment
  EXPECT_EQ(c.other_packets, 2u);      // TCP, ARP
  EXPECT_EQ(c.files, 0u);
}

TEST_F(DatagramSourceTest, UdpCapturePortFilter) {
  const std::string path = TempPath("udp_port.pcap");
  WriteBytes(path, EthernetCapture().bytes());
  std::string error;
  auto source = Open(path, &error, 3333);
  ASSERT_NE(source, nullptr) << error;
  ReadResult r = ReadToEnd(*source);
  ASSERT_EQ(r.datagrams.size(), 1u);
  EXPECT_EQ(r.datagrams[0].bytes, Payload("BB"));
  EXPECT_EQ(source->counters().other_packets, 5u);

  source = Open(path, &error, 2222);
  ASSERT_NE(source, nullptr) << error;
  r = ReadToEnd(*source);
  ASSERT_EQ(r.datagrams.size(), 3u);
  EXPECT_EQ(r.datagrams[0].bytes, Payload("A"));
  EXPECT_EQ(r.datagrams[1].bytes, Payload("CCC"));
  EXPECT_TRUE(r.datagrams[2].bytes.empty());
  EXPECT_EQ(source->counters().other_packets, 3u);
}

TEST_F(DatagramSourceTest, RawIpNanosecondCaptureKeepsNanoseconds) {
  const std::string path = TempPath("raw_ns.pcap");
  test_util::PcapFile pcap(capture::kLinkTypeRaw, /*nanosecond=*/true);
  pcap.Add(kSourceT0 + 123'456'789, test_util::Ipv4Udp(kSensorA, 1, kDaemon4, 2222, Payload("v4")))
      .Add(kSourceT0 + 223'456'789, test_util::Ipv6Udp(kSensorC, 65535, kDaemon6, 2222, Payload("v6")));
  WriteBytes(path, pcap.bytes());
  std::string error;
  auto source = Open(path, &error);
  ASSERT_NE(source, nullptr) << error;
  const ReadResult r = ReadToEnd(*source);
  EXPECT_EQ(r.end, SourceStatus::kEnd) << r.error;
  ASSERT_EQ(r.datagrams.size(), 2u);
  EXPECT_EQ(r.datagrams[0].receive_ns, kSourceT0 + 123'456'789);
  EXPECT_EQ(r.datagrams[0].source, "192.168.1.10:1");
  EXPECT_EQ(r.datagrams[1].receive_ns, kSourceT0 + 223'456'789);
  EXPECT_EQ(r.datagrams[1].source, "[fe80::1]:65535");
}

TEST_F(DatagramSourceTest, PcapngCaptureIsDetectedByContent) {
  const std::string path = TempPath("udp_capture.rec");  // the name does not matter
  test_util::PcapngFile pcapng(capture::kLinkTypeEthernet);
  pcapng.Add(kSourceT0 + 5,
             test_util::Ethernet(test_util::Ipv4Udp(kSensorB, 9, kDaemon4, 2222, Payload("ng"))));
  WriteBytes(path, pcapng.bytes());
  std::string error;
  auto source = Open(path, &error);
  ASSERT_NE(source, nullptr) << error;
  EXPECT_EQ(source->kind(), DatagramFileKind::kCapture);
  const ReadResult r = ReadToEnd(*source);
  EXPECT_EQ(r.end, SourceStatus::kEnd) << r.error;
  ASSERT_EQ(r.datagrams.size(), 1u);
  EXPECT_EQ(r.datagrams[0].receive_ns, kSourceT0 + 5);
  EXPECT_EQ(r.datagrams[0].source, "192.168.1.11:9");
  EXPECT_EQ(r.datagrams[0].bytes, Payload("ng"));
}

TEST_F(DatagramSourceTest, TornCaptureEndsWithAnErrorAfterItsWholePackets) {
  const std::string path = TempPath("torn.pcap");
  const Bytes whole = EthernetCapture().bytes();
  WriteBytes(path, Bytes(whole.begin(), whole.end() - 10));  // into the last packet
  std::string error;
  auto source = Open(path, &error);
  ASSERT_NE(source, nullptr) << error;
  const ReadResult r = ReadToEnd(*source);
  EXPECT_EQ(r.end, SourceStatus::kError);
  EXPECT_EQ(r.datagrams.size(), 3u);
  EXPECT_TRUE(Contains(r.error, "capture '" + path + "'")) << r.error;
  EXPECT_TRUE(Contains(r.error, "after packet 7")) << r.error;
}

TEST_F(DatagramSourceTest, CaptureOfAnUnknownLinkTypeIsRefused) {
  const std::string path = TempPath("user0.pcap");
  test_util::PcapFile pcap(147);  // LINKTYPE_USER0
  pcap.Add(kSourceT0, Payload("whatever"));
  WriteBytes(path, pcap.bytes());
  std::string error;
  EXPECT_EQ(Open(path, &error), nullptr);
  EXPECT_TRUE(Contains(error, "link type 147")) << error;
  EXPECT_TRUE(Contains(error, path)) << error;
}

// A recording of datagrams received at kSourceT0 + the given milliseconds from `sender`.
void WriteRecording(const std::string& path, const std::vector<int>& ms,
                    const std::string& sender) {
  RecordingWriterOptions options;
  options.path = path;
  RecordingWriter writer(options);
  ASSERT_EQ(writer.Open(kSourceT0), std::nullopt);
  for (const int t : ms) {
    writer.Append(MakeDatagram(10, static_cast<std::uint32_t>(t)), sender, kSourceT0 + t * kSourceMs);
  }
  ASSERT_EQ(writer.Close(), std::nullopt);
}

TEST_F(DatagramSourceTest, MergedFilesGiveEveryDatagramInReceiveOrder) {
  // Two sensors' recordings of one session: read as the daemon received them, not file by file.
  WriteRecording(TempPath("merge_a.rec"), {0, 2, 4, 6}, "tracker:a");
  WriteRecording(TempPath("merge_b.rec"), {1, 2, 3, 10}, "tracker:b");
  std::string error;
  std::vector<std::unique_ptr<DatagramSource>> sources;
  sources.push_back(Open(TempPath("merge_a.rec"), &error));
  sources.push_back(Open(TempPath("merge_b.rec"), &error));
  ASSERT_TRUE(sources[0] && sources[1]) << error;
  MergedDatagramSource merged(std::move(sources));
  ReceivedDatagram d;
  std::size_t index = 9;
  std::vector<std::pair<int, std::size_t>> got;
  SourceStatus status;
  while ((status = merged.Next(&d, &index)) == SourceStatus::kDatagram) {
    got.emplace_back(static_cast<int>((d.receive_ns - kSourceT0) / kSourceMs), index);
    EXPECT_EQ(d.source, index == 0 ? "tracker:a" : "tracker:b");
    EXPECT_EQ(d.bytes, MakeDatagram(10, static_cast<std::uint32_t>(got.back().first)));
  }
  EXPECT_EQ(status, SourceStatus::kEnd);
  EXPECT_EQ(merged.Next(&d, &index), SourceStatus::kEnd);
  const std::vector<std::pair<int, std::size_t>> want = {{0, 0}, {1, 1}, {2, 0}, {2, 1},
                                                         {3, 1}, {4, 0}, {6, 0}, {10, 1}};
  EXPECT_EQ(got, want);
  EXPECT_EQ(merged.source(0).counters().datagrams, 4u);
  EXPECT_EQ(merged.source(1).counters().datagrams, 4u);
}

TEST_F(DatagramSourceTest, MergedFilesReportATornOneOnceAndGoOnWithTheOthers) {
  WriteRecording(TempPath("merge_ok.rec"), {0, 5, 9}, "tracker:a");
  WriteRecording(TempPath("merge_torn.rec"), {1, 3, 7}, "tracker:b");
  Bytes torn = ReadBytes(TempPath("merge_torn.rec"));
  torn.resize(torn.size() - 3);  // the last entry is cut
  WriteBytes(TempPath("merge_torn.rec"), torn);
  std::string error;
  std::vector<std::unique_ptr<DatagramSource>> sources;
  sources.push_back(Open(TempPath("merge_ok.rec"), &error));
  sources.push_back(Open(TempPath("merge_torn.rec"), &error));
  ASSERT_TRUE(sources[0] && sources[1]) << error;
  MergedDatagramSource merged(std::move(sources));
  ReceivedDatagram d;
  std::size_t index = 9;
  std::vector<int> got;
  int errors = 0;
  for (SourceStatus status; (status = merged.Next(&d, &index)) != SourceStatus::kEnd;) {
    if (status == SourceStatus::kError) {
      ++errors;
      EXPECT_EQ(index, 1u);
      EXPECT_TRUE(Contains(merged.source(1).error(), "merge_torn.rec")) << merged.source(1).error();
      continue;
    }
    got.push_back(static_cast<int>((d.receive_ns - kSourceT0) / kSourceMs));
  }
  EXPECT_EQ(errors, 1);
  EXPECT_EQ(got, (std::vector<int>{0, 1, 3, 5, 9}));
}

TEST(FormatUdpSourceTest, Ipv4Ipv6AndMapped) {
  capture::IpAddress v4;
  v4.family = capture::IpFamily::kIpv4;
  v4.bytes = {10, 1, 2, 3};
  EXPECT_EQ(FormatUdpSource(v4, 5000), "10.1.2.3:5000");
  capture::IpAddress v6;
  v6.family = capture::IpFamily::kIpv6;
  v6.bytes = {0x20, 0x01, 0x0d, 0xb8, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x01};
  EXPECT_EQ(FormatUdpSource(v6, 1), "[2001:db8::1]:1");
  capture::IpAddress mapped;
  mapped.family = capture::IpFamily::kIpv6;
  mapped.bytes = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0xff, 0xff, 127, 0, 0, 1};
  EXPECT_EQ(FormatUdpSource(mapped, 2222), "127.0.0.1:2222");
}

}  // namespace
}  // namespace lrfnet::daemon
