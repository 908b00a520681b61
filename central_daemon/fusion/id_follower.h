#pragma once
// Following fused ids over time (pure): what became of every id a consumer of the fuser's output
// (lrfnetd's zones, its MQTT objects) has seen, period by period.
//
// Each period the consumer hands the fuser's Output (FusionOutput: the published tracks, the ids
// kept unpublished, the ids that ended and why) and the fuser's generation; the follower keeps the
// set of ids the consumer knows and returns one event per known id (and per new one):
// - present: in the output's tracks (with the track). `returned` when it was held at the end of
//   the previous period.
// - held: absent from the tracks but kept: the fusion says it keeps it (hidden), or it says
//   nothing of it and it has been absent for less than absent_hold_s (an id whose end the fuser
//   no longer reports, a fuser fed without Ticks). `newly_held` in the first period of a hold;
//   held_since_ns is the time of the first period it was absent from.
// - merged: the fusion merged it into another id (the same object). The survivor is the last id
//   of the chain of merges the output lists (a -> b, b -> c: c), walked through ids absent from
//   the tracks; the walk stops at an id in the tracks. A survivor the consumer did not know takes
//   the merged id's place whole (its hold too, if it was held): the consumer moves its state to
//   it. A merge into itself, into a cycle of merges, along more than max_merge_hops merges (all
//   counted), or into an id that ended earlier in the same output (timed out, or its own merge
//   not followed; whether the consumer knew that id or not; counted) is not followed: the id
//   ends (kMergeUnresolved).
// - ended: timed out (the fusion's end), fusion_restarted (a new generation, or EndAll: every
//   known id ends), hold_expired (absent without a word from the fusion for absent_hold_s, or a
//   hold that began after the period's time: the clock stepped back). Ended and merged ids are
//   forgotten; an id is reported in at most one event per period.
// An end the output lists for an id the consumer does not know (never seen, or already ended) is
// ignored; so is an end listed for an id that is in the tracks (the tracks win), and a hidden
// listing of an id in the tracks. Of duplicate ids in the tracks the first counts (counted).
//
// Order of a period's events (the order a consumer applies them in): the ends of a new
// generation, then merges and ends in the output's order of ends (as of the previous period: a
// survivor goes on from there), then present ids in the order of the tracks, then held and
// hold-expired ids in ascending order.
//
// Time is passed in (gateway UTC ns, the output's time base). Not thread-safe.

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "central_daemon/fusion/fusion.h"
#include "common/time.h"

namespace lrfnet::fusion {

struct IdFollowerOptions {
  // How long [s] an id absent from the tracks that the fusion reports nothing of (neither hidden
  // nor ended) is held before it ends (hold_expired). lrfnetd: zones.absent_hold_s (the fusion's
  // max_coast_s unless configured). Hidden ids are held as long as the fusion keeps them, whatever
  // this is. 0: at once.
  double absent_hold_s = 1.5;
  // Most merges followed from one id to its survivor: a chain that is longer is cut (the id ends,
  // kMergeUnresolved). A fuser's chain within its ended_report_s holds a few merges at most.
  std::size_t max_merge_hops = 64;
};
std::optional<std::string> Validate(const IdFollowerOptions& options);

enum class IdEventKind : std::uint8_t { kPresent, kHeld, kMerged, kEnded };
const char* ToString(IdEventKind kind);

enum class IdEndReason : std::uint8_t {
  kTimedOut,  // the fusion ended it (no update for its max_coast_s)
  // merged into itself, into a cycle, along a chain beyond max_merge_hops, or into an id that
  // ended earlier in the same output
  kMergeUnresolved,
  kFusionRestarted,  // a new fuser (generation) or EndAll
  kHoldExpired,      // absent for absent_hold_s with no word from the fusion
};
// "timed_out", "merge_unresolved", "fusion_restarted", "hold_expired".
const char* ToString(IdEndReason reason);

struct IdEvent {
  std::uint64_t id = 0;
  IdEventKind kind = IdEventKind::kPresent;
  // kPresent: its index in the period's tracks (or present ids), and the track when the period
  // was given as a FusionOutput (valid while that output lives), else null.
  std::size_t index = 0;
  const FusedTrack* track = nullptr;
  // kPresent: it was held at the end of the previous period (it came back).
  bool returned = false;
  // kHeld: the fusion keeps it (hidden); false: held by absent_hold_s.
  bool hidden = false;
  // kHeld: the first period of its hold.
  bool newly_held = false;
  // Whether it was held at the end of the previous period (kHeld, kMerged, kEnded; kHeld with
  // newly_held: false) and since when: the time of the first period it was absent from.
  bool was_held = false;
  common::UtcNs held_since_ns = 0;
  // kMerged: the id that goes on as the object, whether the consumer knew it before this event
  // (else it takes this id's place whole; one that took an earlier merged id's place in this
  // period counts as known), and whether that survivor was held at the end of the previous
  // period (for one that took an earlier merged id's place in this period: whether that id was).
  std::uint64_t survivor = 0;
  bool survivor_known = false;
  bool survivor_held = false;
  // kEnded: why; kMerged, kEnded: when (the fusion's time of the end; the period's time for
  // kFusionRestarted and kHoldExpired).
  IdEndReason reason = IdEndReason::kTimedOut;
  common::UtcNs ended_ns = 0;
};

struct IdFollowerCounters {
  std::uint64_t periods = 0;
  std::uint64_t followed = 0;          // ids seen first in the tracks
  std::uint64_t taken_over = 0;        // survivors the consumer knew first as a merge's target
  std::uint64_t held = 0;              // holds started
  std::uint64_t returned = 0;          // held ids back in the tracks
  std::uint64_t merged = 0;            // merged into a survivor
  std::uint64_t timed_out = 0;         // ended by the fusion
  std::uint64_t hold_expired = 0;      // ended after absent_hold_s without a word of the fusion
  std::uint64_t restarted = 0;         // ended by a new generation or EndAll
  std::uint64_t merge_cycles = 0;      // merges into itself or into a cycle (ended)
  std::uint64_t merge_chains_cut = 0;  // chains longer than max_merge_hops (ended)
  std::uint64_t duplicates = 0;        // ids listed again in one period's tracks (ignored)
  // Merges into an id that ended earlier in the same output (known to the consumer or not; ended)
  std::uint64_t merges_into_ended = 0;
};

class IdFollower {
 public:
  // Precondition: Validate(options) (checked; aborts otherwise).
  explicit IdFollower(const IdFollowerOptions& options = {});

  // One period of the fuser's output as of now_ns. The events are valid until the next call.
  const std::vector<IdEvent>& Update(const FusionOutput& output, std::uint64_t generation,
                                     common::UtcNs now_ns);
  // The same from the ids alone: present_ids in the order of the consumer's tracks (IdEvent::index
  // refers to it; track is null).
  const std::vector<IdEvent>& Update(std::span<const std::uint64_t> present_ids,
                                     std::span<const std::uint64_t> hidden_ids,
                                     std::span<const EndedFusedTrack> ended,
                                     std::uint64_t generation, common::UtcNs now_ns);
  // Every known id ends as of now_ns (kFusionRestarted), in ascending order.
  const std::vector<IdEvent>& EndAll(common::UtcNs now_ns);

  bool Known(std::uint64_t id) const { return ids_.count(id) != 0; }
  bool Held(std::uint64_t id) const;
  std::size_t size() const { return ids_.size(); }
  const IdFollowerCounters& counters() const { return counters_; }
  const IdFollowerOptions& options() const { return options_; }

 private:
  struct Followed {
    bool held = false;
    common::UtcNs held_since_ns = 0;
  };
  void EndAllInto(common::UtcNs now_ns);
  // The survivor of a merge of `id` into `into` listed at `position` of the output's ends (0:
  // unresolved, counted).
  std::uint64_t Survivor(std::uint64_t id, std::uint64_t into, std::size_t position);
  // Whether the output ends `id` without a merge before `position` of its ends.
  bool EndedBefore(std::uint64_t id, std::size_t position) const;

  IdFollowerOptions options_;
  std::map<std::uint64_t, Followed> ids_;
  std::uint64_t generation_ = 0;
  bool started_ = false;
  std::vector<IdEvent> events_;
  // Per period, reused: the present ids (sorted), the hidden ids (sorted), the merges listed.
  std::vector<std::uint64_t> present_;
  std::vector<std::uint64_t> hidden_;
  std::map<std::uint64_t, std::uint64_t> merged_into_;
  // Per period, reused: every id the output ends without a merge (absent from the tracks, known
  // or not) and the position of its first such end.
  std::map<std::uint64_t, std::size_t> ended_at_;
  IdFollowerCounters counters_;
};

}  // namespace lrfnet::fusion
