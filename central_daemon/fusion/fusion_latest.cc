// FusionMethod::kLatestStates: the combination of every bound source's latest state (the
// method described in fusion.h under "kLatestStates"), kept to compare with the fused filter and
// to restore the behaviour of earlier releases.

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <tuple>
#include <utility>

#include "central_daemon/fusion/assignment.h"
#include "central_daemon/fusion/fusion_internal.h"
#include "common/cv_model.h"

namespace lrfnet::fusion::internal {
namespace {

using common::CvCovariance;
using common::CvState;
using common::UtcNs;

// Information-weighted combination of independent estimates: accumulate with Add, then Solve.
class InformationSum {
 public:
  bool Add(const CvState& x, const CvCovariance& p) {
    const Eigen::LLT<CvCovariance> llt(p);
    if (llt.info() != Eigen::Success) return false;
    const CvCovariance info = llt.solve(CvCovariance::Identity());
    if (!AllFinite(info)) return false;
    info_ += info;
    info_state_ += info * x;
    ++count_;
    return true;
  }
  int count() const { return count_; }
  bool Solve(CvState& x, CvCovariance& p) const {
    if (count_ == 0) return false;
    const Eigen::LLT<CvCovariance> llt(info_);
    if (llt.info() != Eigen::Success) return false;
    CvCovariance pf = llt.solve(CvCovariance::Identity());
    pf = 0.5 * (pf + pf.transpose()).eval();
    const CvState xf = pf * info_state_;
    if (!AllFinite(pf) || !AllFinite(xf)) return false;
    x = xf;
    p = pf;
    return true;
  }

 private:
  CvCovariance info_ = CvCovariance::Zero();
  CvState info_state_ = CvState::Zero();
  int count_ = 0;
};

bool Disjoint(const std::vector<std::string>& a, const std::vector<std::string>& b) {
  for (const auto& s : a) {
    if (std::find(b.begin(), b.end(), s) != b.end()) return false;
  }
  return true;
}

class LatestStatesEngine final : public Engine {
 public:
  explicit LatestStatesEngine(const FusionOptions& options) : Engine(options) {}

  void SetPlacements(const PlacementMap& next, const PlacementMap& previous) override;
  void Tick(UtcNs now_ns) override;
  std::vector<FusedTrack> Snapshot(UtcNs now_ns, bool include_tentative) const override;
  std::vector<HiddenFusedTrack> Hidden(const std::vector<FusedTrack>& reported,
                                       UtcNs now_ns) const override {
    return HiddenTracks(tracks, reported, now_ns, options_.max_coast_s);
  }
  std::vector<WorldTrack> WorldTracks(UtcNs now_ns) const override;

 private:
  struct LocalTrack {
    daemon::TrackObservation observation;  // as received, sensor frame
    WorldTrack world;
    CvState x = CvState::Zero();            // world state as a fusion source
    CvCovariance p = CvCovariance::Zero();  // world covariance plus the noise floors
    bool usable = false;                    // not tentative, or tentative sources allowed
    std::optional<std::uint64_t> fused_id;
    std::optional<std::uint64_t> left_fused_id;  // unbound for drifting: never re-bind there
    std::uint32_t strikes = 0;                   // consecutive frames inconsistent with its track
    // Frames to wait after unbinding for drift before starting a fused track of its own: the
    // track it belongs to is often freed a frame or two later (its own swapped source).
    std::uint32_t hold_frames = 0;
    UtcNs stamp() const { return world.stamp_ns; }
  };
  struct SensorState {
    FrameClock clock;
    std::map<std::uint32_t, LocalTrack> tracks;
  };
  struct SourceKey {
    std::string sensor_id;
    std::uint32_t track_id = 0;
    bool operator<(const SourceKey& o) const {
      return std::tie(sensor_id, track_id) < std::tie(o.sensor_id, o.track_id);
    }
  };
  struct Track {
    std::uint64_t id = 0;
    UtcNs first_ns = 0;
    UtcNs stamp_ns = 0;  // of x, p: the latest update
    CvState x = CvState::Zero();
    CvCovariance p = CvCovariance::Identity();
    std::uint64_t updates = 0;
    bool confirmed = false;
    std::vector<SourceKey> sources;  // sorted; at most one per sensor
    // Drift reference (header comment).
    bool ref_valid = false;
    UtcNs ref_ns = 0;
    CvState ref_x = CvState::Zero();
    CvCovariance ref_p = CvCovariance::Identity();
    // The sensor whose source timed out last, leaving the track without sources: a source of
    // another sensor binding later is a hand-over.
    std::string last_sensor;
    // Merge candidacy of this (younger) track with an older one.
    std::uint64_t merge_into = 0;
    std::uint32_t merge_count = 0;
  };
  // A source's state predicted to a time.
  struct Contribution {
    std::string sensor_id;
    CvState x;
    CvCovariance p;
    bool measured = true;  // the tracker measured it in that frame (not coasting)
    bool struck = false;
    std::uint32_t track_id = 0;
  };

  std::map<std::string, SensorState, std::less<>> sensors;
  std::map<std::uint64_t, Track> tracks;
  bool have_newest = false;
  UtcNs newest_ns = 0;

  // --- internals ----------------------------------------------------------------------------

  LocalTrack* Find(const SourceKey& key) {
    const auto s = sensors.find(key.sensor_id);
    if (s == sensors.end()) return nullptr;
    const auto t = s->second.tracks.find(key.track_id);
    return t == s->second.tracks.end() ? nullptr : &t->second;
  }
  const LocalTrack* Find(const SourceKey& key) const {
    const auto s = sensors.find(key.sensor_id);
    if (s == sensors.end()) return nullptr;
    const auto t = s->second.tracks.find(key.track_id);
    return t == s->second.tracks.end() ? nullptr : &t->second;
  }

  static void SetSourceState(const FusionOptions& o, LocalTrack& lt) {
    lt.x = CvState(lt.world.x_m, lt.world.y_m, lt.world.vx_mps, lt.world.vy_mps);
    lt.p = lt.world.covariance;
    lt.p(0, 0) += o.position_noise_floor_m2;
    lt.p(1, 1) += o.position_noise_floor_m2;
    lt.p(2, 2) += o.velocity_noise_floor_m2ps2;
    lt.p(3, 3) += o.velocity_noise_floor_m2ps2;
  }

  static bool Measured(const LocalTrack& lt) {
    return lt.observation.state != daemon::TrackState::kCoasting;
  }

  // The source if it contributes at time t: usable, not struck, carried by the latest frame of its
  // sensor (a tracker reports every track it holds in every frame, so one missing from a newer
  // frame was deleted there) and at most source_timeout_s old.
  const LocalTrack* FreshSource(const FusionOptions& o, const SourceKey& key, UtcNs t,
                                bool include_struck = false) const {
    const auto s = sensors.find(key.sensor_id);
    if (s == sensors.end()) return nullptr;
    const auto it = s->second.tracks.find(key.track_id);
    if (it == s->second.tracks.end()) return nullptr;
    const LocalTrack& lt = it->second;
    if (!lt.usable || (lt.strikes != 0 && !include_struck) ||
        lt.stamp() != s->second.clock.latest_ns ||
        std::abs(Seconds(t, lt.stamp())) > o.source_timeout_s) {
      return nullptr;
    }
    return &lt;
  }

  void Unbind(Track& f, const SourceKey& key) {
    f.sources.erase(std::remove_if(f.sources.begin(), f.sources.end(),
                                   [&](const SourceKey& k) {
                                     return k.sensor_id == key.sensor_id &&
                                            k.track_id == key.track_id;
                                   }),
                    f.sources.end());
    if (LocalTrack* lt = Find(key); lt != nullptr && lt->fused_id == f.id) {
      lt->fused_id.reset();
      lt->strikes = 0;
    }
  }

  // Binds, replacing any other source of the same sensor (stale: the caller ensures that).
  void Bind(Track& f, const std::string& sensor_id, std::uint32_t track_id, LocalTrack& lt) {
    for (std::size_t i = 0; i < f.sources.size();) {
      if (f.sources[i].sensor_id == sensor_id && f.sources[i].track_id != track_id) {
        const SourceKey old = f.sources[i];
        LocalTrack* replaced = Find(old);
        if (replaced != nullptr && replaced->strikes > 0) replaced->left_fused_id = f.id;
        Unbind(f, old);
      } else {
        ++i;
      }
    }
    SourceKey key{sensor_id, track_id};
    if (std::find_if(f.sources.begin(), f.sources.end(), [&](const SourceKey& k) {
          return k.sensor_id == sensor_id && k.track_id == track_id;
        }) == f.sources.end()) {
      f.sources.insert(std::upper_bound(f.sources.begin(), f.sources.end(), key), key);
    }
    lt.fused_id = f.id;
    lt.strikes = 0;
  }

  void DeleteTrack(std::map<std::uint64_t, Track>::iterator it) {
    const std::vector<SourceKey> keys = it->second.sources;
    for (const SourceKey& k : keys) Unbind(it->second, k);
    tracks.erase(it);
  }

  // The fresh sources of f (other than those of skip_sensor) predicted to t.
  std::vector<Contribution> Contributions(const FusionOptions& o, const Track& f, UtcNs t,
                                          const std::string* skip_sensor = nullptr,
                                          bool include_struck = false) const {
    std::vector<Contribution> out;
    for (const SourceKey& k : f.sources) {
      if (skip_sensor != nullptr && k.sensor_id == *skip_sensor) continue;
      const LocalTrack* lt = FreshSource(o, k, t, include_struck);
      if (lt == nullptr) continue;
      Contribution c{k.sensor_id, lt->x, lt->p, Measured(*lt), lt->strikes != 0, k.track_id};
      Predict(Seconds(t, lt->stamp()), o.accel_psd, c.x, c.p);
      out.push_back(std::move(c));
    }
    return out;
  }

  static bool Consistent(const FusionOptions& o, const CvState& a, const CvCovariance& pa,
                         const CvState& b, const CvCovariance& pb, double gate) {
    const Eigen::Vector2d pa_m = a.head<2>(), pb_m = b.head<2>();
    if ((pa_m - pb_m).norm() > o.gate_max_distance_m) return false;
    return Mahalanobis2(pa_m, pa.topLeftCorner<2, 2>(), pb_m, pb.topLeftCorner<2, 2>()) <= gate;
  }

  // --- drift --------------------------------------------------------------------------------

  // Judges source `key` of sensor S (its state is from the frame at t) against f's reference;
  // strikes and finally unbinds it (see the header comment).
  void DriftTest(Track& f, const SourceKey& key, LocalTrack& lt, UtcNs t) {
    const FusionOptions& o = options_;
    // A coasting local track is its tracker's prediction: it says nothing about a swap, and it
    // must keep its binding for when the tracker measures the person again.
    if (!f.ref_valid || !Measured(lt)) {
      lt.strikes = 0;
      return;
    }
    CvState xr = f.ref_x;
    CvCovariance pr = f.ref_p;
    Predict(Seconds(t, f.ref_ns), o.accel_psd, xr, pr);
    if (Consistent(o, lt.x, lt.p, xr, pr, o.gate_mahalanobis2)) {
      lt.strikes = 0;
      return;
    }
    // The other sensors' measured sources (coasting ones say nothing), struck ones apart.
    std::vector<Contribution> others = Contributions(o, f, t, &key.sensor_id, true);
    InformationSum unstruck, struck;
    for (const Contribution& c : others) {
      if (c.measured) (c.struck ? struck : unstruck).Add(c.x, c.p);
    }
    CvState xo;
    CvCovariance po;
    bool strike = false;
    bool re_anchor = false;
    if (unstruck.Solve(xo, po)) {
      if (Consistent(o, lt.x, lt.p, xo, po, o.gate_mahalanobis2)) {
        re_anchor = true;  // it moved with the others (a sharp turn): the reference is stale
      } else if (Consistent(o, xo, po, xr, pr, o.gate_mahalanobis2)) {
        strike = true;  // the others still see the person where the reference expects them
      }
      // Otherwise the sources disagree among themselves and nothing says who is right yet.
    } else if (struck.Solve(xo, po) && Consistent(o, lt.x, lt.p, xo, po, o.gate_mahalanobis2)) {
      re_anchor = true;  // it agrees with a source struck before: every tracker saw the same
    } else if (Seconds(t, f.ref_ns) <= o.drift_reference_max_age_s) {
      strike = true;  // a lone source jumped away from where its track just was
    } else {
      re_anchor = true;  // a lone source and an old reference: trust the source
    }
    if (re_anchor) {
      // Forgive the struck sources that agree with this one (both saw the same thing).
      f.ref_valid = false;
      for (const Contribution& c : others) {
        LocalTrack* other = Find(SourceKey{c.sensor_id, c.track_id});
        if (other != nullptr && c.struck &&
            Consistent(o, lt.x, lt.p, c.x, c.p, o.gate_mahalanobis2)) {
          other->strikes = 0;
        }
      }
    }
    if (!strike) {
      lt.strikes = 0;
      return;
    }
    ++lt.strikes;
    ++counters_.source_strikes;
    if (lt.strikes >= o.drift_updates) {
      Unbind(f, key);
      lt.left_fused_id = f.id;
      lt.hold_frames = 2 * o.drift_updates;
      ++counters_.sources_drifted;
    }
  }

  // --- update -------------------------------------------------------------------------------

  // Re-estimates f from its fresh sources at max(t, f's and its sources' times). Returns false
  // (f unchanged) when no source contributes.
  bool Update(Track& f, UtcNs t) {
    const FusionOptions& o = options_;
    UtcNs t_est = std::max(t, f.stamp_ns);
    for (const SourceKey& k : f.sources) {
      const LocalTrack* lt = FreshSource(o, k, t_est);
      if (lt != nullptr) t_est = std::max(t_est, lt->stamp());
    }
    std::vector<Contribution> contributions = Contributions(o, f, t_est);
    // A tracker's coasting track adds nothing to measured ones (it is a constant-velocity
    // prediction, like the fused track's own) and lags when the person turns or stops.
    if (std::any_of(contributions.begin(), contributions.end(),
                    [](const Contribution& c) { return c.measured; })) {
      contributions.erase(std::remove_if(contributions.begin(), contributions.end(),
                                         [](const Contribution& c) { return !c.measured; }),
                          contributions.end());
    }
    // While some source agrees with the reference in position and velocity, the ones that do
    // not are left out: a source that starts to drift (a tracker's id swap) must not drag the
    // track before the drift test can tell, and the reference moves on with the agreeing ones.
    // When none agrees fully but all agree in position, everybody saw the same turn or stop: the
    // reference moves on with all. Otherwise all are used and the reference stays; the drift
    // test decides later.
    bool move_reference = true;
    if (f.ref_valid && !contributions.empty()) {
      CvState xr = f.ref_x;
      CvCovariance pr = f.ref_p;
      Predict(Seconds(t_est, f.ref_ns), o.accel_psd, xr, pr);
      std::vector<Contribution> agreeing;
      bool all_positions_agree = true;
      for (const Contribution& c : contributions) {
        const bool position_agrees =
            Mahalanobis2(c.x.head<2>(), c.p.topLeftCorner<2, 2>(), xr.head<2>(),
                         pr.topLeftCorner<2, 2>()) <= o.agree_mahalanobis2;
        all_positions_agree = all_positions_agree && position_agrees;
        if (position_agrees &&
            Mahalanobis2(c.x.tail<2>(), c.p.bottomRightCorner<2, 2>(), xr.tail<2>(),
                         pr.bottomRightCorner<2, 2>()) <= o.agree_mahalanobis2) {
          agreeing.push_back(c);
        }
      }
      if (!agreeing.empty()) {
        counters_.source_exclusions += contributions.size() - agreeing.size();
        contributions = std::move(agreeing);
      } else {
        move_reference = all_positions_agree;
      }
    }
    InformationSum sum;
    for (const Contribution& c : contributions) {
      if (!sum.Add(c.x, c.p)) ++counters_.numerical_failures;
    }
    CvState x;
    CvCovariance p;
    if (sum.count() == 0) return false;
    if (!sum.Solve(x, p)) {
      ++counters_.numerical_failures;
      return false;
    }
    if (move_reference) {
      f.ref_valid = true;
      f.ref_ns = t_est;
      f.ref_x = x;
      f.ref_p = p;
    }
    f.x = x;
    f.p = p;
    f.stamp_ns = t_est;
    if (f.updates == 0) f.first_ns = t_est;
    ++f.updates;
    if (f.updates >= o.confirm_updates) f.confirmed = true;
    return true;
  }

  // Sensors of f's fresh sources at t.
  std::vector<std::string> ActiveSensors(const FusionOptions& o, const Track& f, UtcNs t) const {
    std::vector<std::string> out;
    for (const SourceKey& k : f.sources) {
      if (FreshSource(o, k, t) != nullptr) out.push_back(k.sensor_id);
    }
    return out;
  }

  // --- merge --------------------------------------------------------------------------------

  // Checks the just updated track f against every other active track; merges a pair that has
  // been consistent for merge_updates checks. Returns the surviving id of f.
  std::uint64_t MergeCheck(std::uint64_t f_id) {
    const FusionOptions& o = options_;
    auto fit = tracks.find(f_id);
    if (fit == tracks.end()) return f_id;
    Track& f = fit->second;
    const UtcNs t = f.stamp_ns;
    const std::vector<std::string> f_sensors = ActiveSensors(o, f, t);
    if (f_sensors.empty()) return f_id;
    for (auto& [g_id, g] : tracks) {
      if (g_id == f_id) continue;
      Track& younger = g_id > f_id ? g : f;
      const std::uint64_t older_id = std::min(g_id, f_id);
      auto reset = [&] {
        if (younger.merge_into == older_id) {
          younger.merge_into = 0;
          younger.merge_count = 0;
        }
      };
      const double dt = Seconds(t, g.stamp_ns);
      if (std::abs(dt) > o.coast_after_s) {
        reset();
        continue;
      }
      const Eigen::Vector2d g_pos = g.x.head<2>() + dt * g.x.tail<2>();
      if ((g_pos - f.x.head<2>()).norm() > o.merge_max_distance_m ||
          (g.x.tail<2>() - f.x.tail<2>()).norm() > o.merge_max_speed_difference_mps) {
        reset();
        continue;
      }
      const std::vector<std::string> g_sensors = ActiveSensors(o, g, t);
      CvState gx = g.x;
      CvCovariance gp = g.p;
      Predict(dt, o.accel_psd, gx, gp);
      if (g_sensors.empty() || !Disjoint(f_sensors, g_sensors) ||
          !Consistent(o, f.x, f.p, gx, gp, o.gate_mahalanobis2)) {
        reset();
        continue;
      }
      if (younger.merge_into == older_id) {
        ++younger.merge_count;
      } else {
        younger.merge_into = older_id;
        younger.merge_count = 1;
      }
      if (younger.merge_count >= o.merge_updates) {
        const std::uint64_t younger_id = std::max(g_id, f_id);
        Merge(older_id, younger_id, t);
        return older_id;
      }
    }
    return f_id;
  }

  void Merge(std::uint64_t older_id, std::uint64_t younger_id, UtcNs t) {
    Track& older = tracks.at(older_id);
    auto yit = tracks.find(younger_id);
    Track& younger = yit->second;
    const std::vector<SourceKey> moving = younger.sources;
    for (const SourceKey& k : moving) {
      LocalTrack* lt = Find(k);
      Unbind(younger, k);
      if (lt == nullptr) continue;
      // One source per sensor: keep the fresher one.
      bool keep_new = true;
      for (const SourceKey& ok : older.sources) {
        if (ok.sensor_id != k.sensor_id) continue;
        const LocalTrack* olt = Find(ok);
        if (olt != nullptr && olt->stamp() >= lt->stamp()) keep_new = false;
      }
      if (keep_new) Bind(older, k.sensor_id, k.track_id, *lt);
    }
    older.first_ns = std::min(older.first_ns, younger.first_ns);
    older.updates += younger.updates;
    older.confirmed = older.confirmed || younger.confirmed;
    older.ref_valid = false;
    older.merge_into = 0;
    older.merge_count = 0;
    const bool younger_confirmed = younger.confirmed;
    tracks.erase(yit);
    for (auto& [id, tr] : tracks) {
      if (tr.merge_into == younger_id) {
        tr.merge_into = 0;
        tr.merge_count = 0;
      }
    }
    ++counters_.fused_merged;
    if (younger_confirmed) RecordEnded(younger_id, t, FusedEndReason::kMerged, older_id);
    Update(older, t);
  }

  // --- frame --------------------------------------------------------------------------------

  // Forgets every local track of a sensor (a tracker restart, a sensor no longer placed).
  void DropSensorTracks(const std::string& sensor_id, SensorState& ss) {
    for (auto& [tid, lt] : ss.tracks) {
      if (!lt.fused_id) continue;
      auto f = tracks.find(*lt.fused_id);
      if (f != tracks.end()) Unbind(f->second, SourceKey{sensor_id, tid});
    }
    ss.tracks.clear();
  }

  void ExpireSources(const std::string& sensor_id, SensorState& ss, UtcNs now) {
    for (auto it = ss.tracks.begin(); it != ss.tracks.end();) {
      LocalTrack& lt = it->second;
      if (Seconds(now, lt.stamp()) <= options_.source_timeout_s) {
        ++it;
        continue;
      }
      if (lt.fused_id) {
        auto f = tracks.find(*lt.fused_id);
        if (f != tracks.end()) {
          Unbind(f->second, SourceKey{sensor_id, it->first});
          // Other sensors continue the track (one source per sensor: the rest are others).
          if (!f->second.sources.empty()) {
            ++counters_.handovers;
          } else {
            f->second.last_sensor = sensor_id;
          }
        }
        ++counters_.sources_timed_out;
      }
      it = ss.tracks.erase(it);
    }
  }

  void AddFrame(const SensorPlacement& placement, const std::string& sensor_id,
                const daemon::TrackFrameData& frame) override {
    const FusionOptions& o = options_;
    FusionCounters& counters = counters_;
    const UtcNs t = frame.scan_start_ns;
    if (t <= 0) {
      ++counters.frames_invalid;
      return;
    }
    SensorState& ss = sensors[sensor_id];
    const FrameAdmission admission =
        AdmitFrame(frame, o.max_out_of_order_s, ss.clock, have_newest, newest_ns);
    if (admission == FrameAdmission::kNewSession) DropSensorTracks(sensor_id, ss);
    if (!CountAdmission(admission, counters)) return;

    // 1. The frame's tracks into the world frame.
    std::vector<std::uint32_t> ids;  // accepted, in this call
    for (const daemon::TrackObservation& received : frame.tracks) {
      const daemon::TrackObservation obs = CentreCorrected(received);
      if (ids.size() >= o.max_tracks_per_frame) {
        ++counters.observations_over_capacity;
        continue;
      }
      if (!PlausibleObservation(o, obs)) {
        ++counters.observations_invalid;
        continue;
      }
      const auto [it, inserted] = ss.tracks.try_emplace(obs.track_id);
      LocalTrack& lt = it->second;
      if (!inserted && lt.stamp() == t) {
        ++counters.observations_invalid;  // the same id twice in one frame
        continue;
      }
      WorldTrack world = ToWorld(placement, sensor_id, t, obs);
      if (!AllFinite(world.covariance) || !std::isfinite(world.x_m) || !std::isfinite(world.y_m) ||
          !std::isfinite(world.vx_mps) || !std::isfinite(world.vy_mps)) {
        ++counters.observations_invalid;
        if (inserted) ss.tracks.erase(it);
        continue;
      }
      lt.observation = obs;
      lt.world = std::move(world);
      SetSourceState(o, lt);
      lt.usable = obs.state != daemon::TrackState::kTentative || o.use_tentative_sources;
      ids.push_back(obs.track_id);
      if (lt.usable) {
        ++counters.observations;
      } else {
        ++counters.observations_ignored;
      }
    }

    // 2. Bound tracks: drift test first, so that an unbound one is re-associated right away.
    std::vector<std::uint64_t> touched;
    for (const std::uint32_t tid : ids) {
      LocalTrack& lt = ss.tracks.at(tid);
      if (!lt.usable || !lt.fused_id) continue;
      auto f = tracks.find(*lt.fused_id);
      if (f == tracks.end()) {
        lt.fused_id.reset();
        continue;
      }
      DriftTest(f->second, SourceKey{sensor_id, tid}, lt, t);
      if (lt.fused_id && lt.strikes == 0) touched.push_back(f->first);
    }

    // 3. Unbound tracks: global nearest neighbour against the fused tracks alive at t that hold
    // no track of this sensor in this frame.
    std::vector<std::pair<std::uint32_t, LocalTrack*>> unbound;
    for (const std::uint32_t tid : ids) {
      LocalTrack& lt = ss.tracks.at(tid);
      if (lt.usable && !lt.fused_id) unbound.emplace_back(tid, &lt);
    }
    if (!unbound.empty()) {
      struct Candidate {
        Track* track;
        CvState x;
        CvCovariance p;
      };
      std::vector<Candidate> candidates;
      for (auto& [id, f] : tracks) {
        const double age = Seconds(t, f.stamp_ns);
        if (age > o.max_coast_s || -age > o.max_out_of_order_s || f.updates == 0) continue;
        bool has_this_frame = false;
        for (const SourceKey& k : f.sources) {
          if (k.sensor_id != sensor_id) continue;
          const LocalTrack* lt = Find(k);
          // A struck one is on its way out: a new local track may take its place.
          if (lt != nullptr && lt->stamp() == t && lt->strikes == 0) has_this_frame = true;
        }
        if (has_this_frame) continue;
        Candidate c{&f, f.x, f.p};
        Predict(age, o.accel_psd, c.x, c.p);
        candidates.push_back(std::move(c));
      }
      Eigen::MatrixXd cost =
          Eigen::MatrixXd::Constant(static_cast<Eigen::Index>(unbound.size()),
                                    static_cast<Eigen::Index>(candidates.size()), kForbiddenCost);
      for (std::size_t i = 0; i < unbound.size(); ++i) {
        const LocalTrack& lt = *unbound[i].second;
        const Eigen::Vector2d z = lt.x.head<2>();
        for (std::size_t j = 0; j < candidates.size(); ++j) {
          const Candidate& c = candidates[j];
          if (lt.left_fused_id == c.track->id) continue;
          const Eigen::Vector2d pos = c.x.head<2>();
          if ((z - pos).norm() > o.gate_max_distance_m) continue;
          double log_det = 0.0;
          const double d2 =
              Mahalanobis2(z, lt.p.topLeftCorner<2, 2>(), pos, c.p.topLeftCorner<2, 2>(), &log_det);
          if (!(d2 <= o.gate_mahalanobis2)) continue;
          // The negative log-likelihood of the pairing up to a constant: ln det S prefers the
          // confident track when a coasting one competes for the same local track.
          cost(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) = d2 + log_det;
        }
      }
      const std::vector<int> assignment = SolveAssignment(cost);
      for (std::size_t i = 0; i < unbound.size(); ++i) {
        const auto [tid, lt] = unbound[i];
        if (assignment[i] >= 0) {
          Track& f = *candidates[static_cast<std::size_t>(assignment[i])].track;
          if (f.sources.empty() && !f.last_sensor.empty() && f.last_sensor != sensor_id) {
            ++counters.handovers;  // picked up by another sensor while coasting
          }
          Bind(f, sensor_id, tid, *lt);
          ++counters.bindings;
          touched.push_back(f.id);
          continue;
        }
        if (lt->hold_frames > 0) {
          --lt->hold_frames;
          continue;
        }
        if (tracks.size() >= o.max_fused_tracks) {
          ++counters.fused_over_capacity;
          continue;
        }
        Track f;
        f.id = next_id_++;
        f.first_ns = t;
        f.stamp_ns = t;
        Track& stored = tracks.emplace(f.id, std::move(f)).first->second;
        Bind(stored, sensor_id, tid, *lt);
        ++counters.fused_created;
        touched.push_back(stored.id);
      }
    }

    // 4. Re-estimate every fused track this frame touched, then look for duplicates.
    std::sort(touched.begin(), touched.end());
    touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
    std::vector<std::uint64_t> updated;
    for (const std::uint64_t id : touched) {
      auto f = tracks.find(id);
      if (f == tracks.end()) continue;
      if (Update(f->second, t)) {
        updated.push_back(id);
      } else if (f->second.updates == 0) {
        DeleteTrack(f);  // born without a usable estimate (numerical failure)
      }
    }
    for (const std::uint64_t id : updated) MergeCheck(id);

    ExpireSources(sensor_id, ss, t);
  }
};
void LatestStatesEngine::SetPlacements(const PlacementMap& next, const PlacementMap& previous) {
  for (auto it = sensors.begin(); it != sensors.end();) {
    const auto placement = next.find(it->first);
    if (placement == next.end()) {
      DropSensorTracks(it->first, it->second);
      it = sensors.erase(it);
      continue;
    }
    const auto old = previous.find(it->first);
    if (old == previous.end() || !SamePlacement(old->second, placement->second)) {
      for (auto& [tid, lt] : it->second.tracks) {
        lt.world = ToWorld(placement->second, it->first, lt.world.stamp_ns, lt.observation);
        SetSourceState(options_, lt);
        lt.strikes = 0;
      }
    }
    ++it;
  }
  // Estimates made with the old poses are no reference for the new ones.
  for (auto& [id, f] : tracks) {
    f.ref_valid = false;
    f.merge_into = 0;
    f.merge_count = 0;
  }
}

void LatestStatesEngine::Tick(UtcNs now_ns) {
  for (auto& [sensor_id, ss] : sensors) ExpireSources(sensor_id, ss, now_ns);
  for (auto it = tracks.begin(); it != tracks.end();) {
    const Track& f = it->second;
    const double age = Seconds(now_ns, f.stamp_ns);
    const bool dead = age > options_.max_coast_s || (!f.confirmed && f.sources.empty());
    if (!dead) {
      ++it;
      continue;
    }
    ++counters_.fused_deleted;
    // A confirmed track ends only by timing out (a tentative one is never reported).
    if (f.updates > 0 && f.confirmed) RecordEnded(it->first, now_ns, FusedEndReason::kTimedOut);
    auto next = std::next(it);
    DeleteTrack(it);
    it = next;
  }
  ForgetEnded();
}

std::vector<FusedTrack> LatestStatesEngine::Snapshot(UtcNs now_ns, bool include_tentative) const {
  std::vector<FusedTrack> out;
  for (const auto& [id, f] : tracks) {
    if (f.updates == 0 || (!f.confirmed && !include_tentative)) continue;
    std::optional<FusedTrack> t = PredictedFusedTrack(
        id, f.confirmed, f.first_ns, f.stamp_ns, f.updates, f.x, f.p, options_, now_ns);
    if (!t) continue;
    for (const SourceKey& k : f.sources) {
      const LocalTrack* lt = Find(k);
      t->sources.push_back(FusedSource{k.sensor_id, k.track_id, lt != nullptr ? lt->stamp() : 0});
    }
    out.push_back(std::move(*t));
  }
  return out;
}

std::vector<WorldTrack> LatestStatesEngine::WorldTracks(UtcNs now_ns) const {
  return RecentWorldTracks(sensors, options_.source_timeout_s, now_ns);
}

}  // namespace

std::unique_ptr<Engine> MakeLatestStatesEngine(const FusionOptions& options) {
  return std::make_unique<LatestStatesEngine>(options);
}

}  // namespace lrfnet::fusion::internal
