#include "tools/replay.h"

#include <cmath>
#include <cstdlib>
#include <limits>

namespace lrfnet::tools {
namespace {

constexpr common::DurationNs kMaxDurationNs = std::numeric_limits<common::DurationNs>::max();
// Keeps max_gap_s * 1e9 well inside int64 (about 31 years).
constexpr double kMaxGapLimitS = 1e9;

}  // namespace

std::optional<std::string> Validate(const ReplayScheduleOptions& options) {
  if (!std::isfinite(options.speed) || options.speed < 0.0)
    return "--speed must be a finite number >= 0 (0 = as fast as possible)";
  if (!std::isfinite(options.max_gap_s) || options.max_gap_s < 0.0 ||
      options.max_gap_s > kMaxGapLimitS)
    return "--max-gap-s must be between 0 (off) and 1e9 seconds";
  return std::nullopt;
}

ReplaySchedule::ReplaySchedule(const ReplayScheduleOptions& options) : options_(options) {
  if (Validate(options_)) std::abort();
  max_gap_ns_ = common::SecondsToNs(options_.max_gap_s);
}

common::DurationNs ReplaySchedule::Next(common::UtcNs receive_ns) {
  if (!started_) {
    started_ = true;
    last_receive_ns_ = receive_ns;
    return 0;
  }
  common::DurationNs step_ns = 0;
  if (receive_ns < last_receive_ns_) {
    ++steps_back_;
  } else {
    // Unsigned: the difference of two arbitrary int64 stamps may not fit int64.
    const std::uint64_t diff =
        static_cast<std::uint64_t>(receive_ns) - static_cast<std::uint64_t>(last_receive_ns_);
    step_ns = diff > static_cast<std::uint64_t>(kMaxDurationNs)
                  ? kMaxDurationNs
                  : static_cast<common::DurationNs>(diff);
    if (max_gap_ns_ > 0 && step_ns > max_gap_ns_) {
      step_ns = max_gap_ns_;
      ++shortened_gaps_;
    }
  }
  last_receive_ns_ = receive_ns;
  recording_ns_ =
      step_ns > kMaxDurationNs - recording_ns_ ? kMaxDurationNs : recording_ns_ + step_ns;

  common::DurationNs offset_ns = 0;
  if (options_.speed == 1.0) {
    offset_ns = recording_ns_;  // exact, whatever the length of the recording
  } else if (options_.speed > 0.0) {
    const double scaled = static_cast<double>(recording_ns_) / options_.speed;
    // 2^63 is the first double above the int64 range.
    offset_ns =
        scaled >= 9223372036854775808.0 ? kMaxDurationNs : static_cast<common::DurationNs>(scaled);
  }
  // Rounding of the division never decreases with t, but the guarantee is cheap to keep exact.
  if (offset_ns < last_offset_ns_) offset_ns = last_offset_ns_;
  last_offset_ns_ = offset_ns;
  return offset_ns;
}

std::vector<common::DurationNs> ComputeSendOffsets(std::span<const common::UtcNs> receive_ns,
                                                   const ReplayScheduleOptions& options) {
  ReplaySchedule schedule(options);
  std::vector<common::DurationNs> offsets;
  offsets.reserve(receive_ns.size());
  for (const common::UtcNs t : receive_ns) offsets.push_back(schedule.Next(t));
  return offsets;
}

SenderSlots::SenderSlots(std::size_t capacity) : capacity_(capacity) {
  if (capacity_ == 0) std::abort();
}

std::size_t SenderSlots::SlotFor(std::string_view source) {
  const auto it = slots_.find(std::string(source));
  if (it != slots_.end()) return it->second;
  if (slots_.size() < capacity_) {
    const std::size_t slot = slots_.size();
    slots_.emplace(std::string(source), slot);
    return slot;
  }
  ++shared_datagrams_;
  return capacity_ - 1;
}

}  // namespace lrfnet::tools
