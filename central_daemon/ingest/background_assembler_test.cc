#include "central_daemon/ingest/background_assembler.h"

#include <gtest/gtest.h>

#include <numeric>
#include <vector>

namespace lrfnet::daemon {
namespace {

constexpr common::UtcNs kReceive = 1'700'000'000'000'000'000;

// Parts of a snapshot of `beams` beams (range = 1000 + beam index), `per_part` beams each.
struct Snapshot {
  Snapshot(std::uint64_t session, std::uint32_t id, std::uint32_t beams, std::uint32_t per_part)
      : ranges(beams) {
    std::iota(ranges.begin(), ranges.end(), 1000u);
    const std::uint32_t count = (beams + per_part - 1) / per_part;
    for (std::uint32_t p = 0; p < count; ++p) {
      BackgroundPart part;
      part.session_id = session;
      part.snapshot_id = id;
      part.learned_until_ns = kReceive - 1000;
      part.first_angle_rad = -1.5;
      part.angle_step_rad = 0.01;
      part.beam_count = beams;
      part.part = p;
      part.part_count = count;
      part.first_beam = p * per_part;
      const std::uint32_t n = std::min(per_part, beams - part.first_beam);
      part.ranges_mm = std::span<const std::uint32_t>(ranges.data() + part.first_beam, n);
      parts.push_back(part);
    }
  }
  std::vector<std::uint32_t> ranges;
  std::vector<BackgroundPart> parts;
};

// Check, then Add when the check passes; nullopt when refused.
std::optional<AssembleOutcome> Offer(BackgroundAssembler& a, const BackgroundPart& p,
                                     BackgroundScan* out) {
  if (a.Check(p, nullptr)) return std::nullopt;
  return a.Add(p, kReceive, out);
}

TEST(BackgroundAssemblerTest, PartsInAnyOrderMakeTheWholeSnapshot) {
  BackgroundAssembler a(65536, 64);
  const Snapshot s(9, 3, 1000, 300);  // parts of 300, 300, 300, 100 beams
  ASSERT_EQ(s.parts.size(), 4u);
  BackgroundScan out;
  for (const std::size_t i : {2u, 0u, 3u}) {
    EXPECT_EQ(Offer(a, s.parts[i], &out), AssembleOutcome::kIncomplete);
  }
  EXPECT_TRUE(a.in_progress());
  EXPECT_EQ(Offer(a, s.parts[1], &out), AssembleOutcome::kCompleted);
  EXPECT_FALSE(a.in_progress());
  EXPECT_EQ(out.session_id, 9u);
  EXPECT_EQ(out.snapshot_id, 3u);
  EXPECT_EQ(out.learned_until_ns, kReceive - 1000);
  EXPECT_EQ(out.first_angle_rad, -1.5);
  EXPECT_EQ(out.angle_step_rad, 0.01);
  EXPECT_EQ(out.ranges_mm, s.ranges);
  EXPECT_EQ(out.receive_ns, kReceive);
  EXPECT_EQ(a.counters().completed, 1u);
  // Once complete, its parts are stale.
  EXPECT_EQ(Offer(a, s.parts[0], &out), AssembleOutcome::kIgnored);
}

TEST(BackgroundAssemblerTest, ARepeatedPartIsIgnored) {
  BackgroundAssembler a(65536, 64);
  const Snapshot s(1, 0, 600, 300);
  BackgroundScan out;
  EXPECT_EQ(Offer(a, s.parts[0], &out), AssembleOutcome::kIncomplete);
  EXPECT_EQ(Offer(a, s.parts[0], &out), AssembleOutcome::kIgnored);
  EXPECT_EQ(Offer(a, s.parts[1], &out), AssembleOutcome::kCompleted);
  EXPECT_EQ(out.ranges_mm, s.ranges);
}

TEST(BackgroundAssemblerTest, ANewerSnapshotAbandonsAnIncompleteOne) {
  BackgroundAssembler a(65536, 64);
  const Snapshot first(1, 4, 600, 300), second(1, 5, 600, 300);
  BackgroundScan out;
  EXPECT_EQ(Offer(a, first.parts[0], &out), AssembleOutcome::kIncomplete);
  EXPECT_EQ(Offer(a, second.parts[1], &out), AssembleOutcome::kIncomplete);
  EXPECT_EQ(a.counters().abandoned, 1u);
  // The late part of the abandoned snapshot is stale, not a reason to go back.
  EXPECT_EQ(Offer(a, first.parts[1], &out), AssembleOutcome::kIgnored);
  EXPECT_EQ(Offer(a, second.parts[0], &out), AssembleOutcome::kCompleted);
  EXPECT_EQ(out.snapshot_id, 5u);
}

TEST(BackgroundAssemblerTest, ANewSessionStartsOverAndResetAbandons) {
  BackgroundAssembler a(65536, 64);
  const Snapshot old_session(1, 7, 600, 300), new_session(2, 0, 600, 300);
  BackgroundScan out;
  EXPECT_EQ(Offer(a, old_session.parts[0], &out), AssembleOutcome::kIncomplete);
  a.Reset();
  EXPECT_EQ(a.counters().abandoned, 1u);
  // snapshot_id 0 < 7, but of the new session.
  EXPECT_EQ(Offer(a, new_session.parts[0], &out), AssembleOutcome::kIncomplete);
  EXPECT_EQ(Offer(a, new_session.parts[1], &out), AssembleOutcome::kCompleted);
  EXPECT_EQ(out.session_id, 2u);
}

TEST(BackgroundAssemblerTest, InconsistentOverlappingOrIncompletePartsAreRefused) {
  BackgroundAssembler a(65536, 64);
  const Snapshot s(1, 0, 900, 300);
  BackgroundScan out;
  ASSERT_EQ(Offer(a, s.parts[0], &out), AssembleOutcome::kIncomplete);
  std::string detail;
  for (auto change : {+[](BackgroundPart& p) { p.beam_count = 901; },
                      +[](BackgroundPart& p) { p.part_count = 4; },
                      +[](BackgroundPart& p) { p.angle_step_rad = 0.02; },
                      +[](BackgroundPart& p) { p.first_angle_rad = 0.0; },
                      +[](BackgroundPart& p) { p.learned_until_ns += 1; },
                      +[](BackgroundPart& p) { p.first_beam = 200; }}) {
    BackgroundPart p = s.parts[1];
    change(p);
    EXPECT_EQ(a.Check(p, &detail), RejectReason::kPart) << detail;
  }
  // The last part must cover exactly the beams left.
  ASSERT_EQ(Offer(a, s.parts[2], &out), AssembleOutcome::kIncomplete);
  BackgroundPart short_part = s.parts[1];
  short_part.ranges_mm = short_part.ranges_mm.first(299);
  EXPECT_EQ(a.Check(short_part, &detail), RejectReason::kPart);
  EXPECT_EQ(Offer(a, s.parts[1], &out), AssembleOutcome::kCompleted);
  EXPECT_EQ(out.ranges_mm, s.ranges);
  // One part that does not cover its snapshot.
  const Snapshot single(1, 1, 100, 100);
  BackgroundPart p = single.parts[0];
  p.ranges_mm = p.ranges_mm.first(50);
  EXPECT_EQ(a.Check(p, &detail), RejectReason::kPart);
}

TEST(BackgroundAssemblerTest, LimitsBoundWhatIsHeld) {
  BackgroundAssembler a(1000, 3);
  std::string detail;
  EXPECT_EQ(a.Check(Snapshot(1, 0, 1001, 1001).parts[0], &detail), RejectReason::kOutOfRange);
  EXPECT_EQ(a.Check(Snapshot(1, 0, 1000, 250).parts[0], &detail), RejectReason::kPart);
  const Snapshot fits(1, 0, 1000, 334);
  EXPECT_EQ(a.Check(fits.parts[0], &detail), std::nullopt);
  BackgroundPart beyond = fits.parts[2];
  beyond.first_beam = 700;
  EXPECT_EQ(a.Check(beyond, &detail), RejectReason::kPart);
}

}  // namespace
}  // namespace lrfnet::daemon
