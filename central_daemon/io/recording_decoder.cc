#include "central_daemon/io/recording_decoder.h"

#include <algorithm>
#include <utility>

namespace lrfnet::daemon {
namespace {

// protobuf's limit for a 32-bit length; a longer varint cannot be a length this reader accepts.
constexpr std::size_t kMaxPrefixBytes = 5;

constexpr std::uint32_t kWireVarint = 0;
constexpr std::uint32_t kWireFixed64 = 1;
constexpr std::uint32_t kWireLengthDelimited = 2;
constexpr std::uint32_t kWireFixed32 = 5;

// Protobuf wire reading over one message; every read is bounds-checked and false on a defect.
class WireReader {
 public:
  explicit WireReader(std::span<const std::uint8_t> bytes) : bytes_(bytes) {}

  bool done() const { return at_ == bytes_.size(); }

  bool Varint(std::uint64_t* value) {
    std::uint64_t v = 0;
    for (int i = 0; i < 10; ++i) {
      if (at_ == bytes_.size()) return false;
      const std::uint8_t b = bytes_[at_++];
      v |= static_cast<std::uint64_t>(b & 0x7f) << (7 * i);
      if ((b & 0x80) == 0) {
        *value = v;
        return true;
      }
    }
    return false;
  }

  // Field number (> 0) and wire type of the next field.
  bool Tag(std::uint32_t* field, std::uint32_t* wire_type) {
    std::uint64_t tag = 0;
    if (!Varint(&tag) || tag > 0xffffffffu || (tag >> 3) == 0) return false;
    *field = static_cast<std::uint32_t>(tag >> 3);
    *wire_type = static_cast<std::uint32_t>(tag & 7);
    return true;
  }

  bool LengthDelimited(std::span<const std::uint8_t>* out) {
    std::uint64_t n = 0;
    if (!Varint(&n) || n > bytes_.size() - at_) return false;
    *out = bytes_.subspan(at_, static_cast<std::size_t>(n));
    at_ += static_cast<std::size_t>(n);
    return true;
  }

  // An unknown field (or a known one with another wire type, as libprotobuf treats it). Groups
  // (wire types 3 and 4, deprecated and never in this schema) count as defects.
  bool Skip(std::uint32_t wire_type) {
    std::uint64_t v = 0;
    std::span<const std::uint8_t> s;
    switch (wire_type) {
      case kWireVarint:
        return Varint(&v);
      case kWireFixed64:
        return Advance(8);
      case kWireLengthDelimited:
        return LengthDelimited(&s);
      case kWireFixed32:
        return Advance(4);
      default:
        return false;
    }
  }

 private:
  bool Advance(std::size_t n) {
    if (n > bytes_.size() - at_) return false;
    at_ += n;
    return true;
  }

  std::span<const std::uint8_t> bytes_;
  std::size_t at_ = 0;
};

void Assign(std::span<const std::uint8_t> bytes, std::string* out) {
  out->assign(reinterpret_cast<const char*>(bytes.data()), bytes.size());
}

// RecordHeader, merged into *header (a header field that occurs twice is merged, as protobuf does).
bool ParseHeader(std::span<const std::uint8_t> bytes, RecordingHeader* header) {
  WireReader r(bytes);
  while (!r.done()) {
    std::uint32_t field = 0;
    std::uint32_t wire_type = 0;
    if (!r.Tag(&field, &wire_type)) return false;
    std::uint64_t v = 0;
    std::span<const std::uint8_t> s;
    if (field == 1 && wire_type == kWireVarint) {
      if (!r.Varint(&v)) return false;
      header->format_version = static_cast<std::uint32_t>(v);
    } else if (field == 2 && wire_type == kWireVarint) {
      if (!r.Varint(&v)) return false;
      header->created_ns = static_cast<common::UtcNs>(v);
    } else if (field == 3 && wire_type == kWireLengthDelimited) {
      if (!r.LengthDelimited(&s)) return false;
      Assign(s, &header->writer);
    } else if (!r.Skip(wire_type)) {
      return false;
    }
  }
  return true;
}

// RecordEntry into *entry (its buffers are reused).
bool ParseEntry(std::span<const std::uint8_t> bytes, RecordingEntry* entry) {
  entry->has_header = false;
  entry->header.format_version = 0;
  entry->header.created_ns = 0;
  entry->header.writer.clear();
  entry->datagram.receive_ns = 0;
  entry->datagram.source.clear();
  entry->datagram.bytes.clear();
  WireReader r(bytes);
  while (!r.done()) {
    std::uint32_t field = 0;
    std::uint32_t wire_type = 0;
    if (!r.Tag(&field, &wire_type)) return false;
    std::uint64_t v = 0;
    std::span<const std::uint8_t> s;
    if (field == 1 && wire_type == kWireVarint) {
      if (!r.Varint(&v)) return false;
      entry->datagram.receive_ns = static_cast<common::UtcNs>(v);
    } else if (field == 2 && wire_type == kWireLengthDelimited) {
      if (!r.LengthDelimited(&s)) return false;
      Assign(s, &entry->datagram.source);
    } else if (field == 3 && wire_type == kWireLengthDelimited) {
      if (!r.LengthDelimited(&s)) return false;
      entry->datagram.bytes.assign(s.begin(), s.end());
    } else if (field == 4 && wire_type == kWireLengthDelimited) {
      if (!r.LengthDelimited(&s) || !ParseHeader(s, &entry->header)) return false;
      entry->has_header = true;
    } else if (!r.Skip(wire_type)) {
      return false;
    }
  }
  return true;
}

}  // namespace

RecordingDecodeStatus RecordingDecoder::Bad(RecordingDefect defect, std::string reason) {
  defect_ = defect;
  error_ = std::move(reason);
  pending_.clear();
  pending_.shrink_to_fit();
  return RecordingDecodeStatus::kBad;
}

RecordingDecodeStatus RecordingDecoder::Feed(std::span<const std::uint8_t> bytes,
                                             std::size_t* consumed) {
  *consumed = 0;
  if (defect_ != RecordingDefect::kNone) return RecordingDecodeStatus::kBad;
  std::size_t at = 0;
  while (!prefix_done_) {
    if (at == bytes.size()) {
      *consumed = at;
      return RecordingDecodeStatus::kNeedMore;
    }
    const std::uint8_t b = bytes[at++];
    prefix_value_ |= static_cast<std::uint64_t>(b & 0x7f) << (7 * prefix_bytes_);
    ++prefix_bytes_;
    if ((b & 0x80) == 0) {
      prefix_done_ = true;
    } else if (prefix_bytes_ == kMaxPrefixBytes) {
      *consumed = at;
      return Bad(RecordingDefect::kBadLengthPrefix, "length prefix longer than 5 bytes");
    }
  }
  if (prefix_value_ > kMaxRecordEntryBytes) {
    *consumed = at;
    return Bad(RecordingDefect::kOversizeEntry,
               "length prefix " + std::to_string(prefix_value_) + " above the " +
                   std::to_string(kMaxRecordEntryBytes) + "-byte limit");
  }
  const auto message_size = static_cast<std::size_t>(prefix_value_);
  const std::size_t available = bytes.size() - at;
  if (message_bytes_ == 0 && available >= message_size) {
    // The usual case: the whole message is in the caller's buffer; parse it in place.
    *consumed = at + message_size;
    return Decode(bytes.subspan(at, message_size));
  }
  const std::size_t take = std::min(message_size - message_bytes_, available);
  pending_.insert(pending_.end(), bytes.begin() + static_cast<std::ptrdiff_t>(at),
                  bytes.begin() + static_cast<std::ptrdiff_t>(at + take));
  message_bytes_ += take;
  *consumed = at + take;
  if (message_bytes_ < message_size) return RecordingDecodeStatus::kNeedMore;
  return Decode(pending_);
}

RecordingDecodeStatus RecordingDecoder::Decode(std::span<const std::uint8_t> message) {
  if (!ParseEntry(message, &entry_)) {
    return Bad(RecordingDefect::kUnparsableEntry,
               "entry of " + std::to_string(message.size()) + " bytes is not a RecordEntry");
  }
  if (entries_ == 0) {
    if (!entry_.has_header) {
      return Bad(RecordingDefect::kMissingHeader, "the first entry carries no recording header");
    }
    if (entry_.header.format_version != kRecordingFormatVersion) {
      return Bad(RecordingDefect::kUnsupportedVersion,
                 "recording format version " + std::to_string(entry_.header.format_version) +
                     " is not supported (this reader knows version " +
                     std::to_string(kRecordingFormatVersion) + ")");
    }
  } else if (entry_.has_header) {
    return Bad(RecordingDefect::kRepeatedHeader, "a second recording header");
  }
  entry_.offset = entry_end_;
  entry_.size_bytes = prefix_bytes_ + message.size();

  entry_end_ += entry_.size_bytes;
  ++entries_;
  prefix_value_ = 0;
  prefix_bytes_ = 0;
  prefix_done_ = false;
  message_bytes_ = 0;
  pending_.clear();
  return RecordingDecodeStatus::kEntry;
}

RecordingDecodeStatus RecordingDecoder::Finish() {
  if (defect_ != RecordingDefect::kNone) return RecordingDecodeStatus::kBad;
  if (prefix_bytes_ == 0) return RecordingDecodeStatus::kEnd;
  if (!prefix_done_) {
    return Bad(RecordingDefect::kTornEntry, "the input ends inside a length prefix");
  }
  return Bad(RecordingDefect::kTornEntry, "torn entry: the input ends " +
                                              std::to_string(message_bytes_) + " bytes into a " +
                                              std::to_string(prefix_value_) + "-byte entry");
}

}  // namespace lrfnet::daemon
