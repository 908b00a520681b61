// The daemon's track store: N sensors x 50 Hz x 5 tracks for one simulated hour (1% of the frames
// arrive one scan late). Reports frames/s added, the time of a 60 s query, memory per sensor-hour
// (the store's estimate, bytes_used(), and the growth of the process's resident memory for the same
// data), and the cost of eviction. Prints a markdown table and writes it to OUT.
//
//   store_benchmark [OUT] [--sensors N] [--minutes M]      (OUT: results/store_benchmark.md)

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "central_daemon/store/track_store.h"

namespace {

using Clock = std::chrono::steady_clock;
using lrfnet::common::kNsPerMs;
using lrfnet::common::kNsPerS;
using lrfnet::common::UtcNs;
using lrfnet::daemon::TrackFrameData;
using lrfnet::daemon::TrackObservation;
using lrfnet::daemon::TrackStore;
using lrfnet::daemon::TrackStoreOptions;

constexpr UtcNs kT0 = 1'700'000'000LL * kNsPerS;
constexpr UtcNs kPeriodNs = 20 * kNsPerMs;  // 50 Hz
constexpr std::size_t kTracks = 5;

// Resident memory of this process (VmRSS), bytes.
std::size_t RssBytes() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::stoull(line.substr(6)) * 1024;
  }
  return 0;
}

double Seconds(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

// The frames of scans [k_begin, k_end) of every sensor, in receive order: scan k of every sensor
// is received 5 ms after it starts, except every 100th, which is received after scan k + 1.
struct Feeder {
  std::vector<std::string> ids;
  std::vector<TrackFrameData> templates;

  explicit Feeder(std::size_t sensors) {
    for (std::size_t s = 0; s < sensors; ++s) {
      char id[16];
      std::snprintf(id, sizeof(id), "s%03zu", s);
      ids.emplace_back(id);
      TrackFrameData f;
      f.session_id = 1000 + s;
      f.scan_period_s = 0.02;
      for (std::size_t i = 0; i < kTracks; ++i) {
        TrackObservation t;
        t.track_id = static_cast<std::uint32_t>(i);
        t.x_m = static_cast<float>(i);
        f.tracks.push_back(t);
      }
      templates.push_back(f);
    }
  }

  TrackFrameData& Scan(std::size_t sensor, std::uint32_t k) {
    TrackFrameData& f = templates[sensor];
    f.scan_counter = k;
    f.scan_start_ns = kT0 + static_cast<UtcNs>(k) * kPeriodNs + static_cast<UtcNs>(sensor) * 1000;
    f.sent_ns = f.scan_start_ns + 2 * kNsPerMs;
    f.receive_ns = f.scan_start_ns + 5 * kNsPerMs;
    return f;
  }

  void Feed(TrackStore& store, std::uint32_t k_begin, std::uint32_t k_end) {
    for (std::uint32_t k = k_begin; k < k_end; ++k) {
      for (std::size_t s = 0; s < ids.size(); ++s) {
        if (k % 100 == 0 && k + 1 < k_end) {
          store.Add(ids[s], Scan(s, k + 1));
          TrackFrameData& late = Scan(s, k);
          late.receive_ns += 2 * kPeriodNs;
          store.Add(ids[s], late);
        } else if (k % 100 != 1 || k == k_begin) {
          store.Add(ids[s], Scan(s, k));
        }
      }
    }
  }
};

}  // namespace

int main(int argc, char** argv) {
  std::string out = "results/store_benchmark.md";
  std::size_t sensors = 10;
  double minutes = 60.0;
  bool have_out = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--sensors" && i + 1 < argc) {
      sensors = std::stoul(argv[++i]);
    } else if (a == "--minutes" && i + 1 < argc) {
      minutes = std::stod(argv[++i]);
    } else if (!have_out && !a.empty() && a[0] != '-') {
      out = a;
      have_out = true;
    } else {
      std::fprintf(stderr, "usage: store_benchmark [OUT] [--sensors N] [--minutes M]\n");
      return 2;
    }
  }
  if (sensors == 0 || sensors > 1024 || !(minutes > 0.0 && minutes <= 600.0)) {
    std::fprintf(stderr, "store_benchmark: --sensors must be 1..1024, --minutes 0..600\n");
    return 2;
  }
  const auto scans = static_cast<std::uint32_t>(minutes * 60.0 * 50.0);
  const double sensor_hours = static_cast<double>(sensors) * minutes / 60.0;

  Feeder feeder(sensors);
  TrackStoreOptions options;
  options.max_bytes = std::size_t{1} << 40;  // keep everything: measure the memory of the full hour
  TrackStore store(options);

  // 1. Fill.
  const std::size_t rss_before = RssBytes();
  const auto t_fill = Clock::now();
  feeder.Feed(store, 0, scans);
  const double fill_s = Seconds(t_fill, Clock::now());
  const std::size_t rss_after = RssBytes();
  const std::size_t frames = store.frames();
  const std::size_t bytes = store.bytes_used();
  const double est_per_sensor_hour = static_cast<double>(bytes) / sensor_hours;
  const double rss_per_sensor_hour = static_cast<double>(rss_after - rss_before) / sensor_hours;

  // 2. Queries of a 60 s window at random places of one random sensor.
  std::mt19937 rng(1);
  const UtcNs window_ns = 60 * kNsPerS;
  const UtcNs span_ns = static_cast<UtcNs>(scans) * kPeriodNs;
  std::vector<double> query_us;
  std::size_t frames_per_query = 0;
  for (int q = 0; q < 300; ++q) {
    const std::string& id = feeder.ids[rng() % sensors];
    const UtcNs from =
        kT0 + (span_ns > window_ns
                   ? static_cast<UtcNs>(rng() % static_cast<std::uint64_t>(span_ns - window_ns))
                   : 0);
    const auto a = Clock::now();
    const auto result = store.Query(id, from, from + window_ns);
    query_us.push_back(Seconds(a, Clock::now()) * 1e6);
    frames_per_query = std::max(frames_per_query, result.size());
  }
  std::sort(query_us.begin(), query_us.end());
  const double query_median_us = query_us[query_us.size() / 2];
  const double query_p99_us = query_us[query_us.size() * 99 / 100];

  // 3. Memory limit at half: the eviction at once, then one more minute of traffic while full.
  options.max_bytes = std::max<std::size_t>(bytes / 2, std::size_t{1} << 20);
  const auto t_shrink = Clock::now();
  store.Reconfigure(options);
  const double shrink_s = Seconds(t_shrink, Clock::now());
  const std::uint64_t shrink_evicted = store.counters().evicted_by_memory;
  const std::uint32_t extra_scans = 60 * 50;
  const std::uint64_t added_before = store.counters().frames_added;
  const auto t_full = Clock::now();
  feeder.Feed(store, scans, scans + extra_scans);
  const double full_s = Seconds(t_full, Clock::now());
  const auto full_frames = static_cast<double>(store.counters().frames_added - added_before);

  // 4. Age eviction of everything.
  const auto t_evict = Clock::now();
  const std::size_t before_evict = store.frames();
  store.Evict(kT0 + span_ns + 10 * 3600 * kNsPerS);
  const double evict_s = Seconds(t_evict, Clock::now());
  const std::size_t rss_end = RssBytes();

  const double mb = 1e6;
  const double default_budget = static_cast<double>(TrackStoreOptions{}.max_bytes);
  char table[4096];
  std::snprintf(
      table, sizeof(table),
      "# Track store (one core)\n\n"
      "%zu sensors x 50 Hz x %zu tracks for %.0f simulated minutes (%zu frames; 1%% of them one "
      "scan late). Estimate per frame: FrameBytes(%zu) = %zu B.\n\n"
      "| measure | value |\n|---|---|\n"
      "| frames added per second (no eviction) | %.0f |\n"
      "| frames added per second (memory limit reached: each add evicts, freed memory is reused) "
      "| %.0f |\n"
      "| query of a 60 s window (%zu frames), median / p99 | %.0f / %.0f µs |\n"
      "| memory per sensor-hour, estimate (bytes_used) | %.1f MB |\n"
      "| memory per sensor-hour, process RSS growth | %.1f MB |\n"
      "| RSS growth / estimate | %.3f |\n"
      "| Reconfigure to half the memory: frames evicted, time | %llu, %.1f ms |\n"
      "| Evict(now) of every frame: frames, time | %zu, %.1f ms |\n"
      "| RSS after evicting everything (malloc keeps freed memory) | %.1f MB above start |\n"
      "| default max_bytes (1 GiB) holds | %.1f sensor-hours (%.1f min of 100 sensors) |\n",
      sensors, kTracks, minutes, frames, kTracks, TrackStore::FrameBytes(kTracks),
      static_cast<double>(frames) / fill_s, full_frames / full_s, frames_per_query, query_median_us,
      query_p99_us, est_per_sensor_hour / mb, rss_per_sensor_hour / mb,
      rss_per_sensor_hour / est_per_sensor_hour, static_cast<unsigned long long>(shrink_evicted),
      shrink_s * 1e3, before_evict, evict_s * 1e3,
      (static_cast<double>(rss_end) - static_cast<double>(rss_before)) / mb,
      default_budget / est_per_sensor_hour, default_budget / est_per_sensor_hour / 100.0 * 60.0);
  std::fputs(table, stdout);
  const auto parent = std::filesystem::path(out).parent_path();
  if (!parent.empty()) std::filesystem::create_directories(parent);
  std::ofstream(out) << table;
  std::printf("\nwritten to %s\n", out.c_str());
  return 0;
}
