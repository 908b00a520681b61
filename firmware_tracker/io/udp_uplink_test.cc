#include "firmware_tracker/io/udp_uplink.h"
#include "tests/support/udp_peer.h"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <pb_decode.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

namespace lrfnet::io {
namespace {

constexpr char kUdpId[] = "gate-3";

// The daemon's side of the loopback.
using FakeDaemon = ::lrfnet::testing::LoopbackUdpPeer;

UdpUplinkOptions Options(const std::string& host, std::uint16_t port) {
  UdpUplinkOptions o;
  o.host = host;
  o.port = port;
  o.sensor_id = kUdpId;
  return o;
}

std::vector<std::uint8_t> RequestBytes(std::string_view id, bool info, bool background) {
  RequestMessage m;
  m.sensor_id = id;
  m.send_sensor_info = info;
  m.send_background = background;
  std::vector<std::uint8_t> out(256);
  out.resize(EncodeRequest(m, out));
  return out;
}

// Polls until something arrives or 2 s passed.
std::size_t PollFor(UdpUplink& uplink) {
  for (int i = 0; i < 200; ++i) {
    if (const std::size_t n = uplink.Poll()) return n;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return 0;
}

void FramesAndRequestsOverLoopback(int family, const std::string& host) {
  FakeDaemon daemon(family);
  if (!daemon.ok()) GTEST_SKIP() << "no " << host << " loopback here";
  UdpUplink uplink(Options(host, daemon.port()));
  ASSERT_EQ(uplink.Open(), std::nullopt);
  EXPECT_NE(uplink.peer().find(std::to_string(daemon.port())), std::string::npos) << uplink.peer();
  EXPECT_NE(uplink.local_port(), 0);

  DatagramEncoderOptions options;
  options.sensor_id = kUdpId;
  DatagramEncoder encoder(options);
  tracking::ScanTracks scan;
  for (std::uint32_t i = 0; i < 20; ++i) {
    tracking::TrackReport t;
    t.track_id = i;
    t.x_m = i;
    ASSERT_TRUE(scan.tracks.push_back(t));
  }
  for (std::uint32_t s = 0; s < 10; ++s) {
    scan.scan_counter = s;
    ASSERT_EQ(encoder.EncodeTracks(scan, 1000 + s, uplink), 2u);  // 20 tracks: two parts
  }
  for (std::uint64_t k = 0; k < 20; ++k) {
    const std::vector<std::uint8_t> bytes = daemon.Receive();
    ASSERT_FALSE(bytes.empty()) << "datagram " << k << " did not arrive";
    lrfnet_proto_Datagram d{};
    pb_istream_t stream = pb_istream_from_buffer(bytes.data(), bytes.size());
    ASSERT_TRUE(pb_decode(&stream, lrfnet_proto_Datagram_fields, &d));
    EXPECT_EQ(d.sequence, k);
    EXPECT_STREQ(d.sensor_id, kUdpId);
    ASSERT_EQ(d.which_payload, lrfnet_proto_Datagram_track_frame_tag);
    EXPECT_EQ(d.payload.track_frame.scan_counter, k / 2);
    EXPECT_EQ(d.payload.track_frame.part, k % 2);
  }
  EXPECT_EQ(uplink.counters().datagrams_sent, 20u);
  EXPECT_EQ(uplink.counters().send_errors, 0u);

  // No request yet.
  EXPECT_EQ(uplink.Poll(), 0u);
  EXPECT_FALSE(uplink.TakeRequests().any());
  // The daemon asks for a background snapshot, then sends garbage and a request for another sensor.
  ASSERT_TRUE(daemon.Reply(RequestBytes(kUdpId, false, true)));
  ASSERT_EQ(PollFor(uplink), 1u);
  PendingRequests pending = uplink.TakeRequests();
  EXPECT_TRUE(pending.send_background);
  EXPECT_FALSE(pending.send_sensor_info);
  EXPECT_FALSE(uplink.TakeRequests().any());  // taken
  ASSERT_TRUE(daemon.Reply(std::vector<std::uint8_t>{0xff, 0xff, 0xff}));
  ASSERT_TRUE(daemon.Reply(RequestBytes("gate-4", true, true)));
  ASSERT_TRUE(daemon.Reply(RequestBytes("", true, false)));
  std::size_t read = 0;
  for (int i = 0; i < 200 && read < 3; ++i) {
    read += uplink.Poll();
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_EQ(read, 3u);
  pending = uplink.TakeRequests();
  EXPECT_TRUE(pending.send_sensor_info);  // the one for every sensor
  EXPECT_FALSE(pending.send_background);  // gate-4's request is not ours
  EXPECT_EQ(uplink.request_counters().accepted, 2u);
  EXPECT_EQ(uplink.request_counters().Rejected(RequestReject::kMalformed), 1u);
  EXPECT_EQ(uplink.request_counters().Rejected(RequestReject::kOtherSensor), 1u);
  EXPECT_EQ(uplink.counters().received, 4u);
}

TEST(UdpUplinkTest, FramesAndRequestsOverIpv4Loopback) {
  FramesAndRequestsOverLoopback(AF_INET, "127.0.0.1");
}

TEST(UdpUplinkTest, FramesAndRequestsOverIpv6Loopback) {
  FramesAndRequestsOverLoopback(AF_INET6, "::1");
}

TEST(UdpUplinkTest, HostNamesAreResolvedOnce) {
  FakeDaemon daemon(AF_INET);
  ASSERT_TRUE(daemon.ok());
  UdpUplink uplink(Options("localhost", daemon.port()));
  const auto error = uplink.Open();
  if (error) GTEST_SKIP() << "localhost does not resolve here: " << *error;
  const std::vector<std::uint8_t> hello = {1, 2, 3};
  uplink.Send(hello, 0);
  // localhost may resolve to ::1 first, where the IPv4 fake daemon does not listen.
  if (uplink.peer().rfind("127.", 0) == 0) {
    EXPECT_EQ(daemon.Receive(), hello);
  }
  EXPECT_TRUE(uplink.is_open());
}

TEST(UdpUplinkTest, OversizeAndClosedSendsAreCountedNotFatal) {
  FakeDaemon daemon(AF_INET);
  ASSERT_TRUE(daemon.ok());
  UdpUplink uplink(Options("127.0.0.1", daemon.port()));
  const std::vector<std::uint8_t> small(10, 1), big(kMaxDatagramBytes + 1, 1);
  uplink.Send(small, 0);
  EXPECT_EQ(uplink.counters().not_open, 1u);
  EXPECT_EQ(uplink.Poll(), 0u);
  ASSERT_EQ(uplink.Open(), std::nullopt);
  uplink.Send(big, 0);
  EXPECT_EQ(uplink.counters().oversize, 1u);
  EXPECT_EQ(uplink.counters().datagrams_sent, 0u);
  // An oversized datagram from the daemon is rejected by size, not parsed.
  uplink.Send(small, 0);  // the daemon learns our address from it
  ASSERT_EQ(daemon.Receive(), small);
  ASSERT_TRUE(daemon.Reply(big));
  ASSERT_EQ(PollFor(uplink), 1u);
  EXPECT_EQ(uplink.request_counters().Rejected(RequestReject::kTooLarge), 1u);
}

// Nobody listens: the kernel reports the ICMP port-unreachable on a later send or receive. Counted,
// sending goes on.
TEST(UdpUplinkTest, DaemonDownMeansCountedErrorsOnly) {
  std::uint16_t port = 0;
  {
    FakeDaemon gone(AF_INET);
    ASSERT_TRUE(gone.ok());
    port = gone.port();
  }
  UdpUplink uplink(Options("127.0.0.1", port));
  ASSERT_EQ(uplink.Open(), std::nullopt);
  const std::vector<std::uint8_t> d(100, 7);
  for (int i = 0; i < 100 && uplink.counters().send_errors + uplink.counters().receive_errors == 0;
       ++i) {
    uplink.Send(d, 0);
    uplink.Poll();
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  EXPECT_GT(uplink.counters().send_errors + uplink.counters().receive_errors, 0u);
  EXPECT_EQ(uplink.counters().last_errno, ECONNREFUSED);
  EXPECT_TRUE(uplink.is_open());
  uplink.Send(d, 0);  // still usable
}

// Between BeginBatch and EndBatch the datagrams are held and then sent in order, in one sendmmsg
// per kMaxHeldDatagrams (8); with batch_sends off, or outside a batch, each at once.
TEST(UdpUplinkTest, BatchedDatagramsLeaveTogetherInOrder) {
  FakeDaemon daemon(AF_INET);
  ASSERT_TRUE(daemon.ok());
  UdpUplink uplink(Options("127.0.0.1", daemon.port()));
  ASSERT_EQ(uplink.Open(), std::nullopt);
  const auto datagram = [](std::uint8_t k) {
    return std::vector<std::uint8_t>(static_cast<std::size_t>(100 + 50 * k), k);
  };
  uplink.BeginBatch();
  for (std::uint8_t k = 0; k < 3; ++k) uplink.Send(datagram(k), 0);
  EXPECT_EQ(uplink.counters().datagrams_sent, 0u);
  EXPECT_TRUE(daemon.Receive(0).empty());  // held
  uplink.EndBatch();
  EXPECT_EQ(uplink.counters().batches, 1u);
  EXPECT_EQ(uplink.counters().batched, 3u);
  EXPECT_EQ(uplink.counters().datagrams_sent, 3u);
  EXPECT_EQ(uplink.counters().bytes_sent, 100u + 150u + 200u);
  for (std::uint8_t k = 0; k < 3; ++k) EXPECT_EQ(daemon.Receive(), datagram(k)) << int{k};
  // Ten: the first eight go when the ninth arrives, the last two at EndBatch.
  uplink.BeginBatch();
  for (std::uint8_t k = 0; k < 10; ++k) uplink.Send(datagram(k), 0);
  EXPECT_EQ(uplink.counters().datagrams_sent, 3u + 8u);
  uplink.EndBatch();
  EXPECT_EQ(uplink.counters().batches, 3u);
  EXPECT_EQ(uplink.counters().batched, 13u);
  for (std::uint8_t k = 0; k < 10; ++k) EXPECT_EQ(daemon.Receive(), datagram(k)) << int{k};
  // Outside a batch: at once.
  uplink.Send(datagram(1), 0);
  EXPECT_EQ(daemon.Receive(), datagram(1));
  EXPECT_EQ(uplink.counters().batches, 3u);
  EXPECT_EQ(uplink.counters().send_errors, 0u);

  UdpUplinkOptions o = Options("127.0.0.1", daemon.port());
  o.batch_sends = false;
  UdpUplink unbatched(o);
  ASSERT_EQ(unbatched.Open(), std::nullopt);
  unbatched.BeginBatch();
  unbatched.Send(datagram(2), 0);
  EXPECT_EQ(unbatched.counters().datagrams_sent, 1u);
  EXPECT_EQ(daemon.Receive(), datagram(2));
  unbatched.EndBatch();
  EXPECT_EQ(unbatched.counters().batches, 0u);
}

// Held datagrams are sent before the socket closes; one alone with send(2).
TEST(UdpUplinkTest, CloseSendsWhatIsHeld) {
  FakeDaemon daemon(AF_INET);
  ASSERT_TRUE(daemon.ok());
  UdpUplink uplink(Options("127.0.0.1", daemon.port()));
  ASSERT_EQ(uplink.Open(), std::nullopt);
  const std::vector<std::uint8_t> d(64, 9);
  uplink.BeginBatch();
  uplink.Send(d, 0);
  uplink.Close();
  EXPECT_EQ(uplink.counters().datagrams_sent, 1u);
  EXPECT_EQ(uplink.counters().batches, 0u);
  EXPECT_EQ(daemon.Receive(), d);
}

TEST(UdpUplinkTest, OptionsAreValidated) {
  EXPECT_EQ(Validate(Options("127.0.0.1", 5000)), std::nullopt);
  EXPECT_TRUE(Validate(Options("", 5000)).has_value());
  EXPECT_TRUE(Validate(Options("127.0.0.1", 0)).has_value());
  UdpUplinkOptions o = Options("127.0.0.1", 5000);
  o.sensor_id = "bad id";
  EXPECT_TRUE(Validate(o).has_value());
  o = Options("127.0.0.1", 5000);
  o.max_datagrams_per_poll = 0;
  EXPECT_TRUE(Validate(o).has_value());
}

}  // namespace
}  // namespace lrfnet::io
