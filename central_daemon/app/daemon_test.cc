#include "central_daemon/app/daemon.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "firmware_tracker/io/datagram_encoder.h"
#include "lrfnet.pb.h"

namespace lrfnet::daemon {
namespace {

constexpr common::UtcNs kT0 = 1'700'000'000'000'000'000;
constexpr common::DurationNs kMs = 1'000'000;

struct Datagram {
  std::vector<std::uint8_t> bytes;
  common::UtcNs sent_ns;
};

// Collects what a real tracker encoder sends.
struct Collect final : io::DatagramSink {
  std::vector<Datagram> out;
  void Send(std::span<const std::uint8_t> d, common::UtcNs t) override {
    out.push_back({{d.begin(), d.end()}, t});
  }
};

struct Recorded {
  std::vector<std::uint8_t> bytes;
  std::string source;
  common::UtcNs receive_ns;
};
struct FakeRecorder final : RecordSink {
  std::vector<Recorded> entries;
  std::vector<common::UtcNs> flush_checks;
  void Record(std::span<const std::uint8_t> d, std::string_view s, common::UtcNs t) override {
    entries.push_back({{d.begin(), d.end()}, std::string(s), t});
  }
  void FlushIfDue(common::UtcNs t) override { flush_checks.push_back(t); }
};
struct FakeReplies final : RequestSink {
  std::vector<std::pair<std::string, proto::Datagram>> sent;
  bool SendTo(std::string_view source, std::span<const std::uint8_t> d) override {
    proto::Datagram m;
    EXPECT_TRUE(m.ParseFromArray(d.data(), static_cast<int>(d.size())));
    sent.emplace_back(std::string(source), m);
    return true;
  }
};

tracking::ScanTracks Scan(std::uint32_t counter, int tracks) {
  tracking::ScanTracks scan;
  scan.scan_start_ns = kT0 + counter * 40 * kMs;
  scan.scan_period_s = 0.04;
  scan.scan_counter = counter;
  for (int i = 0; i < tracks; ++i) {
    tracking::TrackReport* t = scan.tracks.emplace_slot();
    t->track_id = static_cast<std::uint32_t>(i + 1);
    t->state = tracking::TrackState::kConfirmed;
    t->x_m = 1.0 + i;
    t->y_m = -2.0;
    t->covariance = Eigen::Matrix4d::Identity() * 0.01;
  }
  return scan;
}

TEST(DaemonTest, RecordsEverythingStoresValidFramesAndAsksForWhatIsMissing) {
  FakeRecorder recorder;
  FakeReplies replies;
  DaemonOptions options;
  Daemon daemon(options, &recorder, &replies, 42);

  io::DatagramEncoder encoder({"hall-1", 7});
  Collect c;
  for (std::uint32_t i = 0; i < 50; ++i) encoder.EncodeTracks(Scan(i, 3), kT0 + i * 40 * kMs + kMs, c);
  const std::vector<std::uint8_t> garbage = {0xff, 0x00, 0x13, 0x37};
  for (std::size_t i = 0; i < c.out.size(); ++i) {
    daemon.OnDatagram(c.out[i].bytes, "10.0.0.5:40000", c.out[i].sent_ns + 2 * kMs);
    if (i == 10) daemon.OnDatagram(garbage, "10.0.0.9:1", c.out[i].sent_ns + 2 * kMs);
  }
  // Every datagram recorded as received, the invalid one included, in order.
  ASSERT_EQ(recorder.entries.size(), c.out.size() + 1);
  EXPECT_EQ(recorder.entries[11].bytes, garbage);
  EXPECT_EQ(recorder.entries[0].source, "10.0.0.5:40000");
  EXPECT_EQ(recorder.entries[0].bytes, c.out[0].bytes);
  // Valid frames reach the store.
  EXPECT_EQ(daemon.store().frames(), 50u);
  const auto frames = daemon.store().Query("hall-1", kT0, kT0 + 10 * 40 * kMs);
  ASSERT_EQ(frames.size(), 10u);
  EXPECT_EQ(frames[3].tracks.size(), 3u);
  EXPECT_FLOAT_EQ(frames[3].tracks[2].x_m, 3.0f);
  EXPECT_EQ(daemon.ingest().counters().rejected, 1u);

  // No SensorInfo and no background yet: the tick asks the tracker at its source.
  daemon.OnTick(c.out.back().sent_ns + 10 * kMs);
  ASSERT_EQ(replies.sent.size(), 1u);
  EXPECT_EQ(replies.sent[0].first, "10.0.0.5:40000");
  const proto::Datagram& request = replies.sent[0].second;
  EXPECT_EQ(request.version(), proto::PROTOCOL_VERSION_1);
  EXPECT_EQ(request.sensor_id(), "hall-1");
  EXPECT_EQ(request.session_id(), 42u);
  ASSERT_TRUE(request.has_request());
  EXPECT_TRUE(request.request().send_sensor_info());
  EXPECT_TRUE(request.request().send_background());
  EXPECT_EQ(daemon.requests_sent(), 1u);
  EXPECT_FALSE(recorder.flush_checks.empty());

  // The requests are answered: no further request.
  Collect answers;
  encoder.EncodeSensorInfo({"LMS511", "123", "V1", -1.0, 0.01, 200, 2.0, 25.0, 80.0, "0.1",
                            tracking::MeasurementKind::kEllipse},
                           kT0 + 3'000 * kMs, answers);
  const std::vector<float> ranges(300, 5.0f);
  encoder.EncodeBackground({kT0 + 2'900 * kMs, -1.0, 0.01, ranges}, kT0 + 3'000 * kMs, answers);
  for (const Datagram& d : answers.out) daemon.OnDatagram(d.bytes, "10.0.0.5:40000", d.sent_ns);
  daemon.OnTick(kT0 + 20'000 * kMs);
  EXPECT_EQ(replies.sent.size(), 1u);
  ASSERT_NE(daemon.store().Background("hall-1"), nullptr);
  EXPECT_EQ(daemon.store().Background("hall-1")->ranges_mm.size(), 300u);
}

TEST(DaemonTest, StatusLineShowsSensorsRatesLossAndClock) {
  Daemon daemon(DaemonOptions{}, nullptr, nullptr, 1);
  io::DatagramEncoder encoder({"corridor", 9});
  Collect c;
  for (std::uint32_t i = 0; i < 100; ++i) encoder.EncodeTracks(Scan(i, 1), kT0 + i * 40 * kMs, c);
  daemon.StatusLine(kT0);
  // Every 10th datagram lost on the way.
  for (std::size_t i = 0; i < c.out.size(); ++i) {
    if (i % 10 == 5) continue;
    daemon.OnDatagram(c.out[i].bytes, "[fe80::1]:5000", c.out[i].sent_ns + 3 * kMs);
  }
  const std::string line = daemon.StatusLine(kT0 + 4'000 * kMs);
  EXPECT_NE(line.find("1 sensors (0 silent)"), std::string::npos) << line;
  EXPECT_NE(line.find("22.5 datagrams/s"), std::string::npos) << line;  // 90 in 4 s
  EXPECT_NE(line.find("corridor"), std::string::npos) << line;
  EXPECT_NE(line.find("+3.0ms"), std::string::npos) << line;  // receive - sent
  // The loss shows once the reorder window has passed the gaps; at least the status is sane.
  EXPECT_NE(line.find("loss"), std::string::npos) << line;

  // Silence is reported.
  daemon.OnTick(kT0 + 60'000 * kMs);
  const std::string silent = daemon.StatusLine(kT0 + 61'000 * kMs);
  EXPECT_NE(silent.find("(1 silent)"), std::string::npos) << silent;
  EXPECT_NE(silent.find("corridor SILENT"), std::string::npos) << silent;
  bool saw_silent = false;
  for (const SensorEvent& e : daemon.TakeEvents())
    saw_silent |= e.kind == SensorEventKind::kSilent && e.sensor_id == "corridor";
  EXPECT_TRUE(saw_silent);
}

TEST(DaemonTest, RequestDatagramDecodesAsTheTrackerExpects) {
  PendingRequest r;
  r.sensor_id = "s1";
  r.send_background = true;
  const auto bytes = EncodeRequestDatagram(r, 5, kT0, 77);
  proto::Datagram d;
  ASSERT_TRUE(d.ParseFromArray(bytes.data(), static_cast<int>(bytes.size())));
  EXPECT_EQ(d.sequence(), 5u);
  EXPECT_EQ(d.sent_ns(), kT0);
  EXPECT_FALSE(d.request().send_sensor_info());
  EXPECT_TRUE(d.request().send_background());
  EXPECT_LE(bytes.size(), 1400u);
}

}  // namespace
}  // namespace lrfnet::daemon
