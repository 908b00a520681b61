#include "central_daemon/fusion/id_follower.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <set>

namespace lrfnet::fusion {

std::optional<std::string> Validate(const IdFollowerOptions& options) {
  if (!(options.absent_hold_s >= 0.0 && options.absent_hold_s <= 3600.0)) {
    return "absent_hold_s: must be in [0, 3600]";
  }
  if (options.max_merge_hops < 1 || options.max_merge_hops > 1'000'000) {
    return "max_merge_hops: must be in [1, 1000000]";
  }
  return std::nullopt;
}

const char* ToString(IdEventKind kind) {
  switch (kind) {
    case IdEventKind::kPresent:
      return "present";
    case IdEventKind::kHeld:
      return "held";
    case IdEventKind::kMerged:
      return "merged";
    case IdEventKind::kEnded:
      return "ended";
  }
  return "?";
}

const char* ToString(IdEndReason reason) {
  switch (reason) {
    case IdEndReason::kTimedOut:
      return "timed_out";
    case IdEndReason::kMergeUnresolved:
      return "merge_unresolved";
    case IdEndReason::kFusionRestarted:
      return "fusion_restarted";
    case IdEndReason::kHoldExpired:
      return "hold_expired";
  }
  return "?";
}

IdFollower::IdFollower(const IdFollowerOptions& options) : options_(options) {
  if (auto e = Validate(options_)) {
    std::fprintf(stderr, "IdFollower: %s\n", e->c_str());
    std::abort();
  }
}

bool IdFollower::Held(std::uint64_t id) const {
  const auto it = ids_.find(id);
  return it != ids_.end() && it->second.held;
}

const std::vector<IdEvent>& IdFollower::Update(const FusionOutput& output, std::uint64_t generation,
                                               common::UtcNs now_ns) {
  std::vector<std::uint64_t> present_ids;
  present_ids.reserve(output.tracks.size());
  for (const FusedTrack& t : output.tracks) present_ids.push_back(t.id);
  std::vector<std::uint64_t> hidden_ids;
  hidden_ids.reserve(output.hidden.size());
  for (const HiddenFusedTrack& h : output.hidden) hidden_ids.push_back(h.id);
  Update(present_ids, hidden_ids, output.ended, generation, now_ns);
  for (IdEvent& e : events_) {
    if (e.kind == IdEventKind::kPresent) e.track = &output.tracks[e.index];
  }
  return events_;
}

bool IdFollower::EndedBefore(std::uint64_t id, std::size_t position) const {
  const auto it = ended_at_.find(id);
  return it != ended_at_.end() && it->second < position;
}

std::uint64_t IdFollower::Survivor(std::uint64_t id, std::uint64_t into, std::size_t position) {
  // Through ids absent from the tracks that were merged on themselves, to the id that goes on.
  std::set<std::uint64_t> visited{id};
  std::uint64_t survivor = into;
  for (std::size_t hops = 1;; ++hops) {
    if (visited.count(survivor) != 0) {
      ++counters_.merge_cycles;
      return 0;
    }
    if (std::binary_search(present_.begin(), present_.end(), survivor)) return survivor;
    // An id that ended (not merged) before this end in the output cannot take the object on,
    // whether the consumer knew it or not.
    if (EndedBefore(survivor, position)) {
      ++counters_.merges_into_ended;
      return 0;
    }
    const auto next = merged_into_.find(survivor);
    if (next == merged_into_.end()) return survivor;
    if (hops >= options_.max_merge_hops) {
      ++counters_.merge_chains_cut;
      return 0;
    }
    visited.insert(survivor);
    survivor = next->second;
  }
}

const std::vector<IdEvent>& IdFollower::Update(std::span<const std::uint64_t> present_ids,
                                               std::span<const std::uint64_t> hidden_ids,
                                               std::span<const EndedFusedTrack> ended,
                                               std::uint64_t generation, common::UtcNs now_ns) {
  events_.clear();
  ++counters_.periods;
  if (started_ && generation != generation_) EndAllInto(now_ns);
  started_ = true;
  generation_ = generation;
  // Held at the end of the previous period (a survivor that takes a held id's place in this
  // period was not: it is newly held, or present without having come back).
  std::vector<std::uint64_t> was_held;
  for (const auto& [id, f] : ids_) {
    if (f.held) was_held.push_back(id);
  }
  const auto held_before = [&](std::uint64_t id) {
    return std::binary_search(was_held.begin(), was_held.end(), id);
  };
  present_.assign(present_ids.begin(), present_ids.end());
  std::sort(present_.begin(), present_.end());
  hidden_.assign(hidden_ids.begin(), hidden_ids.end());
  std::sort(hidden_.begin(), hidden_.end());
  const auto present = [&](std::uint64_t id) {
    return std::binary_search(present_.begin(), present_.end(), id);
  };
  merged_into_.clear();
  ended_at_.clear();
  for (std::size_t i = 0; i < ended.size(); ++i) {
    const EndedFusedTrack& e = ended[i];
    if (e.merged_into != 0) {
      merged_into_[e.id] = e.merged_into;
    } else if (!present(e.id)) {
      ended_at_.try_emplace(e.id, i);  // known or not: its first end without a merge
    }
  }

  // Ends, as of the previous period. Known ids whose merge is unresolved end too.
  std::set<std::uint64_t> ended_now;
  for (std::size_t i = 0; i < ended.size(); ++i) {
    const EndedFusedTrack& e = ended[i];
    const auto it = ids_.find(e.id);
    if (it == ids_.end() || present(e.id)) continue;
    IdEvent ev;
    ev.id = e.id;
    ev.was_held = it->second.held;
    ev.held_since_ns = it->second.held_since_ns;
    ev.ended_ns = e.ended_ns;
    const Followed followed = it->second;
    ids_.erase(it);
    std::uint64_t survivor = e.merged_into != 0 ? Survivor(e.id, e.merged_into, i) : 0;
    // A survivor that ended earlier in this output (its own merge unresolved) cannot take the
    // object on.
    if (survivor != 0 && ended_now.count(survivor) != 0) {
      ++counters_.merges_into_ended;
      survivor = 0;
    }
    if (survivor != 0) {
      ev.kind = IdEventKind::kMerged;
      ev.survivor = survivor;
      const auto s = ids_.find(survivor);
      ev.survivor_known = s != ids_.end();
      ev.survivor_held = ev.survivor_known && s->second.held;
      if (!ev.survivor_known) {
        ids_.emplace(survivor, followed);  // it takes the merged id's place, its hold too
        ++counters_.taken_over;
      }
      ++counters_.merged;
    } else {
      ev.kind = IdEventKind::kEnded;
      if (e.merged_into != 0) {
        ev.reason = IdEndReason::kMergeUnresolved;
      } else {
        ev.reason = IdEndReason::kTimedOut;
        ++counters_.timed_out;
      }
      ended_now.insert(e.id);
    }
    events_.push_back(ev);
  }

  // Present ids, in the order of the tracks; the first of duplicates counts.
  std::set<std::uint64_t> listed;
  for (std::size_t i = 0; i < present_ids.size(); ++i) {
    const std::uint64_t id = present_ids[i];
    if (!listed.insert(id).second) {
      ++counters_.duplicates;
      continue;
    }
    const auto [it, first] = ids_.try_emplace(id);
    if (first) ++counters_.followed;
    IdEvent ev;
    ev.id = id;
    ev.kind = IdEventKind::kPresent;
    ev.index = i;
    ev.returned = held_before(id);
    if (ev.returned) ++counters_.returned;
    it->second = Followed{};
    events_.push_back(ev);
  }

  // The other known ids: held while the fusion keeps them, else for absent_hold_s.
  const auto hold_ns = static_cast<common::DurationNs>(options_.absent_hold_s * 1e9);
  for (auto it = ids_.begin(); it != ids_.end();) {
    const std::uint64_t id = it->first;
    Followed& f = it->second;
    if (present(id)) {
      ++it;
      continue;
    }
    IdEvent ev;
    ev.id = id;
    ev.was_held = held_before(id);
    if (!f.held) {
      f.held = true;
      f.held_since_ns = now_ns;
    }
    ev.held_since_ns = f.held_since_ns;
    ev.newly_held = !ev.was_held;
    if (ev.newly_held) ++counters_.held;
    ev.hidden = std::binary_search(hidden_.begin(), hidden_.end(), id);
    // A hold that began after now: the clock stepped back; the hold is over.
    const bool expired =
        !ev.hidden && (now_ns - f.held_since_ns >= hold_ns || now_ns < f.held_since_ns);
    if (expired) {
      ev.kind = IdEventKind::kEnded;
      ev.reason = IdEndReason::kHoldExpired;
      ev.ended_ns = now_ns;
      ++counters_.hold_expired;
      it = ids_.erase(it);
    } else {
      ev.kind = IdEventKind::kHeld;
      ++it;
    }
    events_.push_back(ev);
  }
  return events_;
}

void IdFollower::EndAllInto(common::UtcNs now_ns) {
  for (const auto& [id, f] : ids_) {
    IdEvent ev;
    ev.id = id;
    ev.kind = IdEventKind::kEnded;
    ev.reason = IdEndReason::kFusionRestarted;
    ev.was_held = f.held;
    ev.held_since_ns = f.held_since_ns;
    ev.ended_ns = now_ns;
    events_.push_back(ev);
    ++counters_.restarted;
  }
  ids_.clear();
}

const std::vector<IdEvent>& IdFollower::EndAll(common::UtcNs now_ns) {
  events_.clear();
  EndAllInto(now_ns);
  return events_;
}

}  // namespace lrfnet::fusion
