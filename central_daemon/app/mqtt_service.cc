#include "central_daemon/app/mqtt_service.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/host_port.h"

namespace lrfnet::daemon {
namespace {

common::DurationNs PeriodNs(double seconds) {
  return static_cast<common::DurationNs>(seconds * 1e9);
}

// Due when at least 90 % of the period passed (timer jitter), or the clock stepped back.
bool Due(common::UtcNs now_ns, common::UtcNs last_ns, common::DurationNs period_ns) {
  return last_ns == 0 || now_ns < last_ns || now_ns - last_ns >= period_ns * 9 / 10;
}

}  // namespace

MqttService::MqttService(const DaemonConfig& config, MqttSink* sink, std::string version)
    : config_(config.mqtt),
      sink_(sink),
      version_(std::move(version)),
      qos_(static_cast<int>(config.mqtt.qos)),
      objects_qos_(static_cast<int>(config.mqtt.objects_qos)),
      objects_period_ns_(PeriodNs(1.0 / config.mqtt.objects_hz)),
      path_interval_ns_(PeriodNs(config.mqtt.path_interval_s)),
      zones_interval_ns_(PeriodNs(config.mqtt.zones_interval_s)),
      health_interval_ns_(PeriodNs(config.mqtt.health_interval_s)),
      follower_(fusion::IdFollowerOptions{.absent_hold_s = config.zone_options.absent_hold_s}) {}

std::string MqttService::Topic(std::string_view suffix) const {
  return config_.topic_prefix + "/" + config_.site + "/" + std::string(suffix);
}

std::string MqttService::WillPayload() const {
  return StatusJson(config_.site, "offline", version_, std::nullopt);
}

void MqttService::PublishStatus(bool online, common::UtcNs now_ns) {
  sink_->Publish(Topic("status"),
                 StatusJson(config_.site, online ? "online" : "offline", version_, now_ns), qos_,
                 true);
  ++counters_.status;
}

void MqttService::PublishCalibration(const calib::CalibrationResult& result,
                                     common::UtcNs stamp_ns) {
  sink_->Publish(Topic("calibration"), CalibrationJson(config_.site, stamp_ns, result), qos_, true);
  ++counters_.calibrations;
  placed_.clear();
  for (const calib::SensorPose& s : result.sensors) placed_[s.id] = s.calibrated;
}

void MqttService::OnTick(common::UtcNs now_ns, const Daemon& daemon, const FusionService& fusion,
                         const ZoneService& zones) {
  const common::UtcNs data_ns = fusion.now_ns();
  if (fusion.calibrated() && data_ns != 0 && Due(data_ns, last_objects_ns_, objects_period_ns_)) {
    last_objects_ns_ = data_ns;
    PublishObjects(daemon, fusion);
  }
  if (zones.enabled() && zones.updates() > 0) PublishZonesDue(zones, false);
  PublishHealthDue(now_ns, daemon, fusion);
}

void MqttService::PublishZones(const ZoneService& zones) {
  if (zones.enabled() && zones.updates() > 0) PublishZonesDue(zones, true);
}

void MqttService::EndObjects(const std::vector<fusion::IdEvent>& events,
                             std::vector<MqttEndedObject>& ended_out) {
  for (const fusion::IdEvent& e : events) {
    if (e.kind == fusion::IdEventKind::kMerged) {
      const auto it = paths_.find(e.id);
      if (it != paths_.end()) {
        if (!e.survivor_known) {
          paths_[e.survivor] = std::move(it->second);  // the survivor goes on with its path
        } else if (e.survivor_held && !e.was_held) {
          // The survivor's estimate is now the merged one's: its path goes on from there.
          std::deque<PathSample>& path = paths_[e.survivor];
          for (const PathSample& p : it->second) {
            if (path.empty() || p.t_ns > path.back().t_ns) path.push_back(p);
          }
          while (path.size() >
                 static_cast<std::size_t>(std::max<std::int64_t>(config_.path_points, 0))) {
            path.pop_front();
          }
        }
        paths_.erase(e.id);
      }
      ended_out.push_back(
          {e.id, fusion::ToString(fusion::FusedEndReason::kMerged), e.survivor, e.ended_ns});
      ++counters_.objects_merged;
    } else if (e.kind == fusion::IdEventKind::kEnded) {
      paths_.erase(e.id);
      ended_out.push_back({e.id, fusion::ToString(e.reason), 0, e.ended_ns});
      if (e.reason == fusion::IdEndReason::kHoldExpired) {
        ++counters_.objects_gone;
      } else {
        ++counters_.objects_ended;
      }
    }
  }
}

void MqttService::PublishObjects(const Daemon& daemon, const FusionService& fusion) {
  const common::UtcNs stamp_ns = fusion.now_ns();
  const fusion::FusionOutput& output = fusion.Output();
  const std::vector<fusion::FusedTrack>& tracks = output.tracks;
  // Ended ids first (a new fuser ends every one), then the present ones; held ones stay.
  const std::vector<fusion::IdEvent>& events =
      follower_.Update(output, fusion.generation(), stamp_ns);
  const fusion::IdFollowerCounters& f = follower_.counters();
  counters_.objects_duplicates = f.duplicates;
  counters_.objects_merge_cycles = f.merge_cycles;
  counters_.objects_merge_chains_cut = f.merge_chains_cut;
  counters_.objects_merges_into_ended = f.merges_into_ended;
  std::vector<MqttEndedObject> ended;
  EndObjects(events, ended);

  // The newest frame of every sensor that is a source: the tracker's size estimates.
  std::map<std::string, std::vector<TrackObservation>, std::less<>> newest;
  for (const fusion::FusedTrack& t : tracks) {
    for (const fusion::FusedSource& s : t.sources) newest.try_emplace(s.sensor_id);
  }
  for (const SensorStoreInfo& info : daemon.store().Sensors()) {
    auto it = newest.find(info.sensor_id);
    if (it == newest.end() || info.frames == 0) continue;
    std::vector<TrackFrameData> frames =
        daemon.store().Query(info.sensor_id, info.last_scan_ns, info.last_scan_ns + 1);
    if (!frames.empty()) it->second = std::move(frames.back().tracks);
  }

  std::vector<MqttObject> objects;
  objects.reserve(tracks.size());
  for (const fusion::IdEvent& e : events) {
    if (e.kind != fusion::IdEventKind::kPresent) continue;
    const fusion::FusedTrack& t = *e.track;
    MqttObject o;
    o.track = t;
    // The size of the best-measured source (smallest sigma), if any tracker estimated one.
    double best_sigma = std::numeric_limits<double>::infinity();
    for (const fusion::FusedSource& s : t.sources) {
      const auto frame = newest.find(s.sensor_id);
      if (frame == newest.end()) continue;
      for (const TrackObservation& obs : frame->second) {
        if (obs.track_id != s.track_id || !(obs.size_major_m > 0.0f)) continue;
        const double sigma = obs.size_sigma_m > 0.0f ? obs.size_sigma_m : 1e3;
        if (sigma < best_sigma) {
          best_sigma = sigma;
          o.length_m = 2.0 * obs.size_major_m;
          o.width_m = 2.0 * obs.size_minor_m;
        }
      }
    }
    // The path: samples every path_interval_s, the newest last, then the current position.
    if (e.returned) ++counters_.objects_returned;
    std::deque<PathSample>& path = paths_[t.id];
    if (config_.path_points > 0) {
      if (path.empty() || stamp_ns - path.back().t_ns >= path_interval_ns_ ||
          stamp_ns < path.back().t_ns) {
        path.push_back({stamp_ns, t.x_m, t.y_m});
        while (path.size() > static_cast<std::size_t>(config_.path_points)) path.pop_front();
      }
      for (const PathSample& p : path) {
        o.path.push_back({p.x_m, p.y_m, common::NsToSeconds(p.t_ns - stamp_ns)});
      }
    }
    objects.push_back(std::move(o));
  }
  sink_->Publish(Topic("objects"), ObjectsJson(config_.site, ++objects_seq_, stamp_ns, objects),
                 objects_qos_, false);
  ++counters_.objects;
  if (!ended.empty()) {
    sink_->Publish(Topic("objects/ended"),
                   ObjectsEndedJson(config_.site, ++ended_seq_, stamp_ns, ended), qos_, false);
    ++counters_.objects_ended_messages;
  }
}

void MqttService::PublishZonesDue(const ZoneService& zones, bool force) {
  const common::UtcNs stamp_ns = zones.stamp_ns();
  for (const zones::ZoneState& z : zones.States()) {
    ZoneMark& mark = zone_marks_[z.name];
    const bool changed = !mark.published || z.inbound != mark.inbound ||
                         z.outbound != mark.outbound || z.present_ids != mark.present_ids;
    if (!force && !changed && !Due(stamp_ns, mark.published_ns, zones_interval_ns_)) continue;
    mark.published = true;
    mark.published_ns = stamp_ns;
    mark.inbound = z.inbound;
    mark.outbound = z.outbound;
    mark.present_ids = z.present_ids;
    sink_->Publish(Topic("zones/" + z.name), ZoneJson(config_.site, ++mark.seq, stamp_ns, z), qos_,
                   true);
    ++counters_.zones;
  }
}

SensorHealthReport HealthReportOf(const SensorStatus& s, bool placed,
                                  std::string_view monitor_state) {
  SensorHealthReport h;
  h.sensor_id = s.sensor_id;
  h.state = s.silent ? "silent" : (s.counters.track_frames > 0 ? "active" : "waiting");
  if (!s.silent && !monitor_state.empty() && monitor_state != "ok") h.state = monitor_state;
  h.placed = placed;
  if (s.info) h.model = s.info->model;
  const double received = static_cast<double>(s.counters.sequence.received);
  const double lost = static_cast<double>(s.counters.sequence.lost);
  h.loss = received + lost > 0 ? lost / (received + lost) : 0.0;
  h.clock_sync = s.health ? ToString(s.health->clock_sync) : "unknown";
  h.track_frames = s.counters.track_frames;
  for (const std::uint64_t r : s.counters.rejected) h.rejected += r;
  h.restarts = s.counters.sequence.restarts;
  h.last_receive_ns = s.last_receive_ns;
  return h;
}

void MqttService::PublishHealthDue(common::UtcNs now_ns, const Daemon& daemon,
                                   const FusionService& fusion) {
  for (const SensorStatus& s : daemon.ingest().Sensors()) {
    HealthMark& mark = health_marks_[s.sensor_id];
    const auto placed = placed_.find(s.sensor_id);
    const auto monitor = monitor_states_.find(s.sensor_id);
    SensorHealthReport h =
        HealthReportOf(s, fusion.calibrated() && placed != placed_.end() && placed->second,
                       monitor != monitor_states_.end() ? monitor->second : std::string_view{});
    const bool changed = h.state != mark.state || h.placed != mark.placed;
    if (!changed && !Due(now_ns, mark.published_ns, health_interval_ns_)) continue;
    if (mark.datagrams_at_ns != 0 && now_ns > mark.datagrams_at_ns) {
      mark.rate_hz = static_cast<double>(s.counters.datagrams - mark.datagrams) /
                     common::NsToSeconds(now_ns - mark.datagrams_at_ns);
    }
    mark.datagrams = s.counters.datagrams;
    mark.datagrams_at_ns = now_ns;
    h.datagram_rate_hz = mark.rate_hz;
    mark.state = h.state;
    mark.placed = h.placed;
    mark.published_ns = now_ns;
    sink_->Publish(Topic("sensors/" + s.sensor_id + "/health"),
                   SensorHealthJson(config_.site, now_ns, h), qos_, true);
    ++counters_.health;
  }
}

MqttOptions PublisherOptions(const DaemonConfig& config, const MqttService& service) {
  const MqttConfig& m = config.mqtt;
  MqttOptions o;
  std::string error;
  if (const auto hp = common::ParseHostPort(m.broker, "mqtt.broker", 1883, &error)) {
    o.host = hp->host;
    o.port = hp->port;
  }
  o.client_id = m.client_id.empty() ? "lrfnetd-" + m.site : m.client_id;
  o.username = m.username;
  o.password = m.password;
  o.tls = m.tls;
  o.tls_ca_file = m.tls_ca_file;
  o.tls_cert_file = m.tls_cert_file;
  o.tls_key_file = m.tls_key_file;
  o.tls_insecure = m.tls_insecure;
  o.keepalive_s = static_cast<int>(m.keepalive_s);
  o.queue_messages = static_cast<std::size_t>(m.queue_messages);
  o.reconnect_min_s = m.reconnect_min_s;
  o.reconnect_max_s = m.reconnect_max_s;
  o.will_topic = service.WillTopic();
  o.will_payload = service.WillPayload();
  o.will_qos = static_cast<int>(m.qos);
  return o;
}

}  // namespace lrfnet::daemon
