#include "central_daemon/calibration/align.h"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "common/cv_model.h"
#include "common/eigen_instances.h"
#include "firmware_tracker/tracking/cv_ekf.h"

namespace lrfnet::calib {
namespace {

using common::UtcNs;
using daemon::TrackState;

constexpr UtcNs kEpochNs = 1'700'000'000'000'000'000;  // a UTC time of 2023
constexpr UtcNs kStep50msNs = 50'000'000;

SensorRecording Named(const std::string& id) {
  SensorRecording s;
  s.id = id;
  return s;
}

UtcNs At(double t_s) { return kEpochNs + std::llround(t_s * 1e9); }

// The covariance of the tracker's filter after a while on a steady walker at 25 Hz.
Eigen::Matrix4d SteadyCovariance() {
  tracking::CvEkf ekf{tracking::CvEkfOptions{}};
  const Eigen::Matrix2d r = 0.03 * 0.03 * Eigen::Matrix2d::Identity();
  ekf.Init({0.0, 0.0}, r);
  for (int k = 0; k < 100; ++k) {
    ekf.Predict(0.04);
    ekf.Update({0.0, 0.0}, r);
  }
  return ekf.covariance();
}

daemon::TrackObservation Observation(std::uint32_t id, const Eigen::Vector4d& x,
                                     const Eigen::Matrix4d& p,
                                     TrackState state = TrackState::kConfirmed) {
  daemon::TrackObservation o;
  o.track_id = id;
  o.state = state;
  o.kind = daemon::MeasurementKind::kCenterOfMass;
  o.x_m = static_cast<float>(x(0));
  o.y_m = static_cast<float>(x(1));
  o.vx_mps = static_cast<float>(x(2));
  o.vy_mps = static_cast<float>(x(3));
  std::size_t n = 0;
  for (int row = 0; row < 4; ++row) {
    for (int col = row; col < 4; ++col) o.covariance[n++] = static_cast<float>(p(row, col));
  }
  return o;
}

// A target on a constant-velocity line: state (x, y, vx, vy) at t_s seconds after kEpochNs.
struct Line {
  Eigen::Vector4d at_zero;
  Eigen::Vector4d StateAt(double t_s) const { return common::CvTransition(t_s) * at_zero; }
};

struct LineTrack {
  std::uint32_t id = 1;
  Line line;
  double from_s = 0.0;  // present in scans with from_s <= t <= to_s
  double to_s = 0.0;
  TrackState state = TrackState::kConfirmed;
};

// Scans every period_s from offset_s to end_s, with the tracks present at each scan time.
SensorRecording LineSensor(const std::string& id, double period_s, double offset_s, double end_s,
                           const std::vector<LineTrack>& tracks, std::uint64_t session = 7) {
  const Eigen::Matrix4d p = SteadyCovariance();
  SensorRecording s;
  s.id = id;
  s.clock_sync = ClockSync::kSynchronized;
  std::uint32_t counter = 0;
  for (double t = offset_s; t <= end_s + 1e-9; t += period_s) {
    daemon::TrackFrameData f;
    f.session_id = session;
    f.scan_start_ns = At(t);
    f.scan_period_s = period_s;
    f.scan_counter = counter++;
    for (const LineTrack& track : tracks) {
      if (t >= track.from_s - 1e-9 && t <= track.to_s + 1e-9) {
        f.tracks.push_back(Observation(track.id, track.line.StateAt(t), p, track.state));
      }
    }
    s.frames.push_back(std::move(f));
  }
  return s;
}

double TimeOfStep(const AlignedTracks& a, std::size_t step) {
  return common::NsToSeconds(a.t0_ns - kEpochNs) + a.TimeOf(step);
}

bool SymmetricPositiveDefinite(const Eigen::Matrix2d& c) {
  return c.allFinite() && c(0, 1) == c(1, 0) &&
         Eigen::LLT<Eigen::Matrix2d>(c).info() == Eigen::Success;
}

const Line kWalker{Eigen::Vector4d(1.0, 4.0, 1.2, -0.3)};

TEST(AlignOptionsTest, DefaultsValidAndBadValuesRejected) {
  EXPECT_EQ(Validate(AlignOptions{}), std::nullopt);
  EXPECT_NE(Validate(AlignOptions{.grid_step_s = 0.0}), std::nullopt);
  EXPECT_NE(Validate(AlignOptions{.grid_step_s = std::nan("")}), std::nullopt);
  EXPECT_NE(Validate(AlignOptions{.accel_psd_m2ps3 = -1.0}), std::nullopt);
  EXPECT_NE(Validate(AlignOptions{.max_gap_s = 0.0}), std::nullopt);
  EXPECT_NE(Validate(AlignOptions{.min_track_duration_s = -1.0}), std::nullopt);
  EXPECT_NE(Validate(AlignOptions{.min_position_sigma_m = std::numeric_limits<double>::infinity()}),
            std::nullopt);
  EXPECT_NE(Validate(AlignOptions{.max_grid_span_s = 0.01}), std::nullopt);
  const auto reason = Validate(AlignOptions{.max_gap_s = -2.0});
  ASSERT_TRUE(reason.has_value());
  EXPECT_EQ(reason->rfind("max_gap_s", 0), 0u) << *reason;
}

TEST(AlignTest, EmptyInputGivesAnEmptyGrid) {
  AlignStats stats;
  const AlignedTracks none = Align(CalibrationInput{}, AlignOptions{}, &stats);
  EXPECT_EQ(none.steps, 0u);
  EXPECT_TRUE(none.sensors.empty());
  EXPECT_TRUE(stats.sensors.empty());

  CalibrationInput input;
  input.sensors.push_back(Named("a"));
  input.sensors.push_back(Named("b"));
  input.sensors[1].frames.emplace_back();  // a frame without tracks
  const AlignedTracks empty = Align(input, AlignOptions{}, &stats);
  EXPECT_EQ(empty.steps, 0u);
  ASSERT_EQ(empty.sensors.size(), 2u);
  EXPECT_EQ(empty.sensors[0].id, "a");
  EXPECT_EQ(empty.sensors[1].id, "b");
  EXPECT_TRUE(empty.sensors[0].tracks.empty());
  EXPECT_TRUE(empty.sensors[1].tracks.empty());
  EXPECT_EQ(stats.sensors[1].frames, 1u);
}

TEST(AlignTest, SensorsWithDifferentRatesAndOffsetsLandOnTheSameGrid) {
  CalibrationInput input;
  // The same target seen by two sensors (identity poses): 25 Hz from 0.013 s, 15 Hz from 0.031 s.
  input.sensors.push_back(LineSensor("fast", 0.04, 0.013, 6.0, {{1, kWalker, 0.0, 6.0}}));
  input.sensors.push_back(LineSensor("slow", 1.0 / 15.0, 0.031, 6.0, {{4, kWalker, 0.5, 6.0}}));
  AlignStats stats;
  const AlignedTracks a = Align(input, AlignOptions{}, &stats);

  EXPECT_EQ(a.step_s, 0.05);
  EXPECT_EQ(a.t0_ns % kStep50msNs, 0);
  EXPECT_LE(a.t0_ns, At(0.013));
  EXPECT_GT(a.t0_ns, At(0.013) - kStep50msNs);
  EXPECT_GE(a.t0_ns + static_cast<UtcNs>(a.steps - 1) * kStep50msNs,
            input.sensors[0].frames.back().scan_start_ns);
  ASSERT_EQ(a.sensors.size(), 2u);
  ASSERT_EQ(a.sensors[0].tracks.size(), 1u);
  ASSERT_EQ(a.sensors[1].tracks.size(), 1u);
  const GridTrack& fast = a.sensors[0].tracks[0];
  const GridTrack& slow = a.sensors[1].tracks[0];
  EXPECT_EQ(fast.track_id, 1u);
  EXPECT_EQ(slow.track_id, 4u);
  EXPECT_EQ(fast.session_id, 7u);
  EXPECT_EQ(fast.kind, daemon::MeasurementKind::kCenterOfMass);
  // Samples only inside [first, last] state time.
  EXPECT_GE(TimeOfStep(a, fast.first_step), 0.013 - 1e-9);
  EXPECT_LT(TimeOfStep(a, fast.first_step) - 0.05, 0.013);
  EXPECT_GE(TimeOfStep(a, slow.first_step), 0.531 - 1e-9);
  EXPECT_LE(TimeOfStep(a, slow.end_step() - 1), 6.0);

  std::size_t common_steps = 0;
  for (std::size_t step = slow.first_step; step < slow.end_step(); ++step) {
    ASSERT_TRUE(fast.Covers(step)) << step;
    const Eigen::Vector4d truth = kWalker.StateAt(TimeOfStep(a, step));
    // Both interpolate to the target's true position and velocity (float states on the wire).
    EXPECT_LT((fast.At(step).position_m - truth.head<2>()).norm(), 1e-4) << step;
    EXPECT_LT((slow.At(step).position_m - truth.head<2>()).norm(), 1e-4) << step;
    EXPECT_LT((fast.At(step).position_m - slow.At(step).position_m).norm(), 1e-4) << step;
    EXPECT_LT((slow.At(step).velocity_mps - truth.tail<2>()).norm(), 1e-4) << step;
    EXPECT_TRUE(SymmetricPositiveDefinite(slow.At(step).position_cov_m2));
    ++common_steps;
  }
  EXPECT_EQ(common_steps, 108u);  // 0.6 .. 5.95 s
  EXPECT_EQ(stats.sensors[0].frames_used, stats.sensors[0].frames);
  EXPECT_EQ(stats.sensors[0].samples, fast.samples.size());
  EXPECT_EQ(a.sensors[0].observations_used, stats.sensors[0].observations);
}

// A noisy walker filtered by the tracker's own filter: the smoothed samples are clearly closer to
// the truth than the filtered ones.
TEST(AlignTest, SmoothingReducesTheErrorOfTheFilteredTrack) {
  const double q = 0.5, sigma = 0.05, period = 0.04;
  std::mt19937 rng(21);
  std::normal_distribution<double> unit(0.0, 1.0);
  const Eigen::Matrix2d r = sigma * sigma * Eigen::Matrix2d::Identity();
  tracking::CvEkf ekf{tracking::CvEkfOptions{.accel_psd_m2ps3 = q}};
  Eigen::Vector4d x(0.0, 3.0, 1.0, 0.2);
  SensorRecording sensor = Named("s");
  std::vector<Eigen::Vector4d> truth;
  for (int k = 0; k < 1500; ++k) {  // 60 s
    if (k > 0) {
      const Eigen::LLT<Eigen::Matrix4d> chol(common::CvProcessNoise(period, q));
      x = common::CvTransition(period) * x +
          chol.matrixL() * Eigen::Vector4d(unit(rng), unit(rng), unit(rng), unit(rng));
      ekf.Predict(period);
    }
    const Eigen::Vector2d z = x.head<2>() + sigma * Eigen::Vector2d(unit(rng), unit(rng));
    if (k == 0) {
      ekf.Init(z, r);
    } else {
      ekf.Update(z, r);
    }
    truth.push_back(x);
    daemon::TrackFrameData f;
    f.session_id = 1;
    f.scan_start_ns = kEpochNs + static_cast<UtcNs>(k) * 40'000'000;
    f.tracks.push_back(Observation(3, ekf.state(), ekf.covariance()));
    sensor.frames.push_back(std::move(f));
  }
  CalibrationInput input;
  input.sensors.push_back(sensor);
  // Grid = scan times, so the truth is known at every sample.
  AlignOptions options{.grid_step_s = 0.04, .accel_psd_m2ps3 = q};
  const auto rms = [&](const AlignedTracks& a) {
    EXPECT_EQ(a.t0_ns, kEpochNs);
    const GridTrack& t = a.sensors.at(0).tracks.at(0);
    EXPECT_EQ(t.samples.size(), truth.size());
    double sum = 0.0;
    for (std::size_t k = 20; k < t.samples.size(); ++k) {
      sum += (t.At(k).position_m - truth[k].head<2>()).squaredNorm();
    }
    return std::sqrt(sum / static_cast<double>(t.samples.size() - 20));
  };
  options.smooth = false;
  const double filtered = rms(Align(input, options));
  options.smooth = true;
  const double smoothed = rms(Align(input, options));
  EXPECT_LT(smoothed, 0.8 * filtered) << "filtered " << filtered << ", smoothed " << smoothed;
}

TEST(AlignTest, UnsmoothedSamplesBetweenScansArePredictionsOfTheFilteredState) {
  CalibrationInput input;
  // Scans at 0.02, 0.12, ... (10 Hz): every grid step (0.05 s) is 30 or 80 ms after a scan.
  input.sensors.push_back(LineSensor("s", 0.1, 0.02, 3.0, {{1, kWalker, 0.0, 3.0}}));
  const AlignedTracks a = Align(input, AlignOptions{.smooth = false});
  const GridTrack& t = a.sensors.at(0).tracks.at(0);
  for (std::size_t step = t.first_step; step < t.end_step(); ++step) {
    const Eigen::Vector4d truth = kWalker.StateAt(TimeOfStep(a, step));
    EXPECT_LT((t.At(step).position_m - truth.head<2>()).norm(), 1e-4) << step;
  }
  // The position variance grows between scans (prediction) and drops at the next scan.
  // 0.05 s is 30 ms after the scan at 0.02 s, 0.10 s 80 ms after it, 0.15 s 30 ms after 0.12 s.
  const std::size_t first = t.first_step;
  ASSERT_NEAR(TimeOfStep(a, first), 0.05, 1e-9);
  EXPECT_LT(t.At(first).position_cov_m2(0, 0), t.At(first + 1).position_cov_m2(0, 0));
  EXPECT_GT(t.At(first + 1).position_cov_m2(0, 0), t.At(first + 2).position_cov_m2(0, 0));
}

TEST(AlignTest, GapsSplitTracksAndShortPiecesAreDropped) {
  const Eigen::Matrix4d p = SteadyCovariance();
  SensorRecording s = Named("s");
  // Track 2 at 25 Hz from 0 to 3 s, missing 3.0-3.8 s, then to 6 s; then seen again for 0.48 s.
  for (int k = 0; k <= 250; ++k) {
    const double t = 0.04 * k;
    if ((t > 3.01 && t < 3.79) || (t > 6.01 && t < 9.49)) continue;
    daemon::TrackFrameData f;
    f.session_id = 1;
    f.scan_start_ns = At(t);
    f.tracks.push_back(Observation(2, kWalker.StateAt(t), p));
    s.frames.push_back(std::move(f));
  }
  CalibrationInput input;
  input.sensors.push_back(s);
  AlignStats stats;
  const AlignedTracks a = Align(input, AlignOptions{}, &stats);
  const std::vector<GridTrack>& tracks = a.sensors.at(0).tracks;
  ASSERT_EQ(tracks.size(), 2u);
  EXPECT_EQ(tracks[0].track_id, 2u);
  EXPECT_EQ(tracks[1].track_id, 2u);
  EXPECT_NEAR(TimeOfStep(a, tracks[0].end_step() - 1), 3.0, 1e-9);
  EXPECT_NEAR(TimeOfStep(a, tracks[1].first_step), 3.8, 1e-9);
  EXPECT_NEAR(TimeOfStep(a, tracks[1].end_step() - 1), 6.0, 1e-9);
  EXPECT_EQ(stats.sensors[0].gaps_split, 2u);
  EXPECT_EQ(stats.sensors[0].short_pieces, 1u);
  EXPECT_EQ(stats.sensors[0].short_piece_states, 13u);  // 9.52 .. 10.0 s
  EXPECT_EQ(stats.sensors[0].observations_used + 13, stats.sensors[0].observations);

  // A longer max_gap_s bridges the first gap; min_track_duration_s 0 keeps the short piece.
  const AlignedTracks bridged =
      Align(input, AlignOptions{.max_gap_s = 1.0, .min_track_duration_s = 0.0}, &stats);
  const std::vector<GridTrack>& joined = bridged.sensors.at(0).tracks;
  ASSERT_EQ(joined.size(), 2u);
  EXPECT_NEAR(TimeOfStep(bridged, joined[0].end_step() - 1), 6.0, 1e-9);
  EXPECT_NEAR(TimeOfStep(bridged, joined[1].first_step), 9.55, 1e-9);
  // Across the bridged gap the interpolation still follows the line.
  const std::size_t in_gap = joined[0].first_step + 70;  // 3.5 s
  ASSERT_NEAR(TimeOfStep(bridged, in_gap), 3.5, 1e-9);
  EXPECT_LT((joined[0].At(in_gap).position_m - kWalker.StateAt(3.5).head<2>()).norm(), 1e-4);
}

TEST(AlignTest, TentativeSkippedUnlessIncluded) {
  CalibrationInput input;
  input.sensors.push_back(
      LineSensor("s", 0.04, 0.0, 3.0,
                 {{1, kWalker, 0.0, 3.0, TrackState::kTentative}, {2, kWalker, 0.0, 3.0}}));
  AlignStats stats;
  const AlignedTracks a = Align(input, AlignOptions{}, &stats);
  ASSERT_EQ(a.sensors[0].tracks.size(), 1u);
  EXPECT_EQ(a.sensors[0].tracks[0].track_id, 2u);
  EXPECT_EQ(stats.sensors[0].tentative_skipped, 76u);
  const AlignedTracks b = Align(input, AlignOptions{.include_tentative = true}, &stats);
  EXPECT_EQ(b.sensors[0].tracks.size(), 2u);
  EXPECT_EQ(stats.sensors[0].tentative_skipped, 0u);
}

TEST(AlignTest, CoastingStatesKeptInsideATrackAndTrimmedAtItsEnd) {
  CalibrationInput input;
  SensorRecording s = LineSensor("s", 0.04, 0.0, 4.0, {{1, kWalker, 0.0, 4.0}});
  // Coasting from 1.0 to 1.4 s (inside) and from 3.6 s to the end (the tail before deletion).
  for (auto& f : s.frames) {
    const double t = common::NsToSeconds(f.scan_start_ns - kEpochNs);
    if ((t > 0.99 && t < 1.41) || t > 3.59) f.tracks[0].state = TrackState::kCoasting;
  }
  input.sensors.push_back(s);
  AlignStats stats;
  const AlignedTracks a = Align(input, AlignOptions{}, &stats);
  ASSERT_EQ(a.sensors[0].tracks.size(), 1u);
  EXPECT_EQ(stats.sensors[0].coasting_trimmed, 11u);  // 3.6 .. 4.0 s
  EXPECT_EQ(stats.sensors[0].observations_used, 101u - 11u);
  EXPECT_NEAR(TimeOfStep(a, a.sensors[0].tracks[0].end_step() - 1), 3.55, 1e-9);
  const AlignedTracks b = Align(input, AlignOptions{.trim_coasting_tail = false}, &stats);
  EXPECT_EQ(stats.sensors[0].coasting_trimmed, 0u);
  EXPECT_NEAR(TimeOfStep(b, b.sensors[0].tracks[0].end_step() - 1), 4.0, 1e-9);
}

TEST(AlignTest, UnsynchronizedClocksFlaggedOrExcluded) {
  CalibrationInput input;
  input.sensors.push_back(LineSensor("good", 0.04, 0.0, 3.0, {{1, kWalker, 0.0, 3.0}}));
  input.sensors.push_back(LineSensor("bad", 0.04, 0.0, 3.0, {{1, kWalker, 0.0, 3.0}}));
  input.sensors[1].clock_sync = ClockSync::kUnsynchronized;
  AlignStats stats;
  const AlignedTracks kept = Align(input, AlignOptions{}, &stats);
  EXPECT_FALSE(kept.sensors[0].clock_suspect);
  EXPECT_TRUE(kept.sensors[1].clock_suspect);
  EXPECT_EQ(kept.sensors[1].tracks.size(), 1u);
  EXPECT_FALSE(stats.sensors[1].excluded);

  const AlignedTracks excluded = Align(input, AlignOptions{.exclude_unsynchronized = true}, &stats);
  ASSERT_EQ(excluded.sensors.size(), 2u);
  EXPECT_EQ(excluded.sensors[1].id, "bad");
  EXPECT_TRUE(excluded.sensors[1].clock_suspect);
  EXPECT_TRUE(excluded.sensors[1].tracks.empty());
  EXPECT_TRUE(stats.sensors[1].excluded);
  EXPECT_EQ(stats.sensors[1].frames, input.sensors[1].frames.size());
  EXPECT_EQ(excluded.sensors[0].tracks.size(), 1u);
}

TEST(AlignTest, BadValuesSkippedAndCounted) {
  CalibrationInput input;
  SensorRecording s = LineSensor("s", 0.04, 0.0, 4.0, {{1, kWalker, 0.0, 4.0}});
  const AlignedTracks clean = Align(CalibrationInput{{s}});
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  // Seven hostile observations added to frames 10..16 as a second track id (kept apart from the
  // good one), and one bad frame time.
  auto bad = [&](std::size_t frame) -> daemon::TrackObservation& {
    s.frames[frame].tracks.push_back(s.frames[frame].tracks[0]);
    s.frames[frame].tracks.back().track_id = 9;
    return s.frames[frame].tracks.back();
  };
  bad(10).x_m = nan;
  bad(11).vy_mps = inf;
  bad(12).covariance[3] = nan;
  bad(13).covariance[0] = -1.0f;  // negative variance
  bad(14).covariance[1] = 1.0f;   // |xy| > sqrt(xx yy): not PSD
  bad(15).y_m = 1e9f;             // absurd position
  bad(16).covariance[9] = 1e30f;  // absurd variance
  s.frames[20].tracks.push_back(s.frames[20].tracks[0]);
  s.frames[20].tracks.back().track_id = 11;
  s.frames.push_back(s.frames[20]);
  s.frames.back().scan_start_ns = -5;  // before the epoch
  input.sensors.push_back(s);
  AlignStats stats;
  const AlignedTracks a = Align(input, AlignOptions{}, &stats);
  EXPECT_EQ(stats.sensors[0].invalid, 9u);
  ASSERT_EQ(a.sensors[0].tracks.size(), 1u);  // track 9 (all bad) and 11 (one state) are gone
  EXPECT_EQ(a.t0_ns, clean.t0_ns);
  ASSERT_EQ(a.sensors[0].tracks[0].samples.size(), clean.sensors[0].tracks[0].samples.size());
  for (std::size_t i = 0; i < clean.sensors[0].tracks[0].samples.size(); ++i) {
    EXPECT_EQ(a.sensors[0].tracks[0].samples[i].position_m,
              clean.sensors[0].tracks[0].samples[i].position_m);
  }
}

TEST(AlignTest, DuplicatedAndReorderedFramesGiveTheSameTracks) {
  const SensorRecording s =
      LineSensor("s", 0.04, 0.0, 4.0,
                 {{1, kWalker, 0.0, 4.0}, {2, Line{Eigen::Vector4d(5, 5, 0, 1)}, 1.0, 4.0}});
  const AlignedTracks clean = Align(CalibrationInput{{s}});
  SensorRecording messy = s;
  // Every fifth frame twice (a repeated datagram), then shuffled.
  for (std::size_t i = 0; i < s.frames.size(); i += 5) messy.frames.push_back(s.frames[i]);
  std::mt19937 rng(4);
  std::shuffle(messy.frames.begin(), messy.frames.end(), rng);
  AlignStats stats;
  const AlignedTracks a = Align(CalibrationInput{{messy}}, AlignOptions{}, &stats);
  EXPECT_EQ(stats.sensors[0].duplicates, 21u + 16u);  // frames 0, 5, ..., 100; track 2 from 1 s
  EXPECT_GT(stats.sensors[0].unordered_frames, 0u);
  EXPECT_EQ(a.t0_ns, clean.t0_ns);
  EXPECT_EQ(a.steps, clean.steps);
  ASSERT_EQ(a.sensors[0].tracks.size(), 2u);
  for (std::size_t t = 0; t < 2; ++t) {
    const GridTrack& x = a.sensors[0].tracks[t];
    const GridTrack& y = clean.sensors[0].tracks[t];
    EXPECT_EQ(x.track_id, y.track_id);
    EXPECT_EQ(x.first_step, y.first_step);
    ASSERT_EQ(x.samples.size(), y.samples.size());
    for (std::size_t i = 0; i < x.samples.size(); ++i) {
      EXPECT_EQ(x.samples[i].position_m, y.samples[i].position_m);
      EXPECT_EQ(x.samples[i].position_cov_m2, y.samples[i].position_cov_m2);
    }
  }
  // Ordered by first step: track 1 from 0 s, track 2 from 1 s.
  EXPECT_EQ(a.sensors[0].tracks[0].track_id, 1u);
  EXPECT_EQ(a.sensors[0].tracks[1].track_id, 2u);
}

TEST(AlignTest, TrackIdentityIncludesTheSession) {
  CalibrationInput input;
  input.sensors.push_back(LineSensor("s", 0.04, 0.0, 2.0, {{5, kWalker, 0.0, 2.0}}, 100));
  const SensorRecording restarted =
      LineSensor("s", 0.04, 2.04, 4.0, {{5, kWalker, 2.04, 4.0}}, 101);
  input.sensors[0].frames.insert(input.sensors[0].frames.end(), restarted.frames.begin(),
                                 restarted.frames.end());
  const AlignedTracks a = Align(input, AlignOptions{.max_gap_s = 1.0});
  ASSERT_EQ(a.sensors[0].tracks.size(), 2u);
  EXPECT_EQ(a.sensors[0].tracks[0].session_id, 100u);
  EXPECT_EQ(a.sensors[0].tracks[1].session_id, 101u);
}

TEST(AlignTest, FramesSplitIntoPartsUseWhatIsThere) {
  SensorRecording s =
      LineSensor("s", 0.04, 0.0, 3.0,
                 {{1, kWalker, 0.0, 3.0}, {2, Line{Eigen::Vector4d(5, 5, 0, 1)}, 0.0, 3.0}});
  // Every scan as two parts (one track each); the second part of every third scan is lost.
  SensorRecording parts = Named("s");
  for (std::size_t i = 0; i < s.frames.size(); ++i) {
    daemon::TrackFrameData first = s.frames[i];
    first.part_count = 2;
    first.tracks.resize(1);
    parts.frames.push_back(first);
    if (i % 3 == 2) continue;
    daemon::TrackFrameData second = s.frames[i];
    second.part = 1;
    second.part_count = 2;
    second.tracks.erase(second.tracks.begin());
    parts.frames.push_back(second);
  }
  AlignStats stats;
  const AlignedTracks a = Align(CalibrationInput{{parts}}, AlignOptions{}, &stats);
  ASSERT_EQ(a.sensors[0].tracks.size(), 2u);
  EXPECT_EQ(stats.sensors[0].duplicates, 0u);
  EXPECT_EQ(stats.sensors[0].observations_used, 76u + 51u);
  for (const GridTrack& t : a.sensors[0].tracks) {
    EXPECT_EQ(t.samples.size(), 61u);  // 0 .. 3 s
  }
}

TEST(AlignTest, HugeTimeSpanIsClippedToTheBusiestWindow) {
  CalibrationInput input;
  input.sensors.push_back(LineSensor("a", 0.04, 0.0, 10.0, {{1, kWalker, 0.0, 10.0}}));
  input.sensors.push_back(LineSensor("b", 0.04, 0.0, 10.0, {{1, kWalker, 0.0, 10.0}}));
  // One frame of sensor b stamped ~200 years later (a hostile or broken clock).
  input.sensors[1].frames[5].scan_start_ns = kMaxTimeNs;
  AlignStats stats;
  const AlignedTracks a = Align(input, AlignOptions{.max_grid_span_s = 3600.0}, &stats);
  EXPECT_TRUE(stats.grid_clipped);
  EXPECT_NE(stats.error.find("max_grid_span_s"), std::string::npos) << stats.error;
  EXPECT_EQ(stats.sensors[1].outside_window, 1u);
  EXPECT_LE(a.steps, 202u);
  EXPECT_EQ(a.sensors[1].tracks.size(), 1u);

  input.sensors[1].frames[5].scan_start_ns = At(0.2);
  Align(input, AlignOptions{}, &stats);
  EXPECT_FALSE(stats.grid_clipped);
  EXPECT_TRUE(stats.error.empty());
}

// Arbitrary frames (times anywhere in int64, non-finite and huge values, random states and ids,
// any order): Align returns, accounts for every observation, and keeps the grid bounded.
TEST(AlignTest, HostileFramesAreAccountedForAndNeverBlowUpTheGrid) {
  std::mt19937_64 rng(99);
  const auto pick = [&](std::size_t n) { return static_cast<std::size_t>(rng() % n); };
  const std::vector<UtcNs> times = {
      std::numeric_limits<UtcNs>::min(), -1, 0, kMaxTimeNs, kMaxTimeNs + 1,
      std::numeric_limits<UtcNs>::max()};
  const std::vector<float> values = {std::numeric_limits<float>::quiet_NaN(),
                                     std::numeric_limits<float>::infinity(), -1e30f, 3e38f, 0.0f};
  CalibrationInput input;
  for (int sensor = 0; sensor < 3; ++sensor) {
    SensorRecording s = LineSensor("s" + std::to_string(sensor), 0.04, 0.01 * sensor, 20.0,
                                   {{1, kWalker, 0.0, 12.0}, {2, kWalker, 5.0, 20.0}});
    for (auto& f : s.frames) {
      switch (pick(8)) {
        case 0:
          f.scan_start_ns = times[pick(times.size())];
          break;
        case 1:
          f.scan_start_ns = static_cast<UtcNs>(rng());
          break;
        case 2:
          f.tracks.push_back(f.tracks.empty() ? daemon::TrackObservation{} : f.tracks[0]);
          break;
        case 3:
          if (!f.tracks.empty()) {
            auto& o = f.tracks[pick(f.tracks.size())];
            o.covariance[pick(10)] = values[pick(values.size())];
            o.x_m = pick(2) ? o.x_m : values[pick(values.size())];
          }
          break;
        case 4:
          if (!f.tracks.empty()) f.tracks[0].state = static_cast<TrackState>(pick(3));
          break;
        case 5:
          f.session_id = rng();
          break;
        default:
          break;
      }
    }
    s.frames.push_back(s.frames[pick(s.frames.size())]);  // a duplicate
    std::shuffle(s.frames.begin(), s.frames.end(), rng);
    input.sensors.push_back(std::move(s));
  }
  AlignStats stats;
  const AlignedTracks a = Align(input, AlignOptions{.max_grid_span_s = 600.0}, &stats);
  EXPECT_TRUE(stats.grid_clipped);
  EXPECT_LE(a.steps, 600u / 0.05 + 2);
  for (std::size_t s = 0; s < a.sensors.size(); ++s) {
    const AlignSensorStats& st = stats.sensors[s];
    EXPECT_EQ(st.observations, st.tentative_skipped + st.invalid + st.outside_window +
                                   st.duplicates + st.coasting_trimmed + st.short_piece_states +
                                   st.observations_used)
        << s;
    EXPECT_GT(st.invalid, 0u);
    EXPECT_GT(st.observations_used, 0u);
    for (const GridTrack& t : a.sensors[s].tracks) {
      EXPECT_LE(t.end_step(), a.steps);
      for (const TrackSample& sample : t.samples) {
        ASSERT_TRUE(sample.position_m.allFinite() && sample.velocity_mps.allFinite());
        ASSERT_TRUE(SymmetricPositiveDefinite(sample.position_cov_m2));
      }
    }
  }
}

TEST(AlignTest, SampleCovarianceIsFlooredAndPositiveDefinite) {
  CalibrationInput input;
  SensorRecording s = LineSensor("s", 0.04, 0.0, 2.0, {{1, kWalker, 0.0, 2.0}});
  // A (nearly) singular covariance: certain along x, 1 mm along y, perfectly correlated velocity.
  for (auto& f : s.frames) {
    auto& c = f.tracks[0].covariance;
    c.fill(0.0f);
    c[4] = 1e-6f;  // yy
  }
  input.sensors.push_back(s);
  const AlignedTracks a = Align(input, AlignOptions{.min_position_sigma_m = 0.01});
  ASSERT_EQ(a.sensors[0].tracks.size(), 1u);
  for (const TrackSample& sample : a.sensors[0].tracks[0].samples) {
    ASSERT_TRUE(SymmetricPositiveDefinite(sample.position_cov_m2));
    const Eigen::Vector2d eig =
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(sample.position_cov_m2).eigenvalues();
    EXPECT_GE(eig.minCoeff(), 1e-4 * (1.0 - 1e-9));
  }
}

// ---------------------------------------------------------------------------------------------
// The measurement model per sample.

// A walker straight away from the sensor along x (the line of sight is along the walking
// direction, i.e. across the shoulders' minor axis), 8 s at 25 Hz; every frame's observation
// passed through `edit` (by frame index) first.
template <typename Edit>
SensorRecording ModelWalker(Edit edit) {
  const Line away{Eigen::Vector4d(3.0, 0.0, 1.0, 0.0)};
  SensorRecording s = LineSensor("m", 0.04, 0.0, 8.0, {{1, away, 0.0, 8.0}});
  for (std::size_t f = 0; f < s.frames.size(); ++f) {
    for (daemon::TrackObservation& o : s.frames[f].tracks) {
      o.points = 8;
      edit(f, o);
    }
  }
  return s;
}

constexpr double kPi = common::kPi;

// A sample in the middle of the track (away from its ends).
const TrackSample& MiddleSample(const AlignedTracks& a) {
  const GridTrack& t = a.sensors.at(0).tracks.at(0);
  return t.samples[t.samples.size() / 2];
}

TEST(AlignModelTest, CentreOfMassSamplesCarryThePriorBodysBiasAndItsSensitivities) {
  const AlignedTracks a =
      Align(CalibrationInput{{ModelWalker([](std::size_t, daemon::TrackObservation&) {})}}, {});
  const TrackSample& x = MiddleSample(a);
  EXPECT_EQ(x.kind, daemon::MeasurementKind::kCenterOfMass);
  EXPECT_EQ(x.points, 8);
  // Seen along the walking direction: depth of the torso's minor semi-axis (0.15 m), pi/4 of it.
  EXPECT_NEAR(x.bias_m, kPi / 4.0 * 0.15, 1e-4);
  EXPECT_NEAR(x.bias_per_minor, kPi / 4.0, 1e-3);
  EXPECT_NEAR(x.bias_per_major, 0.0, 1e-3);
  EXPECT_NEAR(x.model_sigma_m, AlignOptions{}.model.com_sigma_m, 1e-3);
  // The centre lies behind the tracked point, along the line of sight.
  const Eigen::Vector2d c = CentreOf(x);
  EXPECT_NEAR((c - x.position_m).norm(), x.bias_m, 1e-6);
  EXPECT_GT(c.norm(), x.position_m.norm());
  EXPECT_EQ(a.size_prior_sigma_m, AlignOptions{}.model.prior_size_sigma_m);
}

TEST(AlignModelTest, ShapeFitWithTheTrackersSizeIsTheBodyCentre) {
  const AlignedTracks a =
      Align(CalibrationInput{{ModelWalker([](std::size_t, daemon::TrackObservation& o) {
              o.kind = daemon::MeasurementKind::kShapeFit;
              o.shape = daemon::ObjectShape::kTorso;
              o.size_major_m = 0.22f;
              o.size_minor_m = 0.12f;
              o.size_sigma_m = 0.03f;
            })}},
            {});
  const TrackSample& x = MiddleSample(a);
  EXPECT_EQ(x.kind, daemon::MeasurementKind::kShapeFit);  // not folded onto another kind
  EXPECT_EQ(a.sensors[0].tracks[0].kind, daemon::MeasurementKind::kShapeFit);
  EXPECT_EQ(x.bias_m, 0.0f);
  EXPECT_EQ(x.bias_per_major, 0.0f);
  EXPECT_EQ(x.bias_per_minor, 0.0f);
  EXPECT_NEAR(x.bias_sigma_m, 0.03, 1e-6);
}

TEST(AlignModelTest, AnEstimatorFlippingWithThePointCountGivesTheMixtureOfBothBiases) {
  // Every other scan the fixed-axes ellipse falls back to the centre of mass: the smoothed track
  // carries both biases, the fits weighted as the tracker's filter weighs them.
  const AlignedTracks a = Align(
      CalibrationInput{{ModelWalker([](std::size_t f, daemon::TrackObservation& o) {
        o.kind =
            f % 2 == 0 ? daemon::MeasurementKind::kEllipse : daemon::MeasurementKind::kCenterOfMass;
        o.ellipse_yaw_rad = 0.5f * static_cast<float>(kPi);  // major axis across the line of sight
        o.points = f % 2 == 0 ? 6 : 3;
      })}},
      {});
  const TrackSample& x = MiddleSample(a);
  const double com = kPi / 4.0 * 0.15;  // the fit's bias on the prior body is 0
  const double w = AlignOptions{}.model_fit_weight;
  // 11 states in the window: 5 or 6 of either kind.
  EXPECT_GE(x.bias_m, com * 5.0 / (5.0 + 6.0 * w) - 1e-4);
  EXPECT_LE(x.bias_m, com * 6.0 / (6.0 + 5.0 * w) + 1e-4);
  EXPECT_GT(x.bias_sigma_m, 0.5 * com * std::sqrt(w) / (1.0 + w));  // which mixture is uncertain
  EXPECT_EQ(x.kind, daemon::MeasurementKind::kEllipse);
  EXPECT_TRUE(x.points == 4 || x.points == 5) << x.points;
}

TEST(AlignModelTest, TheEndsOfATrackAreLessCertainThanItsMiddle) {
  const AlignedTracks a =
      Align(CalibrationInput{{ModelWalker([](std::size_t, daemon::TrackObservation&) {})}}, {});
  const GridTrack& t = a.sensors.at(0).tracks.at(0);
  const AlignOptions o;
  const double middle = t.samples[t.samples.size() / 2].model_sigma_m;
  const TrackSample& last = t.samples.back();
  const double edge = o.edge_sigma_per_m * last.position_m.norm();
  EXPECT_NEAR(last.model_sigma_m, std::hypot(o.model.com_sigma_m, edge), 2e-3);
  EXPECT_GT(t.samples.front().model_sigma_m, middle + 0.002);
  EXPECT_GT(last.model_sigma_m, middle + 0.02);
}

TEST(AlignModelTest, BadModelOptionsAreNamed) {
  AlignOptions o;
  o.model.prior_major_m = -1.0;
  ASSERT_TRUE(Validate(o).has_value());
  EXPECT_EQ(Validate(o)->rfind("model: prior_major_m", 0), 0u) << *Validate(o);
  o = {};
  o.model_window_s = -0.1;
  EXPECT_TRUE(Validate(o).has_value());
  o = {};
  o.edge_time_s = std::nan("");
  EXPECT_TRUE(Validate(o).has_value());
  o = {};
  o.model_fit_weight = -1.0;
  EXPECT_TRUE(Validate(o).has_value());
}

}  // namespace
}  // namespace lrfnet::calib
