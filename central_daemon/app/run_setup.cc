#include "central_daemon/app/run_setup.h"

#include <spdlog/spdlog.h>
#include <time.h>

#include <fstream>
#include <random>
#include <span>
#include <sstream>

#include "central_daemon/app/auth_files.h"
#include "central_daemon/calibration/calibration_yaml.h"
#include "common/datagram_auth.h"

#ifndef LRFNET_VERSION
#define LRFNET_VERSION "unknown"
#endif

namespace lrfnet::daemon {

double MonotonicS() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

common::UtcNs NowUtcNs() {
  timespec ts{};
  ::clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<common::UtcNs>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

std::uint64_t RandomSessionId() {
  std::random_device device;
  return (static_cast<std::uint64_t>(device()) << 32) ^ device();
}

std::string Writer() { return std::string("lrfnetd ") + LRFNET_VERSION; }

DaemonOptions CoreOptions(const DaemonConfig& c) {
  DaemonOptions o;
  o.ingest = c.ingest;
  o.store = c.store;
  o.send_requests = c.send_requests;
  return o;
}

// Re-reads the config file over the defaults and applies the flags again.
std::optional<std::string> LoadConfig(const RunOptions& run, DaemonConfig* config) {
  DaemonConfig c;
  if (!run.config_path.empty()) {
    std::ifstream file(run.config_path);
    if (!file) return "--config: cannot read '" + run.config_path + "'";
    std::stringstream text;
    text << file.rdbuf();
    if (auto e = common::LoadYamlConfig(text.str(),
                                        [&](common::ConfigVisitor& v) { VisitDaemonConfig(c, v); }))
      return "--config " + run.config_path + ": " + *e;
  }
  if (run.listen_flag) c.listen = *run.listen_flag;
  if (run.record_flag) c.record_path = *run.record_flag;
  if (run.status_flag) c.status_interval_s = *run.status_flag;
  if (run.calibration_out_flag) c.calibration_output = *run.calibration_out_flag;
  if (run.calibration_report_flag) c.calibration_report_dir = *run.calibration_report_flag;
  if (run.calibration_in_flag) c.calibration_initial = *run.calibration_in_flag;
  if (run.live_view_flag) c.live_view_listen = *run.live_view_flag;
  if (run.fused_out_flag) c.fusion_record = *run.fused_out_flag;
  if (run.fused_udp_flag) c.fusion_publish = *run.fused_udp_flag;
  if (run.mqtt_flag) c.mqtt.broker = *run.mqtt_flag;
  if (run.mqtt_site_flag) c.mqtt.site = *run.mqtt_site_flag;
  if (run.keys_flag) c.auth_keys_dir = *run.keys_flag;
  if (run.state_dir_flag) c.auth_state_dir = *run.state_dir_flag;
  if (run.live_view_token_flag) c.live_view_token_file = *run.live_view_token_flag;
  if (auto e = Validate(c)) return (run.config_path.empty() ? "" : run.config_path + ": ") + *e;
  *config = c;
  return std::nullopt;
}

// calibration.initial: the sensors of a calibration.yaml (poses, covariances, radial biases,
// flags) as a calibration outcome, and the file's text (its history).
std::optional<std::string> LoadInitialCalibration(const std::string& path,
                                                  calib::CalibrationOutcome* outcome,
                                                  std::string* text) {
  calib::PoseFile file;
  std::string error;
  if (!calib::ReadPoseFile(path, &file, &error)) return "calibration.initial: " + error;
  if (text != nullptr) {
    // ReadPoseFile checked the file and its size.
    std::ifstream in(path, std::ios::binary);
    std::stringstream content;
    content << in.rdbuf();
    *text = content.str();
  }
  outcome->ok = true;
  outcome->result.method = "file";
  outcome->result.reference = file.reference.value_or("");
  outcome->result.track_residual_rms_m = file.track_residual_rms_m.value_or(0.0);
  for (std::size_t i = 0; i < file.sensors.size(); ++i) {
    calib::SensorPose pose;
    pose.id = file.sensors[i].first;
    pose.world_from_sensor = file.sensors[i].second;
    pose.calibrated = i < file.calibrated.size() ? file.calibrated[i] : true;
    // What the calibration that wrote the file knew of the pose, as its result carries it: the
    // covariance (fusion and monitoring weigh the pose by it), the radial bias, the flags.
    if (i < file.covariance.size() && file.covariance[i]) pose.covariance = *file.covariance[i];
    if (pose.calibrated && i < file.radial_bias.size()) pose.radial_bias = file.radial_bias[i];
    if (i < file.flag.size()) pose.flag = file.flag[i];
    if (i < file.mount_looks_like_legs.size())
      pose.mount_looks_like_legs = file.mount_looks_like_legs[i];
    if (!pose.flag.empty()) spdlog::warn("calibration.initial ({}): {}", pose.id, pose.flag);
    outcome->result.sensors.push_back(std::move(pose));
  }
  return std::nullopt;
}

// auth.keys: the sensor keys into the ingest's options (live: also the counter check and the
// Requests' salt and counter).
std::optional<std::string> SetUpAuth(DaemonConfig& config, bool live) {
  if (config.auth_keys_dir.empty()) return std::nullopt;
  if (!auth::Init()) return std::string("--keys: libsodium cannot be initialised");
  AuthOptions& a = config.ingest.auth;
  if (auto e = LoadSensorKeys(config.auth_keys_dir, &a)) return "--keys " + *e;
  if (live) {
    a.max_counter_ahead_s = config.ingest.validation.max_future_s;
    auth::RandomBytes(
        std::span(reinterpret_cast<std::uint8_t*>(&a.request_salt), sizeof a.request_salt));
    a.request_first_counter = static_cast<std::uint64_t>(NowUtcNs());
  }
  spdlog::info("authenticated datagrams: {} sensor key(s) from {}", a.keys.size(),
               config.auth_keys_dir);
  return std::nullopt;
}

}  // namespace lrfnet::daemon
