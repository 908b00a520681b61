#include "tools/sim/simulator.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

#include "tools/sim/rng.h"

namespace lrfnet::sim {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kWallRemission = 0.7;      // painted plaster
constexpr double kObstacleRemission = 0.5;  // furniture, machines
// Ranges closer than this are not reported (the front screen).
constexpr double kMinRangeM = 0.05;
// Rays of one beam closer than this in range belong to the same echo even on different surfaces
// (a corner).
constexpr double kSameEchoM = 0.1;
// Energy profile across the beam for the five rays at −1, −½, 0, ½, 1 half-widths.
constexpr std::array<double, 5> kSampleOffset = {-1.0, -0.5, 0.0, 0.5, 1.0};
constexpr std::array<double, 5> kSampleWeight = {0.1, 0.2, 0.4, 0.2, 0.1};
// A surface carrying at least this share of the beam's energy decides the echo alone.
constexpr double kDominantShare = 0.8;
constexpr double kMinorShare = 0.2;

double WrapAngle(double a) { return std::remainder(a, 2.0 * kPi); }

void SetName(cola::ScanChannel* channel, const char* name5) {
  channel->name = {};
  std::memcpy(channel->name.data(), name5, 5);
}

}  // namespace

Simulator::Simulator(const Scenario& scenario) : scenario_(scenario) {
  const WorldSpec& w = scenario_.world;
  StaticWorld& world = worlds_.emplace_back();
  for (std::size_t i = 0; i < w.walls.size(); ++i) {
    for (std::size_t k = 0; k + 1 < w.walls[i].size(); ++k) {
      world.segments.push_back({w.walls[i][k], w.walls[i][k + 1]});
      world.surfaces.push_back(static_cast<int>(surface_remission_.size()));
    }
    surface_remission_.push_back(kWallRemission);
  }
  for (const auto& o : w.obstacles) {
    for (const Segment& e : PolygonEdges(o)) {
      world.segments.push_back(e);
      world.surfaces.push_back(static_cast<int>(surface_remission_.size()));
    }
    surface_remission_.push_back(kObstacleRemission);
  }
  AddWorldChanges();
}

void Simulator::AddWorldChanges() {
  // Surfaces keep their index: walls, the scenario's obstacles, then every added polygon.
  const WorldSpec& w = scenario_.world;
  const int first_obstacle = static_cast<int>(w.walls.size());
  for (const WorldChange& change : w.changes) {
    if (change.at_s > worlds_.back().from_s) {
      StaticWorld next = worlds_.back();
      next.from_s = change.at_s;
      worlds_.push_back(std::move(next));
    }
    StaticWorld& world = worlds_.back();
    if (change.remove) {
      const int surface = first_obstacle + static_cast<int>(*change.remove);
      std::vector<Segment> kept;
      std::vector<int> kept_surfaces;
      for (std::size_t i = 0; i < world.segments.size(); ++i) {
        if (world.surfaces[i] == surface) continue;
        kept.push_back(world.segments[i]);
        kept_surfaces.push_back(world.surfaces[i]);
      }
      world.segments = std::move(kept);
      world.surfaces = std::move(kept_surfaces);
    } else {
      for (const Segment& e : PolygonEdges(change.add)) {
        world.segments.push_back(e);
        world.surfaces.push_back(static_cast<int>(surface_remission_.size()));
      }
      surface_remission_.push_back(kObstacleRemission);
    }
  }
}

const Simulator::StaticWorld& Simulator::WorldAt(double t_s) const {
  std::size_t i = 0;
  while (i + 1 < worlds_.size() && worlds_[i + 1].from_s <= t_s) ++i;
  return worlds_[i];
}

const Simulator::Placement& Simulator::PlacementAt(std::size_t sensor, double t_s) const {
  const std::vector<Placement>& p = sensors_[sensor].placements;
  std::size_t i = 0;
  while (i + 1 < p.size() && p[i + 1].from_s <= t_s) ++i;
  return p[i];
}

Simulator::~Simulator() = default;

std::unique_ptr<Simulator> Simulator::Create(const Scenario& scenario, std::string* error) {
  if (auto invalid = Validate(scenario)) {
    *error = *invalid;
    return nullptr;
  }
  std::unique_ptr<Simulator> sim(new Simulator(scenario));
  if (!BuildTargets(sim->scenario_, &sim->targets_, error)) return nullptr;
  sim->sensors_.resize(scenario.sensors.size());
  for (std::size_t i = 0; i < scenario.sensors.size(); ++i) sim->SetUpSensor(i);
  return sim;
}

void Simulator::SetUpSensor(std::size_t index) {
  const SensorSpec& spec = scenario_.sensors[index];
  SensorState& state = sensors_[index];
  SensorSetup& s = state.setup;
  s.id = spec.id;
  // Create() validated the scenario: the model exists and the overrides resolve.
  ResolveDevice(*FindDeviceModel(spec.model), spec.overrides, &s.device);
  s.x_m = spec.x_m;
  s.y_m = spec.y_m;
  s.yaw_deg = spec.yaw_deg;
  s.bias_m = spec.bias_m.value_or(0.0);
  s.mount = spec.mount;

  // Every default is drawn (in a fixed order) even when the scenario sets it, so setting one value
  // does not change the others.
  Rng rng(MixSeed({scenario_.seed, static_cast<std::uint64_t>(RngStream::kSetup), index}));
  const double offset_s = rng.Uniform(60.0, 4000.0);
  const double drift_ppm = rng.Uniform(-30.0, 30.0);
  const auto year = 17 + rng.Below(6), week = 1 + rng.Below(52), number = rng.Below(10000);
  const double phase = rng.Uniform(0.0, 1.0);
  const auto counter_lag = static_cast<std::uint16_t>(rng.Below(200));
  s.clock_offset_s = spec.clock.offset_s.value_or(offset_s);
  s.drift_ppm = spec.clock.drift_ppm.value_or(drift_ppm);
  s.clock = SensorClock{s.clock_offset_s * 1e6, 1.0 + s.drift_ppm * 1e-6};
  s.latency_ms = spec.network.latency_ms.value_or(0.3);
  s.jitter_ms = spec.network.jitter_ms.value_or(0.1);
  s.gateway_offset_ms = spec.network.gateway_offset_ms.value_or(0.0);
  // SICK serial numbers: two digits year, two digits week, four digits.
  s.serial_number = static_cast<std::uint32_t>(year * 1000000 + week * 10000 + number);
  // The device has been scanning since power-up: the scan counter counts those scans, the telegram
  // counter lags behind it (telegrams are counted only while someone listens).
  s.first_scan_counter = static_cast<std::uint16_t>(
      static_cast<std::uint64_t>(s.clock_offset_s * s.device.rate_hz) & 0xFFFF);
  s.first_telegram_counter = static_cast<std::uint16_t>(s.first_scan_counter - counter_lag);
  s.period_us = s.device.period_s * 1e6;
  s.first_scan_tick_us = s.clock.TickAt(phase * s.device.period_s);
  const double end_tick = s.clock.offset_us + scenario_.duration_s * 1e6 * s.clock.rate;
  const double span = end_tick - static_cast<double>(s.first_scan_tick_us);
  s.scan_count = span <= 0 ? 0 : static_cast<std::uint64_t>(std::ceil(span / s.period_us));

  // One placement per pose and world: the sensor's moves and the world's changes, in time order.
  const std::vector<SensorPoseSpan> spans = PoseSpans(spec, scenario_.duration_s);
  std::vector<double> starts;
  for (const SensorPoseSpan& p : spans) starts.push_back(p.from_s);
  for (const StaticWorld& world : worlds_) starts.push_back(world.from_s);
  std::sort(starts.begin(), starts.end());
  starts.erase(std::unique(starts.begin(), starts.end()), starts.end());
  for (const double from_s : starts) {
    std::size_t k = 0;
    while (k + 1 < spans.size() && spans[k + 1].from_s <= from_s) ++k;
    PlaceSensor(index, from_s, {spans[k].x_m, spans[k].y_m}, spans[k].yaw_deg * kPi / 180.0);
  }
}

void Simulator::PlaceSensor(std::size_t index, double from_s, Vec2 origin, double yaw_rad) {
  SensorState& state = sensors_[index];
  Placement& place = state.placements.emplace_back();
  place.from_s = from_s;
  place.origin = origin;
  place.yaw_rad = yaw_rad;
  const StaticWorld& world = WorldAt(from_s);
  const DeviceConfig& d = state.setup.device;
  const double half_width = d.model->divergence_rad / 2.0;
  place.beams.resize(d.count);
  for (std::size_t b = 0; b < d.count; ++b) {
    Beam& beam = place.beams[b];
    beam.angle_rad = place.yaw_rad + d.first_angle_rad + static_cast<double>(b) * d.step_rad;
    for (int k = 0; k < kSamplesPerBeam; ++k) {
      const double a = beam.angle_rad + kSampleOffset[static_cast<std::size_t>(k)] * half_width;
      beam.dir[k] = {std::cos(a), std::sin(a)};
      beam.static_samples[k] = CastStatic(world, {place.origin, beam.dir[k]});
    }
    beam.static_combined = Combine(beam.static_samples, d.range_m, d.model->resolved_echo_m);
  }
}

Simulator::Sample Simulator::CastStatic(const StaticWorld& world, const Ray& ray) const {
  Sample best;
  for (std::size_t i = 0; i < world.segments.size(); ++i) {
    const double r = RaySegment(ray, world.segments[i]);
    if (r < best.range_m) best = {r, world.surfaces[i]};
  }
  return best;
}

double Simulator::Remission(int surface) const {
  if (surface >= kTargetSurface)
    return targets_[static_cast<std::size_t>(surface - kTargetSurface)].remission();
  if (surface >= 0) return surface_remission_[static_cast<std::size_t>(surface)];
  return 0.0;
}

Simulator::Sample Simulator::Combine(const Sample* samples, double range_limit_m,
                                     double resolved_echo_m) const {
  // Group the rays into echoes: rays on one surface, or within kSameEchoM of each other.
  struct Group {
    double weight = 0;
    double weighted_range = 0;
    double best_weight = 0;
    int surface = -1;
    double Range() const { return weighted_range / weight; }
  };
  std::array<int, kSamplesPerBeam> order{};
  int finite = 0;
  double none_weight = 0;
  for (int k = 0; k < kSamplesPerBeam; ++k) {
    if (samples[k].range_m <= range_limit_m) {
      order[static_cast<std::size_t>(finite++)] = k;
    } else {
      none_weight += kSampleWeight[static_cast<std::size_t>(k)];
    }
  }
  if (finite == 0) return {};
  // Insertion sort by range (five elements; std::sort trips a false -Warray-bounds in g++ 12).
  for (int i = 1; i < finite; ++i) {
    for (int j = i; j > 0 && samples[order[static_cast<std::size_t>(j)]].range_m <
                                 samples[order[static_cast<std::size_t>(j - 1)]].range_m;
         --j) {
      std::swap(order[static_cast<std::size_t>(j)], order[static_cast<std::size_t>(j - 1)]);
    }
  }
  std::array<Group, kSamplesPerBeam> groups{};
  int n_groups = 0;
  double previous_range = -kNoHit;
  for (int i = 0; i < finite; ++i) {
    const Sample& s = samples[order[static_cast<std::size_t>(i)]];
    const double w = kSampleWeight[static_cast<std::size_t>(order[static_cast<std::size_t>(i)])];
    bool joins = false;
    if (n_groups > 0) {
      const Group& g = groups[static_cast<std::size_t>(n_groups - 1)];
      joins = g.surface == s.surface || s.range_m - previous_range <= kSameEchoM;
    }
    if (!joins) ++n_groups;
    Group& g = groups[static_cast<std::size_t>(n_groups - 1)];
    g.weight += w;
    g.weighted_range += w * s.range_m;
    if (w > g.best_weight) {
      g.best_weight = w;
      g.surface = s.surface;
    }
    previous_range = s.range_m;
  }
  const Group& nearest = groups[0];
  const auto as_sample = [](const Group& g) { return Sample{g.Range(), g.surface}; };
  if (n_groups == 1 && none_weight == 0.0) return as_sample(nearest);
  if (nearest.weight >= kDominantShare) return as_sample(nearest);
  // The heaviest echo behind the nearest one.
  const Group* behind = nullptr;
  for (int i = 1; i < n_groups; ++i) {
    if (behind == nullptr || groups[static_cast<std::size_t>(i)].weight > behind->weight) {
      behind = &groups[static_cast<std::size_t>(i)];
    }
  }
  if (nearest.weight <= kMinorShare) {
    if (behind != nullptr && behind->weight >= none_weight) return as_sample(*behind);
    return {};
  }
  if (behind == nullptr) {
    // Only empty space behind the edge: the echo is there if it carries half of the energy.
    return nearest.weight >= 0.5 ? as_sample(nearest) : Sample{};
  }
  if (resolved_echo_m > 0.0 && behind->Range() - nearest.Range() > resolved_echo_m) {
    // Two pulses the receiver tells apart (DeviceModel::resolved_echo_m): the first that carries
    // half of the energy, as with nothing behind.
    if (nearest.weight >= 0.5) return as_sample(nearest);
    return behind->weight >= 0.5 ? as_sample(*behind) : Sample{};
  }
  // A mixed pixel: the receiver sees both echoes merged into one pulse and reports a range
  // between them, weighted by their energy.
  const double w = nearest.weight + behind->weight;
  return {(nearest.weighted_range + behind->weighted_range) / w,
          nearest.weight >= behind->weight ? nearest.surface : behind->surface};
}

ScanTiming Simulator::Timing(std::size_t sensor, std::uint64_t k) const {
  const SensorSetup& s = sensors_[sensor].setup;
  const DeviceModel& m = *s.device.model;
  Rng rng(MixSeed({scenario_.seed, static_cast<std::uint64_t>(RngStream::kTiming), sensor, k}));
  const double jitter =
      std::clamp(rng.Normal() * m.scan_jitter_us, -3.0 * m.scan_jitter_us, 3.0 * m.scan_jitter_us);
  double delay = m.tx_delay_us + rng.Uniform(0.0, m.tx_delay_spread_us);
  if (m.tx_after_next_scan) delay += s.period_us;
  ScanTiming t;
  t.start_tick_us =
      s.first_scan_tick_us + std::llround(static_cast<double>(k) * s.period_us + jitter);
  t.transmit_tick_us = t.start_tick_us + std::llround(delay);
  t.start_s = s.clock.TimeAt(static_cast<double>(t.start_tick_us));
  t.transmit_s = s.clock.TimeAt(static_cast<double>(t.transmit_tick_us));
  return t;
}

void Simulator::SimulateScan(std::size_t sensor, std::uint64_t k, cola::ScanTelegram* out,
                             std::vector<std::uint32_t>* target_hits) const {
  if (target_hits != nullptr) target_hits->assign(targets_.size(), 0);
  const SensorSetup& s = sensors_[sensor].setup;
  const DeviceConfig& d = s.device;
  const DeviceModel& m = *d.model;
  const ScanTiming timing = Timing(sensor, k);
  const Placement& state = PlacementAt(sensor, timing.start_s);

  // Field by field: assigning a fresh ScanTelegram would build a 100 kB temporary per scan.
  cola::ScanTelegram& scan = *out;
  scan.encoders.clear();
  scan.channels16.clear();
  scan.channels8.clear();
  scan.has_position = scan.has_name = scan.has_comment = scan.has_event = false;
  scan.version = m.telegram_version;
  scan.device_number = 1;
  scan.serial_number = s.serial_number;
  scan.device_status = {0, 0};
  scan.telegram_counter = static_cast<std::uint16_t>(s.first_telegram_counter + k);
  scan.scan_counter = static_cast<std::uint16_t>(s.first_scan_counter + k);
  scan.time_since_startup_us = SensorClock::Wire(timing.start_tick_us);
  scan.time_of_transmission_us = SensorClock::Wire(timing.transmit_tick_us);
  scan.digital_inputs = 0;
  scan.digital_outputs = 0;
  scan.layer_angle_raw = 0;
  scan.scan_frequency_raw = d.frequency_raw;
  scan.measurement_frequency_raw = d.measurement_frequency_raw;

  cola::ScanChannel* dist = scan.channels16.emplace_slot();
  SetName(dist, "DIST1");
  dist->bits = 16;
  dist->scale_factor = 1.0f;
  dist->scale_offset = 0.0f;
  dist->start_angle_raw = d.start_angle_raw;
  dist->angle_step_raw = d.step_raw;
  dist->count = d.count;
  cola::ScanChannel* rssi = nullptr;
  if (m.rssi_bits == 16) rssi = scan.channels16.emplace_slot();
  if (m.rssi_bits == 8) rssi = scan.channels8.emplace_slot();
  if (rssi != nullptr) {
    SetName(rssi, "RSSI1");
    rssi->bits = m.rssi_bits;
    rssi->scale_factor = 1.0f;
    rssi->scale_offset = 0.0f;
    rssi->start_angle_raw = d.start_angle_raw;
    rssi->angle_step_raw = d.step_raw;
    rssi->count = d.count;
  }

  // Where a target can be during this scan: an angular window per target around its bearing.
  struct Window {
    std::size_t target;
    double bearing_rad;
    double half_angle_rad;
  };
  std::array<Window, 2 * kMaxTargets> windows{};  // a trolley is two targets
  std::size_t n_windows = 0;
  const double scan_end_s = timing.start_s + d.count * d.beam_time_s;
  const double half_width = m.divergence_rad / 2.0;
  for (std::size_t j = 0; j < targets_.size(); ++j) {
    const Trajectory& traj = targets_[j].trajectory();
    if (traj.knots().empty() || traj.start_s() > scan_end_s || traj.end_s() <= timing.start_s)
      continue;
    const double mid =
        std::clamp(0.5 * (timing.start_s + scan_end_s), traj.start_s(), traj.end_s());
    const Vec2 c = traj.Position(mid);
    const double reach = targets_[j].bound_radius_m() +
                         traj.max_speed_mps() * (scan_end_s - timing.start_s) * 0.5 + 0.01;
    const Vec2 rel = c - state.origin;
    const double dist_m = Norm(rel);
    Window w{j, std::atan2(rel.y, rel.x), kPi};
    if (dist_m > reach) w.half_angle_rad = std::asin(reach / dist_m) + half_width + 1e-9;
    windows[n_windows++] = w;  // Validate allows at most kMaxTargets scenario targets
  }

  Rng rng(MixSeed({scenario_.seed, static_cast<std::uint64_t>(RngStream::kRangeNoise), sensor, k}));
  std::array<Sample, kSamplesPerBeam> samples{};
  for (std::size_t b = 0; b < d.count; ++b) {
    const Beam& beam = state.beams[b];
    Sample echo = beam.static_combined;
    bool touched = false;
    for (std::size_t wi = 0; wi < n_windows; ++wi) {
      const Window& w = windows[wi];
      if (std::abs(WrapAngle(beam.angle_rad - w.bearing_rad)) > w.half_angle_rad) continue;
      if (!touched) {
        std::copy(std::begin(beam.static_samples), std::end(beam.static_samples), samples.begin());
        touched = true;
      }
      const double t_beam = timing.start_s + static_cast<double>(b) * d.beam_time_s;
      const TargetState ts = targets_[w.target].StateAt(t_beam);
      if (!ts.present) continue;
      for (int k2 = 0; k2 < kSamplesPerBeam; ++k2) {
        const double r = targets_[w.target].Intersect({state.origin, beam.dir[k2]}, ts, s.mount);
        if (r < samples[static_cast<std::size_t>(k2)].range_m) {
          samples[static_cast<std::size_t>(k2)] = {r, kTargetSurface + static_cast<int>(w.target)};
        }
      }
    }
    if (touched) echo = Combine(samples.data(), d.range_m, m.resolved_echo_m);
    if (target_hits != nullptr && echo.surface >= kTargetSurface && echo.range_m <= d.range_m) {
      ++(*target_hits)[static_cast<std::size_t>(echo.surface - kTargetSurface)];
    }

    // Always the same draws per beam, so one beam's echo does not shift the noise of the others.
    const double gauss = rng.Normal();
    const double drop = rng.Uniform();
    const double rssi_jitter = rng.Uniform(0.97, 1.03);
    std::uint16_t raw = 0;
    double range = echo.range_m;
    if (range <= d.range_m && drop >= m.dropout) {
      range += s.bias_m;
      range += (d.noise_m + d.noise_per_m * range) * gauss;
      // DIST1 at scale factor 1 (as every shared capture sends it) holds up to 65.535 m; the LMS511
      // reports an echo farther than that as no echo.
      if (range >= kMinRangeM && range <= d.range_m && range < 65.5355) {
        raw = static_cast<std::uint16_t>(std::clamp<long>(std::lround(range * 1000.0), 1L, 65535L));
      }
    }
    dist->raw[b] = raw;
    if (rssi != nullptr) {
      std::uint16_t value = 0;
      if (raw != 0) {
        // Received energy grows with remission and falls with range; the receiver saturates close
        // by (a quarter of the LMS511 capture's 8-bit values are 254).
        const double strength =
            std::min(1.0, Remission(echo.surface) * 6.0 / std::max(range, 0.5)) * rssi_jitter;
        value =
            m.rssi_bits == 8
                ? static_cast<std::uint16_t>(std::clamp(std::lround(254.0 * strength), 1L, 254L))
                : static_cast<std::uint16_t>(
                      std::clamp(std::lround(40000.0 * strength), 1L, 65535L));
      }
      rssi->raw[b] = value;
    }
  }

  // Time block as the devices send it with an unset clock: 1970-01-01 plus the device's time,
  // millisecond resolution (the TiM781 capture's block follows its µs tick this way).
  scan.has_time = true;
  const std::uint32_t tick = scan.time_since_startup_us;
  const std::uint32_t seconds = tick / 1000000u;
  scan.time.year = 1970;
  scan.time.month = 1;
  scan.time.day = static_cast<std::uint8_t>(1 + seconds / 86400u);
  scan.time.hour = static_cast<std::uint8_t>(seconds / 3600u % 24u);
  scan.time.minute = static_cast<std::uint8_t>(seconds / 60u % 60u);
  scan.time.second = static_cast<std::uint8_t>(seconds % 60u);
  scan.time.microsecond = tick % 1000000u / 1000u * 1000u;
}

std::vector<TruthSample> Simulator::TruthAt(double t_s) const {
  std::vector<TruthSample> out;
  for (std::size_t j = 0; j < targets_.size(); ++j) {
    TargetState state = targets_[j].StateAt(t_s);
    if (state.present) out.push_back({j, state});
  }
  return out;
}

bool Simulator::Sees(std::size_t sensor, Vec2 p) const {
  const Placement& state = sensors_[sensor].placements.front();
  const DeviceConfig& d = sensors_[sensor].setup.device;
  const Vec2 rel = p - state.origin;
  const double dist = Norm(rel);
  if (dist > d.range_m || dist < kMinRangeM) return false;
  const double bearing = WrapAngle(std::atan2(rel.y, rel.x) - state.yaw_rad);
  const double half_fov = d.fov_deg / 2.0 * kPi / 180.0;
  if (std::abs(bearing) > half_fov) return false;
  return CastStatic(worlds_.front(), {state.origin, {rel.x / dist, rel.y / dist}}).range_m > dist;
}

double Simulator::NoiselessRange(std::size_t sensor, std::size_t beam_index, double t_s) const {
  const Placement& state = PlacementAt(sensor, t_s);
  const Beam& beam = state.beams[beam_index];
  std::array<Sample, kSamplesPerBeam> samples{};
  std::copy(std::begin(beam.static_samples), std::end(beam.static_samples), samples.begin());
  for (std::size_t j = 0; j < targets_.size(); ++j) {
    const TargetState ts = targets_[j].StateAt(t_s);
    for (int k = 0; k < kSamplesPerBeam; ++k) {
      const double r =
          targets_[j].Intersect({state.origin, beam.dir[k]}, ts, sensors_[sensor].setup.mount);
      if (r < samples[static_cast<std::size_t>(k)].range_m) {
        samples[static_cast<std::size_t>(k)] = {r, kTargetSurface + static_cast<int>(j)};
      }
    }
  }
  const DeviceConfig& device = sensors_[sensor].setup.device;
  const Sample s = Combine(samples.data(), device.range_m, device.model->resolved_echo_m);
  return s.range_m;
}

}  // namespace lrfnet::sim
