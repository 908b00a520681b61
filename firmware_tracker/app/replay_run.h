#pragma once

// lrfnet-tracker --replay: a pcap/pcapng capture of the scanner's TCP stream through the same
// decoder and node as live, on the capture's times.

#include <string>

#include "common/capture/capture_stream.h"
#include "firmware_tracker/app/config.h"
#include "firmware_tracker/app/run_report.h"

namespace lrfnet::tracker {

// Replays `path` (speed: multiple of the recorded pace, 0: as fast as possible) until its end,
// SIGINT/SIGTERM or the log's max_scans; prints the summary line. Returns the process's exit code.
int RunReplay(const TrackerConfig& config, const std::string& path,
              const capture::CaptureStreamOptions& options, const std::string& record_path,
              double speed, ScanLog& log);

}  // namespace lrfnet::tracker
