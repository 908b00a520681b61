#pragma once
// Reassembles one sensor's background snapshots from their parts (pure, no protobuf: the ingest
// converts each BackgroundSnapshot datagram into a BackgroundPart view).
//
// A snapshot is identified by (session_id, snapshot_id); the tracker numbers them upwards within a
// session. Rules:
// - A part of a newer snapshot_id than any seen in the session starts it; a snapshot still in
//   reassembly is abandoned (counted).
// - A part of the snapshot in reassembly must agree with its first part on the geometry
//   (beam_count, part_count, first_angle_rad, angle_step_rad, learned_until_ns) and must not
//   overlap beams of another part (kPart). A part index received before is a repeat and ignored.
// - The snapshot is complete when all part_count parts arrived and every beam is covered exactly
//   once; a part that would complete a snapshot with beams left uncovered is refused (kPart).
// - A part of an older snapshot_id, or of one completed or abandoned already, is stale and ignored.
// - Another session_id starts over (Reset the assembler on a restart; a snapshot in reassembly is
//   abandoned).
// Bounded: one snapshot in reassembly, of at most max_beams beams and max_part_count parts (parts
// beyond those are refused, kOutOfRange / kPart); storage is reused from snapshot to snapshot.
// Not thread-safe.

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "central_daemon/ingest/ingest.h"
#include "central_daemon/ingest/sensor_data.h"
#include "common/time.h"

namespace lrfnet::daemon {

// One part of a snapshot, as received (lrfnet.proto BackgroundSnapshot). The span is the caller's.
struct BackgroundPart {
  std::uint64_t session_id = 0;
  std::uint32_t snapshot_id = 0;
  common::UtcNs learned_until_ns = 0;
  double first_angle_rad = 0.0;
  double angle_step_rad = 0.0;
  std::uint32_t beam_count = 0;
  std::uint32_t part = 0;
  std::uint32_t part_count = 0;
  std::uint32_t first_beam = 0;
  std::span<const std::uint32_t> ranges_mm;
};

enum class AssembleOutcome : std::uint8_t {
  kIncomplete,  // stored; more parts to come
  kCompleted,   // this part completed the snapshot
  kIgnored,     // stale snapshot or a repeated part: nothing changed
};

struct BackgroundAssemblerCounters {
  std::uint64_t completed = 0;
  std::uint64_t abandoned = 0;  // replaced by a newer snapshot or dropped by Reset
  std::uint64_t ignored = 0;    // stale or repeated parts
};

class BackgroundAssembler {
 public:
  // Preconditions: max_beams >= 1, max_part_count >= 1 (checked; aborts otherwise).
  BackgroundAssembler(std::uint32_t max_beams, std::uint32_t max_part_count);

  // Whether `part` may be added (nullopt) or why not; changes nothing. *detail (when not null) is
  // set to one line on refusal.
  std::optional<RejectReason> Check(const BackgroundPart& part, std::string* detail) const;
  // Adds a part that passed Check. On kCompleted, *out is the whole snapshot (receive_ns: this
  // part's).
  AssembleOutcome Add(const BackgroundPart& part, common::UtcNs receive_ns, BackgroundScan* out);
  // Forgets the session: a snapshot in reassembly is abandoned (counted).
  void Reset();

  void set_limits(std::uint32_t max_beams, std::uint32_t max_part_count);

  bool in_progress() const { return in_progress_; }
  const BackgroundAssemblerCounters& counters() const { return counters_; }

 private:
  enum class Relation : std::uint8_t { kNew, kCurrent, kStale };
  Relation Classify(const BackgroundPart& part) const;
  bool Overlaps(std::uint32_t first, std::size_t count) const;

  std::uint32_t max_beams_;
  std::uint32_t max_part_count_;
  BackgroundAssemblerCounters counters_;

  bool has_session_ = false;
  std::uint64_t session_id_ = 0;
  std::uint32_t newest_snapshot_id_ = 0;  // newest started in the session
  bool in_progress_ = false;
  // The snapshot in reassembly: geometry of its first part, beams and parts received so far.
  BackgroundPart geometry_;
  std::vector<std::uint32_t> ranges_mm_;
  std::vector<std::uint64_t> beam_filled_;  // one bit per beam
  std::vector<bool> part_received_;
  std::uint32_t parts_received_ = 0;
  std::uint64_t beams_filled_ = 0;
};

}  // namespace lrfnet::daemon
