#include "common/mount_check.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <vector>

namespace lrfnet::common {
namespace {

// Five people walking at knee height are seen as leg-sized tracks: once they end (a scan without
// them), the verdict turns to legs, reported once; upper-body widths never do.
TEST(MountWatchTest, WalkingLegSizedTracksTurnTheVerdictOnce) {
  for (const double half_width_m : {0.05, 0.22}) {
    MountWatch<8, 16> watch;
    int turned = 0;
    for (std::uint32_t id = 1; id <= 5; ++id) {
      for (int scan = 0; scan < 30; ++scan) {
        watch.Add(id, 1.2, half_width_m);
        turned += watch.EndScan() ? 1 : 0;
      }
    }
    turned += watch.EndScan() ? 1 : 0;  // the last one ends
    const bool legs = half_width_m < 0.09;
    EXPECT_EQ(watch.verdict().tracks, 5u) << half_width_m;
    EXPECT_EQ(watch.verdict().looks_like_legs, legs) << half_width_m;
    EXPECT_EQ(turned, legs ? 1 : 0) << half_width_m;
  }
}

// The same rule written plainly (a search over every live track by id each time), against which
// MountWatch's lookup (the track after the last one found first) must give the same verdict after
// every scan, whatever order the ids come in, with tracks ending, starting and beyond capacity.
class PlainWatch {
 public:
  explicit PlainWatch(std::size_t capacity, std::size_t history)
      : capacity_(capacity), history_(history) {}

  void Add(std::uint32_t id, double speed_mps, double half_width_m) {
    auto it = std::find_if(live_.begin(), live_.end(), [&](const Live& l) { return l.id == id; });
    if (it == live_.end()) {
      if (live_.size() == capacity_) return;
      live_.push_back(Live{id});
      it = live_.end() - 1;
    }
    it->seen = true;
    if (!(speed_mps > options_.min_speed_mps) || it->filed) return;
    it->sum_m += half_width_m;
    if (++it->states == MountWatch<1, 1>::kLongTrackStates) File(*it);
  }

  void EndScan() {
    std::vector<Live> kept;
    for (Live& l : live_) {
      if (!l.seen) {
        if (!l.filed) File(l);
        continue;
      }
      l.seen = false;
      kept.push_back(l);
    }
    live_ = kept;
  }

  MountCheck verdict() const {
    std::vector<double> copy = filed_;
    return CheckUpperBodyMount(copy, options_);
  }

 private:
  struct Live {
    std::uint32_t id = 0;
    std::size_t states = 0;
    double sum_m = 0.0;
    bool seen = false;
    bool filed = false;
  };
  void File(Live& l) {
    l.filed = true;
    if (l.states < options_.min_states) return;
    filed_.push_back(l.sum_m / static_cast<double>(l.states));
    if (filed_.size() > history_) filed_.erase(filed_.begin());
  }

  MountCheckOptions options_;
  std::size_t capacity_, history_;
  std::vector<Live> live_;
  std::vector<double> filed_;
};

TEST(MountWatchTest, LookupGivesTheVerdictOfAPlainSearchInEveryOrder) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  MountWatch<6, 9> watch;
  PlainWatch plain(6, 9);
  std::vector<std::uint32_t> alive;
  std::uint32_t next_id = 1;
  int legs_verdicts = 0;
  for (int scan = 0; scan < 4000; ++scan) {
    // Tracks end and start (ids never reused), sometimes more than the watch holds.
    std::erase_if(alive, [&](std::uint32_t) { return unit(rng) < 0.01; });
    while (alive.size() < 8 && unit(rng) < 0.05) alive.push_back(next_id++);
    std::vector<std::uint32_t> order = alive;
    if (unit(rng) < 0.3) std::shuffle(order.begin(), order.end(), rng);
    for (const std::uint32_t id : order) {
      if (unit(rng) < 0.05) continue;  // not reported this scan (coasting, a box): ends it here
      const double speed_mps = unit(rng) < 0.8 ? 1.2 : 0.1;
      const double half_width_m = (id % 3 == 0 ? 0.05 : 0.2) + 0.02 * unit(rng);
      watch.Add(id, speed_mps, half_width_m);
      plain.Add(id, speed_mps, half_width_m);
    }
    watch.EndScan();
    plain.EndScan();
    const MountCheck a = watch.verdict(), b = plain.verdict();
    ASSERT_EQ(a.tracks, b.tracks) << scan;
    ASSERT_EQ(a.leg_sized, b.leg_sized) << scan;
    ASSERT_DOUBLE_EQ(a.median_half_width_m, b.median_half_width_m) << scan;
    ASSERT_EQ(a.looks_like_legs, b.looks_like_legs) << scan;
    legs_verdicts += a.looks_like_legs ? 1 : 0;
  }
  // Both verdicts occurred (a third of the ids leg-sized: around the 30 % share).
  EXPECT_GT(legs_verdicts, 0);
  EXPECT_LT(legs_verdicts, 4000);
}

}  // namespace
}  // namespace lrfnet::common
