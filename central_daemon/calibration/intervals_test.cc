#include "central_daemon/calibration/intervals.h"

#include <gtest/gtest.h>

namespace lrfnet::calib {
namespace {

GridTrack Track(std::size_t first_step, std::size_t steps) {
  GridTrack t;
  t.first_step = first_step;
  t.samples.resize(steps);
  return t;
}

AlignedTracks TwoSensors(std::vector<GridTrack> r, std::vector<GridTrack> s) {
  AlignedTracks a;
  a.steps = 1000;
  a.sensors.resize(2);
  a.sensors[0].id = "r";
  a.sensors[0].tracks = std::move(r);
  a.sensors[1].id = "s";
  a.sensors[1].tracks = std::move(s);
  return a;
}

using Tracks = std::vector<std::size_t>;

TEST(PairIntervals, OneTrackEachGivesTheirOverlap) {
  const auto a = TwoSensors({Track(10, 100)}, {Track(50, 100)});
  const auto in = PairIntervals(a, 0, 1, {});
  ASSERT_EQ(in.size(), 1u);
  EXPECT_EQ(in[0].first_step, 50u);
  EXPECT_EQ(in[0].end_step, 110u);
  EXPECT_EQ(in[0].tracks_r, Tracks{0});
  EXPECT_EQ(in[0].tracks_s, Tracks{0});
}

TEST(PairIntervals, NewIntervalWheneverATrackAppearsOrVanishesOnEitherSide) {
  // r: track 0 on [0, 300), track 1 on [100, 200). s: track 0 on [50, 250), track 1 on [150, 400).
  const auto a = TwoSensors({Track(0, 300), Track(100, 100)}, {Track(50, 200), Track(150, 250)});
  const auto in = PairIntervals(a, 0, 1, {});
  ASSERT_EQ(in.size(), 5u);
  const std::size_t bounds[][2] = {{50, 100}, {100, 150}, {150, 200}, {200, 250}, {250, 300}};
  const Tracks rs[] = {{0}, {0, 1}, {0, 1}, {0}, {0}};
  const Tracks ss[] = {{0}, {0}, {0, 1}, {0, 1}, {1}};
  for (std::size_t i = 0; i < in.size(); ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(in[i].first_step, bounds[i][0]);
    EXPECT_EQ(in[i].end_step, bounds[i][1]);
    EXPECT_EQ(in[i].tracks_r, rs[i]);
    EXPECT_EQ(in[i].tracks_s, ss[i]);
  }
}

TEST(PairIntervals, TrackHandOverAtTheSameStepSplitsTheInterval) {
  // r's track 0 ends where track 1 starts (a new id for the same person): the visible set changes.
  const auto a = TwoSensors({Track(0, 100), Track(100, 100)}, {Track(0, 200)});
  const auto in = PairIntervals(a, 0, 1, {});
  ASSERT_EQ(in.size(), 2u);
  EXPECT_EQ(in[0].end_step, 100u);
  EXPECT_EQ(in[0].tracks_r, Tracks{0});
  EXPECT_EQ(in[1].first_step, 100u);
  EXPECT_EQ(in[1].tracks_r, Tracks{1});
}

TEST(PairIntervals, ShortIntervalsAndOneSidedStretchesAreDropped) {
  // s's short track creates a 5-step interval (dropped at min_steps 10); where only r sees
  // someone there is no interval at all.
  const auto a = TwoSensors({Track(0, 100)}, {Track(20, 5), Track(60, 100)});
  const auto in = PairIntervals(a, 0, 1, {});
  ASSERT_EQ(in.size(), 1u);
  EXPECT_EQ(in[0].first_step, 60u);
  EXPECT_EQ(in[0].end_step, 100u);

  const auto all = PairIntervals(a, 0, 1, IntervalOptions{1});
  ASSERT_EQ(all.size(), 2u);
  EXPECT_EQ(all[0].first_step, 20u);
  EXPECT_EQ(all[0].end_step, 25u);
}

TEST(PairIntervals, EmptyTracksAndBadIndicesGiveNothing) {
  const auto a = TwoSensors({Track(0, 0)}, {Track(0, 100)});
  EXPECT_TRUE(PairIntervals(a, 0, 1, {}).empty());
  EXPECT_TRUE(PairIntervals(a, 0, 0, {}).empty());
  EXPECT_TRUE(PairIntervals(a, 0, 7, {}).empty());
}

TEST(PairIntervals, OrderOfTheSensorsOnlySwapsTheTrackLists) {
  const auto a = TwoSensors({Track(0, 300), Track(100, 100)}, {Track(50, 200)});
  const auto rs = PairIntervals(a, 0, 1, {});
  const auto sr = PairIntervals(a, 1, 0, {});
  ASSERT_EQ(rs.size(), sr.size());
  for (std::size_t i = 0; i < rs.size(); ++i) {
    EXPECT_EQ(rs[i].first_step, sr[i].first_step);
    EXPECT_EQ(rs[i].end_step, sr[i].end_step);
    EXPECT_EQ(rs[i].tracks_r, sr[i].tracks_s);
    EXPECT_EQ(rs[i].tracks_s, sr[i].tracks_r);
  }
}

TEST(IntervalOptions, ValidateRejectsZeroMinSteps) {
  EXPECT_FALSE(Validate(IntervalOptions{}).has_value());
  EXPECT_TRUE(Validate(IntervalOptions{0}).has_value());
}

}  // namespace
}  // namespace lrfnet::calib
