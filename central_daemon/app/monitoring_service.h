#pragma once
// lrfnetd's monitoring (an adapter around monitoring::Monitor, section `monitoring` of the
// config): once a calibration is in place, every new background snapshot in the store and, every
// track_period_s, the tracks of the last track_window_s go to the monitor. What it decides is
// logged, kept in the calibration's history and applied by the caller (main): a flagged sensor is
// left out of the fusion at once (excluded()), a corrected pose is placed again (result()), and
// calibration.output is rewritten atomically with the event in its `history`.
//
// Time: "now" is the newest scan time in the store (gateway UTC), so a recording replayed
// offline is monitored exactly like the live stream.
// Thread-safety: every function is called on the io thread.

#include <cstdint>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "central_daemon/app/calibration_input.h"
#include "central_daemon/app/config.h"
#include "central_daemon/app/daemon.h"
#include "central_daemon/app/live_state.h"
#include "central_daemon/calibration/pose_history.h"
#include "central_daemon/calibration/types.h"
#include "central_daemon/monitoring/monitor.h"

namespace lrfnet::daemon {

struct MonitoringCounters {
  std::uint64_t snapshots = 0;  // background snapshots checked
  std::uint64_t moved = 0;      // sensors flagged
  std::uint64_t corrected = 0;
  std::uint64_t relearned = 0;
  std::uint64_t writes = 0;  // calibration.output rewritten
  std::uint64_t write_errors = 0;
};

class MonitoringService {
 public:
  explicit MonitoringService(const DaemonConfig& config);

  // Thresholds and the output path (SIGHUP); the sensors' state is kept.
  void Reconfigure(const DaemonConfig& config);
  // The calibration to keep: a new one (`note` says what made it: "calibrated" for a calibration,
  // "loaded" for calibration.initial) replaces the poses watched; the store's current backgrounds
  // become the references. A loaded one brings its `history` (read from `history_text`, the file's
  // text; "" for none).
  void SetCalibration(const calib::CalibrationResult& result, const Daemon& daemon,
                      const std::string& note, const std::string& history_text = "");
  bool active() const { return enabled_ && active_; }

  // New snapshots, track checks, corrections. True when the exclusions or the poses changed: the
  // caller then applies excluded() and result() to the fusion.
  bool OnTick(const Daemon& daemon);

  const std::set<std::string>& excluded() const { return excluded_; }
  // The calibration in use: the last one set, with the corrected poses.
  const calib::CalibrationResult& result() const { return result_; }
  const std::vector<calib::CalibrationEvent>& history() const { return history_; }
  const monitoring::Monitor& monitor() const { return monitor_; }
  const MonitoringCounters& counters() const { return counters_; }

  // calibration.output with the history (atomically); "" or the error. Done by OnTick after every
  // event; offline runs call it once more at the end.
  std::string WriteCalibration();
  // The data the calibration in use was computed from, written with it (`input_window`);
  // nullopt: not known (a calibration read from a file).
  void SetInputWindow(const std::optional<InputWindow>& window) { input_window_ = window; }
  // A few words for the status line ("" when every sensor is fine or nothing is watched).
  std::string StatusText() const;
  // Per sensor: state, counters, the last verdict; the events so far.
  nlohmann::json StatsJson() const;
  // The state of each watched sensor ("ok", "moved") and what was last found, into the live view.
  void Annotate(LiveState* state) const;

 private:
  void Log(const monitoring::MonitorEvent& event) const;

  bool enabled_ = true;
  bool active_ = false;
  std::string output_;
  std::optional<InputWindow> input_window_;
  monitoring::Monitor monitor_;
  calib::CalibrationResult result_;
  std::vector<calib::CalibrationEvent> history_;
  std::set<std::string> excluded_;
  // The snapshot seen last per sensor: (session, snapshot id, receive time).
  std::map<std::string, std::tuple<std::uint64_t, std::uint32_t, common::UtcNs>> seen_;
  MonitoringCounters counters_;
};

}  // namespace lrfnet::daemon
