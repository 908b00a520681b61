#pragma once
// The daemon's verification step (pure: no I/O, no clock): every datagram is checked against the
// sensor keys before its protobuf is decoded (envelope: common/datagram_auth.h).
//
// With keys (AuthOptions::keys not empty), in this order, the first failure decides the reason:
//   unsigned        not an envelope
//   auth_header     a malformed envelope, or one sealed for the tracker direction
//   unknown_sensor  no key for the envelope's sensor id
//   wrong_epoch     no key of that epoch for the sensor, or an epoch older than the newest one
//                   this sensor's datagrams were accepted with (a rotated-out key)
//   wrong_key       the key id differs from the key of that sensor and epoch (another site's key,
//                   an old copy)
//   timestamp       (live only, max_counter_ahead_s > 0) the counter, the sender's start time in
//                   ns, lies further ahead of the receive time than that: a gateway clock far in
//                   the future would otherwise move the window beyond every later counter
//   replayed        the counter was accepted before (inside the window)
//   stale           the counter is older than the window, or not above the stored floor (the
//                   highest counter accepted before the daemon restarted: yesterday's recording)
//   bad_tag         the tag does not verify (forged, damaged, or sealed with another key that
//                   happens to carry the right key id)
// The window (auth::ReplayWindow, per sensor) and the sensor's newest epoch move only in Commit,
// which the ingest calls once the datagram was accepted as a whole.
// Without keys, unsigned datagrams pass unchanged; a sealed one with a plain payload is read
// without verification (counted as unverified: the caller cannot tell it from a forged one) and an
// encrypted one is refused ("encrypted": it cannot be read without the key).
// Not thread-safe: one verifier per ingest.

#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/datagram_auth.h"
#include "common/key_file.h"
#include "common/time.h"

namespace lrfnet::daemon {

struct AuthOptions {
  // The sensor keys (lrfnetd --keys DIR: its sensor-*.key files). Empty: no authentication.
  std::vector<auth::KeyFile> keys;
  // Live daemons: see "timestamp" above. 0: not checked (offline input, replays of old files).
  double max_counter_ahead_s = 0.0;
  // The daemon's own Requests: random salt and the UTC start time in ns as the first counter.
  std::uint32_t request_salt = 0;
  std::uint64_t request_first_counter = 0;
};
std::optional<std::string> Validate(const AuthOptions& options);

enum class AuthFailure : std::uint8_t {
  kNone = 0,
  kUnsigned,
  kHeader,
  kUnknownSensor,
  kWrongEpoch,
  kWrongKey,
  kAhead,
  kReplayed,
  kStale,
  kBadTag,
  kEncrypted,  // without keys: cannot be read
};

// The reason names of the ingest ("unsigned", "auth_header", ..., "timestamp" for kAhead).
const char* ToString(AuthFailure failure);

struct AuthResult {
  AuthFailure failure = AuthFailure::kNone;
  bool sealed = false;         // the datagram came in an envelope
  bool verified = false;       // ... and its tag was verified with the sensor's key
  std::string_view sensor_id;  // of the envelope (empty when unsigned or unparseable)
  std::uint32_t epoch = 0;
  std::uint64_t counter = 0;
  // The Datagram's bytes: the datagram itself when unsigned, else its (decrypted) payload. Valid
  // until the next Verify.
  std::span<const std::uint8_t> payload;
  std::string detail;  // when failed: one line for logs
  bool ok() const { return failure == AuthFailure::kNone; }
};

// What survives a daemon restart, per sensor: the newest epoch and the highest counter accepted.
struct StoredAuthState {
  std::string sensor_id;
  std::uint32_t epoch = 0;
  std::uint64_t counter = 0;
};
// One "sensor_id epoch counter" line per sensor.
std::string FormatAuthState(const std::vector<StoredAuthState>& state);
std::optional<std::string> ParseAuthState(std::string_view text, std::vector<StoredAuthState>* out);

class DatagramVerifier {
 public:
  // Precondition: Validate(options) and auth::Init().
  explicit DatagramVerifier(const AuthOptions& options);
  ~DatagramVerifier();
  DatagramVerifier(const DatagramVerifier&) = delete;
  DatagramVerifier& operator=(const DatagramVerifier&) = delete;

  bool enabled() const { return !sensors_.empty(); }
  AuthResult Verify(std::span<const std::uint8_t> bytes, common::UtcNs receive_ns);
  // The datagram `result` (ok, sealed, verified) was accepted: its counter and epoch count.
  void Commit(const AuthResult& result);

  // Seals a Request payload for `sensor_id` with the epoch its datagrams were last accepted
  // with. 0 when the sensor has no key or no accepted datagram yet, or `out` is too small.
  std::size_t SealRequest(std::string_view sensor_id, std::span<const std::uint8_t> payload,
                          std::span<std::uint8_t> out);

  // Every sensor with an accepted datagram (or a restored state), sorted by id; and the stored
  // state of a previous run (sensors without a key now are ignored). `changes` grows with every
  // Commit.
  std::vector<StoredAuthState> State() const;
  void Restore(const std::vector<StoredAuthState>& state);
  std::uint64_t changes() const { return changes_; }

 private:
  struct Sensor;
  AuthOptions options_;
  std::map<std::string, std::unique_ptr<Sensor>, std::less<>> sensors_;
  std::uint64_t request_counter_ = 0;
  std::uint64_t changes_ = 0;
  std::array<std::uint8_t, 65536> plain_{};
};

}  // namespace lrfnet::daemon
