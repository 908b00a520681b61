#include "firmware_tracker/io/sealing_sink.h"

namespace lrfnet::io {

SealingSink::SealingSink(const auth::SealerOptions& options, DatagramSink& next)
    : sealer_(options), next_(next) {}

void SealingSink::Send(std::span<const std::uint8_t> datagram, common::UtcNs sent_ns) {
  const std::size_t n = sealer_.Seal(datagram, buffer_);
  if (n == 0) {
    ++counters_.too_large;
    return;
  }
  ++counters_.sealed;
  next_.Send(std::span<const std::uint8_t>(buffer_.data(), n), sent_ns);
}

}  // namespace lrfnet::io
