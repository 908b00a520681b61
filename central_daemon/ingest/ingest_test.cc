#include "central_daemon/ingest/ingest.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <set>
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
using testing::MakeTrack;
using testing::RecordingListener;
using testing::Serialize;
using testing::View;

constexpr char kSource[] = "10.0.0.3:5000";

std::uint64_t Sum(const std::array<std::uint64_t, kRejectReasonCount>& a) {
  return std::accumulate(a.begin(), a.end(), std::uint64_t{0});
}

// The counters add up: every datagram is accepted or rejected once, and every rejection is counted
// either unattributed or at exactly one sensor.
void ExpectCountersAddUp(const Ingest& ingest) {
  const IngestCounters& c = ingest.counters();
  EXPECT_EQ(c.accepted + c.rejected, c.datagrams);
  std::uint64_t sensor_rejected = 0, sensor_datagrams = 0, sensor_received = 0;
  for (const SensorStatus& s : ingest.Sensors()) {
    sensor_rejected += Sum(s.counters.rejected);
    sensor_datagrams += s.counters.datagrams;
    sensor_received += s.counters.sequence.received;
    EXPECT_EQ(s.counters.datagrams, s.counters.sequence.received + Sum(s.counters.rejected));
    EXPECT_EQ(s.counters.rejected[static_cast<std::size_t>(RejectReason::kDuplicate)],
              s.counters.sequence.duplicates);
  }
  EXPECT_EQ(Sum(c.unattributed) + sensor_rejected, c.rejected);
  EXPECT_EQ(c.datagrams - Sum(c.unattributed), sensor_datagrams);
  EXPECT_EQ(sensor_received, c.accepted);
}

proto::Datagram ParseDatagram(const Bytes& bytes) {
  proto::Datagram d;
  EXPECT_TRUE(d.ParseFromArray(bytes.data(), static_cast<int>(bytes.size())));
  return d;
}

class IngestTest : public ::testing::Test {
 protected:
  IngestTest() : ingest_(std::make_unique<Ingest>(IngestOptions{}, &listener_)) {}
  void Make(const IngestOptions& options) {
    listener_ = {};
    ingest_ = std::make_unique<Ingest>(options, &listener_);
  }
  Disposition Feed(const Bytes& bytes, common::UtcNs receive_ns = kT0,
                   std::string_view source = kSource) {
    return ingest_->OnDatagram(View(bytes), source, receive_ns);
  }
  void FeedAll(const std::vector<Bytes>& all, common::UtcNs receive_ns = kT0) {
    for (const Bytes& b : all) {
      const Disposition d = Feed(b, receive_ns);
      ASSERT_TRUE(d.accepted) << ToString(d.reason) << ": " << d.detail;
    }
  }
  SensorStatus Status(const std::string& id) {
    const auto s = ingest_->Sensor(id);
    EXPECT_TRUE(s.has_value()) << id;
    return s.value_or(SensorStatus{});
  }

  RecordingListener listener_;
  std::unique_ptr<Ingest> ingest_;
};

TEST_F(IngestTest, TrackFramesOfTheEncoderArriveFieldExactly) {
  FakeTracker tracker("hall-north.lms511", 0xFEEDFACECAFEBEEFull);
  const common::UtcNs sent = kT0 - 3 * kMs;
  const std::vector<Bytes> parts = tracker.Tracks(30, sent, 4711);
  ASSERT_EQ(parts.size(), 3u);
  FeedAll(parts);

  ASSERT_EQ(listener_.frames.size(), 3u);
  std::uint32_t next_track = 0;
  for (std::uint32_t p = 0; p < 3; ++p) {
    const auto& [id, f] = listener_.frames[p];
    EXPECT_EQ(id, "hall-north.lms511");
    EXPECT_EQ(f.session_id, 0xFEEDFACECAFEBEEFull);
    EXPECT_EQ(f.scan_start_ns, sent - 30 * kMs);
    EXPECT_EQ(f.scan_period_s, 0.04);
    EXPECT_EQ(f.scan_counter, 4711u);
    EXPECT_EQ(f.part, p);
    EXPECT_EQ(f.part_count, 3u);
    EXPECT_EQ(f.sent_ns, sent);
    EXPECT_EQ(f.receive_ns, kT0);
    for (const TrackObservation& o : f.tracks) {
      SCOPED_TRACE(next_track);
      const tracking::TrackReport r = MakeTrack(next_track++);
      EXPECT_EQ(o.track_id, r.track_id);
      EXPECT_EQ(ToString(o.state), std::string(ToString(static_cast<TrackState>(r.state))));
      EXPECT_EQ(o.kind, r.kind == tracking::MeasurementKind::kEllipse
                            ? MeasurementKind::kEllipse
                            : MeasurementKind::kCenterOfMass);
      EXPECT_EQ(o.x_m, static_cast<float>(r.x_m));
      EXPECT_EQ(o.y_m, static_cast<float>(r.y_m));
      EXPECT_EQ(o.vx_mps, static_cast<float>(r.vx_mps));
      EXPECT_EQ(o.vy_mps, static_cast<float>(r.vy_mps));
      std::size_t k = 0;
      for (int row = 0; row < 4; ++row) {
        for (int col = row; col < 4; ++col) {
          EXPECT_EQ(o.covariance[k++], static_cast<float>(r.covariance(row, col)));
        }
      }
      EXPECT_EQ(o.age_scans, r.age_scans);
      EXPECT_EQ(o.points, r.points);
      EXPECT_EQ(o.ellipse_yaw_rad, r.kind == tracking::MeasurementKind::kEllipse
                                       ? static_cast<float>(r.ellipse_yaw_rad)
                                       : 0.0f);
    }
  }
  EXPECT_EQ(next_track, 30u);
  const SensorStatus s = Status("hall-north.lms511");
  EXPECT_EQ(s.counters.track_frames, 3u);
  EXPECT_EQ(s.counters.sequence.received, 3u);
  EXPECT_EQ(s.session_id, 0xFEEDFACECAFEBEEFull);
  EXPECT_EQ(s.source, kSource);
  EXPECT_EQ(s.first_receive_ns, kT0);
  EXPECT_EQ(listener_.Count(SensorEventKind::kNew), 1u);
  // A scan without tracks still arrives (one empty part).
  FeedAll(tracker.Tracks(0, sent + 40 * kMs));
  ASSERT_EQ(listener_.frames.size(), 4u);
  EXPECT_TRUE(listener_.frames.back().second.tracks.empty());
  ExpectCountersAddUp(*ingest_);
}

TEST_F(IngestTest, TrackStatesMapOneToOne) {
  // The value type's states are in the tracker's order; the test above relies on that.
  EXPECT_STREQ(ToString(static_cast<TrackState>(tracking::TrackState::kTentative)), "tentative");
  EXPECT_STREQ(ToString(static_cast<TrackState>(tracking::TrackState::kConfirmed)), "confirmed");
  EXPECT_STREQ(ToString(static_cast<TrackState>(tracking::TrackState::kCoasting)), "coasting");
}

TEST_F(IngestTest, BackgroundPartsOutOfOrderMakeOneScan) {
  FakeTracker tracker("lms5", 1);
  std::vector<Bytes> parts = tracker.Background(4561, kT0 - kMs);
  ASSERT_EQ(parts.size(), 12u);
  std::reverse(parts.begin(), parts.end());
  std::swap(parts[3], parts[7]);
  for (std::size_t i = 0; i < parts.size(); ++i) {
    ASSERT_TRUE(Feed(parts[i]).accepted);
    EXPECT_EQ(listener_.backgrounds.size(), i + 1 == parts.size() ? 1u : 0u);
  }
  ASSERT_EQ(listener_.backgrounds.size(), 1u);
  const BackgroundScan& b = listener_.backgrounds[0].second;
  EXPECT_EQ(b.session_id, 1u);
  EXPECT_EQ(b.snapshot_id, 0u);
  EXPECT_EQ(b.learned_until_ns, kT0 - kMs - 500 * kMs);
  EXPECT_EQ(b.first_angle_rad, testing::kBackgroundFirstAngleRad);
  EXPECT_EQ(b.angle_step_rad, testing::kBackgroundStepRad);
  ASSERT_EQ(b.ranges_mm.size(), 4561u);
  for (std::size_t i = 0; i < b.ranges_mm.size(); ++i) {
    const float range_m = i % 13 == 0 ? 0.0f : 1.0f + 0.001f * static_cast<float>(i);
    ASSERT_EQ(b.ranges_mm[i], static_cast<std::uint32_t>(std::lround(range_m * 1000.0f))) << i;
  }
  const SensorStatus s = Status("lms5");
  EXPECT_TRUE(s.has_background);
  EXPECT_EQ(s.background_snapshot_id, 0u);
  EXPECT_EQ(s.counters.background_parts, 12u);
  EXPECT_EQ(s.counters.backgrounds_completed, 1u);
  EXPECT_EQ(s.counters.backgrounds_abandoned, 0u);
}

TEST_F(IngestTest, AMissingPartThenANewSnapshotCountsOneAbandoned) {
  FakeTracker tracker("lms5", 1);
  std::vector<Bytes> first = tracker.Background(1000, kT0 - kMs);
  ASSERT_EQ(first.size(), 3u);
  first.erase(first.begin() + 1);
  FeedAll(first);
  EXPECT_TRUE(listener_.backgrounds.empty());
  FeedAll(tracker.Background(1000, kT0));
  ASSERT_EQ(listener_.backgrounds.size(), 1u);
  EXPECT_EQ(listener_.backgrounds[0].second.snapshot_id, 1u);
  const SensorStatus s = Status("lms5");
  EXPECT_EQ(s.counters.backgrounds_abandoned, 1u);
  EXPECT_EQ(s.counters.backgrounds_completed, 1u);
  EXPECT_EQ(s.background_snapshot_id, 1u);
  EXPECT_EQ(s.counters.sequence.lost, 0u);  // the missing part is inside the reorder window
}

TEST_F(IngestTest, HealthAndSensorInfoArriveFieldExactly) {
  FakeTracker tracker("tim-7", 5);
  ASSERT_TRUE(Feed(tracker.Health(kT0 - kMs)).accepted);
  ASSERT_TRUE(Feed(tracker.Info(kT0 - kMs)).accepted);
  ASSERT_EQ(listener_.healths.size(), 1u);
  const SensorHealth& h = listener_.healths[0].second;
  EXPECT_EQ(h.scans, 1234u);
  EXPECT_EQ(h.bad_frames, 2u);
  EXPECT_EQ(h.decode_errors, 3u);
  EXPECT_EQ(h.reconnects, 4u);
  EXPECT_EQ(h.dropped_tracks, 5u);
  EXPECT_EQ(h.datagrams_sent, 6789u);
  EXPECT_EQ(h.send_errors, 7u);
  EXPECT_EQ(h.scan_cpu_us_mean, 812.5f);
  EXPECT_EQ(h.scan_cpu_us_max, 2048.25f);
  EXPECT_EQ(h.clock_sync, ClockSync::kSynchronized);
  EXPECT_EQ(h.clock_error_estimate_s, 0.0015f);
  EXPECT_EQ(h.tick_offset_s, 1234.5678);
  EXPECT_EQ(h.tick_drift_ppm, -12.5);
  EXPECT_EQ(h.device_restarts, 1u);
  EXPECT_EQ(h.sent_ns, kT0 - kMs);
  EXPECT_EQ(h.receive_ns, kT0);
  ASSERT_EQ(listener_.infos.size(), 1u);
  const SensorDescription& i = listener_.infos[0].second;
  EXPECT_EQ(i.model, "TiM781S");
  EXPECT_EQ(i.serial, "18090362");
  EXPECT_EQ(i.firmware, "V2.10");
  EXPECT_EQ(i.first_angle_rad, -2.35619);
  EXPECT_EQ(i.angle_step_rad, 0.00581776);
  EXPECT_EQ(i.beam_count, 811u);
  EXPECT_EQ(i.fov_rad, 4.71239);
  EXPECT_EQ(i.scan_frequency_hz, 15.0);
  EXPECT_EQ(i.max_range_m, 25.0);
  EXPECT_EQ(i.tracker_version, "lrfnet-tracker 0.1.0");
  EXPECT_EQ(i.kind, MeasurementKind::kEllipse);
  const SensorStatus s = Status("tim-7");
  ASSERT_TRUE(s.info.has_value());
  EXPECT_EQ(s.info->model, "TiM781S");
  ASSERT_TRUE(s.health.has_value());
  EXPECT_EQ(s.health->scans, 1234u);
  EXPECT_EQ(s.counters.health, 1u);
  EXPECT_EQ(s.counters.sensor_info, 1u);
}

TEST_F(IngestTest, EveryRejectReasonIsCountedWhereItBelongs) {
  IngestOptions options;
  options.max_sensors = 2;
  Make(options);
  FakeTracker tracker("gate-3", 11);
  FakeTracker other("gate-4", 12);
  const common::UtcNs sent = kT0 - kMs;
  const Bytes frame = tracker.Tracks(3, sent).at(0);
  const Bytes background = tracker.Background(300, sent).at(0);
  ASSERT_TRUE(Feed(frame).accepted);
  ASSERT_TRUE(Feed(other.Health(sent)).accepted);

  struct Case {
    RejectReason reason;
    Bytes bytes;
    bool attributed;
  };
  std::vector<Case> cases;
  const auto mutated = [&](const Bytes& base, auto change) {
    proto::Datagram d = ParseDatagram(base);
    d.set_sequence(d.sequence() + 100);  // not a duplicate of the base
    change(d);
    return Serialize(d);
  };
  cases.push_back({RejectReason::kOversize, Bytes(1401, 0x08), false});
  cases.push_back({RejectReason::kEmpty, Bytes{}, false});
  cases.push_back({RejectReason::kMalformed, Bytes{0x12, 0x40, 'g'}, false});
  cases.push_back(
      {RejectReason::kVersion,
       mutated(frame,
               [](proto::Datagram& d) { d.set_version(static_cast<proto::ProtocolVersion>(3)); }),
       true});
  cases.push_back({RejectReason::kVersion,
                   mutated(frame,
                           [](proto::Datagram& d) {
                             d.set_version(proto::PROTOCOL_VERSION_UNSPECIFIED);
                             d.set_sensor_id("gate#3");
                           }),
                   false});
  cases.push_back({RejectReason::kSensorId,
                   mutated(frame, [](proto::Datagram& d) { d.set_sensor_id("gate 3"); }), false});
  cases.push_back({RejectReason::kTooManySensors,
                   mutated(frame, [](proto::Datagram& d) { d.set_sensor_id("gate-5"); }), false});
  cases.push_back({RejectReason::kUnknownKind,
                   mutated(frame, [](proto::Datagram& d) { d.clear_payload(); }), true});
  cases.push_back(
      {RejectReason::kUnexpectedKind,
       mutated(frame, [](proto::Datagram& d) { d.mutable_request()->set_send_sensor_info(true); }),
       true});
  cases.push_back({RejectReason::kNotFinite,
                   mutated(frame,
                           [](proto::Datagram& d) {
                             d.mutable_track_frame()->mutable_tracks(2)->set_vx_mps(std::nanf(""));
                           }),
                   true});
  cases.push_back({RejectReason::kCovariance,
                   mutated(frame,
                           [](proto::Datagram& d) {
                             d.mutable_track_frame()->mutable_tracks(0)->set_covariance(0, -1.0f);
                           }),
                   true});
  cases.push_back({RejectReason::kOutOfRange,
                   mutated(frame,
                           [](proto::Datagram& d) {
                             d.mutable_track_frame()->mutable_tracks(1)->set_x_m(5000.0f);
                           }),
                   true});
  cases.push_back(
      {RejectReason::kPart,
       mutated(background, [](proto::Datagram& d) { d.mutable_background()->set_part(7); }), true});
  cases.push_back({RejectReason::kTimestamp,
                   mutated(frame, [](proto::Datagram& d) { d.set_sent_ns(kT0 + 400 * kS); }),
                   true});
  cases.push_back({RejectReason::kDuplicate, frame, true});

  std::set<RejectReason> seen;
  for (const Case& c : cases) {
    SCOPED_TRACE(ToString(c.reason));
    const IngestCounters before = ingest_->counters();
    const std::uint64_t sensor_before = Sum(Status("gate-3").counters.rejected);
    const Disposition d = Feed(c.bytes);
    EXPECT_FALSE(d.accepted);
    EXPECT_EQ(d.reason, c.reason);
    EXPECT_FALSE(d.detail.empty());
    EXPECT_EQ(d.sensor_id, c.attributed ? "gate-3" : "");
    const std::size_t index = static_cast<std::size_t>(c.reason);
    const SensorStatus s = Status("gate-3");
    if (c.attributed) {
      EXPECT_EQ(s.counters.rejected[index], 1u);
      EXPECT_EQ(Sum(s.counters.rejected), sensor_before + 1);
      EXPECT_EQ(ingest_->counters().unattributed, before.unattributed);
    } else {
      EXPECT_EQ(ingest_->counters().unattributed[index], before.unattributed[index] + 1);
      EXPECT_EQ(Sum(s.counters.rejected), sensor_before);
    }
    EXPECT_EQ(ingest_->counters().rejected, before.rejected + 1);
    seen.insert(c.reason);
    ExpectCountersAddUp(*ingest_);
  }
  // Every reason up to the authentication reasons (auth_ingest_test.cc has those).
  EXPECT_EQ(seen.size(), static_cast<std::size_t>(RejectReason::kUnsigned));
  EXPECT_EQ(Status("gate-3").counters.sequence.duplicates, 1u);
  EXPECT_EQ(ingest_->Sensors().size(), 2u);
  // Nothing rejected reached the listener; the frame accepted first did.
  EXPECT_EQ(listener_.frames.size(), 1u);
  EXPECT_TRUE(listener_.backgrounds.empty());
}

TEST_F(IngestTest, LossReorderingAndDuplicatesAreCountedAndOnlyDuplicatesDropped) {
  IngestOptions options;
  options.reorder_window_datagrams = 4;
  Make(options);
  FakeTracker tracker("gate-3", 1);
  std::vector<Bytes> d;
  for (int i = 0; i < 14; ++i) d.push_back(tracker.Health(kT0 - kMs));
  for (const int i : {0, 1, 2, 5, 6}) ASSERT_TRUE(Feed(d[i]).accepted);
  EXPECT_EQ(Status("gate-3").counters.sequence.lost, 0u);  // 3 and 4 may still arrive
  ASSERT_TRUE(Feed(d[4]).accepted);                        // reordered
  EXPECT_FALSE(Feed(d[4]).accepted);                       // duplicate
  EXPECT_FALSE(Feed(d[1]).accepted);                       // duplicate
  ASSERT_TRUE(Feed(d[9]).accepted);                        // 3 leaves the window: lost
  EXPECT_EQ(Status("gate-3").counters.sequence.lost, 1u);
  ASSERT_TRUE(Feed(d[7]).accepted);   // reordered
  EXPECT_FALSE(Feed(d[3]).accepted);  // too late: dropped, counted as a duplicate
  ASSERT_TRUE(Feed(d[13]).accepted);  // 8 leaves the window; 10 to 12 may still arrive
  const SensorStatus s = Status("gate-3");
  EXPECT_EQ(s.counters.sequence.received, 9u);
  EXPECT_EQ(s.counters.sequence.lost, 2u);  // 3 and 8
  EXPECT_EQ(s.counters.sequence.reordered, 2u);
  EXPECT_EQ(s.counters.sequence.duplicates, 3u);
  EXPECT_EQ(s.counters.rejected[static_cast<std::size_t>(RejectReason::kDuplicate)], 3u);
  EXPECT_EQ(listener_.healths.size(), 9u);
  ExpectCountersAddUp(*ingest_);
}

TEST_F(IngestTest, ARestartStartsTheSessionAgain) {
  FakeTracker before("gate-3", 1);
  FeedAll({before.Info(kT0 - kMs)});
  FeedAll(before.Background(300, kT0 - kMs));
  std::vector<Bytes> incomplete = before.Background(1000, kT0 - kMs);
  FeedAll({incomplete[0]});
  EXPECT_TRUE(ingest_->TakeRequests(kT0).empty());

  FakeTracker after("gate-3", 2);  // new session, sequence from 0 again
  ASSERT_TRUE(Feed(after.Tracks(1, kT0 + kS).at(0), kT0 + kS).accepted);
  EXPECT_EQ(listener_.Count(SensorEventKind::kRestart), 1u);
  EXPECT_EQ(listener_.events.back().sensor_id, "gate-3");
  EXPECT_EQ(listener_.events.back().time_ns, kT0 + kS);
  SensorStatus s = Status("gate-3");
  EXPECT_EQ(s.session_id, 2u);
  EXPECT_EQ(s.counters.sequence.restarts, 1u);
  EXPECT_EQ(s.counters.backgrounds_abandoned, 1u);  // the one in reassembly
  EXPECT_TRUE(s.info.has_value());                  // the last one known, kept for status
  EXPECT_TRUE(s.has_background);
  // The new session lacks info and background: asked for both.
  ASSERT_TRUE(Feed(after.Tracks(1, kT0 + kS).at(0), kT0 + kS).accepted);
  const std::vector<PendingRequest> r = ingest_->TakeRequests(kT0 + kS);
  ASSERT_EQ(r.size(), 1u);
  EXPECT_TRUE(r[0].send_sensor_info);
  EXPECT_TRUE(r[0].send_background);
  EXPECT_EQ(listener_.backgrounds.size(), 1u);
}

TEST_F(IngestTest, ASequenceJumpIsAReset) {
  FakeTracker tracker("gate-3", 1);
  const Bytes first = tracker.Health(kT0 - kMs);
  ASSERT_TRUE(Feed(first).accepted);
  proto::Datagram d = ParseDatagram(tracker.Health(kT0 - kMs));
  d.set_sequence(2'000'000);
  ASSERT_TRUE(Feed(Serialize(d)).accepted);
  EXPECT_EQ(listener_.Count(SensorEventKind::kSequenceReset), 1u);
  d.set_sequence(2'000'001);
  ASSERT_TRUE(Feed(Serialize(d)).accepted);
  const SensorStatus s = Status("gate-3");
  EXPECT_EQ(s.counters.sequence.resets, 1u);
  EXPECT_EQ(s.counters.sequence.lost, 0u);
  EXPECT_EQ(s.counters.sequence.received, 3u);
}

TEST_F(IngestTest, ASilentSensorIsReportedOnceAndComesBack) {
  FakeTracker tracker("gate-3", 1);
  ASSERT_TRUE(Feed(tracker.Health(kT0 - kMs)).accepted);
  ingest_->OnTick(kT0 + 3 * kS);
  EXPECT_EQ(listener_.Count(SensorEventKind::kSilent), 0u);
  ingest_->OnTick(kT0 + 3 * kS + kMs);
  ingest_->OnTick(kT0 + 10 * kS);
  EXPECT_EQ(listener_.Count(SensorEventKind::kSilent), 1u);
  EXPECT_EQ(listener_.events.back().time_ns, kT0 + 3 * kS + kMs);
  SensorStatus s = Status("gate-3");
  EXPECT_TRUE(s.silent);
  EXPECT_EQ(s.counters.silent_periods, 1u);
  EXPECT_TRUE(ingest_->TakeRequests(kT0 + 10 * kS).empty());  // no requests into the void

  ASSERT_TRUE(Feed(tracker.Health(kT0 + 11 * kS), kT0 + 11 * kS).accepted);
  EXPECT_EQ(listener_.Count(SensorEventKind::kBack), 1u);
  EXPECT_FALSE(Status("gate-3").silent);
  EXPECT_EQ(ingest_->TakeRequests(kT0 + 11 * kS).size(), 1u);
  ingest_->OnTick(kT0 + 20 * kS);
  EXPECT_EQ(listener_.Count(SensorEventKind::kSilent), 2u);
  EXPECT_EQ(Status("gate-3").counters.silent_periods, 2u);
}

TEST_F(IngestTest, RequestsAreRateLimitedAndStopOnceInfoAndBackgroundArrived) {
  FakeTracker tracker("gate-3", 1);
  ASSERT_TRUE(Feed(tracker.Tracks(2, kT0 - kMs).at(0), kT0, "10.0.0.3:5000").accepted);
  ASSERT_TRUE(Feed(tracker.Tracks(2, kT0 - kMs).at(0), kT0, "10.0.0.3:5001").accepted);
  std::vector<PendingRequest> r = ingest_->TakeRequests(kT0);
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].sensor_id, "gate-3");
  EXPECT_EQ(r[0].source, "10.0.0.3:5001");  // the newest
  EXPECT_TRUE(r[0].send_sensor_info);
  EXPECT_TRUE(r[0].send_background);
  EXPECT_TRUE(ingest_->TakeRequests(kT0 + 4 * kS).empty());
  ASSERT_TRUE(Feed(tracker.Info(kT0 + 4 * kS), kT0 + 4 * kS).accepted);
  r = ingest_->TakeRequests(kT0 + 5 * kS);
  ASSERT_EQ(r.size(), 1u);
  EXPECT_FALSE(r[0].send_sensor_info);
  EXPECT_TRUE(r[0].send_background);
  FeedAll(tracker.Background(900, kT0 + 5 * kS), kT0 + 5 * kS);
  EXPECT_TRUE(ingest_->TakeRequests(kT0 + 20 * kS).empty());
  EXPECT_EQ(Status("gate-3").counters.requests_sent, 2u);
}

TEST_F(IngestTest, ASensorKnownOnlyFromRejectedDatagramsIsCountedButNotAsked) {
  FakeTracker tracker("gate-3", 1);
  proto::Datagram d = ParseDatagram(tracker.Health(kT0 - kMs));
  d.set_version(static_cast<proto::ProtocolVersion>(2));
  const Disposition disposition = Feed(Serialize(d));
  EXPECT_FALSE(disposition.accepted);
  EXPECT_EQ(disposition.sensor_id, "gate-3");
  EXPECT_EQ(listener_.Count(SensorEventKind::kNew), 1u);
  EXPECT_TRUE(ingest_->TakeRequests(kT0).empty());  // its session (and protocol) are unknown
  EXPECT_EQ(Status("gate-3").counters.rejected[static_cast<std::size_t>(RejectReason::kVersion)],
            1u);
}

TEST_F(IngestTest, SensorsBeyondMaxSensorsAreRefused) {
  IngestOptions options;
  options.max_sensors = 3;
  Make(options);
  for (int i = 0; i < 5; ++i) {
    FakeTracker tracker("s" + std::to_string(i), 1);
    const Disposition d = Feed(tracker.Health(kT0 - kMs));
    EXPECT_EQ(d.accepted, i < 3) << i;
    if (i >= 3) {
      EXPECT_EQ(d.reason, RejectReason::kTooManySensors);
    }
  }
  EXPECT_EQ(ingest_->Sensors().size(), 3u);
  EXPECT_EQ(
      ingest_->counters().unattributed[static_cast<std::size_t>(RejectReason::kTooManySensors)],
      2u);
  // The known ones keep working.
  FakeTracker again("s1", 1);
  (void)again.Health(kT0 - kMs);
  EXPECT_TRUE(Feed(again.Health(kT0 - kMs)).accepted);
  const std::vector<SensorStatus> sensors = ingest_->Sensors();
  EXPECT_EQ(sensors[0].sensor_id, "s0");
  EXPECT_EQ(sensors[2].sensor_id, "s2");
  ExpectCountersAddUp(*ingest_);
}

TEST_F(IngestTest, ReceiveMinusSentIsTheRecentMinimum) {
  FakeTracker tracker("gate-3", 1);
  ASSERT_TRUE(Feed(tracker.Health(kT0 - 2 * kMs), kT0).accepted);
  ASSERT_TRUE(Feed(tracker.Health(kT0 + 100 * kMs - 9 * kMs), kT0 + 100 * kMs).accepted);
  EXPECT_NEAR(Status("gate-3").receive_minus_sent_s, 0.002, 1e-9);
  // Six seconds later only larger values were seen: the old minimum has aged out.
  for (int i = 1; i <= 60; ++i) {
    const common::UtcNs receive = kT0 + i * 100 * kMs;
    ASSERT_TRUE(Feed(tracker.Health(receive - 9 * kMs), receive).accepted);
  }
  EXPECT_NEAR(Status("gate-3").receive_minus_sent_s, 0.009, 1e-9);
  // A gateway clock 2 s ahead gives a negative value.
  const common::UtcNs receive = kT0 + 6100 * kMs;
  ASSERT_TRUE(Feed(tracker.Health(receive + 2 * kS), receive).accepted);
  EXPECT_NEAR(Status("gate-3").receive_minus_sent_s, -2.0, 1e-9);
}

TEST_F(IngestTest, EveryTruncationOfEveryValidDatagramIsRefusedAndHandsNothingOn) {
  FakeTracker tracker("hall-north.lms511", 3);
  std::vector<Bytes> all = tracker.Tracks(40, kT0 - kMs);
  for (const Bytes& b : tracker.Background(900, kT0 - kMs)) all.push_back(b);
  all.push_back(tracker.Health(kT0 - kMs));
  all.push_back(tracker.Info(kT0 - kMs));
  std::size_t prefixes = 0;
  for (const Bytes& full : all) {
    for (std::size_t n = 0; n < full.size(); ++n) {
      const Disposition d = ingest_->OnDatagram(std::span(full.data(), n), kSource, kT0);
      ASSERT_FALSE(d.accepted) << n << " of " << full.size();
      ++prefixes;
    }
  }
  EXPECT_GT(prefixes, 5000u);
  EXPECT_TRUE(listener_.frames.empty());
  EXPECT_TRUE(listener_.backgrounds.empty());
  EXPECT_TRUE(listener_.healths.empty());
  EXPECT_TRUE(listener_.infos.empty());
  EXPECT_EQ(ingest_->counters().accepted, 0u);
  // The whole datagrams are accepted afterwards: the truncations left no state behind.
  FeedAll(all);
  EXPECT_EQ(listener_.backgrounds.size(), 1u);
  ExpectCountersAddUp(*ingest_);
}

TEST_F(IngestTest, ReconfigureChangesValidationButNotTheTableSize) {
  IngestOptions options;
  options.max_sensors = 1;
  Make(options);
  FakeTracker tracker("gate-3", 1);
  ASSERT_TRUE(Feed(tracker.Tracks(3, kT0 - kMs).at(0)).accepted);
  IngestOptions stricter;
  stricter.max_sensors = 100;
  stricter.validation.max_position_m = 1.5;  // MakeTrack(0) is at y = -2 m
  stricter.silent_after_s = 1.0;
  ingest_->Reconfigure(stricter);
  const Disposition d = Feed(tracker.Tracks(3, kT0 - kMs).at(0));
  EXPECT_EQ(d.reason, RejectReason::kOutOfRange);
  FakeTracker other("gate-4", 1);
  EXPECT_EQ(Feed(other.Health(kT0 - kMs)).reason, RejectReason::kTooManySensors);
  ingest_->OnTick(kT0 + 1100 * kMs);
  EXPECT_TRUE(Status("gate-3").silent);
}

TEST(IngestOptionsTest, DefaultsAreValidAndBoundsAreChecked) {
  EXPECT_EQ(Validate(IngestOptions{}), std::nullopt);
  IngestOptions o;
  o.reorder_window_datagrams = 65537;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.max_sensors = 0;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.silent_after_s = 0.0;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.request_interval_s = std::numeric_limits<double>::infinity();
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.max_sequence_jump = 10;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.validation.max_speed_mps = -1.0;
  EXPECT_NE(Validate(o), std::nullopt);
}

TEST(IngestNamesTest, EveryReasonAndEventHasItsDocumentedName) {
  const char* expected[] = {"oversize",     "empty",           "malformed",
                            "version",      "sensor_id",       "too_many_sensors",
                            "unknown_kind", "unexpected_kind", "not_finite",
                            "covariance",   "out_of_range",    "part",
                            "timestamp",    "duplicate",       "unsigned",
                            "auth_header",  "unknown_sensor",  "wrong_epoch",
                            "wrong_key",    "replayed",        "stale",
                            "bad_tag",      "encrypted",       "auth_mismatch"};
  ASSERT_EQ(std::size(expected), kRejectReasonCount);
  for (std::size_t i = 0; i < kRejectReasonCount; ++i) {
    EXPECT_STREQ(ToString(static_cast<RejectReason>(i)), expected[i]);
  }
  EXPECT_STREQ(ToString(SensorEventKind::kSequenceReset), "sequence_reset");
  EXPECT_STREQ(ToString(ClockSync::kReplay), "replay");
  EXPECT_STREQ(ToString(MeasurementKind::kCenterOfMass), "center_of_mass");
}

}  // namespace
}  // namespace lrfnet::daemon
