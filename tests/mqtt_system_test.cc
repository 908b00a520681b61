// lrfnetd's MQTT output end to end, against a real mosquitto on a free loopback port: a short
// simulated scene (`lrfnet sim` -> `lrfnet-tracker --replay` per sensor) runs through lrfnetd
// (offline with --input, and live with `lrfnet replay` while the broker restarts); subscribers are
// libmosquitto and mosquitto_sub. The objects are checked against the simulator's truth, the zone
// counts against the people's paths (crossings counted exactly and in the right direction, a
// person walking along the line counted once), and every message against the JSON Schemas.

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "tests/mosquitto_broker.h"
#include "tests/mqtt_subscriber.h"
#include "tests/node_clients.h"
#include "tests/process_harness.h"
#include "tests/support/udp_peer.h"

namespace lrfnet {
namespace {

using nlohmann::json;
using std::chrono::milliseconds;
using testing::MosquittoBroker;
using testing::MqttSubscriber;
using testing::Process;
using testing::ReadText;
using testing::ReceivedMessage;
using testing::ScratchDir;

// A 12 x 8 m room with a doorway in its west wall (y 4.8 .. 6.2), two LMS111 in opposite
// corners, a door line at x = 6 (from (6, 1) to (6, 7): its left side, the inbound side, is
// x < 6) and a "lobby" area in the south-east. People leave the room through the doorway and out
// of the sensors' view, as people do (a simulated target vanishes where its path ends).
//   p1 walks west -> east across the door line (outbound) into the lobby and stands there until
//      the end;
//   p2 walks east -> west across the door line (inbound) and out through the doorway;
//   p3 starts in the lobby, walks to the door line, then 4.7 m *along* it (on the line), then west
//      (one inbound crossing; one lobby exit);
//   p4 comes to 0.7 m of the door line, turns back and heads for the doorway (no crossing).
// The trackers learn their background for the first 5 s: people come after that.
constexpr const char* kScenario = R"(name: mqtt_door
seed: 5
duration_s: 20
truth_rate_hz: 20
world:
  walls: [[[0, 4.8], [0, 0], [12, 0], [12, 8], [0, 8], [0, 6.2]]]
  obstacles: [[[0.2, 7.0], [0.8, 7.0], [0.8, 7.6], [0.2, 7.6]], [[11.2, 0.3], [11.7, 0.3], [11.7, 1.0], [11.2, 1.0]]]
  bounds: [[-3, -0.5], [12.5, 8.5]]
sensors:
  - {id: s1, model: lms111, x_m: 0.3, y_m: 0.3, yaw_deg: 35}
  - {id: s2, model: lms111, x_m: 11.7, y_m: 7.7, yaw_deg: -145}
targets:
  - {id: p1, shape: person, path: [[2, 3], [10, 3]], speed_mps: 1.2, enter_s: 6, stay: true}
  - {id: p2, shape: person, path: [[10.5, 5.5], [-1, 5.5], [-1.5, 2]], speed_mps: 1.2, enter_s: 7.5}
  - {id: p3, shape: person, path: [[9, 1.8], [6.05, 1.8], [6.05, 6.5], [3, 6.5], [0.5, 5.5]], speed_mps: 1.2, enter_s: 9.5}
  - {id: p4, shape: person, path: [[3, 4.3], [5.3, 4.3], [3, 4.3], [0.5, 5.2], [-1, 5.2]], speed_mps: 1.0, enter_s: 11.5}
)";

constexpr const char* kDaemonConfig = R"(zones:
  list:
    - {name: door, line: [[6, 1], [6, 7]]}
    - {name: lobby, polygon: [[7, 0.5], [11.5, 0.5], [11.5, 4], [7, 4]]}
mqtt:
  objects_hz: 5
  path_points: 5
  health_interval_s: 1
)";

struct TruthRow {
  double t_s;
  std::int64_t utc_ns;
  std::string target;
  double x_m, y_m, vx_mps, vy_mps;
};

std::vector<TruthRow> ReadTruth(const std::string& path) {
  std::vector<TruthRow> rows;
  std::istringstream in(ReadText(path));
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    std::vector<std::string> f;
    std::stringstream cells(line);
    for (std::string c; std::getline(cells, c, ',');) f.push_back(c);
    if (f.size() < 8) continue;
    rows.push_back({std::stod(f[0]), std::stoll(f[1]), f[2], std::stod(f[3]), std::stod(f[4]),
                    std::stod(f[6]), std::stod(f[7])});
  }
  return rows;
}

// What the paths say, without the zones code: per target its first and last position.
struct ExpectedCounts {
  int door_inbound = 0, door_outbound = 0, lobby_inbound = 0, lobby_outbound = 0, lobby_end = 0,
      lobby_vanished = 0;
};
bool InLobby(double x, double y) { return x > 7 && x < 11.5 && y > 0.5 && y < 4; }
// A path without loop ends where its target leaves the scene (the simulator's rule): who is
// still there at the end is in the last rows. Targets "pN" and "pN_..." are one person.
std::string PersonOf(const std::string& target) { return target.substr(0, target.find('_')); }
ExpectedCounts FromTruth(const std::vector<TruthRow>& rows) {
  double end_s = 0.0;
  for (const TruthRow& r : rows) end_s = std::max(end_s, r.t_s);
  std::map<std::string, std::pair<const TruthRow*, const TruthRow*>> ends;
  for (const TruthRow& r : rows) {
    auto [it, inserted] = ends.try_emplace(PersonOf(r.target), &r, &r);
    if (r.t_s < it->second.first->t_s) it->second.first = &r;
    if (r.t_s >= it->second.second->t_s) it->second.second = &r;
  }
  ExpectedCounts e;
  for (const auto& [id, fl] : ends) {
    const TruthRow& first = *fl.first;
    const TruthRow& last = *fl.second;
    if (first.x_m > 6 && last.x_m < 6) ++e.door_inbound;
    if (first.x_m < 6 && last.x_m > 6) ++e.door_outbound;
    if (!InLobby(first.x_m, first.y_m) && InLobby(last.x_m, last.y_m)) ++e.lobby_inbound;
    if (InLobby(first.x_m, first.y_m) && !InLobby(last.x_m, last.y_m)) ++e.lobby_outbound;
    if (InLobby(last.x_m, last.y_m)) ++(last.t_s >= end_s - 0.1 ? e.lobby_end : e.lobby_vanished);
  }
  return e;
}

// The scene and its trackers' recordings, made once.
class MqttSystem : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new ScratchDir();
    std::ofstream(*dir_ / "scene.yaml") << kScenario;
    std::ofstream(*dir_ / "lrfnetd.yaml") << kDaemonConfig;
    Process sim(LRFNET_TOOL_BINARY,
                {"sim", *dir_ / "scene.yaml", "--out", *dir_ / "sim", "--jobs", "2"});
    ASSERT_EQ(sim.Wait(milliseconds(120'000)), 0) << sim.err();
    for (const char* id : {"s1", "s2"}) {
      Process tracker(LRFNET_TRACKER_BINARY,
                      {"--replay", *dir_ / ("sim/" + std::string(id) + ".pcap"), "--sensor-id", id,
                       "--out", *dir_ / (std::string(id) + ".rec"), "--log-level", "warn"});
      ASSERT_EQ(tracker.Wait(milliseconds(60'000)), 0) << tracker.err();
    }
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  void SetUp() override {
    if (!testing::HaveBinary(testing::kMosquitto) || !testing::HaveBinary(testing::kMosquittoSub))
      GTEST_SKIP() << "mosquitto / mosquitto-clients are not installed (scripts/install_deps.sh)";
  }
  static ScratchDir* dir_;
};
ScratchDir* MqttSystem::dir_ = nullptr;

std::string SchemaOf(const std::string& topic) {
  if (topic.ends_with("/objects")) return "mqtt_objects.schema.json";
  if (topic.ends_with("/objects/ended")) return "mqtt_objects_ended.schema.json";
  if (topic.find("/zones/") != std::string::npos) return "mqtt_zone.schema.json";
  if (topic.ends_with("/calibration")) return "mqtt_calibration.schema.json";
  if (topic.ends_with("/health")) return "mqtt_sensor_health.schema.json";
  if (topic.ends_with("/status")) return "mqtt_status.schema.json";
  return "unknown";
}

json Parse(const std::string& text) { return json::parse(text, nullptr, false); }

// Position of `target` at utc_ns from the truth (nearest row), or nothing when absent then.
const TruthRow* TruthAt(const std::vector<TruthRow>& rows, const std::string& target,
                        std::int64_t utc_ns) {
  const TruthRow* best = nullptr;
  for (const TruthRow& r : rows) {
    if (r.target != target) continue;
    if (best == nullptr || std::llabs(r.utc_ns - utc_ns) < std::llabs(best->utc_ns - utc_ns))
      best = &r;
  }
  return best != nullptr && std::llabs(best->utc_ns - utc_ns) <= 60'000'000 ? best : nullptr;
}

TEST_F(MqttSystem, OfflineObjectsAndZoneCountsMatchTheTruthAndEveryMessageItsSchema) {
  MosquittoBroker broker;
  ASSERT_TRUE(broker.Start());
  MqttSubscriber subscriber(broker.port(), "lrfnet/lab/#");
  ASSERT_TRUE(subscriber.WaitSubscribed());
  Process sub(testing::kMosquittoSub, {"-h", "127.0.0.1", "-p", std::to_string(broker.port()), "-t",
                                       "lrfnet/lab/zones/#", "-v", "-q", "1"});
  testing::LoopbackUdpPeer udp;
  ScratchDir out;
  Process daemon(
      LRFNET_DAEMON_BINARY,
      {"--input", *dir_ / "s1.rec", *dir_ / "s2.rec", "--calibration-in", *dir_ / "sim/truth.yaml",
       "--config", *dir_ / "lrfnetd.yaml", "--mqtt", broker.address(), "--mqtt-site", "lab",
       "--fused-out", out / "fused.jsonl", "--fused-udp", "127.0.0.1:" + std::to_string(udp.port()),
       "--stats-out", out / "stats.json"});
  ASSERT_EQ(daemon.Wait(milliseconds(120'000)), 0) << daemon.err();
  const json stats = Parse(ReadText(out / "stats.json"));
  ASSERT_TRUE(stats.contains("mqtt")) << stats.dump();
  const json& m = stats["mqtt"];
  // The fuser's lists hold nothing the id follower cannot follow (exported, all 0).
  for (const char* key : {"objects_duplicates", "objects_merge_cycles", "objects_merge_chains_cut",
                          "objects_merges_into_ended"}) {
    ASSERT_TRUE(m.contains(key)) << key;
    EXPECT_EQ(m[key], 0) << key;
  }
  // Offline the daemon waits for the broker instead of dropping.
  EXPECT_EQ(m["dropped_queue_full"], 0);
  EXPECT_EQ(m["dropped_disconnected"], 0);
  EXPECT_EQ(m["unsent"], 0);
  // Everything was sent, except retained states replaced by a newer one before they could go.
  EXPECT_EQ(m["sent"].get<std::uint64_t>() + m["retained_replaced"].get<std::uint64_t>(),
            m["submitted"].get<std::uint64_t>());
  ASSERT_TRUE(subscriber.WaitFor([&](const std::vector<ReceivedMessage>& got) {
    return got.size() >= m["sent"].get<std::size_t>();
  })) << subscriber.messages().size()
      << " of " << m["sent"];

  // Zones: the final state of each (retained, cumulative) against the paths.
  const ExpectedCounts expected = FromTruth(ReadTruth(*dir_ / "sim/truth_tracks.csv"));
  ASSERT_EQ(expected.door_inbound, 2);
  ASSERT_EQ(expected.door_outbound, 1);
  ASSERT_EQ(expected.lobby_end, 1);
  const auto door = subscriber.On("lrfnet/lab/zones/door");
  const auto lobby = subscriber.On("lrfnet/lab/zones/lobby");
  ASSERT_FALSE(door.empty());
  ASSERT_FALSE(lobby.empty());
  const json door_end = Parse(door.back().payload);
  const json lobby_end = Parse(lobby.back().payload);
  EXPECT_EQ(door_end["kind"], "line");
  EXPECT_EQ(door_end["inbound"], expected.door_inbound) << door_end.dump();
  EXPECT_EQ(door_end["outbound"], expected.door_outbound) << door_end.dump();
  EXPECT_EQ(lobby_end["inbound"], expected.lobby_inbound) << lobby_end.dump();
  EXPECT_EQ(lobby_end["outbound"], expected.lobby_outbound) << lobby_end.dump();
  EXPECT_EQ(lobby_end["occupancy"], expected.lobby_end) << lobby_end.dump();
  EXPECT_EQ(lobby_end["lost_inside"], expected.lobby_vanished) << lobby_end.dump();
  // Counts only ever grow, one at a time per update.
  int last_in = 0;
  for (const ReceivedMessage& r : door) {
    const int in = Parse(r.payload)["inbound"].get<int>();
    EXPECT_GE(in, last_in);
    last_in = in;
  }

  // mosquitto_sub saw the same zone states (the last one of each topic).
  sub.Signal(SIGINT);
  sub.Wait();
  std::map<std::string, std::string> last_by_topic;
  std::istringstream lines(sub.out());
  for (std::string line; std::getline(lines, line);) {
    const std::size_t space = line.find(' ');
    if (space != std::string::npos) last_by_topic[line.substr(0, space)] = line.substr(space + 1);
  }
  EXPECT_EQ(last_by_topic["lrfnet/lab/zones/door"], door.back().payload);
  EXPECT_EQ(last_by_topic["lrfnet/lab/zones/lobby"], lobby.back().payload);

  // Objects against the truth: every confirmed object near a person present then, and most of
  // the time one object per person in view.
  const std::vector<TruthRow> truth = ReadTruth(*dir_ / "sim/truth_tracks.csv");
  const auto objects = subscriber.On("lrfnet/lab/objects");
  ASSERT_GT(objects.size(), 60u);  // 20 s at 5 Hz, from the first fused frame on
  std::set<std::string> targets;
  for (const TruthRow& r : truth) targets.insert(r.target);
  std::size_t checked = 0, near = 0, count_matches = 0, messages = 0, velocity_ok = 0;
  std::string far_examples;
  std::uint64_t last_seq = 0;
  for (const ReceivedMessage& r : objects) {
    const json j = Parse(r.payload);
    ASSERT_TRUE(j.is_object());
    EXPECT_EQ(j["seq"].get<std::uint64_t>(), last_seq + 1);
    last_seq = j["seq"].get<std::uint64_t>();
    const std::int64_t stamp = j["stamp_ns"].get<std::int64_t>();
    // Everybody in the scene then; those in the room (beyond the doorway the walls hide them).
    std::vector<const TruthRow*> present;
    std::size_t in_room = 0;
    for (const std::string& id : targets) {
      const TruthRow* t = TruthAt(truth, id, stamp);
      if (t == nullptr) continue;
      present.push_back(t);
      in_room += t->x_m > 0.3 ? 1 : 0;
    }
    std::size_t confirmed = 0;
    for (const json& o : j["objects"]) {
      if (o["state"] != "confirmed") continue;
      confirmed += o["x_m"].get<double>() > 0.3 ? 1 : 0;
      ++checked;
      double best = 1e9;
      const TruthRow* match = nullptr;
      for (const TruthRow* t : present) {
        const double d =
            std::hypot(o["x_m"].get<double>() - t->x_m, o["y_m"].get<double>() - t->y_m);
        if (d < best) {
          best = d;
          match = t;
        }
      }
      near += best < 0.5 ? 1 : 0;
      if (best >= 0.5 && far_examples.size() < 1000) {
        far_examples +=
            "\n  t=" + std::to_string(static_cast<double>(stamp - truth.front().utc_ns) * 1e-9) +
            " id " + std::to_string(o["id"].get<int>()) + " at (" +
            std::to_string(o["x_m"].get<double>()) + ", " + std::to_string(o["y_m"].get<double>()) +
            ") nearest person " + (match ? match->target : "none") + " " + std::to_string(best) +
            " m";
      }
      if (match != nullptr && std::hypot(o["vx_mps"].get<double>() - match->vx_mps,
                                         o["vy_mps"].get<double>() - match->vy_mps) < 0.5)
        ++velocity_ok;
      EXPECT_FALSE(o["sensors"].empty());
      EXPECT_LE(o["path"].size(), 5u);
    }
    ++messages;
    count_matches += confirmed == in_room ? 1 : 0;
  }
  ASSERT_GT(checked, 100u);
  std::printf(
      "objects: %zu confirmed positions, %zu within 0.5 m of a person, %zu with velocity "
      "within 0.5 m/s; %zu of %zu lists with one object per person in the room\n",
      checked, near, velocity_ok, count_matches, messages);
  const auto fraction = [](std::size_t a, std::size_t b) {
    return static_cast<double>(a) / static_cast<double>(b);
  };
  EXPECT_GE(fraction(near, checked), 0.95) << near << " of " << checked << far_examples;
  EXPECT_GE(fraction(velocity_ok, checked), 0.8) << velocity_ok << " of " << checked;
  EXPECT_GE(fraction(count_matches, messages), 0.7) << count_matches << " of " << messages;

  // Calibration (retained), health of both sensors, status online then offline (a clean stop).
  ASSERT_FALSE(subscriber.On("lrfnet/lab/calibration").empty());
  EXPECT_EQ(Parse(subscriber.On("lrfnet/lab/calibration").back().payload)["sensors"].size(), 2u);
  for (const char* id : {"s1", "s2"}) {
    const auto health = subscriber.On("lrfnet/lab/sensors/" + std::string(id) + "/health");
    ASSERT_FALSE(health.empty()) << id;
    EXPECT_EQ(Parse(health.back().payload)["state"], "active");
    EXPECT_TRUE(Parse(health.back().payload)["placed"].get<bool>());
  }
  const auto status = subscriber.On("lrfnet/lab/status");
  ASSERT_GE(status.size(), 2u);
  EXPECT_EQ(Parse(status.front().payload)["state"], "online");
  EXPECT_EQ(Parse(status.back().payload)["state"], "offline");

  // Every message of every kind against its schema: MQTT, JSON lines, UDP datagrams.
  const std::string missing = testing::NodeClientsMissing();
  if (!missing.empty()) GTEST_SKIP() << "schema validation skipped: " << missing;
  std::vector<std::pair<std::string, std::string>> all;
  for (const ReceivedMessage& r : subscriber.messages())
    all.emplace_back(SchemaOf(r.topic), r.payload);
  std::istringstream fused(ReadText(out / "fused.jsonl"));
  std::size_t fused_lines = 0;
  for (std::string line; std::getline(fused, line); ++fused_lines)
    all.emplace_back("fused.schema.json", line);
  EXPECT_GT(fused_lines, 50u);
  std::size_t datagrams = 0;
  for (std::vector<std::uint8_t> d; !(d = udp.Receive(200)).empty(); ++datagrams) {
    all.emplace_back("fused.schema.json", std::string(d.begin(), d.end()));
  }
  EXPECT_GT(datagrams, 50u);
  bool ok = false;
  const std::string report = testing::ValidateJsonMessages(all, out / "messages.tsv", &ok);
  EXPECT_TRUE(ok) << report;
}

// A daemon that computed a calibration and one started later from the calibration.yaml it wrote
// publish the same calibration: poses, sigmas, each sensor's radial bias, the mount verdict.
TEST_F(MqttSystem, ACalibrationReadFromItsFileIsPublishedAsTheDaemonThatComputedIt) {
  MosquittoBroker broker;
  ASSERT_TRUE(broker.Start());
  MqttSubscriber subscriber(broker.port(), "lrfnet/+/calibration");
  ASSERT_TRUE(subscriber.WaitSubscribed());
  ScratchDir out;
  Process computing(LRFNET_DAEMON_BINARY,
                    {"--input", *dir_ / "s1.rec", *dir_ / "s2.rec", "--config",
                     *dir_ / "lrfnetd.yaml", "--calibration-out", out / "calibration.yaml",
                     "--mqtt", broker.address(), "--mqtt-site", "computed"});
  ASSERT_EQ(computing.Wait(milliseconds(120'000)), 0) << computing.err();
  Process loading(LRFNET_DAEMON_BINARY,
                  {"--input", *dir_ / "s1.rec", *dir_ / "s2.rec", "--config",
                   *dir_ / "lrfnetd.yaml", "--calibration-in", out / "calibration.yaml", "--mqtt",
                   broker.address(), "--mqtt-site", "loaded"});
  ASSERT_EQ(loading.Wait(milliseconds(120'000)), 0) << loading.err();
  ASSERT_TRUE(subscriber.WaitFor([](const std::vector<ReceivedMessage>& got) {
    return std::count_if(got.begin(), got.end(),
                         [](const ReceivedMessage& r) {
                           return r.topic.find("/loaded/") != std::string::npos;
                         }) > 0 &&
           std::count_if(got.begin(), got.end(), [](const ReceivedMessage& r) {
             return r.topic.find("/computed/") != std::string::npos;
           }) > 0;
  }));
  const json computed = Parse(subscriber.On("lrfnet/computed/calibration").back().payload);
  const json loaded = Parse(subscriber.On("lrfnet/loaded/calibration").back().payload);
  ASSERT_EQ(computed["sensors"].size(), 2u) << computed.dump(1);
  ASSERT_EQ(loaded["sensors"].size(), 2u) << loaded.dump(1);
  EXPECT_EQ(loaded["reference"], computed["reference"]);
  EXPECT_GT(computed["track_residual_rms_m"].get<double>(), 0.0) << computed.dump();
  EXPECT_NEAR(loaded["track_residual_rms_m"].get<double>(),
              computed["track_residual_rms_m"].get<double>(), 1.1e-4);
  std::printf("computed: %s\nloaded:   %s\n", computed["sensors"].dump().c_str(),
              loaded["sensors"].dump().c_str());
  for (std::size_t i = 0; i < 2; ++i) {
    const json& c = computed["sensors"][i];
    const json& l = loaded["sensors"][i];
    const std::string id = c["id"].get<std::string>();
    EXPECT_EQ(l["id"], c["id"]);
    ASSERT_EQ(c["calibrated"], true) << c.dump();
    EXPECT_EQ(l["calibrated"], true) << id;
    for (const char* key : {"x_m", "y_m", "yaw_deg"}) EXPECT_EQ(l[key], c[key]) << id << " " << key;
    // The file keeps six digits of the sigmas; the message rounds to 1e-5.
    for (const char* key : {"sigma_x_m", "sigma_y_m", "sigma_yaw_deg", "sigma_radial_bias_m"}) {
      ASSERT_TRUE(c[key].is_number()) << id << " " << key << ": " << c.dump();
      ASSERT_TRUE(l[key].is_number()) << id << " " << key << ": " << l.dump();
      EXPECT_NEAR(l[key].get<double>(), c[key].get<double>(), 1.1e-5) << id << " " << key;
    }
    EXPECT_EQ(l["radial_bias_m"], c["radial_bias_m"]) << id;
    EXPECT_EQ(l["radial_bias_estimated"], c["radial_bias_estimated"]) << id;
    EXPECT_EQ(l["mount_looks_like_legs"], c["mount_looks_like_legs"]) << id;
    EXPECT_EQ(l["flag"], c["flag"]) << id;
    // The sensor that is not the reference has an uncertainty to carry.
    if (id != computed["reference"]) {
      EXPECT_GT(l["sigma_x_m"].get<double>() + l["sigma_y_m"].get<double>(), 0.0) << l.dump();
      EXPECT_GT(l["sigma_yaw_deg"].get<double>(), 0.0) << l.dump();
    }
    EXPECT_GT(l["sigma_radial_bias_m"].get<double>(), 0.0) << l.dump();
  }
}

TEST_F(MqttSystem, LiveBrokerRestartPublishingResumesAndTheLossIsCounted) {
  MosquittoBroker broker;
  ASSERT_TRUE(broker.Start());
  ScratchDir out;
  Process daemon(LRFNET_DAEMON_BINARY,
                 {"--listen", "127.0.0.1:0", "--calibration-in", *dir_ / "sim/truth.yaml",
                  "--config", *dir_ / "lrfnetd.yaml", "--mqtt", broker.address(), "--mqtt-site",
                  "lab", "--stats-out", out / "stats.json", "--status-interval-s", "1"});
  ASSERT_TRUE(daemon.WaitForOutput("listening ", milliseconds(20'000))) << daemon.err();
  const std::string out_text = daemon.out();
  const std::string address = out_text.substr(
      out_text.find("listening ") + 10,
      out_text.find('\n', out_text.find("listening ")) - out_text.find("listening ") - 10);
  auto subscriber = std::make_unique<MqttSubscriber>(broker.port(), "lrfnet/lab/#");
  ASSERT_TRUE(subscriber->WaitSubscribed());
  // At twice the recorded pace (the daemon fuses on the scans' own times).
  Process replay1(LRFNET_TOOL_BINARY,
                  {"replay", *dir_ / "s1.rec", "--to", address, "--speed", "2"});
  Process replay2(LRFNET_TOOL_BINARY,
                  {"replay", *dir_ / "s2.rec", "--to", address, "--speed", "2"});
  // Objects flow; then the broker goes away for a while and comes back empty.
  ASSERT_TRUE(subscriber->WaitFor([](const auto& got) {
    return std::count_if(got.begin(), got.end(), [](const ReceivedMessage& r) {
             return r.topic == "lrfnet/lab/objects";
           }) >= 5;
  }));
  std::uint64_t seq_before = 0;
  for (const ReceivedMessage& r : subscriber->On("lrfnet/lab/objects"))
    seq_before = std::max(seq_before, Parse(r.payload)["seq"].get<std::uint64_t>());
  subscriber.reset();
  broker.Stop();
  std::this_thread::sleep_for(milliseconds(1500));
  ASSERT_TRUE(broker.Start());
  subscriber = std::make_unique<MqttSubscriber>(broker.port(), "lrfnet/lab/#");
  ASSERT_TRUE(subscriber->WaitSubscribed());
  // Retained state is there again at once (sent again after the reconnect), then new objects.
  ASSERT_TRUE(subscriber->WaitFor([&](const auto& got) {
    return std::any_of(got.begin(), got.end(), [&](const ReceivedMessage& r) {
      return r.topic == "lrfnet/lab/objects" &&
             Parse(r.payload)["seq"].get<std::uint64_t>() > seq_before + 3;
    });
  })) << daemon.err();
  EXPECT_FALSE(subscriber->On("lrfnet/lab/calibration").empty());
  EXPECT_FALSE(subscriber->On("lrfnet/lab/status").empty());
  EXPECT_EQ(replay1.Wait(milliseconds(60'000)), 0) << replay1.err();
  EXPECT_EQ(replay2.Wait(milliseconds(60'000)), 0) << replay2.err();
  daemon.Signal(SIGINT);
  ASSERT_EQ(daemon.Wait(milliseconds(30'000)), 0) << daemon.err();

  const json stats = Parse(ReadText(out / "stats.json"));
  ASSERT_TRUE(stats.contains("mqtt")) << stats.dump();
  const json& m = stats["mqtt"];
  EXPECT_GE(m["disconnects"].get<int>(), 1) << m.dump();
  EXPECT_GE(m["connects"].get<int>(), 2) << m.dump();
  EXPECT_GE(m["connect_failures"].get<int>(), 1) << m.dump();
  // About 1.5 s (3 s of scene time) of object lists at 5 Hz could not be sent: counted, not lost
  // silently.
  EXPECT_GE(m["dropped_disconnected"].get<int>() + m["lost_in_flight"].get<int>(), 3) << m.dump();
  EXPECT_EQ(m["submitted"].get<std::uint64_t>(),
            m["sent"].get<std::uint64_t>() + m["dropped_disconnected"].get<std::uint64_t>() +
                m["dropped_queue_full"].get<std::uint64_t>() +
                m["lost_in_flight"].get<std::uint64_t>() +
                m["retained_replaced"].get<std::uint64_t>() +
                m["publish_errors"].get<std::uint64_t>() + m["unsent"].get<std::uint64_t>())
      << m.dump();
  // Zone counts survive the restart: cumulative since the daemon started.
  const ExpectedCounts expected = FromTruth(ReadTruth(*dir_ / "sim/truth_tracks.csv"));
  const auto door = subscriber->On("lrfnet/lab/zones/door");
  ASSERT_FALSE(door.empty());
  EXPECT_EQ(Parse(door.back().payload)["inbound"], expected.door_inbound) << door.back().payload;
  EXPECT_EQ(Parse(door.back().payload)["outbound"], expected.door_outbound) << door.back().payload;
}

TEST_F(MqttSystem, TheBrokerPublishesTheLastWillWhenTheDaemonDies) {
  MosquittoBroker broker;
  ASSERT_TRUE(broker.Start());
  MqttSubscriber subscriber(broker.port(), "lrfnet/will/status");
  ASSERT_TRUE(subscriber.WaitSubscribed());
  Process daemon(LRFNET_DAEMON_BINARY,
                 {"--listen", "127.0.0.1:0", "--mqtt", broker.address(), "--mqtt-site", "will"});
  ASSERT_TRUE(subscriber.WaitFor([](const auto& got) {
    return !got.empty() && Parse(got.back().payload)["state"] == "online";
  })) << daemon.err();
  daemon.Signal(SIGKILL);
  daemon.Wait();
  ASSERT_TRUE(subscriber.WaitFor(
      [](const auto& got) { return Parse(got.back().payload)["state"] == "offline"; }));
  const json will = Parse(subscriber.messages().back().payload);
  EXPECT_FALSE(will.contains("stamp_ns"));  // the will, not a clean stop
  EXPECT_EQ(will["site"], "will");
}

}  // namespace
}  // namespace lrfnet
