#pragma once
// Least-squares translations with the rotations fixed (pipeline step 7, after the rotation
// averaging; Quenzel et al. Sec. III-E: "estimating the translation then becomes an easy-to-solve
// linear problem").
//
// With the yaws φ fixed, every used measurement e = (r, s) (graph.h: t_r = t_s + R(φ_s) t_sr)
// gives the linear residual
//     ρ_e = t_r - t_s - R(φ_s) t_sr                                   (metres, world frame)
// and the positions (reference at the origin) minimise Σ_e ρ_e^T Ω_e ρ_e with
//     Ω_e = [use_covariances ? (R(φ_s) Σ_e R(φ_s)^T)^-1 : I] * [use_weights ? weight_e : 1],
// Σ_e the (x, y) block of the measurement's covariance (the translation of s_from_r, expressed
// in frame s, rotated into the world). The uncertainty of φ_s itself is not propagated.
//
// Per-node covariance: the 2x2 diagonal blocks of σ̂² H^-1, H = Σ J^T Ω J the normal matrix. With
// use_covariances and without weights the measurement covariances are taken as true (σ̂² = 1);
// otherwise σ̂² = χ²/dof, the residual variance of unit weight (dof = 2 m_used - 2 (n - 1)), or,
// when dof = 0 (a tree: nothing to estimate it from), prior_sigma_m² (1 with covariances) times
// the mean weight of the used measurements (weights are relative: the prior is the σ of a
// measurement of average weight).
//
// Pure functions; thread-safe.

#include <Eigen/Core>
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "central_daemon/calibration/graph.h"

namespace lrfnet::calib {

struct TranslationOptions {
  bool use_weights = false;      // scale each edge's information by its weight
  bool use_covariances = false;  // use the measurements' translation covariances
  double prior_sigma_m = 0.05;   // σ of a translation measurement when it cannot be estimated
};
std::optional<std::string> Validate(const TranslationOptions& options);

struct TranslationResult {
  bool ok = false;
  std::string error;
  std::vector<Eigen::Vector2d> position_m;       // world_from_node translation; reference 0
  std::vector<Eigen::Matrix2d> position_cov_m2;  // reference 0
  std::vector<double> residual_m;                // per measurement (used or not): |ρ_e|
  double chi2 = 0.0;                             // Σ ρ^T Ω ρ over the used measurements
  long dof = 0;                                  // 2 m_used - 2 (n - 1)
  double variance_factor = 1.0;                  // σ̂² applied to H^-1
};

// Least squares with the rotations fixed (only the measurements flagged in `use` take part;
// `use` has one flag per measurement). Errors (ok = false): bad input (graph.h CheckGraphInput;
// with use_covariances the used measurements' translation covariances must be positive definite),
// yaw_rad not of size n or not finite, `use` of the wrong size, or nodes not connected to the
// reference through the used measurements (the error names them).
TranslationResult SolveTranslations(std::size_t n, std::size_t reference,
                                    const std::vector<double>& yaw_rad,
                                    const std::vector<RelativeMeasurement>& measurements,
                                    const std::vector<bool>& use,
                                    const TranslationOptions& options);

}  // namespace lrfnet::calib
