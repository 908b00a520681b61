#pragma once
// Device models of the simulator: what each SICK scanner measures and how it reports it.
//
// | model  | FOV  | step | rate  | range | σ range noise   | beam divergence | RSSI   | source    |
// |--------|------|------|-------|-------|-----------------|-----------------|--------|-----------|
// | lms111 | 270° | 0.5° | 50 Hz | 20 m  | 12 mm           | 15 mrad + 8 mm  | none   | [1][2]    |
// | lms151 | 270° | 0.5° | 50 Hz | 50 m  | 12 mm           | 15 mrad + 8 mm  | none   | [1][2][5] |
// | lms511 | 190° | 1/6° | 25 Hz | 80 m  | 4 + 0.3 mm/m    | 11 mrad + 13 mm | 8 bit  | [2][3]    |
// | tim561 | 270° | 1/3° | 15 Hz | 10 m  | 20 mm           | 15 mrad (*)     | 16 bit | [4]       |
// | tim781 | 270° | 1/3° | 15 Hz | 25 m  | 20 mm (*)       | 15 mrad (*)     | 16 bit | [4][6]    |
//
// [1] SICK, LMS1xx operating instructions 8012471: beam diameter = distance × 0.015 rad + 8 mm.
// [2] SICK support knowledge base "Measurement Errors LMSxxx": LMS1xx systematic ±30 mm,
//     statistical 12 mm (typical); LMS5xx SR statistical 6 / 8 / 14 mm at 1-10 / 10-20 /
//     20-30 m, systematic ±25 / ±35 / ±50 mm. The σ column fits the LMS5xx figures linearly.
// [3] SICK, LMS5xx operating instructions 8013796: beam diameter = distance × 0.011 rad (SR;
//     HR: 0.0046 rad) + 13 mm; steps 0.1667° ... 1°, 25 ... 100 Hz. Field of view, step, rate
//     and RSSI width as the LMS511 capture in the shared data shows them (1141 points from −5°).
// [4] SICK, TiM55x/TiM56x technical information 8015886: TiM561 statistical error 20 mm (1σ),
//     systematic ±60 mm, 0.05-10 m, 15 Hz; telegram layout 8015883 (measurement frequency
//     field = spot rate / 100 Hz). TiM7xx geometry from the TiM781 capture (811 points,
//     0.3333°, 15 Hz, 16-bit RSSI).
// [5] Schenk et al. (shared papers/001): LMS151, 270° at 0.5°, 50 Hz, 50 m, ±3 cm / ±1.2 cm.
// [6] TiM781 working range 0.05-25 m (SICK product page).
// (*) Not in a document we could read: the TiM beam divergence is taken as the LMS1xx's, and
//     the TiM781 noise as the TiM561's.
// Echoes at an edge (what a beam reports when its footprint covers a body and a surface behind
// it), from the shared captures (sick_scan_xd's recordings, a static scene): the LMS511 (1/6°, its
// footprint about eight beams wide at 1 m) shows no range between two surfaces 0.46-1.43 m apart
// at 326 of 328 such edges in 136 scans, but one at a third of the edges 0.4-0.5 m apart: it
// resolves echoes beyond about 0.5 m (a pulsed time of flight with the LMS5xx's echo filter,
// [3] "multiple echoes": first echo). The LMS111 reports one or two ranges between surfaces
// 0.3-0.85 m apart at 84 % of such edges (its capture has no larger step); LMS1xx [1] §3.8.4
// measures a second reflected pulse only "if produced", after a time that depends on the first
// target. The TiM781 reports ranges between surfaces 0.5-1 m apart at 38 of 87 edges and one
// edge over 1 m (16 scans) as no echo. So the LMS1xx and the TiMs keep the merged echo at every
// separation (resolved_echo_m 0: nothing says where they resolve), the LMS511 resolves at 0.5 m.
// DIST1 goes out at scale factor 1 (whole mm), as in every shared capture; that caps what a
// telegram can carry at 65.535 m, so the LMS511 reports echoes beyond it as 0 (no echo).
// Systematic errors are listed in systematic_m but not applied by default (a per-sensor `bias_m`
// in the scenario applies one).
//
// Timing (from the shared captures; time since startup = the tick of the first beam of the scan):
// time of transmission − time since startup is 3.07-3.27 ms on the LMS111, one scan period plus
// 0.3-1.0 ms on the LMS511 (it sends a scan after the next one has started) and 6.2-7.0 ms on the
// TiM781; scan start ticks scatter by about ±0.15 ms around the nominal period.

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace lrfnet::sim {

struct DeviceModel {
  std::string_view key;            // scenario name, e.g. "lms111"
  std::string_view ident_name;     // sRA DeviceIdent name
  std::string_view ident_version;  // sRA DeviceIdent version
  std::string_view firmware;       // sRA FirmwareVersion text, padded as the device pads it
  double fov_deg;
  double resolution_deg;
  double rate_hz;
  double range_m;
  double noise_m;      // range noise σ at 0 m
  double noise_per_m;  // growth of σ per metre of range
  double systematic_m;
  double divergence_rad;   // full beam divergence
  std::uint8_t rssi_bits;  // 0: no RSSI channel, 8 or 16
  std::uint16_t telegram_version;
  double tx_delay_us;         // time of transmission − time since startup, minimum
  double tx_delay_spread_us;  // ... plus a uniform spread of this width
  bool tx_after_next_scan;    // LMS5xx: add one scan period to the delay
  double scan_jitter_us;      // σ of the scan start tick around the nominal period
  double dropout;             // probability that a beam returns no echo (besides range limits)
  // Two echoes of one beam farther apart in range than this are resolved: the device reports the
  // first that carries at least half of the beam's energy (nothing between them); nearer, or 0,
  // the receiver merges them into one pulse and reports a range between them (a mixed pixel).
  double resolved_echo_m;
};

// The model table above. Keys are lower case.
const std::vector<DeviceModel>& DeviceModels();
const DeviceModel* FindDeviceModel(std::string_view key);
// "lms111, lms151, ..." for error messages.
std::string DeviceModelKeys();

// Per-sensor scenario overrides (nullopt: the model's value).
struct DeviceOverrides {
  std::optional<double> range_m;
  std::optional<double> fov_deg;
  std::optional<double> resolution_deg;
  std::optional<double> rate_hz;
  std::optional<double> noise_m;
  std::optional<double> noise_per_m;
};

// A model with its overrides applied, in the telegram's units too. Beam i points at
// first_angle_rad + i × step_rad in the sensor frame (0 rad = the telegram's 90° beam, counter-
// clockwise), the angles a decoder computes from the telegram's start angle and step fields.
struct DeviceConfig {
  const DeviceModel* model = nullptr;
  double fov_deg = 0;
  double resolution_deg = 0;
  double rate_hz = 0;
  double range_m = 0;
  double noise_m = 0;
  double noise_per_m = 0;
  std::int32_t start_angle_raw = 0;             // 1/10000 °, SICK convention
  std::uint16_t step_raw = 0;                   // 1/10000 °
  std::uint16_t count = 0;                      // beams per scan
  std::uint32_t frequency_raw = 0;              // 1/100 Hz
  std::uint32_t measurement_frequency_raw = 0;  // 100 Hz units (spot rate over 360°)
  double first_angle_rad = 0;
  double step_rad = 0;
  double period_s = 0;     // 1 / scan frequency field
  double beam_time_s = 0;  // time between two beams (the mirror turns 360° per period)
};

// Applies the overrides. Returns an error naming the override key ("resolution_deg: ...") when the
// result cannot be sent in a telegram (more than 2880 beams, a field of view that is not a whole
// number of steps, a non-positive value).
std::optional<std::string> ResolveDevice(const DeviceModel& model, const DeviceOverrides& overrides,
                                         DeviceConfig* out);

}  // namespace lrfnet::sim
