// Zero heap allocations per scan on the uplink path after start-up (DESIGN.md quality bar): the
// global operator new and (outside sanitizer builds) malloc and friends are replaced with counting
// versions, and thousands of scans go through clock mapping, track-frame encoding, UDP send,
// recording write, request polling, health, sensor info and background snapshots; unsealed, sealed
// (SealingSink, sealed Requests verified) and sealed with encryption.

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <new>
#include <optional>
#include <vector>

#include "firmware_tracker/io/datagram_encoder.h"
#include "firmware_tracker/io/recording_writer.h"
#include "firmware_tracker/io/request_decoder.h"
#include "firmware_tracker/io/sealing_sink.h"
#include "firmware_tracker/io/system_clock.h"
#include "firmware_tracker/io/udp_uplink.h"
#include "firmware_tracker/tracking/clock_mapper.h"
#include "tests/support/alloc_counter.h"
#include "tests/support/udp_peer.h"

namespace lrfnet::io {
namespace {

constexpr char kId[] = "gate-3";

TEST(UplinkAllocTest, CounterSeesAllocations) {
  ::lrfnet::testing::StartCountingAllocations();
  auto* p = new std::vector<int>(100);
  EXPECT_GE(::lrfnet::testing::StopCountingAllocations(), 2u);
  delete p;
  if (::lrfnet::testing::CountsMalloc()) {
    ::lrfnet::testing::StartCountingAllocations();
    void* volatile q = std::malloc(64);
    EXPECT_EQ(::lrfnet::testing::StopCountingAllocations(), 1u);
    std::free(q);
  }
}

enum class Sealing { kNone, kSigned, kEncrypted };

auth::SensorKeys Keys() {
  auth::Key site{};
  site.fill(3);
  return auth::DeriveSensorKeys(auth::DeriveSensorKey(site, kId), 1);
}

std::optional<auth::SensorKeys> KeysFor(Sealing sealing) {
  if (sealing == Sealing::kNone) return std::nullopt;
  return Keys();
}

auth::SealerOptions SealerFor(Sealing sealing, auth::Direction direction) {
  auth::SealerOptions o;
  o.sensor_id = kId;
  o.keys = Keys();
  o.direction = direction;
  o.encrypt = sealing == Sealing::kEncrypted;
  o.salt = 9;
  o.first_counter = static_cast<std::uint64_t>(NowUtcNs());
  return o;
}

struct Path {
  tracking::ClockMapper clock;
  DatagramEncoder encoder;
  UdpUplink uplink;
  RecordingWriter recording;
  DatagramFanout fanout;
  std::optional<SealingSink> sealing;
  tracking::ScanTracks scan;
  std::vector<float> background;
  Path(std::uint16_t port, const std::string& recording_path, Sealing mode)
      : encoder(DatagramEncoderOptions{kId, 42}),
        uplink(UdpUplinkOptions{"127.0.0.1", port, kId, 0, 16, KeysFor(mode)}),
        recording(RecordingWriterOptions{recording_path, "lrfnet-tracker test",
                                         TrackerRecordSource(kId), 64 * 1024, 1.0}),
        background(4561) {
    if (mode != Sealing::kNone)
      sealing.emplace(SealerFor(mode, auth::Direction::kToDaemon), fanout);
  }
  DatagramSink& sink() {
    if (sealing) return *sealing;
    return fanout;
  }
};

class UplinkAllocPathTest : public ::testing::TestWithParam<Sealing> {};

TEST_P(UplinkAllocPathTest, NoHeapAllocationPerScanAfterStart) {
  ASSERT_TRUE(auth::Init());
  const Sealing mode = GetParam();
  // The daemon on loopback: receives the datagrams (drained, not checked) and sends Requests.
  ::lrfnet::testing::LoopbackUdpPeer daemon;
  ASSERT_TRUE(daemon.ok());
  const auto recording_path = std::filesystem::temp_directory_path() /
                              ("lrfnet_uplink_alloc_" + std::to_string(::getpid()) + ".rec");
  auto path = std::make_unique<Path>(daemon.port(), recording_path.string(), mode);  // start-up
  ASSERT_EQ(path->uplink.Open(), std::nullopt);
  ASSERT_EQ(path->recording.Open(NowUtcNs()), std::nullopt);
  ASSERT_TRUE(path->fanout.Add(&path->uplink));
  ASSERT_TRUE(path->fanout.Add(&path->recording));
  for (std::size_t i = 0; i < path->background.size(); ++i)
    path->background[i] = i % 11 == 0 ? 0.0f : 2.0f + 0.001f * static_cast<float>(i);
  // The daemon learns the tracker's address from its first datagram.
  path->encoder.EncodeHealth({}, NowUtcNs(), path->sink());
  {
    std::array<std::uint8_t, 2048> buf{};
    ASSERT_GT(daemon.ReceiveInto(buf, 1000), 0);
  }
  std::array<std::uint8_t, 64> request{};
  RequestMessage m;
  m.sensor_id = kId;
  m.send_background = true;
  m.send_sensor_info = true;
  const std::size_t request_size = EncodeRequest(m, request);
  ASSERT_GT(request_size, 0u);
  // The daemon seals every Request anew (a repeated one would be refused as replayed).
  auth::Sealer daemon_sealer(SealerFor(mode, auth::Direction::kToTracker));
  std::array<std::uint8_t, 64 + auth::kMaxOverheadBytes> sealed_request{};

  constexpr int kScans = 5000;  // 200 s at 25 Hz
  std::size_t requests_answered = 0, snapshots = 0, valid_stamps = 0;
  const common::UtcNs t0 = NowUtcNs();
  for (int k = 0; k < kScans; ++k) {
    if (k == 1) ::lrfnet::testing::StartCountingAllocations();
    Path& p = *path;
    // Scan k of a 25 Hz device whose tick started 1000 s ago, received 1-3 ms after transmission.
    const auto tick =
        static_cast<std::uint32_t>(1'000'000'000u + 40'000u * static_cast<std::uint32_t>(k));
    const common::UtcNs receive = t0 + k * 40 * common::kNsPerMs + (1 + k % 3) * common::kNsPerMs;
    const tracking::ClockMapResult stamp = p.clock.Map(tick, tick + 35'000u, receive);
    valid_stamps += stamp.valid ? 1 : 0;

    p.scan.scan_start_ns = stamp.scan_start_ns;
    p.scan.scan_period_s = 0.04;
    p.scan.scan_counter = static_cast<std::uint32_t>(k);
    p.scan.tracks.clear();
    const int n = k % static_cast<int>(tracking::kMaxTracks + 1);
    for (int i = 0; i < n; ++i) {
      tracking::TrackReport* t = p.scan.tracks.emplace_slot();
      t->track_id = static_cast<std::uint32_t>(i + k);
      t->x_m = std::sin(0.01 * k + i);
      t->y_m = std::cos(0.01 * k + i);
      t->kind =
          i % 2 ? tracking::MeasurementKind::kEllipse : tracking::MeasurementKind::kCenterOfMass;
    }
    // The scan's datagrams in one batch (one sendmmsg), as the tracker node sends them.
    p.sink().BeginBatch();
    p.encoder.EncodeTracks(p.scan, receive, p.sink());

    if (k % 25 == 0) {  // once a second: health and the daemon's requests
      const ClockStatus clock = ReadClockStatus();
      const tracking::ClockMapperStatus mapping = p.clock.status();
      HealthReport h;
      h.scans = static_cast<std::uint64_t>(k);
      h.datagrams_sent = p.uplink.counters().datagrams_sent;
      h.send_errors = p.uplink.counters().send_errors;
      h.clock_sync = clock.sync;
      h.clock_error_estimate_s = static_cast<float>(clock.esterror_s);
      h.tick_offset_s = mapping.offset_s;
      h.tick_drift_ppm = mapping.drift_ppm;
      p.encoder.EncodeHealth(h, receive, p.sink());
      daemon.Drain();
      if (k % 500 == 0) {
        if (mode == Sealing::kNone) {
          daemon.Reply(std::span<const std::uint8_t>(request).first(request_size));
        } else {
          const std::size_t sealed_size = daemon_sealer.Seal(
              std::span<const std::uint8_t>(request).first(request_size), sealed_request);
          daemon.Reply(std::span<const std::uint8_t>(sealed_request).first(sealed_size));
        }
      }
      p.uplink.Poll();
      const PendingRequests pending = p.uplink.TakeRequests();
      if (pending.send_sensor_info) {
        SensorInfoReport info;
        info.model = "LMS511";
        info.serial = "18110550";
        info.firmware = "V1.80";
        info.tracker_version = "test";
        info.beam_count = 4561;
        p.encoder.EncodeSensorInfo(info, receive, p.sink());
        ++requests_answered;
      }
      if (pending.send_background) {
        BackgroundSnapshotView view;
        view.learned_until_ns = receive;
        view.first_angle_rad = -0.0873;
        view.angle_step_rad = 0.000727;
        view.range_m = p.background;
        snapshots += p.encoder.EncodeBackground(view, receive, p.sink()) > 0 ? 1 : 0;
      }
    }
    p.sink().EndBatch();
  }
  EXPECT_EQ(::lrfnet::testing::StopCountingAllocations(), 0u);

  // The run exercised every part of the path.
  const Path& p = *path;
  EXPECT_EQ(valid_stamps, static_cast<std::size_t>(kScans));
  EXPECT_GT(p.encoder.counters().track_parts, static_cast<std::uint64_t>(kScans));
  EXPECT_EQ(p.uplink.counters().datagrams_sent, p.encoder.counters().datagrams);
  EXPECT_GT(p.uplink.counters().batches, static_cast<std::uint64_t>(kScans / 2));  // 2+ a scan
  EXPECT_EQ(p.recording.counters().entries, p.encoder.counters().datagrams);
  EXPECT_GT(p.recording.counters().flushes, 100u);
  EXPECT_EQ(p.recording.counters().write_errors, 0u);
  EXPECT_GE(requests_answered, 5u);
  EXPECT_GE(snapshots, 5u);
  EXPECT_TRUE(p.clock.status().valid);
  if (mode != Sealing::kNone) {
    EXPECT_EQ(p.sealing->counters().sealed, p.encoder.counters().datagrams);
    EXPECT_EQ(p.uplink.request_counters().accepted, p.uplink.counters().received);
  }
  path->recording.Close();
  std::filesystem::remove(recording_path);
}

INSTANTIATE_TEST_SUITE_P(Sealing, UplinkAllocPathTest,
                         ::testing::Values(Sealing::kNone, Sealing::kSigned, Sealing::kEncrypted),
                         [](const ::testing::TestParamInfo<Sealing>& param) {
                           switch (param.param) {
                             case Sealing::kNone:
                               return std::string("Unsealed");
                             case Sealing::kSigned:
                               return std::string("Signed");
                             case Sealing::kEncrypted:
                               return std::string("Encrypted");
                           }
                           return std::string("Unknown");
                         });

}  // namespace
}  // namespace lrfnet::io
