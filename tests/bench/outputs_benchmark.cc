// lrfnetd's outputs for other systems: the cost of evaluating the zones on the fused tracks, of
// writing an MQTT object list, and of MqttPublisher::Publish as the io thread sees it (the call
// that must never wait for the network): with a real mosquitto on loopback (when installed), with
// a broker that accepts the connection and then stops reading, and with no broker at all. Prints a
// markdown table and writes it to OUT.
//
//   outputs_benchmark [--out OUT]     (OUT: results/outputs_benchmark.md)

#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "central_daemon/app/mqtt_messages.h"
#include "central_daemon/io/mqtt_publisher.h"
#include "central_daemon/zones/zones.h"

extern char** environ;

namespace {

using Clock = std::chrono::steady_clock;
using lrfnet::daemon::MqttOptions;
using lrfnet::daemon::MqttPublisher;

double Micros(Clock::duration d) { return std::chrono::duration<double, std::micro>(d).count(); }

struct Stats {
  double p50 = 0, p99 = 0, max = 0;
};
Stats Percentiles(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const auto at = [&](double q) {
    return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1))];
  };
  return {at(0.5), at(0.99), v.back()};
}

// Zones: 5 lines and 5 octagons over a 40 x 40 m hall, people walking at random.
std::string ZonesRow(std::size_t tracks) {
  using namespace lrfnet::zones;
  std::vector<Zone> zones;
  for (int i = 0; i < 5; ++i) {
    const double x = 4.0 + 8.0 * i;
    zones.push_back({"line" + std::to_string(i), ZoneKind::kLine, {{x, 0.0}, {x, 40.0}}});
    Zone octagon{"area" + std::to_string(i), ZoneKind::kPolygon, {}};
    for (int k = 0; k < 8; ++k) {
      const double a = k * std::acos(-1.0) / 4.0;
      octagon.points.push_back({x + 3.0 * std::cos(a), 20.0 + 3.0 * std::sin(a)});
    }
    zones.push_back(octagon);
  }
  ZoneCounter counter(zones, ZoneOptions{});
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> place(0.0, 40.0), turn(-0.3, 0.3);
  std::vector<ZoneTrack> people(tracks);
  std::vector<double> heading(tracks);
  for (std::size_t i = 0; i < tracks; ++i) {
    people[i] = {i + 1, place(rng), place(rng), true};
    heading[i] = place(rng);
  }
  std::vector<double> us;
  lrfnet::common::UtcNs now = 1'700'000'000'000'000'000;
  for (int step = 0; step < 600; ++step) {  // one minute at 10 Hz
    for (std::size_t i = 0; i < tracks; ++i) {
      heading[i] += turn(rng);
      people[i].x_m = std::clamp(people[i].x_m + 0.12 * std::cos(heading[i]), 0.0, 40.0);
      people[i].y_m = std::clamp(people[i].y_m + 0.12 * std::sin(heading[i]), 0.0, 40.0);
    }
    now += 100'000'000;
    const auto t0 = Clock::now();
    counter.Update(people, now);
    us.push_back(Micros(Clock::now() - t0));
  }
  std::uint64_t crossings = 0;
  for (const ZoneState& z : counter.States()) crossings += z.inbound + z.outbound;
  const Stats s = Percentiles(us);
  char row[256];
  std::snprintf(
      row, sizeof row,
      "| zones: 10 zones, %zu tracks, one update | %.1f | %.1f | %.1f | %llu crossings in 60 s |\n",
      tracks, s.p50, s.p99, s.max, static_cast<unsigned long long>(crossings));
  return row;
}

std::string ObjectsRow(std::size_t objects) {
  std::vector<lrfnet::daemon::MqttObject> list(objects);
  for (std::size_t i = 0; i < objects; ++i) {
    list[i].track.id = i + 1;
    list[i].track.x_m = 1.0 + 0.37 * static_cast<double>(i);
    list[i].track.sources = {{"s1", 3, 0}, {"s2", 7, 0}};
    for (int k = 0; k < 10; ++k) list[i].path.push_back({1.0 + k, 2.0, -0.5 * (9 - k)});
  }
  std::vector<double> us;
  std::size_t bytes = 0;
  for (int rep = 0; rep < 200; ++rep) {
    const auto t0 = Clock::now();
    const std::string json =
        lrfnet::daemon::ObjectsJson("site", static_cast<std::uint64_t>(rep), 1, list);
    us.push_back(Micros(Clock::now() - t0));
    bytes = json.size();
  }
  const Stats s = Percentiles(us);
  char row[256];
  std::snprintf(row, sizeof row,
                "| object list: %zu objects, path of 10 | %.1f | %.1f | %.1f | %zu bytes |\n",
                objects, s.p50, s.p99, s.max, bytes);
  return row;
}

std::uint16_t FreePort(int* listen_fd) {
  *listen_fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ::bind(*listen_fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  socklen_t len = sizeof a;
  ::getsockname(*listen_fd, reinterpret_cast<sockaddr*>(&a), &len);
  return ntohs(a.sin_port);
}

// 5000 messages of 1 KB offered as fast as the io thread would (a burst), QoS 0.
std::string PublishRow(const std::string& what, std::uint16_t port, bool wait_connected) {
  MqttOptions o;
  o.host = "127.0.0.1";
  o.port = port;
  o.client_id = "lrfnet-bench-" + std::to_string(::getpid());
  o.queue_messages = 1000;
  MqttPublisher publisher(o);
  std::string error;
  if (!publisher.Start(&error)) return "| " + what + " | " + error + " | | | |\n";
  if (wait_connected && !publisher.WaitConnected(10.0))
    return "| " + what + " | not connected | | | |\n";
  const std::string payload(1024, 'x');
  std::vector<double> us;
  for (int i = 0; i < 5000; ++i) {
    const auto t0 = Clock::now();
    publisher.Publish("bench/objects", payload, 0, false);
    us.push_back(Micros(Clock::now() - t0));
  }
  publisher.Flush(wait_connected ? 5.0 : 0.1);
  const lrfnet::daemon::MqttCounters c = publisher.counters();
  const Stats s = Percentiles(us);
  char row[320];
  std::snprintf(row, sizeof row,
                "| Publish, %s | %.2f | %.2f | %.1f | sent %llu, dropped %llu (queue full %llu, "
                "no connection %llu) |\n",
                what.c_str(), s.p50, s.p99, s.max, static_cast<unsigned long long>(c.sent),
                static_cast<unsigned long long>(c.dropped_queue_full + c.dropped_disconnected),
                static_cast<unsigned long long>(c.dropped_queue_full),
                static_cast<unsigned long long>(c.dropped_disconnected));
  return row;
}

std::string RealBrokerRow() {
  if (::access("/usr/sbin/mosquitto", X_OK) != 0)
    return "| Publish, real mosquitto | not installed | | | |\n";
  int fd = -1;
  const std::uint16_t port = FreePort(&fd);
  ::close(fd);
  const std::string conf =
      (std::filesystem::temp_directory_path() / "lrfnet_bench_mosquitto.conf").string();
  std::ofstream(conf) << "listener " << port
                      << " 127.0.0.1\nallow_anonymous true\npersistence false\n";
  pid_t pid = 0;
  std::vector<std::string> args = {"/usr/sbin/mosquitto", "-c", conf};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 2, "/dev/null", 0, 0);
  posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const std::string row = PublishRow("real mosquitto on loopback", port, true);
  ::kill(pid, SIGTERM);
  int status = 0;
  ::waitpid(pid, &status, 0);
  std::filesystem::remove(conf);
  return row;
}

// Accepts one connection, answers CONNECT with CONNACK and then never reads again.
std::string StalledBrokerRow() {
  int listen_fd = -1;
  const std::uint16_t port = FreePort(&listen_fd);
  ::listen(listen_fd, 1);
  std::thread broker([listen_fd] {
    const int c = ::accept(listen_fd, nullptr, nullptr);
    char buffer[256];
    ::recv(c, buffer, sizeof buffer, 0);
    const unsigned char connack[] = {0x20, 0x02, 0x00, 0x00};
    ::send(c, connack, sizeof connack, 0);
    std::this_thread::sleep_for(std::chrono::seconds(3));
    ::close(c);
  });
  const std::string row = PublishRow("broker that stopped reading", port, true);
  broker.join();
  ::close(listen_fd);
  return row;
}

std::string NoBrokerRow() {
  int fd = -1;
  const std::uint16_t port = FreePort(&fd);
  ::close(fd);  // nobody listens: every connection attempt is refused
  return PublishRow("no broker (reconnecting)", port, false);
}

}  // namespace

int main(int argc, char** argv) {
  std::string out = "results/outputs_benchmark.md";
  for (int i = 1; i + 1 < argc; ++i) {
    if (std::string(argv[i]) == "--out") out = argv[i + 1];
  }
  // p99 and max include the times the scheduler took the CPU away: the load is part of the result.
  std::string load = "?";
  std::getline(std::ifstream("/proc/loadavg"), load);
  std::string table =
      "# Outputs benchmark (zones, MQTT)\n\n"
      "Load average when it ran (/proc/loadavg): " +
      load.substr(0, load.find(' ')) + " on " +
      std::to_string(std::thread::hardware_concurrency()) +
      " CPUs.\n\n"
      "`outputs_benchmark` (scripts/bench.sh). Times in microseconds on this machine; Publish is "
      "the call the daemon's io thread makes (5000 messages of 1 KB in one burst, queue of "
      "1000).\n\n"
      "| what | p50 [µs] | p99 [µs] | max [µs] | notes |\n|---|---|---|---|---|\n";
  for (std::size_t tracks : {10u, 100u, 1000u}) table += ZonesRow(tracks);
  for (std::size_t objects : {10u, 100u}) table += ObjectsRow(objects);
  table += RealBrokerRow();
  table += StalledBrokerRow();
  table += NoBrokerRow();
  std::fputs(table.c_str(), stdout);
  std::filesystem::create_directories(std::filesystem::path(out).parent_path());
  std::ofstream(out) << table;
  return 0;
}
