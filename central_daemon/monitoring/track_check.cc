#include "central_daemon/monitoring/track_check.h"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "common/eigen_instances.h"

namespace lrfnet::monitoring {

namespace {

constexpr std::size_t kSensor = 0;  // indices in the two-sensor AlignedTracks
constexpr std::size_t kWorld = 1;
// Association and refit rounds: each refit associates again under the pose it found.
constexpr int kFitRounds = 3;

std::uint64_t MixSession(std::uint64_t session, std::uint64_t index) {
  // SplitMix64 of the pair: distinct sessions of distinct sensors stay distinct.
  std::uint64_t z = session + 0x9E3779B97F4A7C15ull * (index + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

double Chi2(const Eigen::Vector3d& x, const Eigen::Matrix3d& covariance) {
  const Eigen::LDLT<Eigen::Matrix3d> ldlt(covariance);
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive() ||
      !(covariance.diagonal().minCoeff() > 0.0)) {
    return 0.0;
  }
  const double chi2 = x.dot(ldlt.solve(x));
  return std::isfinite(chi2) && chi2 > 0 ? chi2 : 0.0;
}

// Standard deviation along the main direction of the sensor's matched positions.
double Spread(const calib::AlignedTracks& aligned, const std::vector<calib::Match>& matches) {
  if (matches.size() < 2) return 0.0;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  std::size_t n = 0;
  const auto& tracks = aligned.sensors[kSensor].tracks;
  for (const calib::Match& m : matches) {
    mean += tracks[m.track_r].At(m.step).position_m;
    ++n;
  }
  mean /= static_cast<double>(n);
  Eigen::Matrix2d scatter = Eigen::Matrix2d::Zero();
  for (const calib::Match& m : matches) {
    const Eigen::Vector2d d = tracks[m.track_r].At(m.step).position_m - mean;
    scatter += d * d.transpose();
  }
  scatter /= static_cast<double>(n);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen(scatter);
  return std::sqrt(std::max(0.0, eigen.eigenvalues().maxCoeff()));
}

double TrackSpread(const calib::GridTrack& track) {
  if (track.samples.size() < 2) return 0.0;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const calib::TrackSample& s : track.samples) mean += s.position_m;
  mean /= static_cast<double>(track.samples.size());
  Eigen::Matrix2d scatter = Eigen::Matrix2d::Zero();
  for (const calib::TrackSample& s : track.samples) {
    const Eigen::Vector2d d = s.position_m - mean;
    scatter += d * d.transpose();
  }
  scatter /= static_cast<double>(track.samples.size());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen(scatter);
  return std::sqrt(std::max(0.0, eigen.eigenvalues().maxCoeff()));
}

// Sensor samples on grid steps where W has any sample (what could be associated at all).
std::size_t CoVisibleSamples(const calib::AlignedTracks& aligned) {
  std::vector<unsigned char> world(aligned.steps, 0);
  for (const calib::GridTrack& t : aligned.sensors[kWorld].tracks) {
    for (std::size_t k = t.first_step; k < t.end_step() && k < aligned.steps; ++k) world[k] = 1;
  }
  std::size_t n = 0;
  for (const calib::GridTrack& t : aligned.sensors[kSensor].tracks) {
    for (std::size_t k = t.first_step; k < t.end_step() && k < aligned.steps; ++k) n += world[k];
  }
  return n;
}

calib::AlignedTracks AlignPair(const std::vector<TrackFrameData>& sensor,
                               const std::vector<PlacedFrames>& others,
                               const TrackCheckOptions& options) {
  calib::CalibrationInput input;
  calib::SensorRecording own;
  own.id = "sensor";
  own.frames = sensor;
  input.sensors.push_back(std::move(own));
  input.sensors.push_back(WorldRecording(others, options.align.model));
  calib::AlignedTracks aligned = calib::Align(input, options.align);
  // W's positions are body centres already, corrected in their own sensors' frames (see
  // WorldRecording): no measurement model on top (Align's would take the world origin for their
  // sensor and add a bias along the wrong line of sight).
  for (calib::GridTrack& t : aligned.sensors[kWorld].tracks) {
    for (calib::TrackSample& x : t.samples) {
      x.bias_m = 0.0f;
      x.bias_per_major = 0.0f;
      x.bias_per_minor = 0.0f;
      x.bias_sigma_m = 0.0f;
      x.model_sigma_m = 0.0f;
    }
  }
  // Leave out what stands still (see TrackCheckOptions::min_track_spread_m).
  for (calib::SensorTracks& sensor_tracks : aligned.sensors) {
    std::vector<calib::GridTrack> kept;
    for (calib::GridTrack& t : sensor_tracks.tracks) {
      if (TrackSpread(t) >= options.min_track_spread_m) kept.push_back(std::move(t));
    }
    sensor_tracks.tracks = std::move(kept);
  }
  return aligned;
}

// Associate under `pose`, fit, and again under the fit, kFitRounds times.
TrackFit FitFrom(const calib::AlignedTracks& aligned, const Pose2& start,
                 const TrackCheckOptions& options) {
  TrackFit out;
  out.world_from_sensor = start;
  Pose2 pose = start;
  std::vector<calib::Match> matches;
  calib::RigidFit fit;
  for (int round = 0; round < kFitRounds; ++round) {
    matches = calib::AssociatePair(aligned, kSensor, kWorld, pose, options.pairwise.refit_gate_m);
    if (matches.size() < options.min_matches) break;
    fit = calib::FitMatches(aligned, kSensor, kWorld, matches, options.pairwise);
    if (!fit.ok) break;
    pose = fit.s_from_r;
  }
  out.matches = matches.size();
  if (matches.size() < options.min_matches) {
    out.reason =
        fmt::format("{} associated observations ({} needed)", matches.size(), options.min_matches);
    return out;
  }
  if (!fit.ok) {
    out.reason = "the associated observations fix no pose";
    return out;
  }
  out.spread_m = Spread(aligned, matches);
  if (out.spread_m < options.min_match_spread_m) {
    out.reason = fmt::format("the matched tracks span {:.2f} m ({:.2f} m needed)", out.spread_m,
                             options.min_match_spread_m);
    return out;
  }
  out.enough = true;
  out.world_from_sensor = fit.s_from_r;
  out.covariance = fit.covariance;
  out.covariance_sensor_bias = fit.covariance_sensor_bias;
  out.rms_m = fit.rms_m;
  return out;
}

void Judge(const Pose2& current, const Pose2& baseline, const TrackCheckOptions& options,
           TrackFit* fit) {
  if (!fit->enough) return;
  // What the tracks would put at `current` when nothing moved: current * baseline.
  const Pose2 expected = current * baseline;
  fit->correction = current.inverse() * fit->world_from_sensor;
  const Pose2 motion = expected.inverse() * fit->world_from_sensor;
  const Eigen::Vector3d delta(fit->world_from_sensor.x_m - expected.x_m,
                              fit->world_from_sensor.y_m - expected.y_m,
                              common::AngleDiff(fit->world_from_sensor.yaw_rad, expected.yaw_rad));
  // The sensor's shared bias is in the baseline too (track_check.h): not a source of motion.
  fit->chi2 = Chi2(delta, fit->covariance - fit->covariance_sensor_bias);
  const double yaw_deg = common::RadToDeg(motion.yaw_rad);
  const double shift_m = std::hypot(motion.x_m, motion.y_m);
  const bool large =
      std::abs(yaw_deg) >= options.min_yaw_deg || shift_m >= options.min_translation_m;
  fit->moved = large && fit->chi2 >= options.min_chi2 && fit->rms_m <= options.max_fit_rms_m;
  fit->reason = fmt::format(
      "{} associated observations over {:.1f} m, residual {:.3f} m rms; moved by {:.2f} deg, "
      "{:.3f} m (chi2 {:.0f})",
      fit->matches, fit->spread_m, fit->rms_m, yaw_deg, shift_m, fit->chi2);
}

}  // namespace

calib::PairwiseOptions TrackCheckOptions::DefaultPairwise() {
  calib::PairwiseOptions o;
  // The world's tracks come from sensors of known pose; only the sensor's own view offset is
  // estimated (its prior as in the calibration).
  o.min_matches = 60;
  return o;
}

std::optional<std::string> Validate(const TrackCheckOptions& o) {
  if (auto e = calib::Validate(o.align)) return "align." + *e;
  if (auto e = calib::Validate(o.pairwise)) return "pairwise." + *e;
  if (o.min_matches < 10) return "min_matches must be >= 10";
  if (!(std::isfinite(o.min_track_spread_m) && o.min_track_spread_m >= 0.0)) {
    return "min_track_spread_m must be >= 0";
  }
  if (!(std::isfinite(o.max_fit_rms_m) && o.max_fit_rms_m > 0.0)) {
    return "max_fit_rms_m must be > 0";
  }
  if (!(std::isfinite(o.min_match_spread_m) && o.min_match_spread_m >= 0.0)) {
    return "min_match_spread_m must be >= 0";
  }
  if (!(std::isfinite(o.min_yaw_deg) && o.min_yaw_deg >= 0.0)) return "min_yaw_deg must be >= 0";
  if (!(std::isfinite(o.min_translation_m) && o.min_translation_m >= 0.0)) {
    return "min_translation_m must be >= 0";
  }
  if (!(std::isfinite(o.min_chi2) && o.min_chi2 >= 0.0)) return "min_chi2 must be >= 0";
  return std::nullopt;
}

calib::SensorRecording WorldRecording(const std::vector<PlacedFrames>& others,
                                      const daemon::MeasurementModelOptions& model) {
  calib::SensorRecording world;
  world.id = "world";
  for (std::size_t i = 0; i < others.size(); ++i) {
    if (others[i].frames == nullptr) continue;
    const Pose2& pose = others[i].world_from_sensor;
    const Eigen::Matrix2d r = pose.rotation();
    Eigen::Matrix4d j = Eigen::Matrix4d::Zero();
    j.topLeftCorner<2, 2>() = r;
    j.bottomRightCorner<2, 2>() = r;
    for (const TrackFrameData& frame : *others[i].frames) {
      TrackFrameData out = frame;
      out.session_id = MixSession(frame.session_id, i);
      for (daemon::TrackObservation& t : out.tracks) {
        // The body centre the measurement model implies, in the sensor's own frame (its line of
        // sight), with what the model does not know added to the covariance.
        const daemon::CorrectedPosition centre = daemon::CorrectedPositionOf(t, model);
        const Eigen::Vector2d p = pose * Eigen::Vector2d(centre.x_m, centre.y_m);
        const Eigen::Vector2d v = r * Eigen::Vector2d(t.vx_mps, t.vy_mps);
        const auto& c = t.covariance;
        Eigen::Matrix4d cov;
        cov << c[0], c[1], c[2], c[3],  //
            c[1], c[4], c[5], c[6],     //
            c[2], c[5], c[7], c[8],     //
            c[3], c[6], c[8], c[9];
        if (std::isfinite(centre.extra_variance_m2) && centre.extra_variance_m2 > 0.0) {
          cov(0, 0) += centre.extra_variance_m2;
          cov(1, 1) += centre.extra_variance_m2;
        }
        const Eigen::Matrix4d w = j * cov * j.transpose();
        t.x_m = static_cast<float>(p.x());
        t.y_m = static_cast<float>(p.y());
        t.vx_mps = static_cast<float>(v.x());
        t.vy_mps = static_cast<float>(v.y());
        t.covariance = {static_cast<float>(w(0, 0)), static_cast<float>(w(0, 1)),
                        static_cast<float>(w(0, 2)), static_cast<float>(w(0, 3)),
                        static_cast<float>(w(1, 1)), static_cast<float>(w(1, 2)),
                        static_cast<float>(w(1, 3)), static_cast<float>(w(2, 2)),
                        static_cast<float>(w(2, 3)), static_cast<float>(w(3, 3))};
        // A body centre: AlignPair leaves W's samples without a model of their own.
        t.kind = daemon::MeasurementKind::kShapeFit;
      }
      world.frames.push_back(std::move(out));
    }
  }
  return world;
}

TrackFit CheckTracks(const std::vector<TrackFrameData>& sensor, const Pose2& world_from_sensor,
                     const std::vector<PlacedFrames>& others, const TrackCheckOptions& options,
                     const Pose2& baseline) {
  if (auto e = Validate(options)) {
    std::fprintf(stderr, "CheckTracks: invalid options: %s\n", e->c_str());
    std::abort();
  }
  const calib::AlignedTracks aligned = AlignPair(sensor, others, options);
  TrackFit fit = FitFrom(aligned, world_from_sensor, options);
  if (!fit.enough) {
    // The sensor's tracks and the others' overlap in time but hardly associate under the current
    // pose: a move too large for the association gate. Search the pose from scratch.
    const std::size_t co_visible = CoVisibleSamples(aligned);
    if (co_visible >= 4 * options.min_matches && fit.matches * 4 < co_visible) {
      const calib::PairEstimate search =
          calib::EstimatePair(aligned, kSensor, kWorld, options.pairwise);
      if (search.accepted) {
        TrackFit found = FitFrom(aligned, search.s_from_r, options);
        if (found.enough) {
          found.from_search = true;
          fit = found;
        }
      }
    }
  }
  Judge(world_from_sensor, baseline, options, &fit);
  return fit;
}

TrackFit EstimateFromTracks(const std::vector<TrackFrameData>& sensor, const Pose2& initial,
                            const std::vector<PlacedFrames>& others,
                            const TrackCheckOptions& options, const Pose2& baseline) {
  if (auto e = Validate(options)) {
    std::fprintf(stderr, "EstimateFromTracks: invalid options: %s\n", e->c_str());
    std::abort();
  }
  const calib::AlignedTracks aligned = AlignPair(sensor, others, options);
  TrackFit fit = FitFrom(aligned, initial, options);
  if (!fit.enough || fit.rms_m > options.pairwise.max_rms_m) {
    const calib::PairEstimate search =
        calib::EstimatePair(aligned, kSensor, kWorld, options.pairwise);
    if (search.accepted) {
      TrackFit found = FitFrom(aligned, search.s_from_r, options);
      if (found.enough && (!fit.enough || found.rms_m < fit.rms_m)) {
        found.from_search = true;
        fit = found;
      }
    }
  }
  Judge(initial, baseline, options, &fit);
  return fit;
}

}  // namespace lrfnet::monitoring
