#include <gtest/gtest.h>

#include "lrfnet.pb.h"

namespace lrfnet::proto {
namespace {

// A full track frame of a crowded scan must fit the payload budget when split into parts of this
// many tracks (the uplink's part size): 1400 bytes per datagram less the widest authenticated
// envelope (common/datagram_auth.h: 24 + 32 + 16 bytes).
constexpr int kTracksPerPart = 13;
constexpr std::size_t kMaxPayloadBytes = 1400 - 72;

TEST(ProtoTest, DatagramRoundTripsAllFields) {
  Datagram d;
  d.set_version(PROTOCOL_VERSION_1);
  d.set_sensor_id("hall-north.lms511");
  d.set_sequence(123456789);
  d.set_sent_ns(1'700'000'000'123'456'789);
  d.set_session_id(0xDEADBEEFCAFEull);
  TrackFrame* f = d.mutable_track_frame();
  f->set_scan_start_ns(1'700'000'000'100'000'000);
  f->set_scan_period_s(0.04);
  f->set_part_count(1);
  Track* t = f->add_tracks();
  t->set_track_id(7);
  t->set_kind(MEASUREMENT_KIND_ELLIPSE);
  t->set_x_m(3.25f);
  for (int i = 0; i < 10; ++i) t->add_covariance(0.01f * static_cast<float>(i + 1));
  const std::string bytes = d.SerializeAsString();
  Datagram back;
  ASSERT_TRUE(back.ParseFromString(bytes));
  EXPECT_EQ(back.sensor_id(), "hall-north.lms511");
  EXPECT_EQ(back.sequence(), 123456789u);
  EXPECT_EQ(back.payload_case(), Datagram::kTrackFrame);
  EXPECT_EQ(back.track_frame().tracks(0).covariance_size(), 10);
  EXPECT_FLOAT_EQ(back.track_frame().tracks(0).x_m(), 3.25f);
}

TEST(ProtoTest, WorstCaseTrackPartFitsOneDatagram) {
  Datagram d;
  d.set_version(PROTOCOL_VERSION_1);
  d.set_sensor_id(std::string(32, 's'));
  d.set_sequence(~0ull);
  d.set_sent_ns(-1);
  d.set_session_id(~0ull);
  TrackFrame* f = d.mutable_track_frame();
  f->set_scan_start_ns(-1);
  f->set_scan_period_s(1.0 / 7.0);
  f->set_scan_counter(~0u);
  f->set_part(~0u);
  f->set_part_count(~0u);
  for (int k = 0; k < kTracksPerPart; ++k) {
    Track* t = f->add_tracks();
    t->set_track_id(~0u);
    t->set_state(TRACK_STATE_COASTING);
    t->set_kind(MEASUREMENT_KIND_ELLIPSE);
    t->set_x_m(-123.456f);
    t->set_y_m(-123.456f);
    t->set_vx_mps(-1.5f);
    t->set_vy_mps(-1.5f);
    for (int i = 0; i < 10; ++i) t->add_covariance(1e-3f);
    t->set_age_scans(~0u);
    t->set_points(~0u);
    t->set_ellipse_yaw_rad(-3.0f);
  }
  EXPECT_LE(d.ByteSizeLong(), kMaxPayloadBytes);
}

}  // namespace
}  // namespace lrfnet::proto
