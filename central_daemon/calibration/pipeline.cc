#include "central_daemon/calibration/pipeline.h"

#include <spdlog/fmt/fmt.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <utility>

#include "central_daemon/calibration/graph.h"
#include "central_daemon/calibration/placement.h"
#include "central_daemon/calibration/pose_graph.h"
#include "central_daemon/calibration/spectral.h"
#include "common/eigen_instances.h"

namespace lrfnet::calib {
namespace {

// Gate of the matches behind EdgeReport::track_residual_rms_m (metres, sensor s's frame).
constexpr double kEdgeReportGateM = 0.5;

class StageTimer {
 public:
  StageTimer(const StageClock& clock, std::vector<StageTime>* out) : clock_(clock), out_(out) {
    if (clock_) start_ = last_ = clock_();
  }
  void Mark(const char* stage) {
    if (!clock_) return;
    const double now = clock_();
    out_->push_back({stage, now - last_});
    last_ = now;
  }
  void Total() {
    if (clock_) out_->push_back({"total", clock_() - start_});
  }

 private:
  const StageClock& clock_;
  std::vector<StageTime>* out_;
  double start_ = 0.0;
  double last_ = 0.0;
};

std::string JoinIds(const AlignedTracks& tracks, const std::vector<std::size_t>& nodes) {
  std::string out;
  for (std::size_t i : nodes) out += (out.empty() ? "" : ", ") + tracks.sensors[i].id;
  return out;
}

// The sensors that saw people together with sensor i in a pair that was rejected, each with the
// reason's first words ("k1 (pair residual too large), t1 (pair inconsistent)"); empty when none.
std::string RejectedPartners(const AlignedTracks& tracks, const std::vector<PairEstimate>& pairs,
                             std::size_t i) {
  std::string out;
  for (const PairEstimate& p : pairs) {
    if (p.accepted || (p.r != i && p.s != i) || p.matches == 0) continue;
    const std::string why = p.reason.substr(0, p.reason.find(':'));
    out += fmt::format("{}{} (pair {})", out.empty() ? "" : ", ",
                       tracks.sensors[p.r == i ? p.s : p.r].id, why);
  }
  return out;
}

double WeightOf(const PairEstimate& pair) {
  // Schenk et al.: N / d, the number of associated observations over their mean distance.
  const double d = std::max(pair.mean_residual_m, 1e-3);
  return static_cast<double>(pair.matches) / d;
}

// Most strong pairs, then most weak ones, then most matched observations, then the first.
std::size_t BestConnected(const std::vector<PairEstimate>& pairs, std::size_t n) {
  std::vector<std::size_t> strong(n, 0), weak(n, 0), matches(n, 0);
  for (const PairEstimate& p : pairs) {
    if (!p.accepted) continue;
    for (std::size_t i : {p.r, p.s}) {
      ++(p.weak ? weak : strong)[i];
      matches[i] += p.matches;
    }
  }
  std::size_t best = 0;
  for (std::size_t i = 1; i < n; ++i) {
    if (std::tie(strong[i], weak[i], matches[i]) >
        std::tie(strong[best], weak[best], matches[best])) {
      best = i;
    }
  }
  return best;
}

std::optional<std::size_t> IndexOf(const AlignedTracks& tracks, const std::string& id) {
  for (std::size_t i = 0; i < tracks.sensors.size(); ++i) {
    if (tracks.sensors[i].id == id) return i;
  }
  return std::nullopt;
}

// Matched-observation residuals of sensors r and s under their final poses.
struct TrackResidual {
  double sum_sq = 0.0;
  std::size_t count = 0;
};
TrackResidual ResidualOf(const AlignedTracks& tracks, std::size_t r, std::size_t s,
                         const Pose2& s_from_r) {
  TrackResidual out;
  for (const Match& m : AssociatePair(tracks, r, s, s_from_r, kEdgeReportGateM)) {
    const Eigen::Vector2d pr = CentreOf(tracks.sensors[r].tracks[m.track_r].At(m.step));
    const Eigen::Vector2d ps = CentreOf(tracks.sensors[s].tracks[m.track_s].At(m.step));
    out.sum_sq += (s_from_r * pr - ps).squaredNorm();
    ++out.count;
  }
  return out;
}

// Global poses of the nodes connected to `reference` from the pairwise measurements. Fills the
// per-edge status (index = measurement index) and the per-sensor flags.
struct GlobalSolution {
  std::vector<Pose2> world_from_sensor;
  std::vector<bool> calibrated;
  std::vector<Eigen::Matrix3d> covariance;
  std::vector<std::string> edge_status;  // per measurement
  std::vector<bool> edge_used;           // per measurement
  std::vector<std::string> flag;         // per sensor
  // Per sensor where the joint refinement was applied, else empty.
  std::vector<std::optional<RadialBiasEstimate>> radial_bias;
  std::vector<std::string> warnings;
};

// A weak pair, or a strong one outside the rotation averaging, agrees with the poses when its
// Mahalanobis distance to the relative pose they imply is at most this (sigma units, 3 dof).
constexpr double kConsistentSigma = 3.5;
// Hypotheses: at most this many pairs are left out one by one; two placements are told apart when
// their robust costs (placement.h, independent squared sigmas) differ by at least kSeparation.
constexpr std::size_t kMaxHypotheses = 8;
constexpr double kSeparation = 9.0;

// The connected part of `use` around the reference as a sub-problem with its own indices.
struct SubProblem {
  std::vector<std::size_t> to_full;  // sub index -> full index
  std::vector<std::size_t> to_sub;   // full index -> sub index (kNoIndex: not in it)
  std::vector<RelativeMeasurement> measurements;
  std::vector<std::size_t> to_all;  // sub measurement -> measurement index
};
constexpr std::size_t kNoIndex = std::numeric_limits<std::size_t>::max();

SubProblem SubProblemOf(std::size_t n, std::size_t reference,
                        const std::vector<RelativeMeasurement>& all, const std::vector<bool>& use) {
  std::vector<RelativeMeasurement> kept;
  for (std::size_t e = 0; e < all.size(); ++e) {
    if (use[e]) kept.push_back(all[e]);
  }
  const std::vector<std::size_t> unconnected = UnconnectedNodes(n, reference, kept);
  SubProblem p;
  p.to_sub.assign(n, kNoIndex);
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::binary_search(unconnected.begin(), unconnected.end(), i)) {
      p.to_sub[i] = p.to_full.size();
      p.to_full.push_back(i);
    }
  }
  for (std::size_t e = 0; e < all.size(); ++e) {
    if (!use[e] || p.to_sub[all[e].r] == kNoIndex) continue;
    RelativeMeasurement m = all[e];
    m.r = p.to_sub[m.r];
    m.s = p.to_sub[m.s];
    p.measurements.push_back(m);
    p.to_all.push_back(e);
  }
  return p;
}

// Rotation averaging and translations of the spectral baseline (Quenzel et al.'s non-robust
// comparison): weighted spectral relaxation, weighted least-squares translations, every edge used.
GlobalSolution SolveSpectral(std::size_t n, std::size_t reference,
                             const std::vector<RelativeMeasurement>& all,
                             const CalibrationOptions& options) {
  GlobalSolution out;
  out.world_from_sensor.assign(n, Pose2::Identity());
  out.calibrated.assign(n, false);
  out.covariance.assign(n, Eigen::Matrix3d::Zero());
  out.edge_status.assign(all.size(), "used");
  out.edge_used.assign(all.size(), true);
  out.flag.assign(n, "");
  const SubProblem p = SubProblemOf(n, reference, all, std::vector<bool>(all.size(), true));
  for (std::size_t e = 0; e < all.size(); ++e) {
    if (p.to_sub[all[e].r] == kNoIndex) {
      out.edge_status[e] = "not connected to the reference";
      out.edge_used[e] = false;
    }
  }
  const std::size_t m = p.to_full.size();
  out.calibrated[reference] = true;
  if (m == 1) return out;
  const RotationAveragingResult rotations =
      AverageRotationsSpectral(m, p.to_sub[reference], p.measurements, options.weighted);
  if (!rotations.ok) {
    out.warnings.push_back("rotation averaging failed: " + rotations.error);
    return out;
  }
  TranslationOptions translation_options = options.translation;
  translation_options.use_weights = true;
  const TranslationResult translations =
      SolveTranslations(m, p.to_sub[reference], rotations.yaw_rad, p.measurements,
                        std::vector<bool>(p.measurements.size(), true), translation_options);
  if (!translations.ok) {
    out.warnings.push_back("translation estimation failed: " + translations.error);
    return out;
  }
  for (std::size_t i = 0; i < m; ++i) {
    const std::size_t full = p.to_full[i];
    out.calibrated[full] = true;
    out.world_from_sensor[full] = {translations.position_m[i].x(), translations.position_m[i].y(),
                                   common::NormalizeAngle(rotations.yaw_rad[i])};
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    if (i < translations.position_cov_m2.size()) {
      cov.topLeftCorner<2, 2>() = translations.position_cov_m2[i];
    }
    if (i < rotations.yaw_sigma_rad.size()) {
      cov(2, 2) = rotations.yaw_sigma_rad[i] * rotations.yaw_sigma_rad[i];
    }
    out.covariance[full] = cov;
  }
  out.world_from_sensor[reference] = Pose2::Identity();
  out.covariance[reference].setZero();
  return out;
}

// The robust global step of the quenzel method on the strong pairs (pipeline.h "Global step"):
// L1 rotation averaging for the outliers, least-squares translations (and their outliers), then
// the joint weighted least squares of rotations and translations on the inliers.
struct CoreSolution {
  bool ok = false;
  std::vector<bool> placed;                 // full index
  std::vector<Pose2> poses;                 // full index
  std::vector<Eigen::Matrix3d> covariance;  // full index (of the least squares)
  std::vector<bool> used;                   // per measurement: an inlier of the solution
  std::vector<bool> outlier;                // per measurement: considered and dropped
  std::vector<std::string> status;
  std::vector<std::string> warnings;
};

CoreSolution SolveCore(std::size_t n, std::size_t reference,
                       const std::vector<RelativeMeasurement>& all, const std::vector<bool>& strong,
                       const CalibrationOptions& options) {
  CoreSolution out;
  out.placed.assign(n, false);
  out.poses.assign(n, Pose2::Identity());
  out.covariance.assign(n, Eigen::Matrix3d::Zero());
  out.used.assign(all.size(), false);
  out.outlier.assign(all.size(), false);
  out.status.assign(all.size(), "");
  out.placed[reference] = true;
  const SubProblem p = SubProblemOf(n, reference, all, strong);
  const std::size_t m = p.to_full.size();
  const std::size_t ref = p.to_sub[reference];
  out.ok = true;
  if (m == 1) return out;
  RotationAveragingOptions rotation_options = options.rotation;
  rotation_options.use_weights = options.weighted;
  const RotationAveragingResult rotations =
      AverageRotationsL1(m, ref, p.measurements, rotation_options);
  if (!rotations.ok) {
    out.ok = false;
    out.warnings.push_back("rotation averaging failed: " + rotations.error);
    return out;
  }
  std::vector<bool> use(p.measurements.size(), true);
  for (std::size_t e = 0; e < p.measurements.size(); ++e) {
    if (e < rotations.inlier.size() && !rotations.inlier[e]) {
      use[e] = false;
      out.status[p.to_all[e]] = "rotation outlier";
    }
  }
  // Dropping outliers must not disconnect the graph: such an edge is the only link we have.
  const auto kept_of = [&](const std::vector<bool>& flags) {
    std::vector<RelativeMeasurement> kept;
    for (std::size_t e = 0; e < p.measurements.size(); ++e) {
      if (flags[e]) kept.push_back(p.measurements[e]);
    }
    return kept;
  };
  if (!UnconnectedNodes(m, ref, kept_of(use)).empty()) {
    for (std::size_t e = 0; e < p.measurements.size(); ++e) {
      if (!use[e]) {
        use[e] = true;
        out.status[p.to_all[e]] = "used (rotation outlier, but the only link)";
      }
    }
    out.warnings.push_back(
        "a rotation outlier edge is the only link of some sensors; their poses are uncertain");
  }
  TranslationOptions translation_options = options.translation;
  translation_options.use_weights = options.weighted;
  translation_options.use_covariances = !options.weighted;
  TranslationResult translations =
      SolveTranslations(m, ref, rotations.yaw_rad, p.measurements, use, translation_options);
  if (translations.ok) {
    // A rotation-consistent edge can still be a wrong translation (a mismatch along a line of
    // tracks): drop edges far off the solution and solve again, if the graph stays connected.
    std::vector<bool> use2 = use;
    bool dropped = false;
    for (std::size_t e = 0; e < p.measurements.size(); ++e) {
      if (use2[e] && e < translations.residual_m.size() &&
          translations.residual_m[e] > options.max_translation_residual_m) {
        use2[e] = false;
        dropped = true;
      }
    }
    if (dropped && UnconnectedNodes(m, ref, kept_of(use2)).empty()) {
      TranslationResult again =
          SolveTranslations(m, ref, rotations.yaw_rad, p.measurements, use2, translation_options);
      if (again.ok) {
        for (std::size_t e = 0; e < p.measurements.size(); ++e) {
          if (use[e] && !use2[e]) out.status[p.to_all[e]] = "translation outlier";
        }
        use = use2;
        translations = std::move(again);
      }
    }
  }
  if (!translations.ok) {
    out.ok = false;
    out.warnings.push_back("translation estimation failed: " + translations.error);
    return out;
  }
  std::vector<Pose2> initial(m);
  for (std::size_t i = 0; i < m; ++i) {
    initial[i] = {translations.position_m[i].x(), translations.position_m[i].y(),
                  rotations.yaw_rad[i]};
  }
  // The joint weighted least squares on the inliers (pose_graph.h).
  const PoseGraphResult ls = SolvePoseGraph(m, ref, p.measurements, use, initial);
  const std::vector<Pose2>& poses = ls.ok ? ls.world_from_node : initial;
  if (!ls.ok) out.warnings.push_back("weighted least squares failed: " + ls.error);
  for (std::size_t i = 0; i < m; ++i) {
    out.placed[p.to_full[i]] = true;
    out.poses[p.to_full[i]] = poses[i];
    if (ls.ok) out.covariance[p.to_full[i]] = ls.covariance[i];
  }
  out.poses[reference] = Pose2::Identity();
  for (std::size_t e = 0; e < p.measurements.size(); ++e) {
    const std::size_t k = p.to_all[e];
    out.used[k] = use[e];
    out.outlier[k] = !use[e];
    if (use[e] && out.status[k].empty()) out.status[k] = "used";
  }
  return out;
}

// A flag "placed through the weak pair(s) P only" with the weak pair `pair` added ("... weak pairs
// P, pair only"); any other flag unchanged.
std::string WithWeakPair(const std::string& flag, const std::string& pair) {
  const std::string single = "placed through the weak pair ",
                    plural = "placed through the weak pairs ", only = " only";
  const std::string& head = flag.starts_with(plural) ? plural : single;
  if (!flag.starts_with(head) || !flag.ends_with(only) || flag.size() < head.size() + only.size()) {
    return flag;
  }
  return plural + flag.substr(head.size(), flag.size() - head.size() - only.size()) + ", " + pair +
         only;
}

// A sensor placed through a weak pair (or through a sensor so placed): the sensor it hangs on and
// the pair (measurement index).
struct WeakLeaf {
  std::size_t sensor = 0, anchor = 0, edge = 0;
};

// The sensors and pairs the strong core did not settle: pairs between placed sensors are used when
// they agree with the poses (kConsistentSigma); a pair with one placed end places the other
// (flagged when the pair is weak or the placed end is flagged). Candidates in order of their
// translation uncertainty.
void Extend(const std::vector<RelativeMeasurement>& all, const std::vector<bool>& weak,
            const std::vector<std::string>& id, CoreSolution* core, std::vector<std::string>* flag,
            std::vector<WeakLeaf>* leaves) {
  std::vector<std::size_t> order;
  for (std::size_t e = 0; e < all.size(); ++e) {
    if (!core->used[e] && !core->outlier[e]) order.push_back(e);
  }
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return all[a].covariance.topLeftCorner<2, 2>().trace() <
           all[b].covariance.topLeftCorner<2, 2>().trace();
  });
  std::vector<Eigen::Matrix3d> cov = core->covariance;
  std::vector<bool> decided(all.size(), false);
  for (bool changed = true; changed;) {
    changed = false;
    for (std::size_t e : order) {
      if (decided[e]) continue;
      const RelativeMeasurement& m = all[e];
      const bool pr = core->placed[m.r], ps = core->placed[m.s];
      if (pr && ps) {
        // Relative pose of two placed sensors: from the poses, with the placement's rough
        // covariance (composed along the weak links; zero inside the core, whose pairs' own
        // covariances dominate the test).
        const RelativeFromPoses predicted =
            RelativePose(core->poses[m.r], cov[m.r], core->poses[m.s], cov[m.s]);
        const double d = MeasurementDistanceSigma(m.s_from_r, m.covariance, predicted);
        decided[e] = true;
        if (d <= kConsistentSigma) {
          core->used[e] = true;
          core->status[e] = fmt::format("used ({}confirmed by the others, {:.1f} sigma)",
                                        weak[e] ? "weak, " : "", d);
          // A flagged end now rests on this weak pair too: its flag names every weak pair.
          if (weak[e]) {
            for (std::size_t x : {m.r, m.s}) {
              (*flag)[x] = WithWeakPair((*flag)[x], id[m.r] + "-" + id[m.s]);
            }
          }
        } else {
          core->outlier[e] = !weak[e];
          core->status[e] = fmt::format("{}inconsistent with the others ({:.1f} sigma)",
                                        weak[e] ? "weak and " : "", d);
        }
        changed = true;
      } else if (pr != ps) {
        const std::size_t from = pr ? m.r : m.s, to = pr ? m.s : m.r;
        // world_from_r = world_from_s * s_from_r.
        core->poses[to] =
            pr ? core->poses[from] * m.s_from_r.inverse() : core->poses[from] * m.s_from_r;
        cov[to] = cov[from] + m.covariance;  // rough; the least squares below replaces it
        core->placed[to] = true;
        core->used[e] = true;
        decided[e] = true;
        core->status[e] = weak[e] ? "used (weak: the only link)" : "used";
        if (weak[e] || !(*flag)[from].empty()) {
          (*flag)[to] = (*flag)[from].empty()
                            ? "placed through the weak pair " + id[m.r] + "-" + id[m.s] + " only"
                            : (*flag)[from];
          leaves->push_back({to, from, e});
        }
        changed = true;
      }
    }
  }
  for (std::size_t e = 0; e < all.size(); ++e) {
    if (core->status[e].empty()) core->status[e] = "not connected to the reference";
  }
}

void FillEdges(const AlignedTracks& tracks, const std::vector<PairEstimate>& pairs,
               const std::vector<std::size_t>& measurement_of_pair,
               const std::vector<std::string>& edge_status, CalibrationResult* result) {
  double sum_sq = 0.0;
  std::size_t count = 0;
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    const PairEstimate& p = pairs[k];
    EdgeReport e;
    e.r = tracks.sensors[p.r].id;
    e.s = tracks.sensors[p.s].id;
    e.matches = p.matches;
    e.rms_m = p.rms_m;
    e.icp_applied = p.icp_applied;
    if (!p.accepted) {
      e.status = "rejected: " + p.reason;
    } else {
      e.status = edge_status[measurement_of_pair[k]];
      e.used = e.status.rfind("used", 0) == 0;
    }
    const SensorPose& sr = result->sensors[p.r];
    const SensorPose& ss = result->sensors[p.s];
    if (sr.calibrated && ss.calibrated) {
      const Pose2 final_s_from_r = ss.world_from_sensor.inverse() * sr.world_from_sensor;
      if (p.accepted) {
        e.rotation_residual_deg = common::RadToDeg(
            std::abs(common::AngleDiff(p.s_from_r.yaw_rad, final_s_from_r.yaw_rad)));
        e.translation_residual_m = common::TranslationDistanceM(p.s_from_r, final_s_from_r);
      }
      const TrackResidual residual = ResidualOf(tracks, p.r, p.s, final_s_from_r);
      if (residual.count > 0) {
        e.track_residual_rms_m = std::sqrt(residual.sum_sq / static_cast<double>(residual.count));
        if (e.used) {
          sum_sq += residual.sum_sq;
          count += residual.count;
        }
      }
    }
    result->edges.push_back(std::move(e));
  }
  result->track_residual_rms_m = count > 0 ? std::sqrt(sum_sq / static_cast<double>(count)) : 0.0;
}

void ApplyIcp(const AlignedTracks& tracks, const CalibrationOptions& options,
              std::vector<PairEstimate>* pairs) {
  for (PairEstimate& p : *pairs) {
    if (!p.accepted) continue;
    const SensorTracks& r = tracks.sensors[p.r];
    const SensorTracks& s = tracks.sensors[p.s];
    if (!r.background || !s.background) continue;
    const IcpResult icp =
        RefineWithBackgrounds(*r.background, *s.background, p.s_from_r, options.icp);
    p.icp_score_before = icp.score_before;
    p.icp_score_after = icp.score_after;
    if (!icp.applied) continue;
    // The backgrounds agree better; the tracks must still agree with them.
    const Eigen::Matrix3d pair_info_cov = 0.5 * (p.covariance + p.covariance.transpose());
    const Eigen::Matrix3d icp_cov = 0.5 * (icp.covariance + icp.covariance.transpose());
    const Eigen::Vector3d delta(icp.s_from_r.x_m - p.s_from_r.x_m,
                                icp.s_from_r.y_m - p.s_from_r.y_m,
                                common::AngleDiff(icp.s_from_r.yaw_rad, p.s_from_r.yaw_rad));
    // The tracks may carry a bias the model does not know (pipeline.h icp_track_bias_sigma_m).
    Eigen::Matrix3d test_cov = pair_info_cov + icp_cov;
    test_cov.topLeftCorner<2, 2>() += options.icp_track_bias_sigma_m *
                                      options.icp_track_bias_sigma_m * Eigen::Matrix2d::Identity();
    const Eigen::LLT<Eigen::Matrix3d> sum(test_cov);
    const Eigen::LLT<Eigen::Matrix3d> icp_llt(icp_cov), pair_llt(pair_info_cov);
    if (sum.info() != Eigen::Success || icp_llt.info() != Eigen::Success ||
        pair_llt.info() != Eigen::Success) {
      continue;
    }
    const double d = std::sqrt(std::max(0.0, delta.dot(sum.solve(delta))));
    if (!std::isfinite(d)) continue;
    if (d > options.icp_max_disagreement_sigma) {
      if (!options.conflicts_widen_covariance) continue;
      // Walls and tracks that disagree: one of the two carries an error its covariance does not
      // know, and the pair cannot tell which. The tracks' estimate stays, the variance of each
      // component widened by the square of its disagreement (not only along the disagreement:
      // several pairs of one sensor disagree alike, and rank-one widenings along their different
      // directions would cancel in the least squares), and the pair becomes a candidate that the
      // rest of the graph has to confirm.
      p.covariance = pair_info_cov;
      p.covariance.diagonal() += delta.cwiseProduct(delta);
      p.weak = true;
      p.weak_reason = fmt::format(
          "the backgrounds' alignment disagrees with the tracks by {:.1f} sigma ({:.2f} m, "
          "{:.2f} deg)",
          d, delta.head<2>().norm(), common::RadToDeg(std::abs(delta.z())));
      continue;
    }
    // Information-weighted fusion about the tracks' estimate.
    const Eigen::Matrix3d icp_info = icp_llt.solve(Eigen::Matrix3d::Identity());
    const Eigen::Matrix3d pair_info = pair_llt.solve(Eigen::Matrix3d::Identity());
    const Eigen::LLT<Eigen::Matrix3d> fused(icp_info + pair_info);
    if (fused.info() != Eigen::Success) continue;
    const Eigen::Matrix3d covariance = fused.solve(Eigen::Matrix3d::Identity());
    const Eigen::Vector3d step = covariance * (icp_info * delta);
    if (!step.allFinite() || !covariance.allFinite()) continue;
    p.icp_applied = true;
    p.icp_s_from_r = icp.s_from_r;
    p.icp_covariance = icp_cov;
    p.s_from_r = {p.s_from_r.x_m + step.x(), p.s_from_r.y_m + step.y(),
                  common::NormalizeAngle(p.s_from_r.yaw_rad + step.z())};
    p.covariance = 0.5 * (covariance + covariance.transpose());
    if (p.weak) {
      // The walls may fix what the tracks alone left open.
      const double yaw_sigma_deg = common::RadToDeg(std::sqrt(std::max(0.0, p.covariance(2, 2))));
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(
          Eigen::Matrix2d(p.covariance.topLeftCorner<2, 2>()));
      const double t_sigma = std::sqrt(std::max(0.0, eig.eigenvalues().maxCoeff()));
      if (yaw_sigma_deg <= options.pairwise.max_yaw_sigma_deg &&
          t_sigma <= options.pairwise.max_translation_sigma_m) {
        p.weak = false;
        p.weak_reason.clear();
      }
    }
  }
}

// The smallest covariance (in the PSD order, approximately) that is at least both `a` and `b`:
// `a` plus the positive part of b - a in a's whitened coordinates.
Eigen::Matrix3d AtLeast(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  const Eigen::Matrix3d as = 0.5 * (a + a.transpose()), bs = 0.5 * (b + b.transpose());
  const Eigen::LLT<Eigen::Matrix3d> llt(as);
  if (llt.info() != Eigen::Success) return bs;
  const Eigen::Matrix3d l = llt.matrixL();
  const Eigen::Matrix3d l_inv = l.inverse();
  const Eigen::Matrix3d w = l_inv * bs * l_inv.transpose();  // b in a's whitened coordinates
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(
      Eigen::Matrix3d(0.5 * (w + w.transpose())));
  const Eigen::Vector3d grown = eig.eigenvalues().cwiseMax(1.0);
  const Eigen::Matrix3d out =
      l * (eig.eigenvectors() * grown.asDiagonal() * eig.eigenvectors().transpose()) *
      l.transpose();
  return out.allFinite() ? Eigen::Matrix3d(0.5 * (out + out.transpose())) : bs;
}

// The refinement of one placement (the used pairs' ICP alignments as constraints); `refined`
// false when it did not apply (the poses and covariances are then those given).
struct Refined {
  bool refined = false;
  std::string rejected;  // why a refinement that lowered its cost was not kept ("" otherwise)
  std::vector<std::string> kept_pairs;    // weak leaves that kept the pairs' placement (why)
  std::vector<std::size_t> kept_sensors;  // those leaves (full indices)
  JointRefineResult joint;
  std::vector<Pose2> poses;
  std::vector<Eigen::Matrix3d> covariance;
};

Refined Refine(const AlignedTracks& tracks, std::size_t reference,
               const std::vector<RelativeMeasurement>& measurements, const std::vector<bool>& used,
               const std::vector<const PairEstimate*>& pair_of, const std::vector<Pose2>& poses,
               const std::vector<Eigen::Matrix3d>& covariance, const std::vector<bool>& placed,
               const JointRefineOptions& options, double max_disagreement_sigma,
               double max_wall_residual_sigma, bool keep_pairs_uncertainty,
               const std::vector<WeakLeaf>& leaves, double weak_min_move_sigma,
               const std::vector<std::string>& id) {
  // Pairs aligned on their backgrounds are constraints: without them the tracks' systematic
  // errors would pull wall-accurate poses apart.
  std::vector<RelativePoseConstraint> constraints;
  for (std::size_t e = 0; e < measurements.size(); ++e) {
    if (!used[e] || pair_of[e] == nullptr || !pair_of[e]->icp_applied) continue;
    constraints.push_back({measurements[e].r, measurements[e].s, pair_of[e]->icp_s_from_r,
                           pair_of[e]->icp_covariance});
  }
  Refined out;
  out.poses = poses;
  out.covariance = covariance;
  out.joint = RefineJointly(tracks, poses, placed, reference, options, constraints);
  if (!out.joint.ok || !(out.joint.cost_after < out.joint.cost_before)) return out;
  // A sensor whose pairs' least squares rests on walls (a used pair aligned on the backgrounds)
  // and that the refinement, from the tracks, moves farther than the two covariances allow: the
  // refinement's model of the tracks is wrong, the walls are not (pipeline.h). Elsewhere the
  // refinement uses the pairs' tracks better (all sensors at once) and may correct a pair.
  std::vector<bool> on_walls(poses.size(), false);
  for (const RelativePoseConstraint& c : constraints) on_walls[c.r] = on_walls[c.s] = true;
  double worst_sigma = 0.0;
  std::size_t worst = reference;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    if (i == reference || !placed[i] || !out.joint.refined[i] || !on_walls[i]) continue;
    const Pose2& a = poses[i];
    const Pose2& b = out.joint.world_from_sensor[i];
    const Eigen::Vector3d delta(b.x_m - a.x_m, b.y_m - a.y_m,
                                common::AngleDiff(b.yaw_rad, a.yaw_rad));
    const Eigen::Matrix3d sum = covariance[i] + out.joint.covariance[i];
    const Eigen::LLT<Eigen::Matrix3d> llt(0.5 * (sum + sum.transpose()));
    if (llt.info() != Eigen::Success) continue;
    const double d = std::sqrt(std::max(0.0, delta.dot(llt.solve(delta))));
    if (d > worst_sigma) {
      worst_sigma = d;
      worst = i;
    }
  }
  if (worst_sigma > max_disagreement_sigma) {
    out.rejected = fmt::format(
        "joint refinement moved {} {:.1f} sigma away from the pairs' least squares (at most "
        "{:.1f}); not applied",
        tracks.sensors[worst].id, worst_sigma, max_disagreement_sigma);
    return out;
  }
  // The same for each wall constraint itself, against the background alignment's own
  // covariance: the refinement's covariance widens the test above exactly where its robust loss
  // gave a constraint up (biased tracks of two sensors moving both of them and their walls'
  // relative pose, each within the sum of the covariances).
  double worst_wall_sigma = 0.0;
  const RelativePoseConstraint* worst_wall = nullptr;
  for (const RelativePoseConstraint& c : constraints) {
    if (!placed[c.r] || !placed[c.s]) continue;
    const Pose2 after =
        out.joint.world_from_sensor[c.s].inverse() * out.joint.world_from_sensor[c.r];
    const Eigen::Vector3d delta(after.x_m - c.s_from_r.x_m, after.y_m - c.s_from_r.y_m,
                                common::AngleDiff(after.yaw_rad, c.s_from_r.yaw_rad));
    const Eigen::LLT<Eigen::Matrix3d> llt(0.5 * (c.covariance + c.covariance.transpose()));
    if (llt.info() != Eigen::Success) continue;
    const double d = std::sqrt(std::max(0.0, delta.dot(llt.solve(delta))));
    if (d > worst_wall_sigma) {
      worst_wall_sigma = d;
      worst_wall = &c;
    }
  }
  if (worst_wall != nullptr && worst_wall_sigma > max_wall_residual_sigma) {
    out.rejected = fmt::format(
        "joint refinement moved the pair {}-{} {:.1f} sigma off its background alignment (at "
        "most {:.1f}); not applied",
        tracks.sensors[worst_wall->r].id, tracks.sensors[worst_wall->s].id, worst_wall_sigma,
        max_wall_residual_sigma);
    return out;
  }
  out.refined = true;
  out.poses = out.joint.world_from_sensor;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    if (out.joint.refined[i] && i != reference) {
      out.covariance[i] = keep_pairs_uncertainty ? AtLeast(out.joint.covariance[i], covariance[i])
                                                 : out.joint.covariance[i];
    }
  }
  // A sensor hanging on one weak pair: the refinement's pose for it rests on the few observations
  // the pair had plus associations with sensors whose pairs were rejected, which nothing has
  // verified (far-range views, whose systematic errors the model does not carry, pull it while
  // the refinement's covariance claims a precision it does not have). It keeps the pairs'
  // placement, carried along with the sensor it hangs on, unless the refinement moves it relative
  // to that sensor farther than the weak pair's own covariance allows (pipeline.h). In placement
  // order, so that a leaf hanging on a leaf follows its anchor's decision.
  if (weak_min_move_sigma > 0.0) {
    std::vector<std::size_t> used_pairs(poses.size(), 0);
    for (std::size_t e = 0; e < measurements.size(); ++e) {
      if (!used[e]) continue;
      ++used_pairs[measurements[e].r];
      ++used_pairs[measurements[e].s];
    }
    for (const WeakLeaf& leaf : leaves) {
      const std::size_t i = leaf.sensor, a = leaf.anchor;
      // Only where the weak pair is the sensor's one used pair: other pairs that confirmed it
      // put it in a cycle the refinement may resolve.
      if (i == reference || !out.joint.refined[i] || leaf.edge >= measurements.size() ||
          !used[leaf.edge] || used_pairs[i] != 1) {
        continue;
      }
      const RelativeMeasurement& m = measurements[leaf.edge];
      // s_from_r of the weak pair, from the pairs' placement and from the refined one.
      const Pose2 before = poses[m.s].inverse() * poses[m.r];
      const Pose2 after =
          out.joint.world_from_sensor[m.s].inverse() * out.joint.world_from_sensor[m.r];
      const Eigen::Vector3d delta(after.x_m - before.x_m, after.y_m - before.y_m,
                                  common::AngleDiff(after.yaw_rad, before.yaw_rad));
      const Eigen::LLT<Eigen::Matrix3d> llt(0.5 * (m.covariance + m.covariance.transpose()));
      if (llt.info() != Eigen::Success) continue;
      const double d = std::sqrt(std::max(0.0, delta.dot(llt.solve(delta))));
      if (d > weak_min_move_sigma) continue;
      out.poses[i] = out.poses[a] * (poses[a].inverse() * poses[i]);
      out.covariance[i] = AtLeast(covariance[i], out.joint.covariance[a]);
      out.kept_sensors.push_back(i);
      out.kept_pairs.push_back(fmt::format(
          "joint refinement would move {} {:.1f} sigma of its weak pair {}-{} ({:.2f} m, {:.2f} "
          "deg; at least {:.1f} needed): kept the pairs' placement",
          id[i], d, id[m.r], id[m.s], delta.head<2>().norm(), common::RadToDeg(std::abs(delta(2))),
          weak_min_move_sigma));
    }
  }
  return out;
}

// A placement of the sensors from a set of used pairs.
struct Placement {
  bool ok = false;
  std::string description;
  std::vector<bool> used;
  std::vector<Pose2> poses;
  std::vector<Eigen::Matrix3d> covariance;
  std::vector<double> residual_sigma;
  std::vector<double> residual_chi2;
  Refined refined;
  double cost = 0.0;
};

// Joint least squares over the used pairs from `initial` (placed sensors only).
Placement SolvePlacement(std::size_t n, std::size_t reference,
                         const std::vector<RelativeMeasurement>& measurements,
                         const std::vector<bool>& used, const std::vector<bool>& placed,
                         const std::vector<Pose2>& initial) {
  Placement out;
  out.used = used;
  out.residual_chi2.assign(measurements.size(), 0.0);
  // Nodes: the placed sensors.
  std::vector<std::size_t> to_sub(n, kNoIndex), to_full;
  for (std::size_t i = 0; i < n; ++i) {
    if (placed[i]) {
      to_sub[i] = to_full.size();
      to_full.push_back(i);
    }
  }
  std::vector<RelativeMeasurement> sub;
  std::vector<bool> sub_use;
  std::vector<std::size_t> sub_of;
  for (std::size_t e = 0; e < measurements.size(); ++e) {
    if (to_sub[measurements[e].r] == kNoIndex || to_sub[measurements[e].s] == kNoIndex) continue;
    RelativeMeasurement m = measurements[e];
    m.r = to_sub[m.r];
    m.s = to_sub[m.s];
    sub.push_back(m);
    sub_use.push_back(used[e]);
    sub_of.push_back(e);
  }
  std::vector<Pose2> start;
  for (std::size_t i : to_full) start.push_back(initial[i]);
  const PoseGraphResult ls = SolvePoseGraph(to_full.size(), to_sub[reference], sub, sub_use, start);
  if (!ls.ok) {
    out.description = ls.error;
    return out;
  }
  out.ok = true;
  out.poses.assign(n, Pose2::Identity());
  out.covariance.assign(n, Eigen::Matrix3d::Zero());
  out.residual_sigma.assign(measurements.size(), 0.0);
  for (std::size_t i = 0; i < to_full.size(); ++i) {
    out.poses[to_full[i]] = ls.world_from_node[i];
    out.covariance[to_full[i]] = ls.covariance[i];
  }
  for (std::size_t k = 0; k < sub.size(); ++k) {
    out.residual_sigma[sub_of[k]] = ls.residual_sigma[k];
    out.residual_chi2[sub_of[k]] = ls.residual_chi2[k];
  }
  return out;
}

// The statement of CalibrationResult::scale_note from a joint refinement ("" when the scale is
// observable).
std::string ScaleNote(const JointRefineResult& joint, const JointRefineOptions& options,
                      const std::vector<std::string>& id, const std::vector<bool>& placed,
                      const std::vector<Eigen::Matrix3d>& covariance) {
  double correlation = 0.0;
  for (std::size_t k = 0; k < 2; ++k) {
    if (!joint.size_correction_estimated[k] &&
        joint.size_scale_correlation[k] > options.max_size_scale_correlation) {
      correlation = std::max(correlation, joint.size_scale_correlation[k]);
    }
  }
  if (correlation <= 0.0) return "";
  double worst_m = 0.0;
  std::size_t worst = 0;
  for (std::size_t i = 0; i < placed.size() && i < covariance.size(); ++i) {
    const double sigma_m =
        placed[i] ? std::sqrt(std::max(0.0, covariance[i].topLeftCorner<2, 2>().trace())) : 0.0;
    if (sigma_m > worst_m) {
      worst_m = sigma_m;
      worst = i;
    }
  }
  return fmt::format(
      "scale not observable: the people's size and the layout's scale explain the data alike "
      "(correlation {:.2f}), so the distances between the sensors are known only as well as the "
      "size prior; positions uncertain by up to {:.2f} m (1 sigma, {}), in the covariances. Walls "
      "that two sensors both see, or people walking across the line between two sensors, would "
      "fix it",
      correlation, worst_m, placed.empty() ? "" : id[worst]);
}

// Whether two placements put some sensor materially apart: farther than three of its standard
// deviations in `a` and than kMaterial*.
constexpr double kMaterialM = 0.05;
constexpr double kMaterialRad = 0.005;  // 0.29 deg
std::vector<std::size_t> SensorsApart(const Placement& a, const Placement& b,
                                      const std::vector<bool>& placed) {
  std::vector<std::size_t> out;
  for (std::size_t i = 0; i < placed.size(); ++i) {
    if (!placed[i]) continue;
    const double dt = common::TranslationDistanceM(a.poses[i], b.poses[i]);
    const double dyaw = common::RotationDistanceRad(a.poses[i], b.poses[i]);
    const double st = std::sqrt(std::max(0.0, a.covariance[i].topLeftCorner<2, 2>().trace()));
    const double syaw = std::sqrt(std::max(0.0, a.covariance[i](2, 2)));
    if ((dt > kMaterialM && dt > 3.0 * st) || (dyaw > kMaterialRad && dyaw > 3.0 * syaw)) {
      out.push_back(i);
    }
  }
  return out;
}

// The quenzel method's global step with its hypotheses and the joint refinement (pipeline.h).
GlobalSolution SolveRobust(const AlignedTracks& tracks, std::size_t reference,
                           const std::vector<RelativeMeasurement>& measurements,
                           const std::vector<bool>& weak,
                           const std::vector<const PairEstimate*>& pair_of,
                           const CalibrationOptions& options, StageTimer* timer,
                           CalibrationResult* result) {
  const std::size_t n = tracks.sensors.size();
  std::vector<std::string> id(n);
  for (std::size_t i = 0; i < n; ++i) id[i] = tracks.sensors[i].id;
  GlobalSolution out;
  out.world_from_sensor.assign(n, Pose2::Identity());
  out.calibrated.assign(n, false);
  out.covariance.assign(n, Eigen::Matrix3d::Zero());
  out.flag.assign(n, "");
  out.calibrated[reference] = true;

  std::vector<bool> strong(measurements.size());
  for (std::size_t e = 0; e < measurements.size(); ++e) strong[e] = !weak[e];
  CoreSolution core = SolveCore(n, reference, measurements, strong, options);
  for (std::string& w : core.warnings) out.warnings.push_back(std::move(w));
  std::vector<WeakLeaf> leaves;
  Extend(measurements, weak, id, &core, &out.flag, &leaves);
  out.edge_status = core.status;

  Placement best = SolvePlacement(n, reference, measurements, core.used, core.placed, core.poses);
  best.description = "all pairs";
  timer->Mark("rotation averaging + translations");
  if (!best.ok) {
    out.warnings.push_back("weighted least squares failed: " + best.description);
    best.ok = true;
    best.poses = core.poses;
    best.covariance = core.covariance;
    best.residual_sigma.assign(measurements.size(), 0.0);
    best.residual_chi2.assign(measurements.size(), 0.0);
  }

  // Hypotheses where the cycles cannot decide: a pair dropped as an outlier, or left inconsistent
  // with the solution, that lies in fewer than two independent cycles of the graph.
  std::vector<bool> considered(measurements.size());
  for (std::size_t e = 0; e < measurements.size(); ++e) {
    considered[e] = core.used[e] || (core.outlier[e] && core.placed[measurements[e].r] &&
                                     core.placed[measurements[e].s]);
  }
  const std::vector<int> support = CycleSupport(n, measurements, considered);
  // The weakly cycled pairs (in exactly one independent cycle): suspect when one was dropped as
  // an outlier, or when together they do not close (their chi-square against the least squares
  // beyond its 99.9 % level for 3 dof per independent cycle among them).
  std::vector<std::size_t> suspects;
  {
    double chi2 = 0.0;
    std::size_t edges = 0;
    DisjointSets parts(n);
    std::size_t merges = 0;
    std::vector<bool> touched(n, false);
    for (std::size_t e = 0; e < measurements.size(); ++e) {
      if (!considered[e] || support[e] != 1) continue;
      if (core.outlier[e]) suspects.push_back(e);
      if (!best.used[e]) continue;
      chi2 += best.residual_chi2[e];
      ++edges;
      touched[measurements[e].r] = touched[measurements[e].s] = true;
      merges += parts.Union(measurements[e].r, measurements[e].s) ? 1 : 0;
    }
    const double cycles = static_cast<double>(edges) - static_cast<double>(merges);
    if (cycles >= 1.0 && chi2 > 3.0 * cycles + 5.0 * std::sqrt(6.0 * cycles) + 3.0) {
      for (std::size_t e = 0; e < measurements.size(); ++e) {
        if (considered[e] && support[e] == 1 && best.used[e]) suspects.push_back(e);
      }
    }
  }
  std::vector<Placement> tried;
  if (!suspects.empty()) {
    // The pairs that share the suspects' cycles: the 2-edge-connected part around them (without
    // the bridges), restricted to pairs in exactly one independent cycle.
    DisjointSets blocks(n);
    for (std::size_t e = 0; e < measurements.size(); ++e) {
      if (considered[e] && support[e] >= 1) blocks.Union(measurements[e].r, measurements[e].s);
    }
    std::vector<std::size_t> candidates;
    for (std::size_t e = 0; e < measurements.size(); ++e) {
      if (!considered[e] || support[e] != 1) continue;
      for (std::size_t k : suspects) {
        if (blocks.Find(measurements[e].r) == blocks.Find(measurements[k].r)) {
          candidates.push_back(e);
          break;
        }
      }
    }
    if (candidates.size() > kMaxHypotheses) {
      out.warnings.push_back(fmt::format(
          "{} pairs in weakly connected cycles disagree; too many to test one by one ({} max): "
          "the robust averaging decided",
          candidates.size(), kMaxHypotheses));
    } else {
      PlacementOptions placement_options;
      placement_options.icp = options.icp;
      placement_options.model_sigma_m = options.pairwise.model_sigma_m;
      JointRefineOptions quick = options.joint;
      quick.association_rounds = std::min(quick.association_rounds, 3);
      const auto evaluate = [&](Placement& h) {
        if (options.refine) {
          h.refined = Refine(
              tracks, reference, measurements, h.used, pair_of, h.poses, h.covariance, core.placed,
              quick, options.refine_max_disagreement_sigma, options.refine_max_wall_residual_sigma,
              options.conflicts_widen_covariance, leaves, options.weak_refine_min_move_sigma, id);
        } else {
          h.refined.poses = h.poses;
          h.refined.covariance = h.covariance;
        }
        h.cost = EvaluatePlacement(tracks, h.refined.poses, core.placed, placement_options).total;
      };
      // "All pairs": what the robust averaging chose (its outliers left out).
      evaluate(best);
      tried.push_back(best);
      for (std::size_t e : candidates) {
        std::vector<bool> use(measurements.size(), false);
        for (std::size_t k = 0; k < measurements.size(); ++k) use[k] = considered[k] && k != e;
        if (!UnconnectedNodes(n, reference,
                              [&] {
                                std::vector<RelativeMeasurement> kept;
                                for (std::size_t k = 0; k < measurements.size(); ++k) {
                                  if (use[k]) kept.push_back(measurements[k]);
                                }
                                return kept;
                              }())
                 .empty()) {
          continue;
        }
        // Start from the poses composed along the pairs kept, so that no hypothesis inherits
        // another's placement.
        std::vector<Pose2> start = core.poses;
        {
          std::vector<RelativeMeasurement> kept;
          for (std::size_t k = 0; k < measurements.size(); ++k) {
            if (use[k]) kept.push_back(measurements[k]);
          }
          std::vector<bool> done(n, false);
          done[reference] = true;
          start[reference] = Pose2::Identity();
          for (bool changed = true; changed;) {
            changed = false;
            for (const RelativeMeasurement& m : kept) {
              if (done[m.s] && !done[m.r]) {
                start[m.r] = start[m.s] * m.s_from_r;
                done[m.r] = changed = true;
              } else if (done[m.r] && !done[m.s]) {
                start[m.s] = start[m.r] * m.s_from_r.inverse();
                done[m.s] = changed = true;
              }
            }
          }
        }
        Placement h = SolvePlacement(n, reference, measurements, use, core.placed, start);
        if (!h.ok) continue;
        h.description = "without " + id[measurements[e].r] + "-" + id[measurements[e].s];
        evaluate(h);
        tried.push_back(std::move(h));
      }
      timer->Mark("hypotheses");
      std::size_t best_index = 0;
      for (std::size_t k = 1; k < tried.size(); ++k) {
        if (tried[k].cost < tried[best_index].cost) best_index = k;
      }
      // The runner-up that places some sensor elsewhere.
      std::optional<std::size_t> rival;
      std::vector<std::size_t> apart;
      for (std::size_t k = 0; k < tried.size(); ++k) {
        if (k == best_index) continue;
        const std::vector<std::size_t> d = SensorsApart(tried[best_index], tried[k], core.placed);
        if (d.empty()) continue;
        if (!rival || tried[k].cost < tried[*rival].cost) {
          rival = k;
          apart = d;
        }
      }
      for (std::size_t k = 0; k < tried.size(); ++k) {
        result->hypotheses.push_back({tried[k].description, tried[k].cost, k == best_index});
      }
      best = tried[best_index];
      if (rival && tried[*rival].cost - best.cost < kSeparation) {
        // Not separated: refuse the sensors the two placements disagree on, and say which walks
        // would decide (people seen by both sensors of the pairs under suspicion, on paths that
        // turn within the overlap).
        std::string names, walks;
        for (std::size_t i : apart) names += (names.empty() ? "" : ", ") + id[i];
        for (std::size_t e : candidates) {
          walks +=
              (walks.empty() ? "" : ", ") + id[measurements[e].r] + " and " + id[measurements[e].s];
        }
        const Placement& other = tried[*rival];
        double dt = 0.0, dyaw = 0.0;
        for (std::size_t i : apart) {
          dt = std::max(dt, common::TranslationDistanceM(best.poses[i], other.poses[i]));
          dyaw = std::max(dyaw, common::RotationDistanceRad(best.poses[i], other.poses[i]));
        }
        result->ambiguity = fmt::format(
            "{}: two placements ({}; {}) explain the data equally (robust costs {:.1f} and {:.1f}; "
            "up to {:.2f} m / {:.2f} deg apart); let people walk where {} both see them, along "
            "paths that turn inside the overlap",
            names, best.description, other.description, best.cost, other.cost, dt,
            common::RadToDeg(dyaw), walks);
        for (std::size_t i : apart) {
          out.flag[i] = "ambiguous: two placements explain the data equally";
        }
      }
    }
  }

  // The final placement: its least squares, refined.
  if (tried.empty() && options.refine) {
    best.refined =
        Refine(tracks, reference, measurements, best.used, pair_of, best.poses, best.covariance,
               core.placed, options.joint, options.refine_max_disagreement_sigma,
               options.refine_max_wall_residual_sigma, options.conflicts_widen_covariance, leaves,
               options.weak_refine_min_move_sigma, id);
  } else if (!options.refine) {
    best.refined.poses = best.poses;
    best.refined.covariance = best.covariance;
  }
  if (options.refine) {
    timer->Mark("joint refinement");
    const JointRefineResult& joint = best.refined.joint;
    result->refine_cost_before = joint.cost_before;
    result->refine_cost_after = joint.cost_after;
    result->refine_observations = joint.observations;
    result->size_correction_m = joint.size_correction_m;
    result->size_estimated = joint.size_correction_estimated;
    result->size_scale_correlation = joint.size_scale_correlation;
    result->size_data_sigma_m = joint.size_data_sigma_m;
    if (joint.ok) {
      result->scale_note =
          ScaleNote(joint, options.joint, id, core.placed, best.refined.covariance);
    }
    if (!joint.ok) {
      out.warnings.push_back("joint refinement not applied: " + joint.message);
    } else if (!best.refined.rejected.empty()) {
      out.warnings.push_back(best.refined.rejected);
    } else if (!best.refined.refined) {
      out.warnings.push_back("joint refinement did not lower the cost; not applied");
    } else {
      result->refined = true;
      for (const std::string& note : best.refined.kept_pairs) out.warnings.push_back(note);
      // Each sensor the refinement placed (a weak leaf that kept the pairs' placement has the
      // bias at its prior in its pairs' covariance).
      out.radial_bias.assign(n, std::nullopt);
      const auto& kept = best.refined.kept_sensors;
      for (std::size_t i = 0; i < n; ++i) {
        if (std::find(kept.begin(), kept.end(), i) != kept.end()) continue;
        if (i < joint.refined.size() && joint.refined[i] && i < joint.sensor_bias_m.size() &&
            i < joint.sensor_bias_sigma_m.size() && i < joint.sensor_bias_estimated.size() &&
            joint.sensor_bias_sigma_m[i] > 0.0) {
          out.radial_bias[i] = RadialBiasEstimate{
              joint.sensor_bias_m[i], joint.sensor_bias_sigma_m[i], joint.sensor_bias_estimated[i]};
        }
      }
    }
  }
  for (std::size_t e = 0; e < measurements.size(); ++e) {
    if (considered[e] && !best.used[e] && core.used[e]) {
      out.edge_status[e] = "not used: the hypothesis test (" + best.description + ") left it out";
    } else if (considered[e] && best.used[e] && core.outlier[e]) {
      out.edge_status[e] = "used: the hypothesis test kept it";
    }
  }
  out.edge_used.assign(measurements.size(), false);
  for (std::size_t e = 0; e < measurements.size(); ++e) {
    out.edge_used[e] = best.used[e];
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (!core.placed[i]) continue;
    out.calibrated[i] = out.flag[i].rfind("ambiguous", 0) != 0;
    out.world_from_sensor[i] = best.refined.poses[i];
    out.covariance[i] = best.refined.covariance[i];
  }
  out.world_from_sensor[reference] = Pose2::Identity();
  out.covariance[reference].setZero();
  return out;
}

}  // namespace

const char* ToString(Method method) {
  switch (method) {
    case Method::kQuenzel:
      return "quenzel";
    case Method::kSpectral:
      return "spectral";
    case Method::kSchenk:
      return "schenk";
  }
  return "?";
}

std::optional<Method> ParseMethod(const std::string& name) {
  for (Method m : {Method::kQuenzel, Method::kSpectral, Method::kSchenk}) {
    if (name == ToString(m)) return m;
  }
  return std::nullopt;
}

std::optional<std::string> Validate(const CalibrationOptions& options) {
  if (!(options.icp_max_disagreement_sigma > 0.0) ||
      !std::isfinite(options.icp_max_disagreement_sigma)) {
    return "icp_max_disagreement_sigma must be a finite value > 0";
  }
  if (!(options.icp_track_bias_sigma_m >= 0.0) || !std::isfinite(options.icp_track_bias_sigma_m)) {
    return "icp_track_bias_sigma_m must be a finite value >= 0";
  }
  if (!(options.refine_max_disagreement_sigma > 0.0)) {
    return "refine_max_disagreement_sigma must be > 0";
  }
  if (!(options.refine_max_wall_residual_sigma > 0.0)) {
    return "refine_max_wall_residual_sigma must be > 0";
  }
  if (!(options.weak_refine_min_move_sigma >= 0.0) ||
      !std::isfinite(options.weak_refine_min_move_sigma)) {
    return "weak_refine_min_move_sigma must be a finite value >= 0";
  }
  if (!(options.mount_mismatch_bias_sigma_m >= 0.0) ||
      !std::isfinite(options.mount_mismatch_bias_sigma_m)) {
    return "mount_mismatch_bias_sigma_m must be a finite value >= 0";
  }
  if (auto e = common::Validate(options.mount_check)) return "mount_check: " + *e;
  if (!(options.max_translation_residual_m > 0.0) ||
      !std::isfinite(options.max_translation_residual_m)) {
    return "max_translation_residual_m must be a finite value > 0";
  }
  if (!(options.min_pair_overlap_s >= 0.0) || !std::isfinite(options.min_pair_overlap_s)) {
    return "min_pair_overlap_s must be a finite value >= 0";
  }
  if (auto e = Validate(options.align)) return "align: " + *e;
  if (auto e = Validate(options.intervals)) return "intervals: " + *e;
  if (auto e = Validate(options.pairwise)) return "pairwise: " + *e;
  if (auto e = Validate(options.icp)) return "icp: " + *e;
  if (auto e = Validate(options.rotation)) return "rotation: " + *e;
  if (auto e = Validate(options.joint)) return "joint: " + *e;
  if (auto e = Validate(options.schenk)) return "schenk: " + *e;
  return std::nullopt;
}

DataAssessment Assess(const AlignedTracks& tracks, double min_pair_overlap_s) {
  DataAssessment out;
  const std::size_t n = tracks.sensors.size();
  std::vector<std::vector<bool>> seen(n, std::vector<bool>(tracks.steps, false));
  for (std::size_t i = 0; i < n; ++i) {
    const SensorTracks& sensor = tracks.sensors[i];
    SensorData d;
    d.id = sensor.id;
    d.tracks = sensor.tracks.size();
    d.has_background = sensor.background.has_value();
    d.has_description = sensor.description.has_value();
    d.clock_suspect = sensor.clock_suspect;
    for (const GridTrack& t : sensor.tracks) {
      for (std::size_t k = t.first_step; k < std::min(t.end_step(), tracks.steps); ++k) {
        seen[i][k] = true;
      }
    }
    d.tracked_s =
        static_cast<double>(std::count(seen[i].begin(), seen[i].end(), true)) * tracks.step_s;
    out.sensors.push_back(std::move(d));
  }
  // Union-find over the pairs with enough simultaneous tracks.
  DisjointSets sets(n);
  auto find = [&sets](std::size_t i) { return sets.Find(i); };
  for (std::size_t r = 0; r < n; ++r) {
    for (std::size_t s = r + 1; s < n; ++s) {
      std::size_t both = 0;
      for (std::size_t k = 0; k < tracks.steps; ++k) both += (seen[r][k] && seen[s][k]) ? 1 : 0;
      if (both == 0) continue;
      const double overlap_s = static_cast<double>(both) * tracks.step_s;
      out.pairs.push_back({r, s, overlap_s});
      if (overlap_s >= min_pair_overlap_s) sets.Union(r, s);
    }
  }
  // The component of the sensor with the most tracked time is "the network".
  std::size_t main = 0;
  for (std::size_t i = 1; i < n; ++i) {
    if (out.sensors[i].tracked_s > out.sensors[main].tracked_s) main = i;
  }
  std::vector<std::string> no_tracks;
  for (std::size_t i = 0; i < n; ++i) {
    if (out.sensors[i].tracks == 0) no_tracks.push_back(out.sensors[i].id);
    if (find(i) != find(main)) out.unlinked.push_back(out.sensors[i].id);
  }
  if (n == 0) {
    out.missing = "no sensors in the input";
  } else if (n == 1) {
    out.missing = "only one sensor (" + out.sensors[0].id + "): calibration needs at least two";
  } else if (out.sensors[main].tracks == 0) {
    out.missing =
        "no sensor has any track: nobody walked through the scene (or every track was "
        "shorter than align.min_track_duration_s)";
  } else if (!out.unlinked.empty()) {
    std::string text;
    if (!no_tracks.empty()) {
      text = "no tracks from ";
      for (std::size_t k = 0; k < no_tracks.size(); ++k) text += (k ? ", " : "") + no_tracks[k];
      text += "; ";
    }
    std::string linked;
    for (std::size_t k = 0; k < out.unlinked.size(); ++k)
      linked += (k ? ", " : "") + out.unlinked[k];
    // The best link of each unlinked sensor tells the user how far it is from enough.
    double best_s = 0.0;
    for (const PairData& p : out.pairs) {
      if ((find(p.r) == find(main)) != (find(p.s) == find(main)))
        best_s = std::max(best_s, p.overlap_s);
    }
    char buffer[160];
    std::snprintf(buffer, sizeof buffer,
                  " share too few simultaneous tracks with the others (best link %.1f s, need "
                  "%.1f s): let people walk where their fields of view overlap",
                  best_s, min_pair_overlap_s);
    out.missing = text + linked + buffer;
  }
  out.sufficient = out.missing.empty();
  return out;
}

namespace {

// Steps 7-8 of the quenzel and spectral methods from out->pairs (pipeline.h), then the result.
void SolveFromPairs(const CalibrationOptions& options, StageTimer* timer, CalibrationOutcome* out);

// The result's sensors, edges and the outcome's error from a global solution.
void Finish(const GlobalSolution& global_in, std::size_t reference,
            const std::vector<std::size_t>& measurement_of_pair, StageTimer* timer,
            CalibrationOutcome* out) {
  GlobalSolution global = global_in;
  CalibrationResult& result = out->result;
  const AlignedTracks& tracks = out->tracks;
  const std::size_t n = tracks.sensors.size();
  for (std::string& w : global.warnings) result.warnings.push_back(std::move(w));
  result.reference = tracks.sensors[reference].id;
  for (std::size_t i = 0; i < n; ++i) {
    result.sensors[i].calibrated = global.calibrated[i];
    result.sensors[i].world_from_sensor =
        global.calibrated[i] ? global.world_from_sensor[i] : Pose2::Identity();
    result.sensors[i].covariance =
        global.calibrated[i] ? global.covariance[i] : Eigen::Matrix3d::Zero();
    if (i < global.flag.size()) result.sensors[i].flag = global.flag[i];
    result.sensors[i].radial_bias.reset();
    if (global.calibrated[i] && i < global.radial_bias.size()) {
      result.sensors[i].radial_bias = global.radial_bias[i];
    }
  }
  // What data would place a sensor hanging on weak pairs: its pairs that saw people together but
  // were rejected, or more of the walks its weak pair rests on.
  for (std::size_t i = 0; i < n; ++i) {
    std::string& flag = result.sensors[i].flag;
    if (!global.calibrated[i] || flag.rfind("placed through the weak pair", 0) != 0) continue;
    const std::string others = RejectedPartners(tracks, out->pairs, i);
    flag +=
        others.empty()
            ? "; more people walking where the two sensors of its weak pairs both see them would "
              "place it"
            : fmt::format(
                  "; people walking, and turning, where {} and {} both see them would place it, or "
                  "more walks where the two sensors of its weak pairs both see them",
                  tracks.sensors[i].id, others);
  }
  FillEdges(tracks, out->pairs, measurement_of_pair, global.edge_status, &result);
  timer->Total();

  std::vector<std::size_t> unconnected;
  for (std::size_t i = 0; i < n; ++i) {
    if (!global.calibrated[i] && result.sensors[i].flag.empty()) unconnected.push_back(i);
  }
  if (!result.ambiguity.empty()) {
    out->error = "cannot place " + result.ambiguity;
    if (!unconnected.empty()) {
      out->error += "; not connected to the reference " + result.reference + ": " +
                    JoinIds(tracks, unconnected);
    }
    return;
  }
  if (!unconnected.empty()) {
    std::string detail;
    for (const PairEstimate& p : out->pairs) {
      const bool involves =
          std::find(unconnected.begin(), unconnected.end(), p.r) != unconnected.end() ||
          std::find(unconnected.begin(), unconnected.end(), p.s) != unconnected.end();
      if (involves && !p.accepted && detail.size() < 400) {
        detail += "; " + tracks.sensors[p.r].id + "-" + tracks.sensors[p.s].id + ": " + p.reason;
      }
    }
    out->error = "sensors not connected to the reference " + result.reference + ": " +
                 JoinIds(tracks, unconnected) + " (no accepted pairwise estimate links them" +
                 detail + ")";
    // What data would place each of them (as for a sensor hanging on weak pairs).
    for (std::size_t i : unconnected) {
      const std::string others = RejectedPartners(tracks, out->pairs, i);
      std::string& flag = result.sensors[i].flag;
      flag = others.empty()
                 ? fmt::format(
                       "not placed: people walking where {} and another sensor both see "
                       "them would place it",
                       tracks.sensors[i].id)
                 : fmt::format(
                       "not placed: people walking, and turning, where {} and {} both see "
                       "them would place it",
                       tracks.sensors[i].id, others);
      out->error += "; " + tracks.sensors[i].id + " " + flag;
    }
    return;
  }
  out->ok = true;
}

void SolveFromPairs(const CalibrationOptions& options, StageTimer* timer, CalibrationOutcome* out) {
  const AlignedTracks& tracks = out->tracks;
  const std::size_t n = tracks.sensors.size();
  std::size_t reference = BestConnected(out->pairs, n);
  if (!options.reference.empty()) reference = *IndexOf(tracks, options.reference);
  std::vector<RelativeMeasurement> measurements;
  std::vector<std::size_t> measurement_of_pair(out->pairs.size(), 0);
  for (std::size_t k = 0; k < out->pairs.size(); ++k) {
    const PairEstimate& p = out->pairs[k];
    if (!p.accepted || p.r >= n || p.s >= n || p.r == p.s) continue;
    RelativeMeasurement m;
    m.r = p.r;
    m.s = p.s;
    m.s_from_r = p.s_from_r;
    m.weight = WeightOf(p);
    m.covariance = p.covariance;
    measurement_of_pair[k] = measurements.size();
    measurements.push_back(m);
  }
  GlobalSolution global;
  if (options.method == Method::kSpectral) {
    global = SolveSpectral(n, reference, measurements, options);
    timer->Mark("rotation averaging + translations");
  } else {
    std::vector<bool> weak(measurements.size(), false);
    std::vector<const PairEstimate*> pair_of(measurements.size(), nullptr);
    for (std::size_t k = 0; k < out->pairs.size(); ++k) {
      const PairEstimate& p = out->pairs[k];
      if (!p.accepted || p.r >= n || p.s >= n || p.r == p.s) continue;
      weak[measurement_of_pair[k]] = p.weak;
      pair_of[measurement_of_pair[k]] = &p;
    }
    global =
        SolveRobust(tracks, reference, measurements, weak, pair_of, options, timer, &out->result);
  }
  Finish(global, reference, measurement_of_pair, timer, out);
}

// The result's sensor list and the clock warnings of aligned tracks.
void StartResult(const AlignedTracks& tracks, CalibrationResult* result) {
  for (const SensorTracks& s : tracks.sensors) {
    SensorPose pose;
    pose.id = s.id;
    result->sensors.push_back(pose);
    if (s.clock_suspect) {
      result->warnings.push_back("sensor " + s.id + " reports an unsynchronised clock");
    }
  }
}

// The mount check of every sensor configured for upper-body height; a sensor whose tracks look
// like legs gets the shared radial bias of mount_mismatch_bias_sigma_m on its samples: a
// sensitivity to the size correction (types.h TrackSample), whose prior sigma is
// size_prior_sigma_m, of mount_mismatch_bias_sigma_m / size_prior_sigma_m on top of its own.
std::vector<common::MountCheck> CheckMounts(const CalibrationInput& input,
                                            const CalibrationOptions& options,
                                            AlignedTracks* tracks) {
  std::vector<common::MountCheck> out(input.sensors.size());
  if (!options.check_mount) return out;
  const double prior = tracks->size_prior_sigma_m;
  for (std::size_t i = 0; i < input.sensors.size() && i < tracks->sensors.size(); ++i) {
    out[i] = CheckMount(input.sensors[i], options.mount_check);
    if (!out[i].looks_like_legs || !(prior > 0.0) || !std::isfinite(prior)) continue;
    const auto per_minor = static_cast<float>(options.mount_mismatch_bias_sigma_m / prior);
    for (GridTrack& t : tracks->sensors[i].tracks) {
      for (TrackSample& x : t.samples) x.bias_per_minor += per_minor;
    }
  }
  return out;
}

// Every sensor the mount check found mis-mounted: flagged (after any other flag), a warning, and
// named in a refusal.
void AddMountFlags(CalibrationOutcome* out) {
  for (std::size_t i = 0; i < out->mount_checks.size() && i < out->result.sensors.size(); ++i) {
    SensorPose& sensor = out->result.sensors[i];
    const std::string flag = MountFlag(sensor.id, out->mount_checks[i]);
    if (flag.empty()) continue;
    sensor.mount_looks_like_legs = true;
    sensor.flag = sensor.flag.empty() ? flag : flag + "; " + sensor.flag;
    out->result.warnings.push_back(flag);
    if (!out->ok && !out->error.empty()) out->error += "; " + flag;
  }
}

}  // namespace

common::MountCheck CheckMount(const SensorRecording& sensor,
                              const common::MountCheckOptions& options) {
  if (sensor.description && sensor.description->mount == daemon::MountHeight::kLegs) return {};
  struct Key {
    std::uint64_t session;
    std::uint32_t track;
    bool operator<(const Key& o) const {
      return session != o.session ? session < o.session : track < o.track;
    }
  };
  std::map<Key, std::vector<double>> widths;
  for (const TrackFrameData& frame : sensor.frames) {
    for (const TrackObservation& t : frame.tracks) {
      if (t.state != daemon::TrackState::kConfirmed || t.shape == daemon::ObjectShape::kBox ||
          t.shape == daemon::ObjectShape::kLegs || !(t.size_minor_m > 0.0f) ||
          !(t.size_major_m > 0.0f)) {
        continue;
      }
      const double speed = std::hypot(static_cast<double>(t.vx_mps), static_cast<double>(t.vy_mps));
      if (!(speed > options.min_speed_mps)) continue;
      widths[{frame.session_id, t.track_id}].push_back(
          static_cast<double>(std::min(t.size_major_m, t.size_minor_m)));
    }
  }
  std::vector<double> medians;
  for (auto& [key, w] : widths) {
    if (w.size() >= options.min_states) medians.push_back(common::MedianInPlace(w));
  }
  return common::CheckUpperBodyMount(medians, options);
}

std::string MountFlag(const std::string& id, const common::MountCheck& check) {
  if (!check.looks_like_legs) return "";
  return fmt::format(
      "{}: tracks look like legs ({} of {} people tracks leg-sized, median half-width {:.2f} m) "
      "but shape.mount is torso; set shape.mount: legs on its tracker",
      id, check.leg_sized, check.tracks, check.median_half_width_m);
}

CalibrationOutcome CalibrateFromPairs(AlignedTracks tracks, std::vector<PairEstimate> pairs,
                                      const CalibrationOptions& options, const StageClock& clock) {
  CalibrationOutcome out;
  out.result.method = ToString(options.method);
  if (auto e = Validate(options)) {
    out.error = "invalid options: " + *e;
    return out;
  }
  if (options.method == Method::kSchenk) {
    out.error = "the schenk method forms its own pairs";
    return out;
  }
  out.tracks = std::move(tracks);
  out.pairs = std::move(pairs);
  if (out.tracks.sensors.empty()) {
    out.error = "no sensors in the input";
    return out;
  }
  if (!options.reference.empty() && !IndexOf(out.tracks, options.reference)) {
    out.error = "reference sensor '" + options.reference + "' is not in the input";
    return out;
  }
  StageTimer timer(clock, &out.result.timings);
  StartResult(out.tracks, &out.result);
  out.assessment = Assess(out.tracks, options.min_pair_overlap_s);
  SolveFromPairs(options, &timer, &out);
  return out;
}

CalibrationOutcome Calibrate(const CalibrationInput& input, const CalibrationOptions& options,
                             const StageClock& clock) {
  CalibrationOutcome out;
  CalibrationResult& result = out.result;
  result.method = ToString(options.method);
  if (auto e = Validate(options)) {
    out.error = "invalid options: " + *e;
    return out;
  }
  StageTimer timer(clock, &result.timings);

  AlignOptions align = options.align;
  if (options.method == Method::kSchenk) align.smooth = false;  // Schenk et al. use filtered tracks
  out.tracks = Align(input, align);
  out.mount_checks = CheckMounts(input, options, &out.tracks);
  const AlignedTracks& tracks = out.tracks;
  timer.Mark("align + smoothing");
  const std::size_t n = tracks.sensors.size();
  StartResult(tracks, &result);

  out.assessment = Assess(tracks, options.min_pair_overlap_s);
  if (!out.assessment.sufficient) {
    out.error = "too little data: " + out.assessment.missing;
    timer.Total();
    AddMountFlags(&out);
    return out;
  }
  if (!options.reference.empty() && !IndexOf(tracks, options.reference)) {
    out.error = "reference sensor '" + options.reference + "' is not in the input";
    return out;
  }

  if (options.method != Method::kSchenk) {
    out.pairs = EstimateAllPairs(tracks, options.pairwise);
    timer.Mark("pairwise");
    if (options.use_icp) {
      ApplyIcp(tracks, options, &out.pairs);
      timer.Mark("icp");
    }
    // The joint refinement fits every associated observation with the measurement model, which
    // does not know how a torso fit errs on legs: with thousands of them it pulls the poses of a
    // mis-mounted sensor and its neighbours ~0.1 m off while claiming a few centimetres
    // (shop_floor). Its pairs carry the bias prior; the poses are theirs.
    std::string mismounted;
    for (std::size_t i = 0; i < out.mount_checks.size(); ++i) {
      if (out.mount_checks[i].looks_like_legs) {
        mismounted += (mismounted.empty() ? "" : ", ") + tracks.sensors[i].id;
      }
    }
    if (options.refine && !mismounted.empty()) {
      CalibrationOptions pairs_only = options;
      pairs_only.refine = false;
      result.warnings.push_back("joint refinement not run: the tracks of " + mismounted +
                                " carry a bias it does not model (shape.mount)");
      SolveFromPairs(pairs_only, &timer, &out);
    } else {
      SolveFromPairs(options, &timer, &out);
    }
    AddMountFlags(&out);
    return out;
  }

  std::size_t reference = 0;
  if (!options.reference.empty()) {
    reference = *IndexOf(tracks, options.reference);
  } else {
    // Best-connected by simultaneous track time (Schenk's pairs are formed inside).
    std::vector<double> overlap(n, 0.0);
    for (const PairData& p : out.assessment.pairs) {
      overlap[p.r] += p.overlap_s;
      overlap[p.s] += p.overlap_s;
    }
    reference = static_cast<std::size_t>(std::max_element(overlap.begin(), overlap.end()) -
                                         overlap.begin());
  }
  GlobalSolution global;
  std::vector<std::size_t> measurement_of_pair;
  const SchenkResult schenk = CalibrateSchenk(tracks, reference, options.schenk);
  timer.Mark("schenk");
  global.world_from_sensor = schenk.world_from_sensor;
  global.calibrated = schenk.placed;
  global.covariance.assign(n, Eigen::Matrix3d::Zero());
  global.world_from_sensor.resize(n, Pose2::Identity());
  global.calibrated.resize(n, false);
  for (const SchenkEdge& e : schenk.edges) {
    PairEstimate p;
    p.r = std::min(e.r, e.s);
    p.s = std::max(e.r, e.s);
    p.accepted = e.used;
    p.reason = e.used ? "" : "not used by the placement";
    p.s_from_r = e.r < e.s ? e.s_from_r : e.s_from_r.inverse();
    p.matches = e.n;
    p.mean_residual_m = e.d_m;
    p.rms_m = e.d_m;
    out.pairs.push_back(p);
    measurement_of_pair.push_back(global.edge_status.size());
    global.edge_status.push_back("used");
  }
  if (!schenk.ok) global.warnings.push_back(schenk.message);
  Finish(global, reference, measurement_of_pair, &timer, &out);
  AddMountFlags(&out);
  return out;
}

}  // namespace lrfnet::calib
