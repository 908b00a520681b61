#include "central_daemon/app/offline_run.h"

#include <spdlog/spdlog.h>

#include <boost/asio/io_context.hpp>
#include <chrono>
#include <cstdio>
#include <memory>
#include <optional>
#include <span>
#include <string_view>
#include <utility>

#include "central_daemon/app/calibration_input.h"
#include "central_daemon/app/calibration_service.h"
#include "central_daemon/app/daemon.h"
#include "central_daemon/app/fusion_service.h"
#include "central_daemon/app/monitoring_service.h"
#include "central_daemon/app/mqtt_output.h"
#include "central_daemon/app/recorder.h"
#include "central_daemon/app/run_report.h"
#include "central_daemon/app/zone_service.h"
#include "central_daemon/io/datagram_source.h"

namespace lrfnet::daemon {

namespace asio = boost::asio;

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
    if (fusion.calibrated() &&
        (d.receive_ns - last_fusion_ns >= fusion_period_ns || d.receive_ns < last_fusion_ns)) {
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
    spdlog::info("fusion: {} snapshots, {} fused tracks created", fusion.counters().publishes,
                 fusion.fuser().counters().fused_created);
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
        CalibrationInputFrom(core.ingest(), core.store()), config.calibration, [start] {
          return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        });
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
                  monitoring, &mqtt, &fusion, &zones))
    exit_code = kExitFailure;
  std::printf("%s\n", Summary(core).c_str());
  std::fflush(stdout);
  return exit_code;
}

}  // namespace lrfnet::daemon
