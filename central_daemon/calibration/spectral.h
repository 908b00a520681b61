#pragma once
// Spectral relaxation [21] (Singer, angular synchronisation), the non-robust rotation baseline of
// Quenzel et al.: the yaws are the phases of the top eigenvector z of the Hermitian n x n matrix
//     H_rs = Σ_{e = (r, s)} w_e e^{iθ_e},   H_sr = conj(H_rs),   H_vv = 0
// (w_e = weight when use_weights, else 1). Noise-free, H = Z A Z^H with Z = diag(e^{iφ_v}) and A
// the weighted adjacency matrix, whose top eigenvector is positive for a connected graph
// (Perron-Frobenius): the phases of H's top eigenvector Z u are the yaws exactly. Every
// measurement pulls on it in proportion to its weight, so outliers bias every yaw (no
// rejection). Angles are returned relative to the reference. The eigenvector comes from a Lanczos
// iteration with full re-orthogonalisation on the sparse H (O(k m + k^2 n) for k steps, k <= n;
// converged to a Ritz residual of 1e-12 relative), not a dense O(n^3) eigensolver.
//
// Pure functions; thread-safe.

#include <cstddef>
#include <vector>

#include "central_daemon/calibration/graph.h"
#include "central_daemon/calibration/rotation_averaging.h"

namespace lrfnet::calib {

// yaw_rad from the eigenvector; residual_rad, inlier (RotationAveragingOptions defaults:
// outlier_threshold_deg), l1_cost and yaw_sigma_rad as for AverageRotationsL1. Errors as there
// (bad input, a node not connected to the reference).
RotationAveragingResult AverageRotationsSpectral(
    std::size_t n, std::size_t reference, const std::vector<RelativeMeasurement>& measurements,
    bool use_weights);
// The same with the diagnostics' options (options.use_weights is the weighting).
RotationAveragingResult AverageRotationsSpectral(
    std::size_t n, std::size_t reference, const std::vector<RelativeMeasurement>& measurements,
    const RotationAveragingOptions& options);

// The bare eigenvector step: yaws (reference 0) of the top eigenvector; no checks (the inputs
// must pass CheckGraphInput and be connected).
std::vector<double> SpectralYaws(std::size_t n, std::size_t reference,
                                 const std::vector<RelativeMeasurement>& measurements,
                                 bool use_weights);

}  // namespace lrfnet::calib
