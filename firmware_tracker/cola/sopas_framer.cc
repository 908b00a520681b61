#include "firmware_tracker/cola/sopas_framer.h"

#include <algorithm>
#include <cstdlib>
#include <cstring>

#include "common/byte_order.h"
#include "firmware_tracker/cola/framer.h"

namespace lrfnet::cola {
namespace {

constexpr std::size_t kColaBStartBytes = 4;
constexpr std::size_t kMinConfigurablePayload = 64;
constexpr std::size_t kMaxConfigurablePayload = std::size_t{1} << 30;

}  // namespace

const char* DialectName(Dialect d) { return d == Dialect::kColaA ? "CoLa-A" : "CoLa-B"; }

std::optional<std::string> Validate(const SopasFramerOptions& options) {
  if (options.max_payload_bytes < kMinConfigurablePayload ||
      options.max_payload_bytes > kMaxConfigurablePayload) {
    return "sopas framer: max_payload_bytes must be in [" +
           std::to_string(kMinConfigurablePayload) + ", " +
           std::to_string(kMaxConfigurablePayload) + "]";
  }
  return std::nullopt;
}

SopasFramer::SopasFramer(const SopasFramerOptions& options) : options_(options) {
  if (Validate(options_).has_value()) std::abort();  // precondition: callers validate
  buffer_.resize(kFrameHeaderBytes + options_.max_payload_bytes + kFrameTrailerBytes);
}

std::size_t SopasFramer::Feed(std::span<const std::uint8_t> bytes) {
  if (bytes.empty()) return 0;
  if (buffer_.size() - end_ < bytes.size() && begin_ > 0) Compact();
  const std::size_t n = std::min(bytes.size(), buffer_.size() - end_);
  std::memcpy(buffer_.data() + end_, bytes.data(), n);
  end_ += n;
  counters_.bytes_in += n;
  return n;
}

void SopasFramer::Compact() {
  if (pending_a_begin_ != kNoPending) {
    pending_a_begin_ -= begin_;
    pending_a_scanned_ -= begin_;
  }
  const std::size_t n = end_ - begin_;
  if (n > 0 && begin_ > 0) std::memmove(buffer_.data(), buffer_.data() + begin_, n);
  begin_ = 0;
  end_ = n;
}

void SopasFramer::Reset() {
  pending_a_begin_ = kNoPending;
  begin_ = end_ = 0;
  payload_ = {};
  reason_ = "";
}

SopasFrameStatus SopasFramer::Reject(std::uint64_t* counter, const char* reason) {
  ++*counter;
  ++counters_.garbage_bytes;
  ++begin_;  // resynchronise on the next start after the rejected one
  reason_ = reason;
  return SopasFrameStatus::kBad;
}

SopasFrameStatus SopasFramer::Next() {
  payload_ = {};
  const std::uint8_t* const base = buffer_.data();
  const void* hit = std::memchr(base + begin_, kColaAStx, end_ - begin_);
  if (hit == nullptr) {
    counters_.garbage_bytes += end_ - begin_;
    pending_a_begin_ = kNoPending;
    begin_ = end_ = 0;
    return SopasFrameStatus::kNeedMore;
  }
  const auto i = static_cast<std::size_t>(static_cast<const std::uint8_t*>(hit) - base);
  counters_.garbage_bytes += i - begin_;
  begin_ = i;
  std::size_t run = 1;
  while (run < kColaBStartBytes && i + run < end_ && base[i + run] == kColaAStx) ++run;
  if (run < kColaBStartBytes && i + run == end_) return SopasFrameStatus::kNeedMore;

  if (run == kColaBStartBytes) {
    if (end_ - begin_ < kFrameHeaderBytes) return SopasFrameStatus::kNeedMore;
    const std::uint32_t length = common::LoadBe32(base + begin_ + kColaBStartBytes);
    if (length == 0 || length > options_.max_payload_bytes) {
      return Reject(&counters_.oversize_length, length == 0
                                                    ? "CoLa-B length field is zero"
                                                    : "CoLa-B length field above the bound");
    }
    const std::size_t frame_bytes = kFrameHeaderBytes + length + kFrameTrailerBytes;
    if (end_ - begin_ < frame_bytes) return SopasFrameStatus::kNeedMore;
    const std::span<const std::uint8_t> payload(base + begin_ + kFrameHeaderBytes, length);
    if (Checksum(payload) != base[begin_ + kFrameHeaderBytes + length]) {
      return Reject(&counters_.bad_checksum, "CoLa-B checksum mismatch");
    }
    ++counters_.frames_cola_b;
    payload_ = payload;
    dialect_ = Dialect::kColaB;
    begin_ += frame_bytes;
    return SopasFrameStatus::kFrame;
  }

  // CoLa-A: the frame starts at the last STX of the run; the ones before it are stray.
  counters_.garbage_bytes += run - 1;
  begin_ = i + run - 1;
  const std::size_t start = begin_ + 1;
  const std::size_t limit = std::min(end_, start + options_.max_payload_bytes + 1);
  // A long frame fed in small pieces is scanned once, not again from its start on every Feed.
  std::size_t from = start;
  if (pending_a_begin_ == begin_) from = std::max(from, pending_a_scanned_);
  pending_a_begin_ = kNoPending;
  for (std::size_t j = from; j < limit; ++j) {
    if (base[j] == kColaAEtx) {
      if (j == start) {
        counters_.garbage_bytes += 1;  // the ETX; Reject counts the STX
        ++begin_;
        return Reject(&counters_.bad_cola_a, "empty CoLa-A frame");
      }
      ++counters_.frames_cola_a;
      payload_ = std::span<const std::uint8_t>(base + start, j - start);
      dialect_ = Dialect::kColaA;
      begin_ = j + 1;
      return SopasFrameStatus::kFrame;
    }
    if (base[j] == kColaAStx) {
      // A new start before the end: the frame was cut (a client gave up on it). Everything up
      // to the new STX is dropped.
      ++counters_.bad_cola_a;
      counters_.garbage_bytes += j - begin_;
      begin_ = j;
      reason_ = "CoLa-A frame cut by a new STX";
      return SopasFrameStatus::kBad;
    }
  }
  if (end_ - start > options_.max_payload_bytes) {
    return Reject(&counters_.bad_cola_a, "CoLa-A frame longer than the bound");
  }
  pending_a_begin_ = begin_;
  pending_a_scanned_ = limit;
  return SopasFrameStatus::kNeedMore;
}

std::vector<std::uint8_t> EncodeSopasFrame(Dialect dialect, std::span<const std::uint8_t> payload) {
  std::vector<std::uint8_t> frame;
  if (payload.empty()) return frame;
  if (dialect == Dialect::kColaB) {
    frame.resize(kFrameHeaderBytes + payload.size() + kFrameTrailerBytes);
    frame.resize(EncodeFrame(payload, frame));
    return frame;
  }
  for (const std::uint8_t b : payload) {
    if (b == kColaAStx || b == kColaAEtx) return frame;
  }
  frame.reserve(payload.size() + 2);
  frame.push_back(kColaAStx);
  frame.insert(frame.end(), payload.begin(), payload.end());
  frame.push_back(kColaAEtx);
  return frame;
}

}  // namespace lrfnet::cola
