#pragma once
// Test-only: a synthetic SICK device for TrackerNode tests. Renders scenes with the tracking tests'
// ray caster into LMDscandata telegrams (DIST1 in mm, SICK angle convention, µs ticks) and gives
// each one a gateway receive time, and collects and decodes the datagrams a node emits.

#include <pb_decode.h>

#include <cmath>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "common/geometry.h"
#include "common/time.h"
#include "firmware_tracker/cola/scan_telegram.h"
#include "firmware_tracker/io/datagram_encoder.h"
#include "firmware_tracker/tracking/tracking_test_util.h"
#include "lrfnet.nanopb.h"

namespace lrfnet::tracker::testing {

using tracking::testing::Body;
using tracking::testing::ScannerConfig;
using tracking::testing::SyntheticScanner;
using tracking::testing::Wall;

class SyntheticDevice {
 public:
  // Scan k starts at device tick first_tick_us + k * period; the gateway's UTC of tick t is
  // SyntheticScanner::StampNs(0) + (t - first_tick_us) µs, so scan k's true start is StampNs(k).
  explicit SyntheticDevice(const ScannerConfig& config = {}, std::uint32_t first_tick_us = 10'000'000)
      : scanner_(config), first_tick_us_(first_tick_us), telegram_(std::make_unique<cola::ScanTelegram>()) {
    cola::ScanTelegram& t = *telegram_;
    t.version = 1;
    t.device_number = 1;
    t.serial_number = 1234567;
    t.scan_frequency_raw = static_cast<std::uint32_t>(std::lround(config.rate_hz * 100.0));
    t.measurement_frequency_raw = 1350;
    cola::ScanChannel dist;
    dist.name = {'D', 'I', 'S', 'T', '1', '\0'};
    dist.bits = 16;
    dist.scale_factor = 1.0f;
    // Sensor frame 0 rad is the telegram's 90° beam.
    dist.start_angle_raw = static_cast<std::int32_t>(
        std::lround((config.first_angle_rad * 180.0 / M_PI + 90.0) * 10000.0));
    dist.angle_step_raw =
        static_cast<std::uint16_t>(std::lround(config.angle_step_rad * 180.0 / M_PI * 10000.0));
    dist.count = static_cast<std::uint16_t>(config.beams);
    (void)t.channels16.push_back(dist);
  }

  // Scan k of the scene; *receive_ns = true start + transmission delay + latency.
  const cola::ScanTelegram& Scan(std::int64_t k, std::span<const Wall> walls,
                                 std::span<const Body> bodies, common::UtcNs* receive_ns) {
    const tracking::ScanView view = scanner_.Render(k, walls, bodies);
    cola::ScanTelegram& t = *telegram_;
    cola::ScanChannel& dist = t.channels16[0];
    for (std::size_t i = 0; i < view.range_m.size(); ++i) {
      dist.raw[i] = static_cast<std::uint16_t>(
          std::min(65535.0, std::round(static_cast<double>(view.range_m[i]) * 1000.0)));
    }
    t.telegram_counter = static_cast<std::uint16_t>(k + 1);
    t.scan_counter = static_cast<std::uint16_t>(k + 1);
    const double period_us = 1e6 / scanner_.config().rate_hz;
    t.time_since_startup_us =
        first_tick_us_ + static_cast<std::uint32_t>(std::llround(static_cast<double>(k) * period_us));
    t.time_of_transmission_us = t.time_since_startup_us + kTransmitDelayUs;
    // Latency 1..3 ms, deterministic.
    const std::int64_t latency_us = 1000 + (k * 7919) % 2000;
    *receive_ns = TrueStartNs(k) + (kTransmitDelayUs + latency_us) * common::kNsPerUs;
    return t;
  }

  common::UtcNs TrueStartNs(std::int64_t k) const { return scanner_.StampNs(k); }
  cola::ScanTelegram& telegram() { return *telegram_; }
  const SyntheticScanner& scanner() const { return scanner_; }

  static constexpr std::int64_t kTransmitDelayUs = 10'000;

 private:
  SyntheticScanner scanner_;
  std::uint32_t first_tick_us_;
  std::unique_ptr<cola::ScanTelegram> telegram_;
};

// Decoded datagrams (nanopb), in emission order, each with whether it came between BeginBatch()
// and EndBatch().
class CollectingSink final : public io::DatagramSink {
 public:
  void BeginBatch() override {
    batch_open = true;
    ++batches;
  }
  void EndBatch() override { batch_open = false; }
  void Send(std::span<const std::uint8_t> datagram, common::UtcNs) override {
    sizes.push_back(datagram.size());
    in_batch.push_back(batch_open);
    auto d = std::make_unique<lrfnet_proto_Datagram>();
    *d = lrfnet_proto_Datagram{};
    pb_istream_t stream = pb_istream_from_buffer(datagram.data(), datagram.size());
    decoded_ok = decoded_ok && pb_decode(&stream, lrfnet_proto_Datagram_fields, d.get());
    datagrams.push_back(std::move(d));
  }
  std::size_t Count(pb_size_t tag) const {
    std::size_t n = 0;
    for (const auto& d : datagrams) n += d->which_payload == tag ? 1 : 0;
    return n;
  }
  void Clear() {
    datagrams.clear();
    sizes.clear();
    in_batch.clear();
    batches = 0;
  }

  std::vector<std::unique_ptr<lrfnet_proto_Datagram>> datagrams;
  std::vector<std::size_t> sizes;
  std::vector<bool> in_batch;
  bool batch_open = false;
  std::size_t batches = 0;  // BeginBatch calls
  bool decoded_ok = true;
};

// The room of the tracking tests: sensor at the origin looking along +x.
inline std::vector<Wall> Room() { return tracking::testing::Room(); }

}  // namespace lrfnet::tracker::testing
