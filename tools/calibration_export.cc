#include "tools/calibration_export.h"

#include <spdlog/fmt/fmt.h>

#include <cmath>
#include <set>

namespace lrfnet::tools {
namespace {

bool FrameCharsOk(const std::string& s) {
  if (s.empty() || s.size() > 256) return false;
  for (const char c : s) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '_' || c == '/';
    if (!ok) return false;
  }
  return true;
}

std::string Sanitized(const std::string& id) {
  std::string out = id;
  for (char& c : out) {
    const bool ok =
        (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_';
    if (!ok) c = '_';
  }
  return out;
}

// Shortest round-trip text of a double.
std::string Num(double v) { return fmt::format("{}", v); }

struct Entry {
  std::string id;
  std::string frame;
  common::Pose2 pose;
  bool calibrated = true;
};

std::string Ros2(const std::vector<Entry>& entries, const ExportOptions& o,
                 const std::string& source) {
  std::string out = fmt::format(
      "# ROS 2 launch file: the lrfnet sensors as static transforms ({} -> sensor), from {}.\n"
      "# Run with: ros2 launch <this file>. One tf2_ros static_transform_publisher per sensor;\n"
      "# x, y, z in metres, yaw in radians about z (REP 103).\n"
      "launch:\n",
      o.parent_frame, source);
  for (const Entry& e : entries) {
    out += fmt::format(
        "- node:\n"
        "    pkg: tf2_ros\n"
        "    exec: static_transform_publisher\n"
        "    name: lrfnet_static_tf_{}\n"
        "    args: \"--x {} --y {} --z {} --roll 0 --pitch 0 --yaw {} --frame-id {} "
        "--child-frame-id {}\"\n",
        Sanitized(e.id), Num(e.pose.x_m), Num(e.pose.y_m), Num(o.z_m), Num(e.pose.yaw_rad),
        o.parent_frame, e.frame);
  }
  return out;
}

std::string Urdf(const std::vector<Entry>& entries, const ExportOptions& o,
                 const std::string& source) {
  std::string out = fmt::format(
      "<?xml version=\"1.0\"?>\n"
      "<!-- The lrfnet sensors as fixed joints below {}, from {}. Metres and radians. -->\n"
      "<robot name=\"{}\">\n"
      "  <link name=\"{}\"/>\n",
      o.parent_frame, source, o.robot_name, o.parent_frame);
  for (const Entry& e : entries) {
    out += fmt::format(
        "  <link name=\"{}\"/>\n"
        "  <joint name=\"{}_joint\" type=\"fixed\">\n"
        "    <parent link=\"{}\"/>\n"
        "    <child link=\"{}\"/>\n"
        "    <origin xyz=\"{} {} {}\" rpy=\"0 0 {}\"/>\n"
        "  </joint>\n",
        e.frame, Sanitized(e.id), o.parent_frame, e.frame, Num(e.pose.x_m), Num(e.pose.y_m),
        Num(o.z_m), Num(e.pose.yaw_rad));
  }
  out += "</robot>\n";
  return out;
}

std::string Csv(const std::vector<Entry>& entries, const ExportOptions& o) {
  std::string out =
      "sensor,parent_frame,frame,x_m,y_m,z_m,yaw_deg,yaw_rad,qx,qy,qz,qw,calibrated\n";
  for (const Entry& e : entries) {
    // Rotation about z as a unit quaternion.
    const double qz = std::sin(e.pose.yaw_rad / 2.0), qw = std::cos(e.pose.yaw_rad / 2.0);
    out += fmt::format("{},{},{},{},{},{},{},{},0,0,{},{},{}\n", e.id, o.parent_frame, e.frame,
                       Num(e.pose.x_m), Num(e.pose.y_m), Num(o.z_m),
                       Num(e.pose.yaw_rad * 180.0 / std::acos(-1.0)), Num(e.pose.yaw_rad), Num(qz),
                       Num(qw), e.calibrated ? "true" : "false");
  }
  return out;
}

}  // namespace

std::optional<ExportFormat> ParseExportFormat(const std::string& name) {
  if (name == "ros2-static-tf") return ExportFormat::kRos2StaticTf;
  if (name == "urdf") return ExportFormat::kUrdf;
  if (name == "csv") return ExportFormat::kCsv;
  return std::nullopt;
}

std::optional<std::string> Validate(const ExportOptions& o) {
  if (!FrameCharsOk(o.parent_frame)) return "--parent-frame: 1-256 characters of A-Z a-z 0-9 _ /";
  if (o.frame_pattern.find("{id}") == std::string::npos) return "--frame: the pattern needs {id}";
  if (!FrameCharsOk(SensorFrame(o, "x")))
    return "--frame: 1-256 characters of A-Z a-z 0-9 _ / and {id}";
  if (!std::isfinite(o.z_m) || std::abs(o.z_m) > 1e4) return "--z-m: a finite height in metres";
  if (!FrameCharsOk(o.robot_name) || o.robot_name.find('/') != std::string::npos)
    return "--robot-name: 1-256 characters of A-Z a-z 0-9 _";
  return std::nullopt;
}

std::string SensorFrame(const ExportOptions& options, const std::string& sensor_id) {
  std::string out = options.frame_pattern;
  const std::string id = Sanitized(sensor_id);
  for (std::size_t at = out.find("{id}"); at != std::string::npos;
       at = out.find("{id}", at + id.size())) {
    out.replace(at, 4, id);
  }
  return out;
}

ExportResult ExportCalibration(const calib::PoseFile& poses, ExportFormat format,
                               const ExportOptions& options, const std::string& source_name) {
  ExportResult r;
  if (auto e = Validate(options)) {
    r.error = *e;
    return r;
  }
  std::vector<Entry> entries;
  std::set<std::string> frames = {options.parent_frame};
  for (std::size_t i = 0; i < poses.sensors.size(); ++i) {
    const bool calibrated = i < poses.calibrated.size() ? poses.calibrated[i] : true;
    if (!calibrated && !options.include_uncalibrated) continue;
    Entry e{poses.sensors[i].first, SensorFrame(options, poses.sensors[i].first),
            poses.sensors[i].second, calibrated};
    if (!frames.insert(e.frame).second) {
      r.error = "two frames are named '" + e.frame + "' (sensor " + e.id +
                "): change --frame or --parent-frame";
      return r;
    }
    entries.push_back(std::move(e));
  }
  if (entries.empty()) {
    r.error = "no calibrated sensor to export";
    return r;
  }
  // The source's name goes into a comment: no line breaks, no "--" (which ends an XML comment).
  std::string source = source_name;
  for (char& c : source) {
    if (c == '\n' || c == '\r') c = ' ';
  }
  for (std::size_t at = source.find("--"); at != std::string::npos; at = source.find("--", at)) {
    source.replace(at, 2, "- -");
  }
  switch (format) {
    case ExportFormat::kRos2StaticTf:
      r.text = Ros2(entries, options, source);
      break;
    case ExportFormat::kUrdf:
      r.text = Urdf(entries, options, source);
      break;
    case ExportFormat::kCsv:
      r.text = Csv(entries, options);
      break;
  }
  r.ok = true;
  return r;
}

}  // namespace lrfnet::tools
