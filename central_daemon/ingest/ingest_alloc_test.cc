// The ingest's per-datagram path allocates nothing once warm (sensor ids of up to 15 bytes: a
// longer id is copied into Disposition::sensor_id and the parsed message, one allocation each):
// the message is parsed into an arena with a preallocated first block and the listener gets a
// reused TrackFrameData.

#include <gtest/gtest.h>

#include <vector>

#include "central_daemon/ingest/ingest.h"
#include "central_daemon/ingest/ingest_test_util.h"
#include "tests/support/alloc_counter.h"

namespace lrfnet::daemon {
namespace {

using testing::Bytes;
using testing::FakeTracker;
using testing::kMs;
using testing::kT0;
using testing::View;

struct CountingListener final : IngestListener {
  std::size_t tracks = 0;
  std::size_t health = 0;
  void OnTrackFrame(const std::string&, const TrackFrameData& f) override {
    tracks += f.tracks.size();
  }
  void OnHealth(const std::string&, const SensorHealth&) override { ++health; }
};

TEST(IngestAllocTest, ValidTrackFramesAndHealthAllocateNothingOnceWarm) {
  std::vector<std::unique_ptr<FakeTracker>> trackers;
  for (int s = 0; s < 10; ++s)
    trackers.push_back(std::make_unique<FakeTracker>("gate-" + std::to_string(s), 1));
  std::vector<Bytes> datagrams;
  std::vector<common::UtcNs> receive;
  for (int scan = 0; scan < 400; ++scan) {
    const common::UtcNs t = kT0 + scan * 40 * kMs;
    const std::size_t tracks = static_cast<std::size_t>(scan * 7 % 40);  // 0 to 3 parts
    for (auto& tracker : trackers) {
      for (Bytes& b : tracker->Tracks(tracks, t - kMs)) {
        datagrams.push_back(std::move(b));
        receive.push_back(t);
      }
      if (scan % 25 == 0) {
        datagrams.push_back(tracker->Health(t - kMs));
        receive.push_back(t);
      }
    }
  }
  CountingListener listener;
  Ingest ingest({}, &listener);
  const std::size_t half = datagrams.size() / 2;
  for (std::size_t i = 0; i < half; ++i) {
    ASSERT_TRUE(ingest.OnDatagram(View(datagrams[i]), "127.0.0.1:40000", receive[i]).accepted);
  }
  const std::size_t tracks_before = listener.tracks, health_before = listener.health;
  ::lrfnet::testing::StartCountingAllocations();
  std::size_t accepted = 0;
  for (std::size_t i = half; i < datagrams.size(); ++i) {
    accepted += ingest.OnDatagram(View(datagrams[i]), "127.0.0.1:40000", receive[i]).accepted;
  }
  const std::size_t allocations = ::lrfnet::testing::StopCountingAllocations();
  EXPECT_EQ(accepted, datagrams.size() - half);
  EXPECT_GT(listener.tracks, tracks_before + 10000);
  EXPECT_GT(listener.health, health_before);
  EXPECT_EQ(allocations, 0u);
}

}  // namespace
}  // namespace lrfnet::daemon
