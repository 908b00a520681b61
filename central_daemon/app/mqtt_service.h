#pragma once
// lrfnetd's MQTT output (section `mqtt`): builds the messages of mqtt_messages.h from the daemon's
// parts and hands them to a sink (the MqttPublisher in lrfnetd, a fake in tests):
//   <prefix>/<site>/objects              the fused objects, at objects_hz of fused-track time
//   <prefix>/<site>/zones/<name>         retained; when the zone's counts or occupancy change, and
//                                        every zones_interval_s
//   <prefix>/<site>/calibration          retained; every new calibration
//   <prefix>/<site>/sensors/<id>/health  retained; when the sensor's state changes, and every
//                                        health_interval_s of the daemon's clock
//   <prefix>/<site>/status               retained; "online" / "offline" (also the last will)
// Objects and zones run on the fused tracks' time (gateway UTC), health on the daemon's clock (the
// receive times offline), so a silent site still reports its sensors silent.
//   <prefix>/<site>/objects/ended        when objects leave the list for good: each id, why
//                                        ("merged" with the id it goes on as, "timed_out", ...)
// An object absent from the fused tracks is left out of the object list. The fuser's output says
// what became of it (fusion::FusionOutput): one the fusion keeps unpublished (hidden) is held with
// its path for as long as the fusion keeps it, and continues its path when it comes back; one
// that ended is gone at once (a merged object's path goes on in the id it was merged into when
// that one was hidden); one the fusion reports nothing of is held for at most
// zones.absent_hold_s (see config.h). The zones treat ids alike (zones.h), so a hidden person's
// zone counts and present list do not change while it is hidden (its running dwell goes on): both
// follow the ids with fusion::IdFollower (id_follower.h), from the same FusionService::Output.
// Thread-safety: called on the io thread.

#include <cstdint>
#include <deque>
#include <map>
#include <string>
#include <string_view>

#include "central_daemon/app/config.h"
#include "central_daemon/app/daemon.h"
#include "central_daemon/app/fusion_service.h"
#include "central_daemon/app/mqtt_messages.h"
#include "central_daemon/app/zone_service.h"
#include "central_daemon/fusion/id_follower.h"
#include "central_daemon/io/mqtt_publisher.h"

namespace lrfnet::daemon {

// A sensor's health report from what the ingest knows (without the rate, which needs two
// readings). A new sensor state (e.g. a sensor that moved) is added here and in
// SensorHealthReport's list of states; a change of state is published at once. `monitor_state`:
// the monitoring's verdict on the sensor ("moved", "settling"; "" or "ok": nothing found), which
// is its state while it is not silent.
SensorHealthReport HealthReportOf(const SensorStatus& status, bool placed,
                                  std::string_view monitor_state = {});

class MqttSink {
 public:
  virtual ~MqttSink() = default;
  virtual void Publish(const std::string& topic, std::string payload, int qos, bool retain) = 0;
};

struct MqttServiceCounters {
  std::uint64_t objects = 0;
  std::uint64_t zones = 0;
  std::uint64_t calibrations = 0;
  std::uint64_t health = 0;
  std::uint64_t status = 0;
  // Objects absent from the fused tracks that came back (path kept).
  std::uint64_t objects_returned = 0;
  // Objects the fusion reported nothing of, dropped after absent_hold_s (path dropped).
  std::uint64_t objects_gone = 0;
  // Objects whose id the fusion merged into another id (dropped at once).
  std::uint64_t objects_merged = 0;
  // Objects whose id the fusion ended otherwise (timed out; every id at a new fuser).
  std::uint64_t objects_ended = 0;
  // Messages on .../objects/ended.
  std::uint64_t objects_ended_messages = 0;
  // What the id follower dropped or could not follow in the fusion's outputs (fusion::
  // IdFollowerCounters): ids listed again in one output's tracks (left out of the object list),
  // merges into a cycle and chains longer than it follows, merges into an id that ended earlier
  // in the same output (the merged objects end, merge_unresolved).
  std::uint64_t objects_duplicates = 0;
  std::uint64_t objects_merge_cycles = 0;
  std::uint64_t objects_merge_chains_cut = 0;
  std::uint64_t objects_merges_into_ended = 0;
};

class MqttService {
 public:
  // `sink` must outlive the service.
  MqttService(const DaemonConfig& config, MqttSink* sink, std::string version);

  // "<prefix>/<site>/<suffix>".
  std::string Topic(std::string_view suffix) const;
  // The last will's topic and payload (status "offline").
  std::string WillTopic() const { return Topic("status"); }
  std::string WillPayload() const;

  // Status "online" / "offline" (retained). now_ns: the daemon's clock.
  void PublishStatus(bool online, common::UtcNs now_ns);
  void PublishCalibration(const calib::CalibrationResult& result, common::UtcNs stamp_ns);
  // Publishes what is due. now_ns: the daemon's clock (live: UTC now; offline: receive time).
  void OnTick(common::UtcNs now_ns, const Daemon& daemon, const FusionService& fusion,
              const ZoneService& zones);
  // Every zone's state at once (at the end of an offline run).
  void PublishZones(const ZoneService& zones);
  // The monitoring's state of each watched sensor (see HealthReportOf); a change is published
  // with the next health reports.
  void SetMonitorStates(std::map<std::string, std::string, std::less<>> states) {
    monitor_states_ = std::move(states);
  }

  const MqttServiceCounters& counters() const { return counters_; }

 private:
  void PublishObjects(const Daemon& daemon, const FusionService& fusion);
  // Drops the objects the follower's events end or merge (a merged one's path goes on in its
  // survivor's where that takes its place); appends what ended.
  void EndObjects(const std::vector<fusion::IdEvent>& events,
                  std::vector<MqttEndedObject>& ended_out);
  void PublishZonesDue(const ZoneService& zones, bool force);
  void PublishHealthDue(common::UtcNs now_ns, const Daemon& daemon, const FusionService& fusion);

  MqttConfig config_;
  MqttSink* sink_;
  std::string version_;
  int qos_;
  int objects_qos_;
  common::DurationNs objects_period_ns_;
  common::DurationNs path_interval_ns_;
  common::DurationNs zones_interval_ns_;
  common::DurationNs health_interval_ns_;

  std::uint64_t objects_seq_ = 0;
  common::UtcNs last_objects_ns_ = 0;
  struct PathSample {
    common::UtcNs t_ns = 0;
    double x_m = 0.0, y_m = 0.0;
  };
  // Which object ids are known, held, merged or ended (the fusion's output, its generation,
  // zones.absent_hold_s), and the path of each known one.
  fusion::IdFollower follower_;
  std::map<std::uint64_t, std::deque<PathSample>> paths_;
  std::uint64_t ended_seq_ = 0;

  struct ZoneMark {
    std::uint64_t seq = 0;
    common::UtcNs published_ns = 0;
    std::uint64_t inbound = 0, outbound = 0;
    std::vector<std::uint64_t> present_ids;
    bool published = false;
  };
  std::map<std::string, ZoneMark, std::less<>> zone_marks_;

  struct HealthMark {
    std::string state;
    bool placed = false;
    common::UtcNs published_ns = 0;
    std::uint64_t datagrams = 0;
    common::UtcNs datagrams_at_ns = 0;
    double rate_hz = 0.0;
  };
  std::map<std::string, HealthMark, std::less<>> health_marks_;
  std::map<std::string, bool, std::less<>> placed_;
  std::map<std::string, std::string, std::less<>> monitor_states_;
  MqttServiceCounters counters_;
};

// The publisher's options from the config: broker, credentials, TLS, queue, backoff, and the
// service's last will.
MqttOptions PublisherOptions(const DaemonConfig& config, const MqttService& service);

// An MqttSink over an MqttPublisher.
class MqttPublisherSink final : public MqttSink {
 public:
  explicit MqttPublisherSink(MqttPublisher* publisher) : publisher_(publisher) {}
  void set_publisher(MqttPublisher* publisher) { publisher_ = publisher; }
  void Publish(const std::string& topic, std::string payload, int qos, bool retain) override {
    publisher_->Publish(topic, std::move(payload), qos, retain);
  }

 private:
  MqttPublisher* publisher_;
};

}  // namespace lrfnet::daemon
