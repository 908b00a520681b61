#pragma once

// lrfnetd offline (--input): recordings and UDP captures through the same core as live.

#include <cstdint>
#include <string>
#include <vector>

#include "central_daemon/app/config.h"
#include "central_daemon/app/run_setup.h"

namespace lrfnet::daemon {

// Offline: the datagrams of recordings and UDP captures through the same core, with their
// recorded receive times as the clock; several files are read as one stream in receive-time
// order (as they arrived live). With a calibration to start from, the input is fused and
// monitored as it is read, and --calibration-out receives that calibration with what the
// monitoring changed (instead of a new calibration over all the input).
int RunOffline(const RunOptions& run, DaemonConfig config, const std::vector<std::string>& inputs,
               std::uint16_t udp_port);

}  // namespace lrfnet::daemon
