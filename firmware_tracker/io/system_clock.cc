#include "firmware_tracker/io/system_clock.h"

#include <sys/timex.h>

#include <cerrno>
#include <cmath>
#include <ctime>

namespace lrfnet::io {

const char* ToString(ClockSync sync) {
  switch (sync) {
    case ClockSync::kUnknown:
      return "unknown";
    case ClockSync::kSynchronized:
      return "synchronized";
    case ClockSync::kUnsynchronized:
      return "unsynchronized";
    case ClockSync::kReplay:
      return "replay";
  }
  return "unknown";
}

std::optional<std::string> Validate(const ClockStatusOptions& options) {
  if (!std::isfinite(options.max_esterror_s) || options.max_esterror_s <= 0.0)
    return "clock: max_esterror_s must be positive";
  return std::nullopt;
}

ClockStatus ClassifyClock(int kernel_state, int status_bits, long esterror_us, long maxerror_us,
                          const ClockStatusOptions& options) {
  ClockStatus s;
  s.kernel_state = kernel_state;
  if (kernel_state < 0) return s;
  s.esterror_s = static_cast<double>(esterror_us) * 1e-6;
  s.maxerror_s = static_cast<double>(maxerror_us) * 1e-6;
  // The kernel sets STA_UNSYNC until an NTP daemon disciplines the clock, and returns TIME_ERROR
  // while it is unsynchronised (also when maxerror has grown past NTP_PHASE_LIMIT without updates).
  const bool unsync = kernel_state == TIME_ERROR || (status_bits & STA_UNSYNC) != 0;
  s.sync = unsync || s.esterror_s > options.max_esterror_s ? ClockSync::kUnsynchronized
                                                           : ClockSync::kSynchronized;
  return s;
}

ClockStatus ReadClockStatus(const ClockStatusOptions& options) {
  struct timex tx {};
  tx.modes = 0;  // read only
  const int state = ntp_adjtime(&tx);
  if (state < 0) {
    ClockStatus s;
    s.kernel_state = -1;
    s.error_number = errno;
    return s;
  }
  return ClassifyClock(state, tx.status, tx.esterror, tx.maxerror, options);
}

common::UtcNs NowUtcNs() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<common::UtcNs>(ts.tv_sec) * common::kNsPerS + ts.tv_nsec;
}

}  // namespace lrfnet::io
