#pragma once
// Time-ordered store of the track frames of every sensor, for calibration and fusion (pure: no
// clock; time is passed in).
//
// Order: per sensor by (scan_start_ns, session_id, scan_counter). Frames arrive mostly in order; a
// late one (reordered datagram) is inserted at its place. Parts of one scan (same session_id,
// scan_counter and scan_start_ns) are merged into one frame (tracks appended in the order the
// parts arrive, part = 0, part_count = parts held; scan_period_s, sent_ns and receive_ns stay
// those of the first part received). Which parts a frame holds is remembered, so a part received
// twice is ignored (counted in duplicate_parts) and never duplicates tracks. A part outside
// [0, min(part_count, 64)) is refused (refused_parts); the ingest never passes one.
//
// Retention policy (documented for users in the daemon's config):
// 1. Age: on Evict(now_ns), frames whose receive_ns is older than now_ns - max_age_s are dropped.
// 2. Memory: whenever the estimated memory of all frames exceeds max_bytes, the frames with the
//    oldest receive_ns, across all sensors, are dropped until it fits again.
// The newest complete background per sensor is kept regardless (one per sensor).
// Memory is estimated from the container sizes (bytes_used()), not measured.
//
// Eviction always takes a sensor's first frame in scan order, so a sensor's frames are always a
// contiguous run of its stream (a query never sees a hole left by eviction). Both rules compare
// the receive_ns of each sensor's first frame. Frames arrive in receive order except a late
// (reordered) one, which is older in scan order but newer in receive order than the frames after
// it: while it is first, the frames behind it wait until it is old enough too. So a frame is
// dropped when it is too old or at most the reordering delay of its sensor (milliseconds in
// practice) later, and under memory pressure the sensor whose first frame was received earliest
// loses frames first.
//
// bytes_used() estimates the heap memory of the frames and backgrounds held, kept up to date on
// every add, merge, eviction and background change (libstdc++ layout, glibc malloc):
//   per frame:      FrameBytes(tracks.capacity()) = the frame record (TrackFrameData + part mask)
//                   + its share of the deque's block header and map pointer
//                   + tracks.capacity() * sizeof(TrackObservation) + one heap block header
//   per background: BackgroundBytes(ranges_mm.capacity()) = sizeof(BackgroundScan)
//                   + ranges_mm.capacity() * 4 + one heap block header
// Stored tracks are copied to vectors of exact capacity. Not counted: the per-sensor entries
// (name, map node, an empty deque: about 1 KiB per sensor; the number of sensors is bounded by
// the ingest), allocator slack and fragmentation; store_benchmark compares the estimate with
// the process's resident memory.
//
// Not thread-safe: the daemon owns it on its io thread.

#include <cstddef>
#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "central_daemon/ingest/sensor_data.h"
#include "common/time.h"

namespace lrfnet::daemon {

struct TrackStoreOptions {
  double max_age_s = 3600.0;                     // > 0, <= kTrackStoreMaxAgeLimitS
  std::size_t max_bytes = std::size_t{2} << 30;  // >= 1 MiB
};
inline constexpr double kTrackStoreMaxAgeLimitS = 1e9;  // ~31 years; keeps the ns arithmetic exact
std::optional<std::string> Validate(const TrackStoreOptions& options);

struct TrackStoreCounters {
  std::uint64_t frames_added = 0;  // parts merged into an existing frame count once each
  std::uint64_t parts_merged = 0;
  std::uint64_t late_inserts = 0;       // inserted before the newest frame of its sensor
  std::uint64_t evicted_by_age = 0;     // frames
  std::uint64_t evicted_by_memory = 0;  // frames
  std::uint64_t duplicate_parts = 0;    // a part the frame already holds (ignored)
  std::uint64_t refused_parts = 0;      // part >= part_count or part >= 64 (ignored)
  std::uint64_t stale_backgrounds = 0;  // older than the background held (ignored)
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

  // Stores a frame or merges a part into its frame (see above), then applies the memory limit.
  void Add(const std::string& sensor_id, const TrackFrameData& frame);
  // Keeps `background` as the sensor's background unless the one held is newer: of the same
  // session with a higher snapshot_id, or the same snapshot_id and a later learned_until_ns (a
  // snapshot of another session always replaces it: that session is the sensor's current one
  // or a stale datagram the ingest has already reported). Then applies the memory limit.
  void SetBackground(const std::string& sensor_id, const BackgroundScan& background);
  // Drops frames older than the age limit relative to now_ns (receive clock).
  void Evict(common::UtcNs now_ns);
  // New limits; applied at once (may evict): the memory limit, and the age limit relative to the
  // now_ns of the last Evict (none before the first Evict).
  // Precondition: Validate(options) is nullopt (checked; aborts otherwise).
  void Reconfigure(const TrackStoreOptions& options);

  // Frames of `sensor_id` with from_ns <= scan_start_ns < to_ns, in order. Empty for an unknown
  // sensor.
  std::vector<TrackFrameData> Query(std::string_view sensor_id, common::UtcNs from_ns,
                                    common::UtcNs to_ns) const;
  const BackgroundScan* Background(std::string_view sensor_id) const;  // nullptr when none
  std::vector<SensorStoreInfo> Sensors() const;                        // sorted by id
  std::size_t frames() const { return frames_; }
  std::size_t bytes_used() const { return bytes_used_; }
  const TrackStoreCounters& counters() const { return counters_; }
  const TrackStoreOptions& options() const { return options_; }

  // The estimate of bytes_used() for one frame whose track vector has capacity `tracks`, and for
  // one background with `beams` ranges (see above).
  static std::size_t FrameBytes(std::size_t tracks);
  static std::size_t BackgroundBytes(std::size_t beams);

 private:
  struct StoredFrame {
    TrackFrameData frame;         // part = 0, part_count = parts held
    std::uint64_t part_mask = 0;  // bit p set: part p held
  };
  struct SensorFrames {
    std::deque<StoredFrame> frames;  // in order (scan_start_ns, session_id, scan_counter)
    std::size_t tracks = 0;
    std::optional<BackgroundScan> background;
  };
  using SensorMap = std::map<std::string, SensorFrames, std::less<>>;
  // The first frame of every sensor that has frames, by (receive_ns, sensor id): the next frame
  // to evict is the set's first.
  struct Front {
    common::UtcNs receive_ns = 0;
    SensorMap::iterator sensor;
  };
  struct FrontLess {
    bool operator()(const Front& a, const Front& b) const {
      if (a.receive_ns != b.receive_ns) return a.receive_ns < b.receive_ns;
      return a.sensor->first < b.sensor->first;
    }
  };

  void EvictFront(SensorMap::iterator sensor);
  void EvictByAge(common::UtcNs now_ns);
  void EvictByMemory();

  TrackStoreOptions options_;
  SensorMap sensors_;
  std::set<Front, FrontLess> fronts_;
  std::optional<common::UtcNs> last_evict_now_ns_;
  std::size_t frames_ = 0;
  std::size_t bytes_used_ = 0;
  TrackStoreCounters counters_;
};

}  // namespace lrfnet::daemon
