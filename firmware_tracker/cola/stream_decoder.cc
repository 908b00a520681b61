#include "firmware_tracker/cola/stream_decoder.h"

namespace lrfnet::cola {

StreamDecoder::StreamDecoder(const FramerOptions& options) : framer_(options) {}

void StreamDecoder::Feed(std::span<const std::uint8_t> bytes, common::UtcNs receive_time_ns,
                         TelegramListener& listener) {
  while (true) {
    bytes = bytes.subspan(framer_.Feed(bytes));
    while (true) {
      const FrameStatus status = framer_.Next();
      if (status == FrameStatus::kNeedMore) break;
      if (status == FrameStatus::kBad) {
        listener.OnError(framer_.reason(), receive_time_ns);
        continue;
      }
      const std::span<const std::uint8_t> payload = framer_.payload();
      TelegramHeader header;
      const HeaderStatus hs = ParseTelegramHeader(payload, &header);
      if (hs != HeaderStatus::kOk) {
        ++counters_.bad_headers;
        listener.OnError(HeaderStatusName(hs), receive_time_ns);
        continue;
      }
      ++counters_.by_type[static_cast<std::size_t>(header.type)];
      if (IsScanTelegram(payload)) {
        const DecodeResult r = DecodeScanTelegram(payload, &scan_);
        if (r.ok) {
          ++counters_.scans;
          listener.OnScan(scan_, receive_time_ns);
        } else {
          ++counters_.scan_decode_errors;
          listener.OnError(r.reason, receive_time_ns);
        }
      } else {
        ++counters_.other_telegrams;
        listener.OnTelegram(header, payload, receive_time_ns);
      }
    }
    if (bytes.empty()) return;
  }
}

void StreamDecoder::Reset() { framer_.Reset(); }

StreamCounters StreamDecoder::counters() const {
  StreamCounters c = counters_;
  c.framer = framer_.counters();
  return c;
}

}  // namespace lrfnet::cola
