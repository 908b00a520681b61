#pragma once
// Minimum-cost assignment of rows to columns (rectangular), for the fusion's global nearest
// neighbour association. Pure.

#include <Eigen/Core>
#include <cstddef>
#include <vector>

namespace lrfnet::fusion {

// A cost at or above this marks a pair that must not be assigned.
inline constexpr double kForbiddenCost = 1e9;

// Assigns each row at most one column and each column at most one row, so that the number of
// allowed pairs (cost < kForbiddenCost) is maximal and, among those assignments, the sum of their
// costs is minimal. Returns, per row, the column or -1. Costs must be finite (any sign).
// Exact (Hungarian method with potentials, shortest augmenting paths, O(n^2 m) for n <= m) when
// rows * rows * cols <= max_exact_work; larger problems (only hostile input gets there: the gates
// keep clusters small) are solved greedily by increasing cost.
std::vector<int> SolveAssignment(const Eigen::MatrixXd& cost,
                                 std::size_t max_exact_work = 4'000'000);

}  // namespace lrfnet::fusion
