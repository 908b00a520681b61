#pragma once

// What a run of lrfnetd reports: the sensors' events in the log, every counter as JSON
// (--stats-out) and the summary line on stdout.

#include <string>

#include "central_daemon/app/daemon.h"
#include "central_daemon/io/udp_receiver.h"

namespace lrfnet::daemon {

class FusionService;
class MonitoringService;
class Recorder;
struct MqttOutput;
class ZoneService;

// Logs the events the core has collected since the last call (new, restarted, silent, back).
void LogEvents(Daemon& daemon, double silent_after_s);

// Writes every counter as JSON to `path` (nothing when empty); receiver, recorder, mqtt, fusion
// and zones are left out when null (or not started, or no zone configured). False (logged) when
// the file cannot be written.
bool WriteStats(const std::string& path, const Daemon& daemon, const UdpReceiver* receiver,
                const Recorder* recorder, const MonitoringService& monitoring,
                const MqttOutput* mqtt = nullptr, const FusionService* fusion = nullptr,
                const ZoneService* zones = nullptr);

// "summary: sensors=N datagrams=N accepted=N rejected=N lost=N frames=N".
std::string Summary(const Daemon& daemon);

}  // namespace lrfnet::daemon
