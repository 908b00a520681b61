#include "central_daemon/app/calibration_input.h"

#include <memory>

#include "central_daemon/app/daemon.h"
#include "central_daemon/io/datagram_source.h"

namespace lrfnet::daemon {

calib::CalibrationInput CalibrationInputFrom(const Ingest& ingest, const TrackStore& store,
                                             common::UtcNs from_ns, common::UtcNs to_ns) {
  calib::CalibrationInput input;
  const std::vector<SensorStatus> statuses = ingest.Sensors();
  for (const SensorStoreInfo& info : store.Sensors()) {
    calib::SensorRecording sensor;
    sensor.id = info.sensor_id;
    sensor.frames = store.Query(info.sensor_id, from_ns, to_ns);
    if (const BackgroundScan* background = store.Background(info.sensor_id)) {
      sensor.background = *background;
    }
    for (const SensorStatus& status : statuses) {
      if (status.sensor_id != info.sensor_id) continue;
      sensor.description = status.info;
      if (status.health) sensor.clock_sync = status.health->clock_sync;
    }
    input.sensors.push_back(std::move(sensor));
  }
  return input;
}

bool LoadCalibrationInput(const std::vector<std::string>& paths, std::uint16_t udp_port,
                          calib::CalibrationInput* input, LoadCounters* counters,
                          std::string* error, const AuthOptions& auth, const InputWindow& window) {
  DaemonOptions options;
  options.send_requests = false;
  options.ingest.auth = auth;
  // Offline: keep everything the files hold (no tick, so no age eviction; memory stays bounded
  // by the store's byte limit).
  Daemon core(options, nullptr, nullptr, /*session_id=*/1);
  LoadCounters local;
  for (const std::string& path : paths) {
    DatagramSourceOptions source_options;
    source_options.udp_port = udp_port;
    std::string open_error;
    auto source = OpenDatagramFile(path, source_options, &open_error);
    if (!source) {
      *error = path + ": " + open_error;
      return false;
    }
    ++local.files;
    ReceivedDatagram d;
    SourceStatus status;
    while ((status = source->Next(&d)) == SourceStatus::kDatagram) {
      if (d.receive_ns > window.received_until_ns) continue;
      core.OnDatagram(d.bytes, d.source, d.receive_ns);
      ++local.datagrams;
    }
    if (status == SourceStatus::kError) {
      *error = path + ": " + source->error();
      return false;
    }
  }
  local.invalid = core.ingest().counters().rejected;
  local.verified = core.ingest().counters().verified;
  local.unverified = core.ingest().counters().unverified;
  *input = CalibrationInputFrom(core.ingest(), core.store(), window.scan_from_ns);
  if (counters != nullptr) *counters = local;
  return true;
}

}  // namespace lrfnet::daemon
