#pragma once
// The calibration benchmark's chain (lrfnet sim → one lrfnet-tracker --replay per sensor → the
// recordings loaded as the calibration's input), every step checked. A step that fails (could not
// start, ended by a signal, non-zero exit, no output) is run again; what still fails after its
// attempts is named with the cause of every attempt. A seed whose input lacks a sensor is then
// reported as not calibrated, with that cause, instead of being counted as a calibration that did
// not connect every sensor (whose result depends on the seed alone).

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "central_daemon/calibration/types.h"

namespace lrfnet::bench {

// How a child process ended.
struct ProcessExit {
  int spawn_errno = 0;  // posix_spawn's error when it could not start (0: it started)
  bool exited = false;  // ended by exit(); exit_code is then valid
  int exit_code = 0;
  int signal = 0;  // the signal that ended it (0: none)
};
bool Succeeded(const ProcessExit& e);
// One line: "exit code 1", "ended by signal 9 (Killed)", "could not start: Text file busy".
std::string Describe(const ProcessExit& e);

// Runs args[0] (a path) with args, stdout and stderr appended to `log` (created if need be).
ProcessExit RunChild(const std::vector<std::string>& args, const std::string& log);

struct ChainOptions {
  int attempts = 3;            // runs of one step at most (1: none repeated)
  double retry_delay_s = 0.5;  // before the second run of a step, doubled before each further one
};
std::optional<std::string> Validate(const ChainOptions& options);

struct StepReport {
  std::string step;  // e.g. "lrfnet-tracker l3 (ellipse)"
  int attempts = 0;
  bool ok = false;
  std::vector<std::string> causes;  // why each failed attempt failed, in order
};
// "lrfnet-tracker l3 (ellipse): exit code 1; ok at attempt 2" / "...: failed 3 times: A; B; C".
std::string Describe(const StepReport& report);

// Runs `run` until it succeeds and `check` (of what it wrote; nullopt: good) accepts it, at most
// options.attempts times, calling sleep_s(seconds) between attempts. Precondition: Validate.
StepReport RunStep(const std::string& step, const std::function<ProcessExit()>& run,
                   const std::function<std::optional<std::string>()>& check,
                   const ChainOptions& options, const std::function<void(double)>& sleep_s);

// A file a step wrote: nullopt when it exists and is not empty, else why not.
std::optional<std::string> CheckOutputFile(const std::string& path);

// The ids of `expected` that `input` lacks or holds no track frame of, in `expected`'s order (a
// tracker sends a frame per scan, with or without tracks, so every replayed sensor has frames).
std::vector<std::string> MissingSensors(const std::vector<std::string>& expected,
                                        const calib::CalibrationInput& input);

}  // namespace lrfnet::bench
