#pragma once

// lrfnet-tracker live: the scanner over CoLa-B/TCP (reconnecting) through the node to the outputs,
// until a signal or --max-scans.

#include <string>

#include "firmware_tracker/app/config.h"
#include "firmware_tracker/app/run_report.h"

namespace lrfnet::tracker {

// Runs until SIGINT/SIGTERM or the log's max_scans; prints the device line and the summary line
// at the end. Returns the process's exit code.
int RunLive(const TrackerConfig& config, const std::string& record_path, ScanLog& log);

}  // namespace lrfnet::tracker
