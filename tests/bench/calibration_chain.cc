#include "tests/bench/calibration_chain.h"

#include <sys/wait.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include "tests/bench/bench_util.h"

namespace lrfnet::bench {

bool Succeeded(const ProcessExit& e) { return e.spawn_errno == 0 && e.exited && e.exit_code == 0; }

std::string Describe(const ProcessExit& e) {
  if (e.spawn_errno != 0) return std::string("could not start: ") + std::strerror(e.spawn_errno);
  if (e.signal != 0) {
    return "ended by signal " + std::to_string(e.signal) + " (" + strsignal(e.signal) + ")";
  }
  if (!e.exited) return "ended without an exit status";
  return "exit code " + std::to_string(e.exit_code);
}

ProcessExit RunChild(const std::vector<std::string>& args, const std::string& log) {
  ProcessExit out;
  pid_t pid = 0;
  const int rc = SpawnLogged(args, log, &pid);
  if (rc != 0) {
    out.spawn_errno = rc;
    return out;
  }
  int status = 0;
  while (waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) {
      out.spawn_errno = errno;
      return out;
    }
  }
  // glibc's posix_spawn reports a failed exec (a binary being relinked: ETXTBSY, ENOEXEC, ENOENT)
  // as its return value; a child that could not exec otherwise exits 127.
  if (WIFEXITED(status)) {
    out.exited = true;
    out.exit_code = WEXITSTATUS(status);
  } else if (WIFSIGNALED(status)) {
    out.signal = WTERMSIG(status);
  }
  return out;
}

std::optional<std::string> Validate(const ChainOptions& options) {
  if (options.attempts < 1 || options.attempts > 100) return "attempts must be 1 ... 100";
  if (!(options.retry_delay_s >= 0.0 && options.retry_delay_s <= 60.0)) {
    return "retry_delay_s must be 0 ... 60";
  }
  return std::nullopt;
}

std::string Describe(const StepReport& report) {
  std::string causes;
  for (const std::string& c : report.causes) causes += (causes.empty() ? "" : "; ") + c;
  if (report.ok) {
    if (report.causes.empty()) return report.step + ": ok";
    return report.step + ": " + causes + "; ok at attempt " + std::to_string(report.attempts);
  }
  return report.step + ": failed " + std::to_string(report.attempts) +
         (report.attempts == 1 ? " time: " : " times: ") + causes;
}

StepReport RunStep(const std::string& step, const std::function<ProcessExit()>& run,
                   const std::function<std::optional<std::string>()>& check,
                   const ChainOptions& options, const std::function<void(double)>& sleep_s) {
  StepReport report;
  report.step = step;
  double delay_s = options.retry_delay_s;
  for (int attempt = 1; attempt <= options.attempts; ++attempt) {
    if (attempt > 1) {
      sleep_s(delay_s);
      delay_s *= 2.0;
    }
    report.attempts = attempt;
    const ProcessExit e = run();
    if (!Succeeded(e)) {
      report.causes.push_back(Describe(e));
      continue;
    }
    if (std::optional<std::string> bad = check()) {
      report.causes.push_back(*bad);
      continue;
    }
    report.ok = true;
    return report;
  }
  return report;
}

std::optional<std::string> CheckOutputFile(const std::string& path) {
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) return path + ": " + ec.message();
  if (size == 0) return path + ": empty";
  return std::nullopt;
}

std::vector<std::string> MissingSensors(const std::vector<std::string>& expected,
                                        const calib::CalibrationInput& input) {
  std::vector<std::string> missing;
  for (const std::string& id : expected) {
    bool has_frames = false;
    for (const calib::SensorRecording& s : input.sensors) {
      has_frames |= s.id == id && !s.frames.empty();
    }
    if (!has_frames) missing.push_back(id);
  }
  return missing;
}

}  // namespace lrfnet::bench
