#include "firmware_tracker/app/tracker_node.h"

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <string>

#include "firmware_tracker/app/node_test_util.h"

namespace lrfnet::tracker {
namespace {

using testing::Body;
using testing::CollectingSink;
using testing::SyntheticDevice;
using testing::Wall;

constexpr double kRateHz = 25.0;

TrackerConfig Config() {
  TrackerConfig config;
  config.sensor_id = "test.s1";
  return config;
}

io::ClockStatus ReplayClock() {
  io::ClockStatus clock;
  clock.sync = io::ClockSync::kReplay;
  return clock;
}

// A person walking from (3, -3) to (3, 3) at 1.2 m/s, starting at scan `start`.
Body PersonAt(std::int64_t k, std::int64_t start) {
  const double t = static_cast<double>(k - start) / kRateHz;
  return Body{Eigen::Vector2d(3.0, -3.0 + 1.2 * t), 0.25, 0.15, 0.0};
}

struct NodeRun {
  explicit NodeRun(const TrackerConfig& config = Config()) : node(config, 0xABCDEF, sink) {
    node.SetDeviceIdentity("LMS111", "1234567", "V2.10");
  }
  // Scans [from, to) of the scene; OnTick after every scan, like the binary.
  template <typename Scene>
  void Scans(std::int64_t from, std::int64_t to, Scene scene) {
    for (std::int64_t k = from; k < to; ++k) {
      std::vector<Wall> walls;
      std::vector<Body> bodies;
      scene(k, &walls, &bodies);
      common::UtcNs rx = 0;
      const cola::ScanTelegram& scan = device.Scan(k, walls, bodies, &rx);
      node.OnScan(scan, rx, rx);
      node.RecordScanCpu(100.0 + static_cast<double>(k % 10));
      node.OnTick(rx, LinkHealth{}, ReplayClock());
    }
  }
  SyntheticDevice device;
  CollectingSink sink;
  TrackerNode node;
};

void EmptyRoom(std::int64_t, std::vector<Wall>* walls, std::vector<Body>*) {
  *walls = testing::Room();
}

TEST(TrackerNode, CrossingPersonGivesOneTrackFramesSnapshotInfoAndHealth) {
  NodeRun run;
  constexpr std::int64_t kWalkStart = 150;  // learning takes 5 s = 125 scans
  constexpr std::int64_t kScans = 275;
  run.Scans(0, kScans, [&](std::int64_t k, std::vector<Wall>* walls, std::vector<Body>* bodies) {
    *walls = testing::Room();
    if (k >= kWalkStart) bodies->push_back(PersonAt(k, kWalkStart));
  });
  const CollectingSink& sink = run.sink;
  ASSERT_TRUE(sink.decoded_ok);
  ASSERT_FALSE(sink.datagrams.empty());

  // Every datagram: version, id, session, contiguous sequence, size bound.
  for (std::size_t i = 0; i < sink.datagrams.size(); ++i) {
    const lrfnet_proto_Datagram& d = *sink.datagrams[i];
    EXPECT_EQ(d.version, lrfnet_proto_ProtocolVersion_PROTOCOL_VERSION_1);
    EXPECT_STREQ(d.sensor_id, "test.s1");
    EXPECT_EQ(d.session_id, 0xABCDEFu);
    EXPECT_EQ(d.sequence, i);
    EXPECT_LE(sink.sizes[i], io::kMaxDatagramBytes);
  }

  // Sensor info first (with the first scan), once.
  const lrfnet_proto_Datagram& first = *sink.datagrams[0];
  ASSERT_EQ(first.which_payload, lrfnet_proto_Datagram_sensor_info_tag);
  EXPECT_STREQ(first.payload.sensor_info.model, "LMS111");
  EXPECT_STREQ(first.payload.sensor_info.serial, "1234567");
  EXPECT_EQ(first.payload.sensor_info.beam_count, 541u);
  EXPECT_NEAR(first.payload.sensor_info.fov_rad, common::DegToRad(270.0), 1e-6);
  EXPECT_NEAR(first.payload.sensor_info.first_angle_rad, common::DegToRad(-135.0), 1e-6);
  EXPECT_DOUBLE_EQ(first.payload.sensor_info.scan_frequency_hz, kRateHz);
  EXPECT_EQ(first.payload.sensor_info.kind,
            lrfnet_proto_MeasurementKind_MEASUREMENT_KIND_SHAPE_FIT);
  EXPECT_EQ(first.payload.sensor_info.mount, lrfnet_proto_MountHeight_MOUNT_HEIGHT_TORSO);
  EXPECT_EQ(first.payload.sensor_info.accel_psd_m2ps3, 0.5);
  EXPECT_EQ(first.payload.sensor_info.max_speed_mps, 2.5);
  EXPECT_EQ(sink.Count(lrfnet_proto_Datagram_sensor_info_tag), 1u);

  // One frame per scan; scan starts in gateway UTC within the 1-3 ms network latency of the truth.
  std::map<std::uint32_t, int> scans_with_track;  // track id -> scans
  std::size_t frames = 0;
  double max_error_m = 0.0;
  for (const auto& d : sink.datagrams) {
    if (d->which_payload != lrfnet_proto_Datagram_track_frame_tag) continue;
    const lrfnet_proto_TrackFrame& f = d->payload.track_frame;
    EXPECT_EQ(f.part_count, 1u);
    const std::int64_t k = f.scan_counter - 1;
    ASSERT_EQ(static_cast<std::int64_t>(frames), k);
    ++frames;
    const common::DurationNs error_ns = f.scan_start_ns - run.device.TrueStartNs(k);
    EXPECT_GE(error_ns, 0);
    EXPECT_LE(error_ns, 3 * common::kNsPerMs) << "scan " << k;
    EXPECT_DOUBLE_EQ(f.scan_period_s, 1.0 / kRateHz);
    for (pb_size_t i = 0; i < f.tracks_count; ++i) {
      const lrfnet_proto_Track& t = f.tracks[i];
      ++scans_with_track[t.track_id];
      ASSERT_GE(k, 150);
      const Body truth = PersonAt(k, 150);
      max_error_m = std::max(max_error_m, std::hypot(t.x_m - truth.centre_m.x(),
                                                     t.y_m - truth.centre_m.y()));
      EXPECT_EQ(t.covariance_count, 10u);
    }
  }
  EXPECT_EQ(frames, static_cast<std::size_t>(kScans));
  ASSERT_EQ(scans_with_track.size(), 1u) << "one person, one id";
  EXPECT_GT(scans_with_track.begin()->second, 100);
  EXPECT_LT(max_error_m, 0.15);

  // One snapshot (two parts for 541 beams), after learning, matching the walls.
  ASSERT_EQ(sink.Count(lrfnet_proto_Datagram_background_tag), 2u);
  for (const auto& d : sink.datagrams) {
    if (d->which_payload != lrfnet_proto_Datagram_background_tag) continue;
    const lrfnet_proto_BackgroundSnapshot& b = d->payload.background;
    EXPECT_EQ(b.beam_count, 541u);
    EXPECT_EQ(b.part_count, 2u);
    EXPECT_EQ(b.snapshot_id, 0u);
    EXPECT_NEAR(b.first_angle_rad, common::DegToRad(-135.0), 1e-6);
    // Beam 270 looks straight ahead at the front wall 8 m away.
    if (b.first_beam <= 270 && 270 < b.first_beam + b.ranges_mm_count) {
      EXPECT_NEAR(b.ranges_mm[270 - b.first_beam], 8000.0, 50.0);
    }
    EXPECT_GE(b.learned_until_ns, run.device.TrueStartNs(124));
  }

  // Health: at the first tick and then once per second of scan time, replay clock.
  const std::size_t healths = sink.Count(lrfnet_proto_Datagram_health_tag);
  EXPECT_GE(healths, 10u);
  EXPECT_LE(healths, 12u);
  for (const auto& d : sink.datagrams) {
    if (d->which_payload != lrfnet_proto_Datagram_health_tag) continue;
    EXPECT_EQ(d->payload.health.clock_sync, lrfnet_proto_ClockSyncState_CLOCK_SYNC_REPLAY);
    if (d->payload.health.scans > 30) {
      EXPECT_GE(d->payload.health.scan_cpu_us_mean, 100.0f);
      EXPECT_LE(d->payload.health.scan_cpu_us_max, 109.0f);
      EXPECT_NEAR(d->payload.health.tick_offset_s, 1.6e9 - 10.0, 0.01);
    }
  }
}

TEST(TrackerNode, RequestsAreServedWithTheNextScan) {
  NodeRun run;
  run.Scans(0, 140, EmptyRoom);
  run.sink.Clear();
  run.node.RequestSensorInfo();
  run.node.RequestBackground();
  run.Scans(140, 141, EmptyRoom);
  EXPECT_EQ(run.sink.Count(lrfnet_proto_Datagram_sensor_info_tag), 1u);
  EXPECT_EQ(run.sink.Count(lrfnet_proto_Datagram_background_tag), 2u);
  run.sink.Clear();
  run.Scans(141, 160, EmptyRoom);
  EXPECT_EQ(run.sink.Count(lrfnet_proto_Datagram_sensor_info_tag), 0u);
  EXPECT_EQ(run.sink.Count(lrfnet_proto_Datagram_background_tag), 0u);
}

TEST(TrackerNode, BackgroundBeforeLearningIsNotSent) {
  NodeRun run;
  run.node.RequestBackground();
  run.Scans(0, 100, EmptyRoom);
  EXPECT_EQ(run.sink.Count(lrfnet_proto_Datagram_background_tag), 0u);
  EXPECT_EQ(run.sink.Count(lrfnet_proto_Datagram_track_frame_tag), 100u);
}

TEST(TrackerNode, ChangedBackgroundIsSentAgainUnchangedIsNot) {
  NodeRun run;
  // A panel 2 m wide in front of the far wall while learning; it swings away at scan 150.
  const auto scene = [](std::int64_t k, std::vector<Wall>* walls, std::vector<Body>*) {
    *walls = testing::Room();
    if (k < 150) walls->push_back(Wall{{6.0, -4.0}, {6.0, -2.0}});
  };
  run.Scans(0, 150, scene);
  EXPECT_EQ(run.sink.Count(lrfnet_proto_Datagram_background_tag), 2u);
  run.sink.Clear();
  run.Scans(150, 400, scene);  // recede_after_s = 2 s, then the change is published
  ASSERT_EQ(run.sink.Count(lrfnet_proto_Datagram_background_tag), 2u);
  for (const auto& d : run.sink.datagrams) {
    if (d->which_payload != lrfnet_proto_Datagram_background_tag) continue;
    EXPECT_EQ(d->payload.background.snapshot_id, 1u);
    const lrfnet_proto_BackgroundSnapshot& b = d->payload.background;
    // The beam at -26 deg now reaches the front wall at x = 8 m (was the panel at x = 6 m).
    const std::uint32_t beam = static_cast<std::uint32_t>((-26.0 + 135.0) / 0.5);
    if (b.first_beam <= beam && beam < b.first_beam + b.ranges_mm_count) {
      EXPECT_NEAR(b.ranges_mm[beam - b.first_beam], 8000.0 / std::cos(common::DegToRad(26.0)),
                  60.0);
    }
  }
  // Nothing changes for the next 20 s: no snapshot before snapshot_period_s (30 s).
  run.sink.Clear();
  run.Scans(400, 900, scene);
  EXPECT_EQ(run.sink.Count(lrfnet_proto_Datagram_background_tag), 0u);
  EXPECT_EQ(run.node.counters().snapshots, 2u);
}

// Every datagram of a scan (track frame, background snapshot, sensor info) goes to the sink in one
// batch per scan (one sendmmsg on the UDP uplink); health, from OnTick, on its own.
TEST(TrackerNode, ScanDatagramsGoToTheSinkInOneBatch) {
  NodeRun run;
  run.Scans(0, 150, EmptyRoom);
  EXPECT_EQ(run.sink.batches, 150u);
  EXPECT_FALSE(run.sink.batch_open);
  ASSERT_EQ(run.sink.in_batch.size(), run.sink.datagrams.size());
  std::size_t batched = 0;
  for (std::size_t i = 0; i < run.sink.datagrams.size(); ++i) {
    const bool health = run.sink.datagrams[i]->which_payload == lrfnet_proto_Datagram_health_tag;
    EXPECT_EQ(run.sink.in_batch[i], !health) << i;
    batched += run.sink.in_batch[i] ? 1 : 0;
  }
  // 150 frames, the background's first snapshot (two parts) and the sensor info.
  EXPECT_EQ(batched, 150u + 2u + 1u);
}

TEST(TrackerNode, PeriodicSnapshotWithoutChange) {
  TrackerConfig config = Config();
  config.publish.snapshot_period_s = 4.0;
  NodeRun run(config);
  run.Scans(0, 125 + 4 * 25 * 3 + 10, EmptyRoom);
  EXPECT_EQ(run.node.counters().snapshots, 4u);
}

TEST(TrackerNode, FrameDecimation) {
  TrackerConfig config = Config();
  config.publish.frame_every_n_scans = 5;
  NodeRun run(config);
  run.Scans(0, 100, EmptyRoom);
  EXPECT_EQ(run.sink.Count(lrfnet_proto_Datagram_track_frame_tag), 20u);
}

TEST(TrackerNode, ScanWithoutDistanceChannelIsCountedNotTracked) {
  NodeRun run;
  run.Scans(0, 10, EmptyRoom);
  cola::ScanTelegram& t = run.device.telegram();
  t.channels16[0].name = {'R', 'S', 'S', 'I', '1', '\0'};
  run.node.OnScan(t, run.device.TrueStartNs(10) + 5'000'000, run.device.TrueStartNs(10) + 5'000'000);
  EXPECT_EQ(run.node.counters().unusable_scans, 1u);
  EXPECT_EQ(run.node.counters().frames, 10u);
}

TEST(TrackerNode, IdentityChangeResendsSensorInfo) {
  NodeRun run;
  run.Scans(0, 5, EmptyRoom);
  run.node.SetDeviceIdentity("LMS111", "1234567", "V2.10");  // unchanged
  run.Scans(5, 10, EmptyRoom);
  EXPECT_EQ(run.sink.Count(lrfnet_proto_Datagram_sensor_info_tag), 1u);
  run.node.SetDeviceIdentity("LMS111", "7654321", "V2.10");  // a swapped device
  run.Scans(10, 11, EmptyRoom);
  EXPECT_EQ(run.sink.Count(lrfnet_proto_Datagram_sensor_info_tag), 2u);
}

// ShapeOptions::mixed_leg_max_gap_m: an LMS5xx resolves echoes more than ~0.5 m apart, so its
// node takes no mixed pixel over a wider gap whatever the configuration says; an LMS1xx or a TiM
// keeps the configured gap, also after an LMS5xx was swapped for one.
TEST(TrackerNode, AnLms5xxCapsTheMixedLegGapAtItsEchoSeparation) {
  TrackerConfig config = Config();
  config.tracking.shape.mixed_leg_max_gap_m = 1.5;
  NodeRun run(config);
  const auto gap = [&] { return run.node.pipeline().options().shape.mixed_leg_max_gap_m; };
  EXPECT_EQ(gap(), 1.5);  // LMS111
  run.node.SetDeviceIdentity("LMS511-10100", "1234567", "V1.80");
  EXPECT_EQ(gap(), 0.5);
  run.node.SetDeviceIdentity("TiM781-2174101", "1234567", "V3.13");
  EXPECT_EQ(gap(), 1.5);
  config.tracking.shape.mixed_leg_max_gap_m = 0.3;  // narrower than the echo separation
  NodeRun narrow(config);
  narrow.node.SetDeviceIdentity("LMS511-10100", "1234567", "V1.80");
  EXPECT_EQ(narrow.node.pipeline().options().shape.mixed_leg_max_gap_m, 0.3);
  EXPECT_EQ(tracking::ResolvedEchoSeparationM("LMS511-10100"), 0.5);
  EXPECT_EQ(tracking::ResolvedEchoSeparationM("LMS111-10100"), 0.0);
  EXPECT_EQ(tracking::ResolvedEchoSeparationM(""), 0.0);
}

}  // namespace
}  // namespace lrfnet::tracker
