#include "central_daemon/app/mqtt_messages.h"

#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>

namespace lrfnet::daemon {
namespace {

using nlohmann::json;

TEST(MqttMessagesTest, EndedObjectsSayWhyAndWhichIdAMergedOneGoesOnAs) {
  const json j = json::parse(
      ObjectsEndedJson("lab", 4, 3'500'000'000,
                       {{7, "merged", 3, 3'460'000'000}, {9, "timed_out", 0, 3'500'000'000}}));
  EXPECT_EQ(j["type"], "objects_ended");
  EXPECT_EQ(j["site"], "lab");
  EXPECT_EQ(j["seq"], 4);
  EXPECT_EQ(j["stamp_ns"], 3'500'000'000);
  ASSERT_EQ(j["ended"].size(), 2u);
  EXPECT_EQ(j["ended"][0]["id"], 7);
  EXPECT_EQ(j["ended"][0]["reason"], "merged");
  EXPECT_EQ(j["ended"][0]["merged_into"], 3);
  EXPECT_EQ(j["ended"][0]["ended_ns"], 3'460'000'000);
  EXPECT_EQ(j["ended"][1]["reason"], "timed_out");
  EXPECT_TRUE(j["ended"][1]["merged_into"].is_null());
}

TEST(MqttMessagesTest, ObjectsCarryStateCovarianceSizeAgeSensorsAndPath) {
  MqttObject o;
  o.track.id = 7;
  o.track.state = fusion::FusedState::kConfirmed;
  o.track.first_ns = 1'000'000'000;
  o.track.x_m = 1.23456;
  o.track.y_m = std::nan("");
  o.track.vx_mps = 0.5;
  o.track.vy_mps = -0.25;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) o.track.covariance(r, c) = r * 4 + c;
  o.track.sources = {{"s1", 3, 0}, {"s1", 4, 0}, {"s2", 9, 0}};
  o.length_m = 0.5;
  o.width_m = 0.3;
  o.path = {{1.0, 2.0, -1.0}, {1.2, 2.0, 0.0}};
  MqttObject unsized;
  unsized.track.id = 8;
  const json j = json::parse(ObjectsJson("lab", 5, 3'500'000'000, {o, unsized}));
  EXPECT_EQ(j["type"], "objects");
  EXPECT_EQ(j["site"], "lab");
  EXPECT_EQ(j["seq"], 5);
  EXPECT_EQ(j["frame"], "world");
  const json& a = j["objects"][0];
  EXPECT_EQ(a["id"], 7);
  EXPECT_EQ(a["state"], "confirmed");
  EXPECT_DOUBLE_EQ(a["x_m"].get<double>(), 1.235);  // millimetres
  EXPECT_TRUE(a["y_m"].is_null());                  // not finite: null, still JSON
  ASSERT_EQ(a["covariance"].size(), 16u);
  EXPECT_EQ(a["covariance"][6], 6.0);  // row-major: (1, 2)
  EXPECT_EQ(a["size"]["length_m"], 0.5);
  EXPECT_DOUBLE_EQ(a["age_s"].get<double>(), 2.5);
  EXPECT_EQ(a["sensors"], json::parse(R"(["s1","s2"])"));
  EXPECT_EQ(a["path"], json::parse("[[1.0,2.0,-1.0],[1.2,2.0,0.0]]"));
  EXPECT_TRUE(j["objects"][1]["size"].is_null());
}

TEST(MqttMessagesTest, ZoneStatusHealthAndCalibration) {
  zones::ZoneState z;
  z.name = "door";
  z.kind = zones::ZoneKind::kLine;
  z.present_ids = {4, 9};
  z.present_dwell_s = {1.5, 0.25};
  z.inbound = 3;
  z.outbound = 1;
  z.dwells_completed = 4;
  z.dwell_total_s = 10.0;
  z.dwell_max_s = 5.0;
  const json zone = json::parse(ZoneJson("lab", 2, 7, z));
  EXPECT_EQ(zone["kind"], "line");
  EXPECT_EQ(zone["occupancy"], 2);
  EXPECT_EQ(zone["present"][1]["id"], 9);
  EXPECT_EQ(zone["present"][1]["dwell_s"], 0.25);
  EXPECT_EQ(zone["dwell"]["mean_s"], 2.5);
  EXPECT_EQ(zone["inbound"], 3);

  const json will = json::parse(StatusJson("lab", "offline", "lrfnetd 1", std::nullopt));
  EXPECT_FALSE(will.contains("stamp_ns"));
  EXPECT_EQ(json::parse(StatusJson("lab", "online", "lrfnetd 1", 5))["stamp_ns"], 5);

  SensorHealthReport h;
  h.sensor_id = "s\xff";  // not UTF-8: replaced, never an exception
  h.state = "silent";
  EXPECT_EQ(json::parse(SensorHealthJson("lab", 1, h))["state"], "silent");

  calib::CalibrationResult r;
  r.method = "quenzel";
  r.reference = "s1";
  calib::SensorPose p;
  p.id = "s2";
  p.calibrated = true;
  p.world_from_sensor = {1.0, 2.0, std::acos(-1.0) / 2};
  p.covariance(2, 2) = std::pow(std::acos(-1.0) / 180.0, 2);  // 1 degree
  r.sensors = {p};
  calib::SensorPose legs = p;
  legs.id = "s3";
  legs.radial_bias = calib::RadialBiasEstimate{-0.0183, 0.0061, true};
  legs.mount_looks_like_legs = true;
  legs.flag = "s3: tracks look like legs; set shape.mount: legs on its tracker";
  r.sensors = {p, legs};
  const json c = json::parse(CalibrationJson("lab", 9, r));
  EXPECT_EQ(c["sensors"][0]["yaw_deg"], 90.0);
  EXPECT_DOUBLE_EQ(c["sensors"][0]["sigma_yaw_deg"].get<double>(), 1.0);
  // Without a refinement's bias: the three keys null; no mount verdict, no flag.
  EXPECT_TRUE(c["sensors"][0]["radial_bias_m"].is_null());
  EXPECT_TRUE(c["sensors"][0]["sigma_radial_bias_m"].is_null());
  EXPECT_TRUE(c["sensors"][0]["radial_bias_estimated"].is_null());
  EXPECT_EQ(c["sensors"][0]["mount_looks_like_legs"], false);
  EXPECT_EQ(c["sensors"][0]["flag"], "");
  EXPECT_DOUBLE_EQ(c["sensors"][1]["radial_bias_m"].get<double>(), -0.0183);
  EXPECT_DOUBLE_EQ(c["sensors"][1]["sigma_radial_bias_m"].get<double>(), 0.0061);
  EXPECT_EQ(c["sensors"][1]["radial_bias_estimated"], true);
  EXPECT_EQ(c["sensors"][1]["mount_looks_like_legs"], true);
  EXPECT_EQ(c["sensors"][1]["flag"], legs.flag);
}

}  // namespace
}  // namespace lrfnet::daemon
