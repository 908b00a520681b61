#include "firmware_tracker/tracking/pipeline.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>

#include "common/geometry.h"

namespace lrfnet::tracking {

std::optional<std::string> Validate(const TrackerOptions& o) {
  if (auto e = Validate(o.background)) return "background." + *e;
  if (auto e = Validate(o.segmentation)) return "segmentation." + *e;
  if (auto e = Validate(o.measurement)) return "measurement." + *e;
  if (auto e = Validate(o.tracking)) return "tracking." + *e;
  return std::nullopt;
}

namespace {
const TrackerOptions& Checked(const TrackerOptions& o) {
  if (Validate(o)) std::abort();
  return o;
}
}  // namespace

TrackingPipeline::TrackingPipeline(const TrackerOptions& options)
    : options_(Checked(options)), background_(options.background), tracker_(options.tracking) {}

const ScanTracks& TrackingPipeline::Process(const ScanView& scan, std::uint32_t scan_counter) {
  ++counters_.scans;
  segments_.segments.clear();
  segments_.points_m.clear();
  segments_.dropped_segments = 0;
  measurements_.clear();
  offsets_s_.clear();

  const BackgroundResult bg = background_.Update(scan);
  last_scan_error_ = bg.scan_error;
  if (bg.scan_error != ScanError::kNone) {
    ++counters_.rejected_scans;
  } else if (!bg.learned) {
    ++counters_.learning_scans;
  } else {
    SegmentScan(scan, background_.foreground(), options_.segmentation, segments_);
    counters_.segments += segments_.segments.size();
    counters_.dropped_segments += segments_.dropped_segments;
    // The mirror turns 2 pi per scan period; beam 0 is measured at the scan start.
    const double beam_s = std::abs(scan.angle_step_rad) / (2.0 * common::kPi) * scan.scan_period_s;
    for (const Segment& s : segments_.segments) {
      const Measurement m = MeasureSegment(segments_.Points(s), options_.measurement);
      ++(m.kind == MeasurementKind::kEllipse ? counters_.ellipse_measurements
                                             : counters_.com_measurements);
      const double middle_beam = 0.5 * static_cast<double>(s.begin_beam + s.end_beam - 1);
      const double offset_s = options_.correct_beam_time
                                  ? std::clamp(middle_beam * beam_s, 0.0, scan.scan_period_s)
                                  : 0.0;
      // Both have kMaxSegments slots, as many as there are segments.
      (void)measurements_.push_back(m);
      (void)offsets_s_.push_back(offset_s);
    }
  }

  tracker_.Step(scan.stamp_ns, measurements_.span(), offsets_s_.span(), tracks_);
  tracks_.scan_counter = scan_counter;
  tracks_.scan_period_s = bg.scan_error == ScanError::kNone ? scan.scan_period_s : 0.0;
  return tracks_;
}

}  // namespace lrfnet::tracking
