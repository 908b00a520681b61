#include "tools/sim/device_model.h"

#include <cmath>

#include "firmware_tracker/cola/scan_telegram.h"

namespace lrfnet::sim {

namespace {

// Values and sources: see the table in device_model.h.
// clang-format off
const std::vector<DeviceModel> kModels = {
    {"lms111", "LMS111-10100", "V1.80.2", "V1.80.2  ", 270.0, 0.5, 50.0, 20.0, 0.012, 0.0, 0.030,
     0.015, 0, 1, 3050.0, 250.0, false, 50.0, 1e-4, 0.0},
    {"lms151", "LMS151-10100", "V1.80.2", "V1.80.2  ", 270.0, 0.5, 50.0, 50.0, 0.012, 0.0, 0.030,
     0.015, 0, 1, 3050.0, 250.0, false, 50.0, 1e-4, 0.0},
    {"lms511", "LMS511-10100", "V1.80", "V1.80    ", 190.0, 1.0 / 6.0, 25.0, 80.0, 0.004, 0.0003,
     0.025, 0.011, 8, 0, 300.0, 700.0, true, 50.0, 1e-4, 0.5},
    {"tim561", "TiM561-2050101", "V2.53", "V2.53", 270.0, 1.0 / 3.0, 15.0, 10.0, 0.020, 0.0, 0.060,
     0.015, 16, 1, 6200.0, 800.0, false, 30.0, 2e-4, 0.0},
    {"tim781", "TiM781-2174101", "V3.13", "V3.13", 270.0, 1.0 / 3.0, 15.0, 25.0, 0.020, 0.0, 0.060,
     0.015, 16, 1, 6200.0, 800.0, false, 30.0, 2e-4, 0.0},
};
// clang-format on

}  // namespace

const std::vector<DeviceModel>& DeviceModels() { return kModels; }

const DeviceModel* FindDeviceModel(std::string_view key) {
  for (const DeviceModel& m : kModels) {
    if (m.key == key) return &m;
  }
  return nullptr;
}

std::string DeviceModelKeys() {
  std::string keys;
  for (const DeviceModel& m : kModels) {
    if (!keys.empty()) keys += ", ";
    keys += m.key;
  }
  return keys;
}

std::optional<std::string> ResolveDevice(const DeviceModel& model, const DeviceOverrides& o,
                                         DeviceConfig* out) {
  DeviceConfig c;
  c.model = &model;
  c.fov_deg = o.fov_deg.value_or(model.fov_deg);
  c.resolution_deg = o.resolution_deg.value_or(model.resolution_deg);
  c.rate_hz = o.rate_hz.value_or(model.rate_hz);
  c.range_m = o.range_m.value_or(model.range_m);
  c.noise_m = o.noise_m.value_or(model.noise_m);
  c.noise_per_m = o.noise_per_m.value_or(model.noise_per_m);

  if (!(c.fov_deg > 0.0 && c.fov_deg <= 360.0)) return "fov_deg: must be in (0, 360]";
  if (!(c.resolution_deg >= 0.01 && c.resolution_deg <= 10.0)) {
    return "resolution_deg: must be in [0.01, 10]";
  }
  if (!(c.rate_hz >= 1.0 && c.rate_hz <= 200.0)) return "rate_hz: must be in [1, 200]";
  if (!(c.range_m > 0.1 && c.range_m <= 100.0)) return "range_m: must be in (0.1, 100]";
  if (!(c.noise_m >= 0.0 && c.noise_m <= 1.0)) return "noise_m: must be in [0, 1]";
  if (!(c.noise_per_m >= 0.0 && c.noise_per_m <= 0.1)) return "noise_per_m: must be in [0, 0.1]";

  // The telegram carries the step in 1/10000° and the count: the field of view must be a whole
  // number of steps (0.1667° × 1140 = 190° as the LMS511 sends it).
  const double steps = c.fov_deg / c.resolution_deg;
  const double whole = std::round(steps);
  if (whole < 1.0 || std::abs(steps - whole) > std::max(0.01, 5e-4 * whole)) {
    return "resolution_deg: the field of view (" + std::to_string(c.fov_deg) +
           "°) is not a whole number of steps of " + std::to_string(c.resolution_deg) + "°";
  }
  if (whole + 1.0 > static_cast<double>(cola::kMaxPointsPerChannel)) {
    return "resolution_deg: " + std::to_string(static_cast<long>(whole + 1.0)) +
           " beams per scan, more than a telegram holds (" +
           std::to_string(cola::kMaxPointsPerChannel) + ")";
  }
  c.count = static_cast<std::uint16_t>(whole + 1.0);
  c.step_raw = static_cast<std::uint16_t>(std::lround(c.resolution_deg * 10000.0));
  // Raw convention: 90° is straight ahead, so the field of view starts at 90° − fov / 2.
  c.start_angle_raw = static_cast<std::int32_t>(std::lround((90.0 - c.fov_deg / 2.0) * 10000.0));
  c.frequency_raw = static_cast<std::uint32_t>(std::lround(c.rate_hz * 100.0));
  c.measurement_frequency_raw =
      static_cast<std::uint32_t>(std::lround(360.0 / c.resolution_deg * c.rate_hz / 100.0));
  constexpr double kDegToRad = 3.14159265358979323846 / 180.0;
  c.first_angle_rad = (c.start_angle_raw / 10000.0 - 90.0) * kDegToRad;
  c.step_rad = c.step_raw / 10000.0 * kDegToRad;
  c.period_s = 100.0 / c.frequency_raw;
  c.beam_time_s = c.period_s * (c.resolution_deg / 360.0);
  *out = c;
  return std::nullopt;
}

}  // namespace lrfnet::sim
