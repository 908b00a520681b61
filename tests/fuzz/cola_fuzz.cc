// Fuzz target for the CoLa-B codec: the bytes go through a StreamDecoder in chunks whose sizes
// derive from the first byte and, for comparison, in one piece; straight into DecodeScanTelegram
// (seeds include bare scan payloads) and ParseTelegramHeader. Properties checked with
// __builtin_trap:
//   - chunking does not change what the decoder reports;
//   - a decoded scan re-encodes to exactly the bytes it was decoded from, and decodes again;
//   - header views lie inside the payload.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <span>
#include <vector>

#include "firmware_tracker/cola/commands.h"
#include "firmware_tracker/cola/scan_telegram.h"
#include "firmware_tracker/cola/stream_decoder.h"
#include "firmware_tracker/cola/telegram.h"

namespace {

using lrfnet::cola::DecodeScanTelegram;
using lrfnet::cola::EncodeScanTelegram;
using lrfnet::cola::ScanTelegram;

void Check(bool ok) {
  if (!ok) __builtin_trap();
}

// Large enough for any payload the default framer accepts.
std::vector<std::uint8_t>& EncodeBuffer() {
  static std::vector<std::uint8_t> buffer(lrfnet::cola::FramerOptions{}.max_payload_bytes + 1024);
  return buffer;
}

// Two scratch telegrams: the input's decoding and the re-decoding of its encoding.
ScanTelegram& Scratch() {
  static auto* scan = new ScanTelegram();
  return *scan;
}
ScanTelegram& Scratch2() {
  static auto* scan = new ScanTelegram();
  return *scan;
}

// Encode `scan`, decode the result, encode again: both encodings must agree (and match `original`
// when given).
void CheckRoundTrip(const ScanTelegram& scan, std::span<const std::uint8_t> original) {
  auto& buffer = EncodeBuffer();
  const std::size_t size = lrfnet::cola::MaxEncodedSize(scan);
  Check(size <= buffer.size());
  const std::size_t n = EncodeScanTelegram(scan, buffer);
  Check(n == size);
  if (!original.empty())
    Check(n == original.size() && std::memcmp(buffer.data(), original.data(), n) == 0);
  ScanTelegram& again = Scratch2();
  const auto r = DecodeScanTelegram(std::span<const std::uint8_t>(buffer.data(), n), &again);
  Check(r.ok && r.offset == n);
  static std::vector<std::uint8_t> second(buffer.size());
  const std::size_t m = EncodeScanTelegram(again, second);
  Check(m == n && std::memcmp(second.data(), buffer.data(), n) == 0);
}

struct Listener : lrfnet::cola::TelegramListener {
  std::uint64_t digest = 0;  // order-sensitive summary of everything reported
  void Mix(std::uint64_t v) { digest = (digest ^ v) * 0x100000001B3ull; }
  void OnScan(const ScanTelegram& scan, lrfnet::common::UtcNs) override {
    Mix(1);
    Mix(scan.telegram_counter);
    Mix(lrfnet::cola::MaxEncodedSize(scan));
    static auto* polar = new lrfnet::cola::PolarScan();
    if (lrfnet::cola::ToPolarScan(scan, polar)) Mix(polar->count);
    CheckRoundTrip(scan, {});
  }
  void OnTelegram(const lrfnet::cola::TelegramHeader& header, std::span<const std::uint8_t> payload,
                  lrfnet::common::UtcNs) override {
    Mix(2);
    Mix(static_cast<std::uint64_t>(header.type));
    Mix(payload.size());
  }
  void OnError(const char* reason, lrfnet::common::UtcNs) override {
    Mix(3);
    Mix(reason[0]);
  }
};

void CheckHeader(std::span<const std::uint8_t> payload) {
  lrfnet::cola::TelegramHeader h;
  if (lrfnet::cola::ParseTelegramHeader(payload, &h) != lrfnet::cola::HeaderStatus::kOk) return;
  const auto* begin = payload.data();
  const auto* end = payload.data() + payload.size();
  Check(h.type != lrfnet::cola::CommandType::kUnknown);
  Check(h.name.empty() ||
        (reinterpret_cast<const std::uint8_t*>(h.name.data()) >= begin &&
         reinterpret_cast<const std::uint8_t*>(h.name.data()) + h.name.size() <= end));
  Check(h.args.empty() || (h.args.data() >= begin && h.args.data() + h.args.size() <= end));
  // Reply argument decoders on whatever follows the name.
  lrfnet::cola::DeviceIdent ident;
  if (lrfnet::cola::DecodeDeviceIdent(h.args, &ident))
    Check(ident.name.size() + ident.version.size() <= h.args.size());
  lrfnet::cola::FlexString flex;
  if (lrfnet::cola::DecodeFlexString(h.args, &flex)) Check(flex.consumed <= h.args.size());
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::uint8_t> input(data, size);

  // 1. Direct decoding of a bare payload.
  CheckHeader(input);
  {
    ScanTelegram& scan = Scratch();
    const auto r = DecodeScanTelegram(input, &scan);
    if (r.ok) {
      Check(r.offset == size);
      CheckRoundTrip(scan, input);
    } else {
      Check(r.reason != nullptr && r.reason[0] != '\0' && r.offset <= size);
    }
  }

  // 2. The stream path, chunked and whole: the same reports in the same order.
  static auto* chunked = new lrfnet::cola::StreamDecoder();
  static auto* whole = new lrfnet::cola::StreamDecoder();
  chunked->Reset();
  whole->Reset();
  Listener a;
  Listener b;
  const std::size_t step = size == 0 ? 1 : 1 + data[0] % 97;
  std::size_t pos = 0;
  for (std::size_t k = 0; pos < size; ++k) {
    const std::size_t n = std::min(size - pos, 1 + (step * (k + 3)) % 211);
    chunked->Feed(input.subspan(pos, n), static_cast<lrfnet::common::UtcNs>(k), a);
    pos += n;
  }
  whole->Feed(input, 0, b);
  Check(a.digest == b.digest);
  const auto ca = chunked->counters();
  const auto cb = whole->counters();
  Check(ca.framer.frames == cb.framer.frames && ca.scans == cb.scans &&
        ca.framer.garbage_bytes == cb.framer.garbage_bytes &&
        ca.framer.bad_checksum == cb.framer.bad_checksum);
  Check(ca.framer.frames == ca.bad_headers + ca.scans + ca.scan_decode_errors + ca.other_telegrams);
  return 0;
}
