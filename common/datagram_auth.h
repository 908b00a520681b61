#pragma once
// Authenticated datagrams: the envelope every lrfnet datagram travels in when keys are configured
// (tracker -> daemon and the daemon's Requests back), the per-sensor keys, and the replay window.
// libsodium is the one dependency (ChaCha20-Poly1305 IETF, BLAKE2b via crypto_kdf).
//
// Envelope, version 1 (integers big-endian; n = length of the sensor id, 1..32):
//
//   offset  bytes  field
//   0       1      magic 0xB7: no protobuf message starts with it (wire type 7 does not exist),
//                  so a sealed datagram is never taken for an unsigned Datagram and vice versa
//   1       1      envelope version, 1
//   2       1      flags: bit 0 = payload encrypted, bit 1 = direction (0: tracker -> daemon,
//                  1: daemon -> tracker); the other bits are 0
//   3       1      n
//   4       n      sensor id ([A-Za-z0-9_.-]): whose key seals the datagram
//   4+n     4      key epoch (which generation of the site's keys)
//   8+n     4      key id: the first 4 bytes of crypto_kdf(sensor key, 0, "lrfnetid"); tells a
//                  wrong key (another site, a stale copy) from a forged or damaged datagram
//   12+n    4      salt: random per sender start
//   16+n    8      counter: the sender's UTC start time in ns, +1 per datagram it seals
//   24+n    m      payload: the lrfnet.proto Datagram, or its ciphertext (same length)
//   24+n+m  16     tag (Poly1305)
//
// Sealing (crypto_aead_chacha20poly1305_ietf_encrypt_detached):
//   key   = the direction's key: crypto_kdf_derive_from_key(32, 1 (to daemon) | 2 (to tracker),
//           "lrfnetdg", sensor key), so the two directions never share a key;
//   nonce = salt (4 bytes) || counter (8 bytes), 12 bytes;
//   plain payload: message empty, associated data = header || payload (the whole datagram);
//   encrypted:     message = payload, associated data = header.
// A nonce is never used twice with a key: within one sender start the counter grows by one per
// datagram; a restarted sender draws a new salt and starts its counter at its new start time, which
// lies beyond every counter of the earlier start as long as its clock moved forward by more than
// the number of datagrams sent (nanoseconds against datagrams: always, unless the clock was set
// back), and the 32-bit salt covers that case too. For the receiver the counter is a sequence that
// grows across sender restarts: it keeps the highest one (ReplayWindow) and, the daemon, stores it,
// so yesterday's datagrams stay refused after its own restart.
//
// Per-sensor keys from the site key (DeriveSensorKey): the sensor id's bytes are taken in chunks
// of 8 (zero-padded; ids hold no NUL), and every chunk is one crypto_kdf_derive_from_key step with
// the chunk as the 64-bit subkey id (little-endian) and the context "lrfnS" + chunk index (one
// digit) + id length (two digits):
//   K_0 = site key,  K_{i+1} = crypto_kdf_derive_from_key(32, LE64(chunk_i), ctx_i, K_i),
//   sensor key = K_last (1 to 4 steps for ids of 1 to 32 bytes).
// Two different ids never give the same derivation inputs: they differ in length (then every
// context differs) or in a first chunk (then that step's subkey id differs after equal earlier
// steps). A single step could not do this: an id carries up to 192 bits, subkey id + context 128.
//
// Everything here is pure (no I/O, no clock, no allocation); thread-compatible.

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

namespace lrfnet::auth {

inline constexpr std::size_t kKeyBytes = 32;
inline constexpr std::size_t kTagBytes = 16;
inline constexpr std::size_t kNonceBytes = 12;
inline constexpr std::size_t kMaxSensorIdBytes = 32;
inline constexpr std::uint8_t kMagic = 0xB7;
inline constexpr std::uint8_t kEnvelopeVersion = 1;
// Header without the sensor id, and the most an envelope adds to a payload.
inline constexpr std::size_t kFixedHeaderBytes = 24;
inline constexpr std::size_t kMaxOverheadBytes = kFixedHeaderBytes + kMaxSensorIdBytes + kTagBytes;

using Key = std::array<std::uint8_t, kKeyBytes>;

enum class Direction : std::uint8_t { kToDaemon = 0, kToTracker = 1 };

// libsodium's one-time set-up (sodium_init); false when the library cannot be used. Call once at
// start-up, before any other function here (the first call allocates; later calls do not).
bool Init();

// [A-Za-z0-9_.-]{1,32}, the sensor ids of lrfnet.proto.
bool IsValidSensorId(std::string_view id);

// The per-sensor key for `sensor_id` (IsValidSensorId; checked, aborts otherwise), as above.
Key DeriveSensorKey(const Key& site_key, std::string_view sensor_id);

// The keys one sensor's datagrams are sealed with in one epoch, derived once from its key.
struct SensorKeys {
  std::uint32_t epoch = 0;
  std::uint32_t key_id = 0;
  Key to_daemon{};
  Key to_tracker{};
  const Key& For(Direction d) const { return d == Direction::kToDaemon ? to_daemon : to_tracker; }
};
SensorKeys DeriveSensorKeys(const Key& sensor_key, std::uint32_t epoch);

// True when the bytes start like an envelope (the magic byte); unsigned Datagrams never do.
inline bool LooksSealed(std::span<const std::uint8_t> bytes) {
  return !bytes.empty() && bytes[0] == kMagic;
}

enum class HeaderError : std::uint8_t {
  kNone = 0,
  kTooShort,     // shorter than its header + tag
  kNotEnvelope,  // not an envelope
  kVersion,      // an envelope version this program does not know
  kFlags,        // reserved flag bits set
  kSensorId,     // length 0 or > 32, or a byte outside [A-Za-z0-9_.-]
};
const char* ToString(HeaderError error);

// The header fields of an envelope, pointing into its bytes.
struct Envelope {
  std::string_view sensor_id;
  std::uint32_t epoch = 0;
  std::uint32_t key_id = 0;
  std::uint32_t salt = 0;
  std::uint64_t counter = 0;
  bool encrypted = false;
  Direction direction = Direction::kToDaemon;
  std::span<const std::uint8_t> header;   // bytes [0, 24 + n)
  std::span<const std::uint8_t> payload;  // plain or ciphertext
  std::span<const std::uint8_t> tag;      // 16 bytes
};

// Splits `bytes` into header, payload and tag without any cryptography. kNone on success.
HeaderError ParseEnvelope(std::span<const std::uint8_t> bytes, Envelope* out);

// Verifies the tag with `keys` (the key id and epoch are the caller's to check first) and, for an
// encrypted payload, decrypts it into `plain` (at least payload.size() bytes). On success
// *payload is the plain payload (inside the datagram, or inside `plain`). False: bad tag (then
// nothing is written to *payload; `plain` may hold garbage).
bool OpenEnvelope(const Envelope& envelope, const SensorKeys& keys, std::span<std::uint8_t> plain,
                  std::span<const std::uint8_t>* payload);

struct SealerOptions {
  std::string sensor_id;  // IsValidSensorId
  SensorKeys keys;
  Direction direction = Direction::kToDaemon;
  bool encrypt = false;             // encrypt the payload (tracks of people can be personal data)
  std::uint32_t salt = 0;           // random per start (the caller draws it)
  std::uint64_t first_counter = 0;  // the sender's UTC start time in ns
};
std::optional<std::string> Validate(const SealerOptions& options);

// One sender's sealing state: every Seal uses the next counter.
class Sealer {
 public:
  // Precondition: Validate(options) (checked; aborts otherwise).
  explicit Sealer(const SealerOptions& options);

  // Seals `payload` into `out`; returns the envelope's size, or 0 (nothing consumed) when `out`
  // is smaller than payload.size() + overhead(). `payload` and `out` must not overlap.
  std::size_t Seal(std::span<const std::uint8_t> payload, std::span<std::uint8_t> out);

  std::size_t overhead() const { return kFixedHeaderBytes + sensor_id_length_ + kTagBytes; }
  std::uint64_t next_counter() const { return counter_; }
  const SealerOptions& options() const { return options_; }

 private:
  SealerOptions options_;
  std::size_t sensor_id_length_ = 0;
  std::uint64_t counter_ = 0;
};

// RFC 6479-style anti-replay window over the envelope counter: a bitmap of kWindowBits below the
// highest counter seen, kept in 64-bit blocks that are recycled as the window slides (no shifting
// of the whole bitmap). Check before the tag is verified, Commit after the datagram is accepted.
// A floor (e.g. the highest counter stored before a restart) refuses everything at or below it.
class ReplayWindow {
 public:
  static constexpr std::uint64_t kBlockBits = 64;
  static constexpr std::size_t kBlocks = 64;  // one block of them is the one being filled
  static constexpr std::uint64_t kWindowBits = (kBlocks - 1) * kBlockBits;  // 4032

  enum class Verdict : std::uint8_t { kFresh, kReplayed, kTooOld };
  Verdict Check(std::uint64_t counter) const;
  // Marks `counter` as seen (after Check said kFresh and the datagram was accepted).
  void Commit(std::uint64_t counter);
  // Refuses every counter <= floor (kTooOld); the window then starts above it.
  void SetFloor(std::uint64_t floor);

  // The highest counter committed or the floor, and whether there is one.
  std::uint64_t highest() const { return highest_; }
  bool has_highest() const { return has_highest_; }

 private:
  std::array<std::uint64_t, kBlocks> bitmap_{};
  std::uint64_t highest_ = 0;
  bool has_highest_ = false;
  std::uint64_t floor_ = 0;
  bool has_floor_ = false;
};

// Lowercase hex of bytes, and its inverse (false on a wrong length or a non-hex character).
std::string ToHex(std::span<const std::uint8_t> bytes);
bool FromHex(std::string_view hex, std::span<std::uint8_t> out);

// Fills `out` with random bytes (libsodium's randombytes_buf: getrandom(2)).
void RandomBytes(std::span<std::uint8_t> out);

// Constant-time equality of two byte strings of any lengths: the time depends only on the
// lengths, never on where they differ (crypto_generichash of both, then sodium_memcmp).
bool ConstantTimeEquals(std::string_view a, std::string_view b);

}  // namespace lrfnet::auth
