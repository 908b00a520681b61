#include "central_daemon/calibration/pose_history.h"

#include <spdlog/fmt/fmt.h>
#include <yaml-cpp/yaml.h>

#include <cerrno>
#include <cmath>
#include <cstdlib>

#include "common/one_line.h"

namespace lrfnet::calib {

namespace {

std::string Exact(double v) { return std::isfinite(v) ? fmt::format("{}", v) : ".nan"; }

std::string Quoted(const std::string& s) {
  std::string out = "\"";
  for (const char ch : s) {
    const auto c = static_cast<unsigned char>(ch);
    if (c == '"' || c == '\\') {
      out += '\\';
      out += ch;
    } else if (c < 0x20 || c == 0x7f) {
      out += fmt::format("\\x{:02x}", c);
    } else {
      out += ch;
    }
  }
  return out + "\"";
}

std::string PoseText(const Pose2& p) {
  return fmt::format("{{x_m: {}, y_m: {}, yaw_deg: {}}}", Exact(p.x_m), Exact(p.y_m),
                     Exact(common::RadToDeg(p.yaw_rad)));
}

class Reader {
 public:
  std::string error;

  bool Fail(const YAML::Node& near, const std::string& key, const std::string& message) {
    std::string where;
    if (near.IsDefined() && !near.Mark().is_null()) {
      where = "line " + std::to_string(near.Mark().line + 1) + ": ";
    }
    // Keys and values come from the file: one line, a hostile one cut short.
    error = where + common::OneLine(key, 120) + ": " + common::OneLine(message, 600);
    return false;
  }

  bool Number(const YAML::Node& map, const std::string& path, const char* key, double* out) {
    const YAML::Node node = map[key];
    if (!node.IsDefined() || node.IsNull()) return Fail(map, path, std::string("missing ") + key);
    if (!node.IsScalar()) return Fail(node, path + "." + key, "expected a number");
    const std::string& text = node.Scalar();
    errno = 0;
    char* end = nullptr;
    const double v = std::strtod(text.c_str(), &end);
    if (text.empty() || end != text.c_str() + text.size() || errno == ERANGE || !std::isfinite(v))
      return Fail(node, path + "." + key,
                  "expected a finite number, got '" + text.substr(0, 40) + "'");
    *out = v;
    return true;
  }

  bool Stamp(const YAML::Node& map, const std::string& path, common::UtcNs* out) {
    const YAML::Node node = map["stamp_ns"];
    const std::string text = node.IsScalar() ? node.Scalar() : "";
    errno = 0;
    char* end = nullptr;
    const long long v = std::strtoll(text.c_str(), &end, 10);
    if (text.empty() || end != text.c_str() + text.size() || errno == ERANGE || v < 0)
      return Fail(node, path + ".stamp_ns", "expected nanoseconds since 1970 (an integer >= 0)");
    *out = static_cast<common::UtcNs>(v);
    return true;
  }

  bool Text(const YAML::Node& map, const std::string& path, const char* key, std::string* out,
            bool required) {
    const YAML::Node node = map[key];
    if (!node.IsDefined() || node.IsNull()) {
      if (required) return Fail(map, path, std::string("missing ") + key);
      return true;
    }
    if (!node.IsScalar()) return Fail(node, path + "." + key, "expected a string");
    *out = node.Scalar();
    return true;
  }

  bool Pose(const YAML::Node& map, const std::string& path, const char* key,
            std::optional<Pose2>* out) {
    const YAML::Node node = map[key];
    if (!node.IsDefined() || node.IsNull()) return true;
    const std::string p = path + "." + key;
    if (!node.IsMap()) return Fail(node, p, "expected {x_m, y_m, yaw_deg}");
    double x = 0, y = 0, yaw_deg = 0;
    if (!Number(node, p, "x_m", &x) || !Number(node, p, "y_m", &y) ||
        !Number(node, p, "yaw_deg", &yaw_deg))
      return false;
    if (std::abs(x) > kMaxPoseCoordinateM || std::abs(y) > kMaxPoseCoordinateM ||
        std::abs(yaw_deg) > kMaxPoseYawDeg)
      return Fail(node, p, "out of range");
    *out = Pose2{x, y, common::NormalizeAngle(common::DegToRad(yaw_deg))};
    return true;
  }
};

YAML::Node Load(const std::string& text, std::string* error) {
  if (text.find('\0') != std::string::npos) {
    *error = "binary data, not YAML";
    return YAML::Node(YAML::NodeType::Undefined);
  }
  try {
    return YAML::Load(text);
  } catch (const YAML::Exception& e) {
    *error = (e.mark.is_null() ? "" : "line " + std::to_string(e.mark.line + 1) + ": ") +
             "not valid YAML: " + common::OneLine(e.msg);
    return YAML::Node(YAML::NodeType::Undefined);
  }
}

}  // namespace

std::string HistoryYaml(const std::vector<CalibrationEvent>& events) {
  std::string y =
      "# history     what happened since: sensors found moved (and left out of the "
      "fusion), their\n"
      "#             poses corrected, backgrounds re-learned; before/after are the "
      "poses, motion\n"
      "#             after minus before (world frame) [m, deg]\n";
  y += "history:";
  y += events.empty() ? " []\n" : "\n";
  for (const CalibrationEvent& e : events) {
    y += fmt::format(
        "  - {{time_utc: {}, stamp_ns: {}, sensor: {}, event: {}, method: {}, "
        "detail: {}",
        Quoted(e.time_utc), e.stamp_ns, Quoted(e.sensor), Quoted(e.event), Quoted(e.method),
        Quoted(e.detail));
    if (e.before) y += ",\n     before: " + PoseText(*e.before);
    if (e.after) y += ",\n     after: " + PoseText(*e.after);
    if (e.before && e.after) {
      y += fmt::format(
          ",\n     motion: {{dx_m: {}, dy_m: {}, dyaw_deg: {}}}",
          Exact(e.after->x_m - e.before->x_m), Exact(e.after->y_m - e.before->y_m),
          Exact(common::RadToDeg(common::NormalizeAngle(e.after->yaw_rad - e.before->yaw_rad))));
    }
    y += "}\n";
  }
  return y;
}

bool ParseHistoryYaml(const std::string& text, std::vector<CalibrationEvent>* out,
                      std::string* error) {
  if (text.size() > kMaxPoseFileBytes) {
    *error = "larger than the limit of a calibration file";
    return false;
  }
  const YAML::Node root = Load(text, error);
  if (!root.IsDefined()) return false;
  std::vector<CalibrationEvent> events;
  const YAML::Node history = root.IsMap() ? root["history"] : YAML::Node();
  if (!history.IsDefined() || history.IsNull()) {
    *out = {};
    return true;
  }
  Reader r;
  if (!history.IsSequence()) {
    r.Fail(history, "history", "expected a list of events");
    *error = r.error;
    return false;
  }
  const std::size_t first =
      history.size() > kMaxHistoryEvents ? history.size() - kMaxHistoryEvents : 0;
  for (std::size_t i = first; i < history.size(); ++i) {
    const YAML::Node node = history[i];
    const std::string path = "history[" + std::to_string(i) + "]";
    CalibrationEvent e;
    bool ok = node.IsMap() || r.Fail(node, path, "expected a map");
    ok = ok && r.Text(node, path, "sensor", &e.sensor, true) &&
         r.Text(node, path, "event", &e.event, true) &&
         r.Text(node, path, "time_utc", &e.time_utc, false) &&
         r.Text(node, path, "method", &e.method, false) &&
         r.Text(node, path, "detail", &e.detail, false) &&
         r.Pose(node, path, "before", &e.before) && r.Pose(node, path, "after", &e.after);
    if (ok && node["stamp_ns"].IsDefined()) ok = r.Stamp(node, path, &e.stamp_ns);
    if (!ok) {
      *error = r.error;
      return false;
    }
    events.push_back(std::move(e));
  }
  *out = std::move(events);
  return true;
}

bool TruthPosesAt(const std::string& text, double t_s, PoseFile* out, std::string* error) {
  const YAML::Node root = Load(text, error);
  if (!root.IsDefined()) return false;
  const YAML::Node poses = root.IsMap() ? root["poses"] : YAML::Node();
  if (!poses.IsDefined() || !poses.IsSequence() || poses.size() == 0) {
    *error = "no `poses` list (a truth.yaml of lrfnet sim has one)";
    return false;
  }
  Reader r;
  PoseFile file;
  // Per sensor the span holding t_s, else its latest span (t_s at or after the end of the run).
  std::vector<double> latest_from;
  std::vector<bool> exact;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const YAML::Node node = poses[i];
    const std::string path = "poses[" + std::to_string(i) + "]";
    std::string id;
    double from_s = 0, to_s = 0, x = 0, y = 0, yaw_deg = 0;
    if (!(node.IsMap() || r.Fail(node, path, "expected a map")) ||
        !r.Text(node, path, "id", &id, true) || !r.Number(node, path, "from_s", &from_s) ||
        !r.Number(node, path, "to_s", &to_s) || !r.Number(node, path, "x_m", &x) ||
        !r.Number(node, path, "y_m", &y) || !r.Number(node, path, "yaw_deg", &yaw_deg)) {
      *error = r.error;
      return false;
    }
    const Pose2 pose{x, y, common::NormalizeAngle(common::DegToRad(yaw_deg))};
    const bool holds = from_s <= t_s && t_s < to_s;
    auto at = file.Find(id);
    if (!at) {
      file.sensors.emplace_back(id, pose);
      file.calibrated.push_back(true);
      latest_from.push_back(from_s);
      exact.push_back(holds);
      continue;
    }
    if (exact[*at]) continue;
    if (holds || from_s > latest_from[*at]) {
      file.sensors[*at].second = pose;
      latest_from[*at] = from_s;
      exact[*at] = holds;
    }
  }
  *out = std::move(file);
  return true;
}

}  // namespace lrfnet::calib
