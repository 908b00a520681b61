#pragma once
// Whether a scanner configured for upper-body height (shape.mount: torso) sees legs: pure,
// header-only, used by the tracker's gateway (a counter and a log line) and by the daemon's
// calibration (a flag and a wider bias prior on that sensor's tracks).
//
// The statistic is the size each person track learns: the smaller semi-axis of its shape state
// (TrackObservation::size_minor_m; a cylinder's radius). Fitted to a person's upper body it is the
// half depth of a torso, 0.10-0.25 m over every shipped scenario (people of varying size); fitted
// to the two legs a knee-height scanner shows, it settles on one leg's radius, 0.05-0.08 m. Per
// track, its median over the states in which the track is confirmed and walking (an object's size
// is learnt while it moves past the sensor; a standing track keeps its prior); per sensor, the
// share of its tracks whose median lies below leg_max_half_width_m (a leg's radius, 0.05-0.07 m,
// and the fit's spread), measured in results/calibration_benchmark.md ("Mount check"): 50-100 %
// of the tracks of a knee-height scanner run as torso, at most 6 % of an upper-body scanner's.
// A share, not the median, so that a few children (a child's torso half depth is near 0.09 m)
// among adults do not flip the verdict, and a sensor needs min_tracks tracks for one. Carts and
// trolleys (box shapes) are not people and are left out by the caller.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>

namespace lrfnet::common {

struct MountCheckOptions {
  // A track whose learned half-width (median, metres) is below this is leg-sized.
  double leg_max_half_width_m = 0.09;
  // The sensor looks mounted at knee height when at least this share of its tracks is leg-sized.
  double min_leg_share = 0.3;
  // Fewer tracks than this give no verdict.
  std::size_t min_tracks = 5;
  // What makes one track count (the callers' accumulation): confirmed states faster than this
  // (m/s), at least this many of them.
  double min_speed_mps = 0.3;
  std::size_t min_states = 25;
};

inline std::optional<std::string> Validate(const MountCheckOptions& o) {
  if (!(o.leg_max_half_width_m > 0.0) || !std::isfinite(o.leg_max_half_width_m)) {
    return "leg_max_half_width_m must be a finite value > 0";
  }
  if (!(o.min_leg_share > 0.0 && o.min_leg_share <= 1.0)) return "min_leg_share must be in (0, 1]";
  if (o.min_tracks < 1) return "min_tracks must be >= 1";
  if (!(o.min_speed_mps >= 0.0) || !std::isfinite(o.min_speed_mps)) {
    return "min_speed_mps must be a finite value >= 0";
  }
  if (o.min_states < 1) return "min_states must be >= 1";
  return std::nullopt;
}

struct MountCheck {
  std::size_t tracks = 0;            // tracks judged
  std::size_t leg_sized = 0;         // of them below leg_max_half_width_m
  double median_half_width_m = 0.0;  // over the tracks' medians (0 without tracks)
  bool decided = false;              // at least min_tracks tracks
  bool looks_like_legs = false;      // decided, and the leg-sized share reaches min_leg_share
};

// The median of `values` (reordered; 0 when empty).
inline double MedianInPlace(std::span<double> values) {
  if (values.empty()) return 0.0;
  const std::size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(mid), values.end());
  const double upper = values[mid];
  if (values.size() % 2 == 1) return upper;
  const double lower =
      *std::max_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(mid));
  return 0.5 * (lower + upper);
}

// The verdict on an upper-body sensor from its tracks' median half-widths (metres; reordered).
// Non-finite and non-positive values are not counted.
inline MountCheck CheckUpperBodyMount(std::span<double> track_half_widths_m,
                                      const MountCheckOptions& options) {
  MountCheck out;
  const auto valid_end = std::partition(track_half_widths_m.begin(), track_half_widths_m.end(),
                                        [](double w) { return std::isfinite(w) && w > 0.0; });
  const std::span<double> valid(track_half_widths_m.begin(), valid_end);
  out.tracks = valid.size();
  out.leg_sized = static_cast<std::size_t>(std::count_if(
      valid.begin(), valid.end(), [&](double w) { return w < options.leg_max_half_width_m; }));
  out.median_half_width_m = MedianInPlace(valid);
  out.decided = out.tracks >= options.min_tracks;
  out.looks_like_legs = out.decided && static_cast<double>(out.leg_sized) >=
                                           options.min_leg_share * static_cast<double>(out.tracks);
  return out;
}

// A tracker's running check (fixed storage, no allocation after construction): fed every
// confirmed person track of every scan, it keeps each track's mean half-width over its walking
// states and, when the track ends (a scan without it) or has walked kLongTrackStates states, files
// it among the last kHistory tracks and judges them again. Not thread-safe.
template <std::size_t kTracks, std::size_t kHistory>
class MountWatch {
 public:
  static constexpr std::size_t kLongTrackStates = 500;

  explicit MountWatch(const MountCheckOptions& options = {}) : options_(options) {}

  // One confirmed person track (not a box) in the current scan.
  void Add(std::uint32_t track_id, double speed_mps, double half_width_m) {
    // The ids are unique among the live tracks, and a scan's tracks mostly come in the order of the
    // last scan's (new ones after them; a track not reported this scan leaves a gap): the one after
    // the last found is tried first, then every one (mount_check_test: the same verdicts as a plain
    // search, in any order).
    Live* live = nullptr;
    if (next_live_ < live_count_ && live_[next_live_].id == track_id) {
      live = &live_[next_live_];
    } else {
      for (std::size_t i = 0; i < live_count_; ++i) {
        if (live_[i].id == track_id) {
          live = &live_[i];
          break;
        }
      }
    }
    if (live == nullptr) {
      if (live_count_ == kTracks) return;
      live = &live_[live_count_++];
      *live = Live{track_id};
    }
    next_live_ = static_cast<std::size_t>(live - live_.data()) + 1;
    live->seen = true;
    if (!(speed_mps > options_.min_speed_mps) || !std::isfinite(half_width_m) ||
        !(half_width_m > 0.0) || live->filed) {
      return;
    }
    live->sum_m += half_width_m;
    if (++live->states == kLongTrackStates) File(*live);
  }

  // After every scan's Add calls: files the tracks that ended. True when the verdict turned to
  // legs.
  bool EndScan() {
    const bool before = verdict_.looks_like_legs;
    std::size_t kept = 0;
    for (std::size_t i = 0; i < live_count_; ++i) {
      if (!live_[i].seen) {
        if (!live_[i].filed) File(live_[i]);
        continue;
      }
      live_[i].seen = false;
      live_[kept++] = live_[i];
    }
    live_count_ = kept;
    next_live_ = 0;
    return verdict_.looks_like_legs && !before;
  }

  const MountCheck& verdict() const { return verdict_; }

 private:
  struct Live {
    std::uint32_t id = 0;
    std::size_t states = 0;
    double sum_m = 0.0;
    bool seen = false;
    bool filed = false;
  };

  void File(Live& live) {
    live.filed = true;
    if (live.states < options_.min_states) return;
    history_[next_] = live.sum_m / static_cast<double>(live.states);
    next_ = (next_ + 1) % kHistory;
    filled_ = filled_ < kHistory ? filled_ + 1 : kHistory;
    std::array<double, kHistory> copy = history_;
    verdict_ = CheckUpperBodyMount(std::span<double>(copy.data(), filled_), options_);
  }

  MountCheckOptions options_;
  std::array<Live, kTracks> live_{};
  std::size_t live_count_ = 0;
  std::size_t next_live_ = 0;  // where Add looks first
  std::array<double, kHistory> history_{};
  std::size_t next_ = 0, filled_ = 0;
  MountCheck verdict_;
};

}  // namespace lrfnet::common
