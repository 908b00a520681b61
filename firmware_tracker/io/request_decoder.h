#pragma once
// Decodes the daemon's `Request` datagrams (lrfnet.proto) that arrive on the uplink socket, and
// encodes them (for the daemon side of tests and tools that play the daemon).
//
// Accepted: a well-formed Datagram of at most kMaxDatagramBytes, version PROTOCOL_VERSION_1,
// payload `request`, and a sensor_id that is empty (addressed to every tracker) or equals ours.
// Everything else is rejected with a reason, counted per reason, and never read beyond the given
// bytes (nanopb decodes into static fields; over-long strings and arrays are decode errors).
// Unknown fields are skipped (newer daemons may add some).
// With keys (this sensor's, from its key file), a Request must come sealed (common/datagram_auth.h)
// for this sensor, in the daemon -> tracker direction, with the key's epoch and id, a counter not
// seen before (ReplayWindow) and a valid tag; anything else is rejected and counted before its
// protobuf is read. The window lives as long as the decoder: a Request replayed after a tracker
// restart can make the tracker send its sensor info or background once more, nothing else.
// Not thread-safe; no allocation.

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>

#include "common/datagram_auth.h"
#include "common/time.h"
#include "firmware_tracker/io/datagram_encoder.h"
#include "lrfnet.nanopb.h"

namespace lrfnet::io {

enum class RequestReject : std::uint8_t {
  kNone = 0,
  kEmpty,
  kTooLarge,        // more than kMaxDatagramBytes
  kMalformed,       // not a Datagram (or a field beyond the static bounds)
  kUnknownVersion,  // version != PROTOCOL_VERSION_1
  kNotARequest,     // another payload, or none
  kOtherSensor,     // addressed to a different sensor id
  kUnsigned,        // keys configured, but not sealed
  kEnvelope,        // a malformed envelope, or one sealed for the other direction
  kWrongEpoch,      // sealed with another epoch's key
  kWrongKey,        // sealed with another key (its key id is not ours)
  kBadTag,          // forged or damaged
  kReplayed,        // its counter was seen already, or is older than the window
  kCount,
};
const char* ToString(RequestReject reason);

struct DecodedRequest {
  RequestReject reject = RequestReject::kNone;  // kNone = accepted
  bool send_sensor_info = false;
  bool send_background = false;
  std::uint64_t sequence = 0;
  std::uint64_t session_id = 0;  // the sender's
};

struct RequestDecoderCounters {
  std::uint64_t accepted = 0;
  std::array<std::uint64_t, static_cast<std::size_t>(RequestReject::kCount)> rejected{};
  std::uint64_t Rejected(RequestReject reason) const {
    return rejected[static_cast<std::size_t>(reason)];
  }
};

class RequestDecoder {
 public:
  // sensor_id: this tracker's id (IsValidSensorId), copied. keys: this sensor's keys when the
  // uplink is authenticated (auth::Init() called before).
  explicit RequestDecoder(std::string_view sensor_id,
                          const std::optional<auth::SensorKeys>& keys = std::nullopt);

  DecodedRequest Decode(std::span<const std::uint8_t> datagram);
  const RequestDecoderCounters& counters() const { return counters_; }

 private:
  DecodedRequest Reject(RequestReject reason);
  DecodedRequest DecodeProtobuf(std::span<const std::uint8_t> datagram);

  std::array<char, kMaxSensorIdLength + 1> sensor_id_{};
  std::size_t sensor_id_length_ = 0;
  std::optional<auth::SensorKeys> keys_;
  auth::ReplayWindow window_;
  RequestDecoderCounters counters_;
  lrfnet_proto_Datagram message_{};
  std::array<std::uint8_t, kMaxDatagramBytes> plain_{};
};

struct RequestMessage {
  std::string_view sensor_id;  // empty = every tracker; at most kMaxSensorIdLength bytes
  std::uint64_t sequence = 0;
  common::UtcNs sent_ns = 0;
  std::uint64_t session_id = 0;
  bool send_sensor_info = false;
  bool send_background = false;
};

// Serialises a Request datagram into `out`; returns the size, or 0 when it does not fit or the
// sensor id is too long.
std::size_t EncodeRequest(const RequestMessage& request, std::span<std::uint8_t> out);

}  // namespace lrfnet::io
