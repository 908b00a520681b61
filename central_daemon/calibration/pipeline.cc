#include "central_daemon/calibration/pipeline.h"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <utility>

#include "central_daemon/calibration/graph.h"
#include "central_daemon/calibration/spectral.h"

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

double WeightOf(const PairEstimate& pair) {
  // Schenk et al.: N / d, the number of associated observations over their mean distance.
  const double d = std::max(pair.mean_residual_m, 1e-3);
  return static_cast<double>(pair.matches) / d;
}

std::size_t BestConnected(const std::vector<PairEstimate>& pairs, std::size_t n) {
  std::vector<std::size_t> degree(n, 0), matches(n, 0);
  for (const PairEstimate& p : pairs) {
    if (!p.accepted) continue;
    for (std::size_t i : {p.r, p.s}) {
      ++degree[i];
      matches[i] += p.matches;
    }
  }
  std::size_t best = 0;
  for (std::size_t i = 1; i < n; ++i) {
    if (std::tie(degree[i], matches[i]) > std::tie(degree[best], matches[best])) best = i;
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
    const Eigen::Vector2d pr = tracks.sensors[r].tracks[m.track_r].At(m.step).position_m;
    const Eigen::Vector2d ps = tracks.sensors[s].tracks[m.track_s].At(m.step).position_m;
    out.sum_sq += (s_from_r * pr - ps).squaredNorm();
    ++out.count;
  }
  return out;
}

// Global poses of the nodes connected to `reference` from the pairwise measurements, by the
// method's rotation averaging and least-squares translations. Fills result->sensors and the
// per-edge status of `edge_status` (index = measurement index).
struct GlobalSolution {
  std::vector<Pose2> world_from_sensor;
  std::vector<bool> calibrated;
  std::vector<Eigen::Matrix3d> covariance;
  std::vector<std::string> edge_status;  // per measurement
  std::vector<std::string> warnings;
};

GlobalSolution SolveGlobal(std::size_t n, std::size_t reference,
                           const std::vector<RelativeMeasurement>& all, Method method,
                           const CalibrationOptions& options) {
  GlobalSolution out;
  out.world_from_sensor.assign(n, Pose2::Identity());
  out.calibrated.assign(n, false);
  out.covariance.assign(n, Eigen::Matrix3d::Zero());
  out.edge_status.assign(all.size(), "used");

  // The connected part: a sub-problem with its own indices.
  const std::vector<std::size_t> unconnected = UnconnectedNodes(n, reference, all);
  std::vector<std::size_t> to_sub(n, std::numeric_limits<std::size_t>::max());
  std::vector<std::size_t> to_full;
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::binary_search(unconnected.begin(), unconnected.end(), i)) {
      to_sub[i] = to_full.size();
      to_full.push_back(i);
    }
  }
  std::vector<RelativeMeasurement> sub;
  std::vector<std::size_t> sub_to_all;
  for (std::size_t e = 0; e < all.size(); ++e) {
    if (to_sub[all[e].r] == std::numeric_limits<std::size_t>::max()) {
      out.edge_status[e] = "not connected to the reference";
      continue;
    }
    RelativeMeasurement m = all[e];
    m.r = to_sub[m.r];
    m.s = to_sub[m.s];
    sub.push_back(m);
    sub_to_all.push_back(e);
  }
  const std::size_t m = to_full.size();
  const std::size_t ref = to_sub[reference];
  out.calibrated[reference] = true;
  if (m == 1) return out;

  RotationAveragingOptions rotation_options = options.rotation;
  rotation_options.use_weights = options.weighted;
  RotationAveragingResult rotations =
      method == Method::kSpectral ? AverageRotationsSpectral(m, ref, sub, options.weighted)
                                  : AverageRotationsL1(m, ref, sub, rotation_options);
  if (!rotations.ok) {
    out.warnings.push_back("rotation averaging failed: " + rotations.error);
    return out;
  }
  std::vector<bool> use(sub.size(), true);
  if (method == Method::kQuenzel) {
    for (std::size_t e = 0; e < sub.size(); ++e) {
      if (e < rotations.inlier.size() && !rotations.inlier[e]) {
        use[e] = false;
        out.edge_status[sub_to_all[e]] = "rotation outlier";
      }
    }
    // Dropping outliers must not disconnect the graph: such an edge is the only link we have.
    std::vector<RelativeMeasurement> kept;
    for (std::size_t e = 0; e < sub.size(); ++e) {
      if (use[e]) kept.push_back(sub[e]);
    }
    if (!UnconnectedNodes(m, ref, kept).empty()) {
      for (std::size_t e = 0; e < sub.size(); ++e) {
        if (!use[e]) {
          use[e] = true;
          out.edge_status[sub_to_all[e]] = "used (rotation outlier, but the only link)";
        }
      }
      out.warnings.push_back(
          "a rotation outlier edge is the only link of some sensors; their poses are uncertain");
    }
  }
  TranslationOptions translation_options = options.translation;
  translation_options.use_weights = options.weighted || method == Method::kSpectral;
  TranslationResult translations =
      SolveTranslations(m, ref, rotations.yaw_rad, sub, use, translation_options);
  if (translations.ok && method == Method::kQuenzel) {
    // A rotation-consistent edge can still be a wrong translation (a mismatch along a line of
    // tracks): drop edges far off the solution and solve again, if the graph stays connected.
    std::vector<bool> use2 = use;
    bool dropped = false;
    for (std::size_t e = 0; e < sub.size(); ++e) {
      if (use2[e] && e < translations.residual_m.size() &&
          translations.residual_m[e] > options.max_translation_residual_m) {
        use2[e] = false;
        dropped = true;
      }
    }
    if (dropped) {
      std::vector<RelativeMeasurement> kept;
      for (std::size_t e = 0; e < sub.size(); ++e) {
        if (use2[e]) kept.push_back(sub[e]);
      }
      if (UnconnectedNodes(m, ref, kept).empty()) {
        TranslationResult again =
            SolveTranslations(m, ref, rotations.yaw_rad, sub, use2, translation_options);
        if (again.ok) {
          for (std::size_t e = 0; e < sub.size(); ++e) {
            if (use[e] && !use2[e]) out.edge_status[sub_to_all[e]] = "translation outlier";
          }
          use = use2;
          translations = std::move(again);
        }
      }
    }
  }
  if (!translations.ok) {
    out.warnings.push_back("translation estimation failed: " + translations.error);
    return out;
  }
  for (std::size_t i = 0; i < m; ++i) {
    const std::size_t full = to_full[i];
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
        e.rotation_residual_deg =
            common::RadToDeg(std::abs(common::AngleDiff(p.s_from_r.yaw_rad, final_s_from_r.yaw_rad)));
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
    const IcpResult icp = RefineWithBackgrounds(*r.background, *s.background, p.s_from_r, options.icp);
    p.icp_score_before = icp.score_before;
    p.icp_score_after = icp.score_after;
    if (!icp.applied) continue;
    // The backgrounds agree better; the tracks must still agree (within the object-shape bias).
    const TrackResidual before = ResidualOf(tracks, p.r, p.s, p.s_from_r);
    const TrackResidual after = ResidualOf(tracks, p.r, p.s, icp.s_from_r);
    if (before.count == 0 || after.count * 2 < before.count) continue;
    const double rms_before = std::sqrt(before.sum_sq / static_cast<double>(before.count));
    const double rms_after = std::sqrt(after.sum_sq / static_cast<double>(after.count));
    if (rms_after > rms_before + options.icp_max_track_rms_increase_m) continue;
    p.s_from_r = icp.s_from_r;
    p.icp_applied = true;
    // The walls now fix this pair far better than the tracks: the joint refinement keeps it as
    // a constraint with the ICP's covariance.
    if (icp.covariance.allFinite() && icp.covariance.determinant() > 0.0) {
      p.covariance = icp.covariance;
    }
  }
}

}  // namespace

const char* ToString(Method method) {
  switch (method) {
    case Method::kQuenzel: return "quenzel";
    case Method::kSpectral: return "spectral";
    case Method::kSchenk: return "schenk";
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
  if (!(options.icp_max_track_rms_increase_m >= 0.0) ||
      !std::isfinite(options.icp_max_track_rms_increase_m)) {
    return "icp_max_track_rms_increase_m must be a finite value >= 0";
  }
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
    d.tracked_s = static_cast<double>(std::count(seen[i].begin(), seen[i].end(), true)) *
                  tracks.step_s;
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
    out.missing = "no sensor has any track: nobody walked through the scene (or every track was "
                  "shorter than align.min_track_duration_s)";
  } else if (!out.unlinked.empty()) {
    std::string text;
    if (!no_tracks.empty()) {
      text = "no tracks from ";
      for (std::size_t k = 0; k < no_tracks.size(); ++k) text += (k ? ", " : "") + no_tracks[k];
      text += "; ";
    }
    std::string linked;
    for (std::size_t k = 0; k < out.unlinked.size(); ++k) linked += (k ? ", " : "") + out.unlinked[k];
    // The best link of each unlinked sensor tells the user how far it is from enough.
    double best_s = 0.0;
    for (const PairData& p : out.pairs) {
      if ((find(p.r) == find(main)) != (find(p.s) == find(main))) best_s = std::max(best_s, p.overlap_s);
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
  const AlignedTracks& tracks = out.tracks;
  timer.Mark("align + smoothing");
  const std::size_t n = tracks.sensors.size();
  for (const SensorTracks& s : tracks.sensors) {
    SensorPose pose;
    pose.id = s.id;
    result.sensors.push_back(pose);
    if (s.clock_suspect) {
      result.warnings.push_back("sensor " + s.id + " reports an unsynchronised clock");
    }
  }

  out.assessment = Assess(tracks, options.min_pair_overlap_s);
  if (!out.assessment.sufficient) {
    out.error = "too little data: " + out.assessment.missing;
    timer.Total();
    return out;
  }

  std::size_t reference = 0;
  if (!options.reference.empty()) {
    const auto index = IndexOf(tracks, options.reference);
    if (!index) {
      out.error = "reference sensor '" + options.reference + "' is not in the input";
      return out;
    }
    reference = *index;
  }

  GlobalSolution global;
  std::vector<std::size_t> measurement_of_pair;
  if (options.method == Method::kSchenk) {
    if (options.reference.empty()) {
      // Best-connected by simultaneous track time (Schenk's pairs are formed inside).
      std::vector<double> overlap(n, 0.0);
      for (const PairData& p : out.assessment.pairs) {
        overlap[p.r] += p.overlap_s;
        overlap[p.s] += p.overlap_s;
      }
      reference = static_cast<std::size_t>(
          std::max_element(overlap.begin(), overlap.end()) - overlap.begin());
    }
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
  } else {
    out.pairs = EstimateAllPairs(tracks, options.pairwise);
    timer.Mark("pairwise");
    if (options.use_icp) {
      ApplyIcp(tracks, options, &out.pairs);
      timer.Mark("icp");
    }
    if (options.reference.empty()) reference = BestConnected(out.pairs, n);
    std::vector<RelativeMeasurement> measurements;
    measurement_of_pair.assign(out.pairs.size(), 0);
    for (std::size_t k = 0; k < out.pairs.size(); ++k) {
      const PairEstimate& p = out.pairs[k];
      if (!p.accepted) continue;
      RelativeMeasurement m;
      m.r = p.r;
      m.s = p.s;
      m.s_from_r = p.s_from_r;
      m.weight = WeightOf(p);
      m.covariance = p.covariance;
      measurement_of_pair[k] = measurements.size();
      measurements.push_back(m);
    }
    global = SolveGlobal(n, reference, measurements, options.method, options);
    timer.Mark("rotation averaging + translations");

    if (options.refine && options.method == Method::kQuenzel) {
      // Pairs aligned on their backgrounds are constraints: without them the tracks' systematic
      // errors (object-shape bias) would pull wall-accurate poses apart.
      std::vector<RelativePoseConstraint> constraints;
      for (const PairEstimate& p : out.pairs) {
        if (!p.accepted || !p.icp_applied) continue;
        constraints.push_back({p.r, p.s, p.s_from_r, p.covariance});
      }
      const JointRefineResult joint =
          RefineJointly(tracks, global.world_from_sensor, global.calibrated, reference,
                        options.joint, constraints);
      timer.Mark("joint refinement");
      result.refine_cost_before = joint.cost_before;
      result.refine_cost_after = joint.cost_after;
      result.refine_observations = joint.observations;
      if (!joint.ok) {
        result.warnings.push_back("joint refinement not applied: " + joint.message);
      } else if (!(joint.cost_after < joint.cost_before)) {
        result.warnings.push_back("joint refinement did not lower the cost; not applied");
      } else {
        result.refined = true;
        global.world_from_sensor = joint.world_from_sensor;
        for (std::size_t i = 0; i < n && i < joint.covariance.size(); ++i) {
          if (global.calibrated[i]) global.covariance[i] = joint.covariance[i];
        }
      }
    }
  }
  for (std::string& w : global.warnings) result.warnings.push_back(std::move(w));

  result.reference = tracks.sensors[reference].id;
  for (std::size_t i = 0; i < n; ++i) {
    result.sensors[i].calibrated = global.calibrated[i];
    result.sensors[i].world_from_sensor =
        global.calibrated[i] ? global.world_from_sensor[i] : Pose2::Identity();
    result.sensors[i].covariance = global.covariance[i];
  }
  FillEdges(tracks, out.pairs, measurement_of_pair, global.edge_status, &result);
  timer.Total();

  std::vector<std::size_t> unconnected;
  for (std::size_t i = 0; i < n; ++i) {
    if (!global.calibrated[i]) unconnected.push_back(i);
  }
  if (!unconnected.empty()) {
    std::string detail;
    for (const PairEstimate& p : out.pairs) {
      const bool involves = std::find(unconnected.begin(), unconnected.end(), p.r) !=
                                unconnected.end() ||
                            std::find(unconnected.begin(), unconnected.end(), p.s) !=
                                unconnected.end();
      if (involves && !p.accepted && detail.size() < 400) {
        detail += "; " + tracks.sensors[p.r].id + "-" + tracks.sensors[p.s].id + ": " + p.reason;
      }
    }
    out.error = "sensors not connected to the reference " + result.reference + ": " +
                JoinIds(tracks, unconnected) +
                " (no accepted pairwise estimate links them" + detail + ")";
    return out;
  }
  out.ok = true;
  return out;
}

}  // namespace lrfnet::calib
