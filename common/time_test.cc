#include "common/time.h"

#include <gtest/gtest.h>

namespace lrfnet::common {
namespace {

TEST(TickUnwrapperTest, UnwrapsAcrossTheUint32Wrap) {
  TickUnwrapper u;
  EXPECT_EQ(u.Unwrap(0xFFFFFF00u).ticks_us, 0xFFFFFF00ll);
  const auto r = u.Unwrap(0x00000100u);  // 512 µs later, after the wrap
  EXPECT_FALSE(r.restarted);
  EXPECT_EQ(r.ticks_us, 0x100000100ll);
  EXPECT_EQ(u.Unwrap(0x00001000u).ticks_us, 0x100001000ll);
}

TEST(TickUnwrapperTest, ManyWrapsStayMonotonic) {
  TickUnwrapper u;
  std::uint32_t tick = 123;
  std::int64_t last = -1;
  for (int i = 0; i < 10000; ++i) {
    tick += 2'000'000u;  // 2 s steps: 10000 steps wrap ~4.6 times
    const auto r = u.Unwrap(tick);
    ASSERT_GT(r.ticks_us, last);
    last = r.ticks_us;
  }
  EXPECT_EQ(last, 123ll + 10000ll * 2'000'000ll);
}

TEST(TickUnwrapperTest, LargeBackwardStepIsARestart) {
  TickUnwrapper u;
  u.Unwrap(600'000'000u);
  const auto r = u.Unwrap(5'000u);  // device rebooted
  EXPECT_TRUE(r.restarted);
  EXPECT_GT(r.ticks_us, 600'000'000ll);
  EXPECT_EQ(u.restarts(), 1u);
  // Small jitter backwards is not a restart.
  const auto j = u.Unwrap(4'000u);
  EXPECT_FALSE(j.restarted);
  EXPECT_EQ(j.ticks_us, r.ticks_us - 1000);
}

}  // namespace
}  // namespace lrfnet::common
