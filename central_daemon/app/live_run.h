#pragma once

// lrfnetd live: datagrams from the UDP socket through the core, with the calibration, fusion,
// monitoring, zones, MQTT and the live view on one io_context, until a signal or --duration-s.

#include "central_daemon/app/config.h"
#include "central_daemon/app/run_setup.h"

namespace lrfnet::daemon {

// Runs until SIGINT/SIGTERM (or run.duration_s); SIGHUP reloads run.config_path, SIGUSR1
// calibrates. Prints "listening ADDR" (and the live view's address) once bound, the summary line
// at the end. Returns the process's exit code.
int RunLive(const RunOptions& run, DaemonConfig config);

}  // namespace lrfnet::daemon
