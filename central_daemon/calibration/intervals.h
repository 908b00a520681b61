#pragma once
// Dynamic intervals of a sensor pair (Quenzel et al., section III-C): a new interval starts
// whenever the set of tracks visible to either sensor of the pair changes, so that within one
// interval every track of r and of s is present on every grid step.
//
// Pure functions over values; thread-safe for concurrent calls on const inputs.

#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "central_daemon/calibration/types.h"

namespace lrfnet::calib {

// Grid steps [first_step, end_step) during which the sets of visible tracks of both sensors do not
// change; both sets are non-empty. Track indices are ascending.
struct Interval {
  std::size_t first_step = 0, end_step = 0;
  std::vector<std::size_t> tracks_r, tracks_s;  // indices into SensorTracks::tracks

  std::size_t steps() const { return end_step - first_step; }
};

struct IntervalOptions {
  // Intervals shorter than this many grid steps are dropped (0.5 s at the default 0.05 s grid):
  // too short for a hypothesis of their own.
  std::size_t min_steps = 10;
};

std::optional<std::string> Validate(const IntervalOptions& options);

// The intervals of sensors r and s (indices into aligned.sensors, r != s), ordered by first_step,
// non-overlapping. Tracks without samples are ignored; a track is taken to be visible on every
// step it covers (GridTrack::Covers). Returns an empty list for out-of-range or equal indices.
std::vector<Interval> PairIntervals(const AlignedTracks& aligned, std::size_t r, std::size_t s,
                                    const IntervalOptions& options);

}  // namespace lrfnet::calib
