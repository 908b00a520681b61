#pragma once
// Steps 1 and 3 of the calibration (Quenzel et al., section III-C): every sensor's tracks on one
// common UTC time grid, RTS-smoothed (rts.h).
//
// Input: the trackers' filtered EKF states (TrackObservation: x, y, vx, vy and their covariance),
// not measurements. Time of a state: a TrackFrameData's states are all valid at its scan_start_ns
// (the gateway-UTC time of beam 0 of the scan). The tracker predicts every track to the time of
// the measurement it updates it with (the segment's beam time when beam-time correction is on) and
// extrapolates the reported state back to scan_start_ns (firmware_tracker/tracking/multi_tracker.h,
// "Reports"; pipeline.h, "Time"); the uplink sends scan_start_ns unchanged. (That back
// extrapolation adds no process noise, so a reported covariance is a few ms of process noise
// smaller than the filter's prediction to scan start would be: negligible for the smoother.)
//
// Per sensor:
//  - A track is identified by (session_id, track_id). Observations in state kTentative are skipped
//    unless include_tentative; kCoasting states (predicted without a measurement) are valid
//    filtered states and kept, except a track's trailing run of them when trim_coasting_tail
//    (the tracker's extrapolation after the person was lost, up to its coast timeout, which the
//    smoother cannot correct since no later measurement exists).
//  - Observations with a non-finite or absurd value (|position| > kMaxAbsPosition_m, |velocity| >
//    kMaxAbsVelocity_mps, a covariance that is not symmetric PSD within float rounding, a variance
//    above kMaxVariance) or a time outside [0, kMaxTimeNs] are skipped and counted. Frames in any
//    order are accepted (each track's states are sorted by time); the same track at the same time
//    again (a duplicated scan or part) is counted and the first one kept. Parts of a frame are
//    taken as they are: a frame holding only some parts contributes the tracks it holds.
//  - A track is split where two consecutive states are more than max_gap_s apart; a piece shorter
//    than min_track_duration_s (last - first state time) or covering no grid time is dropped.
//  - Each piece is RTS-smoothed (smooth) as a whole with the CV model and accel_psd_m2ps3, or
//    not (its filtered states are then interpolated by prediction from the state before, which is
//    the filtered estimate at that time), and sampled at the grid times inside [first, last] state
//    time with the exact interpolation of rts.h (RtsInterpolate). A sample's covariance is the
//    2x2 position block with every eigenvalue raised to at least min_position_sigma_m^2.
//  - ClockSync kUnsynchronized: the sensor's clock_suspect is set; with exclude_unsynchronized its
//    tracks are not used at all (it stays in the output with no tracks).
//
// Grid: t0_ns = the earliest first-state time of all kept pieces, floored to a multiple of
// grid_step_s (in ns since the epoch); steps such that grid step (steps - 1) is at or after the
// latest last-state time. Grid step i is at t0_ns + i * round(grid_step_s * 1e9) ns. When the
// usable states span more than max_grid_span_s (bad clocks, hostile stamps), only the window of
// that length holding the most states is used; the rest is counted and AlignStats says so.
// No usable state at all: t0_ns = 0, steps = 0, every sensor with no tracks.
//
// Output: AlignedTracks::sensors in input order; each sensor's tracks ordered by
// (first_step, session_id, track_id). GridTrack::kind is the kind most of its states report;
// every sample carries the measurement model of its own time (TrackSample, model_window_s), and
// AlignedTracks::size_prior_sigma_m is model.prior_size_sigma_m.
//
// Smoothing a whole piece rather than each dynamic interval separately (the paper smooths "on each
// time period"): a track's estimate at any time then uses all of its measurements, and the
// intervals of a sensor pair (step 2) can be cut from the aligned tracks afterwards.
//
// Cost: linear in the observations (plus sorting when frames are out of order) and the output
// samples. Memory: at most max_gap_s / grid_step_s + 1 samples per usable state and never more
// than the grid (max_grid_span_s) per piece, so bad timestamps cannot make it grow.
// Pure: no clock, no I/O, no logging; thread-compatible (no shared state).

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "central_daemon/calibration/types.h"
#include "central_daemon/ingest/measurement_model.h"

namespace lrfnet::calib {

inline constexpr double kMaxAbsPosition_m = 1e4;
inline constexpr double kMaxAbsVelocity_mps = 1e3;
inline constexpr double kMaxVariance = 1e8;  // m^2 or m^2/s^2: far beyond any track
inline constexpr common::UtcNs kMaxTimeNs = common::UtcNs{1} << 62;  // year 2116

struct AlignOptions {
  double grid_step_s = 0.05;            // common grid spacing, [0.001, 60]
  double accel_psd_m2ps3 = 0.5;         // the trackers' CV model (CvEkfOptions default), > 0
  double max_gap_s = 0.5;               // a longer gap between states splits a track, > 0
  double min_track_duration_s = 1.0;    // shorter pieces are dropped, >= 0
  bool smooth = true;                   // RTS smoothing (step 3); false: filtered states
  bool include_tentative = false;       // use states in kTentative
  bool exclude_unsynchronized = false;  // drop sensors with kUnsynchronized (else: clock_suspect)
  double min_position_sigma_m = 0.005;  // floor on a sample's position sigma, >= 0
  bool trim_coasting_tail = true;       // drop a track's trailing kCoasting states
  double max_grid_span_s = 86400.0;     // longest grid, [grid_step_s, 1e7]; caps memory
  // The measurement model of every sample (TrackSample): evaluated at the smoothed position and
  // velocity, mixed over the kinds of the measured states within model_window_s of the sample
  // (about the time over which the smoother averages the measurements), [0, 10].
  daemon::MeasurementModelOptions model{};
  double model_window_s = 0.2;
  // Weight of a state of each kind in that mixture, relative to a centre of mass: the trackers'
  // filters weigh a fitted measurement (a few centimetres) more than a centre of mass (0.1 m,
  // firmware measurement.com_sigma_m), so the smoothed position leans towards the fits. >= 0.
  double model_fit_weight = 3.0;
  // Near the ends of a track the smoothed position is one-sided and the person often half hidden
  // (walking into or out of view): isotropic model sigma added, edge_sigma_per_m times the range,
  // decaying as exp(-t / edge_time_s) with the time t to the nearer end of the track. >= 0.
  double edge_sigma_per_m = 0.01;
  double edge_time_s = 0.5;
};

// nullopt when valid, else the reason, naming the field first.
std::optional<std::string> Validate(const AlignOptions& options);

// What happened to the input of one sensor (counts of observations = one track in one frame).
struct AlignSensorStats {
  std::size_t frames = 0;              // input frames
  std::size_t frames_used = 0;         // frames with at least one state in an output track
  std::size_t unordered_frames = 0;    // frames earlier than the frame before them
  std::size_t observations = 0;        // input observations
  std::size_t observations_used = 0;   // states in output tracks
  std::size_t tentative_skipped = 0;   // kTentative, include_tentative false
  std::size_t invalid = 0;             // bad values or time (see above)
  std::size_t duplicates = 0;          // same (session, track, time) again
  std::size_t outside_window = 0;      // outside the max_grid_span_s window
  std::size_t coasting_trimmed = 0;    // trailing kCoasting states dropped
  std::size_t gaps_split = 0;          // splits at gaps > max_gap_s
  std::size_t short_pieces = 0;        // pieces dropped (too short or between grid times)
  std::size_t short_piece_states = 0;  // their states
  std::size_t tracks = 0;              // output GridTracks
  std::size_t samples = 0;             // output TrackSamples
  bool excluded = false;               // kUnsynchronized and exclude_unsynchronized
};

struct AlignStats {
  std::vector<AlignSensorStats> sensors;  // input order
  bool grid_clipped = false;              // states spanned more than max_grid_span_s
  std::string error;                      // why the grid was clipped; "" when not
};

// Aligns (and smooths) every sensor of `input` (see above). Never fails on data; `stats` (when
// given) is overwritten. Precondition: Validate(options) is nullopt (checked; aborts otherwise).
AlignedTracks Align(const CalibrationInput& input, const AlignOptions& options = {},
                    AlignStats* stats = nullptr);

}  // namespace lrfnet::calib
