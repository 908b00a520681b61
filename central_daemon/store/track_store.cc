#include "central_daemon/store/track_store.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <tuple>

namespace lrfnet::daemon {
namespace {

// glibc malloc: an 8-byte chunk header, chunks rounded up to 16 bytes; 16 is the mean cost.
constexpr std::size_t kHeapBlockOverheadBytes = 16;
// libstdc++'s std::deque keeps its elements in blocks of 512 bytes' worth (at least one element)
// and one map pointer per block.
constexpr std::size_t kDequeBlockBytes = 512;

auto OrderKey(const TrackFrameData& f) {
  return std::tie(f.scan_start_ns, f.session_id, f.scan_counter);
}

}  // namespace

std::optional<std::string> Validate(const TrackStoreOptions& options) {
  if (!(std::isfinite(options.max_age_s) && options.max_age_s > 0.0 &&
        options.max_age_s <= kTrackStoreMaxAgeLimitS)) {
    return "max_age_s must be > 0 and at most 1e9";
  }
  if (options.max_bytes < (std::size_t{1} << 20)) return "max_bytes must be at least 1 MiB";
  return std::nullopt;
}

std::size_t TrackStore::FrameBytes(std::size_t tracks) {
  constexpr std::size_t kPerBlock =
      std::max<std::size_t>(1, kDequeBlockBytes / sizeof(StoredFrame));
  constexpr std::size_t kDequeShare =
      (kHeapBlockOverheadBytes + sizeof(void*) + kPerBlock - 1) / kPerBlock;
  return sizeof(StoredFrame) + kDequeShare +
         (tracks > 0 ? tracks * sizeof(TrackObservation) + kHeapBlockOverheadBytes : 0);
}

std::size_t TrackStore::BackgroundBytes(std::size_t beams) {
  return sizeof(BackgroundScan) +
         (beams > 0 ? beams * sizeof(std::uint32_t) + kHeapBlockOverheadBytes : 0);
}

TrackStore::TrackStore(const TrackStoreOptions& options) : options_(options) {
  if (Validate(options_)) std::abort();  // precondition: callers validate their options
}

void TrackStore::Add(const std::string& sensor_id, const TrackFrameData& frame) {
  // The part mask has 64 bits; the ingest bounds part_count by 64.
  if (frame.part >= frame.part_count || frame.part >= 64) {
    ++counters_.refused_parts;
    return;
  }
  const std::uint64_t bit = std::uint64_t{1} << frame.part;
  auto sensor = sensors_.find(sensor_id);
  if (sensor == sensors_.end()) sensor = sensors_.emplace(sensor_id, SensorFrames{}).first;
  SensorFrames& s = sensor->second;
  auto& frames = s.frames;

  // Nearly always the frame is the newest: the binary search is for late ones.
  auto pos = frames.end();
  if (!frames.empty() && !(OrderKey(frames.back().frame) < OrderKey(frame))) {
    pos = std::lower_bound(frames.begin(), frames.end(), frame,
                           [](const StoredFrame& a, const TrackFrameData& b) {
                             return OrderKey(a.frame) < OrderKey(b);
                           });
  }

  if (pos != frames.end() && OrderKey(pos->frame) == OrderKey(frame)) {
    if (pos->part_mask & bit) {
      ++counters_.duplicate_parts;
      return;
    }
    // Grow to the exact size so that the estimate (capacity) stays tight; a scan has few parts.
    auto& tracks = pos->frame.tracks;
    const std::size_t old_capacity = tracks.capacity();
    std::vector<TrackObservation> merged;
    merged.reserve(tracks.size() + frame.tracks.size());
    merged.insert(merged.end(), tracks.begin(), tracks.end());
    merged.insert(merged.end(), frame.tracks.begin(), frame.tracks.end());
    tracks = std::move(merged);
    pos->part_mask |= bit;
    pos->frame.part_count = static_cast<std::uint32_t>(std::popcount(pos->part_mask));
    s.tracks += frame.tracks.size();
    bytes_used_ = bytes_used_ - FrameBytes(old_capacity) + FrameBytes(tracks.capacity());
    ++counters_.parts_merged;
  } else {
    const bool late = pos != frames.end();
    const bool new_front = pos == frames.begin();
    if (new_front && !frames.empty()) fronts_.erase(Front{frames.front().frame.receive_ns, sensor});
    StoredFrame stored{frame, bit};
    stored.frame.part = 0;
    stored.frame.part_count = 1;
    stored.frame.tracks.shrink_to_fit();
    const std::size_t bytes = FrameBytes(stored.frame.tracks.capacity());
    frames.insert(pos, std::move(stored));
    if (new_front) fronts_.insert(Front{frames.front().frame.receive_ns, sensor});
    s.tracks += frame.tracks.size();
    bytes_used_ += bytes;
    ++frames_;
    ++counters_.frames_added;
    if (late) ++counters_.late_inserts;
  }
  EvictByMemory();
}

void TrackStore::SetBackground(const std::string& sensor_id, const BackgroundScan& background) {
  auto sensor = sensors_.find(sensor_id);
  if (sensor == sensors_.end()) sensor = sensors_.emplace(sensor_id, SensorFrames{}).first;
  auto& held = sensor->second.background;
  if (held && held->session_id == background.session_id &&
      std::tie(held->snapshot_id, held->learned_until_ns) >
          std::tie(background.snapshot_id, background.learned_until_ns)) {
    ++counters_.stale_backgrounds;
    return;
  }
  if (held) bytes_used_ -= BackgroundBytes(held->ranges_mm.capacity());
  held = background;
  held->ranges_mm.shrink_to_fit();
  bytes_used_ += BackgroundBytes(held->ranges_mm.capacity());
  EvictByMemory();
}

void TrackStore::Evict(common::UtcNs now_ns) {
  last_evict_now_ns_ = now_ns;
  EvictByAge(now_ns);
}

void TrackStore::Reconfigure(const TrackStoreOptions& options) {
  if (Validate(options)) std::abort();  // precondition: callers validate their options
  options_ = options;
  if (last_evict_now_ns_) EvictByAge(*last_evict_now_ns_);
  EvictByMemory();
}

void TrackStore::EvictFront(SensorMap::iterator sensor) {
  SensorFrames& s = sensor->second;
  const StoredFrame& first = s.frames.front();
  fronts_.erase(Front{first.frame.receive_ns, sensor});
  bytes_used_ -= FrameBytes(first.frame.tracks.capacity());
  s.tracks -= first.frame.tracks.size();
  s.frames.pop_front();
  --frames_;
  if (!s.frames.empty()) fronts_.insert(Front{s.frames.front().frame.receive_ns, sensor});
}

void TrackStore::EvictByAge(common::UtcNs now_ns) {
  // max_age_s <= 1e9 s, so the limit in ns fits; saturate instead of wrapping for a now_ns near
  // the lower end of the range.
  const common::UtcNs max_age_ns = common::SecondsToNs(options_.max_age_s);
  const common::UtcNs cutoff_ns = now_ns < std::numeric_limits<common::UtcNs>::min() + max_age_ns
                                      ? std::numeric_limits<common::UtcNs>::min()
                                      : now_ns - max_age_ns;
  while (!fronts_.empty() && fronts_.begin()->receive_ns < cutoff_ns) {
    EvictFront(fronts_.begin()->sensor);
    ++counters_.evicted_by_age;
  }
}

void TrackStore::EvictByMemory() {
  while (bytes_used_ > options_.max_bytes && !fronts_.empty()) {
    EvictFront(fronts_.begin()->sensor);
    ++counters_.evicted_by_memory;
  }
}

std::vector<TrackFrameData> TrackStore::Query(std::string_view sensor_id, common::UtcNs from_ns,
                                              common::UtcNs to_ns) const {
  std::vector<TrackFrameData> out;
  const auto sensor = sensors_.find(sensor_id);
  if (sensor == sensors_.end() || from_ns >= to_ns) return out;
  const auto& frames = sensor->second.frames;
  const auto by_start = [](const StoredFrame& a, common::UtcNs t) {
    return a.frame.scan_start_ns < t;
  };
  const auto begin = std::lower_bound(frames.begin(), frames.end(), from_ns, by_start);
  const auto end = std::lower_bound(begin, frames.end(), to_ns, by_start);
  out.reserve(static_cast<std::size_t>(end - begin));
  for (auto it = begin; it != end; ++it) out.push_back(it->frame);
  return out;
}

const BackgroundScan* TrackStore::Background(std::string_view sensor_id) const {
  const auto sensor = sensors_.find(sensor_id);
  if (sensor == sensors_.end() || !sensor->second.background) return nullptr;
  return &*sensor->second.background;
}

std::vector<SensorStoreInfo> TrackStore::Sensors() const {
  std::vector<SensorStoreInfo> out;
  out.reserve(sensors_.size());
  for (const auto& [id, s] : sensors_) {
    SensorStoreInfo info;
    info.sensor_id = id;
    info.frames = s.frames.size();
    info.tracks = s.tracks;
    if (!s.frames.empty()) {
      info.first_scan_ns = s.frames.front().frame.scan_start_ns;
      info.last_scan_ns = s.frames.back().frame.scan_start_ns;
    }
    out.push_back(std::move(info));
  }
  return out;
}

}  // namespace lrfnet::daemon
