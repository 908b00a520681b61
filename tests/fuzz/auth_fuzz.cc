// Fuzz target for the authenticated envelope (common/datagram_auth.h) as the daemon and the tracker
// read it: arbitrary bytes as one datagram through ParseEnvelope, the daemon's DatagramVerifier
// with keys and without, and the tracker's RequestDecoder with keys. Seeds (make_fuzz_corpus):
// datagrams sealed with the target's keys (plain and encrypted, both directions, two epochs), their
// truncations and bit flips, unsigned datagrams. Properties checked with __builtin_trap:
//   - a parsed envelope's parts add up to the input, its sensor id is valid;
//   - with keys, an accepted datagram was verified, sealing its payload again with the same header
//     gives the same bytes (no other input can pass), and the same bytes a second time are refused
//     as replayed; a refused one yields no payload;
//   - without keys, an unsigned datagram passes unchanged and a sealed plain one yields its
//   payload;
//   - the tracker's decoder counts every call once and a refused request sets no flag.

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <vector>

#include "central_daemon/ingest/datagram_verifier.h"
#include "common/datagram_auth.h"
#include "firmware_tracker/io/request_decoder.h"
#include "tests/fuzz/auth_fuzz_keys.h"

namespace {

using lrfnet::auth::Envelope;
using lrfnet::auth::HeaderError;

void Check(bool ok) {
  if (!ok) __builtin_trap();
}

std::uint64_t Total(const lrfnet::io::RequestDecoderCounters& c) {
  std::uint64_t n = c.accepted;
  for (const std::uint64_t r : c.rejected) n += r;
  return n;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace lrfnet;
  static const bool initialised = auth::Init();
  Check(initialised);
  static auto* keyed = new daemon::DatagramVerifier(fuzz::AuthFuzzOptions());
  static auto* keyless = new daemon::DatagramVerifier(daemon::AuthOptions{});
  static auto* tracker = new io::RequestDecoder(fuzz::kAuthFuzzSensor, fuzz::AuthFuzzKeys(2));
  const std::span<const std::uint8_t> input(data, size);

  Envelope e;
  const HeaderError header = auth::ParseEnvelope(input, &e);
  if (header == HeaderError::kNone) {
    Check(e.header.size() + e.payload.size() + e.tag.size() == size);
    Check(e.tag.size() == auth::kTagBytes);
    Check(e.header.size() == auth::kFixedHeaderBytes + e.sensor_id.size());
    Check(auth::IsValidSensorId(e.sensor_id));
    Check(auth::LooksSealed(input));
  }

  // The daemon with keys.
  const daemon::AuthResult r = keyed->Verify(input, 0);
  if (r.ok()) {
    Check(r.sealed && r.verified && header == HeaderError::kNone);
    Check(r.payload.size() == e.payload.size());
    const std::vector<std::uint8_t> payload(r.payload.begin(), r.payload.end());
    auth::SealerOptions o;
    o.sensor_id = std::string(e.sensor_id);
    o.keys = fuzz::AuthFuzzKeys(e.epoch);
    o.encrypt = e.encrypted;
    o.salt = e.salt;
    o.first_counter = e.counter;
    auth::Sealer sealer(o);
    std::vector<std::uint8_t> again(payload.size() + sealer.overhead());
    Check(sealer.Seal(payload, again) == size);
    Check(std::memcmp(again.data(), data, size) == 0);
    keyed->Commit(r);
    const daemon::AuthResult twice = keyed->Verify(input, 0);
    Check(twice.failure == daemon::AuthFailure::kReplayed);
  } else {
    Check(r.payload.empty());
  }

  // The daemon without keys.
  const daemon::AuthResult k = keyless->Verify(input, 0);
  if (!auth::LooksSealed(input)) {
    Check(k.ok() && !k.sealed && k.payload.data() == data && k.payload.size() == size);
  } else if (header == HeaderError::kNone && !e.encrypted &&
             e.direction == auth::Direction::kToDaemon) {
    Check(k.ok() && !k.verified && k.payload.data() == e.payload.data());
  } else {
    Check(!k.ok() && k.payload.empty());
  }

  // The tracker's Requests.
  const std::uint64_t before = Total(tracker->counters());
  const io::DecodedRequest q = tracker->Decode(input);
  Check(Total(tracker->counters()) == before + 1);
  if (q.reject != io::RequestReject::kNone) {
    Check(!q.send_sensor_info && !q.send_background);
  } else {
    Check(header == HeaderError::kNone && e.direction == auth::Direction::kToTracker);
  }
  return 0;
}
