#include "central_daemon/ingest/sequence_tracker.h"

#include <algorithm>
#include <bit>
#include <cstdio>
#include <cstdlib>

namespace lrfnet::daemon {

const char* ToString(SequenceVerdict verdict) {
  switch (verdict) {
    case SequenceVerdict::kFirst:
      return "first";
    case SequenceVerdict::kInOrder:
      return "in_order";
    case SequenceVerdict::kReordered:
      return "reordered";
    case SequenceVerdict::kDuplicate:
      return "duplicate";
    case SequenceVerdict::kRestart:
      return "restart";
    case SequenceVerdict::kReset:
      return "reset";
  }
  return "invalid";
}

SequenceTracker::SequenceTracker(std::uint32_t window, std::uint64_t max_jump)
    : window_(window), max_jump_(max_jump) {
  if (window == 0 || window > kMaxSequenceWindow || max_jump == 0) {
    std::fprintf(stderr, "SequenceTracker: window %u (1 to %u) or max_jump %llu (>= 1) invalid\n",
                 window, kMaxSequenceWindow, static_cast<unsigned long long>(max_jump));
    std::abort();
  }
  // A power of two, so a slot is a mask away from its sequence number.
  slots_ = std::bit_ceil(std::max<std::uint64_t>(window_, 64));
  received_.assign(slots_ / 64, 0);
}

void SequenceTracker::set_max_jump(std::uint64_t max_jump) {
  if (max_jump == 0) std::abort();
  max_jump_ = max_jump;
}

bool SequenceTracker::Test(std::uint64_t sequence) const {
  const std::uint64_t slot = sequence & (slots_ - 1);
  return (received_[slot / 64] >> (slot % 64)) & 1u;
}

void SequenceTracker::Set(std::uint64_t sequence) {
  const std::uint64_t slot = sequence & (slots_ - 1);
  received_[slot / 64] |= std::uint64_t{1} << (slot % 64);
}

void SequenceTracker::ClearSlots(std::uint64_t from, std::uint64_t to) {
  std::uint64_t n = to - from;
  if (n >= slots_) {
    std::fill(received_.begin(), received_.end(), 0);
    return;
  }
  std::uint64_t slot = (from + 1) & (slots_ - 1);
  while (n > 0) {
    const std::uint64_t bit = slot % 64;
    const std::uint64_t take = std::min<std::uint64_t>(n, 64 - bit);
    const std::uint64_t mask =
        take == 64 ? ~std::uint64_t{0} : ((std::uint64_t{1} << take) - 1) << bit;
    received_[slot / 64] &= ~mask;
    n -= take;
    slot = (slot + take) & (slots_ - 1);
  }
}

std::uint64_t SequenceTracker::MissingInWindow() const {
  // Numbers (lo, highest_) with lo = max(base_, highest_ - window_): at most window_ - 1 of them.
  // Counted by how many are left, not by comparing with highest_: lo + 1 wraps to 0 where lo is
  // the largest sequence number (a hostile datagram's), and a loop up to highest_ would then run
  // over the whole 64-bit range.
  const std::uint64_t lo = std::max(base_, highest_ - std::min(highest_, window_));
  std::uint64_t missing = 0;
  std::uint64_t left = highest_ - lo;  // lo <= highest_: base_ <= highest_
  left = left > 0 ? left - 1 : 0;
  for (std::uint64_t s = lo + 1; left > 0;) {
    const std::uint64_t slot = s & (slots_ - 1);
    const std::uint64_t bit = slot % 64;
    const std::uint64_t take = std::min<std::uint64_t>(left, 64 - bit);
    const std::uint64_t mask =
        take == 64 ? ~std::uint64_t{0} : ((std::uint64_t{1} << take) - 1) << bit;
    missing += take - static_cast<std::uint64_t>(std::popcount(received_[slot / 64] & mask));
    s += take;
    left -= take;
  }
  return missing;
}

SequenceCounters SequenceTracker::counters() const {
  SequenceCounters out = counters_;
  if (started_) out.lost += missing_in_state_ - MissingInWindow();
  return out;
}

void SequenceTracker::Start(std::uint64_t session_id, std::uint64_t sequence) {
  // What this state still misses can no longer arrive as part of it.
  if (started_) counters_.lost += missing_in_state_;
  missing_in_state_ = 0;
  started_ = true;
  session_id_ = session_id;
  base_ = sequence;
  highest_ = sequence;
  std::fill(received_.begin(), received_.end(), 0);
  Set(sequence);
  ++counters_.received;
}

SequenceVerdict SequenceTracker::Observe(std::uint64_t session_id, std::uint64_t sequence) {
  if (!started_) {
    Start(session_id, sequence);
    return SequenceVerdict::kFirst;
  }
  if (session_id != session_id_) {
    ++counters_.restarts;
    Start(session_id, sequence);
    return SequenceVerdict::kRestart;
  }
  if (sequence > highest_) {
    const std::uint64_t ahead = sequence - highest_;
    if (ahead > max_jump_) {
      ++counters_.resets;
      Start(session_id, sequence);
      return SequenceVerdict::kReset;
    }
    ClearSlots(highest_, sequence);
    missing_in_state_ += ahead - 1;
    highest_ = sequence;
    Set(sequence);
    ++counters_.received;
    return SequenceVerdict::kInOrder;
  }
  const std::uint64_t behind = highest_ - sequence;
  // Far behind is a sequence that started over without a new session (a tracker bug or a
  // counter reset); waiting for it to pass the old highest would drop everything until then.
  if (behind > max_jump_) {
    ++counters_.resets;
    Start(session_id, sequence);
    return SequenceVerdict::kReset;
  }
  if (behind >= window_ || Test(sequence)) {
    ++counters_.duplicates;
    return SequenceVerdict::kDuplicate;
  }
  Set(sequence);
  ++counters_.received;
  ++counters_.reordered;
  // Numbers below the start of the state were never missing.
  if (sequence > base_) --missing_in_state_;
  return SequenceVerdict::kReordered;
}

}  // namespace lrfnet::daemon
