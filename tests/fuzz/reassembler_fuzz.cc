// TcpReassembler on arbitrary segment sequences. Input format: see capture_seeds.h.
// Checks: never more bytes delivered than fed; held bytes and ranges stay within their bounds;
// chunks are non-empty, follow each other without a hole unless marked as a discontinuity, and
// their times never decrease; the delivered counter matches; Finish() leaves nothing held; in
// synthetic mode every delivered byte is the byte that was sent at its sequence number.

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <span>
#include <vector>

#include "common/capture/tcp_reassembler.h"
#include "tests/fuzz/capture_seeds.h"

namespace {

void Check(bool ok, const char* what) {
  if (!ok) {
    std::fprintf(stderr, "reassembler_fuzz: check failed: %s\n", what);
    std::abort();
  }
}

struct Observer {
  bool synthetic = false;
  bool has_previous = false;
  std::uint32_t next_seq = 0;
  lrfnet::common::UtcNs last_time_ns = 0;
  std::uint64_t delivered = 0;

  void Drain(lrfnet::capture::TcpReassembler* reassembler) {
    lrfnet::capture::ReassembledChunk chunk;
    while (reassembler->Pop(&chunk)) {
      Check(!chunk.bytes.empty(), "chunks are not empty");
      if (has_previous) {
        Check(chunk.discontinuity || chunk.seq == next_seq, "contiguous unless marked");
        Check(chunk.time_ns >= last_time_ns, "times never decrease");
      }
      if (synthetic) {
        for (std::size_t i = 0; i < chunk.bytes.size(); ++i) {
          Check(chunk.bytes[i] ==
                    lrfnet::fuzz::SyntheticByte(chunk.seq + static_cast<std::uint32_t>(i)),
                "delivered byte matches its sequence number");
        }
      }
      has_previous = true;
      next_seq = chunk.seq + static_cast<std::uint32_t>(chunk.bytes.size());
      last_time_ns = chunk.time_ns;
      delivered += chunk.bytes.size();
    }
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace lrfnet::capture;
  using namespace lrfnet::fuzz;
  if (size == 0) return 0;
  const std::uint8_t options_byte = data[0];
  TcpReassemblerOptions options;
  options.max_pending_bytes = FuzzMaxPendingBytes(options_byte);
  options.max_pending_ranges = FuzzMaxPendingRanges(options_byte);
  TcpReassembler reassembler(options);
  Observer observer;
  observer.synthetic = (options_byte & kSyntheticPayloadBit) != 0;

  std::uint64_t fed = 0;
  std::vector<std::uint8_t> payload;
  std::size_t at = 1;
  for (std::int64_t index = 0; size - at >= kSegmentRecordHeaderBytes && fed < kFuzzMaxFedBytes;
       ++index) {
    const std::uint32_t seq = (std::uint32_t{data[at]} << 24) |
                              (std::uint32_t{data[at + 1]} << 16) |
                              (std::uint32_t{data[at + 2]} << 8) | std::uint32_t{data[at + 3]};
    const std::uint8_t flags = data[at + 4];
    std::size_t length = (std::size_t{data[at + 5]} << 8) | data[at + 6];
    at += kSegmentRecordHeaderBytes;
    if (observer.synthetic) {
      length %= kSyntheticMaxLength;
      payload.resize(length);
      // The stream starts at the SYN's sequence number + 1.
      const std::uint32_t first = seq + ((flags & kTcpSyn) != 0 ? 1u : 0u);
      for (std::size_t i = 0; i < length; ++i) {
        payload[i] = SyntheticByte(first + static_cast<std::uint32_t>(i));
      }
    } else {
      length = std::min(length, size - at);
      payload.assign(data + at, data + at + length);
      at += length;
    }
    fed += length;
    reassembler.Push({seq, flags, payload, index * 1000});
    observer.Drain(&reassembler);
    Check(reassembler.pending_bytes() <= options.max_pending_bytes, "held bytes bounded");
    Check(reassembler.pending_ranges() <= options.max_pending_ranges, "held ranges bounded");
    Check(observer.delivered <= fed, "never more delivered than fed");
  }
  reassembler.Finish();
  observer.Drain(&reassembler);
  Check(reassembler.pending_bytes() == 0 && reassembler.pending_ranges() == 0, "Finish() empties");
  Check(observer.delivered <= fed, "never more delivered than fed");
  Check(observer.delivered == reassembler.counters().delivered_bytes, "delivered counter");
  return 0;
}
