#include "central_daemon/app/run_report.h"

#include <spdlog/spdlog.h>

#include <cstdint>
#include <fstream>
#include <nlohmann/json.hpp>
#include <vector>

#include "central_daemon/app/fusion_service.h"
#include "central_daemon/app/monitoring_service.h"
#include "central_daemon/app/mqtt_output.h"
#include "central_daemon/app/recorder.h"
#include "central_daemon/app/stats_json.h"
#include "central_daemon/app/zone_service.h"

namespace lrfnet::daemon {

void LogEvents(Daemon& daemon, double silent_after_s) {
  for (const SensorEvent& e : daemon.TakeEvents()) {
    const auto sensor = daemon.ingest().Sensor(e.sensor_id);
    const std::string source = sensor ? sensor->source : "";
    switch (e.kind) {
      case SensorEventKind::kNew:
        spdlog::info("sensor {}: first datagram from {}", e.sensor_id, source);
        break;
      case SensorEventKind::kRestart:
        spdlog::warn("sensor {}: tracker restarted (new session) at {}", e.sensor_id, source);
        break;
      case SensorEventKind::kSequenceReset:
        spdlog::warn("sensor {}: sequence number jumped; sequence state restarted", e.sensor_id);
        break;
      case SensorEventKind::kSilent:
        spdlog::warn("sensor {}: silent (no datagram for {:.1f} s)", e.sensor_id, silent_after_s);
        break;
      case SensorEventKind::kBack:
        spdlog::info("sensor {}: back (from {})", e.sensor_id, source);
        break;
    }
  }
}

bool WriteStats(const std::string& path, const Daemon& daemon, const UdpReceiver* receiver,
                const Recorder* recorder, const MonitoringService& monitoring,
                const MqttOutput* mqtt, const FusionService* fusion, const ZoneService* zones) {
  if (path.empty()) return true;
  nlohmann::json j = StatsJson(daemon.ingest(), daemon.store());
  if (mqtt != nullptr && mqtt->publisher) j["mqtt"] = MqttJson(*mqtt);
  j["monitoring"] = monitoring.StatsJson();
  if (fusion != nullptr) j["fusion"] = fusion->StatsJson();
  if (zones != nullptr && zones->enabled()) {
    const zones::ZoneCounters& z = zones->counters();
    j["zones"] = {{"updates", zones->updates()},
                  {"absent_held", z.absent_held},
                  {"absent_returned", z.absent_returned},
                  {"absent_gone", z.absent_gone},
                  {"merged", z.merged},
                  {"ended", z.ended},
                  {"expired", z.expired},
                  {"restarts", z.restarts},
                  {"merges_unresolved", z.merges_unresolved},
                  {"duplicates", z.duplicates},
                  {"merges_into_ended", z.merges_into_ended}};
  }
  j["requests_sent"] = daemon.requests_sent();
  j["requests_dropped"] = daemon.requests_dropped();
  if (receiver != nullptr) j["receiver"] = ReceiverJson(receiver->counters());
  if (recorder != nullptr) j["recording"] = RecordingJson(recorder->writer().counters());
  std::ofstream out(path);
  out << j.dump(2) << "\n";
  if (!out) {
    spdlog::error("--stats-out {}: cannot write", path);
    return false;
  }
  return true;
}

std::string Summary(const Daemon& daemon) {
  const IngestCounters& c = daemon.ingest().counters();
  const std::vector<SensorStatus> sensors = daemon.ingest().Sensors();
  std::uint64_t lost = 0;
  for (const SensorStatus& s : sensors) lost += s.counters.sequence.lost;
  return fmt::format("summary: sensors={} datagrams={} accepted={} rejected={} lost={} frames={}",
                     sensors.size(), c.datagrams, c.accepted, c.rejected, lost,
                     daemon.store().frames());
}

}  // namespace lrfnet::daemon
