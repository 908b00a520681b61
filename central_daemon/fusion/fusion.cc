#include "central_daemon/fusion/fusion.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <utility>

#include "central_daemon/fusion/fusion_internal.h"
#include "common/cv_model.h"

namespace lrfnet::fusion {

namespace internal {

using common::CvCovariance;
using common::CvState;
using common::UtcNs;

double Seconds(UtcNs a, UtcNs b) {
  UtcNs diff = 0;
  if (__builtin_sub_overflow(a, b, &diff)) {
    return a > b ? std::numeric_limits<double>::infinity()
                 : -std::numeric_limits<double>::infinity();
  }
  return common::NsToSeconds(diff);
}

Eigen::Matrix4d UnpackCovariance(const std::array<float, 10>& c) {
  Eigen::Matrix4d m;
  std::size_t k = 0;
  for (int r = 0; r < 4; ++r) {
    for (int col = r; col < 4; ++col) {
      m(r, col) = m(col, r) = static_cast<double>(c[k++]);
    }
  }
  return m;
}

void Predict(double dt_s, double accel_psd, CvState& x, CvCovariance& p) {
  if (dt_s == 0.0 || !std::isfinite(dt_s)) return;  // infinite: only from saturated hostile stamps
  x(0) += dt_s * x(2);
  x(1) += dt_s * x(3);
  common::CvApplyTransition(dt_s, p);
  common::CvApplyTransitionTransposed(dt_s, p);
  p += common::CvProcessNoise(std::abs(dt_s), accel_psd);
  p = 0.5 * (p + p.transpose()).eval();
}

std::optional<FusedTrack> PredictedFusedTrack(std::uint64_t id, bool confirmed, UtcNs first_ns,
                                              UtcNs stamp_ns, std::uint64_t updates, CvState x,
                                              CvCovariance p, const FusionOptions& options,
                                              UtcNs now_ns) {
  const double age = Seconds(now_ns, stamp_ns);
  if (age > options.max_coast_s || -age > options.max_coast_s) return std::nullopt;
  Predict(age, options.accel_psd, x, p);
  FusedTrack t;
  t.id = id;
  t.state = !confirmed                    ? FusedState::kTentative
            : age > options.coast_after_s ? FusedState::kCoasting
                                          : FusedState::kConfirmed;
  t.stamp_ns = now_ns;
  t.first_ns = first_ns;
  t.x_m = x(0);
  t.y_m = x(1);
  t.vx_mps = x(2);
  t.vy_mps = x(3);
  t.covariance = p;
  t.updates = updates;
  return t;
}

double Mahalanobis2(const Eigen::Vector2d& a, const Eigen::Matrix2d& pa, const Eigen::Vector2d& b,
                    const Eigen::Matrix2d& pb, double* log_det) {
  const Eigen::Matrix2d s = pa + pb;
  const Eigen::LLT<Eigen::Matrix2d> llt(s);
  if (llt.info() != Eigen::Success) return std::numeric_limits<double>::infinity();
  const Eigen::Vector2d r = a - b;
  if (log_det != nullptr) {
    const Eigen::Matrix2d l = llt.matrixL();
    *log_det = 2.0 * (std::log(l(0, 0)) + std::log(l(1, 1)));
  }
  const double d2 = r.dot(llt.solve(r));
  return std::isfinite(d2) ? d2 : std::numeric_limits<double>::infinity();
}

bool PlausibleObservation(const FusionOptions& o, const daemon::TrackObservation& t) {
  const double x = t.x_m, y = t.y_m, vx = t.vx_mps, vy = t.vy_mps;
  if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(vx) || !std::isfinite(vy)) {
    return false;
  }
  if (std::hypot(x, y) > o.max_local_range_m || std::hypot(vx, vy) > o.max_speed_mps) return false;
  const Eigen::Matrix4d c = UnpackCovariance(t.covariance);
  if (!IsCovariance<4>(c)) return false;
  return c(0, 0) <= o.max_position_variance_m2 && c(1, 1) <= o.max_position_variance_m2 &&
         c(2, 2) <= o.max_velocity_variance_m2ps2 && c(3, 3) <= o.max_velocity_variance_m2ps2;
}

daemon::TrackObservation CentreCorrected(const daemon::TrackObservation& observation,
                                         double radial_offset_m) {
  if (radial_offset_m == 0.0) return observation;
  // The centre moved away from the sensor by the offset: p' = p + b p / |p|; its velocity by the
  // derivative, v' = v + b (v - (v.n) n) / |p| (n = p / |p|). The covariance is kept (the
  // Jacobian differs from I by b / |p|).
  const Eigen::Vector2d p(observation.x_m, observation.y_m);
  const Eigen::Vector2d v(observation.vx_mps, observation.vy_mps);
  const double range = p.norm();
  if (!std::isfinite(range) || range < 0.1 || !std::isfinite(radial_offset_m)) return observation;
  const Eigen::Vector2d n = p / range;
  const Eigen::Vector2d p2 = p + radial_offset_m * n;
  const Eigen::Vector2d v2 = v + radial_offset_m / range * (v - v.dot(n) * n);
  daemon::TrackObservation out = observation;
  out.x_m = static_cast<float>(p2.x());
  out.y_m = static_cast<float>(p2.y());
  out.vx_mps = static_cast<float>(v2.x());
  out.vy_mps = static_cast<float>(v2.y());
  return out;
}

bool SamePlacement(const SensorPlacement& a, const SensorPlacement& b) {
  return a.world_from_sensor.x_m == b.world_from_sensor.x_m &&
         a.world_from_sensor.y_m == b.world_from_sensor.y_m &&
         a.world_from_sensor.yaw_rad == b.world_from_sensor.yaw_rad && a.covariance == b.covariance;
}

Eigen::Matrix<double, 4, 3> PoseJacobian(const common::Pose2& world_from_sensor,
                                         const Eigen::Vector2d& p_s, const Eigen::Vector2d& v_s) {
  const Eigen::Matrix2d r = world_from_sensor.rotation();
  Eigen::Matrix2d dr;  // dR/dyaw
  dr << -r(1, 0), -r(0, 0), r(0, 0), -r(1, 0);
  Eigen::Matrix<double, 4, 3> j = Eigen::Matrix<double, 4, 3>::Zero();
  j(0, 0) = 1.0;
  j(1, 1) = 1.0;
  j.col(2).head<2>() = dr * p_s;
  j.col(2).tail<2>() = dr * v_s;
  return j;
}

FrameAdmission AdmitFrame(const daemon::TrackFrameData& frame, double max_out_of_order_s,
                          FrameClock& clock, bool& have_newest, UtcNs& newest_ns) {
  const UtcNs t = frame.scan_start_ns;
  if (t <= 0) return FrameAdmission::kInvalid;
  // Another part of the latest scan (a scan's tracks may come in several datagrams) adds its
  // tracks; anything else not newer than the latest scan is stale.
  const std::uint64_t part_bit = frame.part < 64 ? std::uint64_t{1} << frame.part : 0;
  const bool another_part = clock.has_frame && t == clock.latest_ns &&
                            frame.session_id == clock.session_id &&
                            frame.scan_counter == clock.scan_counter && part_bit != 0 &&
                            (clock.parts_seen & part_bit) == 0;
  if (another_part) {
    clock.parts_seen |= part_bit;
    return FrameAdmission::kAnotherPart;
  }
  if (clock.has_frame && t <= clock.latest_ns) return FrameAdmission::kStale;
  if (have_newest && Seconds(newest_ns, t) > max_out_of_order_s) {
    return FrameAdmission::kOutOfOrder;
  }
  const bool new_session = clock.has_frame && frame.session_id != clock.session_id;
  clock.has_frame = true;
  clock.session_id = frame.session_id;
  clock.scan_counter = frame.scan_counter;
  clock.parts_seen = part_bit;
  clock.latest_ns = t;
  if (!have_newest || t > newest_ns) newest_ns = t;
  have_newest = true;
  return new_session ? FrameAdmission::kNewSession : FrameAdmission::kNewScan;
}

bool CountAdmission(FrameAdmission admission, FusionCounters& counters) {
  switch (admission) {
    case FrameAdmission::kNewScan:
    case FrameAdmission::kAnotherPart:
      return true;
    case FrameAdmission::kNewSession:
      ++counters.session_changes;
      return true;
    case FrameAdmission::kInvalid:
      ++counters.frames_invalid;
      return false;
    case FrameAdmission::kStale:
      ++counters.frames_stale;
      return false;
    case FrameAdmission::kOutOfOrder:
      ++counters.frames_out_of_order;
      return false;
  }
  return false;
}

}  // namespace internal

namespace {

// Bounds well above any calibration's uncertainty; beyond them a pose says nothing.
constexpr double kMaxPlacementVariance = 1e4;  // m^2 and rad^2

bool ValidPlacement(const SensorPlacement& p) {
  const common::Pose2& pose = p.world_from_sensor;
  if (!std::isfinite(pose.x_m) || !std::isfinite(pose.y_m) || !std::isfinite(pose.yaw_rad)) {
    return false;
  }
  if (std::abs(pose.x_m) > 1e6 || std::abs(pose.y_m) > 1e6) return false;
  return internal::IsCovariance<3>(p.covariance) &&
         p.covariance.diagonal().maxCoeff() <= kMaxPlacementVariance;
}

}  // namespace

const char* ToString(FusionMethod method) {
  switch (method) {
    case FusionMethod::kFusedFilter:
      return "fused_filter";
    case FusionMethod::kLatestStates:
      return "latest_states";
  }
  return "invalid";
}

const char* ToString(FusedState state) {
  switch (state) {
    case FusedState::kTentative:
      return "tentative";
    case FusedState::kConfirmed:
      return "confirmed";
    case FusedState::kCoasting:
      return "coasting";
  }
  return "invalid";
}

const char* ToString(FusedEndReason reason) {
  switch (reason) {
    case FusedEndReason::kTimedOut:
      return "timed_out";
    case FusedEndReason::kMerged:
      return "merged";
  }
  return "invalid";
}

std::optional<std::string> Validate(const FusionOptions& o) {
  auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  if (!positive(o.gate_mahalanobis2)) return "gate_mahalanobis2 must be > 0";
  if (!positive(o.gate_max_distance_m)) return "gate_max_distance_m must be > 0";
  if (!positive(o.accel_psd)) return "accel_psd must be > 0";
  if (o.method != FusionMethod::kFusedFilter && o.method != FusionMethod::kLatestStates) {
    return "method must be fused_filter or latest_states";
  }
  if (!positive(o.tracker_accel_psd)) return "tracker_accel_psd must be > 0";
  if (!positive(o.centre_sigma_shape_fit_m) || o.centre_sigma_shape_fit_m > 10.0) {
    return "centre_sigma_shape_fit_m must be in (0, 10]";
  }
  if (!positive(o.centre_sigma_ellipse_m) || o.centre_sigma_ellipse_m > 10.0) {
    return "centre_sigma_ellipse_m must be in (0, 10]";
  }
  if (!positive(o.centre_sigma_com_m) || o.centre_sigma_com_m > 10.0) {
    return "centre_sigma_com_m must be in (0, 10]";
  }
  if (!positive(o.centre_lateral_fraction) || o.centre_lateral_fraction > 1.0) {
    return "centre_lateral_fraction must be in (0, 1]";
  }
  if (!positive(o.centre_correlation_s)) return "centre_correlation_s must be > 0";
  if (!std::isfinite(o.binding_bonus) || o.binding_bonus < 0.0) {
    return "binding_bonus must be >= 0";
  }
  if (!positive(o.manoeuvre_max_distance_m)) return "manoeuvre_max_distance_m must be > 0";
  if (o.max_offset_sensors < 1 || o.max_offset_sensors > 64) {
    return "max_offset_sensors must be 1..64";
  }
  if (!positive(o.sensor_bias_sample_s)) return "sensor_bias_sample_s must be > 0";
  if (o.sensor_bias_min_samples < 2) return "sensor_bias_min_samples must be >= 2";
  if (o.sensor_bias_memory < o.sensor_bias_min_samples) {
    return "sensor_bias_memory must be >= sensor_bias_min_samples";
  }
  if (!positive(o.sensor_bias_pose_prior_scale) || o.sensor_bias_pose_prior_scale > 1e4) {
    return "sensor_bias_pose_prior_scale must be in (0, 1e4]";
  }
  if (!std::isfinite(o.sensor_bias_covariance_scale) || o.sensor_bias_covariance_scale < 1.0 ||
      o.sensor_bias_covariance_scale > 1e4) {
    return "sensor_bias_covariance_scale must be in [1, 1e4]";
  }
  if (!std::isfinite(o.sensor_bias_offset_sigma_fraction) ||
      o.sensor_bias_offset_sigma_fraction < 0.0 || o.sensor_bias_offset_sigma_fraction > 10.0) {
    return "sensor_bias_offset_sigma_fraction must be in [0, 10]";
  }
  if (!std::isfinite(o.max_sensor_bias_m) || o.max_sensor_bias_m < 0.0 ||
      o.max_sensor_bias_m > 10.0) {
    return "max_sensor_bias_m must be in [0, 10]";
  }
  if (!positive(o.position_noise_floor_m2)) return "position_noise_floor_m2 must be > 0";
  if (!positive(o.velocity_noise_floor_m2ps2)) return "velocity_noise_floor_m2ps2 must be > 0";
  if (!positive(o.max_coast_s)) return "max_coast_s must be > 0";
  if (!positive(o.coast_after_s)) return "coast_after_s must be > 0";
  if (!positive(o.source_timeout_s)) return "source_timeout_s must be > 0";
  if (!std::isfinite(o.max_out_of_order_s) || o.max_out_of_order_s < 0.0) {
    return "max_out_of_order_s must be >= 0";
  }
  if (o.confirm_updates < 1) return "confirm_updates must be >= 1";
  if (!positive(o.agree_mahalanobis2)) return "agree_mahalanobis2 must be > 0";
  if (o.agree_mahalanobis2 > o.gate_mahalanobis2) {
    return "agree_mahalanobis2 must not exceed gate_mahalanobis2";
  }
  if (o.drift_updates < 1) return "drift_updates must be >= 1";
  if (!positive(o.drift_reference_max_age_s)) return "drift_reference_max_age_s must be > 0";
  if (o.merge_updates < 1) return "merge_updates must be >= 1";
  if (!positive(o.merge_max_distance_m)) return "merge_max_distance_m must be > 0";
  if (!positive(o.merge_max_speed_difference_mps)) {
    return "merge_max_speed_difference_mps must be > 0";
  }
  if (!(o.merge_sourceless_shadow_m >= 0.0 && o.merge_sourceless_shadow_m <= 2.0)) {
    return "merge_sourceless_shadow_m must be in [0, 2]";
  }
  if (!std::isfinite(o.merge_centre_spread_m) || o.merge_centre_spread_m < 0.0 ||
      o.merge_centre_spread_m > o.merge_max_distance_m) {
    return "merge_centre_spread_m must be in [0, merge_max_distance_m]";
  }
  if (!positive(o.ended_report_s) || o.ended_report_s > 3600.0) {
    return "ended_report_s must be in (0, 3600]";
  }
  if (!positive(o.max_local_range_m)) return "max_local_range_m must be > 0";
  if (!positive(o.max_speed_mps)) return "max_speed_mps must be > 0";
  if (!positive(o.max_position_variance_m2)) return "max_position_variance_m2 must be > 0";
  if (!positive(o.max_velocity_variance_m2ps2)) return "max_velocity_variance_m2ps2 must be > 0";
  if (o.max_tracks_per_frame < 1 || o.max_tracks_per_frame > 100'000) {
    return "max_tracks_per_frame must be 1..100000";
  }
  if (o.max_fused_tracks < 1 || o.max_fused_tracks > 1'000'000) {
    return "max_fused_tracks must be 1..1000000";
  }
  return std::nullopt;
}

WorldTrack ToWorld(const SensorPlacement& placement, const std::string& sensor_id,
                   common::UtcNs stamp_ns, const daemon::TrackObservation& track) {
  const common::Pose2& pose = placement.world_from_sensor;
  const Eigen::Matrix2d r = pose.rotation();
  const Eigen::Vector2d p_s(track.x_m, track.y_m);
  const Eigen::Vector2d v_s(track.vx_mps, track.vy_mps);
  const Eigen::Vector2d p_w = r * p_s + pose.translation();
  const Eigen::Vector2d v_w = r * v_s;

  Eigen::Matrix4d j_s = Eigen::Matrix4d::Zero();
  j_s.topLeftCorner<2, 2>() = r;
  j_s.bottomRightCorner<2, 2>() = r;
  const Eigen::Matrix<double, 4, 3> j_pose = internal::PoseJacobian(pose, p_s, v_s);
  Eigen::Matrix4d cov = j_s * internal::UnpackCovariance(track.covariance) * j_s.transpose() +
                        j_pose * placement.covariance * j_pose.transpose();
  cov = 0.5 * (cov + cov.transpose()).eval();

  WorldTrack w;
  w.sensor_id = sensor_id;
  w.track_id = track.track_id;
  w.state = track.state;
  w.stamp_ns = stamp_ns;
  w.x_m = p_w.x();
  w.y_m = p_w.y();
  w.vx_mps = v_w.x();
  w.vy_mps = v_w.y();
  w.covariance = cov;
  w.position_covariance = cov.topLeftCorner<2, 2>();
  return w;
}

// ---------------------------------------------------------------------------------------------

Fuser::Fuser(const FusionOptions& options) : options_(options) {
  if (Validate(options_)) std::abort();
  engine_ = options_.method == FusionMethod::kLatestStates
                ? internal::MakeLatestStatesEngine(options_)
                : internal::MakeFusedFilterEngine(options_);
}
Fuser::~Fuser() = default;
Fuser::Fuser(Fuser&&) noexcept = default;
Fuser& Fuser::operator=(Fuser&&) noexcept = default;

void Fuser::SetPlacements(const std::vector<SensorPlacement>& placements) {
  internal::PlacementMap next;
  for (const SensorPlacement& p : placements) {
    if (!ValidPlacement(p)) {
      ++engine_->counters().placements_invalid;
      continue;
    }
    next[p.id] = p;
  }
  engine_->SetPlacements(next, placements_);
  placements_ = std::move(next);
}

bool Fuser::HasPlacement(const std::string& sensor_id) const {
  return placements_.find(sensor_id) != placements_.end();
}

void Fuser::AddFrame(const std::string& sensor_id, const daemon::TrackFrameData& frame) {
  ++engine_->counters().frames;
  const auto placement = placements_.find(sensor_id);
  if (placement == placements_.end()) {
    ++engine_->counters().frames_unplaced;
    return;
  }
  engine_->AddFrame(placement->second, sensor_id, frame);
}

void Fuser::SetTrackerModel(const std::string& sensor_id, double accel_psd_m2ps3) {
  engine_->SetTrackerModel(sensor_id, accel_psd_m2ps3);
}

void Fuser::Tick(common::UtcNs now_ns) { engine_->Tick(now_ns); }

std::vector<FusedTrack> Fuser::Snapshot(common::UtcNs now_ns, bool include_tentative) const {
  return engine_->Snapshot(now_ns, include_tentative);
}

FusionOutput Fuser::Output(common::UtcNs now_ns, bool include_tentative, EndsRead ends_read) const {
  FusionOutput out;
  out.stamp_ns = now_ns;
  out.tracks = engine_->Snapshot(now_ns, include_tentative);
  out.hidden = engine_->Hidden(out.tracks, now_ns);
  out.ended = engine_->OutputEnded(now_ns, ends_read == EndsRead::kMark);
  return out;
}

void Fuser::MarkEndsRead(common::UtcNs now_ns) const { engine_->MarkEndedRead(now_ns); }

std::uint64_t Fuser::next_id() const { return engine_->next_id(); }

void Fuser::ContinueIdsFrom(std::uint64_t next_id) { engine_->ContinueIdsFrom(next_id); }

void Fuser::SetEndedReportS(double ended_report_s) {
  FusionOptions changed = options_;
  changed.ended_report_s = ended_report_s;
  if (Validate(changed)) std::abort();
  options_ = changed;
  engine_->SetEndedReportS(ended_report_s);
}

std::vector<WorldTrack> Fuser::WorldTracks(common::UtcNs now_ns) const {
  return engine_->WorldTracks(now_ns);
}

const FusionCounters& Fuser::counters() const { return engine_->counters(); }

CovarianceScales Fuser::covariance_scales() const { return engine_->covariance_scales(); }

std::vector<SensorBias> Fuser::sensor_biases() const { return engine_->sensor_biases(); }

}  // namespace lrfnet::fusion
