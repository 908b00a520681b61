#pragma once

// What lrfnet-tracker's two runs (live and replay) share: the exit codes, a session id and the
// scan path's CPU time.

#include <chrono>
#include <cstdint>

namespace lrfnet::tracker {

inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;
inline constexpr int kExitUsage = 2;

// A fresh random session id (every datagram of this run carries it).
std::uint64_t RandomSessionId();

// Microseconds of the steady clock since `since`.
double ElapsedUs(std::chrono::steady_clock::time_point since);

}  // namespace lrfnet::tracker
