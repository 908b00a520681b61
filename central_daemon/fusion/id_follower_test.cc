#include "central_daemon/fusion/id_follower.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace lrfnet::fusion {
namespace {

constexpr common::UtcNs kT0 = 1'700'000'000'000'000'000;
constexpr common::DurationNs kStepNs = 100'000'000;  // 0.1 s

EndedFusedTrack TimedOut(std::uint64_t id, common::UtcNs at_ns = kT0) {
  return {id, at_ns, FusedEndReason::kTimedOut, 0};
}
EndedFusedTrack Merged(std::uint64_t id, std::uint64_t into, common::UtcNs at_ns = kT0) {
  return {id, at_ns, FusedEndReason::kMerged, into};
}

// A compact view of one event: "3 present", "3 held hidden", "3 merged 1", "3 ended timed_out".
std::string Describe(const IdEvent& e) {
  std::string s = std::to_string(e.id) + " " + ToString(e.kind);
  if (e.kind == IdEventKind::kPresent && e.returned) s += " returned";
  if (e.kind == IdEventKind::kHeld) s += e.hidden ? " hidden" : " absent";
  if (e.kind == IdEventKind::kMerged) s += " " + std::to_string(e.survivor);
  if (e.kind == IdEventKind::kEnded) s += std::string(" ") + ToString(e.reason);
  return s;
}

// Periods of 0.1 s fed from id lists.
class Feed {
 public:
  explicit Feed(IdFollowerOptions options = {}) : follower_(options) {}
  std::vector<std::string> Step(std::vector<std::uint64_t> present,
                                std::vector<std::uint64_t> hidden = {},
                                std::vector<EndedFusedTrack> ended = {},
                                std::uint64_t generation = 0) {
    now_ns_ += kStepNs;
    last_ = follower_.Update(present, hidden, ended, generation, now_ns_);
    std::vector<std::string> out;
    for (const IdEvent& e : last_) out.push_back(Describe(e));
    return out;
  }
  const IdEvent& Event(std::size_t i) const { return last_.at(i); }
  IdFollower& follower() { return follower_; }
  common::UtcNs now_ns() const { return now_ns_; }

 private:
  IdFollower follower_;
  common::UtcNs now_ns_ = kT0;
  std::vector<IdEvent> last_;
};

using Events = std::vector<std::string>;

TEST(IdFollowerTest, PresentHeldHiddenAndBack) {
  Feed f;
  EXPECT_EQ(f.Step({1, 2}), (Events{"1 present", "2 present"}));
  EXPECT_EQ(f.Step({2}, {1}), (Events{"2 present", "1 held hidden"}));
  EXPECT_TRUE(f.Event(1).newly_held);
  EXPECT_FALSE(f.Event(1).was_held);
  EXPECT_EQ(f.Event(1).held_since_ns, f.now_ns());
  const common::UtcNs since_ns = f.now_ns();
  for (int i = 0; i < 100; ++i) {  // 10 s hidden: held as long as the fusion keeps it
    EXPECT_EQ(f.Step({2}, {1}), (Events{"2 present", "1 held hidden"}));
    EXPECT_FALSE(f.Event(1).newly_held);
    EXPECT_TRUE(f.Event(1).was_held);
    EXPECT_EQ(f.Event(1).held_since_ns, since_ns);
  }
  EXPECT_EQ(f.Step({1, 2}), (Events{"1 present returned", "2 present"}));
  EXPECT_EQ(f.Event(0).index, 0u);
  EXPECT_EQ(f.Step({1, 2}), (Events{"1 present", "2 present"}));
  EXPECT_EQ(f.follower().counters().held, 1u);
  EXPECT_EQ(f.follower().counters().returned, 1u);
  EXPECT_EQ(f.follower().counters().followed, 2u);
}

// An id the fusion says nothing of is held for absent_hold_s (1 s: ten periods after the first
// it was absent from), then ends as of then; with 0 at once.
TEST(IdFollowerTest, AnAbsentIdTheFusionSaysNothingOfIsHeldForTheHold) {
  Feed f(IdFollowerOptions{1.0, 64});
  f.Step({7});
  EXPECT_EQ(f.Step({}), (Events{"7 held absent"}));
  const common::UtcNs since_ns = f.now_ns();
  for (int i = 0; i < 9; ++i) EXPECT_EQ(f.Step({}), (Events{"7 held absent"}));
  EXPECT_EQ(f.Step({}), (Events{"7 ended hold_expired"}));
  EXPECT_EQ(f.Event(0).held_since_ns, since_ns);
  EXPECT_EQ(f.Event(0).ended_ns, f.now_ns());
  EXPECT_TRUE(f.Event(0).was_held);
  EXPECT_EQ(f.Step({}), Events{});
  EXPECT_FALSE(f.follower().Known(7));

  Feed at_once(IdFollowerOptions{0.0, 64});
  at_once.Step({7});
  EXPECT_EQ(at_once.Step({}), (Events{"7 ended hold_expired"}));
  EXPECT_FALSE(at_once.Event(0).was_held);  // never held at the end of a period
  EXPECT_EQ(at_once.follower().counters().hold_expired, 1u);
}

TEST(IdFollowerTest, ATimedOutIdEndsAtOnceWithTheFusionsTimeAndOnlyOnce) {
  Feed f;
  f.Step({3});
  f.Step({}, {3});
  const common::UtcNs since_ns = f.now_ns();
  const EndedFusedTrack end = TimedOut(3, kT0 + 123);
  EXPECT_EQ(f.Step({}, {}, {end}), (Events{"3 ended timed_out"}));
  EXPECT_EQ(f.Event(0).ended_ns, kT0 + 123);
  EXPECT_TRUE(f.Event(0).was_held);
  EXPECT_EQ(f.Event(0).held_since_ns, since_ns);
  EXPECT_EQ(f.Step({}, {}, {end}), Events{});  // the end listed again: nothing
  EXPECT_EQ(f.follower().counters().timed_out, 1u);
}

TEST(IdFollowerTest, AMergedIdGoesOnAsItsSurvivor) {
  Feed f;
  f.Step({1, 2});
  EXPECT_EQ(f.Step({1}, {}, {Merged(2, 1, kT0 + 5)}), (Events{"2 merged 1", "1 present"}));
  EXPECT_TRUE(f.Event(0).survivor_known);
  EXPECT_FALSE(f.Event(0).survivor_held);
  EXPECT_FALSE(f.Event(0).was_held);
  EXPECT_EQ(f.Event(0).ended_ns, kT0 + 5);
  EXPECT_EQ(f.follower().counters().merged, 1u);
  // A hidden survivor: the merged id was present, the survivor held.
  Feed g;
  g.Step({1});
  g.Step({}, {1});
  g.Step({2}, {1});
  EXPECT_EQ(g.Step({1}, {}, {Merged(2, 1)}), (Events{"2 merged 1", "1 present returned"}));
  EXPECT_TRUE(g.Event(0).survivor_known);
  EXPECT_TRUE(g.Event(0).survivor_held);
  EXPECT_FALSE(g.Event(0).was_held);
}

// a -> b -> c reported in one output: both go on as c. Over several outputs: each when listed,
// the ends listed again later change nothing.
TEST(IdFollowerTest, MergeChainsInOneOutputAndOverSeveral) {
  Feed one;
  one.Step({1, 2, 3});
  EXPECT_EQ(one.Step({1}, {}, {Merged(3, 2), Merged(2, 1)}),
            (Events{"3 merged 1", "2 merged 1", "1 present"}));
  Feed several;
  several.Step({1, 2, 3});
  EXPECT_EQ(several.Step({1, 2}, {}, {Merged(3, 2)}),
            (Events{"3 merged 2", "1 present", "2 present"}));
  EXPECT_EQ(several.Step({1}, {}, {Merged(3, 2), Merged(2, 1)}),
            (Events{"2 merged 1", "1 present"}));
  EXPECT_EQ(several.Step({1}, {}, {Merged(3, 2), Merged(2, 1)}), (Events{"1 present"}));
  // The walk stops at an id in the tracks (the fusion lists a merge of it, but it is there).
  Feed stop;
  stop.Step({1, 2, 3});
  EXPECT_EQ(stop.Step({1, 2}, {}, {Merged(3, 2), Merged(2, 1)}),
            (Events{"3 merged 2", "1 present", "2 present"}));
}

// The consumer never saw the survivor (it was hidden from before the consumer's first period):
// the survivor takes the merged id's place, its hold too, and is known from then on.
TEST(IdFollowerTest, AMergeIntoASurvivorTheConsumerNeverSaw) {
  Feed f;
  f.Step({2}, {1});
  EXPECT_FALSE(f.follower().Known(1));
  EXPECT_EQ(f.Step({}, {1}, {Merged(2, 1)}), (Events{"2 merged 1", "1 held hidden"}));
  EXPECT_FALSE(f.Event(0).survivor_known);
  EXPECT_TRUE(f.Event(1).newly_held);
  EXPECT_EQ(f.Step({1}, {}, {Merged(2, 1)}), (Events{"1 present returned"}));
  EXPECT_EQ(f.follower().counters().taken_over, 1u);
  EXPECT_EQ(f.follower().counters().merged, 1u);
  // Present at once: it goes on, it did not come back.
  Feed g;
  g.Step({2});
  EXPECT_EQ(g.Step({1}, {}, {Merged(2, 1)}), (Events{"2 merged 1", "1 present"}));
  // The merged id was held (absent without a word): the survivor inherits its hold's start.
  Feed h(IdFollowerOptions{1.0, 64});
  h.Step({2});
  h.Step({});
  const common::UtcNs since_ns = h.now_ns();
  EXPECT_EQ(h.Step({}, {}, {Merged(2, 1)}), (Events{"2 merged 1", "1 held absent"}));
  EXPECT_TRUE(h.Event(0).was_held);
  EXPECT_EQ(h.Event(1).held_since_ns, since_ns);
  for (int i = 0; i < 8; ++i) h.Step({});
  EXPECT_EQ(h.Step({}), (Events{"1 ended hold_expired"}));  // 1 s after 2 was absent first
}

TEST(IdFollowerTest, AFusionRestartEndsEveryKnownId) {
  Feed f;
  f.Step({1, 2}, {}, {}, 0);
  f.Step({2}, {1}, {}, 0);
  EXPECT_EQ(f.Step({5}, {}, {}, 1),
            (Events{"1 ended fusion_restarted", "2 ended fusion_restarted", "5 present"}));
  EXPECT_TRUE(f.Event(0).was_held);
  EXPECT_FALSE(f.Event(1).was_held);
  EXPECT_EQ(f.Event(0).ended_ns, f.now_ns());
  EXPECT_EQ(f.follower().counters().restarted, 2u);
  const std::vector<IdEvent>& all = f.follower().EndAll(f.now_ns());
  ASSERT_EQ(all.size(), 1u);
  EXPECT_EQ(Describe(all[0]), "5 ended fusion_restarted");
  EXPECT_EQ(f.follower().size(), 0u);
}

// Input no fuser gives: an id merged into itself, a cycle, an end of an id never seen,
// duplicate ids, a chain longer than max_merge_hops, a survivor that ended before it.
TEST(IdFollowerTest, HostileInputIsBoundedAndCounted) {
  Feed f;
  f.Step({1, 2, 3});
  EXPECT_EQ(
      f.Step({}, {}, {Merged(1, 1), Merged(2, 3), Merged(3, 2), TimedOut(9), Merged(8, 1)}),
      (Events{"1 ended merge_unresolved", "2 ended merge_unresolved", "3 ended merge_unresolved"}));
  EXPECT_EQ(f.follower().counters().merge_cycles, 3u);
  EXPECT_EQ(f.follower().size(), 0u);
  // A cycle with a member in the tracks goes on as that member.
  Feed g;
  g.Step({1, 2});
  EXPECT_EQ(g.Step({2}, {}, {Merged(1, 2), Merged(2, 1)}), (Events{"1 merged 2", "2 present"}));
  // Duplicates: the first counts; an id in the tracks that is also listed hidden or ended stays.
  Feed d;
  EXPECT_EQ(d.Step({4, 5, 4}, {5}, {TimedOut(5)}), (Events{"4 present", "5 present"}));
  EXPECT_EQ(d.Step({4, 5, 4}, {5}, {TimedOut(5)}), (Events{"4 present", "5 present"}));
  EXPECT_EQ(d.follower().counters().duplicates, 2u);
  // A chain of 3 merges with max_merge_hops 2: cut.
  Feed c(IdFollowerOptions{1.5, 2});
  c.Step({1, 2, 3, 4});
  EXPECT_EQ(c.Step({4}, {}, {Merged(1, 2), Merged(2, 3), Merged(3, 4)}),
            (Events{"1 ended merge_unresolved", "2 merged 4", "3 merged 4", "4 present"}));
  EXPECT_EQ(c.follower().counters().merge_chains_cut, 1u);
  // A survivor that timed out earlier in the same output takes nothing on.
  Feed t;
  t.Step({1, 2});
  EXPECT_EQ(t.Step({}, {}, {TimedOut(1), Merged(2, 1)}),
            (Events{"1 ended timed_out", "2 ended merge_unresolved"}));
  EXPECT_FALSE(t.follower().Known(1));
  EXPECT_EQ(t.follower().counters().merges_into_ended, 1u);
}

// A merge into an id that ended earlier in the same output is unresolved whether the consumer
// knew that id or not: an ended id never takes an object on.
TEST(IdFollowerTest, AMergeIntoAnIdEndedEarlierIsUnresolvedKnownOrNot) {
  // The consumer never knew the survivor (it was hidden from before the consumer's first
  // period): 1 ended, nothing goes on as it.
  Feed u;
  u.Step({2}, {1});
  EXPECT_EQ(u.Step({}, {}, {TimedOut(1), Merged(2, 1)}), (Events{"2 ended merge_unresolved"}));
  EXPECT_FALSE(u.follower().Known(1));
  EXPECT_EQ(u.follower().counters().taken_over, 0u);
  EXPECT_EQ(u.follower().counters().merges_into_ended, 1u);
  // Through a chain: 3 -> 2 -> 1 with 1 (unknown) timed out before; 2 (unknown) merged after.
  Feed w;
  w.Step({3}, {1, 2});
  EXPECT_EQ(w.Step({}, {}, {TimedOut(1), Merged(3, 2), Merged(2, 1)}),
            (Events{"3 ended merge_unresolved"}));
  EXPECT_EQ(w.follower().size(), 0u);
  // An id that ends after the merge into it (later in the list) took the object on first.
  Feed v;
  v.Step({2}, {1});
  EXPECT_EQ(v.Step({}, {}, {Merged(2, 1), TimedOut(1)}),
            (Events{"2 merged 1", "1 ended timed_out"}));
}

// A clock stepped back: a hold that began after the period's time is over.
TEST(IdFollowerTest, AHoldFromAfterNowIsOver) {
  IdFollower f;
  f.Update(std::vector<std::uint64_t>{1}, {}, {}, 0, kT0 + 10 * kStepNs);
  f.Update(std::vector<std::uint64_t>{}, {}, {}, 0, kT0 + 11 * kStepNs);
  const std::vector<IdEvent>& events = f.Update(std::vector<std::uint64_t>{}, {}, {}, 0, kT0);
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(Describe(events[0]), "1 ended hold_expired");
}

TEST(IdFollowerTest, AFusionOutputGivesTheTracks) {
  FusionOutput output;
  output.stamp_ns = kT0;
  output.tracks.resize(2);
  output.tracks[0].id = 4;
  output.tracks[0].x_m = 1.5;
  output.tracks[1].id = 2;
  output.hidden.push_back({3, kT0, 0.0, 0.0, "s1"});
  IdFollower f;
  f.Update(FusionOutput{output.stamp_ns, {output.tracks[1]}, {}, {}}, 0, kT0);
  f.Update(FusionOutput{output.stamp_ns, {}, {output.hidden}, {}}, 0, kT0);  // 2 held
  const std::vector<IdEvent>& events = f.Update(output, 0, kT0 + kStepNs);
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(Describe(events[0]), "4 present");
  ASSERT_NE(events[0].track, nullptr);
  EXPECT_EQ(events[0].track, &output.tracks[0]);
  EXPECT_EQ(Describe(events[1]), "2 present returned");
  EXPECT_EQ(events[1].track, &output.tracks[1]);
}

TEST(IdFollowerTest, ValidateChecksTheOptions) {
  EXPECT_EQ(Validate(IdFollowerOptions{}), std::nullopt);
  EXPECT_NE(Validate(IdFollowerOptions{-1.0, 64}), std::nullopt);
  EXPECT_NE(Validate(IdFollowerOptions{1.0, 0}), std::nullopt);
}

}  // namespace
}  // namespace lrfnet::fusion
