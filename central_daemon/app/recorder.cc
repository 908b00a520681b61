#include "central_daemon/app/recorder.h"

#include <spdlog/spdlog.h>

#include <cstring>

namespace lrfnet::daemon {

void Recorder::CheckErrors() {
  const RecordingWriterCounters& c = writer_.counters();
  if (c.write_errors != reported_errors_) {
    spdlog::error("recording {}: write error ({}), {} entries lost so far", writer_.current_path(),
                  std::strerror(c.last_errno), c.dropped_entries);
    reported_errors_ = c.write_errors;
  }
}

}  // namespace lrfnet::daemon
