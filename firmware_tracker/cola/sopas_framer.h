#pragma once
// Framing of both SOPAS dialects on one byte stream, as a device's port 2112 sees it:
//   CoLa-B: 02 02 02 02 | uint32 big-endian payload length | payload | uint8 XOR of the payload;
//   CoLa-A: 02 | printable payload | 03 (STX ... ETX, no length, no checksum).
// A device answers each request in the dialect it came in, so a client may probe with one and
// switch to the other (SICK's driver sends `sRN SCdevicestate` in both when the first gets no
// answer).
//
// SopasFramer is incremental and never touches a socket: feed it arbitrary chunks and it reports
// complete frames with their dialect. At every 0x02 it decides: four of them start a CoLa-B frame
// (split by its length field, so 02 02 02 02 inside a payload is no frame start); one to three
// followed by another byte start a CoLa-A frame at the last 0x02. A CoLa-A frame that meets a new
// 0x02 before its 0x03, or grows beyond the bound, is dropped and the search resumes at the byte
// after its start. One fixed buffer, sized at construction.
//
// Thread-safety: none; one SopasFramer per stream.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace lrfnet::cola {

enum class Dialect : std::uint8_t { kColaA, kColaB };
const char* DialectName(Dialect d);  // "CoLa-A" / "CoLa-B"

inline constexpr std::uint8_t kColaAStx = 0x02;
inline constexpr std::uint8_t kColaAEtx = 0x03;

struct SopasFramerOptions {
  // Largest payload accepted in either dialect (requests to a device are small; the default also
  // holds any reply a client may echo back).
  std::size_t max_payload_bytes = 64 * 1024;
};
std::optional<std::string> Validate(const SopasFramerOptions& options);

struct SopasFramerCounters {
  std::uint64_t frames_cola_a = 0;
  std::uint64_t frames_cola_b = 0;
  std::uint64_t bad_checksum = 0;     // CoLa-B frames whose XOR did not match
  std::uint64_t oversize_length = 0;  // CoLa-B length field zero or above the bound
  std::uint64_t bad_cola_a = 0;  // CoLa-A frames cut by a new STX, empty, or longer than the bound
  std::uint64_t garbage_bytes = 0;  // bytes skipped outside frames (rejected starts included)
  std::uint64_t bytes_in = 0;
};

enum class SopasFrameStatus { kFrame, kNeedMore, kBad };

class SopasFramer {
 public:
  explicit SopasFramer(const SopasFramerOptions& options = {});

  // Appends bytes; returns how many were taken (fewer only when the buffer is full: drain with
  // Next() and feed the rest).
  std::size_t Feed(std::span<const std::uint8_t> bytes);
  // The next event from the buffered bytes.
  SopasFrameStatus Next();

  // Valid after kFrame until the next call.
  std::span<const std::uint8_t> payload() const { return payload_; }
  Dialect dialect() const { return dialect_; }
  // Why the last kBad was reported (static string).
  const char* reason() const { return reason_; }

  void Reset();  // drops buffered bytes, keeps counters
  const SopasFramerCounters& counters() const { return counters_; }
  std::size_t buffered_bytes() const { return end_ - begin_; }

  // Feeds all bytes; on_frame(dialect, payload) per frame, on_bad(reason) per rejected one.
  template <typename OnFrame, typename OnBad>
  void FeedAll(std::span<const std::uint8_t> bytes, OnFrame&& on_frame, OnBad&& on_bad) {
    while (true) {
      bytes = bytes.subspan(Feed(bytes));
      while (true) {
        const SopasFrameStatus s = Next();
        if (s == SopasFrameStatus::kFrame) {
          on_frame(dialect_, payload_);
        } else if (s == SopasFrameStatus::kBad) {
          on_bad(reason_);
        } else {
          break;
        }
      }
      if (bytes.empty()) return;
    }
  }

 private:
  SopasFrameStatus Reject(std::uint64_t* counter, const char* reason);
  void Compact();

  SopasFramerOptions options_;
  std::vector<std::uint8_t> buffer_;
  std::size_t begin_ = 0;
  std::size_t end_ = 0;
  // An incomplete CoLa-A frame starting at pending_a_begin_ holds neither STX nor ETX before
  // pending_a_scanned_ (buffer indices).
  static constexpr std::size_t kNoPending = ~std::size_t{0};
  std::size_t pending_a_begin_ = kNoPending;
  std::size_t pending_a_scanned_ = 0;
  std::span<const std::uint8_t> payload_;
  Dialect dialect_ = Dialect::kColaB;
  const char* reason_ = "";
  SopasFramerCounters counters_;
};

// Wraps `payload` in a frame of `dialect` (EncodeFrame for CoLa-B; STX payload ETX for CoLa-A,
// where the payload must not contain 0x02 or 0x03). Returns an empty vector when it cannot.
std::vector<std::uint8_t> EncodeSopasFrame(Dialect dialect, std::span<const std::uint8_t> payload);

}  // namespace lrfnet::cola
