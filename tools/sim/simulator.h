#pragma once
// The simulated world: sensors with device model, pose, clock and network; static geometry; moving
// targets. Produces each sensor's k-th scan as the device would send it (cola::ScanTelegram) and
// the ground truth. Pure: time is an argument; nothing here reads a clock or a socket.
//
// Scan timing. A sensor's device clock ticks in µs: tick(t) = offset + t × 10^6 × (1 + drift_ppm ×
// 10^-6), t in scenario seconds; the wire carries it modulo 2^32. Scan k starts (first beam) at
// tick S_k = S_0 + k × period + jitter (σ per model), S_0 falling at a random phase within the
// first period after t = 0, and is sent at tick S_k + the model's processing delay. Beams follow
// each other at beam_time_s (the mirror turns 360° per period), so a moving target is seen where it
// is when each beam passes. The scans of a sensor are those that start before duration_s.
//
// Range model per beam: five rays across the beam's width (the model's divergence) against the
// static world (cast once per sensor) and the targets (cast per scan where a target can be); rays
// on different surfaces that each carry 20-80 % of the beam's energy give a mixed pixel between
// them, as real scanners report at edges (where the model resolves two echoes farther apart than
// its resolved_echo_m, the first with half of the energy instead); then the per-sensor bias,
// Gaussian noise (σ = noise_m + noise_per_m × range), random drop-outs, no echo beyond range_m, and
// quantisation to whole mm. RSSI (when the model sends it) falls with range and grows with the
// surface's remission.
//
// Determinism: every random draw comes from the scenario seed and (sensor, scan index), so scan k
// of a sensor is the same whichever scans were simulated before it, and SimulateScan may run for
// different sensors on different threads (it is const).

#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/time.h"
#include "firmware_tracker/cola/scan_telegram.h"
#include "tools/sim/device_model.h"
#include "tools/sim/geometry2d.h"
#include "tools/sim/scenario.h"
#include "tools/sim/targets.h"

namespace lrfnet::sim {

// A device clock: scenario seconds <-> µs ticks since the device's power-up (unwrapped).
struct SensorClock {
  double offset_us = 0;  // tick at scenario time 0
  double rate = 1.0;     // ticks per µs of scenario time: 1 + drift_ppm × 1e-6

  std::int64_t TickAt(double t_s) const {
    return static_cast<std::int64_t>(std::floor(offset_us + t_s * 1e6 * rate));
  }
  double TimeAt(double tick_us) const { return (tick_us - offset_us) / (rate * 1e6); }
  // The telegram's uint32 field.
  static std::uint32_t Wire(std::int64_t tick_us) {
    return static_cast<std::uint32_t>(tick_us & 0xFFFFFFFF);
  }
};

// What the sensor is, resolved from the scenario (defaults drawn from the seed filled in).
struct SensorSetup {
  std::string id;
  DeviceConfig device;
  double x_m = 0;
  double y_m = 0;
  double yaw_deg = 0;  // as in the scenario
  double bias_m = 0;
  Mount mount = Mount::kTorso;
  double clock_offset_s = 0;
  double drift_ppm = 0;
  SensorClock clock;
  double latency_ms = 0;
  double jitter_ms = 0;
  double gateway_offset_ms = 0;
  std::uint32_t serial_number = 0;
  std::uint16_t first_telegram_counter = 0;
  std::uint16_t first_scan_counter = 0;
  std::int64_t first_scan_tick_us = 0;  // S_0, unwrapped
  double period_us = 0;                 // nominal, in ticks
  std::uint64_t scan_count = 0;
};

struct ScanTiming {
  std::int64_t start_tick_us = 0;     // unwrapped; first beam
  std::int64_t transmit_tick_us = 0;  // unwrapped
  double start_s = 0;                 // scenario time of the first beam
  double transmit_s = 0;              // scenario time the device sends the telegram
};

// Ground truth of one target at one time.
struct TruthSample {
  std::size_t target = 0;
  TargetState state;
};

class Simulator {
 public:
  // nullptr with *error (one line) when `scenario` fails Validate or a random walk finds no room.
  static std::unique_ptr<Simulator> Create(const Scenario& scenario, std::string* error);
  ~Simulator();

  const Scenario& scenario() const { return scenario_; }
  std::size_t sensor_count() const { return sensors_.size(); }
  const SensorSetup& sensor(std::size_t i) const { return sensors_[i].setup; }
  const std::vector<Target>& targets() const { return targets_; }

  ScanTiming Timing(std::size_t sensor, std::uint64_t k) const;
  // Fills `out` with sensor `sensor`'s scan k (k < scan_count: callers check). Reuses out's storage
  // (no allocation). With `target_hits`, also the number of beams whose echo came from each target
  // (indexed like targets(); before noise and drop-outs), e.g. to tell which targets a scan saw.
  void SimulateScan(std::size_t sensor, std::uint64_t k, cola::ScanTelegram* out,
                    std::vector<std::uint32_t>* target_hits = nullptr) const;
  // Every target present at scenario time t_s.
  std::vector<TruthSample> TruthAt(double t_s) const;

  // Whether `sensor` has a clear line of sight to world point `p`: within its range and field of
  // view, no wall or obstacle in between (targets are ignored), from its pose at the start and in
  // the world at the start. For checking scenario designs.
  bool Sees(std::size_t sensor, Vec2 p) const;

  // The range (m, before noise and quantisation; kNoHit for no echo) beam `beam` of `sensor` would
  // measure with every target frozen at time t_s; for tests and tools.
  double NoiselessRange(std::size_t sensor, std::size_t beam, double t_s) const;

 private:
  struct Sample {
    double range_m = kNoHit;
    int surface = -1;  // static surface index, or kTargetSurface + target index; -1 none
  };
  static constexpr int kSamplesPerBeam = 5;
  static constexpr int kTargetSurface = 1 << 20;
  struct Beam {
    double angle_rad = 0;  // world frame, centre ray
    Vec2 dir[kSamplesPerBeam];
    Sample static_samples[kSamplesPerBeam];
    Sample static_combined;  // what the beam measures when no target is near it
  };
  // The static world from from_s on (world.changes start a new one).
  struct StaticWorld {
    double from_s = 0;
    std::vector<Segment> segments;
    std::vector<int> surfaces;  // per segment
  };
  // A sensor's pose and its beams against the static world from from_s on (a new one at every
  // move of the sensor and every change of the world).
  struct Placement {
    double from_s = 0;
    Vec2 origin;
    double yaw_rad = 0;
    std::vector<Beam> beams;
  };
  struct SensorState {
    SensorSetup setup;
    std::vector<Placement> placements;  // from_s increasing, the first at 0
  };

  explicit Simulator(const Scenario& scenario);
  void SetUpSensor(std::size_t index);
  void AddWorldChanges();
  void PlaceSensor(std::size_t index, double from_s, Vec2 origin, double yaw_rad);
  const Placement& PlacementAt(std::size_t sensor, double t_s) const;
  const StaticWorld& WorldAt(double t_s) const;
  Sample CastStatic(const StaticWorld& world, const Ray& ray) const;
  double Remission(int surface) const;
  Sample Combine(const Sample* samples, double range_limit_m, double resolved_echo_m) const;

  Scenario scenario_;
  std::vector<StaticWorld> worlds_;  // from_s increasing, the first at 0
  std::vector<double> surface_remission_;
  std::vector<SensorState> sensors_;
  std::vector<Target> targets_;
};

}  // namespace lrfnet::sim
