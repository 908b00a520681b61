#include "central_daemon/app/calibration_service.h"

#include <spdlog/spdlog.h>

#include <boost/asio/post.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <fstream>

#include "central_daemon/app/calibration_input.h"
#include "central_daemon/calibration/calibration_yaml.h"
#include "central_daemon/calibration/graph.h"
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

// The data check behind the progress runs this often while collecting.
constexpr double kProgressPeriodS = 2.0;

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

CalibrationProgress ProgressOf(const calib::DataAssessment& assessment, double required_overlap_s) {
  CalibrationProgress out;
  const std::size_t n = assessment.sensors.size();
  if (n < 2) {
    out.text = n == 0 ? "waiting for sensors" : "waiting for a second sensor";
    return out;
  }
  std::vector<std::string> no_tracks;
  for (const calib::SensorData& s : assessment.sensors) {
    if (s.tracks == 0) no_tracks.push_back(s.id);
  }
  // Kruskal over the pairs by decreasing overlap: the maximum spanning forest. Its links are the
  // strongest way to connect every sensor, so its weakest link bounds what the data supports.
  std::vector<calib::PairData> pairs = assessment.pairs;
  std::sort(pairs.begin(), pairs.end(),
            [](const calib::PairData& a, const calib::PairData& b) { return a.overlap_s > b.overlap_s; });
  calib::DisjointSets sets(n);
  double sum = 0.0;
  std::size_t links = 0;
  const calib::PairData* weakest = nullptr;
  for (const calib::PairData& p : pairs) {
    if (p.r >= n || p.s >= n || !sets.Union(p.r, p.s)) continue;
    ++links;
    sum += std::min(1.0, p.overlap_s / required_overlap_s);
    if (weakest == nullptr || p.overlap_s < weakest->overlap_s) weakest = &p;
  }
  out.fraction = std::clamp(sum / static_cast<double>(n - 1), 0.0, 1.0);
  out.sufficient = links == n - 1 && weakest != nullptr && weakest->overlap_s >= required_overlap_s;
  char buffer[200];
  if (!no_tracks.empty()) {
    std::string ids;
    for (std::size_t k = 0; k < no_tracks.size(); ++k) ids += (k ? ", " : "") + no_tracks[k];
    out.text = "no tracks yet from " + ids;
  } else if (links < n - 1) {
    out.text = "sensors not yet linked by shared tracks: " + std::to_string(n - 1 - links) +
               " link(s) missing";
  } else if (weakest != nullptr) {
    std::snprintf(buffer, sizeof buffer, "weakest link %s-%s %.1f of %.0f s shared",
                  assessment.sensors[weakest->r].id.c_str(),
                  assessment.sensors[weakest->s].id.c_str(), weakest->overlap_s, required_overlap_s);
    out.text = buffer;
  }
  if (out.sufficient) out.text = "enough data";
  return out;
}

std::string ProgressBar(double fraction, int width) {
  const double f = std::isfinite(fraction) ? std::clamp(fraction, 0.0, 1.0) : 0.0;
  // Rounded down: 100 % only when the data is complete.
  const int filled = static_cast<int>(std::floor(f * width));
  char percent[8];
  std::snprintf(percent, sizeof percent, "%3d%%", static_cast<int>(std::floor(f * 100.0)));
  return "[" + std::string(static_cast<std::size_t>(filled), '#') +
         std::string(static_cast<std::size_t>(width - filled), '-') + "] " + percent;
}

bool AttemptDue(const CalibrationSchedule& schedule, const DaemonConfig& config, double now_s) {
  if (schedule.requested) return true;
  if (!config.calibration_auto) return false;
  if (!schedule.last_success_s && !schedule.data_sufficient) return false;
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
                                  const std::vector<std::string>& inputs,
                                  const std::optional<InputWindow>& window) {
  if (!output.empty()) {
    calib::YamlContext context;
    context.created_utc = UtcNowText();
    context.inputs = inputs;
    if (window) {
      context.received_until_ns = window->received_until_ns;
      context.scan_from_ns = window->scan_from_ns;
    }
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

calib::CalibrationInput WindowInput(const Daemon& daemon, double window_s, InputWindow* window) {
  common::UtcNs newest_ns = 0;
  for (const SensorStoreInfo& s : daemon.store().Sensors()) {
    newest_ns = std::max(newest_ns, s.last_scan_ns);
  }
  const auto window_ns = static_cast<common::UtcNs>(window_s * 1e9);
  const common::UtcNs from_ns = newest_ns > window_ns ? newest_ns - window_ns : 0;
  if (window != nullptr) {
    // Everything the store holds arrived at or before the newest receive time of any sensor (one
    // receive clock, datagrams ingested in the order received).
    window->received_until_ns = 0;
    for (const SensorStatus& s : daemon.ingest().Sensors()) {
      window->received_until_ns = std::max(window->received_until_ns, s.last_receive_ns);
    }
    window->scan_from_ns = from_ns;
  }
  return CalibrationInputFrom(daemon.ingest(), daemon.store(), from_ns);
}

void CalibrationService::UpdateProgress(double now_s, const Daemon& daemon) {
  last_progress_s_ = now_s;
  const calib::CalibrationInput input = WindowInput(daemon, config_.calibration_window_s, nullptr);
  const calib::AlignedTracks tracks = calib::Align(input, config_.calibration.align);
  progress_ = ProgressOf(calib::Assess(tracks, config_.calibration.min_pair_overlap_s),
                         config_.calibration.min_pair_overlap_s);
  schedule_.data_sufficient = progress_.sufficient;
  progress_history_.emplace_back(now_s, progress_.fraction);
  while (progress_history_.size() > 2 && now_s - progress_history_.front().first > 60.0) {
    progress_history_.pop_front();
  }
}

std::optional<double> CalibrationService::RemainingS() const {
  if (progress_.sufficient) return 0.0;
  if (progress_history_.size() < 2) return std::nullopt;
  const auto& [t0, f0] = progress_history_.front();
  const auto& [t1, f1] = progress_history_.back();
  if (t1 - t0 < 4.0 || f1 <= f0) return std::nullopt;
  return (1.0 - f1) * (t1 - t0) / (f1 - f0);
}

void CalibrationService::SetInitial(calib::CalibrationOutcome outcome) {
  latest_ = std::move(outcome);
  latest_window_.reset();
}

void CalibrationService::OnTick(double now_s, const Daemon& daemon) {
  // The data check runs until the first calibration (cheap: alignment without estimation).
  if (!latest_ && !busy_ && (!last_progress_s_ || now_s - *last_progress_s_ >= kProgressPeriodS ||
                             now_s < *last_progress_s_)) {
    UpdateProgress(now_s, daemon);
  }
  if (busy_ || !AttemptDue(schedule_, config_, now_s)) return;
  schedule_.requested = false;
  schedule_.last_attempt_s = now_s;
  ++counters_.attempts;
  InputWindow window;
  auto input = std::make_shared<calib::CalibrationInput>(
      WindowInput(daemon, config_.calibration_window_s, &window));
  if (worker_.joinable()) worker_.join();
  busy_ = true;
  const DaemonConfig config = config_;
  worker_ = std::thread([this, input, config, window] {
    const auto start = std::chrono::steady_clock::now();
    const calib::StageClock clock = [start] {
      return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    };
    auto outcome = std::make_shared<calib::CalibrationOutcome>(
        calib::Calibrate(*input, config.calibration, clock));
    std::string write_error;
    if (outcome->ok) {
      write_error = WriteCalibrationFiles(*outcome, config.calibration_output,
                                          config.calibration_report_dir, {"lrfnetd"}, window);
    }
    boost::asio::post(
        io_, [this, outcome, write_error, window] { Finish(outcome, write_error, window); });
  });
}

void CalibrationService::Finish(std::shared_ptr<calib::CalibrationOutcome> outcome,
                                std::string write_error, InputWindow window) {
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
  latest_window_ = window;
}

std::string CalibrationService::StatusText() const {
  if (busy_) return "calibrating";
  if (latest_) return "calibrated (" + std::to_string(latest_->result.sensors.size()) + " sensors)";
  std::string text = "collecting " + ProgressBar(progress_.fraction);
  if (!progress_.text.empty()) text += " " + progress_.text;
  if (const auto remaining = RemainingS(); remaining && *remaining >= 1.0) {
    text += fmt::format(", about {:.0f} s more", *remaining);
  }
  if (!last_problem_.empty()) text += "; last attempt: " + last_problem_;
  return text;
}

}  // namespace lrfnet::daemon
