#include "central_daemon/ingest/background_assembler.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>

namespace lrfnet::daemon {
namespace {

std::optional<RejectReason> Refuse(RejectReason reason, std::string* detail, const char* what) {
  if (detail != nullptr) detail->assign(what);
  return reason;
}

}  // namespace

BackgroundAssembler::BackgroundAssembler(std::uint32_t max_beams, std::uint32_t max_part_count) {
  set_limits(max_beams, max_part_count);
}

void BackgroundAssembler::set_limits(std::uint32_t max_beams, std::uint32_t max_part_count) {
  if (max_beams == 0 || max_part_count == 0) {
    std::fprintf(stderr, "BackgroundAssembler: limits must be >= 1\n");
    std::abort();
  }
  max_beams_ = max_beams;
  max_part_count_ = max_part_count;
}

BackgroundAssembler::Relation BackgroundAssembler::Classify(const BackgroundPart& part) const {
  if (!has_session_ || part.session_id != session_id_) return Relation::kNew;
  if (part.snapshot_id > newest_snapshot_id_) return Relation::kNew;
  if (part.snapshot_id == newest_snapshot_id_ && in_progress_) return Relation::kCurrent;
  return Relation::kStale;
}

bool BackgroundAssembler::Overlaps(std::uint32_t first, std::size_t count) const {
  for (std::size_t i = first; i < first + count; ++i) {
    if ((beam_filled_[i / 64] >> (i % 64)) & 1u) return true;
  }
  return false;
}

std::optional<RejectReason> BackgroundAssembler::Check(const BackgroundPart& part,
                                                       std::string* detail) const {
  const std::size_t count = part.ranges_mm.size();
  if (part.beam_count == 0 || part.beam_count > max_beams_) {
    return Refuse(RejectReason::kOutOfRange, detail, "background beam_count outside its bound");
  }
  if (part.part_count == 0 || part.part_count > max_part_count_ || part.part >= part.part_count) {
    return Refuse(RejectReason::kPart, detail, "background part index or count outside its bound");
  }
  if (static_cast<std::uint64_t>(part.first_beam) + count > part.beam_count) {
    return Refuse(RejectReason::kPart, detail, "background part beyond beam_count");
  }
  switch (Classify(part)) {
    case Relation::kStale:
      return std::nullopt;
    case Relation::kNew:
      if (part.part_count == 1 && count != part.beam_count) {
        return Refuse(RejectReason::kPart, detail,
                      "background snapshot of one part leaves beams uncovered");
      }
      return std::nullopt;
    case Relation::kCurrent:
      break;
  }
  if (part.beam_count != geometry_.beam_count || part.part_count != geometry_.part_count ||
      part.first_angle_rad != geometry_.first_angle_rad ||
      part.angle_step_rad != geometry_.angle_step_rad ||
      part.learned_until_ns != geometry_.learned_until_ns) {
    return Refuse(RejectReason::kPart, detail,
                  "background part disagrees with its snapshot's geometry");
  }
  if (part_received_[part.part]) return std::nullopt;  // a repeat, ignored by Add
  if (Overlaps(part.first_beam, count)) {
    return Refuse(RejectReason::kPart, detail, "background part overlaps another part's beams");
  }
  if (parts_received_ + 1 == geometry_.part_count &&
      beams_filled_ + count != geometry_.beam_count) {
    return Refuse(RejectReason::kPart, detail, "background parts leave beams uncovered");
  }
  return std::nullopt;
}

AssembleOutcome BackgroundAssembler::Add(const BackgroundPart& part, common::UtcNs receive_ns,
                                         BackgroundScan* out) {
  switch (Classify(part)) {
    case Relation::kStale:
      ++counters_.ignored;
      return AssembleOutcome::kIgnored;
    case Relation::kNew:
      if (in_progress_) ++counters_.abandoned;
      has_session_ = true;
      session_id_ = part.session_id;
      newest_snapshot_id_ = part.snapshot_id;
      in_progress_ = true;
      geometry_ = part;
      geometry_.ranges_mm = {};
      ranges_mm_.assign(part.beam_count, 0);
      beam_filled_.assign((static_cast<std::size_t>(part.beam_count) + 63) / 64, 0);
      part_received_.assign(part.part_count, false);
      parts_received_ = 0;
      beams_filled_ = 0;
      break;
    case Relation::kCurrent:
      if (part_received_[part.part]) {
        ++counters_.ignored;
        return AssembleOutcome::kIgnored;
      }
      break;
  }
  std::copy(part.ranges_mm.begin(), part.ranges_mm.end(),
            ranges_mm_.begin() + static_cast<std::ptrdiff_t>(part.first_beam));
  for (std::size_t i = part.first_beam; i < part.first_beam + part.ranges_mm.size(); ++i) {
    beam_filled_[i / 64] |= std::uint64_t{1} << (i % 64);
  }
  part_received_[part.part] = true;
  ++parts_received_;
  beams_filled_ += part.ranges_mm.size();
  if (parts_received_ < geometry_.part_count) return AssembleOutcome::kIncomplete;

  in_progress_ = false;
  if (beams_filled_ != geometry_.beam_count) {  // only when Check was skipped
    ++counters_.abandoned;
    return AssembleOutcome::kIgnored;
  }
  ++counters_.completed;
  out->session_id = session_id_;
  out->snapshot_id = geometry_.snapshot_id;
  out->learned_until_ns = geometry_.learned_until_ns;
  out->first_angle_rad = geometry_.first_angle_rad;
  out->angle_step_rad = geometry_.angle_step_rad;
  out->ranges_mm.assign(ranges_mm_.begin(), ranges_mm_.end());
  out->receive_ns = receive_ns;
  return AssembleOutcome::kCompleted;
}

void BackgroundAssembler::Reset() {
  if (in_progress_) ++counters_.abandoned;
  in_progress_ = false;
  has_session_ = false;
}

}  // namespace lrfnet::daemon
