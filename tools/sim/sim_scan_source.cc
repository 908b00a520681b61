#include "tools/sim/sim_scan_source.h"

#include <algorithm>
#include <cmath>

#include "tools/sim/sim_output.h"

namespace lrfnet::sim {

namespace {

// A scan due more than this long ago means the stream was interrupted (or never started): jump to
// the present instead of replaying the backlog.
constexpr double kLateS = 2e-3;

tools::DeviceIdentity IdentityWithGeometry(const SensorSetup& sensor) {
  tools::DeviceIdentity id = IdentityOf(sensor);
  const DeviceConfig& d = sensor.device;
  id.geometry = {d.start_angle_raw, d.step_raw, d.count, d.frequency_raw, d.model->rssi_bits};
  return id;
}

class SimScanSource : public tools::ScanSource {
 public:
  SimScanSource(std::shared_ptr<const Simulator> sim, std::size_t sensor,
                std::function<double()> now_s)
      : sim_(std::move(sim)),
        sensor_(sensor),
        now_s_(std::move(now_s)),
        identity_(IdentityWithGeometry(sim_->sensor(sensor))),
        count_(sim_->sensor(sensor).scan_count),
        duration_s_(sim_->scenario().duration_s) {}

  const tools::DeviceIdentity& identity() const override { return identity_; }

  bool Next(cola::ScanTelegram* scan, common::DurationNs* since_previous_ns) override {
    if (k_ >= count_) return false;
    const double now = now_s_();
    double gap_s = 0.0;
    if (!synced_ || TransmitS(k_) < now - kLateS) {
      // Resynchronise: the last scan sent at or before now, or the next one if none was yet.
      const double pass_start = static_cast<double>(pass_) * duration_s_;
      if (now > pass_start + sim_->Timing(sensor_, count_ - 1).transmit_s) {
        k_ = count_;  // this pass is over
        return false;
      }
      std::uint64_t j = k_;
      const double period = sim_->sensor(sensor_).device.period_s;
      const double estimate = (now - TransmitS(0)) / period;
      if (estimate > 0) j = std::max<std::uint64_t>(j, static_cast<std::uint64_t>(estimate));
      j = std::min(j, count_ - 1);
      while (j + 1 < count_ && TransmitS(j + 1) <= now) ++j;
      while (j > k_ && TransmitS(j) > now) --j;
      k_ = j;
      correction_s_ = now - TransmitS(k_);
      synced_ = true;
    } else {
      gap_s = std::max(0.0, TransmitS(k_) - previous_s_ - correction_s_);
      correction_s_ = 0.0;
    }
    previous_s_ = TransmitS(k_);
    sim_->SimulateScan(sensor_, k_, scan);
    ++k_;
    *since_previous_ns = std::llround(gap_s * 1e9);
    return true;
  }

  void Rewind() override {
    ++pass_;
    k_ = 0;
    synced_ = false;
  }

  common::DurationNs nominal_period_ns() const override {
    return std::llround(sim_->sensor(sensor_).device.period_s * 1e9);
  }

 private:
  double TransmitS(std::uint64_t k) const {
    return static_cast<double>(pass_) * duration_s_ + sim_->Timing(sensor_, k).transmit_s;
  }

  std::shared_ptr<const Simulator> sim_;
  std::size_t sensor_;
  std::function<double()> now_s_;
  tools::DeviceIdentity identity_;
  std::uint64_t count_;
  double duration_s_;
  std::uint64_t k_ = 0;
  std::uint64_t pass_ = 0;
  bool synced_ = false;
  double previous_s_ = 0.0;
  double correction_s_ = 0.0;
};

}  // namespace

std::unique_ptr<tools::ScanSource> MakeSimScanSource(std::shared_ptr<const Simulator> sim,
                                                     std::size_t sensor,
                                                     std::function<double()> now_s) {
  return std::make_unique<SimScanSource>(std::move(sim), sensor, std::move(now_s));
}

}  // namespace lrfnet::sim
