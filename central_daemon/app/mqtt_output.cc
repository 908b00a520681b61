#include "central_daemon/app/mqtt_output.h"

#include <spdlog/spdlog.h>

#include <cstdio>
#include <map>
#include <string>
#include <utility>

#include "central_daemon/app/monitoring_service.h"
#include "central_daemon/app/run_setup.h"

namespace lrfnet::daemon {

bool StartMqtt(const DaemonConfig& config, bool offline, MqttOutput* out) {
  if (config.mqtt.broker.empty()) return true;
  out->sink = std::make_unique<MqttPublisherSink>(nullptr);
  out->service = std::make_unique<MqttService>(config, out->sink.get(), Writer());
  MqttOptions options = PublisherOptions(config, *out->service);
  options.wait_when_full = offline;
  out->publisher = std::make_unique<MqttPublisher>(options);
  out->sink->set_publisher(out->publisher.get());
  std::string error;
  if (!out->publisher->Start(&error)) {
    std::fprintf(stderr, "lrfnetd: %s\n", error.c_str());
    return false;
  }
  spdlog::info("mqtt: publishing to {} as {}/{}/...", config.mqtt.broker, config.mqtt.topic_prefix,
               config.mqtt.site);
  return true;
}

void StopMqtt(MqttOutput* mqtt, const ZoneService& zones, common::UtcNs now_ns, double timeout_s) {
  if (!mqtt->service) return;
  mqtt->service->PublishZones(zones);
  mqtt->service->PublishStatus(false, now_ns);
  mqtt->publisher->Stop(timeout_s);
  const MqttCounters c = mqtt->publisher->counters();
  spdlog::info(
      "mqtt: {} messages sent, {} dropped (queue full {}, broker unreachable {}, lost in "
      "flight {}), {} connects, {} lost connections",
      c.sent, c.dropped_queue_full + c.dropped_disconnected + c.lost_in_flight,
      c.dropped_queue_full, c.dropped_disconnected, c.lost_in_flight, c.connects, c.disconnects);
}

void PublishMonitoring(const MonitoringService& monitoring, MqttOutput* mqtt,
                       common::UtcNs stamp_ns) {
  if (!mqtt->service) return;
  std::map<std::string, std::string, std::less<>> states;
  for (const auto& [id, watch] : monitoring.monitor().sensors()) {
    states[id] = monitoring::ToString(watch.state);
  }
  mqtt->service->SetMonitorStates(std::move(states));
  mqtt->service->PublishCalibration(monitoring.result(), stamp_ns);
}

nlohmann::json MqttJson(const MqttOutput& mqtt) {
  const MqttCounters c = mqtt.publisher->counters();
  const MqttServiceCounters& s = mqtt.service->counters();
  return {{"submitted", c.submitted},
          {"sent", c.sent},
          {"dropped_queue_full", c.dropped_queue_full},
          {"dropped_disconnected", c.dropped_disconnected},
          {"lost_in_flight", c.lost_in_flight},
          {"retained_replaced", c.retained_replaced},
          {"publish_errors", c.publish_errors},
          {"connects", c.connects},
          {"connect_failures", c.connect_failures},
          {"disconnects", c.disconnects},
          {"resent", c.resent},
          {"unsent", c.queued + c.in_flight},
          {"objects", s.objects},
          {"zones", s.zones},
          {"calibrations", s.calibrations},
          {"health", s.health},
          {"objects_returned", s.objects_returned},
          {"objects_gone", s.objects_gone},
          {"objects_merged", s.objects_merged},
          {"objects_ended", s.objects_ended},
          {"objects_ended_messages", s.objects_ended_messages},
          {"objects_duplicates", s.objects_duplicates},
          {"objects_merge_cycles", s.objects_merge_cycles},
          {"objects_merge_chains_cut", s.objects_merge_chains_cut},
          {"objects_merges_into_ended", s.objects_merges_into_ended}};
}

}  // namespace lrfnet::daemon
