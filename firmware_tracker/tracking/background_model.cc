#include "firmware_tracker/tracking/background_model.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>

namespace lrfnet::tracking {
namespace {

bool Positive(double v) { return std::isfinite(v) && v > 0.0; }
bool NonNegative(double v) { return std::isfinite(v) && v >= 0.0; }

}  // namespace

std::optional<std::string> Validate(const BackgroundOptions& o) {
  if (!NonNegative(o.learn_duration_s)) return "learn_duration_s must be >= 0";
  if (!NonNegative(o.min_range_m)) return "min_range_m must be >= 0";
  if (!Positive(o.max_range_m) || o.max_range_m <= o.min_range_m) {
    return "max_range_m must be finite and greater than min_range_m";
  }
  if (!NonNegative(o.base_margin_m) || !NonNegative(o.range_noise_m) ||
      !NonNegative(o.range_noise_per_m) || !NonNegative(o.noise_margin_k)) {
    return "base_margin_m, range_noise_m, range_noise_per_m and noise_margin_k must be >= 0";
  }
  if (!(o.base_margin_m > 0.0 || (o.noise_margin_k > 0.0 && o.range_noise_m > 0.0))) {
    return "the foreground margin must be positive at every range";
  }
  if (!Positive(o.absorb_after_s)) return "absorb_after_s must be > 0";
  if (!Positive(o.recede_after_s)) return "recede_after_s must be > 0";
  if (!Positive(o.track_time_constant_s)) return "track_time_constant_s must be > 0";
  if (!(o.free_fraction >= 0.0 && o.free_fraction <= 1.0)) return "free_fraction must be in [0, 1]";
  if (!Positive(o.max_scan_gap_s)) return "max_scan_gap_s must be > 0";
  return std::nullopt;
}

BackgroundModel::BackgroundModel(const BackgroundOptions& options) : options_(options) {
  if (Validate(options_)) std::abort();
}

void BackgroundModel::Reset() {
  learned_ = false;
  has_scan_ = false;
  learn_elapsed_s_ = 0.0;
  learn_scans_ = 0;
  beams_.clear();
  candidate_.clear();
  candidate_m_.clear();
  candidate_age_s_.clear();
  background_m_.clear();
  foreground_.clear();
}

double BackgroundModel::Margin(double range_m) const {
  return options_.base_margin_m +
         options_.noise_margin_k * (options_.range_noise_m + options_.range_noise_per_m * range_m);
}

std::size_t BackgroundModel::CountMovedBeams(std::span<const float> reference_m) const {
  const std::span<const float> now_m = background_m_.span();
  const std::size_t n = std::min(now_m.size(), reference_m.size());
  const double base = options_.base_margin_m, k = options_.noise_margin_k;
  const double noise = options_.range_noise_m, per_m = options_.range_noise_per_m;
  // Without branches (Margin's arithmetic, in the same order) and in blocks of a fixed length, so
  // that the compiler vectorises it: it runs on every scan once a snapshot may be sent again.
  const auto moved_at = [&](std::size_t i) {
    const float a = now_m[i];
    const float b = reference_m[i];
    const bool a_free = a == 0.0f;
    const bool b_free = b == 0.0f;
    const double diff = std::abs(static_cast<double>(a) - static_cast<double>(b));
    const double margin = base + k * (noise + per_m * static_cast<double>(std::min(a, b)));
    return static_cast<std::uint32_t>((a_free != b_free) | (!a_free & (diff > margin)));
  };
  constexpr std::size_t kBlock = 8;
  std::size_t moved = 0;
  std::size_t i = 0;
  for (; i + kBlock <= n; i += kBlock) {
    std::uint32_t block = 0;
    for (std::size_t j = 0; j < kBlock; ++j) block += moved_at(i + j);
    moved += block;
  }
  for (; i < n; ++i) moved += moved_at(i);
  return moved;
}

float BackgroundModel::Sanitize(float range_m) const {
  // 0 is the telegram's "no echo"; out-of-window and non-finite values are treated the same way.
  if (!std::isfinite(range_m) || range_m < options_.min_range_m || range_m > options_.max_range_m) {
    return 0.0f;
  }
  return range_m;
}

void BackgroundModel::StartLearning(const ScanView& scan) {
  const std::size_t n = scan.range_m.size();
  learned_ = false;
  learn_elapsed_s_ = 0.0;
  learn_scans_ = 0;
  first_angle_rad_ = scan.first_angle_rad;
  angle_step_rad_ = scan.angle_step_rad;
  // Capacity was checked by CheckScan; resize cannot fail here.
  (void)beams_.resize(0);
  (void)beams_.resize(n);
  (void)candidate_.resize(0);
  (void)candidate_.resize(n);
  (void)candidate_m_.resize(0);
  (void)candidate_m_.resize(n);
  (void)candidate_age_s_.resize(0);
  (void)candidate_age_s_.resize(n);
  (void)background_m_.resize(0);
  (void)background_m_.resize(n);
  (void)foreground_.resize(0);
  (void)foreground_.resize(n);
}

void BackgroundModel::Learn(std::size_t i, float r) {
  Beam& b = beams_[i];
  if (r == 0.0f) {
    ++b.no_echo_scans;
  } else {
    ++b.echo_scans;
    if (b.prev_m != 0.0f && std::abs(r - b.prev_m) <= Margin(r)) {
      b.learn_max_m = std::max(b.learn_max_m, std::min(r, b.prev_m));
    }
  }
  b.prev_m = r;
}

void BackgroundModel::FinishLearning() {
  for (std::size_t i = 0; i < beams_.size(); ++i) {
    Beam& b = beams_[i];
    const double total = static_cast<double>(b.echo_scans + b.no_echo_scans);
    const bool mostly_no_echo =
        static_cast<double>(b.no_echo_scans) > options_.free_fraction * total;
    background_m_[i] = mostly_no_echo ? 0.0f : b.learn_max_m;
    b = Beam{};
    candidate_[i] = Candidate::kNone;
    candidate_m_[i] = 0.0f;
    candidate_age_s_[i] = 0.0f;
  }
  learned_ = true;
}

bool BackgroundModel::UpdateBeam(std::size_t i, float r, float dt, double alpha) {
  float& bg = background_m_[i];
  const double margin = Margin(bg);
  const bool echo = r != 0.0f;
  // Classified against the model as it was before this scan.
  const bool fg = echo && (bg == 0.0f || r < bg - margin);
  const bool at_background = echo ? bg != 0.0f && std::abs(r - bg) <= margin : bg == 0.0f;
  Candidate& candidate = candidate_[i];
  if (at_background) {
    if (echo) bg += static_cast<float>(alpha * (r - bg));
    // The candidate's range and age are left: they are read only while candidate is not kNone,
    // and a beam leaves kNone only by a restart, which sets both.
    candidate = Candidate::kNone;
    return fg;
  }

  // A change candidate (a person's beams, mostly): its next state is selected from the outcomes
  // (follow, hold behind an occluder, restart; absorb or recede when old enough).
  float& candidate_m_ref = candidate_m_[i];
  float& candidate_age_s = candidate_age_s_[i];
  const bool nearer = echo && (bg == 0.0f || r < bg);
  const Candidate kind = nearer ? Candidate::kNearer : Candidate::kFarther;
  const float candidate_m = candidate_m_ref;
  const bool same_as_candidate =
      candidate == kind &&
      (echo ? candidate_m != 0.0f && std::abs(r - candidate_m) <= Margin(candidate_m)
            : candidate_m == 0.0f);
  // Something passes in front of a candidate static object: its clock holds, it does not restart.
  const bool holds =
      !same_as_candidate && nearer && candidate == Candidate::kNearer && r < candidate_m;
  const bool restarts = !same_as_candidate && !holds;
  const float followed_m = echo ? candidate_m + 0.5f * (r - candidate_m) : candidate_m;
  const float age_s = same_as_candidate ? candidate_age_s + dt : restarts ? 0.0f : candidate_age_s;
  const float new_m = same_as_candidate ? followed_m : restarts ? r : candidate_m;
  const Candidate new_candidate = restarts ? kind : candidate;
  const double limit_s = nearer ? options_.absorb_after_s : options_.recede_after_s;
  if (same_as_candidate && age_s >= limit_s) [[unlikely]] {
    bg = new_m;
    candidate = Candidate::kNone;
    candidate_m_ref = new_m;
    candidate_age_s = 0.0f;
    ++(nearer ? counters_.absorbed_beams : counters_.receded_beams);
    return fg;
  }
  candidate = new_candidate;
  candidate_m_ref = new_m;
  candidate_age_s = age_s;
  return fg;
}

void BackgroundModel::Absorb(const ScanView& scan, std::size_t begin_beam, std::size_t end_beam) {
  if (!learned_ || scan.range_m.size() != beams_.size() ||
      scan.first_angle_rad != first_angle_rad_ || scan.angle_step_rad != angle_step_rad_) {
    return;
  }
  end_beam = std::min(end_beam, beams_.size());
  std::size_t taken = 0;
  for (std::size_t i = begin_beam; i < end_beam; ++i) {
    const float r = Sanitize(scan.range_m[i]);
    const float bg = background_m_[i];
    if (r == 0.0f || !(bg == 0.0f || r < bg - Margin(bg))) continue;
    background_m_[i] = r;
    candidate_[i] = Candidate::kNone;
    candidate_age_s_[i] = 0.0f;
    ++taken;
  }
  counters_.absorbed_beams += taken;
  counters_.objects_absorbed += taken > 0 ? 1 : 0;
}

BackgroundResult BackgroundModel::Update(const ScanView& scan) {
  BackgroundResult result;
  result.scan_error = CheckScan(scan);
  if (result.scan_error != ScanError::kNone) {
    ++counters_.rejected_scans;
    result.learned = learned_;
    return result;
  }

  double dt_s = 0.0;
  const bool same_geometry = has_scan_ && scan.range_m.size() == beams_.size() &&
                             scan.first_angle_rad == first_angle_rad_ &&
                             scan.angle_step_rad == angle_step_rad_;
  if (!same_geometry) {
    if (has_scan_) {
      ++counters_.geometry_changes;
      result.relearn_started = true;
    }
    StartLearning(scan);
  } else {
    dt_s = common::NsToSeconds(scan.stamp_ns - last_stamp_ns_);
    if (dt_s < 0.0) {
      ++counters_.time_steps_backwards;
      dt_s = 0.0;
    }
    dt_s = std::min(dt_s, options_.max_scan_gap_s);
  }
  has_scan_ = true;
  last_stamp_ns_ = scan.stamp_ns;

  const std::size_t n = scan.range_m.size();
  if (!learned_) {
    learn_elapsed_s_ += dt_s;
    ++learn_scans_;
    for (std::size_t i = 0; i < n; ++i) {
      foreground_[i] = 0;
      Learn(i, Sanitize(scan.range_m[i]));
    }
    if (learn_elapsed_s_ >= options_.learn_duration_s && learn_scans_ >= 2) FinishLearning();
    return result;  // the scan that completes learning is not classified: the model was not ready
  }

  result.learned = true;
  // The background's tracking gain (track_time_constant_s) is the same for every beam of a scan.
  const double alpha = dt_s / (options_.track_time_constant_s + dt_s);
  const auto dt = static_cast<float>(dt_s);
  std::size_t foreground_beams = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const bool fg = UpdateBeam(i, Sanitize(scan.range_m[i]), dt, alpha);
    foreground_[i] = fg ? 1 : 0;
    foreground_beams += fg ? 1 : 0;
  }
  result.foreground_beams = foreground_beams;
  return result;
}

}  // namespace lrfnet::tracking
