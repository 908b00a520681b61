#include "common/capture/tcp_reassembler.h"

#include <algorithm>
#include <cstdlib>
#include <limits>

#include "common/capture/packet_parser.h"

namespace lrfnet::capture {
namespace {

constexpr std::int64_t kEndOfStream = std::numeric_limits<std::int64_t>::max();
constexpr std::size_t kMaxPendingBytes = std::size_t{1} << 30;
constexpr std::size_t kMaxPendingRanges = 65536;

}  // namespace

std::optional<std::string> Validate(const TcpReassemblerOptions& options) {
  if (options.max_pending_bytes < 1 || options.max_pending_bytes > kMaxPendingBytes) {
    return "max_pending_bytes must be between 1 and 1 GiB";
  }
  if (options.max_pending_ranges < 1 || options.max_pending_ranges > kMaxPendingRanges) {
    return "max_pending_ranges must be between 1 and 65536";
  }
  if (options.jump_confirm_segments < 1 || options.jump_confirm_segments > 64) {
    return "jump_confirm_segments must be between 1 and 64";
  }
  return std::nullopt;
}

TcpReassembler::TcpReassembler(const TcpReassemblerOptions& options) : options_(options) {
  if (Validate(options_)) std::abort();
  ring_.resize(options_.max_pending_bytes);
  // Store() checks the bound before it erases the merged ranges and inserts one: never reallocates.
  ranges_.reserve(options_.max_pending_ranges);
  // Per Push() every held range is emitted at most in two parts (before and after the segment),
  // each split in two at the ring's end, plus the segment itself.
  out_.reserve(4 * options_.max_pending_ranges + 2);
}

void TcpReassembler::CheckDrained() const {
  // Chunks point into the previous payload and the ring: pushing more before they are popped would
  // invalidate them.
  if (out_read_ != out_.size()) std::abort();
}

void TcpReassembler::Push(const TcpSegment& segment) {
  CheckDrained();
  ++counters_.segments;
  if (!has_time_ || segment.time_ns > now_ns_) now_ns_ = segment.time_ns;
  has_time_ = true;
  // A reset aborts the connection; any payload it carries is diagnostic text, not stream data.
  if ((segment.flags & kTcpRst) != 0) return;

  std::uint32_t data_seq = segment.seq;
  if ((segment.flags & kTcpSyn) != 0) {
    // The SYN occupies one sequence number: data starts at ISN + 1.
    data_seq = segment.seq + 1;
    if (!has_syn_ || segment.seq != syn_seq_) {
      if (has_stream_) {
        GiveUpBefore(kEndOfStream, kEndOfStream);
        discontinuity_ = true;
      }
      StartStream(data_seq);
      has_syn_ = true;
      syn_seq_ = segment.seq;
      ++counters_.connections;
    }
  } else if (!has_stream_) {
    // Capture started mid-connection: the first data segment defines the stream start.
    if (segment.payload.empty()) return;
    StartStream(segment.seq);
  }
  HandleData(data_seq, segment.payload);
}

void TcpReassembler::Finish() {
  CheckDrained();
  GiveUpBefore(kEndOfStream, kEndOfStream);
}

bool TcpReassembler::Pop(ReassembledChunk* chunk) {
  if (out_read_ >= out_.size()) return false;
  *chunk = out_[out_read_++];
  counters_.delivered_bytes += chunk->bytes.size();
  if (out_read_ == out_.size()) {
    out_.clear();
    out_read_ = 0;
  }
  return true;
}

void TcpReassembler::StartStream(std::uint32_t first_seq) {
  has_stream_ = true;
  next_seq_ = first_seq;
  ranges_.clear();
  pending_bytes_ = 0;
  jump_run_ = 0;
}

void TcpReassembler::HandleData(std::uint32_t seq, std::span<const std::uint8_t> payload) {
  if (payload.empty()) return;
  // Signed modular distance from the next expected byte: correct across the 2^32 wrap.
  const auto distance = static_cast<std::int32_t>(seq - next_seq_);
  std::int64_t pos = next_pos_ + distance;
  const std::int64_t end = pos + static_cast<std::int64_t>(payload.size());
  if (end <= next_pos_) {
    counters_.retransmitted_bytes += payload.size();
    return;
  }
  if (pos < next_pos_) {
    const auto seen = static_cast<std::size_t>(next_pos_ - pos);
    counters_.retransmitted_bytes += seen;
    payload = payload.subspan(seen);
    pos = next_pos_;
  }
  if (pos == next_pos_) {
    jump_run_ = 0;
    Emit(payload);
    DrainContiguous();
    return;
  }
  ++counters_.out_of_order_segments;
  const auto ring_size = static_cast<std::int64_t>(ring_.size());
  // Distance from the frontier of what has been seen: a segment near the highest held byte is the
  // stream continuing past a loss; one far beyond it is a stray or forged packet until confirmed.
  const std::int64_t frontier = ranges_.empty() ? next_pos_ : ranges_.back().end;
  if (pos - frontier >= ring_size) {
    // Beyond anything that can be held: jump only when a contiguous run of such segments confirms
    // that the stream really continues there (a capture that lost more than the window).
    jump_run_ = (jump_run_ > 0 && pos == jump_run_end_) ? jump_run_ + 1 : 1;
    jump_run_end_ = end;
    if (jump_run_ < options_.jump_confirm_segments) {
      ++counters_.out_of_window_segments;
      counters_.out_of_window_bytes += payload.size();
      return;
    }
  }
  jump_run_ = 0;
  if (end - next_pos_ <= ring_size && Store(pos, payload)) return;
  // Held bytes would exceed the bound: give up on the holes before this segment.
  GiveUpBefore(pos, end);
  if (pos > next_pos_) Gap(pos);
  Emit(payload);
  DrainContiguous();
}

bool TcpReassembler::Store(std::int64_t pos, std::span<const std::uint8_t> payload) {
  const std::int64_t end = pos + static_cast<std::int64_t>(payload.size());
  // Ranges [first, last) touch or overlap [pos, end) and merge with it.
  std::size_t first = 0;
  while (first < ranges_.size() && ranges_[first].end < pos) ++first;
  std::size_t last = first;
  while (last < ranges_.size() && ranges_[last].begin <= end) ++last;
  if (ranges_.size() - (last - first) + 1 > options_.max_pending_ranges) return false;

  const auto copy = [&](std::int64_t from, std::int64_t to) {
    const std::int64_t ring_size = static_cast<std::int64_t>(ring_.size());
    while (from < to) {
      const std::int64_t index = from % ring_size;
      const std::int64_t n = std::min(to - from, ring_size - index);
      std::copy_n(payload.begin() + (from - pos), n, ring_.begin() + index);
      from += n;
    }
  };
  std::int64_t cursor = pos;
  std::int64_t duplicate = 0;
  for (std::size_t k = first; k < last; ++k) {
    const std::int64_t overlap_begin = std::max(ranges_[k].begin, pos);
    const std::int64_t overlap_end = std::min(ranges_[k].end, end);
    if (overlap_begin > cursor) copy(cursor, overlap_begin);
    if (overlap_end > overlap_begin) duplicate += overlap_end - overlap_begin;
    cursor = std::max(cursor, overlap_end);
  }
  if (end > cursor) copy(cursor, end);
  counters_.retransmitted_bytes += static_cast<std::uint64_t>(duplicate);
  pending_bytes_ += static_cast<std::size_t>(end - pos - duplicate);

  Range merged{pos, end};
  if (last > first) {
    merged.begin = std::min(pos, ranges_[first].begin);
    merged.end = std::max(end, ranges_[last - 1].end);
  }
  ranges_.erase(ranges_.begin() + static_cast<std::ptrdiff_t>(first),
                ranges_.begin() + static_cast<std::ptrdiff_t>(last));
  ranges_.insert(ranges_.begin() + static_cast<std::ptrdiff_t>(first), merged);
  return true;
}

void TcpReassembler::GiveUpBefore(std::int64_t limit, std::int64_t drop_until) {
  std::size_t keep = 0;
  for (std::size_t k = 0; k < ranges_.size(); ++k) {
    Range r = ranges_[k];
    if (r.begin < limit) {
      if (r.begin > next_pos_) Gap(r.begin);
      const std::int64_t deliver_end = std::min(r.end, limit);
      EmitFromRing(r.begin, deliver_end);
      r.begin = deliver_end;
    }
    if (r.begin < drop_until && r.begin < r.end) {
      const std::int64_t drop_end = std::min(r.end, drop_until);
      counters_.retransmitted_bytes += static_cast<std::uint64_t>(drop_end - r.begin);
      pending_bytes_ -= static_cast<std::size_t>(drop_end - r.begin);
      r.begin = drop_end;
    }
    if (r.begin < r.end) ranges_[keep++] = r;
  }
  ranges_.resize(keep);
}

void TcpReassembler::DrainContiguous() {
  std::size_t done = 0;
  while (done < ranges_.size() && ranges_[done].begin <= next_pos_) {
    const Range r = ranges_[done++];
    // The part before next_pos_ arrived again in the segment just delivered.
    const std::int64_t seen = std::min(r.end, next_pos_) - r.begin;
    counters_.retransmitted_bytes += static_cast<std::uint64_t>(seen);
    pending_bytes_ -= static_cast<std::size_t>(seen);
    if (r.end > next_pos_) EmitFromRing(next_pos_, r.end);
  }
  ranges_.erase(ranges_.begin(), ranges_.begin() + static_cast<std::ptrdiff_t>(done));
}

void TcpReassembler::EmitFromRing(std::int64_t begin, std::int64_t end) {
  const std::int64_t ring_size = static_cast<std::int64_t>(ring_.size());
  pending_bytes_ -= static_cast<std::size_t>(end - begin);
  while (begin < end) {
    const std::int64_t index = begin % ring_size;
    const std::int64_t n = std::min(end - begin, ring_size - index);
    Emit(std::span<const std::uint8_t>(ring_).subspan(static_cast<std::size_t>(index),
                                                      static_cast<std::size_t>(n)));
    begin += n;
  }
}

void TcpReassembler::Gap(std::int64_t to) {
  ++counters_.gaps;
  counters_.gap_bytes += static_cast<std::uint64_t>(to - next_pos_);
  next_seq_ += static_cast<std::uint32_t>(to - next_pos_);
  next_pos_ = to;
  discontinuity_ = true;
}

// Bytes are emitted strictly in stream order: bytes[0] is at next_pos_.
void TcpReassembler::Emit(std::span<const std::uint8_t> bytes) {
  if (bytes.empty()) return;
  if (out_.size() == out_.capacity()) std::abort();  // bounded by construction (see reserve)
  out_.push_back({bytes, next_seq_, now_ns_, discontinuity_});
  discontinuity_ = false;
  next_pos_ += static_cast<std::int64_t>(bytes.size());
  next_seq_ += static_cast<std::uint32_t>(bytes.size());
}

}  // namespace lrfnet::capture
