#include "central_daemon/store/track_store.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <random>
#include <set>
#include <vector>

namespace lrfnet::daemon {
namespace {

using common::kNsPerMs;
using common::kNsPerS;
using common::UtcNs;

constexpr UtcNs kT0 = 1'700'000'000LL * kNsPerS;  // an arbitrary UTC time
constexpr UtcNs kPeriodNs = 20 * kNsPerMs;        // 50 Hz

// Frame k of a 50 Hz stream: scan k starts at kT0 + k * 20 ms and is received 5 ms later, unless
// receive_ns is given. Track ids are first_track_id, first_track_id + 1, ...
TrackFrameData Frame(std::uint32_t k, std::size_t tracks, std::uint64_t session = 1,
                     std::optional<UtcNs> receive_ns = std::nullopt,
                     std::uint32_t first_track_id = 0) {
  TrackFrameData f;
  f.session_id = session;
  f.scan_counter = k;
  f.scan_start_ns = kT0 + static_cast<UtcNs>(k) * kPeriodNs;
  f.scan_period_s = 0.02;
  f.sent_ns = f.scan_start_ns + 2 * kNsPerMs;
  f.receive_ns = receive_ns.value_or(f.scan_start_ns + 5 * kNsPerMs);
  for (std::size_t i = 0; i < tracks; ++i) {
    TrackObservation t;
    t.track_id = first_track_id + static_cast<std::uint32_t>(i);
    t.state = TrackState::kConfirmed;
    t.kind = MeasurementKind::kCenterOfMass;
    t.x_m = static_cast<float>(k) * 0.01f;
    t.y_m = static_cast<float>(i);
    f.tracks.push_back(t);
  }
  return f;
}

TrackFrameData Part(std::uint32_t k, std::uint32_t part, std::uint32_t part_count) {
  TrackFrameData f = Frame(k, 2, 1, std::nullopt, 10 * part);
  f.part = part;
  f.part_count = part_count;
  return f;
}

BackgroundScan Background(std::uint64_t session, std::uint32_t snapshot, std::size_t beams,
                          std::uint32_t range_mm) {
  BackgroundScan b;
  b.session_id = session;
  b.snapshot_id = snapshot;
  b.learned_until_ns = kT0 + snapshot * kNsPerS;
  b.angle_step_rad = 0.01;
  b.ranges_mm.assign(beams, range_mm);
  return b;
}

std::vector<UtcNs> ScanStarts(const std::vector<TrackFrameData>& frames) {
  std::vector<UtcNs> out;
  for (const auto& f : frames) out.push_back(f.scan_start_ns);
  return out;
}

std::multiset<std::uint32_t> TrackIds(const TrackFrameData& f) {
  std::multiset<std::uint32_t> out;
  for (const auto& t : f.tracks) out.insert(t.track_id);
  return out;
}

SensorStoreInfo Info(const TrackStore& store, const std::string& id) {
  for (auto& s : store.Sensors()) {
    if (s.sensor_id == id) return s;
  }
  ADD_FAILURE() << "no sensor " << id;
  return {};
}

constexpr UtcNs kAll = std::numeric_limits<UtcNs>::max();
constexpr UtcNs kNone = std::numeric_limits<UtcNs>::min();

TEST(TrackStoreOptionsTest, Validate) {
  EXPECT_EQ(Validate(TrackStoreOptions{}), std::nullopt);
  for (double age : {0.0, -1.0, std::nan(""), std::numeric_limits<double>::infinity(), 2e9}) {
    TrackStoreOptions o;
    o.max_age_s = age;
    EXPECT_NE(Validate(o), std::nullopt) << age;
  }
  TrackStoreOptions o;
  o.max_bytes = (std::size_t{1} << 20) - 1;
  EXPECT_NE(Validate(o), std::nullopt);
  o.max_bytes = std::size_t{1} << 20;
  EXPECT_EQ(Validate(o), std::nullopt);
}

TEST(TrackStoreTest, ShuffledFramesComeOutInScanOrder) {
  std::vector<std::uint32_t> order(300);
  std::iota(order.begin(), order.end(), 0u);
  std::mt19937 rng(42);
  std::shuffle(order.begin(), order.end(), rng);

  TrackStore store;
  for (std::uint32_t k : order) store.Add("s1", Frame(k, 3));

  const auto frames = store.Query("s1", kNone, kAll);
  ASSERT_EQ(frames.size(), 300u);
  for (std::uint32_t k = 0; k < 300; ++k) {
    EXPECT_EQ(frames[k].scan_counter, k);
    EXPECT_EQ(frames[k].tracks.size(), 3u);
  }
  EXPECT_EQ(store.frames(), 300u);
  EXPECT_EQ(store.counters().frames_added, 300u);
  EXPECT_GT(store.counters().late_inserts, 0u);
  EXPECT_LT(store.counters().late_inserts, 300u);
}

TEST(TrackStoreTest, InOrderFramesAreNotLate) {
  TrackStore store;
  for (std::uint32_t k = 0; k < 10; ++k) store.Add("s1", Frame(k, 1));
  EXPECT_EQ(store.counters().late_inserts, 0u);
  store.Add("s1", Frame(20, 1));
  store.Add("s1", Frame(15, 1));  // reordered datagram
  EXPECT_EQ(store.counters().late_inserts, 1u);
  EXPECT_EQ(ScanStarts(store.Query("s1", kNone, kAll)).back(), kT0 + 20 * kPeriodNs);
}

TEST(TrackStoreTest, SameStartTimeIsOrderedBySessionThenCounter) {
  TrackStore store;
  TrackFrameData a = Frame(7, 1, /*session=*/2);
  TrackFrameData b = Frame(3, 1, /*session=*/1);
  TrackFrameData c = Frame(9, 1, /*session=*/1);
  b.scan_start_ns = c.scan_start_ns = a.scan_start_ns;  // e.g. a restart with a coarse clock
  store.Add("s1", a);
  store.Add("s1", c);
  store.Add("s1", b);
  const auto frames = store.Query("s1", kNone, kAll);
  ASSERT_EQ(frames.size(), 3u);  // three scans, none merged
  EXPECT_EQ(frames[0].session_id, 1u);
  EXPECT_EQ(frames[0].scan_counter, 3u);
  EXPECT_EQ(frames[1].session_id, 1u);
  EXPECT_EQ(frames[1].scan_counter, 9u);
  EXPECT_EQ(frames[2].session_id, 2u);
}

TEST(TrackStoreTest, MergesPartsInAnyOrderAndIgnoresDuplicates) {
  TrackStore store;
  store.Add("s1", Frame(0, 1));
  store.Add("s1", Frame(2, 1));
  for (std::uint32_t part : {2u, 0u, 2u, 1u, 0u}) store.Add("s1", Part(1, part, 3));

  const auto frames = store.Query("s1", kNone, kAll);
  ASSERT_EQ(frames.size(), 3u);
  const TrackFrameData& merged = frames[1];
  EXPECT_EQ(merged.scan_counter, 1u);
  EXPECT_EQ(merged.part, 0u);
  EXPECT_EQ(merged.part_count, 3u);
  EXPECT_EQ(TrackIds(merged), (std::multiset<std::uint32_t>{0, 1, 10, 11, 20, 21}));
  EXPECT_EQ(store.counters().frames_added, 3u);
  EXPECT_EQ(store.counters().parts_merged, 2u);
  EXPECT_EQ(store.counters().duplicate_parts, 2u);
  EXPECT_EQ(Info(store, "s1").tracks, 8u);
  EXPECT_EQ(store.bytes_used(), 2 * TrackStore::FrameBytes(1) + TrackStore::FrameBytes(6));
}

TEST(TrackStoreTest, IncompleteFrameReportsThePartsHeld) {
  TrackStore store;
  store.Add("s1", Part(4, 3, 4));
  store.Add("s1", Part(4, 1, 4));
  const auto frames = store.Query("s1", kNone, kAll);
  ASSERT_EQ(frames.size(), 1u);
  EXPECT_EQ(frames[0].part, 0u);
  EXPECT_EQ(frames[0].part_count, 2u);
  EXPECT_EQ(TrackIds(frames[0]), (std::multiset<std::uint32_t>{10, 11, 30, 31}));
}

TEST(TrackStoreTest, PartsOfDifferentScansAreNotMerged) {
  TrackStore store;
  TrackFrameData other_session = Part(5, 1, 2);
  other_session.session_id = 2;
  TrackFrameData other_start = Part(5, 1, 2);
  other_start.scan_start_ns += 1;
  store.Add("s1", Part(5, 0, 2));
  store.Add("s1", other_session);
  store.Add("s1", other_start);
  store.Add("s2", Part(5, 1, 2));
  EXPECT_EQ(store.Query("s1", kNone, kAll).size(), 3u);
  EXPECT_EQ(store.Query("s2", kNone, kAll).size(), 1u);
  EXPECT_EQ(store.counters().parts_merged, 0u);
}

TEST(TrackStoreTest, RefusesPartsOutsideTheMask) {
  TrackStore store;
  store.Add("s1", Part(0, 2, 2));    // part >= part_count
  store.Add("s1", Part(0, 64, 65));  // beyond the 64 parts the ingest allows
  TrackFrameData none = Part(0, 0, 0);
  store.Add("s1", none);
  EXPECT_EQ(store.counters().refused_parts, 3u);
  EXPECT_EQ(store.frames(), 0u);
  EXPECT_EQ(store.bytes_used(), 0u);
  store.Add("s1", Part(0, 63, 64));
  EXPECT_EQ(store.frames(), 1u);
}

TEST(TrackStoreTest, QueryBoundaries) {
  TrackStore store;
  EXPECT_TRUE(store.Query("s1", kNone, kAll).empty());
  for (std::uint32_t k = 0; k < 10; ++k) store.Add("s1", Frame(k, 1));
  const auto start = [](std::uint32_t k) { return kT0 + static_cast<UtcNs>(k) * kPeriodNs; };

  EXPECT_TRUE(store.Query("nobody", kNone, kAll).empty());
  EXPECT_TRUE(store.Query("s", kNone, kAll).empty());  // a prefix is another sensor
  // [from, to): the start is included, the end is not.
  EXPECT_EQ(ScanStarts(store.Query("s1", start(2), start(5))),
            (std::vector<UtcNs>{start(2), start(3), start(4)}));
  EXPECT_EQ(ScanStarts(store.Query("s1", start(2) + 1, start(5) + 1)),
            (std::vector<UtcNs>{start(3), start(4), start(5)}));
  EXPECT_EQ(ScanStarts(store.Query("s1", start(9), start(9) + 1)), (std::vector<UtcNs>{start(9)}));
  EXPECT_TRUE(store.Query("s1", start(3), start(3)).empty());
  EXPECT_TRUE(store.Query("s1", start(5), start(3)).empty());
  EXPECT_TRUE(store.Query("s1", kNone, start(0)).empty());
  EXPECT_TRUE(store.Query("s1", start(9) + 1, kAll).empty());
  EXPECT_TRUE(store.Query("s1", start(3) + 1, start(4)).empty());  // between two scans
  EXPECT_EQ(store.Query("s1", start(0), start(9) + 1).size(), 10u);
}

TEST(TrackStoreTest, QueryReturnsTheStoredValues) {
  TrackStore store;
  const TrackFrameData in = Frame(3, 2, 77, kT0 + 123);
  store.Add("s1", in);
  const auto out = store.Query("s1", kNone, kAll);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].session_id, 77u);
  EXPECT_EQ(out[0].scan_counter, 3u);
  EXPECT_EQ(out[0].scan_start_ns, in.scan_start_ns);
  EXPECT_EQ(out[0].sent_ns, in.sent_ns);
  EXPECT_EQ(out[0].receive_ns, kT0 + 123);
  EXPECT_DOUBLE_EQ(out[0].scan_period_s, 0.02);
  ASSERT_EQ(out[0].tracks.size(), 2u);
  EXPECT_EQ(out[0].tracks[1].track_id, 1u);
  EXPECT_FLOAT_EQ(out[0].tracks[1].y_m, 1.0f);
  EXPECT_EQ(out[0].tracks[1].state, TrackState::kConfirmed);
}

TEST(TrackStoreTest, SensorsReportsSpanAndSize) {
  TrackStore store;
  EXPECT_TRUE(store.Sensors().empty());
  for (std::uint32_t k = 3; k < 8; ++k) store.Add("zeta", Frame(k, 2));
  store.Add("alpha", Frame(1, 4));
  store.SetBackground("mid", BackgroundScan{});
  const auto sensors = store.Sensors();
  ASSERT_EQ(sensors.size(), 3u);
  EXPECT_EQ(sensors[0].sensor_id, "alpha");
  EXPECT_EQ(sensors[0].frames, 1u);
  EXPECT_EQ(sensors[0].tracks, 4u);
  EXPECT_EQ(sensors[0].first_scan_ns, kT0 + kPeriodNs);
  EXPECT_EQ(sensors[0].last_scan_ns, kT0 + kPeriodNs);
  EXPECT_EQ(sensors[1].sensor_id, "mid");
  EXPECT_EQ(sensors[1].frames, 0u);
  EXPECT_EQ(sensors[1].first_scan_ns, 0);
  EXPECT_EQ(sensors[1].last_scan_ns, 0);
  EXPECT_EQ(sensors[2].sensor_id, "zeta");
  EXPECT_EQ(sensors[2].frames, 5u);
  EXPECT_EQ(sensors[2].tracks, 10u);
  EXPECT_EQ(sensors[2].first_scan_ns, kT0 + 3 * kPeriodNs);
  EXPECT_EQ(sensors[2].last_scan_ns, kT0 + 7 * kPeriodNs);
  EXPECT_EQ(store.frames(), 6u);
}

TEST(TrackStoreTest, EvictsByReceiveAge) {
  TrackStoreOptions o;
  o.max_age_s = 5.0;
  TrackStore store(o);
  // One frame per second of receive time on each of two sensors.
  for (std::uint32_t k = 0; k < 10; ++k) {
    store.Add("a", Frame(k, 1, 1, kT0 + k * kNsPerS));
    store.Add("b", Frame(k, 1, 1, kT0 + k * kNsPerS));
  }
  store.Evict(kT0 + 5 * kNsPerS);  // nothing is older than 5 s
  EXPECT_EQ(store.frames(), 20u);
  store.Evict(kT0 + 10 * kNsPerS);  // receive times 0..4 s are older than 5 s; 5 s is not
  EXPECT_EQ(store.frames(), 10u);
  EXPECT_EQ(store.counters().evicted_by_age, 10u);
  EXPECT_EQ(Info(store, "a").first_scan_ns, kT0 + 5 * kPeriodNs);
  EXPECT_EQ(Info(store, "b").first_scan_ns, kT0 + 5 * kPeriodNs);
  EXPECT_EQ(store.bytes_used(), 10 * TrackStore::FrameBytes(1));
  store.Evict(kT0 + 100 * kNsPerS);
  EXPECT_EQ(store.frames(), 0u);
  EXPECT_EQ(store.Sensors().size(), 2u);  // the sensors stay known
  EXPECT_EQ(Info(store, "a").frames, 0u);
}

// A late (reordered) frame is older in scan order but newer in receive order than the frames
// after it: while it is the first frame, they wait for it (documented in the header).
TEST(TrackStoreTest, AgeEvictionWaitsBehindALateFrame) {
  TrackStoreOptions o;
  o.max_age_s = 5.0;
  TrackStore store(o);
  store.Add("s1", Frame(1, 1, 1, kT0 + 1 * kNsPerS));
  store.Add("s1", Frame(3, 1, 1, kT0 + 2 * kNsPerS));
  store.Add("s1", Frame(2, 1, 1, kT0 + 8 * kNsPerS));  // late
  EXPECT_EQ(store.counters().late_inserts, 1u);

  store.Evict(kT0 + 7500 * kNsPerMs);  // cutoff 2.5 s: frame 1 goes; frame 3 waits behind 2
  EXPECT_EQ(store.counters().evicted_by_age, 1u);
  std::vector<std::uint32_t> counters;
  for (const auto& f : store.Query("s1", kNone, kAll)) counters.push_back(f.scan_counter);
  EXPECT_EQ(counters, (std::vector<std::uint32_t>{2, 3}));

  store.Evict(kT0 + 13 * kNsPerS);  // cutoff 8 s: frame 2 is not older than it
  EXPECT_EQ(store.frames(), 2u);
  store.Evict(kT0 + 13 * kNsPerS + 1);  // both go, in scan order
  EXPECT_EQ(store.frames(), 0u);
  EXPECT_EQ(store.counters().evicted_by_age, 3u);
}

TEST(TrackStoreTest, LateFrameBeforeTheFirstHoldsBackAgeEviction) {
  TrackStoreOptions o;
  o.max_age_s = 5.0;
  TrackStore store(o);
  for (std::uint32_t k = 5; k < 10; ++k) store.Add("s1", Frame(k, 1, 1, kT0 + (k - 4) * kNsPerS));
  store.Add("s1", Frame(0, 1, 1, kT0 + 6 * kNsPerS));  // late, now the first frame
  EXPECT_EQ(Info(store, "s1").first_scan_ns, kT0);
  store.Evict(kT0 + 10500 * kNsPerMs);  // frames 5..8 are old, but wait behind frame 0
  EXPECT_EQ(store.frames(), 6u);
  store.Evict(kT0 + 11500 * kNsPerMs);
  EXPECT_EQ(store.frames(), 0u);
  EXPECT_EQ(store.bytes_used(), 0u);
}

// Random scan order, parts, duplicates and three sensors under a small memory limit: the
// accounting matches what a query returns, and evicting everything leaves nothing.
TEST(TrackStoreTest, AccountingStaysConsistentUnderRandomTraffic) {
  TrackStoreOptions o;
  o.max_bytes = std::size_t{1} << 20;
  o.max_age_s = 60.0;
  TrackStore store(o);
  std::mt19937 rng(7);
  const std::vector<std::string> ids = {"a", "b", "c"};
  UtcNs receive_ns = kT0;
  for (int i = 0; i < 20000; ++i) {
    receive_ns += kNsPerMs;
    const std::uint32_t k = static_cast<std::uint32_t>(i / 3) + rng() % 8;  // mostly in order
    const auto part_count = static_cast<std::uint32_t>(1 + rng() % 3);
    TrackFrameData f = Frame(k, rng() % 6, 1, receive_ns);
    f.part_count = part_count;
    f.part = static_cast<std::uint32_t>(rng() % part_count);
    store.Add(ids[rng() % ids.size()], f);
    if (i % 1000 == 0) {
      store.SetBackground(ids[rng() % ids.size()],
                          Background(1, static_cast<std::uint32_t>(i), rng() % 2000, 100));
    }
    if (i % 997 == 0) store.Evict(receive_ns);
  }
  EXPECT_GT(store.counters().evicted_by_memory, 0u);
  EXPECT_GT(store.counters().parts_merged, 0u);
  EXPECT_GT(store.counters().duplicate_parts, 0u);
  EXPECT_GT(store.counters().late_inserts, 0u);

  std::size_t frames = 0, bytes = 0;
  for (const auto& info : store.Sensors()) {
    const auto q = store.Query(info.sensor_id, kNone, kAll);
    std::size_t tracks = 0;
    for (std::size_t j = 0; j < q.size(); ++j) {
      if (j > 0) {
        EXPECT_LT(q[j - 1].scan_start_ns, q[j].scan_start_ns);
      }
      bytes += TrackStore::FrameBytes(q[j].tracks.size());
      tracks += q[j].tracks.size();
    }
    if (const BackgroundScan* bg = store.Background(info.sensor_id)) {
      bytes += TrackStore::BackgroundBytes(bg->ranges_mm.size());
    }
    EXPECT_EQ(info.frames, q.size());
    EXPECT_EQ(info.tracks, tracks);
    frames += q.size();
  }
  EXPECT_EQ(store.frames(), frames);
  EXPECT_EQ(store.bytes_used(), bytes);
  EXPECT_LE(store.bytes_used(), o.max_bytes);
  EXPECT_EQ(store.counters().frames_added,
            frames + store.counters().evicted_by_memory + store.counters().evicted_by_age);

  store.Evict(receive_ns + 61 * kNsPerS);
  EXPECT_EQ(store.frames(), 0u);
  std::size_t background_bytes = 0;
  for (const auto& id : ids) {
    if (const BackgroundScan* bg = store.Background(id)) {
      background_bytes += TrackStore::BackgroundBytes(bg->ranges_mm.size());
    }
  }
  EXPECT_EQ(store.bytes_used(), background_bytes);
}

TEST(TrackStoreTest, MemoryEvictionTakesTheOlderSensorFirst) {
  TrackStoreOptions o;
  o.max_bytes = std::size_t{1} << 20;
  TrackStore store(o);
  const std::size_t fit = o.max_bytes / TrackStore::FrameBytes(5);
  ASSERT_GT(fit, 1500u);
  ASSERT_LT(fit, 3000u);
  // "old" streamed first (receive times 0..1499 ms), then "new" (10 s later).
  for (std::uint32_t k = 0; k < 1500; ++k) store.Add("old", Frame(k, 5, 1, kT0 + k * kNsPerMs));
  EXPECT_EQ(store.counters().evicted_by_memory, 0u);
  for (std::uint32_t k = 0; k < 1500; ++k) {
    store.Add("new", Frame(k, 5, 1, kT0 + 10 * kNsPerS + k * kNsPerMs));
  }
  EXPECT_LE(store.bytes_used(), o.max_bytes);
  EXPECT_EQ(store.frames(), fit);
  EXPECT_EQ(store.counters().evicted_by_memory, 3000u - fit);
  const SensorStoreInfo old_info = Info(store, "old");
  const SensorStoreInfo new_info = Info(store, "new");
  EXPECT_EQ(new_info.frames, 1500u);
  EXPECT_EQ(old_info.frames, fit - 1500u);
  // The old sensor kept its newest frames, without a hole.
  EXPECT_EQ(old_info.last_scan_ns, kT0 + 1499 * kPeriodNs);
  EXPECT_EQ(old_info.first_scan_ns, kT0 + static_cast<UtcNs>(3000u - fit) * kPeriodNs);
}

TEST(TrackStoreTest, MemoryEvictionIsGloballyByReceiveTime) {
  TrackStoreOptions o;
  o.max_bytes = std::size_t{1} << 20;
  TrackStore store(o);
  // Two sensors interleaved; "b" sends three frames for every one of "a". Receive time = add index.
  std::uint32_t ka = 0, kb = 0;
  UtcNs t = kT0;
  for (int i = 0; i < 4000; ++i, t += kNsPerMs) {
    if (i % 4 == 0) {
      store.Add("a", Frame(ka++, 5, 1, t));
    } else {
      store.Add("b", Frame(kb++, 5, 1, t));
    }
  }
  const std::size_t held = store.frames();
  ASSERT_LT(held, 4000u);
  // What is held is exactly the last `held` frames received.
  const UtcNs oldest_kept = t - static_cast<UtcNs>(held) * kNsPerMs;
  for (const char* id : {"a", "b"}) {
    const auto frames = store.Query(id, kNone, kAll);
    ASSERT_FALSE(frames.empty());
    EXPECT_GE(frames.front().receive_ns, oldest_kept) << id;
    EXPECT_LT(frames.front().receive_ns, oldest_kept + 4 * kNsPerMs) << id;
  }
}

TEST(TrackStoreTest, BytesUsedGrowsLinearlyAndReturnsToZero) {
  TrackStore store;
  EXPECT_EQ(store.bytes_used(), 0u);
  const std::size_t per_frame = TrackStore::FrameBytes(5);
  EXPECT_GT(per_frame, 5 * sizeof(TrackObservation) + sizeof(TrackFrameData));
  for (std::uint32_t k = 0; k < 1000; ++k) {
    store.Add(k % 2 ? "a" : "b", Frame(k, 5));
    ASSERT_EQ(store.bytes_used(), (k + 1) * per_frame);
  }
  store.Add("a", Frame(5000, 0));  // an empty scan still costs its record
  EXPECT_EQ(store.bytes_used(), 1000 * per_frame + TrackStore::FrameBytes(0));
  EXPECT_GT(TrackStore::FrameBytes(0), 0u);
  store.Evict(kT0 + 365LL * 24 * 3600 * kNsPerS);
  EXPECT_EQ(store.frames(), 0u);
  EXPECT_EQ(store.bytes_used(), 0u);
}

TEST(TrackStoreTest, BytesUsedFollowsMergesAndEvictionOfMergedFrames) {
  TrackStoreOptions o;
  o.max_age_s = 1.0;
  TrackStore store(o);
  for (std::uint32_t part = 0; part < 4; ++part) store.Add("s1", Part(0, part, 4));
  EXPECT_EQ(store.bytes_used(), TrackStore::FrameBytes(8));
  store.Evict(kT0 + 10 * kNsPerS);
  EXPECT_EQ(store.bytes_used(), 0u);
  EXPECT_EQ(Info(store, "s1").tracks, 0u);
}

TEST(TrackStoreTest, KeepsTheNewestBackgroundPerSensor) {
  TrackStore store;
  EXPECT_EQ(store.Background("s1"), nullptr);
  store.SetBackground("s1", Background(1, 1, 100, 1000));
  store.SetBackground("s2", Background(1, 1, 200, 2000));
  ASSERT_NE(store.Background("s1"), nullptr);
  EXPECT_EQ(store.Background("s1")->ranges_mm.size(), 100u);
  EXPECT_EQ(store.Background("s2")->ranges_mm.front(), 2000u);
  EXPECT_EQ(store.Background("s3"), nullptr);
  EXPECT_EQ(store.bytes_used(),
            TrackStore::BackgroundBytes(100) + TrackStore::BackgroundBytes(200));

  store.SetBackground("s1", Background(1, 2, 150, 1500));  // newer snapshot replaces
  EXPECT_EQ(store.Background("s1")->snapshot_id, 2u);
  EXPECT_EQ(store.Background("s1")->ranges_mm.front(), 1500u);
  store.SetBackground("s1", Background(1, 1, 100, 1000));  // late older snapshot: ignored
  EXPECT_EQ(store.Background("s1")->snapshot_id, 2u);
  EXPECT_EQ(store.counters().stale_backgrounds, 1u);
  store.SetBackground("s1", Background(9, 1, 120, 1200));  // the tracker restarted
  EXPECT_EQ(store.Background("s1")->session_id, 9u);
  EXPECT_EQ(store.bytes_used(),
            TrackStore::BackgroundBytes(120) + TrackStore::BackgroundBytes(200));
  EXPECT_EQ(store.Background("s2")->snapshot_id, 1u);
}

TEST(TrackStoreTest, BackgroundsOutliveFrameEviction) {
  TrackStoreOptions o;
  o.max_age_s = 1.0;
  o.max_bytes = std::size_t{1} << 20;
  TrackStore store(o);
  for (std::uint32_t k = 0; k < 100; ++k) store.Add("s1", Frame(k, 5));
  store.SetBackground("s1", Background(1, 1, 1000, 5000));
  store.Evict(kT0 + 100 * kNsPerS);
  EXPECT_EQ(store.frames(), 0u);
  ASSERT_NE(store.Background("s1"), nullptr);
  EXPECT_EQ(store.bytes_used(), TrackStore::BackgroundBytes(1000));

  // A background larger than the whole budget: every frame goes, the background stays.
  for (std::uint32_t k = 200; k < 300; ++k) store.Add("s1", Frame(k, 5));
  store.SetBackground("s2", Background(1, 1, 300'000, 5000));
  EXPECT_EQ(store.frames(), 0u);
  EXPECT_NE(store.Background("s1"), nullptr);
  EXPECT_NE(store.Background("s2"), nullptr);
  EXPECT_GT(store.bytes_used(), o.max_bytes);
  store.Add("s1", Frame(300, 5));  // cannot fit either
  EXPECT_EQ(store.frames(), 0u);
  EXPECT_EQ(store.counters().evicted_by_memory, 101u);
}

TEST(TrackStoreTest, ReconfigureAppliesTheMemoryLimitAtOnce) {
  TrackStore store;
  for (std::uint32_t k = 0; k < 4000; ++k) store.Add("s1", Frame(k, 5));
  EXPECT_EQ(store.frames(), 4000u);
  TrackStoreOptions o;
  o.max_bytes = std::size_t{1} << 20;
  store.Reconfigure(o);
  EXPECT_EQ(store.options().max_bytes, o.max_bytes);
  EXPECT_LE(store.bytes_used(), o.max_bytes);
  EXPECT_EQ(store.frames(), o.max_bytes / TrackStore::FrameBytes(5));
  EXPECT_EQ(Info(store, "s1").last_scan_ns, kT0 + 3999 * kPeriodNs);  // the newest stay
  o.max_bytes = std::size_t{1} << 30;
  store.Reconfigure(o);  // a larger limit keeps everything
  EXPECT_EQ(store.frames(), (std::size_t{1} << 20) / TrackStore::FrameBytes(5));
}

TEST(TrackStoreTest, ReconfigureAppliesTheAgeLimitFromTheLastEvict) {
  TrackStore store;
  for (std::uint32_t k = 0; k < 10; ++k) store.Add("s1", Frame(k, 1, 1, kT0 + k * kNsPerS));
  TrackStoreOptions o;
  o.max_age_s = 1.0;
  store.Reconfigure(o);  // no Evict yet: no "now" to measure age against
  EXPECT_EQ(store.frames(), 10u);
  o.max_age_s = 100.0;
  store.Reconfigure(o);
  store.Evict(kT0 + 10 * kNsPerS);
  EXPECT_EQ(store.frames(), 10u);
  o.max_age_s = 3.0;
  store.Reconfigure(o);  // now - 3 s = 7 s: 0..6 go
  EXPECT_EQ(store.frames(), 3u);
  EXPECT_EQ(store.counters().evicted_by_age, 7u);
}

TEST(TrackStoreDeathTest, InvalidOptionsAbort) {
  TrackStoreOptions bad;
  bad.max_bytes = 0;
  EXPECT_DEATH(TrackStore{bad}, "");
  TrackStore store;
  EXPECT_DEATH(store.Reconfigure(bad), "");
}

}  // namespace
}  // namespace lrfnet::daemon
