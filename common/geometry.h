#pragma once
// Planar geometry: angles and SE(2) poses.
//
// Frames follow the driver convention of DESIGN.md: a sensor's x axis points forward (the telegram's 90°
// beam), y to the left, angles counter-clockwise, metres and radians. A pose named `a_from_b` maps
// coordinates in frame b to frame a:  p_a = a_from_b * p_b.

#include <Eigen/Core>
#include <cmath>
#include <numbers>
#include <utility>

namespace lrfnet::common {

inline constexpr double kPi = std::numbers::pi;

constexpr double DegToRad(double deg) { return deg * (kPi / 180.0); }
constexpr double RadToDeg(double rad) { return rad * (180.0 / kPi); }

// Wraps an angle to (-pi, pi].
inline double NormalizeAngle(double angle_rad) {
  double a = std::remainder(angle_rad, 2.0 * kPi);  // in [-pi, pi]
  if (a <= -kPi) a += 2.0 * kPi;
  return a;
}

// std::remainder(a_rad, kPi) bit for bit (in [-pi/2, pi/2]), without the libm call where the
// quotient's nearest integer n is plain: |a| < pi/2 gives n = 0 (a itself); pi/2 < |a| < 3 pi/2
// gives n = +-1, and a -+ pi is exact there (Sterbenz: within a factor 2 of pi). |a| = pi (a zero
// whose sign libm takes from a), pi/2 and 3 pi/2 (ties), beyond, and NaN go to libm.
inline double RemainderHalfTurn(double a_rad) {
  const double m = std::abs(a_rad);
  if (m < kPi / 2) return a_rad;
  // 1.5 * kPi rounds to a neighbour of 3 pi/2: no double lies strictly between the two, so
  // m < 1.5 * kPi holds for the same doubles as m < 3 pi/2.
  if (m > kPi / 2 && m < 1.5 * kPi && m != kPi) return a_rad > 0.0 ? a_rad - kPi : a_rad + kPi;
  return std::remainder(a_rad, kPi);
}

// std::hypot(x, y) without the libm call where both magnitudes lie in [2^-459, 2^511] (inputs
// there never overflow or underflow when squared): the root of the sum of squares, corrected by
// the rounding error of the squares as glibc's FMA-free hypot does (C. F. Borges, "An Improved
// Algorithm for hypot(a,b)", arXiv:1904.09481, 2019, algorithm 4; glibc 2.35 e_hypot.c), bit for
// bit what glibc's x86-64 libm returns. Zeros, tiny, huge and non-finite inputs go to libm.
inline double Hypot(double x, double y) {
  double ax = std::abs(x), ay = std::abs(y);
  if (ax < ay) std::swap(ax, ay);
  if (!(ay >= 0x1p-459 && ax <= 0x1p511)) return std::hypot(x, y);
  if (ay <= ax * 0x1p-54) return ax + ay;
  double h = std::sqrt(ax * ax + ay * ay);
  double t1, t2;
  if (h <= 2.0 * ay) {
    const double delta = h - ay;
    t1 = ax * (2.0 * delta - ax);
    t2 = (delta - 2.0 * (ax - ay)) * delta;
  } else {
    const double delta = h - ax;
    t1 = 2.0 * delta * (ax - 2.0 * ay);
    t2 = (4.0 * delta - ay) * ay + delta * delta;
  }
  h -= (t1 + t2) / (2.0 * h);
  return h;
}

// Smallest signed difference a - b, wrapped to (-pi, pi].
inline double AngleDiff(double a_rad, double b_rad) { return NormalizeAngle(a_rad - b_rad); }

// A rigid transform in the plane: rotation by yaw_rad, then translation (x_m, y_m).
struct Pose2 {
  double x_m = 0.0;
  double y_m = 0.0;
  double yaw_rad = 0.0;

  static Pose2 Identity() { return {}; }

  Eigen::Vector2d translation() const { return {x_m, y_m}; }
  Eigen::Matrix2d rotation() const {
    const double c = std::cos(yaw_rad), s = std::sin(yaw_rad);
    Eigen::Matrix2d r;
    r << c, -s, s, c;
    return r;
  }

  // this * p (p given in the right-hand frame).
  Eigen::Vector2d operator*(const Eigen::Vector2d& p) const { return rotation() * p + translation(); }

  // Composition: (a_from_b * b_from_c) = a_from_c. Yaw is kept in (-pi, pi].
  Pose2 operator*(const Pose2& o) const {
    const Eigen::Vector2d t = (*this) * o.translation();
    return {t.x(), t.y(), NormalizeAngle(yaw_rad + o.yaw_rad)};
  }

  Pose2 inverse() const {
    const Eigen::Vector2d t = -(rotation().transpose() * translation());
    return {t.x(), t.y(), NormalizeAngle(-yaw_rad)};
  }
};

// Rotation distance |yaw_a - yaw_b| in radians, wrapped, and translation distance in metres.
inline double RotationDistanceRad(const Pose2& a, const Pose2& b) {
  return std::abs(AngleDiff(a.yaw_rad, b.yaw_rad));
}
inline double TranslationDistanceM(const Pose2& a, const Pose2& b) {
  return (a.translation() - b.translation()).norm();
}

}  // namespace lrfnet::common
