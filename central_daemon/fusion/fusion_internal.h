#pragma once
// Internals of the Fuser shared by its two methods (fusion.h, FusionMethod): the engine interface,
// the admission of frames, and small numerical functions. Not part of the library's interface.

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <deque>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "central_daemon/fusion/fusion.h"
#include "common/cv_model.h"
#include "common/eigen_instances.h"

namespace lrfnet::fusion::internal {

using PlacementMap = std::map<std::string, SensorPlacement, std::less<>>;

// a - b in seconds; saturates instead of overflowing for hostile stamps.
double Seconds(common::UtcNs a, common::UtcNs b);

// One fusion method. The Fuser validates placements and counts frames; the engine does the rest.
class Engine {
 public:
  explicit Engine(const FusionOptions& options) : options_(options) {}
  virtual ~Engine() = default;
  Engine(const Engine&) = delete;
  Engine& operator=(const Engine&) = delete;

  // `next`: the new (valid) placements; `previous`: the ones they replace. Sensors missing from
  // `next` lose their local tracks; sensors whose placement changed are transformed again.
  virtual void SetPlacements(const PlacementMap& next, const PlacementMap& previous) = 0;
  virtual void AddFrame(const SensorPlacement& placement, const std::string& sensor_id,
                        const daemon::TrackFrameData& frame) = 0;
  virtual void SetTrackerModel(const std::string& /*sensor_id*/, double /*accel_psd*/) {}
  virtual void Tick(common::UtcNs now_ns) = 0;
  virtual std::vector<FusedTrack> Snapshot(common::UtcNs now_ns, bool include_tentative) const = 0;
  virtual std::vector<WorldTrack> WorldTracks(common::UtcNs now_ns) const = 0;
  virtual CovarianceScales covariance_scales() const { return {}; }
  virtual std::vector<SensorBias> sensor_biases() const { return {}; }
  // The confirmed fused tracks kept but not in `reported` (Snapshot's tracks at now_ns, ordered
  // by id) and not older than max_coast_s at now_ns (those end at the next Tick).
  virtual std::vector<HiddenFusedTrack> Hidden(const std::vector<FusedTrack>& reported,
                                               common::UtcNs now_ns) const = 0;

  FusionCounters& counters() { return counters_; }
  std::uint64_t next_id() const { return next_id_; }
  void ContinueIdsFrom(std::uint64_t next_id) { next_id_ = std::max(next_id_, next_id); }
  void SetEndedReportS(double s) { options_.ended_report_s = s; }
  const FusionCounters& counters() const { return counters_; }
  const FusionOptions& options() const { return options_; }
  // The ends kept (FusionOutput::ended), in the order recorded, for an output at now_ns. When
  // mark_read: notes that they were read then (their retention counts from their first read, and
  // only reads advance its clock); else they are only looked at.
  std::vector<EndedFusedTrack> OutputEnded(common::UtcNs now_ns, bool mark_read) const {
    if (mark_read) MarkEndedRead(now_ns);
    std::vector<EndedFusedTrack> out;
    out.reserve(ended_.size());
    for (const KeptEnd& k : ended_) out.push_back(k.end);
    return out;
  }
  // Notes that the ends kept were read at now_ns (as OutputEnded with mark_read).
  void MarkEndedRead(common::UtcNs now_ns) const {
    latest_output_ns_ = now_ns;
    for (KeptEnd& k : ended_) {
      if (k.first_output_ns == 0) k.first_output_ns = now_ns;
    }
  }

 protected:
  // Notes the end of a confirmed fused id for FusionOutput::ended (a tentative id was never
  // reported: nobody follows it, and it must not push real ends out of the bounded list).
  void RecordEnded(std::uint64_t id, common::UtcNs ended_ns, FusedEndReason reason,
                   std::uint64_t merged_into = 0) {
    ended_.push_back(KeptEnd{EndedFusedTrack{id, ended_ns, reason, merged_into}, 0});
    while (ended_.size() > options_.max_fused_tracks) {
      ended_.pop_front();
      ++counters_.ended_evicted;
    }
  }
  // Forgets the ends that were in read outputs spanning more than ended_report_s (call from
  // Tick): the time is the reads', so a gap in the data between an end and the next read does
  // not take the end away before a consumer read it. Ends first read later are behind the others.
  void ForgetEnded() {
    while (!ended_.empty() && ended_.front().first_output_ns != 0 &&
           Seconds(latest_output_ns_, ended_.front().first_output_ns) > options_.ended_report_s) {
      ended_.pop_front();
    }
  }

  FusionOptions options_;
  FusionCounters counters_;
  std::uint64_t next_id_ = 1;  // the id of the next fused track

 private:
  struct KeptEnd {
    EndedFusedTrack end;
    common::UtcNs first_output_ns = 0;  // the first read output it was in, 0 before
  };
  // Output (const) notes which ends were read: the fuser is used from one thread.
  mutable std::deque<KeptEnd> ended_;
  mutable common::UtcNs latest_output_ns_ = 0;
};

// The confirmed fused tracks of `tracks` (a map of id to a track with updates, confirmed,
// stamp_ns, x and last_sensor) that are not in `reported` (ordered by id): what a snapshot left
// out of them, without the ones older than max_coast_s at now_ns. Those are due to end at the
// next Tick; should no Tick come (fusion disabled), a consumer bounds them by its own hold
// instead of holding them for good.
template <typename Tracks>
std::vector<HiddenFusedTrack> HiddenTracks(const Tracks& tracks,
                                           const std::vector<FusedTrack>& reported,
                                           common::UtcNs now_ns, double max_coast_s) {
  std::vector<HiddenFusedTrack> out;
  for (const auto& [id, f] : tracks) {
    if (f.updates == 0 || !f.confirmed) continue;
    if (Seconds(now_ns, f.stamp_ns) > max_coast_s) continue;
    const auto r = std::lower_bound(reported.begin(), reported.end(), id,
                                    [](const FusedTrack& t, std::uint64_t v) { return t.id < v; });
    if (r != reported.end() && r->id == id) continue;
    out.push_back(HiddenFusedTrack{id, f.stamp_ns, f.x(0), f.x(1), f.last_sensor});
  }
  return out;
}

// The latest-states combination (FusionMethod::kLatestStates, fusion_latest.cc).
std::unique_ptr<Engine> MakeLatestStatesEngine(const FusionOptions& options);
// The fused filter (FusionMethod::kFusedFilter, fusion_filter.cc).
std::unique_ptr<Engine> MakeFusedFilterEngine(const FusionOptions& options);

// --- frames ---------------------------------------------------------------------------------

// Per sensor: what the admission of its frames needs to remember.
struct FrameClock {
  bool has_frame = false;
  std::uint64_t session_id = 0;
  std::uint32_t scan_counter = 0;
  std::uint64_t parts_seen = 0;  // bit p: part p of the latest scan was added
  common::UtcNs latest_ns = 0;
};

enum class FrameAdmission : std::uint8_t {
  kNewScan,      // newer than the sensor's latest scan
  kNewSession,   // the same, from a new tracker session (the caller drops the old local tracks)
  kAnotherPart,  // a part of the latest scan not seen before
  kInvalid,      // scan time <= 0
  kStale,        // not newer than the latest scan (and not another part of it)
  kOutOfOrder,   // older than the newest frame of any sensor by more than max_out_of_order_s
};

// Decides about a frame of one sensor (see "Time" in fusion.h) and, when it is admitted, updates
// the sensor's clock and the newest frame time of all sensors. Counts nothing.
FrameAdmission AdmitFrame(const daemon::TrackFrameData& frame, double max_out_of_order_s,
                          FrameClock& clock, bool& have_newest, common::UtcNs& newest_ns);

// Counts a frame that was not admitted; returns whether it was admitted.
bool CountAdmission(FrameAdmission admission, FusionCounters& counters);

// --- numbers --------------------------------------------------------------------------------

template <typename Derived>
bool AllFinite(const Eigen::MatrixBase<Derived>& m) {
  return m.array().isFinite().all();
}

// The wire's upper triangle (TrackObservation::covariance) as a symmetric matrix.
Eigen::Matrix4d UnpackCovariance(const std::array<float, 10>& c);

// Symmetric and positive semi-definite within rounding.
template <int N>
bool IsCovariance(const Eigen::Matrix<double, N, N>& m) {
  if (!AllFinite(m)) return false;
  const double scale = std::max(1.0, m.cwiseAbs().maxCoeff());
  if (((m - m.transpose()).cwiseAbs().array() > 1e-6 * scale).any()) return false;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, N, N>> eig(m, Eigen::EigenvaluesOnly);
  return eig.info() == Eigen::Success && eig.eigenvalues().minCoeff() >= -1e-9 * scale;
}

// Constant-velocity prediction over a signed dt (common/cv_model.h): x <- F(dt) x,
// P <- F(dt) P F(dt)^T + Q(|dt|, q). Backwards the process noise is still added: going back in
// time is no more certain than going forward.
void Predict(double dt_s, double accel_psd, common::CvState& x, common::CvCovariance& p);

// What a snapshot reports of a fused track whose estimate (x, p) is from stamp_ns: predicted to
// now_ns, its state by its age (coasting after coast_after_s), without sources (the caller's);
// nothing once it is older or newer than max_coast_s.
std::optional<FusedTrack> PredictedFusedTrack(std::uint64_t id, bool confirmed,
                                              common::UtcNs first_ns, common::UtcNs stamp_ns,
                                              std::uint64_t updates, common::CvState x,
                                              common::CvCovariance p, const FusionOptions& options,
                                              common::UtcNs now_ns);

// Every sensor's local tracks heard within source_timeout_s of now_ns, in the world frame with
// the fused track they are bound to. Sensors: a map of sensor id to a state with `tracks`, a map
// of local tracks with `world`, `fused_id` and `stamp()`.
template <typename Sensors>
std::vector<WorldTrack> RecentWorldTracks(const Sensors& sensors, double source_timeout_s,
                                          common::UtcNs now_ns) {
  std::vector<WorldTrack> out;
  for (const auto& [sensor_id, ss] : sensors) {
    for (const auto& [tid, lt] : ss.tracks) {
      if (std::abs(Seconds(now_ns, lt.stamp())) > source_timeout_s) continue;
      WorldTrack w = lt.world;
      w.fused_id = lt.fused_id;
      out.push_back(std::move(w));
    }
  }
  return out;
}

// Squared Mahalanobis distance of two 2-vectors with the sum of their covariances; +inf when that
// is not positive definite. log_det (optional): ln det of the sum.
double Mahalanobis2(const Eigen::Vector2d& a, const Eigen::Matrix2d& pa, const Eigen::Vector2d& b,
                    const Eigen::Matrix2d& pb, double* log_det = nullptr);

// Placements with the same pose and covariance (nothing to transform again).
bool SamePlacement(const SensorPlacement& a, const SensorPlacement& b);

// d(p_w, v_w)/d(x, y, yaw) of p_w = R(yaw) p_s + t, v_w = R(yaw) v_s: [I, R' p_s; 0, R' v_s].
Eigen::Matrix<double, 4, 3> PoseJacobian(const common::Pose2& world_from_sensor,
                                         const Eigen::Vector2d& p_s, const Eigen::Vector2d& v_s);

// The per-sample correction of a local track's centre (DESIGN.md, "Measurement model"): where the
// shared model of what bias is left in a tracker's object centre is applied, for both methods and
// for what the live view draws. The trackers report the body's centre; what is left is the
// sensor's constant offset towards itself (radial_offset_m, learnt by the fused filter, see
// "Sensor bias" in fusion.h; 0: the identity) and noise (FusionOptions::centre_sigma_*). The
// centre is moved away from the sensor by radial_offset_m.
daemon::TrackObservation CentreCorrected(const daemon::TrackObservation& observation,
                                         double radial_offset_m = 0.0);

// A local track that is finite, within the plausibility bounds of the options, and has a valid
// covariance.
bool PlausibleObservation(const FusionOptions& o, const daemon::TrackObservation& t);

}  // namespace lrfnet::fusion::internal
