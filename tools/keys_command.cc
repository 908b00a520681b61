// lrfnet keys init|rotate|derive|token|list --dir DIR [SENSOR_ID] [--epoch N]
//
// The site key and the per-sensor keys of authenticated datagrams (common/datagram_auth.h, key
// files: common/key_file.h). Keys are created with mode 0600 in DIR (made with mode 0700) and never
// overwritten; nothing is ever sent over the network.

#include <sys/stat.h>

#include <algorithm>
#include <array>
#include <boost/program_options.hpp>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "common/datagram_auth.h"
#include "common/key_file.h"
#include "tools/subcommands.h"

namespace lrfnet::tools {

namespace po = boost::program_options;

namespace {

int Fail(const std::string& message) {
  std::fprintf(stderr, "lrfnet keys: %s\n", message.c_str());
  return kExitFailure;
}

// The site keys in `dir`, sorted by epoch.
std::optional<std::string> SiteKeys(const std::string& dir, std::vector<auth::KeyFile>* out) {
  std::error_code ec;
  if (!std::filesystem::exists(dir, ec)) {
    out->clear();
    return std::nullopt;
  }
  if (auto e = auth::ReadKeyDir(dir, auth::KeyFile::Kind::kSite, out)) return e;
  std::sort(out->begin(), out->end(),
            [](const auth::KeyFile& a, const auth::KeyFile& b) { return a.epoch < b.epoch; });
  return std::nullopt;
}

std::optional<std::string> MakeDir(const std::string& dir) {
  std::error_code ec;
  if (std::filesystem::exists(dir, ec)) return std::nullopt;
  std::filesystem::create_directories(dir, ec);
  if (ec) return "cannot create " + dir + ": " + ec.message();
  ::chmod(dir.c_str(), 0700);
  return std::nullopt;
}

std::optional<std::string> WriteSiteKey(const std::string& dir, std::uint32_t epoch,
                                        std::string* path) {
  auth::KeyFile site;
  site.kind = auth::KeyFile::Kind::kSite;
  site.epoch = epoch;
  auth::RandomBytes(site.key);
  *path = auth::SiteKeyPath(dir, epoch);
  return auth::WriteSecretFile(*path, auth::FormatKeyFile(site));
}

std::optional<std::string> WriteSensorKey(const std::string& dir, const auth::KeyFile& site,
                                          const std::string& sensor_id, std::string* path) {
  auth::KeyFile sensor;
  sensor.kind = auth::KeyFile::Kind::kSensor;
  sensor.sensor_id = sensor_id;
  sensor.epoch = site.epoch;
  sensor.key = auth::DeriveSensorKey(site.key, sensor_id);
  *path = auth::SensorKeyPath(dir, sensor_id, site.epoch);
  return auth::WriteSecretFile(*path, auth::FormatKeyFile(sensor));
}

}  // namespace

int RunKeys(int argc, char** argv) {
  po::options_description visible(
      "lrfnet keys init --dir DIR            a new site key (epoch 1): DIR/site-e1.key\n"
      "lrfnet keys derive --dir DIR SENSOR_ID  the sensor's key from the newest site key "
      "(--epoch N: that\n"
      "                                      epoch's); prints the path of the file it wrote\n"
      "lrfnet keys rotate --dir DIR          the next epoch's site key, and the keys of every "
      "sensor of the\n"
      "                                      epoch before; prints the paths\n"
      "lrfnet keys token --dir DIR           an access token for the live view: "
      "DIR/live-view.token\n"
      "lrfnet keys list --dir DIR            epochs and sensors (no secrets)\n"
      "Keys of authenticated datagrams: lrfnetd --keys DIR reads DIR's sensor keys, each gateway "
      "gets its own\nsensor key file (lrfnet-tracker --key FILE). Files are created with mode 0600 "
      "and never replaced.\nOptions",
      100, 50);
  std::string dir;
  std::uint32_t epoch = 0;
  visible.add_options()("help,h", "this help")("dir", po::value<std::string>(&dir),
                                               "the key folder (created with mode 0700)")(
      "epoch", po::value<std::uint32_t>(&epoch), "derive: the site key of this epoch");
  po::options_description hidden;
  hidden.add_options()("action", po::value<std::string>(), "action")(
      "sensor", po::value<std::string>(), "sensor id");
  po::options_description all;
  all.add(visible).add(hidden);
  po::positional_options_description positional;
  positional.add("action", 1).add("sensor", 1);
  po::variables_map vm;
  try {
    po::store(po::command_line_parser(argc, argv).options(all).positional(positional).run(), vm);
    po::notify(vm);
  } catch (const po::error& e) {
    return UsageError("keys", e.what());
  }
  if (vm.count("help") != 0) {
    std::cout << visible << "\n";
    return kExitOk;
  }
  if (vm.count("action") == 0)
    return UsageError("keys", "missing init, derive, rotate, token or list");
  const std::string action = vm["action"].as<std::string>();
  if (dir.empty()) return UsageError("keys", "missing --dir DIR");
  const std::string sensor_id = vm.count("sensor") != 0 ? vm["sensor"].as<std::string>() : "";
  if (action == "derive") {
    if (sensor_id.empty()) return UsageError("keys", "derive: missing SENSOR_ID");
    if (!auth::IsValidSensorId(sensor_id))
      return UsageError("keys", "sensor id '" + sensor_id + "' must match [A-Za-z0-9_.-]{1,32}");
  } else if (!sensor_id.empty()) {
    return UsageError("keys", action + ": unexpected argument '" + sensor_id + "'");
  }
  if (vm.count("epoch") != 0 && (action != "derive" || epoch == 0))
    return UsageError("keys", "--epoch N (>= 1) goes with derive");
  if (!auth::Init()) return Fail("libsodium cannot be initialised");

  std::vector<auth::KeyFile> sites;
  if (auto e = SiteKeys(dir, &sites)) return Fail(*e);
  std::string path;
  if (action == "init") {
    if (!sites.empty()) {
      return Fail(dir + " has a site key already (epoch " + std::to_string(sites.back().epoch) +
                  "); lrfnet keys rotate makes the next one");
    }
    if (auto e = MakeDir(dir)) return Fail(*e);
    if (auto e = WriteSiteKey(dir, 1, &path)) return Fail(*e);
    std::printf("%s\n", path.c_str());
    return kExitOk;
  }
  if (action == "token") {
    if (auto e = MakeDir(dir)) return Fail(*e);
    std::array<std::uint8_t, 16> random{};
    auth::RandomBytes(random);
    path = (std::filesystem::path(dir) / "live-view.token").string();
    if (auto e = auth::WriteSecretFile(path, auth::ToHex(random) + "\n")) return Fail(*e);
    std::printf("%s\n", path.c_str());
    return kExitOk;
  }
  if (sites.empty()) return Fail("no site key in " + dir + " (lrfnet keys init --dir " + dir + ")");
  if (action == "derive") {
    const auth::KeyFile* site = &sites.back();
    if (epoch != 0) {
      const auto it = std::find_if(sites.begin(), sites.end(),
                                   [&](const auth::KeyFile& k) { return k.epoch == epoch; });
      if (it == sites.end())
        return Fail("no site key of epoch " + std::to_string(epoch) + " in " + dir);
      site = &*it;
    }
    if (auto e = WriteSensorKey(dir, *site, sensor_id, &path)) return Fail(*e);
    std::printf("%s\n", path.c_str());
    return kExitOk;
  }
  std::vector<auth::KeyFile> sensors;
  if (auto e = auth::ReadKeyDir(dir, auth::KeyFile::Kind::kSensor, &sensors)) return Fail(*e);
  if (action == "rotate") {
    const std::uint32_t previous = sites.back().epoch;
    if (previous == UINT32_MAX) return Fail("no epoch after " + std::to_string(previous));
    if (auto e = WriteSiteKey(dir, previous + 1, &path)) return Fail(*e);
    std::printf("%s\n", path.c_str());
    auth::KeyFile next;
    if (auto e = auth::ReadKeyFile(path, &next)) return Fail(*e);
    for (const auth::KeyFile& s : sensors) {
      if (s.epoch != previous) continue;
      std::string sensor_path;
      if (auto e = WriteSensorKey(dir, next, s.sensor_id, &sensor_path)) return Fail(*e);
      std::printf("%s\n", sensor_path.c_str());
    }
    return kExitOk;
  }
  if (action == "list") {
    for (const auth::KeyFile& s : sites) std::printf("site epoch %u\n", s.epoch);
    for (const auth::KeyFile& s : sensors) {
      std::printf("sensor %s epoch %u key id %08x\n", s.sensor_id.c_str(), s.epoch,
                  auth::DeriveSensorKeys(s.key, s.epoch).key_id);
    }
    return kExitOk;
  }
  return UsageError("keys", "unknown action '" + action + "' (init, derive, rotate, token, list)");
}

}  // namespace lrfnet::tools
