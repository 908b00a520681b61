#include "firmware_tracker/tracking/clock_mapper.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>

namespace lrfnet::tracking {
namespace {

// The model's time origin moves forward after this much device time, so tick differences in ns stay
// small enough for doubles to hold them exactly (2^36 µs, about 19 hours).
constexpr std::int64_t kRebaseAfterUs = std::int64_t{1} << 36;
// Unwrapped ticks beyond +-2^52 µs (142 years) only come from a long series of hostile restarts;
// the bound keeps tick * 1000 and every difference in ns within int64.
constexpr std::int64_t kMaxUnwrappedTickUs = std::int64_t{1} << 52;

bool Positive(double v) { return std::isfinite(v) && v > 0.0; }

std::int64_t FloorDiv(std::int64_t a, std::int64_t b) {
  const std::int64_t q = a / b;
  return (a % b != 0 && (a < 0) != (b < 0)) ? q - 1 : q;
}

}  // namespace

std::optional<std::string> Validate(const ClockMapperOptions& o) {
  if (!Positive(o.bin_s)) return "clock: bin_s must be positive";
  if (!Positive(o.window_s) || o.window_s < o.bin_s) return "clock: window_s must be >= bin_s";
  if (!Positive(o.drift_window_s) || o.drift_window_s < o.window_s)
    return "clock: drift_window_s must be >= window_s";
  const double keep_s = o.estimate_drift ? o.drift_window_s : o.window_s;
  if (keep_s / o.bin_s > static_cast<double>(kMaxClockBins - 2))
    return "clock: (drift_)window_s / bin_s exceeds the fixed bin capacity (" +
           std::to_string(kMaxClockBins - 2) + ")";
  if (!std::isfinite(o.min_drift_span_s) || o.min_drift_span_s < o.bin_s ||
      o.min_drift_span_s > o.drift_window_s)
    return "clock: min_drift_span_s must lie in [bin_s, drift_window_s]";
  if (!Positive(o.max_drift_ppm) || o.max_drift_ppm > 1e4)
    return "clock: max_drift_ppm must lie in (0, 10000]";
  // Half a tick wrap (2^31 µs) is the unwrapper's limit for a forward step.
  if (!Positive(o.restart_threshold_s) || o.restart_threshold_s > 2000.0)
    return "clock: restart_threshold_s must lie in (0, 2000]";
  if (!Positive(o.step_threshold_s)) return "clock: step_threshold_s must be positive";
  if (!std::isfinite(o.settle_s) || o.settle_s < 0.0 || o.settle_s > o.window_s)
    return "clock: settle_s must lie in [0, window_s]";
  if (!Positive(o.step_forward_confirm_s)) return "clock: step_forward_confirm_s must be positive";
  if (o.step_back_confirm_scans == 0) return "clock: step_back_confirm_scans must be >= 1";
  if (!std::isfinite(o.max_device_delay_s) || o.max_device_delay_s < 0.0 ||
      o.max_device_delay_s > 2000.0)
    return "clock: max_device_delay_s must lie in [0, 2000]";
  return std::nullopt;
}

const char* ToString(ClockEvent event) {
  switch (event) {
    case ClockEvent::kNone:
      return "none";
    case ClockEvent::kFirstSample:
      return "first sample";
    case ClockEvent::kDeviceRestart:
      return "device restart";
    case ClockEvent::kClockStepBack:
      return "clock step back";
    case ClockEvent::kClockStepForward:
      return "clock step forward";
    case ClockEvent::kEarlyOutlier:
      return "early outlier";
    case ClockEvent::kRejectedReceiveTime:
      return "rejected receive time";
  }
  return "unknown";
}

ClockMapper::ClockMapper(const ClockMapperOptions& options)
    : options_(options),
      bin_ns_(static_cast<std::int64_t>(options.bin_s * 1e9)),
      unwrapper_(static_cast<std::uint32_t>(options.restart_threshold_s * 1e6)) {
  if (const auto error = Validate(options)) {
    std::fprintf(stderr, "ClockMapper: invalid options: %s\n", error->c_str());
    std::abort();
  }
}

void ClockMapper::Reset() {
  ResetModel();
  carried_slope_.reset();
  unwrapper_.Reset();
}

void ClockMapper::ResetModel() {
  if (slope_fitted_) carried_slope_ = line_b_;
  has_model_ = false;
  model_samples_ = 0;
  bins_.clear();
  line_a_ns_ = line_t_ns_ = line_b_ = 0.0;
  slope_fitted_ = false;
  bins_changed_ = false;
  hull_slope_ = 0.0;
  early_run_ = 0;
  late_since_ns_.reset();
}

void ClockMapper::StartModel(std::int64_t tick_us, common::UtcNs receive_ns) {
  has_model_ = true;
  t_ref_us_ = tick_us;
  d_ref_ns_ = receive_ns - tick_us * common::kNsPerUs;
  index_origin_ns_ = 0;
  model_samples_ = 1;
  Insert(0, 0);
  Estimate();
}

ClockMapResult ClockMapper::Map(std::uint32_t stamp_tick_us, std::uint32_t transmit_tick_us,
                                common::UtcNs receive_ns) {
  ++counters_.samples;
  // Both ticks come from the same device counter, so their modular difference is the device's
  // internal delay between the scan stamp and the transmission.
  std::uint32_t delay_us = transmit_tick_us - stamp_tick_us;
  std::uint32_t offset_tick_us = transmit_tick_us;
  if (static_cast<double>(delay_us) > options_.max_device_delay_s * 1e6) {
    ++counters_.untrusted_transmit_ticks;
    delay_us = 0;
    offset_tick_us = stamp_tick_us;
  }
  common::TickUnwrapper::Result unwrapped = unwrapper_.Unwrap(offset_tick_us);
  if (unwrapped.ticks_us > kMaxUnwrappedTickUs || unwrapped.ticks_us < -kMaxUnwrappedTickUs) {
    unwrapper_.Reset();
    unwrapped = unwrapper_.Unwrap(offset_tick_us);
    unwrapped.restarted = true;
  }
  const std::int64_t tick_us = unwrapped.ticks_us;
  const std::int64_t stamp_us = tick_us - delay_us;

  ClockEvent event = ClockEvent::kNone;
  if (unwrapped.restarted) {
    ++counters_.device_restarts;
    ResetModel();
    event = ClockEvent::kDeviceRestart;
  }

  if (receive_ns <= 0 || receive_ns > kMaxPlausibleUtcNs) {
    ++counters_.rejected_receive_times;
    return Mapped(stamp_us, event == ClockEvent::kNone ? ClockEvent::kRejectedReceiveTime : event,
                  0.0);
  }

  if (!has_model_) {
    StartModel(tick_us, receive_ns);
    return Mapped(stamp_us, event == ClockEvent::kNone ? ClockEvent::kFirstSample : event, 0.0);
  }

  if (tick_us - t_ref_us_ > kRebaseAfterUs) {
    const std::int64_t shift_ns = (tick_us - t_ref_us_) * common::kNsPerUs;
    t_ref_us_ = tick_us;
    for (std::size_t i = 0; i < bins_.size(); ++i) bins_[i].t_ns -= shift_ns;
    line_t_ns_ -= static_cast<double>(shift_ns);
    if (late_since_ns_) *late_since_ns_ -= shift_ns;
    index_origin_ns_ += shift_ns;
  }

  const std::int64_t t_ns = (tick_us - t_ref_us_) * common::kNsPerUs;
  const std::int64_t d_ns = (receive_ns - d_ref_ns_) - tick_us * common::kNsPerUs;
  const double residual_ns = static_cast<double>(d_ns) - LineD(static_cast<double>(t_ns));
  const double threshold_ns = options_.step_threshold_s * 1e9;
  const bool settled = static_cast<double>(t_ns - bins_.front().t_ns) >= options_.settle_s * 1e9;

  if (settled && residual_ns < -threshold_ns) {
    // Received before it was sent by the model's account: not a delay.
    if (++early_run_ >= options_.step_back_confirm_scans) {
      ++counters_.clock_steps_back;
      ResetModel();
      StartModel(tick_us, receive_ns);
      return Mapped(stamp_us, ClockEvent::kClockStepBack, 0.0);
    }
    ++counters_.early_outliers;
    return Mapped(stamp_us, ClockEvent::kEarlyOutlier, residual_ns * 1e-9);
  }
  early_run_ = 0;

  if (settled && residual_ns > threshold_ns) {
    if (!late_since_ns_) {
      late_since_ns_ = t_ns;
    } else if (static_cast<double>(t_ns - *late_since_ns_) >=
               options_.step_forward_confirm_s * 1e9) {
      ++counters_.clock_steps_forward;
      ResetModel();
      StartModel(tick_us, receive_ns);
      return Mapped(stamp_us, ClockEvent::kClockStepForward, 0.0);
    }
  } else {
    late_since_ns_.reset();
  }

  Insert(t_ns, d_ns);
  ++model_samples_;
  Estimate();
  const double latency_ns = static_cast<double>(d_ns) - LineD(static_cast<double>(t_ns));
  return Mapped(stamp_us, event, latency_ns * 1e-9);
}

void ClockMapper::Insert(std::int64_t t_ns, std::int64_t d_ns) {
  const std::int64_t index = FloorDiv(t_ns + index_origin_ns_, bin_ns_);
  if (bins_.empty() || index > bins_.back().index) {
    if (bins_.full()) ++counters_.bins_dropped;
    bins_.push_back(Bin{index, t_ns, d_ns});
    bins_changed_ = true;
  } else {
    // Same bin as the newest, or (tick jitter backwards) an older one still held.
    for (std::size_t i = bins_.size(); i-- > 0;) {
      Bin& bin = bins_[i];
      if (bin.index == index) {
        if (d_ns < bin.d_ns) {
          bin.t_ns = t_ns;
          bin.d_ns = d_ns;
          bins_changed_ = true;
        }
        break;
      }
      if (bin.index < index) break;  // a gap in the envelope: nothing to lower
    }
  }
  const double keep_s = options_.estimate_drift ? options_.drift_window_s : options_.window_s;
  const auto keep_ns = static_cast<std::int64_t>(keep_s * 1e9);
  const std::int64_t newest_ns = bins_.back().t_ns;
  while (bins_.size() > 1 && bins_.front().t_ns < newest_ns - keep_ns) {
    bins_.pop_front();
    bins_changed_ = true;
  }
}

double ClockMapper::HullSlope() {
  // Andrew's monotone chain, lower half; bins are ordered by tick.
  const std::size_t n = bins_.size();
  double mean_t = 0.0;
  std::size_t h = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const double x = static_cast<double>(bins_[i].t_ns);
    const double y = static_cast<double>(bins_[i].d_ns);
    mean_t += x;
    while (h >= 2) {
      const Bin& a = bins_[hull_[h - 2]];
      const Bin& b = bins_[hull_[h - 1]];
      const double ax = static_cast<double>(a.t_ns), ay = static_cast<double>(a.d_ns);
      const double cross = (static_cast<double>(b.t_ns) - ax) * (y - ay) -
                           (static_cast<double>(b.d_ns) - ay) * (x - ax);
      if (cross > 0.0) break;  // counter-clockwise: b stays on the lower hull
      --h;
    }
    hull_[h++] = static_cast<std::uint32_t>(i);
  }
  mean_t /= static_cast<double>(n);
  if (h < 2) return 0.0;
  // The supporting line at the mean tick maximises a + b * mean(t) under a + b * t_i <= d_i.
  for (std::size_t k = 0; k + 1 < h; ++k) {
    const Bin& a = bins_[hull_[k]];
    const Bin& b = bins_[hull_[k + 1]];
    if (static_cast<double>(b.t_ns) >= mean_t || k + 2 == h) {
      return static_cast<double>(b.d_ns - a.d_ns) / static_cast<double>(b.t_ns - a.t_ns);
    }
  }
  return 0.0;
}

void ClockMapper::Estimate() {
  const std::int64_t newest_ns = bins_.back().t_ns;
  double slope = 0.0;
  slope_fitted_ = false;
  if (options_.estimate_drift) {
    const double span_s = common::NsToSeconds(newest_ns - bins_.front().t_ns);
    if (bins_.size() >= 2 && span_s >= options_.min_drift_span_s) {
      if (bins_changed_) hull_slope_ = HullSlope();
      bins_changed_ = false;
      const double max_slope = options_.max_drift_ppm * 1e-6;
      slope = std::clamp(hull_slope_, -max_slope, max_slope);
      slope_fitted_ = true;
    } else if (carried_slope_) {
      slope = *carried_slope_;
    }
  }
  // Schenk et al.'s minimum over the recent window, of d with the drift removed.
  const auto window_ns = static_cast<std::int64_t>(options_.window_s * 1e9);
  double a = std::numeric_limits<double>::infinity();
  for (std::size_t i = bins_.size(); i-- > 0;) {
    const Bin& bin = bins_[i];
    if (bin.t_ns < newest_ns - window_ns) break;
    a = std::min(a,
                 static_cast<double>(bin.d_ns) - slope * static_cast<double>(bin.t_ns - newest_ns));
  }
  line_a_ns_ = a;
  line_b_ = slope;
  line_t_ns_ = static_cast<double>(newest_ns);
}

ClockMapResult ClockMapper::Mapped(std::int64_t stamp_tick_us, ClockEvent event,
                                   double latency_s) const {
  ClockMapResult r;
  r.event = event;
  r.latency_s = latency_s;
  if (!has_model_) return r;
  const std::int64_t t_ns = (stamp_tick_us - t_ref_us_) * common::kNsPerUs;
  r.valid = true;
  r.scan_start_ns =
      stamp_tick_us * common::kNsPerUs + d_ref_ns_ + std::llround(LineD(static_cast<double>(t_ns)));
  return r;
}

ClockMapperStatus ClockMapper::status() const {
  ClockMapperStatus s;
  if (!has_model_) return s;
  s.valid = true;
  s.offset_s = common::NsToSeconds(d_ref_ns_) + line_a_ns_ * 1e-9;
  s.drift_ppm = line_b_ * 1e6;
  s.drift_estimated = slope_fitted_;
  s.samples = model_samples_;
  s.bins = bins_.size();
  s.span_s = common::NsToSeconds(bins_.back().t_ns - bins_.front().t_ns);
  return s;
}

}  // namespace lrfnet::tracking
