// Zero heap allocations per scan on the tracker's whole path after start-up (issue: fixed
// allocation): capture file -> TCP reassembly -> CoLa-B decoding -> clock mapping -> tracking ->
// datagram encoding -> sealing (authenticated datagrams, some passes encrypted) -> UDP send (to a
// receiver on loopback) and recording write, over all scans of the shipped captures (several
// passes, sealed and not) and over thousands of scans of a synthetic crowd (sealed, encrypted).

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "common/capture/capture_stream.h"
#include "firmware_tracker/app/node_test_util.h"
#include "firmware_tracker/app/tracker_node.h"
#include "firmware_tracker/cola/framer.h"
#include "firmware_tracker/cola/stream_decoder.h"
#include "firmware_tracker/io/recording_writer.h"
#include "firmware_tracker/io/sealing_sink.h"
#include "firmware_tracker/io/udp_uplink.h"
#include "tests/support/alloc_counter.h"
#include "tests/support/test_data.h"
#include "tests/support/udp_peer.h"

namespace lrfnet::tracker {
namespace {

// Everything a running tracker holds, built before counting starts.
enum class Sealing { kNone, kSigned, kEncrypted };

struct Tracker : cola::TelegramListener {
  Tracker(const std::string& id, std::uint16_t port, const std::string& recording,
          Sealing sealing = Sealing::kNone) {
    EXPECT_TRUE(auth::Init());
    auth::Key site{};
    site.fill(5);
    const auth::SensorKeys keys = auth::DeriveSensorKeys(auth::DeriveSensorKey(site, id), 1);
    io::UdpUplinkOptions udp_options;
    udp_options.host = "127.0.0.1";
    udp_options.port = port;
    udp_options.sensor_id = id;
    if (sealing != Sealing::kNone) udp_options.keys = keys;
    udp = std::make_unique<io::UdpUplink>(udp_options);
    EXPECT_EQ(udp->Open(), std::nullopt);
    io::RecordingWriterOptions rec_options;
    rec_options.path = recording;
    rec_options.source = io::TrackerRecordSource(id);
    writer = std::make_unique<io::RecordingWriter>(rec_options);
    EXPECT_EQ(writer->Open(1'600'000'000 * common::kNsPerS), std::nullopt);
    EXPECT_TRUE(fanout.Add(udp.get()));
    EXPECT_TRUE(fanout.Add(writer.get()));
    if (sealing != Sealing::kNone) {
      auth::SealerOptions sealer;
      sealer.sensor_id = id;
      sealer.keys = keys;
      sealer.encrypt = sealing == Sealing::kEncrypted;
      sealer.salt = 77;
      sealer.first_counter = 1'700'000'000'000'000'000ULL;
      sealing_sink = std::make_unique<io::SealingSink>(sealer, fanout);
    }
    TrackerConfig config;
    config.sensor_id = id;
    node = std::make_unique<TrackerNode>(
        config, 42, sealing_sink ? static_cast<io::DatagramSink&>(*sealing_sink) : fanout);
    node->SetDeviceIdentity("LMS511", "12345678", "V3.10");
    clock.sync = io::ClockSync::kReplay;
  }
  ~Tracker() override { (void)writer->Close(); }

  void OnScan(const cola::ScanTelegram& scan, common::UtcNs receive_ns) override {
    udp->Poll();
    const io::PendingRequests requests = udp->TakeRequests();
    if (requests.send_background) node->RequestBackground();
    node->OnScan(scan, receive_ns, receive_ns);
    node->RecordScanCpu(50.0);
    node->OnTick(receive_ns, LinkHealth{}, clock);
    ++scans;
  }

  std::unique_ptr<io::UdpUplink> udp;
  std::unique_ptr<io::RecordingWriter> writer;
  io::DatagramFanout fanout;
  std::unique_ptr<io::SealingSink> sealing_sink;
  std::unique_ptr<TrackerNode> node;
  std::unique_ptr<cola::StreamDecoder> decoder = std::make_unique<cola::StreamDecoder>();
  io::ClockStatus clock;
  std::size_t scans = 0;
};

std::string TempPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() /
          (name + "." + std::to_string(::getpid()) + ".rec"))
      .string();
}

TEST(TrackerAllocTest, CounterSeesAllocations) {
  lrfnet::testing::StartCountingAllocations();
  auto* v = new std::vector<int>(100);
  const std::size_t n = lrfnet::testing::StopCountingAllocations();
  delete v;
  EXPECT_GE(n, 2u);
}

TEST(TrackerAllocTest, ShippedCapturesAllocateNothingPerScan) {
  bool any = false;
  std::size_t total_scans = 0;
  lrfnet::testing::LoopbackUdpPeer receiver;  // lrfnetd's end, drained between passes
  for (const std::string& name : lrfnet::testing::SickCaptureNames()) {
    const std::optional<std::string> path = lrfnet::testing::SharedFile("data/sick/" + name);
    if (!path) continue;
    any = true;
    const std::string recording = TempPath("alloc_" + name);
    std::size_t counted_scans = 0;
    std::size_t allocations = 0;
    // Several passes, each a fresh tracker start: the capture is short (4-9 s).
    for (int pass = 0; pass < 5; ++pass) {
      // Passes 1 and 3 sealed (3 encrypted), the others not.
      const Sealing sealing =
          pass == 1 ? Sealing::kSigned : (pass == 3 ? Sealing::kEncrypted : Sealing::kNone);
      Tracker tracker("alloc", receiver.port(), recording, sealing);
      std::string error;
      auto capture = capture::CaptureStream::Open(*path, capture::CaptureStreamOptions{}, &error);
      ASSERT_NE(capture, nullptr) << error;
      capture::StreamChunk chunk;
      bool counting = false;
      std::size_t scans_at_start = 0;
      while (capture->Next(&chunk)) {
        if (chunk.discontinuity) tracker.decoder->Reset();
        tracker.decoder->Feed(chunk.bytes, chunk.receive_time_ns, tracker);
        // Start-up: the first scans (first sensor info, first buffers touched).
        if (!counting && tracker.scans >= 3) {
          counting = true;
          scans_at_start = tracker.scans;
          lrfnet::testing::StartCountingAllocations();
        }
      }
      if (counting) allocations += lrfnet::testing::StopCountingAllocations();
      counted_scans += tracker.scans - scans_at_start;
      EXPECT_GT(tracker.node->counters().frames, 0u);
      EXPECT_EQ(tracker.udp->counters().send_errors, 0u);
      if (tracker.sealing_sink) {
        EXPECT_EQ(tracker.sealing_sink->counters().sealed,
                  tracker.node->encoder().counters().datagrams);
      }
      receiver.Drain();
    }
    std::filesystem::remove(recording);
    EXPECT_EQ(allocations, 0u) << name << " over " << counted_scans << " scans";
    EXPECT_GT(counted_scans, 0u) << name;
    total_scans += counted_scans;
  }
  if (!any) GTEST_SKIP() << "shared SICK captures not found (LRFNET_SHARED_DIR)";
  EXPECT_GT(total_scans, 1000u);
}

TEST(TrackerAllocTest, SyntheticCrowdAllocatesNothingPerScan) {
  lrfnet::testing::LoopbackUdpPeer receiver;  // lrfnetd's end, drained between passes
  const std::string recording = TempPath("alloc_crowd");
  Tracker tracker("crowd", receiver.port(), recording, Sealing::kEncrypted);
  testing::ScannerConfig scanner;  // LMS1xx: 541 beams, 25 Hz
  testing::SyntheticDevice device(scanner);
  const auto room = testing::Room();
  // 20 people on random walks inside the room (x in [-1.5, 7.5], y in [-4.5, 4.5]).
  constexpr int kPeople = 20;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> ux(-1.0, 7.0), uy(-4.0, 4.0), ua(-M_PI, M_PI);
  std::vector<testing::Body> bodies(kPeople);
  std::vector<double> heading(kPeople);
  for (int i = 0; i < kPeople; ++i) {
    bodies[static_cast<std::size_t>(i)] = {{ux(rng), uy(rng)}, 0.25, 0.15, 0.0};
    heading[static_cast<std::size_t>(i)] = ua(rng);
  }
  std::vector<std::uint8_t> payload(cola::MaxEncodedSize(device.telegram()) + 64);
  std::vector<std::uint8_t> frame(payload.size() + 16);
  constexpr int kScans = 3000;  // 2 minutes at 25 Hz
  std::size_t allocations = 0;
  for (int k = 0; k < kScans; ++k) {
    const std::vector<testing::Body> empty;
    const bool people = k >= 150;  // after the background is learned
    if (people) {
      for (int i = 0; i < kPeople; ++i) {
        auto& b = bodies[static_cast<std::size_t>(i)];
        double& h = heading[static_cast<std::size_t>(i)];
        h += 0.05 * ua(rng) / M_PI;
        b.centre_m += 0.05 * Eigen::Vector2d(std::cos(h), std::sin(h));
        if (b.centre_m.x() < -1.0 || b.centre_m.x() > 7.0 || std::abs(b.centre_m.y()) > 4.0) {
          h += M_PI;
          b.centre_m += 0.1 * Eigen::Vector2d(std::cos(h), std::sin(h));
        }
        b.yaw_rad = h + M_PI / 2;
      }
    }
    common::UtcNs rx = 0;
    const cola::ScanTelegram& scan = device.Scan(k, room, people ? bodies : empty, &rx);
    const std::size_t payload_size = cola::EncodeScanTelegram(scan, payload);
    const std::size_t frame_size =
        cola::EncodeFrame(std::span(payload).first(payload_size), frame);
    ASSERT_GT(frame_size, 0u);
    if (k >= 3) lrfnet::testing::StartCountingAllocations();
    tracker.decoder->Feed(std::span(frame).first(frame_size), rx, tracker);
    if (k >= 3) allocations += lrfnet::testing::StopCountingAllocations();
    if (k % 500 == 0) receiver.Drain();
  }
  EXPECT_EQ(allocations, 0u);
  EXPECT_EQ(tracker.scans, static_cast<std::size_t>(kScans));
  EXPECT_GE(tracker.node->pipeline().tracker().counters().confirmed, 15u);
  EXPECT_GE(tracker.node->counters().snapshots, 1u);
  EXPECT_EQ(tracker.sealing_sink->counters().sealed, tracker.node->encoder().counters().datagrams);
  std::filesystem::remove(recording);
}

}  // namespace
}  // namespace lrfnet::tracker
