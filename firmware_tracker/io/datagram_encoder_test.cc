#include "firmware_tracker/io/datagram_encoder.h"

#include <gtest/gtest.h>
#include <pb_decode.h>
#include <pb_encode.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace lrfnet::io {
namespace {

constexpr common::UtcNs kSentNs = 1'700'000'000'123'456'789;

struct CollectSink final : DatagramSink {
  std::vector<std::vector<std::uint8_t>> datagrams;
  std::vector<common::UtcNs> sent;
  void Send(std::span<const std::uint8_t> d, common::UtcNs sent_ns) override {
    datagrams.emplace_back(d.begin(), d.end());
    sent.push_back(sent_ns);
  }
};

// nanopb is the decoder here so these tests also run in the tracker-only build; uplink_wire_test
// repeats the essentials with libprotobuf.
lrfnet_proto_Datagram Decode(const std::vector<std::uint8_t>& bytes) {
  lrfnet_proto_Datagram d{};
  pb_istream_t stream = pb_istream_from_buffer(bytes.data(), bytes.size());
  EXPECT_TRUE(pb_decode(&stream, lrfnet_proto_Datagram_fields, &d)) << PB_GET_ERROR(&stream);
  return d;
}

DatagramEncoderOptions Options(const std::string& id = "hall-north.lms511") {
  DatagramEncoderOptions o;
  o.sensor_id = id;
  o.session_id = 0xC0FFEE1234ull;
  return o;
}

tracking::TrackReport MakeTrack(std::uint32_t id) {
  tracking::TrackReport t;
  t.track_id = id;
  t.state = tracking::TrackState::kConfirmed;
  t.kind = tracking::MeasurementKind::kEllipse;
  t.x_m = 1.5 + id;
  t.y_m = -2.25;
  t.vx_mps = 0.5;
  t.vy_mps = -1.25;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) t.covariance(r, c) = 0.01 * (1 + std::min(r, c)) + 0.1 * (r == c);
  }
  t.covariance(0, 1) = t.covariance(1, 0) = 0.002;
  t.covariance(2, 3) = t.covariance(3, 2) = 0.003;
  t.age_scans = 10 * id;
  t.points = 7;
  t.ellipse_yaw_rad = 0.75;
  return t;
}

// Every field at its widest encoding.
tracking::TrackReport WorstCaseTrack(std::uint32_t id) {
  tracking::TrackReport t;
  t.track_id = 0xF0000000u | id;
  t.state = tracking::TrackState::kCoasting;
  t.kind = tracking::MeasurementKind::kEllipse;
  t.x_m = t.y_m = -123.456;
  t.vx_mps = t.vy_mps = -1.5;
  t.covariance.setConstant(1e-3);
  t.age_scans = ~0u;
  t.points = ~0u;
  t.ellipse_yaw_rad = -3.0;
  t.kind = tracking::MeasurementKind::kShapeFit;
  t.shape = tracking::ObjectShape::kBox;
  t.size_major_m = 0.51;
  t.size_minor_m = 0.33;
  t.size_sigma_m = 0.04;
  return t;
}

TEST(DatagramEncoderTest, SensorIdsFollowTheDocumentedPattern) {
  EXPECT_TRUE(IsValidSensorId("s1"));
  EXPECT_TRUE(IsValidSensorId("hall-north.lms_511"));
  EXPECT_TRUE(IsValidSensorId(std::string(32, 'a')));
  EXPECT_FALSE(IsValidSensorId(""));
  EXPECT_FALSE(IsValidSensorId(std::string(33, 'a')));
  EXPECT_FALSE(IsValidSensorId("a b"));
  EXPECT_FALSE(IsValidSensorId("sensor/1"));
  EXPECT_FALSE(IsValidSensorId("caf\xc3\xa9"));
  ASSERT_TRUE(Validate(Options("bad id")).has_value());
  EXPECT_NE(Validate(Options("bad id"))->find("bad id"), std::string::npos);
}

TEST(DatagramEncoderTest, TrackFrameCarriesHeaderAndEveryTrackField) {
  DatagramEncoder encoder(Options());
  CollectSink sink;
  tracking::ScanTracks scan;
  scan.scan_start_ns = kSentNs - 40'000'000;
  scan.scan_period_s = 0.04;
  scan.scan_counter = 65535;
  for (std::uint32_t i = 1; i <= 3; ++i) ASSERT_TRUE(scan.tracks.push_back(MakeTrack(i)));
  scan.tracks[2].kind = tracking::MeasurementKind::kCenterOfMass;
  scan.tracks[1].kind = tracking::MeasurementKind::kShapeFit;
  scan.tracks[1].shape = tracking::ObjectShape::kTorso;
  scan.tracks[1].size_major_m = 0.24;
  scan.tracks[1].size_minor_m = 0.13;
  scan.tracks[1].size_sigma_m = 0.02;
  scan.tracks[2].state = tracking::TrackState::kTentative;

  ASSERT_EQ(encoder.EncodeTracks(scan, kSentNs, sink), 1u);
  ASSERT_EQ(sink.datagrams.size(), 1u);
  EXPECT_EQ(sink.sent[0], kSentNs);
  const lrfnet_proto_Datagram d = Decode(sink.datagrams[0]);
  EXPECT_EQ(d.version, lrfnet_proto_ProtocolVersion_PROTOCOL_VERSION_1);
  EXPECT_STREQ(d.sensor_id, "hall-north.lms511");
  EXPECT_EQ(d.sequence, 0u);
  EXPECT_EQ(d.sent_ns, kSentNs);
  EXPECT_EQ(d.session_id, 0xC0FFEE1234ull);
  ASSERT_EQ(d.which_payload, lrfnet_proto_Datagram_track_frame_tag);
  const lrfnet_proto_TrackFrame& f = d.payload.track_frame;
  EXPECT_EQ(f.scan_start_ns, scan.scan_start_ns);
  EXPECT_EQ(f.scan_period_s, 0.04);
  EXPECT_EQ(f.scan_counter, 65535u);
  EXPECT_EQ(f.part, 0u);
  EXPECT_EQ(f.part_count, 1u);
  ASSERT_EQ(f.tracks_count, 3);
  const lrfnet_proto_Track& t = f.tracks[0];
  EXPECT_EQ(t.track_id, 1u);
  EXPECT_EQ(t.state, lrfnet_proto_TrackState_TRACK_STATE_CONFIRMED);
  EXPECT_EQ(t.kind, lrfnet_proto_MeasurementKind_MEASUREMENT_KIND_ELLIPSE);
  EXPECT_FLOAT_EQ(t.x_m, 2.5f);
  EXPECT_FLOAT_EQ(t.y_m, -2.25f);
  EXPECT_FLOAT_EQ(t.vx_mps, 0.5f);
  EXPECT_FLOAT_EQ(t.vy_mps, -1.25f);
  EXPECT_EQ(t.age_scans, 10u);
  EXPECT_EQ(t.points, 7u);
  EXPECT_FLOAT_EQ(t.ellipse_yaw_rad, 0.75f);
  // Upper triangle row-major: xx, xy, xvx, xvy, yy, yvx, yvy, vxvx, vxvy, vyvy.
  ASSERT_EQ(t.covariance_count, 10);
  const Eigen::Matrix4d& c = scan.tracks[0].covariance;
  const double expected[10] = {c(0, 0), c(0, 1), c(0, 2), c(0, 3), c(1, 1),
                               c(1, 2), c(1, 3), c(2, 2), c(2, 3), c(3, 3)};
  for (int i = 0; i < 10; ++i)
    EXPECT_FLOAT_EQ(t.covariance[i], static_cast<float>(expected[i])) << i;
  EXPECT_FLOAT_EQ(t.covariance[1], 0.002f);
  EXPECT_FLOAT_EQ(t.covariance[8], 0.003f);
  // A centre-of-mass track has no ellipse orientation.
  EXPECT_EQ(f.tracks[2].kind, lrfnet_proto_MeasurementKind_MEASUREMENT_KIND_CENTER_OF_MASS);
  EXPECT_EQ(f.tracks[2].state, lrfnet_proto_TrackState_TRACK_STATE_TENTATIVE);
  EXPECT_EQ(f.tracks[2].ellipse_yaw_rad, 0.0f);
  EXPECT_EQ(t.shape, lrfnet_proto_ObjectShape_OBJECT_SHAPE_UNSPECIFIED);
  EXPECT_EQ(t.size_major_m, 0.0f);
  // A shape-fit track carries its orientation, shape and size state.
  const lrfnet_proto_Track& s = f.tracks[1];
  EXPECT_EQ(s.kind, lrfnet_proto_MeasurementKind_MEASUREMENT_KIND_SHAPE_FIT);
  EXPECT_EQ(s.shape, lrfnet_proto_ObjectShape_OBJECT_SHAPE_TORSO);
  EXPECT_FLOAT_EQ(s.ellipse_yaw_rad, 0.75f);
  EXPECT_FLOAT_EQ(s.size_major_m, 0.24f);
  EXPECT_FLOAT_EQ(s.size_minor_m, 0.13f);
  EXPECT_FLOAT_EQ(s.size_sigma_m, 0.02f);
}

TEST(DatagramEncoderTest, ScanWithoutTracksIsStillOnePart) {
  DatagramEncoder encoder(Options());
  CollectSink sink;
  tracking::ScanTracks scan;
  scan.scan_start_ns = kSentNs;
  scan.scan_counter = 9;
  ASSERT_EQ(encoder.EncodeTracks(scan, kSentNs, sink), 1u);
  const lrfnet_proto_Datagram d = Decode(sink.datagrams[0]);
  ASSERT_EQ(d.which_payload, lrfnet_proto_Datagram_track_frame_tag);
  EXPECT_EQ(d.payload.track_frame.part_count, 1u);
  EXPECT_EQ(d.payload.track_frame.tracks_count, 0);
  EXPECT_EQ(d.payload.track_frame.scan_counter, 9u);
}

TEST(DatagramEncoderTest, SixtyFourWorstCaseTracksSplitIntoPartsOfEleven) {
  DatagramEncoder encoder(Options(std::string(32, 's')));
  CollectSink sink;
  tracking::ScanTracks scan;
  scan.scan_start_ns = -1;
  scan.scan_period_s = 1.0 / 7.0;
  scan.scan_counter = ~0u;
  for (std::uint32_t i = 0; i < tracking::kMaxTracks; ++i)
    ASSERT_TRUE(scan.tracks.push_back(WorstCaseTrack(i)));
  ASSERT_EQ(encoder.EncodeTracks(scan, -1, sink), 6u);
  std::vector<std::uint32_t> ids;
  std::size_t largest = 0;
  for (std::size_t p = 0; p < sink.datagrams.size(); ++p) {
    largest = std::max(largest, sink.datagrams[p].size());
    EXPECT_LE(sink.datagrams[p].size(), kMaxPayloadBytes);
    const lrfnet_proto_Datagram d = Decode(sink.datagrams[p]);
    EXPECT_EQ(d.sequence, p);
    const lrfnet_proto_TrackFrame& f = d.payload.track_frame;
    EXPECT_EQ(f.part, p);
    EXPECT_EQ(f.part_count, 6u);
    EXPECT_EQ(f.scan_start_ns, -1);
    EXPECT_EQ(f.tracks_count, p < 5 ? 11 : 9);
    for (pb_size_t i = 0; i < f.tracks_count; ++i) ids.push_back(f.tracks[i].track_id & 0xffu);
  }
  ASSERT_EQ(ids.size(), tracking::kMaxTracks);
  for (std::uint32_t i = 0; i < ids.size(); ++i) EXPECT_EQ(ids[i], i);
  RecordProperty("worst_case_11_track_datagram_bytes", static_cast<int>(largest));

  // 11 is the most that fits: the widest header (every varint at 10 bytes) plus 11 widest tracks
  // stays within the payload budget (1400 bytes less the widest envelope), one more would not.
  lrfnet_proto_Datagram d = Decode(sink.datagrams[0]);
  d.sequence = ~0ull;
  d.session_id = ~0ull;
  d.payload.track_frame.part = d.payload.track_frame.part_count = ~0u;
  std::array<std::uint8_t, kMaxDatagramBytes> buffer{};
  pb_ostream_t stream = pb_ostream_from_buffer(buffer.data(), buffer.size());
  ASSERT_TRUE(pb_encode(&stream, lrfnet_proto_Datagram_fields, &d));
  std::size_t track_bytes = 0;
  ASSERT_TRUE(pb_get_encoded_size(&track_bytes, lrfnet_proto_Track_fields,
                                  &d.payload.track_frame.tracks[0]));
  const std::size_t one_more = stream.bytes_written + 1 /* tag */ + 1 /* length */ + track_bytes;
  EXPECT_LE(stream.bytes_written, kMaxPayloadBytes);
  EXPECT_GT(one_more, kMaxPayloadBytes) << "a 12th track would fit: raise kTracksPerPart";
  RecordProperty("widest_11_track_datagram_bytes", static_cast<int>(stream.bytes_written));
}

// The track frame is assembled from tracks encoded once each: its bytes must be exactly what
// nanopb writes for the same message (fields in number order), for 0, some and a full part of
// tracks, plain and widest.
TEST(DatagramEncoderTest, AssembledTrackFramesAreNanopbsOwnBytes) {
  for (const bool widest : {false, true}) {
    for (const std::uint32_t n : {0u, 1u, 5u, 11u, 12u, 23u}) {
      DatagramEncoder encoder(Options(widest ? std::string(32, 'w') : "s1"));
      CollectSink sink;
      tracking::ScanTracks scan;
      scan.scan_start_ns = widest ? -1 : 1'700'000'000'000'000'000;
      scan.scan_period_s = 1.0 / 25.0;
      scan.scan_counter = widest ? ~0u : 17u;
      for (std::uint32_t i = 0; i < n; ++i)
        ASSERT_TRUE(scan.tracks.push_back(widest ? WorstCaseTrack(i) : MakeTrack(i)));
      const std::size_t parts = encoder.EncodeTracks(scan, 42, sink);
      ASSERT_EQ(parts, std::max<std::size_t>(1, (n + 10) / 11));
      ASSERT_EQ(sink.datagrams.size(), parts);
      std::uint32_t tracks = 0;
      for (const auto& bytes : sink.datagrams) {
        const lrfnet_proto_Datagram d = Decode(bytes);
        tracks += d.payload.track_frame.tracks_count;
        std::array<std::uint8_t, kMaxDatagramBytes> again{};
        pb_ostream_t stream = pb_ostream_from_buffer(again.data(), again.size());
        ASSERT_TRUE(pb_encode(&stream, lrfnet_proto_Datagram_fields, &d));
        EXPECT_EQ(std::vector<std::uint8_t>(again.begin(), again.begin() + stream.bytes_written),
                  bytes)
            << n << " tracks, widest " << widest;
      }
      EXPECT_EQ(tracks, n);
      EXPECT_EQ(encoder.counters().tracks, n);
      EXPECT_EQ(encoder.counters().encode_errors, 0u);
    }
  }
}

// Track frames are written without nanopb's encoder: on random headers and tracks (every state,
// kind and shape, zeros that proto3 leaves out, -0.0 that it keeps, negative int64, widest and
// one-byte varints) the datagrams decode to exactly the values sent and are byte for byte what
// nanopb writes for them.
TEST(DatagramEncoderTest, RandomTracksAreNanopbsOwnBytesAndValues) {
  std::mt19937 rng(14);
  std::uniform_int_distribution<int> pick(0, 5);
  const auto value = [&](double typical) {
    switch (pick(rng)) {
      case 0:
        return 0.0;
      case 1:
        return -0.0;
      case 2:
        return typical * 1e-30;  // a float denormal or zero
      default:
        return typical * std::uniform_real_distribution<double>(-1.0, 1.0)(rng);
    }
  };
  const auto count = [&]() -> std::uint32_t {
    switch (pick(rng)) {
      case 0:
        return 0u;
      case 1:
        return ~0u;
      case 2:
        return 127u;
      case 3:
        return 128u;
      default:
        return static_cast<std::uint32_t>(rng());
    }
  };
  const auto stamp = [&]() -> common::UtcNs {
    switch (pick(rng)) {
      case 0:
        return 0;
      case 1:
        return -1;
      case 2:
        return std::numeric_limits<common::UtcNs>::max();
      default:
        return kSentNs + static_cast<common::UtcNs>(rng());
    }
  };
  for (int round = 0; round < 40; ++round) {
    DatagramEncoderOptions options = Options(round % 2 == 0 ? "s1" : std::string(32, 'w'));
    options.session_id = round % 3 == 0 ? 0u : (round % 3 == 1 ? ~0ull : rng());
    DatagramEncoder encoder(options);
    CollectSink sink;
    tracking::ScanTracks scan;
    scan.scan_start_ns = stamp();
    scan.scan_period_s = value(0.1);
    scan.scan_counter = count();
    const common::UtcNs sent_ns = stamp();
    // A first frame without tracks: sequence 0 (left out), then 1.
    if (round % 4 == 0) encoder.EncodeTracks(tracking::ScanTracks{}, sent_ns, sink);
    const std::uint32_t n = static_cast<std::uint32_t>(round) % 24;
    for (std::uint32_t i = 0; i < n; ++i) {
      tracking::TrackReport t;
      t.track_id = count();
      t.state = static_cast<tracking::TrackState>(pick(rng) % 3);
      t.kind = static_cast<tracking::MeasurementKind>(pick(rng) % 3);
      t.x_m = value(30.0);
      t.y_m = value(30.0);
      t.vx_mps = value(2.0);
      t.vy_mps = value(2.0);
      for (int r = 0; r < 4; ++r) {
        for (int c = r; c < 4; ++c) t.covariance(r, c) = t.covariance(c, r) = value(0.1);
      }
      t.age_scans = count();
      t.points = count();
      t.ellipse_yaw_rad = value(3.0);
      t.shape = static_cast<tracking::ObjectShape>(pick(rng) % 5);
      t.size_major_m = value(0.3);
      t.size_minor_m = value(0.2);
      t.size_sigma_m = value(0.05);
      ASSERT_TRUE(scan.tracks.push_back(t));
    }
    encoder.EncodeTracks(scan, sent_ns, sink);
    ASSERT_EQ(encoder.counters().tracks, n);
    ASSERT_EQ(encoder.counters().encode_errors, 0u);
    std::uint32_t next = 0;
    for (std::size_t k = 0; k < sink.datagrams.size(); ++k) {
      const auto& bytes = sink.datagrams[k];
      const lrfnet_proto_Datagram d = Decode(bytes);
      EXPECT_EQ(d.sequence, k);
      EXPECT_EQ(d.sent_ns, sent_ns);
      EXPECT_EQ(d.session_id, options.session_id);
      EXPECT_STREQ(d.sensor_id, options.sensor_id.c_str());
      if (round % 4 == 0 && k == 0) continue;  // the empty frame
      const lrfnet_proto_TrackFrame& f = d.payload.track_frame;
      EXPECT_EQ(f.scan_start_ns, scan.scan_start_ns);
      EXPECT_EQ(std::memcmp(&f.scan_period_s, &scan.scan_period_s, sizeof(double)), 0);
      EXPECT_EQ(f.scan_counter, scan.scan_counter);
      std::array<std::uint8_t, kMaxDatagramBytes> again{};
      pb_ostream_t stream = pb_ostream_from_buffer(again.data(), again.size());
      ASSERT_TRUE(pb_encode(&stream, lrfnet_proto_Datagram_fields, &d));
      ASSERT_EQ(std::vector<std::uint8_t>(again.begin(), again.begin() + stream.bytes_written),
                bytes)
          << "round " << round;
      const auto same_bits = [](float got, double sent) {
        const auto as_float = static_cast<float>(sent);
        return std::memcmp(&got, &as_float, sizeof as_float) == 0;
      };
      for (pb_size_t t = 0; t < d.payload.track_frame.tracks_count; ++t) {
        const lrfnet_proto_Track& got = d.payload.track_frame.tracks[t];
        const tracking::TrackReport& sent = scan.tracks[next++];
        SCOPED_TRACE("round " + std::to_string(round) + " track " + std::to_string(next - 1));
        EXPECT_EQ(got.track_id, sent.track_id);
        EXPECT_EQ(got.state, static_cast<int>(sent.state) + 1);
        EXPECT_EQ(got.age_scans, sent.age_scans);
        EXPECT_EQ(got.points, sent.points);
        EXPECT_TRUE(same_bits(got.x_m, sent.x_m));
        EXPECT_TRUE(same_bits(got.y_m, sent.y_m));
        EXPECT_TRUE(same_bits(got.vx_mps, sent.vx_mps));
        EXPECT_TRUE(same_bits(got.vy_mps, sent.vy_mps));
        EXPECT_TRUE(same_bits(got.covariance[9], sent.covariance(3, 3)));
        if (sent.kind != tracking::MeasurementKind::kCenterOfMass) {
          EXPECT_TRUE(same_bits(got.ellipse_yaw_rad, sent.ellipse_yaw_rad));
        }
        if (sent.shape != tracking::ObjectShape::kUnspecified) {
          EXPECT_TRUE(same_bits(got.size_sigma_m, sent.size_sigma_m));
        }
      }
    }
    EXPECT_EQ(next, n);
  }
}

TEST(DatagramEncoderTest, TracksWithNonFiniteValuesAreDroppedAndCounted) {
  DatagramEncoder encoder(Options());
  CollectSink sink;
  tracking::ScanTracks scan;
  for (std::uint32_t i = 0; i < 14; ++i) ASSERT_TRUE(scan.tracks.push_back(MakeTrack(i)));
  scan.tracks[3].x_m = std::numeric_limits<double>::quiet_NaN();
  scan.tracks[7].covariance(2, 3) = std::numeric_limits<double>::infinity();
  scan.tracks[9].vy_mps = 1e300;  // infinite as a float
  scan.tracks[12].shape = tracking::ObjectShape::kTorso;
  scan.tracks[12].size_sigma_m = std::numeric_limits<double>::quiet_NaN();
  ASSERT_EQ(encoder.EncodeTracks(scan, kSentNs, sink), 1u);  // 10 tracks left: one part
  const lrfnet_proto_Datagram d = Decode(sink.datagrams[0]);
  EXPECT_EQ(d.payload.track_frame.tracks_count, 10);
  for (pb_size_t i = 0; i < d.payload.track_frame.tracks_count; ++i) {
    const std::uint32_t id = d.payload.track_frame.tracks[i].track_id;
    EXPECT_TRUE(id != 3 && id != 7 && id != 9 && id != 12) << id;
  }
  EXPECT_EQ(encoder.counters().dropped_tracks, 4u);
  EXPECT_EQ(encoder.counters().tracks, 10u);
}

// Only the values a track sends decide whether it is dropped: a centre-of-mass track sends no
// orientation and a track of unspecified shape no size, whatever those hold. A dropped track's
// bytes leave no trace in the next one's.
TEST(DatagramEncoderTest, ValuesNotSentDoNotDropATrack) {
  DatagramEncoder encoder(Options());
  CollectSink sink;
  tracking::ScanTracks scan;
  for (std::uint32_t i = 0; i < 4; ++i) ASSERT_TRUE(scan.tracks.push_back(MakeTrack(i)));
  const double nan = std::numeric_limits<double>::quiet_NaN();
  scan.tracks[0].kind = tracking::MeasurementKind::kCenterOfMass;
  scan.tracks[0].ellipse_yaw_rad = nan;
  scan.tracks[1].size_major_m = nan;  // shape unspecified
  scan.tracks[1].size_sigma_m = std::numeric_limits<double>::infinity();
  scan.tracks[2].ellipse_yaw_rad = nan;  // sent (an ellipse): dropped
  scan.tracks[3].shape = tracking::ObjectShape::kCylinder;
  scan.tracks[3].size_major_m = scan.tracks[3].size_minor_m = 0.25;
  scan.tracks[3].size_sigma_m = 0.02;
  ASSERT_EQ(encoder.EncodeTracks(scan, kSentNs, sink), 1u);
  const lrfnet_proto_Datagram d = Decode(sink.datagrams[0]);
  const lrfnet_proto_TrackFrame& f = d.payload.track_frame;
  ASSERT_EQ(f.tracks_count, 3);
  EXPECT_EQ(f.tracks[0].track_id, 0u);
  EXPECT_EQ(f.tracks[0].ellipse_yaw_rad, 0.0f);
  EXPECT_EQ(f.tracks[1].track_id, 1u);
  EXPECT_EQ(f.tracks[1].shape, lrfnet_proto_ObjectShape_OBJECT_SHAPE_UNSPECIFIED);
  EXPECT_EQ(f.tracks[1].size_major_m, 0.0f);
  EXPECT_EQ(f.tracks[1].size_sigma_m, 0.0f);
  EXPECT_EQ(f.tracks[1].ellipse_yaw_rad, 0.75f);
  EXPECT_EQ(f.tracks[2].track_id, 3u);
  EXPECT_EQ(f.tracks[2].shape, lrfnet_proto_ObjectShape_OBJECT_SHAPE_CYLINDER);
  EXPECT_EQ(f.tracks[2].size_minor_m, 0.25f);
  EXPECT_EQ(f.tracks[2].size_sigma_m, 0.02f);
  EXPECT_EQ(f.tracks[2].x_m, 4.5f);
  EXPECT_EQ(f.tracks[2].covariance_count, 10);
  EXPECT_EQ(f.tracks[2].covariance[1], 0.002f);
  EXPECT_EQ(f.tracks[2].covariance[9], static_cast<float>(0.14));
  EXPECT_EQ(encoder.counters().dropped_tracks, 1u);
  // The frame is nanopb's own encoding of what it decodes to.
  std::array<std::uint8_t, kMaxDatagramBytes> again{};
  pb_ostream_t stream = pb_ostream_from_buffer(again.data(), again.size());
  ASSERT_TRUE(pb_encode(&stream, lrfnet_proto_Datagram_fields, &d));
  EXPECT_EQ(std::vector<std::uint8_t>(again.begin(), again.begin() + stream.bytes_written),
            sink.datagrams[0]);
}

TEST(DatagramEncoderTest, BackgroundSnapshotOf4561BeamsReassembles) {
  DatagramEncoder encoder(Options(std::string(32, 'x')));
  CollectSink sink;
  std::vector<float> ranges(4561);
  for (std::size_t i = 0; i < ranges.size(); ++i) {
    ranges[i] = (i % 17 == 0) ? 0.0f : 0.5f + 0.01f * static_cast<float>(i % 5000);
  }
  BackgroundSnapshotView view;
  view.learned_until_ns = kSentNs - 1;
  view.first_angle_rad = -1.658;
  view.angle_step_rad = 0.000727;
  view.range_m = ranges;
  ASSERT_EQ(encoder.EncodeBackground(view, kSentNs, sink), 12u);
  std::vector<std::uint32_t> mm(ranges.size(), 0xdeadbeef);
  for (std::size_t p = 0; p < sink.datagrams.size(); ++p) {
    EXPECT_LE(sink.datagrams[p].size(), kMaxPayloadBytes);
    const lrfnet_proto_Datagram d = Decode(sink.datagrams[p]);
    ASSERT_EQ(d.which_payload, lrfnet_proto_Datagram_background_tag);
    const lrfnet_proto_BackgroundSnapshot& s = d.payload.background;
    EXPECT_EQ(s.snapshot_id, 0u);
    EXPECT_EQ(s.learned_until_ns, kSentNs - 1);
    EXPECT_EQ(s.first_angle_rad, -1.658);
    EXPECT_EQ(s.angle_step_rad, 0.000727);
    EXPECT_EQ(s.beam_count, 4561u);
    EXPECT_EQ(s.part, p);
    EXPECT_EQ(s.part_count, 12u);
    EXPECT_EQ(s.first_beam, p * kBeamsPerPart);
    for (pb_size_t i = 0; i < s.ranges_mm_count; ++i) mm[s.first_beam + i] = s.ranges_mm[i];
  }
  for (std::size_t i = 0; i < ranges.size(); ++i) {
    ASSERT_EQ(mm[i], static_cast<std::uint32_t>(std::lround(ranges[i] * 1000.0f))) << "beam " << i;
  }
  // The next snapshot has the next id.
  sink.datagrams.clear();
  ASSERT_EQ(encoder.EncodeBackground(view, kSentNs, sink), 12u);
  EXPECT_EQ(Decode(sink.datagrams[0]).payload.background.snapshot_id, 1u);
  EXPECT_EQ(encoder.counters().snapshots, 2u);
  EXPECT_EQ(encoder.counters().snapshot_parts, 24u);
}

TEST(DatagramEncoderTest, WidestSnapshotPartIsExactlyTheBudget) {
  DatagramEncoder encoder(Options(std::string(32, 'x')));
  CollectSink sink;
  std::vector<float> ranges(kBeamsPerPart, 1e6f);  // clamped to kMaxRangeMm: 3 varint bytes each
  BackgroundSnapshotView view;
  view.learned_until_ns = -1;
  view.first_angle_rad = -1.0;
  view.angle_step_rad = 1e-3;
  view.range_m = ranges;
  ASSERT_EQ(encoder.EncodeBackground(view, -1, sink), 1u);
  EXPECT_EQ(encoder.counters().clamped_ranges, kBeamsPerPart);
  lrfnet_proto_Datagram d = Decode(sink.datagrams[0]);
  d.sequence = d.session_id = ~0ull;
  d.payload.background.snapshot_id = d.payload.background.beam_count = ~0u;
  d.payload.background.part = d.payload.background.part_count = ~0u;
  d.payload.background.first_beam = ~0u;
  std::size_t size = 0;
  ASSERT_TRUE(pb_get_encoded_size(&size, lrfnet_proto_Datagram_fields, &d));
  EXPECT_EQ(size, kMaxPayloadBytes);
  RecordProperty("widest_snapshot_part_bytes", static_cast<int>(size));
}

TEST(DatagramEncoderTest, RangesBecomeMillimetresWithFreeBeamsAsZero) {
  DatagramEncoder encoder(Options());
  CollectSink sink;
  const std::vector<float> ranges = {0.0f,
                                     -1.0f,
                                     std::numeric_limits<float>::quiet_NaN(),
                                     std::numeric_limits<float>::infinity(),
                                     0.0004f,
                                     1.2344f,
                                     1.2346f,
                                     80.0f,
                                     1e7f};
  BackgroundSnapshotView view;
  view.range_m = ranges;
  ASSERT_EQ(encoder.EncodeBackground(view, kSentNs, sink), 1u);
  const lrfnet_proto_BackgroundSnapshot s = Decode(sink.datagrams[0]).payload.background;
  ASSERT_EQ(s.ranges_mm_count, ranges.size());
  const std::uint32_t expected[] = {0, 0, 0, 0, 1, 1234, 1235, 80000, kMaxRangeMm};
  for (std::size_t i = 0; i < ranges.size(); ++i) EXPECT_EQ(s.ranges_mm[i], expected[i]) << i;
  EXPECT_EQ(encoder.counters().clamped_ranges, 1u);
}

TEST(DatagramEncoderTest, EmptySnapshotSendsNothingAndKeepsTheId) {
  DatagramEncoder encoder(Options());
  CollectSink sink;
  EXPECT_EQ(encoder.EncodeBackground(BackgroundSnapshotView{}, kSentNs, sink), 0u);
  EXPECT_TRUE(sink.datagrams.empty());
  EXPECT_EQ(encoder.next_snapshot_id(), 0u);
}

TEST(DatagramEncoderTest, HealthRoundTrips) {
  DatagramEncoder encoder(Options());
  CollectSink sink;
  HealthReport h;
  h.scans = 123456;
  h.bad_frames = 2;
  h.decode_errors = 3;
  h.reconnects = 4;
  h.dropped_tracks = 5;
  h.datagrams_sent = 6;
  h.send_errors = 7;
  h.scan_cpu_us_mean = 812.5f;
  h.scan_cpu_us_max = 2048.0f;
  h.clock_sync = ClockSync::kUnsynchronized;
  h.clock_error_estimate_s = 0.016f;
  h.tick_offset_s = 1.7e9 + 0.125;
  h.tick_drift_ppm = -12.5;
  h.device_restarts = 1;
  ASSERT_TRUE(encoder.EncodeHealth(h, kSentNs, sink));
  const lrfnet_proto_Datagram d = Decode(sink.datagrams[0]);
  ASSERT_EQ(d.which_payload, lrfnet_proto_Datagram_health_tag);
  const lrfnet_proto_Health& p = d.payload.health;
  EXPECT_EQ(p.scans, 123456u);
  EXPECT_EQ(p.bad_frames, 2u);
  EXPECT_EQ(p.decode_errors, 3u);
  EXPECT_EQ(p.reconnects, 4u);
  EXPECT_EQ(p.dropped_tracks, 5u);
  EXPECT_EQ(p.datagrams_sent, 6u);
  EXPECT_EQ(p.send_errors, 7u);
  EXPECT_EQ(p.scan_cpu_us_mean, 812.5f);
  EXPECT_EQ(p.scan_cpu_us_max, 2048.0f);
  EXPECT_EQ(p.clock_sync, lrfnet_proto_ClockSyncState_CLOCK_SYNC_UNSYNCHRONIZED);
  EXPECT_EQ(p.clock_error_estimate_s, 0.016f);
  EXPECT_EQ(p.tick_offset_s, 1.7e9 + 0.125);
  EXPECT_EQ(p.tick_drift_ppm, -12.5);
  EXPECT_EQ(p.device_restarts, 1u);
}

TEST(DatagramEncoderTest, SensorInfoStringsAreBoundedAndPrintable) {
  DatagramEncoder encoder(Options());
  CollectSink sink;
  const std::string long_model(100, 'M');
  SensorInfoReport info;
  info.model = long_model;
  info.serial = "18110550";
  info.firmware = "V1.80\x01\xff";
  info.tracker_version = "lrfnet-tracker 0.1.0";
  info.first_angle_rad = -0.087;
  info.angle_step_rad = 0.0029;
  info.beam_count = 1141;
  info.fov_rad = 3.3;
  info.scan_frequency_hz = 25.0;
  info.max_range_m = 80.0;
  info.kind = tracking::MeasurementKind::kEllipse;
  info.mount = tracking::Mount::kLegs;
  info.accel_psd_m2ps3 = 2.0;
  info.max_speed_mps = 6.0;
  ASSERT_TRUE(encoder.EncodeSensorInfo(info, kSentNs, sink));
  const lrfnet_proto_Datagram d = Decode(sink.datagrams[0]);
  ASSERT_EQ(d.which_payload, lrfnet_proto_Datagram_sensor_info_tag);
  const lrfnet_proto_SensorInfo& p = d.payload.sensor_info;
  EXPECT_EQ(std::string(p.model), std::string(64, 'M'));
  EXPECT_STREQ(p.serial, "18110550");
  EXPECT_STREQ(p.firmware, "V1.80??");
  EXPECT_STREQ(p.tracker_version, "lrfnet-tracker 0.1.0");
  EXPECT_EQ(p.first_angle_rad, -0.087);
  EXPECT_EQ(p.angle_step_rad, 0.0029);
  EXPECT_EQ(p.beam_count, 1141u);
  EXPECT_EQ(p.fov_rad, 3.3);
  EXPECT_EQ(p.scan_frequency_hz, 25.0);
  EXPECT_EQ(p.max_range_m, 80.0);
  EXPECT_EQ(p.kind, lrfnet_proto_MeasurementKind_MEASUREMENT_KIND_ELLIPSE);
  EXPECT_EQ(p.mount, lrfnet_proto_MountHeight_MOUNT_HEIGHT_LEGS);
  EXPECT_EQ(p.accel_psd_m2ps3, 2.0);
  EXPECT_EQ(p.max_speed_mps, 6.0);
  EXPECT_EQ(encoder.counters().truncated_strings, 1u);
  EXPECT_LE(sink.datagrams[0].size(), kMaxPayloadBytes);
}

TEST(DatagramEncoderTest, SequenceCountsEveryDatagramOfTheSession) {
  DatagramEncoder encoder(Options());
  CollectSink sink;
  tracking::ScanTracks scan;
  for (std::uint32_t i = 0; i < 20; ++i) ASSERT_TRUE(scan.tracks.push_back(MakeTrack(i)));
  std::vector<float> ranges(500, 3.0f);
  BackgroundSnapshotView view;
  view.range_m = ranges;
  encoder.EncodeTracks(scan, kSentNs, sink);      // 2 parts
  encoder.EncodeHealth({}, kSentNs, sink);        // 1
  encoder.EncodeBackground(view, kSentNs, sink);  // 2 parts
  encoder.EncodeSensorInfo({}, kSentNs, sink);    // 1
  ASSERT_EQ(sink.datagrams.size(), 6u);
  for (std::size_t i = 0; i < sink.datagrams.size(); ++i) {
    const lrfnet_proto_Datagram d = Decode(sink.datagrams[i]);
    EXPECT_EQ(d.sequence, i);
    EXPECT_EQ(d.session_id, 0xC0FFEE1234ull);
  }
  EXPECT_EQ(encoder.next_sequence(), 6u);
  EXPECT_EQ(encoder.counters().datagrams, 6u);
}

TEST(DatagramEncoderTest, FanoutHandsTheSameBytesToEverySink) {
  DatagramFanout fanout;
  CollectSink a, b;
  ASSERT_TRUE(fanout.Add(&a));
  ASSERT_TRUE(fanout.Add(&b));
  EXPECT_FALSE(fanout.Add(nullptr));
  CollectSink c, d;
  EXPECT_TRUE(fanout.Add(&c));
  EXPECT_TRUE(fanout.Add(&d));
  CollectSink e;
  EXPECT_FALSE(fanout.Add(&e));  // capacity 4
  DatagramEncoder encoder(Options());
  encoder.EncodeHealth({}, kSentNs, fanout);
  ASSERT_EQ(a.datagrams.size(), 1u);
  EXPECT_EQ(a.datagrams, b.datagrams);
  EXPECT_EQ(a.datagrams, d.datagrams);
  EXPECT_TRUE(e.datagrams.empty());
}

}  // namespace
}  // namespace lrfnet::io
