// Zero heap allocations per scan after start-up (DESIGN.md quality bar): replaces the global
// allocation functions with counting ones and runs thousands of synthetic scans through background
// model, segmentation, measurement and per-segment filters, and through the whole
// TrackingPipeline with a crowd of 20 people.

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <memory>
#include <new>
#include <vector>

#include "firmware_tracker/tracking/background_model.h"
#include "firmware_tracker/tracking/cv_ekf.h"
#include "firmware_tracker/tracking/measurement.h"
#include "firmware_tracker/tracking/pipeline.h"
#include "firmware_tracker/tracking/segmentation.h"
#include "firmware_tracker/tracking/tracking_test_util.h"
#include "tests/support/alloc_counter.h"

namespace lrfnet::tracking {
namespace {

struct Stages {
  BackgroundModel background{BackgroundOptions{}};
  SegmentList segments;
  common::FixedVector<CvEkf, kMaxSegments> filters;
};

TEST(TrackingAllocTest, CounterSeesAllocations) {
  ::lrfnet::testing::StartCountingAllocations();
  auto* p = new std::vector<int>(100);
  const std::size_t allocations = ::lrfnet::testing::StopCountingAllocations();
  delete p;
  EXPECT_GE(allocations, 2u);
}

TEST(TrackingAllocTest, NoHeapAllocationPerScanAfterTheFirst) {
  testing::SyntheticScanner scanner;
  const auto room = testing::Room();
  auto pipeline = std::make_unique<Stages>();  // large: fixed buffers for kMaxBeams beams
  const SegmentationOptions seg_options;
  const MeasurementOptions meas_options;
  std::vector<testing::Body> bodies(3);
  constexpr int kScans = 3000;  // 2 minutes at 25 Hz, past learning and cart absorption
  std::size_t ellipses = 0, updates = 0, measured_scans = 0;
  std::size_t allocations = 0;

  for (int k = 0; k < kScans; ++k) {
    const double t = k / 25.0;
    // Two people walking back and forth, a cart parked at t = 20 s.
    bodies[0] = {{3.0 + 2.0 * std::sin(0.3 * t), -2.0 + 0.5 * t - 5.0 * std::floor(0.1 * t)},
                 0.25,
                 0.15,
                 0.2};
    bodies[1] = {{5.0 - 0.8 * t + 6.0 * std::floor(t / 7.5), 2.0}, 0.25, 0.15, 1.4};
    bodies[2] = {{t > 20.0 ? 4.0 : 30.0, -3.5}, 0.4, 0.3, 0.0};
    const ScanView scan = scanner.Render(k, room, bodies);  // outside the counted region

    if (k >= 1) ::lrfnet::testing::StartCountingAllocations();
    Stages& p = *pipeline;
    const BackgroundResult bg = p.background.Update(scan);
    if (bg.learned) {
      SegmentScan(scan, p.background.foreground(), seg_options, p.segments);
      measured_scans += p.segments.segments.empty() ? 0 : 1;
      for (std::size_t s = 0; s < p.segments.segments.size(); ++s) {
        const Measurement m =
            MeasureSegment(p.segments.Points(p.segments.segments[s]), meas_options);
        ellipses += m.kind == MeasurementKind::kEllipse ? 1 : 0;
        if (s >= p.filters.size()) {
          CvEkf* f = p.filters.emplace_slot();
          f->Init(m.position_m, m.covariance_m2);
        } else {
          p.filters[s].Predict(1.0 / 25.0);
          if (p.filters[s].MahalanobisSq(m.position_m, m.covariance_m2) < 1e3) {
            updates += p.filters[s].Update(m.position_m, m.covariance_m2) ? 1 : 0;
          } else {
            p.filters[s].Init(m.position_m, m.covariance_m2);
          }
        }
      }
    }
    if (k >= 1) allocations += ::lrfnet::testing::StopCountingAllocations();
  }
  EXPECT_EQ(allocations, 0u);
  // The run exercised every stage.
  EXPECT_GT(measured_scans, 2000u);
  EXPECT_GT(ellipses, 2000u);
  EXPECT_GT(updates, 1000u);
  EXPECT_GT(pipeline->background.counters().absorbed_beams, 0u);
}

TEST(TrackingAllocTest, WholePipelineOnACrowdAllocatesNothingAfterTheFirstScan) {
  testing::SyntheticScanner scanner;
  const auto room = testing::Room();
  // Allocated once, like the tracker application does.
  auto pipeline = std::make_unique<TrackingPipeline>(TrackerOptions{});
  constexpr int kPeople = 20;
  constexpr int kScans = 3000;  // 2 minutes at 25 Hz
  std::vector<testing::Body> bodies(kPeople);
  std::size_t max_confirmed = 0, max_segments = 0;
  std::size_t allocations = 0;

  for (int k = 0; k < kScans; ++k) {
    const double t = k / 25.0;
    // People wander on Lissajous curves (0.3-1.5 m/s) over the room in front of the sensor and
    // pass through each other; they enter after the background was learned.
    for (int i = 0; i < kPeople; ++i) {
      const double phase = 0.7 * i;
      const double wx = 0.11 + 0.013 * i, wy = 0.07 + 0.017 * i;
      const Eigen::Vector2d c(3.5 + 3.0 * std::sin(wx * t + phase),
                              -0.5 + 3.8 * std::sin(wy * t + 2.0 * phase));
      const Eigen::Vector2d v(3.0 * wx * std::cos(wx * t + phase),
                              3.8 * wy * std::cos(wy * t + 2.0 * phase));
      bodies[i] = {t < 6.0 ? Eigen::Vector2d(40.0, 0.0) : c, 0.25, 0.15,
                   std::atan2(v.y(), v.x()) + common::kPi / 2};
    }
    const ScanView scan = scanner.Render(k, room, bodies);  // outside the counted region

    if (k >= 1) ::lrfnet::testing::StartCountingAllocations();
    const ScanTracks& out = pipeline->Process(scan, static_cast<std::uint32_t>(k));
    if (k >= 1) allocations += ::lrfnet::testing::StopCountingAllocations();
    max_confirmed = std::max(max_confirmed, out.tracks.size());
    max_segments = std::max(max_segments, pipeline->last_segment_count());
  }
  EXPECT_EQ(allocations, 0u);
  // The run exercised the whole pipeline: many tracks at once, births and deaths.
  const MultiTrackerCounters& c = pipeline->tracker().counters();
  EXPECT_GE(max_confirmed, 10u);
  EXPECT_GE(max_segments, 10u);
  EXPECT_GT(c.created, 20u);
  EXPECT_GT(c.deleted(), 0u);
  EXPECT_GT(c.associations, 10u * 2000u);
  EXPECT_GT(pipeline->counters().shape_fits, 10u * 2000u);
}

TEST(TrackingAllocTest, KneeHeightPipelineAllocatesNothingAfterTheFirstScan) {
  testing::ScannerConfig config;
  config.max_range_m = 30.0;
  testing::SyntheticScanner scanner(config);
  // A hall 14 m deep: people at 8-12 m, where the legs' mixed-pixel rules apply.
  const std::vector<testing::Wall> hall = {{{14.0, -8.0}, {14.0, 8.0}},
                                           {{14.0, 8.0}, {-1.0, 8.0}},
                                           {{-1.0, 8.0}, {-1.0, -8.0}},
                                           {{-1.0, -8.0}, {14.0, -8.0}}};
  TrackerOptions options;
  options.shape.mount = Mount::kLegs;
  auto pipeline = std::make_unique<TrackingPipeline>(options);
  constexpr int kPeople = 10;
  constexpr int kScans = 1000;
  std::vector<testing::Body> bodies(2 * kPeople);
  std::size_t allocations = 0;
  for (int k = 0; k < kScans; ++k) {
    const double t = k / 25.0;
    for (int i = 0; i < kPeople; ++i) {
      const double phase = 0.7 * i;
      const Eigen::Vector2d c(4.0 + 6.0 * std::abs(std::sin((0.1 + 0.01 * i) * t + phase)),
                              -6.0 + 1.2 * i + std::sin(0.2 * t + phase));
      const Eigen::Vector2d off(0.1 * std::cos(2.0 * t + i), 0.1);
      bodies[2 * i] = testing::Cylinder(t < 6.0 ? Eigen::Vector2d(40.0, 0.0) : c + off, 0.06);
      bodies[2 * i + 1] = testing::Cylinder(t < 6.0 ? Eigen::Vector2d(40.0, 0.0) : c - off, 0.06);
    }
    // A mixed pixel behind every other leg's edge beam.
    const ScanView scan = scanner.Render(k, hall, bodies);  // outside the counted region
    std::vector<float>& r = scanner.ranges();
    for (std::size_t b = 1; b + 1 < r.size(); b += 2) {
      if (r[b - 1] > 0.0f && r[b] > r[b - 1] + 1.0f) r[b] = 0.5f * (r[b - 1] + r[b]);
    }
    if (k >= 1) ::lrfnet::testing::StartCountingAllocations();
    (void)pipeline->Process(scan, static_cast<std::uint32_t>(k));
    if (k >= 1) allocations += ::lrfnet::testing::StopCountingAllocations();
  }
  EXPECT_EQ(allocations, 0u);
  EXPECT_GT(pipeline->counters().leg_pairs, 1000u);
  EXPECT_GT(pipeline->counters().veiled_segments + pipeline->counters().shadowed_legs, 0u);
  EXPECT_GT(pipeline->tracker().counters().confirmed, 5u);
}

}  // namespace
}  // namespace lrfnet::tracking
