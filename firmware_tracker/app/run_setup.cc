#include "firmware_tracker/app/run_setup.h"

#include <random>

namespace lrfnet::tracker {

std::uint64_t RandomSessionId() {
  std::random_device device;
  return (static_cast<std::uint64_t>(device()) << 32) ^ device();
}

double ElapsedUs(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - since)
      .count();
}

}  // namespace lrfnet::tracker
