#include "central_daemon/calibration/eval.h"

#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <nlohmann/json.hpp>

namespace lrfnet::calib {

namespace {

double Mean(const std::vector<double>& v) {
  double sum = 0.0;
  for (const double x : v) sum += x;
  return v.empty() ? 0.0 : sum / static_cast<double>(v.size());
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

std::string JoinIds(const std::vector<std::string>& ids) {
  std::string out;
  for (const std::string& id : ids) out += (out.empty() ? "" : ", ") + id;
  return out;
}

}  // namespace

EvalResult Evaluate(const PoseFile& calibration, const PoseFile& truth,
                    const std::optional<std::string>& reference) {
  EvalResult result;
  const auto calibrated_in = [](const PoseFile& file, const std::string& id) {
    const auto i = file.Find(id);
    return i && file.calibrated[*i] ? i : std::nullopt;
  };

  if (reference) {
    result.reference = *reference;
  } else if (calibration.reference) {
    result.reference = *calibration.reference;
  } else {
    for (std::size_t i = 0; i < calibration.sensors.size(); ++i) {
      if (calibration.calibrated[i] && calibrated_in(truth, calibration.sensors[i].first)) {
        result.reference = calibration.sensors[i].first;
        break;
      }
    }
    if (result.reference.empty()) {
      result.error = "the calibration and the truth have no calibrated sensor in common";
      return result;
    }
  }
  const auto cal_ref = calibrated_in(calibration, result.reference);
  const auto truth_ref = calibrated_in(truth, result.reference);
  if (!cal_ref) {
    result.error = "reference sensor '" + result.reference + "' has no pose in the calibration";
    return result;
  }
  if (!truth_ref) {
    result.error = "reference sensor '" + result.reference + "' has no pose in the truth";
    return result;
  }

  const Pose2 cal_ref_from_world = calibration.sensors[*cal_ref].second.inverse();
  const Pose2 truth_ref_from_world = truth.sensors[*truth_ref].second.inverse();
  std::vector<double> d_r, d_t;
  for (std::size_t i = 0; i < truth.sensors.size(); ++i) {
    const auto& [id, truth_pose] = truth.sensors[i];
    if (id == result.reference || !truth.calibrated[i]) continue;
    const auto c = calibrated_in(calibration, id);
    if (!c) {
      result.missing.push_back(id);
      continue;
    }
    const Pose2 estimated = cal_ref_from_world * calibration.sensors[*c].second;
    const Pose2 actual = truth_ref_from_world * truth_pose;
    SensorError e;
    e.id = id;
    e.d_r_deg = common::RadToDeg(common::RotationDistanceRad(estimated, actual));
    e.d_t_m = common::TranslationDistanceM(estimated, actual);
    d_r.push_back(e.d_r_deg);
    d_t.push_back(e.d_t_m);
    result.sensors.push_back(std::move(e));
  }
  for (std::size_t i = 0; i < calibration.sensors.size(); ++i) {
    if (calibration.calibrated[i] && !truth.Find(calibration.sensors[i].first))
      result.unknown.push_back(calibration.sensors[i].first);
  }
  if (result.sensors.empty()) {
    result.error =
        "no sensor besides the reference '" + result.reference + "' has a pose in both files" +
        (result.missing.empty() ? "" : " (not calibrated: " + JoinIds(result.missing) + ")");
    return result;
  }
  result.mean_d_r_deg = Mean(d_r);
  result.median_d_r_deg = Median(d_r);
  result.mean_d_t_m = Mean(d_t);
  result.median_d_t_m = Median(d_t);
  result.ok = true;
  return result;
}

std::string EvalTable(const EvalResult& result) {
  if (!result.ok) return "error: " + result.error + "\n";
  std::size_t width = std::string("median").size();
  for (const SensorError& e : result.sensors) width = std::max(width, e.id.size());
  width = std::min<std::size_t>(width, 40);
  std::string out = "reference: " + result.reference + "\n";
  out += fmt::format("{:<{}}  {:>10}  {:>10}\n", "sensor", width, "d_R [deg]", "d_t [m]");
  for (const SensorError& e : result.sensors)
    out += fmt::format("{:<{}}  {:>10.4f}  {:>10.4f}\n", e.id, width, e.d_r_deg, e.d_t_m);
  out += fmt::format("{:<{}}  {:>10.4f}  {:>10.4f}\n", "mean", width, result.mean_d_r_deg,
                     result.mean_d_t_m);
  out += fmt::format("{:<{}}  {:>10.4f}  {:>10.4f}\n", "median", width, result.median_d_r_deg,
                     result.median_d_t_m);
  if (!result.missing.empty()) out += "not calibrated: " + JoinIds(result.missing) + "\n";
  if (!result.unknown.empty()) out += "not in the truth: " + JoinIds(result.unknown) + "\n";
  return out;
}

std::string EvalJson(const EvalResult& result) {
  nlohmann::json j;
  j["ok"] = result.ok;
  if (!result.ok) {
    j["error"] = result.error;
  } else {
    j["reference"] = result.reference;
    nlohmann::json sensors = nlohmann::json::array();
    for (const SensorError& e : result.sensors)
      sensors.push_back({{"id", e.id}, {"d_r_deg", e.d_r_deg}, {"d_t_m", e.d_t_m}});
    j["sensors"] = std::move(sensors);
    j["mean_d_r_deg"] = result.mean_d_r_deg;
    j["median_d_r_deg"] = result.median_d_r_deg;
    j["mean_d_t_m"] = result.mean_d_t_m;
    j["median_d_t_m"] = result.median_d_t_m;
    j["missing"] = result.missing;
    j["unknown"] = result.unknown;
  }
  // Ids come from files: invalid UTF-8 must not make dump() throw.
  return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

}  // namespace lrfnet::calib
