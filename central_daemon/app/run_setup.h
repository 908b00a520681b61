#pragma once

// What lrfnetd's two runs (live on the socket, offline on files) share: the flags that override
// the config file, the config loaded over its defaults, the exit codes, the clocks, and the set-up
// of the sensor keys and of a calibration to start from.

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>

#include "central_daemon/app/config.h"
#include "central_daemon/app/daemon.h"
#include "central_daemon/calibration/pipeline.h"
#include "common/time.h"

namespace lrfnet::daemon {

inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;
inline constexpr int kExitUsage = 2;
// The core's tick: live on a timer, offline on the input's receive times.
inline constexpr auto kTickPeriod = std::chrono::milliseconds(250);
inline constexpr common::DurationNs kTickPeriodNs = 250'000'000;

// The steady clock, s.
double MonotonicS();
// The wall clock (CLOCK_REALTIME).
common::UtcNs NowUtcNs();
// A fresh random id for the daemon's session (its Requests).
std::uint64_t RandomSessionId();
// "lrfnetd VERSION", the writer named in recordings and messages.
std::string Writer();
// The core's options out of the config.
DaemonOptions CoreOptions(const DaemonConfig& c);

// The command line: the config file, the flags given (they override the file) and the run's own.
struct RunOptions {
  std::string config_path;
  std::optional<std::string> listen_flag;
  std::optional<std::string> record_flag;
  std::optional<double> status_flag;
  std::optional<std::string> calibration_out_flag;
  std::optional<std::string> calibration_report_flag;
  std::optional<std::string> calibration_in_flag;
  std::optional<std::string> live_view_flag;
  std::optional<std::string> fused_out_flag;
  std::optional<std::string> fused_udp_flag;
  std::optional<std::string> mqtt_flag;
  std::optional<std::string> mqtt_site_flag;
  std::optional<std::string> keys_flag;
  std::optional<std::string> state_dir_flag;
  std::optional<std::string> live_view_token_flag;
  double duration_s = 0.0;
  std::string stats_out;
};

// Re-reads the config file over the defaults and applies the flags again; the error names the
// file or the flag.
std::optional<std::string> LoadConfig(const RunOptions& run, DaemonConfig* config);

// calibration.initial: the sensors of a calibration.yaml (poses, covariances, radial biases,
// flags) as a calibration outcome, and the file's text (its history) when `text` is given.
std::optional<std::string> LoadInitialCalibration(const std::string& path,
                                                  calib::CalibrationOutcome* outcome,
                                                  std::string* text = nullptr);

// auth.keys: the sensor keys into the ingest's options (live: also the counter check and the
// Requests' salt and counter). Nothing to do without auth.keys.
std::optional<std::string> SetUpAuth(DaemonConfig& config, bool live);

}  // namespace lrfnet::daemon
