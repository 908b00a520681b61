// lrfnetd as a user runs it: several lrfnet-tracker --replay processes send to one daemon over
// loopback UDP; the daemon's recording must hold exactly what every tracker sent (each tracker also
// writes its own datagrams with --out). Also: a tracker restarting mid-run, injected loss /
// reordering / duplicates, hostile datagrams, SIGKILL durability, SIGHUP reload, offline --input,
// and the command line's errors.

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "central_daemon/io/datagram_source.h"
#include "firmware_tracker/io/datagram_encoder.h"
#include "lrfnet.pb.h"
#include "tests/process_harness.h"

namespace lrfnet::testing {
namespace {

using std::chrono::milliseconds;
namespace fs = std::filesystem;

constexpr common::UtcNs kT0 = 1'700'000'000'000'000'000;
constexpr common::DurationNs kMs = 1'000'000;

// A short scene: three scanners around a 10 x 8 m room, two people walking.
constexpr const char* kScenario = R"(name: daemon_test
seed: 5
duration_s: 6
world:
  walls: [[[0, 0], [10, 0], [10, 8], [0, 8], [0, 0]]]
  obstacles: [[[8.5, 3.5], [9.2, 3.5], [9.2, 4.2], [8.5, 4.2]]]
sensors:
  - {id: s1, model: lms111, x_m: 0.5, y_m: 0.5, yaw_deg: 45}
  - {id: s2, model: tim561, x_m: 9.5, y_m: 0.5, yaw_deg: 135}
  - {id: s3, model: lms511, x_m: 5, y_m: 7.5, yaw_deg: -90}
targets:
  - {shape: person, a_m: 0.25, b_m: 0.15, path: [[2, 2], [8, 6], [2, 6]], speed_mps: 1.2, loop: true}
  - {shape: cylinder, radius_m: 0.2, path: [[8, 2], [2, 5]], speed_mps: 1.0, loop: true}
)";

using TempDir = testing::ScratchDir;

struct Entry {
  std::string source;
  common::UtcNs receive_ns;
  std::vector<std::uint8_t> bytes;
};

std::vector<Entry> ReadDatagrams(const std::string& path, std::string* error = nullptr) {
  std::string e;
  auto source = daemon::OpenDatagramFile(path, {}, &e);
  EXPECT_NE(source, nullptr) << e;
  std::vector<Entry> out;
  if (!source) return out;
  daemon::ReceivedDatagram d;
  daemon::SourceStatus status;
  while ((status = source->Next(&d)) == daemon::SourceStatus::kDatagram)
    out.push_back({d.source, d.receive_ns, d.bytes});
  if (error != nullptr) *error = status == daemon::SourceStatus::kError ? source->error() : "";
  return out;
}

std::string SensorOf(const std::vector<std::uint8_t>& bytes) {
  proto::Datagram d;
  if (!d.ParseFromArray(bytes.data(), static_cast<int>(bytes.size()))) return "";
  return d.sensor_id();
}

nlohmann::json ReadJson(const std::string& path) {
  std::ifstream in(path);
  if (!in) return nlohmann::json();
  return nlohmann::json::parse(in, nullptr, false);
}

const nlohmann::json* FindSensor(const nlohmann::json& stats, const std::string& id) {
  if (!stats.contains("sensors")) return nullptr;
  for (const auto& s : stats["sensors"])
    if (s["sensor_id"] == id) return &s;
  return nullptr;
}

// lrfnetd on an ephemeral loopback port; returns the port once it listens.
int StartDaemon(Process& daemon) {
  if (!daemon.WaitForOutput("listening ", milliseconds(10'000))) return 0;
  const std::string out = daemon.out();
  const auto colon = out.find(':', out.find("listening "));
  return std::atoi(out.c_str() + colon + 1);
}

// A plain UDP sender for hand-made datagrams.
class UdpSender {
 public:
  UdpSender() { fd_ = ::socket(AF_INET, SOCK_DGRAM, 0); }
  ~UdpSender() { ::close(fd_); }
  bool Send(int port, std::span<const std::uint8_t> bytes) {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    return ::sendto(fd_, bytes.data(), bytes.size(), 0, reinterpret_cast<sockaddr*>(&a),
                    sizeof(a)) == static_cast<ssize_t>(bytes.size());
  }

 private:
  int fd_;
};

struct Collect final : io::DatagramSink {
  std::vector<std::vector<std::uint8_t>> out;
  void Send(std::span<const std::uint8_t> d, common::UtcNs) override { out.emplace_back(d.begin(), d.end()); }
};

// `count` track frames of one sensor as the tracker encodes them, stamped now-ish so any
// validation window accepts them.
std::vector<std::vector<std::uint8_t>> TrackFrames(const std::string& sensor, std::uint64_t session,
                                                   int count) {
  io::DatagramEncoder encoder({sensor, session});
  Collect c;
  const common::UtcNs now = static_cast<common::UtcNs>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(
          std::chrono::system_clock::now().time_since_epoch())
          .count());
  for (int i = 0; i < count; ++i) {
    tracking::ScanTracks scan;
    scan.scan_start_ns = now + i * 20 * kMs;
    scan.scan_period_s = 0.02;
    scan.scan_counter = static_cast<std::uint32_t>(i);
    tracking::TrackReport* t = scan.tracks.emplace_slot();
    t->track_id = 1;
    t->state = tracking::TrackState::kConfirmed;
    t->x_m = 2.0 + 0.01 * i;
    t->covariance = Eigen::Matrix4d::Identity() * 0.01;
    encoder.EncodeTracks(scan, scan.scan_start_ns + kMs, c);
  }
  return c.out;
}

TEST(DaemonCliTest, SeveralTrackerReplaysIntoOneDaemonRecordingHoldsExactlyWhatWasSent) {
  TempDir dir;
  {
    std::ofstream(dir / "scene.yaml") << kScenario;
  }
  Process sim(LRFNET_TOOL_BINARY, {"sim", dir / "scene.yaml", "--out", dir / "sim"});
  ASSERT_EQ(sim.Wait(milliseconds(120'000)), 0) << sim.err();

  Process daemon(LRFNET_DAEMON_BINARY,
                 {"--listen", "127.0.0.1:0", "--record", dir / "all.rec", "--stats-out",
                  dir / "stats.json", "--status-interval-s", "0.5"});
  const int port = StartDaemon(daemon);
  ASSERT_GT(port, 0) << daemon.err();

  std::vector<std::unique_ptr<Process>> trackers;
  for (const std::string id : {"s1", "s2", "s3"}) {
    trackers.push_back(std::make_unique<Process>(
        LRFNET_TRACKER_BINARY,
        std::vector<std::string>{"--replay", dir / ("sim/" + id + ".pcap"), "--sensor-id", id,
                                 "--uplink", "127.0.0.1:" + std::to_string(port), "--out",
                                 dir / (id + ".rec"), "--speed", "3", "--log-level", "warn"}));
  }
  for (auto& t : trackers) ASSERT_EQ(t->Wait(milliseconds(60'000)), 0) << t->err();
  std::this_thread::sleep_for(milliseconds(300));
  daemon.Signal(SIGTERM);
  ASSERT_EQ(daemon.Wait(), 0) << daemon.err();
  EXPECT_NE(daemon.err().find("status: 3 sensors"), std::string::npos) << daemon.err();

  // Per sensor, the daemon's recording holds the tracker's datagrams, byte for byte, in order.
  std::string error;
  const std::vector<Entry> recorded = ReadDatagrams(dir / "all.rec", &error);
  EXPECT_EQ(error, "");
  std::map<std::string, std::vector<std::vector<std::uint8_t>>> by_sensor;
  std::map<std::string, std::string> source_of;
  for (const Entry& e : recorded) {
    by_sensor[SensorOf(e.bytes)].push_back(e.bytes);
    source_of[SensorOf(e.bytes)] = e.source;
  }
  std::size_t total = 0;
  for (const std::string id : {"s1", "s2", "s3"}) {
    const std::vector<Entry> sent = ReadDatagrams(dir / (id + ".rec"));
    ASSERT_GT(sent.size(), 50u) << id;
    std::vector<std::vector<std::uint8_t>> sent_bytes;
    for (const Entry& e : sent) sent_bytes.push_back(e.bytes);
    EXPECT_EQ(by_sensor[id], sent_bytes) << id << ": " << by_sensor[id].size() << " recorded, "
                                         << sent_bytes.size() << " sent";
    EXPECT_EQ(source_of[id].rfind("127.0.0.1:", 0), 0u) << source_of[id];
    total += sent.size();
  }
  EXPECT_EQ(recorded.size(), total);

  const nlohmann::json stats = ReadJson(dir / "stats.json");
  ASSERT_TRUE(stats.is_object()) << daemon.err();
  EXPECT_EQ(stats["datagrams"], total);
  EXPECT_EQ(stats["rejected"], 0);
  EXPECT_EQ(stats["recording"]["entries_written"], total);
  for (const std::string id : {"s1", "s2", "s3"}) {
    const nlohmann::json* s = FindSensor(stats, id);
    ASSERT_NE(s, nullptr) << id;
    EXPECT_EQ((*s)["sequence"]["lost"], 0) << id;
    EXPECT_EQ((*s)["sequence"]["duplicates"], 0) << id;
    EXPECT_GT((*s)["stored_frames"].get<int>(), 50) << id;
    EXPECT_TRUE(s->contains("info")) << id;  // the tracker's SensorInfo arrived
  }
  // The models as the simulated devices identify themselves.
  EXPECT_EQ((*FindSensor(stats, "s3"))["info"]["model"].get<std::string>().rfind("LMS5", 0), 0u);
}

TEST(DaemonCliTest, InjectedLossReorderingDuplicatesAndARestartAreCountedPerSensor) {
  TempDir dir;
  {
    std::ofstream(dir / "lrfnetd.yaml") << "sensors: {reorder_window_datagrams: 32, send_requests: false}\n";
  }
  Process daemon(LRFNET_DAEMON_BINARY,
                 {"--config", dir / "lrfnetd.yaml", "--listen", "127.0.0.1:0", "--record",
                  dir / "rec", "--stats-out", dir / "stats.json", "--status-interval-s", "0"});
  const int port = StartDaemon(daemon);
  ASSERT_GT(port, 0) << daemon.err();

  const auto frames = TrackFrames("gate", 11, 400);
  UdpSender sender;
  std::size_t sent = 0;
  std::vector<std::size_t> order;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    if (i % 50 == 7) continue;               // lost: 8 datagrams
    if (i % 100 == 20) {                     // reordered: 20 after 21 (4 times)
      order.push_back(i + 1);
      order.push_back(i);
      ++i;
      continue;
    }
    order.push_back(i);
    if (i % 100 == 60) order.push_back(i);  // duplicated (4 times)
  }
  for (std::size_t i : order) {
    ASSERT_TRUE(sender.Send(port, frames[i]));
    ++sent;
    if (sent % 50 == 0) std::this_thread::sleep_for(milliseconds(2));
  }
  // The tracker restarts: a new session starting at sequence 0.
  const auto restarted = TrackFrames("gate", 12, 100);
  for (const auto& f : restarted) {
    ASSERT_TRUE(sender.Send(port, f));
    ++sent;
  }
  std::this_thread::sleep_for(milliseconds(300));
  daemon.Signal(SIGINT);
  ASSERT_EQ(daemon.Wait(), 0) << daemon.err();
  EXPECT_NE(daemon.err().find("sensor gate: tracker restarted"), std::string::npos) << daemon.err();

  const nlohmann::json stats = ReadJson(dir / "stats.json");
  const nlohmann::json* s = FindSensor(stats, "gate");
  ASSERT_NE(s, nullptr) << stats.dump();
  EXPECT_EQ((*s)["sequence"]["lost"], 8) << s->dump();
  EXPECT_EQ((*s)["sequence"]["reordered"], 4) << s->dump();
  EXPECT_EQ((*s)["sequence"]["duplicates"], 4) << s->dump();
  EXPECT_EQ((*s)["sequence"]["restarts"], 1) << s->dump();
  EXPECT_EQ((*s)["rejected"]["duplicate"], 4) << s->dump();
  EXPECT_EQ((*s)["session_id"], 12);
  // Everything received is recorded, duplicates included.
  EXPECT_EQ(ReadDatagrams(dir / "rec").size(), sent);
}

TEST(DaemonCliTest, HostileDatagramsAreCountedRecordedAndNeverStopTheDaemon) {
  TempDir dir;
  Process daemon(LRFNET_DAEMON_BINARY,
                 {"--listen", "127.0.0.1:0", "--record", dir / "rec", "--stats-out",
                  dir / "stats.json", "--status-interval-s", "0"});
  const int port = StartDaemon(daemon);
  ASSERT_GT(port, 0) << daemon.err();
  UdpSender sender;
  std::vector<std::vector<std::uint8_t>> hostile;
  hostile.push_back({});                                   // empty
  hostile.push_back(std::vector<std::uint8_t>(2000, 0x0a));  // oversize
  hostile.push_back({0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x01});  // varint bomb
  const auto valid = TrackFrames("cell-7", 3, 5);
  for (std::size_t cut = 1; cut < valid[0].size(); cut += 7)  // truncations
    hostile.emplace_back(valid[0].begin(), valid[0].begin() + static_cast<long>(cut));
  proto::Datagram bad_version;
  ASSERT_TRUE(bad_version.ParseFromArray(valid[1].data(), static_cast<int>(valid[1].size())));
  bad_version.set_version(static_cast<proto::ProtocolVersion>(9));
  hostile.push_back({});
  hostile.back().resize(bad_version.ByteSizeLong());
  bad_version.SerializeToArray(hostile.back().data(), static_cast<int>(hostile.back().size()));
  proto::Datagram nan_track = bad_version;
  nan_track.set_version(proto::PROTOCOL_VERSION_1);
  nan_track.mutable_track_frame()->mutable_tracks(0)->set_x_m(std::nanf(""));
  hostile.push_back({});
  hostile.back().resize(nan_track.ByteSizeLong());
  nan_track.SerializeToArray(hostile.back().data(), static_cast<int>(hostile.back().size()));

  for (const auto& h : hostile) ASSERT_TRUE(sender.Send(port, h));
  for (const auto& v : valid) ASSERT_TRUE(sender.Send(port, v));
  std::this_thread::sleep_for(milliseconds(300));
  daemon.Signal(SIGTERM);
  ASSERT_EQ(daemon.Wait(), 0) << daemon.err();

  const nlohmann::json stats = ReadJson(dir / "stats.json");
  ASSERT_TRUE(stats.is_object());
  EXPECT_EQ(stats["datagrams"], hostile.size() + valid.size());
  EXPECT_EQ(stats["accepted"], valid.size());
  EXPECT_EQ(stats["rejected"], hostile.size());
  EXPECT_EQ(stats["unattributed"]["empty"], 1);
  EXPECT_EQ(stats["unattributed"]["oversize"], 1);
  const nlohmann::json* s = FindSensor(stats, "cell-7");
  ASSERT_NE(s, nullptr);
  EXPECT_EQ((*s)["rejected"]["version"], 1) << s->dump();
  EXPECT_EQ((*s)["rejected"]["not_finite"], 1) << s->dump();
  EXPECT_EQ((*s)["stored_frames"], valid.size());
  // The recording keeps even the hostile datagrams (the empty one included), for replay.
  EXPECT_EQ(ReadDatagrams(dir / "rec").size(), hostile.size() + valid.size());
}

TEST(DaemonCliTest, AKillLosesAtMostTheLastSecondOfTheRecording) {
  TempDir dir;
  Process daemon(LRFNET_DAEMON_BINARY, {"--listen", "127.0.0.1:0", "--record", dir / "rec",
                                        "--status-interval-s", "0", "--log-level", "warn"});
  const int port = StartDaemon(daemon);
  ASSERT_GT(port, 0) << daemon.err();
  const auto frames = TrackFrames("door", 1, 150);
  UdpSender sender;
  const auto start = std::chrono::steady_clock::now();
  std::size_t sent_before_last_1500ms = 0;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    ASSERT_TRUE(sender.Send(port, frames[i]));
    std::this_thread::sleep_for(milliseconds(20));  // 3 s in all
    if (std::chrono::steady_clock::now() - start < milliseconds(1500)) sent_before_last_1500ms = i + 1;
  }
  daemon.Signal(SIGKILL);
  daemon.Wait();
  std::string error;
  const auto recorded = ReadDatagrams(dir / "rec", &error);
  EXPECT_EQ(error, "");  // only whole entries reach the file
  EXPECT_GE(recorded.size(), sent_before_last_1500ms);
  EXPECT_LE(recorded.size(), frames.size());
}

TEST(DaemonCliTest, SighupReloadsTheConfigAndABrokenFileKeepsTheOldOne) {
  TempDir dir;
  const std::string config = dir / "lrfnetd.yaml";
  {
    std::ofstream(config) << "sensors: {silent_after_s: 3}\n";
  }
  Process daemon(LRFNET_DAEMON_BINARY,
                 {"--config", config, "--listen", "127.0.0.1:0", "--status-interval-s", "0"});
  ASSERT_GT(StartDaemon(daemon), 0) << daemon.err();
  {
    std::ofstream(config) << "sensors: {silent_after_s: 9}\n";
  }
  daemon.Signal(SIGHUP);
  // Each reload is awaited before the file changes again: two SIGHUPs sent before the daemon
  // handled the first are one signal to it (the kernel keeps one pending), and a loaded machine
  // can take longer than any fixed sleep.
  EXPECT_TRUE(daemon.WaitForError("SIGHUP: config reloaded", milliseconds(10'000))) << daemon.err();
  {
    std::ofstream(config) << "sensors: {silent_after_s: [broken\n";
  }
  daemon.Signal(SIGHUP);
  EXPECT_TRUE(daemon.WaitForError("SIGHUP: config not reloaded", milliseconds(10'000)))
      << daemon.err();
  // Still serving with the config it had: a third reload of a good file works again.
  { std::ofstream(config) << "sensors: {silent_after_s: 4}\n"; }
  daemon.Signal(SIGHUP);
  EXPECT_TRUE(daemon.WaitForError("SIGHUP: config reloaded", milliseconds(10'000), 2))
      << daemon.err();
  daemon.Signal(SIGTERM);
  ASSERT_EQ(daemon.Wait(), 0) << daemon.err();
}

TEST(DaemonCliTest, OfflineInputReadsARecordingThroughTheSameIngest) {
  TempDir dir;
  Process live(LRFNET_DAEMON_BINARY, {"--listen", "127.0.0.1:0", "--record", dir / "rec",
                                      "--stats-out", dir / "live.json", "--status-interval-s", "0"});
  const int port = StartDaemon(live);
  ASSERT_GT(port, 0) << live.err();
  UdpSender sender;
  for (const auto& f : TrackFrames("a", 1, 60)) ASSERT_TRUE(sender.Send(port, f));
  for (const auto& f : TrackFrames("b", 2, 40)) ASSERT_TRUE(sender.Send(port, f));
  const std::vector<std::uint8_t> junk = {1, 2, 3};
  ASSERT_TRUE(sender.Send(port, junk));
  std::this_thread::sleep_for(milliseconds(300));
  live.Signal(SIGTERM);
  ASSERT_EQ(live.Wait(), 0) << live.err();

  Process offline(LRFNET_DAEMON_BINARY,
                  {"--input", dir / "rec", "--stats-out", dir / "offline.json"});
  ASSERT_EQ(offline.Wait(), 0) << offline.err();
  EXPECT_NE(offline.out().find("summary: sensors=2 datagrams=101 accepted=100 rejected=1"),
            std::string::npos)
      << offline.out();
  const nlohmann::json a = ReadJson(dir / "live.json");
  const nlohmann::json b = ReadJson(dir / "offline.json");
  EXPECT_EQ(a["accepted"], b["accepted"]);
  EXPECT_EQ(a["store"]["frames"], b["store"]["frames"]);
  EXPECT_EQ(a["unattributed"], b["unattributed"]);
}

TEST(DaemonCliTest, CommandLineErrorsAreOneLineWithExitCodes) {
  struct Case {
    std::vector<std::string> args;
    int exit_code;
    const char* expected;
  };
  const Case cases[] = {
      {{"--listen", "127.0.0.1"}, 2, "port is required"},
      {{"--listen", "127.0.0.1:70000"}, 2, "bad port"},
      {{"--no-such-flag"}, 2, "no-such-flag"},
      {{"--config", "/nonexistent/lrfnetd.yaml"}, 2, "cannot read"},
      {{"--input", "/nonexistent/rec"}, 1, "/nonexistent/rec"},
      {{"--listen", "192.0.2.1:5800"}, 1, "cannot bind"},  // not an address of this host
  };
  for (const Case& c : cases) {
    Process p(LRFNET_DAEMON_BINARY, c.args);
    EXPECT_EQ(p.Wait(), c.exit_code) << c.args[0] << ": " << p.err();
    EXPECT_NE(p.err().find(c.expected), std::string::npos) << p.err();
    EXPECT_EQ(CountLines(p.err()), 1u) << p.err();
  }
  Process help(LRFNET_DAEMON_BINARY, {"--help"});
  EXPECT_EQ(help.Wait(), 0);
  EXPECT_NE(help.out().find("--listen"), std::string::npos);
  Process print(LRFNET_DAEMON_BINARY, {"--print-config"});
  EXPECT_EQ(print.Wait(), 0);
  EXPECT_EQ(print.out(), ReadText(LRFNET_DAEMON_CONFIG_FILE));
}

}  // namespace
}  // namespace lrfnet::testing
