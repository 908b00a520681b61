#include "firmware_tracker/app/config.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <ostream>
#include <sstream>
#include <string>

namespace lrfnet::tracker {
namespace {

using common::ConfigKeys;

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

TEST(TrackerConfig, EncryptionNeedsAKey) {
  TrackerConfig config;
  const auto error = LoadTrackerConfig("auth:\n  encrypt: true\n", config);
  ASSERT_TRUE(error.has_value());
  EXPECT_NE(error->find("auth.encrypt"), std::string::npos) << *error;
  TrackerConfig keyed;
  ASSERT_EQ(LoadTrackerConfig("auth:\n  key: /etc/lrfnet/sensor.key\n  encrypt: true\n", keyed),
            std::nullopt);
  EXPECT_EQ(keyed.key_file, "/etc/lrfnet/sensor.key");
  EXPECT_TRUE(keyed.encrypt);
}

TEST(TrackerConfig, DefaultsAreValid) {
  TrackerConfig config;
  EXPECT_EQ(Validate(config), std::nullopt);
}

TEST(TrackerConfig, PrintedDefaultsLoadBackUnchanged) {
  const TrackerConfig defaults;
  const std::string printed = PrintTrackerConfig(defaults);
  TrackerConfig loaded;
  loaded.tracking.tracking.confirm_hits = 2;  // must be overwritten by the file
  ASSERT_EQ(LoadTrackerConfig(printed, loaded), std::nullopt);
  EXPECT_EQ(PrintTrackerConfig(loaded), printed);
  EXPECT_EQ(loaded.tracking.tracking.confirm_hits, defaults.tracking.tracking.confirm_hits);
}

TEST(TrackerConfig, ChangedValuesRoundTripExactly) {
  TrackerConfig config;
  config.sensor_id = "hall-2.lms511";
  config.uplink_address = "[fd00::7]:47800";
  config.tracking.background.learn_duration_s = 0.1 + 0.2;  // not exactly representable
  config.tracking.method = tracking::MeasurementMethod::kCenterOfMass;
  config.tracking.shape.mount = tracking::Mount::kLegs;
  config.tracking.tracking.max_speed_mps = 6.0;
  config.tracking.tracking.association = tracking::Association::kClosest;
  config.tracking.tracking.max_tracks = 17;
  config.link.reply_timeout = std::chrono::milliseconds(1234);
  config.publish.frame_every_n_scans = 3;
  config.clock_status.max_esterror_s = 0.002;
  TrackerConfig loaded;
  ASSERT_EQ(LoadTrackerConfig(PrintTrackerConfig(config), loaded), std::nullopt);
  EXPECT_EQ(loaded.sensor_id, "hall-2.lms511");
  EXPECT_EQ(loaded.uplink_address, "[fd00::7]:47800");
  EXPECT_EQ(loaded.tracking.background.learn_duration_s, 0.1 + 0.2);
  EXPECT_EQ(loaded.tracking.method, tracking::MeasurementMethod::kCenterOfMass);
  EXPECT_EQ(loaded.tracking.shape.mount, tracking::Mount::kLegs);
  EXPECT_EQ(loaded.tracking.tracking.max_speed_mps, 6.0);
  EXPECT_EQ(loaded.tracking.tracking.association, tracking::Association::kClosest);
  EXPECT_EQ(loaded.tracking.tracking.max_tracks, 17u);
  EXPECT_EQ(loaded.link.reply_timeout, std::chrono::milliseconds(1234));
  EXPECT_EQ(loaded.publish.frame_every_n_scans, 3u);
  EXPECT_EQ(loaded.clock_status.max_esterror_s, 0.002);
  EXPECT_EQ(PrintTrackerConfig(loaded), PrintTrackerConfig(config));
}

TEST(TrackerConfig, EveryOptionIsDocumented) {
  TrackerConfig config;
  const std::string printed = PrintTrackerConfig(config);
  const std::vector<std::string> keys =
      ConfigKeys([&](ConfigVisitor& v) { VisitTrackerConfig(config, v); });
  EXPECT_GT(keys.size(), 60u);
  std::istringstream lines(printed);
  std::string previous;
  std::size_t documented = 0;
  for (std::string line; std::getline(lines, line); previous = line) {
    if (line.rfind("  ", 0) == 0 && line.rfind("  #", 0) != 0) {
      EXPECT_EQ(previous.rfind("  # ", 0), 0u) << "undocumented option: " << line;
      ++documented;
    }
  }
  EXPECT_EQ(documented, keys.size());
}

TEST(TrackerConfig, ShippedFileIsThePrintedDefaults) {
  const std::string shipped = ReadFile(LRFNET_TRACKER_CONFIG_FILE);
  ASSERT_FALSE(shipped.empty()) << "cannot read " << LRFNET_TRACKER_CONFIG_FILE;
  EXPECT_EQ(shipped, PrintTrackerConfig(TrackerConfig{}))
      << "regenerate it with: lrfnet-tracker --print-config > "
         "firmware_tracker/config/lrfnet-tracker.yaml";
  TrackerConfig loaded;
  EXPECT_EQ(LoadTrackerConfig(shipped, loaded), std::nullopt);
}

TEST(TrackerConfig, PartialFileKeepsOtherDefaults) {
  TrackerConfig config;
  ASSERT_EQ(LoadTrackerConfig("tracking:\n  coast_timeout_s: 2.5\n", config), std::nullopt);
  EXPECT_EQ(config.tracking.tracking.coast_timeout_s, 2.5);
  EXPECT_EQ(config.tracking.background.learn_duration_s, TrackerConfig{}.tracking.background.learn_duration_s);
  TrackerConfig empty;
  EXPECT_EQ(LoadTrackerConfig("", empty), std::nullopt);
  EXPECT_EQ(LoadTrackerConfig("# only a comment\n", empty), std::nullopt);
}

struct BadCase {
  const char* yaml;
  const char* expected;  // substring of the one-line error
};

// Readable test names in ctest instead of a byte dump.
void PrintTo(const BadCase& c, std::ostream* os) { *os << c.expected; }

class TrackerConfigErrors : public ::testing::TestWithParam<BadCase> {};

TEST_P(TrackerConfigErrors, OneLineNamingTheKey) {
  TrackerConfig config;
  const auto error = LoadTrackerConfig(GetParam().yaml, config);
  ASSERT_TRUE(error.has_value()) << GetParam().yaml;
  EXPECT_NE(error->find(GetParam().expected), std::string::npos) << *error;
  EXPECT_EQ(error->find('\n'), std::string::npos) << *error;
  EXPECT_TRUE(std::none_of(error->begin(), error->end(),
                           [](char c) { return static_cast<unsigned char>(c) < 0x20; }))
      << *error;
}

INSTANTIATE_TEST_SUITE_P(
    Cases, TrackerConfigErrors,
    ::testing::Values(
        BadCase{"trackin:\n  max_tracks: 3\n", "trackin: unknown section"},
        BadCase{"tracking:\n  max_trakcs: 3\n", "tracking.max_trakcs: unknown option"},
        BadCase{"tracking:\n  coast_timeout_s: soon\n", "tracking.coast_timeout_s: expected a"},
        BadCase{"tracking:\n  coast_timeout_s: .nan\n", "tracking.coast_timeout_s"},
        BadCase{"tracking:\n  confirm_hits: -1\n", "tracking.confirm_hits: -1 is out of range"},
        BadCase{"tracking:\n  confirm_hits: 2.5\n", "tracking.confirm_hits: expected an integer"},
        BadCase{"tracking:\n  confirm_hits: 0\n", "tracking.confirm_hits"},
        BadCase{"tracking:\n  association: nearest\n", "unknown value 'nearest'"},
        BadCase{"tracking:\n  report_tentative: maybe\n", "expected true or false"},
        BadCase{"tracking:\n  max_tracks:\n", "tracking.max_tracks: has no value"},
        BadCase{"tracking:\n  max_tracks: [1, 2]\n", "tracking.max_tracks"},
        BadCase{"tracking: 5\n", "tracking: expected a map"},
        BadCase{"- a\n- b\n", "top level must be a map"},
        BadCase{"tracking:\n  max_tracks: 3\n max_tracks: 4\n", "YAML syntax error at line"},
        BadCase{"sensor:\n  id: \"bad id\"\n", "sensor.id"},
        BadCase{"measurement:\n  kind: blob\n", "one of: center_of_mass, ellipse"},
        BadCase{"background:\n  learn_duration_s: -1\n", "background."},
        BadCase{"shape:\n  stance_leg_weight: 0.4\n", "shape.stance_leg_weight"},
        BadCase{"shape:\n  standing_leg_memory_s: -0.1\n", "shape.standing_leg_memory_s"},
        BadCase{"publish:\n  frame_every_n_scans: 0\n", "publish.frame_every_n_scans"},
        BadCase{"clock:\n  max_error_s: 0\n", "clock.max_error_s"},
        BadCase{"link:\n  backoff_jitter: 1.5\n", "link"},
        // Hostile bytes quoted in the error are shown as '?': the error stays one line.
        BadCase{"\"track\\ning\": 1\n", "track?ing: unknown section"},
        BadCase{"tracking:\n  \"max\\ttracks\": 3\n", "tracking.max?tracks: unknown option"},
        BadCase{"tracking:\n  gate_mahalanobis_sq: \"1\\n2\"\n", "got '1?2'"},
        BadCase{"tracking: \"\\\r\"\n", "unknown escape character: ?"}));

}  // namespace
}  // namespace lrfnet::tracker
