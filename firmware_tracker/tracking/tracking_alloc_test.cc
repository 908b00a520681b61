// Zero heap allocations per scan after start-up (DESIGN.md quality bar): replaces the global
// allocation functions with counting ones and runs thousands of synthetic scans through background
// model, segmentation, measurement and per-segment filters.

#include <gtest/gtest.h>

#include <atomic>
#include <cstddef>
#include <cstdlib>
#include <new>
#include <vector>

#include "firmware_tracker/tracking/background_model.h"
#include "firmware_tracker/tracking/cv_ekf.h"
#include "firmware_tracker/tracking/measurement.h"
#include "firmware_tracker/tracking/segmentation.h"
#include "firmware_tracker/tracking/tracking_test_util.h"

namespace {
std::atomic<bool> g_counting{false};
std::atomic<std::size_t> g_allocations{0};

void* CountedAlloc(std::size_t size, std::size_t alignment) {
  if (g_counting.load(std::memory_order_relaxed))
    g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (size == 0) size = 1;
  void* p = nullptr;
  if (alignment <= alignof(std::max_align_t)) {
    p = std::malloc(size);
  } else {
    p = std::aligned_alloc(alignment, (size + alignment - 1) / alignment * alignment);
  }
  if (p == nullptr) throw std::bad_alloc();
  return p;
}
}  // namespace

void* operator new(std::size_t size) { return CountedAlloc(size, 0); }
void* operator new[](std::size_t size) { return CountedAlloc(size, 0); }
void* operator new(std::size_t size, std::align_val_t a) {
  return CountedAlloc(size, static_cast<std::size_t>(a));
}
void* operator new[](std::size_t size, std::align_val_t a) {
  return CountedAlloc(size, static_cast<std::size_t>(a));
}
void* operator new(std::size_t size, const std::nothrow_t&) noexcept {
  try {
    return CountedAlloc(size, 0);
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t size, const std::nothrow_t&) noexcept {
  try {
    return CountedAlloc(size, 0);
  } catch (...) {
    return nullptr;
  }
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }

namespace lrfnet::tracking {
namespace {

struct Pipeline {
  BackgroundModel background{BackgroundOptions{}};
  SegmentList segments;
  common::FixedVector<CvEkf, kMaxSegments> filters;
};

TEST(TrackingAllocTest, CounterSeesAllocations) {
  g_allocations = 0;
  g_counting = true;
  auto* p = new std::vector<int>(100);
  g_counting = false;
  delete p;
  EXPECT_EQ(g_allocations.load(), 2u);
}

TEST(TrackingAllocTest, NoHeapAllocationPerScanAfterTheFirst) {
  testing::SyntheticScanner scanner;
  const auto room = testing::Room();
  auto pipeline = std::make_unique<Pipeline>();  // large: fixed buffers for kMaxBeams beams
  const SegmentationOptions seg_options;
  const MeasurementOptions meas_options;
  std::vector<testing::Body> bodies(3);
  constexpr int kScans = 3000;  // 2 minutes at 25 Hz, past learning and cart absorption
  std::size_t ellipses = 0, updates = 0, measured_scans = 0;

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

    if (k == 1) {
      g_allocations = 0;
      g_counting = true;
    }
    Pipeline& p = *pipeline;
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
    g_counting = false;
  }
  EXPECT_EQ(g_allocations.load(), 0u);
  // The run exercised every stage.
  EXPECT_GT(measured_scans, 2000u);
  EXPECT_GT(ellipses, 2000u);
  EXPECT_GT(updates, 1000u);
  EXPECT_GT(pipeline->background.counters().absorbed_beams, 0u);
}

}  // namespace
}  // namespace lrfnet::tracking
