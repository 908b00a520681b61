#include "firmware_tracker/tracking/assignment.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <memory>
#include <numeric>
#include <random>
#include <vector>

namespace lrfnet::tracking {
namespace {

constexpr double kUnassignable = 1e9;  // as MultiTracker::kUnassignableCost

struct Problem {
  std::size_t n = 0, m = 0;
  std::unique_ptr<AssignmentCosts> cost = std::make_unique<AssignmentCosts>();
  std::unique_ptr<AssignmentAllowed> allowed = std::make_unique<AssignmentAllowed>();
};

struct Score {
  std::size_t pairs = 0;  // allowed pairs used
  double cost = 0.0;      // their summed cost
};

// People-like scenes: tracks and measurements scattered over an area, allowed within a radius
// (groups of a few), cost a squared distance plus noise; or uniform random allowed pairs.
Problem RandomProblem(std::mt19937_64& rng, std::size_t n, std::size_t m, bool spatial) {
  Problem p;
  p.n = n;
  p.m = m;
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const double side_m = std::sqrt(static_cast<double>(std::max(n, m))) * (0.5 + 1.5 * unit(rng));
  const double density = unit(rng);
  std::vector<std::array<double, 2>> tracks(n), meas(m);
  for (auto& t : tracks) t = {side_m * unit(rng), side_m * unit(rng)};
  for (auto& z : meas) z = {side_m * unit(rng), side_m * unit(rng)};
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = 0; j < m; ++j) {
      bool ok = false;
      double c = 0.0;
      if (spatial) {
        const double d2 =
            std::pow(tracks[i][0] - meas[j][0], 2) + std::pow(tracks[i][1] - meas[j][1], 2);
        ok = d2 <= 1.0;
        c = 9.0 * d2 + 0.5 * unit(rng) - 3.0;  // d2 + ln det S may be negative
      } else {
        ok = unit(rng) < 0.3 * density;
        // Some exact ties (integers) next to continuous costs.
        c = unit(rng) < 0.3 ? std::floor(4.0 * unit(rng)) : 10.0 * unit(rng) - 2.0;
      }
      (*p.allowed)[i][j] = ok;
      (*p.cost)[i][j] = ok ? c : kUnassignable;
    }
  }
  return p;
}

std::vector<std::size_t> Iota(std::size_t k) {
  std::vector<std::size_t> v(k);
  std::iota(v.begin(), v.end(), std::size_t{0});
  return v;
}

Score WholeMatrix(const Problem& p) {
  std::vector<int> assignment(std::max(p.n, p.m), -1);
  Score s;
  auto count = [&](std::size_t i, std::size_t j) {
    if (!(*p.allowed)[i][j]) return;
    ++s.pairs;
    s.cost += (*p.cost)[i][j];
  };
  if (p.n <= p.m) {
    SolveAssignment(
        p.n, p.m, [&](std::size_t i, std::size_t j) { return (*p.cost)[i][j]; }, assignment.data());
    for (std::size_t i = 0; i < p.n; ++i) count(i, static_cast<std::size_t>(assignment[i]));
  } else {
    SolveAssignment(
        p.m, p.n, [&](std::size_t j, std::size_t i) { return (*p.cost)[i][j]; }, assignment.data());
    for (std::size_t j = 0; j < p.m; ++j) count(static_cast<std::size_t>(assignment[j]), j);
  }
  return s;
}

// The grouped solution, checked to be a matching of allowed pairs with consistent directions.
Score Grouped(const Problem& p) {
  const std::vector<std::size_t> rows = Iota(p.n), cols = Iota(p.m);
  std::vector<int> row_to_col(p.n, 7), col_to_row(p.m, 7);
  SolveGatedAssignment(*p.cost, *p.allowed, rows, cols, row_to_col.data(), col_to_row.data());
  Score s;
  for (std::size_t i = 0; i < p.n; ++i) {
    if (row_to_col[i] < 0) {
      EXPECT_EQ(row_to_col[i], -1);
      continue;
    }
    const auto j = static_cast<std::size_t>(row_to_col[i]);
    EXPECT_LT(j, p.m);
    EXPECT_TRUE((*p.allowed)[i][j]) << i << " " << j;
    EXPECT_EQ(col_to_row[j], static_cast<int>(i));
    ++s.pairs;
    s.cost += (*p.cost)[i][j];
  }
  std::size_t cols_used = 0;
  for (std::size_t j = 0; j < p.m; ++j) {
    if (col_to_row[j] >= 0)
      ++cols_used;
    else
      EXPECT_EQ(col_to_row[j], -1);
  }
  EXPECT_EQ(cols_used, s.pairs);
  return s;
}

// Exhaustive: the most allowed pairs, then the least cost (rows in order, each takes a free
// allowed column or none).
void BruteForce(const Problem& p, std::size_t i, std::vector<bool>& used, Score current,
                Score& best) {
  if (i == p.n) {
    if (current.pairs > best.pairs || (current.pairs == best.pairs && current.cost < best.cost)) {
      best = current;
    }
    return;
  }
  BruteForce(p, i + 1, used, current, best);
  for (std::size_t j = 0; j < p.m; ++j) {
    if (used[j] || !(*p.allowed)[i][j]) continue;
    used[j] = true;
    BruteForce(p, i + 1, used, Score{current.pairs + 1, current.cost + (*p.cost)[i][j]}, best);
    used[j] = false;
  }
}

TEST(GatedAssignment, SmallProblemsEqualExhaustiveSearch) {
  std::mt19937_64 rng(14);
  for (int trial = 0; trial < 600; ++trial) {
    const auto n = static_cast<std::size_t>(1 + trial % 6);
    const auto m = static_cast<std::size_t>(1 + (trial / 6) % 6);
    const Problem p = RandomProblem(rng, n, m, trial % 2 == 0);
    Score best{0, std::numeric_limits<double>::infinity()};
    std::vector<bool> used(m, false);
    BruteForce(p, 0, used, Score{}, best);
    if (best.pairs == 0) best.cost = 0.0;
    const Score grouped = Grouped(p);
    ASSERT_EQ(grouped.pairs, best.pairs) << "trial " << trial;
    ASSERT_NEAR(grouped.cost, best.cost, 1e-9) << "trial " << trial;
  }
}

TEST(GatedAssignment, PerGroupEqualsWholeMatrixTotalCost) {
  std::mt19937_64 rng(2014);
  std::uniform_int_distribution<std::size_t> size(1, kMaxAssignmentDim);
  std::size_t multi_row_groups = 0;
  for (int trial = 0; trial < 400; ++trial) {
    // The first ones at the full width (every bit of the solver's 64-bit masks).
    const std::size_t n = trial < 4 ? kMaxAssignmentDim : size(rng);
    const std::size_t m =
        trial < 4 ? kMaxAssignmentDim - static_cast<std::size_t>(trial % 2) : size(rng);
    const Problem p = RandomProblem(rng, n, m, trial % 4 != 0);
    const Score whole = WholeMatrix(p);
    const Score grouped = Grouped(p);
    ASSERT_EQ(grouped.pairs, whole.pairs) << "trial " << trial << " " << p.n << "x" << p.m;
    // The whole matrix carries the 1e9 of unpaired rows through its potentials: its sums are good
    // to ~1e-7 there, the groups' exactly.
    ASSERT_NEAR(grouped.cost, whole.cost, 1e-6) << "trial " << trial << " " << p.n << "x" << p.m;
    std::size_t allowed_in_row = 0;
    for (std::size_t j = 0; j < p.m; ++j) allowed_in_row += (*p.allowed)[0][j] ? 1 : 0;
    if (allowed_in_row > 1) ++multi_row_groups;
  }
  EXPECT_GT(multi_row_groups, 100u);  // the problems are not all trivial
}

TEST(GatedAssignment, SubsetsOfRowsAndColumns) {
  // The tracker's second stage: some rows and columns of the matrices only.
  std::mt19937_64 rng(7);
  for (int trial = 0; trial < 100; ++trial) {
    const Problem p = RandomProblem(rng, 40, 50, true);
    std::vector<std::size_t> rows, cols;
    for (std::size_t i = 0; i < p.n; ++i) {
      if (i % 3 != 1) rows.push_back(i);
    }
    for (std::size_t j = 0; j < p.m; ++j) {
      if (j % 4 != 2) cols.push_back(j);
    }
    Problem sub;
    sub.n = rows.size();
    sub.m = cols.size();
    for (std::size_t a = 0; a < sub.n; ++a) {
      for (std::size_t b = 0; b < sub.m; ++b) {
        (*sub.cost)[a][b] = (*p.cost)[rows[a]][cols[b]];
        (*sub.allowed)[a][b] = (*p.allowed)[rows[a]][cols[b]];
      }
    }
    std::vector<int> row_to_col(sub.n), col_to_row(sub.m);
    SolveGatedAssignment(*p.cost, *p.allowed, rows, cols, row_to_col.data(), col_to_row.data());
    std::vector<int> direct_rows(sub.n), direct_cols(sub.m);
    SolveGatedAssignment(*sub.cost, *sub.allowed, Iota(sub.n), Iota(sub.m), direct_rows.data(),
                         direct_cols.data());
    EXPECT_EQ(row_to_col, direct_rows);
    EXPECT_EQ(col_to_row, direct_cols);
  }
}

TEST(GatedAssignment, AllColumnsTakesNoFlagBeyondTheLastColumn) {
  // Every column in order (the tracker's first stage: the masks 8 flags at a time): flags set
  // beyond the m columns change nothing, at every m (every remainder of 8).
  std::mt19937_64 rng(8);
  for (std::size_t m = 1; m <= kMaxAssignmentDim; ++m) {
    for (int trial = 0; trial < 4; ++trial) {
      const std::size_t n = 1 + m % 17;
      Problem p = RandomProblem(rng, n, m, trial % 2 == 0);
      std::vector<int> rows_clean(n), cols_clean(m);
      SolveGatedAssignment(*p.cost, *p.allowed, Iota(n), Iota(m), rows_clean.data(),
                           cols_clean.data());
      for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t j = m; j < kMaxAssignmentDim; ++j) {
          (*p.allowed)[i][j] = true;
          (*p.cost)[i][j] = 0.0;
        }
      }
      std::vector<int> rows_set(n), cols_set(m);
      SolveGatedAssignment(*p.cost, *p.allowed, Iota(n), Iota(m), rows_set.data(), cols_set.data());
      EXPECT_EQ(rows_set, rows_clean) << m;
      EXPECT_EQ(cols_set, cols_clean) << m;
      for (std::size_t i = 0; i < n; ++i) {
        if (rows_set[i] >= 0) {
          EXPECT_TRUE((*p.allowed)[i][static_cast<std::size_t>(rows_set[i])]);
        }
      }
    }
  }
}

}  // namespace
}  // namespace lrfnet::tracking
