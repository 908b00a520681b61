#include "central_daemon/io/recording_decoder.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <string>
#include <vector>

#include "lrfnet.pb.h"

namespace lrfnet::daemon {
namespace {

using Bytes = std::vector<std::uint8_t>;

constexpr common::UtcNs kDecoderT0 = 1'700'000'000'000'000'000;

void AppendVarint(std::uint64_t v, Bytes* out) {
  while (v >= 0x80) {
    out->push_back(static_cast<std::uint8_t>(v | 0x80));
    v >>= 7;
  }
  out->push_back(static_cast<std::uint8_t>(v));
}

void AppendEntry(const proto::RecordEntry& e, Bytes* out) {
  const std::string message = e.SerializeAsString();
  AppendVarint(message.size(), out);
  out->insert(out->end(), message.begin(), message.end());
}

proto::RecordEntry Header(std::uint32_t version = 1) {
  proto::RecordEntry e;
  e.set_receive_ns(kDecoderT0);
  e.mutable_header()->set_format_version(version);
  e.mutable_header()->set_created_ns(kDecoderT0);
  e.mutable_header()->set_writer("lrfnetd test");
  return e;
}

proto::RecordEntry Datagram(int i, std::size_t size) {
  proto::RecordEntry e;
  e.set_receive_ns(kDecoderT0 + i * common::kNsPerMs);
  e.set_source("10.0.0." + std::to_string(i) + ":4000");
  std::string bytes(size, '\0');
  for (std::size_t k = 0; k < size; ++k) bytes[k] = static_cast<char>(i * 31 + k);
  e.set_datagram(bytes);
  return e;
}

struct Outcome {
  std::vector<RecordingEntry> entries;
  RecordingDecodeStatus end = RecordingDecodeStatus::kNeedMore;
  RecordingDefect defect = RecordingDefect::kNone;
  std::string error;
  std::uint64_t error_offset = 0;
};

// Feeds `bytes` in chunks of `chunk` bytes (0 = all at once), then Finish().
Outcome Decode(const Bytes& bytes, std::size_t chunk = 0) {
  RecordingDecoder decoder;
  Outcome out;
  std::size_t at = 0;
  while (out.end != RecordingDecodeStatus::kBad) {
    if (at == bytes.size()) {
      out.end = decoder.Finish();
      break;
    }
    const std::size_t n = chunk == 0 ? bytes.size() - at : std::min(chunk, bytes.size() - at);
    std::span<const std::uint8_t> piece(bytes.data() + at, n);
    while (!piece.empty()) {
      std::size_t consumed = 0;
      const RecordingDecodeStatus status = decoder.Feed(piece, &consumed);
      piece = piece.subspan(consumed);
      if (status == RecordingDecodeStatus::kEntry) {
        out.entries.push_back(decoder.entry());
      } else if (status == RecordingDecodeStatus::kBad) {
        out.end = status;
        break;
      } else {
        EXPECT_TRUE(piece.empty());
      }
    }
    at += n;
  }
  out.defect = decoder.defect();
  out.error = decoder.error();
  out.error_offset = decoder.error_offset();
  return out;
}

Bytes SmallRecording(std::vector<std::size_t>* boundaries = nullptr) {
  Bytes bytes;
  AppendEntry(Header(), &bytes);
  if (boundaries != nullptr) boundaries->push_back(bytes.size());
  for (int i = 0; i < 4; ++i) {
    AppendEntry(Datagram(i, static_cast<std::size_t>(i) * 90), &bytes);  // 0, 90, 180, 270 bytes
    if (boundaries != nullptr) boundaries->push_back(bytes.size());
  }
  return bytes;
}

TEST(RecordingDecoderTest, DecodesHeaderAndDatagramsInOrder) {
  const Outcome out = Decode(SmallRecording());
  EXPECT_EQ(out.end, RecordingDecodeStatus::kEnd);
  ASSERT_EQ(out.entries.size(), 5u);
  EXPECT_TRUE(out.entries[0].has_header);
  EXPECT_EQ(out.entries[0].header.format_version, 1u);
  EXPECT_EQ(out.entries[0].header.created_ns, kDecoderT0);
  EXPECT_EQ(out.entries[0].header.writer, "lrfnetd test");
  for (int i = 0; i < 4; ++i) {
    const RecordingEntry& e = out.entries[static_cast<std::size_t>(i) + 1];
    const proto::RecordEntry want = Datagram(i, static_cast<std::size_t>(i) * 90);
    EXPECT_FALSE(e.has_header);
    EXPECT_EQ(e.datagram.receive_ns, want.receive_ns());
    EXPECT_EQ(e.datagram.source, want.source());
    EXPECT_EQ(std::string(e.datagram.bytes.begin(), e.datagram.bytes.end()), want.datagram());
  }
}

TEST(RecordingDecoderTest, ChunkingDoesNotChangeTheResult) {
  const Bytes bytes = SmallRecording();
  const Outcome whole = Decode(bytes);
  for (const std::size_t chunk : {1, 2, 3, 7, 64, 100}) {
    const Outcome split = Decode(bytes, chunk);
    EXPECT_EQ(split.end, RecordingDecodeStatus::kEnd) << chunk;
    ASSERT_EQ(split.entries.size(), whole.entries.size()) << chunk;
    for (std::size_t i = 0; i < whole.entries.size(); ++i) {
      EXPECT_EQ(split.entries[i].datagram.bytes, whole.entries[i].datagram.bytes);
      EXPECT_EQ(split.entries[i].offset, whole.entries[i].offset);
      EXPECT_EQ(split.entries[i].size_bytes, whole.entries[i].size_bytes);
    }
  }
}

TEST(RecordingDecoderTest, EveryCutGivesTheWholeEntriesBeforeIt) {
  std::vector<std::size_t> boundaries;
  const Bytes bytes = SmallRecording(&boundaries);
  for (std::size_t cut = 0; cut <= bytes.size(); ++cut) {
    const Outcome out = Decode(Bytes(bytes.begin(), bytes.begin() + static_cast<long>(cut)));
    std::size_t whole = 0;
    while (whole < boundaries.size() && boundaries[whole] <= cut) ++whole;
    EXPECT_EQ(out.entries.size(), whole) << "cut at " << cut;
    const bool at_boundary = cut == 0 || (whole > 0 && boundaries[whole - 1] == cut);
    if (at_boundary) {
      EXPECT_EQ(out.end, RecordingDecodeStatus::kEnd) << "cut at " << cut;
    } else {
      EXPECT_EQ(out.end, RecordingDecodeStatus::kBad) << "cut at " << cut;
      EXPECT_EQ(out.defect, RecordingDefect::kTornEntry);
      EXPECT_EQ(out.error_offset, whole == 0 ? 0u : boundaries[whole - 1]);
    }
  }
}

TEST(RecordingDecoderTest, OversizeLengthIsRejectedBeforeItsBytesArrive) {
  Bytes bytes;
  AppendEntry(Header(), &bytes);
  const std::size_t header_end = bytes.size();
  AppendVarint(kMaxRecordEntryBytes + 1, &bytes);
  RecordingDecoder decoder;
  std::size_t consumed = 0;
  ASSERT_EQ(decoder.Feed(bytes, &consumed), RecordingDecodeStatus::kEntry);
  const std::span<const std::uint8_t> rest(bytes.data() + consumed, bytes.size() - consumed);
  EXPECT_EQ(decoder.Feed(rest, &consumed), RecordingDecodeStatus::kBad);
  EXPECT_EQ(decoder.defect(), RecordingDefect::kOversizeEntry);
  EXPECT_EQ(decoder.error_offset(), header_end);
  EXPECT_NE(decoder.error().find("65537"), std::string::npos) << decoder.error();
  // Final: nothing more is taken.
  EXPECT_EQ(decoder.Feed(rest, &consumed), RecordingDecodeStatus::kBad);
  EXPECT_EQ(consumed, 0u);
  EXPECT_EQ(decoder.Finish(), RecordingDecodeStatus::kBad);
}

TEST(RecordingDecoderTest, LargestEntryIsAccepted) {
  Bytes bytes;
  AppendEntry(Header(), &bytes);
  proto::RecordEntry big = Datagram(1, 0);
  // The datagram field adds its tag and a 3-byte length to its bytes.
  big.set_datagram(std::string(kMaxRecordEntryBytes - big.ByteSizeLong() - 4, 'x'));
  ASSERT_EQ(big.ByteSizeLong(), kMaxRecordEntryBytes);
  AppendEntry(big, &bytes);
  const Outcome out = Decode(bytes, 1000);
  EXPECT_EQ(out.end, RecordingDecodeStatus::kEnd) << out.error;
  ASSERT_EQ(out.entries.size(), 2u);
  EXPECT_EQ(out.entries[1].datagram.bytes.size(), big.datagram().size());
}

TEST(RecordingDecoderTest, DefectsHaveTheirReasons) {
  struct Case {
    const char* name;
    Bytes bytes;
    RecordingDefect defect;
    std::uint64_t offset;
  };
  Bytes header;
  AppendEntry(Header(), &header);
  const auto after_header = [&](Bytes tail) {
    Bytes b = header;
    b.insert(b.end(), tail.begin(), tail.end());
    return b;
  };
  Bytes no_header;
  AppendEntry(Datagram(0, 10), &no_header);
  Bytes version2;
  AppendEntry(Header(2), &version2);
  Bytes twice = header;
  AppendEntry(Header(), &twice);
  const std::vector<Case> cases = {
      {"long varint", after_header({0x80, 0x80, 0x80, 0x80, 0x80, 0x01}),
       RecordingDefect::kBadLengthPrefix, header.size()},
      {"unparsable", after_header({0x02, 0xff, 0xff}), RecordingDefect::kUnparsableEntry,
       header.size()},
      {"no header", no_header, RecordingDefect::kMissingHeader, 0},
      {"empty first entry", Bytes{0x00}, RecordingDefect::kMissingHeader, 0},
      {"version 2", version2, RecordingDefect::kUnsupportedVersion, 0},
      {"second header", twice, RecordingDefect::kRepeatedHeader, header.size()},
  };
  for (const Case& c : cases) {
    const Outcome out = Decode(c.bytes);
    EXPECT_EQ(out.end, RecordingDecodeStatus::kBad) << c.name;
    EXPECT_EQ(out.defect, c.defect) << c.name;
    EXPECT_EQ(out.error_offset, c.offset) << c.name;
    EXPECT_FALSE(out.error.empty()) << c.name;
    EXPECT_EQ(out.error.find('\n'), std::string::npos) << c.name;
  }
}

TEST(RecordingDecoderTest, FollowsTheWireRulesForUnknownAndRepeatedFields) {
  // Unknown fields of every wire type in the entry and the header, a known field number with an
  // unexpected wire type, a repeated scalar (last wins) and a source that is not UTF-8.
  const Bytes header_message = {
      0x08, 0x01,                           // format_version 1
      0x18, 0x05,                           // field 3 (writer) as a varint: skipped
      0x1a, 0x02, 'w', '1',                 // writer "w1"
      0x79, 1,    2,   3,   4, 5, 6, 7, 8,  // field 15, fixed64
      0x1a, 0x02, 'w', '2',                 // writer again: "w2" wins
  };
  Bytes header_entry = {0x22, static_cast<std::uint8_t>(header_message.size())};
  header_entry.insert(header_entry.end(), header_message.begin(), header_message.end());
  const Bytes datagram_entry = {
      0x08, 0x05,                   // receive_ns 5
      0x08, 0x07,                   // receive_ns 7 (wins)
      0x12, 0x03, 0xff, 0xfe, 'x',  // source: not UTF-8
      0x45, 1,    2,    3,    4,    // field 8, fixed32
      0x52, 0x02, 0,    0,          // field 10, length-delimited
      0x60, 0xff, 0x01,             // field 12, varint
      0x1a, 0x02, 0xaa, 0xbb,       // datagram
  };
  Bytes bytes;
  for (const Bytes* message : std::vector<const Bytes*>{&header_entry, &datagram_entry}) {
    AppendVarint(message->size(), &bytes);
    bytes.insert(bytes.end(), message->begin(), message->end());
  }
  const Outcome out = Decode(bytes);
  EXPECT_EQ(out.end, RecordingDecodeStatus::kEnd) << out.error;
  ASSERT_EQ(out.entries.size(), 2u);
  EXPECT_EQ(out.entries[0].header.writer, "w2");
  EXPECT_EQ(out.entries[1].datagram.receive_ns, 7);
  EXPECT_EQ(out.entries[1].datagram.source, "\xff\xfex");
  EXPECT_EQ(out.entries[1].datagram.bytes, (Bytes{0xaa, 0xbb}));
}

TEST(RecordingDecoderTest, BrokenWireFormatIsUnparsable) {
  Bytes header;
  AppendEntry(Header(), &header);
  const std::vector<Bytes> messages = {
      {0x00, 0x01},                          // field number 0
      {0x0b, 0x0c},                          // a group (wire type 3)
      {0x0e},                                // wire type 6
      {0x12, 0x05, 'a'},                     // length beyond the message
      {0x08, 0x80, 0x80},                    // varint cut by the message end
      {0x22, 0x02, 0x1a, 0x05},              // header whose writer runs past it
      {0x80, 0x80, 0x80, 0x80, 0x80, 0x01},  // tag above 32 bits
  };
  for (const Bytes& m : messages) {
    Bytes bytes = header;
    AppendVarint(m.size(), &bytes);
    bytes.insert(bytes.end(), m.begin(), m.end());
    const Outcome out = Decode(bytes);
    EXPECT_EQ(out.defect, RecordingDefect::kUnparsableEntry) << testing::PrintToString(m);
    EXPECT_EQ(out.entries.size(), 1u);
  }
}

TEST(RecordingDecoderTest, EmptyInputEndsCleanlyWithoutEntries) {
  const Outcome out = Decode({});
  EXPECT_EQ(out.end, RecordingDecodeStatus::kEnd);
  EXPECT_TRUE(out.entries.empty());
}

}  // namespace
}  // namespace lrfnet::daemon
