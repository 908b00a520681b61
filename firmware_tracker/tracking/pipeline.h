#pragma once
// The per-scan tracking pipeline of one sensor (Quenzel et al., section III-B): background model ->
// segmentation of the foreground -> one measurement (CoM or fixed-axes ellipse) per segment ->
// multi-target tracker -> ScanTracks.
//
// Time: ScanView::stamp_ns is the time of beam 0 (scan start, gateway UTC). The mirror turns once
// per scan_period_s and the telegram lists beams in the order they were measured, so beam i is
// measured i * |angle_step_rad| / (2 pi) * scan_period_s after the scan start (an LMS1xx at 25 Hz
// and 0.5 deg: 55.6 us per beam, 30 ms across 270 deg; a person at 1.5 m/s moves 4.5 cm in that
// time). With correct_beam_time each measurement is stamped with the beam time of its segment's
// middle beam and the tracker predicts to that instant; without it, every measurement counts as
// taken at scan start. Either way all reported tracks are valid at the scan start.
//
// Rejected scans (CheckScan) and scans while the background is being learned produce no
// measurements; existing tracks coast through them.
//
// Fixed allocation: every buffer is a member sized at compile time (kMaxBeams, kMaxSegments,
// kMaxTracks); Process never allocates. The object is large (sizeof(TrackingPipeline) is
// 337,968 bytes, ~330 KiB, on x86-64 and aarch64; most of it the per-beam background model and the
// segment point pool): allocate it once at start-up (e.g. std::make_unique), not on the stack.
// Process itself needs about 30 KiB of stack (the ellipse fit's per-point scratch).
// Not thread-safe; one instance per sensor.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>

#include "common/fixed_capacity.h"
#include "firmware_tracker/tracking/background_model.h"
#include "firmware_tracker/tracking/measurement.h"
#include "firmware_tracker/tracking/multi_tracker.h"
#include "firmware_tracker/tracking/scan_view.h"
#include "firmware_tracker/tracking/segmentation.h"
#include "firmware_tracker/tracking/track_report.h"

namespace lrfnet::tracking {

struct TrackerOptions {
  BackgroundOptions background;
  SegmentationOptions segmentation;
  MeasurementOptions measurement;
  MultiTrackerOptions tracking;
  // Stamp each measurement with its middle beam's time instead of the scan start (see above).
  bool correct_beam_time = true;
};

// nullopt when valid, else the reason prefixed by the section, e.g.
// "tracking.confirm_hits must be in [1, confirm_window]".
std::optional<std::string> Validate(const TrackerOptions& options);

struct PipelineCounters {
  std::uint64_t scans = 0;           // Process calls
  std::uint64_t rejected_scans = 0;  // failed CheckScan (reason: last_scan_error())
  std::uint64_t learning_scans = 0;  // accepted while the background was not yet learned
  std::uint64_t segments = 0;
  std::uint64_t dropped_segments = 0;  // did not fit into kMaxSegments
  std::uint64_t ellipse_measurements = 0;
  std::uint64_t com_measurements = 0;
};

class TrackingPipeline {
 public:
  // Precondition: Validate(options) is nullopt (checked; aborts otherwise).
  explicit TrackingPipeline(const TrackerOptions& options);

  // Runs one scan; scans must come in time order. The result (tracks at scan.stamp_ns, with
  // scan_counter and scan.scan_period_s copied in; scan_period_s is 0 for a rejected scan) stays
  // valid until the next call. The scan's ranges are read during the call only.
  const ScanTracks& Process(const ScanView& scan, std::uint32_t scan_counter);

  const TrackerOptions& options() const { return options_; }
  const BackgroundModel& background() const { return background_; }
  const MultiTracker& tracker() const { return tracker_; }
  const PipelineCounters& counters() const { return counters_; }
  const ScanTracks& last_tracks() const { return tracks_; }
  ScanError last_scan_error() const { return last_scan_error_; }
  // Of the last scan: segments, their measurements (same order) and the measurements' times after
  // the scan start in seconds.
  const SegmentList& segments() const { return segments_; }
  std::span<const Measurement> measurements() const { return measurements_.span(); }
  std::span<const double> measurement_offsets_s() const { return offsets_s_.span(); }
  std::size_t last_segment_count() const { return segments_.segments.size(); }

 private:
  TrackerOptions options_;
  PipelineCounters counters_;
  ScanError last_scan_error_ = ScanError::kNone;
  BackgroundModel background_;
  SegmentList segments_;
  common::FixedVector<Measurement, kMaxSegments> measurements_;
  common::FixedVector<double, kMaxSegments> offsets_s_;
  MultiTracker tracker_;
  ScanTracks tracks_;
};

}  // namespace lrfnet::tracking
