// lrfnet-tracker's outputs as a user and the daemon see them: --print-config is the shipped
// config file; --replay --out writes a recording (DESIGN.md format) that libprotobuf reads, with
// one track frame per scan, identical on a second run; --sensor --uplink sends the datagrams over
// UDP and answers the daemon's Request datagrams.

#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "lrfnet.pb.h"
#include "tests/process_harness.h"
#include "tests/support/test_data.h"
#include "tests/support/udp_peer.h"

namespace lrfnet {
namespace {

using std::chrono::milliseconds;
using std::chrono::seconds;
using testing::Process;
using testing::ReadText;

const char* const kTool = LRFNET_TOOL_BINARY;
const char* const kTracker = LRFNET_TRACKER_BINARY;

// A recording: varint length + RecordEntry, repeated. nullopt when the framing is broken.
std::optional<std::vector<proto::RecordEntry>> ReadRecording(const std::string& path) {
  const std::string bytes = ReadText(path);
  std::vector<proto::RecordEntry> entries;
  std::size_t i = 0;
  while (i < bytes.size()) {
    std::uint64_t length = 0;
    int shift = 0;
    while (true) {
      if (i >= bytes.size() || shift > 63) return std::nullopt;
      const auto byte = static_cast<std::uint8_t>(bytes[i++]);
      length |= static_cast<std::uint64_t>(byte & 0x7f) << shift;
      shift += 7;
      if ((byte & 0x80) == 0) break;
    }
    if (length > bytes.size() - i) return std::nullopt;
    proto::RecordEntry entry;
    if (!entry.ParseFromArray(bytes.data() + i, static_cast<int>(length))) return std::nullopt;
    entries.push_back(std::move(entry));
    i += length;
  }
  return entries;
}

std::vector<proto::Datagram> Datagrams(const std::vector<proto::RecordEntry>& entries) {
  std::vector<proto::Datagram> out;
  for (const proto::RecordEntry& e : entries) {
    if (e.has_header()) continue;
    proto::Datagram d;
    EXPECT_TRUE(d.ParseFromString(e.datagram()));
    EXPECT_LE(e.datagram().size(), 1400u);
    out.push_back(std::move(d));
  }
  return out;
}

std::string TempFile(const std::string& name) {
  return (std::filesystem::path(::testing::TempDir()) /
          (name + "_" + std::to_string(::getpid())))
      .string();
}

TEST(TrackerCliTest, PrintConfigIsTheShippedFileAndLoadsBack) {
  Process printed(kTracker, {"--print-config"});
  ASSERT_EQ(printed.Wait(), 0) << printed.err();
  const std::string shipped = ReadText(LRFNET_TRACKER_CONFIG_FILE);
  EXPECT_EQ(printed.out(), shipped);
  Process again(kTracker, {"--config", LRFNET_TRACKER_CONFIG_FILE, "--print-config"});
  ASSERT_EQ(again.Wait(), 0) << again.err();
  EXPECT_EQ(again.out(), shipped);

  const std::string bad = TempFile("bad_config.yaml");
  std::ofstream(bad) << "tracking:\n  confirm_hits: many\n";
  Process rejected(kTracker, {"--config", bad, "--replay", "x.pcap", "--sensor-id", "s"});
  EXPECT_EQ(rejected.Wait(), 2);
  EXPECT_NE(rejected.err().find("tracking.confirm_hits: expected an integer"), std::string::npos)
      << rejected.err();
  std::filesystem::remove(bad);
}

// --speed paces the replay by the capture's packet times: the LMS511 capture spans 5.4 s, so at
// speed 4 it takes about 1.35 s, and it still processes every scan.
TEST(TrackerCliTest, ReplaySpeedPacesByTheCaptureTimes) {
  LRFNET_REQUIRE_SHARED_FILE(capture, "data/sick/lms511_20210301.pcap");
  const auto start = std::chrono::steady_clock::now();
  Process run(kTracker, {"--replay", capture, "--sensor-id", "paced", "--speed", "4",
                         "--log-level", "warn"});
  ASSERT_EQ(run.Wait(), 0) << run.err();
  const double elapsed_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_NE(run.out().find("scans=136"), std::string::npos) << run.out();
  EXPECT_GT(elapsed_s, 1.1);
  EXPECT_LT(elapsed_s, 10.0);
  Process bad(kTracker, {"--replay", capture, "--sensor-id", "paced", "--speed", "-1"});
  EXPECT_EQ(bad.Wait(), 2);
  EXPECT_NE(bad.err().find("--speed"), std::string::npos) << bad.err();
}

TEST(TrackerCliTest, ReplayWritesARecordingWithAFramePerScanSameOnEveryRun) {
  LRFNET_REQUIRE_SHARED_FILE(capture, "data/sick/lms511_20210301.pcap");
  const std::string rec_a = TempFile("replay_a.rec");
  const std::string rec_b = TempFile("replay_b.rec");
  for (const std::string& rec : {rec_a, rec_b}) {
    Process run(kTracker, {"--replay", capture, "--sensor-id", "hall.lms511", "--out", rec,
                           "--log-level", "warn"});
    ASSERT_EQ(run.Wait(), 0) << run.err();
    EXPECT_NE(run.out().find("summary: sensor=hall.lms511 mode=replay scans=136"),
              std::string::npos)
        << run.out();
  }
  const auto a = ReadRecording(rec_a);
  const auto b = ReadRecording(rec_b);
  ASSERT_TRUE(a.has_value() && b.has_value());
  ASSERT_FALSE(a->empty());
  ASSERT_TRUE(a->front().has_header());
  EXPECT_EQ(a->front().header().format_version(), 1u);
  EXPECT_EQ(a->front().header().writer().rfind("lrfnet-tracker", 0), 0u);

  const std::vector<proto::Datagram> da = Datagrams(*a);
  const std::vector<proto::Datagram> db = Datagrams(*b);
  ASSERT_EQ(da.size(), db.size());
  std::map<proto::Datagram::PayloadCase, int> kinds;
  std::vector<std::string> frames_a, frames_b;
  for (std::size_t i = 0; i < da.size(); ++i) {
    EXPECT_EQ(da[i].sequence(), i);
    EXPECT_EQ(da[i].sensor_id(), "hall.lms511");
    EXPECT_EQ(da[i].version(), proto::PROTOCOL_VERSION_1);
    EXPECT_EQ(da[i].session_id(), da[0].session_id());
    ++kinds[da[i].payload_case()];
    if (da[i].has_track_frame()) frames_a.push_back(da[i].track_frame().SerializeAsString());
    if (db[i].has_track_frame()) frames_b.push_back(db[i].track_frame().SerializeAsString());
  }
  EXPECT_EQ(kinds[proto::Datagram::kTrackFrame], 136);
  EXPECT_EQ(kinds[proto::Datagram::kSensorInfo], 1);
  EXPECT_GE(kinds[proto::Datagram::kBackground], 1);  // learned after 5 s of the 8 s capture
  EXPECT_GE(kinds[proto::Datagram::kHealth], 5);
  EXPECT_EQ(frames_a, frames_b) << "replay is deterministic";
  EXPECT_NE(da[0].session_id(), db[0].session_id()) << "a new session per start";
  const proto::SensorInfo& info = da[0].sensor_info();
  EXPECT_EQ(info.beam_count(), 1141u);
  EXPECT_NEAR(info.scan_frequency_hz(), 25.0, 1e-9);
  std::filesystem::remove(rec_a);
  std::filesystem::remove(rec_b);
}

// Next datagram from the tracker within ~200 ms, parsed.
std::optional<proto::Datagram> ReceiveDatagram(testing::LoopbackUdpPeer& daemon) {
  const std::vector<std::uint8_t> bytes = daemon.Receive(200);
  if (bytes.empty()) return std::nullopt;
  EXPECT_LE(bytes.size(), 1400u);
  proto::Datagram d;
  EXPECT_TRUE(d.ParseFromArray(bytes.data(), static_cast<int>(bytes.size())));
  return d;
}

TEST(TrackerCliTest, LiveTrackerSendsOverUdpAndAnswersRequests) {
  Process emulator(kTool, {"emulate", "--synthetic", "lms511", "--port", "0", "--log-level",
                           "warn"});
  ASSERT_TRUE(emulator.WaitForOutput("\n", seconds(10))) << emulator.err();
  const std::string line = emulator.out();
  const std::string prefix = "lrfnet emulate: listening on 127.0.0.1:";
  ASSERT_EQ(line.rfind(prefix, 0), 0u) << line;
  const std::string port = line.substr(prefix.size(), line.find('\n') - prefix.size());

  const std::string config = TempFile("fast_learning.yaml");
  std::ofstream(config) << "background:\n  learn_duration_s: 1.0\n";
  testing::LoopbackUdpPeer daemon;  // lrfnetd's end of the uplink
  Process tracker(kTracker, {"--config", config, "--sensor", "127.0.0.1:" + port, "--sensor-id",
                             "live-1", "--uplink", "127.0.0.1:" + std::to_string(daemon.port()),
                             "--max-scans", "100", "--log-level", "warn"});
  std::map<proto::Datagram::PayloadCase, int> kinds;
  bool requested = false;
  int infos_after_request = 0;
  std::uint64_t expected_sequence = 0;
  const auto deadline = std::chrono::steady_clock::now() + seconds(20);
  while (std::chrono::steady_clock::now() < deadline) {
    const std::optional<proto::Datagram> d = ReceiveDatagram(daemon);
    if (!d) {
      if (kinds[proto::Datagram::kTrackFrame] >= 100) break;  // the tracker stopped
      continue;
    }
    EXPECT_EQ(d->sensor_id(), "live-1");
    EXPECT_EQ(d->sequence(), expected_sequence++) << "loopback loses nothing";
    ++kinds[d->payload_case()];
    if (requested && d->has_sensor_info()) ++infos_after_request;
    if (!requested && kinds[proto::Datagram::kTrackFrame] == 50) {
      proto::Datagram request;
      request.set_version(proto::PROTOCOL_VERSION_1);
      request.set_sensor_id("live-1");
      request.mutable_request()->set_send_sensor_info(true);
      request.mutable_request()->set_send_background(true);
      const std::string bytes = request.SerializeAsString();
      daemon.Reply(std::span(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size()));
      requested = true;
    }
  }
  ASSERT_EQ(tracker.Wait(seconds(10)), 0) << tracker.err();
  EXPECT_EQ(kinds[proto::Datagram::kTrackFrame], 100);
  EXPECT_GE(kinds[proto::Datagram::kHealth], 3);
  EXPECT_EQ(infos_after_request, 1) << "the Request was answered";
  EXPECT_GE(kinds[proto::Datagram::kBackground], 6) << "snapshot at learning + on request";
  EXPECT_NE(tracker.out().find("udp_sent="), std::string::npos) << tracker.out();
  std::filesystem::remove(config);
  emulator.Signal(SIGTERM);
  EXPECT_EQ(emulator.Wait(seconds(10)), 0) << emulator.err();
}

}  // namespace
}  // namespace lrfnet
