#pragma once
// `lrfnet replay`: the pure parts of sending a recording (or UDP capture) again with its timing.
//
// ReplaySchedule turns the receive times of the datagrams, in file order, into send offsets from
// the start of the replay:
//   recording time t_i = sum over j <= i of clamp(receive_ns_j - receive_ns_{j-1}, 0, max_gap)
//   offset_i          = t_i / speed                (speed 0: every offset is 0, as fast as
//   possible)
// so with monotonic receive times and no gap limit offset_i = (receive_ns_i - receive_ns_0) /
// speed. The sender waits until start + offset_i on a steady clock, so rounding and late wake-ups
// never accumulate. A receive time that steps back (a clock step on the recording host) adds 0: the
// schedule never goes backwards; the next step counts from the earlier time, so a step back does
// not stall the replay until the old time is reached again.
//
// SenderSlots maps every distinct recorded source ("ip:port", "tracker:<id>") to one of at most
// `capacity` sender sockets, so the receiver sees distinct senders as it did live; sources beyond
// the capacity share the last slot.
//
// Pure: no clock, no socket, no logging. Not thread-safe.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "common/time.h"

namespace lrfnet::tools {

struct ReplayScheduleOptions {
  // Playback rate: 1 = recorded timing, 10 = ten times faster, 0 = as fast as possible. Finite,
  // >= 0.
  double speed = 1.0;
  // Gaps between consecutive datagrams longer than this (recording time, seconds) are shortened to
  // it; 0 = off. Finite, >= 0.
  double max_gap_s = 0.0;
};
std::optional<std::string> Validate(const ReplayScheduleOptions& options);

class ReplaySchedule {
 public:
  // Precondition: Validate(options) is nullopt (checked; aborts otherwise).
  explicit ReplaySchedule(const ReplayScheduleOptions& options);

  // The send offset of the next datagram (received at receive_ns), ns from the start of the
  // replay: >= 0 and >= every offset returned before. Saturates at the largest DurationNs.
  common::DurationNs Next(common::UtcNs receive_ns);

  // Recording time covered so far after steps back and gaps were clamped (t_i above).
  common::DurationNs recording_ns() const { return recording_ns_; }
  std::uint64_t steps_back() const { return steps_back_; }          // receive times that went back
  std::uint64_t shortened_gaps() const { return shortened_gaps_; }  // gaps cut to max_gap_s

 private:
  ReplayScheduleOptions options_;
  common::DurationNs max_gap_ns_ = 0;  // 0 = off
  bool started_ = false;
  common::UtcNs last_receive_ns_ = 0;
  common::DurationNs recording_ns_ = 0;
  common::DurationNs last_offset_ns_ = 0;
  std::uint64_t steps_back_ = 0;
  std::uint64_t shortened_gaps_ = 0;
};

// The schedule of a whole list of receive times (for tests and tools that hold them all).
std::vector<common::DurationNs> ComputeSendOffsets(std::span<const common::UtcNs> receive_ns,
                                                   const ReplayScheduleOptions& options);

inline constexpr std::size_t kMaxReplaySenders = 256;

class SenderSlots {
 public:
  // Precondition: capacity >= 1.
  explicit SenderSlots(std::size_t capacity = kMaxReplaySenders);

  // The slot (0 .. capacity - 1) of `source`: a new slot for each new source while there are
  // free ones, the last slot for every source after that. Slots are handed out in order 0, 1, ...
  std::size_t SlotFor(std::string_view source);

  std::size_t slots_used() const { return slots_.size(); }
  // Calls for sources that got no slot of their own (the capacity was used up before they came).
  std::uint64_t shared_datagrams() const { return shared_datagrams_; }

 private:
  std::size_t capacity_;
  std::unordered_map<std::string, std::size_t> slots_;  // at most capacity entries
  std::uint64_t shared_datagrams_ = 0;
};

}  // namespace lrfnet::tools
