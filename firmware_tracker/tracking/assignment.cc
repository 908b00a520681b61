#include "firmware_tracker/tracking/assignment.h"

#include <bit>
#include <cstdint>
#include <cstring>

namespace lrfnet::tracking {

void SolveGatedAssignment(const AssignmentCosts& cost, const AssignmentAllowed& allowed,
                          std::span<const std::size_t> rows, std::span<const std::size_t> cols,
                          int* row_to_col, int* col_to_row) {
  constexpr std::size_t kDim = kMaxAssignmentDim;
  const std::size_t n = std::min(rows.size(), kDim);
  const std::size_t m = std::min(cols.size(), kDim);
  std::fill_n(row_to_col, n, -1);
  std::fill_n(col_to_row, m, -1);
  // Groups by breadth-first search over the allowed pairs, in bit masks (kDim = 64: one word per
  // row's columns and per column's rows): each row's allowed columns gathered once without a
  // branch, then whole fronts of the search at a time. A crowd's matrix is mostly not allowed: the
  // branch per pair of the search cost more than the pairs that are.
  static_assert(kDim == 64, "one 64-bit mask per row and column");
  using Mask = std::uint64_t;
  const auto all = [](std::size_t count) {
    return count >= 64 ? ~Mask{0} : (Mask{1} << count) - 1;
  };
  std::array<Mask, kDim> row_cols;  // bit b: allowed[rows[a]][cols[b]]; the first n set below
  std::array<Mask, kDim> col_rows;  // bit a: the same pair; the first m set below
  std::fill_n(col_rows.begin(), m, Mask{0});
  // Columns 0, 1, ..., m - 1 (the tracker's first stage: every measurement): a row's mask from its
  // flags 8 at a time, each byte (a bool: 0 or 1) moved to its bit by one multiplication (byte k of
  // x times 2^(56 - 7 k) lands on bit 56 + k, and no two products meet in the top byte), instead
  // of a shift and an or per pair.
  bool identity = std::endian::native == std::endian::little;
  for (std::size_t b = 0; b < m; ++b) identity = identity && cols[b] == b;
  for (std::size_t a = 0; a < n; ++a) {
    const auto& allowed_row = allowed[rows[a]];
    Mask mask = 0;
    if (identity) {
      constexpr std::uint64_t kGather = 0x0102040810204080ull;
      for (std::size_t b = 0; b < m; b += 8) {
        std::uint64_t bytes = 0;
        std::memcpy(&bytes, allowed_row.data() + b, 8);  // b + 8 <= kDim: within the row
        if (m - b < 8) bytes &= (std::uint64_t{1} << (8 * (m - b))) - 1;  // only columns < m
        mask |= ((bytes * kGather) >> 56) << b;
      }
    } else {
      for (std::size_t b = 0; b < m; ++b) mask |= Mask{allowed_row[cols[b]]} << b;
    }
    row_cols[a] = mask;
    for (Mask bits = mask; bits != 0; bits &= bits - 1) {
      col_rows[static_cast<std::size_t>(std::countr_zero(bits))] |= Mask{1} << a;
    }
  }
  std::array<std::size_t, kDim> group_rows{};  // positions in rows / cols
  std::array<std::size_t, kDim> group_cols{};
  std::array<int, kDim> group_assignment{};
  Mask rows_left = all(n), cols_left = all(m);
  while (rows_left != 0) {
    // The group of the first row not yet reached, front by front.
    Mask group_row_mask = rows_left & (~rows_left + 1);
    Mask group_col_mask = 0;
    rows_left &= ~group_row_mask;
    for (Mask front = group_row_mask; front != 0;) {
      Mask new_cols = 0;
      for (Mask bits = front; bits != 0; bits &= bits - 1) {
        new_cols |= row_cols[static_cast<std::size_t>(std::countr_zero(bits))];
      }
      new_cols &= cols_left;
      cols_left &= ~new_cols;
      group_col_mask |= new_cols;
      Mask new_rows = 0;
      for (Mask bits = new_cols; bits != 0; bits &= bits - 1) {
        new_rows |= col_rows[static_cast<std::size_t>(std::countr_zero(bits))];
      }
      new_rows &= rows_left;
      rows_left &= ~new_rows;
      group_row_mask |= new_rows;
      front = new_rows;
    }
    if (group_col_mask == 0) continue;  // a row without allowed pairs
    // The group's rows and columns in their given order.
    std::size_t gn = 0, gm = 0;
    for (Mask bits = group_row_mask; bits != 0; bits &= bits - 1) {
      group_rows[gn++] = static_cast<std::size_t>(std::countr_zero(bits));
    }
    for (Mask bits = group_col_mask; bits != 0; bits &= bits - 1) {
      group_cols[gm++] = static_cast<std::size_t>(std::countr_zero(bits));
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
