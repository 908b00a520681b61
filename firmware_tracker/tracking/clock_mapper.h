#pragma once
// Maps a SICK device's free-running µs tick to the gateway's UTC clock.
//
// Model. The gateway receives a scan telegram at receive_ns; the telegram carries the device ticks
// "time since startup" (the scan stamp) and "time of transmission". With d = receive - tick:
//     d(tick) = offset + drift * tick + latency,   latency >= latency_min > 0,
// so the samples of d lie on or above a line, and the line is what we want. Schenk et al. (section
// IV-A, "it is sufficient to maintain the minimum offset observed between the timestamp of a laser
// scan and the time of reception") keep offset = min over recent scans of d. We do the same and
// track the drift:
//   - the samples are reduced to a lower envelope: one minimum per bin of bin_s device seconds;
//   - drift is the slope of the line that lies below every bin minimum of the last drift_window_s
//     and is tightest on average: it maximises a + b * mean(t), i.e. it is the edge of the lower
//     convex hull of the bin minima above their mean tick (the linear-programming skew estimator
//     for one-way delays of Moon, Skelly and Towsley, "Estimation and removal of clock skew from
//     network delay measurements", INFOCOM 1999). Delay spikes only lift points above the hull, so
//     they cannot bias the slope;
//   - the offset is Schenk's minimum over the last window_s of d after removing that slope, so the
//     rule is the paper's when estimate_drift is off, or before the samples span min_drift_span_s
//     (then the slope carried over from before the last reset is used, else 0).
// The offset is estimated from the *transmission* tick when the telegram has one: d then contains
// only the network and gateway latency. The scan stamp precedes the transmission by a
// model-specific internal delay (3 ms on an LMS111 at 50 Hz, 40 ms on an LMS511 at 25 Hz, 65 ms on
// an MRS1104 in the shipped captures), which the minimum rule applied to the stamp tick would add
// to every scan time as a bias.
//     mapped scan start = stamp tick + offset + drift * (stamp tick - newest tick).
//
// Events (each counted, none fatal):
//   - device restart: the tick steps back by more than restart_threshold_s (common::TickUnwrapper),
//     or the unwrapped tick leaves +-2^52 µs. The model is reset.
//   - clock step back: d falls below the line by more than step_threshold_s. Impossible for a
//     delay, so it is the gateway clock stepping back, the tick jumping forward, or a corrupt
//     receive time. Such samples are rejected (the scan is mapped with the old model);
//     step_back_confirm_scans of them in a row reset the model.
//   - clock step forward: every sample lies above the line by more than step_threshold_s for
//     step_forward_confirm_s of device time (a network stall drains within that; a clock step does
//     not). The model is reset.
//   - a model younger than settle_s has no step detection: lower samples are simply new minima.
//   - receive times outside (0, kMaxPlausibleUtcNs] are rejected; the scan is mapped with the
//     model.
// A reset keeps the last slope fitted over at least min_drift_span_s: the oscillators are the same.
//
// Pure: time is an argument, no clock reads, no allocation (fixed-capacity storage).
// Not thread-safe.

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>

#include "common/fixed_capacity.h"
#include "common/time.h"

namespace lrfnet::tracking {

// Compile-time bound on the lower-envelope bins kept (drift_window_s / bin_s must stay below it).
inline constexpr std::size_t kMaxClockBins = 2048;
// Receive times after this (in 2096) are rejected as corrupt; the bound keeps arithmetic in int64.
inline constexpr common::UtcNs kMaxPlausibleUtcNs = std::int64_t{4'000'000'000} * common::kNsPerS;

struct ClockMapperOptions {
  double window_s = 30.0;  // minimum-offset window (Schenk et al.)
  bool estimate_drift = true;
  double drift_window_s = 600.0;  // lower envelope used for the slope
  // The samples must span this much device time before a slope is fitted.
  double min_drift_span_s = 60.0;
  double max_drift_ppm = 300.0;      // slope estimates are clamped to +-this
  double bin_s = 1.0;                // lower-envelope resolution: one minimum per bin
  double restart_threshold_s = 1.0;  // the tick stepping back by more than this is a device restart
  double step_threshold_s = 0.05;    // |d - line| beyond this is a clock-step candidate
  // A model younger than this (device time) takes every sample as it comes, without step detection,
  // so a start in the middle of a network backlog converges instead of cascading into resets.
  double settle_s = 5.0;
  double step_forward_confirm_s = 5.0;
  std::uint32_t step_back_confirm_scans = 5;
  // Transmission tick minus stamp tick beyond this: the transmission tick is not trusted (counted)
  // and the stamp tick is used for the offset.
  double max_device_delay_s = 1.0;
};

std::optional<std::string> Validate(const ClockMapperOptions& options);

enum class ClockEvent : std::uint8_t {
  kNone,
  kFirstSample,       // the first sample of a new model (start or after a reset)
  kDeviceRestart,     // model reset
  kClockStepBack,     // model reset
  kClockStepForward,  // model reset
  kEarlyOutlier,      // sample below the line beyond the threshold: rejected, not (yet) a step
  kRejectedReceiveTime,
};
const char* ToString(ClockEvent event);

struct ClockMapResult {
  bool valid = false;               // false only before the first usable sample
  common::UtcNs scan_start_ns = 0;  // the stamp tick in gateway UTC
  ClockEvent event = ClockEvent::kNone;
  double latency_s = 0.0;  // this sample's d above the line (>= 0 for samples that shape it)
};

struct ClockMapperCounters {
  std::uint64_t samples = 0;  // calls to Map
  std::uint64_t device_restarts = 0;
  std::uint64_t clock_steps_back = 0;
  std::uint64_t clock_steps_forward = 0;
  std::uint64_t early_outliers = 0;
  std::uint64_t rejected_receive_times = 0;
  std::uint64_t untrusted_transmit_ticks = 0;
  std::uint64_t bins_dropped = 0;  // envelope bins evicted because the ring was full
};

struct ClockMapperStatus {
  bool valid = false;
  double offset_s = 0.0;         // gateway UTC - device tick at the newest sample, seconds
  double drift_ppm = 0.0;        // d(gateway - tick) / d(tick), parts per million
  bool drift_estimated = false;  // the slope was fitted in this model (not carried over or 0)
  std::uint64_t samples = 0;     // samples in the current model (since the last reset)
  std::size_t bins = 0;          // lower-envelope bins held
  double span_s = 0.0;           // device time the bins span
};

class ClockMapper {
 public:
  // Precondition: Validate(options) is nullopt (checked; aborts otherwise).
  explicit ClockMapper(const ClockMapperOptions& options = {});

  // One scan telegram: its stamp tick ("time since startup"), its transmission tick ("time of
  // transmission"), both raw uint32 µs, and the gateway UTC time it was received (live: read after
  // the telegram's last byte arrived; replay: the capture's packet timestamp).
  ClockMapResult Map(std::uint32_t stamp_tick_us, std::uint32_t transmit_tick_us,
                     common::UtcNs receive_ns);
  // Without a transmission tick: the stamp tick is used for the offset too (Schenk et al. as
  // written).
  ClockMapResult Map(std::uint32_t stamp_tick_us, common::UtcNs receive_ns) {
    return Map(stamp_tick_us, stamp_tick_us, receive_ns);
  }

  ClockMapperStatus status() const;
  const ClockMapperCounters& counters() const { return counters_; }
  // Forgets everything but the counters (including the carried slope and the tick history).
  void Reset();

 private:
  struct Bin {
    std::int64_t index = 0;  // floor(t / bin)
    std::int64_t t_ns = 0;   // device tick of the minimum, relative to t_ref_us_
    std::int64_t d_ns = 0;   // receive - tick of the minimum, relative to d_ref_ns_
  };

  void ResetModel();
  void StartModel(std::int64_t tick_us, common::UtcNs receive_ns);
  void Insert(std::int64_t t_ns, std::int64_t d_ns);
  void Estimate();
  double HullSlope();
  double LineD(double t_ns) const { return line_a_ns_ + line_b_ * (t_ns - line_t_ns_); }
  ClockMapResult Mapped(std::int64_t stamp_tick_us, ClockEvent event, double latency_s) const;

  ClockMapperOptions options_;
  std::int64_t bin_ns_;
  common::TickUnwrapper unwrapper_;
  ClockMapperCounters counters_;

  // Current model; times relative to the references so doubles stay exact.
  bool has_model_ = false;
  std::int64_t t_ref_us_ = 0;  // unwrapped tick of the model's first sample
  std::int64_t d_ref_ns_ = 0;  // receive - tick of the model's first sample
  // Bin index = floor((t + index_origin) / bin), so indices stay ordered across rebases.
  std::int64_t index_origin_ns_ = 0;
  std::uint64_t model_samples_ = 0;
  common::RingBuffer<Bin, kMaxClockBins> bins_;
  double line_a_ns_ = 0.0;  // d of the line at line_t_ns_
  double line_t_ns_ = 0.0;
  double line_b_ = 0.0;  // slope (dimensionless)
  bool slope_fitted_ = false;
  bool bins_changed_ = false;
  double hull_slope_ = 0.0;
  std::optional<double> carried_slope_;
  std::uint32_t early_run_ = 0;
  std::optional<std::int64_t> late_since_ns_;
  std::array<std::uint32_t, kMaxClockBins> hull_{};  // scratch: lower-hull bin indices
};

}  // namespace lrfnet::tracking
