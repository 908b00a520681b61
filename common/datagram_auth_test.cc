// The envelope and the keys. Known answers were computed independently of libsodium: BLAKE2b
// (Python's hashlib, with libsodium's documented crypto_kdf parameters: salt = LE64(subkey id)
// padded to 16 bytes, personal = context padded to 16 bytes) and ChaCha20-Poly1305 IETF (Python's
// cryptography package), so they pin the byte layout and the derivation, not only a round trip.

#include "common/datagram_auth.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <vector>

#include "common/key_file.h"

namespace lrfnet::auth {
namespace {

Key SiteKey() {
  Key k{};
  for (std::size_t i = 0; i < k.size(); ++i) k[i] = static_cast<std::uint8_t>(i);
  return k;
}

std::vector<std::uint8_t> Bytes(std::string_view s) { return {s.begin(), s.end()}; }

class AuthTest : public ::testing::Test {
 protected:
  void SetUp() override { ASSERT_TRUE(Init()); }
};

TEST_F(AuthTest, SensorKeyDerivationKnownAnswers) {
  const struct {
    const char* id;
    const char* key;
  } cases[] = {
      {"d1", "678b361d77ccaaac1d9d930fc4289534b59d31b42c5a5521c2ac8efefd3d6cfe"},
      {"s1", "8ff3f0fe50a9437e29ddbbfb4c02b485cf7f7a584fef7e04df759be78267f4d2"},
      {"gate-3", "7147f50bbd32b8d6daf7d8e994ce385e39f33522071b75a923842fa2d36e1b25"},
      {"abcdefgh", "dc0f32f7df148259130d10960affe9206342318517d270537c2c6d748a60fad0"},
      {"abcdefghi", "45e8235940e4322dbbd6ce1517f0115e4a79be2c817a4dda731dbb1ddc9556b6"},
      {"AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA",
       "e6ec74421930b82382d7f86c2a5c3cea5326cb3fb84608c20c5b8aa50721806a"},
  };
  for (const auto& c : cases) {
    EXPECT_EQ(ToHex(DeriveSensorKey(SiteKey(), c.id)), c.key) << c.id;
  }
}

TEST_F(AuthTest, DirectionKeysAndKeyIdKnownAnswers) {
  const SensorKeys keys = DeriveSensorKeys(DeriveSensorKey(SiteKey(), "gate-3"), 7);
  EXPECT_EQ(keys.epoch, 7u);
  EXPECT_EQ(keys.key_id, 0xb9393c5du);
  EXPECT_EQ(ToHex(keys.to_daemon),
            "0db7f695803dc9d916213e381e549b2b74ad17135448fbe59859372091222d5c");
  EXPECT_EQ(ToHex(keys.to_tracker),
            "955c86dc294eebea47f692b6b89c8004f1eed32a3587ca3daada0b232399d5aa");
}

TEST_F(AuthTest, IdsThatShareAPrefixOrPaddingGetDifferentKeys) {
  // Same first chunk, different lengths; ids that differ only beyond 8 bytes; every length.
  std::set<std::string> keys;
  const std::vector<std::string> ids = {"a",
                                        "aa",
                                        "aaaaaaaa",
                                        "aaaaaaaaa",
                                        "aaaaaaaab",
                                        "aaaaaaaaaaaaaaaa",
                                        "aaaaaaaaaaaaaaaaa",
                                        "b",
                                        "A",
                                        "a-",
                                        "a.",
                                        "a_",
                                        "0",
                                        std::string(32, 'z'),
                                        std::string(31, 'z')};
  for (const std::string& id : ids) keys.insert(ToHex(DeriveSensorKey(SiteKey(), id)));
  EXPECT_EQ(keys.size(), ids.size());
  Key other = SiteKey();
  other[0] ^= 1;
  EXPECT_NE(DeriveSensorKey(other, "d1"), DeriveSensorKey(SiteKey(), "d1"));
}

SealerOptions GateOptions(bool encrypt) {
  SealerOptions o;
  o.sensor_id = "gate-3";
  o.keys = DeriveSensorKeys(DeriveSensorKey(SiteKey(), "gate-3"), 7);
  o.encrypt = encrypt;
  o.salt = 0x01020304;
  o.first_counter = 1700000000123456789ULL;
  return o;
}

TEST_F(AuthTest, EnvelopeBytesKnownAnswers) {
  const auto payload = Bytes("hello lrfnet");
  std::vector<std::uint8_t> out(payload.size() + kMaxOverheadBytes);
  Sealer plain(GateOptions(false));
  std::size_t n = plain.Seal(payload, out);
  ASSERT_EQ(n, 24 + 6 + payload.size() + 16);
  EXPECT_EQ(ToHex(std::span(out).first(n)),
            "b7010006676174652d3300000007b9393c5d0102030417979cfe3d85cd1568656c6c6f206c72666e6574"
            "67f3b84dccdb59418596672597e72df8");
  EXPECT_EQ(plain.next_counter(), 1700000000123456790ULL);
  Sealer encrypted(GateOptions(true));
  n = encrypted.Seal(payload, out);
  EXPECT_EQ(ToHex(std::span(out).first(n)),
            "b7010106676174652d3300000007b9393c5d0102030417979cfe3d85cd155450a53b42b965cda095ead3"
            "cee18fea84f1c63f2be6f5b16a7f84ec");
}

TEST_F(AuthTest, SealedDatagramsOpenAndEveryFlippedBitIsRefused) {
  for (const bool encrypt : {false, true}) {
    const auto payload = Bytes("a datagram of the tracker, any bytes \x01\x02");
    Sealer sealer(GateOptions(encrypt));
    std::vector<std::uint8_t> sealed(payload.size() + sealer.overhead());
    ASSERT_EQ(sealer.Seal(payload, sealed), sealed.size());
    Envelope e;
    ASSERT_EQ(ParseEnvelope(sealed, &e), HeaderError::kNone);
    EXPECT_EQ(e.sensor_id, "gate-3");
    EXPECT_EQ(e.epoch, 7u);
    EXPECT_EQ(e.counter, 1700000000123456789ULL);
    EXPECT_EQ(e.encrypted, encrypt);
    EXPECT_EQ(e.direction, Direction::kToDaemon);
    std::vector<std::uint8_t> plain(payload.size());
    std::span<const std::uint8_t> opened;
    ASSERT_TRUE(OpenEnvelope(e, GateOptions(false).keys, plain, &opened));
    EXPECT_EQ(std::vector<std::uint8_t>(opened.begin(), opened.end()), payload);
    if (encrypt) {
      EXPECT_EQ(std::search(sealed.begin(), sealed.end(), payload.begin(), payload.begin() + 12),
                sealed.end())
          << "the payload must not appear in the encrypted datagram";
    }
    // Every single-bit change is refused: by the header check or by the tag.
    for (std::size_t byte = 0; byte < sealed.size(); ++byte) {
      for (int bit = 0; bit < 8; ++bit) {
        std::vector<std::uint8_t> bad = sealed;
        bad[byte] ^= static_cast<std::uint8_t>(1 << bit);
        Envelope b;
        if (ParseEnvelope(bad, &b) != HeaderError::kNone) continue;
        EXPECT_FALSE(OpenEnvelope(b, GateOptions(false).keys, plain, &opened))
            << "byte " << byte << " bit " << bit;
      }
    }
    // Another sensor's keys (or another epoch's key) do not open it; nor does the other direction.
    Envelope again;
    ASSERT_EQ(ParseEnvelope(sealed, &again), HeaderError::kNone);
    EXPECT_FALSE(OpenEnvelope(again, DeriveSensorKeys(DeriveSensorKey(SiteKey(), "gate-4"), 7),
                              plain, &opened));
    SensorKeys swapped = GateOptions(false).keys;
    std::swap(swapped.to_daemon, swapped.to_tracker);
    EXPECT_FALSE(OpenEnvelope(again, swapped, plain, &opened));
  }
}

TEST_F(AuthTest, HeaderErrors) {
  Envelope e;
  EXPECT_EQ(ParseEnvelope({}, &e), HeaderError::kTooShort);
  const std::uint8_t protobuf[] = {0x08, 0x01, 0x12, 0x02, 'd', '1'};
  EXPECT_EQ(ParseEnvelope(protobuf, &e), HeaderError::kNotEnvelope);
  EXPECT_FALSE(LooksSealed(protobuf));
  Sealer sealer(GateOptions(false));
  std::vector<std::uint8_t> sealed(sealer.overhead() + 3);
  ASSERT_GT(sealer.Seal(Bytes("abc"), sealed), 0u);
  for (std::size_t n = 0; n < 24 + 6 + 16; ++n) {
    EXPECT_EQ(ParseEnvelope(std::span(sealed).first(n), &e), HeaderError::kTooShort) << n;
  }
  auto bad = sealed;
  bad[1] = 2;
  EXPECT_EQ(ParseEnvelope(bad, &e), HeaderError::kVersion);
  bad = sealed;
  bad[2] = 0x04;
  EXPECT_EQ(ParseEnvelope(bad, &e), HeaderError::kFlags);
  bad = sealed;
  bad[3] = 0;
  EXPECT_EQ(ParseEnvelope(bad, &e), HeaderError::kSensorId);
  bad = sealed;
  bad[3] = 33;
  EXPECT_EQ(ParseEnvelope(bad, &e), HeaderError::kSensorId);
  bad = sealed;
  bad[5] = '/';
  EXPECT_EQ(ParseEnvelope(bad, &e), HeaderError::kSensorId);
  // Too small an output buffer: nothing written, no counter used.
  std::vector<std::uint8_t> small(sealer.overhead() + 2);
  const std::uint64_t counter = sealer.next_counter();
  EXPECT_EQ(sealer.Seal(Bytes("abc"), small), 0u);
  EXPECT_EQ(sealer.next_counter(), counter);
}

TEST_F(AuthTest, ReplayWindowFreshReplayedTooOld) {
  ReplayWindow w;
  using V = ReplayWindow::Verdict;
  EXPECT_EQ(w.Check(1000), V::kFresh);
  w.Commit(1000);
  EXPECT_EQ(w.Check(1000), V::kReplayed);
  EXPECT_EQ(w.Check(1001), V::kFresh);
  EXPECT_EQ(w.Check(999), V::kFresh);  // reordered, inside the window
  w.Commit(1005);
  w.Commit(1002);  // late arrival
  EXPECT_EQ(w.Check(1002), V::kReplayed);
  EXPECT_EQ(w.Check(1003), V::kFresh);
  EXPECT_EQ(w.Check(1005), V::kReplayed);
  // Old beyond the window.
  w.Commit(1005 + ReplayWindow::kWindowBits);
  EXPECT_EQ(w.Check(1005), V::kTooOld);
  EXPECT_EQ(w.Check(1006), V::kFresh);
  // A huge jump (a restarted sender: a new start time) clears the recycled blocks.
  const std::uint64_t far = 1'700'000'000'000'000'000ULL;
  w.Commit(far);
  EXPECT_EQ(w.Check(far), V::kReplayed);
  for (std::uint64_t c = far - 1; c > far - 300; --c) EXPECT_EQ(w.Check(c), V::kFresh) << c;
  EXPECT_EQ(w.Check(1006), V::kTooOld);
}

TEST_F(AuthTest, ReplayWindowMatchesAReferenceSetOverRandomTraffic) {
  ReplayWindow w;
  std::set<std::uint64_t> seen;
  std::uint64_t highest = 0;
  std::uint64_t x = 88172645463325252ULL;  // xorshift
  std::uint64_t base = 50'000;
  for (int i = 0; i < 200'000; ++i) {
    x ^= x << 13;
    x ^= x >> 7;
    x ^= x << 17;
    if (x % 97 == 0) base += x % 20'000;  // jumps
    const std::uint64_t c = base + x % 6000;
    const auto verdict = w.Check(c);
    ReplayWindow::Verdict expected;
    if (!seen.empty() && c <= highest && highest - c >= ReplayWindow::kWindowBits) {
      expected = ReplayWindow::Verdict::kTooOld;
    } else if (seen.count(c) != 0) {
      expected = ReplayWindow::Verdict::kReplayed;
    } else {
      expected = ReplayWindow::Verdict::kFresh;
    }
    ASSERT_EQ(verdict, expected) << "step " << i << " counter " << c;
    if (verdict == ReplayWindow::Verdict::kFresh) {
      w.Commit(c);
      seen.insert(c);
      highest = std::max(highest, c);
    }
  }
}

TEST_F(AuthTest, ReplayWindowFloorRefusesEverythingStoredBefore) {
  ReplayWindow w;
  w.SetFloor(5000);
  EXPECT_EQ(w.Check(5000), ReplayWindow::Verdict::kTooOld);
  EXPECT_EQ(w.Check(4999), ReplayWindow::Verdict::kTooOld);
  EXPECT_EQ(w.Check(1), ReplayWindow::Verdict::kTooOld);
  EXPECT_EQ(w.Check(5001), ReplayWindow::Verdict::kFresh);
  w.Commit(5003);
  EXPECT_EQ(w.Check(5001), ReplayWindow::Verdict::kFresh);
  EXPECT_EQ(w.Check(5000), ReplayWindow::Verdict::kTooOld);
  // A floor below what was committed keeps the window.
  w.SetFloor(10);
  EXPECT_EQ(w.Check(5003), ReplayWindow::Verdict::kReplayed);
  EXPECT_EQ(w.Check(5002), ReplayWindow::Verdict::kFresh);
}

TEST_F(AuthTest, ConstantTimeEqualsAndHex) {
  EXPECT_TRUE(ConstantTimeEquals("token-123", "token-123"));
  EXPECT_FALSE(ConstantTimeEquals("token-123", "token-124"));
  EXPECT_FALSE(ConstantTimeEquals("token-123", "token-12"));
  EXPECT_FALSE(ConstantTimeEquals("", "x"));
  EXPECT_TRUE(ConstantTimeEquals("", ""));
  std::array<std::uint8_t, 3> b{};
  EXPECT_TRUE(FromHex("0aFf10", b));
  EXPECT_EQ(ToHex(b), "0aff10");
  EXPECT_FALSE(FromHex("0aFf1", b));
  EXPECT_FALSE(FromHex("0aFg10", b));
}

TEST_F(AuthTest, KeyFilesRoundTripAndBadFilesSayWhy) {
  KeyFile f;
  f.kind = KeyFile::Kind::kSensor;
  f.sensor_id = "gate-3";
  f.epoch = 12;
  f.key = DeriveSensorKey(SiteKey(), "gate-3");
  KeyFile back;
  ASSERT_EQ(ParseKeyFile(FormatKeyFile(f), &back), std::nullopt);
  EXPECT_EQ(back.kind, f.kind);
  EXPECT_EQ(back.sensor_id, f.sensor_id);
  EXPECT_EQ(back.epoch, 12u);
  EXPECT_EQ(back.key, f.key);
  const std::string key_line = "key " + ToHex(f.key) + "\n";
  const struct {
    std::string text;
    std::string error;
  } bad[] = {
      {"", "not an lrfnet key file"},
      {"lrfnet-key 2\n", "unknown key file format"},
      {"lrfnet-key 1\nkind site\nepoch 1\n", "missing 'key'"},
      {"lrfnet-key 1\nkind site\nepoch 0\n" + key_line, "epoch must be"},
      {"lrfnet-key 1\nkind site\nepoch 1\nkey 00\n", "64 hex digits"},
      {"lrfnet-key 1\nkind sensor\nepoch 1\n" + key_line, "needs 'sensor'"},
      {"lrfnet-key 1\nkind sensor\nsensor a/b\nepoch 1\n" + key_line, "sensor id"},
      {"lrfnet-key 1\nkind site\nepoch 1\nepoch 2\n" + key_line, "given twice"},
      {"lrfnet-key 1\nkind site\nepoch 1\ncolour blue\n" + key_line, "line 4: unknown entry"},
  };
  for (const auto& b : bad) {
    const auto error = ParseKeyFile(b.text, &back);
    ASSERT_TRUE(error.has_value()) << b.text;
    EXPECT_NE(error->find(b.error), std::string::npos) << *error;
  }
}

TEST_F(AuthTest, SecretFilesAreCreatedPrivateAndRefusedWhenOthersMayReadThem) {
  const auto dir =
      std::filesystem::path(::testing::TempDir()) / ("lrfnet_keys_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  KeyFile f;
  f.key = SiteKey();
  const std::string path = SiteKeyPath(dir.string(), 1);
  EXPECT_EQ(path, (dir / "site-e1.key").string());
  ASSERT_EQ(WriteSecretFile(path, FormatKeyFile(f)), std::nullopt);
  struct stat st {};
  ASSERT_EQ(::stat(path.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  // Never replaced.
  const auto again = WriteSecretFile(path, "x");
  ASSERT_TRUE(again.has_value());
  KeyFile read;
  ASSERT_EQ(ReadKeyFile(path, &read), std::nullopt);
  EXPECT_EQ(read.key, f.key);
  ::chmod(path.c_str(), 0640);
  const auto refused = ReadKeyFile(path, &read);
  ASSERT_TRUE(refused.has_value());
  EXPECT_NE(refused->find("chmod 600"), std::string::npos) << *refused;
  ::chmod(path.c_str(), 0600);
  // A folder of keys: only the asked-for kind.
  KeyFile s;
  s.kind = KeyFile::Kind::kSensor;
  s.sensor_id = "d1";
  s.key = DeriveSensorKey(SiteKey(), "d1");
  ASSERT_EQ(WriteSecretFile(SensorKeyPath(dir.string(), "d1", 1), FormatKeyFile(s)), std::nullopt);
  std::vector<KeyFile> sensors;
  ASSERT_EQ(ReadKeyDir(dir.string(), KeyFile::Kind::kSensor, &sensors), std::nullopt);
  ASSERT_EQ(sensors.size(), 1u);
  EXPECT_EQ(sensors[0].sensor_id, "d1");
  // $CREDENTIALS_DIRECTORY
  std::string expanded;
  ::setenv("CREDENTIALS_DIRECTORY", dir.string().c_str(), 1);
  ASSERT_EQ(ExpandPath("$CREDENTIALS_DIRECTORY/site-e1.key", &expanded), std::nullopt);
  EXPECT_EQ(expanded, dir.string() + "/site-e1.key");
  ::unsetenv("CREDENTIALS_DIRECTORY");
  EXPECT_TRUE(ExpandPath("${CREDENTIALS_DIRECTORY}/x", &expanded).has_value());
  ASSERT_EQ(ExpandPath("/etc/lrfnet/x.key", &expanded), std::nullopt);
  EXPECT_EQ(expanded, "/etc/lrfnet/x.key");
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace lrfnet::auth
