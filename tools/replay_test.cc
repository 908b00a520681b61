#include "tools/replay.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace lrfnet::tools {
namespace {

using common::DurationNs;
using common::kNsPerMs;
using common::kNsPerS;
using common::UtcNs;

constexpr UtcNs kT0 = 1'700'000'000'000'000'000;

std::vector<DurationNs> Offsets(const std::vector<UtcNs>& receive_ns, double speed,
                                double max_gap_s = 0.0) {
  ReplayScheduleOptions options;
  options.speed = speed;
  options.max_gap_s = max_gap_s;
  return ComputeSendOffsets(receive_ns, options);
}

TEST(ReplayScheduleTest, RecordedTimingAtSpeedOneIsExact) {
  const std::vector<UtcNs> t = {kT0, kT0 + 40 * kNsPerMs + 1, kT0 + 80 * kNsPerMs + 3,
                                kT0 + 3600 * kNsPerS + 7};
  EXPECT_EQ(Offsets(t, 1.0),
            (std::vector<DurationNs>{0, 40 * kNsPerMs + 1, 80 * kNsPerMs + 3, 3600 * kNsPerS + 7}));
}

TEST(ReplayScheduleTest, SpeedScalesEveryOffsetFromTheFirstDatagram) {
  const std::vector<UtcNs> t = {kT0, kT0 + kNsPerS, kT0 + 2 * kNsPerS};
  EXPECT_EQ(Offsets(t, 10.0), (std::vector<DurationNs>{0, 100 * kNsPerMs, 200 * kNsPerMs}));
  EXPECT_EQ(Offsets(t, 0.5), (std::vector<DurationNs>{0, 2 * kNsPerS, 4 * kNsPerS}));
  EXPECT_EQ(Offsets(t, 0.0), (std::vector<DurationNs>{0, 0, 0}));
}

TEST(ReplayScheduleTest, OffsetsDoNotDriftOverAMillionDatagrams) {
  // 1 ms apart at speed 3: each step is 333333.33 ns; rounding each step would lose 0.33 ns per
  // datagram (a third of a millisecond over the run).
  ReplayScheduleOptions options;
  options.speed = 3.0;
  ReplaySchedule schedule(options);
  DurationNs last = 0;
  for (int i = 0; i <= 1'000'000; ++i) last = schedule.Next(kT0 + i * kNsPerMs);
  EXPECT_NEAR(static_cast<double>(last), 1e12 / 3.0, 1.0);
}

TEST(ReplayScheduleTest, LongGapsAreShortenedToTheMaximum) {
  const std::vector<UtcNs> t = {kT0, kT0 + kNsPerS, kT0 + 601 * kNsPerS, kT0 + 602 * kNsPerS};
  EXPECT_EQ(Offsets(t, 1.0, 5.0), (std::vector<DurationNs>{0, kNsPerS, 6 * kNsPerS, 7 * kNsPerS}));
  // The gap limit is recording time: at speed 2 the 5 s gap takes 2.5 s.
  EXPECT_EQ(Offsets(t, 2.0, 5.0),
            (std::vector<DurationNs>{0, kNsPerS / 2, 3 * kNsPerS, 7 * kNsPerS / 2}));
  ReplayScheduleOptions options;
  options.max_gap_s = 5.0;
  ReplaySchedule schedule(options);
  for (const UtcNs x : t) schedule.Next(x);
  EXPECT_EQ(schedule.shortened_gaps(), 1u);
  EXPECT_EQ(schedule.recording_ns(), 7 * kNsPerS);
}

TEST(ReplayScheduleTest, ReceiveTimesGoingBackwardsNeverMakeTheScheduleGoBackwards) {
  // A clock step back of 10 s after the second datagram; afterwards the stream goes on normally
  // from the new time.
  const std::vector<UtcNs> t = {kT0, kT0 + kNsPerS, kT0 - 9 * kNsPerS, kT0 - 8 * kNsPerS,
                                kT0 - 8 * kNsPerS - 1};
  const std::vector<DurationNs> offsets = Offsets(t, 1.0);
  EXPECT_EQ(offsets, (std::vector<DurationNs>{0, kNsPerS, kNsPerS, 2 * kNsPerS, 2 * kNsPerS}));
  for (std::size_t i = 1; i < offsets.size(); ++i) EXPECT_GE(offsets[i], offsets[i - 1]) << i;

  ReplaySchedule schedule(ReplayScheduleOptions{});
  for (const UtcNs x : t) schedule.Next(x);
  EXPECT_EQ(schedule.steps_back(), 2u);
}

TEST(ReplayScheduleTest, ExtremeReceiveTimesSaturateInsteadOfOverflowing) {
  constexpr UtcNs kMin = std::numeric_limits<UtcNs>::min();
  constexpr UtcNs kMax = std::numeric_limits<UtcNs>::max();
  EXPECT_EQ(Offsets({kMin, kMax, kMin, kMax}, 1.0), (std::vector<DurationNs>{0, kMax, kMax, kMax}));
  EXPECT_EQ(Offsets({0, kMax}, 1e-9), (std::vector<DurationNs>{0, kMax}));
  const std::vector<DurationNs> fast = Offsets({kMin, kMax}, 4.0);
  EXPECT_GT(fast[1], kMax / 5);
  EXPECT_LE(fast[1], kMax / 4 + 1);
}

TEST(ReplayScheduleTest, ValidateRejectsNegativeAndNonFiniteValues) {
  for (const double speed :
       {-1.0, std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    ReplayScheduleOptions options;
    options.speed = speed;
    EXPECT_TRUE(Validate(options).has_value()) << speed;
  }
  for (const double gap : {-0.5, 1e12, std::numeric_limits<double>::quiet_NaN()}) {
    ReplayScheduleOptions options;
    options.max_gap_s = gap;
    EXPECT_TRUE(Validate(options).has_value()) << gap;
  }
  ReplayScheduleOptions fastest;
  fastest.speed = 0.0;
  fastest.max_gap_s = 0.5;
  EXPECT_FALSE(Validate(fastest).has_value());
}

TEST(SenderSlotsTest, EachSourceGetsItsOwnSlotUntilTheLastIsShared) {
  SenderSlots slots(3);
  EXPECT_EQ(slots.SlotFor("10.0.0.1:5000"), 0u);
  EXPECT_EQ(slots.SlotFor("10.0.0.2:5000"), 1u);
  EXPECT_EQ(slots.SlotFor("10.0.0.1:5000"), 0u);
  EXPECT_EQ(slots.SlotFor("tracker:s3"), 2u);
  EXPECT_EQ(slots.SlotFor("tracker:s4"), 2u);
  EXPECT_EQ(slots.SlotFor("tracker:s5"), 2u);
  EXPECT_EQ(slots.SlotFor("10.0.0.2:5000"), 1u);
  EXPECT_EQ(slots.slots_used(), 3u);
  EXPECT_EQ(slots.shared_datagrams(), 2u);
}

TEST(SenderSlotsTest, TheDefaultCapacityIs256) {
  SenderSlots slots;
  for (int i = 0; i < 300; ++i) {
    const std::size_t slot = slots.SlotFor("10.0.1." + std::to_string(i) + ":1");
    EXPECT_EQ(slot, static_cast<std::size_t>(std::min(i, 255))) << i;
  }
  EXPECT_EQ(slots.slots_used(), kMaxReplaySenders);
}

}  // namespace
}  // namespace lrfnet::tools
