#pragma once
// Seals every datagram the encoder produces into an authenticated envelope (common/datagram_auth.h)
// before it goes on to the next sink (the UDP uplink and the recording alike, so a recording holds
// the bytes that went over the network). A datagram that does not fit the envelope (larger than
// kMaxPayloadBytes: never from the encoder) is dropped and counted. No allocation: the sealed bytes
// go through one fixed buffer. Not thread-safe.

#include <array>
#include <cstdint>
#include <span>

#include "common/datagram_auth.h"
#include "firmware_tracker/io/datagram_encoder.h"

namespace lrfnet::io {

struct SealingCounters {
  std::uint64_t sealed = 0;
  std::uint64_t too_large = 0;
};

class SealingSink final : public DatagramSink {
 public:
  // Precondition: auth::Validate(options) (checked). `next` must outlive this sink.
  SealingSink(const auth::SealerOptions& options, DatagramSink& next);

  void Send(std::span<const std::uint8_t> datagram, common::UtcNs sent_ns) override;
  // Passed on to `next` (which holds its own copies of the sealed bytes).
  void BeginBatch() override { next_.BeginBatch(); }
  void EndBatch() override { next_.EndBatch(); }

  const SealingCounters& counters() const { return counters_; }
  const auth::Sealer& sealer() const { return sealer_; }

 private:
  auth::Sealer sealer_;
  DatagramSink& next_;
  SealingCounters counters_;
  std::array<std::uint8_t, kMaxDatagramBytes> buffer_{};
};

}  // namespace lrfnet::io
