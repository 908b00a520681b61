#include "common/fixed_capacity.h"

#include <gtest/gtest.h>

namespace lrfnet::common {
namespace {

TEST(FixedVectorTest, OverflowIsRefusedAndCounted) {
  FixedVector<int, 3> v;
  EXPECT_TRUE(v.push_back(1));
  EXPECT_TRUE(v.push_back(2));
  EXPECT_TRUE(v.push_back(3));
  EXPECT_FALSE(v.push_back(4));
  EXPECT_EQ(v.size(), 3u);
  EXPECT_EQ(v.overflow_count(), 1u);
  EXPECT_EQ(v.emplace_slot(), nullptr);
  EXPECT_EQ(v.overflow_count(), 2u);
  EXPECT_FALSE(v.resize(4));
  v.swap_remove(0);
  EXPECT_EQ(v.size(), 2u);
  EXPECT_EQ(v[0], 3);
  int sum = 0;
  for (int x : v) sum += x;
  EXPECT_EQ(sum, 5);
}

TEST(RingBufferTest, KeepsNewestAndCountsDrops) {
  RingBuffer<int, 3> r;
  for (int i = 1; i <= 5; ++i) r.push_back(i);
  EXPECT_EQ(r.size(), 3u);
  EXPECT_EQ(r.dropped_count(), 2u);
  EXPECT_EQ(r.front(), 3);
  EXPECT_EQ(r.back(), 5);
  r.pop_front();
  EXPECT_EQ(r[0], 4);
}

}  // namespace
}  // namespace lrfnet::common
