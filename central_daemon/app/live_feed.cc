#include "central_daemon/app/live_feed.h"

#include <algorithm>
#include <cmath>

namespace lrfnet::daemon {
namespace {

// Background points in the frame of `pose` (identity: the sensor frame), at most `max_points`.
std::vector<std::array<float, 2>> BackgroundPoints(const BackgroundScan& scan,
                                                   const common::Pose2& pose,
                                                   std::size_t max_points) {
  std::vector<std::array<float, 2>> out;
  std::size_t valid = 0;
  for (std::uint32_t r : scan.ranges_mm) valid += r > 0 ? 1 : 0;
  if (valid == 0 || max_points == 0) return out;
  const std::size_t stride = (valid + max_points - 1) / max_points;
  std::size_t k = 0;
  for (std::size_t i = 0; i < scan.ranges_mm.size(); ++i) {
    if (scan.ranges_mm[i] == 0) continue;
    if (k++ % stride != 0) continue;
    const double angle = scan.first_angle_rad + static_cast<double>(i) * scan.angle_step_rad;
    const double range_m = scan.ranges_mm[i] * 1e-3;
    const Eigen::Vector2d p =
        pose * Eigen::Vector2d(range_m * std::cos(angle), range_m * std::sin(angle));
    out.push_back({static_cast<float>(p.x()), static_cast<float>(p.y())});
  }
  return out;
}

}  // namespace

namespace {

// Every k-th beam (k as BackgroundPoints takes every k-th valid point) of the scan.
void BackgroundScanOf(const BackgroundScan& scan, std::size_t max_points, LiveSensor* sensor) {
  std::size_t valid = 0;
  for (std::uint32_t r : scan.ranges_mm) valid += r > 0 ? 1 : 0;
  if (valid == 0 || max_points == 0) return;
  const std::size_t stride = (valid + max_points - 1) / max_points;
  sensor->background_first_angle_rad = scan.first_angle_rad;
  sensor->background_angle_step_rad = scan.angle_step_rad * static_cast<double>(stride);
  for (std::size_t i = 0; i < scan.ranges_mm.size(); i += stride) {
    sensor->background_ranges_m.push_back(static_cast<float>(scan.ranges_mm[i] * 1e-3));
  }
}

}  // namespace

LiveSensor::Calibration LiveCalibrationOf(const calib::SensorPose& pose) {
  LiveSensor::Calibration c;
  c.calibrated = true;
  if (pose.calibrated) {
    const auto sigma = [&](int i) { return std::sqrt(std::max(0.0, pose.covariance(i, i))); };
    c.sigma_x_m = sigma(0);
    c.sigma_y_m = sigma(1);
    c.sigma_yaw_rad = sigma(2);
  }
  if (pose.radial_bias) {
    c.has_radial_bias = true;
    c.radial_bias_m = pose.radial_bias->bias_m;
    c.sigma_radial_bias_m = pose.radial_bias->sigma_m;
    c.radial_bias_estimated = pose.radial_bias->estimated;
  }
  c.mount_looks_like_legs = pose.mount_looks_like_legs;
  c.flag = pose.flag;
  return c;
}

LiveState LiveFeed::Build(const Daemon& daemon, const CalibrationService& calibration,
                          const FusionService& fusion, common::UtcNs now_ns,
                          const std::string& version, const ZoneService* zones) {
  LiveState state;
  state.stamp_ns = fusion.now_ns() != 0 ? fusion.now_ns() : now_ns;
  state.version = version;
  state.authenticated = daemon.ingest().authenticated();

  // Calibration.
  const auto& latest = calibration.latest();
  std::map<std::string, common::Pose2, std::less<>> poses;
  std::map<std::string, const calib::SensorPose*, std::less<>> calibrated;
  if (latest) {
    for (const calib::SensorPose& s : latest->result.sensors) {
      if (s.calibrated) poses[s.id] = s.world_from_sensor;
      calibrated[s.id] = &s;
    }
    state.calibration.state = "calibrated";
    state.calibration.progress = 1.0;
    state.calibration.reference = latest->result.reference;
    state.calibration.track_residual_rms_m = latest->result.track_residual_rms_m;
    char text[120];
    std::snprintf(text, sizeof text, "%zu sensors placed, track residual %.3f m rms", poses.size(),
                  latest->result.track_residual_rms_m);
    state.calibration.message = text;
    if (calibration.busy()) state.calibration.message += "; recalibrating";
  } else {
    state.calibration.state = calibration.busy() ? "calibrating" : "collecting";
    state.calibration.progress = calibration.progress().fraction;
    state.calibration.message = calibration.progress().text;
    if (const auto remaining = calibration.RemainingS(); remaining && *remaining >= 1.0) {
      char text[64];
      std::snprintf(text, sizeof text, ", about %.0f s more", *remaining);
      state.calibration.message += text;
    }
  }

  // Sensors.
  for (const SensorStatus& s : daemon.ingest().Sensors()) {
    LiveSensor sensor;
    sensor.id = s.sensor_id;
    const auto pose = poses.find(s.sensor_id);
    sensor.placed = pose != poses.end();
    if (sensor.placed) sensor.world_from_sensor = pose->second;
    if (const auto c = calibrated.find(s.sensor_id); c != calibrated.end()) {
      sensor.calibration = LiveCalibrationOf(*c->second);
    }
    if (s.info) {
      sensor.model = s.info->model;
      sensor.first_angle_rad = s.info->first_angle_rad;
      sensor.fov_rad = s.info->fov_rad;
      sensor.max_range_m = s.info->max_range_m;
    }
    sensor.status = s.silent ? "silent" : (s.counters.track_frames > 0 ? "active" : "waiting");
    Mark& mark = marks_[s.sensor_id];
    if (mark.at_ns != 0 && now_ns > mark.at_ns) {
      mark.rate_hz = static_cast<double>(s.counters.datagrams - mark.datagrams) /
                     (static_cast<double>(now_ns - mark.at_ns) * 1e-9);
    }
    mark.datagrams = s.counters.datagrams;
    mark.at_ns = now_ns;
    sensor.datagram_rate_hz = mark.rate_hz;
    const double received = static_cast<double>(s.counters.sequence.received);
    const double lost = static_cast<double>(s.counters.sequence.lost);
    sensor.loss = received + lost > 0 ? lost / (received + lost) : 0.0;
    sensor.clock_sync = s.health ? ToString(s.health->clock_sync) : "unknown";
    sensor.track_frames = s.counters.track_frames;
    if (const BackgroundScan* background = daemon.store().Background(s.sensor_id)) {
      sensor.background_xy = BackgroundPoints(
          *background, sensor.placed ? sensor.world_from_sensor : common::Pose2::Identity(),
          background_points_);
      BackgroundScanOf(*background, background_points_, &sensor);
    }
    state.sensors.push_back(std::move(sensor));
  }

  // Raw tracks: world frame where placed (from the fuser, with their fused ids), else the
  // sensor's latest frame in its own frame.
  if (fusion.calibrated()) {
    for (const fusion::WorldTrack& t : fusion.fuser().WorldTracks(fusion.now_ns())) {
      LiveTrack track;
      track.sensor_id = t.sensor_id;
      track.track_id = t.track_id;
      track.state = ToString(t.state);
      track.x_m = t.x_m;
      track.y_m = t.y_m;
      track.vx_mps = t.vx_mps;
      track.vy_mps = t.vy_mps;
      track.fused_id = t.fused_id;
      state.tracks.push_back(std::move(track));
    }
    const fusion::FusionOutput& output = fusion.PeekOutput();
    for (const fusion::HiddenFusedTrack& h : output.hidden) {
      state.hidden.push_back(
          {h.id, h.x_m, h.y_m,
           common::NsToSeconds(std::max<common::DurationNs>(0, output.stamp_ns - h.last_ns)),
           h.last_sensor});
    }
    for (const fusion::FusedTrack& f : output.tracks) {
      LiveFusedTrack fused;
      fused.id = f.id;
      fused.state = fusion::ToString(f.state);
      fused.x_m = f.x_m;
      fused.y_m = f.y_m;
      fused.vx_mps = f.vx_mps;
      fused.vy_mps = f.vy_mps;
      fused.cov_xx = f.covariance(0, 0);
      fused.cov_xy = f.covariance(0, 1);
      fused.cov_yy = f.covariance(1, 1);
      for (const fusion::FusedSource& source : f.sources) fused.sensors.push_back(source.sensor_id);
      state.fused.push_back(std::move(fused));
    }
  }
  // A frame older than this is not drawn (the sensor lost its tracks or went silent).
  constexpr common::DurationNs kStaleNs = 1'000'000'000;
  for (const SensorStoreInfo& info : daemon.store().Sensors()) {
    if (poses.count(info.sensor_id) != 0 && fusion.calibrated()) continue;
    if (info.frames == 0 || fusion.now_ns() - info.last_scan_ns > kStaleNs) continue;
    // The newest scan, its parts merged by the store.
    const std::vector<TrackFrameData> newest =
        daemon.store().Query(info.sensor_id, info.last_scan_ns, info.last_scan_ns + 1);
    if (newest.empty()) continue;
    const std::string& sensor_id = info.sensor_id;
    for (const TrackObservation& o : newest.back().tracks) {
      if (o.state == TrackState::kTentative) continue;
      LiveTrack track;
      track.sensor_id = sensor_id;
      track.track_id = o.track_id;
      track.state = ToString(o.state);
      track.x_m = o.x_m;
      track.y_m = o.y_m;
      track.vx_mps = o.vx_mps;
      track.vy_mps = o.vy_mps;
      state.tracks.push_back(std::move(track));
    }
  }
  if (zones != nullptr) {
    const std::vector<zones::ZoneState> states = zones->States();
    for (std::size_t i = 0; i < zones->zones().size(); ++i) {
      const zones::Zone& z = zones->zones()[i];
      LiveZone zone;
      zone.name = z.name;
      zone.kind = zones::ToString(z.kind);
      for (const zones::Point& p : z.points) zone.points.push_back({p.x_m, p.y_m});
      if (i < states.size()) {
        zone.occupancy = states[i].present_ids.size();
        zone.inbound = states[i].inbound;
        zone.outbound = states[i].outbound;
      }
      state.zones.push_back(std::move(zone));
    }
  }
  return state;
}

}  // namespace lrfnet::daemon
