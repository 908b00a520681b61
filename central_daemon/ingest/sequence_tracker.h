#pragma once
// Sequence state of one sensor (Datagram.session_id and .sequence), as ingest.h documents it:
// - the first datagram starts the state;
// - a new session_id is a restart: the state starts again at its sequence number;
// - a sequence number more than max_jump ahead of the highest seen, or more than max_jump behind
//   it, is a reset within the session: the state starts again at it;
// - above the highest: in order (the numbers skipped may still arrive);
// - below the highest and inside the window (highest - sequence < window): reordered when not
//   received yet (accepted), a duplicate when received already (to be dropped);
// - below the window: it can no longer be told from a duplicate, so it is dropped and counted as
//   one.
// `lost` counts the skipped numbers that can no longer arrive: not received while inside the
// window, or still missing when the state restarted (restart, reset). So it never decreases, and a
// late arrival inside the window is never counted as lost.
// Memory: one bit per window slot (window <= kMaxSequenceWindow), fixed at construction; no
// allocation per datagram (counters() counts the missing numbers inside the window: O(window/64)).
// Not thread-safe.

#include <cstdint>
#include <vector>

#include "central_daemon/ingest/ingest.h"

namespace lrfnet::daemon {

inline constexpr std::uint32_t kMaxSequenceWindow = 65536;

enum class SequenceVerdict : std::uint8_t {
  kFirst,      // the first datagram of this tracker
  kInOrder,    // above the highest seen (possibly after a gap)
  kReordered,  // below the highest, inside the window, not seen yet
  kDuplicate,  // seen already, or too old to tell: drop it
  kRestart,    // new session_id; the state restarted at this datagram
  kReset,      // jump beyond max_jump within the session; the state restarted at this datagram
};
const char* ToString(SequenceVerdict verdict);

// True when the datagram is to be kept.
inline bool Accepted(SequenceVerdict v) { return v != SequenceVerdict::kDuplicate; }

class SequenceTracker {
 public:
  // Preconditions: 1 <= window <= kMaxSequenceWindow, max_jump >= 1 (checked; aborts otherwise).
  SequenceTracker(std::uint32_t window, std::uint64_t max_jump);

  SequenceVerdict Observe(std::uint64_t session_id, std::uint64_t sequence);

  void set_max_jump(std::uint64_t max_jump);

  bool started() const { return started_; }
  std::uint64_t session_id() const { return session_id_; }
  std::uint64_t highest() const { return highest_; }
  SequenceCounters counters() const;

 private:
  void Start(std::uint64_t session_id, std::uint64_t sequence);
  bool Test(std::uint64_t sequence) const;
  void Set(std::uint64_t sequence);
  // Clears the slots of sequence numbers (from, to], which are about to be reused.
  void ClearSlots(std::uint64_t from, std::uint64_t to);
  // Numbers in (base_, highest_) not received that are still inside the window.
  std::uint64_t MissingInWindow() const;

  std::uint64_t window_;
  std::uint64_t max_jump_;
  std::uint64_t slots_;  // bits in received_, a multiple of 64 and >= window_
  std::vector<std::uint64_t> received_;
  bool started_ = false;
  std::uint64_t session_id_ = 0;
  std::uint64_t base_ = 0;  // first sequence number of the current state (no loss counted below)
  std::uint64_t highest_ = 0;
  // Numbers in (base_, highest_) not received yet; those outside the window are lost.
  std::uint64_t missing_in_state_ = 0;
  SequenceCounters counters_;  // lost: of earlier states only (counters() adds this state's)
};

}  // namespace lrfnet::daemon
