// The ingest with keys: every datagram verified before its protobuf is read. Each way a datagram
// can fail authentication is counted under its own reason, none reaches the listener, forged ones
// create no sensor and change no source address; the stored state refuses yesterday's datagrams
// after a restart; Requests go out sealed. Without keys, sealed plain datagrams are read (counted
// as unverified) and encrypted ones refused.

#include <gtest/gtest.h>

#include <set>
#include <string>
#include <vector>

#include "central_daemon/ingest/datagram_verifier.h"
#include "central_daemon/ingest/ingest.h"
#include "central_daemon/ingest/ingest_test_util.h"
#include "common/datagram_auth.h"
#include "firmware_tracker/io/request_decoder.h"

namespace lrfnet::daemon {
namespace {

using testing::Bytes;
using testing::FakeTracker;
using testing::kMs;
using testing::kS;
using testing::kT0;

auth::Key Site(std::uint8_t fill) {
  auth::Key k{};
  k.fill(fill);
  return k;
}

auth::KeyFile SensorKeyFile(const std::string& id, std::uint32_t epoch, std::uint8_t site = 1) {
  auth::KeyFile f;
  f.kind = auth::KeyFile::Kind::kSensor;
  f.sensor_id = id;
  f.epoch = epoch;
  f.key = auth::DeriveSensorKey(Site(static_cast<std::uint8_t>(site + epoch)), id);
  return f;
}

// A tracker's sealer: sensor `id`, key of `epoch` (of site `site`), counter from `start`.
auth::Sealer TrackerSealer(const std::string& id, std::uint32_t epoch, std::uint64_t start,
                           bool encrypt = false, std::uint8_t site = 1) {
  auth::SealerOptions o;
  o.sensor_id = id;
  const auth::KeyFile f = SensorKeyFile(id, epoch, site);
  o.keys = auth::DeriveSensorKeys(f.key, f.epoch);
  o.encrypt = encrypt;
  o.salt = 42;
  o.first_counter = start;
  return auth::Sealer(o);
}

Bytes Seal(auth::Sealer& sealer, const Bytes& payload) {
  Bytes out(payload.size() + sealer.overhead());
  EXPECT_EQ(sealer.Seal(payload, out), out.size());
  return out;
}

struct Listener final : IngestListener {
  std::size_t frames = 0;
  std::size_t infos = 0;
  void OnTrackFrame(const std::string&, const TrackFrameData&) override { ++frames; }
  void OnSensorInfo(const std::string&, const SensorDescription&) override { ++infos; }
};

IngestOptions KeyedOptions() {
  IngestOptions o;
  o.auth.keys = {SensorKeyFile("gate-3", 1), SensorKeyFile("gate-3", 2),
                 SensorKeyFile("gate-4", 1)};
  o.auth.max_counter_ahead_s = 300.0;
  o.auth.request_salt = 7;
  o.auth.request_first_counter = static_cast<std::uint64_t>(kT0);
  return o;
}

class AuthIngestTest : public ::testing::Test {
 protected:
  void SetUp() override { ASSERT_TRUE(auth::Init()); }
  std::uint64_t Rejected(const Ingest& ingest, RejectReason r, const std::string& sensor = "") {
    const auto i = static_cast<std::size_t>(r);
    if (sensor.empty()) return ingest.counters().unattributed[i];
    return ingest.Sensor(sensor)->counters.rejected[i];
  }
};

TEST_F(AuthIngestTest, EveryAuthenticationFailureIsCountedUnderItsReasonAndNoneIsAccepted) {
  Listener listener;
  Ingest ingest(KeyedOptions(), &listener);
  FakeTracker tracker("gate-3", 11);
  const std::uint64_t start = static_cast<std::uint64_t>(kT0 - 60 * kS);
  auth::Sealer sealer = TrackerSealer("gate-3", 2, start);
  // A good datagram first: the sensor becomes known (later failures count at it).
  const Bytes good = Seal(sealer, tracker.Tracks(2, kT0 - 2 * kMs)[0]);
  const Disposition first = ingest.OnDatagram(good, "10.0.0.3:4000", kT0);
  ASSERT_TRUE(first.accepted) << first.detail;
  EXPECT_EQ(ingest.counters().verified, 1u);
  ASSERT_EQ(listener.frames, 1u);

  struct Case {
    std::string name;
    Bytes bytes;
    RejectReason reason;
    std::string sensor;  // where it is counted ("": unattributed)
  };
  std::vector<Case> cases;
  const Bytes plain = tracker.Tracks(1, kT0 - kMs)[0];
  cases.push_back({"unsigned", plain, RejectReason::kUnsigned, ""});
  {
    Bytes b = Seal(sealer, tracker.Tracks(1, kT0 - kMs)[0]);
    b[b.size() - 30] ^= 0x04;  // a payload bit
    cases.push_back({"bit-flipped", b, RejectReason::kBadTag, "gate-3"});
  }
  {
    Bytes b = Seal(sealer, tracker.Tracks(1, kT0 - kMs)[0]);
    b[b.size() - 1] ^= 0x80;  // a tag bit
    cases.push_back({"forged tag", b, RejectReason::kBadTag, "gate-3"});
  }
  {
    // Forged: right header (sensor, epoch, key id), tag computed with a made-up key.
    auth::SealerOptions o = sealer.options();
    o.keys.to_daemon = Site(99);
    o.first_counter = sealer.next_counter() + 10;
    auth::Sealer forger(o);
    cases.push_back({"forged", Seal(forger, plain), RejectReason::kBadTag, "gate-3"});
  }
  cases.push_back({"replayed", good, RejectReason::kReplayed, "gate-3"});
  {
    auth::Sealer old_epoch = TrackerSealer("gate-3", 1, start + 1'000'000);
    cases.push_back({"older epoch", Seal(old_epoch, plain), RejectReason::kWrongEpoch, "gate-3"});
    auth::Sealer unknown_epoch = TrackerSealer("gate-3", 3, start + 1'000'000);
    cases.push_back(
        {"unknown epoch", Seal(unknown_epoch, plain), RejectReason::kWrongEpoch, "gate-3"});
    auth::Sealer other_site = TrackerSealer("gate-3", 2, start + 1'000'000, false, 50);
    cases.push_back(
        {"other site's key", Seal(other_site, plain), RejectReason::kWrongKey, "gate-3"});
    auth::Sealer stranger = TrackerSealer("gate-9", 1, start + 1'000'000);
    cases.push_back({"unknown sensor", Seal(stranger, plain), RejectReason::kUnknownSensor, ""});
    auth::Sealer future = TrackerSealer("gate-3", 2, static_cast<std::uint64_t>(kT0 + 400 * kS));
    cases.push_back({"counter ahead", Seal(future, plain), RejectReason::kTimestamp, "gate-3"});
    auth::Sealer yesterday = TrackerSealer("gate-3", 2, start - 86400ULL * 1'000'000'000ULL);
    cases.push_back({"yesterday", Seal(yesterday, plain), RejectReason::kStale, "gate-3"});
    auth::Sealer other_sensor_payload = TrackerSealer("gate-4", 1, start);
    cases.push_back({"payload of another sensor",
                     Seal(other_sensor_payload, tracker.Tracks(1, kT0 - kMs)[0]),
                     RejectReason::kAuthMismatch, ""});
  }
  {
    auth::SealerOptions o = sealer.options();
    o.direction = auth::Direction::kToTracker;
    o.first_counter = sealer.next_counter() + 20;
    auth::Sealer reflected(o);
    cases.push_back(
        {"sealed for a tracker", Seal(reflected, plain), RejectReason::kAuthHeader, "gate-3"});
    Bytes b = Seal(sealer, plain);
    b[1] = 9;  // envelope version
    cases.push_back({"bad envelope", b, RejectReason::kAuthHeader, ""});
  }

  std::set<RejectReason> seen;
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::uint64_t before = Rejected(ingest, c.reason, c.sensor);
    const Disposition d = ingest.OnDatagram(c.bytes, "10.66.6.6:666", kT0 + kMs);
    EXPECT_FALSE(d.accepted);
    EXPECT_EQ(d.reason, c.reason) << d.detail;
    EXPECT_EQ(d.sensor_id, c.sensor);
    EXPECT_NE(d.detail.find("10.66.6.6:666"), std::string::npos) << d.detail;
    EXPECT_EQ(Rejected(ingest, c.reason, c.sensor), before + 1);
    seen.insert(c.reason);
  }
  EXPECT_EQ(listener.frames, 1u) << "no refused datagram reaches the listener";
  EXPECT_EQ(ingest.counters().accepted, 1u);
  EXPECT_EQ(ingest.counters().rejected, cases.size());
  EXPECT_EQ(ingest.Sensors().size(), 1u) << "forged datagrams create no sensor";
  EXPECT_EQ(ingest.Sensor("gate-3")->source, "10.0.0.3:4000")
      << "a forged datagram must not redirect the Requests";
  // Every authentication reason but "encrypted" (keyless only), and "timestamp".
  EXPECT_EQ(seen.size(), 10u);

  // The tracker's next datagrams (also encrypted, and reordered) are still accepted.
  auth::Sealer encrypted = TrackerSealer("gate-3", 2, sealer.next_counter() + 100, true);
  const Bytes a = Seal(encrypted, tracker.Tracks(1, kT0 + 10 * kMs)[0]);
  const Bytes b = Seal(encrypted, tracker.Tracks(1, kT0 + 20 * kMs)[0]);
  EXPECT_TRUE(ingest.OnDatagram(b, "10.0.0.3:4000", kT0 + 30 * kMs).accepted);
  EXPECT_TRUE(ingest.OnDatagram(a, "10.0.0.3:4000", kT0 + 31 * kMs).accepted);
  EXPECT_EQ(listener.frames, 3u);
  EXPECT_EQ(ingest.counters().verified, 3u);
}

TEST_F(AuthIngestTest, StoredStateRefusesYesterdaysDatagramsAfterARestart) {
  FakeTracker tracker("gate-4", 1);
  auth::Sealer yesterday = TrackerSealer("gate-4", 1, static_cast<std::uint64_t>(kT0 - 86400 * kS));
  std::vector<Bytes> recording;
  for (int i = 0; i < 20; ++i) {
    recording.push_back(Seal(yesterday, tracker.Tracks(1, kT0 - 86400 * kS + i * 40 * kMs)[0]));
  }
  std::vector<StoredAuthState> stored;
  {
    Ingest first(KeyedOptions(), nullptr);
    for (std::size_t i = 0; i < 10; ++i) {
      ASSERT_TRUE(first.OnDatagram(recording[i], "a:1", kT0 - 86400 * kS + 50 * kMs).accepted);
    }
    stored = first.AuthState();
    ASSERT_EQ(stored.size(), 1u);
    EXPECT_EQ(stored[0].sensor_id, "gate-4");
    EXPECT_EQ(stored[0].epoch, 1u);
    EXPECT_EQ(stored[0].counter, static_cast<std::uint64_t>(kT0 - 86400 * kS) + 9);
    EXPECT_EQ(first.auth_changes(), 10u);
  }
  // Written and read back as the daemon does.
  std::vector<StoredAuthState> loaded;
  ASSERT_EQ(ParseAuthState(FormatAuthState(stored), &loaded), std::nullopt);
  ASSERT_EQ(loaded.size(), 1u);
  EXPECT_EQ(loaded[0].counter, stored[0].counter);

  Ingest restarted(KeyedOptions(), nullptr);
  restarted.RestoreAuthState(loaded);
  // The whole recording sent again: everything it accepted before is stale now.
  for (std::size_t i = 0; i < 10; ++i) {
    const Disposition d = restarted.OnDatagram(recording[i], "b:2", kT0);
    EXPECT_FALSE(d.accepted);
    EXPECT_EQ(d.reason, RejectReason::kStale);
  }
  EXPECT_EQ(Rejected(restarted, RejectReason::kStale), 10u);
  // Today's tracker (a new start: a new counter base) is accepted.
  auth::Sealer today = TrackerSealer("gate-4", 1, static_cast<std::uint64_t>(kT0 - 5 * kS));
  EXPECT_TRUE(
      restarted.OnDatagram(Seal(today, tracker.Tracks(1, kT0 - kMs)[0]), "c:3", kT0).accepted);
  std::vector<StoredAuthState> bad;
  EXPECT_NE(ParseAuthState("gate-4 1\n", &bad), std::nullopt);
  EXPECT_NE(ParseAuthState("gate/4 1 2\n", &bad), std::nullopt);
  EXPECT_NE(ParseAuthState("gate-4 x 2\n", &bad), std::nullopt);
}

TEST_F(AuthIngestTest, RequestsAreSealedForTheSensorAndOpenAtTheTracker) {
  Ingest ingest(KeyedOptions(), nullptr);
  FakeTracker tracker("gate-3", 5);
  auth::Sealer sealer = TrackerSealer("gate-3", 2, static_cast<std::uint64_t>(kT0 - kS));
  const std::uint8_t request[] = {0x08, 0x01};
  std::array<std::uint8_t, 1400> out{};
  EXPECT_EQ(ingest.SealRequest("gate-3", request, out), 0u) << "no accepted datagram yet";
  ASSERT_TRUE(ingest.OnDatagram(Seal(sealer, tracker.Health(kT0 - kMs)), "a:1", kT0).accepted);
  EXPECT_EQ(ingest.SealRequest("gate-9", request, out), 0u);
  const std::size_t n = ingest.SealRequest("gate-3", request, out);
  ASSERT_GT(n, 0u);
  auth::Envelope e;
  ASSERT_EQ(auth::ParseEnvelope(std::span(out).first(n), &e), auth::HeaderError::kNone);
  EXPECT_EQ(e.direction, auth::Direction::kToTracker);
  EXPECT_EQ(e.epoch, 2u);
  EXPECT_EQ(e.counter, static_cast<std::uint64_t>(kT0));
  // The tracker's decoder with gate-3's epoch-2 key takes it (the payload is a real Request).
  io::RequestMessage m;
  m.sensor_id = "gate-3";
  m.send_background = true;
  std::array<std::uint8_t, 1400> plain{};
  const std::size_t plain_size = io::EncodeRequest(m, plain);
  const std::size_t sealed_size =
      ingest.SealRequest("gate-3", std::span(plain).first(plain_size), out);
  const auth::KeyFile key = SensorKeyFile("gate-3", 2);
  io::RequestDecoder decoder("gate-3", auth::DeriveSensorKeys(key.key, key.epoch));
  const io::DecodedRequest r = decoder.Decode(std::span(out).first(sealed_size));
  EXPECT_EQ(r.reject, io::RequestReject::kNone);
  EXPECT_TRUE(r.send_background);
}

TEST_F(AuthIngestTest, WithoutKeysSealedPlainDatagramsAreReadUnverifiedAndEncryptedOnesRefused) {
  Listener listener;
  Ingest ingest(IngestOptions{}, &listener);
  EXPECT_FALSE(ingest.authenticated());
  FakeTracker tracker("gate-3", 11);
  auth::Sealer plain = TrackerSealer("gate-3", 1, static_cast<std::uint64_t>(kT0));
  EXPECT_TRUE(ingest.OnDatagram(Seal(plain, tracker.Tracks(1, kT0 - kMs)[0]), "a:1", kT0).accepted);
  EXPECT_EQ(ingest.counters().unverified, 1u);
  auth::Sealer encrypted = TrackerSealer("gate-3", 1, static_cast<std::uint64_t>(kT0) + 5, true);
  const Disposition d =
      ingest.OnDatagram(Seal(encrypted, tracker.Tracks(1, kT0 - kMs)[0]), "a:1", kT0);
  EXPECT_FALSE(d.accepted);
  EXPECT_EQ(d.reason, RejectReason::kEncrypted);
  EXPECT_EQ(Rejected(ingest, RejectReason::kEncrypted, "gate-3"), 1u);
  // Unsigned datagrams as always.
  EXPECT_TRUE(ingest.OnDatagram(tracker.Tracks(1, kT0 - kMs)[0], "a:1", kT0).accepted);
  EXPECT_EQ(listener.frames, 2u);
}

TEST_F(AuthIngestTest, OptionsAreValidated) {
  AuthOptions o;
  o.keys = {SensorKeyFile("a", 1), SensorKeyFile("a", 1)};
  EXPECT_NE(Validate(o), std::nullopt);
  o.keys = {SensorKeyFile("a", 1)};
  o.keys[0].kind = auth::KeyFile::Kind::kSite;
  EXPECT_NE(Validate(o), std::nullopt);
  o.keys = {SensorKeyFile("a", 1), SensorKeyFile("a", 2)};
  EXPECT_EQ(Validate(o), std::nullopt);
  o.max_counter_ahead_s = -1.0;
  EXPECT_NE(Validate(o), std::nullopt);
}

}  // namespace
}  // namespace lrfnet::daemon
