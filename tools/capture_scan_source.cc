// ScanSource over a recorded capture: the scans of the sensor -> client stream, decoded once up
// front.

#include <algorithm>
#include <string_view>
#include <utility>

#include "firmware_tracker/cola/commands.h"
#include "firmware_tracker/cola/stream_decoder.h"
#include "tools/scan_source.h"

namespace lrfnet::tools {
namespace {

// A pause longer than this between two scans of a capture is not the device's rhythm (a new
// connection or a stopped measurement in the recording); the emulator uses one scan period there
// instead.
constexpr common::DurationNs kMaxReplayPauseNs = 2 * common::kNsPerS;
constexpr common::DurationNs kFallbackPeriodNs = 40 * common::kNsPerMs;

class Collector : public cola::TelegramListener {
 public:
  void OnScan(const cola::ScanTelegram& scan, common::UtcNs receive_time_ns) override {
    std::vector<std::uint8_t> payload(cola::MaxEncodedSize(scan));
    const std::size_t n = cola::EncodeScanTelegram(scan, payload);
    if (n == 0) {
      ++unencodable;
      return;
    }
    payload.resize(n);
    payloads.push_back(std::move(payload));
    receive_times_ns.push_back(receive_time_ns);
    if (payloads.size() == 1) {
      first_serial = scan.serial_number;
      first_frequency_raw = scan.scan_frequency_raw;
      guessed_model = GuessModelName(scan);
      if (const cola::ScanChannel* dist = scan.FindChannel("DIST1")) {
        const cola::ScanChannel* rssi = scan.FindChannel("RSSI1");
        identity.geometry = {dist->start_angle_raw, dist->angle_step_raw, dist->count,
                             scan.scan_frequency_raw,
                             static_cast<std::uint8_t>(rssi != nullptr ? rssi->bits : 0)};
      }
    }
  }

  void OnTelegram(const cola::TelegramHeader& header, std::span<const std::uint8_t>,
                  common::UtcNs) override {
    if (header.type != cola::CommandType::kReadAnswer) return;
    // The device's own answers: the emulated device answers these reads as it did.
    identity.recorded_reads.try_emplace(std::string(header.name), header.args.begin(),
                                        header.args.end());
    if (header.name == "DeviceIdent") {
      cola::DeviceIdent ident;
      if (cola::DecodeDeviceIdent(header.args, &ident)) {
        identity.name = std::string(ident.name);
        identity.version = std::string(ident.version);
      }
      return;
    }
    cola::FlexString text;
    if (header.name == "FirmwareVersion" && cola::DecodeFlexString(header.args, &text)) {
      identity.firmware_version = std::string(text.text);
    } else if (header.name == "SerialNumber" && cola::DecodeFlexString(header.args, &text)) {
      identity.serial_number = std::string(text.text);
    }
  }

  std::vector<std::vector<std::uint8_t>> payloads;
  std::vector<common::UtcNs> receive_times_ns;
  DeviceIdentity identity;
  std::uint32_t first_serial = 0;
  std::uint32_t first_frequency_raw = 0;
  std::string guessed_model;
  std::size_t unencodable = 0;
};

class CaptureScanSource : public ScanSource {
 public:
  CaptureScanSource(std::vector<std::vector<std::uint8_t>> payloads,
                    std::vector<common::DurationNs> gaps_ns, DeviceIdentity identity,
                    common::DurationNs period_ns)
      : payloads_(std::move(payloads)),
        gaps_ns_(std::move(gaps_ns)),
        identity_(std::move(identity)),
        period_ns_(period_ns) {}

  const DeviceIdentity& identity() const override { return identity_; }

  bool Next(cola::ScanTelegram* scan, common::DurationNs* since_previous_ns) override {
    while (next_ < payloads_.size()) {
      const std::size_t i = next_++;
      // These bytes were produced by the encoder from a decoded scan, so decoding cannot fail; skip
      // defensively rather than send a half-filled telegram.
      if (!cola::DecodeScanTelegram(payloads_[i], scan).ok) continue;
      *since_previous_ns = gaps_ns_[i];
      return true;
    }
    return false;
  }

  void Rewind() override { next_ = 0; }
  common::DurationNs nominal_period_ns() const override { return period_ns_; }

 private:
  std::vector<std::vector<std::uint8_t>> payloads_;
  std::vector<common::DurationNs> gaps_ns_;
  DeviceIdentity identity_;
  common::DurationNs period_ns_;
  std::size_t next_ = 0;
};

}  // namespace

std::string GuessModelName(const cola::ScanTelegram& scan) {
  const cola::ScanChannel* dist = scan.FindChannel("DIST1");
  if (dist == nullptr) return "SICK scanner";
  struct Geometry {
    std::uint16_t count;
    std::uint16_t step_raw;
    const char* family;
  };
  static constexpr Geometry kKnown[] = {
      {1141, 1667, "LMS5xx"},
      {541, 5000, "LMS1xx"},
      {811, 3333, "TiM7xx"},
      {1101, 2500, "MRS1xxx"},
  };
  for (const Geometry& g : kKnown) {
    if (dist->count == g.count && dist->angle_step_raw == g.step_raw) return g.family;
  }
  return "SICK scanner";
}

std::unique_ptr<ScanSource> OpenCaptureScanSource(const std::string& path,
                                                  const CaptureScanSourceOptions& options,
                                                  std::string* error) {
  std::unique_ptr<capture::CaptureStream> capture =
      capture::CaptureStream::Open(path, options.capture, error);
  if (!capture) return nullptr;
  auto decoder = std::make_unique<cola::StreamDecoder>();
  Collector collector;
  capture::StreamChunk chunk;
  while (capture->Next(&chunk)) {
    if (chunk.discontinuity) decoder->Reset();
    decoder->Feed(chunk.bytes, chunk.receive_time_ns, collector);
  }
  if (!capture->error().empty() && collector.payloads.empty()) {
    *error = capture->error();
    return nullptr;
  }
  if (collector.payloads.empty()) {
    *error = path + ": no LMDscandata telegram in the sensor -> client stream (sensor port " +
             std::to_string(options.capture.sensor_port) + ")";
    return nullptr;
  }

  common::DurationNs period_ns = kFallbackPeriodNs;
  if (collector.first_frequency_raw > 0) {
    // Scan frequency field: 1/100 Hz.
    period_ns = static_cast<common::DurationNs>(100.0 * 1e9 / collector.first_frequency_raw);
  }
  std::vector<common::DurationNs> gaps_ns(collector.receive_times_ns.size(), 0);
  for (std::size_t i = 1; i < gaps_ns.size(); ++i) {
    const common::DurationNs gap =
        collector.receive_times_ns[i] - collector.receive_times_ns[i - 1];
    gaps_ns[i] = gap > kMaxReplayPauseNs ? period_ns : std::max<common::DurationNs>(gap, 0);
  }

  DeviceIdentity identity = collector.identity;
  if (identity.name.empty()) identity.name = collector.guessed_model;
  if (identity.version.empty()) identity.version = "emulated";
  if (identity.firmware_version.empty()) identity.firmware_version = "unknown (emulated)";
  if (identity.serial_number.empty())
    identity.serial_number = std::to_string(collector.first_serial);
  if (!options.model_name.empty()) identity.name = options.model_name;

  return std::make_unique<CaptureScanSource>(std::move(collector.payloads), std::move(gaps_ns),
                                             std::move(identity), period_ns);
}

}  // namespace lrfnet::tools
