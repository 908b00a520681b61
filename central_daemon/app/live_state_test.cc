#include "central_daemon/app/live_state.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>

namespace lrfnet::daemon {
namespace {

using nlohmann::json;

LiveState TwoSensors() {
  LiveState s;
  s.stamp_ns = 1'700'000'000'123'456'789;
  s.version = "0.1.0";
  s.calibration = {"calibrated", 1.0, "residual 0.031 m", "s1", 0.031};
  LiveSensor a;
  a.id = "s1";
  a.model = "lms111";
  a.placed = true;
  a.world_from_sensor = {1.5, -2.25, 0.785398};
  a.first_angle_rad = -2.356194;
  a.fov_rad = 4.712389;
  a.max_range_m = 20.0;
  a.status = "active";
  a.datagram_rate_hz = 25.0;
  a.loss = 0.0125;
  a.clock_sync = "synchronized";
  a.track_frames = 12345;
  a.background_xy = {{1.0f, 2.0f}, {3.25f, -4.5f}};
  a.calibration.calibrated = true;
  a.calibration.sigma_x_m = 0.0114;
  a.calibration.sigma_y_m = 0.0098;
  a.calibration.sigma_yaw_rad = 0.001;
  a.calibration.has_radial_bias = true;
  a.calibration.radial_bias_m = -0.0183;
  a.calibration.sigma_radial_bias_m = 0.0061;
  a.calibration.radial_bias_estimated = true;
  a.calibration.mount_looks_like_legs = true;
  a.calibration.flag = "s1: tracks look like legs";
  LiveSensor b;
  b.id = "s2";
  b.model = "tim561";
  b.status = "waiting";
  b.clock_sync = "unknown";
  s.sensors = {a, b};
  LiveTrack t;
  t.sensor_id = "s1";
  t.track_id = 3;
  t.state = "confirmed";
  t.x_m = 4.0;
  t.y_m = 5.0;
  t.vx_mps = 1.0;
  t.vy_mps = -0.5;
  t.fused_id = 7;
  LiveTrack u = t;
  u.sensor_id = "s2";
  u.track_id = 9;
  u.state = "tentative";
  u.fused_id.reset();
  s.tracks = {t, u};
  LiveFusedTrack f;
  f.id = 7;
  f.state = "confirmed";
  f.x_m = 4.01;
  f.y_m = 5.02;
  f.vx_mps = 1.0;
  f.cov_xx = 0.0004;
  f.cov_xy = -0.0001;
  f.cov_yy = 0.0009;
  f.sensors = {"s1", "s2"};
  s.fused = {f};
  return s;
}

json Parse(const std::string& text) {
  EXPECT_TRUE(json::accept(text)) << text;
  return json::parse(text, nullptr, false);
}

TEST(LiveStateJson, ParsesBackWithTheValues) {
  const json j = Parse(LiveStateJson(TwoSensors()));
  EXPECT_EQ(j["type"], "state");
  EXPECT_EQ(j["stamp_ns"].get<std::int64_t>(), 1'700'000'000'123'456'789);
  EXPECT_EQ(j["version"], "0.1.0");
  EXPECT_EQ(j["calibration"]["state"], "calibrated");
  EXPECT_DOUBLE_EQ(j["calibration"]["progress"].get<double>(), 1.0);
  EXPECT_EQ(j["calibration"]["message"], "residual 0.031 m");
  EXPECT_EQ(j["calibration"]["reference"], "s1");
  EXPECT_DOUBLE_EQ(j["calibration"]["track_residual_rms_m"].get<double>(), 0.031);

  ASSERT_EQ(j["sensors"].size(), 2u);
  const json& a = j["sensors"][0];
  EXPECT_EQ(a["id"], "s1");
  EXPECT_EQ(a["model"], "lms111");
  EXPECT_EQ(a["placed"], true);
  EXPECT_DOUBLE_EQ(a["x_m"].get<double>(), 1.5);
  EXPECT_DOUBLE_EQ(a["y_m"].get<double>(), -2.25);
  EXPECT_NEAR(a["yaw_rad"].get<double>(), 0.785398, 1e-9);
  EXPECT_NEAR(a["first_angle_rad"].get<double>(), -2.356194, 1e-9);
  EXPECT_NEAR(a["fov_rad"].get<double>(), 4.712389, 1e-9);
  EXPECT_DOUBLE_EQ(a["max_range_m"].get<double>(), 20.0);
  EXPECT_EQ(a["status"], "active");
  EXPECT_DOUBLE_EQ(a["datagram_rate_hz"].get<double>(), 25.0);
  EXPECT_DOUBLE_EQ(a["loss"].get<double>(), 0.0125);
  EXPECT_EQ(a["clock_sync"], "synchronized");
  EXPECT_EQ(a["track_frames"].get<std::uint64_t>(), 12345u);
  EXPECT_EQ(a["background"], json::parse("[[1,2],[3.25,-4.5]]"));
  EXPECT_EQ(j["sensors"][1]["placed"], false);
  EXPECT_EQ(j["sensors"][1]["status"], "waiting");
  EXPECT_TRUE(j["sensors"][1]["background"].empty());
  // What the calibration says of each sensor (null: none names it).
  const json& c = a["calibration"];
  EXPECT_DOUBLE_EQ(c["sigma_x_m"].get<double>(), 0.0114);
  EXPECT_DOUBLE_EQ(c["sigma_y_m"].get<double>(), 0.0098);
  EXPECT_NEAR(c["sigma_yaw_deg"].get<double>(), 0.0572958, 1e-7);
  EXPECT_DOUBLE_EQ(c["radial_bias"]["m"].get<double>(), -0.0183);
  EXPECT_DOUBLE_EQ(c["radial_bias"]["sigma_m"].get<double>(), 0.0061);
  EXPECT_EQ(c["radial_bias"]["estimated"], true);
  EXPECT_EQ(c["mount_looks_like_legs"], true);
  EXPECT_EQ(c["flag"], "s1: tracks look like legs");
  EXPECT_TRUE(j["sensors"][1]["calibration"].is_null());

  ASSERT_EQ(j["tracks"].size(), 2u);
  EXPECT_EQ(j["tracks"][0]["sensor"], "s1");
  EXPECT_EQ(j["tracks"][0]["id"], 3);
  EXPECT_EQ(j["tracks"][0]["state"], "confirmed");
  EXPECT_DOUBLE_EQ(j["tracks"][0]["x_m"].get<double>(), 4.0);
  EXPECT_DOUBLE_EQ(j["tracks"][0]["vy_mps"].get<double>(), -0.5);
  EXPECT_EQ(j["tracks"][0]["fused"], 7);
  EXPECT_TRUE(j["tracks"][1]["fused"].is_null());

  ASSERT_EQ(j["fused"].size(), 1u);
  const json& f = j["fused"][0];
  EXPECT_EQ(f["id"], 7);
  EXPECT_DOUBLE_EQ(f["x_m"].get<double>(), 4.01);
  EXPECT_DOUBLE_EQ(f["y_m"].get<double>(), 5.02);
  EXPECT_DOUBLE_EQ(f["cov_xx"].get<double>(), 0.0004);
  EXPECT_DOUBLE_EQ(f["cov_xy"].get<double>(), -0.0001);
  EXPECT_EQ(f["sensors"], json::parse(R"(["s1","s2"])"));
}

TEST(LiveStateJson, HiddenPeopleSayWhereAndWhenTheyWereLastSeen) {
  LiveState state;
  state.hidden.push_back({5, 1.2344, -2.5, 0.75, "s2"});
  const json j = Parse(LiveStateJson(state));
  ASSERT_EQ(j["hidden"].size(), 1u);
  EXPECT_EQ(j["hidden"][0]["id"], 5);
  EXPECT_DOUBLE_EQ(j["hidden"][0]["x_m"].get<double>(), 1.234);
  EXPECT_DOUBLE_EQ(j["hidden"][0]["y_m"].get<double>(), -2.5);
  EXPECT_DOUBLE_EQ(j["hidden"][0]["age_s"].get<double>(), 0.75);
  EXPECT_EQ(j["hidden"][0]["sensor"], "s2");
  EXPECT_TRUE(Parse(LiveStateJson(LiveState{}))["hidden"].empty());
}

TEST(LiveStateJson, EmptyStateIsAValidMessage) {
  const json j = Parse(LiveStateJson(LiveState{}));
  EXPECT_EQ(j["type"], "state");
  EXPECT_TRUE(j["sensors"].is_array() && j["sensors"].empty());
  EXPECT_TRUE(j["tracks"].is_array() && j["tracks"].empty());
  EXPECT_TRUE(j["fused"].is_array() && j["fused"].empty());
}

TEST(LiveStateJson, CoordinatesAreRoundedToTheMillimetre) {
  LiveState s = TwoSensors();
  s.tracks[0].x_m = 1.23456789;
  s.tracks[0].y_m = -0.0000004;  // rounds to zero, written without a minus sign
  s.sensors[0].background_xy = {{0.1f, 1.0f / 3.0f}};
  const std::string text = LiveStateJson(s);
  const json j = Parse(text);
  EXPECT_DOUBLE_EQ(j["tracks"][0]["x_m"].get<double>(), 1.235);
  EXPECT_EQ(j["sensors"][0]["background"], json::parse("[[0.1,0.333]]"));
  EXPECT_NE(text.find("\"x_m\":1.235,\"y_m\":0,"), std::string::npos) << text;

  // Leading zeros of the fraction, negative values, and values too large for a fixed point.
  s.tracks[0].x_m = -0.0072;
  s.tracks[0].y_m = 1e13;
  s.fused[0].x_m = -12.0405;
  const std::string more = LiveStateJson(s);
  const json k = Parse(more);
  EXPECT_NE(more.find("\"x_m\":-0.007,"), std::string::npos) << more;
  EXPECT_DOUBLE_EQ(k["tracks"][0]["y_m"].get<double>(), 1e13);
  EXPECT_DOUBLE_EQ(k["fused"][0]["x_m"].get<double>(), -12.041);
}

TEST(LiveStateJson, NonFiniteNumbersAreNull) {
  LiveState s = TwoSensors();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  s.calibration.progress = nan;
  s.sensors[0].world_from_sensor.x_m = inf;
  s.sensors[0].loss = -inf;
  s.sensors[0].background_xy = {{std::numeric_limits<float>::quiet_NaN(), 1.0f}};
  s.tracks[0].vx_mps = nan;
  s.fused[0].cov_yy = nan;
  const json j = Parse(LiveStateJson(s));
  EXPECT_TRUE(j["calibration"]["progress"].is_null());
  EXPECT_TRUE(j["sensors"][0]["x_m"].is_null());
  EXPECT_TRUE(j["sensors"][0]["loss"].is_null());
  EXPECT_TRUE(j["sensors"][0]["background"][0][0].is_null());
  EXPECT_DOUBLE_EQ(j["sensors"][0]["background"][0][1].get<double>(), 1.0);
  EXPECT_TRUE(j["tracks"][0]["vx_mps"].is_null());
  EXPECT_TRUE(j["fused"][0]["cov_yy"].is_null());
  // The neighbours of a null are untouched.
  EXPECT_DOUBLE_EQ(j["sensors"][0]["y_m"].get<double>(), -2.25);
}

TEST(LiveStateJson, HostileStringsAreEscaped) {
  LiveState s = TwoSensors();
  const std::string hostile = "a\"b\\c\n\t\x01</script><img src=x onerror=alert(1)>\"},{\"id\":\"x";
  s.sensors[0].id = hostile;
  s.tracks[0].sensor_id = hostile;
  s.fused[0].sensors = {hostile};
  s.calibration.message = std::string("nul\0byte", 8);
  const std::string text = LiveStateJson(s);
  const json j = Parse(text);
  EXPECT_EQ(j["sensors"][0]["id"], hostile);
  EXPECT_EQ(j["sensors"].size(), 2u);  // the id did not open a new object
  EXPECT_EQ(j["tracks"][0]["sensor"], hostile);
  EXPECT_EQ(j["fused"][0]["sensors"][0], hostile);
  EXPECT_EQ(j["calibration"]["message"].get<std::string>(), std::string("nul\0byte", 8));
  for (const char c : text) EXPECT_GE(static_cast<unsigned char>(c), 0x20) << "raw control byte";
}

TEST(LiveStateJson, InvalidUtf8BecomesReplacementCharacters) {
  LiveState s = TwoSensors();
  // Valid multi-byte text stays; a lone continuation byte, a truncated sequence, an overlong '/'
  // and an encoded surrogate are each replaced, so the message is valid UTF-8 for the browser.
  s.sensors[0].id =
      "gr\xC3\xBC\xC3\x9F \xE2\x82\xAC \xF0\x9F\x98\x80|\x80|\xE2\x82|\xC0\xAF|\xED\xA0\x80";
  const json j = Parse(LiveStateJson(s));
  const std::string r = "\xEF\xBF\xBD";
  EXPECT_EQ(j["sensors"][0]["id"].get<std::string>(),
            "gr\xC3\xBC\xC3\x9F \xE2\x82\xAC \xF0\x9F\x98\x80|" + r + "|" + r + r + "|" + r + r +
                "|" + r + r + r);
}

}  // namespace
}  // namespace lrfnet::daemon
