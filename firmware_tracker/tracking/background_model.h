#pragma once
// Per-beam background model of a stationary scanner (Quenzel et al., section III-B: "we first
// subtract the background to distinguish range measurements belonging to static elements like walls
// from dynamic objects").
//
// Contract:
// - One model per sensor, fed every scan in time order; the scan stamp is the only clock (pure, no
// I/O).
// - A beam's background is a range in metres, or 0 = "free": the beam has no static return (it
// looks into
//   open space beyond max_range_m, or its echoes are too rare to count as a wall).
// - Start-up: for learn_duration_s the model only learns: per beam, the largest range that appeared
// in two
//   consecutive scans within the noise margin ("max of stable ranges", so people walking through
//   the field of view during start-up are ignored and single-scan outliers are not taken). No
//   foreground is reported while learning.
// - Afterwards a return is foreground when it is nearer than the background by more than
//   Margin(background) = base_margin_m + noise_margin_k * (range_noise_m + range_noise_per_m *
//   background); on a free beam every valid return is foreground.
// - Slow update with separate time constants:
//   * returns within the margin of the background track it with time constant
//   track_time_constant_s;
//   * a nearer return that stays at the same range (within its margin) for absorb_after_s becomes
//   the
//     background (a parked cart); anything shorter (a person standing still for a few seconds) does
//     not; while something even nearer occludes it, the nearer object's clock holds;
//   * a farther return or a no-echo on a beam with a background, persisting for recede_after_s,
//   replaces it
//     (a door opened, the cart left).
// - A change of beam count, first angle or step restarts learning (counted).
// - Fixed capacity: all storage is sized kMaxBeams at construction; Update never allocates.
// Not thread-safe; use one instance per thread.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>

#include "common/fixed_capacity.h"
#include "common/time.h"
#include "firmware_tracker/tracking/scan_view.h"

namespace lrfnet::tracking {

struct BackgroundOptions {
  double learn_duration_s = 5.0;
  double min_range_m = 0.05;  // nearer returns count as no echo (near-field / dazzle values)
  double max_range_m = 30.0;  // farther returns count as no echo
  double base_margin_m = 0.10;
  double range_noise_m = 0.015;      // 1-sigma range noise at 0 m
  double range_noise_per_m = 0.001;  // added 1-sigma noise per metre of range
  double noise_margin_k = 3.0;
  double absorb_after_s = 30.0;
  double recede_after_s = 2.0;
  double track_time_constant_s = 10.0;
  // During learning, a beam with no echo in more than this fraction of scans is free.
  double free_fraction = 0.5;
  // Time steps between scans are clamped to [0, max_scan_gap_s], so a pause in the stream neither
  // absorbs nor recedes anything by itself.
  double max_scan_gap_s = 1.0;
};

std::optional<std::string> Validate(const BackgroundOptions& options);

struct BackgroundResult {
  ScanError scan_error = ScanError::kNone;  // != kNone: the scan was ignored
  bool learned = false;                     // foreground() classifies this scan
  bool relearn_started = false;  // the scan geometry changed; learning restarted with this scan
  std::size_t foreground_beams = 0;
};

struct BackgroundCounters {
  std::uint64_t rejected_scans = 0;
  std::uint64_t geometry_changes = 0;
  std::uint64_t time_steps_backwards = 0;
  std::uint64_t absorbed_beams = 0;    // a nearer static object became background
  std::uint64_t objects_absorbed = 0;  // Absorb calls that took at least one beam
  std::uint64_t receded_beams = 0;     // the background moved farther away or became free
};

namespace internal {
// Per-beam state. Outside the class: a nested type with member initializers is not yet default-
// constructible where the class body instantiates FixedVector<Beam>.
enum class BackgroundCandidate : std::uint8_t { kNone, kNearer, kFarther };
// Learning (until the model is learned; untouched afterwards). The change candidates after
// learning are BackgroundModel's arrays.
struct BackgroundBeam {
  float learn_max_m = 0.0f;
  float prev_m = 0.0f;
  std::uint32_t echo_scans = 0;
  std::uint32_t no_echo_scans = 0;
};
}  // namespace internal

class BackgroundModel {
 public:
  // Precondition: Validate(options) is nullopt (checked; aborts otherwise).
  explicit BackgroundModel(const BackgroundOptions& options);

  // Classifies the scan against the model as it was before this scan, then updates the model.
  BackgroundResult Update(const ScanView& scan);

  bool learned() const { return learned_; }
  // Per beam of the last accepted scan: 1 = foreground. Empty before the first accepted scan.
  std::span<const std::uint8_t> foreground() const { return foreground_.span(); }
  // Per beam, metres, 0 = free. Meaningful once learned(); same beam geometry as the last scan.
  std::span<const float> background_range_m() const { return background_m_.span(); }
  double Margin(double range_m) const;
  // Beams of `reference_m` (a background published earlier, same geometry) that the present
  // background no longer matches: free in one and not the other, or apart by more than
  // Margin(nearer of the two). reference_m.size() must equal background_range_m().size().
  std::size_t CountMovedBeams(std::span<const float> reference_m) const;
  const BackgroundCounters& counters() const { return counters_; }
  // Forgets the model and starts learning again with the next scan; counters are kept.
  void Reset();
  // Makes the foreground returns of beams [begin_beam, end_beam) of `scan` (the scan last passed
  // to Update) background at once: a static object the tracker recognised (a door that swung
  // open, a chair left behind, clutter that never moved). Counted in absorbed_beams and
  // objects_absorbed. Ignored before learning or for another beam geometry.
  void Absorb(const ScanView& scan, std::size_t begin_beam, std::size_t end_beam);

 private:
  using Beam = internal::BackgroundBeam;
  using Candidate = internal::BackgroundCandidate;

  float Sanitize(float range_m) const;
  void StartLearning(const ScanView& scan);
  void Learn(std::size_t i, float r);
  void FinishLearning();
  // Classifies beam i's sanitised return r (true: foreground) and updates the beam; dt is the time
  // since the last scan, alpha the background's tracking gain for that time.
  bool UpdateBeam(std::size_t i, float r, float dt, double alpha);

  BackgroundOptions options_;
  bool learned_ = false;
  bool has_scan_ = false;
  double learn_elapsed_s_ = 0.0;
  std::uint32_t learn_scans_ = 0;
  common::UtcNs last_stamp_ns_ = 0;
  double first_angle_rad_ = 0.0;
  double angle_step_rad_ = 0.0;
  common::FixedVector<Beam, kMaxBeams> beams_;
  // Change candidate after learning, one array per field: the only per-beam state besides the
  // background range that a scan reads or writes. A beam at its background writes only its kind
  // (kNone: its range and age are read only after a restart, which sets both), so the per-beam
  // pass streams 1 byte a beam of it instead of the 28 of a structure shared with the learning
  // state (at 1141 beams 1 instead of 32 KiB through the first-level data cache, which the tracks'
  // data then shares); a person's beams read and write the other two.
  common::FixedVector<Candidate, kMaxBeams> candidate_;
  common::FixedVector<float, kMaxBeams> candidate_m_;  // 0 = no echo
  common::FixedVector<float, kMaxBeams> candidate_age_s_;
  common::FixedVector<float, kMaxBeams> background_m_;
  common::FixedVector<std::uint8_t, kMaxBeams> foreground_;
  BackgroundCounters counters_;
};

}  // namespace lrfnet::tracking
