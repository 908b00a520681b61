#pragma once
// Pure incremental decoder of one recording file (lrfnet.proto, DESIGN.md "Recording"): bytes in,
// entries out. The caller reads the file (or a fuzzer hands it bytes) and feeds them in chunks of
// any size; the decoder never touches a file, a clock or a log.
//
// Format: varint length prefix + RecordEntry, repeated. The first entry must carry the header with
// a format version this reader knows (kRecordingFormatVersion); no later entry may carry one.
// Entries are parsed by the protobuf wire rules (unknown fields skipped, a repeated scalar's last
// value wins, a repeated header is merged) with strings taken as bytes: unlike libprotobuf, a
// source that is not UTF-8 is kept rather than failing the entry (and logging), as the tracker's
// nanopb writer and the network may produce one.
//
// Bounded: a length prefix above kMaxRecordEntryBytes is rejected as soon as it is read, and only
// an entry split across Feed calls is copied (at most kMaxRecordEntryBytes + the prefix), so memory
// stays below ~2 * kMaxRecordEntryBytes whatever the input.
//
// Not thread-safe.

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "central_daemon/io/datagram_source.h"
#include "common/time.h"

namespace lrfnet::daemon {

inline constexpr std::uint32_t kRecordingFormatVersion = 1;

struct RecordingHeader {
  std::uint32_t format_version = 0;
  common::UtcNs created_ns = 0;
  std::string writer;
};

// One decoded entry: the header entry (has_header) or a datagram.
struct RecordingEntry {
  bool has_header = false;
  RecordingHeader header;      // valid when has_header
  ReceivedDatagram datagram;   // receive_ns, source, bytes as recorded (empty for the header)
  std::uint64_t offset = 0;    // byte offset of the entry's length prefix in the stream
  std::size_t size_bytes = 0;  // prefix + message
};

enum class RecordingDecodeStatus : std::uint8_t {
  kEntry,     // entry() holds the next entry
  kNeedMore,  // every byte offered was taken; feed more (or Finish at the end of the input)
  kEnd,       // Finish(): the input ended on an entry boundary
  kBad,       // damaged input: error() and error_offset(); final
};

enum class RecordingDefect : std::uint8_t {
  kNone,
  kTornEntry,           // the input ended inside an entry
  kBadLengthPrefix,     // varint longer than 5 bytes
  kOversizeEntry,       // length prefix above kMaxRecordEntryBytes
  kUnparsableEntry,     // the message breaks the protobuf wire format
  kMissingHeader,       // the first entry carries no header
  kUnsupportedVersion,  // header of a format version other than kRecordingFormatVersion
  kRepeatedHeader,      // a header after the first entry
};

class RecordingDecoder {
 public:
  RecordingDecoder() = default;
  RecordingDecoder(const RecordingDecoder&) = delete;
  RecordingDecoder& operator=(const RecordingDecoder&) = delete;

  // Takes bytes from the front of `bytes` up to the end of the next entry and sets *consumed.
  // kEntry: an entry is ready (more bytes may remain: call again with the rest). kNeedMore: all of
  // `bytes` was taken. kBad: *consumed may be less than the bytes up to the defect.
  RecordingDecodeStatus Feed(std::span<const std::uint8_t> bytes, std::size_t* consumed);
  // The input ended: kEnd on an entry boundary, else kBad (kTornEntry).
  RecordingDecodeStatus Finish();

  // The entry of the last kEntry; its strings and bytes may be moved out.
  RecordingEntry& entry() { return entry_; }

  std::uint64_t entries() const { return entries_; }  // decoded so far, header included
  // Bytes of the whole entries decoded so far.
  std::uint64_t offset() const { return entry_end_; }
  RecordingDefect defect() const { return defect_; }
  // One line without the file name, e.g. "length prefix 1048576 above the 65536-byte limit".
  const std::string& error() const { return error_; }
  // Byte offset of the damaged entry's length prefix (== offset()).
  std::uint64_t error_offset() const { return entry_end_; }

 private:
  RecordingDecodeStatus Bad(RecordingDefect defect, std::string reason);
  RecordingDecodeStatus Decode(std::span<const std::uint8_t> message);
  RecordingEntry entry_;
  std::uint64_t entries_ = 0;
  std::uint64_t entry_end_ = 0;  // stream offset after the last whole entry
  // The entry in progress: its prefix, then (when split across Feed calls) its message bytes.
  std::uint64_t prefix_value_ = 0;
  std::size_t prefix_bytes_ = 0;
  bool prefix_done_ = false;
  std::size_t message_bytes_ = 0;
  std::vector<std::uint8_t> pending_;
  RecordingDefect defect_ = RecordingDefect::kNone;
  std::string error_;
};

}  // namespace lrfnet::daemon
