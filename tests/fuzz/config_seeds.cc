// Seeds for config_fuzz (its first byte chooses the reader: 0 tracker config, 1 daemon config,
// 2 scenario, 3 key file, 4 calibration history, 5 truth poses): the configs the programs print (defaults and a
// site's values), every shipped scenario, site and sensor key files, a history of each event kind,
// and damaged copies of each (cut at several places, a value replaced by hostile YAML).

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "central_daemon/app/config.h"
#include "central_daemon/calibration/pose_history.h"
#include "common/key_file.h"
#include "firmware_tracker/app/config.h"
#include "tests/fuzz/daemon_seeds.h"
#include "tools/sim/scenario.h"

namespace lrfnet::fuzz {
namespace {

// The text, its cuts, and copies with the value after each of `keys` replaced by hostile YAML.
std::vector<std::string> WithDamage(const std::string& text, const std::vector<std::string>& keys) {
  std::vector<std::string> out{text};
  for (const double share : {0.05, 0.3, 0.5, 0.8, 0.97}) {
    out.push_back(text.substr(0, static_cast<std::size_t>(share * static_cast<double>(text.size()))));
  }
  for (const auto& key : keys) {
    const std::size_t at = text.find(key);
    if (at == std::string::npos) continue;
    const std::size_t end = text.find('\n', at);
    for (const char* value : {" [nan, {x: .inf}]", " -1e309", " &a *a", " \"\\xff\\x00\"", " 18446744073709551616"}) {
      std::string bad = text;
      bad.replace(at, end - at, key + value);
      out.push_back(bad);
    }
  }
  return out;
}

}  // namespace

void WriteConfigSeeds(const std::string& dir) {
  std::vector<std::string> seeds;
  const auto add = [&](char reader, const std::vector<std::string>& texts) {
    for (const auto& t : texts) seeds.push_back(std::string(1, reader) + t);
  };

  tracker::TrackerConfig tracker;
  add(0, WithDamage(tracker::PrintTrackerConfig(tracker),
                    {"sensor_id:", "confirm_hits:", "max_width_m:", "frame_every_n_scans:"}));
  tracker.sensor_id = "gate-1";
  tracker.sensor_address = "192.168.0.1:2112";
  tracker.uplink_address = "[fd00::1]:5800";
  tracker.key_file = "$CREDENTIALS_DIRECTORY/sensor-gate-1-e1.key";
  tracker.encrypt = true;
  add(0, {tracker::PrintTrackerConfig(tracker), "sensor:\n  id: a\n", "{}", "[1, 2]", "shape: 3\n",
          "tracking: {unknown_key: 1}\n"});

  daemon::DaemonConfig site;
  add(1, WithDamage(daemon::PrintDaemonConfig(site), {"listen:", "list:", "max_age_s:", "broker:"}));
  site.zones_list =
      "[{name: door, line: [[0, 0], [1, 0]]}, {name: hall, polygon: [[0, 0], [4, 0], [4, 3], [0, 3]]}]";
  site.mqtt.broker = "127.0.0.1:1883";
  add(1, {daemon::PrintDaemonConfig(site), "zones:\n  list: \"[{name: a, polygon: [[0,0],[1,0]]}]\"\n",
          "listen: \"[::1]:5800\"\n", "listen: 300.1.1.1:99999\n"});

  for (const char* name : {"computer_lab", "industrial", "office_distributed", "office_semicircle",
                           "quenzel_sim", "schenk_A", "shop_floor"}) {
    const auto path = sim::FindScenarioFile(name);
    if (!path) continue;
    std::ifstream in(*path);
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    add(2, WithDamage(text, {"model:", "x_m:", "yaw_deg:", "duration_s:", "speed_mps:"}));
  }

  auth::KeyFile key;
  for (std::size_t i = 0; i < key.key.size(); ++i) key.key[i] = static_cast<std::uint8_t>(37 * i + 11);
  add(3, WithDamage(auth::FormatKeyFile(key), {"epoch", "key "}));
  key.kind = auth::KeyFile::Kind::kSensor;
  key.sensor_id = "gate-1";
  key.epoch = 4294967295u;
  add(3, WithDamage(auth::FormatKeyFile(key), {"sensor", "kind"}));

  std::vector<calib::CalibrationEvent> events(3);
  events[0] = {"2024-05-01T12:00:03Z", 1714564803000000000, "s2", "moved", "background",
               "yaw changed by 2.0 deg", common::Pose2{1, 2, 0.5}, common::Pose2{1.02, 2, 0.53}};
  events[1] = {"2024-05-01T12:01:00Z", 0, "s2", "corrected", "tracks", "", {}, common::Pose2{1.02, 2, 0.53}};
  events[2] = {"", 0, "s3", "background_relearned", "", "a door opened", {}, {}};
  add(4, WithDamage(calib::HistoryYaml(events), {"stamp_ns:", "before:", "event:"}));
  add(4, {"history: []\n", "history: {}\n", "sensors: []\n"});

  add(5, WithDamage("sensors:\n  - {id: a, x_m: 5, y_m: 0, yaw_deg: 10}\n"
                    "poses:\n"
                    "  - {id: a, from_s: 0, to_s: 30, from_utc_ns: 0, x_m: 4, y_m: 0, yaw_deg: 0}\n"
                    "  - {id: a, from_s: 30, to_s: 60, from_utc_ns: 30000000000, x_m: 5, y_m: 0, yaw_deg: 10}\n"
                    "  - {id: b, from_s: 0, to_s: 60, from_utc_ns: 0, x_m: 1, y_m: 1, yaw_deg: 0}\n",
                    {"from_s:", "x_m:", "id:"}));

  for (std::size_t i = 0; i < seeds.size(); ++i) {
    std::ofstream(std::filesystem::path(dir) / ("seed_" + std::to_string(i)), std::ios::binary) << seeds[i];
  }
}

}  // namespace lrfnet::fuzz
