#pragma once
// The gateway's clock: UTC now, and the kernel's view of its NTP discipline (adjtimex).
//
// Live, scan times are gateway UTC (ClockMapper); how far that is from true UTC is what the
// kernel's NTP state says. The classification is a pure function so it can be tested without a
// disciplined clock; ReadClockStatus() is the thin adapter over ntp_adjtime(2), read-only
// (modes = 0), so no privileges are needed. Thread-safe (no state).

#include <cstdint>
#include <optional>
#include <string>

#include "common/time.h"

namespace lrfnet::io {

enum class ClockSync : std::uint8_t {
  kUnknown,         // the kernel could not be asked
  kSynchronized,    // NTP-disciplined, estimated error within the bound
  kUnsynchronized,  // TIME_ERROR / STA_UNSYNC, or the estimated error above the bound
  kReplay,          // times come from a capture's packet timestamps (set by the caller, never read)
};
const char* ToString(ClockSync sync);

struct ClockStatusOptions {
  // Largest kernel error estimate (esterror) still reported as synchronized. 10 ms is 1.5 cm of a
  // person walking at 1.5 m/s.
  double max_esterror_s = 0.010;
};
std::optional<std::string> Validate(const ClockStatusOptions& options);

struct ClockStatus {
  ClockSync sync = ClockSync::kUnknown;
  double esterror_s = 0.0;  // kernel's estimated error
  double maxerror_s = 0.0;  // kernel's maximum error bound
  int kernel_state = 0;     // ntp_adjtime's return value (TIME_OK ... TIME_ERROR), -1 on failure
  int error_number = 0;     // errno when the call failed
};

// Pure: the classification of an ntp_adjtime(2) answer (return value, status bits, esterror and
// maxerror in µs as struct timex reports them).
ClockStatus ClassifyClock(int kernel_state, int status_bits, long esterror_us, long maxerror_us,
                          const ClockStatusOptions& options = {});

// Asks the kernel (ntp_adjtime with modes = 0). Never fails: a failed call gives kUnknown + errno.
ClockStatus ReadClockStatus(const ClockStatusOptions& options = {});

// CLOCK_REALTIME as UTC ns.
common::UtcNs NowUtcNs();

}  // namespace lrfnet::io
