#pragma once
// lrfnetd's calibration: when to calibrate, on which data, and what happens with the result (an
// adapter: a worker thread, the clock, files and logs).
//
// Policy (calibration.* of the config): while no calibration of every sensor exists, an attempt
// starts every attempt_interval_s (when `auto`); after a success, again every
// recalibrate_interval_s (0: never); Request() (SIGUSR1) starts one at the next tick regardless.
// An attempt copies the newest window_s of the store (on the io thread: the store is not
// thread-safe), then calibrates on a worker thread; at most one runs at a time. The result comes
// back to the io thread: logged (poses, edges, or what data is missing), written to `output`
// (atomically: a temporary file renamed) and `report_dir`, and kept as latest().
//
// Thread-safety: every public function is called on the io thread.

#include <atomic>
#include <boost/asio/io_context.hpp>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include "central_daemon/app/calibration_input.h"
#include "central_daemon/app/config.h"
#include "central_daemon/app/daemon.h"
#include "central_daemon/calibration/pipeline.h"
#include "common/time.h"

namespace lrfnet::daemon {

struct CalibrationCounters {
  std::uint64_t attempts = 0;
  std::uint64_t successes = 0;
  std::uint64_t insufficient = 0;  // too little data (or not yet connected)
  std::uint64_t write_errors = 0;
};

// Pure scheduling: should an attempt start at now_s (seconds on a monotonic clock)?
struct CalibrationSchedule {
  std::optional<double> last_attempt_s;
  std::optional<double> last_success_s;
  bool requested = false;
  // Before the first success, automatic attempts wait until the data links every sensor.
  bool data_sufficient = true;
};
bool AttemptDue(const CalibrationSchedule& schedule, const DaemonConfig& config, double now_s);

// How far the data is from what the first calibration needs (pure): every sensor linked to the
// others by pairs with at least required_overlap_s of simultaneous tracks. The links are those of
// a maximum spanning tree over the pairs' overlap times; each of the n - 1 links counts
// min(1, overlap / required) (a missing link 0), the fraction is their mean. `text` names the
// weakest link or the sensors without tracks.
struct CalibrationProgress {
  double fraction = 0.0;  // 0..1
  bool sufficient = false;
  std::string text;
};
CalibrationProgress ProgressOf(const calib::DataAssessment& assessment, double required_overlap_s);
// "[##########----------]  50%" (width characters between the brackets).
std::string ProgressBar(double fraction, int width = 20);

// Replaces `path` by `text` through a temporary file and a rename, so a reader never sees half a
// file and a failed write leaves the previous one in place. Returns "" or the error.
std::string WriteFileAtomically(const std::string& path, const std::string& text);
// The wall clock as "YYYY-MM-DDTHH:MM:SSZ" (the `created` field of calibration.yaml).
std::string UtcNowText();

// Writes the calibration (YAML) and, when report_dir is set, the report. Returns "" or the error.
// With `window`, the YAML says which of the received data made the input (`input_window`).
std::string WriteCalibrationFiles(const calib::CalibrationOutcome& outcome,
                                  const std::string& output, const std::string& report_dir,
                                  const std::vector<std::string>& inputs,
                                  const std::optional<InputWindow>& window = std::nullopt);

// The store's newest window_s of tracks (copied), and in *window what that is in the daemon's
// receive clock and in scan time: the same input again from its recording (LoadCalibrationInput).
calib::CalibrationInput WindowInput(const Daemon& daemon, double window_s, InputWindow* window);

class CalibrationService {
 public:
  CalibrationService(boost::asio::io_context& io, const DaemonConfig& config);
  ~CalibrationService();  // waits for a running attempt
  CalibrationService(const CalibrationService&) = delete;
  CalibrationService& operator=(const CalibrationService&) = delete;

  void Reconfigure(const DaemonConfig& config);
  void Request() { schedule_.requested = true; }
  // Starts an attempt when due; now_s is a monotonic clock in seconds.
  void OnTick(double now_s, const Daemon& daemon);
  bool busy() const { return busy_; }
  const std::optional<calib::CalibrationOutcome>& latest() const { return latest_; }
  // The data of latest() when this service computed it (nullopt for one set by SetInitial).
  const std::optional<InputWindow>& latest_window() const { return latest_window_; }
  const CalibrationCounters& counters() const { return counters_; }
  // The calibration state in a few words for the status line (with the progress bar and the
  // estimated time still needed while collecting).
  std::string StatusText() const;
  // The data check behind the progress, refreshed every few seconds until the first success.
  const CalibrationProgress& progress() const { return progress_; }
  // Seconds still needed at the recent rate of progress; nullopt when unknown.
  std::optional<double> RemainingS() const;
  // Starts from a calibration read from a file (calibration.initial): latest() has its poses.
  void SetInitial(calib::CalibrationOutcome outcome);

 private:
  void Finish(std::shared_ptr<calib::CalibrationOutcome> outcome, std::string write_error,
              InputWindow window);
  void UpdateProgress(double now_s, const Daemon& daemon);

  boost::asio::io_context& io_;
  DaemonConfig config_;
  CalibrationSchedule schedule_;
  std::thread worker_;
  bool busy_ = false;
  std::optional<calib::CalibrationOutcome> latest_;
  std::optional<InputWindow> latest_window_;
  std::string last_problem_;
  CalibrationCounters counters_;
  CalibrationProgress progress_;
  std::optional<double> last_progress_s_;
  std::deque<std::pair<double, double>> progress_history_;  // (now_s, fraction), last minute
};

}  // namespace lrfnet::daemon
