#include "firmware_tracker/tracking/background_model.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <random>
#include <span>
#include <vector>

#include "firmware_tracker/tracking/tracking_test_util.h"

namespace lrfnet::tracking {
namespace {

using testing::Body;
using testing::Room;
using testing::SyntheticScanner;
using testing::Wall;

using testing::kRateHz;

std::int64_t Scans(double seconds) {
  return static_cast<std::int64_t>(std::lround(seconds * kRateHz));
}

// Runs scans [k_begin, k_end) of a fixed scene; returns the largest foreground count seen.
std::size_t RunScans(BackgroundModel& model, SyntheticScanner& scanner, std::int64_t k_begin,
                     std::int64_t k_end, const std::vector<Wall>& walls,
                     const std::vector<Body>& bodies) {
  std::size_t max_fg = 0;
  for (std::int64_t k = k_begin; k < k_end; ++k) {
    const BackgroundResult r = model.Update(scanner.Render(k, walls, bodies));
    EXPECT_EQ(r.scan_error, ScanError::kNone);
    max_fg = std::max(max_fg, r.foreground_beams);
  }
  return max_fg;
}

// Beams whose ray passes within `radius_m` of `p`.
std::vector<std::size_t> BeamsTowards(const SyntheticScanner& s, const Eigen::Vector2d& p,
                                      double radius_m) {
  std::vector<std::size_t> out;
  const double half = std::asin(radius_m / p.norm());
  const double centre = std::atan2(p.y(), p.x());
  for (std::size_t i = 0; i < s.config().beams; ++i) {
    if (std::abs(common::AngleDiff(s.BeamAngle(i), centre)) < half) out.push_back(i);
  }
  return out;
}

TEST(BackgroundOptionsTest, DefaultsValidAndBadValuesRejected) {
  EXPECT_EQ(Validate(BackgroundOptions{}), std::nullopt);
  BackgroundOptions o;
  o.max_range_m = 0.01;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.absorb_after_s = 0.0;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.base_margin_m = 0.0;
  o.range_noise_m = 0.0;
  EXPECT_NE(Validate(o), std::nullopt);
  o = {};
  o.free_fraction = 1.5;
  EXPECT_NE(Validate(o), std::nullopt);
}

TEST(BackgroundModelTest, LearnsWallsAndFreeBeamsDespiteSomeoneWalkingThrough) {
  SyntheticScanner scanner;
  BackgroundModel model(BackgroundOptions{});
  const auto room = Room();
  // A person crosses the room during the whole start-up period.
  for (std::int64_t k = 0; k < Scans(5.0) + 1; ++k) {
    const double t = static_cast<double>(k) / kRateHz;
    const std::vector<Body> person = {{{3.0, -3.0 + 1.2 * t}, 0.25, 0.15, 0.0}};
    const BackgroundResult r = model.Update(scanner.Render(k, room, person));
    EXPECT_EQ(r.foreground_beams, 0u);
  }
  ASSERT_TRUE(model.learned());
  const std::vector<Body> none;
  SyntheticScanner noiseless({.noise_sigma_m = 0.0});
  const ScanView clean = noiseless.Render(0, room, none);
  const auto bg = model.background_range_m();
  ASSERT_EQ(bg.size(), clean.range_m.size());
  std::size_t free_beams = 0;
  for (std::size_t i = 0; i < bg.size(); ++i) {
    if (clean.range_m[i] == 0.0f) {
      EXPECT_EQ(bg[i], 0.0f) << "beam " << i << " looks through the opening";
      ++free_beams;
    } else {
      EXPECT_NEAR(bg[i], clean.range_m[i], 0.05) << "beam " << i;
    }
  }
  EXPECT_GT(free_beams, 10u);
}

TEST(BackgroundModelTest, NoiseOnlyGivesNoForeground) {
  SyntheticScanner scanner({.noise_sigma_m = 0.02, .seed = 7});
  BackgroundModel model(BackgroundOptions{});
  const auto room = Room();
  RunScans(model, scanner, 0, Scans(5.0) + 1, room, {});
  ASSERT_TRUE(model.learned());
  EXPECT_EQ(RunScans(model, scanner, Scans(5.0) + 1, Scans(65.0), room, {}), 0u);
  EXPECT_EQ(model.counters().absorbed_beams, 0u);
}

TEST(BackgroundModelTest, NoForegroundWhileLearning) {
  SyntheticScanner scanner;
  BackgroundModel model(BackgroundOptions{});
  const auto room = Room();
  const std::vector<Body> person = {{{3.0, 0.0}, 0.25, 0.15, 0.0}};
  const BackgroundResult r = model.Update(scanner.Render(0, room, person));
  EXPECT_FALSE(r.learned);
  EXPECT_EQ(r.foreground_beams, 0u);
}

TEST(BackgroundModelTest, PersonInFrontOfLearnedWallIsForeground) {
  SyntheticScanner scanner;
  BackgroundModel model(BackgroundOptions{});
  const auto room = Room();
  RunScans(model, scanner, 0, Scans(6.0), room, {});
  const Eigen::Vector2d at(4.0, -2.0);
  const BackgroundResult r =
      model.Update(scanner.Render(Scans(6.0), room, std::vector<Body>{{at, 0.25, 0.15, 0.0}}));
  ASSERT_TRUE(r.learned);
  const auto beams = BeamsTowards(scanner, at, 0.12);
  ASSERT_FALSE(beams.empty());
  for (std::size_t i : beams) EXPECT_EQ(model.foreground()[i], 1) << "beam " << i;
  EXPECT_LE(r.foreground_beams, BeamsTowards(scanner, at, 0.3).size());
}

TEST(BackgroundModelTest, DoorOpeningRecedesBackgroundThenReveals) {
  SyntheticScanner scanner;
  BackgroundOptions options;
  BackgroundModel model(options);
  auto closed = Room();
  closed.push_back({{3.0, -1.0}, {3.0, 0.0}});  // a door 3 m ahead, in front of the wall at 8 m
  const auto open = Room();
  RunScans(model, scanner, 0, Scans(6.0), closed, {});
  const auto door_beams = BeamsTowards(scanner, {3.0, -0.5}, 0.4);
  ASSERT_FALSE(door_beams.empty());
  for (std::size_t i : door_beams)
    ASSERT_NEAR(model.background_range_m()[i], 3.0 / std::cos(scanner.BeamAngle(i)), 0.05);

  // Opening reveals farther ranges: never foreground, and the background follows after
  // recede_after_s.
  std::int64_t k = Scans(6.0);
  EXPECT_EQ(RunScans(model, scanner, k, k + Scans(options.recede_after_s + 0.5), open, {}), 0u);
  k += Scans(options.recede_after_s + 0.5);
  for (std::size_t i : door_beams) {
    EXPECT_NEAR(model.background_range_m()[i], 8.0 / std::cos(scanner.BeamAngle(i)), 0.1);
  }
  EXPECT_GE(model.counters().receded_beams, door_beams.size());

  // Someone walking in the doorway at 6 m is now foreground (behind the old door range).
  const Eigen::Vector2d at(6.0, -0.5);
  const BackgroundResult r =
      model.Update(scanner.Render(k, open, std::vector<Body>{{at, 0.25, 0.15, 0.0}}));
  EXPECT_GT(r.foreground_beams, 3u);
  for (std::size_t i : BeamsTowards(scanner, at, 0.1)) EXPECT_EQ(model.foreground()[i], 1);
}

TEST(BackgroundModelTest, CountMovedBeamsAgainstAnEarlierBackground) {
  SyntheticScanner scanner;
  BackgroundModel model(BackgroundOptions{});
  RunScans(model, scanner, 0, Scans(6.0), Room(), {});
  const std::span<const float> now = model.background_range_m();
  ASSERT_GT(now.size(), 100u);
  std::vector<float> ref(now.begin(), now.end());
  EXPECT_EQ(model.CountMovedBeams(ref), 0u);
  // Moves just within and just beyond each beam's margin, beams becoming free and taken, both
  // free: the count is the beams beyond the margin of the nearer range or of another freeness.
  std::size_t expected = 0;
  std::size_t free_both = 0;
  for (std::size_t i = 0; i < ref.size(); ++i) {
    const float a = now[i];
    switch (i % 6) {
      case 0:  // nearer by half the margin: within it
        if (a != 0.0f) ref[i] = a - static_cast<float>(0.5 * model.Margin(a));
        break;
      case 1:  // farther by more than the margin
        if (a != 0.0f) {
          ref[i] = a + static_cast<float>(1.1 * model.Margin(a));
          ++expected;
        }
        break;
      case 2:  // free in the reference only
        if (a != 0.0f) {
          ref[i] = 0.0f;
          ++expected;
        }
        break;
      case 3:  // taken in the reference only
        if (a == 0.0f) {
          ref[i] = 5.0f;
          ++expected;
        }
        break;
      default:
        free_both += a == 0.0f ? 1 : 0;
        break;
    }
  }
  ASSERT_GT(expected, 50u);
  ASSERT_GT(free_both, 0u);  // the room's open side: free in both, not moved
  // The count agrees with the rule written beam by beam.
  std::size_t by_rule = 0;
  for (std::size_t i = 0; i < ref.size(); ++i) {
    const float a = now[i], b = ref[i];
    if ((a == 0.0f) != (b == 0.0f)) {
      ++by_rule;
    } else if (a != 0.0f && std::abs(static_cast<double>(a) - static_cast<double>(b)) >
                                model.Margin(std::min(a, b))) {
      ++by_rule;
    }
  }
  EXPECT_EQ(by_rule, expected);
  EXPECT_EQ(model.CountMovedBeams(ref), expected);
}

TEST(BackgroundModelTest, ParkedCartIsAbsorbedAfterTimeConstant) {
  SyntheticScanner scanner;
  BackgroundOptions options;
  BackgroundModel model(options);
  const auto room = Room();
  RunScans(model, scanner, 0, Scans(6.0), room, {});
  const std::vector<Body> cart = {{{4.0, 2.0}, 0.4, 0.3, 0.5}};
  std::int64_t k = Scans(6.0);
  // Still foreground shortly before absorb_after_s ...
  const std::int64_t before = Scans(options.absorb_after_s - 1.0);
  RunScans(model, scanner, k, k + before, room, cart);
  k += before;
  EXPECT_GT(model.Update(scanner.Render(k++, room, cart)).foreground_beams, 5u);
  // ... and background shortly after it.
  RunScans(model, scanner, k, k + Scans(2.0), room, cart);
  k += Scans(2.0);
  EXPECT_EQ(model.Update(scanner.Render(k++, room, cart)).foreground_beams, 0u);
  EXPECT_GT(model.counters().absorbed_beams, 5u);
  // When the cart leaves, the wall behind it comes back as background without foreground.
  EXPECT_EQ(RunScans(model, scanner, k, k + Scans(options.recede_after_s + 1.0), room, {}), 0u);
  const std::vector<Body> none;
  SyntheticScanner noiseless({.noise_sigma_m = 0.0});
  const ScanView clean = noiseless.Render(0, room, none);
  for (std::size_t i : BeamsTowards(scanner, {4.0, 2.0}, 0.2)) {
    EXPECT_NEAR(model.background_range_m()[i], clean.range_m[i], 0.1);
  }
}

TEST(BackgroundModelTest, CartsClockHoldsWhileSomeonePassesInFront) {
  SyntheticScanner scanner;
  BackgroundOptions options;
  BackgroundModel model(options);
  const auto room = Room();
  RunScans(model, scanner, 0, Scans(6.0), room, {});
  // A cart parked at (4, 2); for 2 s of its absorb_after_s a person stands on the same rays at
  // (2, 1), across them. The cart's clock holds meanwhile (it neither runs nor restarts).
  const std::vector<Body> cart = {{{4.0, 2.0}, 0.4, 0.3, 0.5}};
  std::vector<Body> both = cart;
  both.push_back({{2.0, 1.0}, 0.25, 0.15, 0.46 + 1.57});
  std::int64_t k = Scans(6.0);
  const auto run = [&](double seconds, const std::vector<Body>& bodies) {
    RunScans(model, scanner, k, k + Scans(seconds), room, bodies);
    k += Scans(seconds);
  };
  run(options.absorb_after_s - 3.0, cart);
  run(2.0, both);
  // Had the clock run on, the cart would be background here; had it restarted, 27 s from now.
  run(2.0, cart);
  EXPECT_GT(model.Update(scanner.Render(k++, room, cart)).foreground_beams, 5u);
  run(1.5, cart);
  EXPECT_EQ(model.Update(scanner.Render(k++, room, cart)).foreground_beams, 0u);
  EXPECT_GT(model.counters().absorbed_beams, 5u);
}

TEST(BackgroundModelTest, PersonStandingStillForSecondsIsNotAbsorbed) {
  SyntheticScanner scanner;
  BackgroundModel model(BackgroundOptions{});
  const auto room = Room();
  RunScans(model, scanner, 0, Scans(6.0), room, {});
  const Eigen::Vector2d at(3.0, 1.0);
  std::int64_t k = Scans(6.0);
  for (int i = 0; i < Scans(8.0); ++i, ++k) {
    // Standing, but swaying by a centimetre or two.
    const Eigen::Vector2d sway(0.015 * std::sin(0.7 * static_cast<double>(i)), 0.0);
    const BackgroundResult r =
        model.Update(scanner.Render(k, room, std::vector<Body>{{at + sway, 0.25, 0.15, 1.5}}));
    ASSERT_GT(r.foreground_beams, 5u) << "scan " << i;
  }
  EXPECT_EQ(model.counters().absorbed_beams, 0u);
  EXPECT_EQ(RunScans(model, scanner, k, k + Scans(2.0), room, {}), 0u);
}

TEST(BackgroundModelTest, BadScanRejectedAndGeometryChangeRelearns) {
  SyntheticScanner scanner;
  BackgroundModel model(BackgroundOptions{});
  const auto room = Room();
  RunScans(model, scanner, 0, Scans(6.0), room, {});
  ASSERT_TRUE(model.learned());

  ScanView bad = scanner.Render(Scans(6.0), room, {});
  bad.angle_step_rad = std::nan("");
  EXPECT_EQ(model.Update(bad).scan_error, ScanError::kBadAngles);
  bad.range_m = {};
  EXPECT_EQ(model.Update(bad).scan_error, ScanError::kEmpty);
  EXPECT_EQ(model.counters().rejected_scans, 2u);
  EXPECT_TRUE(model.learned());

  ScanView shorter = scanner.Render(Scans(6.0), room, {});
  shorter.range_m = shorter.range_m.first(300);
  const BackgroundResult r = model.Update(shorter);
  EXPECT_TRUE(r.relearn_started);
  EXPECT_FALSE(model.learned());
  EXPECT_EQ(model.counters().geometry_changes, 1u);
}

TEST(BackgroundModelTest, TimeGoingBackwardsIsCountedNotFatal) {
  SyntheticScanner scanner;
  BackgroundModel model(BackgroundOptions{});
  const auto room = Room();
  RunScans(model, scanner, 0, Scans(6.0), room, {});
  EXPECT_EQ(model.Update(scanner.Render(10, room, {})).foreground_beams, 0u);
  EXPECT_EQ(model.counters().time_steps_backwards, 1u);
}

// The per-beam update after learning, written out plainly (one struct per beam, every outcome of a
// change candidate by ternaries), against which the model's per-scan pass is checked bit for bit
// when it is made faster. Learning is done by the model; this reference starts from its learned
// background.
class ReferenceBeams {
 public:
  ReferenceBeams(const BackgroundOptions& o, std::span<const float> learned)
      : o_(o), bg_(learned.begin(), learned.end()), beams_(learned.size()) {}

  double Margin(double range_m) const {
    return o_.base_margin_m +
           o_.noise_margin_k * (o_.range_noise_m + o_.range_noise_per_m * range_m);
  }

  // One scan of sanitised returns (0 = no echo), dt seconds after the last.
  std::vector<std::uint8_t> Update(std::span<const float> ranges, double dt_s) {
    const double alpha = dt_s / (o_.track_time_constant_s + dt_s);
    const auto dt = static_cast<float>(dt_s);
    std::vector<std::uint8_t> fg_out(ranges.size());
    for (std::size_t i = 0; i < ranges.size(); ++i) {
      const float r = ranges[i];
      float& bg = bg_[i];
      Beam& b = beams_[i];
      const double margin = Margin(bg);
      const bool echo = r != 0.0f;
      fg_out[i] = echo && (bg == 0.0f || r < bg - margin) ? 1 : 0;
      const bool at_background = echo ? bg != 0.0f && std::abs(r - bg) <= margin : bg == 0.0f;
      if (at_background) {
        if (echo) bg += static_cast<float>(alpha * (r - bg));
        b.candidate = 0;
        b.age_s = 0.0f;
        continue;
      }
      const bool nearer = echo && (bg == 0.0f || r < bg);
      const int kind = nearer ? 1 : 2;
      const float cm = b.m;
      const bool same =
          b.candidate == kind && (echo ? cm != 0.0f && std::abs(r - cm) <= Margin(cm) : cm == 0.0f);
      const bool holds = !same && nearer && b.candidate == 1 && r < cm;
      const bool restarts = !same && !holds;
      const float followed_m = echo ? cm + 0.5f * (r - cm) : cm;
      const float age_s = same ? b.age_s + dt : restarts ? 0.0f : b.age_s;
      const float new_m = same ? followed_m : restarts ? r : cm;
      const int new_candidate = restarts ? kind : b.candidate;
      const double limit_s = nearer ? o_.absorb_after_s : o_.recede_after_s;
      if (same && age_s >= limit_s) {
        bg = new_m;
        b = Beam{0, new_m, 0.0f};
        ++(nearer ? absorbed : receded);
        continue;
      }
      b = Beam{new_candidate, new_m, age_s};
    }
    return fg_out;
  }

  std::span<const float> background_m() const { return bg_; }
  std::uint64_t absorbed = 0;
  std::uint64_t receded = 0;

 private:
  struct Beam {
    int candidate = 0;  // 0 none, 1 nearer, 2 farther
    float m = 0.0f;
    float age_s = 0.0f;
  };
  BackgroundOptions o_;
  std::vector<float> bg_;
  std::vector<Beam> beams_;
};

TEST(BackgroundModelTest, CandidateOutcomesMatchThePerBeamReferenceBitForBit) {
  // Short absorb and recede times, so that every outcome of a change candidate occurs many times:
  // people passing (restarts), an object standing long enough to be absorbed, something passing in
  // front of it (holds), a wall's beam losing its echo or returning farther (recedes), free beams.
  BackgroundOptions o;
  o.learn_duration_s = 0.2;
  o.absorb_after_s = 0.6;
  o.recede_after_s = 0.3;
  BackgroundModel model(o);
  constexpr std::size_t kBeams = 96;
  constexpr double kDt = 0.04;
  std::mt19937 rng(7);
  std::normal_distribution<float> noise(0.0f, 0.01f);
  std::uniform_real_distribution<float> uniform(0.0f, 1.0f);
  std::vector<float> wall(kBeams);
  for (std::size_t i = 0; i < kBeams; ++i)
    wall[i] = i % 16 == 15 ? 0.0f : 3.0f + 0.05f * static_cast<float>(i);
  std::vector<float> ranges(kBeams);
  ScanView scan;
  scan.first_angle_rad = -1.0;
  scan.angle_step_rad = 0.01;
  scan.scan_period_s = kDt;
  scan.range_m = ranges;
  std::int64_t k = 0;
  const auto stamp = [&](std::int64_t n) { return static_cast<common::UtcNs>(n * 40'000'000); };
  while (!model.learned()) {
    for (std::size_t i = 0; i < kBeams; ++i)
      ranges[i] = wall[i] == 0.0f ? 0.0f : wall[i] + noise(rng);
    scan.stamp_ns = stamp(k++);
    ASSERT_EQ(model.Update(scan).scan_error, ScanError::kNone);
  }
  ReferenceBeams reference(o, model.background_range_m());
  // Per beam, a piecewise scene: what the beam sees and for how many more scans.
  enum Sees { kWall, kPerson, kObject, kNoEcho, kFarther };
  std::vector<Sees> sees(kBeams, kWall);
  std::vector<int> left(kBeams, 0);
  std::vector<float> object_m(kBeams, 0.0f);
  std::size_t candidates_seen = 0;
  for (int scan_index = 0; scan_index < 3000; ++scan_index) {
    for (std::size_t i = 0; i < kBeams; ++i) {
      if (left[i]-- <= 0) {
        const float u = uniform(rng);
        sees[i] = u < 0.4f    ? kWall
                  : u < 0.7f  ? kPerson
                  : u < 0.85f ? kObject
                  : u < 0.93f ? kNoEcho
                              : kFarther;
        left[i] = 1 + static_cast<int>(uniform(rng) * (sees[i] == kObject ? 40.0f : 12.0f));
        object_m[i] = 0.5f + 2.0f * uniform(rng);
      }
      float r = 0.0f;
      switch (sees[i]) {
        case kWall:
          r = wall[i] == 0.0f ? 0.0f : wall[i] + noise(rng);
          break;
        // A person moves along the beam by up to 20 cm a scan, sometimes in front of an object.
        case kPerson:
          r = 0.4f + 2.5f * uniform(rng);
          break;
        case kObject:
          r = uniform(rng) < 0.1f ? 0.3f + 0.1f * uniform(rng) : object_m[i] + noise(rng);
          break;
        case kNoEcho:
          r = 0.0f;
          break;
        case kFarther:
          r = (wall[i] == 0.0f ? 10.0f : wall[i] + 1.0f) + noise(rng);
          break;
      }
      ranges[i] = r;
    }
    scan.stamp_ns = stamp(k++);
    const BackgroundResult result = model.Update(scan);
    ASSERT_TRUE(result.learned);
    const std::vector<std::uint8_t> fg = reference.Update(ranges, kDt);
    candidates_seen += result.foreground_beams;
    for (std::size_t i = 0; i < kBeams; ++i) {
      ASSERT_EQ(model.foreground()[i], fg[i]) << "scan " << scan_index << " beam " << i;
      ASSERT_EQ(std::bit_cast<std::uint32_t>(model.background_range_m()[i]),
                std::bit_cast<std::uint32_t>(reference.background_m()[i]))
          << "scan " << scan_index << " beam " << i;
    }
  }
  EXPECT_EQ(model.counters().absorbed_beams, reference.absorbed);
  EXPECT_EQ(model.counters().receded_beams, reference.receded);
  // Every outcome occurred often.
  EXPECT_GT(reference.absorbed, 200u);
  EXPECT_GT(reference.receded, 200u);
  EXPECT_GT(candidates_seen, 50'000u);
}

}  // namespace
}  // namespace lrfnet::tracking
