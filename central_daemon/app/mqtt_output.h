#pragma once

// lrfnetd's MQTT output (section mqtt): started and stopped with a run, the monitoring's changes
// published, its counters for --stats-out.

#include <memory>
#include <nlohmann/json.hpp>

#include "central_daemon/app/config.h"
#include "central_daemon/app/mqtt_service.h"
#include "central_daemon/app/zone_service.h"
#include "common/time.h"

namespace lrfnet::daemon {

class MonitoringService;

// The MQTT output of a run: the service, its publisher and the sink between them.
struct MqttOutput {
  std::unique_ptr<MqttPublisher> publisher;
  std::unique_ptr<MqttPublisherSink> sink;
  std::unique_ptr<MqttService> service;
};

// Starts the MQTT output when configured. False (with the error printed) when it cannot start.
bool StartMqtt(const DaemonConfig& config, bool offline, MqttOutput* out);

// The final zone states and "offline", then a clean disconnect (the will is not used).
void StopMqtt(MqttOutput* mqtt, const ZoneService& zones, common::UtcNs now_ns, double timeout_s);

// What the monitoring changed, to MQTT: each watched sensor's state (in its health) and the poses
// in use (retained calibration).
void PublishMonitoring(const MonitoringService& monitoring, MqttOutput* mqtt,
                       common::UtcNs stamp_ns);

// Its counters and the service's, for --stats-out. Needs a started output.
nlohmann::json MqttJson(const MqttOutput& mqtt);

}  // namespace lrfnet::daemon
