#pragma once
// CoLa-B framing: 02 02 02 02 | uint32 big-endian payload length | payload | uint8 XOR of the payload.
//
// Framer is an incremental parser that never touches a socket: feed it arbitrary chunks (one byte at a
// time works) and it reports complete frames. It owns one fixed buffer sized at construction (no further
// allocation). A frame is split by its length field, so a start sequence inside a payload (the LMS111
// `sRA LIDinputstate` reply carries 02 02 02 02) is not a frame start. After garbage, a bad checksum or an
// impossible length it resynchronises on the next start sequence *after* the start it rejected.
//
// Thread-safety: none; one Framer per stream.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace lrfnet::cola {

inline constexpr std::size_t kFrameHeaderBytes = 8;   // start sequence + length
inline constexpr std::size_t kFrameTrailerBytes = 1;  // checksum

struct FramerOptions {
  // Largest payload accepted. Longer length fields are rejected and counted (oversize_length). The default
  // holds the largest telegram of any supported device with all channels enabled.
  std::size_t max_payload_bytes = 64 * 1024;
};
std::optional<std::string> Validate(const FramerOptions& options);

struct FramerCounters {
  std::uint64_t frames = 0;            // complete frames with a correct checksum
  std::uint64_t bad_checksum = 0;      // complete frames whose XOR did not match (dropped)
  std::uint64_t oversize_length = 0;   // length field above max_payload_bytes or zero (dropped)
  std::uint64_t garbage_bytes = 0;     // bytes skipped while searching for a start sequence (the bytes of
                                       // rejected frames included; buffered bytes not yet)
  std::uint64_t bytes_in = 0;          // all bytes fed
};

// What Next() found.
enum class FrameStatus {
  kFrame,     // a complete frame with a valid checksum: payload() is valid until the next call
  kNeedMore,  // all buffered bytes consumed; feed more
  kBad,       // a frame was rejected (reason() says why); call Next() again to continue
};

class Framer {
 public:
  explicit Framer(const FramerOptions& options = {});

  // Appends bytes. Returns how many were taken: fewer than bytes.size() only when the internal buffer is
  // full, in which case the caller must drain with Next() and feed the rest.
  std::size_t Feed(std::span<const std::uint8_t> bytes);

  // Extracts the next event from the buffered bytes.
  FrameStatus Next();

  // The payload of the last kFrame (without header and checksum).
  std::span<const std::uint8_t> payload() const { return payload_; }
  // Why the last kBad was reported (static string).
  const char* reason() const { return reason_; }

  // Drops all buffered bytes (e.g. after a reconnect). Counters are kept.
  void Reset();

  const FramerCounters& counters() const { return counters_; }
  std::size_t buffered_bytes() const { return end_ - begin_; }

  // Convenience: feeds all bytes and calls on_frame(payload) for every valid frame and
  // on_bad(reason) for every rejected one.
  template <typename OnFrame, typename OnBad>
  void FeedAll(std::span<const std::uint8_t> bytes, OnFrame&& on_frame, OnBad&& on_bad) {
    while (true) {
      const std::size_t taken = Feed(bytes);
      bytes = bytes.subspan(taken);
      while (true) {
        const FrameStatus s = Next();
        if (s == FrameStatus::kFrame) {
          on_frame(payload());
        } else if (s == FrameStatus::kBad) {
          on_bad(reason());
        } else {
          break;
        }
      }
      if (bytes.empty()) return;
    }
  }

 private:
  void Compact();

  FramerOptions options_;
  std::vector<std::uint8_t> buffer_;  // allocated once in the constructor
  std::size_t begin_ = 0;
  std::size_t end_ = 0;
  std::span<const std::uint8_t> payload_;
  const char* reason_ = "";
  FramerCounters counters_;
};

// Writes one frame around `payload` into `out`. Returns the frame size, or 0 if `out` is too small.
std::size_t EncodeFrame(std::span<const std::uint8_t> payload, std::span<std::uint8_t> out);
// XOR of all bytes (the CoLa-B checksum).
std::uint8_t Checksum(std::span<const std::uint8_t> payload);

}  // namespace lrfnet::cola
