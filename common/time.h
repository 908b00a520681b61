#pragma once
// Time types. Absolute time is UTC in integer nanoseconds since the Unix epoch (int64 covers ±292 years).
// SICK devices stamp scans with a free-running uint32 microsecond tick that wraps every 2^32 µs (~71.6 min);
// TickUnwrapper turns that into a monotonic int64 microsecond count.

#include <cstdint>

namespace lrfnet::common {

using UtcNs = std::int64_t;       // UTC, ns since 1970-01-01T00:00:00Z
using DurationNs = std::int64_t;  // a signed span of time, ns

inline constexpr DurationNs kNsPerUs = 1000;
inline constexpr DurationNs kNsPerMs = 1000 * 1000;
inline constexpr DurationNs kNsPerS = 1000 * 1000 * 1000;

constexpr double NsToSeconds(DurationNs ns) { return static_cast<double>(ns) * 1e-9; }
constexpr DurationNs SecondsToNs(double s) { return static_cast<DurationNs>(s * 1e9); }

// Unwraps a uint32 µs sensor tick. Consecutive ticks are assumed less than half a wrap (~35.8 min) apart;
// a step backwards by more than `restart_threshold_us` (default 10 s) is treated as a device restart rather
// than jitter and reported, so callers can reset their clock models.
class TickUnwrapper {
 public:
  struct Result {
    std::int64_t ticks_us = 0;  // unwrapped, monotonic within one device session
    bool restarted = false;     // the device restarted before this tick (ticks_us starts a new epoch)
  };

  explicit TickUnwrapper(std::uint32_t restart_threshold_us = 10'000'000)
      : restart_threshold_us_(restart_threshold_us) {}

  Result Unwrap(std::uint32_t tick_us) {
    Result r;
    if (!has_last_) {
      has_last_ = true;
      last_raw_ = tick_us;
      unwrapped_ = epoch_base_ + tick_us;
      r.ticks_us = unwrapped_;
      return r;
    }
    // Modular difference: small positive = forward, huge = backwards.
    const std::uint32_t forward = tick_us - last_raw_;
    const std::uint32_t backward = last_raw_ - tick_us;
    if (forward <= 0x7fffffffu) {
      unwrapped_ += forward;
    } else if (backward <= restart_threshold_us_) {
      unwrapped_ -= backward;  // small jitter backwards: keep it, callers see a non-monotonic stamp
    } else {
      // Restart: the new session starts after everything seen so far, so stamps stay ordered.
      epoch_base_ = unwrapped_ + 1;
      unwrapped_ = epoch_base_ + tick_us;
      r.restarted = true;
      ++restarts_;
    }
    last_raw_ = tick_us;
    r.ticks_us = unwrapped_;
    return r;
  }

  void Reset() { *this = TickUnwrapper(restart_threshold_us_); }
  std::uint64_t restarts() const { return restarts_; }

 private:
  std::uint32_t restart_threshold_us_;
  bool has_last_ = false;
  std::uint32_t last_raw_ = 0;
  std::int64_t unwrapped_ = 0;
  std::int64_t epoch_base_ = 0;
  std::uint64_t restarts_ = 0;
};

}  // namespace lrfnet::common
