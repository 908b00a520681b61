#include "central_daemon/app/config.h"

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

namespace lrfnet::daemon {
namespace {

TEST(DaemonConfigTest, ShippedFileIsPrintConfigOfTheDefaults) {
  std::ifstream file(LRFNET_DAEMON_CONFIG_FILE);
  ASSERT_TRUE(file) << "missing " << LRFNET_DAEMON_CONFIG_FILE;
  std::stringstream text;
  text << file.rdbuf();
  EXPECT_EQ(text.str(), PrintDaemonConfig(DaemonConfig{}))
      << "regenerate central_daemon/config/lrfnetd.yaml with lrfnetd --print-config";
  DaemonConfig loaded;
  EXPECT_EQ(LoadDaemonConfig(text.str(), loaded), std::nullopt);
  EXPECT_EQ(loaded.receiver.port, kDefaultPort);
  EXPECT_EQ(loaded.receiver.address, "::");
}

TEST(DaemonConfigTest, ValuesRoundTripThroughPrint) {
  DaemonConfig c;
  c.listen = "127.0.0.1:6000";
  c.record_path = "session.lrfrec";
  c.ingest.validation.max_clock_offset_s = 2.5;
  c.ingest.silent_after_s = 7.0;
  c.store.max_age_s = 600.0;
  c.store_max_mb = 64;
  c.send_requests = false;
  ASSERT_EQ(Validate(c), std::nullopt);
  DaemonConfig back;
  ASSERT_EQ(LoadDaemonConfig(PrintDaemonConfig(c), back), std::nullopt);
  EXPECT_EQ(back.receiver.address, "127.0.0.1");
  EXPECT_EQ(back.receiver.port, 6000);
  EXPECT_EQ(back.record_path, "session.lrfrec");
  EXPECT_EQ(back.ingest.validation.max_clock_offset_s, 2.5);
  EXPECT_EQ(back.ingest.silent_after_s, 7.0);
  EXPECT_EQ(back.store.max_age_s, 600.0);
  EXPECT_EQ(back.store.max_bytes, std::size_t{64} << 20);
  EXPECT_FALSE(back.send_requests);
}

TEST(DaemonConfigTest, FusionOptionsRoundTripThroughPrint) {
  DaemonConfig c;
  c.fusion.method = fusion::FusionMethod::kLatestStates;
  c.fusion.max_coast_s = 2.5;
  c.fusion.tracker_accel_psd = 1.25;
  c.fusion.centre_sigma_shape_fit_m = 0.04;
  c.fusion.binding_bonus = 0.0;
  c.fusion.adapt_covariances = false;
  c.fusion.confirm_updates = 5;
  c.fusion.learn_sensor_bias = false;
  c.fusion.sensor_bias_min_samples = 20;
  c.fusion.sensor_bias_sample_s = 3.0;
  c.fusion.max_sensor_bias_m = 0.1;
  c.fusion.sensor_bias_offset_sigma_fraction = 0.5;
  ASSERT_EQ(Validate(c), std::nullopt);
  DaemonConfig back;
  ASSERT_EQ(LoadDaemonConfig(PrintDaemonConfig(c), back), std::nullopt);
  EXPECT_TRUE(back.fusion == c.fusion);
  DaemonConfig partial;
  ASSERT_EQ(LoadDaemonConfig("fusion: {method: latest_states}", partial), std::nullopt);
  EXPECT_EQ(partial.fusion.method, fusion::FusionMethod::kLatestStates);
  EXPECT_EQ(partial.fusion.max_coast_s, fusion::FusionOptions{}.max_coast_s);
  EXPECT_TRUE(partial.fusion.learn_sensor_bias);
  DaemonConfig no_bias;
  ASSERT_EQ(LoadDaemonConfig("fusion: {learn_sensor_bias: false}", no_bias), std::nullopt);
  EXPECT_FALSE(no_bias.fusion.learn_sensor_bias);
  DaemonConfig bad;
  EXPECT_NE(LoadDaemonConfig("fusion: {max_sensor_bias_m: -1}", bad), std::nullopt);
}

TEST(DaemonConfigTest, LiveViewBeyondLoopbackNeedsAToken) {
  DaemonConfig c;
  ASSERT_EQ(LoadDaemonConfig("live_view:\n  listen: \"8080\"\n", c), std::nullopt);
  EXPECT_EQ(c.live_view_listen, "127.0.0.1:8080") << "a bare port is loopback only";
  for (const char* listen : {"0.0.0.0:8080", "[::]:8080", "192.168.1.5:80", "viewer.local:80"}) {
    DaemonConfig open;
    const auto error =
        LoadDaemonConfig(std::string("live_view:\n  listen: \"") + listen + "\"\n", open);
    ASSERT_TRUE(error.has_value()) << listen;
    EXPECT_NE(error->find("token_file"), std::string::npos) << *error;
    DaemonConfig with_token;
    EXPECT_EQ(LoadDaemonConfig(std::string("live_view:\n  listen: \"") + listen +
                                   "\"\n  token_file: /etc/lrfnet/live-view.token\n",
                               with_token),
              std::nullopt)
        << listen;
  }
  for (const char* host : {"127.0.0.1", "127.1.2.3", "::1", "localhost"})
    EXPECT_TRUE(IsLoopbackHost(host)) << host;
  for (const char* host : {"0.0.0.0", "::", "127.0.0", "127.0.0.1.5", "1.127.0.0", "127.a.0.1", ""})
    EXPECT_FALSE(IsLoopbackHost(host)) << host;
  DaemonConfig auth;
  ASSERT_EQ(
      LoadDaemonConfig("auth:\n  keys: /etc/lrfnet/keys\n  state_dir: /var/lib/lrfnet\n", auth),
      std::nullopt);
  EXPECT_EQ(auth.auth_keys_dir, "/etc/lrfnet/keys");
  EXPECT_EQ(auth.auth_state_dir, "/var/lib/lrfnet");
}

TEST(DaemonConfigTest, ErrorsNameTheKey) {
  struct Case {
    const char* yaml;
    const char* expected;
  };
  const Case cases[] = {
      {"listen: {address: 'nohostport'}", "listen.address"},
      {"listen: {address: '[::1]:99999'}", "listen.address"},
      {"record: {flush_interval_s: 0}", "record.flush_interval_s"},
      {"store: {max_age_s: -1}", "store."},
      {"store: {max_mb: 0}", "store.max_mb"},
      {"sensors: {silent_after_s: abc}", "sensors.silent_after_s"},
      {"sensors: {no_such_key: 1}", "no_such_key"},
      {"status: {interval_s: -2}", "status.interval_s"},
      {"listen: {receive_buffer_bytes: 10}", "receive_buffer_bytes"},
      {"zones: {list: 5}", "zones.list"},
      {"zones: {list: [{name: a, line: [[0, 0]]}]}", "zones.list[0]: zone 'a'"},
      {"zones: {list: [{name: a, line: [[0, 0], [1, x]]}]}", "zones.list[0].line"},
      {"zones: {list: [{name: a, circle: 1}]}", "zones.list[0].circle"},
      {"zones: {list: [{name: a}]}", "exactly one of polygon or line"},
      {"zones: {list: [{name: 'a b', line: [[0, 0], [1, 0]]}]}", "zones.list[0]"},
      {"zones: {list: [{name: a, line: [[0, 0], [1, 0]]}, {name: a, line: [[0, 0], [1, 0]]}]}",
       "twice"},
      {"zones: {hysteresis_m: -1}", "zones.hysteresis_m"},
      {"zones: {absent_hold_s: 4000}", "zones.absent_hold_s"},
      {"zones: {absent_hold_s: .nan}", "zones.absent_hold_s"},
      {"fusion: {ended_report_s: 0}", "ended_report_s"},
      {"fusion: {ended_report_s: 5}\nzones: {update_hz: 0.1, list: [{name: a, line: [[0, 0], "
       "[1, 0]]}]}",
       "fusion.ended_report_s"},
      {"mqtt: {broker: 'nope'}", "mqtt.broker"},
      {"mqtt: {site: 'a/b'}", "mqtt.site"},
      {"mqtt: {topic_prefix: 'a/#'}", "mqtt.topic_prefix"},
      {"mqtt: {qos: 2}", "mqtt.qos"},
      {"mqtt: {password: x}", "mqtt.password"},
      {"mqtt: {tls_ca_file: ca.pem}", "mqtt.tls"},
      {"mqtt: {objects_hz: 0}", "mqtt.objects_hz"},
      // A bad rate is named itself, not through fusion.ended_report_s's check against it.
      {"mqtt: {broker: 'localhost:1883', objects_hz: 0.05}", "mqtt.objects_hz"},
      {"mqtt: {reconnect_min_s: 50}", "mqtt.reconnect_min_s"},
      {"fusion: {method: kalman}", "fusion.method"},
      {"fusion: {centre_sigma_shape_fit_m: 0}", "fusion.centre_sigma_shape_fit_m"},
      {"fusion: {centre_lateral_fraction: 2}", "fusion.centre_lateral_fraction"},
      {"fusion: {max_coast_s: -1}", "fusion.max_coast_s"},
      {"fusion: {merge_sourceless_shadow_m: -0.1}", "fusion.merge_sourceless_shadow_m"},
      {"fusion: {binding_bonus: .nan}", "fusion.binding_bonus"},
      {"monitoring: {track_window_s: 0}", "monitoring.track_window_s"},
      {"monitoring: {background_min_yaw_deg: -1}", "monitoring.background_min_yaw_deg"},
      {"monitoring: {tracks_min_matches: 2}", "monitoring.tracks_min_matches"},
      {"monitoring: {correct_min_inliers: 2}", "monitoring.correct_min_inliers"},
  };
  for (const Case& c : cases) {
    DaemonConfig config;
    const auto error = LoadDaemonConfig(c.yaml, config);
    ASSERT_TRUE(error.has_value()) << c.yaml;
    EXPECT_NE(error->find(c.expected), std::string::npos) << c.yaml << " -> " << *error;
    EXPECT_EQ(error->find('\n'), std::string::npos) << *error;
  }
}

TEST(DaemonConfigTest, ZonesAndMqttLoadFromBlockYamlAndRoundTripThroughPrint) {
  DaemonConfig c;
  ASSERT_EQ(LoadDaemonConfig(R"(
zones:
  hysteresis_m: 0.25
  list:
    - name: door
      line: [[1, 0], [1, 2.5]]
    - {name: lobby, polygon: [[0, 0], [5, 0], [5, 4], [0, 4]]}
mqtt:
  broker: 127.0.0.1:1883
  site: lab-2
  username: daemon
  password: "p: w"
)",
                             c),
            std::nullopt);
  ASSERT_EQ(c.zones.size(), 2u);
  EXPECT_EQ(c.zones[0].name, "door");
  EXPECT_EQ(c.zones[0].kind, zones::ZoneKind::kLine);
  EXPECT_EQ(c.zones[0].points[1].y_m, 2.5);
  EXPECT_EQ(c.zones[1].kind, zones::ZoneKind::kPolygon);
  EXPECT_EQ(c.zones[1].points.size(), 4u);
  EXPECT_EQ(c.zone_options.hysteresis_m, 0.25);
  EXPECT_EQ(c.mqtt.site, "lab-2");

  const std::string printed = PrintDaemonConfig(c);
  EXPECT_NE(printed.find("list: [{name: door, line: [[1, 0], [1, 2.5]]}"), std::string::npos)
      << printed;
  DaemonConfig back;
  ASSERT_EQ(LoadDaemonConfig(printed, back), std::nullopt);
  ASSERT_EQ(back.zones.size(), 2u);
  EXPECT_EQ(back.zones[1].points[2].x_m, 5.0);
  EXPECT_EQ(back.mqtt.broker, "127.0.0.1:1883");
  EXPECT_EQ(back.mqtt.password, "p: w");
}

// A reload checks fusion.ended_report_s against the rates the zones and MQTT run with, not
// against rates the reloaded file names (those change only with a restart).
TEST(DaemonConfigTest, EndedReportIsCheckedAgainstTheRunningRates) {
  DaemonConfig running;
  ASSERT_EQ(
      LoadDaemonConfig("zones: {update_hz: 1, list: [{name: a, line: [[0, 0], [1, 0]]}]}", running),
      std::nullopt);
  DaemonConfig reloaded;
  ASSERT_EQ(LoadDaemonConfig("fusion: {ended_report_s: 1}\nzones: {update_hz: 10, list: [{name: "
                             "a, line: [[0, 0], [1, 0]]}]}",
                             reloaded),
            std::nullopt);  // fits the file's own rate
  const auto error = ValidateEndedReport(reloaded.fusion, running);
  ASSERT_TRUE(error.has_value());
  EXPECT_NE(error->find("zones.update_hz"), std::string::npos) << *error;
  reloaded.fusion.ended_report_s = 2.0;
  EXPECT_EQ(ValidateEndedReport(reloaded.fusion, running), std::nullopt);
}

TEST(DaemonConfigTest, AbsentIdsAreHeldForTheFusionsMaxCoastUnlessConfigured) {
  DaemonConfig c;
  ASSERT_EQ(LoadDaemonConfig("fusion: {max_coast_s: 2.5}", c), std::nullopt);
  EXPECT_LT(c.absent_hold_s, 0.0);
  EXPECT_EQ(c.zone_options.absent_hold_s, 2.5);
  EXPECT_FALSE(c.fusion.report_sourceless);  // ids may leave the fused tracks and come back
  DaemonConfig set;
  ASSERT_EQ(LoadDaemonConfig("fusion: {max_coast_s: 2.5}\nzones: {absent_hold_s: 0.7}", set),
            std::nullopt);
  EXPECT_EQ(set.zone_options.absent_hold_s, 0.7);
  DaemonConfig off;
  ASSERT_EQ(LoadDaemonConfig("zones: {absent_hold_s: 0}", off), std::nullopt);
  EXPECT_EQ(off.zone_options.absent_hold_s, 0.0);
}

}  // namespace
}  // namespace lrfnet::daemon
