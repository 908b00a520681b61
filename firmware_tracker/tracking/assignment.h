#pragma once
// Minimum-cost assignment of tracks to measurements (the multi-target tracker's global nearest
// neighbour step).
//
// SolveAssignment: the Hungarian method as shortest augmenting paths with potentials
// (Kuhn-Munkres / Jonker-Volgenant family), exact, O(n^2 m) on an n x m matrix with n <= m; every
// row gets a column.
//
// SolveGatedAssignment: the same optimum when only some pairs are allowed (gated) and every other
// pair costs a constant far above any sum of allowed costs (the tracker's kUnassignableCost): the
// assignment pairs the most allowed pairs and, among those, minimises their summed cost. Allowed
// pairs connect rows and columns into groups (connected components of the bipartite graph of
// allowed pairs) that share nothing, so the optimum is the union of each group's optimum: the
// Hungarian method runs per group (a few tracks each, even in a crowd) instead of once on the
// whole matrix. Rows and columns keep their order inside a group; a group of one row and one column
// needs no solver. Of several optima with the same total cost, a group may pick another one than
// the whole matrix would.
//
// Fixed storage, no allocation.

#include <algorithm>
#include <array>
#include <cstddef>
#include <limits>
#include <span>

namespace lrfnet::tracking {

inline constexpr std::size_t kMaxAssignmentDim = 64;
using AssignmentCosts = std::array<std::array<double, kMaxAssignmentDim>, kMaxAssignmentDim>;
using AssignmentAllowed = std::array<std::array<bool, kMaxAssignmentDim>, kMaxAssignmentDim>;

// n <= m <= kMaxAssignmentDim; cost(i, j) for 0-based i, j; row_to_col receives every row's column.
template <typename CostFn>
void SolveAssignment(std::size_t n, std::size_t m, const CostFn& cost, int* row_to_col) {
  constexpr std::size_t kDim = kMaxAssignmentDim + 1;
  constexpr double kInf = std::numeric_limits<double>::infinity();
  // 1-based as in the textbook formulation; index 0 is the virtual start column.
  std::array<double, kDim> u{};
  std::array<double, kDim> v{};
  std::array<std::size_t, kDim> row_of_col{};  // 0 = column free
  std::array<std::size_t, kDim> way{};
  std::array<double, kDim> min_slack{};
  std::array<bool, kDim> used{};
  for (std::size_t i = 1; i <= n; ++i) {
    row_of_col[0] = i;
    std::size_t j0 = 0;
    std::fill_n(min_slack.begin(), m + 1, kInf);
    std::fill_n(used.begin(), m + 1, false);
    do {
      used[j0] = true;
      const std::size_t i0 = row_of_col[j0];
      double delta = kInf;
      std::size_t j1 = 0;
      for (std::size_t j = 1; j <= m; ++j) {
        if (used[j]) continue;
        const double slack = cost(i0 - 1, j - 1) - u[i0] - v[j];
        if (slack < min_slack[j]) {
          min_slack[j] = slack;
          way[j] = j0;
        }
        if (min_slack[j] < delta) {
          delta = min_slack[j];
          j1 = j;
        }
      }
      for (std::size_t j = 0; j <= m; ++j) {
        if (used[j]) {
          u[row_of_col[j]] += delta;
          v[j] -= delta;
        } else {
          min_slack[j] -= delta;
        }
      }
      j0 = j1;
    } while (row_of_col[j0] != 0);
    do {
      const std::size_t j1 = way[j0];
      row_of_col[j0] = row_of_col[j1];
      j0 = j1;
    } while (j0 != 0);
  }
  for (std::size_t j = 1; j <= m; ++j) {
    if (row_of_col[j] != 0) row_to_col[row_of_col[j] - 1] = static_cast<int>(j - 1);
  }
}

// The problem of the rows `rows` and the columns `cols` (indices into cost and allowed, at most
// kMaxAssignmentDim each, ascending). row_to_col[a]: the position in `cols` of row rows[a]'s
// column, -1 when it gets no allowed pair; col_to_row[b] likewise.
void SolveGatedAssignment(const AssignmentCosts& cost, const AssignmentAllowed& allowed,
                          std::span<const std::size_t> rows, std::span<const std::size_t> cols,
                          int* row_to_col, int* col_to_row);

}  // namespace lrfnet::tracking
