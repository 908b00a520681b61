#include "central_daemon/app/live_run.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <boost/asio/io_context.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "central_daemon/app/auth_files.h"
#include "central_daemon/app/calibration_service.h"
#include "central_daemon/app/daemon.h"
#include "central_daemon/app/foxglove_feed.h"
#include "central_daemon/app/fusion_service.h"
#include "central_daemon/app/live_feed.h"
#include "central_daemon/app/live_state.h"
#include "central_daemon/app/monitoring_service.h"
#include "central_daemon/app/mqtt_output.h"
#include "central_daemon/app/recorder.h"
#include "central_daemon/app/run_report.h"
#include "central_daemon/app/zone_service.h"
#include "central_daemon/io/live_view_server.h"
#include "central_daemon/io/udp_receiver.h"
#include "common/host_port.h"
#include "common/systemd_notify.h"

namespace lrfnet::daemon {

namespace {

namespace asio = boost::asio;

class Replies final : public RequestSink {
 public:
  UdpReceiver* receiver = nullptr;
  bool SendTo(std::string_view source, std::span<const std::uint8_t> datagram) override {
    return receiver != nullptr && receiver->SendTo(source, datagram);
  }
};

LiveViewOptions LiveOptions(const DaemonConfig& config) {
  LiveViewOptions o;
  std::string error;
  if (const auto hp =
          common::ParseHostPort(config.live_view_listen, "live_view.listen", 0, &error, true)) {
    o.bind_address = hp->host;
    o.port = hp->port;
  }
  o.max_clients = static_cast<std::size_t>(config.live_view_max_clients);
  return o;
}

}  // namespace

int RunLive(const RunOptions& run, DaemonConfig config) {
  if (auto e = SetUpAuth(config, true)) {
    std::fprintf(stderr, "lrfnetd: %s\n", e->c_str());
    return kExitFailure;
  }
  asio::io_context io;
  std::optional<Recorder> recorder;
  if (!config.record_path.empty()) {
    recorder.emplace(RecordingOptions(config, Writer()));
    if (auto e = recorder->Open(NowUtcNs())) {
      std::fprintf(stderr, "lrfnetd: %s\n", e->c_str());
      return kExitFailure;
    }
  }
  Replies replies;
  Daemon daemon(CoreOptions(config), recorder ? &*recorder : nullptr, &replies, RandomSessionId());
  AuthStateFile auth_state(config.auth_state_dir);
  if (daemon.ingest().authenticated()) {
    std::vector<StoredAuthState> stored;
    if (auto e = auth_state.Load(&stored)) {
      std::fprintf(stderr, "lrfnetd: auth state: %s\n", e->c_str());
      return kExitFailure;
    }
    daemon.RestoreAuthState(stored);
    if (auth_state.path().empty()) {
      spdlog::warn(
          "no --state-dir (nor $STATE_DIRECTORY): after a restart this daemon would "
          "accept datagrams of its earlier run once more");
    } else {
      spdlog::info("replay state {} ({} sensors)", auth_state.path(), stored.size());
    }
  }
  CalibrationService calibration(io, config);
  FusionService fusion(io, config);
  MonitoringService monitoring(config);
  if (std::string e = fusion.Open(); !e.empty()) {
    std::fprintf(stderr, "lrfnetd: %s\n", e.c_str());
    return kExitFailure;
  }
  daemon.set_frame_listener(&fusion);
  ZoneService zones(config);
  MqttOutput mqtt;
  if (!StartMqtt(config, false, &mqtt)) return kExitFailure;
  if (mqtt.service) mqtt.service->PublishStatus(true, NowUtcNs());
  std::uint64_t applied_calibrations = 0;
  if (!config.calibration_initial.empty()) {
    calib::CalibrationOutcome initial;
    std::string text;
    if (auto e = LoadInitialCalibration(config.calibration_initial, &initial, &text)) {
      std::fprintf(stderr, "lrfnetd: %s\n", e->c_str());
      return kExitFailure;
    }
    spdlog::info("calibration: starting from {} ({} sensors)", config.calibration_initial,
                 initial.result.sensors.size());
    fusion.SetCalibration(initial.result);
    if (mqtt.service) mqtt.service->PublishCalibration(initial.result, NowUtcNs());
    monitoring.SetCalibration(initial.result, daemon, "loaded", text);
    calibration.SetInitial(std::move(initial));
  }
  std::optional<LiveViewServer> live_view;
  LiveFeed live_feed(static_cast<std::size_t>(config.live_view_background_points));
  if (!config.live_view_listen.empty()) {
    LiveViewOptions live_options = LiveOptions(config);
    if (!config.live_view_token_file.empty()) {
      if (auto e = LoadAccessToken(config.live_view_token_file, &live_options.access_token)) {
        std::fprintf(stderr, "lrfnetd: live_view.token_file %s\n", e->c_str());
        return kExitFailure;
      }
    }
    live_view.emplace(io, live_options);
    std::string error;
    if (!live_view->Start(&error)) {
      std::fprintf(stderr, "lrfnetd: --live-view %s: %s\n", config.live_view_listen.c_str(),
                   error.c_str());
      return kExitFailure;
    }
  }
  UdpReceiver receiver(
      io, config.receiver,
      [&](std::span<const std::uint8_t> bytes, const std::string& source,
          common::UtcNs receive_ns) { daemon.OnDatagram(bytes, source, receive_ns); });
  if (auto e = receiver.Open()) {
    std::fprintf(stderr, "lrfnetd: --listen %s: %s\n", config.listen.c_str(), e->c_str());
    return kExitFailure;
  }
  replies.receiver = &receiver;
  spdlog::info("listening on {} (receive buffer {} KiB){}", receiver.local_address(),
               receiver.receive_buffer_bytes() / 1024,
               recorder ? ", recording to " + config.record_path : "");
  if (receiver.receive_buffer_bytes() < config.receiver.receive_buffer_bytes / 2)
    spdlog::warn(
        "the kernel granted {} KiB of the {} KiB receive buffer asked for "
        "(net.core.rmem_max); bursts may be dropped",
        receiver.receive_buffer_bytes() / 1024, config.receiver.receive_buffer_bytes / 1024);
  if (!daemon.ingest().authenticated()) {
    spdlog::warn(
        "no --keys: the network is unauthenticated; any host that can send to {} can "
        "feed tracks into calibration and fusion (README: Keys)",
        receiver.local_address());
  }
  // Printed on stdout for scripts and tests that bind port 0.
  std::printf("listening %s\n", receiver.local_address().c_str());
  // Under systemd (Type=notify): ready once the socket is bound; the watchdog is fed from the tick
  // on the io thread, which also receives and ingests, so a hung io loop gets lrfnetd restarted.
  common::SystemdNotifier notifier(common::SystemdNotifier::ProcessEnvironment());
  if (!notifier.error().empty()) spdlog::warn("systemd notification: {}", notifier.error());
  notifier.Ready("listening on " + receiver.local_address());
  notifier.Watchdog(common::SteadyNowNs());
  if (live_view) {
    const std::string host = LiveOptions(config).bind_address;
    const std::string shown = host.find(':') != std::string::npos ? "[" + host + "]" : host;
    std::printf("live view http://%s:%u/\n", shown.c_str(),
                static_cast<unsigned>(live_view->port()));
    spdlog::info("live view on http://{}:{}/", shown, live_view->port());
  }
  std::fflush(stdout);

  bool stopping = false;
  auto stop = [&](const std::string& why) {
    if (stopping) return;
    stopping = true;
    spdlog::info("{}: stopping", why);
    notifier.Stopping();
    receiver.Close();
    if (live_view) live_view->Stop();
    io.stop();
  };

  asio::steady_timer tick(io);
  std::function<void()> schedule_tick = [&] {
    tick.expires_after(kTickPeriod);
    tick.async_wait([&](const boost::system::error_code& ec) {
      if (ec) return;
      daemon.OnTick(NowUtcNs());
      notifier.Watchdog(common::SteadyNowNs());
      LogEvents(daemon, config.ingest.silent_after_s);
      if (const std::string e = auth_state.Save(daemon.ingest(), MonotonicS(), false); !e.empty())
        spdlog::error("auth state: {}", e);
      calibration.OnTick(MonotonicS(), daemon);
      if (calibration.counters().successes != applied_calibrations && calibration.latest()) {
        applied_calibrations = calibration.counters().successes;
        monitoring.SetCalibration(calibration.latest()->result, daemon, "calibrated");
        monitoring.SetInputWindow(calibration.latest_window());
        if (std::string e = monitoring.WriteCalibration(); !e.empty()) {
          spdlog::error("monitoring: {}", e);
        }
        fusion.SetExcluded(monitoring.excluded());
        fusion.SetCalibration(calibration.latest()->result);
        if (mqtt.service)
          mqtt.service->PublishCalibration(calibration.latest()->result, NowUtcNs());
        // One line on stdout per calibration, for scripts.
        std::printf("calibrated %s\n", config.calibration_output.empty()
                                           ? "(not written)"
                                           : config.calibration_output.c_str());
        std::fflush(stdout);
      }
      if (monitoring.OnTick(daemon)) {
        // A sensor flagged (left out of the fusion) or its pose corrected (placed again).
        fusion.SetCalibration(monitoring.result());
        fusion.SetExcluded(monitoring.excluded());
        calib::CalibrationOutcome in_use;
        in_use.ok = true;
        in_use.result = monitoring.result();
        calibration.SetInitial(std::move(in_use));
        PublishMonitoring(monitoring, &mqtt, NowUtcNs());
      }
      schedule_tick();
    });
  };
  schedule_tick();

  asio::steady_timer status(io);
  std::function<void()> schedule_status = [&] {
    if (config.status_interval_s <= 0) return;
    status.expires_after(std::chrono::duration_cast<std::chrono::steady_clock::duration>(
        std::chrono::duration<double>(config.status_interval_s)));
    status.async_wait([&](const boost::system::error_code& ec) {
      if (ec) return;
      const UdpReceiverCounters& r = receiver.counters();
      std::string line = daemon.StatusLine(NowUtcNs());
      if (r.kernel_drops > 0) line += fmt::format(" | kernel drops {}", r.kernel_drops);
      line += " | " + calibration.StatusText();
      if (const std::string moved = monitoring.StatusText(); !moved.empty()) line += " | " + moved;
      if (fusion.calibrated()) {
        line += fmt::format(" | fused tracks {}", fusion.PeekOutput().tracks.size());
      }
      if (mqtt.publisher) {
        const MqttCounters m = mqtt.publisher->counters();
        line += fmt::format(" | mqtt {} sent {} dropped {}",
                            mqtt.publisher->connected() ? "connected" : "disconnected", m.sent,
                            m.dropped_queue_full + m.dropped_disconnected + m.lost_in_flight);
        if (!mqtt.publisher->connected() && !mqtt.publisher->last_error().empty())
          line += " (" + mqtt.publisher->last_error() + ")";
      }
      if (recorder)
        line += fmt::format(
            " | recorded {:.1f} MiB",
            static_cast<double>(recorder->writer().counters().bytes_written) / (1 << 20));
      spdlog::info("status: {}", line);
      notifier.Status(line);
      schedule_status();
    });
  };
  daemon.StatusLine(NowUtcNs());  // starts the first rate interval
  schedule_status();

  // Fused tracks are published at their own rate (fusion.publish_hz), not the tick's.
  asio::steady_timer fusion_timer(io);
  std::function<void()> schedule_fusion = [&] {
    fusion_timer.expires_after(std::chrono::duration_cast<std::chrono::steady_clock::duration>(
        std::chrono::duration<double>(1.0 / config.fusion_publish_hz)));
    fusion_timer.async_wait([&](const boost::system::error_code& ec) {
      if (ec || stopping) return;
      fusion.OnTick(MonotonicS());
      schedule_fusion();
    });
  };
  schedule_fusion();

  // Zones and MQTT: checked at the higher of their rates; each is due on its own clock.
  asio::steady_timer outputs_timer(io);
  const double outputs_hz = std::max(config.zones_update_hz, config.mqtt.objects_hz);
  std::function<void()> schedule_outputs = [&] {
    if (!zones.enabled() && !mqtt.service) return;
    outputs_timer.expires_after(std::chrono::duration_cast<std::chrono::steady_clock::duration>(
        std::chrono::duration<double>(1.0 / outputs_hz)));
    outputs_timer.async_wait([&](const boost::system::error_code& ec) {
      if (ec || stopping) return;
      zones.OnTick(fusion);
      if (mqtt.service) mqtt.service->OnTick(NowUtcNs(), daemon, fusion, zones);
      schedule_outputs();
    });
  };
  schedule_outputs();

  asio::steady_timer live_timer(io);
  std::function<void()> schedule_live = [&] {
    if (!live_view) return;
    live_timer.expires_after(std::chrono::duration_cast<std::chrono::steady_clock::duration>(
        std::chrono::duration<double>(1.0 / config.live_view_publish_hz)));
    live_timer.async_wait([&](const boost::system::error_code& ec) {
      if (ec || stopping) return;
      LiveState state = live_feed.Build(daemon, calibration, fusion, NowUtcNs(), Writer(), &zones);
      monitoring.Annotate(&state);
      live_view->PublishFoxglove(FoxgloveMessagesOf(state));
      live_view->Publish(LiveStateJson(state));
      schedule_live();
    });
  };
  schedule_live();

  asio::steady_timer deadline(io);
  if (run.duration_s > 0) {
    deadline.expires_after(std::chrono::duration_cast<std::chrono::steady_clock::duration>(
        std::chrono::duration<double>(run.duration_s)));
    deadline.async_wait([&](const boost::system::error_code& ec) {
      if (!ec) stop("--duration-s reached");
    });
  }

  asio::signal_set signals(io, SIGINT, SIGTERM, SIGHUP);
  signals.add(SIGUSR1);
  std::function<void()> wait_signal = [&] {
    signals.async_wait([&](const boost::system::error_code& ec, int signal_number) {
      if (ec) return;
      if (signal_number == SIGUSR1) {
        spdlog::info("SIGUSR1: calibrating{}",
                     calibration.busy() ? " after the running attempt" : "");
        calibration.Request();
        wait_signal();
        return;
      }
      if (signal_number != SIGHUP) {
        stop(signal_number == SIGINT ? "SIGINT" : "SIGTERM");
        return;
      }
      DaemonConfig reloaded;
      if (auto e = LoadConfig(run, &reloaded)) {
        spdlog::error("SIGHUP: config not reloaded: {}", *e);
      } else if (auto ended = ValidateEndedReport(reloaded.fusion, config)) {
        // The zones and MQTT keep the rates they started with: the new options must fit those.
        spdlog::error(
            "SIGHUP: config not reloaded: {} (the running zones.update_hz and "
            "mqtt.objects_hz; they change only with a restart)",
            *ended);
      } else {
        if (reloaded.listen != config.listen || reloaded.record_path != config.record_path ||
            reloaded.record_max_file_mb != config.record_max_file_mb ||
            reloaded.ingest.max_sensors != config.ingest.max_sensors ||
            reloaded.auth_keys_dir != config.auth_keys_dir ||
            reloaded.auth_state_dir != config.auth_state_dir)
          spdlog::warn(
              "SIGHUP: listen, record, auth and sensors.max_sensors changes need a restart");
        const bool status_changed = reloaded.status_interval_s != config.status_interval_s;
        config.ingest.validation = reloaded.ingest.validation;
        config.ingest.silent_after_s = reloaded.ingest.silent_after_s;
        config.ingest.request_interval_s = reloaded.ingest.request_interval_s;
        config.ingest.max_sequence_jump = reloaded.ingest.max_sequence_jump;
        config.send_requests = reloaded.send_requests;
        config.store = reloaded.store;
        config.store_max_mb = reloaded.store_max_mb;
        config.status_interval_s = reloaded.status_interval_s;
        config.calibration_auto = reloaded.calibration_auto;
        config.calibration_attempt_interval_s = reloaded.calibration_attempt_interval_s;
        config.calibration_window_s = reloaded.calibration_window_s;
        config.calibration_recalibrate_interval_s = reloaded.calibration_recalibrate_interval_s;
        config.calibration_output = reloaded.calibration_output;
        config.calibration_report_dir = reloaded.calibration_report_dir;
        config.calibration = reloaded.calibration;
        config.fusion_enabled = reloaded.fusion_enabled;
        config.fusion_publish_hz = reloaded.fusion_publish_hz;
        config.fusion = reloaded.fusion;
        config.monitoring_enabled = reloaded.monitoring_enabled;
        config.monitoring = reloaded.monitoring;
        daemon.Reconfigure(CoreOptions(config));
        calibration.Reconfigure(config);
        fusion.Reconfigure(config);
        monitoring.Reconfigure(config);
        if (status_changed) {
          status.cancel();
          schedule_status();
        }
        spdlog::info("SIGHUP: config reloaded{}",
                     run.config_path.empty() ? " (no --config file: flags and defaults)" : "");
      }
      wait_signal();
    });
  };
  wait_signal();

  io.run();

  daemon.set_frame_listener(nullptr);
  fusion.Close();
  daemon.OnTick(NowUtcNs());
  LogEvents(daemon, config.ingest.silent_after_s);
  StopMqtt(&mqtt, zones, NowUtcNs(), 2.0);
  int exit_code = kExitOk;
  if (const std::string e = auth_state.Save(daemon.ingest(), MonotonicS(), true); !e.empty()) {
    spdlog::error("auth state: {}", e);
    exit_code = kExitFailure;
  }
  if (recorder) {
    if (auto e = recorder->Close()) {
      spdlog::error("{}", *e);
      exit_code = kExitFailure;
    }
  }
  if (!WriteStats(run.stats_out, daemon, &receiver, recorder ? &*recorder : nullptr, monitoring,
                  &mqtt, &fusion, &zones))
    exit_code = kExitFailure;
  std::printf("%s received=%llu kernel_drops=%llu requests_sent=%llu%s\n", Summary(daemon).c_str(),
              static_cast<unsigned long long>(receiver.counters().datagrams),
              static_cast<unsigned long long>(receiver.counters().kernel_drops),
              static_cast<unsigned long long>(daemon.requests_sent()),
              recorder ? fmt::format(" recorded={} recording_bytes={}",
                                     recorder->writer().counters().entries_written,
                                     recorder->writer().counters().bytes_written)
                             .c_str()
                       : "");
  std::fflush(stdout);
  return exit_code;
}

}  // namespace lrfnet::daemon
