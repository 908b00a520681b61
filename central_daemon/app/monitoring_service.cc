#include "central_daemon/app/monitoring_service.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>

#include "central_daemon/app/calibration_service.h"
#include "central_daemon/calibration/calibration_yaml.h"

namespace lrfnet::daemon {

namespace {

// The monitor reads the store's frames.
class StoreFrames final : public monitoring::FrameSource {
 public:
  explicit StoreFrames(const TrackStore& store) : store_(store) {}
  std::vector<TrackFrameData> Frames(const std::string& sensor_id, common::UtcNs from_ns,
                                     common::UtcNs to_ns) const override {
    return store_.Query(sensor_id, from_ns, to_ns);
  }

 private:
  const TrackStore& store_;
};

common::UtcNs NewestScan(const TrackStore& store) {
  common::UtcNs newest = 0;
  for (const SensorStoreInfo& s : store.Sensors()) newest = std::max(newest, s.last_scan_ns);
  return newest;
}

std::string MotionText(const common::Pose2& before, const common::Pose2& after) {
  const common::Pose2 m = before.inverse() * after;
  return fmt::format("{:+.2f} deg, {:.3f} m", common::RadToDeg(m.yaw_rad),
                     std::hypot(m.x_m, m.y_m));
}

}  // namespace

MonitoringService::MonitoringService(const DaemonConfig& config)
    : enabled_(config.monitoring_enabled),
      output_(config.calibration_output),
      monitor_(config.monitoring) {}

void MonitoringService::Reconfigure(const DaemonConfig& config) {
  enabled_ = config.monitoring_enabled;
  output_ = config.calibration_output;
  monitor_.SetOptions(config.monitoring);
}

void MonitoringService::SetCalibration(const calib::CalibrationResult& result, const Daemon& daemon,
                                       const std::string& note, const std::string& history_text) {
  result_ = result;
  if (!history_text.empty()) {
    std::vector<calib::CalibrationEvent> loaded;
    std::string error;
    if (calib::ParseHistoryYaml(history_text, &loaded, &error)) {
      history_ = std::move(loaded);
    } else {
      spdlog::warn("monitoring: the calibration's history is not readable ({}); it starts anew",
                   error);
    }
  }
  std::vector<monitoring::SensorPose> poses;
  std::map<std::string, BackgroundScan> backgrounds;
  for (const calib::SensorPose& s : result.sensors) {
    if (!s.calibrated) continue;
    poses.push_back({s.id, s.world_from_sensor, s.covariance});
    if (const BackgroundScan* b = daemon.store().Background(s.id)) {
      backgrounds.emplace(s.id, *b);
      seen_[s.id] = {b->session_id, b->snapshot_id, b->receive_ns};
    }
  }
  monitor_.SetPoses(poses, backgrounds);
  excluded_.clear();
  active_ = !poses.empty();
  if (note == "calibrated") {
    calib::CalibrationEvent e;
    e.time_utc = UtcNowText();
    e.stamp_ns = NewestScan(daemon.store());
    e.sensor = "*";
    e.event = "calibrated";
    e.method = result.method;
    e.detail = fmt::format("{} sensors placed, reference {}, track residual {:.3f} m rms",
                           poses.size(), result.reference, result.track_residual_rms_m);
    history_.push_back(std::move(e));
    if (history_.size() > calib::kMaxHistoryEvents) history_.erase(history_.begin());
  }
}

bool MonitoringService::OnTick(const Daemon& daemon) {
  if (!active()) return false;
  const TrackStore& store = daemon.store();
  const common::UtcNs now_ns = NewestScan(store);
  if (now_ns == 0) return false;
  for (const SensorStoreInfo& info : store.Sensors()) {
    const BackgroundScan* b = store.Background(info.sensor_id);
    if (b == nullptr) continue;
    const auto key = std::make_tuple(b->session_id, b->snapshot_id, b->receive_ns);
    const auto it = seen_.find(info.sensor_id);
    if (it != seen_.end() && it->second == key) continue;
    seen_[info.sensor_id] = key;
    ++counters_.snapshots;
    monitor_.OnBackground(info.sensor_id, *b, now_ns);
  }
  monitor_.Update(now_ns, StoreFrames(store));

  const std::vector<monitoring::MonitorEvent> events = monitor_.TakeEvents();
  bool poses_changed = false;
  for (const monitoring::MonitorEvent& e : events) {
    Log(e);
    calib::CalibrationEvent h;
    h.time_utc = UtcNowText();
    h.stamp_ns = e.stamp_ns;
    h.sensor = e.sensor_id;
    h.event = monitoring::ToString(e.kind);
    h.method = e.method;
    h.detail = e.detail;
    h.before = e.before;
    h.after = e.after;
    history_.push_back(std::move(h));
    if (history_.size() > calib::kMaxHistoryEvents) history_.erase(history_.begin());
    switch (e.kind) {
      case monitoring::MonitorEventKind::kMoved:
        ++counters_.moved;
        result_.warnings.push_back(
            fmt::format("{}: found moved ({}); left out of the fusion until "
                        "its pose is estimated again",
                        e.sensor_id, e.method));
        break;
      case monitoring::MonitorEventKind::kCorrected:
        ++counters_.corrected;
        poses_changed = true;
        break;
      case monitoring::MonitorEventKind::kBackgroundRelearned:
        ++counters_.relearned;
        break;
    }
  }
  if (poses_changed) {
    for (const monitoring::SensorPose& p : monitor_.Poses()) {
      for (calib::SensorPose& s : result_.sensors) {
        if (s.id != p.id || !s.calibrated) continue;
        if (common::TranslationDistanceM(s.world_from_sensor, p.world_from_sensor) == 0.0 &&
            s.world_from_sensor.yaw_rad == p.world_from_sensor.yaw_rad) {
          continue;
        }
        s.world_from_sensor = p.world_from_sensor;
        s.covariance = p.covariance;
        result_.warnings.push_back(
            fmt::format("{}: pose estimated again after a move (history)", s.id));
      }
    }
  }
  std::set<std::string> excluded;
  for (const auto& [id, watch] : monitor_.sensors()) {
    if (watch.state != monitoring::WatchState::kWatched) excluded.insert(id);
  }
  for (const std::string& id : excluded_) {
    if (excluded.count(id) == 0) spdlog::info("monitoring: sensor {} fused again", id);
  }
  const bool exclusions_changed = excluded != excluded_;
  excluded_ = std::move(excluded);
  if (!events.empty()) {
    if (std::string error = WriteCalibration(); !error.empty()) {
      spdlog::error("monitoring: {}", error);
    }
  }
  return poses_changed || exclusions_changed;
}

std::string MonitoringService::WriteCalibration() {
  if (output_.empty() || !active_) return "";
  calib::YamlContext context;
  context.created_utc = UtcNowText();
  context.inputs = {"lrfnetd"};
  if (input_window_) {
    context.received_until_ns = input_window_->received_until_ns;
    context.scan_from_ns = input_window_->scan_from_ns;
  }
  const std::string text = calib::CalibrationYaml(result_, context) + calib::HistoryYaml(history_);
  if (std::string e = WriteFileAtomically(output_, text); !e.empty()) {
    ++counters_.write_errors;
    return e;
  }
  ++counters_.writes;
  return "";
}

void MonitoringService::Log(const monitoring::MonitorEvent& e) const {
  switch (e.kind) {
    case monitoring::MonitorEventKind::kMoved:
      spdlog::warn("monitoring: sensor {} MOVED (found by {}), left out of the fusion: {}",
                   e.sensor_id, e.method, e.detail);
      break;
    case monitoring::MonitorEventKind::kCorrected:
      spdlog::info("monitoring: sensor {} pose corrected ({}, {}): {}", e.sensor_id, e.method,
                   e.before && e.after ? MotionText(*e.before, *e.after) : "", e.detail);
      break;
    case monitoring::MonitorEventKind::kBackgroundRelearned:
      spdlog::info("monitoring: sensor {}: {}", e.sensor_id, e.detail);
      break;
  }
}

std::string MonitoringService::StatusText() const {
  if (!active()) return "";
  std::string moved;
  for (const auto& [id, watch] : monitor_.sensors()) {
    if (watch.state == monitoring::WatchState::kWatched) continue;
    if (watch.state == monitoring::WatchState::kSettling) {
      moved +=
          fmt::format("{}{} (corrected, its tracker re-learning)", moved.empty() ? "" : ", ", id);
      continue;
    }
    moved += fmt::format("{}{} ({}, about {:+.1f} deg {:.2f} m)", moved.empty() ? "" : ", ", id,
                         watch.flag_method, common::RadToDeg(watch.estimated_motion.yaw_rad),
                         std::hypot(watch.estimated_motion.x_m, watch.estimated_motion.y_m));
  }
  return moved.empty() ? "" : "MOVED, not fused: " + moved;
}

nlohmann::json MonitoringService::StatsJson() const {
  nlohmann::json j;
  j["enabled"] = enabled_;
  j["active"] = active();
  j["snapshots"] = counters_.snapshots;
  j["moved"] = counters_.moved;
  j["corrected"] = counters_.corrected;
  j["relearned"] = counters_.relearned;
  j["writes"] = counters_.writes;
  j["write_errors"] = counters_.write_errors;
  nlohmann::json sensors = nlohmann::json::object();
  for (const auto& [id, w] : monitor_.sensors()) {
    nlohmann::json s;
    s["state"] = monitoring::ToString(w.state);
    s["x_m"] = w.world_from_sensor.x_m;
    s["y_m"] = w.world_from_sensor.y_m;
    s["yaw_deg"] = common::RadToDeg(w.world_from_sensor.yaw_rad);
    s["snapshots_checked"] = w.snapshots_checked;
    s["track_checks"] = w.track_checks;
    s["moves"] = w.moves;
    s["corrections"] = w.corrections;
    s["relearns"] = w.relearns;
    s["max_track_chi2"] = w.max_track_chi2;
    s["detail"] = w.detail;
    sensors[id] = std::move(s);
  }
  j["sensors"] = std::move(sensors);
  nlohmann::json events = nlohmann::json::array();
  for (const calib::CalibrationEvent& e : history_) {
    nlohmann::json x;
    x["time_utc"] = e.time_utc;
    x["stamp_ns"] = e.stamp_ns;
    x["sensor"] = e.sensor;
    x["event"] = e.event;
    x["method"] = e.method;
    x["detail"] = e.detail;
    events.push_back(std::move(x));
  }
  j["history"] = std::move(events);
  return j;
}

void MonitoringService::Annotate(LiveState* state) const {
  if (!active()) return;
  for (LiveSensor& s : state->sensors) {
    const auto it = monitor_.sensors().find(s.id);
    if (it == monitor_.sensors().end()) continue;
    s.monitor_state = monitoring::ToString(it->second.state);
    s.monitor_detail = it->second.detail;
  }
}

}  // namespace lrfnet::daemon
