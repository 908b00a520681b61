#include "central_daemon/calibration/calibration_yaml.h"

#include <spdlog/fmt/fmt.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>

#include "common/eigen_instances.h"
#include "common/one_line.h"

namespace lrfnet::calib {

namespace {

constexpr const char* kHeader =
    "# Sensor poses calibrated by lrfnet from people (or objects) tracked by several laser\n"
    "# scanners at once (Quenzel et al.; `method` says which algorithm).\n"
    "#\n"
    "# reference   the sensor fixed at the origin: every pose below is in its frame.\n"
    "# sensors     one entry per sensor, the same format as the simulator's truth.yaml:\n"
    "#   x_m, y_m    position of the sensor in the reference frame [m]\n"
    "#   yaw_deg     heading of the sensor's x axis (its forward beam), counter-clockwise [deg];\n"
    "#               together: p_reference = R(yaw) * p_sensor + (x_m, y_m)\n"
    "#   sigma_*     one standard deviation of x_m, y_m [m] and yaw_deg [deg]; cov_xy_m2,\n"
    "#               cov_xyaw_m_deg, cov_yyaw_m_deg the covariances between them [m^2, m deg]\n"
    "#   calibrated: false   the data did not connect this sensor to the reference: no pose\n"
    "#   radial_bias_m   (only where the joint refinement ran) how far this sensor's people's\n"
    "#               centres lie towards it along its line of sight beyond the measurement model\n"
    "#               [m; negative: beyond it]; sigma_radial_bias_m its standard deviation\n"
    "#               after the refinement;\n"
    "#               radial_bias_estimated: false = the data do not observe it, held at its prior\n"
    "#               (0 +- sigma), which the pose sigmas include\n"
    "#   flag        what a person should know about this sensor's pose\n"
    "#   mount_looks_like_legs: true   its tracks are leg-sized although its tracker is set up\n"
    "#               for upper-body height: set shape.mount: legs on that tracker\n"
    "# quality     how well the data supports the poses:\n"
    "#   edges       one per sensor pair with a pairwise estimate: `used` by the global solution "
    "or\n"
    "#               not (`status` says why); matches = associated simultaneous observations,\n"
    "#               rms_m = their residual under the pairwise estimate; rotation_residual_deg /\n"
    "#               translation_residual_m = pairwise estimate vs the final poses;\n"
    "#               track_residual_rms_m = the pair's matched observations under the final\n"
    "#               poses; icp_applied = the background scans refined the estimate\n"
    "#   joint_refinement  robust cost over all associated observations before/after the joint\n"
    "#               least-squares refinement of all poses (applied: false = not run or no gain)\n"
    "#   track_residual_rms_m  all matched observations under the final poses [m]\n"
    "#   scale       present when the layout's scale is not observable apart from the people's\n"
    "#               size: what that means for the poses and what data would fix it\n"
    "#   warnings    anything a person should check\n"
    "#   timings_s   wall time of each stage [s]\n";

// Shortest text that reads back as the same double (fmt's default for floating point).
std::string Exact(double v) {
  if (std::isnan(v)) return ".nan";
  if (std::isinf(v)) return v > 0 ? ".inf" : "-.inf";
  return fmt::format("{}", v);
}

// Six significant digits: statistics a person reads.
std::string Short(double v) {
  if (std::isnan(v)) return ".nan";
  if (std::isinf(v)) return v > 0 ? ".inf" : "-.inf";
  return fmt::format("{:.6g}", v);
}

// A YAML double-quoted scalar: any id (quotes, colons, '#', control characters) reads back as
// itself.
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

std::string Bool(bool b) { return b ? "true" : "false"; }

double SigmaOf(const Eigen::Matrix3d& cov, int i) {
  const double v = cov(i, i);
  // Beyond the reader's bounds a pose is as good as unknown: written at the bound.
  const double limit = i < 2 ? kMaxPoseCoordinateM : common::DegToRad(kMaxPoseYawDeg);
  return v > 0.0 && std::isfinite(v) ? std::min(std::sqrt(v), limit) : 0.0;
}

// cov(i, j) as the reader accepts it back: finite, within the product of the two sigmas.
double CrossOf(const Eigen::Matrix3d& cov, int i, int j) {
  const double bound = SigmaOf(cov, i) * SigmaOf(cov, j);
  return std::isfinite(cov(i, j)) ? std::clamp(cov(i, j), -bound, bound) : 0.0;
}

// A pose the reader accepts back (finite, within its bounds).
bool Readable(const SensorPose& s) {
  const Pose2& p = s.world_from_sensor;
  return std::isfinite(p.x_m) && std::isfinite(p.y_m) && std::isfinite(p.yaw_rad) &&
         std::abs(p.x_m) <= kMaxPoseCoordinateM && std::abs(p.y_m) <= kMaxPoseCoordinateM;
}

// A radial bias the reader accepts back.
bool ReadableBias(const RadialBiasEstimate& b) {
  return std::isfinite(b.bias_m) && std::isfinite(b.sigma_m) &&
         std::abs(b.bias_m) <= kMaxRadialBiasM && b.sigma_m >= 0.0 && b.sigma_m <= kMaxRadialBiasM;
}

// ---------------------------------------------------------------------------------------------
// Reading.

class Reader {
 public:
  explicit Reader(std::string source) : source_(std::move(source)) {}

  std::string error;

  bool Fail(const YAML::Node& near, const std::string& key, const std::string& message) {
    std::string where = source_;
    if (near.IsDefined() && !near.Mark().is_null()) {
      where += (where.empty() ? "line " : ":") + std::to_string(near.Mark().line + 1);
    }
    error = (where.empty() ? "" : where + ": ") + (key.empty() ? "" : key + ": ") + message;
    return false;
  }

  bool Parse(const std::string& text, PoseFile* out) {
    if (text.find('\0') != std::string::npos) {
      error = (source_.empty() ? "" : source_ + ": ") + "binary data, not a YAML pose file";
      return false;
    }
    YAML::Node root;
    try {
      root = YAML::Load(text);
    } catch (const YAML::Exception& e) {
      // yaml-cpp throws for malformed YAML (and for nesting beyond its depth guard).
      std::string where = source_;
      if (!e.mark.is_null())
        where += (where.empty() ? "line " : ":") + std::to_string(e.mark.line + 1);
      error = (where.empty() ? "" : where + ": ") + "not valid YAML: " + Clip(e.msg, 120);
      return false;
    }
    try {
      return ParseRoot(root, out);
    } catch (const YAML::Exception& e) {
      // Only reached for shapes the checks below do not anticipate; still one clear line.
      return Fail(root, "", "unexpected structure: " + Clip(e.what(), 120));
    }
  }

 private:
  static bool Has(const YAML::Node& map, const char* key) {
    return map[key].IsDefined() && !map[key].IsNull();
  }

  // entry[key] as a finite number with |value| <= limit. `key_path` names it in errors
  // ("sensors[2].x_m"), `note` follows the message (" (sensor 's3')").
  bool Number(const YAML::Node& entry, const std::string& key_path, const std::string& note,
              const char* key, double limit, double* out) {
    if (!Has(entry, key)) return Fail(entry, key_path, "missing key" + note);
    const YAML::Node node = entry[key];
    if (!node.IsScalar()) return Fail(node, key_path, "expected a number" + note);
    const std::string& text = node.Scalar();
    char* end = nullptr;
    // Overflow gives +-HUGE_VAL (caught as not finite); underflow gives ~0, which is fine.
    const double v = std::strtod(text.c_str(), &end);
    if (text.empty() || end != text.c_str() + text.size()) {
      return Fail(node, key_path, "expected a number, got '" + Clip(text) + "'" + note);
    }
    if (!std::isfinite(v))
      return Fail(node, key_path, "expected a finite number, got '" + Clip(text) + "'" + note);
    if (std::abs(v) > limit) {
      return Fail(node, key_path,
                  fmt::format("{} is out of range (|value| <= {:g}){}", Clip(text), limit, note));
    }
    *out = v;
    return true;
  }

  // entry[key], when present, as true or false (absent: *out unchanged).
  bool Boolean(const YAML::Node& entry, const std::string& key_path, const std::string& note,
               const char* key, bool* out) {
    if (!Has(entry, key)) return true;
    const YAML::Node node = entry[key];
    const std::string text = node.IsScalar() ? node.Scalar() : "";
    if (text != "true" && text != "false")
      return Fail(node, key_path, "expected true or false" + note);
    *out = text == "true";
    return true;
  }

  // The pose's covariance (x, y, yaw; metres and radians) from sigma_x_m, sigma_y_m,
  // sigma_yaw_deg (none of them: nullopt; one absent: 0) and the optional cov_xy_m2,
  // cov_xyaw_m_deg, cov_yyaw_m_deg (absent: 0). A covariance beyond the product of its two sigmas
  // (a correlation above 1, more than the sigmas' six digits explain) is an error; what rounding
  // leaves of a matrix that is not positive semi-definite is taken off its eigenvalues.
  bool Covariance(const YAML::Node& entry, const std::string& path, const std::string& note,
                  std::optional<Eigen::Matrix3d>* out) {
    static constexpr std::array<const char*, 3> kSigma = {"sigma_x_m", "sigma_y_m",
                                                          "sigma_yaw_deg"};
    static constexpr std::array<const char*, 3> kCross = {"cov_xy_m2", "cov_xyaw_m_deg",
                                                          "cov_yyaw_m_deg"};
    bool any = false;
    for (const char* key : kSigma) any = any || Has(entry, key);
    if (!any) {
      for (const char* key : kCross) {
        if (Has(entry, key))
          return Fail(entry[key], path + "." + key,
                      "without sigma_x_m, sigma_y_m, sigma_yaw_deg" + note);
      }
      return true;
    }
    std::array<double, 3> sigma{};
    for (std::size_t i = 0; i < 3; ++i) {
      if (!Has(entry, kSigma[i])) continue;
      const double limit = i < 2 ? kMaxPoseCoordinateM : kMaxPoseYawDeg;
      if (!Number(entry, path + "." + kSigma[i], note, kSigma[i], limit, &sigma[i])) return false;
      if (sigma[i] < 0.0)
        return Fail(entry[kSigma[i]], path + "." + kSigma[i], "expected a number >= 0" + note);
    }
    // The file's units (m, m, deg) to the covariance's (m, m, rad).
    const std::array<double, 3> to_si = {1.0, 1.0, common::DegToRad(1.0)};
    Eigen::Matrix3d c = Eigen::Matrix3d::Zero();
    for (int i = 0; i < 3; ++i) c(i, i) = sigma[i] * sigma[i] * to_si[i] * to_si[i];
    static constexpr std::array<std::array<int, 2>, 3> kPair = {{{0, 1}, {0, 2}, {1, 2}}};
    for (std::size_t k = 0; k < 3; ++k) {
      if (!Has(entry, kCross[k])) continue;
      const auto [i, j] = kPair[k];
      const double bound = sigma[static_cast<std::size_t>(i)] * sigma[static_cast<std::size_t>(j)];
      double v = 0.0;
      if (!Number(entry, path + "." + kCross[k], note, kCross[k],
                  kMaxPoseCoordinateM * kMaxPoseYawDeg, &v)) {
        return false;
      }
      if (std::abs(v) > bound * (1.0 + 1e-4) + 1e-12) {
        return Fail(entry[kCross[k]], path + "." + kCross[k],
                    fmt::format("|{}| is beyond {} * {} (a correlation above 1){}", Short(v),
                                kSigma[i], kSigma[j], note));
      }
      v = std::clamp(v, -bound, bound);
      c(i, j) = c(j, i) =
          v * to_si[static_cast<std::size_t>(i)] * to_si[static_cast<std::size_t>(j)];
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(c);
    if (eig.info() == Eigen::Success && eig.eigenvalues().minCoeff() < 0.0) {
      c = eig.eigenvectors() * eig.eigenvalues().cwiseMax(0.0).asDiagonal() *
          eig.eigenvectors().transpose();
      c = (0.5 * (c + c.transpose())).eval();
    }
    *out = c;
    return true;
  }

  // Error messages quote at most this much of a hostile value, on one line.
  static std::string Clip(const std::string& s, std::size_t max_chars = 40) {
    return common::OneLine(s, max_chars);
  }

  bool ParseRoot(const YAML::Node& root, PoseFile* out) {
    if (!root.IsDefined() || root.IsNull())
      return Fail(root, "", "empty; expected a map with a `sensors` list");
    if (!root.IsMap()) return Fail(root, "", "expected a map with a `sensors` list");
    const YAML::Node sensors = root["sensors"];
    if (!sensors.IsDefined() || sensors.IsNull()) return Fail(root, "sensors", "missing key");
    if (!sensors.IsSequence())
      return Fail(sensors, "sensors", "expected a list of {id, x_m, y_m, yaw_deg}");
    if (sensors.size() == 0) return Fail(sensors, "sensors", "empty list");

    PoseFile file;
    std::set<std::string> ids;
    for (std::size_t i = 0; i < sensors.size(); ++i) {
      const YAML::Node entry = sensors[i];
      const std::string path = fmt::format("sensors[{}]", i);
      if (!entry.IsMap()) return Fail(entry, path, "expected a map {id, x_m, y_m, yaw_deg}");
      if (!Has(entry, "id")) return Fail(entry, path + ".id", "missing key");
      if (!entry["id"].IsScalar() || entry["id"].Scalar().empty())
        return Fail(entry["id"], path + ".id", "expected a non-empty string");
      const std::string id = entry["id"].Scalar();
      const std::string note = " (sensor '" + Clip(id) + "')";
      if (!ids.insert(id).second) return Fail(entry["id"], path + ".id", "duplicate id" + note);

      bool calibrated = true;
      if (Has(entry, "calibrated")) {
        const YAML::Node node = entry["calibrated"];
        const std::string text = node.IsScalar() ? node.Scalar() : "";
        if (text == "true") {
          calibrated = true;
        } else if (text == "false") {
          calibrated = false;
        } else {
          return Fail(node, path + ".calibrated", "expected true or false" + note);
        }
      }
      Pose2 pose;
      // An uncalibrated sensor has no pose; if it gives one anyway, it must still be valid.
      if (calibrated || Has(entry, "x_m") || Has(entry, "y_m") || Has(entry, "yaw_deg")) {
        double yaw_deg = 0.0;
        if (!Number(entry, path + ".x_m", note, "x_m", kMaxPoseCoordinateM, &pose.x_m) ||
            !Number(entry, path + ".y_m", note, "y_m", kMaxPoseCoordinateM, &pose.y_m) ||
            !Number(entry, path + ".yaw_deg", note, "yaw_deg", kMaxPoseYawDeg, &yaw_deg)) {
          return false;
        }
        pose.yaw_rad = common::NormalizeAngle(common::DegToRad(yaw_deg));
      }
      // The refinement's radial bias: all three keys or none.
      std::optional<RadialBiasEstimate> bias;
      if (Has(entry, "radial_bias_m") || Has(entry, "sigma_radial_bias_m") ||
          Has(entry, "radial_bias_estimated")) {
        RadialBiasEstimate b;
        if (!Number(entry, path + ".radial_bias_m", note, "radial_bias_m", kMaxRadialBiasM,
                    &b.bias_m) ||
            !Number(entry, path + ".sigma_radial_bias_m", note, "sigma_radial_bias_m",
                    kMaxRadialBiasM, &b.sigma_m)) {
          return false;
        }
        if (b.sigma_m < 0.0) {
          return Fail(entry["sigma_radial_bias_m"], path + ".sigma_radial_bias_m",
                      "expected a number >= 0" + note);
        }
        if (!Has(entry, "radial_bias_estimated")) {
          return Fail(entry, path + ".radial_bias_estimated", "missing key" + note);
        }
        const YAML::Node node = entry["radial_bias_estimated"];
        const std::string text = node.IsScalar() ? node.Scalar() : "";
        if (text != "true" && text != "false") {
          return Fail(node, path + ".radial_bias_estimated", "expected true or false" + note);
        }
        b.estimated = text == "true";
        bias = b;
      }
      std::optional<Eigen::Matrix3d> covariance;
      if (!Covariance(entry, path, note, &covariance)) return false;
      std::string flag;
      if (Has(entry, "flag")) {
        if (!entry["flag"].IsScalar())
          return Fail(entry["flag"], path + ".flag", "expected a string" + note);
        flag = entry["flag"].Scalar();
      }
      bool legs = false;
      if (!Boolean(entry, path + ".mount_looks_like_legs", note, "mount_looks_like_legs", &legs))
        return false;
      file.sensors.emplace_back(id, pose);
      file.calibrated.push_back(calibrated);
      file.radial_bias.push_back(bias);
      file.covariance.push_back(covariance);
      file.flag.push_back(std::move(flag));
      file.mount_looks_like_legs.push_back(legs);
    }

    // The one quality figure a daemon started from the file reports again.
    const YAML::Node quality = root["quality"];
    if (quality.IsDefined() && quality.IsMap() && Has(quality, "track_residual_rms_m")) {
      double rms = 0.0;
      if (!Number(quality, "quality.track_residual_rms_m", "", "track_residual_rms_m",
                  kMaxPoseCoordinateM, &rms)) {
        return false;
      }
      if (rms < 0.0) {
        return Fail(quality["track_residual_rms_m"], "quality.track_residual_rms_m",
                    "expected a number >= 0");
      }
      file.track_residual_rms_m = rms;
    }

    if (Has(root, "reference")) {
      const YAML::Node node = root["reference"];
      if (!node.IsScalar()) return Fail(node, "reference", "expected a sensor id");
      const std::string& reference = node.Scalar();
      const auto index = file.Find(reference);
      if (!index) return Fail(node, "reference", "'" + Clip(reference) + "' is not in `sensors`");
      if (!file.calibrated[*index])
        return Fail(node, "reference", "'" + Clip(reference) + "' is not calibrated");
      file.reference = reference;
    }
    *out = std::move(file);
    return true;
  }

  std::string source_;
};

}  // namespace

std::optional<std::size_t> PoseFile::Find(const std::string& id) const {
  for (std::size_t i = 0; i < sensors.size(); ++i)
    if (sensors[i].first == id) return i;
  return std::nullopt;
}

PoseFile PoseFileOf(const CalibrationResult& result) {
  PoseFile file;
  for (const SensorPose& s : result.sensors) {
    file.sensors.emplace_back(s.id, s.world_from_sensor);
    file.calibrated.push_back(s.calibrated);
    file.radial_bias.push_back(s.calibrated && s.radial_bias && ReadableBias(*s.radial_bias)
                                   ? s.radial_bias
                                   : std::nullopt);
    file.covariance.push_back(s.calibrated ? std::optional<Eigen::Matrix3d>(s.covariance)
                                           : std::nullopt);
    file.flag.push_back(s.flag);
    file.mount_looks_like_legs.push_back(s.mount_looks_like_legs);
    if (s.calibrated && s.id == result.reference) file.reference = s.id;
  }
  return file;
}

std::string CalibrationYaml(const CalibrationResult& result, const YamlContext& context) {
  std::string y = kHeader;
  y += "method: " + Quoted(result.method) + "\n";
  // The reader insists that `reference` names a sensor with a pose: a failed calibration
  // without one says so in a comment instead.
  bool reference_ok = false;
  for (const SensorPose& s : result.sensors)
    reference_ok = reference_ok || (s.id == result.reference && s.calibrated && Readable(s));
  if (reference_ok) {
    y += "reference: " + Quoted(result.reference) + "\n";
  } else {
    y += "# reference: none (no sensor could be placed)\n";
  }
  if (!context.created_utc.empty()) y += "created_utc: " + Quoted(context.created_utc) + "\n";
  if (!context.inputs.empty()) {
    y += "inputs:\n";
    for (const std::string& input : context.inputs) y += "  - " + Quoted(input) + "\n";
  }
  if (context.received_until_ns && context.scan_from_ns) {
    y += "# input_window: the datagrams received up to received_until_utc_ns (the receive clock\n"
         "# of the daemon's recording), their frames from scan time scan_from_utc_ns on; `lrfnet\n"
         "# calibrate RECORDING --received-until-ns N --scan-from-ns M` calibrates them again\n";
    y += "input_window: {received_until_utc_ns: " + std::to_string(*context.received_until_ns) +
         ", scan_from_utc_ns: " + std::to_string(*context.scan_from_ns) + "}\n";
  }

  y += "sensors:\n";
  std::size_t calibrated = 0;
  for (const SensorPose& s : result.sensors) {
    if (s.calibrated && !Readable(s)) {
      y += "  # the estimate of this sensor's pose is not finite or absurdly far away\n";
    }
    // What a person should know about the pose (types.h SensorPose::flag).
    std::string flag = s.flag.empty() ? "" : ", flag: " + Quoted(s.flag);
    if (s.mount_looks_like_legs) flag += ", mount_looks_like_legs: true";
    if (!s.calibrated || !Readable(s)) {
      y += "  - {id: " + Quoted(s.id) + ", calibrated: false" + flag + "}\n";
      continue;
    }
    ++calibrated;
    const Pose2& p = s.world_from_sensor;
    std::string bias;
    if (s.radial_bias && ReadableBias(*s.radial_bias)) {
      bias = fmt::format(", radial_bias_m: {}, sigma_radial_bias_m: {}, radial_bias_estimated: {}",
                         Exact(s.radial_bias->bias_m), Short(s.radial_bias->sigma_m),
                         Bool(s.radial_bias->estimated));
    }
    y += fmt::format(
        "  - {{id: {}, x_m: {}, y_m: {}, yaw_deg: {}, sigma_x_m: {}, sigma_y_m: {}, "
        "sigma_yaw_deg: {}, cov_xy_m2: {}, cov_xyaw_m_deg: {}, cov_yyaw_m_deg: {}{}{}}}\n",
        Quoted(s.id), Exact(p.x_m), Exact(p.y_m), Exact(common::RadToDeg(p.yaw_rad)),
        Short(SigmaOf(s.covariance, 0)), Short(SigmaOf(s.covariance, 1)),
        Short(common::RadToDeg(SigmaOf(s.covariance, 2))), Short(CrossOf(s.covariance, 0, 1)),
        Short(common::RadToDeg(CrossOf(s.covariance, 0, 2))),
        Short(common::RadToDeg(CrossOf(s.covariance, 1, 2))), bias, flag);
  }

  std::size_t used = 0;
  for (const EdgeReport& e : result.edges) used += e.used ? 1 : 0;
  y += "quality:\n";
  y += fmt::format("  sensors_calibrated: {}\n  sensors_total: {}\n", calibrated,
                   result.sensors.size());
  y += fmt::format("  edges_used: {}\n  edges_not_used: {}\n", used, result.edges.size() - used);
  // Where the pose graph could not decide: what was refused and what walk would decide.
  if (!result.ambiguity.empty()) y += "  ambiguity: " + Quoted(result.ambiguity) + "\n";
  // The layout's scale not told apart from the people's size (and what would fix it).
  if (!result.scale_note.empty()) y += "  scale: " + Quoted(result.scale_note) + "\n";
  y += "  edges:";
  y += result.edges.empty() ? " []\n" : "\n";
  for (const EdgeReport& e : result.edges) {
    y += fmt::format(
        "    - {{r: {}, s: {}, used: {}, status: {}, matches: {}, rms_m: {}, "
        "rotation_residual_deg: {}, translation_residual_m: {}, track_residual_rms_m: {}, "
        "icp_applied: {}}}\n",
        Quoted(e.r), Quoted(e.s), Bool(e.used), Quoted(e.status), e.matches, Short(e.rms_m),
        Short(e.rotation_residual_deg), Short(e.translation_residual_m),
        Short(e.track_residual_rms_m), Bool(e.icp_applied));
  }
  y += fmt::format(
      "  joint_refinement: {{applied: {}, cost_before: {}, cost_after: {}, observations: {}}}\n",
      Bool(result.refined), Short(result.refine_cost_before), Short(result.refine_cost_after),
      result.refine_observations);
  // Read back by lrfnetd (calibration.initial): written only when it is a number.
  if (std::isfinite(result.track_residual_rms_m) && result.track_residual_rms_m >= 0.0)
    y += "  track_residual_rms_m: " + Short(result.track_residual_rms_m) + "\n";
  y += "  warnings:";
  y += result.warnings.empty() ? " []\n" : "\n";
  for (const std::string& w : result.warnings) y += "    - " + Quoted(w) + "\n";
  y += "  timings_s:";
  y += result.timings.empty() ? " []\n" : "\n";
  for (const StageTime& t : result.timings) {
    y += fmt::format("    - {{stage: {}, seconds: {}}}\n", Quoted(t.stage), Short(t.seconds));
  }
  return y;
}

bool ParsePoseYaml(const std::string& text, PoseFile* out, std::string* error) {
  if (text.size() > kMaxPoseFileBytes) {
    *error = fmt::format("larger than {} bytes: not a pose file", kMaxPoseFileBytes);
    return false;
  }
  Reader reader("");
  if (reader.Parse(text, out)) return true;
  *error = reader.error;
  return false;
}

bool ReadPoseFile(const std::string& path, PoseFile* out, std::string* error) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    *error = path + ": is a directory, not a pose file";
    return false;
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    *error = path + ": cannot open (" + std::strerror(errno) + ")";
    return false;
  }
  // Read in chunks, at most one chunk beyond the limit: a huge file (or a device that never ends)
  // is refused without reading it whole.
  std::string text;
  std::string chunk(1 << 16, '\0');
  while (in && text.size() <= kMaxPoseFileBytes) {
    in.read(chunk.data(), static_cast<std::streamsize>(chunk.size()));
    text.append(chunk.data(), static_cast<std::size_t>(in.gcount()));
  }
  if (in.bad()) {
    *error = path + ": read error";
    return false;
  }
  if (text.size() > kMaxPoseFileBytes) {
    *error = fmt::format("{}: larger than {} bytes: not a pose file", path, kMaxPoseFileBytes);
    return false;
  }
  Reader reader(path);
  if (reader.Parse(text, out)) return true;
  *error = reader.error;
  return false;
}

}  // namespace lrfnet::calib
