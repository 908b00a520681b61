// Fuzz target for the files an operator writes and the programs read at start and on reload: the
// tracker's config (lrfnet-tracker --config), the daemon's config (lrfnetd --config, its zones
// list), a simulator scenario (lrfnet sim), a key file (lrfnet keys, --key-file), the `history`
// of a calibration.yaml and the `poses` of a truth.yaml (lrfnet eval --truth). The input's first
// byte chooses the reader (byte % 6, in that order), the rest is the file's text (seeds:
// config_seeds.cc).
// Properties checked with __builtin_trap:
//   - every reader either accepts the text or refuses it with a non-empty error of one line (no
//     control characters: a hostile file's bytes are not echoed raw), and never throws (a YAML
//     error is an error message, not an exception);
//   - an accepted config validates, and its printed YAML (what --print-config shows) loads again
//     into a default config and prints the same text: what the programs print, they read;
//   - an accepted scenario validates;
//   - an accepted key file, formatted again, reads back the same kind, sensor, epoch and key;
//   - an accepted history, written again, reads back the same events (by their written text);
//   - accepted truth poses name each sensor once, with a finite pose.
// Built in the ordinary build only (its readers need the tracker's and daemon's app libraries,
// which the libFuzzer tree does not build); there it runs every seed and a fixed number of
// deterministic mutations as a test.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "central_daemon/app/config.h"
#include "central_daemon/calibration/pose_history.h"
#include "common/key_file.h"
#include "firmware_tracker/app/config.h"
#include "tools/sim/scenario.h"

namespace {

void Check(bool ok) {
  if (!ok) __builtin_trap();
}

// Not empty, and one line: no control characters (a hostile file's bytes are not echoed raw).
void CheckError(const std::string& error) {
  Check(!error.empty());
  for (const char c : error) Check(static_cast<unsigned char>(c) >= 0x20);
}

void TrackerConfig(std::string_view text) {
  lrfnet::tracker::TrackerConfig config;
  if (const auto error = lrfnet::tracker::LoadTrackerConfig(text, config)) {
    CheckError(*error);
    return;
  }
  Check(!lrfnet::tracker::Validate(config).has_value());
  const std::string printed = lrfnet::tracker::PrintTrackerConfig(config);
  lrfnet::tracker::TrackerConfig again;
  Check(!lrfnet::tracker::LoadTrackerConfig(printed, again).has_value());
  Check(lrfnet::tracker::PrintTrackerConfig(again) == printed);
}

void DaemonConfig(std::string_view text) {
  lrfnet::daemon::DaemonConfig config;
  if (const auto error = lrfnet::daemon::LoadDaemonConfig(text, config)) {
    CheckError(*error);
    return;
  }
  Check(!lrfnet::daemon::Validate(config).has_value());
  const std::string printed = lrfnet::daemon::PrintDaemonConfig(config);
  lrfnet::daemon::DaemonConfig again;
  Check(!lrfnet::daemon::LoadDaemonConfig(printed, again).has_value());
  Check(lrfnet::daemon::PrintDaemonConfig(again) == printed);
  Check(again.zones.size() == config.zones.size());
}

void Scenario(const std::string& text) {
  lrfnet::sim::Scenario scenario;
  std::string error;
  if (!lrfnet::sim::ParseScenario(text, "fuzz.yaml", &scenario, &error)) {
    CheckError(error);
    return;
  }
  Check(!lrfnet::sim::Validate(scenario).has_value());
}

void KeyFile(std::string_view text) {
  lrfnet::auth::KeyFile file;
  if (const auto error = lrfnet::auth::ParseKeyFile(text, &file)) {
    CheckError(*error);
    return;
  }
  lrfnet::auth::KeyFile back;
  Check(!lrfnet::auth::ParseKeyFile(lrfnet::auth::FormatKeyFile(file), &back).has_value());
  Check(back.kind == file.kind && back.sensor_id == file.sensor_id && back.epoch == file.epoch &&
        back.key == file.key);
}

void History(const std::string& text) {
  std::vector<lrfnet::calib::CalibrationEvent> events;
  std::string error;
  if (!lrfnet::calib::ParseHistoryYaml(text, &events, &error)) {
    CheckError(error);
    Check(events.empty());
    return;
  }
  Check(events.size() <= lrfnet::calib::kMaxHistoryEvents);
  const std::string written = lrfnet::calib::HistoryYaml(events);
  std::vector<lrfnet::calib::CalibrationEvent> back;
  std::string back_error;
  Check(lrfnet::calib::ParseHistoryYaml(written, &back, &back_error));
  Check(back.size() == events.size());
  Check(lrfnet::calib::HistoryYaml(back) == written);
}

void TruthPoses(const std::string& text) {
  lrfnet::calib::PoseFile poses;
  std::string error;
  if (!lrfnet::calib::TruthPosesAt(text, 30.0, &poses, &error)) {
    CheckError(error);
    return;
  }
  std::set<std::string> ids;
  for (const auto& [id, pose] : poses.sensors) {
    Check(ids.insert(id).second);
    Check(std::isfinite(pose.x_m) && std::isfinite(pose.y_m) && std::isfinite(pose.yaw_rad));
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  try {
    switch (data[0] % 6) {
      case 0: TrackerConfig(text); break;
      case 1: DaemonConfig(text); break;
      case 2: Scenario(text); break;
      case 3: KeyFile(text); break;
      case 4: History(text); break;
      default: TruthPoses(text); break;
    }
  } catch (...) {
    __builtin_trap();  // a reader let an exception out
  }
  return 0;
}
