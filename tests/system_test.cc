// The whole chain as processes on loopback, like the demo: `lrfnet sim --serve` (one emulated SICK
// device per sensor, CoLa-B over TCP) → one `lrfnet-tracker` per device (tracks over UDP) →
// `lrfnetd` (collects, calibrates by itself, fuses, serves the live view), with authenticated
// datagrams: a site key, one key per sensor (`lrfnet keys`), trackers with --key, the daemon with
// --keys. One tracker is killed and restarted while the daemon fuses, and later one sensor is
// bumped (turned by 3 degrees, pushed 9 cm): the daemon must flag it, show it as moved, keep it out
// of the fused output and correct its pose. Asserts the calibration against the simulator's truth
// (the pose after the bump), the continuity of the fused tracks, and the live view's state.

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <csignal>
#include <fstream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "tests/process_harness.h"

namespace lrfnet::testing {
namespace {

using std::chrono::milliseconds;
using std::chrono::seconds;

// A 12 x 8 m room, three TiM561 (10 m, 15 Hz) in three corners, two people walking loops the
// whole time, a cabinet for the background; s3 is bumped at kMoveS (the daemon calibrates after
// about 15 s, then a tracker is restarted). The scenario lasts long enough for the correction
// (kCorrectedWithinS); it is stopped as soon as the live view shows s3 fused again.
constexpr double kMoveS = 32.0;
constexpr double kCorrectedWithinS = 22.0;
constexpr const char* kScenario = R"(name: system_room
seed: 5
duration_s: 56
world:
  walls:
    - [[0, 0], [12, 0], [12, 8], [0, 8], [0, 0]]
  obstacles:
    - [[5.5, 7.0], [7.5, 7.0], [7.5, 7.6], [5.5, 7.6]]
sensors:
  - {id: s1, model: tim561, x_m: 0.3, y_m: 0.3, yaw_deg: 40}
  - {id: s2, model: tim561, x_m: 11.7, y_m: 0.3, yaw_deg: 140}
  - {id: s3, model: tim561, x_m: 11.7, y_m: 7.7, yaw_deg: -140,
     moves: [{at_s: 32, x_m: 11.64, y_m: 7.63, yaw_deg: -137}]}
targets:
  - {shape: person, a_m: 0.25, b_m: 0.15, path: [[2.5, 2], [9.5, 2], [9.5, 5.5], [2.5, 5.5]], speed_mps: 1.2, loop: true}
  - {shape: person, a_m: 0.22, b_m: 0.14, path: [[4, 3.5], [8.5, 3.5], [6.5, 6]], speed_mps: 1.0, loop: true}
)";

constexpr double kSpeed = 1.0;  // scenario seconds per wall-clock second (faster: people "run")

std::vector<std::pair<std::string, std::string>> Devices(const std::string& sim_out) {
  std::vector<std::pair<std::string, std::string>> out;
  std::istringstream in(sim_out);
  for (std::string line; std::getline(in, line);) {
    const auto space = line.find(' ');
    if (space == std::string::npos || line.find(':', space) == std::string::npos) continue;
    out.emplace_back(line.substr(0, space), line.substr(space + 1));
  }
  return out;
}

// GET `path` from 127.0.0.1:port; the body, or "" on failure.
std::string HttpGet(std::uint16_t port, const std::string& path) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return "";
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(port);
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  timeval timeout{5, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof timeout);
  std::string response;
  if (::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0) {
    const std::string request =
        "GET " + path + " HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n";
    if (::send(fd, request.data(), request.size(), 0) == static_cast<ssize_t>(request.size())) {
      char buffer[65536];
      for (ssize_t n; (n = ::recv(fd, buffer, sizeof buffer, 0)) > 0;) {
        response.append(buffer, static_cast<std::size_t>(n));
      }
    }
  }
  ::close(fd);
  const auto body = response.find("\r\n\r\n");
  if (response.rfind("HTTP/1.1 200", 0) != 0 || body == std::string::npos) return "";
  return response.substr(body + 4);
}

TEST(SystemTest, SimTrackersDaemonCalibrateFuseSurviveATrackerRestartAndCorrectABumpedSensor) {
  ScratchDir dir;
  {
    std::ofstream scenario(dir / "scenario.yaml");
    scenario << kScenario;
  }
  {
    std::ofstream config(dir / "lrfnetd.yaml");
    config << "status:\n  interval_s: 1.0\n"
              "calibration:\n  attempt_interval_s: 2.0\n  min_pair_overlap_s: 8.0\n"
              "fusion:\n  publish_hz: 10.0\n";
  }
  // The keys: the site's and one per sensor.
  {
    Process init(LRFNET_TOOL_BINARY, {"keys", "init", "--dir", dir / "keys"});
    ASSERT_EQ(init.Wait(), 0) << init.err();
    for (const char* id : {"s1", "s2", "s3"}) {
      Process derive(LRFNET_TOOL_BINARY, {"keys", "derive", "--dir", dir / "keys", id});
      ASSERT_EQ(derive.Wait(), 0) << derive.err();
    }
  }
  Process sim(LRFNET_TOOL_BINARY, {"sim", dir / "scenario.yaml", "--serve", "--speed",
                                   std::to_string(kSpeed), "--out", dir / "sim", "--log-level",
                                   "warn"});
  ASSERT_TRUE(sim.WaitForOutput("s3 ", seconds(10))) << sim.err();
  std::this_thread::sleep_for(milliseconds(100));
  const auto devices = Devices(sim.out());
  ASSERT_EQ(devices.size(), 3u) << sim.out();

  // The fused-track stream's receiver: a UDP socket on a free port.
  const int fused_socket = ::socket(AF_INET, SOCK_DGRAM, 0);
  ASSERT_GE(fused_socket, 0);
  sockaddr_in fused_address{};
  fused_address.sin_family = AF_INET;
  fused_address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t fused_length = sizeof fused_address;
  ASSERT_EQ(::bind(fused_socket, reinterpret_cast<sockaddr*>(&fused_address), sizeof fused_address),
            0);
  ASSERT_EQ(::getsockname(fused_socket, reinterpret_cast<sockaddr*>(&fused_address), &fused_length),
            0);
  const std::string fused_udp = "127.0.0.1:" + std::to_string(ntohs(fused_address.sin_port));

  Process daemon(LRFNET_DAEMON_BINARY,
                 {"--listen", "127.0.0.1:0", "--config", dir / "lrfnetd.yaml", "--calibration-out",
                  dir / "calibration.yaml", "--fused-out", dir / "fused.jsonl", "--fused-udp",
                  fused_udp, "--live-view", "127.0.0.1:0", "--stats-out", dir / "stats.json",
                  "--keys", dir / "keys", "--state-dir", dir / "state"});
  ASSERT_TRUE(daemon.WaitForOutput("live view http://", seconds(10))) << daemon.err();
  std::string uplink, live_port;
  {
    std::istringstream in(daemon.out());
    for (std::string line; std::getline(in, line);) {
      if (line.rfind("listening ", 0) == 0) uplink = line.substr(10);
      if (line.rfind("live view http://127.0.0.1:", 0) == 0) {
        live_port = line.substr(27, line.size() - 28);
      }
    }
  }
  ASSERT_FALSE(uplink.empty()) << daemon.out();
  ASSERT_FALSE(live_port.empty()) << daemon.out();

  auto start_tracker = [&](const std::pair<std::string, std::string>& device) {
    return std::make_unique<Process>(
        LRFNET_TRACKER_BINARY,
        std::vector<std::string>{"--sensor", device.second, "--sensor-id", device.first, "--uplink",
                                 uplink, "--key", dir / ("keys/sensor-" + device.first + "-e1.key"),
                                 "--log-level", "warn"});
  };
  std::vector<std::unique_ptr<Process>> trackers;
  for (const auto& device : devices) trackers.push_back(start_tracker(device));

  // The daemon calibrates by itself once the data links every sensor (before the bump).
  const auto started = std::chrono::steady_clock::now();
  ASSERT_TRUE(daemon.WaitForOutput("calibrated ", seconds(60))) << daemon.err();
  ASSERT_LT(std::chrono::steady_clock::now() - started, seconds(static_cast<int>(kMoveS) - 8))
      << "calibrated too late to watch the bump";
  // Kill one tracker mid-fusion and start it again: a new session of the same sensor.
  std::this_thread::sleep_for(milliseconds(1500));
  trackers[1]->Signal(SIGKILL);
  EXPECT_EQ(trackers[1]->Wait(milliseconds(5000)), -2);
  std::this_thread::sleep_for(milliseconds(1000));
  trackers[1] = start_tracker(devices[1]);

  // The live view's state while fusing: every sensor placed, fused tracks present.
  std::this_thread::sleep_for(milliseconds(3000));
  const nlohmann::json live = nlohmann::json::parse(
      HttpGet(static_cast<std::uint16_t>(std::stoi(live_port)), "/state"), nullptr, false);
  ASSERT_TRUE(live.is_object()) << "GET /state";
  EXPECT_EQ(live["calibration"]["state"], "calibrated");
  EXPECT_EQ(live["authenticated"], true);
  ASSERT_EQ(live["sensors"].size(), 3u);
  for (const auto& sensor : live["sensors"]) EXPECT_TRUE(sensor["placed"].get<bool>()) << sensor;
  EXPECT_GE(live["fused"].size(), 1u);

  // The fused tracks also arrive as JSON datagrams.
  {
    timeval timeout{2, 0};
    ::setsockopt(fused_socket, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof timeout);
    char buffer[65536];
    const ssize_t n = ::recv(fused_socket, buffer, sizeof buffer, 0);
    ASSERT_GT(n, 0) << "no fused-track datagram";
    EXPECT_LE(n, 1400);
    const nlohmann::json d =
        nlohmann::json::parse(std::string(buffer, static_cast<std::size_t>(n)), nullptr, false);
    ASSERT_TRUE(d.is_object());
    EXPECT_EQ(d["type"], "fused");
    EXPECT_TRUE(d["tracks"].is_array());
  }
  ::close(fused_socket);

  // The bump: the live view shows s3 as moved (and only s3), then fused again with its new pose.
  bool seen_moved = false, seen_back = false, others_moved = false;
  const auto deadline = started + seconds(static_cast<int>(kMoveS + kCorrectedWithinS));
  while (std::chrono::steady_clock::now() < deadline && !seen_back) {
    const nlohmann::json state = nlohmann::json::parse(
        HttpGet(static_cast<std::uint16_t>(std::stoi(live_port)), "/state"), nullptr, false);
    if (state.is_object()) {
      for (const auto& sensor : state["sensors"]) {
        if (!sensor["monitor"].is_object()) continue;
        const bool moved = sensor["monitor"]["state"] == "moved";
        if (sensor["id"] == "s3") {
          seen_moved = seen_moved || moved;
          seen_back = seen_moved && !moved;
        } else {
          others_moved = others_moved || moved;
        }
      }
    }
    std::this_thread::sleep_for(milliseconds(200));
  }
  EXPECT_TRUE(seen_moved) << "s3 never shown as moved: " << daemon.err();
  EXPECT_TRUE(seen_back) << "s3 not corrected within " << kCorrectedWithinS
                         << " s of the bump: " << daemon.err();
  EXPECT_FALSE(others_moved) << daemon.err();

  // Nothing more to see: the devices stop (the rest of the scenario adds nothing the checks below
  // need), then the daemon on SIGINT.
  sim.Signal(SIGINT);
  EXPECT_EQ(sim.Wait(seconds(20)), 0) << sim.err();
  daemon.Signal(SIGINT);
  ASSERT_EQ(daemon.Wait(seconds(20)), 0) << daemon.err();
  for (auto& tracker : trackers) tracker->Signal(SIGTERM);
  EXPECT_NE(daemon.err().find("tracker restarted"), std::string::npos) << daemon.err();
  // Every datagram sealed and verified, none refused by the keys (the restarted tracker's new
  // start is a new counter base above the old one).
  {
    const nlohmann::json stats =
        nlohmann::json::parse(ReadText(dir / "stats.json"), nullptr, false);
    ASSERT_TRUE(stats.is_object());
    EXPECT_TRUE(stats["authenticated"].get<bool>());
    EXPECT_EQ(stats["verified"], stats["accepted"]);
    EXPECT_GT(stats["verified"].get<std::uint64_t>(), 1000u);
    for (const auto& sensor : stats["sensors"]) {
      for (const char* reason : {"unsigned", "bad_tag", "replayed", "stale", "wrong_key",
                                 "wrong_epoch", "auth_header", "auth_mismatch"}) {
        EXPECT_FALSE(sensor["rejected"].contains(reason)) << sensor["sensor_id"] << " " << reason;
      }
      EXPECT_GE(sensor["requests_sent"].get<std::uint64_t>(), 1u) << "sealed Requests went out";
    }
    std::ifstream state(dir / "state/auth-state");
    EXPECT_TRUE(state.good()) << "the replay state is kept";
  }
  EXPECT_NE(daemon.err().find("sensor s3 MOVED"), std::string::npos) << daemon.err();

  // Flagged once, corrected, both in the calibration's history; nobody else was flagged.
  std::int64_t moved_ns = 0, corrected_ns = 0;
  {
    std::ifstream in(dir / "stats.json");
    const nlohmann::json stats = nlohmann::json::parse(in, nullptr, false);
    ASSERT_TRUE(stats.is_object());
    const nlohmann::json& m = stats["monitoring"];
    EXPECT_EQ(m["moved"], 1) << m.dump(2);
    EXPECT_EQ(m["sensors"]["s1"]["moves"], 0) << m.dump(2);
    EXPECT_EQ(m["sensors"]["s2"]["moves"], 0) << m.dump(2);
    // Corrected; fused again once its tracker has re-learned its background (maybe after the end).
    EXPECT_NE(m["sensors"]["s3"]["state"], "moved") << m.dump(2);
    for (const auto& event : m["history"]) {
      if (event["event"] == "moved" && event["sensor"] == "s3") {
        moved_ns = event["stamp_ns"].get<std::int64_t>();
      }
      if (event["event"] == "corrected" && event["sensor"] == "s3" && corrected_ns == 0) {
        corrected_ns = event["stamp_ns"].get<std::int64_t>();
      }
    }
    EXPECT_GT(corrected_ns, moved_ns) << m.dump(2);
    std::ifstream yaml(dir / "calibration.yaml");
    std::stringstream text;
    text << yaml.rdbuf();
    EXPECT_NE(text.str().find("event: \"moved\""), std::string::npos) << text.str();
    EXPECT_NE(text.str().find("event: \"corrected\""), std::string::npos) << text.str();
    // Rewritten with the history, it still says which received data the calibration took.
    EXPECT_NE(text.str().find("\ninput_window: {received_until_utc_ns: "), std::string::npos)
        << text.str();
  }

  // Calibration against the truth.
  Process eval(LRFNET_TOOL_BINARY,
               {"eval", dir / "calibration.yaml", dir / "sim/truth.yaml", "--json"});
  ASSERT_EQ(eval.Wait(), 0) << eval.err();
  const nlohmann::json e = nlohmann::json::parse(eval.out(), nullptr, false);
  ASSERT_TRUE(e.is_object()) << eval.out();
  EXPECT_LT(e["mean_d_r_deg"].get<double>(), 1.0) << eval.out();
  EXPECT_LT(e["mean_d_t_m"].get<double>(), 0.15) << eval.out();

  // When s3 was bumped (gateway UTC, from the truth's pose history) and how soon it was flagged.
  std::int64_t bump_ns = 0;
  {
    std::ifstream truth(dir / "sim/truth.yaml");
    for (std::string line; std::getline(truth, line);) {
      if (line.find("id: \"s3\", from_s: " + std::to_string(static_cast<int>(kMoveS))) ==
          std::string::npos) {
        continue;
      }
      const auto at = line.find("from_utc_ns: ");
      if (at != std::string::npos) bump_ns = std::stoll(line.substr(at + 13));
    }
  }
  ASSERT_GT(bump_ns, 0) << "no pose history in truth.yaml";
  EXPECT_GT(moved_ns, bump_ns);
  EXPECT_LT(moved_ns - bump_ns, 10'000'000'000LL) << "flagged more than 10 s after the bump";

  // Fused-track continuity: two people, so (almost) never more than two confirmed fused tracks at
  // once, few distinct ids, and the two longest-lived ids cover most of the fused time. Between
  // the bump and its flag s3's tracker takes walls for people and its tracks went through its old
  // pose; after the flag, the fused tracks only s3 fed are kept until fusion.max_coast_s (1.5 s)
  // has passed without an update (published as coasting only with fusion.report_sourceless on;
  // measured with it: the last of them ended 1.47 s after the flag). Not counted (that is what
  // the flag bounds, asserted above); one publish period of margin.
  constexpr std::int64_t kCoastNs = 1'500'000'000LL + 100'000'000LL;
  std::ifstream fused(dir / "fused.jsonl");
  ASSERT_TRUE(fused) << "no fused tracks recorded";
  std::size_t snapshots = 0, crowded = 0, with_tracks = 0, through_wrong_pose = 0;
  std::map<std::uint64_t, std::size_t> seen;  // confirmed id → snapshots
  // The same before the bump and after the flag: s3's tracks fed through its old pose before the
  // flag may have pulled a person's fused track away so that the others start a new one for them
  // (measured: one such switch, the old id kept without sources until max_coast_s); the ids are
  // to be kept on either side.
  std::array<std::map<std::uint64_t, std::size_t>, 2> seen_side;
  std::map<std::uint64_t, std::pair<std::int64_t, std::int64_t>> span;  // id → first, last stamp
  for (std::string line; std::getline(fused, line);) {
    const nlohmann::json j = nlohmann::json::parse(line, nullptr, false);
    ASSERT_TRUE(j.is_object()) << line;
    const std::int64_t stamp = j["stamp_ns"].get<std::int64_t>();
    if (stamp >= bump_ns && stamp <= moved_ns + kCoastNs) continue;
    ++snapshots;
    std::size_t confirmed = 0;
    for (const auto& t : j["tracks"]) {
      for (const auto& source : t["sources"]) {
        if (source["sensor"] == "s3" && stamp > moved_ns && stamp < corrected_ns) {
          ++through_wrong_pose;
        }
      }
      if (t["state"] == "tentative") continue;
      ++confirmed;
      const std::uint64_t id = t["id"].get<std::uint64_t>();
      ++seen[id];
      ++seen_side[stamp < bump_ns ? 0 : 1][id];
      auto [it, inserted] = span.try_emplace(id, stamp, stamp);
      if (!inserted) it->second.second = stamp;
    }
    crowded += confirmed > 2 ? 1 : 0;
    with_tracks += confirmed > 0 ? 1 : 0;
  }
  ASSERT_GT(snapshots, 50u);
  EXPECT_EQ(through_wrong_pose, 0u) << "s3 fused while flagged as moved";
  EXPECT_GT(with_tracks, snapshots * 8 / 10);
  EXPECT_LT(crowded, snapshots / 10) << "duplicated fused tracks";
  // Each id's life in seconds from the bump, for a failure's message.
  std::string lives_text;
  for (const auto& [id, n] : seen) {
    lives_text += std::to_string(id) + ": " + std::to_string(n) + " snapshots, " +
                  std::to_string(static_cast<double>(span[id].first - bump_ns) * 1e-9) + " .. " +
                  std::to_string(static_cast<double>(span[id].second - bump_ns) * 1e-9) + " s\n";
  }
  lives_text += "flagged " + std::to_string(static_cast<double>(moved_ns - bump_ns) * 1e-9) +
                " s, corrected " +
                std::to_string(static_cast<double>(corrected_ns - bump_ns) * 1e-9) +
                " s after the bump\n";
  EXPECT_LE(seen.size(), 6u) << "fused ids were not kept\n" << lives_text;
  for (const auto& side : seen_side) {
    std::vector<std::size_t> lives;
    std::size_t total = 0;
    for (const auto& [id, n] : side) {
      lives.push_back(n);
      total += n;
    }
    std::sort(lives.rbegin(), lives.rend());
    ASSERT_GE(lives.size(), 2u) << lives_text;
    EXPECT_GT(lives[0] + lives[1], total * 8 / 10)
        << "the two people's fused ids cover too little of the time "
        << (&side == &seen_side[0] ? "before the bump" : "after the flag") << "\n"
        << lives_text;
  }
}

}  // namespace
}  // namespace lrfnet::testing
