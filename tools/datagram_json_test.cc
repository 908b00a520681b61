#include "tools/datagram_json.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <deque>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "lrfnet.pb.h"

namespace lrfnet::tools {
namespace {

using nlohmann::json;

std::vector<std::uint8_t> Bytes(const proto::Datagram& d) {
  const std::string s = d.SerializeAsString();
  return {s.begin(), s.end()};
}

proto::Datagram Header(const std::string& sensor_id, std::uint64_t sequence) {
  proto::Datagram d;
  d.set_version(proto::PROTOCOL_VERSION_1);
  d.set_sensor_id(sensor_id);
  d.set_sequence(sequence);
  d.set_sent_ns(1'700'000'000'123'456'789);
  d.set_session_id(0xfedcba9876543210ULL);
  return d;
}

// The line as a user reads it, parsed back; also checks it is one line in nlohmann's key order.
json Line(const proto::Datagram& d, common::UtcNs receive_ns = 1'700'000'000'200'000'000,
          const std::string& source = "10.0.0.7:40001") {
  const std::string line = DatagramJsonLine(receive_ns, source, Bytes(d));
  EXPECT_EQ(line.find('\n'), std::string::npos) << line;
  const json j = json::parse(line);
  EXPECT_EQ(j.dump(), line) << "keys not sorted or not compact";
  return j;
}

TEST(DatagramJsonTest, TrackFrameHasEveryFieldWithProtoNamesAndEnumNames) {
  proto::Datagram d = Header("s1", 42);
  proto::TrackFrame* f = d.mutable_track_frame();
  f->set_scan_start_ns(1'700'000'000'100'000'000);
  f->set_scan_period_s(0.04);
  f->set_scan_counter(65535);
  f->set_part(1);
  f->set_part_count(2);
  proto::Track* t = f->add_tracks();
  t->set_track_id(7);
  t->set_state(proto::TRACK_STATE_CONFIRMED);
  t->set_kind(proto::MEASUREMENT_KIND_ELLIPSE);
  t->set_x_m(1.25f);
  t->set_y_m(-0.1f);
  t->set_vx_mps(0.5f);
  t->set_vy_mps(0.0f);
  for (const float c : {0.01f, 0.02f, 0.03f, 0.04f, 0.05f, 0.06f, 0.07f, 0.08f, 0.09f, 0.1f})
    t->add_covariance(c);
  t->set_age_scans(12);
  t->set_points(33);
  t->set_ellipse_yaw_rad(0.3f);
  t->set_shape(proto::OBJECT_SHAPE_TORSO);
  t->set_size_major_m(0.24f);
  t->set_size_minor_m(0.13f);
  t->set_size_sigma_m(0.02f);
  proto::Track* coasting = f->add_tracks();
  coasting->set_track_id(8);
  coasting->set_state(proto::TRACK_STATE_COASTING);
  coasting->set_kind(proto::MEASUREMENT_KIND_CENTER_OF_MASS);

  const json j = Line(d);
  EXPECT_EQ(j["receive_ns"], 1'700'000'000'200'000'000);
  EXPECT_EQ(j["source"], "10.0.0.7:40001");
  EXPECT_EQ(j["size"], Bytes(d).size());
  EXPECT_EQ(j["version"], "PROTOCOL_VERSION_1");
  EXPECT_EQ(j["sensor_id"], "s1");
  EXPECT_EQ(j["sequence"], 42u);
  EXPECT_EQ(j["sent_ns"], 1'700'000'000'123'456'789);
  EXPECT_EQ(j["session_id"].get<std::uint64_t>(), 0xfedcba9876543210ULL);  // exact, not a double
  EXPECT_EQ(j["kind"], "track_frame");
  EXPECT_FALSE(j.contains("error"));

  const json& frame = j["track_frame"];
  EXPECT_EQ(frame["scan_start_ns"], 1'700'000'000'100'000'000);
  EXPECT_EQ(frame["scan_period_s"], 0.04);
  EXPECT_EQ(frame["scan_counter"], 65535);
  EXPECT_EQ(frame["part"], 1);
  EXPECT_EQ(frame["part_count"], 2);
  ASSERT_EQ(frame["tracks"].size(), 2u);
  const json& t0 = frame["tracks"][0];
  EXPECT_EQ(t0.size(), 15u) << t0.dump();
  EXPECT_EQ(t0["track_id"], 7);
  EXPECT_EQ(t0["state"], "TRACK_STATE_CONFIRMED");
  EXPECT_EQ(t0["kind"], "MEASUREMENT_KIND_ELLIPSE");
  EXPECT_EQ(t0["x_m"], 1.25);
  // Floats print with float precision: -0.1f as -0.1, not -0.10000000149011612.
  EXPECT_EQ(t0["y_m"].dump(), "-0.1");
  EXPECT_EQ(t0["vx_mps"], 0.5);
  EXPECT_EQ(t0["vy_mps"], 0.0);
  ASSERT_EQ(t0["covariance"].size(), 10u);
  EXPECT_EQ(t0["covariance"][0].dump(), "0.01");
  EXPECT_EQ(t0["covariance"][9].dump(), "0.1");
  EXPECT_EQ(t0["age_scans"], 12);
  EXPECT_EQ(t0["points"], 33);
  EXPECT_EQ(t0["ellipse_yaw_rad"].dump(), "0.3");
  EXPECT_EQ(t0["shape"], "OBJECT_SHAPE_TORSO");
  EXPECT_EQ(t0["size_major_m"].dump(), "0.24");
  EXPECT_EQ(t0["size_minor_m"].dump(), "0.13");
  EXPECT_EQ(t0["size_sigma_m"].dump(), "0.02");
  const json& t1 = frame["tracks"][1];
  EXPECT_EQ(t1["state"], "TRACK_STATE_COASTING");
  EXPECT_EQ(t1["kind"], "MEASUREMENT_KIND_CENTER_OF_MASS");
  EXPECT_EQ(t1["points"], 0);  // defaults are printed too
  EXPECT_EQ(t1["shape"], "OBJECT_SHAPE_UNSPECIFIED");  // an old tracker's: no shape state
  EXPECT_EQ(t1["size_major_m"], 0.0);
  EXPECT_TRUE(t1["covariance"].is_array());
}

TEST(DatagramJsonTest, BackgroundHasItsScalarsAndRanges) {
  proto::Datagram d = Header("bg", 3);
  proto::BackgroundSnapshot* b = d.mutable_background();
  b->set_snapshot_id(5);
  b->set_learned_until_ns(-1);
  b->set_first_angle_rad(-2.35619449);
  b->set_angle_step_rad(0.0043633);
  b->set_beam_count(1081);
  b->set_part(2);
  b->set_part_count(3);
  b->set_first_beam(600);
  for (std::uint32_t r : {0u, 1500u, 4294967295u}) b->add_ranges_mm(r);
  const json j = Line(d);
  EXPECT_EQ(j["kind"], "background");
  const json& bg = j["background"];
  EXPECT_EQ(bg.size(), 9u) << bg.dump();
  EXPECT_EQ(bg["snapshot_id"], 5);
  EXPECT_EQ(bg["learned_until_ns"], -1);
  EXPECT_EQ(bg["first_angle_rad"], -2.35619449);
  EXPECT_EQ(bg["angle_step_rad"], 0.0043633);
  EXPECT_EQ(bg["beam_count"], 1081);
  EXPECT_EQ(bg["part"], 2);
  EXPECT_EQ(bg["part_count"], 3);
  EXPECT_EQ(bg["first_beam"], 600);
  EXPECT_EQ(bg["ranges_mm"], json::array({0, 1500, 4294967295u}));
  EXPECT_FALSE(j.contains("track_frame"));
}

TEST(DatagramJsonTest, HealthHasEveryCounterExactly) {
  proto::Datagram d = Header("h", 9);
  proto::Health* h = d.mutable_health();
  h->set_scans(std::numeric_limits<std::uint64_t>::max());
  h->set_bad_frames(1);
  h->set_decode_errors(2);
  h->set_reconnects(3);
  h->set_dropped_tracks(4);
  h->set_datagrams_sent(5);
  h->set_send_errors(6);
  h->set_scan_cpu_us_mean(120.5f);
  h->set_scan_cpu_us_max(900.25f);
  h->set_clock_sync(proto::CLOCK_SYNC_REPLAY);
  h->set_clock_error_estimate_s(0.002f);
  h->set_tick_offset_s(1234.5);
  h->set_tick_drift_ppm(-15.0);
  h->set_device_restarts(1);
  const json j = Line(d);
  EXPECT_EQ(j["kind"], "health");
  const json& health = j["health"];
  EXPECT_EQ(health.size(), 14u) << health.dump();
  EXPECT_EQ(health["scans"].get<std::uint64_t>(), std::numeric_limits<std::uint64_t>::max());
  EXPECT_EQ(health["bad_frames"], 1);
  EXPECT_EQ(health["decode_errors"], 2);
  EXPECT_EQ(health["reconnects"], 3);
  EXPECT_EQ(health["dropped_tracks"], 4);
  EXPECT_EQ(health["datagrams_sent"], 5);
  EXPECT_EQ(health["send_errors"], 6);
  EXPECT_EQ(health["scan_cpu_us_mean"], 120.5);
  EXPECT_EQ(health["scan_cpu_us_max"], 900.25);
  EXPECT_EQ(health["clock_sync"], "CLOCK_SYNC_REPLAY");
  EXPECT_EQ(health["clock_error_estimate_s"].dump(), "0.002");
  EXPECT_EQ(health["tick_offset_s"], 1234.5);
  EXPECT_EQ(health["tick_drift_ppm"], -15.0);
  EXPECT_EQ(health["device_restarts"], 1);
}

TEST(DatagramJsonTest, SensorInfoAndRequestHaveAllFields) {
  proto::Datagram d = Header("info", 0);
  proto::SensorInfo* s = d.mutable_sensor_info();
  s->set_model("LMS511");
  s->set_serial("12345678");
  s->set_firmware("V1.2");
  s->set_first_angle_rad(-1.5);
  s->set_angle_step_rad(0.25);
  s->set_beam_count(1141);
  s->set_fov_rad(3.0);
  s->set_scan_frequency_hz(25.0);
  s->set_max_range_m(80.0);
  s->set_tracker_version("lrfnet-tracker 0.1.0");
  s->set_kind(proto::MEASUREMENT_KIND_SHAPE_FIT);
  s->set_mount(proto::MOUNT_HEIGHT_LEGS);
  s->set_accel_psd_m2ps3(0.5);
  s->set_max_speed_mps(2.5);
  const json info = Line(d);
  EXPECT_EQ(info["kind"], "sensor_info");
  EXPECT_EQ(info["sequence"], 0);
  const json expected_info = {{"model", "LMS511"},
                              {"serial", "12345678"},
                              {"firmware", "V1.2"},
                              {"first_angle_rad", -1.5},
                              {"angle_step_rad", 0.25},
                              {"beam_count", 1141},
                              {"fov_rad", 3.0},
                              {"scan_frequency_hz", 25.0},
                              {"max_range_m", 80.0},
                              {"tracker_version", "lrfnet-tracker 0.1.0"},
                              {"kind", "MEASUREMENT_KIND_SHAPE_FIT"},
                              {"mount", "MOUNT_HEIGHT_LEGS"},
                              {"accel_psd_m2ps3", 0.5},
                              {"max_speed_mps", 2.5}};
  EXPECT_EQ(info["sensor_info"], expected_info);

  proto::Datagram r = Header("lrfnetd", 1);
  r.mutable_request()->set_send_background(true);
  const json request = Line(r);
  EXPECT_EQ(request["kind"], "request");
  EXPECT_EQ(request["request"], (json{{"send_sensor_info", false}, {"send_background", true}}));
}

TEST(DatagramJsonTest, NoPayloadIsKindNone) {
  const json j = Line(Header("s", 1));
  EXPECT_EQ(j["kind"], "none");
  for (const char* payload : {"track_frame", "background", "health", "sensor_info", "request"})
    EXPECT_FALSE(j.contains(payload)) << payload;
}

TEST(DatagramJsonTest, UnnamedEnumValuesPrintAsNumbers) {
  proto::Datagram d = Header("s", 1);
  d.set_version(static_cast<proto::ProtocolVersion>(2));
  proto::Track* t = d.mutable_track_frame()->add_tracks();
  t->set_state(static_cast<proto::TrackState>(9));
  t->set_kind(proto::MEASUREMENT_KIND_UNSPECIFIED);
  const json j = Line(d);
  EXPECT_EQ(j["version"], 2);
  EXPECT_EQ(j["track_frame"]["tracks"][0]["state"], 9);
  EXPECT_EQ(j["track_frame"]["tracks"][0]["kind"], "MEASUREMENT_KIND_UNSPECIFIED");
}

TEST(DatagramJsonTest, NonFiniteNumbersAreNull) {
  proto::Datagram d = Header("s", 1);
  proto::TrackFrame* f = d.mutable_track_frame();
  f->set_scan_period_s(std::numeric_limits<double>::infinity());
  proto::Track* t = f->add_tracks();
  t->set_x_m(std::numeric_limits<float>::quiet_NaN());
  t->set_y_m(-std::numeric_limits<float>::infinity());
  t->add_covariance(std::numeric_limits<float>::quiet_NaN());
  t->add_covariance(2.0f);
  const std::string line = DatagramJsonLine(5, "x", Bytes(d));
  EXPECT_EQ(line.find("NaN"), std::string::npos) << line;
  EXPECT_EQ(line.find("nan"), std::string::npos) << line;
  const json j = json::parse(line);  // would throw on a bare NaN token
  EXPECT_TRUE(j["track_frame"]["scan_period_s"].is_null());
  EXPECT_TRUE(j["track_frame"]["tracks"][0]["x_m"].is_null());
  EXPECT_TRUE(j["track_frame"]["tracks"][0]["y_m"].is_null());
  EXPECT_EQ(j["track_frame"]["tracks"][0]["covariance"], json::array({nullptr, 2.0}));
}

TEST(DatagramJsonTest, BytesThatDoNotParseGiveTheErrorLine) {
  // A field tag with wire type 7 (invalid), and a length-delimited field running past the end.
  for (const std::vector<std::uint8_t>& bytes :
       {std::vector<std::uint8_t>{0x0f, 0x01}, std::vector<std::uint8_t>{0x12, 0x40, 'a', 'b'},
        std::vector<std::uint8_t>(100, 0xff)}) {
    const json j = json::parse(DatagramJsonLine(-7, "[::1]:5800", bytes));
    const json expected = {{"error", "not a lrfnet datagram"},
                           {"receive_ns", -7},
                           {"size", bytes.size()},
                           {"source", "[::1]:5800"}};
    EXPECT_EQ(j, expected);
  }
}

TEST(DatagramJsonTest, InvalidUtf8NeverThrows) {
  const std::string bad_source = "tracker:\xff\xfe";
  std::string line;
  ASSERT_NO_THROW(line = DatagramJsonLine(1, bad_source, std::vector<std::uint8_t>{0x0f}));
  EXPECT_TRUE(json::accept(line)) << line;
}

// A DatagramSource over a list, ending in kEnd or kError.
class FakeSource : public daemon::DatagramSource {
 public:
  FakeSource(std::deque<daemon::ReceivedDatagram> datagrams, std::string error)
      : datagrams_(std::move(datagrams)), final_error_(std::move(error)) {}
  daemon::SourceStatus Next(daemon::ReceivedDatagram* d) override {
    if (datagrams_.empty()) {
      error_ = final_error_;
      return error_.empty() ? daemon::SourceStatus::kEnd : daemon::SourceStatus::kError;
    }
    *d = std::move(datagrams_.front());
    datagrams_.pop_front();
    ++counters_.datagrams;
    return daemon::SourceStatus::kDatagram;
  }
  daemon::DatagramFileKind kind() const override { return daemon::DatagramFileKind::kRecording; }
  const daemon::DatagramSourceCounters& counters() const override { return counters_; }
  const std::string& error() const override { return error_; }
  std::uint32_t format_version() const override { return 1; }
  common::UtcNs created_ns() const override { return 99; }
  const std::string& writer() const override { return writer_; }

 private:
  std::deque<daemon::ReceivedDatagram> datagrams_;
  std::string final_error_;
  std::string error_;
  std::string writer_ = "lrfnetd 0.1.0";
  daemon::DatagramSourceCounters counters_{.datagrams = 0, .files = 1};
};

daemon::ReceivedDatagram Received(common::UtcNs t, const std::vector<std::uint8_t>& bytes) {
  return {t, "10.0.0.1:5000", bytes};
}

std::deque<daemon::ReceivedDatagram> MixedFile() {
  proto::Datagram frame = Header("a", 0);
  frame.mutable_track_frame();
  proto::Datagram health = Header("a", 1);
  health.mutable_health();
  proto::Datagram other = Header("b", 0);
  other.mutable_track_frame();
  return {Received(100, Bytes(frame)), Received(300, Bytes(health)),
          Received(200, Bytes(other)),  // receive time steps back
          Received(400, {0x0f, 0x00})};
}

TEST(DatagramJsonTest, DumpWritesOneLinePerDatagramAndSummarises) {
  FakeSource source(MixedFile(), "");
  std::ostringstream out;
  DatagramSummary summary;
  std::string error;
  ASSERT_TRUE(DumpDatagrams(source, &out, &summary, &error)) << error;
  std::istringstream lines(out.str());
  std::vector<json> parsed;
  for (std::string line; std::getline(lines, line);) parsed.push_back(json::parse(line));
  ASSERT_EQ(parsed.size(), 4u);
  EXPECT_EQ(parsed[0]["kind"], "track_frame");
  EXPECT_EQ(parsed[1]["kind"], "health");
  EXPECT_EQ(parsed[2]["sensor_id"], "b");
  EXPECT_EQ(parsed[3]["error"], "not a lrfnet datagram");

  const json s = json::parse(DatagramSummaryJson(summary, source));
  EXPECT_EQ(s["datagrams"], 4);
  EXPECT_EQ(s["parse_errors"], 1);
  EXPECT_EQ(s["first_receive_ns"], 100);
  EXPECT_EQ(s["last_receive_ns"], 400);
  EXPECT_EQ(s["receive_time_steps_back"], 1);
  EXPECT_EQ(s["kinds"], (json{{"health", 1}, {"track_frame", 2}}));
  EXPECT_EQ(s["sensors"],
            (json{{"a", {{"health", 1}, {"track_frame", 1}}}, {"b", {{"track_frame", 1}}}}));
  EXPECT_EQ(s["file"]["kind"], "recording");
  EXPECT_EQ(s["file"]["datagrams"], 4);
  EXPECT_EQ(s["file"]["files"], 1);
  EXPECT_EQ(s["file"]["writer"], "lrfnetd 0.1.0");
  EXPECT_EQ(s["file"]["created_ns"], 99);
  EXPECT_FALSE(s.contains("error"));
}

TEST(DatagramJsonTest, DumpOfADamagedFileKeepsTheLinesBeforeTheError) {
  FakeSource source(MixedFile(), "rec: torn entry at byte 512");
  std::ostringstream out;
  DatagramSummary summary;
  std::string error;
  EXPECT_FALSE(DumpDatagrams(source, &out, &summary, &error));
  EXPECT_EQ(error, "rec: torn entry at byte 512");
  const std::string text = out.str();
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 4);
  const json s = json::parse(DatagramSummaryJson(summary, source));
  EXPECT_EQ(s["error"], "rec: torn entry at byte 512");
  EXPECT_EQ(s["datagrams"], 4);
}

TEST(DatagramJsonTest, EmptyFileSummaryHasNullTimes) {
  FakeSource source({}, "");
  DatagramSummary summary;
  std::string error;
  ASSERT_TRUE(DumpDatagrams(source, nullptr, &summary, &error));
  const json s = json::parse(DatagramSummaryJson(summary, source));
  EXPECT_EQ(s["datagrams"], 0);
  EXPECT_TRUE(s["first_receive_ns"].is_null());
  EXPECT_TRUE(s["last_receive_ns"].is_null());
  EXPECT_EQ(s["sensors"], json::object());
}

TEST(DatagramJsonTest, SummaryBoundsTheNumberOfSensors) {
  DatagramSummary summary;
  for (std::size_t i = 0; i < kMaxSummarySensors + 10; ++i) {
    proto::Datagram d = Header("s" + std::to_string(i), 0);
    d.mutable_health();
    summary.Add(static_cast<common::UtcNs>(i), Bytes(d));
  }
  EXPECT_EQ(summary.by_sensor_kind.size(), kMaxSummarySensors);
  EXPECT_EQ(summary.sensors_over_limit, 10u);
  EXPECT_EQ(summary.by_kind["health"], kMaxSummarySensors + 10);
}

}  // namespace
}  // namespace lrfnet::tools
