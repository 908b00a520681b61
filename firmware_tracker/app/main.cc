// lrfnet-tracker: the gateway program next to one SICK scanner.
//
//   lrfnet-tracker --sensor HOST[:PORT] --sensor-id ID --uplink HOST:PORT   live: CoLa-B over TCP in,
//                                                                           tracks over UDP out
//   lrfnet-tracker --replay CAPTURE --sensor-id ID --out REC                offline: a pcap/pcapng of
//                                                                           the scanner's TCP stream
//                                                                           in, a recording out
//   lrfnet-tracker --print-config                                           the documented defaults
//
// Both modes feed cola::StreamDecoder and one TrackerNode (clock mapping, tracking, datagrams);
// --uplink and --out may be combined in either mode. SIGINT / SIGTERM stop cleanly (the recording
// is flushed and closed) and print the counters.

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <boost/program_options.hpp>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>

#include "common/capture/capture_stream.h"
#include "common/host_port.h"
#include "firmware_tracker/app/config.h"
#include "firmware_tracker/app/live_run.h"
#include "firmware_tracker/app/replay_run.h"
#include "firmware_tracker/app/run_report.h"
#include "firmware_tracker/app/run_setup.h"

namespace lrfnet::tracker {
namespace {

namespace po = boost::program_options;

int UsageError(const std::string& message) {
  std::fprintf(stderr, "lrfnet-tracker: %s (see lrfnet-tracker --help)\n", message.c_str());
  return kExitUsage;
}

using common::ParseHostPort;

int Run(int argc, char** argv) {
  po::options_description visible(
      "lrfnet-tracker --sensor HOST[:PORT] --sensor-id ID --uplink HOST:PORT [options]\n"
      "lrfnet-tracker --replay CAPTURE --sensor-id ID --out REC [options]\n"
      "lrfnet-tracker --print-config\n"
      "Reads a SICK scanner live (CoLa-B over TCP; reconnects on failure) or a pcap/pcapng "
      "capture of\n"
      "its TCP stream, tracks the moving objects and sends track frames, background snapshots, "
      "health and\n"
      "sensor info as UDP datagrams (--uplink) and/or writes them to a recording (--out). "
      "Options",
      100, 50);
  std::string config_path;
  std::string sensor;
  std::string replay;
  std::string sensor_id;
  std::string uplink;
  std::string out;
  long long print_every = 0;
  long long max_scans = 0;
  double speed = 0.0;
  int capture_port = 2112;
  long long connect_timeout_ms = 0;
  long long reply_timeout_ms = 0;
  double read_deadline_periods = 0.0;
  std::string log_level = "info";
  visible.add_options()("help,h", "this help")(
      "print-config", "print every option with its default and documentation (YAML) and exit")(
      "config", po::value<std::string>(&config_path),
      "YAML config file (see --print-config); flags override it")(
      "sensor", po::value<std::string>(&sensor),
      "live: the scanner's address, HOST or HOST:PORT (port 2112)")(
      "replay", po::value<std::string>(&replay),
      "offline: a pcap/pcapng capture of the scanner's TCP stream")(
      "sensor-id", po::value<std::string>(&sensor_id),
      "name of this sensor in every datagram (required here or in the config)")(
      "uplink", po::value<std::string>(&uplink), "send datagrams over UDP to lrfnetd at HOST:PORT")(
      "out", po::value<std::string>(&out), "write the datagrams to this recording file")(
      "key", po::value<std::string>(),
      "seal every datagram with this sensor's key file (lrfnet keys derive) and serve only sealed "
      "Requests (auth.key)")("encrypt",
                             "also encrypt the datagrams' content (auth.encrypt; needs --key)")(
      "print-every", po::value<long long>(&print_every)->default_value(0),
      "print the tracks of every N-th scan (0: none)")(
      "speed", po::value<double>(&speed)->default_value(0.0),
      "replay: play the capture at this multiple of its recorded pace (1: real time; 0: as fast "
      "as possible)")("max-scans", po::value<long long>(&max_scans)->default_value(0),
                      "stop after N scans (0: never)")(
      "capture-port", po::value<int>(&capture_port)->default_value(2112),
      "replay: the scanner's TCP port in the capture")(
      "connect-timeout-ms", po::value<long long>(&connect_timeout_ms),
      "live: TCP connect deadline (link.connect_timeout_ms)")(
      "reply-timeout-ms", po::value<long long>(&reply_timeout_ms),
      "live: deadline for each start-up reply (link.reply_timeout_ms)")(
      "read-deadline-periods", po::value<double>(&read_deadline_periods),
      "live: reconnect after this many scan periods without a scan")(
      "log-level", po::value<std::string>(&log_level)->default_value("info"),
      "trace, debug, info, warn, error or off (stderr)");

  po::variables_map vm;
  try {
    po::store(po::command_line_parser(argc, argv).options(visible).run(), vm);
    po::notify(vm);
  } catch (const po::error& e) {
    return UsageError(e.what());
  }
  if (vm.count("help") != 0) {
    std::cout << visible << "\n";
    return kExitOk;
  }

  TrackerConfig config;
  if (!config_path.empty()) {
    std::ifstream file(config_path);
    if (!file) return UsageError("--config: cannot read '" + config_path + "'");
    std::stringstream text;
    text << file.rdbuf();
    if (auto e = LoadTrackerConfig(text.str(), config)) {
      return UsageError("--config " + config_path + ": " + *e);
    }
  }
  if (vm.count("print-config") != 0) {
    std::cout << PrintTrackerConfig(config);
    return kExitOk;
  }

  if (!sensor.empty()) config.sensor_address = sensor;
  if (!sensor_id.empty()) config.sensor_id = sensor_id;
  if (!uplink.empty()) config.uplink_address = uplink;
  if (vm.count("key") != 0) config.key_file = vm["key"].as<std::string>();
  if (vm.count("encrypt") != 0) config.encrypt = true;
  if (vm.count("connect-timeout-ms") != 0)
    config.link.connect_timeout = std::chrono::milliseconds(connect_timeout_ms);
  if (vm.count("reply-timeout-ms") != 0)
    config.link.reply_timeout = std::chrono::milliseconds(reply_timeout_ms);
  if (vm.count("read-deadline-periods") != 0)
    config.link.read_deadline_scan_periods = read_deadline_periods;

  if (replay.empty() && config.sensor_address.empty())
    return UsageError("give --sensor HOST[:PORT] (or sensor.address in the config) or --replay CAPTURE");
  if (!replay.empty() && !sensor.empty()) return UsageError("give either --sensor or --replay, not both");
  if (config.sensor_id.empty()) return UsageError("--sensor-id is required");
  if (print_every < 0) return UsageError("--print-every must be >= 0");
  if (max_scans < 0) return UsageError("--max-scans must be >= 0");
  if (!(speed >= 0.0 && speed <= 1e6)) return UsageError("--speed must be in [0, 1e6]");
  const spdlog::level::level_enum level = spdlog::level::from_str(log_level);
  if (level == spdlog::level::off && log_level != "off") {
    return UsageError("unknown --log-level '" + log_level + "'");
  }
  std::string error;
  if (replay.empty()) {
    const auto endpoint = ParseHostPort(config.sensor_address, "--sensor", 2112, &error);
    if (!endpoint) return UsageError(error);
    config.link.host = endpoint->host;
    config.link.port = endpoint->port;
  }
  if (!config.uplink_address.empty() &&
      !ParseHostPort(config.uplink_address, "--uplink", 0, &error)) {
    return UsageError(error);
  }
  if (auto e = Validate(config)) return UsageError(*e);
  spdlog::set_default_logger(spdlog::stderr_color_mt("lrfnet-tracker"));
  spdlog::set_level(level);

  ScanLog log(static_cast<std::uint64_t>(print_every), static_cast<std::uint64_t>(max_scans));
  if (!replay.empty()) {
    capture::CaptureStreamOptions options;
    if (capture_port < 1 || capture_port > 65535)
      return UsageError("--capture-port must be 1..65535");
    options.sensor_port = static_cast<std::uint16_t>(capture_port);
    if (auto e = capture::Validate(options)) return UsageError(*e);
    return RunReplay(config, replay, options, out, speed, log);
  }
  return RunLive(config, out, log);
}

}  // namespace
}  // namespace lrfnet::tracker

int main(int argc, char** argv) {
  try {
    return lrfnet::tracker::Run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lrfnet-tracker: %s\n", e.what());
    return 1;
  }
}
