#pragma once
// Where an emulated device gets its scans: a recorded capture, a synthetic room, or (later) the
// simulator. The emulator asks for one scan at a time together with the time since the previous
// one, so every source carries its own timing.

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/capture/capture_stream.h"
#include "common/time.h"
#include "firmware_tracker/cola/scan_telegram.h"

namespace lrfnet::tools {

// The scans a device produces on its own (before any output configuration): what it reports as
// LMPoutputRange / LMPscancfg and the defaults of LMDscandatacfg. count 0: unknown (the device
// family's typical values apply).
struct ScanGeometry {
  std::int32_t start_angle_raw = 0;      // 1/10000 °, SICK convention (first beam)
  std::uint16_t angle_step_raw = 0;      // 1/10000 °
  std::uint16_t count = 0;               // beams per scan
  std::uint32_t scan_frequency_raw = 0;  // 1/100 Hz (telegram rate; MRS1xxx: 4 layers per turn)
  std::uint8_t rssi_bits = 0;            // 0, 8 or 16
};

// What the device reports about itself in the start-up dialogue (sRA DeviceIdent /
// FirmwareVersion / SerialNumber), its scan geometry, and for a recorded device its recorded
// answers to reads.
struct DeviceIdentity {
  std::string name;     // DeviceIdent name, e.g. "LMS511"
  std::string version;  // DeviceIdent version
  std::string firmware_version;
  std::string serial_number;
  ScanGeometry geometry;
  // `sRA <name>` arguments (CoLa-B bytes) as the recorded device sent them, first reply per name.
  std::map<std::string, std::vector<std::uint8_t>> recorded_reads;
};

class ScanSource {
 public:
  virtual ~ScanSource() = default;

  virtual const DeviceIdentity& identity() const = 0;

  // Writes the next scan of the current pass into *scan and the time the device waits after the
  // previous scan before sending it (`since_previous_ns`, >= 0; the first scan of a pass gets 0).
  // Returns false at the end of a pass (finite sources); *scan is then unspecified.
  virtual bool Next(cola::ScanTelegram* scan, common::DurationNs* since_previous_ns) = 0;

  // Starts the next pass at the first scan. Endless sources ignore it.
  virtual void Rewind() = 0;

  // The device's scan period: the spacing used between the last scan of a pass and the first of the
  // next.
  virtual common::DurationNs nominal_period_ns() const = 0;
};

// ---- every scan of a capture (sensor -> client stream), with the capture's receive-time spacing

struct CaptureScanSourceOptions {
  capture::CaptureStreamOptions capture;
  // Overrides the identity found in the capture (empty: keep).
  std::string model_name;
};

// Reads the whole capture into memory (the encoded scan payloads, a few hundred kB for the shipped
// captures). Identity comes from sRA DeviceIdent / FirmwareVersion / SerialNumber replies in the
// capture when present, else from the scans (serial number field, device family guessed from the
// scan geometry). Returns nullptr and sets *error (one line) when the file cannot be read or holds
// no scan.
std::unique_ptr<ScanSource> OpenCaptureScanSource(const std::string& path,
                                                  const CaptureScanSourceOptions& options,
                                                  std::string* error);

// ---- a synthetic device: a rectangular room with a person-sized blob walking an ellipse

struct SyntheticScanOptions {
  std::string model = "lms511";  // lms511 | lms111 | tim561 | tim781 | tim781s | mrs1104
  std::uint64_t seed = 1;        // range noise
  double noise_m = 0.01;         // uniform range noise amplitude
};
std::optional<std::string> Validate(const SyntheticScanOptions& options);
// The models SyntheticScanOptions::model accepts.
const std::vector<std::string>& SyntheticModels();

// Endless; telegram and scan counters start at 1, the µs tick at 10 s after power-up. Scan k shows
// the blob at time k / rate_hz. Deterministic for a given seed.
std::unique_ptr<ScanSource> MakeSyntheticScanSource(const SyntheticScanOptions& options);

// Device family guessed from the DIST1 geometry of a scan (e.g. 1141 points at 0.1667° ->
// "LMS5xx").
std::string GuessModelName(const cola::ScanTelegram& scan);

}  // namespace lrfnet::tools
