#include "central_daemon/calibration/intervals.h"

#include <algorithm>
#include <cstdint>

namespace lrfnet::calib {

std::optional<std::string> Validate(const IntervalOptions& options) {
  if (options.min_steps < 1) return "intervals.min_steps must be at least 1";
  return std::nullopt;
}

namespace {

struct Event {
  std::size_t step;
  bool of_s;    // track of sensor s (else r)
  bool starts;  // the track becomes visible (else it vanishes)
  std::size_t track;
};

void Apply(const Event& e, std::vector<std::size_t>& active) {
  const auto it = std::lower_bound(active.begin(), active.end(), e.track);
  if (e.starts) {
    active.insert(it, e.track);
  } else if (it != active.end() && *it == e.track) {
    active.erase(it);
  }
}

}  // namespace

std::vector<Interval> PairIntervals(const AlignedTracks& aligned, std::size_t r, std::size_t s,
                                    const IntervalOptions& options) {
  std::vector<Interval> out;
  if (r == s || r >= aligned.sensors.size() || s >= aligned.sensors.size()) return out;
  const std::size_t min_steps = std::max<std::size_t>(options.min_steps, 1);

  // A sweep over track births and deaths: between two consecutive event steps the visible sets
  // of both sensors are constant, which is exactly the paper's "change in visible objects".
  std::vector<Event> events;
  const auto add_events = [&](const SensorTracks& sensor, bool of_s) {
    for (std::size_t i = 0; i < sensor.tracks.size(); ++i) {
      const GridTrack& t = sensor.tracks[i];
      if (t.samples.empty() || t.end_step() < t.first_step) continue;  // none, or wrapped
      events.push_back({t.first_step, of_s, true, i});
      events.push_back({t.end_step(), of_s, false, i});
    }
  };
  add_events(aligned.sensors[r], false);
  add_events(aligned.sensors[s], true);
  // Deaths before births at the same step, so a track ending where another starts never makes
  // both look visible at once.
  std::sort(events.begin(), events.end(), [](const Event& a, const Event& b) {
    if (a.step != b.step) return a.step < b.step;
    return a.starts < b.starts;
  });

  std::vector<std::size_t> active_r, active_s;
  std::size_t i = 0;
  while (i < events.size()) {
    const std::size_t step = events[i].step;
    for (; i < events.size() && events[i].step == step; ++i) {
      Apply(events[i], events[i].of_s ? active_s : active_r);
    }
    if (i == events.size()) break;  // every track has ended
    const std::size_t next = events[i].step;
    if (!active_r.empty() && !active_s.empty() && next - step >= min_steps) {
      out.push_back({step, next, active_r, active_s});
    }
  }
  return out;
}

}  // namespace lrfnet::calib
