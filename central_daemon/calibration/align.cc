#include "central_daemon/calibration/align.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <limits>
#include <unordered_map>
#include <utility>

#include "central_daemon/calibration/rts.h"

namespace lrfnet::calib {
namespace {

using common::UtcNs;
using daemon::TrackState;

// One usable observation: a track's filtered state in one frame (24 bytes: sorted and copied).
struct Record {
  UtcNs t_ns = 0;
  const daemon::TrackObservation* obs = nullptr;  // in the input, which outlives Align
  std::uint32_t frame = 0;                        // index into the sensor's frames
  std::uint32_t slot = 0;  // index of the track (session_id, track_id) within its sensor
};

struct TrackKey {
  std::uint64_t session_id = 0;
  std::uint32_t track_id = 0;
  bool operator==(const TrackKey&) const = default;
};

struct TrackKeyHash {
  std::size_t operator()(const TrackKey& k) const {
    return std::hash<std::uint64_t>{}((k.session_id * 0x9E3779B97F4A7C15ull) ^ k.track_id);
  }
};

// A run [begin, end) of SensorWork::sorted: one track piece without gaps.
struct Piece {
  std::size_t begin = 0;
  std::size_t end = 0;
};

struct SensorWork {
  std::vector<Record> records;  // usable observations, input order
  std::vector<TrackKey> keys;   // per slot
  std::vector<Record> sorted;   // by (slot, time), deduplicated and trimmed
  std::vector<Piece> pieces;
};

// Scratch reused across pieces so sampling does not allocate per piece or sample.
struct PieceScratch {
  std::vector<FilteredState> states;
  std::vector<UtcNs> times_ns;
};

bool Finite(double v) { return std::isfinite(v); }

Eigen::Matrix4d CovarianceOf(const daemon::TrackObservation& o) {
  // Upper triangle, row-major (sensor_data.h / lrfnet.proto).
  Eigen::Matrix4d p;
  std::size_t n = 0;
  for (int row = 0; row < 4; ++row) {
    for (int col = row; col < 4; ++col) {
      p(row, col) = p(col, row) = static_cast<double>(o.covariance[n++]);
    }
  }
  return p;
}

Eigen::Vector4d StateOf(const daemon::TrackObservation& o) {
  return {static_cast<double>(o.x_m), static_cast<double>(o.y_m), static_cast<double>(o.vx_mps),
          static_cast<double>(o.vy_mps)};
}

bool Usable(const daemon::TrackObservation& o) {
  const Eigen::Vector4d x = StateOf(o);
  if (!x.allFinite()) return false;
  if (std::abs(x(0)) > kMaxAbsPosition_m || std::abs(x(1)) > kMaxAbsPosition_m) return false;
  if (std::abs(x(2)) > kMaxAbsVelocity_mps || std::abs(x(3)) > kMaxAbsVelocity_mps) return false;
  const Eigen::Matrix4d p = CovarianceOf(o);
  if (!p.allFinite()) return false;
  for (int i = 0; i < 4; ++i) {
    if (!(p(i, i) >= 0.0 && p(i, i) <= kMaxVariance)) return false;
  }
  // PSD up to the rounding of the floats on the wire (relative 6e-8 per entry).
  const double tolerance = 1e-6 * p.diagonal().maxCoeff() + 1e-12;
  return Ldlt4(p + tolerance * Eigen::Matrix4d::Identity()).ok();
}

bool UsableTime(UtcNs t_ns) { return t_ns >= 0 && t_ns <= kMaxTimeNs; }

// The 2x2 position covariance, symmetrised, with both eigenvalues raised to at least min_var.
Eigen::Matrix2d FlooredPositionCovariance(const Eigen::Matrix4d& p, double min_var) {
  const double a = p(0, 0), d = p(1, 1), b = 0.5 * (p(0, 1) + p(1, 0));
  const double half_trace = 0.5 * (a + d);
  const double radius = std::hypot(0.5 * (a - d), b);
  const double small = half_trace - radius, large = half_trace + radius;
  Eigen::Matrix2d c;
  c << a, b, b, d;
  if (small >= min_var) return c;
  // Rebuild from the eigen-decomposition; theta is the direction of the large eigenvalue.
  const double theta = 0.5 * std::atan2(2.0 * b, a - d);
  const Eigen::Vector2d v_large(std::cos(theta), std::sin(theta));
  const Eigen::Vector2d v_small(-v_large.y(), v_large.x());
  c = std::max(large, min_var) * v_large * v_large.transpose() +
      std::max(small, min_var) * v_small * v_small.transpose();
  return 0.5 * (c + c.transpose());
}

// Records of one sensor (phase 1): usable observations in input order, one slot per track.
void Collect(const SensorRecording& sensor, const AlignOptions& options, SensorWork* work,
             AlignSensorStats* st) {
  std::unordered_map<TrackKey, std::uint32_t, TrackKeyHash> slot_of;
  constexpr std::size_t kRecentSlots = 64;
  std::vector<std::uint32_t> recent;  // slot of the track at position i of the last frame
  std::size_t total = 0;
  for (const auto& frame : sensor.frames) total += frame.tracks.size();
  work->records.reserve(total);
  bool has_previous = false;
  UtcNs previous_ns = 0;
  // Frame indices are 32 bits: more than 2^32 - 1 frames (hundreds of GiB) cannot be held anyway.
  const std::size_t frames = std::min<std::size_t>(sensor.frames.size(), UINT32_MAX);
  for (std::size_t f = 0; f < frames; ++f) {
    const daemon::TrackFrameData& frame = sensor.frames[f];
    ++st->frames;
    if (has_previous && frame.scan_start_ns < previous_ns) ++st->unordered_frames;
    has_previous = true;
    previous_ns = frame.scan_start_ns;
    const bool time_ok = UsableTime(frame.scan_start_ns);
    for (std::size_t i = 0; i < frame.tracks.size(); ++i) {
      const daemon::TrackObservation& o = frame.tracks[i];
      ++st->observations;
      if (o.state == TrackState::kTentative && !options.include_tentative) {
        ++st->tentative_skipped;
        continue;
      }
      if (!time_ok || !Usable(o)) {
        ++st->invalid;
        continue;
      }
      const TrackKey key{frame.session_id, o.track_id};
      // Tracks persist from scan to scan, usually in the same order: try the slot of the same
      // position in the previous frame before the hash map.
      std::uint32_t slot = 0;
      if (i < recent.size() && work->keys[recent[i]] == key) {
        slot = recent[i];
      } else {
        const auto [it, inserted] =
            slot_of.try_emplace(key, static_cast<std::uint32_t>(work->keys.size()));
        if (inserted) work->keys.push_back(key);
        slot = it->second;
      }
      if (i < kRecentSlots) {
        if (recent.size() <= i) recent.resize(i + 1);
        recent[i] = slot;
      }
      work->records.push_back(Record{frame.scan_start_ns, &o, static_cast<std::uint32_t>(f), slot});
    }
  }
}

// The window of at most span_ns holding the most records of all sensors (phase 2, only when the
// records span more than the grid may). Returns [from_ns, to_ns].
std::pair<UtcNs, UtcNs> BestWindow(const std::vector<SensorWork>& work, UtcNs span_ns) {
  std::vector<UtcNs> times;
  for (const SensorWork& w : work) {
    for (const Record& r : w.records) times.push_back(r.t_ns);
  }
  std::sort(times.begin(), times.end());
  std::size_t best_begin = 0, best_count = 0;
  std::size_t j = 0;
  for (std::size_t i = 0; i < times.size(); ++i) {
    if (j < i) j = i;
    while (j + 1 < times.size() && times[j + 1] - times[i] <= span_ns) ++j;
    if (j - i + 1 > best_count) {
      best_count = j - i + 1;
      best_begin = i;
    }
  }
  return {times[best_begin], times[best_begin] + span_ns};
}

// Phase 3: sorts one sensor's records by (track, time), drops duplicates and coasting tails, and
// cuts the tracks into pieces at gaps.
void BuildPieces(const AlignOptions& options, SensorWork* work, AlignSensorStats* st) {
  const std::size_t slots = work->keys.size();
  // Counting sort by slot: stable, so each track's records stay in input order.
  std::vector<std::size_t> offset(slots + 1, 0);
  for (const Record& r : work->records) ++offset[r.slot + 1];
  for (std::size_t s = 0; s < slots; ++s) offset[s + 1] += offset[s];
  work->sorted.resize(work->records.size());
  {
    std::vector<std::size_t> next(offset.begin(), offset.end() - 1);
    for (const Record& r : work->records) work->sorted[next[r.slot]++] = r;
  }
  const auto by_time = [](const Record& a, const Record& b) { return a.t_ns < b.t_ns; };
  const UtcNs max_gap_ns = common::SecondsToNs(options.max_gap_s);
  const UtcNs min_duration_ns = common::SecondsToNs(options.min_track_duration_s);
  std::size_t write = 0;
  for (std::size_t s = 0; s < slots; ++s) {
    const auto begin = work->sorted.begin() + static_cast<std::ptrdiff_t>(offset[s]);
    const auto end = work->sorted.begin() + static_cast<std::ptrdiff_t>(offset[s + 1]);
    // Stable: among states of the same time the first received is kept.
    if (!std::is_sorted(begin, end, by_time)) std::stable_sort(begin, end, by_time);
    const std::size_t track_begin = write;
    for (auto it = begin; it != end; ++it) {
      if (write > track_begin && work->sorted[write - 1].t_ns == it->t_ns) {
        ++st->duplicates;
        continue;
      }
      work->sorted[write++] = *it;
    }
    if (options.trim_coasting_tail) {
      while (write > track_begin && work->sorted[write - 1].obs->state == TrackState::kCoasting) {
        --write;
        ++st->coasting_trimmed;
      }
    }
    std::size_t piece_begin = track_begin;
    for (std::size_t i = track_begin; i < write; ++i) {
      const bool last = i + 1 == write;
      if (!last && work->sorted[i + 1].t_ns - work->sorted[i].t_ns <= max_gap_ns) continue;
      if (!last) ++st->gaps_split;
      const Piece piece{piece_begin, i + 1};
      if (work->sorted[i].t_ns - work->sorted[piece_begin].t_ns >= min_duration_ns) {
        work->pieces.push_back(piece);
      } else {
        ++st->short_pieces;
        st->short_piece_states += piece.end - piece.begin;
      }
      piece_begin = i + 1;
    }
  }
  work->sorted.resize(write);
}

// Fills a piece's grid samples: those strictly inside interval k from the interval
// (RtsInterpolate), those at a state's own time from the state. Every grid step in [first, last]
// state time is one of the two.
class GridSampler final : public RtsIntervalSink {
 public:
  GridSampler(const std::vector<UtcNs>& times_ns, UtcNs t0_ns, UtcNs step_ns, UtcNs first_step,
              double accel_psd_m2ps3, double min_var, std::vector<TrackSample>* samples)
      : times_ns_(times_ns),
        t0_ns_(t0_ns),
        step_ns_(step_ns),
        first_step_(first_step),
        q_(accel_psd_m2ps3),
        min_var_(min_var),
        samples_(samples) {}

  bool Wants(std::size_t k) override { return TimeOf(FirstStepAfter(k)) < times_ns_[k + 1]; }

  void Take(std::size_t k, const RtsInterval& interval) override {
    for (UtcNs step = FirstStepAfter(k); TimeOf(step) < times_ns_[k + 1]; ++step) {
      Fill(step, RtsInterpolate(interval, common::NsToSeconds(TimeOf(step) - times_ns_[k]), q_));
    }
  }

  // The samples at the states' own times.
  void FillNodes(const std::vector<FilteredState>& states) {
    for (std::size_t k = 0; k < states.size(); ++k) {
      const UtcNs since_t0_ns = times_ns_[k] - t0_ns_;
      if (since_t0_ns % step_ns_ == 0) Fill(since_t0_ns / step_ns_, states[k]);
    }
  }

 private:
  UtcNs TimeOf(UtcNs step) const { return t0_ns_ + step * step_ns_; }
  // The first grid step after state k's time (times are >= t0_ns).
  UtcNs FirstStepAfter(std::size_t k) const { return (times_ns_[k] - t0_ns_) / step_ns_ + 1; }

  void Fill(UtcNs step, const FilteredState& s) {
    TrackSample& sample = (*samples_)[static_cast<std::size_t>(step - first_step_)];
    sample.position_m = s.x.head<2>();
    sample.velocity_mps = s.x.tail<2>();
    sample.position_cov_m2 = FlooredPositionCovariance(s.p, min_var_);
  }

  const std::vector<UtcNs>& times_ns_;
  UtcNs t0_ns_;
  UtcNs step_ns_;
  UtcNs first_step_;
  double q_;
  double min_var_;
  std::vector<TrackSample>* samples_;
};

constexpr std::size_t kKinds = 4;  // MeasurementKind values

std::size_t KindIndex(MeasurementKind kind) {
  const auto k = static_cast<std::size_t>(kind);
  return k < kKinds ? k : 0;
}

// A state measured in its scan (not predicted only).
bool Measured(const daemon::TrackObservation& o) {
  return o.state != TrackState::kCoasting || o.points > 0;
}

// The measurement model of every sample of a piece (TrackSample): at the sample's smoothed
// position and velocity, for each kind of the measured states within model_window_s (weighted by
// their number; the nearest state's kind when none was measured), mixed.
void ModelSamples(const Record* records, std::size_t n, UtcNs first_ns, UtcNs step_ns,
                  const AlignOptions& options, GridTrack* out) {
  const UtcNs window_ns = common::SecondsToNs(options.model_window_s);
  std::size_t lo = 0, hi = 0;  // records with time in [t - window, t + window]
  for (std::size_t k = 0; k < out->samples.size(); ++k) {
    TrackSample& x = out->samples[k];
    const UtcNs t_ns = first_ns + static_cast<UtcNs>(k) * step_ns;
    while (lo < n && records[lo].t_ns < t_ns - window_ns) ++lo;
    if (hi < lo) hi = lo;
    while (hi < n && records[hi].t_ns <= t_ns + window_ns) ++hi;
    std::array<double, kKinds> weight{};
    std::array<const daemon::TrackObservation*, kKinds> nearest{};
    std::array<UtcNs, kKinds> nearest_dt{};
    double points = 0.0, measured = 0.0;
    for (std::size_t i = lo; i < hi; ++i) {
      const daemon::TrackObservation& o = *records[i].obs;
      if (!Measured(o)) continue;
      const std::size_t kind = KindIndex(o.kind);
      weight[kind] += kind == KindIndex(MeasurementKind::kCenterOfMass) ||
                              kind == KindIndex(MeasurementKind::kUnspecified)
                          ? 1.0
                          : options.model_fit_weight;
      points += static_cast<double>(o.points);
      measured += 1.0;
      const UtcNs dt = records[i].t_ns > t_ns ? records[i].t_ns - t_ns : t_ns - records[i].t_ns;
      if (nearest[kind] == nullptr || dt < nearest_dt[kind]) {
        nearest[kind] = &o;
        nearest_dt[kind] = dt;
      }
    }
    double weight_sum = 0.0;
    for (double w : weight) weight_sum += w;
    if (measured == 0.0 || !(weight_sum > 0.0)) {
      // Coasting only: the kind of the nearest state (the one the filter last used).
      std::size_t best = 0;
      UtcNs best_dt = std::numeric_limits<UtcNs>::max();
      for (std::size_t i = lo > 0 ? lo - 1 : 0; i < std::min(n, hi + 1); ++i) {
        const UtcNs dt = records[i].t_ns > t_ns ? records[i].t_ns - t_ns : t_ns - records[i].t_ns;
        if (dt < best_dt) {
          best_dt = dt;
          best = i;
        }
      }
      const std::size_t kind = KindIndex(records[best].obs->kind);
      weight.fill(0.0);
      weight[kind] = 1.0;
      nearest[kind] = records[best].obs;
    }
    double total = 0.0;
    for (double w : weight) total += w;
    double bias = 0.0, per_major = 0.0, per_minor = 0.0, size_var = 0.0, model_var = 0.0;
    double bias2 = 0.0, shared_var = 0.0;
    std::size_t main_kind = 0;
    for (std::size_t kind = 0; kind < kKinds; ++kind) {
      if (weight[kind] == 0.0) continue;
      if (weight[kind] > weight[main_kind]) main_kind = kind;
      daemon::MeasurementContext c = daemon::ContextOf(*nearest[kind]);
      c.x_m = x.position_m.x();
      c.y_m = x.position_m.y();
      c.vx_mps = x.velocity_mps.x();
      c.vy_mps = x.velocity_mps.y();
      const daemon::CentreBias b = daemon::CentreBiasOf(c, options.model);
      const double f = weight[kind] / total;
      bias += f * b.toward_sensor_m;
      bias2 += f * b.toward_sensor_m * b.toward_sensor_m;
      per_major += f * b.per_major_m_per_m;
      per_minor += f * b.per_minor_m_per_m;
      size_var += f * b.size_sigma_m * b.size_sigma_m;
      model_var += f * b.sigma_m * b.sigma_m;
      shared_var += f * b.shared_sigma_m * b.shared_sigma_m;
    }
    // Which kinds the smoother mixed, and in which proportion, is known only roughly: the
    // spread of the kinds' biases is uncertainty of the mixture.
    size_var += std::max(0.0, bias2 - bias * bias);
    // Ends of the track (see AlignOptions::edge_sigma_per_m).
    const double edge_s = static_cast<double>(std::min(k, out->samples.size() - 1 - k)) *
                          common::NsToSeconds(step_ns);
    const double edge_sigma = options.edge_sigma_per_m * x.position_m.norm() *
                              std::exp(-edge_s / std::max(options.edge_time_s, 1e-9));
    model_var += edge_sigma * edge_sigma;
    x.kind = static_cast<MeasurementKind>(main_kind);
    x.points = static_cast<std::uint16_t>(
        std::min(65535.0, measured > 0.0 ? std::round(points / measured) : 0.0));
    x.bias_m = static_cast<float>(bias);
    x.bias_per_major = static_cast<float>(per_major);
    x.bias_per_minor = static_cast<float>(per_minor);
    x.bias_sigma_m = static_cast<float>(std::sqrt(size_var));
    x.model_sigma_m = static_cast<float>(std::sqrt(model_var));
    x.shared_bias_sigma_m = static_cast<float>(std::sqrt(shared_var));
  }
}

// Phase 5: smooths one piece and samples it on the grid into `out`. False when the piece covers no
// grid time.
bool SamplePiece(const SensorWork& work, const Piece& piece, UtcNs t0_ns, UtcNs step_ns,
                 const AlignOptions& options, PieceScratch* scratch, GridTrack* out) {
  const Record* records = work.sorted.data() + piece.begin;
  const std::size_t n = piece.end - piece.begin;
  const UtcNs first_step = (records[0].t_ns - t0_ns + step_ns - 1) / step_ns;  // both >= 0
  const UtcNs last_step = (records[n - 1].t_ns - t0_ns) / step_ns;
  if (first_step > last_step) return false;

  std::array<std::size_t, kKinds> kinds{};
  scratch->states.resize(n);
  scratch->times_ns.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const daemon::TrackObservation& o = *records[i].obs;
    ++kinds[KindIndex(o.kind)];
    scratch->times_ns[i] = records[i].t_ns;
    scratch->states[i] =
        FilteredState{common::NsToSeconds(records[i].t_ns - t0_ns), StateOf(o), CovarianceOf(o)};
  }

  const TrackKey& key = work.keys[records[0].slot];
  out->track_id = key.track_id;
  out->session_id = key.session_id;
  out->kind =
      static_cast<MeasurementKind>(std::max_element(kinds.begin(), kinds.end()) - kinds.begin());
  out->first_step = static_cast<std::size_t>(first_step);
  out->samples.resize(static_cast<std::size_t>(last_step - first_step + 1));
  const double min_var =
      std::max(options.min_position_sigma_m * options.min_position_sigma_m, 1e-12);
  GridSampler sampler(scratch->times_ns, t0_ns, step_ns, first_step, options.accel_psd_m2ps3,
                      min_var, &out->samples);
  if (options.smooth) {
    RtsSmoothWithSink(&scratch->states, options.accel_psd_m2ps3, sampler);
  } else {
    for (std::size_t k = 0; k + 1 < n; ++k) {
      if (!sampler.Wants(k)) continue;
      sampler.Take(k, RtsIntervalWithoutSmoothing(
                          scratch->states[k], scratch->states[k + 1].t_s - scratch->states[k].t_s));
    }
  }
  sampler.FillNodes(scratch->states);
  ModelSamples(records, n, t0_ns + first_step * step_ns, step_ns, options, out);
  return true;
}

std::string Seconds(double s) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.6g s", s);
  return buffer;
}

}  // namespace

std::optional<std::string> Validate(const AlignOptions& o) {
  if (!(Finite(o.grid_step_s) && o.grid_step_s >= 0.001 && o.grid_step_s <= 60.0)) {
    return "grid_step_s must be in [0.001, 60]";
  }
  if (!(Finite(o.accel_psd_m2ps3) && o.accel_psd_m2ps3 > 0.0)) {
    return "accel_psd_m2ps3 must be > 0";
  }
  if (!(Finite(o.max_grid_span_s) && o.max_grid_span_s >= o.grid_step_s &&
        o.max_grid_span_s <= 1e7)) {
    return "max_grid_span_s must be in [grid_step_s, 1e7]";
  }
  if (!(Finite(o.max_gap_s) && o.max_gap_s > 0.0 && o.max_gap_s <= o.max_grid_span_s)) {
    return "max_gap_s must be in (0, max_grid_span_s]";
  }
  if (!(Finite(o.min_track_duration_s) && o.min_track_duration_s >= 0.0 &&
        o.min_track_duration_s <= o.max_grid_span_s)) {
    return "min_track_duration_s must be in [0, max_grid_span_s]";
  }
  if (!(Finite(o.min_position_sigma_m) && o.min_position_sigma_m >= 0.0 &&
        o.min_position_sigma_m <= 10.0)) {
    return "min_position_sigma_m must be in [0, 10]";
  }
  if (!(Finite(o.model_window_s) && o.model_window_s >= 0.0 && o.model_window_s <= 10.0)) {
    return "model_window_s must be in [0, 10]";
  }
  if (!(Finite(o.model_fit_weight) && o.model_fit_weight >= 0.0 && o.model_fit_weight <= 1e3)) {
    return "model_fit_weight must be in [0, 1000]";
  }
  if (!(Finite(o.edge_sigma_per_m) && o.edge_sigma_per_m >= 0.0 && o.edge_sigma_per_m <= 1.0)) {
    return "edge_sigma_per_m must be in [0, 1]";
  }
  if (!(Finite(o.edge_time_s) && o.edge_time_s >= 0.0 && o.edge_time_s <= 60.0)) {
    return "edge_time_s must be in [0, 60]";
  }
  if (auto e = daemon::Validate(o.model)) return "model: " + *e;
  return std::nullopt;
}

AlignedTracks Align(const CalibrationInput& input, const AlignOptions& options, AlignStats* stats) {
  if (Validate(options)) std::abort();
  AlignStats local_stats;
  AlignStats& st = stats != nullptr ? *stats : local_stats;
  st = AlignStats{};
  const std::size_t sensor_count = input.sensors.size();
  st.sensors.resize(sensor_count);

  AlignedTracks out;
  out.step_s = options.grid_step_s;
  out.size_prior_sigma_m = options.model.prior_size_sigma_m;
  out.sensors.resize(sensor_count);
  std::vector<SensorWork> work(sensor_count);

  // Phase 1: usable observations per sensor.
  for (std::size_t s = 0; s < sensor_count; ++s) {
    const SensorRecording& in = input.sensors[s];
    SensorTracks& sensor = out.sensors[s];
    sensor.id = in.id;
    sensor.description = in.description;
    sensor.background = in.background;
    sensor.clock_suspect = in.clock_sync == ClockSync::kUnsynchronized;
    if (sensor.clock_suspect && options.exclude_unsynchronized) {
      st.sensors[s].excluded = true;
      st.sensors[s].frames = in.frames.size();
      for (const auto& frame : in.frames) st.sensors[s].observations += frame.tracks.size();
      continue;
    }
    Collect(in, options, &work[s], &st.sensors[s]);
  }

  // Phase 2: bound the grid. Times are in [0, kMaxTimeNs], so differences do not overflow.
  UtcNs min_ns = std::numeric_limits<UtcNs>::max(), max_ns = -1;
  for (const SensorWork& w : work) {
    for (const Record& r : w.records) {
      min_ns = std::min(min_ns, r.t_ns);
      max_ns = std::max(max_ns, r.t_ns);
    }
  }
  const UtcNs span_limit_ns = common::SecondsToNs(options.max_grid_span_s);
  if (max_ns >= 0 && max_ns - min_ns > span_limit_ns) {
    const auto [from_ns, to_ns] = BestWindow(work, span_limit_ns);
    std::size_t outside = 0;
    for (std::size_t s = 0; s < sensor_count; ++s) {
      auto& records = work[s].records;
      const auto kept = std::remove_if(records.begin(), records.end(), [&](const Record& r) {
        return r.t_ns < from_ns || r.t_ns > to_ns;
      });
      st.sensors[s].outside_window = static_cast<std::size_t>(records.end() - kept);
      outside += st.sensors[s].outside_window;
      records.erase(kept, records.end());
    }
    st.grid_clipped = true;
    st.error = "track states span " + Seconds(common::NsToSeconds(max_ns - min_ns)) +
               ", more than max_grid_span_s (" + Seconds(options.max_grid_span_s) +
               "): kept the window with the most states, dropped " + std::to_string(outside) +
               " states outside it";
  }

  // Phase 3: tracks, cut into pieces.
  for (std::size_t s = 0; s < sensor_count; ++s) {
    BuildPieces(options, &work[s], &st.sensors[s]);
  }

  // Phase 4: the grid over all pieces.
  min_ns = std::numeric_limits<UtcNs>::max();
  max_ns = -1;
  for (const SensorWork& w : work) {
    for (const Piece& p : w.pieces) {
      min_ns = std::min(min_ns, w.sorted[p.begin].t_ns);
      max_ns = std::max(max_ns, w.sorted[p.end - 1].t_ns);
    }
  }
  if (max_ns < 0) return out;  // nothing usable: empty grid
  const UtcNs step_ns = std::max<UtcNs>(1, std::llround(options.grid_step_s * 1e9));
  out.t0_ns = min_ns - min_ns % step_ns;
  out.steps = static_cast<std::size_t>((max_ns - out.t0_ns + step_ns - 1) / step_ns + 1);

  // Phase 5: smoothing and sampling.
  PieceScratch scratch;
  for (std::size_t s = 0; s < sensor_count; ++s) {
    const SensorWork& w = work[s];
    const SensorRecording& in = input.sensors[s];
    SensorTracks& sensor = out.sensors[s];
    AlignSensorStats& sst = st.sensors[s];
    std::vector<bool> frame_used(in.frames.size(), false);
    sensor.tracks.reserve(w.pieces.size());
    for (const Piece& piece : w.pieces) {
      GridTrack track;
      if (!SamplePiece(w, piece, out.t0_ns, step_ns, options, &scratch, &track)) {
        ++sst.short_pieces;
        sst.short_piece_states += piece.end - piece.begin;
        continue;
      }
      for (std::size_t i = piece.begin; i < piece.end; ++i) frame_used[w.sorted[i].frame] = true;
      sst.observations_used += piece.end - piece.begin;
      sst.samples += track.samples.size();
      sensor.tracks.push_back(std::move(track));
    }
    std::sort(sensor.tracks.begin(), sensor.tracks.end(),
              [](const GridTrack& a, const GridTrack& b) {
                if (a.first_step != b.first_step) return a.first_step < b.first_step;
                if (a.session_id != b.session_id) return a.session_id < b.session_id;
                return a.track_id < b.track_id;
              });
    sst.tracks = sensor.tracks.size();
    sst.frames_used =
        static_cast<std::size_t>(std::count(frame_used.begin(), frame_used.end(), true));
    sensor.frames_used = sst.frames_used;
    sensor.observations_used = sst.observations_used;
  }
  return out;
}

}  // namespace lrfnet::calib
