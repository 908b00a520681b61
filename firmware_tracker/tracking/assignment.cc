#include "firmware_tracker/tracking/assignment.h"

namespace lrfnet::tracking {

void SolveGatedAssignment(const AssignmentCosts& cost, const AssignmentAllowed& allowed,
                          std::span<const std::size_t> rows, std::span<const std::size_t> cols,
                          int* row_to_col, int* col_to_row) {
  constexpr std::size_t kDim = kMaxAssignmentDim;
  const std::size_t n = std::min(rows.size(), kDim);
  const std::size_t m = std::min(cols.size(), kDim);
  std::fill_n(row_to_col, n, -1);
  std::fill_n(col_to_row, m, -1);
  // Groups by breadth-first search over the allowed pairs; group number + 1, 0 = not yet reached.
  std::array<std::size_t, kDim> row_group{};
  std::array<std::size_t, kDim> col_group{};
  std::array<std::size_t, 2 * kDim> queue{};   // row a as a, column b as kDim + b
  std::array<std::size_t, kDim> group_rows{};  // positions in rows / cols
  std::array<std::size_t, kDim> group_cols{};
  std::array<int, kDim> group_assignment{};
  std::size_t groups = 0;
  for (std::size_t start = 0; start < n; ++start) {
    if (row_group[start] != 0) continue;
    const std::size_t g = ++groups;
    std::size_t head = 0, tail = 0;
    queue[tail++] = start;
    row_group[start] = g;
    std::size_t gn = 0, gm = 0;
    while (head < tail) {
      const std::size_t node = queue[head++];
      if (node < kDim) {
        ++gn;
        const auto& allowed_row = allowed[rows[node]];
        for (std::size_t b = 0; b < m; ++b) {
          if (col_group[b] == 0 && allowed_row[cols[b]]) {
            col_group[b] = g;
            queue[tail++] = kDim + b;
          }
        }
      } else {
        ++gm;
        const std::size_t col = cols[node - kDim];
        for (std::size_t a = start + 1; a < n; ++a) {
          if (row_group[a] == 0 && allowed[rows[a]][col]) {
            row_group[a] = g;
            queue[tail++] = a;
          }
        }
      }
    }
    if (gm == 0) continue;  // a row without allowed pairs
    // The group's rows and columns in their given order.
    std::size_t k = 0;
    for (std::size_t a = start; a < n && k < gn; ++a) {
      if (row_group[a] == g) group_rows[k++] = a;
    }
    k = 0;
    for (std::size_t b = 0; b < m && k < gm; ++b) {
      if (col_group[b] == g) group_cols[k++] = b;
    }
    auto pair = [&](std::size_t a, std::size_t b) {
      if (!allowed[rows[a]][cols[b]]) return;  // the group could not pair every row
      row_to_col[a] = static_cast<int>(b);
      col_to_row[b] = static_cast<int>(a);
    };
    if (gn == 1 && gm == 1) {
      pair(group_rows[0], group_cols[0]);
    } else if (gn <= gm) {
      SolveAssignment(
          gn, gm,
          [&](std::size_t r, std::size_t c) {
            return cost[rows[group_rows[r]]][cols[group_cols[c]]];
          },
          group_assignment.data());
      for (std::size_t r = 0; r < gn; ++r) {
        pair(group_rows[r], group_cols[static_cast<std::size_t>(group_assignment[r])]);
      }
    } else {
      SolveAssignment(
          gm, gn,
          [&](std::size_t c, std::size_t r) {
            return cost[rows[group_rows[r]]][cols[group_cols[c]]];
          },
          group_assignment.data());
      for (std::size_t c = 0; c < gm; ++c) {
        pair(group_rows[static_cast<std::size_t>(group_assignment[c])], group_cols[c]);
      }
    }
  }
}

}  // namespace lrfnet::tracking
