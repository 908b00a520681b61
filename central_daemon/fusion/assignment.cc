#include "central_daemon/fusion/assignment.h"

#include <algorithm>
#include <limits>
#include <tuple>

namespace lrfnet::fusion {
namespace {

// Hungarian method for n <= m (rows <= columns), 1-based potentials u (rows) and v (columns);
// p[j] is the row assigned to column j, way[j] the previous column on the augmenting path
// (Kuhn-Munkres in the shortest-augmenting-path form of Jonker & Volgenant 1987).
std::vector<int> HungarianRowsLeCols(const Eigen::MatrixXd& a) {
  const auto n = static_cast<std::size_t>(a.rows());
  const auto m = static_cast<std::size_t>(a.cols());
  constexpr double kInf = std::numeric_limits<double>::infinity();
  std::vector<double> u(n + 1, 0.0), v(m + 1, 0.0);
  std::vector<std::size_t> p(m + 1, 0), way(m + 1, 0);
  std::vector<double> minv(m + 1);
  std::vector<char> used(m + 1);
  for (std::size_t i = 1; i <= n; ++i) {
    p[0] = i;
    std::size_t j0 = 0;
    std::fill(minv.begin(), minv.end(), kInf);
    std::fill(used.begin(), used.end(), 0);
    do {
      used[j0] = 1;
      const std::size_t i0 = p[j0];
      double delta = kInf;
      std::size_t j1 = 0;
      for (std::size_t j = 1; j <= m; ++j) {
        if (used[j]) continue;
        const double cur =
            a(static_cast<Eigen::Index>(i0 - 1), static_cast<Eigen::Index>(j - 1)) - u[i0] - v[j];
        if (cur < minv[j]) {
          minv[j] = cur;
          way[j] = j0;
        }
        if (minv[j] < delta) {
          delta = minv[j];
          j1 = j;
        }
      }
      for (std::size_t j = 0; j <= m; ++j) {
        if (used[j]) {
          u[p[j]] += delta;
          v[j] -= delta;
        } else {
          minv[j] -= delta;
        }
      }
      j0 = j1;
    } while (p[j0] != 0);
    do {
      const std::size_t j1 = way[j0];
      p[j0] = p[j1];
      j0 = j1;
    } while (j0 != 0);
  }
  std::vector<int> row_to_col(n, -1);
  for (std::size_t j = 1; j <= m; ++j) {
    if (p[j] != 0) row_to_col[p[j] - 1] = static_cast<int>(j - 1);
  }
  return row_to_col;
}

std::vector<int> Greedy(const Eigen::MatrixXd& cost) {
  std::vector<std::tuple<double, Eigen::Index, Eigen::Index>> pairs;
  for (Eigen::Index r = 0; r < cost.rows(); ++r) {
    for (Eigen::Index c = 0; c < cost.cols(); ++c) {
      if (cost(r, c) < kForbiddenCost) pairs.emplace_back(cost(r, c), r, c);
    }
  }
  std::sort(pairs.begin(), pairs.end());
  std::vector<int> row_to_col(static_cast<std::size_t>(cost.rows()), -1);
  std::vector<char> col_used(static_cast<std::size_t>(cost.cols()), 0);
  for (const auto& [c, r, col] : pairs) {
    auto& rc = row_to_col[static_cast<std::size_t>(r)];
    if (rc >= 0 || col_used[static_cast<std::size_t>(col)]) continue;
    rc = static_cast<int>(col);
    col_used[static_cast<std::size_t>(col)] = 1;
  }
  return row_to_col;
}

}  // namespace

std::vector<int> SolveAssignment(const Eigen::MatrixXd& cost, std::size_t max_exact_work) {
  const auto rows = static_cast<std::size_t>(cost.rows());
  const auto cols = static_cast<std::size_t>(cost.cols());
  if (rows == 0 || cols == 0) return std::vector<int>(rows, -1);
  const std::size_t small = std::min(rows, cols);
  const std::size_t large = std::max(rows, cols);
  std::vector<int> row_to_col;
  if (small * small > max_exact_work / large) {
    row_to_col = Greedy(cost);
  } else if (rows <= cols) {
    row_to_col = HungarianRowsLeCols(cost);
  } else {
    const std::vector<int> col_to_row = HungarianRowsLeCols(cost.transpose());
    row_to_col.assign(rows, -1);
    for (std::size_t c = 0; c < cols; ++c) {
      if (col_to_row[c] >= 0)
        row_to_col[static_cast<std::size_t>(col_to_row[c])] = static_cast<int>(c);
    }
  }
  // The exact solution pairs every row (or column) of the smaller side; forbidden pairs are the
  // ones it had to take.
  for (std::size_t r = 0; r < rows; ++r) {
    int& c = row_to_col[r];
    if (c >= 0 && !(cost(static_cast<Eigen::Index>(r), c) < kForbiddenCost)) c = -1;
  }
  return row_to_col;
}

}  // namespace lrfnet::fusion
