#include "firmware_tracker/io/request_decoder.h"

#include <pb_decode.h>
#include <pb_encode.h>

#include <algorithm>
#include <cstring>
#include <type_traits>

namespace lrfnet::io {

const char* ToString(RequestReject reason) {
  switch (reason) {
    case RequestReject::kNone:
      return "accepted";
    case RequestReject::kEmpty:
      return "empty datagram";
    case RequestReject::kTooLarge:
      return "datagram too large";
    case RequestReject::kMalformed:
      return "malformed datagram";
    case RequestReject::kUnknownVersion:
      return "unknown protocol version";
    case RequestReject::kNotARequest:
      return "not a request";
    case RequestReject::kOtherSensor:
      return "addressed to another sensor";
    case RequestReject::kUnsigned:
      return "not sealed";
    case RequestReject::kEnvelope:
      return "malformed envelope";
    case RequestReject::kWrongEpoch:
      return "sealed with another key epoch";
    case RequestReject::kWrongKey:
      return "sealed with another key";
    case RequestReject::kBadTag:
      return "bad tag";
    case RequestReject::kReplayed:
      return "replayed";
    case RequestReject::kCount:
      break;
  }
  return "unknown";
}

RequestDecoder::RequestDecoder(std::string_view sensor_id,
                               const std::optional<auth::SensorKeys>& keys)
    : keys_(keys) {
  const std::size_t n = std::min(sensor_id.size(), kMaxSensorIdLength);
  if (n > 0) std::memcpy(sensor_id_.data(), sensor_id.data(), n);
  sensor_id_length_ = n;
}

DecodedRequest RequestDecoder::Reject(RequestReject reason) {
  ++counters_.rejected[static_cast<std::size_t>(reason)];
  DecodedRequest r;
  r.reject = reason;
  return r;
}

DecodedRequest RequestDecoder::Decode(std::span<const std::uint8_t> datagram) {
  if (datagram.empty()) return Reject(RequestReject::kEmpty);
  if (datagram.size() > kMaxDatagramBytes) return Reject(RequestReject::kTooLarge);
  if (!keys_) return DecodeProtobuf(datagram);
  // Authenticated: everything about the envelope is checked before the protobuf is read.
  if (!auth::LooksSealed(datagram)) return Reject(RequestReject::kUnsigned);
  auth::Envelope e;
  if (auth::ParseEnvelope(datagram, &e) != auth::HeaderError::kNone ||
      e.direction != auth::Direction::kToTracker) {
    return Reject(RequestReject::kEnvelope);
  }
  if (e.sensor_id != std::string_view(sensor_id_.data(), sensor_id_length_))
    return Reject(RequestReject::kOtherSensor);
  if (e.epoch != keys_->epoch) return Reject(RequestReject::kWrongEpoch);
  if (e.key_id != keys_->key_id) return Reject(RequestReject::kWrongKey);
  if (window_.Check(e.counter) != auth::ReplayWindow::Verdict::kFresh)
    return Reject(RequestReject::kReplayed);
  std::span<const std::uint8_t> payload;
  if (!auth::OpenEnvelope(e, *keys_, plain_, &payload)) return Reject(RequestReject::kBadTag);
  const DecodedRequest r = DecodeProtobuf(payload);
  if (r.reject == RequestReject::kNone) window_.Commit(e.counter);
  return r;
}

DecodedRequest RequestDecoder::DecodeProtobuf(std::span<const std::uint8_t> datagram) {
  if (datagram.empty()) return Reject(RequestReject::kEmpty);
  pb_istream_t stream = pb_istream_from_buffer(datagram.data(), datagram.size());
  message_ = lrfnet_proto_Datagram{};  // nothing of an earlier datagram survives, padding included
  if (!pb_decode(&stream, lrfnet_proto_Datagram_fields, &message_))
    return Reject(RequestReject::kMalformed);
  // nanopb (C) stores whatever number arrived in the enum field; reading a value outside the
  // enumerators through the C++ enum type is undefined, so the raw integer is compared.
  std::underlying_type_t<lrfnet_proto_ProtocolVersion> version = 0;
  static_assert(sizeof(version) == sizeof(message_.version));
  std::memcpy(&version, &message_.version, sizeof(version));
  if (version != lrfnet_proto_ProtocolVersion_PROTOCOL_VERSION_1)
    return Reject(RequestReject::kUnknownVersion);
  if (message_.which_payload != lrfnet_proto_Datagram_request_tag)
    return Reject(RequestReject::kNotARequest);
  // sensor_id is NUL-terminated within its 33 bytes by the decoder; compare the whole field so an
  // embedded NUL cannot make a longer id match ours.
  if (message_.sensor_id[0] != '\0' &&
      std::memcmp(message_.sensor_id, sensor_id_.data(), sensor_id_.size()) != 0)
    return Reject(RequestReject::kOtherSensor);
  ++counters_.accepted;
  DecodedRequest r;
  r.send_sensor_info = message_.payload.request.send_sensor_info;
  r.send_background = message_.payload.request.send_background;
  r.sequence = message_.sequence;
  r.session_id = message_.session_id;
  return r;
}

std::size_t EncodeRequest(const RequestMessage& request, std::span<std::uint8_t> out) {
  if (request.sensor_id.size() > kMaxSensorIdLength) return 0;
  lrfnet_proto_Datagram message{};
  message.version = lrfnet_proto_ProtocolVersion_PROTOCOL_VERSION_1;
  if (!request.sensor_id.empty())
    std::memcpy(message.sensor_id, request.sensor_id.data(), request.sensor_id.size());
  message.sequence = request.sequence;
  message.sent_ns = request.sent_ns;
  message.session_id = request.session_id;
  message.which_payload = lrfnet_proto_Datagram_request_tag;
  message.payload.request.send_sensor_info = request.send_sensor_info;
  message.payload.request.send_background = request.send_background;
  pb_ostream_t stream = pb_ostream_from_buffer(out.data(), out.size());
  if (!pb_encode(&stream, lrfnet_proto_Datagram_fields, &message)) return 0;
  return stream.bytes_written;
}

}  // namespace lrfnet::io
