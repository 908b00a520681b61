#include "central_daemon/fusion/assignment.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <numeric>
#include <random>

namespace lrfnet::fusion {
namespace {

constexpr double kF = kForbiddenCost;

Eigen::MatrixXd M(int rows, int cols, std::initializer_list<double> values) {
  Eigen::MatrixXd m(rows, cols);
  auto it = values.begin();
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) m(r, c) = *it++;
  }
  return m;
}

TEST(AssignmentTest, BeatsGreedy) {
  // Greedy takes (0,0) = 1 and is left with (1,1) = 10; the optimum pairs crosswise (2 + 2).
  EXPECT_EQ(SolveAssignment(M(2, 2, {1, 2, 2, 10})), (std::vector<int>{1, 0}));
}

TEST(AssignmentTest, ForbiddenPairsAreNeverAssigned) {
  EXPECT_EQ(SolveAssignment(M(2, 2, {kF, 1, kF, 2})), (std::vector<int>{1, -1}));
  EXPECT_EQ(SolveAssignment(M(2, 2, {kF, kF, kF, kF})), (std::vector<int>{-1, -1}));
  // More pairs before lower cost: (0,0) + (1,1) = 101 rather than (0,1) alone = 5.
  EXPECT_EQ(SolveAssignment(M(2, 2, {1, 5, kF, 100})), (std::vector<int>{0, 1}));
}

TEST(AssignmentTest, RectangularAndEmpty) {
  EXPECT_EQ(SolveAssignment(M(2, 4, {9, 9, 1, 9, 9, 9, 2, 3})), (std::vector<int>{2, 3}));
  EXPECT_EQ(SolveAssignment(M(4, 2, {9, 9, 1, 9, 9, 1, 9, 9})), (std::vector<int>{-1, 0, 1, -1}));
  EXPECT_EQ(SolveAssignment(Eigen::MatrixXd(3, 0)), (std::vector<int>{-1, -1, -1}));
  EXPECT_TRUE(SolveAssignment(Eigen::MatrixXd(0, 3)).empty());
  // Negative costs (ln det S of small covariances) are fine.
  EXPECT_EQ(SolveAssignment(M(2, 2, {-5, -9, -8, -1})), (std::vector<int>{1, 0}));
}

// Brute force over all injective maps of rows into columns-or-nothing.
double BestCost(const Eigen::MatrixXd& c, std::size_t row, std::vector<char>& used,
                int& pairs_out) {
  if (row == static_cast<std::size_t>(c.rows())) {
    pairs_out = 0;
    return 0.0;
  }
  int best_pairs = -1;
  double best = 0.0;
  int sub_pairs = 0;
  const double skip = BestCost(c, row + 1, used, sub_pairs);
  best_pairs = sub_pairs;
  best = skip;
  for (Eigen::Index col = 0; col < c.cols(); ++col) {
    if (used[static_cast<std::size_t>(col)] || c(static_cast<Eigen::Index>(row), col) >= kF)
      continue;
    used[static_cast<std::size_t>(col)] = 1;
    const double v = c(static_cast<Eigen::Index>(row), col) + BestCost(c, row + 1, used, sub_pairs);
    used[static_cast<std::size_t>(col)] = 0;
    if (sub_pairs + 1 > best_pairs || (sub_pairs + 1 == best_pairs && v < best)) {
      best_pairs = sub_pairs + 1;
      best = v;
    }
  }
  pairs_out = best_pairs;
  return best;
}

TEST(AssignmentTest, OptimalOnRandomProblems) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-3.0, 10.0);
  for (int round = 0; round < 300; ++round) {
    const int rows = 1 + static_cast<int>(rng() % 5), cols = 1 + static_cast<int>(rng() % 5);
    Eigen::MatrixXd c(rows, cols);
    for (int r = 0; r < rows; ++r) {
      for (int col = 0; col < cols; ++col) c(r, col) = rng() % 3 == 0 ? kF : u(rng);
    }
    const std::vector<int> a = SolveAssignment(c);
    std::vector<char> used(static_cast<std::size_t>(cols), 0);
    int pairs = 0;
    double cost = 0.0;
    for (int r = 0; r < rows; ++r) {
      if (a[static_cast<std::size_t>(r)] < 0) continue;
      EXPECT_LT(c(r, a[static_cast<std::size_t>(r)]), kF);
      EXPECT_FALSE(used[static_cast<std::size_t>(a[static_cast<std::size_t>(r)])]);
      used[static_cast<std::size_t>(a[static_cast<std::size_t>(r)])] = 1;
      ++pairs;
      cost += c(r, a[static_cast<std::size_t>(r)]);
    }
    std::vector<char> scratch(static_cast<std::size_t>(cols), 0);
    int best_pairs = 0;
    const double best = BestCost(c, 0, scratch, best_pairs);
    EXPECT_EQ(pairs, best_pairs) << c;
    EXPECT_NEAR(cost, best, 1e-9) << c;
  }
}

TEST(AssignmentTest, GreedyFallbackStaysConsistent) {
  const Eigen::MatrixXd c = M(3, 3, {1, 2, kF, 2, 10, 3, kF, kF, 4});
  const std::vector<int> a = SolveAssignment(c, 0);
  EXPECT_EQ(a, (std::vector<int>{0, 2, -1}));  // greedy by cost: (0,0)=1, (1,2)=3; row 2 left out
}

}  // namespace
}  // namespace lrfnet::fusion
