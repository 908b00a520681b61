#include "central_daemon/app/foxglove_feed.h"

#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

namespace lrfnet::daemon {
namespace {

using Json = nlohmann::ordered_json;

std::string Dump(const Json& j) { return j.dump(-1, ' ', false, Json::error_handler_t::replace); }

// Finite or 0 (JSON has no NaN; Foxglove's schemas want numbers).
double F(double v) { return std::isfinite(v) ? v : 0.0; }

Json Time(common::UtcNs ns) {
  const common::UtcNs t = std::max<common::UtcNs>(0, ns);
  return {{"sec", t / 1'000'000'000}, {"nsec", t % 1'000'000'000}};
}
Json Vector3(double x, double y, double z) { return {{"x", F(x)}, {"y", F(y)}, {"z", F(z)}}; }
Json YawQuaternion(double yaw_rad) {
  return {
      {"x", 0.0}, {"y", 0.0}, {"z", F(std::sin(yaw_rad / 2.0))}, {"w", F(std::cos(yaw_rad / 2.0))}};
}
Json PoseJson(double x, double y, double z, double yaw_rad) {
  return {{"position", Vector3(x, y, z)}, {"orientation", YawQuaternion(yaw_rad)}};
}
Json Color(double r, double g, double b, double a) {
  return {{"r", r}, {"g", g}, {"b", b}, {"a", a}};
}

Json Entity(common::UtcNs stamp_ns, const std::string& frame, const std::string& id) {
  Json e;
  e["timestamp"] = Time(stamp_ns);
  e["frame_id"] = frame;
  e["id"] = id;
  e["lifetime"] = {{"sec", 0}, {"nsec", 0}};
  e["frame_locked"] = false;
  e["metadata"] = Json::array();
  for (const char* key :
       {"arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models"}) {
    e[key] = Json::array();
  }
  return e;
}

Json Text(double x, double y, double z, const std::string& text, const Json& color) {
  return {{"pose", PoseJson(x, y, z, 0.0)}, {"billboard", true}, {"font_size", 14.0},
          {"scale_invariant", true},        {"color", color},    {"text", text}};
}

Json Arrow(double x, double y, double z, double vx, double vy, const Json& color) {
  const double speed = std::hypot(F(vx), F(vy));
  return {{"pose", PoseJson(x, y, z, std::atan2(F(vy), F(vx)))},
          {"shaft_length", std::max(0.01, speed)},  // one second of motion
          {"shaft_diameter", 0.05},
          {"head_length", 0.15},
          {"head_diameter", 0.12},
          {"color", color}};
}

Json SceneUpdate(common::UtcNs stamp_ns, Json entities) {
  Json j;
  j["deletions"] = Json::array({{{"timestamp", Time(stamp_ns)}, {"type", 1}, {"id", ""}}});
  j["entities"] = std::move(entities);
  return j;
}

// The schemas advertised (JSON Schema of what is sent; names and fields are Foxglove's).
constexpr const char* kTimeSchema =
    R"({"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}})";
std::string Replace(std::string text, const std::string& what, const std::string& with) {
  for (std::size_t at = text.find(what); at != std::string::npos;
       at = text.find(what, at + with.size()))
    text.replace(at, what.size(), with);
  return text;
}
const std::string& Vector3Schema() {
  static const std::string s =
      R"({"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}})";
  return s;
}
const std::string& PoseSchema() {
  static const std::string s =
      R"({"type":"object","properties":{"position":)" + Vector3Schema() +
      R"(,"orientation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}}})";
  return s;
}
const std::string& ColorSchema() {
  static const std::string s =
      R"({"type":"object","properties":{"r":{"type":"number"},"g":{"type":"number"},"b":{"type":"number"},"a":{"type":"number"}}})";
  return s;
}
const std::string& SceneUpdateSchema() {
  static const std::string s = Replace(
      Replace(
          Replace(
              Replace(
                  R"({"title":"foxglove.SceneUpdate","type":"object","required":["deletions","entities"],"properties":{)"
                  R"("deletions":{"type":"array","items":{"type":"object","properties":{"timestamp":TIME,"type":{"type":"integer"},"id":{"type":"string"}}}},)"
                  R"("entities":{"type":"array","items":{"type":"object","properties":{"timestamp":TIME,"frame_id":{"type":"string"},"id":{"type":"string"},)"
                  R"("lifetime":TIME,"frame_locked":{"type":"boolean"},)"
                  R"("metadata":{"type":"array","items":{"type":"object","properties":{"key":{"type":"string"},"value":{"type":"string"}}}},)"
                  R"("arrows":{"type":"array","items":{"type":"object","properties":{"pose":POSE,"shaft_length":{"type":"number"},"shaft_diameter":{"type":"number"},"head_length":{"type":"number"},"head_diameter":{"type":"number"},"color":COLOR}}},)"
                  R"("cubes":{"type":"array"},"spheres":{"type":"array","items":{"type":"object","properties":{"pose":POSE,"size":VECTOR3,"color":COLOR}}},)"
                  R"("cylinders":{"type":"array","items":{"type":"object","properties":{"pose":POSE,"size":VECTOR3,"bottom_scale":{"type":"number"},"top_scale":{"type":"number"},"color":COLOR}}},)"
                  R"("lines":{"type":"array","items":{"type":"object","properties":{"type":{"type":"integer"},"pose":POSE,"thickness":{"type":"number"},"scale_invariant":{"type":"boolean"},"points":{"type":"array","items":VECTOR3},"color":COLOR,"colors":{"type":"array"},"indices":{"type":"array"}}}},)"
                  R"("triangles":{"type":"array"},)"
                  R"("texts":{"type":"array","items":{"type":"object","properties":{"pose":POSE,"billboard":{"type":"boolean"},"font_size":{"type":"number"},"scale_invariant":{"type":"boolean"},"color":COLOR,"text":{"type":"string"}}}},)"
                  R"("models":{"type":"array"}}}}}})",
                  "TIME", kTimeSchema),
              "POSE", PoseSchema()),
          "COLOR", ColorSchema()),
      "VECTOR3", Vector3Schema());
  return s;
}
const std::string& FrameTransformsSchema() {
  static const std::string s = Replace(
      Replace(
          Replace(
              R"({"title":"foxglove.FrameTransforms","type":"object","required":["transforms"],"properties":{"transforms":{"type":"array","items":{"type":"object",)"
              R"("required":["timestamp","parent_frame_id","child_frame_id","translation","rotation"],"properties":{"timestamp":TIME,)"
              R"("parent_frame_id":{"type":"string"},"child_frame_id":{"type":"string"},"translation":VECTOR3,"rotation":QUAT}}}}})",
              "TIME", kTimeSchema),
          "VECTOR3", Vector3Schema()),
      "QUAT",
      R"({"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}})");
  return s;
}
const std::string& LaserScanSchema() {
  static const std::string s = Replace(
      Replace(
          R"({"title":"foxglove.LaserScan","type":"object","required":["timestamp","frame_id","pose","start_angle","end_angle","ranges","intensities"],)"
          R"("properties":{"timestamp":TIME,"frame_id":{"type":"string"},"pose":POSE,"start_angle":{"type":"number"},"end_angle":{"type":"number"},)"
          R"("ranges":{"type":"array","items":{"type":"number"}},"intensities":{"type":"array","items":{"type":"number"}}}})",
          "TIME", kTimeSchema),
      "POSE", PoseSchema());
  return s;
}
constexpr const char* kCalibrationSchema =
    R"({"title":"lrfnet.Calibration","type":"object","required":["state","progress","message","reference","sensors"],)"
    R"("properties":{"state":{"enum":["collecting","calibrating","calibrated","failed"]},"progress":{"type":"number"},)"
    R"("message":{"type":"string"},"reference":{"type":"string"},"track_residual_rms_m":{"type":"number"},)"
    R"("sensors":{"type":"array","items":{"type":"object","required":["id","placed"],"properties":{"id":{"type":"string"},)"
    R"("placed":{"type":"boolean"},"status":{"type":"string"},"x_m":{"type":"number"},"y_m":{"type":"number"},"yaw_rad":{"type":"number"},)"
    R"("sigma_x_m":{"type":"number"},"sigma_y_m":{"type":"number"},"sigma_yaw_rad":{"type":"number"},)"
    R"("radial_bias_m":{"type":"number"},"sigma_radial_bias_m":{"type":"number"},"radial_bias_estimated":{"type":"boolean"},)"
    R"("mount_looks_like_legs":{"type":"boolean"},"flag":{"type":"string"}}}}}})";

FoxgloveChannelMessage Message(std::string topic, const std::string& schema_name,
                               const std::string& schema, const Json& payload,
                               common::UtcNs stamp_ns) {
  return {std::move(topic), schema_name, schema, Dump(payload),
          static_cast<std::uint64_t>(std::max<common::UtcNs>(0, stamp_ns))};
}

}  // namespace

std::vector<FoxgloveChannelMessage> FoxgloveMessagesOf(const LiveState& state) {
  std::vector<FoxgloveChannelMessage> out;
  const common::UtcNs t = state.stamp_ns;

  Json transforms = Json::array();
  for (const LiveSensor& s : state.sensors) {
    if (!s.placed) continue;
    transforms.push_back(
        {{"timestamp", Time(t)},
         {"parent_frame_id", "world"},
         {"child_frame_id", s.id},
         {"translation", Vector3(s.world_from_sensor.x_m, s.world_from_sensor.y_m, 0.0)},
         {"rotation", YawQuaternion(s.world_from_sensor.yaw_rad)}});
  }
  out.push_back(Message("/tf", "foxglove.FrameTransforms", FrameTransformsSchema(),
                        {{"transforms", std::move(transforms)}}, t));

  const Json fused_color = Color(0.1, 0.6, 1.0, 0.8);
  Json fused = Json::array();
  for (const LiveFusedTrack& f : state.fused) {
    Json e = Entity(t, "world", "fused/" + std::to_string(f.id));
    e["metadata"].push_back({{"key", "state"}, {"value", f.state}});
    std::string sensors;
    for (const std::string& s : f.sensors) sensors += (sensors.empty() ? "" : ",") + s;
    e["metadata"].push_back({{"key", "sensors"}, {"value", sensors}});
    e["cylinders"].push_back({{"pose", PoseJson(f.x_m, f.y_m, 0.85, 0.0)},
                              {"size", Vector3(0.5, 0.5, 1.7)},
                              {"bottom_scale", 1.0},
                              {"top_scale", 1.0},
                              {"color", fused_color}});
    e["arrows"].push_back(Arrow(f.x_m, f.y_m, 1.0, f.vx_mps, f.vy_mps, Color(1.0, 1.0, 1.0, 0.9)));
    e["texts"].push_back(Text(f.x_m, f.y_m, 2.0, std::to_string(f.id), Color(1, 1, 1, 1)));
    fused.push_back(std::move(e));
  }
  out.push_back(Message("/lrfnet/fused", "foxglove.SceneUpdate", SceneUpdateSchema(),
                        SceneUpdate(t, std::move(fused)), t));

  for (const LiveSensor& s : state.sensors) {
    Json tracks = Json::array();
    for (const LiveTrack& track : state.tracks) {
      if (track.sensor_id != s.id) continue;
      Json e = Entity(t, s.placed ? "world" : s.id,
                      "track/" + s.id + "/" + std::to_string(track.track_id));
      e["metadata"].push_back({{"key", "state"}, {"value", track.state}});
      if (track.fused_id)
        e["metadata"].push_back({{"key", "fused"}, {"value", std::to_string(*track.fused_id)}});
      e["spheres"].push_back({{"pose", PoseJson(track.x_m, track.y_m, 1.0, 0.0)},
                              {"size", Vector3(0.3, 0.3, 0.3)},
                              {"color", Color(1.0, 0.6, 0.1, 0.8)}});
      e["arrows"].push_back(
          Arrow(track.x_m, track.y_m, 1.0, track.vx_mps, track.vy_mps, Color(1.0, 0.6, 0.1, 0.8)));
      tracks.push_back(std::move(e));
    }
    out.push_back(Message("/lrfnet/tracks/" + s.id, "foxglove.SceneUpdate", SceneUpdateSchema(),
                          SceneUpdate(t, std::move(tracks)), t));
    if (!s.background_ranges_m.empty()) {
      Json ranges = Json::array();
      for (const float r : s.background_ranges_m) ranges.push_back(F(r));
      const double end =
          s.background_first_angle_rad +
          s.background_angle_step_rad * static_cast<double>(s.background_ranges_m.size() - 1);
      out.push_back(Message("/lrfnet/background/" + s.id, "foxglove.LaserScan", LaserScanSchema(),
                            {{"timestamp", Time(t)},
                             {"frame_id", s.id},
                             {"pose", PoseJson(0, 0, 0, 0)},
                             {"start_angle", F(s.background_first_angle_rad)},
                             {"end_angle", F(end)},
                             {"ranges", std::move(ranges)},
                             {"intensities", Json::array()}},
                            t));
    }
  }

  if (!state.zones.empty()) {
    Json zones = Json::array();
    for (const LiveZone& z : state.zones) {
      Json e = Entity(t, "world", "zone/" + z.name);
      Json points = Json::array();
      double cx = 0.0, cy = 0.0;
      for (const auto& p : z.points) {
        points.push_back(Vector3(p[0], p[1], 0.02));
        cx += p[0] / static_cast<double>(z.points.size());
        cy += p[1] / static_cast<double>(z.points.size());
      }
      e["lines"].push_back({{"type", z.kind == "line" ? 0 : 1},
                            {"pose", PoseJson(0, 0, 0, 0)},
                            {"thickness", 0.05},
                            {"scale_invariant", false},
                            {"points", std::move(points)},
                            {"color", Color(0.2, 0.9, 0.3, 1.0)},
                            {"colors", Json::array()},
                            {"indices", Json::array()}});
      e["texts"].push_back(Text(cx, cy, 0.3,
                                z.name + ": " + std::to_string(z.occupancy) + " in, " +
                                    std::to_string(z.inbound) + " inbound, " +
                                    std::to_string(z.outbound) + " outbound",
                                Color(0.2, 0.9, 0.3, 1.0)));
      zones.push_back(std::move(e));
    }
    out.push_back(Message("/lrfnet/zones", "foxglove.SceneUpdate", SceneUpdateSchema(),
                          SceneUpdate(t, std::move(zones)), t));
  }

  Json calibration;
  calibration["state"] = state.calibration.state;
  calibration["progress"] = F(state.calibration.progress);
  calibration["message"] = state.calibration.message;
  calibration["reference"] = state.calibration.reference;
  calibration["track_residual_rms_m"] = F(state.calibration.track_residual_rms_m);
  Json sensors = Json::array();
  for (const LiveSensor& s : state.sensors) {
    Json e = {{"id", s.id}, {"placed", s.placed}, {"status", s.status}};
    if (s.placed) {
      e["x_m"] = F(s.world_from_sensor.x_m);
      e["y_m"] = F(s.world_from_sensor.y_m);
      e["yaw_rad"] = F(s.world_from_sensor.yaw_rad);
    }
    // What the calibration says of the sensor (LiveSensor::Calibration).
    const LiveSensor::Calibration& c = s.calibration;
    if (c.calibrated) {
      if (s.placed) {
        e["sigma_x_m"] = F(c.sigma_x_m);
        e["sigma_y_m"] = F(c.sigma_y_m);
        e["sigma_yaw_rad"] = F(c.sigma_yaw_rad);
      }
      if (c.has_radial_bias) {
        e["radial_bias_m"] = F(c.radial_bias_m);
        e["sigma_radial_bias_m"] = F(c.sigma_radial_bias_m);
        e["radial_bias_estimated"] = c.radial_bias_estimated;
      }
      e["mount_looks_like_legs"] = c.mount_looks_like_legs;
      e["flag"] = c.flag;
    }
    sensors.push_back(std::move(e));
  }
  calibration["sensors"] = std::move(sensors);
  out.push_back(
      Message("/lrfnet/calibration", "lrfnet.Calibration", kCalibrationSchema, calibration, t));
  return out;
}

}  // namespace lrfnet::daemon
