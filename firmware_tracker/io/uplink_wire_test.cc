// Wire compatibility: what the tracker's nanopb encoder and recording writer produce, decoded by
// the daemon's libprotobuf classes (lrfnet::proto), and libprotobuf-made requests decoded by the
// tracker.

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "firmware_tracker/io/datagram_encoder.h"
#include "firmware_tracker/io/recording_writer.h"
#include "firmware_tracker/io/request_decoder.h"
#include "lrfnet.pb.h"
#include "tests/support/test_data.h"

namespace lrfnet::io {
namespace {

namespace pb = ::lrfnet::proto;

constexpr common::UtcNs kSentNs = 1'700'000'000'987'654'321;

struct CollectSink final : DatagramSink {
  std::vector<std::string> datagrams;
  void Send(std::span<const std::uint8_t> d, common::UtcNs) override {
    datagrams.emplace_back(reinterpret_cast<const char*>(d.data()), d.size());
  }
};

pb::Datagram Parse(const std::string& bytes) {
  pb::Datagram d;
  EXPECT_TRUE(d.ParseFromString(bytes));
  return d;
}

DatagramEncoderOptions Options(const std::string& id) {
  DatagramEncoderOptions o;
  o.sensor_id = id;
  o.session_id = 0xFEEDFACECAFEBEEFull;
  return o;
}

tracking::TrackReport Track(std::uint32_t id, bool worst_case) {
  tracking::TrackReport t;
  t.track_id = worst_case ? (0xF0000000u | id) : id;
  t.state = worst_case ? tracking::TrackState::kCoasting : tracking::TrackState::kConfirmed;
  t.kind = tracking::MeasurementKind::kEllipse;
  t.x_m = worst_case ? -123.456 : 0.25 * id;
  t.y_m = worst_case ? -123.456 : -1.0 - 0.5 * id;
  t.vx_mps = worst_case ? -1.5 : 0.1 * id;
  t.vy_mps = -1.5;
  for (int r = 0; r < 4; ++r) {
    for (int c = r; c < 4; ++c) t.covariance(r, c) = t.covariance(c, r) = 1e-3 * (1 + 4 * r + c);
  }
  t.age_scans = worst_case ? ~0u : 3 * id;
  t.points = worst_case ? ~0u : 11;
  t.ellipse_yaw_rad = worst_case ? -3.0 : 0.1 * id;
  if (worst_case || id % 3 == 0) {
    // A shape-fit track: the body centre, with the shape state (the largest track on the wire).
    t.kind = tracking::MeasurementKind::kShapeFit;
    t.shape = worst_case ? tracking::ObjectShape::kBox : tracking::ObjectShape::kTorso;
    t.size_major_m = 0.23 + 0.001 * id;
    t.size_minor_m = 0.14;
    t.size_sigma_m = 0.02;
  }
  return t;
}

TEST(UplinkWireTest, TrackFramesParseWithLibprotobuf) {
  DatagramEncoder encoder(Options("hall-north.lms511"));
  CollectSink sink;
  tracking::ScanTracks scan;
  scan.scan_start_ns = kSentNs - 55'000'000;
  scan.scan_period_s = 0.04;
  scan.scan_counter = 4711;
  for (std::uint32_t i = 0; i < 30; ++i) ASSERT_TRUE(scan.tracks.push_back(Track(i, false)));
  scan.tracks[5].kind = tracking::MeasurementKind::kCenterOfMass;
  scan.tracks[6].state = tracking::TrackState::kTentative;
  ASSERT_EQ(encoder.EncodeTracks(scan, kSentNs, sink), 3u);

  std::vector<pb::Track> tracks;
  for (std::size_t p = 0; p < sink.datagrams.size(); ++p) {
    const pb::Datagram d = Parse(sink.datagrams[p]);
    EXPECT_EQ(d.version(), pb::PROTOCOL_VERSION_1);
    EXPECT_EQ(d.sensor_id(), "hall-north.lms511");
    EXPECT_EQ(d.sequence(), p);
    EXPECT_EQ(d.sent_ns(), kSentNs);
    EXPECT_EQ(d.session_id(), 0xFEEDFACECAFEBEEFull);
    ASSERT_EQ(d.payload_case(), pb::Datagram::kTrackFrame);
    const pb::TrackFrame& f = d.track_frame();
    EXPECT_EQ(f.scan_start_ns(), scan.scan_start_ns);
    EXPECT_EQ(f.scan_period_s(), 0.04);
    EXPECT_EQ(f.scan_counter(), 4711u);
    EXPECT_EQ(f.part(), p);
    EXPECT_EQ(f.part_count(), 3u);
    tracks.insert(tracks.end(), f.tracks().begin(), f.tracks().end());
  }
  ASSERT_EQ(tracks.size(), 30u);
  for (std::uint32_t i = 0; i < 30; ++i) {
    SCOPED_TRACE(i);
    const pb::Track& t = tracks[i];
    const tracking::TrackReport& r = scan.tracks[i];
    EXPECT_EQ(t.track_id(), i);
    EXPECT_EQ(t.state(), i == 6 ? pb::TRACK_STATE_TENTATIVE : pb::TRACK_STATE_CONFIRMED);
    EXPECT_EQ(t.kind(), i == 5        ? pb::MEASUREMENT_KIND_CENTER_OF_MASS
                        : i % 3 == 0 ? pb::MEASUREMENT_KIND_SHAPE_FIT
                                     : pb::MEASUREMENT_KIND_ELLIPSE);
    EXPECT_EQ(t.shape(), i % 3 == 0 ? pb::OBJECT_SHAPE_TORSO : pb::OBJECT_SHAPE_UNSPECIFIED);
    EXPECT_EQ(t.size_major_m(), i % 3 == 0 ? static_cast<float>(r.size_major_m) : 0.0f);
    EXPECT_EQ(t.size_minor_m(), i % 3 == 0 ? 0.14f : 0.0f);
    EXPECT_EQ(t.size_sigma_m(), i % 3 == 0 ? 0.02f : 0.0f);
    EXPECT_EQ(t.x_m(), static_cast<float>(r.x_m));
    EXPECT_EQ(t.y_m(), static_cast<float>(r.y_m));
    EXPECT_EQ(t.vx_mps(), static_cast<float>(r.vx_mps));
    EXPECT_EQ(t.vy_mps(), static_cast<float>(r.vy_mps));
    EXPECT_EQ(t.age_scans(), r.age_scans);
    EXPECT_EQ(t.points(), r.points);
    EXPECT_EQ(t.ellipse_yaw_rad(), i == 5 ? 0.0f : static_cast<float>(r.ellipse_yaw_rad));
    // Upper triangle, row-major, as lrfnet.proto documents.
    ASSERT_EQ(t.covariance_size(), 10);
    int k = 0;
    for (int row = 0; row < 4; ++row) {
      for (int col = row; col < 4; ++col) {
        EXPECT_EQ(t.covariance(k++), static_cast<float>(1e-3 * (1 + 4 * row + col)));
      }
    }
  }
}

TEST(UplinkWireTest, ElevenWorstCaseTracksFitAndTwelveDoNot) {
  DatagramEncoder encoder(Options(std::string(32, 's')));
  CollectSink sink;
  tracking::ScanTracks scan;
  scan.scan_start_ns = -1;
  scan.scan_period_s = 1.0 / 7.0;
  scan.scan_counter = ~0u;
  for (std::uint32_t i = 0; i < tracking::kMaxTracks; ++i)
    ASSERT_TRUE(scan.tracks.push_back(Track(i, true)));
  ASSERT_EQ(encoder.EncodeTracks(scan, -1, sink), 6u);
  std::size_t total = 0;
  for (const std::string& bytes : sink.datagrams) {
    EXPECT_LE(bytes.size(), kMaxPayloadBytes);
    total += static_cast<std::size_t>(Parse(bytes).track_frame().tracks_size());
  }
  EXPECT_EQ(total, tracking::kMaxTracks);
  // Widen the header to its limits; 11 tracks still fit the payload budget, a 12th does not.
  pb::Datagram d = Parse(sink.datagrams[0]);
  d.set_sequence(~0ull);
  d.set_session_id(~0ull);
  d.mutable_track_frame()->set_part(~0u);
  d.mutable_track_frame()->set_part_count(~0u);
  ASSERT_EQ(d.track_frame().tracks_size(), 11);
  const std::size_t widest = d.ByteSizeLong();
  EXPECT_LE(widest, kMaxPayloadBytes);
  *d.mutable_track_frame()->add_tracks() = d.track_frame().tracks(0);
  EXPECT_GT(d.ByteSizeLong(), kMaxPayloadBytes);
  RecordProperty("widest_11_track_datagram_bytes", static_cast<int>(widest));
}

TEST(UplinkWireTest, BackgroundSnapshotOf4561BeamsReassembles) {
  DatagramEncoder encoder(Options(std::string(32, 'b')));
  CollectSink sink;
  std::vector<float> ranges(4561);
  for (std::size_t i = 0; i < ranges.size(); ++i) {
    ranges[i] = (i % 13 == 0) ? 0.0f : 0.2f + 0.037f * static_cast<float>(i % 2000);
  }
  BackgroundSnapshotView view;
  view.learned_until_ns = kSentNs - 1;
  view.first_angle_rad = -0.0873;
  view.angle_step_rad = 0.000727;
  view.range_m = ranges;
  ASSERT_EQ(encoder.EncodeBackground(view, kSentNs, sink), 12u);
  std::vector<std::uint32_t> mm(ranges.size(), 0xdeadbeef);
  for (std::size_t p = 0; p < sink.datagrams.size(); ++p) {
    EXPECT_LE(sink.datagrams[p].size(), kMaxPayloadBytes);
    const pb::Datagram d = Parse(sink.datagrams[p]);
    ASSERT_EQ(d.payload_case(), pb::Datagram::kBackground);
    const pb::BackgroundSnapshot& s = d.background();
    EXPECT_EQ(s.snapshot_id(), 0u);
    EXPECT_EQ(s.learned_until_ns(), kSentNs - 1);
    EXPECT_EQ(s.first_angle_rad(), -0.0873);
    EXPECT_EQ(s.angle_step_rad(), 0.000727);
    EXPECT_EQ(s.beam_count(), 4561u);
    EXPECT_EQ(s.part(), p);
    EXPECT_EQ(s.part_count(), 12u);
    for (int i = 0; i < s.ranges_mm_size(); ++i)
      mm.at(s.first_beam() + static_cast<std::uint32_t>(i)) = s.ranges_mm(i);
  }
  for (std::size_t i = 0; i < ranges.size(); ++i) {
    ASSERT_EQ(mm[i], static_cast<std::uint32_t>(std::lround(ranges[i] * 1000.0f))) << "beam " << i;
  }
}

TEST(UplinkWireTest, BeamsPerPartIsTheMostThatFits) {
  DatagramEncoder encoder(Options(std::string(32, 'b')));
  CollectSink sink;
  std::vector<float> ranges(kBeamsPerPart, 5000.0f);  // clamped: every value at its widest
  BackgroundSnapshotView view;
  view.learned_until_ns = -1;
  view.first_angle_rad = 1.0;
  view.angle_step_rad = 1.0;
  view.range_m = ranges;
  ASSERT_EQ(encoder.EncodeBackground(view, -1, sink), 1u);
  pb::Datagram d = Parse(sink.datagrams[0]);
  d.set_sequence(~0ull);
  d.set_session_id(~0ull);
  pb::BackgroundSnapshot* s = d.mutable_background();
  s->set_snapshot_id(~0u);
  s->set_beam_count(~0u);
  s->set_part(~0u);
  s->set_part_count(~0u);
  s->set_first_beam(~0u);
  EXPECT_EQ(d.ByteSizeLong(), kMaxPayloadBytes);
  s->add_ranges_mm(kMaxRangeMm);
  EXPECT_GT(d.ByteSizeLong(), kMaxPayloadBytes);
}

TEST(UplinkWireTest, HealthAndSensorInfoParse) {
  DatagramEncoder encoder(Options("s1"));
  CollectSink sink;
  HealthReport h;
  h.scans = 1ull << 40;
  h.send_errors = 3;
  h.scan_cpu_us_max = 1234.5f;
  h.clock_sync = ClockSync::kReplay;
  h.clock_error_estimate_s = 0.002f;
  h.tick_offset_s = 1'699'999'000.000125;
  h.tick_drift_ppm = 49.75;
  h.device_restarts = 2;
  ASSERT_TRUE(encoder.EncodeHealth(h, kSentNs, sink));
  SensorInfoReport info;
  info.model = "LMS511";
  info.serial = "18110550";
  info.firmware = "V1.80";
  info.tracker_version = "lrfnet-tracker 0.1.0";
  info.first_angle_rad = -0.0873;
  info.angle_step_rad = 0.00291;
  info.beam_count = 1141;
  info.fov_rad = 3.3161;
  info.scan_frequency_hz = 25.0;
  info.max_range_m = 80.0;
  info.kind = tracking::MeasurementKind::kShapeFit;
  info.mount = tracking::Mount::kLegs;
  info.accel_psd_m2ps3 = 0.5;
  info.max_speed_mps = 2.5;
  ASSERT_TRUE(encoder.EncodeSensorInfo(info, kSentNs, sink));

  const pb::Datagram hd = Parse(sink.datagrams[0]);
  ASSERT_EQ(hd.payload_case(), pb::Datagram::kHealth);
  EXPECT_EQ(hd.health().scans(), 1ull << 40);
  EXPECT_EQ(hd.health().send_errors(), 3u);
  EXPECT_EQ(hd.health().scan_cpu_us_max(), 1234.5f);
  EXPECT_EQ(hd.health().clock_sync(), pb::CLOCK_SYNC_REPLAY);
  EXPECT_EQ(hd.health().clock_error_estimate_s(), 0.002f);
  EXPECT_EQ(hd.health().tick_offset_s(), 1'699'999'000.000125);
  EXPECT_EQ(hd.health().tick_drift_ppm(), 49.75);
  EXPECT_EQ(hd.health().device_restarts(), 2u);
  const pb::Datagram sd = Parse(sink.datagrams[1]);
  ASSERT_EQ(sd.payload_case(), pb::Datagram::kSensorInfo);
  EXPECT_EQ(sd.sequence(), 1u);
  EXPECT_EQ(sd.sensor_info().model(), "LMS511");
  EXPECT_EQ(sd.sensor_info().serial(), "18110550");
  EXPECT_EQ(sd.sensor_info().firmware(), "V1.80");
  EXPECT_EQ(sd.sensor_info().tracker_version(), "lrfnet-tracker 0.1.0");
  EXPECT_EQ(sd.sensor_info().beam_count(), 1141u);
  EXPECT_EQ(sd.sensor_info().fov_rad(), 3.3161);
  EXPECT_EQ(sd.sensor_info().scan_frequency_hz(), 25.0);
  EXPECT_EQ(sd.sensor_info().max_range_m(), 80.0);
  EXPECT_EQ(sd.sensor_info().kind(), pb::MEASUREMENT_KIND_SHAPE_FIT);
  EXPECT_EQ(sd.sensor_info().mount(), pb::MOUNT_HEIGHT_LEGS);
  EXPECT_EQ(sd.sensor_info().accel_psd_m2ps3(), 0.5);
  EXPECT_EQ(sd.sensor_info().max_speed_mps(), 2.5);
}

TEST(UplinkWireTest, RecordingReadsBackWithLibprotobuf) {
  const auto path = std::filesystem::temp_directory_path() /
                    ("lrfnet_wire_test_" + std::to_string(::getpid()) + ".rec");
  DatagramEncoder encoder(Options("gate-3"));
  RecordingWriterOptions options;
  options.path = path.string();
  options.writer = "lrfnet-tracker 0.1.0";
  options.source = TrackerRecordSource("gate-3");
  std::vector<common::UtcNs> sent_times;
  {
    RecordingWriter writer(options);
    ASSERT_EQ(writer.Open(kSentNs), std::nullopt);
    tracking::ScanTracks scan;
    for (int k = 0; k < 100; ++k) {
      scan.tracks.clear();
      for (std::uint32_t i = 0; i < static_cast<std::uint32_t>(k % 40); ++i)
        ASSERT_TRUE(scan.tracks.push_back(Track(i, false)));
      scan.scan_counter = static_cast<std::uint32_t>(k);
      const common::UtcNs t = kSentNs + k * 40 * common::kNsPerMs;
      const std::size_t parts = encoder.EncodeTracks(scan, t, writer);
      for (std::size_t p = 0; p < parts; ++p) sent_times.push_back(t);
    }
    ASSERT_EQ(writer.Close(), std::nullopt);
  }
  const std::vector<std::uint8_t> bytes = testing::ReadFileBytes(path.string());
  google::protobuf::io::ArrayInputStream raw(bytes.data(), static_cast<int>(bytes.size()));
  google::protobuf::io::CodedInputStream in(&raw);
  std::vector<pb::RecordEntry> entries;
  for (;;) {
    std::uint32_t size = 0;
    if (!in.ReadVarint32(&size)) break;  // clean end of the stream
    const auto limit = in.PushLimit(static_cast<int>(size));
    pb::RecordEntry e;
    ASSERT_TRUE(e.ParseFromCodedStream(&in));
    ASSERT_TRUE(in.ConsumedEntireMessage());
    in.PopLimit(limit);
    entries.push_back(e);
  }
  EXPECT_EQ(static_cast<std::size_t>(in.CurrentPosition()), bytes.size());
  ASSERT_EQ(entries.size(), sent_times.size() + 1);
  ASSERT_TRUE(entries[0].has_header());
  EXPECT_EQ(entries[0].header().format_version(), 1u);
  EXPECT_EQ(entries[0].header().created_ns(), kSentNs);
  EXPECT_EQ(entries[0].header().writer(), "lrfnet-tracker 0.1.0");
  std::uint64_t expected_sequence = 0;
  for (std::size_t i = 1; i < entries.size(); ++i) {
    EXPECT_FALSE(entries[i].has_header());
    EXPECT_EQ(entries[i].source(), "tracker:gate-3");
    EXPECT_EQ(entries[i].receive_ns(), sent_times[i - 1]);
    const pb::Datagram d = Parse(entries[i].datagram());
    EXPECT_EQ(d.sequence(), expected_sequence++);
    EXPECT_EQ(d.sent_ns(), entries[i].receive_ns());
  }
  std::filesystem::remove(path);
}

TEST(UplinkWireTest, RequestsFromLibprotobufAreAccepted) {
  pb::Datagram request;
  request.set_version(pb::PROTOCOL_VERSION_1);
  request.set_sensor_id("gate-3");
  request.set_sequence(12);
  request.set_sent_ns(kSentNs);
  request.mutable_request()->set_send_background(true);
  const std::string bytes = request.SerializeAsString();
  RequestDecoder decoder("gate-3");
  const DecodedRequest r = decoder.Decode(std::span<const std::uint8_t>(
      reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size()));
  EXPECT_EQ(r.reject, RequestReject::kNone);
  EXPECT_TRUE(r.send_background);
  EXPECT_FALSE(r.send_sensor_info);
  EXPECT_EQ(r.sequence, 12u);
  // And our own encoder's request parses with libprotobuf, byte for byte the same.
  RequestMessage m;
  m.sensor_id = "gate-3";
  m.sequence = 12;
  m.sent_ns = kSentNs;
  m.send_background = true;
  std::vector<std::uint8_t> ours(64);
  ours.resize(EncodeRequest(m, ours));
  EXPECT_EQ(std::string(ours.begin(), ours.end()), bytes);
}

}  // namespace
}  // namespace lrfnet::io
