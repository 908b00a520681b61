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

#include <fcntl.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <time.h>
#include <unistd.h>

#include <boost/asio/io_context.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/program_options.hpp>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <exception>
#include <fstream>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "central_daemon/app/auth_files.h"
#include "central_daemon/app/calibration_input.h"
#include "central_daemon/app/calibration_service.h"
#include "central_daemon/app/config.h"
#include "central_daemon/app/daemon.h"
#include "central_daemon/app/foxglove_feed.h"
#include "central_daemon/app/fusion_service.h"
#include "central_daemon/app/live_feed.h"
#include "central_daemon/app/live_run.h"
#include "central_daemon/app/live_state.h"
#include "central_daemon/app/monitoring_service.h"
#include "central_daemon/app/mqtt_output.h"
#include "central_daemon/app/mqtt_service.h"
#include "central_daemon/app/recorder.h"
#include "central_daemon/app/run_report.h"
#include "central_daemon/app/run_setup.h"
#include "central_daemon/app/stats_json.h"
#include "central_daemon/app/zone_service.h"
#include "central_daemon/calibration/calibration_yaml.h"
#include "central_daemon/io/datagram_source.h"
#include "central_daemon/io/live_view_server.h"
#include "central_daemon/io/recording_writer.h"
#include "central_daemon/io/udp_receiver.h"
#include "common/datagram_auth.h"
#include "common/host_port.h"
#include "common/systemd_notify.h"
#include "google/protobuf/stubs/logging.h"

namespace lrfnet::daemon {
namespace {

namespace asio = boost::asio;
namespace po = boost::program_options;

int UsageError(const std::string& message) {
  std::fprintf(stderr, "lrfnetd: %s (see lrfnetd --help)\n", message.c_str());
  return kExitUsage;
}

// Offline: the datagrams of recordings and UDP captures through the same core, with their
// recorded receive times as the clock; several files are read as one stream in receive-time
// order (as they arrived live). With a calibration to start from, the input is fused and
// monitored as it is read, and --calibration-out receives that calibration with what the
// monitoring changed (instead of a new calibration over all the input).
int RunOffline(const RunOptions& run, DaemonConfig config, const std::vector<std::string>& inputs,
               std::uint16_t udp_port) {
  // Offline: verified with fresh windows (no state: the input is what was recorded), no counter
  // check against the receive time (old files).
  if (auto e = SetUpAuth(config, false)) {
    std::fprintf(stderr, "lrfnetd: %s\n", e->c_str());
    return kExitFailure;
  }
  std::optional<Recorder> recorder;
  if (!config.record_path.empty()) recorder.emplace(RecordingOptions(config, Writer()));
  struct Tee final : RecordSink {
    Recorder* recorder = nullptr;
    bool opened = false;
    std::optional<std::string> error;
    void Record(std::span<const std::uint8_t> d, std::string_view s, common::UtcNs t) override {
      if (!opened && recorder != nullptr) {
        opened = true;
        error = recorder->Open(t);
      }
      if (recorder != nullptr && !error) recorder->Record(d, s, t);
    }
    void FlushIfDue(common::UtcNs t) override {
      if (recorder != nullptr && opened && !error) recorder->FlushIfDue(t);
    }
  } tee;
  tee.recorder = recorder ? &*recorder : nullptr;
  Daemon core(CoreOptions(config), &tee, nullptr, RandomSessionId());
  // With a calibration to start from, the input is fused as it is read (on its receive times).
  asio::io_context io;
  FusionService fusion(io, config);
  ZoneService zones(config);
  MqttOutput mqtt;
  if (!StartMqtt(config, true, &mqtt)) return kExitFailure;
  if (mqtt.service) {
    // Offline the input is read as fast as it goes: wait for the broker rather than drop.
    if (!mqtt.publisher->WaitConnected(10.0))
      spdlog::warn("mqtt: not connected to {} after 10 s ({}); publishing what can be",
                   config.mqtt.broker, mqtt.publisher->last_error());
  }
  MonitoringService monitoring(config);
  if (!config.calibration_initial.empty()) {
    calib::CalibrationOutcome initial;
    std::string text;
    if (auto e = LoadInitialCalibration(config.calibration_initial, &initial, &text)) {
      std::fprintf(stderr, "lrfnetd: %s\n", e->c_str());
      return kExitFailure;
    }
    if (std::string e = fusion.Open(); !e.empty()) {
      std::fprintf(stderr, "lrfnetd: %s\n", e.c_str());
      return kExitFailure;
    }
    fusion.SetCalibration(initial.result);
    monitoring.SetCalibration(initial.result, core, "loaded", text);
    core.set_frame_listener(&fusion);
    if (mqtt.service) mqtt.service->PublishCalibration(initial.result, 0);
  }
  const auto fusion_period_ns = static_cast<common::DurationNs>(1e9 / config.fusion_publish_hz);
  common::UtcNs last_fusion_ns = 0;

  int exit_code = kExitOk;
  common::UtcNs last_tick_ns = 0;
  common::UtcNs last_ns = 0;
  // Every input at once, in receive order: the sensors' recordings of one session interleave as
  // the daemon would have received them (read one after the other, fusion and zones would see
  // one sensor's whole session before the next one's).
  std::vector<std::unique_ptr<DatagramSource>> sources;
  for (const std::string& path : inputs) {
    std::string error;
    DatagramSourceOptions options;
    options.udp_port = udp_port;
    auto source = OpenDatagramFile(path, options, &error);
    if (!source) {
      std::fprintf(stderr, "lrfnetd: --input %s: %s\n", path.c_str(), error.c_str());
      return kExitFailure;
    }
    sources.push_back(std::move(source));
  }
  MergedDatagramSource merged(std::move(sources));
  ReceivedDatagram d;
  std::size_t index = 0;
  for (SourceStatus status; (status = merged.Next(&d, &index)) != SourceStatus::kEnd;) {
    if (status == SourceStatus::kError) {
      spdlog::error("--input {}", merged.source(index).error());
      exit_code = kExitFailure;
      continue;
    }
    core.OnDatagram(d.bytes, d.source, d.receive_ns);
    if (last_ns == 0 && mqtt.service) mqtt.service->PublishStatus(true, d.receive_ns);
    last_ns = d.receive_ns;
    if (fusion.calibrated() && (d.receive_ns - last_fusion_ns >= fusion_period_ns ||
                                d.receive_ns < last_fusion_ns)) {
      fusion.OnTick(static_cast<double>(d.receive_ns) * 1e-9);
      last_fusion_ns = d.receive_ns;
    }
    zones.OnTick(fusion);
    if (mqtt.service) mqtt.service->OnTick(d.receive_ns, core, fusion, zones);
    if (d.receive_ns - last_tick_ns >= kTickPeriodNs || d.receive_ns < last_tick_ns) {
      core.OnTick(d.receive_ns);
      LogEvents(core, config.ingest.silent_after_s);
      last_tick_ns = d.receive_ns;
      if (monitoring.OnTick(core)) {
        fusion.SetCalibration(monitoring.result());
        fusion.SetExcluded(monitoring.excluded());
        PublishMonitoring(monitoring, &mqtt, d.receive_ns);
      }
    }
  }
  for (std::size_t i = 0; i < merged.size(); ++i) {
    spdlog::info("input {}: {} datagrams", inputs[i], merged.source(i).counters().datagrams);
  }
  if (last_ns != 0) core.OnTick(last_ns);
  LogEvents(core, config.ingest.silent_after_s);
  if (!core.ingest().authenticated()) {
    const IngestCounters& c = core.ingest().counters();
    std::uint64_t encrypted = c.unattributed[static_cast<std::size_t>(RejectReason::kEncrypted)];
    for (const SensorStatus& s : core.ingest().Sensors())
      encrypted += s.counters.rejected[static_cast<std::size_t>(RejectReason::kEncrypted)];
    if (c.unverified > 0 || encrypted > 0) {
      spdlog::warn(
          "without --keys: {} sealed datagrams read unverified (forged ones would count), "
          "{} encrypted ones could not be read",
          c.unverified, encrypted);
    }
  }
  core.set_frame_listener(nullptr);
  if (fusion.calibrated()) {
    fusion.Close();
    spdlog::info("fusion: {} snapshots, {} fused tracks created",
                 fusion.counters().publishes, fusion.fuser().counters().fused_created);
  }
  if (tee.error) {
    std::fprintf(stderr, "lrfnetd: %s\n", tee.error->c_str());
    exit_code = kExitFailure;
  }
  if (recorder && tee.opened && !tee.error) {
    if (auto e = recorder->Close()) {
      spdlog::error("{}", *e);
      exit_code = kExitFailure;
    }
  }
  spdlog::info("status: {}", core.StatusLine(last_ns));
  if (monitoring.active()) {
    if (const std::string moved = monitoring.StatusText(); !moved.empty()) {
      spdlog::warn("monitoring: {}", moved);
    }
    if (!config.calibration_output.empty()) {
      if (std::string e = monitoring.WriteCalibration(); !e.empty()) {
        spdlog::error("monitoring: {}", e);
        exit_code = kExitFailure;
      } else {
        spdlog::info("monitoring: wrote {} ({} events in its history)", config.calibration_output,
                     monitoring.history().size());
      }
    }
  } else if ((config.calibration_auto && config.calibration_initial.empty()) ||
             !config.calibration_output.empty()) {
    const auto start = std::chrono::steady_clock::now();
    const calib::CalibrationOutcome outcome = calib::Calibrate(
        CalibrationInputFrom(core.ingest(), core.store()), config.calibration,
        [start] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(); });
    if (!outcome.ok) {
      spdlog::warn("calibration: {}", outcome.error);
      if (!config.calibration_output.empty()) exit_code = kExitFailure;
    } else {
      spdlog::info("calibration: reference {}, {} sensors, track residual {:.3f} m rms",
                   outcome.result.reference, outcome.result.sensors.size(),
                   outcome.result.track_residual_rms_m);
      if (mqtt.service) mqtt.service->PublishCalibration(outcome.result, last_ns);
      const std::string e = WriteCalibrationFiles(outcome, config.calibration_output,
                                                  config.calibration_report_dir, inputs);
      if (!e.empty()) {
        spdlog::error("calibration: {}", e);
        exit_code = kExitFailure;
      } else if (!config.calibration_output.empty()) {
        spdlog::info("calibration: wrote {}", config.calibration_output);
      }
    }
  }
  StopMqtt(&mqtt, zones, last_ns, 30.0);
  if (!WriteStats(run.stats_out, core, nullptr, recorder && tee.opened ? &*recorder : nullptr,
                  monitoring, &mqtt))
    exit_code = kExitFailure;
  std::printf("%s\n", Summary(core).c_str());
  std::fflush(stdout);
  return exit_code;
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
