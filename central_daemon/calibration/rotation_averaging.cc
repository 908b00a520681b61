#include "central_daemon/calibration/rotation_averaging.h"

#include <Eigen/SparseCholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "central_daemon/calibration/spectral.h"

namespace lrfnet::calib {
namespace {

constexpr double kTwoPi = 2.0 * common::kPi;
constexpr std::size_t kNone = std::numeric_limits<std::size_t>::max();
// Residuals this small count as zero (exact ties of noise-free data); radians.
constexpr double kZeroResidualRad = 1e-12;
// Relative excess of a tree edge's dual flow over its weight still accepted as optimal: the
// vertex is then within this relative gap of the optimum (g / (1 + tolerance) is dual feasible).
constexpr double kCertifyTolerance = 1e-9;
// Relative weight increase that breaks ties towards cycle-consistent measurements.
constexpr double kTieBreak = 1e-6;
// IRLS smoothing (radians) below which the exact finish is attempted at every iteration.
constexpr double kFinishEpsilon = 1e-6;

using SparseMatrix = Eigen::SparseMatrix<double>;
using Solver = Eigen::SimplicialLDLT<SparseMatrix>;

// The node-angle form with fixed 2π offsets: residual r_e = φ_r - φ_s - b_e.
struct NodeProblem {
  std::size_t n = 0;
  std::size_t reference = 0;
  std::vector<std::size_t> r, s;
  std::vector<double> theta;                       // measured yaw (any representative)
  std::vector<double> weight;                      // w_e
  std::vector<double> b;                           // theta + 2π k_e
  std::vector<Eigen::Index> column;                // node -> unknown index, -1 for the reference
  std::vector<std::vector<std::size_t>> adjacent;  // node -> its edges

  std::size_t edges() const { return r.size(); }
};

NodeProblem MakeProblem(std::size_t n, std::size_t reference,
                        const std::vector<RelativeMeasurement>& measurements, bool use_weights) {
  NodeProblem p;
  p.n = n;
  p.reference = reference;
  for (const RelativeMeasurement& m : measurements) {
    p.r.push_back(m.r);
    p.s.push_back(m.s);
    // Any representative may come in; wrapped first so that the offsets stay small integers.
    p.theta.push_back(common::NormalizeAngle(m.s_from_r.yaw_rad));
    p.weight.push_back(use_weights ? m.weight : 1.0);
  }
  p.b = p.theta;
  p.adjacent.assign(n, {});
  for (std::size_t e = 0; e < p.edges(); ++e) {
    p.adjacent[p.r[e]].push_back(e);
    p.adjacent[p.s[e]].push_back(e);
  }
  p.column.assign(n, -1);
  Eigen::Index next = 0;
  for (std::size_t v = 0; v < n; ++v) {
    if (v != reference) p.column[v] = next++;
  }
  return p;
}

// The 2π normalisation: every measurement is taken in the branch nearest to the current relative
// yaw, so that each residual lies in [-π, π]. Returns whether any offset changed.
bool NormaliseOffsets(const std::vector<double>& phi, NodeProblem* p) {
  bool changed = false;
  for (std::size_t e = 0; e < p->edges(); ++e) {
    const double k = std::round((phi[p->r[e]] - phi[p->s[e]] - p->theta[e]) / kTwoPi);
    const double b = p->theta[e] + kTwoPi * k;
    if (b != p->b[e]) changed = true;
    p->b[e] = b;
  }
  return changed;
}

std::vector<double> Residuals(const NodeProblem& p, const std::vector<double>& phi) {
  std::vector<double> r(p.edges());
  for (std::size_t e = 0; e < p.edges(); ++e) r[e] = phi[p.r[e]] - phi[p.s[e]] - p.b[e];
  return r;
}

double Cost(const NodeProblem& p, const std::vector<double>& residual) {
  double cost = 0.0;
  for (std::size_t e = 0; e < p.edges(); ++e) cost += p.weight[e] * std::abs(residual[e]);
  return cost;
}

// Weighted least squares Σ c_e (φ_r - φ_s - b_e)^2 over the non-reference yaws (the reduced graph
// Laplacian). The sparsity pattern does not depend on c, so it is analysed once.
bool SolveWeighted(const NodeProblem& p, const std::vector<double>& c, Solver* solver,
                   bool* analysed, std::vector<double>* phi) {
  const auto unknowns = static_cast<Eigen::Index>(p.n - 1);
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(4 * p.edges());
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(unknowns);
  for (std::size_t e = 0; e < p.edges(); ++e) {
    const Eigen::Index cr = p.column[p.r[e]], cs = p.column[p.s[e]];
    if (cr >= 0) {
      triplets.emplace_back(cr, cr, c[e]);
      rhs(cr) += c[e] * p.b[e];
    }
    if (cs >= 0) {
      triplets.emplace_back(cs, cs, c[e]);
      rhs(cs) -= c[e] * p.b[e];
    }
    if (cr >= 0 && cs >= 0) {
      triplets.emplace_back(cr, cs, -c[e]);
      triplets.emplace_back(cs, cr, -c[e]);
    }
  }
  SparseMatrix laplacian(unknowns, unknowns);
  laplacian.setFromTriplets(triplets.begin(), triplets.end());
  if (!*analysed) {
    solver->analyzePattern(laplacian);
    *analysed = true;
  }
  solver->factorize(laplacian);
  if (solver->info() != Eigen::Success) return false;
  const Eigen::VectorXd x = solver->solve(rhs);
  if (solver->info() != Eigen::Success || !x.allFinite()) return false;
  phi->assign(p.n, 0.0);
  for (std::size_t v = 0; v < p.n; ++v) {
    if (p.column[v] >= 0) (*phi)[v] = x(p.column[v]);
  }
  return true;
}

// A spanning tree rooted at the reference.
struct Tree {
  std::vector<bool> in_tree;             // per edge
  std::vector<std::size_t> parent_edge;  // per node; kNone at the root
  std::vector<std::size_t> order;        // breadth-first from the root
};

Tree RootTree(const NodeProblem& p, std::vector<bool> in_tree) {
  Tree t;
  t.in_tree = std::move(in_tree);
  t.parent_edge.assign(p.n, kNone);
  t.order.reserve(p.n);
  t.order.push_back(p.reference);
  std::vector<bool> seen(p.n, false);
  seen[p.reference] = true;
  for (std::size_t i = 0; i < t.order.size(); ++i) {
    const std::size_t v = t.order[i];
    for (std::size_t e : p.adjacent[v]) {
      if (!t.in_tree[e]) continue;
      const std::size_t u = p.r[e] == v ? p.s[e] : p.r[e];
      if (seen[u]) continue;
      seen[u] = true;
      t.parent_edge[u] = e;
      t.order.push_back(u);
    }
  }
  return t;
}

// Kruskal on ascending key (ties: heavier edge first, then lower index).
std::vector<bool> KruskalTree(const NodeProblem& p, const std::vector<double>& key) {
  std::vector<std::size_t> idx(p.edges());
  std::iota(idx.begin(), idx.end(), std::size_t{0});
  std::sort(idx.begin(), idx.end(), [&](std::size_t a, std::size_t b) {
    if (key[a] != key[b]) return key[a] < key[b];
    if (p.weight[a] != p.weight[b]) return p.weight[a] > p.weight[b];
    return a < b;
  });
  std::vector<std::size_t> root(p.n);
  std::iota(root.begin(), root.end(), std::size_t{0});
  auto find = [&](std::size_t v) {
    while (root[v] != v) {
      root[v] = root[root[v]];
      v = root[v];
    }
    return v;
  };
  std::vector<bool> in_tree(p.edges(), false);
  for (std::size_t e : idx) {
    const std::size_t a = find(p.r[e]), b = find(p.s[e]);
    if (a == b) continue;
    root[a] = b;
    in_tree[e] = true;
  }
  return in_tree;
}

// The tree of the most nearly active measurements: the LP basis the IRLS point is closest to.
std::vector<bool> SmallestResidualTree(const NodeProblem& p, const std::vector<double>& residual) {
  std::vector<double> key(residual.size());
  for (std::size_t e = 0; e < residual.size(); ++e) key[e] = std::abs(residual[e]);
  return KruskalTree(p, key);
}

// Yaws with every tree edge's residual exactly zero.
std::vector<double> TreeYaws(const NodeProblem& p, const Tree& t) {
  std::vector<double> phi(p.n, 0.0);
  for (std::size_t v : t.order) {
    const std::size_t e = t.parent_edge[v];
    if (e == kNone) continue;
    phi[v] = v == p.r[e] ? phi[p.s[e]] + p.b[e] : phi[p.r[e]] - p.b[e];
  }
  return phi;
}

// Completes the flow g (given on the non-tree edges) on the tree edges so that it is conserved at
// every node but the root: Σ_{e: r_e = v} g_e - Σ_{e: s_e = v} g_e = 0, the stationarity of the
// Lagrangian Σ g_e r_e(φ) in φ_v (the LP dual's equality constraints).
void CompleteTreeFlows(const NodeProblem& p, const Tree& t, std::vector<double>* g) {
  std::vector<double> divergence(p.n, 0.0);
  for (std::size_t e = 0; e < p.edges(); ++e) {
    if (t.in_tree[e]) continue;
    divergence[p.r[e]] += (*g)[e];
    divergence[p.s[e]] -= (*g)[e];
  }
  for (auto it = t.order.rbegin(); it != t.order.rend(); ++it) {
    const std::size_t v = *it;
    const std::size_t e = t.parent_edge[v];
    if (e == kNone) continue;
    const double ge = v == p.r[e] ? -divergence[v] : divergence[v];
    (*g)[e] = ge;
    const std::size_t u = v == p.r[e] ? p.s[e] : p.r[e];
    divergence[u] += u == p.r[e] ? ge : -ge;
  }
}

// Lower bound -Σ g_e b_e of the optimum from a flow g that is conserved (tree completion) and
// within |g_e| <= w_e (scaled down if needed): weak LP duality.
double LowerBound(const NodeProblem& p, const Tree& t, std::vector<double> g) {
  CompleteTreeFlows(p, t, &g);
  double scale = 1.0;
  for (std::size_t e = 0; e < p.edges(); ++e) scale = std::max(scale, std::abs(g[e]) / p.weight[e]);
  double bound = 0.0;
  for (std::size_t e = 0; e < p.edges(); ++e) bound -= g[e] / scale * p.b[e];
  return bound;
}

struct Finish {
  std::vector<double> phi;
  double cost = std::numeric_limits<double>::infinity();
  bool certified = false;
  int pivots = 0;
};

struct Breakpoint {
  double t;
  double w;
  std::size_t e;
};

// Moving the subtree below `child` by t turns every cut edge f's residual into r_f + σ_f t, so the
// cost along this direction is Σ w_f |t - t_f| (breakpoints t_f = -σ_f r_f), minimised on
// [cut[lo].t, cut[hi].t]: the weighted median (an interval when the weights split exactly).
struct CutLine {
  std::vector<Breakpoint> cut;  // sorted by t
  double t_lo = 0.0;
  double t_hi = 0.0;
  std::size_t lo = 0;
  std::size_t hi = 0;
};

CutLine MinimiseAlongCut(const NodeProblem& p, const Tree& t, const std::vector<double>& r,
                         std::size_t child) {
  std::vector<bool> below(p.n, false);
  below[child] = true;
  for (std::size_t v : t.order) {
    const std::size_t e = t.parent_edge[v];
    if (e == kNone || v == child) continue;
    const std::size_t parent = v == p.r[e] ? p.s[e] : p.r[e];
    if (below[parent]) below[v] = true;
  }
  CutLine line;
  double total = 0.0;
  for (std::size_t e = 0; e < p.edges(); ++e) {
    if (below[p.r[e]] == below[p.s[e]]) continue;
    const double sigma = below[p.r[e]] ? 1.0 : -1.0;
    line.cut.push_back({-sigma * r[e], p.weight[e], e});
    total += p.weight[e];
  }
  std::sort(line.cut.begin(), line.cut.end(), [](const Breakpoint& a, const Breakpoint& b) {
    return a.t != b.t ? a.t < b.t : a.e < b.e;
  });
  double cumulative = 0.0;
  std::size_t k = 0;
  while (k + 1 < line.cut.size() && (cumulative + line.cut[k].w) * 2.0 < total) {
    cumulative += line.cut[k++].w;
  }
  line.lo = line.hi = k;
  if ((cumulative + line.cut[k].w) * 2.0 == total && k + 1 < line.cut.size()) line.hi = k + 1;
  line.t_lo = line.cut[line.lo].t;
  line.t_hi = line.cut[line.hi].t;
  return line;
}

// The exact finish: the vertex of the smallest-residual tree, certified by the LP dual or improved
// by network-simplex pivots (see the header). `g_hint` supplies the flows of non-tree edges whose
// residual is zero (the dual is not unique there).
Finish FinishExactly(const NodeProblem& p, const std::vector<double>& residual,
                     const std::vector<double>& g_hint, int max_pivots) {
  Finish best;
  std::vector<bool> in_tree = SmallestResidualTree(p, residual);
  for (int pivot = 0;; ++pivot) {
    const Tree t = RootTree(p, in_tree);
    best.phi = TreeYaws(p, t);
    const std::vector<double> r = Residuals(p, best.phi);
    best.cost = Cost(p, r);
    best.pivots = pivot;

    std::vector<double> g(p.edges(), 0.0);
    for (std::size_t e = 0; e < p.edges(); ++e) {
      if (t.in_tree[e]) continue;
      g[e] = std::abs(r[e]) > kZeroResidualRad ? std::copysign(p.weight[e], r[e])
                                               : std::clamp(g_hint[e], -p.weight[e], p.weight[e]);
    }
    CompleteTreeFlows(p, t, &g);
    std::size_t leaving = kNone;
    double worst = kCertifyTolerance;
    for (std::size_t e = 0; e < p.edges(); ++e) {
      if (!t.in_tree[e]) continue;
      const double violation = std::abs(g[e]) / p.weight[e] - 1.0;
      if (violation > worst) {
        worst = violation;
        leaving = e;
      }
    }
    if (leaving == kNone) {
      best.certified = true;
      break;
    }
    if (pivot >= max_pivots) break;
    const std::size_t child = t.parent_edge[p.r[leaving]] == leaving ? p.r[leaving] : p.s[leaving];
    const CutLine line = MinimiseAlongCut(p, t, r, child);
    if (line.t_lo <= 0.0 && 0.0 <= line.t_hi) break;  // no improving move along this cut
    // The minimiser nearest to the current position; its edge's residual becomes zero. The gain
    // is computed on the cut alone (the total cost would drown it in round-off).
    const Breakpoint& target = line.cut[line.t_lo > 0.0 ? line.lo : line.hi];
    double gain = 0.0;
    for (const Breakpoint& b : line.cut) gain += b.w * (std::abs(b.t) - std::abs(target.t - b.t));
    if (!(gain > 0.0)) break;
    in_tree[leaving] = false;
    in_tree[target.e] = true;
  }
  return best;
}

// The vote with the most supporting weight within `tol` (ties: the first), refined to the
// weighted circular mean of its supporters.
double Consensus(const std::vector<double>& vote, const std::vector<double>& weight, double tol) {
  std::size_t best = 0;
  double best_support = -1.0;
  for (std::size_t k = 0; k < vote.size(); ++k) {
    double support = 0.0;
    for (std::size_t j = 0; j < vote.size(); ++j) {
      if (std::abs(common::AngleDiff(vote[j], vote[k])) <= tol) support += weight[j];
    }
    if (support > best_support) {
      best_support = support;
      best = k;
    }
  }
  double sum = 0.0;
  for (std::size_t j = 0; j < vote.size(); ++j) {
    const double d = common::AngleDiff(vote[j], vote[best]);
    if (std::abs(d) <= tol) sum += weight[j] * d;
  }
  return common::NormalizeAngle(vote[best] + sum / best_support);
}

}  // namespace

std::vector<double> ConsensusYaws(std::size_t n, std::size_t reference,
                                  const std::vector<RelativeMeasurement>& measurements,
                                  bool use_weights, double consensus_tol_rad, int sweeps) {
  NodeProblem p = MakeProblem(n, reference, measurements, use_weights);
  std::vector<double> yaw(n, 0.0);
  if (reference >= n) return yaw;
  // Votes count by the cycle consistency of their measurement: an outlier rarely closes a
  // triangle, so its vote weighs little wherever the graph has triangles.
  const std::vector<std::size_t> triangles =
      ConsistentTriangles(n, measurements, std::sqrt(3.0) * consensus_tol_rad);
  for (std::size_t e = 0; e < p.edges(); ++e) {
    p.weight[e] *= 0.1 + static_cast<double>(triangles[e]);
  }
  std::vector<bool> placed(n, false);
  std::vector<double> placed_weight(n, 0.0);
  std::vector<std::size_t> order;
  std::vector<double> vote, weight;
  auto votes_for = [&](std::size_t v, bool only_placed) {
    vote.clear();
    weight.clear();
    for (std::size_t e : p.adjacent[v]) {
      const std::size_t u = p.r[e] == v ? p.s[e] : p.r[e];
      if (only_placed && !placed[u]) continue;
      // φ_r = φ_s + θ
      vote.push_back(v == p.r[e] ? yaw[u] + p.theta[e] : yaw[u] - p.theta[e]);
      weight.push_back(p.weight[e]);
    }
  };
  auto place = [&](std::size_t v) {
    placed[v] = true;
    order.push_back(v);
    for (std::size_t e : p.adjacent[v]) {
      placed_weight[p.r[e] == v ? p.s[e] : p.r[e]] += p.weight[e];
    }
  };
  place(reference);
  for (std::size_t step = 1; step < n; ++step) {
    std::size_t next = kNone;
    for (std::size_t v = 0; v < n; ++v) {
      if (!placed[v] && placed_weight[v] > 0.0 &&
          (next == kNone || placed_weight[v] > placed_weight[next])) {
        next = v;
      }
    }
    if (next == kNone) break;  // not connected: the rest stays at 0
    votes_for(next, true);
    yaw[next] = Consensus(vote, weight, consensus_tol_rad);
    place(next);
  }
  for (int sweep = 0; sweep < sweeps; ++sweep) {
    double change = 0.0;
    for (std::size_t v : order) {
      if (v == reference) continue;
      votes_for(v, true);
      const double updated = Consensus(vote, weight, consensus_tol_rad);
      change = std::max(change, std::abs(common::AngleDiff(updated, yaw[v])));
      yaw[v] = updated;
    }
    if (change < 1e-12) break;
  }
  return yaw;
}

std::vector<std::size_t> ConsistentTriangles(std::size_t n,
                                             const std::vector<RelativeMeasurement>& measurements,
                                             double tol_rad) {
  const NodeProblem p = MakeProblem(n, 0, measurements, false);
  std::vector<std::size_t> count(p.edges(), 0);
  // d(e, a): φ_b - φ_a along edge e from its end a to its other end b (φ_r - φ_s = θ).
  auto d = [&](std::size_t e, std::size_t a) { return a == p.s[e] ? p.theta[e] : -p.theta[e]; };
  auto other = [&](std::size_t e, std::size_t a) { return a == p.r[e] ? p.s[e] : p.r[e]; };
  // Every triangle u < v < w once: edges e1 = (u, v), e2 = (v, w), e3 = (w, u).
  std::vector<std::vector<std::size_t>> to(n);  // edges from u to the neighbour w, for lookup
  for (std::size_t u = 0; u < n; ++u) {
    for (std::size_t e3 : p.adjacent[u]) {
      const std::size_t w = other(e3, u);
      if (w > u) to[w].push_back(e3);
    }
    for (std::size_t e1 : p.adjacent[u]) {
      const std::size_t v = other(e1, u);
      if (v <= u) continue;
      for (std::size_t e2 : p.adjacent[v]) {
        const std::size_t w = other(e2, v);
        if (w <= v) continue;
        for (std::size_t e3 : to[w]) {
          if (other(e3, w) != u) continue;
          const double sum = d(e1, u) + d(e2, v) + d(e3, w);
          if (std::abs(common::NormalizeAngle(sum)) <= tol_rad) {
            ++count[e1];
            ++count[e2];
            ++count[e3];
          }
        }
      }
    }
    for (std::size_t e3 : p.adjacent[u]) {
      const std::size_t w = other(e3, u);
      if (w > u) to[w].clear();
    }
  }
  return count;
}

std::vector<double> ConsistentTreeYaws(std::size_t n, std::size_t reference,
                                       const std::vector<RelativeMeasurement>& measurements,
                                       bool use_weights, double triangle_tol_rad) {
  NodeProblem p = MakeProblem(n, reference, measurements, use_weights);
  if (reference >= n) return std::vector<double>(n, 0.0);
  const std::vector<std::size_t> count = ConsistentTriangles(n, measurements, triangle_tol_rad);
  std::vector<double> key(p.edges());
  for (std::size_t e = 0; e < p.edges(); ++e) key[e] = -static_cast<double>(count[e]);
  const Tree t = RootTree(p, KruskalTree(p, key));
  std::vector<double> yaw = TreeYaws(p, t);
  for (double& y : yaw) y = common::NormalizeAngle(y);
  return yaw;
}

std::optional<std::string> Validate(const RotationAveragingOptions& o) {
  if (!(o.irls_epsilon > 0.0) || !std::isfinite(o.irls_epsilon)) return "irls_epsilon must be > 0";
  if (!(o.initial_epsilon >= o.irls_epsilon) || !std::isfinite(o.initial_epsilon)) {
    return "initial_epsilon must be finite and >= irls_epsilon";
  }
  if (!(o.epsilon_factor > 0.0 && o.epsilon_factor <= 1.0))
    return "epsilon_factor must be in (0, 1]";
  if (o.max_iterations < 1) return "max_iterations must be >= 1";
  if (o.max_offset_rounds < 1) return "max_offset_rounds must be >= 1";
  if (!(o.tolerance >= 0.0) || !std::isfinite(o.tolerance))
    return "tolerance must be finite and >= 0";
  if (!(o.outlier_threshold_deg > 0.0 && o.outlier_threshold_deg <= 180.0)) {
    return "outlier_threshold_deg must be in (0, 180]";
  }
  if (!(o.prior_sigma_deg > 0.0) || !std::isfinite(o.prior_sigma_deg)) {
    return "prior_sigma_deg must be finite and > 0";
  }
  for (double yaw : o.initial_yaw_rad) {
    if (!std::isfinite(yaw)) return "initial_yaw_rad must be finite";
  }
  return std::nullopt;
}

std::vector<double> LeastSquaresYaws(std::size_t n, std::size_t reference,
                                     const std::vector<RelativeMeasurement>& measurements,
                                     bool use_weights, const std::vector<double>& branch_yaw_rad) {
  NodeProblem p = MakeProblem(n, reference, measurements, use_weights);
  std::vector<double> phi(n, 0.0);
  if (branch_yaw_rad.size() != n) return phi;
  NormaliseOffsets(branch_yaw_rad, &p);
  Solver solver;
  bool analysed = false;
  if (!SolveWeighted(p, p.weight, &solver, &analysed, &phi)) return std::vector<double>(n, 0.0);
  for (double& y : phi) y = common::NormalizeAngle(y);
  return phi;
}

void FillRotationDiagnostics(std::size_t n, std::size_t reference,
                             const std::vector<RelativeMeasurement>& measurements,
                             const RotationAveragingOptions& options,
                             RotationAveragingResult* result) {
  const std::vector<double>& yaw = result->yaw_rad;
  const double threshold_rad = common::DegToRad(options.outlier_threshold_deg);
  result->residual_rad.assign(measurements.size(), 0.0);
  result->inlier.assign(measurements.size(), true);
  result->l1_cost = 0.0;
  for (std::size_t e = 0; e < measurements.size(); ++e) {
    const RelativeMeasurement& m = measurements[e];
    const double r = common::NormalizeAngle(yaw[m.r] - yaw[m.s] - m.s_from_r.yaw_rad);
    result->residual_rad[e] = r;
    result->inlier[e] = std::abs(r) <= threshold_rad;
    result->l1_cost += (options.use_weights ? m.weight : 1.0) * std::abs(r);
  }

  // Yaw σ: weighted least squares on the inlier edges (all edges if the inliers do not connect
  // the graph) at the offsets of the given yaws.
  std::vector<RelativeMeasurement> kept;
  for (std::size_t e = 0; e < measurements.size(); ++e) {
    if (result->inlier[e]) kept.push_back(measurements[e]);
  }
  if (!UnconnectedNodes(n, reference, kept).empty()) kept = measurements;
  NodeProblem p = MakeProblem(n, reference, kept, options.use_weights);
  NormaliseOffsets(yaw, &p);
  Solver solver;
  bool analysed = false;
  std::vector<double> phi_ls;
  result->yaw_sigma_rad.assign(n, 0.0);
  if (!SolveWeighted(p, p.weight, &solver, &analysed, &phi_ls)) return;
  const std::vector<double> r = Residuals(p, phi_ls);
  double chi2 = 0.0;
  for (std::size_t e = 0; e < p.edges(); ++e) chi2 += p.weight[e] * r[e] * r[e];
  const long dof = static_cast<long>(p.edges()) - static_cast<long>(n - 1);
  const double prior = common::DegToRad(options.prior_sigma_deg);
  // Without redundancy the prior is the σ of a measurement of average weight.
  double mean_weight = 0.0;
  for (double w : p.weight) mean_weight += w / static_cast<double>(p.edges());
  const double variance = dof > 0 ? chi2 / static_cast<double>(dof) : prior * prior * mean_weight;
  const auto unknowns = static_cast<Eigen::Index>(n - 1);
  const Eigen::MatrixXd inverse = solver.solve(Eigen::MatrixXd::Identity(unknowns, unknowns));
  for (std::size_t v = 0; v < n; ++v) {
    if (p.column[v] >= 0) {
      result->yaw_sigma_rad[v] =
          std::sqrt(std::max(0.0, variance * inverse(p.column[v], p.column[v])));
    }
  }
}

namespace {

// One solve of the node form from a start: offsets normalised against the start, IRLS + exact
// finish, offsets re-normalised against the solution until they no longer change.
struct Run {
  bool ok = false;
  std::vector<double> phi;
  double cost = 0.0;  // wrapped L1 cost
  bool certified = false;
  double lower_bound = 0.0;
  int iterations = 0;
  int pivots = 0;
  int rounds = 0;
};

double WrappedCost(const NodeProblem& p, const std::vector<double>& phi) {
  double cost = 0.0;
  for (std::size_t e = 0; e < p.edges(); ++e) {
    cost += p.weight[e] * std::abs(common::NormalizeAngle(phi[p.r[e]] - phi[p.s[e]] - p.theta[e]));
  }
  return cost;
}

Run SolveFrom(NodeProblem& p, std::vector<double> phi, const RotationAveragingOptions& options,
              Solver* solver, bool* analysed) {
  Run run;
  double total_weight = 0.0;
  for (double w : p.weight) total_weight += w;
  for (int round = 0; round < options.max_offset_rounds; ++round) {
    const bool changed = NormaliseOffsets(phi, &p);
    if (round > 0 && !changed) break;
    run.rounds = round + 1;
    run.certified = false;
    std::vector<double> best_phi = phi;
    double best_cost = Cost(p, Residuals(p, phi));
    double bound = -std::numeric_limits<double>::infinity();
    double epsilon = options.initial_epsilon;
    std::vector<double> current = phi;
    for (bool first = true; run.iterations < options.max_iterations; first = false) {
      // IRLS: the L1 cost majorised by a weighted quadratic at the current residuals, ε
      // shrinking geometrically (the IRLS only has to find the LP basis; the finish is exact).
      if (!first) epsilon = std::max(options.irls_epsilon, epsilon * options.epsilon_factor);
      const std::vector<double> r_old = Residuals(p, current);
      std::vector<double> c(p.edges());
      for (std::size_t e = 0; e < p.edges(); ++e) {
        c[e] = p.weight[e] / std::max(std::abs(r_old[e]), epsilon);
      }
      if (!SolveWeighted(p, c, solver, analysed, &current)) return run;
      ++run.iterations;
      const std::vector<double> r = Residuals(p, current);
      const double cost = Cost(p, r);
      if (cost < best_cost) {
        best_cost = cost;
        best_phi = current;
      }
      std::vector<double> g(p.edges());
      for (std::size_t e = 0; e < p.edges(); ++e) g[e] = c[e] * r[e];
      bound = std::max(bound, LowerBound(p, RootTree(p, SmallestResidualTree(p, r)), g));

      // The exact finish pays once the IRLS point is near the optimum (few pivots left).
      const bool near = best_cost - bound <= 1e-3 * best_cost || epsilon <= kFinishEpsilon ||
                        epsilon <= options.irls_epsilon;
      if (!near) continue;
      const Finish finish = FinishExactly(p, r, g, 10 * static_cast<int>(p.n));
      run.pivots += finish.pivots;
      // (Certified is optimal; the slack only absorbs round-off, e.g. of a zero cost.)
      if (finish.certified && finish.cost <= best_cost * (1.0 + 1e-12) + 1e-13 * total_weight) {
        best_cost = finish.cost;
        best_phi = finish.phi;
        bound = std::max(bound, finish.cost);
        run.certified = true;
        break;
      }
      if (finish.cost < best_cost) {
        best_cost = finish.cost;
        best_phi = finish.phi;
      }
      if (best_cost - bound <= options.tolerance * best_cost + 1e-15 * total_weight) break;
    }
    phi = best_phi;
    run.lower_bound = bound;
    if (run.iterations >= options.max_iterations) break;
  }
  run.ok = true;
  run.cost = WrappedCost(p, phi);
  run.phi = std::move(phi);
  return run;
}

}  // namespace

std::optional<std::string> CheckRotationProblem(std::size_t n, std::size_t reference,
                                                const std::vector<RelativeMeasurement>& measurements,
                                                const RotationAveragingOptions& options) {
  if (auto error = Validate(options)) return "invalid options: " + *error;
  if (auto error = CheckGraphInput(n, reference, measurements)) return error;
  return ConnectivityError(n, reference, measurements);
}

RotationAveragingResult AverageRotationsL1(std::size_t n, std::size_t reference,
                                           const std::vector<RelativeMeasurement>& measurements,
                                           const RotationAveragingOptions& options) {
  RotationAveragingResult result;
  if (auto error = CheckRotationProblem(n, reference, measurements, options)) {
    result.error = *error;
    return result;
  }
  if (!options.initial_yaw_rad.empty() && options.initial_yaw_rad.size() != n) {
    result.error = "initial_yaw_rad has " + std::to_string(options.initial_yaw_rad.size()) +
                   " values for " + std::to_string(n) + " nodes";
    return result;
  }

  // Starts. The wrapped cost has local minima (a block of nodes turned by a wrong 2π branch of
  // the measurements between it and the rest), so several starts are solved and the lowest cost
  // is kept; all of them discount the measurements that close no consistent triangle.
  std::vector<std::vector<double>> starts;
  const double tol_rad = common::DegToRad(options.outlier_threshold_deg);
  const std::vector<std::size_t> triangles =
      ConsistentTriangles(n, measurements, std::sqrt(3.0) * tol_rad);
  if (options.initial_yaw_rad.size() == n) {
    starts.push_back(options.initial_yaw_rad);
  } else {
    starts.push_back(ConsensusYaws(n, reference, measurements, options.use_weights, tol_rad));
    if (options.multi_start) {
      std::vector<RelativeMeasurement> discounted = measurements;
      for (std::size_t e = 0; e < discounted.size(); ++e) {
        discounted[e].weight = (options.use_weights ? discounted[e].weight : 1.0) *
                               (0.1 + static_cast<double>(triangles[e]));
      }
      starts.push_back(SpectralYaws(n, reference, discounted, true));
      starts.push_back(ConsistentTreeYaws(n, reference, measurements, options.use_weights,
                                          std::sqrt(3.0) * tol_rad));
    }
  }

  NodeProblem p = MakeProblem(n, reference, measurements, options.use_weights);
  // Ties (a flat optimal face, e.g. a node held by as much weight on either side) are broken
  // towards the measurements that close consistent triangles: their weight grows by at most
  // kTieBreak relative, which moves the optimal cost by at most that much.
  std::size_t most = 0;
  for (std::size_t count : triangles) most = std::max(most, count);
  for (std::size_t e = 0; e < p.edges(); ++e) {
    p.weight[e] *=
        1.0 + kTieBreak * static_cast<double>(triangles[e]) / static_cast<double>(1 + most);
  }
  Solver solver;
  bool analysed = false;
  Run best;
  for (const std::vector<double>& start : starts) {
    Run run = SolveFrom(p, start, options, &solver, &analysed);
    if (!run.ok) {
      result.error = "rotation averaging: the weighted normal equations are singular";
      return result;
    }
    result.iterations += run.iterations;
    result.pivots += run.pivots;
    ++result.starts;
    if (!best.ok || run.cost < best.cost * (1.0 - 1e-12)) best = std::move(run);
  }

  result.ok = true;
  result.certified = best.certified;
  result.l1_lower_bound = best.lower_bound / (1.0 + kTieBreak);  // valid for the unscaled weights
  result.offset_rounds = best.rounds;
  result.yaw_rad.assign(n, 0.0);
  for (std::size_t v = 0; v < n; ++v) {
    result.yaw_rad[v] = common::NormalizeAngle(best.phi[v] - best.phi[reference]);
  }
  result.yaw_rad[reference] = 0.0;
  FillRotationDiagnostics(n, reference, measurements, options, &result);
  if (options.inlier_least_squares) {
    std::vector<RelativeMeasurement> inliers;
    for (std::size_t e = 0; e < measurements.size(); ++e) {
      if (result.inlier[e]) inliers.push_back(measurements[e]);
    }
    if (UnconnectedNodes(n, reference, inliers).empty()) {
      result.yaw_rad = LeastSquaresYaws(n, reference, inliers, options.use_weights, result.yaw_rad);
      FillRotationDiagnostics(n, reference, measurements, options, &result);
    }
  }
  return result;
}

namespace {

// The generic exact finish at one active set S: x from the rows in S, and the LP dual on them from
// A_S^T g_S = -A_N^T g_N with g_N = w sign(r_N) (the solution nearest to the IRLS flow, as the
// dual is not unique at a degenerate vertex). Optimal iff the rows in S hold exactly and
// |g_S| <= w_S (up to kCertifyTolerance); false otherwise or when S does not determine x.
bool FinishGenericAt(const SparseMatrix& a, const Eigen::VectorXd& b, const Eigen::VectorXd& weight,
                     const Eigen::VectorXd& g_irls, const std::vector<bool>& active,
                     Eigen::VectorXd* x_out, double* cost_out) {
  const Eigen::Index rows = a.rows();
  Eigen::VectorXd mask(rows);
  for (Eigen::Index i = 0; i < rows; ++i) mask(i) = active[static_cast<std::size_t>(i)] ? 1.0 : 0.0;
  const SparseMatrix as = mask.asDiagonal() * a;  // inactive rows zeroed
  const SparseMatrix ast = as.transpose();
  Solver solver(ast * as);
  if (solver.info() != Eigen::Success) return false;
  const Eigen::VectorXd x = solver.solve(ast * mask.cwiseProduct(b));
  if (solver.info() != Eigen::Success || !x.allFinite()) return false;
  const Eigen::VectorXd r = a * x - b;
  const double scale = 1.0 + b.cwiseAbs().maxCoeff();
  Eigen::VectorXd g_n = Eigen::VectorXd::Zero(rows);
  for (Eigen::Index i = 0; i < rows; ++i) {
    if (active[static_cast<std::size_t>(i)]) {
      if (std::abs(r(i)) > 1e-9 * scale) return false;  // the active rows are not consistent
    } else {
      g_n(i) = std::copysign(weight(i), r(i));
    }
  }
  Eigen::VectorXd g_s = mask.cwiseProduct(g_irls);
  g_s += as * solver.solve(-(a.transpose() * g_n) - ast * g_s);
  for (Eigen::Index i = 0; i < rows; ++i) {
    if (active[static_cast<std::size_t>(i)] &&
        std::abs(g_s(i)) > weight(i) * (1.0 + kCertifyTolerance)) {
      return false;
    }
  }
  if ((a.transpose() * (g_n + g_s)).cwiseAbs().maxCoeff() > 1e-9 * weight.cwiseAbs().sum())
    return false;
  *x_out = x;
  *cost_out = weight.dot(r.cwiseAbs());
  return true;
}

// Active sets from the IRLS residuals: at least as many rows as unknowns, cut where the sorted
// |residual| jumps most (a degenerate vertex, e.g. the full form's constraint rows, has more
// active rows than unknowns, left by the IRLS orders of magnitude below the others); the few
// largest jumps are tried in turn, as the smallest rows alone may not determine x.
bool FinishGeneric(const SparseMatrix& a, const Eigen::VectorXd& b, const Eigen::VectorXd& weight,
                   const Eigen::VectorXd& r_irls, const Eigen::VectorXd& g_irls,
                   Eigen::VectorXd* x_out, double* cost_out) {
  const Eigen::Index rows = a.rows(), cols = a.cols();
  if (rows <= cols) return false;
  std::vector<Eigen::Index> order(static_cast<std::size_t>(rows));
  std::iota(order.begin(), order.end(), Eigen::Index{0});
  std::sort(order.begin(), order.end(), [&](Eigen::Index i, Eigen::Index j) {
    return std::abs(r_irls(i)) < std::abs(r_irls(j));
  });
  std::vector<std::pair<double, Eigen::Index>> jumps;  // (ratio, last active position)
  for (Eigen::Index k = cols - 1; k + 1 < rows; ++k) {
    const double here = std::max(std::abs(r_irls(order[static_cast<std::size_t>(k)])), 1e-300);
    jumps.emplace_back(std::abs(r_irls(order[static_cast<std::size_t>(k + 1)])) / here, k);
  }
  const std::size_t tries = std::min<std::size_t>(4, jumps.size());
  std::partial_sort(jumps.begin(), jumps.begin() + static_cast<std::ptrdiff_t>(tries), jumps.end(),
                    [](const auto& x, const auto& y) { return x.first > y.first; });
  for (std::size_t t = 0; t < tries; ++t) {
    std::vector<bool> active(static_cast<std::size_t>(rows), false);
    for (Eigen::Index k = 0; k <= jumps[t].second; ++k) {
      active[static_cast<std::size_t>(order[static_cast<std::size_t>(k)])] = true;
    }
    if (FinishGenericAt(a, b, weight, g_irls, active, x_out, cost_out)) return true;
  }
  return false;
}

}  // namespace

L1IrlsResult SolveL1Irls(const Eigen::SparseMatrix<double>& a, const Eigen::VectorXd& b,
                         const Eigen::VectorXd& weight, const Eigen::VectorXd& x0,
                         const L1IrlsOptions& options) {
  L1IrlsResult result;
  if (a.rows() != b.size() || a.rows() != weight.size()) return result;
  Eigen::VectorXd x = x0.size() == a.cols() ? x0 : Eigen::VectorXd::Zero(a.cols());
  const SparseMatrix at = a.transpose();
  Solver solver;
  bool analysed = false;
  // For the dual bound: g must satisfy A^T g = 0 exactly, which the IRLS flow does only up to the
  // round-off of a badly scaled solve; it is projected with the well-conditioned A^T A.
  Solver projector(at * a);
  if (projector.info() != Eigen::Success) return result;
  double epsilon = options.initial_epsilon;
  double best_cost = std::numeric_limits<double>::infinity();
  double bound = -std::numeric_limits<double>::infinity();
  Eigen::VectorXd best_x = x;
  for (int it = 0; it < options.max_iterations; ++it) {
    if (it > 0) epsilon = std::max(options.final_epsilon, epsilon * options.epsilon_factor);
    const Eigen::VectorXd r_old = a * x - b;
    const Eigen::VectorXd c = weight.array() / r_old.array().abs().max(epsilon);
    const SparseMatrix normal = at * c.asDiagonal() * a;
    if (!analysed) {
      solver.analyzePattern(normal);
      analysed = true;
    }
    solver.factorize(normal);
    if (solver.info() != Eigen::Success) return result;
    x = solver.solve(at * c.cwiseProduct(b));
    if (solver.info() != Eigen::Success || !x.allFinite()) return result;
    ++result.iterations;
    const Eigen::VectorXd r = a * x - b;
    const double cost = weight.dot(r.cwiseAbs());
    if (cost < best_cost) {
      best_cost = cost;
      best_x = x;
    }
    // g = C r (A^T g = 0 up to round-off), projected onto A^T g = 0 and scaled into |g| <= w:
    // a dual-feasible point, so -g^T b bounds the optimum from below.
    Eigen::VectorXd g = c.cwiseProduct(r);
    g -= a * projector.solve(at * g);
    const double scale = std::max(1.0, (g.cwiseAbs().array() / weight.array()).maxCoeff());
    bound = std::max(bound, -(g / scale).dot(b));
    if (best_cost - bound <= options.tolerance * best_cost) break;
    if (best_cost - bound <= 1e-2 * best_cost) {
      Eigen::VectorXd vertex;
      double vertex_cost = 0.0;
      if (FinishGeneric(a, b, weight, r, c.cwiseProduct(r), &vertex, &vertex_cost) &&
          vertex_cost <= best_cost) {
        best_x = vertex;
        best_cost = vertex_cost;
        bound = vertex_cost;
        result.exact = true;
        break;
      }
    }
  }
  result.ok = true;
  result.x = best_x;
  result.cost = best_cost;
  result.lower_bound = bound;
  return result;
}

}  // namespace lrfnet::calib
