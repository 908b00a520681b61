// Authenticated datagrams end to end, with the binaries as processes and real UDP on loopback:
// `lrfnet keys` makes the keys; a tracker with --key feeds lrfnetd --keys; forged, bit-flipped,
// wrong-epoch, wrong-key, unknown-sensor and unsigned datagrams and a real recording sent again
// (lrfnet replay) are each counted under their reason and none is accepted; a restarted daemon
// refuses the earlier run's recording from its stored state; the offline readers (lrfnetd --input,
// lrfnet dump, lrfnet replay --keys) verify with keys and say what they read without.

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <csignal>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "central_daemon/io/datagram_source.h"
#include "common/datagram_auth.h"
#include "common/key_file.h"
#include "firmware_tracker/io/datagram_encoder.h"
#include "tests/process_harness.h"

namespace lrfnet::testing {
namespace {

using std::chrono::milliseconds;
using std::chrono::seconds;
using Bytes = std::vector<std::uint8_t>;

// One scanner, one person walking: a few hundred datagrams.
constexpr const char* kAuthScenario = R"(name: auth_test
seed: 3
duration_s: 8
world:
  walls: [[[0, 0], [10, 0], [10, 8], [0, 8], [0, 0]]]
  obstacles: [[[8.5, 3.5], [9.2, 3.5], [9.2, 4.2], [8.5, 4.2]]]
sensors:
  - {id: s1, model: tim561, x_m: 0.5, y_m: 0.5, yaw_deg: 45}
targets:
  - {shape: person, a_m: 0.25, b_m: 0.15, path: [[2, 2], [8, 6], [2, 6]], speed_mps: 1.2, loop: true}
)";

std::string FirstLine(const std::string& text) { return text.substr(0, text.find('\n')); }

// "listening 127.0.0.1:PORT" of a daemon's stdout.
std::string ListenAddress(const Process& daemon) {
  std::istringstream in(daemon.out());
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("listening ", 0) == 0) return line.substr(10);
  }
  return "";
}

std::uint16_t PortOf(const std::string& address) {
  return static_cast<std::uint16_t>(std::stoi(address.substr(address.rfind(':') + 1)));
}

bool SendUdp(std::uint16_t port, const Bytes& bytes) {
  const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  const ssize_t n =
      ::sendto(fd, bytes.data(), bytes.size(), 0, reinterpret_cast<sockaddr*>(&a), sizeof a);
  ::close(fd);
  return n == static_cast<ssize_t>(bytes.size());
}

std::vector<Bytes> ReadAuthDatagrams(const std::string& path) {
  std::string error;
  auto source = daemon::OpenDatagramFile(path, {}, &error);
  EXPECT_NE(source, nullptr) << error;
  std::vector<Bytes> out;
  if (!source) return out;
  daemon::ReceivedDatagram d;
  while (source->Next(&d) == daemon::SourceStatus::kDatagram) out.push_back(d.bytes);
  return out;
}

nlohmann::json ReadAuthJson(const std::string& path) {
  return nlohmann::json::parse(ReadText(path), nullptr, false);
}

// Rejections of one reason: unattributed plus at every sensor.
std::uint64_t Refused(const nlohmann::json& stats, const std::string& reason) {
  std::uint64_t n = stats["unattributed"].value(reason, std::uint64_t{0});
  for (const auto& s : stats["sensors"]) n += s["rejected"].value(reason, std::uint64_t{0});
  return n;
}

auth::KeyFile ReadKey(const std::string& path) {
  auth::KeyFile k;
  EXPECT_EQ(auth::ReadKeyFile(path, &k), std::nullopt);
  return k;
}

// A datagram sealed for `id` with `keys`, starting its counter at `counter`.
Bytes SealWith(const std::string& id, const auth::SensorKeys& keys, std::uint64_t counter,
               const Bytes& payload) {
  auth::SealerOptions o;
  o.sensor_id = id;
  o.keys = keys;
  o.salt = 1234;
  o.first_counter = counter;
  auth::Sealer sealer(o);
  Bytes out(payload.size() + sealer.overhead());
  EXPECT_EQ(sealer.Seal(payload, out), out.size());
  return out;
}

// A valid, unsigned health datagram of sensor `id` (what a tracker without --key sends).
Bytes UnsignedHealth(const std::string& id) {
  struct CollectSealed final : io::DatagramSink {
    Bytes bytes;
    void Send(std::span<const std::uint8_t> d, common::UtcNs) override {
      bytes.assign(d.begin(), d.end());
    }
  } sink;
  io::DatagramEncoder encoder(io::DatagramEncoderOptions{id, 77});
  timespec now{};
  ::clock_gettime(CLOCK_REALTIME, &now);
  encoder.EncodeHealth({}, now.tv_sec * 1'000'000'000LL + now.tv_nsec, sink);
  return sink.bytes;
}

TEST(AuthCliTest, KeysCommandWritesPrivateFilesAndRefusesToOverwrite) {
  ScratchDir dir;
  const std::string keys = dir / "keys";
  Process init(LRFNET_TOOL_BINARY, {"keys", "init", "--dir", keys});
  ASSERT_EQ(init.Wait(), 0) << init.err();
  EXPECT_EQ(FirstLine(init.out()), keys + "/site-e1.key");
  struct stat st {};
  ASSERT_EQ(::stat((keys + "/site-e1.key").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  ASSERT_EQ(::stat(keys.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0700u);
  Process again(LRFNET_TOOL_BINARY, {"keys", "init", "--dir", keys});
  EXPECT_EQ(again.Wait(), 1);
  EXPECT_NE(again.err().find("rotate"), std::string::npos) << again.err();
  Process derive(LRFNET_TOOL_BINARY, {"keys", "derive", "--dir", keys, "gate-7"});
  ASSERT_EQ(derive.Wait(), 0) << derive.err();
  EXPECT_EQ(FirstLine(derive.out()), keys + "/sensor-gate-7-e1.key");
  // The file holds the derivation of the site key (the documented one).
  const auth::KeyFile site = ReadKey(keys + "/site-e1.key");
  const auth::KeyFile sensor = ReadKey(keys + "/sensor-gate-7-e1.key");
  EXPECT_EQ(sensor.sensor_id, "gate-7");
  EXPECT_EQ(sensor.key, auth::DeriveSensorKey(site.key, "gate-7"));
  Process twice(LRFNET_TOOL_BINARY, {"keys", "derive", "--dir", keys, "gate-7"});
  EXPECT_EQ(twice.Wait(), 1) << "an existing key file is never replaced";
  Process bad(LRFNET_TOOL_BINARY, {"keys", "derive", "--dir", keys, "gate/7"});
  EXPECT_EQ(bad.Wait(), 2);
  Process rotate(LRFNET_TOOL_BINARY, {"keys", "rotate", "--dir", keys});
  ASSERT_EQ(rotate.Wait(), 0) << rotate.err();
  EXPECT_EQ(rotate.out(), keys + "/site-e2.key\n" + keys + "/sensor-gate-7-e2.key\n");
  Process list(LRFNET_TOOL_BINARY, {"keys", "list", "--dir", keys});
  ASSERT_EQ(list.Wait(), 0);
  EXPECT_NE(list.out().find("sensor gate-7 epoch 2"), std::string::npos) << list.out();
  EXPECT_EQ(list.out().find(auth::ToHex(site.key)), std::string::npos) << "no secret printed";
  Process token(LRFNET_TOOL_BINARY, {"keys", "token", "--dir", keys});
  ASSERT_EQ(token.Wait(), 0);
  EXPECT_EQ(ReadText(keys + "/live-view.token").size(), 33u);
  // A key that others may read is refused by the tracker (an empty capture to replay).
  {
    const std::uint8_t pcap_header[24] = {0xd4, 0xc3, 0xb2, 0xa1, 2,    0,    4, 0, 0, 0, 0, 0,
                                          0,    0,    0,    0,    0xff, 0xff, 0, 0, 1, 0, 0, 0};
    std::ofstream(dir / "empty.pcap", std::ios::binary)
        .write(reinterpret_cast<const char*>(pcap_header), sizeof pcap_header);
  }
  ::chmod((keys + "/sensor-gate-7-e2.key").c_str(), 0644);
  Process tracker(LRFNET_TRACKER_BINARY, {"--replay", dir / "empty.pcap", "--sensor-id", "gate-7",
                                          "--key", keys + "/sensor-gate-7-e2.key"});
  EXPECT_EQ(tracker.Wait(), 1);
  EXPECT_NE(tracker.err().find("chmod 600"), std::string::npos) << tracker.err();
  Process other(LRFNET_TRACKER_BINARY, {"--replay", dir / "empty.pcap", "--sensor-id", "gate-8",
                                        "--key", keys + "/sensor-gate-7-e1.key"});
  EXPECT_EQ(other.Wait(), 1);
  EXPECT_NE(other.err().find("not of 'gate-8'"), std::string::npos) << other.err();
}

TEST(AuthCliTest, OnlyTheTrackersSealedDatagramsAreAcceptedOverUdp) {
  ASSERT_TRUE(auth::Init());
  ScratchDir dir;
  const std::string keys = dir / "keys", other_site = dir / "other";
  for (const auto& args :
       std::vector<std::vector<std::string>>{{"keys", "init", "--dir", keys},
                                             {"keys", "derive", "--dir", keys, "s1"},
                                             {"keys", "init", "--dir", other_site},
                                             {"keys", "derive", "--dir", other_site, "s1"},
                                             {"keys", "derive", "--dir", other_site, "s9"}}) {
    Process p(LRFNET_TOOL_BINARY, args);
    ASSERT_EQ(p.Wait(), 0) << p.err();
  }
  std::ofstream(dir / "scene.yaml") << kAuthScenario;
  Process sim(LRFNET_TOOL_BINARY, {"sim", dir / "scene.yaml", "--out", dir / "sim"});
  ASSERT_EQ(sim.Wait(milliseconds(120'000)), 0) << sim.err();

  // The daemon, with the keys and a state directory.
  const std::vector<std::string> daemon_args = {
      "--listen",    "127.0.0.1:0",         "--keys", keys,          "--state-dir",
      dir / "state", "--status-interval-s", "0",      "--log-level", "warn"};
  auto with = [&](std::vector<std::string> args, const std::vector<std::string>& more) {
    args.insert(args.end(), more.begin(), more.end());
    return args;
  };
  auto daemon = std::make_unique<Process>(
      LRFNET_DAEMON_BINARY,
      with(daemon_args, {"--record", dir / "rec1", "--stats-out", dir / "stats1.json"}));
  ASSERT_TRUE(daemon->WaitForOutput("listening ", seconds(10))) << daemon->err();
  const std::string address = ListenAddress(*daemon);
  const std::uint16_t port = PortOf(address);

  // The tracker seals everything (encrypted) and answers only sealed Requests.
  Process tracker(LRFNET_TRACKER_BINARY,
                  {"--replay", dir / "sim/s1.pcap", "--sensor-id", "s1", "--key",
                   keys + "/sensor-s1-e1.key", "--encrypt", "--uplink", address, "--out",
                   dir / "tracker.rec", "--speed", "2", "--log-level", "warn"});
  ASSERT_EQ(tracker.Wait(milliseconds(60'000)), 0) << tracker.err();
  const std::vector<Bytes> sent = ReadAuthDatagrams(dir / "tracker.rec");
  ASSERT_GT(sent.size(), 100u);
  for (const Bytes& b : sent) ASSERT_TRUE(auth::LooksSealed(b));
  EXPECT_NE(tracker.out().find("requests_accepted="), std::string::npos);
  EXPECT_EQ(tracker.out().find("requests_accepted=0 "), std::string::npos)
      << "the daemon's sealed Requests were served: " << tracker.out();
  EXPECT_NE(tracker.out().find("requests_refused=0"), std::string::npos) << tracker.out();

  // The attacks, over UDP from other sockets.
  const auth::KeyFile s1 = ReadKey(keys + "/sensor-s1-e1.key");
  const auth::SensorKeys real = auth::DeriveSensorKeys(s1.key, 1);
  auth::Envelope e;
  ASSERT_EQ(auth::ParseEnvelope(sent.back(), &e), auth::HeaderError::kNone);
  const std::uint64_t next = e.counter + 1000;  // fresh counters: only the keys can refuse them
  const Bytes payload = UnsignedHealth("s1");
  std::map<std::string, std::uint64_t> expected;
  {
    auth::SensorKeys forged = real;  // the right header (epoch, key id), a made-up key
    forged.to_daemon.fill(0x5a);
    ASSERT_TRUE(SendUdp(port, SealWith("s1", forged, next, payload)));
    ++expected["bad_tag"];
    // A bit flipped on the way (in the payload; a fresh counter, so only the tag can tell).
    Bytes flipped = SealWith("s1", real, next + 3, payload);
    flipped[flipped.size() - 16 - 3] ^= 0x10;
    ASSERT_TRUE(SendUdp(port, flipped));
    ++expected["bad_tag"];
    auth::SensorKeys epoch2 = real;
    epoch2.epoch = 2;
    ASSERT_TRUE(SendUdp(port, SealWith("s1", epoch2, next + 1, payload)));
    ++expected["wrong_epoch"];
    const auth::KeyFile other = ReadKey(other_site + "/sensor-s1-e1.key");
    ASSERT_TRUE(
        SendUdp(port, SealWith("s1", auth::DeriveSensorKeys(other.key, 1), next + 2, payload)));
    ++expected["wrong_key"];
    const auth::KeyFile stranger = ReadKey(other_site + "/sensor-s9-e1.key");
    ASSERT_TRUE(SendUdp(
        port, SealWith("s9", auth::DeriveSensorKeys(stranger.key, 1), next, UnsignedHealth("s9"))));
    ++expected["unknown_sensor"];
    ASSERT_TRUE(SendUdp(port, payload));
    ++expected["unsigned"];
  }
  // The tracker's own recording sent again.
  Process replay(LRFNET_TOOL_BINARY,
                 {"replay", dir / "tracker.rec", "--to", address, "--speed", "0"});
  ASSERT_EQ(replay.Wait(milliseconds(30'000)), 0) << replay.err();
  expected["replayed"] += sent.size();
  std::this_thread::sleep_for(milliseconds(500));
  daemon->Signal(SIGINT);
  ASSERT_EQ(daemon->Wait(seconds(20)), 0) << daemon->err();
  const nlohmann::json stats = ReadAuthJson(dir / "stats1.json");
  ASSERT_TRUE(stats.is_object());
  EXPECT_TRUE(stats["authenticated"].get<bool>());
  EXPECT_EQ(stats["accepted"].get<std::uint64_t>(), sent.size()) << "only the tracker's datagrams";
  EXPECT_EQ(stats["verified"].get<std::uint64_t>(), sent.size());
  std::uint64_t total_expected = 0;
  for (const auto& [reason, n] : expected) {
    EXPECT_EQ(Refused(stats, reason), n) << reason << "\n" << stats.dump(1);
    total_expected += n;
  }
  EXPECT_EQ(stats["rejected"].get<std::uint64_t>(), total_expected) << stats.dump(1);
  ASSERT_EQ(stats["sensors"].size(), 1u) << "no sensor made up by a forged datagram";
  EXPECT_EQ(stats["sensors"][0]["sensor_id"], "s1");
  EXPECT_GE(stats["sensors"][0]["track_frames"].get<std::uint64_t>(), 100u);
  // The recording keeps everything received, refused or not.
  const std::vector<Bytes> recorded = ReadAuthDatagrams(dir / "rec1");
  EXPECT_EQ(recorded.size(), sent.size() + total_expected);

  // A restarted daemon (same state) refuses the earlier run's datagrams: yesterday's recording.
  daemon = std::make_unique<Process>(LRFNET_DAEMON_BINARY,
                                     with(daemon_args, {"--stats-out", dir / "stats2.json"}));
  ASSERT_TRUE(daemon->WaitForOutput("listening ", seconds(10))) << daemon->err();
  Process yesterday(LRFNET_TOOL_BINARY, {"replay", dir / "tracker.rec", "--to",
                                         ListenAddress(*daemon), "--speed", "0"});
  ASSERT_EQ(yesterday.Wait(milliseconds(30'000)), 0) << yesterday.err();
  std::this_thread::sleep_for(milliseconds(500));
  daemon->Signal(SIGINT);
  ASSERT_EQ(daemon->Wait(seconds(20)), 0) << daemon->err();
  const nlohmann::json stats2 = ReadAuthJson(dir / "stats2.json");
  EXPECT_EQ(stats2["accepted"].get<std::uint64_t>(), 0u) << stats2.dump(1);
  EXPECT_EQ(Refused(stats2, "stale"), sent.size()) << stats2.dump(1);

  // Offline readers. lrfnetd --input with the keys: what the live daemon accepted, no more.
  Process offline(LRFNET_DAEMON_BINARY, {"--input", dir / "rec1", "--keys", keys, "--stats-out",
                                         dir / "stats3.json", "--log-level", "warn"});
  EXPECT_EQ(offline.Wait(milliseconds(60'000)), 0) << offline.err();
  const nlohmann::json stats3 = ReadAuthJson(dir / "stats3.json");
  EXPECT_EQ(stats3["accepted"].get<std::uint64_t>(), sent.size()) << stats3.dump(1);
  EXPECT_EQ(Refused(stats3, "replayed"), sent.size());
  // Without keys: the encrypted datagrams cannot be read (and the daemon says so).
  Process keyless(LRFNET_DAEMON_BINARY, {"--input", dir / "tracker.rec", "--stats-out",
                                         dir / "stats4.json", "--log-level", "warn"});
  EXPECT_EQ(keyless.Wait(milliseconds(60'000)), 0) << keyless.err();
  EXPECT_NE(keyless.err().find(std::to_string(sent.size()) + " encrypted ones could not be read"),
            std::string::npos)
      << keyless.err();
  const nlohmann::json stats4 = ReadAuthJson(dir / "stats4.json");
  EXPECT_EQ(stats4["accepted"].get<std::uint64_t>(), 0u);
  EXPECT_EQ(Refused(stats4, "encrypted"), sent.size());
  // lrfnet dump: verified with keys; header only without.
  Process dump(LRFNET_TOOL_BINARY, {"dump", dir / "rec1", "--keys", keys, "--summary"});
  ASSERT_EQ(dump.Wait(), 0) << dump.err();
  const nlohmann::json summary = nlohmann::json::parse(dump.out(), nullptr, false);
  ASSERT_TRUE(summary.is_object()) << dump.out();
  EXPECT_EQ(summary["verified"].get<std::uint64_t>(), sent.size());
  EXPECT_EQ(summary["kinds"]["track_frame"].get<std::uint64_t>(),
            stats["sensors"][0]["track_frames"].get<std::uint64_t>());
  Process dump_plain(LRFNET_TOOL_BINARY, {"dump", dir / "tracker.rec"});
  ASSERT_EQ(dump_plain.Wait(), 0) << dump_plain.err();
  const nlohmann::json line = nlohmann::json::parse(FirstLine(dump_plain.out()), nullptr, false);
  ASSERT_TRUE(line.is_object()) << dump_plain.out().substr(0, 300);
  EXPECT_EQ(line["auth"]["sensor_id"], "s1");
  EXPECT_EQ(line["auth"]["encrypted"], true);
  EXPECT_EQ(line["auth"]["verified"], false);
  EXPECT_EQ(line["auth"]["error"], "encrypted");
  EXPECT_FALSE(line.contains("kind")) << "nothing of an encrypted payload without the key";
  // lrfnet replay --keys sends only what verifies: the attacker's datagrams stay behind.
  Process sink_daemon(LRFNET_DAEMON_BINARY,
                      {"--listen", "127.0.0.1:0", "--keys", keys, "--status-interval-s", "0",
                       "--stats-out", dir / "stats5.json", "--log-level", "warn"});
  ASSERT_TRUE(sink_daemon.WaitForOutput("listening ", seconds(10))) << sink_daemon.err();
  Process clean(LRFNET_TOOL_BINARY, {"replay", dir / "rec1", "--to", ListenAddress(sink_daemon),
                                     "--speed", "0", "--keys", keys});
  ASSERT_EQ(clean.Wait(milliseconds(30'000)), 0) << clean.err();
  EXPECT_NE(clean.out().find("refused=" + std::to_string(total_expected)), std::string::npos)
      << clean.out();
  std::this_thread::sleep_for(milliseconds(500));
  sink_daemon.Signal(SIGINT);
  ASSERT_EQ(sink_daemon.Wait(seconds(20)), 0);
  const nlohmann::json stats5 = ReadAuthJson(dir / "stats5.json");
  EXPECT_EQ(stats5["accepted"].get<std::uint64_t>(), sent.size()) << stats5.dump(1);
  EXPECT_EQ(stats5["rejected"].get<std::uint64_t>(), 0u) << stats5.dump(1);
}

}  // namespace
}  // namespace lrfnet::testing
