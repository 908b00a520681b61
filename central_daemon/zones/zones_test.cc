#include "central_daemon/zones/zones.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace lrfnet::zones {
namespace {

constexpr common::UtcNs kT0 = 1'700'000'000'000'000'000;
constexpr common::DurationNs kStepNs = 100'000'000;  // 10 Hz, as the fusion publishes

Zone Line(const char* name, Point a, Point b) { return Zone{name, ZoneKind::kLine, {a, b}}; }
Zone Square(const char* name, double x0, double y0, double side) {
  return Zone{name,
              ZoneKind::kPolygon,
              {{x0, y0}, {x0 + side, y0}, {x0 + side, y0 + side}, {x0, y0 + side}}};
}

// Feeds one track along a list of positions, one update each, and returns the counter.
class Walk {
 public:
  // absent_hold_s 0: an absent id is gone at once (the tests of crossings and dwell).
  Walk(std::vector<Zone> zones, double hysteresis_m = 0.3, double absent_hold_s = 0.0)
      : counter_(std::move(zones), ZoneOptions{hysteresis_m, absent_hold_s}) {}
  void To(std::uint64_t id, Point p, bool measured = true) {
    const ZoneTrack t{id, p.x_m, p.y_m, measured};
    counter_.Update(std::span<const ZoneTrack>(&t, 1), Now());
  }
  // Straight from a to b in steps of step_m (both ends included).
  void Straight(std::uint64_t id, Point a, Point b, double step_m = 0.12) {
    const double len = std::hypot(b.x_m - a.x_m, b.y_m - a.y_m);
    const int n = std::max(1, static_cast<int>(std::ceil(len / step_m)));
    for (int i = 0; i <= n; ++i) {
      const double f = static_cast<double>(i) / n;
      To(id, {a.x_m + f * (b.x_m - a.x_m), a.y_m + f * (b.y_m - a.y_m)});
    }
  }
  void Nothing() { counter_.Update({}, Now()); }
  ZoneState State(std::size_t i = 0) const { return counter_.States().at(i); }
  ZoneCounter& counter() { return counter_; }
  double elapsed_s() const { return common::NsToSeconds(now_ns_ - kT0); }

 private:
  common::UtcNs Now() { return now_ns_ += kStepNs; }
  ZoneCounter counter_;
  common::UtcNs now_ns_ = kT0;
};

// The line runs along +x; its left side (inbound side) is +y.
TEST(ZonesTest, LineCountsEachCrossingOnceInItsDirection) {
  Walk w({Line("door", {-1, 0}, {1, 0})});
  w.Straight(1, {0, -2}, {0, 2});
  EXPECT_EQ(w.State().inbound, 1u);
  EXPECT_EQ(w.State().outbound, 0u);
  w.Straight(1, {0, 2}, {0.5, -2});
  EXPECT_EQ(w.State().inbound, 1u);
  EXPECT_EQ(w.State().outbound, 1u);
  // A second person crossing inbound at the other end of the door.
  w.Straight(2, {-0.9, -1}, {-0.9, 1});
  EXPECT_EQ(w.State().inbound, 2u);
  EXPECT_EQ(w.State().outbound, 1u);
}

TEST(ZonesTest, StandingOnTheLineIsCountedOnceWhenCrossingAndNeverWhenTurningBack) {
  Walk w({Line("door", {-1, 0}, {1, 0})});
  w.Straight(1, {0, -2}, {0, -0.05});
  // Stands on the line for 20 s, swaying 25 cm across it (inside the band).
  for (int i = 0; i < 200; ++i) w.To(1, {0.02 * (i % 3), (i % 2 == 0) ? 0.25 : -0.25});
  EXPECT_EQ(w.State().inbound + w.State().outbound, 0u);
  EXPECT_EQ(w.State().present_ids, std::vector<std::uint64_t>{1});
  w.Straight(1, {0, 0.1}, {0, 2});
  EXPECT_EQ(w.State().inbound, 1u);
  EXPECT_EQ(w.State().outbound, 0u);
  EXPECT_TRUE(w.State().present_ids.empty());
  EXPECT_EQ(w.State().dwells_completed, 1u);
  EXPECT_GT(w.State().dwell_total_s, 20.0);

  // Onto the line and back the way it came: no crossing.
  w.Straight(1, {0, 2}, {0, 0.1});
  for (int i = 0; i < 30; ++i) w.To(1, {0, (i % 2 == 0) ? -0.2 : 0.2});
  w.Straight(1, {0, 0.1}, {0, 2});
  EXPECT_EQ(w.State().inbound, 1u);
  EXPECT_EQ(w.State().outbound, 0u);
}

TEST(ZonesTest, LineIgnoresWalkingAroundItsEnds) {
  Walk w({Line("door", {-1, 0}, {1, 0})});
  w.Straight(1, {3, -2}, {3, 2});    // beyond B
  w.Straight(1, {3, 2}, {-3, 2});    // along the left side
  w.Straight(1, {-3, 2}, {-3, -2});  // beyond A
  EXPECT_EQ(w.State().inbound + w.State().outbound, 0u);
  // A jump straight across in one update (a gap in the fused track) still counts.
  w.To(2, {0.3, -1.5});
  w.To(2, {0.2, 1.5});
  EXPECT_EQ(w.State().inbound, 1u);
}

TEST(ZonesTest, TracksSeenFirstInsideTheBandCountOnlyWhenTheyLeaveAcross) {
  Walk w({Line("door", {-1, 0}, {1, 0})});
  w.Straight(1, {0, 0.1}, {0, 2});  // appears on the line: no "before" side
  EXPECT_EQ(w.State().inbound + w.State().outbound, 0u);
  w.Straight(1, {0, 2}, {0, -2});
  EXPECT_EQ(w.State().outbound, 1u);
}

TEST(ZonesTest, PolygonOccupancyCrossingsAndDwell) {
  Walk w({Square("room", 0, 0, 4)});
  w.Straight(1, {-2, 2}, {2, 2});
  EXPECT_EQ(w.State().inbound, 1u);
  EXPECT_EQ(w.State().present_ids, std::vector<std::uint64_t>{1});
  for (int i = 0; i < 100; ++i) w.To(1, {2, 2});  // 10 s inside
  ASSERT_EQ(w.State().present_dwell_s.size(), 1u);
  // Inside since it was 0.3 m (the hysteresis) past the edge: 14 steps of 0.12 m before the
  // wait, then 100 updates, 0.1 s each.
  EXPECT_NEAR(w.State().present_dwell_s[0], 11.4, 1e-6);
  w.Straight(1, {2, 2}, {6, 2});
  EXPECT_EQ(w.State().outbound, 1u);
  EXPECT_TRUE(w.State().present_ids.empty());
  EXPECT_EQ(w.State().dwells_completed, 1u);
  EXPECT_NEAR(w.State().dwell_total_s, w.State().dwell_max_s, 1e-9);
  EXPECT_EQ(w.State().lost_inside, 0u);
}

TEST(ZonesTest, PolygonBoundaryHysteresisAndLostTracks) {
  Walk w({Square("room", 0, 0, 4)});
  w.Straight(1, {-2, 2}, {-0.05, 2});
  // Lingers on the boundary, 20 cm either side.
  for (int i = 0; i < 50; ++i) w.To(1, {(i % 2 == 0) ? 0.2 : -0.2, 2});
  EXPECT_EQ(w.State().inbound + w.State().outbound, 0u);
  w.Straight(1, {0, 2}, {1, 2});
  EXPECT_EQ(w.State().inbound, 1u);
  // Another track is born inside (no inbound) and disappears there: lost inside.
  w.To(2, {3, 3});
  // (track 1 was absent from that update: it is gone, inside.)
  EXPECT_EQ(w.State().lost_inside, 1u);
  EXPECT_EQ(w.State().present_ids, std::vector<std::uint64_t>{2});
  w.Nothing();
  EXPECT_EQ(w.State().lost_inside, 2u);
  EXPECT_EQ(w.State().inbound, 1u);
  EXPECT_EQ(w.State().outbound, 0u);
  EXPECT_EQ(w.State().dwells_completed, 2u);
  // Born inside and walking out is an exit.
  w.Straight(3, {3, 3}, {3, 6});
  EXPECT_EQ(w.State().outbound, 1u);
}

TEST(ZonesTest, CoastingTracksKeepTheirState) {
  Walk w({Line("door", {-1, 0}, {1, 0}), Square("room", -1, 0, 2)});
  w.Straight(1, {0, -2}, {0, -1});
  // The prediction runs across the line; nothing is counted until a measurement confirms it.
  w.To(1, {0, 1}, false);
  w.To(1, {0, 2}, false);
  EXPECT_EQ(w.State(0).inbound, 0u);
  EXPECT_EQ(w.State(1).inbound, 0u);
  w.To(1, {0, 1.5});
  EXPECT_EQ(w.State(0).inbound, 1u);
  EXPECT_EQ(w.State(1).inbound, 1u);
}

// A person hidden from every sensor for 1 s (the fusion leaves the id out) while crossing the
// door line into the room, then seen again inside: held, nothing ends or restarts.
TEST(ZonesTest, AnIdThatComesBackWithinTheHoldIsNeitherGoneNorNew) {
  for (const double hold_s : {0.0, 1.5}) {
    SCOPED_TRACE(hold_s);
    Walk w({Line("door", {-1, 0}, {1, 0}), Square("room", -1, 0, 2)}, 0.3, hold_s);
    w.Straight(1, {0, -2}, {0, -0.2});
    for (int i = 0; i < 10; ++i) w.Nothing();  // 1 s hidden
    w.Straight(1, {0, 1.0}, {0, 1.2});
    const ZoneState door = w.State(0), room = w.State(1);
    if (hold_s == 0.0) {
      // Earlier releases: gone, then a new track inside: no crossing, a dwell ended.
      EXPECT_EQ(door.inbound, 0u);
      EXPECT_EQ(room.inbound, 0u);
      EXPECT_EQ(door.dwells_completed, 1u);
      EXPECT_EQ(w.counter().counters().absent_gone, 1u);
      EXPECT_EQ(w.counter().counters().absent_returned, 0u);
    } else {
      EXPECT_EQ(door.inbound, 1u);  // the crossing while hidden, once
      EXPECT_EQ(door.outbound, 0u);
      EXPECT_EQ(room.inbound, 1u);
      EXPECT_EQ(room.outbound, 0u);
      EXPECT_EQ(room.lost_inside, 0u);
      EXPECT_EQ(door.dwells_completed, 1u);  // it left the door's band, once
      EXPECT_EQ(room.dwells_completed, 0u);
      EXPECT_EQ(room.present_ids, std::vector<std::uint64_t>{1});
      EXPECT_EQ(w.counter().counters().absent_held, 1u);
      EXPECT_EQ(w.counter().counters().absent_returned, 1u);
      EXPECT_EQ(w.counter().counters().absent_gone, 0u);
    }
  }
}

// Held while absent: still present (occupancy unchanged); absent for the hold: gone exactly once,
// its dwell ended at the first update it was absent from.
TEST(ZonesTest, AnIdAbsentForTheHoldIsGoneOnceAsOfItsDisappearance) {
  Walk w({Square("room", 0, 0, 4)}, 0.3, 1.0);
  for (int i = 0; i < 20; ++i) w.To(7, {2, 2});  // 2 s inside (seen first inside)
  w.Nothing();
  EXPECT_EQ(w.State().present_ids, std::vector<std::uint64_t>{7});
  EXPECT_EQ(w.State().lost_inside, 0u);
  for (int i = 0; i < 9; ++i) w.Nothing();  // 0.9 s after the first update without it
  EXPECT_EQ(w.State().present_ids, std::vector<std::uint64_t>{7});
  EXPECT_EQ(w.State().dwells_completed, 0u);
  w.Nothing();  // 1.0 s: gone
  EXPECT_TRUE(w.State().present_ids.empty());
  EXPECT_EQ(w.State().lost_inside, 1u);
  EXPECT_EQ(w.State().dwells_completed, 1u);
  EXPECT_EQ(w.State().outbound, 0u);
  // In it from the first update (0.1 s) to the first one it was absent from (2.1 s).
  EXPECT_NEAR(w.State().dwell_max_s, 2.0, 1e-6);
  for (int i = 0; i < 30; ++i) w.Nothing();
  EXPECT_EQ(w.State().lost_inside, 1u);
  EXPECT_EQ(w.State().dwells_completed, 1u);
  EXPECT_EQ(w.counter().counters().absent_gone, 1u);
  EXPECT_EQ(w.counter().counters().absent_returned, 0u);
}

// Updates with the fusion's lists (what ZoneService passes from fusion::FusionOutput).
struct FusionStep {
  std::vector<ZoneTrack> tracks;
  std::vector<std::uint64_t> hidden;
  std::vector<ZoneEnded> ended;
};
class FusionFeed {
 public:
  FusionFeed(std::vector<Zone> zones, double absent_hold_s)
      : counter_(std::move(zones), ZoneOptions{0.3, absent_hold_s}) {}
  void Step(const FusionStep& s) {
    counter_.Update(s.tracks, s.hidden, s.ended, now_ns_ += kStepNs);
  }
  ZoneState State(std::size_t i = 0) const { return counter_.States().at(i); }
  const ZoneCounters& counters() const { return counter_.counters(); }
  ZoneCounter& counter() { return counter_; }

 private:
  ZoneCounter counter_;
  common::UtcNs now_ns_ = kT0;
};

// One person inside the room has two fused ids (2, a second sensor's duplicate started 1 s after
// 1); the fusion merges 2 into 1. From that update on the room holds one person: no exit, no
// lost_inside, one dwell running from 1's entry. Without the fusion's lists (earlier releases)
// the merged id was held as absent for absent_hold_s: the room counted two, then lost one.
TEST(ZonesTest, AMergedIdIsFoldedIntoItsSurvivorAtOnce) {
  for (const bool with_lists : {false, true}) {
    SCOPED_TRACE(with_lists);
    FusionFeed f({Square("room", 0, 0, 4)}, 1.5);
    for (int i = 0; i < 10; ++i) f.Step({{{1, 2.0, 2.0, true}}, {}, {}});
    for (int i = 0; i < 10; ++i) f.Step({{{1, 2.0, 2.0, true}, {2, 2.1, 2.0, true}}, {}, {}});
    EXPECT_EQ(f.State().present_ids, (std::vector<std::uint64_t>{1, 2}));
    std::size_t most_after = 0;
    for (int i = 0; i < 30; ++i) {  // 3 s after the merge
      FusionStep s{{{1, 2.05, 2.0, true}}, {}, {}};
      if (with_lists) s.ended = {{2, 1}};
      f.Step(s);
      most_after = std::max(most_after, f.State().present_ids.size());
    }
    const ZoneState room = f.State();
    EXPECT_EQ(room.present_ids, std::vector<std::uint64_t>{1});
    EXPECT_EQ(room.inbound, 0u);
    EXPECT_EQ(room.outbound, 0u);
    if (with_lists) {
      EXPECT_EQ(most_after, 1u);
      EXPECT_EQ(room.lost_inside, 0u);
      EXPECT_EQ(room.dwells_completed, 0u);
      EXPECT_NEAR(room.present_dwell_s[0], 4.9, 1e-6);  // from 1's first update
      EXPECT_EQ(f.counters().merged, 1u);
      EXPECT_EQ(f.counters().absent_held, 0u);
    } else {
      EXPECT_EQ(most_after, 2u);  // the merged id held for absent_hold_s
      EXPECT_EQ(room.lost_inside, 1u);
      EXPECT_EQ(room.dwells_completed, 1u);
    }
  }
}

// Survivor hidden: person id 1 walks towards the room's wall and is hidden from every sensor
// outside it (the fusion keeps 1, hidden); a sensor starts id 2 on them inside the room; the
// fusion merges 2 into the older 1, which goes on from 2's estimate. The room counts one entry
// (2 was seen first inside: its side unknown, 1 goes on from it), nothing lost, one person.
TEST(ZonesTest, AHiddenSurvivorGoesOnFromTheMergedIdsState) {
  FusionFeed f({Square("room", 0, 0, 4)}, 1.5);
  for (int i = 0; i <= 10; ++i) f.Step({{{1, -2.0 + 0.15 * i, 2.0, true}}, {}, {}});  // to x -0.5
  for (int i = 0; i < 5; ++i) f.Step({{}, {1}, {}});                                  // hidden
  for (int i = 0; i < 5; ++i) f.Step({{{2, 0.5 + 0.1 * i, 2.0, true}}, {1}, {}});     // 2 inside
  EXPECT_EQ(f.State().present_ids, std::vector<std::uint64_t>{2});  // 1 held outside
  for (int i = 0; i < 10; ++i) {
    FusionStep s{{{1, 1.0 + 0.1 * i, 2.0, true}}, {}, {{2, 1}}};
    f.Step(s);
    EXPECT_EQ(f.State().present_ids, std::vector<std::uint64_t>{1});
  }
  const ZoneState room = f.State();
  EXPECT_EQ(room.inbound, 0u);  // seen first inside (as 2): no entry crossing
  EXPECT_EQ(room.outbound, 0u);
  EXPECT_EQ(room.lost_inside, 0u);
  EXPECT_EQ(room.dwells_completed, 0u);
  EXPECT_NEAR(room.present_dwell_s[0], 1.4, 1e-6);  // from 2's entry
  EXPECT_EQ(f.counters().merged, 1u);
  EXPECT_EQ(f.counters().absent_returned, 1u);
}

// The zones know only id 2 (1 was hidden before their first update), inside the room; 2 is
// absent without a word from the fusion for 1 s, then merged into 1, of which the fusion says
// nothing either. The object was last seen when 2 was: 1 takes 2's hold whole and is gone
// absent_hold_s (1.5 s) after 2 was first absent, 0.5 s after the merge, lost inside with the
// dwell ending where 2 was last seen (1 s long).
TEST(ZonesTest, AnUnknownSurvivorTakesTheMergedIdsHoldWhole) {
  FusionFeed f({Square("room", 0, 0, 4)}, 1.5);
  for (int i = 0; i < 10; ++i) f.Step({{{2, 2.0, 2.0, true}}, {}, {}});
  for (int i = 0; i < 10; ++i) f.Step({});  // 2 absent: 0 .. 0.9 s
  f.Step({{}, {}, {{2, 1}}});               // 1.0 s: merged into 1
  EXPECT_EQ(f.State().present_ids, std::vector<std::uint64_t>{1});
  for (int i = 0; i < 4; ++i) {  // 1.1 .. 1.4 s
    f.Step({});
    EXPECT_EQ(f.State().present_ids, std::vector<std::uint64_t>{1});
  }
  f.Step({});  // 1.5 s after 2 was first absent: gone
  const ZoneState room = f.State();
  EXPECT_TRUE(room.present_ids.empty());
  EXPECT_EQ(room.lost_inside, 1u);
  EXPECT_EQ(room.dwells_completed, 1u);
  EXPECT_NEAR(room.dwell_max_s, 1.0, 1e-6);
  EXPECT_EQ(f.counters().merged, 1u);
  EXPECT_EQ(f.counters().expired, 1u);
}

// A hidden id is held for as long as the fusion keeps it, whatever absent_hold_s is (no timer of
// the zones' own that could end it early or keep it late); when the fusion ends it (timed out),
// it is gone at once, as of the first update it was absent from.
TEST(ZonesTest, AHiddenIdIsHeldWhileTheFusionKeepsItAndGoneWhenItEnds) {
  for (const double hold_s : {0.0, 0.5, 1.5, 60.0}) {
    SCOPED_TRACE(hold_s);
    // Back after 1 s hidden: no exit, no entry.
    FusionFeed back({Square("room", 0, 0, 4)}, hold_s);
    for (int i = 0; i < 10; ++i) back.Step({{{1, 2.0, 2.0, true}}, {}, {}});
    for (int i = 0; i < 10; ++i) {
      back.Step({{}, {1}, {}});
      EXPECT_EQ(back.State().present_ids, std::vector<std::uint64_t>{1});
    }
    for (int i = 0; i < 5; ++i) back.Step({{{1, 2.2, 2.0, true}}, {}, {}});
    EXPECT_EQ(back.State().lost_inside, 0u);
    EXPECT_EQ(back.State().dwells_completed, 0u);
    EXPECT_EQ(back.counters().absent_returned, 1u);
    // Hidden 1 s, then ended by the fusion: gone at that update, as of its disappearance.
    FusionFeed ended({Square("room", 0, 0, 4)}, hold_s);
    for (int i = 0; i < 10; ++i) ended.Step({{{1, 2.0, 2.0, true}}, {}, {}});
    for (int i = 0; i < 10; ++i) ended.Step({{}, {1}, {}});
    EXPECT_EQ(ended.State().present_ids, std::vector<std::uint64_t>{1});
    ended.Step({{}, {}, {{1, 0}}});
    EXPECT_TRUE(ended.State().present_ids.empty());
    EXPECT_EQ(ended.State().lost_inside, 1u);
    EXPECT_EQ(ended.State().dwells_completed, 1u);
    EXPECT_NEAR(ended.State().dwell_max_s, 1.0, 1e-6);  // 0.1 s to 1.1 s, the first absence
    EXPECT_EQ(ended.counters().ended, 1u);
    EXPECT_EQ(ended.counters().absent_gone, 1u);
    EXPECT_EQ(ended.counters().expired, 0u);
    for (int i = 0; i < 5; ++i) ended.Step({{}, {}, {{1, 0}}});  // reported again: nothing
    EXPECT_EQ(ended.State().lost_inside, 1u);
  }
}

// A chain of merges reported at once (3 into 2, 2 into 1) folds both into 1; the fusion
// starting afresh (EndAll) ends every id.
TEST(ZonesTest, MergeChainsAndAFusionRestart) {
  FusionFeed f({Square("room", 0, 0, 4)}, 1.5);
  for (int i = 0; i < 5; ++i) {
    f.Step({{{1, 2.0, 2.0, true}, {2, 2.1, 2.0, true}, {3, 2.2, 2.0, true}}, {}, {}});
  }
  EXPECT_EQ(f.State().present_ids.size(), 3u);
  f.Step({{{1, 2.0, 2.0, true}}, {}, {{3, 2}, {2, 1}}});
  EXPECT_EQ(f.State().present_ids, std::vector<std::uint64_t>{1});
  EXPECT_EQ(f.State().lost_inside, 0u);
  EXPECT_EQ(f.counters().merged, 2u);
  f.Step({{}, {1}, {}});  // 1 hidden: held
  EXPECT_EQ(f.counters().absent_held, 1u);
  f.counter().EndAll(kT0 + 10 * kStepNs);
  EXPECT_TRUE(f.State().present_ids.empty());
  EXPECT_EQ(f.State().lost_inside, 1u);
  EXPECT_EQ(f.counters().restarts, 1u);
  // The held id ended with the restart: held = returned + gone.
  EXPECT_EQ(f.counters().absent_returned, 0u);
  EXPECT_EQ(f.counters().absent_gone, 1u);
}

// Lists no sound fuser gives: an id merged into itself and a cycle of two merges end the ids
// (gone, lost inside), counted; a duplicate id counts once.
TEST(ZonesTest, UnresolvableMergesEndTheIdsAndDuplicatesCountOnce) {
  FusionFeed f({Square("room", 0, 0, 4)}, 1.5);
  f.Step({{{1, 2.0, 2.0, true}, {2, 2.5, 2.0, true}, {3, 3.0, 2.0, true}, {1, 9.0, 9.0, true}},
          {},
          {}});
  EXPECT_EQ(f.State().present_ids, (std::vector<std::uint64_t>{1, 2, 3}));
  EXPECT_EQ(f.counters().duplicates, 1u);
  f.Step({{}, {}, {{1, 1}, {2, 3}, {3, 2}}});
  EXPECT_TRUE(f.State().present_ids.empty());
  EXPECT_EQ(f.State().lost_inside, 3u);
  EXPECT_EQ(f.counters().ended, 3u);
  EXPECT_EQ(f.counters().merges_unresolved, 3u);
  EXPECT_EQ(f.counters().merged, 0u);
  EXPECT_EQ(f.counters().merges_into_ended, 0u);
  // A merge into an id that timed out earlier in the same list (one the zones never knew).
  f.Step({{{4, 2.0, 2.0, true}}, {5}, {}});
  f.Step({{}, {}, {{5, 0}, {4, 5}}});
  EXPECT_TRUE(f.State().present_ids.empty());
  EXPECT_EQ(f.counters().merges_unresolved, 4u);
  EXPECT_EQ(f.counters().merges_into_ended, 1u);
  EXPECT_EQ(f.counters().merged, 0u);
}

TEST(ZonesTest, ManyPeopleBothWaysAtOnce) {
  Walk w({Line("corridor", {0, 0}, {0, 10})});  // left of +y is -x: inbound walks towards -x
  ZoneCounter& c = w.counter();
  common::UtcNs now = kT0;
  for (int step = 0; step <= 40; ++step) {
    std::vector<ZoneTrack> tracks;
    for (std::uint64_t k = 0; k < 8; ++k) {
      const double x = (k % 2 == 0 ? 2.0 : -2.0) + (k % 2 == 0 ? -0.1 : 0.1) * step;
      tracks.push_back({k + 1, x, 0.5 + static_cast<double>(k), true});
    }
    c.Update(tracks, now += kStepNs);
  }
  EXPECT_EQ(c.States()[0].inbound, 4u);
  EXPECT_EQ(c.States()[0].outbound, 4u);
  EXPECT_FALSE(c.Update({}, kT0));  // time going back is ignored
}

TEST(ZonesTest, SignedDistance) {
  const std::vector<Point> square = {{0, 0}, {4, 0}, {4, 4}, {0, 4}};
  EXPECT_NEAR(SignedDistanceToPolygon(square, {2, 2}), 2.0, 1e-12);
  EXPECT_NEAR(SignedDistanceToPolygon(square, {5, 2}), -1.0, 1e-12);
  EXPECT_NEAR(SignedDistanceToPolygon(square, {-3, -4}), -5.0, 1e-12);
  // Clockwise vertex order gives the same.
  const std::vector<Point> clockwise(square.rbegin(), square.rend());
  EXPECT_NEAR(SignedDistanceToPolygon(clockwise, {1, 2}), 1.0, 1e-12);
}

TEST(ZonesTest, ValidationNamesTheZoneAndTheProblem) {
  struct Case {
    Zone zone;
    const char* expected;
  };
  const Case cases[] = {
      {Zone{"", ZoneKind::kLine, {{0, 0}, {1, 0}}}, "name"},
      {Zone{"a/b", ZoneKind::kLine, {{0, 0}, {1, 0}}}, "name"},
      {Zone{"door", ZoneKind::kLine, {{0, 0}, {1, 0}, {2, 0}}}, "exactly 2 points"},
      {Zone{"door", ZoneKind::kLine, {{0, 0}, {0, 0}}}, "apart"},
      {Zone{"hall", ZoneKind::kPolygon, {{0, 0}, {1, 0}}}, "at least 3"},
      {Zone{"hall", ZoneKind::kPolygon, {{0, 0}, {1, 0}, {2, 0}}}, "no area"},
      {Zone{"bowtie", ZoneKind::kPolygon, {{0, 0}, {2, 2}, {2, 0}, {0, 2}}}, "cross"},
      {Zone{"far", ZoneKind::kLine, {{0, 0}, {NAN, 1}}}, "finite"},
  };
  for (const Case& c : cases) {
    const auto e = Validate(c.zone);
    ASSERT_TRUE(e.has_value()) << c.expected;
    EXPECT_NE(e->find(c.expected), std::string::npos) << *e;
  }
  const std::vector<Zone> twice = {Square("a", 0, 0, 1), Square("a", 5, 5, 1)};
  ASSERT_TRUE(Validate(std::span<const Zone>(twice)).has_value());
  EXPECT_NE(Validate(std::span<const Zone>(twice))->find("twice"), std::string::npos);
  EXPECT_FALSE(Validate(Square("ok-zone_1", 0, 0, 1)).has_value());
  EXPECT_TRUE(Validate(ZoneOptions{-1.0}).has_value());
}

// The zone counter checks its options before it builds anything from them: a bad absent_hold_s
// aborts with the zones' message.
TEST(ZonesDeathTest, ABadOptionAbortsNamingTheZoneCounter) {
  EXPECT_DEATH(ZoneCounter({Square("room", 0, 0, 4)}, ZoneOptions{0.3, -1.0}),
               "ZoneCounter: absent_hold_s");
  EXPECT_DEATH(ZoneCounter({Square("room", 0, 0, 4)}, ZoneOptions{0.3, 1e9}),
               "ZoneCounter: absent_hold_s");
}

}  // namespace
}  // namespace lrfnet::zones
