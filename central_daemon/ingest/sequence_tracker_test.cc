#include "central_daemon/ingest/sequence_tracker.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <set>
#include <vector>

namespace lrfnet::daemon {
namespace {

using V = SequenceVerdict;

TEST(SequenceTrackerTest, SkippedNumbersAreLostOnceTheWindowHasPassedThem) {
  SequenceTracker t(4, 1000);
  EXPECT_EQ(t.Observe(1, 0), V::kFirst);
  EXPECT_EQ(t.Observe(1, 1), V::kInOrder);
  EXPECT_EQ(t.Observe(1, 5), V::kInOrder);  // 2, 3, 4 may still arrive
  EXPECT_EQ(t.counters().lost, 0u);
  EXPECT_EQ(t.Observe(1, 6), V::kInOrder);  // 2 is out of the window now
  EXPECT_EQ(t.counters().lost, 1u);
  EXPECT_EQ(t.Observe(1, 9), V::kInOrder);  // 3 and 4 too; 7 and 8 may still arrive
  EXPECT_EQ(t.counters().lost, 3u);
  EXPECT_EQ(t.counters().received, 5u);
  EXPECT_EQ(t.highest(), 9u);
}

TEST(SequenceTrackerTest, ALateArrivalInsideTheWindowIsNeverLost) {
  SequenceTracker t(4, 1000);
  t.Observe(1, 10);
  t.Observe(1, 13);
  EXPECT_EQ(t.Observe(1, 12), V::kReordered);
  EXPECT_EQ(t.Observe(1, 11), V::kReordered);
  t.Observe(1, 30);
  EXPECT_EQ(t.counters().lost, 13u);  // 14 to 26; 27 to 29 may still arrive
  EXPECT_EQ(t.counters().reordered, 2u);
  EXPECT_EQ(t.counters().received, 5u);
  EXPECT_EQ(t.highest(), 30u);
}

TEST(SequenceTrackerTest, DuplicatesAndArrivalsOlderThanTheWindowAreDropped) {
  SequenceTracker t(64, 1000);
  t.Observe(1, 0);
  t.Observe(1, 1);
  EXPECT_EQ(t.Observe(1, 1), V::kDuplicate);
  EXPECT_EQ(t.Observe(1, 0), V::kDuplicate);
  t.Observe(1, 100);  // 2..99 skipped, 2..36 out of the window
  EXPECT_EQ(t.counters().lost, 35u);
  EXPECT_EQ(t.Observe(1, 36), V::kDuplicate);  // 100 - 36 = 64: outside the window, stays lost
  EXPECT_EQ(t.Observe(1, 37), V::kReordered);  // inside
  EXPECT_EQ(t.Observe(1, 37), V::kDuplicate);
  EXPECT_EQ(t.counters().duplicates, 4u);
  EXPECT_EQ(t.counters().lost, 35u);
  EXPECT_EQ(t.counters().received, 4u);
  t.Observe(1, 200);
  EXPECT_EQ(t.counters().lost, 97u + 100u - 64u);  // 2..99 but 37, and 101..136
}

TEST(SequenceTrackerTest, ArrivalsBeforeTheFirstSeenAreReorderedNotRecoveredLoss) {
  SequenceTracker t(64, 1000);
  t.Observe(1, 50);  // the daemon started while the tracker was running
  EXPECT_EQ(t.Observe(1, 49), V::kReordered);
  EXPECT_EQ(t.Observe(1, 49), V::kDuplicate);
  EXPECT_EQ(t.counters().lost, 0u);
}

TEST(SequenceTrackerTest, ANewSessionRestartsTheState) {
  SequenceTracker t(64, 1000);
  t.Observe(1, 0);
  t.Observe(1, 1);
  t.Observe(1, 4);
  EXPECT_EQ(t.Observe(2, 0), V::kRestart);
  EXPECT_EQ(t.session_id(), 2u);
  EXPECT_EQ(t.Observe(2, 1), V::kInOrder);
  EXPECT_EQ(t.Observe(2, 0), V::kDuplicate);
  EXPECT_EQ(t.counters().restarts, 1u);
  EXPECT_EQ(t.counters().lost, 2u);  // 2 and 3 of the first session can no longer arrive
}

TEST(SequenceTrackerTest, AJumpBeyondMaxJumpIsAResetWithoutLoss) {
  SequenceTracker t(64, 1000);
  t.Observe(1, 0);
  EXPECT_EQ(t.Observe(1, 1000), V::kInOrder);  // exactly max_jump ahead: a gap
  EXPECT_EQ(t.counters().lost, 999u - 63u);    // 937 to 999 may still arrive
  EXPECT_EQ(t.Observe(1, 2001), V::kReset);
  EXPECT_EQ(t.Observe(1, 2002), V::kInOrder);
  EXPECT_EQ(t.counters().resets, 1u);
  EXPECT_EQ(t.counters().lost, 999u);  // a reset ends the wait for them
  // Far behind within the session is a reset too (the counter started over).
  EXPECT_EQ(t.Observe(1, 3), V::kReset);
  EXPECT_EQ(t.Observe(1, 4), V::kInOrder);
  EXPECT_EQ(t.counters().resets, 2u);
}

TEST(SequenceTrackerTest, WrapsAroundTheTopOfTheSequenceSpace) {
  SequenceTracker t(64, 1000);
  const std::uint64_t top = ~std::uint64_t{0};
  t.Observe(1, top - 3);
  EXPECT_EQ(t.Observe(1, top), V::kInOrder);
  EXPECT_EQ(t.Observe(1, top - 1), V::kReordered);
  EXPECT_EQ(t.Observe(1, top), V::kDuplicate);
  EXPECT_EQ(t.counters().lost, 0u);  // top - 2 is still inside the window
}

// A state that starts at the largest sequence number (a hostile or corrupt datagram's): counting
// what it misses ends at once (it ran over the whole 64-bit range before) and finds nothing.
TEST(SequenceTrackerTest, AStateStartedAtTheTopOfTheSequenceSpaceMissesNothing) {
  const std::uint64_t top = ~std::uint64_t{0};
  SequenceTracker t(64, 1000);
  EXPECT_EQ(t.Observe(1, top), V::kFirst);
  EXPECT_EQ(t.counters().lost, 0u);
  EXPECT_EQ(t.Observe(1, top - 2), V::kReordered);
  EXPECT_EQ(t.counters().lost, 0u);
  EXPECT_EQ(t.counters().received, 2u);
  SequenceTracker u(4, 1000);
  u.Observe(1, top - 10);
  EXPECT_EQ(u.Observe(1, top), V::kInOrder);  // top - 9 to top - 4 left the window: lost
  EXPECT_EQ(u.counters().lost, 6u);
}

// Reference model: the documented rules over the set of every accepted number of the state.
struct Model {
  Model(std::uint64_t w, std::uint64_t j) : window(w), max_jump(j) {}
  std::uint64_t window, max_jump;
  bool started = false;
  std::uint64_t base = 0, highest = 0;
  std::uint64_t lost_of_earlier_states = 0;
  std::set<std::uint64_t> received;

  // Skipped numbers of the current state not received: (base, highest) minus received; with
  // `window`, only those that left it.
  std::uint64_t MissingInState(std::uint64_t w) const {
    std::uint64_t n = 0;
    for (std::uint64_t s = base + 1; s < highest; ++s) {
      n += (received.count(s) == 0 && highest - s >= w) ? 1 : 0;
    }
    return n;
  }
  std::uint64_t Lost() const { return lost_of_earlier_states + MissingInState(window); }
  void Start(std::uint64_t s) {
    if (started) lost_of_earlier_states += MissingInState(0);
    started = true;
    base = highest = s;
    received = {s};
  }
  V Observe(std::uint64_t s) {
    if (!started) {
      Start(s);
      return V::kFirst;
    }
    if (s > highest) {
      if (s - highest > max_jump) {
        Start(s);
        return V::kReset;
      }
      highest = s;
      received.insert(s);
      return V::kInOrder;
    }
    if (highest - s > max_jump) {
      Start(s);
      return V::kReset;
    }
    if (highest - s >= window || received.count(s)) return V::kDuplicate;
    received.insert(s);
    return V::kReordered;
  }
};

TEST(SequenceTrackerTest, MatchesTheReferenceModelOnRandomReorderingLossAndDuplicates) {
  std::mt19937_64 rng(2024);
  for (const std::uint32_t window : {1u, 7u, 64u, 100u, 1024u}) {
    SCOPED_TRACE(window);
    SequenceTracker t(window, 5000);
    Model m(window, 5000);
    std::uint64_t next = 1000;
    constexpr int kSteps = 5000;
    for (int i = 0; i < kSteps; ++i) {
      std::uint64_t s = 0;
      const auto dice = rng() % 100;
      if (dice < 60) {
        s = next++;
      } else if (dice < 70) {
        next += 1 + rng() % 5;  // a gap
        s = next++;
      } else if (dice < 95) {  // late, duplicate or older than the window
        s = next - 1 - std::min<std::uint64_t>(next - 1, rng() % (2 * window + 2));
      } else if (dice < 96) {
        next += 6000;  // beyond max_jump
        s = next++;
      } else {
        s = next + rng() % 3;
      }
      const V expected = m.Observe(s);
      ASSERT_EQ(ToString(t.Observe(7, s)), std::string(ToString(expected))) << "step " << i;
      if (i % 97 == 0) {
        ASSERT_EQ(t.counters().lost, m.Lost()) << "step " << i;
      }
      next = std::max(next, m.highest + 1);
    }
    EXPECT_EQ(t.counters().lost, m.Lost());
    EXPECT_EQ(t.counters().received + t.counters().duplicates, static_cast<std::uint64_t>(kSteps));
    if (window > 1) {
      EXPECT_GT(t.counters().reordered, 0u);
    }
    EXPECT_GT(t.counters().resets, 0u);
  }
}

}  // namespace
}  // namespace lrfnet::daemon
