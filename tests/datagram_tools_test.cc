// `lrfnet dump` and `lrfnet replay` on datagram files as a user runs them: recordings (written here
// as the DESIGN.md format: varint-delimited RecordEntry, header first; rotation parts REC.1) and
// pcap captures of the UDP stream; replay into a test-owned UDP socket on loopback (IPv4, IPv6);
// timing, signals, exit codes and one-line errors. The scan path of dump (golden files) must not
// change: every shared capture still gives the library's scan lines.

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "central_daemon/io/udp_capture_test_util.h"
#include "common/byte_order.h"
#include "common/capture/packet_parser.h"
#include "lrfnet.pb.h"
#include "tests/process_harness.h"
#include "tests/support/test_data.h"
#include "tests/support/udp_peer.h"
#include "tools/dump.h"

namespace lrfnet {
namespace {

using nlohmann::json;
using std::chrono::milliseconds;
using std::chrono::seconds;
using testing::CountLines;
using testing::Process;

const char* const kTool = LRFNET_TOOL_BINARY;
constexpr common::UtcNs kT0 = 1'700'000'000'000'000'000;

using Bytes = std::vector<std::uint8_t>;

struct Entry {
  common::UtcNs receive_ns = 0;
  std::string source;
  Bytes datagram;
};

void AppendDelimited(const google::protobuf::MessageLite& message, std::string* out) {
  std::string body = message.SerializeAsString();
  for (std::uint64_t n = body.size();; n >>= 7) {
    if (n < 0x80) {
      out->push_back(static_cast<char>(n));
      break;
    }
    out->push_back(static_cast<char>((n & 0x7f) | 0x80));
  }
  *out += body;
}

// A recording file as DESIGN.md "Recording" describes it.
void WriteRecording(const std::string& path, const std::vector<Entry>& entries) {
  std::string bytes;
  proto::RecordEntry header;
  header.mutable_header()->set_format_version(1);
  header.mutable_header()->set_created_ns(kT0);
  header.mutable_header()->set_writer("datagram_tools_test");
  AppendDelimited(header, &bytes);
  for (const Entry& e : entries) {
    proto::RecordEntry entry;
    entry.set_receive_ns(e.receive_ns);
    entry.set_source(e.source);
    entry.set_datagram(e.datagram.data(), e.datagram.size());
    AppendDelimited(entry, &bytes);
  }
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

void WriteFile(const std::string& path, const Bytes& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
}

Bytes Serialize(const proto::Datagram& d) {
  const std::string s = d.SerializeAsString();
  return {s.begin(), s.end()};
}

proto::Datagram Header(const std::string& sensor_id, std::uint64_t sequence,
                       common::UtcNs sent_ns) {
  proto::Datagram d;
  d.set_version(proto::PROTOCOL_VERSION_1);
  d.set_sensor_id(sensor_id);
  d.set_sequence(sequence);
  d.set_sent_ns(sent_ns);
  d.set_session_id(77);
  return d;
}

Bytes TrackFrame(const std::string& sensor_id, std::uint64_t sequence, common::UtcNs sent_ns) {
  proto::Datagram d = Header(sensor_id, sequence, sent_ns);
  proto::TrackFrame* f = d.mutable_track_frame();
  f->set_scan_start_ns(sent_ns - 30'000'000);
  f->set_scan_period_s(0.04);
  f->set_scan_counter(static_cast<std::uint32_t>(sequence));
  f->set_part_count(1);
  for (std::uint32_t id : {3u, 4u}) {
    proto::Track* t = f->add_tracks();
    t->set_track_id(id);
    t->set_state(id == 3 ? proto::TRACK_STATE_CONFIRMED : proto::TRACK_STATE_TENTATIVE);
    t->set_kind(proto::MEASUREMENT_KIND_CENTER_OF_MASS);
    t->set_x_m(1.5f * static_cast<float>(id));
    for (int i = 0; i < 10; ++i) t->add_covariance(0.01f);
  }
  return Serialize(d);
}

Bytes Health(const std::string& sensor_id, std::uint64_t sequence, common::UtcNs sent_ns) {
  proto::Datagram d = Header(sensor_id, sequence, sent_ns);
  d.mutable_health()->set_scans(1000 + sequence);
  d.mutable_health()->set_clock_sync(proto::CLOCK_SYNC_SYNCHRONIZED);
  return Serialize(d);
}

// Two sensors over ~2 s, a not-a-datagram in the middle.
std::vector<Entry> SmallSession() {
  return {
      {kT0, "10.0.0.5:40000", TrackFrame("s1", 0, kT0 - 1000)},
      {kT0 + 500'000'000, "10.0.0.6:40000", TrackFrame("s2", 0, kT0 + 499'000'000)},
      {kT0 + 1'000'000'000, "10.0.0.5:40000", Health("s1", 1, kT0 + 999'000'000)},
      {kT0 + 1'500'000'000, "10.0.0.9:1234", Bytes{0x0f, 0xff, 0x00}},
      {kT0 + 2'000'000'000, "10.0.0.5:40000", TrackFrame("s1", 2, kT0 + 1'999'000'000)},
  };
}

class DatagramToolsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::path(::testing::TempDir()) /
           ("lrfnet_datagram_tools_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  std::filesystem::path dir_;
};

std::vector<json> JsonLines(const std::string& text) {
  std::vector<json> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    EXPECT_TRUE(json::accept(line)) << line;
    if (json::accept(line)) lines.push_back(json::parse(line));
  }
  return lines;
}

// "key=value" of the replay's summary line.
std::map<std::string, std::string> SummaryFields(const std::string& out) {
  std::map<std::string, std::string> fields;
  const auto at = out.rfind("summary: ");
  if (at == std::string::npos) return fields;
  std::istringstream in(out.substr(at + 9, out.find('\n', at) - at - 9));
  for (std::string word; in >> word;) {
    const auto eq = word.find('=');
    if (eq != std::string::npos) fields[word.substr(0, eq)] = word.substr(eq + 1);
  }
  return fields;
}

TEST_F(DatagramToolsTest, DumpPrintsOneLinePerDatagramOfARecording) {
  const std::string rec = Path("session.rec");
  const std::vector<Entry> entries = SmallSession();
  WriteRecording(rec, entries);
  Process dump(kTool, {"dump", rec});
  ASSERT_EQ(dump.Wait(), 0) << dump.err();
  const std::vector<json> lines = JsonLines(dump.out());
  ASSERT_EQ(lines.size(), entries.size()) << dump.out();
  for (std::size_t i = 0; i < lines.size(); ++i) {
    EXPECT_EQ(lines[i]["receive_ns"], entries[i].receive_ns) << i;
    EXPECT_EQ(lines[i]["source"], entries[i].source) << i;
    EXPECT_EQ(lines[i]["size"], entries[i].datagram.size()) << i;
  }
  EXPECT_EQ(lines[0]["sensor_id"], "s1");
  EXPECT_EQ(lines[0]["sequence"], 0);
  EXPECT_EQ(lines[0]["sent_ns"], kT0 - 1000);
  EXPECT_EQ(lines[0]["version"], "PROTOCOL_VERSION_1");
  EXPECT_EQ(lines[0]["kind"], "track_frame");
  ASSERT_EQ(lines[0]["track_frame"]["tracks"].size(), 2u);
  EXPECT_EQ(lines[0]["track_frame"]["tracks"][0]["track_id"], 3);
  EXPECT_EQ(lines[0]["track_frame"]["tracks"][0]["state"], "TRACK_STATE_CONFIRMED");
  EXPECT_EQ(lines[0]["track_frame"]["tracks"][1]["track_id"], 4);
  EXPECT_EQ(lines[0]["track_frame"]["tracks"][1]["state"], "TRACK_STATE_TENTATIVE");
  EXPECT_EQ(lines[1]["sensor_id"], "s2");
  EXPECT_EQ(lines[2]["kind"], "health");
  EXPECT_EQ(lines[2]["health"]["clock_sync"], "CLOCK_SYNC_SYNCHRONIZED");
  EXPECT_EQ(lines[3]["error"], "not a lrfnet datagram");
  EXPECT_FALSE(lines[3].contains("sensor_id"));
  EXPECT_EQ(lines[4]["sequence"], 2);

  Process summary(kTool, {"dump", "--summary", rec});
  ASSERT_EQ(summary.Wait(), 0) << summary.err();
  ASSERT_EQ(CountLines(summary.out()), 1u) << summary.out();
  const json s = json::parse(summary.out());
  EXPECT_EQ(s["datagrams"], 5);
  EXPECT_EQ(s["parse_errors"], 1);
  EXPECT_EQ(s["first_receive_ns"], kT0);
  EXPECT_EQ(s["last_receive_ns"], kT0 + 2'000'000'000);
  EXPECT_EQ(s["sensors"],
            (json{{"s1", {{"health", 1}, {"track_frame", 2}}}, {"s2", {{"track_frame", 1}}}}));
  EXPECT_EQ(s["file"]["kind"], "recording");
  EXPECT_EQ(s["file"]["writer"], "datagram_tools_test");
}

TEST_F(DatagramToolsTest, DumpReadsTheRotationPartsOfARecordingAsOne) {
  const std::string rec = Path("rotated.rec");
  std::vector<Entry> entries = SmallSession();
  WriteRecording(rec, {entries.begin(), entries.begin() + 2});
  WriteRecording(rec + ".1", {entries.begin() + 2, entries.end()});
  Process dump(kTool, {"dump", rec});
  ASSERT_EQ(dump.Wait(), 0) << dump.err();
  const std::vector<json> lines = JsonLines(dump.out());
  ASSERT_EQ(lines.size(), entries.size()) << dump.out();
  for (std::size_t i = 0; i < lines.size(); ++i)
    EXPECT_EQ(lines[i]["receive_ns"], entries[i].receive_ns) << i;
}

TEST_F(DatagramToolsTest, DumpOfATornRecordingPrintsWhatWasReadableAndExits1) {
  const std::string rec = Path("torn.rec");
  WriteRecording(rec, SmallSession());
  std::filesystem::resize_file(rec, std::filesystem::file_size(rec) - 5);
  Process dump(kTool, {"dump", rec});
  EXPECT_EQ(dump.Wait(), 1);
  EXPECT_EQ(JsonLines(dump.out()).size(), SmallSession().size() - 1);
  EXPECT_EQ(CountLines(dump.err()), 1u) << dump.err();
}

Bytes Udp(std::uint8_t src_host, std::uint16_t src_port, std::uint16_t dst_port,
          const Bytes& payload) {
  return daemon::test_util::Ethernet(
      daemon::test_util::Ipv4Udp({10, 0, 0, src_host}, src_port, {10, 0, 0, 1}, dst_port, payload));
}

// A TCP segment (no options) from the scanner's port: enough for dump to see a scanner stream.
Bytes ScannerTcp(std::uint16_t scanner_port) {
  Bytes ip = daemon::test_util::Ipv4Udp({10, 0, 0, 2}, scanner_port, {10, 0, 0, 1}, 50000, Bytes{});
  ip[9] = 6;  // TCP
  ip.resize(40, 0);
  common::StoreBe16(&ip[2], 40);
  ip[32] = 0x50;  // data offset 5 words
  ip[33] = capture::kTcpAck;
  return daemon::test_util::Ethernet(ip);
}

TEST_F(DatagramToolsTest, DumpOfAUdpCapturePrintsItsDatagrams) {
  const std::string pcap = Path("udp.pcap");
  daemon::test_util::PcapFile file(capture::kLinkTypeEthernet, /*nanosecond=*/true);
  file.Add(kT0 + 10, Udp(5, 40000, 5800, TrackFrame("s1", 0, kT0)));
  file.Add(kT0 + 20, Udp(6, 40001, 5800, Health("s2", 0, kT0)));
  file.Add(kT0 + 30, Udp(6, 40001, 9999, Health("s2", 1, kT0)));
  WriteFile(pcap, file.bytes());

  Process all(kTool, {"dump", pcap});
  ASSERT_EQ(all.Wait(), 0) << all.err();
  const std::vector<json> lines = JsonLines(all.out());
  ASSERT_EQ(lines.size(), 3u) << all.out();
  EXPECT_EQ(lines[0]["source"], "10.0.0.5:40000");
  EXPECT_EQ(lines[0]["receive_ns"], kT0 + 10);
  EXPECT_EQ(lines[0]["kind"], "track_frame");
  EXPECT_EQ(lines[1]["source"], "10.0.0.6:40001");
  EXPECT_EQ(lines[1]["sensor_id"], "s2");

  Process one_port(kTool, {"dump", "--udp-port", "5800", pcap});
  ASSERT_EQ(one_port.Wait(), 0) << one_port.err();
  EXPECT_EQ(CountLines(one_port.out()), 2u) << one_port.out();

  Process summary(kTool, {"dump", "--summary", pcap});
  ASSERT_EQ(summary.Wait(), 0) << summary.err();
  const json s = json::parse(summary.out());
  EXPECT_EQ(s["datagrams"], 3);
  EXPECT_EQ(s["file"]["kind"], "capture");
  EXPECT_EQ(s["file"]["packets"], 3);
}

TEST_F(DatagramToolsTest, ACaptureWithTheScannerStreamStaysOnTheScanPathUnlessAsked) {
  const std::string pcap = Path("mixed.pcap");
  daemon::test_util::PcapFile file(capture::kLinkTypeEthernet, /*nanosecond=*/true);
  file.Add(kT0 + 10, Udp(5, 40000, 5800, TrackFrame("s1", 0, kT0)));
  file.Add(kT0 + 20, ScannerTcp(2112));
  file.Add(kT0 + 30, Udp(5, 40000, 5800, Health("s1", 1, kT0)));
  WriteFile(pcap, file.bytes());

  Process scans(kTool, {"dump", "--summary", pcap});
  ASSERT_EQ(scans.Wait(), 0) << scans.err();
  EXPECT_NE(scans.out().find("\"frames\": 0"), std::string::npos) << scans.out();
  EXPECT_EQ(scans.out().find("\"datagrams\""), std::string::npos) << scans.out();

  Process datagrams(kTool, {"dump", "--summary", "--datagrams", pcap});
  ASSERT_EQ(datagrams.Wait(), 0) << datagrams.err();
  EXPECT_EQ(json::parse(datagrams.out())["datagrams"], 2);

  // Another scanner port: the TCP segment is not the scanner's, so the UDP datagrams are printed.
  Process other_port(kTool, {"dump", "--port", "2111", pcap});
  ASSERT_EQ(other_port.Wait(), 0) << other_port.err();
  EXPECT_EQ(JsonLines(other_port.out()).size(), 2u) << other_port.out();
}

TEST_F(DatagramToolsTest, SharedScannerCapturesStillGiveTheScanLines) {
  for (const std::string& name : testing::SickCaptureNames()) {
    SCOPED_TRACE(name);
    const auto capture = testing::SharedFile("data/sick/" + name);
    if (!capture) GTEST_SKIP() << "shared test data absent: data/sick/" << name;
    std::ostringstream expected;
    std::string error;
    ASSERT_TRUE(tools::DumpCapture(*capture, {}, &expected, nullptr, &error)) << error;
    Process dump(kTool, {"dump", *capture});
    ASSERT_EQ(dump.Wait(), 0) << dump.err();
    EXPECT_EQ(dump.out(), expected.str());
    EXPECT_GT(CountLines(dump.out()), 0u);
  }
}

TEST_F(DatagramToolsTest, ReplayAsFastAsPossibleSendsExactlyTheRecordedBytesInOrder) {
  const std::string rec = Path("session.rec");
  const std::vector<Entry> entries = SmallSession();
  WriteRecording(rec, entries);
  testing::LoopbackUdpPeer peer;
  ASSERT_TRUE(peer.ok());
  Process replay(kTool, {"replay", rec, "--to", "127.0.0.1:" + std::to_string(peer.port()),
                         "--speed", "0", "--log-level", "warn"});
  ASSERT_EQ(replay.Wait(), 0) << replay.err();
  for (std::size_t i = 0; i < entries.size(); ++i)
    EXPECT_EQ(peer.Receive(2000), entries[i].datagram) << "datagram " << i;
  EXPECT_TRUE(peer.Receive(0).empty()) << "more datagrams than recorded";
  const auto summary = SummaryFields(replay.out());
  EXPECT_EQ(summary.at("datagrams"), std::to_string(entries.size())) << replay.out();
  std::size_t bytes = 0;
  for (const Entry& e : entries) bytes += e.datagram.size();
  EXPECT_EQ(summary.at("bytes"), std::to_string(bytes));
  EXPECT_EQ(summary.at("send_errors"), "0");
  EXPECT_EQ(summary.at("senders"), "3");  // three distinct recorded sources
  EXPECT_EQ(summary.at("interrupted"), "no");
}

// recvfrom with the sender's port, for the distinct-senders check.
std::vector<std::pair<Bytes, std::uint16_t>> ReceiveWithPorts(int fd, std::size_t count) {
  std::vector<std::pair<Bytes, std::uint16_t>> out;
  while (out.size() < count) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 2000) != 1) break;
    Bytes buffer(2048);
    sockaddr_in from{};
    socklen_t from_len = sizeof from;
    const ssize_t n = ::recvfrom(fd, buffer.data(), buffer.size(), 0,
                                 reinterpret_cast<sockaddr*>(&from), &from_len);
    if (n < 0) break;
    buffer.resize(static_cast<std::size_t>(n));
    out.emplace_back(std::move(buffer), ntohs(from.sin_port));
  }
  return out;
}

TEST_F(DatagramToolsTest, ReplayGivesEveryRecordedSourceASenderOfItsOwn) {
  const std::string rec = Path("session.rec");
  const std::vector<Entry> entries = SmallSession();
  WriteRecording(rec, entries);
  const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  ASSERT_GE(fd, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
  socklen_t len = sizeof addr;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  Process replay(kTool, {"replay", rec, "--to", "127.0.0.1:" + std::to_string(ntohs(addr.sin_port)),
                         "--speed", "0"});
  ASSERT_EQ(replay.Wait(), 0) << replay.err();
  const auto received = ReceiveWithPorts(fd, entries.size());
  ::close(fd);
  ASSERT_EQ(received.size(), entries.size());
  std::map<std::string, std::set<std::uint16_t>> ports_by_source;
  std::set<std::uint16_t> ports;
  for (std::size_t i = 0; i < entries.size(); ++i) {
    ports_by_source[entries[i].source].insert(received[i].second);
    ports.insert(received[i].second);
  }
  for (const auto& [source, source_ports] : ports_by_source)
    EXPECT_EQ(source_ports.size(), 1u) << source << " came from several ports";
  EXPECT_EQ(ports.size(), ports_by_source.size()) << "sources share a sender";
}

TEST_F(DatagramToolsTest, ReplayResolvesHostNames) {
  const std::string rec = Path("session.rec");
  WriteRecording(rec, SmallSession());
  // "localhost" may resolve to 127.0.0.1 or ::1 first: listen on both with the same port.
  testing::LoopbackUdpPeer peer4;
  ASSERT_TRUE(peer4.ok());
  int fd6 = ::socket(AF_INET6, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd6 >= 0) {
    sockaddr_in6 addr{};
    addr.sin6_family = AF_INET6;
    addr.sin6_addr = in6addr_loopback;
    addr.sin6_port = htons(peer4.port());
    if (::bind(fd6, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
      ::close(fd6);
      fd6 = -1;
    }
  }
  Process replay(kTool, {"replay", rec, "--to", "localhost:" + std::to_string(peer4.port()),
                         "--speed", "0", "--log-level", "warn"});
  ASSERT_EQ(replay.Wait(), 0) << replay.err();
  std::size_t received = peer4.Drain();
  if (fd6 >= 0) {
    Bytes buffer(2048);
    while (::recv(fd6, buffer.data(), buffer.size(), MSG_DONTWAIT) > 0) ++received;
    ::close(fd6);
  }
  EXPECT_EQ(received, SmallSession().size());
}

TEST_F(DatagramToolsTest, ReplayKeepsTheRecordedTimingScaledBySpeed) {
  const std::string rec = Path("session.rec");
  WriteRecording(rec, SmallSession());  // spans 2 s
  testing::LoopbackUdpPeer peer;
  ASSERT_TRUE(peer.ok());
  const auto start = std::chrono::steady_clock::now();
  Process replay(kTool, {"replay", rec, "--to", "127.0.0.1:" + std::to_string(peer.port()),
                         "--speed", "10", "--log-level", "warn"});
  ASSERT_EQ(replay.Wait(), 0) << replay.err();
  const double wall_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_GT(wall_s, 0.1);
  EXPECT_LT(wall_s, 2.0);
  const double elapsed_s = std::stod(SummaryFields(replay.out()).at("elapsed_s"));
  EXPECT_GT(elapsed_s, 0.1);
  EXPECT_LT(elapsed_s, 2.0);
  EXPECT_EQ(peer.Drain(), SmallSession().size());
}

TEST_F(DatagramToolsTest, ReplayClampsStepsBackAndLongGaps) {
  const std::string rec = Path("odd_times.rec");
  // A clock step back of an hour, then a gap of ten minutes: with --max-gap-s 0.1 the replay takes
  // ~0.15 s, not an hour or ten minutes.
  WriteRecording(rec, {{kT0, "10.0.0.5:1", Health("s", 0, kT0)},
                       {kT0 + 50'000'000, "10.0.0.5:1", Health("s", 1, kT0)},
                       {kT0 - 3'600'000'000'000, "10.0.0.5:1", Health("s", 2, kT0)},
                       {kT0 - 3'000'000'000'000, "10.0.0.5:1", Health("s", 3, kT0)}});
  testing::LoopbackUdpPeer peer;
  ASSERT_TRUE(peer.ok());
  Process replay(kTool, {"replay", rec, "--to", "127.0.0.1:" + std::to_string(peer.port()),
                         "--max-gap-s", "0.1", "--log-level", "warn"});
  ASSERT_EQ(replay.Wait(seconds(10)), 0) << replay.err();
  const auto summary = SummaryFields(replay.out());
  EXPECT_EQ(summary.at("datagrams"), "4") << replay.out();
  EXPECT_EQ(summary.at("steps_back"), "1");
  EXPECT_EQ(summary.at("shortened_gaps"), "1");
  EXPECT_LT(std::stod(summary.at("elapsed_s")), 2.0);
  EXPECT_EQ(peer.Drain(), 4u);
}

TEST_F(DatagramToolsTest, ReplayToAnIpv6Target) {
  testing::LoopbackUdpPeer peer(AF_INET6);
  if (!peer.ok()) GTEST_SKIP() << "no IPv6 loopback here";
  const std::string rec = Path("session.rec");
  const std::vector<Entry> entries = SmallSession();
  WriteRecording(rec, entries);
  Process replay(kTool, {"replay", rec, "--to", "[::1]:" + std::to_string(peer.port()), "--speed",
                         "0", "--log-level", "warn"});
  ASSERT_EQ(replay.Wait(), 0) << replay.err();
  for (std::size_t i = 0; i < entries.size(); ++i)
    EXPECT_EQ(peer.Receive(2000), entries[i].datagram) << "datagram " << i;
}

TEST_F(DatagramToolsTest, ReplayOfAUdpCaptureSendsItsPayloads) {
  const std::string pcap = Path("udp.pcap");
  const Bytes a = TrackFrame("s1", 0, kT0), b = Health("s2", 0, kT0);
  daemon::test_util::PcapFile file(capture::kLinkTypeEthernet, /*nanosecond=*/true);
  file.Add(kT0, Udp(5, 40000, 5800, a));
  file.Add(kT0 + 1000, Udp(6, 40000, 5801, b));
  WriteFile(pcap, file.bytes());
  testing::LoopbackUdpPeer peer;
  ASSERT_TRUE(peer.ok());
  Process replay(kTool, {"replay", pcap, "--to", "127.0.0.1:" + std::to_string(peer.port()),
                         "--udp-port", "5801", "--log-level", "warn"});
  ASSERT_EQ(replay.Wait(), 0) << replay.err();
  EXPECT_EQ(peer.Receive(2000), b);
  EXPECT_TRUE(peer.Receive(0).empty());
}

TEST_F(DatagramToolsTest, ReplayCountsRepliesAndStopsOnSigintWithItsSummary) {
  const std::string rec = Path("long.rec");
  std::vector<Entry> entries;
  for (int i = 0; i < 6; ++i)  // one every 10 s for a minute
    entries.push_back({kT0 + i * 10 * common::kNsPerS, "10.0.0.5:1", Health("s", i, kT0)});
  WriteRecording(rec, entries);
  testing::LoopbackUdpPeer peer;
  ASSERT_TRUE(peer.ok());
  Process replay(kTool, {"replay", rec, "--to", "127.0.0.1:" + std::to_string(peer.port()),
                         "--log-level", "warn"});
  ASSERT_EQ(peer.Receive(5000), entries[0].datagram);
  proto::Datagram request = Header("lrfnetd", 0, kT0);
  request.mutable_request()->set_send_sensor_info(true);
  ASSERT_TRUE(peer.Reply(Serialize(request)));
  std::this_thread::sleep_for(milliseconds(200));  // the reply is read while the replay waits
  replay.Signal(SIGINT);
  ASSERT_EQ(replay.Wait(seconds(5)), 0) << replay.err();
  const auto summary = SummaryFields(replay.out());
  EXPECT_EQ(summary.at("interrupted"), "yes") << replay.out();
  EXPECT_EQ(summary.at("datagrams"), "1");
  EXPECT_EQ(summary.at("replies"), "1");
}

TEST_F(DatagramToolsTest, AGapBeyondTheClockRangeWaitsInsteadOfWrappingAround) {
  const std::string rec = Path("extreme.rec");
  WriteRecording(rec, {{std::numeric_limits<common::UtcNs>::min(), "a:1", Health("s", 0, 0)},
                       {std::numeric_limits<common::UtcNs>::max(), "a:1", Health("s", 1, 0)}});
  testing::LoopbackUdpPeer peer;
  ASSERT_TRUE(peer.ok());
  Process replay(kTool, {"replay", rec, "--to", "127.0.0.1:" + std::to_string(peer.port()),
                         "--log-level", "warn"});
  ASSERT_FALSE(peer.Receive(5000).empty());
  EXPECT_TRUE(peer.Receive(300).empty()) << "the second datagram is due in 292 years";
  replay.Signal(SIGINT);
  ASSERT_EQ(replay.Wait(seconds(5)), 0) << replay.err();
  EXPECT_EQ(SummaryFields(replay.out()).at("datagrams"), "1") << replay.out();
}

TEST_F(DatagramToolsTest, BadArgumentsGiveOneLineAndExitCode2) {
  const std::string rec = Path("session.rec");
  WriteRecording(rec, SmallSession());
  const std::vector<std::vector<std::string>> cases = {
      {"replay"},
      {"replay", rec},
      {"replay", rec, "--to", "127.0.0.1"},
      {"replay", rec, "--to", "127.0.0.1:0"},
      {"replay", rec, "--to", "127.0.0.1:70000"},
      {"replay", rec, "--to", "[::1:5800"},
      {"replay", rec, "--to", "127.0.0.1:5800", "--speed", "-1"},
      {"replay", rec, "--to", "127.0.0.1:5800", "--speed", "fast"},
      {"replay", rec, "--to", "127.0.0.1:5800", "--speed", "nan"},
      {"replay", rec, "--to", "127.0.0.1:5800", "--max-gap-s", "-1"},
      {"replay", rec, "--to", "127.0.0.1:5800", "--udp-port", "70000"},
      {"replay", rec, "--to", "127.0.0.1:5800", "--log-level", "loud"},
      {"replay", rec, rec, "--to", "127.0.0.1:5800"},
      {"replay", rec, "--to", "127.0.0.1:5800", "--bogus"},
      {"dump", rec, "--udp-port", "-1"},
      {"dump", rec, "--udp-port", "65536"},
  };
  for (const auto& args : cases) {
    SCOPED_TRACE(::testing::PrintToString(args));
    Process p(kTool, args);
    EXPECT_EQ(p.Wait(), 2);
    EXPECT_EQ(CountLines(p.err()), 1u) << p.err();
    EXPECT_TRUE(p.out().empty()) << p.out();
  }
}

TEST_F(DatagramToolsTest, AMissingFileExits1WithOneLineNamingIt) {
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"replay", "no/such/session.rec", "--to", "127.0.0.1:5800"},
        std::vector<std::string>{"dump", "no/such/session.rec"},
        std::vector<std::string>{"dump", "--datagrams", "no/such/session.rec"}}) {
    SCOPED_TRACE(::testing::PrintToString(args));
    Process p(kTool, args);
    EXPECT_EQ(p.Wait(), 1);
    EXPECT_EQ(CountLines(p.err()), 1u) << p.err();
    EXPECT_NE(p.err().find("no/such/session.rec"), std::string::npos) << p.err();
  }
}

TEST_F(DatagramToolsTest, HelpDescribesTheNewOptions) {
  for (const auto& [args, needle] : std::vector<std::pair<std::vector<std::string>, std::string>>{
           {{"--help"}, "replay"},
           {{"dump", "--help"}, "--datagrams"},
           {{"dump", "--help"}, "recording"},
           {{"replay", "--help"}, "--max-gap-s"}}) {
    Process p(kTool, args);
    EXPECT_EQ(p.Wait(), 0);
    EXPECT_NE(p.out().find(needle), std::string::npos) << p.out();
  }
}

}  // namespace
}  // namespace lrfnet
