#include "central_daemon/ingest/datagram_decoder.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "central_daemon/ingest/ingest_test_util.h"

namespace lrfnet::daemon {
namespace {

using testing::Bytes;
using testing::FakeTracker;
using testing::kMs;
using testing::kS;
using testing::kT0;
using testing::Serialize;
using testing::View;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr common::UtcNs kSent = kT0 - 2 * kMs;

proto::Datagram Parse(const Bytes& bytes) {
  proto::Datagram d;
  EXPECT_TRUE(d.ParseFromArray(bytes.data(), static_cast<int>(bytes.size())));
  return d;
}

// One valid datagram of each kind, made by the tracker's encoder.
struct Bases {
  Bases() {
    FakeTracker tracker("gate-3", 0xABCDEF0123456789ull);
    track_frame = Parse(tracker.Tracks(3, kSent).at(0));
    background = Parse(tracker.Background(300, kSent).at(0));
    health = Parse(tracker.Health(kSent));
    info = Parse(tracker.Info(kSent));
  }
  proto::Datagram track_frame, background, health, info;
};

TEST(SensorIdTest, OnlyTheDocumentedAlphabetAndLength) {
  EXPECT_TRUE(IsValidSensorId("a"));
  EXPECT_TRUE(IsValidSensorId("hall-north.lms511_2"));
  EXPECT_TRUE(IsValidSensorId(std::string(32, 'Z')));
  EXPECT_FALSE(IsValidSensorId(""));
  EXPECT_FALSE(IsValidSensorId(std::string(33, 'Z')));
  EXPECT_FALSE(IsValidSensorId("gate 3"));
  EXPECT_FALSE(IsValidSensorId("gate/3"));
  EXPECT_FALSE(IsValidSensorId(std::string("ga\0e", 4)));
  EXPECT_FALSE(IsValidSensorId("gäte"));
}

std::vector<float> Upper(const Eigen::Matrix4d& m) {
  std::vector<float> v;
  for (int r = 0; r < 4; ++r) {
    for (int c = r; c < 4; ++c) v.push_back(static_cast<float>(m(r, c)));
  }
  return v;
}

TEST(CovarianceTest, PositiveDefiniteAndSemiDefiniteAreAccepted) {
  EXPECT_TRUE(IsCovariancePsd(Upper(Eigen::Matrix4d::Identity())));
  EXPECT_TRUE(IsCovariancePsd(Upper(Eigen::Matrix4d::Zero())));
  EXPECT_TRUE(IsCovariancePsd(Upper(testing::MakeTrack(5).covariance)));
  // Position and velocity perfectly correlated (rank 2): semi-definite.
  Eigen::Matrix<double, 4, 2> b;
  b << 1e-2, 0, 0, 3e-3, 2e-2, 0, 0, 6e-3;
  EXPECT_TRUE(IsCovariancePsd(Upper(b * b.transpose())));
  // Units far apart (mm^2 against (m/s)^2) and tiny correlation left: still fine after rounding.
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.diagonal() << 1e-6, 4e-6, 25.0, 36.0;
  m(0, 2) = m(2, 0) = 0.999999 * std::sqrt(1e-6 * 25.0);
  EXPECT_TRUE(IsCovariancePsd(Upper(m)));
}

TEST(CovarianceTest, BrokenMatricesAreRefused) {
  std::vector<float> v = Upper(Eigen::Matrix4d::Identity());
  v[4] = -1e-3f;  // yy < 0
  EXPECT_FALSE(IsCovariancePsd(v));
  v = Upper(Eigen::Matrix4d::Identity());
  v[1] = 1.01f;  // |xy| > sqrt(xx yy)
  EXPECT_FALSE(IsCovariancePsd(v));
  // A zero variance with a non-zero covariance.
  Eigen::Matrix4d z = Eigen::Matrix4d::Identity();
  z(0, 0) = 0.0;
  z(0, 1) = z(1, 0) = 1e-9;
  EXPECT_FALSE(IsCovariancePsd(Upper(z)));
  // Every pair's correlation is valid (0.9) but the three together are not: eigenvalue -0.8.
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m(0, 1) = m(1, 0) = 0.9;
  m(0, 2) = m(2, 0) = 0.9;
  m(1, 2) = m(2, 1) = -0.9;
  EXPECT_FALSE(IsCovariancePsd(Upper(m)));
  // Slightly indefinite, beyond rounding: eigenvalue -1e-3.
  Eigen::Matrix4d s = Eigen::Matrix4d::Identity();
  s(0, 1) = s(1, 0) = 1.0005;
  EXPECT_FALSE(IsCovariancePsd(Upper(s)));
  v = Upper(Eigen::Matrix4d::Identity());
  v.pop_back();
  EXPECT_FALSE(IsCovariancePsd(v));
  v = Upper(Eigen::Matrix4d::Identity());
  v[9] = kNaN;
  EXPECT_FALSE(IsCovariancePsd(v));
}

TEST(DatagramDecoderTest, EncoderDatagramsOfEveryKindAreValid) {
  FakeTracker tracker("hall-north.lms511", 42);
  std::vector<Bytes> all = tracker.Tracks(40, kSent);
  const std::vector<Bytes> background = tracker.Background(4561, kSent);
  all.insert(all.end(), background.begin(), background.end());
  all.push_back(tracker.Health(kSent));
  all.push_back(tracker.Info(kSent));
  all.push_back(tracker.Tracks(0, kSent).at(0));
  DatagramDecoder decoder({});
  for (std::size_t i = 0; i < all.size(); ++i) {
    const DecodeStatus s = decoder.Decode(View(all[i]), kT0);
    EXPECT_TRUE(s.ok()) << i << ": " << ToString(s.reason) << " " << decoder.detail();
    EXPECT_TRUE(s.attributed);
    EXPECT_EQ(decoder.datagram().sequence(), i);
    EXPECT_EQ(decoder.datagram().sensor_id(), "hall-north.lms511");
  }
}

struct HostileCase {
  std::string name;
  const proto::Datagram Bases::*base;
  std::function<void(proto::Datagram&)> mutate;
  RejectReason expected;
  bool attributed = true;
  ValidationOptions options = {};
};

std::vector<HostileCase> HostileCases() {
  using D = proto::Datagram;
  const auto track = [](D& d) -> proto::Track& {
    return *d.mutable_track_frame()->mutable_tracks(1);
  };
  const auto bg = [](D& d) { return d.mutable_background(); };
  return {
      {"version_unspecified", &Bases::track_frame,
       [](D& d) { d.set_version(proto::PROTOCOL_VERSION_UNSPECIFIED); }, RejectReason::kVersion},
      {"version_2", &Bases::health,
       [](D& d) { d.set_version(static_cast<proto::ProtocolVersion>(2)); }, RejectReason::kVersion},
      {"version_2_bad_id", &Bases::health,
       [](D& d) {
         d.set_version(static_cast<proto::ProtocolVersion>(2));
         d.set_sensor_id("a b");
       },
       RejectReason::kVersion, false},
      {"sensor_id_empty", &Bases::track_frame, [](D& d) { d.clear_sensor_id(); },
       RejectReason::kSensorId, false},
      {"sensor_id_long", &Bases::track_frame, [](D& d) { d.set_sensor_id(std::string(33, 'x')); },
       RejectReason::kSensorId, false},
      {"sensor_id_space", &Bases::info, [](D& d) { d.set_sensor_id("gate 3"); },
       RejectReason::kSensorId, false},
      {"request", &Bases::health, [](D& d) { d.mutable_request()->set_send_background(true); },
       RejectReason::kUnexpectedKind},
      {"no_payload", &Bases::health, [](D& d) { d.clear_payload(); }, RejectReason::kUnknownKind},
      {"sent_before_2000", &Bases::health, [](D& d) { d.set_sent_ns(946684799LL * 1000000000LL); },
       RejectReason::kTimestamp},
      {"sent_negative", &Bases::info,
       [](D& d) { d.set_sent_ns(std::numeric_limits<std::int64_t>::min()); },
       RejectReason::kTimestamp},
      {"sent_in_the_future", &Bases::health, [](D& d) { d.set_sent_ns(kT0 + 301 * kS); },
       RejectReason::kTimestamp},
      {"sent_max", &Bases::health,
       [](D& d) { d.set_sent_ns(std::numeric_limits<std::int64_t>::max()); },
       RejectReason::kTimestamp},
      {"scan_start_too_old", &Bases::track_frame,
       [](D& d) { d.mutable_track_frame()->set_scan_start_ns(kSent - 61 * kS); },
       RejectReason::kTimestamp},
      {"scan_start_min", &Bases::track_frame,
       [](D& d) {
         d.mutable_track_frame()->set_scan_start_ns(std::numeric_limits<std::int64_t>::min());
       },
       RejectReason::kTimestamp},
      {"scan_start_ahead", &Bases::track_frame,
       [](D& d) { d.mutable_track_frame()->set_scan_start_ns(kSent + 301 * kS); },
       RejectReason::kTimestamp},
      {"learned_until_too_old", &Bases::background,
       [bg](D& d) { bg(d)->set_learned_until_ns(kSent - 61 * kS); }, RejectReason::kTimestamp},
      {"scan_period_nan", &Bases::track_frame,
       [](D& d) { d.mutable_track_frame()->set_scan_period_s(std::nan("")); },
       RejectReason::kNotFinite},
      {"scan_period_zero", &Bases::track_frame,
       [](D& d) { d.mutable_track_frame()->set_scan_period_s(0.0); }, RejectReason::kOutOfRange},
      {"scan_period_two", &Bases::track_frame,
       [](D& d) { d.mutable_track_frame()->set_scan_period_s(2.0); }, RejectReason::kOutOfRange},
      {"frame_part_beyond_count", &Bases::track_frame,
       [](D& d) { d.mutable_track_frame()->set_part(1); }, RejectReason::kPart},
      {"frame_part_count_zero", &Bases::track_frame,
       [](D& d) { d.mutable_track_frame()->set_part_count(0); }, RejectReason::kPart},
      {"frame_part_count_huge", &Bases::track_frame,
       [](D& d) {
         d.mutable_track_frame()->set_part_count(65);
         d.mutable_track_frame()->set_part(3);
       },
       RejectReason::kPart},
      // 1400 bytes hold about 27 tracks, so the default bound of 256 is checked with a lower one.
      {"too_many_tracks", &Bases::track_frame, [](D&) {}, RejectReason::kOutOfRange, true,
       [] {
         ValidationOptions o;
         o.max_tracks_per_frame = 2;
         return o;
       }()},
      {"track_state_unspecified", &Bases::track_frame,
       [track](D& d) { track(d).set_state(proto::TRACK_STATE_UNSPECIFIED); },
       RejectReason::kOutOfRange},
      {"track_state_unknown", &Bases::track_frame,
       [track](D& d) { track(d).set_state(static_cast<proto::TrackState>(9)); },
       RejectReason::kOutOfRange},
      {"track_kind_unknown", &Bases::track_frame,
       [track](D& d) { track(d).set_kind(static_cast<proto::MeasurementKind>(4)); },
       RejectReason::kOutOfRange},
      {"track_shape_unknown", &Bases::track_frame,
       [track](D& d) { track(d).set_shape(static_cast<proto::ObjectShape>(5)); },
       RejectReason::kOutOfRange},
      {"track_size_nan", &Bases::track_frame, [track](D& d) { track(d).set_size_minor_m(kNaN); },
       RejectReason::kNotFinite},
      {"track_size_negative", &Bases::track_frame,
       [track](D& d) { track(d).set_size_major_m(-0.1f); }, RejectReason::kOutOfRange},
      {"track_size_huge", &Bases::track_frame,
       [track](D& d) { track(d).set_size_sigma_m(1e6f); }, RejectReason::kOutOfRange},
      {"track_x_nan", &Bases::track_frame, [track](D& d) { track(d).set_x_m(kNaN); },
       RejectReason::kNotFinite},
      {"track_vy_inf", &Bases::track_frame,
       [track](D& d) { track(d).set_vy_mps(std::numeric_limits<float>::infinity()); },
       RejectReason::kNotFinite},
      {"track_yaw_nan", &Bases::track_frame, [track](D& d) { track(d).set_ellipse_yaw_rad(kNaN); },
       RejectReason::kNotFinite},
      {"covariance_nan", &Bases::track_frame, [track](D& d) { track(d).set_covariance(4, kNaN); },
       RejectReason::kNotFinite},
      {"covariance_nine", &Bases::track_frame,
       [track](D& d) { track(d).mutable_covariance()->RemoveLast(); }, RejectReason::kCovariance},
      {"covariance_none", &Bases::track_frame, [track](D& d) { track(d).clear_covariance(); },
       RejectReason::kCovariance},
      {"covariance_eleven", &Bases::track_frame, [track](D& d) { track(d).add_covariance(1.0f); },
       RejectReason::kCovariance},
      {"covariance_negative_variance", &Bases::track_frame,
       [track](D& d) { track(d).set_covariance(7, -0.5f); }, RejectReason::kCovariance},
      {"covariance_correlation_above_one", &Bases::track_frame,
       [track](D& d) {
         const auto& c = track(d).covariance();
         track(d).set_covariance(1, 1.01f * std::sqrt(c.Get(0) * c.Get(4)));
       },
       RejectReason::kCovariance},
      {"position_far", &Bases::track_frame, [track](D& d) { track(d).set_y_m(-1000.5f); },
       RejectReason::kOutOfRange},
      {"speed_fast", &Bases::track_frame, [track](D& d) { track(d).set_vx_mps(100.5f); },
       RejectReason::kOutOfRange},
      {"background_angle_nan", &Bases::background,
       [bg](D& d) { bg(d)->set_angle_step_rad(std::nan("")); }, RejectReason::kNotFinite},
      {"background_step_zero", &Bases::background, [bg](D& d) { bg(d)->set_angle_step_rad(0.0); },
       RejectReason::kOutOfRange},
      {"background_first_angle_far", &Bases::background,
       [bg](D& d) { bg(d)->set_first_angle_rad(7.0); }, RejectReason::kOutOfRange},
      {"background_more_than_a_turn", &Bases::background,
       [bg](D& d) { bg(d)->set_angle_step_rad(0.022); }, RejectReason::kOutOfRange},
      {"background_zero_beams", &Bases::background, [bg](D& d) { bg(d)->set_beam_count(0); },
       RejectReason::kOutOfRange},
      {"background_too_many_beams", &Bases::background,
       [bg](D& d) {
         bg(d)->set_beam_count(65537);
         bg(d)->set_angle_step_rad(1e-5);
       },
       RejectReason::kOutOfRange},
      {"background_part_beyond_count", &Bases::background, [bg](D& d) { bg(d)->set_part(1); },
       RejectReason::kPart},
      {"background_part_count_zero", &Bases::background, [bg](D& d) { bg(d)->set_part_count(0); },
       RejectReason::kPart},
      {"background_beams_beyond_count", &Bases::background,
       [bg](D& d) { bg(d)->set_first_beam(1); }, RejectReason::kPart},
      {"background_first_beam_huge", &Bases::background,
       [bg](D& d) { bg(d)->set_first_beam(0xFFFFFFFFu); }, RejectReason::kPart},
      {"health_nan", &Bases::health,
       [](D& d) { d.mutable_health()->set_tick_drift_ppm(std::nan("")); },
       RejectReason::kNotFinite},
      {"health_clock_sync_unknown", &Bases::health,
       [](D& d) { d.mutable_health()->set_clock_sync(static_cast<proto::ClockSyncState>(4)); },
       RejectReason::kOutOfRange},
      {"info_inf", &Bases::info,
       [](D& d) {
         d.mutable_sensor_info()->set_max_range_m(std::numeric_limits<double>::infinity());
       },
       RejectReason::kNotFinite},
      {"info_long_model", &Bases::info,
       [](D& d) { d.mutable_sensor_info()->set_model(std::string(65, 'm')); },
       RejectReason::kOutOfRange},
      {"info_long_tracker_version", &Bases::info,
       [](D& d) { d.mutable_sensor_info()->set_tracker_version(std::string(200, 'v')); },
       RejectReason::kOutOfRange},
      {"info_kind_unknown", &Bases::info,
       [](D& d) { d.mutable_sensor_info()->set_kind(static_cast<proto::MeasurementKind>(-1)); },
       RejectReason::kOutOfRange},
      {"info_mount_unknown", &Bases::info,
       [](D& d) { d.mutable_sensor_info()->set_mount(static_cast<proto::MountHeight>(3)); },
       RejectReason::kOutOfRange},
      {"info_psd_negative", &Bases::info,
       [](D& d) { d.mutable_sensor_info()->set_accel_psd_m2ps3(-1.0); }, RejectReason::kOutOfRange},
      {"info_speed_nan", &Bases::info,
       [](D& d) { d.mutable_sensor_info()->set_max_speed_mps(std::nan("")); },
       RejectReason::kNotFinite},
  };
}

TEST(DatagramDecoderTest, EveryHostileFieldIsRefusedWithItsReason) {
  const Bases bases;
  DatagramDecoder decoder({});
  for (const HostileCase& c : HostileCases()) {
    SCOPED_TRACE(c.name);
    proto::Datagram d = bases.*(c.base);
    decoder.set_options({});
    ASSERT_TRUE(decoder.Decode(View(Serialize(d)), kT0).ok()) << decoder.detail();
    c.mutate(d);
    const Bytes bytes = Serialize(d);
    ASSERT_LE(bytes.size(), kMaxDatagramBytes);
    decoder.set_options(c.options);
    const DecodeStatus s = decoder.Decode(View(bytes), kT0);
    EXPECT_EQ(ToString(s.reason), std::string(ToString(c.expected)));
    EXPECT_EQ(s.attributed, c.attributed);
    EXPECT_FALSE(decoder.detail().empty());
    EXPECT_EQ(decoder.detail().find('\n'), std::string::npos);
  }
}

TEST(DatagramDecoderTest, SizeAndParseErrorsAreUnattributed) {
  DatagramDecoder decoder({});
  EXPECT_EQ(decoder.Decode({}, kT0).reason, RejectReason::kEmpty);
  const Bytes big(kMaxDatagramBytes + 1, 0);
  const DecodeStatus oversize = decoder.Decode(View(big), kT0);
  EXPECT_EQ(oversize.reason, RejectReason::kOversize);
  EXPECT_FALSE(oversize.attributed);
  // A length prefix promising more than there is, an invalid wire type, a bad varint, and a
  // sensor id that is not UTF-8.
  for (const Bytes& garbage :
       {Bytes{0x12, 0x7f, 'a'}, Bytes{0x0f},
        Bytes{0x08, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x01},
        Bytes{0x12, 0x02, 0xc3, 0x28}}) {
    const DecodeStatus s = decoder.Decode(View(garbage), kT0);
    EXPECT_EQ(s.reason, RejectReason::kMalformed);
    EXPECT_FALSE(s.attributed);
  }
}

void AppendVarint(Bytes& out, std::uint64_t v) {
  while (v >= 0x80) {
    out.push_back(static_cast<std::uint8_t>(v | 0x80));
    v >>= 7;
  }
  out.push_back(static_cast<std::uint8_t>(v));
}

TEST(DatagramDecoderTest, AnUnknownFieldAsPayloadIsAnUnknownKind) {
  const Bases bases;
  Bytes bytes = Serialize(bases.health);
  // Replace the health payload (field 12) by field 20, length-delimited, same content.
  proto::Datagram header = bases.health;
  header.clear_payload();
  Bytes out = Serialize(header);
  const std::string payload = bases.health.health().SerializeAsString();
  AppendVarint(out, (20 << 3) | 2);
  AppendVarint(out, payload.size());
  out.insert(out.end(), payload.begin(), payload.end());
  DatagramDecoder decoder({});
  const DecodeStatus s = decoder.Decode(View(out), kT0);
  EXPECT_EQ(s.reason, RejectReason::kUnknownKind);
  EXPECT_TRUE(s.attributed);
  // Unknown fields next to a known payload are ignored (forward compatibility).
  AppendVarint(bytes, (21 << 3) | 0);
  AppendVarint(bytes, 5);
  EXPECT_TRUE(decoder.Decode(View(bytes), kT0).ok()) << decoder.detail();
}

TEST(DatagramDecoderTest, ClockOffsetIsCheckedOnlyWhenConfigured) {
  const Bases bases;
  proto::Datagram d = bases.health;
  d.set_sent_ns(kT0 - 10 * kS);
  const Bytes bytes = Serialize(d);
  DatagramDecoder decoder({});
  EXPECT_TRUE(decoder.Decode(View(bytes), kT0).ok());
  ValidationOptions strict;
  strict.max_clock_offset_s = 5.0;
  decoder.set_options(strict);
  EXPECT_EQ(decoder.Decode(View(bytes), kT0).reason, RejectReason::kTimestamp);
  EXPECT_TRUE(decoder.Decode(View(bytes), kT0 - 6 * kS).ok());
  // Without the bound, a capture replayed long after (receive times of today, stamps of then) is
  // accepted; a stamp far after the receive time never is.
  decoder.set_options({});
  EXPECT_TRUE(decoder.Decode(View(bytes), kT0 + 3600 * kS).ok());
  EXPECT_EQ(decoder.Decode(View(bytes), kT0 - 3600 * kS).reason, RejectReason::kTimestamp);
}

TEST(DatagramDecoderTest, EveryStrictPrefixOfAValidDatagramIsRefused) {
  FakeTracker tracker("gate-3", 7);
  std::vector<Bytes> all = tracker.Tracks(20, kSent);
  for (const Bytes& b : tracker.Background(500, kSent)) all.push_back(b);
  all.push_back(tracker.Health(kSent));
  all.push_back(tracker.Info(kSent));
  DatagramDecoder decoder({});
  std::size_t prefixes = 0;
  for (const Bytes& full : all) {
    ASSERT_TRUE(decoder.Decode(View(full), kT0).ok());
    for (std::size_t n = 0; n < full.size(); ++n) {
      const DecodeStatus s = decoder.Decode(std::span(full.data(), n), kT0);
      ASSERT_FALSE(s.ok()) << n << " of " << full.size() << " bytes accepted";
      ++prefixes;
    }
  }
  EXPECT_GT(prefixes, 2500u);
}

TEST(ValidationOptionsTest, DefaultsAreValidAndNonsenseIsNot) {
  EXPECT_EQ(Validate(ValidationOptions{}), std::nullopt);
  ValidationOptions o;
  o.max_future_s = std::nan("");
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.max_position_m = 0.0;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.max_part_count = 0;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.max_background_beams = 0;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.max_clock_offset_s = -1.0;
  EXPECT_NE(Validate(o), std::nullopt);
}

}  // namespace
}  // namespace lrfnet::daemon
