#pragma once
// Pure TCP reassembler for one direction of one connection: segments in capture order -> the
// in-order byte stream the receiving application read. No socket, no clock, no logging; all memory
// is allocated in the constructor (pending byte ring and range/chunk tables), so hostile input
// cannot make it grow.
//
// Sequence numbers are compared modulo 2^32 (RFC 1982 style: a segment is "ahead" when it starts
// less than 2^31 bytes after the next expected byte), so a stream whose sequence number wraps is
// followed across the wrap.
//
// Behaviour:
//  - The stream starts at a SYN (data begins at ISN + 1) or, for a capture that begins
//    mid-connection, at the first segment that carries data.
//  - Bytes already delivered (retransmissions, overlapping segments) are dropped and counted; only
//    new bytes are delivered. Of two copies of a byte that arrive out of order, the first one is
//    kept.
//  - A segment that starts after the next expected byte is held until the hole before it is filled.
//    When the held bytes would exceed max_pending_bytes (or the held ranges max_pending_ranges), or
//    at Finish(), the reassembler gives up on the hole: it is skipped, counted with its size, and
//    the next chunk carries discontinuity = true.
//  - A SYN with a new initial sequence number starts a new connection: held bytes are given up on
//    as at Finish() and the next chunk carries discontinuity = true. A repeated SYN with the same
//    ISN is ignored.
//  - RST segments are ignored (their payload is not stream data). FIN carries data like any
//    segment.
//  - Each chunk carries the time of the segment whose arrival made it deliverable (for bytes held
//    out of order, the segment that filled the hole), which is when a receiving host would have
//    passed them to the application. Chunk times never decrease: a segment time earlier than one
//    already seen is raised to it.
//
// Usage: Push(segment); while (Pop(&chunk)) {...}; ... at the end: Finish(); while (Pop(&chunk))
// {...}. Push() and Finish() require that every chunk has been popped (a broken precondition
// aborts): chunks point into the pushed payload or into the ring, which the next Push() may
// overwrite.
//
// Thread-safety: none; one reassembler per stream direction.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "common/time.h"

namespace lrfnet::capture {

struct TcpReassemblerOptions {
  // Out-of-order bytes held while waiting for a missing segment (the ring is allocated at this
  // size).
  std::size_t max_pending_bytes = 1 << 20;
  // Disjoint held byte ranges (holes between them each need one): bounds the bookkeeping per
  // segment.
  std::size_t max_pending_ranges = 256;
  // A segment that starts more than max_pending_bytes beyond the highest byte seen so far is a stray
  // or forged packet unless more follow it: the stream jumps there only
  // after this many contiguous such segments; until then they are dropped and counted
  // (out_of_window_*), so one bogus packet cannot make the stream skip ahead and lose what follows.
  std::size_t jump_confirm_segments = 3;
};
// Accepts 1 <= max_pending_bytes <= 1 GiB, 1 <= max_pending_ranges <= 65536 and
// 1 <= jump_confirm_segments <= 64.
std::optional<std::string> Validate(const TcpReassemblerOptions& options);

struct TcpSegment {
  // Sequence number of the first payload byte (of the SYN itself if kTcpSyn is set).
  std::uint32_t seq = 0;
  std::uint8_t flags = 0;  // kTcp* bits of packet_parser.h
  std::span<const std::uint8_t> payload;
  common::UtcNs time_ns = 0;
};

struct ReassembledChunk {
  std::span<const std::uint8_t> bytes;  // valid until the next Push() or Finish()
  std::uint32_t seq = 0;                // sequence number of bytes[0]
  common::UtcNs time_ns = 0;
  bool discontinuity = false;  // a skipped hole or a new connection precedes these bytes
};

struct TcpReassemblerCounters {
  std::uint64_t segments = 0;               // segments pushed
  std::uint64_t retransmitted_bytes = 0;    // duplicate bytes dropped (retransmissions, overlaps)
  std::uint64_t out_of_order_segments = 0;  // segments that started after the next expected byte
  std::uint64_t gaps = 0;                   // holes given up on
  std::uint64_t gap_bytes = 0;              // their total size
  std::uint64_t connections = 0;            // SYNs that started a stream
  std::uint64_t delivered_bytes = 0;        // bytes handed out by Pop()
  std::uint64_t out_of_window_segments = 0; // far-ahead segments dropped (not, or not yet, a jump)
  std::uint64_t out_of_window_bytes = 0;
};

class TcpReassembler {
 public:
  explicit TcpReassembler(const TcpReassemblerOptions& options = {});  // options must Validate

  // Takes one segment of this direction, in capture order.
  void Push(const TcpSegment& segment);
  // End of input: gives up on every hole so that all held bytes become poppable.
  void Finish();
  // Next in-order chunk; false when none is waiting.
  bool Pop(ReassembledChunk* chunk);

  std::size_t pending_bytes() const { return pending_bytes_; }
  std::size_t pending_ranges() const { return ranges_.size(); }
  const TcpReassemblerCounters& counters() const { return counters_; }
  const TcpReassemblerOptions& options() const { return options_; }

 private:
  struct Range {  // held bytes [begin, end), stream positions
    std::int64_t begin = 0;
    std::int64_t end = 0;
  };

  void StartStream(std::uint32_t first_seq);
  void HandleData(std::uint32_t seq, std::span<const std::uint8_t> payload);
  // Delivers held bytes before `limit` (skipping holes); held bytes at or after `limit` that lie
  // before `drop_until` are dropped as duplicates.
  void GiveUpBefore(std::int64_t limit, std::int64_t drop_until);
  void DrainContiguous();
  bool Store(std::int64_t pos, std::span<const std::uint8_t> payload);
  void EmitFromRing(std::int64_t begin, std::int64_t end);
  void Gap(std::int64_t to);
  void Emit(std::span<const std::uint8_t> bytes);
  void CheckDrained() const;

  TcpReassemblerOptions options_;
  std::vector<std::uint8_t> ring_;     // held byte at position p is ring_[p % size]
  std::vector<Range> ranges_;          // sorted, disjoint, non-adjacent, all after next_pos_
  std::vector<ReassembledChunk> out_;  // chunks waiting for Pop()
  std::size_t out_read_ = 0;
  std::size_t pending_bytes_ = 0;

  bool has_stream_ = false;
  bool has_syn_ = false;
  std::uint32_t syn_seq_ = 0;
  // Stream positions are 64-bit byte offsets; next_seq_ is the sequence number at next_pos_.
  std::int64_t next_pos_ = 0;
  std::uint32_t next_seq_ = 0;
  bool discontinuity_ = false;  // attach to the next emitted chunk
  // Run of contiguous far-ahead segments seen so far (see jump_confirm_segments).
  std::size_t jump_run_ = 0;
  std::int64_t jump_run_end_ = 0;
  common::UtcNs now_ns_ = 0;
  bool has_time_ = false;
  TcpReassemblerCounters counters_;
};

}  // namespace lrfnet::capture
