#include "firmware_tracker/tracking/shape_fit.h"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>
#if defined(__SSE__)
#include <xmmintrin.h>
#endif

#include "common/geometry.h"

namespace lrfnet::tracking {
namespace {

using Vec5 = Eigen::Matrix<double, 5, 1>;
using Mat5 = Eigen::Matrix<double, 5, 5>;

// Parameter indices.
constexpr int kCx = 0, kCy = 1, kYaw = 2, kA = 3, kB = 4;
// A weak prior on the centre (1 m around the start) keeps the normal matrix invertible when the
// data leave a direction open (one point, no silhouette edge); its variance then says so.
constexpr double kCentrePriorSigmaM = 1.0;
// Largest Gauss-Newton step per iteration.
constexpr double kMaxCentreStepM = 0.25;
constexpr double kMaxYawStepRad = 0.6;
constexpr double kMaxSizeStepM = 0.1;
// Steps below these end the iteration.
constexpr double kConvergedCentreM = 0.003;
constexpr double kConvergedYawRad = 0.05;
constexpr std::size_t kMaxFitPoints = 64;

bool Positive(double v) { return std::isfinite(v) && v > 0.0; }

// Eigen's allFinite without a branch per entry: x - x is 0 for a finite entry and NaN otherwise,
// and a NaN stays NaN through the sum.
template <class Derived>
bool AllFinite(const Eigen::MatrixBase<Derived>& m) {
  const double t = (m - m).sum();
  return t == t;
}

// Axis directions are defined modulo pi. Within (-pi/2, pi/2) (a yaw's deviation from its prior,
// nearly always) remainder(a, pi) is a itself, within 3 pi/2 (a fitted yaw) a -+ pi: no libm call
// there (common::RemainderHalfTurn).
double WrapHalfTurn(double a) {
  a = common::RemainderHalfTurn(a);
  if (a <= -common::kPi / 2) a += common::kPi;
  return a;
}

// Two values side by side, one per SIMD lane (SSE2, NEON): the fit's independent chains of square
// roots and divisions (two points, two silhouette edges) run together. The same IEEE operations in
// the same order as the scalar code, so the same results.
using Lanes = Eigen::Array2d;

// Distance of a point from the outline and its gradient with respect to x.
struct PointTerm {
  double d = 0.0;
  Vec5 grad = Vec5::Zero();
};

// The superellipse exponents with a path of their own (kAnyExponent: pow).
enum ExponentKind : int { kAnyExponent = 0, kExponent2 = 1, kExponent2_5 = 2 };

// |x|^p and d|x|^p / dx, the common exponents without pow or a division.
template <int kKind = kAnyExponent>
inline void PowerTerm(double x, double p, double* value, double* derivative) {
  if (kKind == kExponent2 || (kKind == kAnyExponent && p == 2.0)) {
    *value = x * x;
    *derivative = 2.0 * x;
    return;
  }
  const double ax = std::abs(x);
  if (kKind == kExponent2_5 || (kKind == kAnyExponent && p == 2.5)) {
    const double root = std::sqrt(ax);
    *value = x * x * root;
    *derivative = 2.5 * x * root;
    return;
  }
  const double v = std::pow(ax, p);
  *value = v;
  *derivative = ax > 0.0 ? p * v / x : 0.0;
}

// x^(1/n) for the support function's powers, by Halley's iteration for r^n = x from a first guess
// built from the exponent bits (relative error at most 0.06 after the guess; cubic convergence:
// after two steps the cube root is within 1.2e-12 of libm's, the fifth root within 1.4e-10, over
// 1e-280..1e280: far below the points' noise; a third step (7e-16 and 8e-15) cost 1.3 us per
// 50-people scan and changed no fit by more than 1e-10 m). libm's cbrt and pow took several times
// as long, an eighth of the fit. Outside the normal range (0, subnormal, infinite, NaN) libm
// answers.
constexpr int kRootSteps = 2;

template <int kN>
double RootGuess(double x) {
  // A linear approximation of log2(x) / n in the exponent bits.
  constexpr std::uint64_t kOne = 0x3FF0000000000000ull;
  const auto bits = std::bit_cast<std::int64_t>(x);
  constexpr auto kOneBits = static_cast<std::int64_t>(kOne);
  return std::bit_cast<double>(kOneBits + (bits - kOneBits) / kN);
}

template <int kN>
double RootN(double x) {
  if (!(x >= 1e-290 && x <= 1e290)) return kN == 3 ? std::cbrt(x) : std::pow(x, 1.0 / kN);
  double r = RootGuess<kN>(x);
  for (int i = 0; i < kRootSteps; ++i) {
    double rn = r * r;  // r^n
    for (int k = 2; k < kN; ++k) rn *= r;
    r *= ((kN - 1) * rn + (kN + 1) * x) / ((kN + 1) * rn + (kN - 1) * x);
  }
  return r;
}

// RootN of two values at once (the same steps per lane).
template <int kN>
Lanes RootN(const Lanes& x) {
  if (!((x >= 1e-290).all() && (x <= 1e290).all())) return Lanes(RootN<kN>(x(0)), RootN<kN>(x(1)));
  Lanes r(RootGuess<kN>(x(0)), RootGuess<kN>(x(1)));
  constexpr double kLow = kN - 1, kHigh = kN + 1;
  for (int i = 0; i < kRootSteps; ++i) {
    Lanes rn = r * r;  // r^n
    for (int k = 2; k < kN; ++k) rn *= r;
    r *= (kLow * rn + kHigh * x) / (kHigh * rn + kLow * x);
  }
  return r;
}

// RootN of two pairs of values, x's and y's, in one sequence whose two chains of Halley steps
// interleave: the same steps per lane as RootN's (the same bits), but the second pair's divisions
// run while the first's are in flight instead of after them (the support function's two powers are
// independent of each other; called one after the other, each waited on its own chain).
template <int kN>
[[gnu::always_inline]] inline void RootNInterleaved(const Lanes& x, const Lanes& y, Lanes* root_x,
                                                    Lanes* root_y) {
  if (!((x >= 1e-290).all() && (x <= 1e290).all() && (y >= 1e-290).all() &&
        (y <= 1e290).all())) [[unlikely]] {
    *root_x = RootN<kN>(x);
    *root_y = RootN<kN>(y);
    return;
  }
  Lanes r(RootGuess<kN>(x(0)), RootGuess<kN>(x(1)));
  Lanes q(RootGuess<kN>(y(0)), RootGuess<kN>(y(1)));
  constexpr double kLow = kN - 1, kHigh = kN + 1;
  for (int i = 0; i < kRootSteps; ++i) {
    Lanes rn = r * r;  // r^n
    Lanes qn = q * q;  // q^n
    for (int k = 2; k < kN; ++k) {
      rn *= r;
      qn *= q;
    }
    r *= (kLow * rn + kHigh * x) / (kHigh * rn + kLow * x);
    q *= (kLow * qn + kHigh * y) / (kHigh * qn + kLow * y);
  }
  *root_x = r;
  *root_y = q;
}

// (cos_yaw, sin_yaw) of x(kYaw) and (inv_a, inv_b) = (1 / x(kA), 1 / x(kB)): the caller's, once
// per evaluation rather than per point. Instantiated per model and exponent kind for the fit's
// loop over the points (no branch on either per point; the same arithmetic).
template <ShapeModel kModel, int kKind>
[[gnu::always_inline]] inline PointTerm PointResidual(const Vec5& x, double cos_yaw, double sin_yaw,
                                                      double inv_a, double inv_b, double exponent,
                                                      const Eigen::Vector2d& p) {
  constexpr ShapeModel model = kModel;
  PointTerm t;
  const double dx = p.x() - x(kCx), dy = p.y() - x(kCy);
  if constexpr (model == ShapeModel::kCircle) {
    const double r = std::sqrt(dx * dx + dy * dy);
    t.d = r - x(kA);
    if (r > 1e-12) {
      t.grad(kCx) = -dx / r;
      t.grad(kCy) = -dy / r;
    }
    t.grad(kA) = -1.0;
    return t;
  }
  const double a = x(kA), b = x(kB);
  const double u = cos_yaw * dx + sin_yaw * dy;
  const double v = -sin_yaw * dx + cos_yaw * dy;
  // d/dq of d as (gu, gv) in the body frame; q = R^T (p - c): dq/dc = -R^T, dq/dyaw = (v, -u).
  double gu = 0.0, gv = 0.0;
  if constexpr (model == ShapeModel::kSuperellipse) {
    double s1 = 0.0, d1 = 0.0, s2 = 0.0, d2 = 0.0;
    PowerTerm<kKind>(u * inv_a, exponent, &s1, &d1);
    PowerTerm<kKind>(v * inv_b, exponent, &s2, &d2);
    const double su = d1 * inv_a, sv = d2 * inv_b;  // dS/du, dS/dv
    const double g2 = su * su + sv * sv;
    if (!(g2 > 1e-24)) {
      t.d = -std::min(a, b);  // at the centre
      return t;
    }
    // First-order (Sampson) distance; the gradient treats the normalisation 1 / |grad S| as
    // constant.
    const double inv_g = 1.0 / std::sqrt(g2);
    t.d = (s1 + s2 - 1.0) * inv_g;
    gu = su * inv_g;
    gv = sv * inv_g;
    t.grad(kA) = -gu * u * inv_a;
    t.grad(kB) = -gv * v * inv_b;
  } else {  // box: signed distance
    const double su = u < 0 ? -1.0 : 1.0, sv = v < 0 ? -1.0 : 1.0;
    const double du = std::abs(u) - a, dv = std::abs(v) - b;
    if (du > 0.0 && dv > 0.0) {
      t.d = std::sqrt(du * du + dv * dv);
      gu = su * du / t.d;
      gv = sv * dv / t.d;
      t.grad(kA) = -du / t.d;
      t.grad(kB) = -dv / t.d;
    } else if (du > dv) {
      t.d = du;
      gu = su;
      t.grad(kA) = -1.0;
    } else {
      t.d = dv;
      gv = sv;
      t.grad(kB) = -1.0;
    }
  }
  t.grad(kCx) = -(cos_yaw * gu - sin_yaw * gv);
  t.grad(kCy) = -(sin_yaw * gu + cos_yaw * gv);
  t.grad(kYaw) = gu * v - gv * u;
  return t;
}

// Support function h(n; x) and its gradient with respect to (yaw, a, b).
// (cos_yaw, sin_yaw) of x(kYaw): the caller's, computed once per evaluation. kLibmRoots: the
// exponent 2.5's powers by libm's cbrt and pow (as before RootN; the equivalence test's reference).
template <bool kLibmRoots = false>
double Support(ShapeModel model, const Vec5& x, double c, double s, const Eigen::Vector2d& n,
               double exponent, Vec5* grad) {
  if (model == ShapeModel::kCircle) {
    if (grad != nullptr) (*grad)(kA) = 1.0;
    return x(kA);
  }
  const double p = n.x() * c + n.y() * s;   // n . e1
  const double q = -n.x() * s + n.y() * c;  // n . e2; dp/dyaw = q, dq/dyaw = -p
  const double a = x(kA), b = x(kB);
  if (model == ShapeModel::kSuperellipse) {
    // The dual norm: h = (|a p|^k + |b q|^k)^(1/k), 1/exponent + 1/k = 1.
    const double k = exponent / (exponent - 1.0);
    const double ap = std::abs(a * p), bq = std::abs(b * q);
    // |x|^k: exponent 2.5 (the person model) has k = 5/3, x^(5/3) = x cbrt(x^2).
    // and h = t^(3/5) = (t^(1/5))^3.
    const bool five_thirds = std::abs(k - 5.0 / 3.0) < 1e-12;
    const auto power = [k, five_thirds](double v) {
      if (k == 2.0) return v * v;
      if (five_thirds) return v * (kLibmRoots ? std::cbrt(v * v) : RootN<3>(v * v));
      return std::pow(v, k);
    };
    double tp = 0.0, tq = 0.0;
    if (five_thirds && !kLibmRoots) {
      // The two cube roots side by side, one per lane (the same steps as one at a time).
      const Lanes root = RootN<3>(Lanes(ap * ap, bq * bq));
      tp = ap * root(0);
      tq = bq * root(1);
    } else {
      tp = power(ap);
      tq = power(bq);
    }
    const double t = tp + tq;
    if (!(t > 0.0)) return 0.0;
    double h = 0.0;
    if (k == 2.0) {
      h = std::sqrt(t);
    } else if (five_thirds && !kLibmRoots) {
      const double root = RootN<5>(t);
      h = root * root * root;
    } else {
      h = std::pow(t, 1.0 / k);
    }
    if (grad != nullptr) {
      const double scale = h / t;  // h^(1 - k)
      (*grad)(kA) = scale * tp / a;
      (*grad)(kB) = scale * tq / b;
      const double dtp = ap > 0.0 ? tp / p : 0.0;  // |a p|^k / p: sign of p included
      const double dtq = bq > 0.0 ? tq / q : 0.0;
      (*grad)(kYaw) = scale * (dtp * q - dtq * p);
    }
    return h;
  }
  if (grad != nullptr) {
    const double sp = p < 0 ? -1.0 : 1.0, sq = q < 0 ? -1.0 : 1.0;
    (*grad)(kYaw) = a * sp * q - b * sq * p;
    (*grad)(kA) = std::abs(p);
    (*grad)(kB) = std::abs(q);
  }
  return a * std::abs(p) + b * std::abs(q);
}

struct Edge {
  Eigen::Vector2d n = Eigen::Vector2d::Zero();  // normal of the edge ray, away from the body
  double weight = 0.0;                          // 1 / sigma^2
};

// Whether SupportPair serves the superellipse with this exponent (its dual exponent k = 2 or 5/3).
bool PairedSupport(ShapeModel model, double exponent) {
  if (model != ShapeModel::kSuperellipse) return false;
  const double k = exponent / (exponent - 1.0);
  return k == 2.0 || std::abs(k - 5.0 / 3.0) < 1e-12;
}

// Support<false> of a superellipse for the two silhouette edges at once (precondition:
// PairedSupport), each edge's chain of roots in one lane: h(n_e; x) and the gradients' (yaw, a, b)
// entries (left as they are where h is 0, as Support leaves them).
Lanes SupportPair(const Vec5& x, double c, double s, const Edge& e0, const Edge& e1,
                  double exponent, Vec5* grad0, Vec5* grad1) {
  const Lanes nx(e0.n.x(), e1.n.x()), ny(e0.n.y(), e1.n.y());
  const Lanes p = nx * c + ny * s;   // n . e1
  const Lanes q = -nx * s + ny * c;  // n . e2
  const double a = x(kA), b = x(kB);
  const Lanes ap = (a * p).abs(), bq = (b * q).abs();
  const bool square = exponent / (exponent - 1.0) == 2.0;
  // |x|^k: k = 2, or 5/3 (x^(5/3) = x cbrt(x^2)).
  Lanes tp, tq;
  if (square) {
    tp = ap * ap;
    tq = bq * bq;
  } else {
    Lanes root_p, root_q;
    RootNInterleaved<3>(Lanes(ap * ap), Lanes(bq * bq), &root_p, &root_q);
    tp = ap * root_p;
    tq = bq * root_q;
  }
  const Lanes t = tp + tq;
  Lanes h;
  if (square) {
    h = t.sqrt();
  } else {
    const Lanes root = RootN<5>(t);
    h = root * root * root;
  }
  const Lanes scale = h / t;
  const Lanes grad_a = scale * tp / a;
  const Lanes grad_b = scale * tq / b;
  Lanes dtp = tp / p, dtq = tq / q;  // 0 where the power is 0 (below)
  for (int e = 0; e < 2; ++e) {
    if (!(ap(e) > 0.0)) dtp(e) = 0.0;
    if (!(bq(e) > 0.0)) dtq(e) = 0.0;
  }
  const Lanes grad_yaw = scale * (dtp * q - dtq * p);
  Vec5* grads[2] = {grad0, grad1};
  for (int e = 0; e < 2; ++e) {
    if (!(t(e) > 0.0)) {
      h(e) = 0.0;
      continue;
    }
    (*grads[e])(kA) = grad_a(e);
    (*grads[e])(kB) = grad_b(e);
    (*grads[e])(kYaw) = grad_yaw(e);
  }
  return h;
}

// Sum of w g g^T, upper triangle, written out: the loops over a 5 x 5 block (or Eigen's rank
// update) cost several times the 15 products at this size. Two entries per SIMD lane pair: entry
// (r, c) is the sum of (w g_r) g_c in the order of the calls, as one entry at a time, so the same
// bits; the lanes take 8 multiplications and 9 additions per call instead of 20 and 15.
class UpperSum5 {
 public:
  [[gnu::always_inline]] void Add(const Vec5& gr, double w) {
    Add(Lanes(gr(0), gr(1)), Lanes(gr(2), gr(3)), gr(4), w);
  }
  // The gradient as (g0, g1), (g2, g3), g4.
  [[gnu::always_inline]] void Add(const Lanes& g01, const Lanes& g23, double g4, double w) {
    const Lanes w01 = w * g01;  // (w g0, w g1)
    const Lanes w23 = w * g23;  // (w g2, w g3)
    const double w0 = w01(0), w2 = w23(0), w4 = w * g4;
    const Lanes g22 = Lanes::Constant(g23(0)), g33 = Lanes::Constant(g23(1));
    const Lanes g44 = Lanes::Constant(g4);
    s00_11_ += w01 * g01;
    s02_12_ += w01 * g22;
    s03_13_ += w01 * g33;
    s04_14_ += w01 * g44;
    s22_33_ += w23 * g23;
    s24_34_ += w23 * g44;
    s01_ += w0 * g01(1);
    s23_ += w2 * g23(1);
    s44_ += w4 * g4;
  }
  // A sum formed elsewhere (in another order), handed in as the members hold it: the entries
  // (0, 0) and (1, 1) as one pair, (0, 2) and (1, 2) as the next, and so on.
  static UpperSum5 FromEntries(const Lanes& s00_11, const Lanes& s02_12, const Lanes& s03_13,
                               const Lanes& s04_14, const Lanes& s22_33, const Lanes& s24_34,
                               double s01, double s23, double s44) {
    UpperSum5 u;
    u.s00_11_ = s00_11;
    u.s02_12_ = s02_12;
    u.s03_13_ = s03_13;
    u.s04_14_ = s04_14;
    u.s22_33_ = s22_33;
    u.s24_34_ = s24_34;
    u.s01_ = s01;
    u.s23_ = s23;
    u.s44_ = s44;
    return u;
  }
  // The sum into m's upper triangle (the entries below it left as they are).
  void WriteUpper(Mat5& m) const {
    m(0, 0) = s00_11_(0);
    m(1, 1) = s00_11_(1);
    m(0, 1) = s01_;
    m(0, 2) = s02_12_(0);
    m(1, 2) = s02_12_(1);
    m(0, 3) = s03_13_(0);
    m(1, 3) = s03_13_(1);
    m(0, 4) = s04_14_(0);
    m(1, 4) = s04_14_(1);
    m(2, 2) = s22_33_(0);
    m(3, 3) = s22_33_(1);
    m(2, 3) = s23_;
    m(2, 4) = s24_34_(0);
    m(3, 4) = s24_34_(1);
    m(4, 4) = s44_;
  }

 private:
  Lanes s00_11_ = Lanes::Zero(), s02_12_ = Lanes::Zero(), s03_13_ = Lanes::Zero();
  Lanes s04_14_ = Lanes::Zero(), s22_33_ = Lanes::Zero(), s24_34_ = Lanes::Zero();
  double s01_ = 0.0, s23_ = 0.0, s44_ = 0.0;
};

// The points' part of the fit's objective at x (Huber, see Fit's evaluate): the normal matrix's
// sum, gradient, cost and sum of squared distances, for one model and exponent kind. The gradient
// as (g0, g1), (g2, g3), g4 like UpperSum5 (each entry the same sum in the same order).
struct PointSums {
  UpperSum5 outer;
  Lanes g01 = Lanes::Zero(), g23 = Lanes::Zero();
  double g4 = 0.0;
  double cost = 0.0;
  double sq = 0.0;

  // One point's gradient, weight w and weighted distance wd = w d.
  [[gnu::always_inline]] void Add(const Lanes& grad01, const Lanes& grad23, double grad4, double w,
                                  double wd) {
    outer.Add(grad01, grad23, grad4, w);
    g01 += wd * grad01;
    g23 += wd * grad23;
    g4 += wd * grad4;
  }
  [[gnu::always_inline]] void Add(const Vec5& grad, double w, double wd) {
    Add(Lanes(grad(0), grad(1)), Lanes(grad(2), grad(3)), grad(4), w, wd);
  }
  Vec5 Gradient() const {
    Vec5 v;
    v << g01(0), g01(1), g23(0), g23(1), g4;
    return v;
  }
};

template <ShapeModel kModel, int kKind>
void SumPoints(const Vec5& at, double c, double s, double inv_a, double inv_b, double exponent,
               std::span<const Eigen::Vector2d> points, const double* base_weight, double discount,
               double k2, PointSums& sums) {
  for (std::size_t i = 0; i < points.size(); ++i) {
    const PointTerm t = PointResidual<kModel, kKind>(at, c, s, inv_a, inv_b, exponent, points[i]);
    const double z2 = t.d * t.d * base_weight[i] * discount / k2;  // (s / k)^2
    const double z = z2 > 1.0 ? std::sqrt(z2) : 1.0;
    const double w = base_weight[i] / z;
    sums.Add(t.grad, w, w * t.d);
    sums.cost += k2 / discount * (z2 > 1.0 ? 2.0 * z - 1.0 : z2);
    sums.sq += t.d * t.d;
  }
}

// |x|^p and its derivative of two values (PowerTerm's arithmetic; p = 2 or 2.5).
template <int kKind>
inline void PowerTerm(const Lanes& x, Lanes* value, Lanes* derivative) {
  static_assert(kKind == kExponent2 || kKind == kExponent2_5);
  if constexpr (kKind == kExponent2) {
    *value = x * x;
    *derivative = 2.0 * x;
  } else {
    const Lanes root = x.abs().sqrt();
    *value = x * x * root;
    *derivative = 2.5 * x * root;
  }
}

// SumPoints of the superellipse with exponent 2 or 2.5, two points at a time: PointResidual's and
// the Huber weight's arithmetic per lane (their square roots and divisions side by side), the sums
// taken point by point in order as SumPoints does, so the same result.
template <int kKind>
void SumPointsPaired(const Vec5& at, double c, double s, double inv_a, double inv_b, double,
                     std::span<const Eigen::Vector2d> points, const double* base_weight,
                     double discount, double k2, PointSums& sums) {
  const std::size_t n = points.size();
  const double cx = at(kCx), cy = at(kCy);
  const double centre_d = -std::min(at(kA), at(kB));  // a point at the centre
  // First every pair's distances, gradients and weights (independent chains of square roots and
  // divisions that the processor overlaps), then the sums point by point.
  constexpr std::size_t kPairs = kMaxFitPoints / 2;
  std::array<Lanes, kPairs> dist, grad_cx, grad_cy, grad_yaw, grad_a, grad_b, w, z2, z;
  for (std::size_t i = 0, k = 0; i < n; i += 2, ++k) {
    const std::size_t j = i + 1 < n ? i + 1 : i;  // an odd count: the last point twice, summed once
    const Lanes dx = Lanes(points[i].x(), points[j].x()) - cx;
    const Lanes dy = Lanes(points[i].y(), points[j].y()) - cy;
    const Lanes u = c * dx + s * dy;
    const Lanes v = -s * dx + c * dy;
    Lanes s1, d1, s2, d2;
    PowerTerm<kKind>(u * inv_a, &s1, &d1);
    PowerTerm<kKind>(v * inv_b, &s2, &d2);
    const Lanes su = d1 * inv_a, sv = d2 * inv_b;
    const Lanes g2 = su * su + sv * sv;
    const Lanes inv_g = g2.sqrt().inverse();
    // No per-lane selects in the lanes (Eigen evaluates them one value at a time, and a value
    // stored alone then loaded as a pair stalls the store forwarding): the rare exceptions are
    // mended afterwards.
    dist[k] = (s1 + s2 - 1.0) * inv_g;
    const Lanes gu = su * inv_g, gv = sv * inv_g;
    grad_cx[k] = -(c * gu - s * gv);
    grad_cy[k] = -(s * gu + c * gv);
    grad_yaw[k] = gu * v - gv * u;
    grad_a[k] = -gu * u * inv_a;
    grad_b[k] = -gv * v * inv_b;
    if (!(g2(0) > 1e-24) || !(g2(1) > 1e-24)) {
      for (int l = 0; l < 2; ++l) {
        if (g2(l) > 1e-24) continue;
        dist[k](l) = centre_d;
        grad_cx[k](l) = grad_cy[k](l) = grad_yaw[k](l) = grad_a[k](l) = grad_b[k](l) = 0.0;
      }
    }
    // Huber weights (SumPoints): z = max(1, |s| / k) (the square root of 1 is 1 exactly). Most
    // pairs have both points within k sigma: their weights need no root and no division.
    const Lanes weight(base_weight[i], base_weight[j]);
    z2[k] = dist[k] * dist[k] * weight * discount / k2;
    if (z2[k](0) > 1.0 || z2[k](1) > 1.0) {
      z[k] = z2[k].max(1.0).sqrt();
      w[k] = weight / z[k];
    } else {
      z[k] = Lanes::Ones();
      w[k] = weight;
    }
  }
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t k = i / 2;
    const auto l = static_cast<Eigen::Index>(i % 2);
    const double d = dist[k](l);
    sums.Add(Lanes(grad_cx[k](l), grad_cy[k](l)), Lanes(grad_yaw[k](l), grad_a[k](l)), grad_b[k](l),
             w[k](l), w[k](l) * d);
    const double zz = z2[k](l);
    sums.cost += k2 / discount * (zz > 1.0 ? 2.0 * z[k](l) - 1.0 : zz);
    sums.sq += d * d;
  }
}

using SumPointsFn = void (*)(const Vec5&, double, double, double, double, double,
                             std::span<const Eigen::Vector2d>, const double*, double, double,
                             PointSums&);

// The sums of a SumPointsFn from zero.
PointSums SumPointsFrom(SumPointsFn sum_points, const Vec5& at, double c, double s, double inv_a,
                        double inv_b, double exponent, std::span<const Eigen::Vector2d> points,
                        const double* base_weight, double discount, double k2) {
  PointSums sums;
  sum_points(at, c, s, inv_a, inv_b, exponent, points, base_weight, discount, k2, sums);
  return sums;
}

// paired: SumPointsPaired where it serves (the same results as SumPoints).
SumPointsFn SumPointsFor(ShapeModel model, double exponent, bool paired) {
  switch (model) {
    case ShapeModel::kCircle:
      return &SumPoints<ShapeModel::kCircle, kAnyExponent>;
    case ShapeModel::kBox:
      return &SumPoints<ShapeModel::kBox, kAnyExponent>;
    case ShapeModel::kSuperellipse:
      break;
  }
  if (exponent == 2.0) {
    return paired ? &SumPointsPaired<kExponent2>
                  : &SumPoints<ShapeModel::kSuperellipse, kExponent2>;
  }
  if (exponent == 2.5) {
    return paired ? &SumPointsPaired<kExponent2_5>
                  : &SumPoints<ShapeModel::kSuperellipse, kExponent2_5>;
  }
  return &SumPoints<ShapeModel::kSuperellipse, kAnyExponent>;
}

// The points of a superellipse fit (exponent 2 or 2.5) in single precision, four per SIMD lane
// group (ShapeFitOptions::single_precision_points): SumPointsPaired's distances, gradients and
// Huber weights with twice the points per instruction; the Sampson distance's 1 / |grad S| as a
// reciprocal square root (Eigen's: the estimate and one Newton step, within a few ulp of float).
// The points are held relative to their mean (a body's points lie within about a metre of it,
// where float's 24 bits resolve 0.1 um), the centre's offset from that origin is formed in double
// and then rounded. Each lane sums its points; the four lanes are added at the end and the sums
// continue in double (edges, priors, solver). Rounding: about 1e-7 relative on each distance and
// each sum, i.e. about 1e-8 m on a distance, about a million times below a point's range noise
// (point_sigma_m); the Gauss-Newton step inherits it, the solve and the covariance stay in double
// (shape_fit_test: over 598 random fits the centres differ by 8e-9 m median, 1e-7 m p99).
struct QuadPoints {
  // [0, 4 quads): points minus origin, weights (the fit's base weights), 1 for a point and 0 for a
  // padding lane (the last point again with weight 0: it adds nothing).
  alignas(16) std::array<float, kMaxFitPoints> x, y, weight, used;
  std::size_t quads = 0;
  Eigen::Vector2d origin = Eigen::Vector2d::Zero();
  // The fit's constants of the Huber loss, once per fit rather than per pass (the same values):
  // z^2 = d^2 w discount / k^2, and k^2 / discount, the scale of the loss's sum.
  float huber = 0.0f;
  double cost_scale = 0.0;
};

// The lane sums of four vectors, (sum a, sum b, sum c, sum d): SSE's transposing adds (7
// instructions for the four) where there is SSE, four reductions elsewhere.
inline Eigen::Array4f LaneSums(const Eigen::Array4f& a, const Eigen::Array4f& b,
                               const Eigen::Array4f& c, const Eigen::Array4f& d) {
#if defined(__SSE__)
  const __m128 pa = _mm_load_ps(a.data()), pb = _mm_load_ps(b.data());
  const __m128 pc = _mm_load_ps(c.data()), pd = _mm_load_ps(d.data());
  // (a0 + a2, b0 + b2, a1 + a3, b1 + b3) and the same of c, d.
  const __m128 ab = _mm_add_ps(_mm_unpacklo_ps(pa, pb), _mm_unpackhi_ps(pa, pb));
  const __m128 cd = _mm_add_ps(_mm_unpacklo_ps(pc, pd), _mm_unpackhi_ps(pc, pd));
  Eigen::Array4f r;
  _mm_store_ps(r.data(), _mm_add_ps(_mm_movelh_ps(ab, cd), _mm_movehl_ps(cd, ab)));
  return r;
#else
  return {a.sum(), b.sum(), c.sum(), d.sum()};
#endif
}

// One quad's contributions to the sums of SumPointsQuad, lane by lane: the normal matrix's upper
// triangle (w g_r) g_c, the gradient (w d) g_r, the Huber loss and the squared distance.
struct QuadTerms {
  using F4 = Eigen::Array4f;
  F4 h00, h01, h02, h03, h04, h11, h12, h13, h14, h22, h23, h24, h33, h34, h44;
  F4 g0, g1, g2, g3, g4;
  F4 cost, sq;

  [[gnu::always_inline]] void operator+=(const QuadTerms& o) {
    h00 += o.h00;
    h01 += o.h01;
    h02 += o.h02;
    h03 += o.h03;
    h04 += o.h04;
    h11 += o.h11;
    h12 += o.h12;
    h13 += o.h13;
    h14 += o.h14;
    h22 += o.h22;
    h23 += o.h23;
    h24 += o.h24;
    h33 += o.h33;
    h34 += o.h34;
    h44 += o.h44;
    g0 += o.g0;
    g1 += o.g1;
    g2 += o.g2;
    g3 += o.g3;
    g4 += o.g4;
    cost += o.cost;
    sq += o.sq;
  }
};

// The per-fit constants of SumPointsQuad's pass, in single precision.
struct QuadFrame {
  float ox, oy, cf, sf, ia, ib, huber, centre_d;
};

template <int kKind>
[[gnu::always_inline]] inline QuadTerms QuadTermsAt(const QuadPoints& q, std::size_t k,
                                                    const QuadFrame& f) {
  static_assert(kKind == kExponent2 || kKind == kExponent2_5);
  using F4 = Eigen::Array4f;
  using Quad = Eigen::Map<const F4, Eigen::Aligned16>;
  const float cf = f.cf, sf = f.sf, ia = f.ia, ib = f.ib;
  const F4 weight = Quad(q.weight.data() + 4 * k);
  const F4 dx = Quad(q.x.data() + 4 * k) - f.ox, dy = Quad(q.y.data() + 4 * k) - f.oy;
  const F4 u = cf * dx + sf * dy;
  const F4 v = cf * dy - sf * dx;
  const F4 xu = u * ia, xv = v * ib;
  F4 s1, d1, s2, d2;
  if constexpr (kKind == kExponent2) {
    s1 = xu * xu;
    d1 = 2.0f * xu;
    s2 = xv * xv;
    d2 = 2.0f * xv;
  } else {
    const F4 ru = xu.abs().sqrt(), rv = xv.abs().sqrt();
    s1 = xu * xu * ru;
    d1 = 2.5f * xu * ru;
    s2 = xv * xv * rv;
    d2 = 2.5f * xv * rv;
  }
  const F4 su = d1 * ia, sv = d2 * ib;  // dS/du, dS/dv
  const F4 g2 = su * su + sv * sv;
  const F4 inv_g = g2.rsqrt();
  F4 d = (s1 + s2 - 1.0f) * inv_g;
  const F4 gu = su * inv_g, gv = sv * inv_g;
  F4 gcx = gv * sf - gu * cf;
  F4 gcy = -(gu * sf + gv * cf);
  F4 gyaw = gu * v - gv * u;
  F4 ga = -gu * u * ia;
  F4 gb = -gv * v * ib;
  if (!(g2.minCoeff() > 1e-24f)) [[unlikely]] {
    for (int l = 0; l < 4; ++l) {
      if (g2(l) > 1e-24f) continue;
      d(l) = f.centre_d;
      gcx(l) = gcy(l) = gyaw(l) = ga(l) = gb(l) = 0.0f;
    }
  }
  // Huber (SumPoints): z = max(1, |s| / k), w = weight / z, rho = z^2 within k and 2 z - 1
  // beyond, i.e. z^2 - (z - 1)^2 for both.
  const F4 z2 = d * d * weight * f.huber;
  F4 w = weight;
  F4 rho = z2;
  if (z2.maxCoeff() > 1.0f) {
    const F4 z = z2.max(1.0f).sqrt();
    w = w / z;
    rho = z2 - (z - 1.0f).square();
  }
  const F4 wcx = w * gcx, wcy = w * gcy, wyaw = w * gyaw, wa = w * ga, wb = w * gb;
  const F4 wd = w * d;
  QuadTerms t;
  t.h00 = wcx * gcx;
  t.h01 = wcx * gcy;
  t.h02 = wcx * gyaw;
  t.h03 = wcx * ga;
  t.h04 = wcx * gb;
  t.h11 = wcy * gcy;
  t.h12 = wcy * gyaw;
  t.h13 = wcy * ga;
  t.h14 = wcy * gb;
  t.h22 = wyaw * gyaw;
  t.h23 = wyaw * ga;
  t.h24 = wyaw * gb;
  t.h33 = wa * ga;
  t.h34 = wa * gb;
  t.h44 = wb * gb;
  t.g0 = wd * gcx;
  t.g1 = wd * gcy;
  t.g2 = wd * gyaw;
  t.g3 = wd * ga;
  t.g4 = wd * gb;
  t.cost = rho;
  t.sq = d * d * Quad(q.used.data() + 4 * k);
  return t;
}

// Returns the sums (rather than adding to the caller's: every member is set here, so the caller
// clears nothing).
template <int kKind>
PointSums SumPointsQuad(const Vec5& at, double c, double s, double inv_a, double inv_b,
                        const QuadPoints& q) {
  static_assert(kKind == kExponent2 || kKind == kExponent2_5);
  using F4 = Eigen::Array4f;
  QuadFrame f;
  f.ox = static_cast<float>(at(kCx) - q.origin.x());
  f.oy = static_cast<float>(at(kCy) - q.origin.y());
  f.cf = static_cast<float>(c);
  f.sf = static_cast<float>(s);
  f.ia = static_cast<float>(inv_a);
  f.ib = static_cast<float>(inv_b);
  f.huber = q.huber;
  f.centre_d = static_cast<float>(-std::min(at(kA), at(kB)));  // a point at the centre
  // Each lane's sum over the quads in order (a fit has at least one point, so one quad), started
  // from the first quad's terms rather than from zeros (0 + x is x, but for the sign of a zero sum:
  // a sign that reaches no result)
  // and the usual one or two quads (max_points 8) without a loop: the accumulators neither cleared
  // nor carried from one quad to the next (they outnumber the registers).
  QuadTerms t = QuadTermsAt<kKind>(q, 0, f);
  if (q.quads == 2) {
    t += QuadTermsAt<kKind>(q, 1, f);
  } else if (q.quads > 2) [[unlikely]] {
    for (std::size_t k = 1; k < q.quads; ++k) t += QuadTermsAt<kKind>(q, k, f);
  }
  // Each entry's four lanes added, four entries at a time, then in double.
  const F4 s0 = LaneSums(t.h00, t.h11, t.h02, t.h12), s1 = LaneSums(t.h03, t.h13, t.h04, t.h14);
  const F4 s2 = LaneSums(t.h22, t.h33, t.h24, t.h34), s3 = LaneSums(t.g0, t.g1, t.g2, t.g3);
  const F4 s4 = LaneSums(t.h01, t.h23, t.h44, t.g4),
           s5 = LaneSums(t.cost, t.sq, F4::Zero(), F4::Zero());
  const auto lanes = [](const F4& v, int i) {
    return Lanes(static_cast<double>(v(i)), static_cast<double>(v(i + 1)));
  };
  PointSums sums;
  sums.outer = UpperSum5::FromEntries(lanes(s0, 0), lanes(s0, 2), lanes(s1, 0), lanes(s1, 2),
                                      lanes(s2, 0), lanes(s2, 2), static_cast<double>(s4(0)),
                                      static_cast<double>(s4(1)), static_cast<double>(s4(2)));
  sums.g01 = lanes(s3, 0);
  sums.g23 = lanes(s3, 2);
  sums.g4 = static_cast<double>(s4(3));
  sums.cost = q.cost_scale * static_cast<double>(s5(0));
  sums.sq = static_cast<double>(s5(1));
  return sums;
}

using SumQuadsFn = PointSums (*)(const Vec5&, double, double, double, double, const QuadPoints&);

// SumPointsQuad where it serves (a superellipse with exponent 2 or 2.5), else nullptr.
SumQuadsFn SumQuadsFor(ShapeModel model, double exponent) {
  if (model != ShapeModel::kSuperellipse) return nullptr;
  if (exponent == 2.0) return &SumPointsQuad<kExponent2>;
  if (exponent == 2.5) return &SumPointsQuad<kExponent2_5>;
  return nullptr;
}

// The normal matrix is symmetric positive definite by construction (weighted outer products plus
// the priors, each of which bounds a parameter). A 5 x 5 root-free Cholesky (h = L D L^T, L unit
// lower triangular) by hand: Eigen's pivoted LDLT and its general solve against the identity for
// the covariance cost more than a pass over the points at this size. A pivot that is not positive
// (rounding on a nearly singular matrix) falls back to the pivoted LDLT. Without square roots the
// factorisation's dependent chain is one division per column (L L^T had a square root and a
// division). The loops are unrolled completely (the pragmas): with constant bounds the triangular
// loops become straight code. Factor reads h's upper triangle only (the fit forms only that).
class NormalSolver {
 public:
  bool Factor(const Mat5& h) {
    use_ldlt_ = false;
#pragma GCC unroll 5
    for (int j = 0; j < 5; ++j) {
      // u_[i][k] = l_[i][k] d_k (i > k): the products before the division.
      double d = h(j, j);
#pragma GCC unroll 5
      for (int k = 0; k < j; ++k) d -= u_[j][k] * l_[j][k];
      if (!(d > 0.0) || !std::isfinite(d)) [[unlikely]] {
        return FactorLdlt(h);
      }
      inv_diag_[j] = 1.0 / d;
#pragma GCC unroll 5
      for (int i = j + 1; i < 5; ++i) {
        double v = h(j, i);  // h(i, j) of the symmetric matrix
#pragma GCC unroll 5
        for (int k = 0; k < j; ++k) v -= u_[i][k] * l_[j][k];
        u_[i][j] = v;
        l_[i][j] = v * inv_diag_[j];
      }
    }
    return true;
  }
  // h^-1 b: L y = b, then L^T x = D^-1 y.
  Vec5 Solve(const Vec5& b) const {
    if (use_ldlt_) [[unlikely]] {
      return SolveLdlt(b);
    }
    std::array<double, 5> y{};
#pragma GCC unroll 5
    for (int i = 0; i < 5; ++i) {
      double v = b(i);
#pragma GCC unroll 5
      for (int k = 0; k < i; ++k) v -= l_[i][k] * y[k];
      y[i] = v;
    }
    Vec5 x;
#pragma GCC unroll 5
    for (int i = 4; i >= 0; --i) {
      double v = y[i] * inv_diag_[i];
#pragma GCC unroll 5
      for (int k = i + 1; k < 5; ++k) v -= l_[k][i] * x(k);
      x(i) = v;
    }
    return x;
  }
  // h^-1 = L^-T D^-1 L^-1.
  Mat5 Inverse() const { return InverseEntries<false>(); }
  // The entries of h^-1 a fit reports (InverseEntries<true>), the same values as Inverse's; the
  // others 0.
  Mat5 ResultInverse() const { return InverseEntries<true>(); }

 private:
  // The entries a fit's result takes from the covariance: the centre's block, the yaw's variance,
  // the size's block (a circle: (kA, kA) alone), each diagonal entry among them.
  static constexpr bool ResultEntry(int i, int j) {
    return (i < 2 && j < 2) || (i == kYaw && j == kYaw) || (i >= kA && j >= kA);
  }
  // kResultOnly: only the ResultEntry entries (the others 0), each with the same arithmetic as in
  // the full inverse: 20 of the 35 products' terms.
  template <bool kResultOnly>
  Mat5 InverseEntries() const {
    if (use_ldlt_) [[unlikely]] {
      return InverseLdlt();
    }
    double m[5][5] = {};  // L^-1, unit lower triangular
#pragma GCC unroll 5
    for (int j = 0; j < 5; ++j) {
      m[j][j] = 1.0;
#pragma GCC unroll 5
      for (int i = j + 1; i < 5; ++i) {
        double v = 0.0;
#pragma GCC unroll 5
        for (int k = j; k < i; ++k) v -= l_[i][k] * m[k][j];
        m[i][j] = v;
      }
    }
    Mat5 inv;
#pragma GCC unroll 5
    for (int i = 0; i < 5; ++i) {
#pragma GCC unroll 5
      for (int j = i; j < 5; ++j) {
        double v = 0.0;
        if (kResultOnly && !ResultEntry(i, j)) {
          inv(i, j) = 0.0;
          inv(j, i) = 0.0;
          continue;
        }
#pragma GCC unroll 5
        for (int k = j; k < 5; ++k) v += m[k][i] * inv_diag_[k] * m[k][j];
        inv(i, j) = v;
        inv(j, i) = v;
      }
    }
    return inv;
  }

  // The pivoted LDLT (rare: a pivot that is not positive) out of line and in the cold section, so
  // that its code does not share the instruction cache with the fit's hot path.
  [[gnu::cold, gnu::noinline]] bool FactorLdlt(const Mat5& h) {
    use_ldlt_ = true;
    const Mat5 full = h.selfadjointView<Eigen::Upper>();
    ldlt_.compute(full);
    return ldlt_.info() == Eigen::Success;
  }
  [[gnu::cold, gnu::noinline]] Vec5 SolveLdlt(const Vec5& b) const { return ldlt_.solve(b); }
  [[gnu::cold, gnu::noinline]] Mat5 InverseLdlt() const { return ldlt_.solve(Mat5::Identity()); }

  // Not zeroed (one solver per fit): Factor writes every entry below the diagonal and every
  // inverse pivot before Solve and the inverse read them, and nothing reads the rest.
  double l_[5][5];                  // L below the diagonal
  double u_[5][5];                  // L D below the diagonal
  std::array<double, 5> inv_diag_;  // D^-1
  bool use_ldlt_ = false;
  Eigen::LDLT<Mat5> ldlt_;
};

// Eigen's pivoted LDLT for every solve: what FitShape used before NormalSolver, kept as the
// reference of the equivalence test (internal::FitShapeWithPivotedLdlt).
class PivotedLdltSolver {
 public:
  // h's upper triangle, as NormalSolver.
  bool Factor(const Mat5& h) {
    const Mat5 full = h.selfadjointView<Eigen::Upper>();
    ldlt_.compute(full);
    return ldlt_.info() == Eigen::Success;
  }
  Vec5 Solve(const Vec5& b) const { return ldlt_.solve(b); }
  Mat5 Inverse() const { return ldlt_.solve(Mat5::Identity()); }
  Mat5 ResultInverse() const { return Inverse(); }

 private:
  Eigen::LDLT<Mat5> ldlt_;
};

}  // namespace

std::optional<std::string> Validate(const ShapeFitOptions& o) {
  auto nonneg = [](double v) { return std::isfinite(v) && v >= 0.0; };
  if (!nonneg(o.point_sigma_m) || !nonneg(o.point_sigma_per_m) || !nonneg(o.model_sigma_m) ||
      !(o.point_sigma_m + o.model_sigma_m > 0.0)) {
    return "point_sigma_m, point_sigma_per_m and model_sigma_m must be >= 0 and not all 0";
  }
  if (!Positive(o.edge_floor_sigma_m)) return "edge_floor_sigma_m must be > 0";
  if (!(std::isfinite(o.effective_points) && o.effective_points >= 1.0)) {
    return "effective_points must be >= 1";
  }
  if (!Positive(o.robust_k)) return "robust_k must be > 0";
  if (o.max_iterations < 1 || o.max_iterations > 50) return "max_iterations must be in [1, 50]";
  if (o.max_points < 2 || o.max_points > kMaxFitPoints) {
    return "max_points must be in [2, " + std::to_string(kMaxFitPoints) + "]";
  }
  if (!Positive(o.min_size_m) || !Positive(o.max_size_m) || o.max_size_m <= o.min_size_m) {
    return "need 0 < min_size_m < max_size_m";
  }
  if (o.outside_guess_start > OutsideGuessStart::kBetter) {
    return "outside_guess_start must be guess, silhouette or better";
  }
  return std::nullopt;
}

double ShapeSupport(ShapeModel model, const Eigen::Vector2d& size_m, double yaw_rad,
                    const Eigen::Vector2d& n, double exponent, Eigen::Vector2d* d_size) {
  Vec5 x = Vec5::Zero();
  x(kYaw) = yaw_rad;
  x(kA) = size_m.x();
  x(kB) = size_m.y();
  Vec5 grad = Vec5::Zero();
  // Both from one local value, so that the compiler makes them one sincos call.
  const double yaw = yaw_rad;
  const double cos_yaw = std::cos(yaw), sin_yaw = std::sin(yaw);
  const double h =
      Support(model, x, cos_yaw, sin_yaw, n, exponent, d_size != nullptr ? &grad : nullptr);
  if (d_size != nullptr) *d_size = Eigen::Vector2d(grad(kA), grad(kB));
  return h;
}

void ShapeSupportPair(ShapeModel model, const Eigen::Vector2d& size_m, double yaw_rad,
                      const Eigen::Vector2d& n0, const Eigen::Vector2d& n1, double exponent,
                      Eigen::Vector2d* d_size0, Eigen::Vector2d* d_size1) {
  Vec5 x = Vec5::Zero();
  x(kYaw) = yaw_rad;
  x(kA) = size_m.x();
  x(kB) = size_m.y();
  Vec5 grad0 = Vec5::Zero(), grad1 = Vec5::Zero();
  const double cos_yaw = std::cos(yaw_rad), sin_yaw = std::sin(yaw_rad);
  if (PairedSupport(model, exponent)) {
    (void)SupportPair(x, cos_yaw, sin_yaw, Edge{n0, 0.0}, Edge{n1, 0.0}, exponent, &grad0, &grad1);
  } else {
    (void)Support(model, x, cos_yaw, sin_yaw, n0, exponent, &grad0);
    (void)Support(model, x, cos_yaw, sin_yaw, n1, exponent, &grad1);
  }
  *d_size0 = Eigen::Vector2d(grad0(kA), grad0(kB));
  *d_size1 = Eigen::Vector2d(grad1(kA), grad1(kB));
}

namespace {

// The rare paths of Fit out of line and in the cold section (their code then does not share the
// instruction cache with the fit's hot path, which a crowd's many fits per scan run through).

// The fit's points where some are not finite: the finite ones, evenly subsampled to want (of
// finite), into pts; returns their count.
[[gnu::cold, gnu::noinline]] std::size_t PickFinitePoints(
    std::span<const Eigen::Vector2d> points, std::size_t finite, std::size_t want,
    std::array<Eigen::Vector2d, kMaxFitPoints>& pts) {
  std::size_t n = 0;
  std::size_t seen = 0;
  std::size_t next_pick = 0;  // index among finite points of the next one to take
  for (const auto& p : points) {
    if (!p.allFinite()) continue;
    if (seen == next_pick && n < want) {
      pts[n++] = p;
      // round(n (finite - 1) / (want - 1)), halves up, in integers.
      next_pick = want <= 1 ? finite : (2 * n * (finite - 1) + (want - 1)) / (2 * (want - 1));
    }
    ++seen;
  }
  return n;
}

// The unit vector at the mean of two points' bearings.
[[gnu::cold, gnu::noinline]] Eigen::Vector2d RayByMeanAngle(const Eigen::Vector2d& first,
                                                            const Eigen::Vector2d& last) {
  const double mid_angle =
      0.5 * (std::atan2(first.y(), first.x()) + std::atan2(last.y(), last.x()));
  return {std::cos(mid_angle), std::sin(mid_angle)};
}

// How far the start's guess (ShapePrior::centre_guess_m) may lie from the start on the ray.
constexpr double kMaxGuessOffsetM = 0.5;

// Whether `guess` lies within kMaxGuessOffsetM of (nearest_along + depth) ray for every depth the
// superellipse's support function along the ray can take, by a margin far above the roots' and
// the sums' rounding: h = (|a p|^k + |b q|^k)^(1/k) (p, q the ray's components along the axes,
// k >= 1) lies between the largest of a |p|, b |q| and their sum (the k-norm between the max-norm
// and the 1-norm), and the distance to the guess, a convex function of the depth, is largest at
// an end of that interval. False where that does not settle it (or for the other models, whose
// support function is cheap): the caller then computes the depth.
bool GuessWithinReach(ShapeModel model, const Vec5& x, double cos_yaw, double sin_yaw,
                      const Eigen::Vector2d& ray, double nearest_along,
                      const Eigen::Vector2d& guess) {
  if (model != ShapeModel::kSuperellipse) return false;
  constexpr double kMarginM = 1e-6;
  const double ap = std::abs(x(kA) * (ray.x() * cos_yaw + ray.y() * sin_yaw));
  const double bq = std::abs(x(kB) * (-ray.x() * sin_yaw + ray.y() * cos_yaw));
  const double low = std::max(ap, bq), high = ap + bq;
  const Eigen::Vector2d e = guess - nearest_along * ray;
  const double along = e.dot(ray);
  const double across = e.x() * ray.y() - e.y() * ray.x();
  const double far = std::max(std::abs(along - low), std::abs(along - high));
  const double reach = kMaxGuessOffsetM - kMarginM;
  return across * across + far * far < reach * reach;
}

// kReference: the fit's numerics before RootN and the ray by the bisector (libm's roots, the ray's
// angle by atan2), for the equivalence test. kPaired: two points' and the two edges' arithmetic
// side by side (SumPointsPaired, SupportPair; the same results).
template <class Solver, bool kReference = false, bool kPaired = !kReference>
ShapeFitResult Fit(std::span<const Eigen::Vector2d> points, const Silhouette& silhouette,
                   const ShapePrior& prior, const ShapeFitOptions& o) {
  ShapeFitResult result;
  // The points used: finite ones, evenly subsampled to max_points.
  std::array<Eigen::Vector2d, kMaxFitPoints> pts;
  std::size_t finite = 0;
  // x - x is 0 for a finite coordinate and NaN otherwise (allFinite's test without a branch per
  // coordinate). Nearly always every point is finite: one sum over all coordinates, two at a time
  // (Eigen's packets), shows it; only where it is NaN are the finite points counted.
  static_assert(sizeof(Eigen::Vector2d) == 2 * sizeof(double), "points are contiguous (x, y)");
  const Eigen::Map<const Eigen::ArrayXd> coordinates(points.empty() ? nullptr : points[0].data(),
                                                     static_cast<Eigen::Index>(2 * points.size()));
  if (const double all = (coordinates - coordinates).sum(); all == all) {
    finite = points.size();
  } else [[unlikely]] {
    for (const auto& p : points) {
      const double t = (p.x() - p.x()) + (p.y() - p.y());
      finite += t == t ? 1 : 0;
    }
  }
  if (finite == 0) return result;
  const std::size_t want = std::min(finite, o.max_points);
  std::size_t n = 0;
  if (finite == points.size()) {
    // Every point finite (nearly always): the same picks by index, the rounded quotient stepped
    // on in integers (one division per fit instead of one per pick and a pass over every point).
    if (want <= 1) {
      pts[n++] = points[0];
    } else {
      const std::size_t divisor = 2 * (want - 1);
      const std::size_t step = 2 * (finite - 1);
      const std::size_t step_quotient = step / divisor, step_remainder = step % divisor;
      std::size_t index = 0, remainder = want - 1;  // (2 n (finite - 1) + (want - 1)), n = 0
      for (; n < want; ++n) {
        pts[n] = points[index];
        index += step_quotient;
        remainder += step_remainder;
        if (remainder >= divisor) {
          remainder -= divisor;
          ++index;
        }
      }
    }
  } else [[unlikely]] {
    n = PickFinitePoints(points, finite, want, pts);
  }
  const std::span<const Eigen::Vector2d> used(pts.data(), n);
  result.points_used = n;

  // Per-point weights: noise and model error, discounted for correlation (with each point's range
  // in the pass that sums them).
  const double discount = std::max(1.0, static_cast<double>(n) / o.effective_points);
  std::array<double, kMaxFitPoints> base_weight;  // [0, n) set below
  // Shape of the point set: principal line and extent (flat objects: doors, boards).
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  double range_sum = 0.0;
  std::array<double, kMaxFitPoints> range_m;  // each point's range; [0, n)
  // Two points at a time: each lane's range and weight the same operations as one point's
  // (|p| = sqrt(x^2 + y^2)), the sums taken point by point in order (the same bits on x86-64;
  // where multiply-adds are fused, e.g. aarch64, the lanes and the scalar tail may round
  // differently in the last bit).
  const double model_var = o.model_sigma_m * o.model_sigma_m;
  std::size_t j = 0;
  for (; j + 1 < n; j += 2) {
    const Lanes px(used[j].x(), used[j + 1].x()), py(used[j].y(), used[j + 1].y());
    const Lanes range = (px * px + py * py).sqrt();
    const Lanes noise = o.point_sigma_m + o.point_sigma_per_m * range;
    mean += used[j];
    mean += used[j + 1];
    range_m[j] = range(0);
    range_m[j + 1] = range(1);
    range_sum += range(0);
    range_sum += range(1);
    const Lanes weight = 1.0 / ((noise * noise + model_var) * discount);
    base_weight[j] = weight(0);
    base_weight[j + 1] = weight(1);
  }
  if (j < n) {
    mean += used[j];
    range_m[j] = used[j].norm();
    range_sum += range_m[j];
    const double noise = o.point_sigma_m + o.point_sigma_per_m * range_m[j];
    base_weight[j] = 1.0 / ((noise * noise + model_var) * discount);
  }
  mean /= static_cast<double>(n);
  const double mean_range = range_sum / static_cast<double>(n);

  const ShapeModel model = prior.model;
  const bool circle = model == ShapeModel::kCircle;
  const double exponent = std::max(2.0, prior.exponent);
  // The points in single precision about their mean, four to a lane group (SumPointsQuad), where
  // the fit takes them so: filled in the scatter's pass below (the same differences).
  const SumQuadsFn sum_quads =
      kPaired && !kReference && o.single_precision_points ? SumQuadsFor(model, exponent) : nullptr;
  QuadPoints quad_points;

  // Start: on the ray through the middle of the silhouette, the body's extent behind the points
  // (the bisector of the first and last point's directions: their mean angle without atan2).
  Eigen::Vector2d ray;
  if constexpr (kReference) {
    ray = RayByMeanAngle(used.front(), used.back());
  } else {
    // used.front().norm(), back's (bit for bit on x86-64; where multiply-adds are fused, e.g.
    // aarch64, a range from a lane may differ from norm() in the last bit).
    const double front = range_m[0], back = range_m[n - 1];
    ray = used.front() / front + used.back() / back;
    const double length = ray.norm();
    // Points on opposite sides of the sensor or at it: the angles' mean as before.
    if (!(front > 0.0 && back > 0.0 && length > 1e-6)) [[unlikely]] {
      ray = RayByMeanAngle(used.front(), used.back());
    } else {
      ray /= length;
    }
  }
  // The scatter matrix's three distinct entries, each the same sum of the same products as the
  // matrix's outer-product sum; in the same pass the nearest point along the ray.
  double sxx = 0.0, sxy = 0.0, syy = 0.0;
  double nearest_along = mean_range;
  if (sum_quads != nullptr) {
    // (dx, dy) and (sxx, syy) as lane pairs (each the same difference, product and sum).
    Lanes sxx_syy = Lanes::Zero();
    for (std::size_t i = 0; i < n; ++i) {
      const Eigen::Vector2d& p = used[i];
      const Lanes d = p.array() - mean.array();
      sxx_syy += d * d;
      sxy += d(0) * d(1);
      nearest_along = std::min(nearest_along, p.dot(ray));
      const Eigen::Array2f df = d.cast<float>();
      quad_points.x[i] = df(0);
      quad_points.y[i] = df(1);
      quad_points.weight[i] = static_cast<float>(base_weight[i]);
      quad_points.used[i] = 1.0f;
    }
    sxx = sxx_syy(0);
    syy = sxx_syy(1);
  } else {
    for (const auto& p : used) {
      const double dx = p.x() - mean.x(), dy = p.y() - mean.y();
      sxx += dx * dx;
      sxy += dx * dy;
      syy += dy * dy;
      nearest_along = std::min(nearest_along, p.dot(ray));
    }
  }
  {
    const double count = static_cast<double>(n);
    sxx /= count;
    sxy /= count;
    syy /= count;
    const double half_trace = 0.5 * (sxx + syy);
    const double half_diff = 0.5 * (sxx - syy);
    const double smallest = half_trace - std::sqrt(half_diff * half_diff + sxy * sxy);
    result.line_rms_m = std::sqrt(std::max(0.0, smallest));
  }
  result.extent_m = (used.front() - used.back()).norm();

  Vec5 x = Vec5::Zero();
  x(kYaw) = circle ? 0.0 : prior.yaw_rad;
  x(kA) = std::clamp(prior.size_m.x(), o.min_size_m, o.max_size_m);
  x(kB) = circle ? x(kA) : std::clamp(prior.size_m.y(), o.min_size_m, o.max_size_m);

  // The sine and cosine of the last yaw evaluated (the start's is the first evaluation's too).
  double cos_yaw = std::cos(x(kYaw)), sin_yaw = std::sin(x(kYaw)), trig_yaw = x(kYaw);
  // The guess (the track's prediction) is taken where it lies behind the points and within
  // kMaxGuessOffsetM of the start on the ray. Where that holds for every depth the body's extent
  // along the ray can have, the depth's support function (a chain of roots) is not needed.
  const bool guess = prior.centre_guess_m && prior.centre_guess_m->allFinite();
  Eigen::Vector2d start;
  if (guess && prior.centre_guess_m->dot(ray) > nearest_along &&
      GuessWithinReach(model, x, cos_yaw, sin_yaw, ray, nearest_along, *prior.centre_guess_m)) {
    start = *prior.centre_guess_m;
  } else {
    const double depth = Support<kReference>(model, x, cos_yaw, sin_yaw, ray, exponent, nullptr);
    start = (nearest_along + depth) * ray;
    if (guess) {
      const Eigen::Vector2d& g = *prior.centre_guess_m;
      if (g.dot(ray) > nearest_along && (g - start).norm() < kMaxGuessOffsetM) start = g;
    }
  }
  x(kCx) = start.x();
  x(kCy) = start.y();
  const Eigen::Vector2d centre_prior = start;

  // Silhouette edges, half a step outwards of the first and last hit beams, each normal pointing
  // away from the body: away from the bisector of the points (inside both edges' rays), not from
  // the start, which (the track's prediction) may lie beyond an edge's ray when the track has
  // drifted; the edge then held the body outside the silhouette.
  const Eigen::Vector2d edge_inside = o.edges_face_points ? ray : start;
  std::array<Edge, 2> edges{};
  std::size_t n_edges = 0;
  {
    const double range_sigma = mean_range * silhouette.step_rad / std::sqrt(12.0);
    const double weight =
        1.0 / (range_sigma * range_sigma + o.edge_floor_sigma_m * o.edge_floor_sigma_m);
    // The edge ray's direction (cos, sin): the caller's where it has them (the same values).
    const auto add = [&](double angle, bool unit_known, const std::array<double, 2>& unit) {
      Eigen::Vector2d nrm;
      if (unit_known && !kReference) {
        nrm = Eigen::Vector2d(unit[1], -unit[0]);
      } else {
        nrm = Eigen::Vector2d(std::sin(angle), -std::cos(angle));
      }
      if (nrm.dot(edge_inside) > 0.0) nrm = -nrm;
      edges[n_edges++] = {nrm, weight};
    };
    if (silhouette.first_valid) {
      add(silhouette.first_edge_rad, silhouette.first_edge_unit_known, silhouette.first_edge_unit);
    }
    if (silhouette.last_valid) {
      add(silhouette.last_edge_rad, silhouette.last_edge_unit_known, silhouette.last_edge_unit);
    }
  }

  // Priors: size information, yaw, weak centre.
  Eigen::Matrix2d size_info = Eigen::Matrix2d::Zero();
  if (circle) {
    size_info(0, 0) = 1.0 / std::max(prior.size_cov_m2(0, 0), 1e-12);
  } else {
    bool invertible = false;
    prior.size_cov_m2.computeInverseWithCheck(size_info, invertible, 1e-18);
    if (!invertible) size_info = Eigen::Matrix2d::Identity() * 1e6;
  }
  const double yaw_info = circle ? 0.0 : 1.0 / (prior.yaw_sigma_rad * prior.yaw_sigma_rad + 1e-12);
  const double centre_info = 1.0 / (kCentrePriorSigmaM * kCentrePriorSigmaM);
  const Eigen::Vector2d size0(x(kA), x(kB));

  // The objective at x: Huber on the points (rho(s) = s^2 within k, 2 k |s| - k^2 beyond, s the
  // normalised distance), squares on edges and priors. Fills the Gauss-Newton normal matrix h (its
  // upper triangle, which is all the solvers read; the entries below it are not written) and
  // gradient g (halves) with the IRLS weights min(1, k / |s|) of x; one pass over the points.
  const double k2 = o.robust_k * o.robust_k;
  const SumPointsFn sum_points = SumPointsFor(model, exponent, kPaired);
  if (sum_quads != nullptr) {
    quad_points.origin = mean;
    quad_points.huber = static_cast<float>(discount / k2);
    quad_points.cost_scale = k2 / discount;
    quad_points.quads = (n + 3) / 4;
    for (std::size_t i = n; i < 4 * quad_points.quads; ++i) {
      quad_points.x[i] = quad_points.x[n - 1];
      quad_points.y[i] = quad_points.y[n - 1];
      quad_points.weight[i] = 0.0f;
      quad_points.used[i] = 0.0f;
    }
  }
  const bool paired_edges = kPaired && n_edges == 2 && PairedSupport(model, exponent);
  int evaluations = 0;
  // Inlined at both calls (the start, each trial): called out of line it read every captured value
  // through its closure and spilled around the calls (about 230 instructions a fit more).
  auto evaluate = [&](const Vec5& at, Mat5* h, Vec5* g, double* points_sq)
      __attribute__((always_inline)) {
    ++evaluations;
    // A circle has no orientation (its yaw stays 0).
    if (!circle && !(at(kYaw) == trig_yaw)) {
      // Both from one local value, so that the compiler makes them one sincos call (the captured
      // trig_yaw would be read again after the store to cos_yaw).
      const double yaw = at(kYaw);
      trig_yaw = yaw;
      cos_yaw = std::cos(yaw);
      sin_yaw = std::sin(yaw);
    }
    const double c = circle ? 1.0 : cos_yaw, s = circle ? 0.0 : sin_yaw;
    const double inv_a = 1.0 / at(kA), inv_b = 1.0 / at(kB);
    // The edges' support functions first: their chain of roots does not depend on the points, so
    // it runs while the points' pass does. Summed after the points, as before.
    std::array<Vec5, 2> edge_grad = {Vec5::Zero(), Vec5::Zero()};
    std::array<double, 2> support{};
    if (paired_edges) {
      const Lanes h_pair =
          SupportPair(at, c, s, edges[0], edges[1], exponent, &edge_grad[0], &edge_grad[1]);
      support = {h_pair(0), h_pair(1)};
    } else {
      for (std::size_t e = 0; e < n_edges; ++e) {
        support[e] = Support<kReference>(model, at, c, s, edges[e].n, exponent, &edge_grad[e]);
      }
    }
    PointSums sums = sum_quads != nullptr
                         ? sum_quads(at, c, s, inv_a, inv_b, quad_points)
                         : SumPointsFrom(sum_points, at, c, s, inv_a, inv_b, exponent, used,
                                         base_weight.data(), discount, k2);
    UpperSum5& outer = sums.outer;
    Vec5 gg = sums.Gradient();
    double cost = sums.cost;
    const double sq = sums.sq;
    for (std::size_t e = 0; e < n_edges; ++e) {
      Vec5& grad = edge_grad[e];
      const double r = edges[e].n.dot(at.head<2>()) + support[e];
      grad(kCx) = edges[e].n.x();
      grad(kCy) = edges[e].n.y();
      outer.Add(grad, edges[e].weight);
      gg += (edges[e].weight * r) * grad;
      cost += edges[e].weight * r * r;
    }
    // Straight into the caller's matrix (its entries below the diagonal are read by no solver).
    Mat5& hh = *h;
    outer.WriteUpper(hh);
    // Priors.
    const Eigen::Vector2d dc = at.head<2>() - centre_prior;
    hh(kCx, kCx) += centre_info;
    hh(kCy, kCy) += centre_info;
    gg.head<2>() += centre_info * dc;
    cost += centre_info * dc.squaredNorm();
    if (circle) {
      const double ds = at(kA) - size0.x();
      hh(kA, kA) += size_info(0, 0);
      gg(kA) += size_info(0, 0) * ds;
      cost += size_info(0, 0) * ds * ds;
      hh(kYaw, kYaw) += 1.0;  // fixed parameters: keep the matrix regular
      hh(kB, kB) += 1.0;
      gg(kYaw) = 0.0;
      gg(kB) = 0.0;
    } else {
      const Eigen::Vector2d ds(at(kA) - size0.x(), at(kB) - size0.y());
      // The upper triangle only (the matrix is reused from evaluation to evaluation).
      hh(kA, kA) += size_info(0, 0);
      hh(kA, kB) += size_info(0, 1);
      hh(kB, kB) += size_info(1, 1);
      gg.segment<2>(kA) += size_info * ds;
      cost += ds.dot(size_info * ds);
      const double dyaw = WrapHalfTurn(at(kYaw) - prior.yaw_rad);
      hh(kYaw, kYaw) += yaw_info;
      gg(kYaw) += yaw_info * dyaw;
      cost += yaw_info * dyaw * dyaw;
    }
    *g = gg;
    if (points_sq != nullptr) *points_sq = sq;
    return cost;
  };

  // The normal matrices of x and of the trial, swapped when a trial is taken instead of copied
  // (only their upper triangles are written and read: the entries below are left unset).
  std::array<Mat5, 2> normal;
  Mat5* h_at = &normal[0];
  Mat5* h_next = &normal[1];
  Vec5 g;
  double points_cost = 0.0;
  double cost = evaluate(x, h_at, &g, &points_cost);
  Eigen::Vector2d cost_centre = x.head<2>();  // where `cost` was evaluated
  int iterations = 0;
  // The solver holds the factorisation of h while `factored`: the covariance at the end reuses it
  // when the last step changed nothing (converged or rejected).
  Solver solver;
  bool factored = false;
  for (; iterations < o.max_iterations; ++iterations) {
    factored = solver.Factor(*h_at);
    if (!factored) break;
    Vec5 step = -solver.Solve(g);
    if (!AllFinite(step)) break;
    // Trust region in parameter units.
    // The largest of the five (std::max over an initializer list walks them with a branch each;
    // the chain of maxima gives the same value for finite ones without a branch).
    // Within every bound (nearly always) each ratio is at most 1 (IEEE division is monotone and
    // c / c is 1), so the scale is 1 and the step stays as it is: the divisions, which lie on the
    // chain from the solve to the next evaluation, are left out with the same result.
    const double centre_step = step.head<2>().norm();
    if (!(centre_step <= kMaxCentreStepM && std::abs(step(kYaw)) <= kMaxYawStepRad &&
          std::abs(step(kA)) <= kMaxSizeStepM && std::abs(step(kB)) <= kMaxSizeStepM)) {
      const double scale = std::max(
          std::max(std::max(1.0, centre_step / kMaxCentreStepM),
                   std::abs(step(kYaw)) / kMaxYawStepRad),
          std::max(std::abs(step(kA)) / kMaxSizeStepM, std::abs(step(kB)) / kMaxSizeStepM));
      step /= scale;
    }
    // Converged: a step this small changes nothing that matters, and evaluating it would cost a
    // pass over the points (the normal matrix at x serves for the covariance).
    if (step.head<2>().norm() < kConvergedCentreM &&
        std::abs(step(kA)) + std::abs(step(kB)) < kConvergedCentreM &&
        std::abs(step(kYaw)) < kConvergedYawRad) {
      x += step;
      ++iterations;
      break;
    }
    bool accepted = false;
    for (int halving = 0; halving < 3 && !accepted; ++halving) {
      Vec5 trial = x + step;
      trial(kA) = std::clamp(trial(kA), o.min_size_m, o.max_size_m);
      trial(kB) = circle ? trial(kA) : std::clamp(trial(kB), o.min_size_m, o.max_size_m);
      Vec5 g_trial;
      double sq_trial = 0.0;
      const double cost_trial = evaluate(trial, h_next, &g_trial, &sq_trial);
      if (std::isfinite(cost_trial) && cost_trial <= cost) {
        x = trial;
        std::swap(h_at, h_next);
        g = g_trial;
        cost = cost_trial;
        cost_centre = x.head<2>();
        points_cost = sq_trial;
        accepted = true;
        factored = false;
      } else {
        step *= 0.5;
      }
    }
    if (!accepted) break;
  }

  if (!factored && !solver.Factor(*h_at)) return result;
  // Only the entries the result takes: the others are used by nothing, so they are neither formed
  // nor tested for finiteness.
  const Mat5 cov = solver.ResultInverse();
  if (!AllFinite(cov)) return result;
  result.centre_m = x.head<2>();
  result.centre_cov_m2 = 0.5 * (cov.block<2, 2>(0, 0) + cov.block<2, 2>(0, 0).transpose());
  if (circle) {
    result.size_m = Eigen::Vector2d(x(kA), x(kA));
    result.size_cov_m2 = Eigen::Matrix2d::Constant(cov(kA, kA));
    result.yaw_rad = 0.0;
  } else {
    result.size_m = Eigen::Vector2d(x(kA), x(kB));
    result.size_cov_m2 = 0.5 * (cov.block<2, 2>(kA, kA) + cov.block<2, 2>(kA, kA).transpose());
    result.yaw_rad = WrapHalfTurn(x(kYaw));
    result.yaw_sigma_rad = std::sqrt(std::max(0.0, cov(kYaw, kYaw)));
  }
  result.cost = cost - centre_info * (cost_centre - centre_prior).squaredNorm();
  result.rms_m = std::sqrt(points_cost / static_cast<double>(n));
  result.iterations = iterations;
  result.evaluations = evaluations;
  result.ok = AllFinite(result.centre_m) && AllFinite(result.centre_cov_m2);
  return result;
}

// Whether the start's guess lies outside the wedge between the silhouette's two ends (the rays half
// a beam step beyond the outermost beams that hit; ShapeFitOptions::outside_guess_start applies).
bool GuessOutsideSilhouette(std::span<const Eigen::Vector2d> points, const Silhouette& silhouette,
                            const ShapePrior& prior, const ShapeFitOptions& o) {
  if (o.outside_guess_start == OutsideGuessStart::kGuess || !prior.centre_guess_m ||
      !prior.centre_guess_m->allFinite() || points.size() > o.outside_guess_max_points ||
      !silhouette.first_valid || !silhouette.last_valid) {
    return false;
  }
  // The rays' directions (the caller's where it has them; the same values); the wedge is the one
  // between them narrower than a half turn: in front of both, anticlockwise of the one with the
  // smaller angle and clockwise of the other. No atan2 per fit.
  const auto unit = [](double angle, bool known, const std::array<double, 2>& u) {
    return known ? Eigen::Vector2d(u[0], u[1]) : Eigen::Vector2d(std::cos(angle), std::sin(angle));
  };
  Eigen::Vector2d low =
      unit(silhouette.first_edge_rad, silhouette.first_edge_unit_known, silhouette.first_edge_unit);
  Eigen::Vector2d high =
      unit(silhouette.last_edge_rad, silhouette.last_edge_unit_known, silhouette.last_edge_unit);
  if (low.x() * high.y() - low.y() * high.x() < 0.0) std::swap(low, high);
  const Eigen::Vector2d& g = *prior.centre_guess_m;
  const bool inside = low.x() * g.y() - low.y() * g.x() >= 0.0 &&
                      g.x() * high.y() - g.y() * high.x() >= 0.0 && g.dot(low + high) > 0.0;
  return !inside;
}

// The fit from the track's guess, or where that lies outside the silhouette from behind the points
// (ShapeFitOptions::outside_guess_start); every entry point, the reference solvers' too, the same.
template <class Solver, bool... kArgs>
ShapeFitResult FitFromStart(std::span<const Eigen::Vector2d> points, const Silhouette& silhouette,
                            const ShapePrior& prior, const ShapeFitOptions& options) {
  if (!GuessOutsideSilhouette(points, silhouette, prior, options)) [[likely]] {
    return Fit<Solver, kArgs...>(points, silhouette, prior, options);
  }
  ShapePrior without_guess = prior;
  without_guess.centre_guess_m.reset();
  const ShapeFitResult from_silhouette =
      Fit<Solver, kArgs...>(points, silhouette, without_guess, options);
  if (options.outside_guess_start == OutsideGuessStart::kSilhouette) return from_silhouette;
  const ShapeFitResult from_guess = Fit<Solver, kArgs...>(points, silhouette, prior, options);
  return from_silhouette.ok && (!from_guess.ok || from_silhouette.cost < from_guess.cost)
             ? from_silhouette
             : from_guess;
}

}  // namespace

ShapeFitResult FitShape(std::span<const Eigen::Vector2d> points, const Silhouette& silhouette,
                        const ShapePrior& prior, const ShapeFitOptions& options) {
  return FitFromStart<NormalSolver>(points, silhouette, prior, options);
}

namespace internal {

ShapeFitResult FitShapeWithPivotedLdlt(std::span<const Eigen::Vector2d> points,
                                       const Silhouette& silhouette, const ShapePrior& prior,
                                       const ShapeFitOptions& options) {
  return FitFromStart<PivotedLdltSolver, true>(points, silhouette, prior, options);
}

ShapeFitResult FitShapeUnpaired(std::span<const Eigen::Vector2d> points,
                                const Silhouette& silhouette, const ShapePrior& prior,
                                const ShapeFitOptions& options) {
  return FitFromStart<NormalSolver, false, false>(points, silhouette, prior, options);
}

bool GuessWithinReach(ShapeModel model, const Eigen::Vector2d& size_m, double yaw_rad,
                      const Eigen::Vector2d& ray, double nearest_along,
                      const Eigen::Vector2d& guess) {
  Vec5 x = Vec5::Zero();
  x(kYaw) = yaw_rad;
  x(kA) = size_m.x();
  x(kB) = size_m.y();
  return lrfnet::tracking::GuessWithinReach(model, x, std::cos(yaw_rad), std::sin(yaw_rad), ray,
                                            nearest_along, guess);
}

Mat5 NormalSolverInverse(const Mat5& h, bool result_entries_only) {
  NormalSolver solver;
  if (!solver.Factor(h)) return Mat5::Constant(std::numeric_limits<double>::quiet_NaN());
  return result_entries_only ? solver.ResultInverse() : solver.Inverse();
}

double FitCubeRoot(double x) { return RootN<3>(x); }

Eigen::Vector2d FitCubeRootPair(double x0, double x1) {
  const Lanes root = RootN<3>(Lanes(x0, x1));
  return Eigen::Vector2d(root(0), root(1));
}

}  // namespace internal

}  // namespace lrfnet::tracking
