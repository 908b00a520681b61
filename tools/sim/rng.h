#pragma once
// The simulator's random numbers: a small counter-seeded generator (SplitMix64 to seed
// xoshiro256**), so every stream is fixed by (scenario seed, purpose, sensor, scan index) and a
// scan's noise does not depend on which scans were simulated before it. Implemented here rather
// than with <random> distributions, whose algorithms differ between standard libraries: the same
// seed gives the same capture on every platform the project builds for (up to the last ulp of
// std::log / std::cos, which the millimetre quantisation hides in all but pathological cases).
//
// Thread-safety: a Rng is a value; use one per thread.

#include <cmath>
#include <cstdint>
#include <initializer_list>

namespace lrfnet::sim {

inline std::uint64_t SplitMix64(std::uint64_t* state) {
  std::uint64_t z = (*state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

// Mixes a list of integers (seed, purpose tag, indices) into one 64-bit seed.
inline std::uint64_t MixSeed(std::initializer_list<std::uint64_t> parts) {
  std::uint64_t state = 0x6C72666E65742D73ull;  // "lrfnet-s"
  std::uint64_t out = 0;
  for (std::uint64_t p : parts) {
    state ^= p;
    out = SplitMix64(&state);
    state = out;
  }
  return out;
}

// Purpose tags for MixSeed: one independent stream per use.
enum class RngStream : std::uint64_t {
  kRangeNoise = 1,
  kTiming = 2,
  kLatency = 3,
  kSetup = 4,
  kRandomWalk = 5,
  kSession = 6,
  kBody = 7,
};

class Rng {
 public:
  explicit Rng(std::uint64_t seed) {
    std::uint64_t sm = seed;
    for (std::uint64_t& w : s_) w = SplitMix64(&sm);
  }

  std::uint64_t NextU64() {
    const std::uint64_t result = Rotl(s_[1] * 5, 7) * 9;
    const std::uint64_t t = s_[1] << 17;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = Rotl(s_[3], 45);
    return result;
  }

  // Uniform in [0, 1) with 53 random bits.
  double Uniform() { return static_cast<double>(NextU64() >> 11) * 0x1.0p-53; }
  double Uniform(double lo, double hi) { return lo + (hi - lo) * Uniform(); }
  // Uniform integer in [0, n), n > 0 (the bias of the modulo is below 2^-40 for n < 2^24).
  std::uint64_t Below(std::uint64_t n) { return NextU64() % n; }

  // Standard normal (Box-Muller; the second value is kept for the next call).
  double Normal() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    double u1 = Uniform();
    while (u1 <= 0.0) u1 = Uniform();
    const double u2 = Uniform();
    const double r = std::sqrt(-2.0 * std::log(u1));
    constexpr double kTwoPi = 6.283185307179586476925;
    spare_ = r * std::sin(kTwoPi * u2);
    has_spare_ = true;
    return r * std::cos(kTwoPi * u2);
  }

  // Exponential with the given mean (>= 0).
  double Exponential(double mean) {
    double u = Uniform();
    while (u <= 0.0) u = Uniform();
    return -mean * std::log(u);
  }

 private:
  static std::uint64_t Rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

  std::uint64_t s_[4];
  bool has_spare_ = false;
  double spare_ = 0.0;
};

}  // namespace lrfnet::sim
