#include "firmware_tracker/tracking/clock_mapper.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>

namespace lrfnet::tracking {
namespace {

constexpr common::UtcNs kUtc0 = 1'700'000'000 * common::kNsPerS;

// A simulated device and link. Device time tau (seconds since the simulation start) maps to the
// device tick tick0 + tau (µs, wrapping) and to the true gateway time kUtc0 + tau * (1 + drift).
// The scan is stamped at tau, transmitted device_delay_s later and received after the link latency.
struct Link {
  double drift_ppm = 0.0;
  std::uint32_t tick0_us = 123'456'789;
  double period_s = 0.04;
  double device_delay_s = 0.040;
  double base_latency_s = 0.0003;
  double mean_jitter_s = 0.002;  // exponential
  std::mt19937_64 rng{42};

  common::UtcNs TrueUtc(double tau_s) const {
    return kUtc0 + std::llround(tau_s * (1.0 + drift_ppm * 1e-6) * 1e9);
  }
  static std::uint32_t Tick(std::uint32_t tick0, double tau_s) {
    return tick0 + static_cast<std::uint32_t>(std::llround(tau_s * 1e6) & 0xffffffffLL);
  }
  double Latency() {
    std::exponential_distribution<double> exp(1.0 / mean_jitter_s);
    return base_latency_s + exp(rng);
  }
};

struct Sample {
  std::uint32_t stamp_us;
  std::uint32_t transmit_us;
  common::UtcNs receive_ns;
  common::UtcNs true_stamp_ns;
};

Sample Make(Link& link, std::int64_t k, double extra_latency_s = 0.0) {
  const double tau = static_cast<double>(k) * link.period_s;
  const double tx = tau + link.device_delay_s;
  Sample s;
  s.stamp_us = Link::Tick(link.tick0_us, tau);
  s.transmit_us = Link::Tick(link.tick0_us, tx);
  s.receive_ns = link.TrueUtc(tx) + std::llround((link.Latency() + extra_latency_s) * 1e9);
  s.true_stamp_ns = link.TrueUtc(tau);
  return s;
}

double ErrorS(const ClockMapResult& r, const Sample& s) {
  return static_cast<double>(r.scan_start_ns - s.true_stamp_ns) * 1e-9;
}

TEST(ClockMapperTest, DefaultsValidateAndBadOptionsAreNamed) {
  EXPECT_EQ(Validate(ClockMapperOptions{}), std::nullopt);
  ClockMapperOptions o;
  o.window_s = 0.0;
  ASSERT_TRUE(Validate(o).has_value());
  EXPECT_NE(Validate(o)->find("window_s"), std::string::npos);
  o = {};
  o.drift_window_s = 1e5;  // more bins than the fixed capacity
  ASSERT_TRUE(Validate(o).has_value());
  EXPECT_NE(Validate(o)->find("capacity"), std::string::npos);
  o = {};
  o.max_drift_ppm = std::numeric_limits<double>::quiet_NaN();
  EXPECT_TRUE(Validate(o).has_value());
  o = {};
  o.step_back_confirm_scans = 0;
  EXPECT_TRUE(Validate(o).has_value());
}

TEST(ClockMapperTest, NothingMappedBeforeTheFirstUsableSample) {
  ClockMapper mapper;
  const ClockMapResult r = mapper.Map(1000, 0);  // receive time 0: rejected
  EXPECT_FALSE(r.valid);
  EXPECT_EQ(r.event, ClockEvent::kRejectedReceiveTime);
  EXPECT_FALSE(mapper.status().valid);
  const ClockMapResult first = mapper.Map(2000, kUtc0);
  EXPECT_TRUE(first.valid);
  EXPECT_EQ(first.event, ClockEvent::kFirstSample);
  EXPECT_EQ(first.scan_start_ns, kUtc0);  // one sample: tick + (receive - tick)
}

// Constant offset, exponential latency: after one window the mapped stamp is late by no more than
// the link's minimum latency plus a small margin, for the plain minimum rule and with drift
// tracking.
TEST(ClockMapperTest, ConstantOffsetWithExponentialLatency) {
  for (const bool drift : {false, true}) {
    SCOPED_TRACE(drift ? "drift estimated" : "Schenk minimum only");
    ClockMapperOptions options;
    options.estimate_drift = drift;
    ClockMapper mapper(options);
    Link link;
    double max_error_s = -1.0, min_error_s = 1.0;
    for (std::int64_t k = 0; k < 25 * 180; ++k) {
      const Sample s = Make(link, k);
      const ClockMapResult r = mapper.Map(s.stamp_us, s.transmit_us, s.receive_ns);
      ASSERT_TRUE(r.valid);
      if (static_cast<double>(k) * link.period_s < options.window_s) continue;
      max_error_s = std::max(max_error_s, ErrorS(r, s));
      min_error_s = std::min(min_error_s, ErrorS(r, s));
    }
    EXPECT_GE(min_error_s, link.base_latency_s - 50e-6);
    EXPECT_LE(max_error_s, link.base_latency_s + 150e-6);
    EXPECT_EQ(mapper.counters().early_outliers, 0u);
    EXPECT_EQ(mapper.counters().clock_steps_forward + mapper.counters().clock_steps_back, 0u);
    EXPECT_NEAR(mapper.status().drift_ppm, 0.0, 2.0);
  }
}

// The device stamps the scan before it transmits it (40 ms on an LMS511 at 25 Hz). The minimum rule
// on the stamp tick alone puts that delay into every scan time; with the transmission tick it is
// gone.
TEST(ClockMapperTest, TransmissionTickRemovesTheDeviceDelayBias) {
  ClockMapper with_tx;
  ClockMapper stamp_only;
  Link link;
  link.device_delay_s = 0.040;
  double error_tx = 0.0, error_stamp = 0.0;
  for (std::int64_t k = 0; k < 25 * 60; ++k) {
    const Sample s = Make(link, k);
    error_tx = ErrorS(with_tx.Map(s.stamp_us, s.transmit_us, s.receive_ns), s);
    error_stamp = ErrorS(stamp_only.Map(s.stamp_us, s.receive_ns), s);
  }
  EXPECT_NEAR(error_tx, link.base_latency_s, 150e-6);
  EXPECT_NEAR(error_stamp, link.device_delay_s + link.base_latency_s, 150e-6);
}

TEST(ClockMapperTest, ImplausibleTransmissionTickFallsBackToTheStamp) {
  ClockMapper mapper;
  Link link;
  for (std::int64_t k = 0; k < 100; ++k) {
    const Sample s = Make(link, k);
    // Transmission "before" the stamp: the modular difference is ~2^32 µs, far beyond 1 s.
    const ClockMapResult r = mapper.Map(s.stamp_us, s.stamp_us - 5, s.receive_ns);
    ASSERT_TRUE(r.valid);
  }
  EXPECT_EQ(mapper.counters().untrusted_transmit_ticks, 100u);
  EXPECT_EQ(mapper.counters().device_restarts, 0u);
}

// 50 ppm over two hours, the tick wrapping 10 minutes in: the slope is found and the stamps stay
// within the minimum latency plus a margin; without drift tracking the same data lags by ~1.5 ms.
TEST(ClockMapperTest, DriftOverTwoHoursAcrossATickWrap) {
  ClockMapperOptions no_drift;
  no_drift.estimate_drift = false;
  ClockMapper mapper;
  ClockMapper plain(no_drift);
  Link link;
  link.drift_ppm = 50.0;
  link.tick0_us = 0xffffffffu - 600'000'000u;  // wraps after 600 s
  const std::int64_t scans = static_cast<std::int64_t>(2 * 3600 / link.period_s);
  double max_error_s = 0.0, max_plain_error_s = 0.0;
  bool wrapped = false;
  std::uint32_t last_stamp = 0;
  for (std::int64_t k = 0; k < scans; ++k) {
    const Sample s = Make(link, k);
    wrapped |= k > 0 && s.stamp_us < last_stamp;
    last_stamp = s.stamp_us;
    const ClockMapResult r = mapper.Map(s.stamp_us, s.transmit_us, s.receive_ns);
    const ClockMapResult p = plain.Map(s.stamp_us, s.transmit_us, s.receive_ns);
    ASSERT_TRUE(r.valid);
    ASSERT_TRUE(r.event == ClockEvent::kNone || k == 0) << ToString(r.event) << " at scan " << k;
    if (static_cast<double>(k) * link.period_s < 120.0) continue;  // one drift span plus one window
    max_error_s = std::max(max_error_s, std::abs(ErrorS(r, s) - link.base_latency_s));
    max_plain_error_s = std::max(max_plain_error_s, std::abs(ErrorS(p, s) - link.base_latency_s));
  }
  EXPECT_TRUE(wrapped);
  EXPECT_LT(max_error_s, 150e-6);
  EXPECT_GT(max_plain_error_s, 1.0e-3);
  const ClockMapperStatus st = mapper.status();
  EXPECT_TRUE(st.drift_estimated);
  EXPECT_NEAR(st.drift_ppm, 50.0, 1.0);
  EXPECT_EQ(mapper.counters().device_restarts, 0u);
  EXPECT_NEAR(st.span_s, 600.0, 2.0);
  // Offset = gateway UTC - tick at the newest sample.
  const double tau = static_cast<double>(scans - 1) * link.period_s + link.device_delay_s;
  const double tick_s = (static_cast<double>(link.tick0_us) + tau * 1e6) * 1e-6;  // unwrapped
  EXPECT_NEAR(st.offset_s, static_cast<double>(link.TrueUtc(tau)) * 1e-9 - tick_s, 1e-3);
}

// A device restart (tick back to near zero) resets the model; the next scans map correctly at once
// and the drift estimated before is kept.
TEST(ClockMapperTest, DeviceRestartResetsAndKeepsTheDrift) {
  ClockMapper mapper;
  Link link;
  link.drift_ppm = -30.0;
  std::int64_t k = 0;
  for (; k < 25 * 200; ++k) {
    const Sample s = Make(link, k);
    mapper.Map(s.stamp_us, s.transmit_us, s.receive_ns);
  }
  ASSERT_NEAR(mapper.status().drift_ppm, -30.0, 2.0);
  // Restart: 20 s later, the tick starts again at 0.
  const double restart_tau = static_cast<double>(k) * link.period_s + 20.0;
  link.tick0_us = Link::Tick(0, 0.0) - static_cast<std::uint32_t>(std::llround(restart_tau * 1e6));
  const std::int64_t first_after = k + 500;
  double max_error_s = 0.0;
  for (std::int64_t j = first_after; j < first_after + 25 * 30; ++j) {
    const Sample s = Make(link, j);
    const ClockMapResult r = mapper.Map(s.stamp_us, s.transmit_us, s.receive_ns);
    ASSERT_TRUE(r.valid);
    if (j == first_after) {
      EXPECT_EQ(r.event, ClockEvent::kDeviceRestart);
    }
    // After the first second the minimum has seen a few dozen samples.
    if (j >= first_after + 25) max_error_s = std::max(max_error_s, ErrorS(r, s));
  }
  EXPECT_EQ(mapper.counters().device_restarts, 1u);
  EXPECT_LT(max_error_s, link.base_latency_s + 0.5e-3);
  const ClockMapperStatus st = mapper.status();
  EXPECT_FALSE(st.drift_estimated);  // too little time since the restart to fit a new slope
  EXPECT_NEAR(st.drift_ppm, -30.0, 2.0);
  EXPECT_EQ(st.samples, 25u * 30u);
}

// Late scans (a spike, a stalled connection draining its backlog) are still stamped right: the
// mapping uses the device tick, and late samples never pull the minimum.
TEST(ClockMapperTest, LatencySpikesAndStallsDoNotMoveTheStamps) {
  ClockMapper mapper;
  Link link;
  std::mt19937_64 rng(7);
  double max_error_s = 0.0;
  for (std::int64_t k = 0; k < 25 * 300; ++k) {
    const double tau = static_cast<double>(k) * link.period_s;
    double extra = 0.0;
    if (rng() % 100 == 0) extra = 10.0;  // 1% of the scans 10 s late
    if (tau >= 100.0 && tau < 103.0) extra = 103.0 - tau + 0.0001 * (tau - 100.0);  // 3 s stall
    const Sample s = Make(link, k, extra);
    const ClockMapResult r = mapper.Map(s.stamp_us, s.transmit_us, s.receive_ns);
    ASSERT_TRUE(r.valid);
    if (tau >= 30.0) max_error_s = std::max(max_error_s, std::abs(ErrorS(r, s)));
  }
  EXPECT_LT(max_error_s, link.base_latency_s + 150e-6);
  EXPECT_EQ(mapper.counters().clock_steps_forward, 0u);
  EXPECT_EQ(mapper.counters().clock_steps_back, 0u);
}

// One receive time far in the past (a corrupt capture timestamp) is rejected, the stamps stay
// right. The gateway clock stepping back for good is confirmed after a few scans and followed.
TEST(ClockMapperTest, ReceiveTimeGoingBackwards) {
  ClockMapper mapper;
  Link link;
  std::int64_t k = 0;
  for (; k < 25 * 60; ++k) {
    const Sample s = Make(link, k);
    mapper.Map(s.stamp_us, s.transmit_us, s.receive_ns);
  }
  {
    const Sample s = Make(link, k++);
    const ClockMapResult r =
        mapper.Map(s.stamp_us, s.transmit_us, s.receive_ns - 2 * common::kNsPerS);
    EXPECT_EQ(r.event, ClockEvent::kEarlyOutlier);
    EXPECT_NEAR(ErrorS(r, s), link.base_latency_s, 150e-6);
    EXPECT_NEAR(r.latency_s, -2.0, 0.01);
  }
  for (int j = 0; j < 50; ++j, ++k) {
    const Sample s = Make(link, k);
    EXPECT_NEAR(ErrorS(mapper.Map(s.stamp_us, s.transmit_us, s.receive_ns), s), link.base_latency_s,
                150e-6);
  }
  EXPECT_EQ(mapper.counters().early_outliers, 1u);
  EXPECT_EQ(mapper.counters().clock_steps_back, 0u);

  // The gateway clock steps back by 1 s and stays there.
  const common::DurationNs step = -common::kNsPerS;
  int resets_at = -1;
  double max_error_s = 0.0;
  for (int j = 0; j < 25 * 60; ++j, ++k) {
    Sample s = Make(link, k);
    s.receive_ns += step;
    s.true_stamp_ns += step;
    const ClockMapResult r = mapper.Map(s.stamp_us, s.transmit_us, s.receive_ns);
    if (r.event == ClockEvent::kClockStepBack) resets_at = j;
    if (j >= 25 * 2) max_error_s = std::max(max_error_s, std::abs(ErrorS(r, s)));
  }
  EXPECT_EQ(resets_at, 4);  // the fifth early scan in a row confirms the step
  EXPECT_EQ(mapper.counters().clock_steps_back, 1u);
  EXPECT_LT(max_error_s, link.base_latency_s + 1e-3);
}

TEST(ClockMapperTest, GatewayClockStepForwardIsFollowedAfterConfirmation) {
  ClockMapper mapper;
  Link link;
  std::int64_t k = 0;
  for (; k < 25 * 60; ++k) {
    const Sample s = Make(link, k);
    mapper.Map(s.stamp_us, s.transmit_us, s.receive_ns);
  }
  double max_error_s = 0.0;
  int reset_at = -1;
  for (int j = 0; j < 25 * 60; ++j, ++k) {
    Sample s = Make(link, k);
    s.receive_ns += common::kNsPerS;
    s.true_stamp_ns += common::kNsPerS;
    const ClockMapResult r = mapper.Map(s.stamp_us, s.transmit_us, s.receive_ns);
    if (r.event == ClockEvent::kClockStepForward) reset_at = j;
    if (j >= 25 * 7) max_error_s = std::max(max_error_s, std::abs(ErrorS(r, s)));
  }
  // Confirmed after step_forward_confirm_s (5 s) of device time.
  EXPECT_EQ(reset_at, 125);
  EXPECT_EQ(mapper.counters().clock_steps_forward, 1u);
  EXPECT_LT(max_error_s, link.base_latency_s + 1e-3);
}

TEST(ClockMapperTest, StartInsideABacklogConvergesWithoutResets) {
  ClockMapper mapper;
  Link link;
  double error_s = 1.0;
  for (std::int64_t k = 0; k < 25 * 40; ++k) {
    const double tau = static_cast<double>(k) * link.period_s;
    // The first 2 s of scans arrive together, then normal latency.
    const double extra = tau < 2.0 ? 2.0 - tau : 0.0;
    const Sample s = Make(link, k, extra);
    error_s = ErrorS(mapper.Map(s.stamp_us, s.transmit_us, s.receive_ns), s);
  }
  EXPECT_NEAR(error_s, link.base_latency_s, 150e-6);
  EXPECT_EQ(mapper.counters().clock_steps_back + mapper.counters().clock_steps_forward, 0u);
}

TEST(ClockMapperTest, HostileReceiveTimesAreRejected) {
  ClockMapper mapper;
  Link link;
  std::int64_t k = 0;
  for (; k < 25 * 40; ++k) {
    const Sample s = Make(link, k);
    mapper.Map(s.stamp_us, s.transmit_us, s.receive_ns);
  }
  for (const common::UtcNs bad :
       {common::UtcNs{0}, common::UtcNs{-1}, std::numeric_limits<common::UtcNs>::min(),
        std::numeric_limits<common::UtcNs>::max(), kMaxPlausibleUtcNs + 1}) {
    const Sample s = Make(link, k++);
    const ClockMapResult r = mapper.Map(s.stamp_us, s.transmit_us, bad);
    EXPECT_TRUE(r.valid);
    EXPECT_EQ(r.event, ClockEvent::kRejectedReceiveTime);
    EXPECT_NEAR(ErrorS(r, s), link.base_latency_s, 150e-6);
  }
  EXPECT_EQ(mapper.counters().rejected_receive_times, 5u);
}

// Arbitrary ticks and receive times: every result is either invalid or a time, and the counters add
// up. Run under the sanitizer build this also shows there is no signed overflow.
TEST(ClockMapperTest, RandomInputsNeverBreakTheModel) {
  ClockMapper mapper;
  std::mt19937_64 rng(99);
  std::uint64_t events = 0;
  for (int i = 0; i < 200'000; ++i) {
    const auto stamp = static_cast<std::uint32_t>(rng());
    const auto tx = (rng() % 4 == 0) ? static_cast<std::uint32_t>(rng()) : stamp + 1000u;
    common::UtcNs receive = static_cast<common::UtcNs>(rng());
    if (rng() % 2) receive = kUtc0 + static_cast<common::UtcNs>(rng() % (1ull << 40));
    const ClockMapResult r = mapper.Map(stamp, tx, receive);
    events += r.event != ClockEvent::kNone ? 1 : 0;
    ASSERT_TRUE(std::isfinite(r.latency_s));
  }
  EXPECT_GT(events, 0u);
  // Then a well-behaved link: the model recovers.
  Link link;
  link.tick0_us = 7;
  double error_s = 1.0;
  for (std::int64_t k = 0; k < 25 * 40; ++k) {
    const Sample s = Make(link, k);
    error_s = ErrorS(mapper.Map(s.stamp_us, s.transmit_us, s.receive_ns), s);
  }
  EXPECT_NEAR(error_s, link.base_latency_s, 0.5e-3);
}

// Ticks that jump almost half a wrap forward every time unwrap to ever larger values; long before
// the nanosecond arithmetic could overflow, the mapper starts over (a restart) and keeps working.
TEST(ClockMapperTest, RunawayTicksRestartInsteadOfOverflowing) {
  ClockMapper mapper;
  std::uint32_t tick = 0;
  for (int i = 0; i < (1 << 21) + 1000; ++i) {
    tick += 0x7fffffffu;
    mapper.Map(tick, kUtc0 + i * common::kNsPerMs);
  }
  EXPECT_EQ(mapper.counters().device_restarts, 1u);
  Link link;
  double error_s = 1.0;
  for (std::int64_t k = 0; k < 25 * 40; ++k) {
    const Sample s = Make(link, k);
    error_s = ErrorS(mapper.Map(s.stamp_us, s.transmit_us, s.receive_ns), s);
  }
  EXPECT_NEAR(error_s, link.base_latency_s, 0.5e-3);
}

// Beyond the model's rebase interval (~19 h of device time) the stamps stay exact.
TEST(ClockMapperTest, DayLongRunAcrossRebases) {
  ClockMapper mapper;
  Link link;
  link.period_s = 0.5;  // fewer samples; the model does not depend on the rate
  link.drift_ppm = 20.0;
  double max_error_s = 0.0;
  const std::int64_t scans = static_cast<std::int64_t>(30 * 3600 / link.period_s);
  for (std::int64_t k = 0; k < scans; ++k) {
    const Sample s = Make(link, k);
    const ClockMapResult r = mapper.Map(s.stamp_us, s.transmit_us, s.receive_ns);
    if (static_cast<double>(k) * link.period_s > 120.0)
      max_error_s = std::max(max_error_s, std::abs(ErrorS(r, s)));
  }
  EXPECT_LT(max_error_s, link.base_latency_s + 1e-3);
  EXPECT_NEAR(mapper.status().drift_ppm, 20.0, 2.0);
  EXPECT_EQ(mapper.counters().device_restarts + mapper.counters().clock_steps_back +
                mapper.counters().clock_steps_forward,
            0u);
}

}  // namespace
}  // namespace lrfnet::tracking
