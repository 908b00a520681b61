// The tracker's authenticated uplink: every datagram sealed (SealingSink) before the UDP socket and
// the recording, within 1400 bytes at the widest; Requests from the daemon accepted only when
// sealed for this sensor, and every other kind refused with its reason (RequestDecoder with keys).

#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include "common/datagram_auth.h"
#include "firmware_tracker/io/datagram_encoder.h"
#include "firmware_tracker/io/request_decoder.h"
#include "firmware_tracker/io/sealing_sink.h"
#include "firmware_tracker/io/udp_uplink.h"
#include "tests/support/udp_peer.h"

namespace lrfnet::io {
namespace {

constexpr char kSealedId[] = "gate-3";

auth::Key Site(std::uint8_t fill) {
  auth::Key k{};
  k.fill(fill);
  return k;
}

auth::SensorKeys KeysOf(std::string_view id, std::uint32_t epoch = 1, std::uint8_t site = 7) {
  return auth::DeriveSensorKeys(auth::DeriveSensorKey(Site(site), id), epoch);
}

auth::SealerOptions Tracker(std::string_view id, bool encrypt) {
  auth::SealerOptions o;
  o.sensor_id = std::string(id);
  o.keys = KeysOf(id);
  o.encrypt = encrypt;
  o.salt = 0xabcdef01;
  o.first_counter = 1'750'000'000'000'000'000ULL;
  return o;
}

// The daemon's side of a Request: encoded, then sealed for the tracker.
std::vector<std::uint8_t> SealedRequest(auth::Sealer& daemon, bool info, bool background) {
  RequestMessage m;
  m.sensor_id = daemon.options().sensor_id;
  m.send_sensor_info = info;
  m.send_background = background;
  std::array<std::uint8_t, kMaxDatagramBytes> plain{};
  const std::size_t n = EncodeRequest(m, plain);
  std::vector<std::uint8_t> out(n + daemon.overhead());
  EXPECT_EQ(daemon.Seal(std::span(plain).first(n), out), out.size());
  return out;
}

auth::SealerOptions Daemon(std::string_view id, std::uint32_t epoch = 1, std::uint8_t site = 7) {
  auth::SealerOptions o;
  o.sensor_id = std::string(id);
  o.keys = KeysOf(id, epoch, site);
  o.direction = auth::Direction::kToTracker;
  o.salt = 0x55;
  o.first_counter = 1'760'000'000'000'000'000ULL;
  return o;
}

class SealedUplinkTest : public ::testing::Test {
 protected:
  void SetUp() override { ASSERT_TRUE(auth::Init()); }
};

TEST_F(SealedUplinkTest, WidestDatagramsStayWithin1400BytesSealedAndOpenToTheEncodersBytes) {
  for (const bool encrypt : {false, true}) {
    struct Collect final : DatagramSink {
      std::vector<std::vector<std::uint8_t>> got;
      void Send(std::span<const std::uint8_t> d, common::UtcNs) override {
        got.emplace_back(d.begin(), d.end());
      }
    } plain, sealed_out;
    const std::string id(32, 'w');  // the widest id: the widest envelope
    SealingSink sealing(Tracker(id, encrypt), sealed_out);
    DatagramFanout both;
    ASSERT_TRUE(both.Add(&plain));
    ASSERT_TRUE(both.Add(&sealing));
    DatagramEncoder encoder(DatagramEncoderOptions{id, ~0ull});
    tracking::ScanTracks scan;
    scan.scan_start_ns = -1;
    scan.scan_period_s = 1.0 / 7.0;
    scan.scan_counter = ~0u;
    for (std::uint32_t i = 0; i < tracking::kMaxTracks; ++i) {
      tracking::TrackReport t;
      t.track_id = ~0u - i;
      t.state = tracking::TrackState::kCoasting;
      t.kind = tracking::MeasurementKind::kEllipse;
      t.x_m = t.y_m = -123.456;
      t.vx_mps = t.vy_mps = -1.5;
      t.covariance = Eigen::Matrix4d::Identity() * 1e-3;
      t.age_scans = t.points = ~0u;
      t.ellipse_yaw_rad = -3.0;
      ASSERT_TRUE(scan.tracks.push_back(t));
    }
    encoder.EncodeTracks(scan, -1, both);
    std::vector<float> ranges(4561, 1e6f);
    encoder.EncodeBackground({-1, -1.0, 1e-3, ranges}, -1, both);
    ASSERT_EQ(plain.got.size(), sealed_out.got.size());
    ASSERT_EQ(sealing.counters().sealed, plain.got.size());
    std::array<std::uint8_t, kMaxDatagramBytes> buffer{};
    for (std::size_t i = 0; i < plain.got.size(); ++i) {
      EXPECT_LE(sealed_out.got[i].size(), kMaxDatagramBytes);
      EXPECT_EQ(sealed_out.got[i].size(), plain.got[i].size() + auth::kMaxOverheadBytes);
      auth::Envelope e;
      ASSERT_EQ(auth::ParseEnvelope(sealed_out.got[i], &e), auth::HeaderError::kNone);
      EXPECT_EQ(e.counter, 1'750'000'000'000'000'000ULL + i);
      std::span<const std::uint8_t> payload;
      ASSERT_TRUE(auth::OpenEnvelope(e, KeysOf(id), buffer, &payload));
      EXPECT_EQ(std::vector<std::uint8_t>(payload.begin(), payload.end()), plain.got[i]);
    }
  }
}

TEST_F(SealedUplinkTest, SealedDatagramsOverUdpAndOnlySealedRequestsCount) {
  lrfnet::testing::LoopbackUdpPeer daemon_socket;
  ASSERT_TRUE(daemon_socket.ok());
  UdpUplinkOptions options;
  options.host = "127.0.0.1";
  options.port = daemon_socket.port();
  options.sensor_id = kSealedId;
  options.keys = KeysOf(kSealedId);
  UdpUplink uplink(options);
  ASSERT_EQ(uplink.Open(), std::nullopt);
  SealingSink sealing(Tracker(kSealedId, true), uplink);
  DatagramEncoder encoder(DatagramEncoderOptions{kSealedId, 5});
  ASSERT_TRUE(encoder.EncodeHealth({}, 1'700'000'000'000'000'000, sealing));
  const std::vector<std::uint8_t> got = daemon_socket.Receive();
  auth::Envelope e;
  ASSERT_EQ(auth::ParseEnvelope(got, &e), auth::HeaderError::kNone);
  EXPECT_EQ(e.sensor_id, kSealedId);
  EXPECT_TRUE(e.encrypted);

  auth::Sealer daemon(Daemon(kSealedId));
  const auto good = SealedRequest(daemon, true, false);
  // Every kind of bad Request, each followed by a check that it set nothing.
  RequestMessage m;
  m.sensor_id = kSealedId;
  m.send_background = true;
  std::array<std::uint8_t, kMaxDatagramBytes> unsigned_request{};
  const std::size_t unsigned_size = EncodeRequest(m, unsigned_request);
  auto forged = good;
  forged[forged.size() - 20] ^= 0x01;  // a payload bit: the tag no longer matches
  auth::Sealer other_epoch(Daemon(kSealedId, 2));
  auth::Sealer other_site(Daemon(kSealedId, 1, 8));
  auth::Sealer other_sensor(Daemon("gate-4"));
  auth::SealerOptions wrong_direction = Daemon(kSealedId);
  wrong_direction.direction = auth::Direction::kToDaemon;
  auth::Sealer reflected(wrong_direction);
  const std::vector<std::pair<std::vector<std::uint8_t>, RequestReject>> bad = {
      {{unsigned_request.begin(), unsigned_request.begin() + unsigned_size},
       RequestReject::kUnsigned},
      {forged, RequestReject::kBadTag},
      {SealedRequest(other_epoch, true, true), RequestReject::kWrongEpoch},
      {SealedRequest(other_site, true, true), RequestReject::kWrongKey},
      {SealedRequest(other_sensor, true, true), RequestReject::kOtherSensor},
      {SealedRequest(reflected, true, true), RequestReject::kEnvelope},
  };
  for (const auto& [bytes, reason] : bad) {
    ASSERT_TRUE(daemon_socket.Reply(bytes));
  }
  ASSERT_TRUE(daemon_socket.Reply(good));
  ASSERT_TRUE(daemon_socket.Reply(good));  // replayed
  for (int i = 0; i < 200 && uplink.counters().received < bad.size() + 2; ++i) {
    uplink.Poll();
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_EQ(uplink.counters().received, bad.size() + 2);
  const RequestDecoderCounters& c = uplink.request_counters();
  EXPECT_EQ(c.accepted, 1u);
  for (const auto& [bytes, reason] : bad) EXPECT_EQ(c.Rejected(reason), 1u) << ToString(reason);
  EXPECT_EQ(c.Rejected(RequestReject::kReplayed), 1u);
  const PendingRequests pending = uplink.TakeRequests();
  EXPECT_TRUE(pending.send_sensor_info);
  EXPECT_FALSE(pending.send_background) << "only the good request may set a flag";
}

}  // namespace
}  // namespace lrfnet::io
