// Fuzz target for the tracker's request decoder: arbitrary bytes as one datagram from the network
// (seeds: requests for this and other sensors, the tracker's own datagram kinds, hostile lengths).
// Properties checked with __builtin_trap:
//   - decoding is deterministic and every call is counted exactly once, accepted or with a reason;
//   - a rejected datagram sets no flag;
//   - an accepted request fits the datagram budget and, encoded again, decodes to the same request.

#include <cstddef>
#include <cstdint>
#include <span>

#include "firmware_tracker/io/request_decoder.h"

namespace {

using lrfnet::io::DecodedRequest;
using lrfnet::io::RequestDecoder;
using lrfnet::io::RequestDecoderCounters;
using lrfnet::io::RequestReject;

// The sensor id the seeds address (make_fuzz_corpus writes them).
constexpr char kSensorId[] = "gate-3";

void Check(bool ok) {
  if (!ok) __builtin_trap();
}

std::uint64_t Total(const RequestDecoderCounters& c) {
  std::uint64_t n = c.accepted;
  for (const std::uint64_t r : c.rejected) n += r;
  return n;
}

bool Same(const DecodedRequest& a, const DecodedRequest& b) {
  return a.reject == b.reject && a.send_sensor_info == b.send_sensor_info &&
         a.send_background == b.send_background && a.sequence == b.sequence &&
         a.session_id == b.session_id;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static auto* decoder = new RequestDecoder(kSensorId);
  const std::span<const std::uint8_t> input(data, size);
  const std::uint64_t before = Total(decoder->counters());
  const DecodedRequest a = decoder->Decode(input);
  const DecodedRequest b = decoder->Decode(input);
  Check(Same(a, b));
  Check(Total(decoder->counters()) == before + 2);
  Check(static_cast<int>(a.reject) < static_cast<int>(RequestReject::kCount));
  if (a.reject != RequestReject::kNone) {
    Check(!a.send_sensor_info && !a.send_background);
    return 0;
  }
  Check(size > 0 && size <= lrfnet::io::kMaxDatagramBytes);
  lrfnet::io::RequestMessage again;
  again.sensor_id = kSensorId;
  again.sequence = a.sequence;
  again.session_id = a.session_id;
  again.send_sensor_info = a.send_sensor_info;
  again.send_background = a.send_background;
  static std::uint8_t buffer[lrfnet::io::kMaxDatagramBytes];
  const std::size_t n = lrfnet::io::EncodeRequest(again, buffer);
  Check(n > 0);
  const DecodedRequest c = decoder->Decode(std::span<const std::uint8_t>(buffer, n));
  Check(Same(a, c));
  return 0;
}
