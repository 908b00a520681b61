#include "firmware_tracker/io/system_clock.h"

#include <gtest/gtest.h>
#include <sys/timex.h>

namespace lrfnet::io {
namespace {

TEST(SystemClockTest, KernelUnsyncStatesAreUnsynchronized) {
  // A fresh kernel without an NTP daemon: TIME_ERROR, STA_UNSYNC, 16 s error estimates.
  ClockStatus s = ClassifyClock(TIME_ERROR, STA_UNSYNC, 16'000'000, 16'000'000);
  EXPECT_EQ(s.sync, ClockSync::kUnsynchronized);
  EXPECT_DOUBLE_EQ(s.esterror_s, 16.0);
  EXPECT_DOUBLE_EQ(s.maxerror_s, 16.0);
  EXPECT_EQ(s.kernel_state, TIME_ERROR);
  // Either signal alone is enough.
  EXPECT_EQ(ClassifyClock(TIME_OK, STA_UNSYNC, 100, 1000).sync, ClockSync::kUnsynchronized);
  EXPECT_EQ(ClassifyClock(TIME_ERROR, STA_PLL, 100, 1000).sync, ClockSync::kUnsynchronized);
}

TEST(SystemClockTest, DisciplinedClockWithinTheBoundIsSynchronized) {
  const ClockStatus s = ClassifyClock(TIME_OK, STA_PLL, 250, 12'000);
  EXPECT_EQ(s.sync, ClockSync::kSynchronized);
  EXPECT_DOUBLE_EQ(s.esterror_s, 250e-6);
  EXPECT_DOUBLE_EQ(s.maxerror_s, 12e-3);
  // Leap-second states are still synchronised.
  EXPECT_EQ(ClassifyClock(TIME_INS, STA_PLL | STA_INS, 250, 12'000).sync, ClockSync::kSynchronized);
  // An estimate above the bound is not.
  ClockStatusOptions strict;
  strict.max_esterror_s = 100e-6;
  EXPECT_EQ(ClassifyClock(TIME_OK, STA_PLL, 250, 12'000, strict).sync, ClockSync::kUnsynchronized);
  EXPECT_TRUE(Validate(ClockStatusOptions{}) == std::nullopt);
  strict.max_esterror_s = 0.0;
  EXPECT_TRUE(Validate(strict).has_value());
}

TEST(SystemClockTest, FailedKernelCallIsUnknown) {
  const ClockStatus s = ClassifyClock(-1, 0, 0, 0);
  EXPECT_EQ(s.sync, ClockSync::kUnknown);
  EXPECT_STREQ(ToString(s.sync), "unknown");
  EXPECT_STREQ(ToString(ClockSync::kReplay), "replay");
}

TEST(SystemClockTest, ReadsTheKernelAndTheRealtimeClock) {
  const ClockStatus s = ReadClockStatus();
  EXPECT_GE(s.kernel_state, 0) << "ntp_adjtime failed, errno " << s.error_number;
  EXPECT_NE(s.sync, ClockSync::kUnknown);
  EXPECT_NE(s.sync, ClockSync::kReplay);
  const common::UtcNs a = NowUtcNs();
  const common::UtcNs b = NowUtcNs();
  EXPECT_GT(a, 1'600'000'000 * common::kNsPerS);  // after 2020
  EXPECT_GE(b, a);
}

}  // namespace
}  // namespace lrfnet::io
