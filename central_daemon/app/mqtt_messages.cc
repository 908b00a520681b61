#include "central_daemon/app/mqtt_messages.h"

#include <cmath>
#include <nlohmann/json.hpp>

namespace lrfnet::daemon {
namespace {

using Json = nlohmann::ordered_json;

double Rounded(double v, double per_unit) {
  if (!std::isfinite(v) || std::abs(v) > 1e12) return v;
  return std::round(v * per_unit) / per_unit;
}

std::string Dump(const Json& j) { return j.dump(-1, ' ', false, Json::error_handler_t::replace); }

Json Header(const char* type, const std::string& site) {
  Json j;
  j["type"] = type;
  j["site"] = site;
  return j;
}

double RadToDeg(double rad) { return rad * 180.0 / std::acos(-1.0); }

}  // namespace

std::string ObjectsJson(const std::string& site, std::uint64_t seq, common::UtcNs stamp_ns,
                        const std::vector<MqttObject>& objects) {
  Json j = Header("objects", site);
  j["seq"] = seq;
  j["stamp_ns"] = stamp_ns;
  j["frame"] = "world";
  Json list = Json::array();
  for (const MqttObject& o : objects) {
    const fusion::FusedTrack& t = o.track;
    Json e;
    e["id"] = t.id;
    e["state"] = fusion::ToString(t.state);
    e["x_m"] = Rounded(t.x_m, 1e3);
    e["y_m"] = Rounded(t.y_m, 1e3);
    e["vx_mps"] = Rounded(t.vx_mps, 1e3);
    e["vy_mps"] = Rounded(t.vy_mps, 1e3);
    Json cov = Json::array();
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) cov.push_back(Rounded(t.covariance(r, c), 1e6));
    }
    e["covariance"] = std::move(cov);
    if (o.length_m && o.width_m) {
      e["size"] = {{"length_m", Rounded(*o.length_m, 1e3)}, {"width_m", Rounded(*o.width_m, 1e3)}};
    } else {
      e["size"] = nullptr;
    }
    e["age_s"] =
        Rounded(common::NsToSeconds(std::max<common::DurationNs>(0, stamp_ns - t.first_ns)), 1e3);
    Json sensors = Json::array();
    for (const fusion::FusedSource& s : t.sources) {
      if (sensors.empty() || sensors.back() != s.sensor_id) sensors.push_back(s.sensor_id);
    }
    e["sensors"] = std::move(sensors);
    Json path = Json::array();
    for (const MqttObject::PathPoint& p : o.path) {
      path.push_back(Json::array({Rounded(p.x_m, 1e3), Rounded(p.y_m, 1e3), Rounded(p.t_s, 1e3)}));
    }
    e["path"] = std::move(path);
    list.push_back(std::move(e));
  }
  j["objects"] = std::move(list);
  return Dump(j);
}

std::string ObjectsEndedJson(const std::string& site, std::uint64_t seq, common::UtcNs stamp_ns,
                             const std::vector<MqttEndedObject>& ended) {
  Json j = Header("objects_ended", site);
  j["seq"] = seq;
  j["stamp_ns"] = stamp_ns;
  Json list = Json::array();
  for (const MqttEndedObject& e : ended) {
    Json o;
    o["id"] = e.id;
    o["reason"] = e.reason;
    if (e.merged_into != 0) {
      o["merged_into"] = e.merged_into;
    } else {
      o["merged_into"] = nullptr;
    }
    o["ended_ns"] = e.ended_ns;
    list.push_back(std::move(o));
  }
  j["ended"] = std::move(list);
  return Dump(j);
}

std::string ZoneJson(const std::string& site, std::uint64_t seq, common::UtcNs stamp_ns,
                     const zones::ZoneState& zone) {
  Json j = Header("zone", site);
  j["seq"] = seq;
  j["stamp_ns"] = stamp_ns;
  j["name"] = zone.name;
  j["kind"] = zones::ToString(zone.kind);
  j["occupancy"] = zone.present_ids.size();
  Json present = Json::array();
  for (std::size_t i = 0; i < zone.present_ids.size(); ++i) {
    present.push_back(
        {{"id", zone.present_ids[i]},
         {"dwell_s",
          Rounded(i < zone.present_dwell_s.size() ? zone.present_dwell_s[i] : 0.0, 1e3)}});
  }
  j["present"] = std::move(present);
  j["inbound"] = zone.inbound;
  j["outbound"] = zone.outbound;
  const double mean_s = zone.dwells_completed > 0
                            ? zone.dwell_total_s / static_cast<double>(zone.dwells_completed)
                            : 0.0;
  j["dwell"] = {{"completed", zone.dwells_completed},
                {"mean_s", Rounded(mean_s, 1e3)},
                {"max_s", Rounded(zone.dwell_max_s, 1e3)}};
  j["lost_inside"] = zone.lost_inside;
  return Dump(j);
}

std::string CalibrationJson(const std::string& site, common::UtcNs stamp_ns,
                            const calib::CalibrationResult& result) {
  Json j = Header("calibration", site);
  j["stamp_ns"] = stamp_ns;
  j["method"] = result.method;
  j["reference"] = result.reference;
  j["track_residual_rms_m"] = Rounded(result.track_residual_rms_m, 1e4);
  Json sensors = Json::array();
  for (const calib::SensorPose& s : result.sensors) {
    Json e;
    e["id"] = s.id;
    e["calibrated"] = s.calibrated;
    e["x_m"] = Rounded(s.world_from_sensor.x_m, 1e4);
    e["y_m"] = Rounded(s.world_from_sensor.y_m, 1e4);
    e["yaw_deg"] = Rounded(RadToDeg(s.world_from_sensor.yaw_rad), 1e4);
    const auto sigma = [&](int i) { return std::sqrt(std::max(0.0, s.covariance(i, i))); };
    e["sigma_x_m"] = Rounded(sigma(0), 1e5);
    e["sigma_y_m"] = Rounded(sigma(1), 1e5);
    e["sigma_yaw_deg"] = Rounded(RadToDeg(sigma(2)), 1e5);
    // The joint refinement's shared radial bias of the sensor (null where it did not place it).
    if (s.radial_bias) {
      e["radial_bias_m"] = Rounded(s.radial_bias->bias_m, 1e5);
      e["sigma_radial_bias_m"] = Rounded(s.radial_bias->sigma_m, 1e5);
      e["radial_bias_estimated"] = s.radial_bias->estimated;
    } else {
      e["radial_bias_m"] = nullptr;
      e["sigma_radial_bias_m"] = nullptr;
      e["radial_bias_estimated"] = nullptr;
    }
    e["mount_looks_like_legs"] = s.mount_looks_like_legs;
    e["flag"] = s.flag;
    sensors.push_back(std::move(e));
  }
  j["sensors"] = std::move(sensors);
  return Dump(j);
}

std::string SensorHealthJson(const std::string& site, common::UtcNs stamp_ns,
                             const SensorHealthReport& h) {
  Json j = Header("sensor_health", site);
  j["stamp_ns"] = stamp_ns;
  j["sensor"] = h.sensor_id;
  j["state"] = h.state;
  j["placed"] = h.placed;
  j["model"] = h.model;
  j["datagram_rate_hz"] = Rounded(h.datagram_rate_hz, 1e2);
  j["loss"] = Rounded(h.loss, 1e5);
  j["clock_sync"] = h.clock_sync;
  j["track_frames"] = h.track_frames;
  j["rejected"] = h.rejected;
  j["restarts"] = h.restarts;
  j["last_receive_ns"] = h.last_receive_ns;
  return Dump(j);
}

std::string StatusJson(const std::string& site, const std::string& state,
                       const std::string& version, std::optional<common::UtcNs> stamp_ns) {
  Json j = Header("status", site);
  j["state"] = state;
  j["version"] = version;
  if (stamp_ns) j["stamp_ns"] = *stamp_ns;
  return Dump(j);
}

}  // namespace lrfnet::daemon
