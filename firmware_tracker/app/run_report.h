#pragma once

// What lrfnet-tracker prints: the scan lines (--print-every) with the stop rule (--max-scans), and
// the parts of the summary line.

#include <cstdint>
#include <string>

#include "common/time.h"
#include "firmware_tracker/app/tracker_node.h"
#include "firmware_tracker/cola/scan_telegram.h"
#include "firmware_tracker/cola/stream_decoder.h"
#include "firmware_tracker/tracking/pipeline.h"

namespace lrfnet::tracker {

// UTC as 2021-01-01T12:00:03.123456Z.
std::string FormatUtc(common::UtcNs t_ns);

// The decoder's counters as "frames=N bad_checksums=N ... scan_decode_errors=N".
std::string DecoderSummary(const cola::StreamCounters& c);

// The tracking pipeline's counters as "rejected_scans=N ... unseen_coasting=N" (its scans are the
// summary's scans).
std::string PipelineSummary(const tracking::PipelineCounters& c);

// The multi-tracker's counters beyond tracks_created / tracks_confirmed as "measurements=N ...
// resumed=N".
std::string MultiTrackerSummary(const tracking::MultiTrackerCounters& c);

// The node's counters as "tracks_created=N ... mount_looks_like_legs=N", then the pipeline's and
// the multi-tracker's.
std::string NodeSummary(const TrackerNode& node);

// Scan printing and the stop rule, shared by both modes. Prints on stdout.
class ScanLog {
 public:
  ScanLog(std::uint64_t print_every, std::uint64_t max_scans)
      : print_every_(print_every), max_scans_(max_scans) {}

  // Prints every print_every-th scan (the first one included) with the node's last tracks, and
  // logs one warning each time the node's mount check turns to legs.
  // Returns false once max_scans were seen (the caller stops).
  bool OnScan(const std::string& sensor_id, const cola::ScanTelegram& scan,
              common::UtcNs receive_time_ns, const TrackerNode& node);
  std::uint64_t scans() const { return scans_; }

 private:
  std::uint64_t print_every_;
  std::uint64_t max_scans_;
  std::uint64_t scans_ = 0;
  std::uint64_t mount_warnings_ = 0;
};

}  // namespace lrfnet::tracker
