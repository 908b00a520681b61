#include "firmware_tracker/cola/framer.h"

#include <algorithm>
#include <cstdlib>
#include <cstring>

#include "common/byte_order.h"

namespace lrfnet::cola {
namespace {

constexpr std::uint8_t kStx = 0x02;
constexpr std::size_t kStartBytes = 4;
// The length field is a uint32; a bound beyond 1 GiB would only let one bad length field pin that
// much memory.
constexpr std::size_t kMaxConfigurablePayload = std::size_t{1} << 30;
// Smallest bound that still holds the telegrams the codec decodes ("sSN LMDscandata " + fixed
// header).
constexpr std::size_t kMinConfigurablePayload = 64;


}  // namespace

std::optional<std::string> Validate(const FramerOptions& options) {
  if (options.max_payload_bytes < kMinConfigurablePayload) {
    return "framer: max_payload_bytes must be at least " + std::to_string(kMinConfigurablePayload);
  }
  if (options.max_payload_bytes > kMaxConfigurablePayload) {
    return "framer: max_payload_bytes must be at most " + std::to_string(kMaxConfigurablePayload);
  }
  return std::nullopt;
}

Framer::Framer(const FramerOptions& options) : options_(options) {
  if (Validate(options_).has_value()) std::abort();  // precondition: callers validate their options
  buffer_.resize(kFrameHeaderBytes + options_.max_payload_bytes + kFrameTrailerBytes);
}

std::size_t Framer::Feed(std::span<const std::uint8_t> bytes) {
  if (bytes.empty()) return 0;
  if (buffer_.size() - end_ < bytes.size() && begin_ > 0) Compact();
  const std::size_t n = std::min(bytes.size(), buffer_.size() - end_);
  std::memcpy(buffer_.data() + end_, bytes.data(), n);
  end_ += n;
  counters_.bytes_in += n;
  return n;
}

void Framer::Compact() {
  const std::size_t n = end_ - begin_;
  if (n > 0 && begin_ > 0) std::memmove(buffer_.data(), buffer_.data() + begin_, n);
  begin_ = 0;
  end_ = n;
}

FrameStatus Framer::Next() {
  payload_ = {};
  const std::uint8_t* const base = buffer_.data();
  // Search for a start sequence at or after begin_. Bytes before it are garbage; a tail that could
  // still become a start sequence (up to three 0x02) is kept for the next Feed.
  std::size_t i = begin_;
  while (true) {
    const void* hit = std::memchr(base + i, kStx, end_ - i);
    if (hit == nullptr) {
      i = end_;
      break;
    }
    i = static_cast<std::size_t>(static_cast<const std::uint8_t*>(hit) - base);
    std::size_t run = 1;
    while (run < kStartBytes && i + run < end_ && base[i + run] == kStx) ++run;
    if (run == kStartBytes || i + run == end_)
      break;  // a start, or a possible start cut by the end
    i += run;
  }
  counters_.garbage_bytes += i - begin_;
  begin_ = i;
  if (end_ - begin_ < kFrameHeaderBytes) {
    if (begin_ == end_) begin_ = end_ = 0;  // empty: a free rewind instead of a later memmove
    return FrameStatus::kNeedMore;
  }
  const std::uint32_t length = common::LoadBe32(base + begin_ + kStartBytes);
  if (length == 0 || length > options_.max_payload_bytes) {
    ++counters_.oversize_length;
    ++counters_.garbage_bytes;
    ++begin_;  // resynchronise on the next start after the rejected one
    reason_ =
        length == 0 ? "frame length field is zero" : "frame length field above max_payload_bytes";
    return FrameStatus::kBad;
  }
  const std::size_t frame_bytes = kFrameHeaderBytes + length + kFrameTrailerBytes;
  if (end_ - begin_ < frame_bytes) return FrameStatus::kNeedMore;
  const std::span<const std::uint8_t> payload(base + begin_ + kFrameHeaderBytes, length);
  if (Checksum(payload) != base[begin_ + kFrameHeaderBytes + length]) {
    // The length field may itself be corrupt, so the bytes it covers may hold the next real frame:
    // search again from the byte after this start.
    ++counters_.bad_checksum;
    ++counters_.garbage_bytes;
    ++begin_;
    reason_ = "frame checksum mismatch";
    return FrameStatus::kBad;
  }
  ++counters_.frames;
  payload_ = payload;
  begin_ += frame_bytes;
  return FrameStatus::kFrame;
}

void Framer::Reset() {
  begin_ = end_ = 0;
  payload_ = {};
  reason_ = "";
}

std::size_t EncodeFrame(std::span<const std::uint8_t> payload, std::span<std::uint8_t> out) {
  const std::size_t size = kFrameHeaderBytes + payload.size() + kFrameTrailerBytes;
  if (payload.size() > 0xFFFFFFFFu || out.size() < size) return 0;
  std::uint8_t* p = out.data();
  p[0] = p[1] = p[2] = p[3] = kStx;
  const auto n = static_cast<std::uint32_t>(payload.size());
  common::StoreBe32(p + 4, n);
  if (!payload.empty()) std::memcpy(p + kFrameHeaderBytes, payload.data(), payload.size());
  p[kFrameHeaderBytes + payload.size()] = Checksum(payload);
  return size;
}

std::uint8_t Checksum(std::span<const std::uint8_t> payload) {
  // Fold eight bytes at a time: XOR is associative, so the folded word XORs down to the same byte.
  std::uint64_t acc = 0;
  std::size_t i = 0;
  for (; i + 8 <= payload.size(); i += 8) {
    std::uint64_t w;
    std::memcpy(&w, payload.data() + i, 8);
    acc ^= w;
  }
  acc ^= acc >> 32;
  acc ^= acc >> 16;
  acc ^= acc >> 8;
  auto sum = static_cast<std::uint8_t>(acc);
  for (; i < payload.size(); ++i) sum ^= payload[i];
  return sum;
}

}  // namespace lrfnet::cola
