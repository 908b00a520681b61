#include "central_daemon/zones/zones.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <set>

namespace lrfnet::zones {
namespace {

double Cross(Point a, Point b, Point c) {  // (b - a) x (c - a)
  return (b.x_m - a.x_m) * (c.y_m - a.y_m) - (b.y_m - a.y_m) * (c.x_m - a.x_m);
}

double DistanceToSegment(Point a, Point b, Point p) {
  const double dx = b.x_m - a.x_m, dy = b.y_m - a.y_m;
  const double len2 = dx * dx + dy * dy;
  double t = len2 > 0.0 ? ((p.x_m - a.x_m) * dx + (p.y_m - a.y_m) * dy) / len2 : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  return std::hypot(p.x_m - (a.x_m + t * dx), p.y_m - (a.y_m + t * dy));
}

// Proper or touching intersection of the closed segments ab and cd.
bool SegmentsIntersect(Point a, Point b, Point c, Point d) {
  const double d1 = Cross(c, d, a), d2 = Cross(c, d, b), d3 = Cross(a, b, c), d4 = Cross(a, b, d);
  if (((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0))) {
    return true;
  }
  const auto on = [](Point p, Point q, Point r) {  // r on segment pq, given collinear
    return std::min(p.x_m, q.x_m) <= r.x_m && r.x_m <= std::max(p.x_m, q.x_m) &&
           std::min(p.y_m, q.y_m) <= r.y_m && r.y_m <= std::max(p.y_m, q.y_m);
  };
  return (d1 == 0 && on(c, d, a)) || (d2 == 0 && on(c, d, b)) || (d3 == 0 && on(a, b, c)) ||
         (d4 == 0 && on(a, b, d));
}

bool ValidName(const std::string& name) {
  if (name.empty() || name.size() > 64) return false;
  return std::all_of(name.begin(), name.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' ||
           c == '-';
  });
}

// Line A->B: signed distance (> 0 left) and the parameter of p's projection (0 at A, 1 at B).
struct LineCoordinates {
  double d_m = 0.0;
  double t = 0.0;
};
LineCoordinates OnLine(const Zone& zone, Point p) {
  const Point a = zone.points[0], b = zone.points[1];
  const double dx = b.x_m - a.x_m, dy = b.y_m - a.y_m;
  const double len = std::hypot(dx, dy);
  return {Cross(a, b, p) / len, ((p.x_m - a.x_m) * dx + (p.y_m - a.y_m) * dy) / (len * len)};
}

}  // namespace

const char* ToString(ZoneKind kind) { return kind == ZoneKind::kLine ? "line" : "polygon"; }

std::optional<std::string> Validate(const ZoneOptions& options) {
  if (!(options.hysteresis_m >= 0.0 && options.hysteresis_m <= 10.0)) {
    return "hysteresis_m: must be in [0, 10]";
  }
  if (!(options.absent_hold_s >= 0.0 && options.absent_hold_s <= 3600.0)) {
    return "absent_hold_s: must be in [0, 3600]";
  }
  return std::nullopt;
}

std::optional<std::string> Validate(const Zone& zone) {
  if (!ValidName(zone.name)) {
    return "zone '" + zone.name + "': the name must be 1-64 characters of A-Z, a-z, 0-9, _ and -";
  }
  const std::string where = "zone '" + zone.name + "': ";
  for (const Point& p : zone.points) {
    if (!std::isfinite(p.x_m) || !std::isfinite(p.y_m) || std::abs(p.x_m) > 1e6 ||
        std::abs(p.y_m) > 1e6) {
      return where + "coordinates must be finite metres within 1e6";
    }
  }
  if (zone.kind == ZoneKind::kLine) {
    if (zone.points.size() != 2) return where + "a line has exactly 2 points";
    if (std::hypot(zone.points[1].x_m - zone.points[0].x_m,
                   zone.points[1].y_m - zone.points[0].y_m) < 1e-3) {
      return where + "the line's points must be at least 1 mm apart";
    }
    return std::nullopt;
  }
  const std::size_t n = zone.points.size();
  if (n < 3) return where + "a polygon has at least 3 points";
  if (n > kMaxZonePoints) return where + "a polygon has at most 1024 points";
  // Simple: no two edges meet except neighbours at their shared vertex.
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j) {
      const bool neighbours = j == i + 1 || (i == 0 && j == n - 1);
      if (neighbours) continue;
      if (SegmentsIntersect(zone.points[i], zone.points[(i + 1) % n], zone.points[j],
                            zone.points[(j + 1) % n])) {
        return where + "the polygon's edges cross (edges " + std::to_string(i) + " and " +
               std::to_string(j) + ")";
      }
    }
  }
  double area2 = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const Point a = zone.points[i], b = zone.points[(i + 1) % n];
    area2 += a.x_m * b.y_m - b.x_m * a.y_m;
  }
  if (std::abs(area2) < 2e-6) return where + "the polygon has no area";
  return std::nullopt;
}

std::optional<std::string> Validate(std::span<const Zone> zones) {
  if (zones.size() > kMaxZones) return "at most 256 zones";
  std::set<std::string> names;
  for (const Zone& z : zones) {
    if (auto e = Validate(z)) return e;
    if (!names.insert(z.name).second) return "zone '" + z.name + "': the name is used twice";
  }
  return std::nullopt;
}

double SignedDistanceToPolygon(std::span<const Point> polygon, Point p) {
  const std::size_t n = polygon.size();
  double distance = std::numeric_limits<double>::infinity();
  bool inside = false;
  for (std::size_t i = 0, j = n - 1; i < n; j = i++) {
    const Point a = polygon[i], b = polygon[j];
    distance = std::min(distance, DistanceToSegment(a, b, p));
    if ((a.y_m > p.y_m) != (b.y_m > p.y_m) &&
        p.x_m < (b.x_m - a.x_m) * (p.y_m - a.y_m) / (b.y_m - a.y_m) + a.x_m) {
      inside = !inside;
    }
  }
  return inside ? distance : -distance;
}

namespace {

// The options, once the zones and they are valid (checked before the id follower is built from
// them: a bad option aborts naming the zones' option; aborts otherwise).
const ZoneOptions& Checked(std::span<const Zone> zones, const ZoneOptions& options) {
  if (auto e = Validate(zones)) {
    std::fprintf(stderr, "ZoneCounter: %s\n", e->c_str());
    std::abort();
  }
  if (auto e = Validate(options)) {
    std::fprintf(stderr, "ZoneCounter: %s\n", e->c_str());
    std::abort();
  }
  return options;
}

}  // namespace

ZoneCounter::ZoneCounter(std::vector<Zone> zones, const ZoneOptions& options)
    : zones_(std::move(zones)),
      options_(Checked(zones_, options)),
      follower_(fusion::IdFollowerOptions{.absent_hold_s = options_.absent_hold_s}) {
  for (const Zone& z : zones_) {
    ZoneData data;
    data.state.name = z.name;
    data.state.kind = z.kind;
    data_.push_back(std::move(data));
  }
}

void ZoneCounter::EndDwell(ZoneData& data, TrackInZone& t, common::UtcNs now_ns) {
  if (!t.in_region) return;
  t.in_region = false;
  const double dwell_s =
      common::NsToSeconds(std::max<common::DurationNs>(0, now_ns - t.region_since_ns));
  ++data.state.dwells_completed;
  data.state.dwell_total_s += dwell_s;
  data.state.dwell_max_s = std::max(data.state.dwell_max_s, dwell_s);
}

void ZoneCounter::UpdateTrack(const Zone& zone, ZoneData& data, const ZoneTrack& track,
                              common::UtcNs now_ns) {
  TrackInZone& t = data.tracks[track.id];
  if (!track.measured && t.has_last) return;  // a prediction keeps the state
  const Point p{track.x_m, track.y_m};
  const double h = options_.hysteresis_m;
  bool in_region = false;
  if (zone.kind == ZoneKind::kPolygon) {
    const double s = SignedDistanceToPolygon(zone.points, p);
    if (s >= h && t.side != Side::kB) {
      if (t.side == Side::kA) ++data.state.inbound;
      t.side = Side::kB;
    } else if (s <= -h && t.side != Side::kA) {
      if (t.side == Side::kB) ++data.state.outbound;
      t.side = Side::kA;
    }
    in_region = t.side == Side::kB || (t.side == Side::kUnknown && s > 0.0);
  } else {
    const LineCoordinates c = OnLine(zone, p);
    if (t.has_last && ((t.last_d < 0.0) != (c.d_m < 0.0))) {
      // Where the straight step between the two updates crosses the line.
      const double alpha = t.last_d / (t.last_d - c.d_m);
      const Point q{t.last_p.x_m + alpha * (p.x_m - t.last_p.x_m),
                    t.last_p.y_m + alpha * (p.y_m - t.last_p.y_m)};
      t.last_crossing_t = OnLine(zone, q).t;
    }
    const bool crossed_on_segment =
        t.last_crossing_t && *t.last_crossing_t >= 0.0 && *t.last_crossing_t <= 1.0;
    if (c.d_m >= h) {
      if (t.side == Side::kA && crossed_on_segment) ++data.state.inbound;
      t.side = Side::kB;
      t.last_crossing_t.reset();
    } else if (c.d_m <= -h) {
      if (t.side == Side::kB && crossed_on_segment) ++data.state.outbound;
      t.side = Side::kA;
      t.last_crossing_t.reset();
    }
    t.last_d = c.d_m;
    in_region = std::abs(c.d_m) < h && c.t >= 0.0 && c.t <= 1.0;
  }
  t.last_p = p;
  t.has_last = true;
  if (in_region && !t.in_region) {
    t.in_region = true;
    t.region_since_ns = now_ns;
  } else if (!in_region && t.in_region) {
    EndDwell(data, t, now_ns);
  }
}

void ZoneCounter::Gone(std::uint64_t id, common::UtcNs since_ns) {
  for (ZoneData& data : data_) {
    const auto it = data.tracks.find(id);
    if (it == data.tracks.end()) continue;
    if (it->second.in_region) ++data.state.lost_inside;
    EndDwell(data, it->second, since_ns);
    data.tracks.erase(it);
  }
}

void ZoneCounter::Fold(std::uint64_t merged, std::uint64_t survivor, bool take_merged,
                       common::UtcNs now_ns) {
  for (ZoneData& data : data_) {
    const auto m = data.tracks.find(merged);
    if (m == data.tracks.end()) continue;
    TrackInZone tm = m->second;
    data.tracks.erase(m);
    const auto s = data.tracks.find(survivor);
    if (s == data.tracks.end()) {
      data.tracks.emplace(survivor, tm);
      continue;
    }
    TrackInZone& ts = s->second;
    TrackInZone& kept = take_merged ? tm : ts;
    TrackInZone& dropped = take_merged ? ts : tm;
    if (kept.in_region && dropped.in_region) {
      kept.region_since_ns = std::min(kept.region_since_ns, dropped.region_since_ns);
    } else if (dropped.in_region) {
      EndDwell(data, dropped, now_ns);  // the person is where the kept state says: not here
    }
    if (take_merged) ts = tm;
  }
}

void ZoneCounter::Apply(const std::vector<fusion::IdEvent>& events,
                        std::span<const ZoneTrack> tracks, std::span<const std::size_t> track_index,
                        common::UtcNs now_ns) {
  using fusion::IdEndReason;
  using fusion::IdEventKind;
  for (const fusion::IdEvent& e : events) {
    // An id that ends is gone as of the first update it was absent from.
    const common::UtcNs since_ns = e.was_held ? e.held_since_ns : now_ns;
    switch (e.kind) {
      case IdEventKind::kPresent: {
        if (e.returned) ++counters_.absent_returned;
        const ZoneTrack& track = tracks[track_index[e.index]];
        for (std::size_t i = 0; i < zones_.size(); ++i) {
          UpdateTrack(zones_[i], data_[i], track, now_ns);
        }
        break;
      }
      case IdEventKind::kHeld:
        if (e.newly_held) ++counters_.absent_held;
        break;
      case IdEventKind::kMerged:
        // The survivor goes on from the merged id's state when it was held at the previous
        // update (hidden) and the merged id was not.
        Fold(e.id, e.survivor, e.survivor_known && e.survivor_held && !e.was_held, now_ns);
        ++counters_.merged;
        if (e.was_held) ++counters_.absent_gone;
        break;
      case IdEventKind::kEnded:
        if (e.reason == IdEndReason::kHoldExpired) {
          if (!e.was_held) ++counters_.absent_held;  // absent_hold_s 0: held and gone at once
          ++counters_.absent_gone;
          ++counters_.expired;
          Gone(e.id, e.held_since_ns);
          break;
        }
        Gone(e.id, since_ns);
        if (e.was_held) ++counters_.absent_gone;  // absent_held = returned + gone + still held
        if (e.reason != IdEndReason::kFusionRestarted) ++counters_.ended;
        if (e.reason == IdEndReason::kMergeUnresolved) ++counters_.merges_unresolved;
        break;
    }
  }
}

bool ZoneCounter::Update(std::span<const ZoneTrack> tracks,
                         std::span<const std::uint64_t> hidden_ids,
                         std::span<const ZoneEnded> ended, common::UtcNs now_ns) {
  if (started_ && now_ns < now_ns_) return false;
  started_ = true;
  now_ns_ = now_ns;
  if (zones_.empty()) return true;  // no zone knows any id
  // Tracks without a finite position are absent.
  std::vector<std::uint64_t> present;
  std::vector<std::size_t> track_index;
  for (std::size_t i = 0; i < tracks.size(); ++i) {
    if (!std::isfinite(tracks[i].x_m) || !std::isfinite(tracks[i].y_m)) continue;
    present.push_back(tracks[i].id);
    track_index.push_back(i);
  }
  std::vector<fusion::EndedFusedTrack> ends;
  ends.reserve(ended.size());
  for (const ZoneEnded& e : ended) {
    ends.push_back(
        {e.id, now_ns,
         e.merged_into != 0 ? fusion::FusedEndReason::kMerged : fusion::FusedEndReason::kTimedOut,
         e.merged_into});
  }
  Apply(follower_.Update(present, hidden_ids, ends, 0, now_ns), tracks, track_index, now_ns);
  counters_.duplicates = follower_.counters().duplicates;
  counters_.merges_into_ended = follower_.counters().merges_into_ended;
  return true;
}

void ZoneCounter::EndAll(common::UtcNs now_ns) {
  Apply(follower_.EndAll(now_ns), {}, {}, now_ns);
  ++counters_.restarts;
}

std::vector<ZoneState> ZoneCounter::States() const {
  std::vector<ZoneState> out;
  out.reserve(data_.size());
  for (const ZoneData& data : data_) {
    ZoneState s = data.state;
    for (const auto& [id, t] : data.tracks) {
      if (!t.in_region) continue;
      s.present_ids.push_back(id);
      s.present_dwell_s.push_back(
          common::NsToSeconds(std::max<common::DurationNs>(0, now_ns_ - t.region_since_ns)));
    }
    out.push_back(std::move(s));
  }
  return out;
}

}  // namespace lrfnet::zones
