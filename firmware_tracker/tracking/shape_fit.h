#pragma once
// The body centre of one segment from a fit of the object's known shape, whose size is a state of
// its track (not the centre of the visible side: the sensor sees only the near half of a body).
//
// Model. The object's cross-section at the scan plane is one of
//   - kSuperellipse: |u / a|^p + |v / b|^p = 1 with semi-axes a (along yaw) and b and a fixed
//     exponent p (2: an ellipse, a cylinder when a = b; larger: towards a rectangle), a person's
//     upper body (between an ellipse and a rounded box: p = 2.5);
//   - kBox: a rectangle with half-lengths a (along yaw) and b, a trolley or a cart;
//   - kCircle: radius a (b is ignored), a leg at knee height;
// with centre c and orientation yaw. The unknowns x = (c_x, c_y, yaw, a, b) (kCircle: (c_x, c_y,
// a)) are found by maximising their posterior (Gauss-Newton on the sum of squares below):
//   points:  r_i = d(p_i; x) / sigma_i,  d the distance of point p_i from the shape's outline
//            (superellipse: the first-order (Sampson) distance (S - 1) / |grad S| with
//            S = |u / a|^p + |v / b|^p, (u, v) = R(yaw)^T (p_i - c); box: the signed distance to
//            the rectangle; circle: |p_i - c| - a),
//            sigma_i^2 = (point_sigma_m + point_sigma_per_m |p_i|)^2 + model_sigma_m^2, inflated by
//            n / effective_points when there are more points than that (model errors of
//            neighbouring points are correlated: the data do not average them away), with Huber's
//            loss beyond robust_k sigma against points of something else in the segment;
//   edges:   the silhouette. The rays through the two ends of the segment's beam run, half a beam
//            step outwards (the outline's tangent lies between the last beam that hit and the first
//            that missed: uniform, sigma = range * step / sqrt(12)), touch the body:
//            r_e = (n_e . c + h(n_e; x)) / sigma_e with n_e the ray's normal pointing away from the
//            body and h the support function (superellipse: the dual norm
//            (|a n.e1|^q + |b n.e2|^q)^(1/q), 1/p + 1/q = 1; box: a |n.e1| + b |n.e2|; circle: a).
//            An edge whose neighbouring beam is nearer (an
//            occluder) or outside the field of view is not a silhouette and is left out;
//   priors:  size (a, b) ~ N(prior.size_m, prior.size_cov_m2) (the track's size state), yaw ~
//            N(prior.yaw_rad, prior.yaw_sigma_rad^2) modulo pi (a track's walking direction; a
//            flat prior when unknown).
// With 2-4 points the priors and the direction to the sensor (edges) carry the fit: the centre
// lies behind the points by the body's extent along the ray, with a covariance that grows with what
// the data leave open. The covariance of x is the inverse of the Gauss-Newton normal matrix at the
// solution; its (c_x, c_y) block is the measurement covariance, its (a, b) block the track's new
// size covariance (the prior was the old state: no double counting).
//
// Frames: sensor frame (sensor at the origin), metres, radians. Pure and allocation-free (per-point
// scratch on the stack, at most max_points points are used: evenly subsampled beyond that).

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>

namespace lrfnet::tracking {

enum class ShapeModel : std::uint8_t { kSuperellipse, kBox, kCircle };

// Sigma of a yaw prior that says nothing (a flat prior over [0, pi)).
inline constexpr double kUnknownYawSigmaRad = 100.0;

// Where the segment's silhouette ends (see the header comment).
struct Silhouette {
  double first_edge_rad = 0.0;  // where the first hit beam's outline tangent is expected
  double last_edge_rad = 0.0;   // and the last hit beam's
  double step_rad = 0.0;        // uncertainty of those angles (a uniform width, radians)
  bool first_valid = false;
  bool last_valid = false;
  // (cos, sin) of first_edge_rad and last_edge_rad where the caller has them (the same values as
  // std::cos and std::sin of the angles, e.g. from a table of the scan's beams); unknown: the fit
  // computes them.
  std::array<double, 2> first_edge_unit = {0.0, 0.0};
  std::array<double, 2> last_edge_unit = {0.0, 0.0};
  bool first_edge_unit_known = false;
  bool last_edge_unit_known = false;
};

// Where a fit starts when the start's guess (the track's prediction) lies outside the silhouette's
// wedge (between the rays through its two ends, half a beam step beyond the outermost beams that
// hit): no body there touches both ends.
enum class OutsideGuessStart : std::uint8_t {
  kGuess,       // at the guess, as anywhere else (as before)
  kSilhouette,  // where no guess is given: behind the points on the ray through their middle
  kBetter,      // from both; the solution with the lower cost of the terms that do not depend on
                // the start (ShapeFitResult::cost: points, edges, size and yaw priors)
};

struct ShapePrior {
  ShapeModel model = ShapeModel::kSuperellipse;
  Eigen::Vector2d size_m = Eigen::Vector2d(0.23, 0.14);  // (a, b); kCircle: (radius, unused)
  double exponent = 2.5;                                 // kSuperellipse: p (>= 2)
  Eigen::Matrix2d size_cov_m2 = 0.04 * 0.04 * Eigen::Matrix2d::Identity();
  double yaw_rad = 0.0;  // direction of axis a
  double yaw_sigma_rad = kUnknownYawSigmaRad;
  // Where to start (e.g. the track's predicted centre); used when it lies behind the points.
  std::optional<Eigen::Vector2d> centre_guess_m;
};

struct ShapeFitOptions {
  double point_sigma_m = 0.015;      // range noise at 0 m (1 sigma)
  // Range noise growth per metre. The scanners' statistical errors (1 sigma): LMS1xx 12 mm and TiM
  // 20 mm over their ranges, LMS5xx 6 / 8 / 14 mm at 1-10 / 10-20 / 20-30 m (the only one that
  // grows, ~0.3-0.4 mm/m); with point_sigma_m that is at most 0.015 + 0.0002 R (0.019 m at 20 m).
  // 0.001 (as before: 0.03 m at 15 m, 2.5 times an LMS1xx's noise) made far fits lean on the
  // priors and report a covariance that far too large (tracking_benchmark --before-range-noise,
  // upper body per sensor, shipped scenes: clear view of an LMS111 NEES 0.74; range 10-20 m 1.19).
  double point_sigma_per_m = 0.0002;
  double model_sigma_m = 0.01;       // how far a real outline departs from the model, per point
  double edge_floor_sigma_m = 0.01;  // mixed pixels and beam width at an edge
  double effective_points = 8.0;     // points beyond this count as correlated (see above)
  double robust_k = 2.0;             // Huber threshold, in sigmas
  int max_iterations = 6;
  std::size_t max_points = 8;
  double min_size_m = 0.01;
  double max_size_m = 2.0;
  // A superellipse's points (exponent 2 or 2.5) in single precision, four at a time: distances,
  // gradients and their sums rounded to about 1e-7 relative (about 1e-8 m on a distance, far below
  // the range noise); edges, priors, solver and covariance in double. Default true; false: every
  // point in double, two at a time (the previous arithmetic, the same results as before).
  bool single_precision_points = true;
  // Each silhouette edge's normal points away from the bisector of the points (inside the wedge
  // between the edges' rays). false: away from the start (the track's prediction where one is
  // taken), as before; a prediction beyond an edge's ray then turned that edge round and held the
  // body outside the silhouette (far views of 2-4 points, the centre 0.25-0.37 m to the side).
  bool edges_face_points = true;
  // A view whose track's prediction has drifted beside its silhouette (far views of 2-4 points:
  // from the prediction the fit stayed beside the points and the error crept from scan to scan).
  // Applies to fits of segments of at most outside_guess_max_points points with both silhouette
  // ends. kBetter was measured too and kept fewer tracks on their people than kSilhouette.
  OutsideGuessStart outside_guess_start = OutsideGuessStart::kSilhouette;
  std::size_t outside_guess_max_points = 1000;
};

std::optional<std::string> Validate(const ShapeFitOptions& options);

struct ShapeFitResult {
  bool ok = false;  // false: degenerate input (no finite point), nothing below is meaningful
  Eigen::Vector2d centre_m = Eigen::Vector2d::Zero();
  Eigen::Matrix2d centre_cov_m2 = Eigen::Matrix2d::Identity();
  Eigen::Vector2d size_m = Eigen::Vector2d::Zero();
  Eigen::Matrix2d size_cov_m2 = Eigen::Matrix2d::Identity();
  double yaw_rad = 0.0;
  double yaw_sigma_rad = kUnknownYawSigmaRad;
  // The objective at the solution without the weak prior on the centre around the start: points,
  // silhouette edges, size and yaw priors (the fits from two starts compare by it).
  double cost = 0.0;
  double rms_m = 0.0;       // RMS of the point distances to the fitted outline
  double line_rms_m = 0.0;  // RMS distance of the points to their principal line (flat: small)
  double extent_m = 0.0;    // first to last point
  std::size_t points_used = 0;
  int iterations = 0;
  int evaluations = 0;  // evaluations of the objective (each one pass over the points)
};

// Precondition: options valid; prior sizes positive, covariance positive definite.
ShapeFitResult FitShape(std::span<const Eigen::Vector2d> points, const Silhouette& silhouette,
                        const ShapePrior& prior, const ShapeFitOptions& options);

namespace internal {
// FitShape with Eigen's pivoted LDLT for every solve of the normal equations, as FitShape solved
// them before its own 5 x 5 Cholesky: the same iterations, so the same result up to rounding. For
// the equivalence test only.
ShapeFitResult FitShapeWithPivotedLdlt(std::span<const Eigen::Vector2d> points,
                                       const Silhouette& silhouette, const ShapePrior& prior,
                                       const ShapeFitOptions& options);
// FitShape with every point's and edge's arithmetic one at a time, as FitShape did before it
// took two side by side: the same operations, so the same result. For the equivalence test only.
ShapeFitResult FitShapeUnpaired(std::span<const Eigen::Vector2d> points,
                                const Silhouette& silhouette, const ShapePrior& prior,
                                const ShapeFitOptions& options);
// The fit's own 5 x 5 solver on a symmetric positive definite h: its inverse, all of it or only
// the entries a fit reports (the centre's and the size's blocks, the yaw's variance; the others
// 0). For the test that both give those entries with the same bits.
Eigen::Matrix<double, 5, 5> NormalSolverInverse(const Eigen::Matrix<double, 5, 5>& h,
                                                bool result_entries_only);
// Whether the start's guess lies within reach (0.5 m) of (nearest_along + depth) ray for every
// depth (the support function along the ray) a superellipse of this size and orientation can
// have; false where that does not settle it or for the other models. Where true, the fit takes
// the guess without computing the depth.
bool GuessWithinReach(ShapeModel model, const Eigen::Vector2d& size_m, double yaw_rad,
                      const Eigen::Vector2d& ray, double nearest_along,
                      const Eigen::Vector2d& guess);
// The fit's cube root (Halley's iteration from a guess built from the exponent bits; libm's cbrt
// outside [1e-290, 1e290]) of x, and of two values side by side in one lane pair as the support
// function takes them. For the test that both give the same bits.
double FitCubeRoot(double x);
Eigen::Vector2d FitCubeRootPair(double x0, double x1);
}  // namespace internal

// Support function of the shape (extent from the centre in direction n, unit vector); d_size, if
// given, receives its derivative with respect to the size (a, b).
double ShapeSupport(ShapeModel model, const Eigen::Vector2d& size_m, double yaw_rad,
                    const Eigen::Vector2d& n, double exponent = 2.0,
                    Eigen::Vector2d* d_size = nullptr);

// ShapeSupport in two directions n0 and n1 of the same shape at once (the same values as two
// calls; one sine and cosine of the yaw, the superellipse's two chains of roots side by side):
// their derivatives with respect to the size into d_size0 and d_size1 (both required).
void ShapeSupportPair(ShapeModel model, const Eigen::Vector2d& size_m, double yaw_rad,
                      const Eigen::Vector2d& n0, const Eigen::Vector2d& n1, double exponent,
                      Eigen::Vector2d* d_size0, Eigen::Vector2d* d_size1);

}  // namespace lrfnet::tracking
