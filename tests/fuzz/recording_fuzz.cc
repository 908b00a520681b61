// Fuzz target for the recording reader: arbitrary bytes as one recording file (seeds: recordings of
// the daemon's and the tracker's writers, whole and damaged, and small UDP captures).
// Properties checked with __builtin_trap:
//   - RecordingDecoder never delivers an entry larger than kMaxRecordEntryBytes; entries are
//     contiguous from byte 0, the first is the header and no other is; after kBad nothing more is
//     delivered and the error names the offset right after the last entry delivered;
//   - the result does not depend on how the bytes are split across Feed calls;
//   - the same bytes as a file through OpenDatagramFile give the decoder's datagrams and end (or
//     no source when not even a header decodes); a capture (pcap/pcapng magic) accounts for every
//     packet it read.

#include <sys/mman.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "central_daemon/io/datagram_source.h"
#include "central_daemon/io/recording_decoder.h"

namespace {

using lrfnet::daemon::kMaxRecordEntryBytes;
using lrfnet::daemon::RecordingDecoder;
using lrfnet::daemon::RecordingDecodeStatus;
using lrfnet::daemon::RecordingDefect;

void Check(bool ok) {
  if (!ok) __builtin_trap();
}

std::uint64_t Mix(std::uint64_t h, std::span<const std::uint8_t> bytes) {
  for (const std::uint8_t b : bytes) h = (h ^ b) * 1099511628211ULL;  // FNV-1a
  return h;
}

std::uint64_t HashDatagram(const lrfnet::daemon::ReceivedDatagram& d) {
  std::uint64_t h = 1469598103934665603ULL;
  h = Mix(h, d.bytes);
  h = Mix(h, std::span(reinterpret_cast<const std::uint8_t*>(d.source.data()), d.source.size()));
  return h ^ static_cast<std::uint64_t>(d.receive_ns);
}

struct Outcome {
  std::vector<std::uint64_t> entry_ends;
  std::vector<std::uint64_t> datagram_hashes;  // entries after the header
  RecordingDecodeStatus end = RecordingDecodeStatus::kNeedMore;
  RecordingDefect defect = RecordingDefect::kNone;
  std::uint64_t error_offset = 0;
};

// Decodes `input` in pieces whose sizes cycle through `chunks` (an empty list: all at once).
Outcome Decode(std::span<const std::uint8_t> input, const std::vector<std::size_t>& chunks) {
  RecordingDecoder decoder;
  Outcome out;
  std::uint64_t last_end = 0;
  std::size_t at = 0;
  std::size_t k = 0;
  while (out.end != RecordingDecodeStatus::kBad) {
    if (at == input.size()) {
      out.end = decoder.Finish();
      break;
    }
    const std::size_t n = chunks.empty() ? input.size() - at
                                         : std::min(chunks[k++ % chunks.size()], input.size() - at);
    std::span<const std::uint8_t> piece = input.subspan(at, n);
    at += n;
    while (!piece.empty()) {
      std::size_t consumed = 0;
      const RecordingDecodeStatus status = decoder.Feed(piece, &consumed);
      Check(consumed <= piece.size());
      piece = piece.subspan(consumed);
      if (status == RecordingDecodeStatus::kEntry) {
        const lrfnet::daemon::RecordingEntry& e = decoder.entry();
        Check(e.size_bytes <= kMaxRecordEntryBytes + 5);
        Check(e.datagram.bytes.size() <= kMaxRecordEntryBytes);
        Check(e.offset == last_end);
        Check(e.has_header == out.entry_ends.empty());
        last_end = e.offset + e.size_bytes;
        Check(last_end <= input.size());
        out.entry_ends.push_back(last_end);
        if (!e.has_header) out.datagram_hashes.push_back(HashDatagram(e.datagram));
      } else if (status == RecordingDecodeStatus::kBad) {
        out.end = status;
        break;
      } else {
        Check(status == RecordingDecodeStatus::kNeedMore && piece.empty());
      }
    }
  }
  Check(decoder.offset() == last_end);
  out.defect = decoder.defect();
  out.error_offset = decoder.error_offset();
  if (out.end == RecordingDecodeStatus::kEnd) {
    Check(last_end == input.size() && out.defect == RecordingDefect::kNone);
  } else {
    Check(out.end == RecordingDecodeStatus::kBad && out.defect != RecordingDefect::kNone);
    Check(!decoder.error().empty() && out.error_offset == last_end);
    std::size_t consumed = 1;
    Check(decoder.Feed(input, &consumed) == RecordingDecodeStatus::kBad && consumed == 0);
    Check(decoder.Finish() == RecordingDecodeStatus::kBad);
  }
  return out;
}

bool IsCaptureMagic(std::span<const std::uint8_t> d) {
  if (d.size() < 4) return false;
  const std::uint32_t le =
      d[0] | (d[1] << 8) | (d[2] << 16) | (static_cast<std::uint32_t>(d[3]) << 24);
  for (const std::uint32_t m : {0xa1b2c3d4u, 0xd4c3b2a1u, 0xa1b23c4du, 0x4d3cb2a1u, 0x0a0d0d0au}) {
    if (le == m) return true;
  }
  return false;
}

// The input as a file (an in-memory one), read through OpenDatagramFile.
void CheckFileSource(std::span<const std::uint8_t> input, const Outcome& decoded) {
  const int fd = ::memfd_create("recording_fuzz", MFD_CLOEXEC);
  if (fd < 0) return;  // no memfd here: the decoder checks above still ran
  std::size_t written = 0;
  while (written < input.size()) {
    const ssize_t n = ::write(fd, input.data() + written, input.size() - written);
    if (n <= 0) break;
    written += static_cast<std::size_t>(n);
  }
  const std::string path = "/proc/self/fd/" + std::to_string(fd);
  if (written == input.size() && ::access(path.c_str(), R_OK) == 0) {
    std::string error;
    auto source = lrfnet::daemon::OpenDatagramFile(path, {}, &error);
    lrfnet::daemon::ReceivedDatagram d;
    if (IsCaptureMagic(input)) {
      if (source != nullptr) {
        Check(source->kind() == lrfnet::daemon::DatagramFileKind::kCapture);
        lrfnet::daemon::SourceStatus status;
        std::uint64_t n = 0;
        while ((status = source->Next(&d)) == lrfnet::daemon::SourceStatus::kDatagram) ++n;
        const auto& c = source->counters();
        Check(c.datagrams == n && c.packets == n + c.malformed_packets + c.other_packets);
        Check((status == lrfnet::daemon::SourceStatus::kError) == !source->error().empty());
      } else {
        Check(!error.empty());
      }
    } else if (decoded.entry_ends.empty()) {
      Check(source == nullptr && !error.empty());
    } else {
      Check(source != nullptr);
      std::size_t i = 0;
      lrfnet::daemon::SourceStatus status;
      while ((status = source->Next(&d)) == lrfnet::daemon::SourceStatus::kDatagram) {
        Check(i < decoded.datagram_hashes.size() && HashDatagram(d) == decoded.datagram_hashes[i]);
        ++i;
      }
      Check(i == decoded.datagram_hashes.size());
      Check((status == lrfnet::daemon::SourceStatus::kEnd) ==
            (decoded.end == RecordingDecodeStatus::kEnd));
      Check(source->Next(&d) == status);
    }
  }
  ::close(fd);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::uint8_t> input(data, size);
  const Outcome whole = Decode(input, {});
  // Split points that land inside prefixes and messages alike, and one byte at a time for small
  // inputs.
  std::vector<std::vector<std::size_t>> splits = {{3, 17, 1, 4096}, {65537}};
  if (size <= 4096) splits.push_back({1});
  for (const auto& chunks : splits) {
    const Outcome split = Decode(input, chunks);
    Check(split.entry_ends == whole.entry_ends);
    Check(split.datagram_hashes == whole.datagram_hashes);
    Check(split.end == whole.end && split.defect == whole.defect);
    Check(split.error_offset == whole.error_offset);
  }
  CheckFileSource(input, whole);
  return 0;
}
