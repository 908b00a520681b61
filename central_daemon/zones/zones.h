#pragma once
// Zones (pure): named polygons and lines in the world frame, and what the fused tracks do in them:
// occupancy, inbound / outbound counts since start, dwell times.
//
// Every zone has a *region* a track can be in: the inside of a polygon, or for a line the band of
// half-width hysteresis_m around the segment ("on the line"). Occupancy and dwell times count the
// tracks in the region.
//
// Crossings, with hysteresis so that a person standing on the boundary is counted once:
// - Polygon: s = the signed distance of the track to the boundary (> 0 inside). A track is
//   *inside* once s >= hysteresis_m and *outside* once s <= -hysteresis_m; in between it keeps its
//   state. outside -> inside is one inbound, inside -> outside one outbound.
// - Line A->B: d = cross(B - A, p - A) / |B - A|, the signed distance to the line (> 0 on the left
//   of A->B, i.e. walking from A to B the left-hand side). A track is on the left once
//   d >= hysteresis_m and on the right once d <= -hysteresis_m; in between it keeps its side. A
//   change of side counts when the track's last crossing of the line itself (d changing sign
//   between two updates, interpolated) lies on the segment: right -> left is inbound (moving
//   along the left normal of A->B), left -> right outbound. A track that walks around the end of
//   the segment is not counted.
// A track seen first somewhere in the band or inside a polygon has no "before" side: it counts
// when it leaves to a side, never as a crossing. Coasting tracks (predictions, measured = false)
// keep their state and are not used to change it.
//
// Dwell: a track's dwell in a region starts when it is first seen in it and ends when it leaves it
// or is gone. Ended dwells are summed (count, total, longest); a track that is gone in a polygon
// is also counted as lost_inside (it left the sensors' view there, or its fused track was merged).
//
// Absent tracks: the fusion may leave a hidden person's id out of its published tracks for a while
// and publish it again when a sensor sees the person again (fusion.report_sourceless off); it says
// which ids it keeps so (hidden) and which ended and why (fusion::FusionOutput). An id absent from
// an update is:
// - hidden (the fusion keeps it): *held* for as long as the fusion keeps it, with no timer of the
//   zones' own: it keeps its side, its region and its dwell (a hidden person is still where it
//   was last seen), and if it comes back it simply continues from its new position (a line
//   crossed while hidden counts once, as one straight step);
// - merged into another id (the fusion found the two are one object): folded into the surviving
//   id at once, before the update's positions are applied. No exit, no lost_inside: the person
//   goes on as the survivor. Per zone, the survivor goes on from the state of whichever of the
//   two was in the previous update (the merged id's when the survivor was held: the fusion
//   continues the survivor from the merged id's estimate then; else its own); where both were in
//   the region its dwell runs from the earlier start of the two; where only the one whose state
//   is dropped was in the region, that stay ends there as a completed dwell (the person is where
//   the other says). A survivor the zones did not know takes the merged id's state whole, its
//   hold too: the object was last seen when the merged id was, so a survivor absent without a
//   word from the fusion is gone absent_hold_s after the merged id was first absent (its dwell
//   ending then), not absent_hold_s after the merge (as lrfnetd's MQTT objects).
//   Crossings both ids counted before the merge stay counted;
// - otherwise ended (timed out): gone at once, as of the first update it was absent from;
// - none of these (the fusion reports nothing of it: Update without the fusion's lists, or an id
//   whose end is no longer reported): held for absent_hold_s, then gone as of the first update it
//   was absent from (absent_hold_s = 0: at once).
// A gone id ends its dwell and, inside a polygon or on a line, counts as lost_inside. Fused ids
// are never reused within one fusion; EndAll ends every id when the fusion starts afresh.
// Which of these an id is in each update is fusion::IdFollower's answer (id_follower.h: chains of
// merges, hostile lists), the same as for lrfnetd's MQTT objects.
// Before a merge the fusion reports two ids for one person (e.g. a hidden id and the new one a
// sensor started, until merge_updates checks join them), and the zones count both until then.
//
// Time is passed in (gateway UTC ns, the fused tracks' time base). Not thread-safe.

#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "central_daemon/fusion/id_follower.h"
#include "common/time.h"

namespace lrfnet::zones {

struct Point {
  double x_m = 0.0;
  double y_m = 0.0;
};

enum class ZoneKind : std::uint8_t { kPolygon, kLine };
const char* ToString(ZoneKind kind);

struct Zone {
  std::string name;  // [A-Za-z0-9_-]+, at most 64 bytes: also an MQTT topic level
  ZoneKind kind = ZoneKind::kPolygon;
  std::vector<Point> points;  // world frame; polygon: >= 3 vertices (not closed), line: 2 points
};

struct ZoneOptions {
  // Half-width of the hysteresis band [m] around polygon edges and lines (see the header). About
  // a person's radius plus the fused position's noise; a polygon narrower than twice this never
  // holds a track.
  double hysteresis_m = 0.3;
  // How long [s] an absent id the fusion reports nothing of (neither hidden nor ended: see the
  // header) is held before it is gone; lrfnetd sets it to the fusion's max_coast_s unless
  // configured. Ids the fusion reports hidden are held as long as it keeps them, ended ones end
  // at once, whatever this is. 0: gone at once.
  double absent_hold_s = 1.5;
};
std::optional<std::string> Validate(const ZoneOptions& options);

// Name, point count, finite coordinates, a line of non-zero length, a simple polygon (no
// crossing edges) with non-zero area. The error names the zone ("zone 'door': ...").
std::optional<std::string> Validate(const Zone& zone);
// Every zone and unique names; at most kMaxZones.
std::optional<std::string> Validate(std::span<const Zone> zones);
inline constexpr std::size_t kMaxZones = 256;
inline constexpr std::size_t kMaxZonePoints = 1024;

// Signed distance [m] of p to the polygon's boundary, > 0 inside (even-odd rule).
double SignedDistanceToPolygon(std::span<const Point> polygon, Point p);

// What became of absent ids (see the header), since start; ids known to some zone only.
struct ZoneCounters {
  std::uint64_t absent_held = 0;      // ids absent from an update while in some zone's state
  std::uint64_t absent_returned = 0;  // of these, came back
  std::uint64_t absent_gone = 0;      // of these, gone or merged (not come back)
  std::uint64_t merged = 0;           // ids merged into another id (folded into it, no exit)
  std::uint64_t ended = 0;            // ids the fusion ended otherwise (gone at once)
  std::uint64_t expired = 0;          // ids the fusion reported nothing of, gone after the hold
  std::uint64_t restarts = 0;         // EndAll calls (every id gone)
  // Of ended: a merge the fusion listed that cannot be followed (into the id itself, into a
  // cycle, along more merges than the follower follows, into an id that ended in the same list).
  std::uint64_t merges_unresolved = 0;
  std::uint64_t duplicates = 0;  // ids listed again in one update's tracks (the first counts)
  // Of merges_unresolved: merges into an id that ended earlier in the same list.
  std::uint64_t merges_into_ended = 0;
};

// An id the fusion ended (fusion::EndedFusedTrack as the zones need it).
struct ZoneEnded {
  std::uint64_t id = 0;
  std::uint64_t merged_into = 0;  // != 0: merged, the object goes on as this id
};

// A fused track as the zones see it.
struct ZoneTrack {
  std::uint64_t id = 0;
  double x_m = 0.0;
  double y_m = 0.0;
  bool measured = true;  // false: coasting (a prediction)
};

struct ZoneState {
  std::string name;
  ZoneKind kind = ZoneKind::kPolygon;
  std::vector<std::uint64_t> present_ids;  // tracks in the region now, ascending
  std::vector<double> present_dwell_s;     // how long each has been in it (same order)
  std::uint64_t inbound = 0;               // crossings since start (see the header)
  std::uint64_t outbound = 0;
  std::uint64_t dwells_completed = 0;  // tracks that left the region or disappeared in it
  double dwell_total_s = 0.0;          // sum of the completed dwells
  double dwell_max_s = 0.0;            // longest completed dwell
  std::uint64_t lost_inside = 0;       // tracks that disappeared in the region
};

class ZoneCounter {
 public:
  // Preconditions: Validate(zones), Validate(options) (checked; aborts otherwise).
  ZoneCounter(std::vector<Zone> zones, const ZoneOptions& options);

  // All current tracks at now_ns, the ids the fusion keeps without publishing them (hidden) and
  // the ids it ended (in the order they ended; ids the zones do not know are ignored), see the
  // header. Updates with a time before the previous one are ignored (returns false).
  bool Update(std::span<const ZoneTrack> tracks, std::span<const std::uint64_t> hidden_ids,
              std::span<const ZoneEnded> ended, common::UtcNs now_ns);
  // Without the fusion's lists: every absent id is held for absent_hold_s.
  bool Update(std::span<const ZoneTrack> tracks, common::UtcNs now_ns) {
    return Update(tracks, {}, {}, now_ns);
  }
  // Every id gone as of now_ns (the fusion started afresh: its ids are no longer the ones known
  // here); as when each ended.
  void EndAll(common::UtcNs now_ns);

  // Every zone's state as of the last update, in the order of the zones.
  std::vector<ZoneState> States() const;
  const std::vector<Zone>& zones() const { return zones_; }
  const ZoneOptions& options() const { return options_; }
  const ZoneCounters& counters() const { return counters_; }

 private:
  enum class Side : std::uint8_t { kUnknown, kA, kB };  // polygon: A outside, B inside
  struct TrackInZone {
    Side side = Side::kUnknown;
    bool in_region = false;
    common::UtcNs region_since_ns = 0;
    std::optional<double> last_crossing_t;  // line: where it last crossed (0..1 on the segment)
    double last_d = 0.0;                    // line: signed distance of the previous update
    Point last_p;
    bool has_last = false;
  };
  struct ZoneData {
    ZoneState state;
    std::map<std::uint64_t, TrackInZone> tracks;
  };
  void UpdateTrack(const Zone& zone, ZoneData& data, const ZoneTrack& track, common::UtcNs now_ns);
  static void EndDwell(ZoneData& data, TrackInZone& t, common::UtcNs now_ns);
  // id gone as of since_ns in every zone (its dwell ends; lost_inside where it was in a region).
  void Gone(std::uint64_t id, common::UtcNs since_ns);
  // merged folded into survivor (see the header), as of the previous update; take_merged: the
  // survivor goes on from the merged id's state.
  void Fold(std::uint64_t merged, std::uint64_t survivor, bool take_merged, common::UtcNs now_ns);
  // What the id follower says of a period: tracks[track_index[e.index]] for present ids.
  void Apply(const std::vector<fusion::IdEvent>& events, std::span<const ZoneTrack> tracks,
             std::span<const std::size_t> track_index, common::UtcNs now_ns);

  std::vector<Zone> zones_;
  ZoneOptions options_;
  std::vector<ZoneData> data_;
  // Which ids are known, held, merged or gone (absent_hold_s; the fusion's lists).
  fusion::IdFollower follower_;
  ZoneCounters counters_;
  common::UtcNs now_ns_ = 0;
  bool started_ = false;
};

}  // namespace lrfnet::zones
