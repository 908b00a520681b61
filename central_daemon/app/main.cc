// lrfnetd: collects the track streams of the trackers over UDP, records everything received and
// keeps the tracks for calibration and fusion.
//
//   lrfnetd --listen ADDR:PORT --record REC           live
//   lrfnetd --input REC_OR_CAPTURE... [--record REC]  offline: recordings or UDP captures in
//   lrfnetd --print-config
//
// SIGINT / SIGTERM stop cleanly (the recording is flushed and closed); SIGHUP reloads --config;
// SIGUSR1 calibrates at once. Calibration also runs by itself once the data connects every sensor
// (config section `calibration`, progress in the status line); offline (--input) it runs once over
// all the input. Once calibrated, tracks are fused (section `fusion`: JSON over UDP and/or JSON
// lines) and the live view (section `live_view`, --live-view) shows it all in a browser. With
// --mqtt (section `mqtt`) the objects, the zones' counts (section `zones`), the calibration and
// every sensor's health are published to an MQTT broker. Once calibrated, the sensors are watched
// (section `monitoring`): a moved one is left out of the fusion, its pose estimated again and
// calibration.output rewritten with the event.

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <boost/program_options.hpp>
#include <csignal>
#include <cstdio>
#include <exception>
#include <iostream>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "central_daemon/app/config.h"
#include "central_daemon/app/live_run.h"
#include "central_daemon/app/offline_run.h"
#include "central_daemon/app/run_setup.h"
#include "google/protobuf/stubs/logging.h"

namespace lrfnet::daemon {
namespace {

namespace po = boost::program_options;

int UsageError(const std::string& message) {
  std::fprintf(stderr, "lrfnetd: %s (see lrfnetd --help)\n", message.c_str());
  return kExitUsage;
}

int Run(int argc, char** argv) {
  po::options_description visible(
      "lrfnetd --listen ADDR:PORT [--record REC] [options]\n"
      "lrfnetd --input REC_OR_CAPTURE... [--record REC] [options]\n"
      "lrfnetd --print-config\n"
      "Collects the trackers' UDP datagrams (track frames, background snapshots, health, sensor "
      "info),\nvalidates them, keeps the tracks of every sensor and records everything received. "
      "--input reads\nrecordings or pcap/pcapng captures of the UDP stream instead of the socket. "
      "SIGINT/SIGTERM stop,\nSIGHUP reloads --config. Options",
      100, 50);
  RunOptions run;
  std::string listen;
  std::string record;
  std::vector<std::string> inputs;
  int udp_port = 0;
  double status_interval_s = 0;
  std::string log_level = "info";
  visible.add_options()("help,h", "this help")("config", po::value<std::string>(&run.config_path),
                                               "YAML config file (see --print-config)")(
      "print-config", "print the configuration in effect (documented YAML) and exit")(
      "listen", po::value<std::string>(&listen),
      "UDP address to receive on, ADDR:PORT (default [::]:5800; port 0: any free port)")(
      "record", po::value<std::string>(&record), "record everything received to this file")(
      "input", po::value<std::vector<std::string>>(&inputs)->multitoken(),
      "offline: read these recordings or UDP captures instead of the socket")(
      "udp-port", po::value<int>(&udp_port)->default_value(0),
      "--input captures: only UDP datagrams to this port (0: all)")(
      "status-interval-s", po::value<double>(&status_interval_s),
      "a status line this often (overrides status.interval_s; 0: none)")(
      "duration-s", po::value<double>(&run.duration_s)->default_value(0.0),
      "live: stop after this many seconds (0: run until a signal)")(
      "calibration-out", po::value<std::string>(),
      "write calibration.yaml here when a calibration succeeds (overrides calibration.output)")(
      "calibration-report", po::value<std::string>(),
      "write the calibration report into this folder (overrides calibration.report_dir)")(
      "calibration-in", po::value<std::string>(),
      "start from this calibration.yaml: fuse at once (overrides calibration.initial)")(
      "live-view", po::value<std::string>(),
      "serve the live view (web page) on ADDR:PORT, e.g. 127.0.0.1:8080 (overrides "
      "live_view.listen)")(
      "fused-out", po::value<std::string>(),
      "append the fused tracks as JSON lines to this file (overrides fusion.record)")(
      "fused-udp", po::value<std::string>(),
      "send the fused tracks as JSON datagrams to HOST:PORT (overrides fusion.publish)")(
      "mqtt", po::value<std::string>(),
      "publish objects, zones, calibration and health to the MQTT broker at HOST:PORT (overrides "
      "mqtt.broker)")("mqtt-site", po::value<std::string>(),
                      "the site's name in the MQTT topics (overrides mqtt.site)")(
      "keys", po::value<std::string>(),
      "authenticate every datagram with the sensor keys in this folder (lrfnet keys derive); "
      "unsigned, forged and replayed ones are dropped (overrides auth.keys)")(
      "state-dir", po::value<std::string>(),
      "keep the replay state here across restarts (overrides auth.state_dir)")(
      "live-view-token-file", po::value<std::string>(),
      "the live view's access token (overrides live_view.token_file)")(
      "stats-out", po::value<std::string>(&run.stats_out),
      "at exit, write every counter (per sensor and reason) as JSON to this file")(
      "log-level", po::value<std::string>(&log_level)->default_value("info"),
      "trace, debug, info, warn, error or off (stderr)");
  po::variables_map vm;
  try {
    po::store(po::parse_command_line(argc, argv, visible), vm);
    po::notify(vm);
  } catch (const po::error& e) {
    return UsageError(e.what());
  }
  if (vm.count("help") != 0) {
    std::cout << visible << "\n";
    return kExitOk;
  }
  if (vm.count("listen") != 0) run.listen_flag = listen;
  if (vm.count("record") != 0) run.record_flag = record;
  if (vm.count("status-interval-s") != 0) run.status_flag = status_interval_s;
  if (vm.count("calibration-out") != 0)
    run.calibration_out_flag = vm["calibration-out"].as<std::string>();
  if (vm.count("calibration-report") != 0)
    run.calibration_report_flag = vm["calibration-report"].as<std::string>();
  for (const auto& [flag, target] :
       {std::pair{"calibration-in", &run.calibration_in_flag},
        std::pair{"live-view", &run.live_view_flag}, std::pair{"fused-out", &run.fused_out_flag},
        std::pair{"fused-udp", &run.fused_udp_flag}, std::pair{"mqtt", &run.mqtt_flag},
        std::pair{"mqtt-site", &run.mqtt_site_flag}, std::pair{"keys", &run.keys_flag},
        std::pair{"state-dir", &run.state_dir_flag},
        std::pair{"live-view-token-file", &run.live_view_token_flag}}) {
    if (vm.count(flag) != 0) *target = vm[flag].as<std::string>();
  }
  if (udp_port < 0 || udp_port > 65535) return UsageError("--udp-port must be 0..65535");
  if (!(run.duration_s >= 0.0)) return UsageError("--duration-s must be >= 0");
  if (!inputs.empty() && run.listen_flag) return UsageError("give either --listen or --input");

  DaemonConfig config;
  if (auto e = LoadConfig(run, &config)) return UsageError(*e);
  if (vm.count("print-config") != 0) {
    std::cout << PrintDaemonConfig(config);
    return kExitOk;
  }
  const spdlog::level::level_enum level = spdlog::level::from_str(log_level);
  if (level == spdlog::level::off && log_level != "off")
    return UsageError("unknown --log-level '" + log_level + "'");
  spdlog::set_default_logger(spdlog::stderr_color_mt("lrfnetd"));
  spdlog::set_level(level);

  if (!inputs.empty())
    return RunOffline(run, config, inputs, static_cast<std::uint16_t>(udp_port));
  return RunLive(run, config);
}

}  // namespace
}  // namespace lrfnet::daemon

int main(int argc, char** argv) {
  // A file-size limit must give a counted write error (EFBIG), not kill the daemon.
  std::signal(SIGXFSZ, SIG_IGN);
  // libprotobuf logs every string field that is not UTF-8; hostile datagrams are counted instead.
  google::protobuf::SetLogHandler(nullptr);
  try {
    return lrfnet::daemon::Run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lrfnetd: %s\n", e.what());
    return 1;
  }
}
