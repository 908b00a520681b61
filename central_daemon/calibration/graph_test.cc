#include "central_daemon/calibration/graph.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace lrfnet::calib {
namespace {

RelativeMeasurement GraphEdge(std::size_t r, std::size_t s, double yaw_rad = 0.0) {
  RelativeMeasurement m;
  m.r = r;
  m.s = s;
  m.s_from_r.yaw_rad = yaw_rad;
  return m;
}

TEST(UnconnectedNodes, ListsTheNodesWithoutAPathToTheReferenceSorted) {
  // 0-1-2 connected, 3-4 an island, 5 alone.
  const std::vector<RelativeMeasurement> m = {GraphEdge(1, 0), GraphEdge(2, 1), GraphEdge(4, 3)};
  EXPECT_EQ(UnconnectedNodes(6, 0, m), (std::vector<std::size_t>{3, 4, 5}));
  EXPECT_EQ(UnconnectedNodes(6, 3, m), (std::vector<std::size_t>{0, 1, 2, 5}));
  EXPECT_TRUE(UnconnectedNodes(3, 2, m).empty());
}

TEST(UnconnectedNodes, IgnoresBadIndicesAndAnOutOfRangeReference) {
  const std::vector<RelativeMeasurement> m = {GraphEdge(1, 0), GraphEdge(7, 2), GraphEdge(2, 2)};
  EXPECT_EQ(UnconnectedNodes(3, 0, m), (std::vector<std::size_t>{2}));
  EXPECT_EQ(UnconnectedNodes(3, 3, m), (std::vector<std::size_t>{0, 1, 2}));
}

TEST(ConnectivityError, NamesTheNodesAndHonoursTheUseFlags) {
  const std::vector<RelativeMeasurement> m = {GraphEdge(1, 0), GraphEdge(2, 1), GraphEdge(3, 2)};
  EXPECT_FALSE(ConnectivityError(4, 0, m).has_value());
  const auto error = ConnectivityError(4, 0, m, {true, false, true});
  ASSERT_TRUE(error.has_value());
  EXPECT_EQ(*error, "nodes 2, 3 are not connected to the reference node 0");
  const auto one = ConnectivityError(4, 0, m, {true, true, false});
  ASSERT_TRUE(one.has_value());
  EXPECT_EQ(*one, "node 3 is not connected to the reference node 0");
}

TEST(FormatNodeList, ShortensLongLists) {
  EXPECT_EQ(FormatNodeList({1, 4, 7}), "1, 4, 7");
  EXPECT_EQ(FormatNodeList({1, 2, 3, 4}, 2), "1, 2, ... (2 more)");
}

TEST(CheckGraphInput, RejectsWhatNoSolverCanUse) {
  const std::vector<RelativeMeasurement> ok = {GraphEdge(1, 0)};
  EXPECT_FALSE(CheckGraphInput(2, 0, ok).has_value());
  EXPECT_NE(CheckGraphInput(0, 0, {})->find("at least 2 nodes"), std::string::npos);
  EXPECT_NE(CheckGraphInput(1, 0, {})->find("at least 2 nodes"), std::string::npos);
  EXPECT_NE(CheckGraphInput(2, 2, ok)->find("reference node 2 out of range"), std::string::npos);
  EXPECT_NE(CheckGraphInput(2, 0, {GraphEdge(1, 5)})->find("out of range"), std::string::npos);
  EXPECT_NE(CheckGraphInput(2, 0, {GraphEdge(1, 1)})->find("itself"), std::string::npos);

  std::vector<RelativeMeasurement> nan = {GraphEdge(1, 0), GraphEdge(0, 1)};
  nan[1].s_from_r.yaw_rad = std::numeric_limits<double>::quiet_NaN();
  const auto nan_error = CheckGraphInput(2, 0, nan);
  ASSERT_TRUE(nan_error.has_value());
  EXPECT_NE(nan_error->find("measurement 1 (0, 1): pose is not finite"), std::string::npos);
  nan[1].s_from_r.yaw_rad = 0.0;
  nan[1].s_from_r.x_m = std::numeric_limits<double>::infinity();
  EXPECT_TRUE(CheckGraphInput(2, 0, nan).has_value());

  std::vector<RelativeMeasurement> weight = {GraphEdge(1, 0)};
  weight[0].weight = 0.0;
  EXPECT_NE(CheckGraphInput(2, 0, weight)->find("weight"), std::string::npos);
  weight[0].weight = std::numeric_limits<double>::quiet_NaN();
  EXPECT_TRUE(CheckGraphInput(2, 0, weight).has_value());
}

TEST(CheckGraphInput, ChecksTheTranslationCovarianceOnlyWhereAsked) {
  std::vector<RelativeMeasurement> m = {GraphEdge(1, 0), GraphEdge(1, 0)};
  m[1].covariance(0, 0) = -1.0;
  EXPECT_FALSE(CheckGraphInput(2, 0, m).has_value());
  const auto error = CheckGraphInput(2, 0, m, true);
  ASSERT_TRUE(error.has_value());
  EXPECT_NE(error->find("measurement 1"), std::string::npos);
  EXPECT_NE(error->find("positive definite"), std::string::npos);
  EXPECT_FALSE(CheckGraphInput(2, 0, m, true, {true, false}).has_value());
  m[1].covariance(0, 0) = 1.0;
  m[1].covariance(0, 1) = 0.5;  // not symmetric
  EXPECT_TRUE(CheckGraphInput(2, 0, m, true).has_value());
  m[1].covariance(1, 0) = 0.5;
  EXPECT_FALSE(CheckGraphInput(2, 0, m, true).has_value());
  // The yaw entries do not matter for the translations.
  m[1].covariance(2, 2) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(CheckGraphInput(2, 0, m, true).has_value());
}

TEST(SpanningTreeYaws, ComposesTheMeasurementsFromTheReference) {
  // φ_r = φ_s + θ: node 1 = node 0 + 0.5, node 2 = node 1 - 0.25 (measured as 1 from 2: +0.25).
  const std::vector<RelativeMeasurement> m = {GraphEdge(1, 0, 0.5), GraphEdge(1, 2, 0.25)};
  const std::vector<double> yaw = SpanningTreeYaws(3, 0, m);
  EXPECT_NEAR(yaw[0], 0.0, 1e-15);
  EXPECT_NEAR(yaw[1], 0.5, 1e-15);
  EXPECT_NEAR(yaw[2], 0.25, 1e-15);
  const std::vector<double> from1 = SpanningTreeYaws(3, 1, m);
  EXPECT_NEAR(from1[0], -0.5, 1e-15);
}

TEST(DisjointSets, UnionReportsWhetherItJoinedTwoSets) {
  DisjointSets sets(4);
  EXPECT_TRUE(sets.Union(0, 1));
  EXPECT_TRUE(sets.Union(2, 3));
  EXPECT_FALSE(sets.Union(1, 0));
  EXPECT_NE(sets.Find(0), sets.Find(2));
  EXPECT_TRUE(sets.Union(1, 3));
  EXPECT_EQ(sets.Find(0), sets.Find(2));
  EXPECT_FALSE(sets.Union(0, 3));
}

}  // namespace
}  // namespace lrfnet::calib
