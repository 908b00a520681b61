#include "central_daemon/app/calibration_service.h"

#include <spdlog/spdlog.h>

#include <boost/asio/post.hpp>
#include <chrono>
#include <ctime>
#include <filesystem>
#include <fstream>

#include "central_daemon/app/calibration_input.h"
#include "central_daemon/calibration/calibration_yaml.h"
#include "central_daemon/calibration/report.h"

namespace lrfnet::daemon {

std::string UtcNowText() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char buffer[32];
  std::strftime(buffer, sizeof buffer, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buffer;
}

std::string WriteFileAtomically(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::trunc);
    out << text;
    out.flush();
    if (!out.good()) return tmp + ": write error";
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) return path + ": " + ec.message();
  return "";
}

namespace {

void LogOutcome(const calib::CalibrationOutcome& outcome) {
  const calib::CalibrationResult& r = outcome.result;
  for (const calib::SensorPose& s : r.sensors) {
    if (!s.calibrated) continue;
    spdlog::info("calibration: {} x={:.3f} m y={:.3f} m yaw={:.2f} deg", s.id,
                 s.world_from_sensor.x_m, s.world_from_sensor.y_m,
                 common::RadToDeg(s.world_from_sensor.yaw_rad));
  }
  std::size_t used = 0;
  for (const calib::EdgeReport& e : r.edges) used += e.used ? 1 : 0;
  double total_s = 0.0;
  for (const calib::StageTime& t : r.timings) {
    if (t.stage == "total") total_s = t.seconds;
  }
  spdlog::info("calibration: reference {}, {} of {} pairs used, track residual {:.3f} m rms, "
               "{:.2f} s",
               r.reference, used, r.edges.size(), r.track_residual_rms_m, total_s);
  for (const std::string& w : r.warnings) spdlog::warn("calibration: {}", w);
}

}  // namespace

bool AttemptDue(const CalibrationSchedule& schedule, const DaemonConfig& config, double now_s) {
  if (schedule.requested) return true;
  if (!config.calibration_auto) return false;
  if (schedule.last_success_s) {
    if (config.calibration_recalibrate_interval_s <= 0.0) return false;
    return now_s - *schedule.last_success_s >= config.calibration_recalibrate_interval_s &&
           (!schedule.last_attempt_s ||
            now_s - *schedule.last_attempt_s >= config.calibration_attempt_interval_s);
  }
  return !schedule.last_attempt_s ||
         now_s - *schedule.last_attempt_s >= config.calibration_attempt_interval_s;
}

std::string WriteCalibrationFiles(const calib::CalibrationOutcome& outcome,
                                  const std::string& output, const std::string& report_dir,
                                  const std::vector<std::string>& inputs) {
  if (!output.empty()) {
    calib::YamlContext context;
    context.created_utc = UtcNowText();
    context.inputs = inputs;
    if (std::string e = WriteFileAtomically(output, calib::CalibrationYaml(outcome.result, context));
        !e.empty())
      return e;
  }
  if (!report_dir.empty()) {
    calib::ReportInput report;
    report.result = &outcome.result;
    report.tracks = &outcome.tracks;
    report.pairs = outcome.pairs;
    std::string error;
    if (!calib::WriteReport(report_dir, report, &error)) return error;
  }
  return "";
}

CalibrationService::CalibrationService(boost::asio::io_context& io, const DaemonConfig& config)
    : io_(io), config_(config) {}

CalibrationService::~CalibrationService() {
  if (worker_.joinable()) worker_.join();
}

void CalibrationService::Reconfigure(const DaemonConfig& config) { config_ = config; }

void CalibrationService::OnTick(double now_s, const Daemon& daemon) {
  if (busy_ || !AttemptDue(schedule_, config_, now_s)) return;
  schedule_.requested = false;
  schedule_.last_attempt_s = now_s;
  ++counters_.attempts;
  common::UtcNs newest_ns = 0;
  for (const SensorStoreInfo& s : daemon.store().Sensors()) {
    newest_ns = std::max(newest_ns, s.last_scan_ns);
  }
  const auto window_ns = static_cast<common::UtcNs>(config_.calibration_window_s * 1e9);
  const common::UtcNs from_ns = newest_ns > window_ns ? newest_ns - window_ns : 0;
  auto input = std::make_shared<calib::CalibrationInput>(
      CalibrationInputFrom(daemon.ingest(), daemon.store(), from_ns));
  if (worker_.joinable()) worker_.join();
  busy_ = true;
  const DaemonConfig config = config_;
  worker_ = std::thread([this, input, config] {
    const auto start = std::chrono::steady_clock::now();
    const calib::StageClock clock = [start] {
      return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    };
    auto outcome = std::make_shared<calib::CalibrationOutcome>(
        calib::Calibrate(*input, config.calibration, clock));
    std::string write_error;
    if (outcome->ok) {
      write_error = WriteCalibrationFiles(*outcome, config.calibration_output,
                                          config.calibration_report_dir, {"lrfnetd"});
    }
    boost::asio::post(io_, [this, outcome, write_error] { Finish(outcome, write_error); });
  });
}

void CalibrationService::Finish(std::shared_ptr<calib::CalibrationOutcome> outcome,
                                std::string write_error) {
  busy_ = false;
  if (!outcome->ok) {
    ++counters_.insufficient;
    if (outcome->error != last_problem_) spdlog::info("calibration: {}", outcome->error);
    last_problem_ = outcome->error;
    return;
  }
  ++counters_.successes;
  schedule_.last_success_s = schedule_.last_attempt_s;
  last_problem_.clear();
  LogOutcome(*outcome);
  if (!write_error.empty()) {
    ++counters_.write_errors;
    spdlog::error("calibration: {}", write_error);
  } else if (!config_.calibration_output.empty()) {
    spdlog::info("calibration: wrote {}", config_.calibration_output);
  }
  latest_ = std::move(*outcome);
}

std::string CalibrationService::StatusText() const {
  if (busy_) return "calibrating";
  if (latest_) return "calibrated (" + std::to_string(latest_->result.sensors.size()) + " sensors)";
  if (!last_problem_.empty()) return "not calibrated: " + last_problem_;
  return "not calibrated";
}

}  // namespace lrfnet::daemon
