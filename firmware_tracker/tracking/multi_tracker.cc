#include "firmware_tracker/tracking/multi_tracker.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>

#include "common/cv_model.h"
#include "firmware_tracker/tracking/assignment.h"

namespace lrfnet::tracking {
namespace {

bool Positive(double v) { return std::isfinite(v) && v > 0.0; }

// scan_start_ns + offset without int64 overflow on hostile stamps (offset_s is in [0, gap limit]).
common::UtcNs AtOffset(common::UtcNs scan_start_ns, double offset_s) {
  const common::DurationNs offset_ns = common::SecondsToNs(offset_s);
  return scan_start_ns > std::numeric_limits<common::UtcNs>::max() - offset_ns
             ? std::numeric_limits<common::UtcNs>::max()
             : scan_start_ns + offset_ns;
}

double LargestEigenvalue(const Eigen::Matrix2d& m) {
  const double half_trace = 0.5 * (m(0, 0) + m(1, 1));
  const double half_diff = 0.5 * (m(0, 0) - m(1, 1));
  const double off = 0.5 * (m(0, 1) + m(1, 0));
  return half_trace + std::sqrt(half_diff * half_diff + off * off);
}

// Files item in a fixed list of records (lost tracks, where moved ones were lost): the records
// stamp(record) older than max_age_s at now_ns are forgotten first; when the list is still full,
// the oldest record gives its place.
template <typename T, std::size_t N, typename Stamp>
void KeepRecent(common::FixedVector<T, N>& list, const T& item, common::UtcNs now_ns,
                double max_age_s, Stamp stamp) {
  std::size_t kept = 0;
  for (std::size_t i = 0; i < list.size(); ++i) {
    if (common::NsToSeconds(now_ns - stamp(list[i])) > max_age_s) continue;
    if (kept != i) list[kept] = list[i];
    ++kept;
  }
  while (list.size() > kept) list.pop_back();
  if (list.full()) {
    std::size_t oldest = 0;
    for (std::size_t i = 1; i < list.size(); ++i) {
      if (stamp(list[i]) < stamp(list[oldest])) oldest = i;
    }
    list[oldest] = item;
    return;
  }
  (void)list.push_back(item);
}

}  // namespace

namespace internal {

// F x and F p F^T by F's structure (common/cv_model.h): the same result as the full products up to
// floating-point contraction (their other terms are multiplications by 1 and additions of 0; a
// target that fuses multiply-adds may round the two forms differently).
void Extrapolate(double dt_s, Eigen::Vector4d& x, Eigen::Matrix4d& p) {
  x(0) += dt_s * x(2);
  x(1) += dt_s * x(3);
  common::CvTransitionSymmetric(dt_s, p);  // p is a filter's covariance: exactly symmetric
}

}  // namespace internal

std::optional<std::string> Validate(const MultiTrackerOptions& o) {
  if (auto e = Validate(o.ekf)) return "ekf." + *e;
  if (o.association != Association::kGlobalNearestNeighbour &&
      o.association != Association::kClosest) {
    return "association must be global_nearest_neighbour or closest";
  }
  if (!Positive(o.gate_mahalanobis_sq)) return "gate_mahalanobis_sq must be > 0";
  if (!Positive(o.max_gate_distance_m)) return "max_gate_distance_m must be > 0";
  if (!(std::isfinite(o.recover_gate_mahalanobis_sq) && o.recover_gate_mahalanobis_sq >= 0.0)) {
    return "recover_gate_mahalanobis_sq must be >= 0";
  }
  if (!(std::isfinite(o.inflate_nis_above) &&
        (o.inflate_nis_above == 0.0 || o.inflate_nis_above >= 2.0))) {
    return "inflate_nis_above must be 0 (off) or >= 2";
  }
  // A memory below 2 would weigh each update by more than the whole mean (1 / updates > 1).
  if (!(std::isfinite(o.measured_noise_memory_scans) &&
        (o.measured_noise_memory_scans == 0.0 || o.measured_noise_memory_scans >= 2.0))) {
    return "measured_noise_memory_scans must be 0 (off) or >= 2";
  }
  if (!(std::isfinite(o.extra_measurement_sigma_m) && o.extra_measurement_sigma_m >= 0.0)) {
    return "extra_measurement_sigma_m must be >= 0";
  }
  if (o.confirm_window < 1 || o.confirm_window > 32) return "confirm_window must be in [1, 32]";
  if (o.confirm_hits < 1 || o.confirm_hits > o.confirm_window) {
    return "confirm_hits must be in [1, confirm_window]";
  }
  if (!(std::isfinite(o.confirm_min_s) && o.confirm_min_s >= 0.0 && o.confirm_min_s <= 10.0)) {
    return "confirm_min_s must be in [0, 10]";
  }
  if (!Positive(o.coast_timeout_s)) return "coast_timeout_s must be > 0";
  if (!(std::isfinite(o.resume_window_s) && o.resume_window_s >= 0.0)) {
    return "resume_window_s must be >= 0";
  }
  if (!(std::isfinite(o.adopt_successor_m) && o.adopt_successor_m >= 0.0)) {
    return "adopt_successor_m must be >= 0";
  }
  if (o.adopt_after_hits < 1 || o.adopt_after_hits > 32) {
    return "adopt_after_hits must be in [1, 32]";
  }
  if (!Positive(o.max_position_sigma_m)) return "max_position_sigma_m must be > 0";
  if (o.max_tracks < 1 || o.max_tracks > kMaxTracks) {
    return "max_tracks must be in [1, " + std::to_string(kMaxTracks) + "]";
  }
  if (!Positive(o.max_time_gap_s)) return "max_time_gap_s must be > 0";
  if (!(std::isfinite(o.report_coasting_s) && o.report_coasting_s >= 0.0)) {
    return "report_coasting_s must be >= 0";
  }
  if (!(std::isfinite(o.report_coasting_per_measured_s) &&
        o.report_coasting_per_measured_s >= 0.0)) {
    return "report_coasting_per_measured_s must be >= 0";
  }
  if (!(std::isfinite(o.seen_gap_s) && o.seen_gap_s >= 0.0)) return "seen_gap_s must be >= 0";
  if (!Positive(o.max_speed_mps)) return "max_speed_mps must be > 0";
  if (!Positive(o.still_radius_m)) return "still_radius_m must be > 0";
  if (!(std::isfinite(o.moving_speed_mps) && o.moving_speed_mps >= 0.0)) {
    return "moving_speed_mps must be >= 0";
  }
  if (!Positive(o.never_moved_to_background_s)) return "never_moved_to_background_s must be > 0";
  if (!Positive(o.static_object_to_background_s)) {
    return "static_object_to_background_s must be > 0";
  }
  if (!(std::isfinite(o.inherit_moved_s) && o.inherit_moved_s >= 0.0)) {
    return "inherit_moved_s must be >= 0";
  }
  return std::nullopt;
}

MultiTracker::MultiTracker(const MultiTrackerOptions& options) : options_(options) {
  if (Validate(options_)) std::abort();
}

void MultiTracker::Clear() {
  tracks_.clear();
  lost_.clear();
  lost_moved_.clear();
}

std::size_t MultiTracker::confirmed_count() const {
  return static_cast<std::size_t>(
      std::count_if(tracks_.begin(), tracks_.end(), [](const Track& t) { return t.confirmed; }));
}

std::uint32_t MultiTracker::NewId() {
  const std::uint32_t id = next_id_++;
  if (next_id_ == 0) next_id_ = 1;
  return id;
}

void MultiTracker::Step(common::UtcNs scan_start_ns, std::span<const Measurement> measurements,
                        ScanTracks& out) {
  Step(scan_start_ns, measurements, {}, out);
}

void MultiTracker::Step(common::UtcNs scan_start_ns, std::span<const Measurement> measurements,
                        std::span<const double> time_offsets_s, ScanTracks& out) {
  Step(scan_start_ns, measurements, time_offsets_s, nullptr, out);
}

std::size_t MultiTracker::Predict(common::UtcNs t_ns, std::span<TrackPrediction> out) const {
  std::size_t n = 0;
  for (const bool confirmed : {true, false}) {
    for (const Track& t : tracks_) {
      if (t.confirmed != confirmed || n == out.size()) continue;
      const CvEkf::Prediction f = t.filter.Predicted(common::NsToSeconds(t_ns - t.filter_ns));
      TrackPrediction& p = out[n++];
      p.id = t.id;
      p.confirmed = t.confirmed;
      p.position_m = f.position_m();
      p.covariance_m2 = f.covariance().topLeftCorner<2, 2>();
      p.model = t.shape.model;
      p.size_m = t.shape.size_m;
      p.size_cov_m2 = t.shape.size_cov_m2;
      p.yaw_rad = t.shape.yaw_rad;
    }
  }
  return n;
}

void MultiTracker::Step(common::UtcNs scan_start_ns, std::span<const Measurement> measurements,
                        std::span<const double> time_offsets_s, MeasurementRefiner* refiner,
                        ScanTracks& out) {
  ++counters_.scans;
  absorbed_.clear();
  HandleTime(scan_start_ns);
  for (Track& t : tracks_) {
    ++t.age_scans;
    t.hits <<= 1;
    t.updated = false;
    t.points = 0;
  }
  AcceptMeasurements(measurements, time_offsets_s);
  Gate(scan_start_ns);
  // Confirmed tracks first: a young track with its vague velocity must not outbid an established
  // one for the same person.
  Associate(/*confirmed=*/true);
  Associate(/*confirmed=*/false);
  Recover();
  UpdateAssigned(scan_start_ns, measurements, refiner);
  ManageLifecycle(scan_start_ns);
  AdoptSuccessors(scan_start_ns);
  StartTracks(scan_start_ns, measurements, refiner);
  Report(scan_start_ns, out);
}

void MultiTracker::HandleTime(common::UtcNs scan_start_ns) {
  if (has_time_) {
    // In double: arbitrary (hostile) stamps must not overflow the int64 difference.
    const double dt_s =
        (static_cast<double>(scan_start_ns) - static_cast<double>(last_scan_ns_)) * 1e-9;
    if (dt_s < 0.0) ++counters_.time_steps_backwards;
    if (std::abs(dt_s) > options_.max_time_gap_s) {
      ++counters_.time_resets;
      counters_.deleted_time_reset += tracks_.size();
      tracks_.clear();
      lost_.clear();
      lost_moved_.clear();
    }
  }
  has_time_ = true;
  last_scan_ns_ = scan_start_ns;
}

void MultiTracker::AcceptMeasurements(std::span<const Measurement> measurements,
                                      std::span<const double> time_offsets_s) {
  candidates_.clear();
  for (std::size_t j = 0; j < measurements.size(); ++j) {
    const Measurement& m = measurements[j];
    if (candidates_.full()) {
      counters_.measurements_over_capacity += measurements.size() - j;
      break;
    }
    Eigen::Matrix2d r = 0.5 * (m.covariance_m2 + m.covariance_m2.transpose());
    // The measurement's own covariance must be positive definite before any inflation.
    const bool positive_definite = r(0, 0) > 0.0 && r(0, 0) * r(1, 1) - r(0, 1) * r(1, 0) > 0.0;
    if (!m.position_m.allFinite() || !r.allFinite() || !positive_definite) {
      ++counters_.rejected_measurements;
      continue;
    }
    r += options_.extra_measurement_sigma_m * options_.extra_measurement_sigma_m *
         Eigen::Matrix2d::Identity();
    Candidate* c = candidates_.emplace_slot();
    c->z_m = m.position_m;
    c->r_m2 = r;
    c->source = j;
    c->evidence_only = m.evidence_only;
    double offset_s = j < time_offsets_s.size() ? time_offsets_s[j] : 0.0;
    if (!(std::isfinite(offset_s) && offset_s >= 0.0)) offset_s = 0.0;
    c->offset_s = std::min(offset_s, options_.max_time_gap_s);
  }
  counters_.measurements += candidates_.size();
}

double MultiTracker::MahalanobisSq(const Eigen::Vector2d& predicted_m,
                                   const Eigen::Matrix2d& predicted_cov_m2, const Candidate& c,
                                   double* det_out) const {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  const Eigen::Vector2d y = c.z_m - predicted_m;
  if (!(y.norm() <= options_.max_gate_distance_m)) return kInf;
  const Eigen::Matrix2d s = predicted_cov_m2 + c.r_m2;
  const double det = s(0, 0) * s(1, 1) - s(0, 1) * s(1, 0);
  if (!(det > 0.0 && s(0, 0) > 0.0) || !std::isfinite(det)) return kInf;
  // 2x2 inverse in closed form: y^T S^-1 y.
  const double m2 =
      (s(1, 1) * y.x() * y.x() - (s(0, 1) + s(1, 0)) * y.x() * y.y() + s(0, 0) * y.y() * y.y()) /
      det;
  if (det_out != nullptr) *det_out = det;
  return std::isfinite(m2) ? m2 : kInf;
}

bool MultiTracker::InsideGate(const Eigen::Vector2d& predicted_m,
                              const Eigen::Matrix2d& predicted_cov_m2, const Candidate& c,
                              double* d2, double* log_det) const {
  double det = 1.0;
  const double m2 = MahalanobisSq(predicted_m, predicted_cov_m2, c, &det);
  if (!(m2 <= options_.gate_mahalanobis_sq)) return false;
  if (d2 != nullptr) *d2 = m2;
  if (log_det != nullptr) *log_det = std::log(det);
  return true;
}

void MultiTracker::Gate(common::UtcNs scan_start_ns) {
  const double q = options_.ekf.accel_psd_m2ps3;
  const double max_gate_sq_m2 = options_.max_gate_distance_m * options_.max_gate_distance_m;
  constexpr double kInf = std::numeric_limits<double>::infinity();
  // Most pairs of a crowded scene lie beyond max_gate_distance_m (InsideGate's first test: out
  // whatever the covariance). That test runs on blocks of 8 measurements at once (Eigen's packets,
  // on contiguous copies of their positions and beam times), the rows are filled as "out" in bulk,
  // and only a block with a pair within is looked at pair by pair. The padding lies at infinity.
  constexpr std::size_t kBlock = 8;
  static_assert(kMaxSegments % kBlock == 0, "whole blocks");
  using Block = Eigen::Array<double, kBlock, 1>;
  const std::size_t n = candidates_.size();
  const std::size_t padded = (n + kBlock - 1) / kBlock * kBlock;
  alignas(16) std::array<double, kMaxSegments> z_x_m;
  alignas(16) std::array<double, kMaxSegments> z_y_m;
  alignas(16) std::array<double, kMaxSegments> offset_s;
  for (std::size_t j = 0; j < n; ++j) {
    z_x_m[j] = candidates_[j].z_m.x();
    z_y_m[j] = candidates_[j].z_m.y();
    offset_s[j] = candidates_[j].offset_s;
  }
  std::fill_n(gated_any_.begin(), n, false);
  for (std::size_t j = n; j < padded; ++j) {
    z_x_m[j] = kInf;
    z_y_m[j] = kInf;
    offset_s[j] = 0.0;
  }
  for (std::size_t i = 0; i < tracks_.size(); ++i) {
    const CvEkf::Prediction predicted =
        tracks_[i].filter.Predicted(common::NsToSeconds(scan_start_ns - tracks_[i].filter_ns));
    track_to_candidate_[i] = -1;
    const Eigen::Vector4d& x = predicted.state();
    const Eigen::Matrix4d& p = predicted.covariance();
    std::array<double, kMaxSegments>& distance_row = distance_[i];
    std::array<bool, kMaxSegments>& gated_row = gated_[i];
    std::array<double, kMaxSegments>& cost_row = cost_[i];
    std::array<double, kMaxSegments>& d2_row = d2_[i];
    alignas(16) std::array<double, kBlock> distance_sq_m2;
    for (std::size_t b = 0; b < padded; b += kBlock) {
      // distance_ is read only where gated_ is set (kClosest): its pairs out are not written (at 50
      // people the three rows filled per track are more than the data cache holds).
      Eigen::Map<Block>(cost_row.data() + b).setConstant(kUnassignableCost);
      Eigen::Map<Block>(d2_row.data() + b).setConstant(kInf);
      std::fill_n(gated_row.begin() + static_cast<std::ptrdiff_t>(b), kBlock, false);
      // The same arithmetic as below: (z - (x + d v)).squaredNorm(), 8 pairs at once.
      const Block off = Eigen::Map<const Block, Eigen::Aligned16>(offset_s.data() + b);
      const Block dx_m =
          Eigen::Map<const Block, Eigen::Aligned16>(z_x_m.data() + b) - (x(0) + off * x(2));
      const Block dy_m =
          Eigen::Map<const Block, Eigen::Aligned16>(z_y_m.data() + b) - (x(1) + off * x(3));
      Eigen::Map<Block, Eigen::Aligned16> dsq(distance_sq_m2.data());
      dsq = dx_m * dx_m + dy_m * dy_m;
      // A NaN comes only from a state gone bad and is then in every pair of the row, all out (as
      // pair by pair); the minimum of the others is exact.
      if (!(dsq.minCoeff() <= max_gate_sq_m2)) continue;
      for (std::size_t j = b; j < b + kBlock; ++j) {
        if (!(distance_sq_m2[j - b] <= max_gate_sq_m2)) continue;
        const Candidate& c = candidates_[j];
        // The track moved on to the measurement's beam time: position block of F P F^T + Q over
        // offset_s, in closed form (exact for the constant-velocity model).
        const double d = c.offset_s;
        const Eigen::Vector2d at = x.head<2>() + d * x.tail<2>();
        distance_row[j] = std::sqrt(distance_sq_m2[j - b]);
        const Eigen::Matrix2d cov = p.topLeftCorner<2, 2>() +
                                    d * (p.topRightCorner<2, 2>() + p.bottomLeftCorner<2, 2>()) +
                                    d * d * p.bottomRightCorner<2, 2>() +
                                    (q * d * d * d / 3.0) * Eigen::Matrix2d::Identity();
        double det = 1.0;
        const double d2 = MahalanobisSq(at, cov, c, &det);
        const bool inside = d2 <= options_.gate_mahalanobis_sq;
        d2_row[j] = d2;
        gated_row[j] = inside;
        gated_any_[j] = gated_any_[j] || inside;
        cost_row[j] = inside ? d2 + std::log(det) : kUnassignableCost;
      }
    }
  }
  for (std::size_t j = 0; j < candidates_.size(); ++j) candidate_to_track_[j] = -1;
}

void MultiTracker::Associate(bool confirmed) {
  // Rows: this stage's tracks; columns: measurements nobody took yet.
  std::array<std::size_t, kMaxTracks> rows{};
  std::array<std::size_t, kMaxSegments> cols{};
  std::size_t n = 0, m = 0;
  for (std::size_t i = 0; i < tracks_.size(); ++i) {
    if (tracks_[i].confirmed == confirmed) rows[n++] = i;
  }
  for (std::size_t j = 0; j < candidates_.size(); ++j) {
    // Evidence-only measurements are for confirmed tracks (step 3c).
    if (candidate_to_track_[j] < 0 && (confirmed || !candidates_[j].evidence_only)) cols[m++] = j;
  }
  if (n == 0 || m == 0) return;
  auto assign = [this](std::size_t i, std::size_t j) {
    if (!gated_[i][j]) return;  // the solver had to use a non-candidate pair: stays unassigned
    track_to_candidate_[i] = static_cast<int>(j);
    candidate_to_track_[j] = static_cast<int>(i);
  };

  if (options_.association == Association::kClosest) {
    for (;;) {
      double best = std::numeric_limits<double>::infinity();
      std::size_t best_i = 0, best_j = 0;
      for (std::size_t a = 0; a < n; ++a) {
        const std::size_t i = rows[a];
        if (track_to_candidate_[i] >= 0) continue;
        for (std::size_t b = 0; b < m; ++b) {
          const std::size_t j = cols[b];
          if (!gated_[i][j] || candidate_to_track_[j] >= 0) continue;
          if (distance_[i][j] < best) {
            best = distance_[i][j];
            best_i = i;
            best_j = j;
          }
        }
      }
      if (!std::isfinite(best)) return;
      assign(best_i, best_j);
    }
  }

  static_assert(kMaxTracks == kMaxAssignmentDim && kMaxSegments == kMaxAssignmentDim,
                "cost_ and gated_ are the assignment's matrices");
  // The Hungarian method per group of tracks and measurements linked by gated pairs (a crowd splits
  // into small groups); the same optimum as on the whole matrix (assignment.h).
  std::array<int, kMaxTracks> row_to_col{};
  std::array<int, kMaxSegments> col_to_row{};
  SolveGatedAssignment(cost_, gated_, std::span<const std::size_t>(rows.data(), n),
                       std::span<const std::size_t>(cols.data(), m), row_to_col.data(),
                       col_to_row.data());
  for (std::size_t a = 0; a < n; ++a) {
    if (row_to_col[a] >= 0) assign(rows[a], cols[static_cast<std::size_t>(row_to_col[a])]);
  }
}

void MultiTracker::Recover() {
  if (!(options_.recover_gate_mahalanobis_sq > options_.gate_mahalanobis_sq)) return;
  for (;;) {
    double best = options_.recover_gate_mahalanobis_sq;
    std::size_t best_i = 0, best_j = 0;
    bool found = false;
    for (std::size_t i = 0; i < tracks_.size(); ++i) {
      // Only a track measured in the previous scan: it lags behind its object. A coasting one
      // would take whatever came near its growing covariance.
      if (!tracks_[i].confirmed || track_to_candidate_[i] >= 0 || (tracks_[i].hits & 2u) == 0) {
        continue;
      }
      for (std::size_t j = 0; j < candidates_.size(); ++j) {
        if (candidate_to_track_[j] >= 0 || !(d2_[i][j] <= best)) continue;
        best = d2_[i][j];
        best_i = i;
        best_j = j;
        found = true;
      }
    }
    if (!found) return;
    track_to_candidate_[best_i] = static_cast<int>(best_j);
    candidate_to_track_[best_j] = static_cast<int>(best_i);
    ++counters_.recovered;
  }
}

void MultiTracker::LimitSpeed(Track& t) {
  const Eigen::Vector2d v = t.filter.velocity_mps();
  const double speed = v.norm();
  if (!(speed > options_.max_speed_mps)) return;
  ++counters_.speed_clamps;
  Eigen::Vector4d x = t.filter.state();
  x.tail<2>() *= options_.max_speed_mps / speed;
  t.filter.SetState(x);
}

void MultiTracker::UpdateAssigned(common::UtcNs scan_start_ns,
                                  std::span<const Measurement> measurements,
                                  MeasurementRefiner* refiner) {
  for (std::size_t i = 0; i < tracks_.size(); ++i) {
    Track& t = tracks_[i];
    const int j = track_to_candidate_[i];
    if (j < 0) {
      // Coasting: the filter moves to the scan start (never backwards).
      if (scan_start_ns > t.filter_ns) {
        t.filter.Predict(common::NsToSeconds(scan_start_ns - t.filter_ns));
        t.filter_ns = scan_start_ns;
      }
      continue;
    }
    const Candidate& c = candidates_[static_cast<std::size_t>(j)];
    const common::UtcNs at_ns = AtOffset(scan_start_ns, c.offset_s);
    const double predicted_s = common::NsToSeconds(at_ns - t.filter_ns);
    t.filter.Predict(predicted_s);
    t.filter_ns = std::max(t.filter_ns, at_ns);
    const double pair_d2 = d2_[i][static_cast<std::size_t>(j)];
    if (options_.inflate_nis_above > 0.0 && pair_d2 > options_.inflate_nis_above) {
      // The track ran off its object by more than its covariance allows (a start, stop or turn
      // the constant-velocity model did not predict): scale P so this innovation becomes as likely
      // as an average one (d2 -> ~2, its expectation for 2 dof), and let the measurement pull.
      t.filter.InflateCovariance(pair_d2 / 2.0);
    }
    Measurement m;
    Eigen::Vector2d z;
    Eigen::Matrix2d r;
    if (!MeasureForTrack(t, c, at_ns, measurements, refiner, 4.0 * options_.gate_mahalanobis_sq, &m,
                         &z, &r)) {
      ++counters_.refine_failures;
      continue;
    }
    // Less what the measurement says its error does not have (two legs seen still,
    // ShapeOptions::still_legs_cov): noise the gains allow for, and the process noise predicted
    // since the last update where the body did not move.
    const Eigen::Matrix2d gain_r = MeasuredNoise(t, z, r) - m.gain_relief_m2;
    if (m.gain_restart && KeepGainCovariance()) t.filter.StartGainCovariance();
    if (m.gain_still || m.gain_walking) t.filter.RelieveGainProcessNoise(predicted_s);
    if (!t.filter.Update(z, r, &gain_r)) {
      ++counters_.failed_updates;
      continue;
    }
    LimitSpeed(t);
    ++counters_.associations;
    t.hits |= 1u;
    NoteUpdate(t, m, c, z, at_ns, scan_start_ns);
  }
}

Eigen::Matrix2d MultiTracker::MeasuredNoise(Track& t, const Eigen::Vector2d& z_m,
                                            const Eigen::Matrix2d& r_m2) const {
  const double memory = options_.measured_noise_memory_scans;
  const double range_m = z_m.norm();
  if (!GainCovariance() || !(range_m > 0.0)) return r_m2;
  // Across the line of sight (the sensor at the origin): along it the measurement's error is
  // mostly the body's extent towards the sensor, which successive scans share and which the
  // innovations therefore do not show.
  const Eigen::Vector2d u = z_m / range_m;
  const Eigen::Vector2d w(-u.y(), u.x());
  const double nu_across = w.dot(z_m - t.filter.position_m());
  const double excess_m2 =
      nu_across * nu_across - w.dot(t.filter.gain_covariance().topLeftCorner<2, 2>() * w);
  t.innovation_updates = std::min(memory, t.innovation_updates + 1.0);
  t.innovation_excess_m2 += (excess_m2 - t.innovation_excess_m2) / t.innovation_updates;
  if (t.innovation_updates < 0.5 * memory) return r_m2;
  // Another object beside the body, an outline that departs from the model by more than the
  // filter's R allows for per scan, or a view resting on the priors: errors successive scans
  // share, which the innovations do not show; the filter's R stays.
  if (t.shape.reported_neighbour_m2 > 0.0 || t.shape.reported_departure_m2 > w.dot(r_m2 * w) ||
      !t.shape.reported_partial_cov_m2.isZero() || !t.shape.reported_excess_cov_m2.isZero()) {
    return r_m2;
  }
  const double along_m2 = u.dot(r_m2 * u);
  const double across_m2 = std::max(0.0, t.innovation_excess_m2);
  return along_m2 * u * u.transpose() + across_m2 * w * w.transpose();
}

bool MultiTracker::MeasureForTrack(Track& t, const Candidate& c, common::UtcNs at_ns,
                                   std::span<const Measurement> measurements,
                                   MeasurementRefiner* refiner, double max_d2, Measurement* m,
                                   Eigen::Vector2d* z, Eigen::Matrix2d* r) const {
  *m = measurements[c.source];
  *z = c.z_m;
  *r = c.r_m2;
  if (refiner == nullptr) return true;
  const Eigen::Vector4d& x = t.filter.state();
  const Eigen::Matrix4d& p = t.filter.covariance();
  // The shape is refined in place (one copy of it per update instead of two); a refinement that
  // is not taken leaves the track's shape as it was.
  const TrackShape before = t.shape;
  const auto refused = [&] {
    t.shape = before;
    return false;
  };
  if (!refiner->Refine(c.source, at_ns, &x, &p, t.shape, *m)) return refused();
  // The refiner's covariance is its own, model errors included: no extra sigma.
  *z = m->position_m;
  *r = 0.5 * (m->covariance_m2 + m->covariance_m2.transpose());
  if (!z->allFinite() || !r->allFinite()) return refused();
  if (std::isfinite(max_d2)) {
    Candidate refined = c;
    refined.z_m = *z;
    refined.r_m2 = *r;
    if (!(MahalanobisSq(x.head<2>(), p.topLeftCorner<2, 2>(), refined, nullptr) <= max_d2)) {
      return refused();
    }
  }
  return true;
}

void MultiTracker::NoteUpdate(Track& t, const Measurement& m, const Candidate& c,
                              const Eigen::Vector2d& z, common::UtcNs at_ns,
                              common::UtcNs scan_start_ns) {
  t.updated = true;
  const double gap_s = common::NsToSeconds(at_ns - t.last_update_ns);
  if (gap_s > 0.0 && gap_s <= options_.seen_gap_s) t.measured_s += gap_s;
  t.last_update_ns = at_ns;
  t.kind = m.kind;
  t.ellipse_yaw_rad = m.kind == MeasurementKind::kCenterOfMass ? 0.0 : m.orientation_rad;
  t.points = static_cast<std::uint32_t>(std::min<std::size_t>(m.point_count, UINT32_MAX));
  t.source = c.source;
  t.z_m = z;
  t.z_offset_s = common::NsToSeconds(at_ns - scan_start_ns);
}

void MultiTracker::ManageLifecycle(common::UtcNs scan_start_ns) {
  const std::uint32_t window_mask =
      options_.confirm_window >= 32 ? ~0u : ((1u << options_.confirm_window) - 1u);
  std::size_t kept = 0;
  for (std::size_t i = 0; i < tracks_.size(); ++i) {
    Track& t = tracks_[i];
    bool remove = false;
    if (!t.confirmed) {
      // All scans of a young track lie in its first window: bits 0..age_scans; later, the latest
      // confirm_window scans (confirm_min_s).
      const auto hits = static_cast<std::uint32_t>(std::popcount(t.hits & window_mask));
      const bool long_enough =
          options_.confirm_min_s <= 0.0 ||
          common::NsToSeconds(t.last_update_ns - t.first_update_ns) >= options_.confirm_min_s;
      if (hits >= options_.confirm_hits && long_enough) {
        t.confirmed = true;
        ++counters_.confirmed;
        if (KeepGainCovariance()) t.filter.StartGainCovariance();
      } else {
        const std::uint32_t scans_left = t.age_scans + 1 >= options_.confirm_window
                                             ? 0
                                             : options_.confirm_window - t.age_scans - 1;
        if (hits + scans_left < options_.confirm_hits) {
          remove = true;
          ++counters_.deleted_tentative;
        }
      }
    } else if (!t.updated &&
               common::NsToSeconds(scan_start_ns - t.last_update_ns) > options_.coast_timeout_s) {
      remove = true;
      ++counters_.deleted_coast_timeout;
      Lose(t, scan_start_ns);
      NoteLostMoved(t, scan_start_ns);
    }
    if (!remove) {
      const Eigen::Matrix2d p = t.filter.covariance().topLeftCorner<2, 2>();
      if (!(LargestEigenvalue(p) <=
            options_.max_position_sigma_m * options_.max_position_sigma_m)) {
        remove = true;
        ++counters_.deleted_covariance;
        if (t.confirmed && !t.updated) Lose(t, scan_start_ns);
        if (t.confirmed) NoteLostMoved(t, scan_start_ns);
      }
    }
    if (!remove && t.updated && options_.static_objects) {
      // Static objects: measured positions only (a coasting track says nothing about motion).
      const Eigen::Vector2d position = t.filter.position_m();
      bool moving = false;
      if (!t.moved && t.confirmed && options_.moving_speed_mps > 0.0) {
        const Eigen::Vector2d v = t.filter.velocity_mps();
        const double speed = v.norm();
        if (speed > options_.moving_speed_mps) {
          const Eigen::Vector2d u = v / speed;
          const double var = u.dot(t.filter.covariance().bottomRightCorner<2, 2>() * u);
          moving = speed * speed > 9.0 * var;
        }
      }
      if (!t.moved && t.confirmed && options_.inherit_moved_s > 0.0 && t.shape.person_like &&
          Inherit(t, scan_start_ns)) {
        moving = true;
        ++counters_.inherited_moved;
      }
      if (moving || (position - t.anchor_m).norm() > options_.still_radius_m) {
        t.anchor_m = position;
        t.anchor_ns = scan_start_ns;
        t.moved = true;
      }
      const double still_s = common::NsToSeconds(scan_start_ns - t.anchor_ns);
      const bool clutter = !t.moved && still_s >= options_.never_moved_to_background_s;
      const bool left_behind =
          t.moved && !t.shape.person_like && still_s >= options_.static_object_to_background_s;
      if (clutter || left_behind) {
        remove = true;
        ++counters_.deleted_static;
        (void)absorbed_.push_back(t.source);  // at most one per track
      }
    }
    if (remove) continue;
    if (kept != i) tracks_[kept] = t;
    ++kept;
  }
  while (tracks_.size() > kept) tracks_.pop_back();
}

void MultiTracker::AdoptSuccessors(common::UtcNs scan_start_ns) {
  if (!(options_.adopt_successor_m > 0.0)) return;
  const double reach_sq = options_.adopt_successor_m * options_.adopt_successor_m;
  for (;;) {
    // The nearest pair of a coasting confirmed track (its filter at the scan start) and a younger
    // track measured in this scan.
    double best = reach_sq;
    std::size_t best_old = tracks_.size(), best_young = tracks_.size();
    for (std::size_t i = 0; i < tracks_.size(); ++i) {
      const Track& old = tracks_[i];
      if (!old.confirmed || old.updated) continue;
      for (std::size_t k = 0; k < tracks_.size(); ++k) {
        const Track& young = tracks_[k];
        if (k == i || !young.updated || young.first_update_ns <= old.last_update_ns ||
            static_cast<std::uint32_t>(std::popcount(young.hits)) < options_.adopt_after_hits) {
          continue;
        }
        // Of the same kind (a trolley's track does not take over its pusher's).
        if (old.shape.shape != ObjectShape::kUnspecified &&
            young.shape.shape != ObjectShape::kUnspecified &&
            old.shape.shape != young.shape.shape) {
          continue;
        }
        // The coasting filter lives at the scan start (UpdateAssigned); the younger one's at its
        // measurement's beam time: moved on by that offset.
        const Eigen::Vector2d predicted =
            old.filter.position_m() + young.z_offset_s * old.filter.velocity_mps();
        const double d_sq = (young.filter.position_m() - predicted).squaredNorm();
        if (d_sq < best) {
          best = d_sq;
          best_old = i;
          best_young = k;
        }
      }
    }
    if (best_old == tracks_.size()) return;
    Track& old = tracks_[best_old];
    const Track& young = tracks_[best_young];
    old.filter = young.filter;
    if (KeepGainCovariance() && old.confirmed) old.filter.StartGainCovariance();
    old.filter_ns = young.filter_ns;
    old.last_update_ns = young.last_update_ns;
    old.measured_s += young.measured_s;
    old.updated = true;
    old.hits |= 1u;
    old.kind = young.kind;
    old.ellipse_yaw_rad = young.ellipse_yaw_rad;
    old.points = young.points;
    old.shape = young.shape;
    old.source = young.source;
    old.z_m = young.z_m;
    old.z_offset_s = young.z_offset_s;
    // Where it stands now is where the static-object clocks start again.
    old.anchor_m = young.filter.position_m();
    old.anchor_ns = scan_start_ns;
    ++counters_.adopted;
    // Removed in place: the others keep their order (reports by id).
    for (std::size_t k = best_young; k + 1 < tracks_.size(); ++k) tracks_[k] = tracks_[k + 1];
    tracks_.pop_back();
  }
}

void MultiTracker::NoteLostMoved(const Track& t, common::UtcNs scan_start_ns) {
  if (!(options_.inherit_moved_s > 0.0) || !options_.static_objects || !t.moved) return;
  internal::LostMoved lost;
  lost.position_m = t.z_m;  // where it was last measured: not where its velocity took it since
  lost.cov_m2 = t.filter.covariance().topLeftCorner<2, 2>();
  lost.lost_ns = scan_start_ns;
  lost.last_update_ns = t.last_update_ns;
  // Kept while an heir may still come: born within inherit_moved_s, confirmed and not yet absorbed
  // as never moved.
  KeepRecent(lost_moved_, lost, scan_start_ns,
             options_.inherit_moved_s + options_.never_moved_to_background_s,
             [](const internal::LostMoved& l) { return l.lost_ns; });
}

bool MultiTracker::Inherit(const Track& t, common::UtcNs scan_start_ns) {
  const double keep_s = options_.inherit_moved_s + options_.never_moved_to_background_s;
  const Eigen::Vector2d position = t.filter.position_m();
  const Eigen::Matrix2d cov = t.filter.covariance().topLeftCorner<2, 2>();
  const double max_sq = options_.max_gate_distance_m * options_.max_gate_distance_m;
  for (std::size_t i = 0; i < lost_moved_.size(); ++i) {
    const internal::LostMoved& lost = lost_moved_[i];
    if (common::NsToSeconds(scan_start_ns - lost.lost_ns) > keep_s ||
        t.first_update_ns <= lost.last_update_ns ||
        common::NsToSeconds(t.first_update_ns - lost.last_update_ns) > options_.inherit_moved_s) {
      continue;
    }
    const Eigen::Vector2d d = position - lost.position_m;
    if (!(d.squaredNorm() <= max_sq)) continue;
    const Eigen::Matrix2d s = lost.cov_m2 + cov;
    const double det = s(0, 0) * s(1, 1) - s(0, 1) * s(1, 0);
    if (!(det > 0.0)) continue;
    const double m2 =
        (d.x() * d.x() * s(1, 1) - 2.0 * d.x() * d.y() * s(0, 1) + d.y() * d.y() * s(0, 0)) / det;
    if (!(m2 <= options_.gate_mahalanobis_sq)) continue;
    lost_moved_.swap_remove(i);
    return true;
  }
  return false;
}

void MultiTracker::Lose(const Track& t, common::UtcNs scan_start_ns) {
  if (!(options_.resume_window_s > 0.0)) return;
  KeepRecent(lost_, t, scan_start_ns, options_.coast_timeout_s + options_.resume_window_s,
             [](const Track& l) { return l.last_update_ns; });
}

bool MultiTracker::Resume(common::UtcNs scan_start_ns, const Candidate& c,
                          std::span<const Measurement> measurements, MeasurementRefiner* refiner) {
  const common::UtcNs at_ns = AtOffset(scan_start_ns, c.offset_s);
  double best_d2 = std::numeric_limits<double>::infinity();
  std::size_t best = lost_.size();
  for (std::size_t i = 0; i < lost_.size(); ++i) {
    const Track& t = lost_[i];
    if (common::NsToSeconds(at_ns - t.last_update_ns) >
            options_.coast_timeout_s + options_.resume_window_s ||
        at_ns < t.filter_ns) {
      continue;
    }
    const CvEkf::Prediction predicted =
        t.filter.Predicted(common::NsToSeconds(at_ns - t.filter_ns));
    double d2 = 0.0;
    if (InsideGate(predicted.position_m(), predicted.covariance().topLeftCorner<2, 2>(), c, &d2,
                   nullptr) &&
        d2 < best_d2) {
      best_d2 = d2;
      best = i;
    }
  }
  if (best == lost_.size()) return false;
  Track t = lost_[best];
  // The walk before the gap says little of the one after it (a person who waited behind a pillar,
  // turned or slowed): the filter starts again from the last measurement with the velocity prior
  // of a new track, so this measurement's displacement over the gap gives the velocity.
  t.filter = CvEkf(options_.ekf);
  t.filter.Init(t.z_m, c.r_m2);
  t.filter.Predict(common::NsToSeconds(at_ns - t.last_update_ns));
  t.filter_ns = at_ns;
  Measurement m;
  Eigen::Vector2d z;
  Eigen::Matrix2d r;
  // Not this track's when the refiner has no answer: a new one may start from it.
  if (!MeasureForTrack(t, c, at_ns, measurements, refiner, std::numeric_limits<double>::infinity(),
                       &m, &z, &r)) {
    return false;
  }
  if (!t.filter.Update(z, r)) return false;
  LimitSpeed(t);
  // Confirmed again as a new track is (M of N from here), so that clutter near the prediction
  // does not bring a lost track back; then reported at once (it has moved).
  t.hits = 1u;
  t.age_scans = 0;
  t.confirmed = options_.confirm_hits <= 1 && options_.confirm_min_s <= 0.0;
  if (t.confirmed && KeepGainCovariance()) t.filter.StartGainCovariance();
  NoteUpdate(t, m, c, z, at_ns, scan_start_ns);
  t.first_update_ns = at_ns;
  // Still for as long as it was lost: the static-object clocks restart here.
  t.anchor_m = t.filter.position_m();
  t.anchor_ns = scan_start_ns;
  lost_[best] = lost_[lost_.size() - 1];
  lost_.pop_back();
  (void)tracks_.push_back(t);
  ++counters_.resumed;
  ++counters_.associations;
  return true;
}

void MultiTracker::StartTracks(common::UtcNs scan_start_ns,
                               std::span<const Measurement> measurements,
                               MeasurementRefiner* refiner) {
  // gated_any_ still refers to the tracks as they were before the lifecycle step (Gate's), which is
  // what "inside an existing track's gate" means for this scan.
  const std::size_t first_born = tracks_.size();
  for (std::size_t j = 0; j < candidates_.size(); ++j) {
    if (candidate_to_track_[j] >= 0) continue;
    const Candidate& c = candidates_[j];
    if (c.evidence_only) continue;  // step 3c: never a new or resumed track
    bool suppressed = gated_any_[j];
    for (std::size_t b = first_born; b < tracks_.size() && !suppressed; ++b) {
      const Track& born = tracks_[b];
      suppressed = InsideGate(born.filter.position_m(),
                              born.filter.covariance().topLeftCorner<2, 2>(), c, nullptr, nullptr);
    }
    if (suppressed) {
      ++counters_.births_suppressed;
      continue;
    }
    if (tracks_.size() >= options_.max_tracks) {
      ++counters_.dropped_capacity;
      continue;
    }
    if (!lost_.empty() && Resume(scan_start_ns, c, measurements, refiner)) continue;
    const common::UtcNs at_ns = AtOffset(scan_start_ns, c.offset_s);
    Measurement m = measurements[c.source];
    Eigen::Vector2d z = c.z_m;
    Eigen::Matrix2d r = c.r_m2;
    TrackShape shape;
    if (refiner != nullptr) {
      if (!refiner->Refine(c.source, at_ns, nullptr, nullptr, shape, m) ||
          !m.position_m.allFinite() || !m.covariance_m2.allFinite()) {
        ++counters_.refine_failures;
        continue;
      }
      z = m.position_m;
      r = 0.5 * (m.covariance_m2 + m.covariance_m2.transpose());
    }
    Track* t = tracks_.emplace_slot();
    t->filter = CvEkf(options_.ekf);
    t->filter.Init(z, r);
    t->filter_ns = at_ns;
    t->last_update_ns = at_ns;
    t->first_update_ns = at_ns;
    t->measured_s = 0.0;
    t->id = NewId();
    t->updated = true;
    t->hits = 1u;
    t->age_scans = 0;
    t->kind = m.kind;
    t->ellipse_yaw_rad = m.kind == MeasurementKind::kCenterOfMass ? 0.0 : m.orientation_rad;
    t->points = static_cast<std::uint32_t>(std::min<std::size_t>(m.point_count, UINT32_MAX));
    t->shape = shape;
    t->anchor_m = z;
    t->anchor_ns = scan_start_ns;
    t->moved = false;
    t->source = c.source;
    t->z_m = z;
    t->z_offset_s = common::NsToSeconds(at_ns - scan_start_ns);
    t->confirmed = options_.confirm_hits <= 1 && options_.confirm_min_s <= 0.0;
    if (t->confirmed && KeepGainCovariance()) t->filter.StartGainCovariance();
    ++counters_.created;
    if (t->confirmed) ++counters_.confirmed;
  }
}

void MultiTracker::Report(common::UtcNs scan_start_ns, ScanTracks& out) {
  out.scan_start_ns = scan_start_ns;
  out.tracks.clear();
  for (const Track& t : tracks_) {
    // A confirmed track that never moved is not reported as one (step 5).
    const bool reportable = t.confirmed && (t.moved || !options_.static_objects);
    if (reportable && !t.updated) {
      const double coasting_s = common::NsToSeconds(scan_start_ns - t.last_update_ns);
      double limit_s = options_.report_coasting_s;
      if (options_.report_coasting_per_measured_s > 0.0) {
        limit_s = std::min(limit_s, options_.report_coasting_per_measured_s * t.measured_s);
      }
      if (coasting_s > limit_s) {
        ++counters_.coasting_unreported;
        continue;
      }
    }
    if (!reportable && !options_.report_tentative) continue;
    Eigen::Vector4d x = t.filter.state();
    // The gain covariance is kept only with report_gain_covariance (GainCovariance()); else it is
    // the filter's own.
    Eigen::Matrix4d p = t.updated ? t.filter.gain_covariance() : t.filter.covariance();
    const double back_s = common::NsToSeconds(scan_start_ns - t.filter_ns);
    if (back_s < 0.0) internal::Extrapolate(back_s, x, p);
    TrackReport* r = out.tracks.emplace_slot();
    if (r == nullptr) break;  // max_tracks <= kMaxTracks: cannot happen
    r->track_id = t.id;
    r->state = !reportable ? TrackState::kTentative
                           : (t.updated ? TrackState::kConfirmed : TrackState::kCoasting);
    r->kind = t.kind;
    r->x_m = x(0);
    r->y_m = x(1);
    r->vx_mps = x(2);
    r->vy_mps = x(3);
    // The filter averages its measurements as independent; what they share is added back. The
    // outline's departure only where this scan measured it: a coasting report stands for where
    // the body may be now (the filter's prediction, which grows with the time coasted), and the
    // coasting checks (seen through, unseen) take their reach from it; an outline that was not
    // the model's in the last scans is no reason to report the track where the beams pass.
    p.topLeftCorner<2, 2>() += t.shape.centre_bias_cov_m2;
    if (t.updated) {
      p.topLeftCorner<2, 2>() += t.shape.reported_departure_m2 * Eigen::Matrix2d::Identity();
      p.topLeftCorner<2, 2>() += t.shape.reported_partial_cov_m2;
      p.topLeftCorner<2, 2>() += t.shape.reported_neighbour_m2 * Eigen::Matrix2d::Identity();
      p.topLeftCorner<2, 2>() += t.shape.reported_excess_cov_m2;
      p.topLeftCorner<2, 2>() += t.shape.reported_box_view_cov_m2;
      p.topLeftCorner<2, 2>() -= t.shape.reported_bias_relief_m2;
      if (t.shape.walking_relieved) {
        p.topLeftCorner<2, 2>().diagonal().array() += double{t.shape.reported_gait_m2};
      }
    }
    r->covariance = p;
    r->age_scans = t.age_scans;
    r->points = t.points;
    if (t.updated) {
      r->measured_x_m = t.z_m.x();
      r->measured_y_m = t.z_m.y();
      r->measured_offset_s = t.z_offset_s;
    } else {
      r->coasted_s = common::NsToSeconds(scan_start_ns - t.last_update_ns);
    }
    r->ellipse_yaw_rad = t.ellipse_yaw_rad;
    r->shape = t.shape.shape;
    if (t.shape.shape != ObjectShape::kUnspecified) {
      r->size_major_m = t.shape.size_m.x();
      r->size_minor_m = t.shape.size_m.y();
      r->size_sigma_m = std::sqrt(std::max(0.0, LargestEigenvalue(t.shape.size_cov_m2)));
    }
  }
}

}  // namespace lrfnet::tracking
