#pragma once
// Time-ordered store of the track frames of every sensor, for calibration and fusion (pure: no
// clock; time is passed in).
//
// Order: per sensor by (scan_start_ns, session_id, scan_counter). Frames arrive mostly in order; a
// late one (reordered datagram) is inserted at its place. Parts of one scan (same session_id,
// scan_counter and scan_start_ns) are merged into one frame (tracks appended, part_count = parts
// held).
//
// Retention policy (documented for users in the daemon's config):
// 1. Age: on Evict(now_ns), frames whose receive_ns is older than now_ns - max_age_s are dropped.
// 2. Memory: whenever the estimated memory of all frames exceeds max_bytes, the frames with the
//    oldest receive_ns, across all sensors, are dropped until it fits again.
// The newest complete background per sensor is kept regardless (one per sensor).
// Memory is estimated from the container sizes (bytes_used()), not measured.
//
// Not thread-safe: the daemon owns it on its io thread.

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "central_daemon/ingest/sensor_data.h"
#include "common/time.h"

namespace lrfnet::daemon {

struct TrackStoreOptions {
  double max_age_s = 6.0 * 3600.0;           // > 0
  std::size_t max_bytes = std::size_t{1} << 30;  // >= 1 MiB
};
std::optional<std::string> Validate(const TrackStoreOptions& options);

struct TrackStoreCounters {
  std::uint64_t frames_added = 0;       // parts merged into an existing frame count once each
  std::uint64_t parts_merged = 0;
  std::uint64_t late_inserts = 0;       // inserted before the newest frame of its sensor
  std::uint64_t evicted_by_age = 0;     // frames
  std::uint64_t evicted_by_memory = 0;  // frames
};

// Time span and size of one sensor's frames.
struct SensorStoreInfo {
  std::string sensor_id;
  std::size_t frames = 0;
  std::size_t tracks = 0;
  common::UtcNs first_scan_ns = 0;  // of the oldest frame held (0 when none)
  common::UtcNs last_scan_ns = 0;   // of the newest
};

class TrackStore {
 public:
  // Precondition: Validate(options) is nullopt (checked; aborts otherwise).
  explicit TrackStore(const TrackStoreOptions& options = {});

  void Add(const std::string& sensor_id, const TrackFrameData& frame);
  void SetBackground(const std::string& sensor_id, const BackgroundScan& background);
  // Drops frames older than the age limit relative to now_ns (receive clock).
  void Evict(common::UtcNs now_ns);
  // New limits; applied at once (may evict).
  void Reconfigure(const TrackStoreOptions& options);

  // Frames of `sensor_id` with from_ns <= scan_start_ns < to_ns, in order. Empty for an unknown
  // sensor.
  std::vector<TrackFrameData> Query(std::string_view sensor_id, common::UtcNs from_ns,
                                    common::UtcNs to_ns) const;
  const BackgroundScan* Background(std::string_view sensor_id) const;  // nullptr when none
  std::vector<SensorStoreInfo> Sensors() const;  // sorted by id
  std::size_t frames() const;
  std::size_t bytes_used() const { return bytes_used_; }
  const TrackStoreCounters& counters() const { return counters_; }

 private:
  // Implementation's choice (per-sensor deque of frames, byte accounting, ...).
  struct SensorFrames;
  TrackStoreOptions options_;
  std::map<std::string, SensorFrames, std::less<>>* unused_ = nullptr;  // replace freely
  std::size_t bytes_used_ = 0;
  TrackStoreCounters counters_;
};

}  // namespace lrfnet::daemon
