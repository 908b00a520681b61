#pragma once
// The one path from a device byte stream to telegrams, shared by the live TCP client and the capture
// source: framing, header parsing, scan decoding, counters. Pure: bytes and receive times in, callbacks out.

#include <array>
#include <cstdint>
#include <span>

#include "common/time.h"
#include "firmware_tracker/cola/framer.h"
#include "firmware_tracker/cola/scan_telegram.h"
#include "firmware_tracker/cola/telegram.h"

namespace lrfnet::cola {

class TelegramListener {
 public:
  virtual ~TelegramListener() = default;
  // A decoded LMDscandata telegram. `receive_time_ns` is the time of the chunk that completed the frame.
  virtual void OnScan(const ScanTelegram& scan, common::UtcNs receive_time_ns) = 0;
  // Any other well-formed telegram (replies, other events); the payload view is valid during the call.
  virtual void OnTelegram(const TelegramHeader& header, std::span<const std::uint8_t> payload,
                          common::UtcNs receive_time_ns) {
    (void)header, (void)payload, (void)receive_time_ns;
  }
  // A rejected frame or undecodable telegram; `reason` is a static string.
  virtual void OnError(const char* reason, common::UtcNs receive_time_ns) {
    (void)reason, (void)receive_time_ns;
  }
};

struct StreamCounters {
  FramerCounters framer;
  std::uint64_t scans = 0;
  std::uint64_t other_telegrams = 0;
  std::uint64_t bad_headers = 0;
  std::uint64_t scan_decode_errors = 0;
  std::array<std::uint64_t, 11> by_type{};  // indexed by CommandType
};

// Every valid frame is counted exactly once: framer.frames == bad_headers + scans + scan_decode_errors +
// other_telegrams. Rejected frames (framer.bad_checksum, framer.oversize_length) and undecodable telegrams
// also reach OnError. No heap allocation after construction.
// Thread-safety: none; the listener must not call Feed or Reset of the decoder that is calling it.
class StreamDecoder {
 public:
  explicit StreamDecoder(const FramerOptions& options = {});

  void Feed(std::span<const std::uint8_t> bytes, common::UtcNs receive_time_ns,
            TelegramListener& listener);
  // Forget partial frames (after a reconnect or a stream gap). Counters are kept.
  void Reset();

  StreamCounters counters() const;

 private:
  Framer framer_;
  ScanTelegram scan_;  // reused for every scan: no allocation per scan
  StreamCounters counters_;
};

}  // namespace lrfnet::cola
