#include "central_daemon/calibration/placement.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>

namespace lrfnet::calib {
namespace {

// The samples of one sensor on the used steps, flat (CSR by used step).
struct StepIndex {
  std::vector<std::size_t> begin;  // per used step, into the arrays below; size used + 1
  std::vector<Eigen::Vector2d> centre;
  std::vector<Eigen::Matrix2d> cov;
};

bool Finite(const TrackSample& x) {
  return x.position_m.allFinite() && x.position_cov_m2.allFinite() && std::isfinite(x.bias_m) &&
         std::isfinite(x.bias_per_major) && std::isfinite(x.bias_per_minor) &&
         std::isfinite(x.bias_sigma_m) && std::isfinite(x.model_sigma_m) &&
         x.position_m.cwiseAbs().maxCoeff() < 1e5;
}

StepIndex IndexOf(const SensorTracks& sensor, std::size_t steps, std::size_t stride,
                  double prior_var) {
  const std::size_t used = steps == 0 ? 0 : (steps - 1) / stride + 1;
  std::vector<std::size_t> count(used + 1, 0);
  for (const GridTrack& t : sensor.tracks) {
    for (std::size_t k = (t.first_step + stride - 1) / stride * stride;
         k < std::min(t.end_step(), steps); k += stride) {
      if (Finite(t.At(k))) ++count[k / stride + 1];
    }
  }
  StepIndex out;
  out.begin.assign(used + 1, 0);
  for (std::size_t i = 0; i < used; ++i) out.begin[i + 1] = out.begin[i] + count[i + 1];
  const std::size_t total = out.begin[used];
  out.centre.resize(total);
  out.cov.resize(total);
  std::vector<std::size_t> next(out.begin.begin(), out.begin.end() - (used > 0 ? 1 : 0));
  for (const GridTrack& t : sensor.tracks) {
    for (std::size_t k = (t.first_step + stride - 1) / stride * stride;
         k < std::min(t.end_step(), steps); k += stride) {
      const TrackSample& x = t.At(k);
      if (!Finite(x)) continue;
      const std::size_t i = next[k / stride]++;
      out.centre[i] = CentreOf(x);
      const Eigen::Matrix2d j = CentrePerSizeCorrection(x);
      out.cov[i] = CentreCovariance(x) + prior_var * (j * j.transpose());
    }
  }
  return out;
}

}  // namespace

PlacementCost EvaluatePlacement(const AlignedTracks& tracks,
                                const std::vector<Pose2>& world_from_sensor,
                                const std::vector<bool>& placed, const PlacementOptions& options) {
  PlacementCost out;
  const std::size_t n = tracks.sensors.size();
  if (world_from_sensor.size() != n || placed.size() != n) return out;
  const std::size_t stride = std::max<std::size_t>(1, options.stride);
  const double prior_var = std::isfinite(tracks.size_prior_sigma_m)
                               ? tracks.size_prior_sigma_m * tracks.size_prior_sigma_m
                               : 0.0;
  std::vector<StepIndex> index(n);
  for (std::size_t s = 0; s < n; ++s) {
    if (placed[s]) index[s] = IndexOf(tracks.sensors[s], tracks.steps, stride, prior_var);
  }
  const double gate2 = options.gate * options.gate;
  const double model_var = options.model_sigma_m * options.model_sigma_m;
  double track = 0.0;
  for (std::size_t r = 0; r < n; ++r) {
    if (!placed[r]) continue;
    for (std::size_t s = 0; s < n; ++s) {
      if (s == r || !placed[s]) continue;
      const Pose2 s_from_r = world_from_sensor[s].inverse() * world_from_sensor[r];
      const Eigen::Matrix2d rot = s_from_r.rotation();
      const StepIndex& ir = index[r];
      const StepIndex& is = index[s];
      const std::size_t used = ir.begin.empty() ? 0 : ir.begin.size() - 1;
      for (std::size_t k = 0; k < used; ++k) {
        if (is.begin[k] == is.begin[k + 1]) continue;  // s tracks nobody at that step
        for (std::size_t i = ir.begin[k]; i < ir.begin[k + 1]; ++i) {
          const Eigen::Vector2d p = s_from_r * ir.centre[i];
          const Eigen::Matrix2d cp = rot * ir.cov[i] * rot.transpose();
          double best = gate2;
          for (std::size_t j = is.begin[k]; j < is.begin[k + 1]; ++j) {
            Eigen::Matrix2d c = cp + is.cov[j];
            c.diagonal().array() += model_var;
            const Eigen::Vector2d d = p - is.centre[j];
            if (d.squaredNorm() >= best * c.trace()) continue;  // cheap bound
            const Eigen::LLT<Eigen::Matrix2d> llt(c);
            if (llt.info() != Eigen::Success) continue;
            best = std::min(best, d.dot(llt.solve(d)));
          }
          track += best;
          ++out.observations;
        }
      }
    }
  }
  out.track = track * std::min(1.0, static_cast<double>(stride) / options.correlation_steps);
  for (std::size_t r = 0; r < n; ++r) {
    if (!placed[r] || !tracks.sensors[r].background) continue;
    for (std::size_t s = r + 1; s < n; ++s) {
      if (!placed[s] || !tracks.sensors[s].background) continue;
      const Pose2 s_from_r = world_from_sensor[s].inverse() * world_from_sensor[r];
      const auto score = ScoreBackgrounds(*tracks.sensors[r].background,
                                          *tracks.sensors[s].background, s_from_r, options.icp);
      if (!score) continue;
      out.background += score->score * static_cast<double>(score->points) /
                        std::max(1.0, options.background_correlation);
    }
  }
  out.total = out.track + out.background;
  return out;
}

}  // namespace lrfnet::calib
