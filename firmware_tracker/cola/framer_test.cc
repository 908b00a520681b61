#include "firmware_tracker/cola/framer.h"

#include <gtest/gtest.h>

#include <random>
#include <string>
#include <string_view>
#include <vector>

#include "firmware_tracker/cola/cola_test_util.h"

namespace lrfnet::cola {
namespace {

using Bytes = std::vector<std::uint8_t>;

using test::Append;
using test::Frame;
Bytes ToBytes(std::string_view s) { return test::B(s); }

// What a user of the framer sees: the sequence of frames and rejections, and the counters.
struct Trace {
  std::vector<std::string> events;  // "F:<payload>" or "B:<reason>"
  FramerCounters counters;
  std::size_t buffered = 0;
};

// Feeds `stream` in chunks of the sizes `next_chunk()` returns.
template <typename ChunkSize>
Trace RunChunked(const Bytes& stream, ChunkSize next_chunk, FramerOptions options = {}) {
  Framer framer(options);
  Trace t;
  std::span<const std::uint8_t> rest(stream);
  while (!rest.empty()) {
    const std::size_t n = std::min(rest.size(), std::max<std::size_t>(1, next_chunk()));
    framer.FeedAll(
        rest.first(n),
        [&](std::span<const std::uint8_t> p) {
          t.events.push_back("F:" + std::string(p.begin(), p.end()));
        },
        [&](const char* reason) { t.events.push_back(std::string("B:") + reason); });
    rest = rest.subspan(n);
  }
  t.counters = framer.counters();
  t.buffered = framer.buffered_bytes();
  return t;
}

Trace RunWhole(const Bytes& stream, FramerOptions options = {}) {
  return RunChunked(
      stream, [&] { return stream.size(); }, options);
}
Trace RunByteWise(const Bytes& stream, FramerOptions options = {}) {
  return RunChunked(
      stream, [] { return std::size_t{1}; }, options);
}

void ExpectSameTrace(const Trace& a, const Trace& b) {
  EXPECT_EQ(a.events, b.events);
  EXPECT_EQ(a.counters.frames, b.counters.frames);
  EXPECT_EQ(a.counters.bad_checksum, b.counters.bad_checksum);
  EXPECT_EQ(a.counters.oversize_length, b.counters.oversize_length);
  EXPECT_EQ(a.counters.garbage_bytes, b.counters.garbage_bytes);
  EXPECT_EQ(a.counters.bytes_in, b.counters.bytes_in);
  EXPECT_EQ(a.buffered, b.buffered);
}

// The LMS111 capture's `sRA LIDinputstate` reply: its payload carries 02 02 02 02.
const Bytes kLidInputState = ToBytes(
    std::string_view("sRA LIDinputstate \x00\x01\x00\x00\x00\x00\x02\x02\x02\x02\x00\x00", 30));

// A stream with every kind of trouble: garbage, a bad checksum, an impossible length, a zero
// length, a start sequence inside a payload, a partial start sequence, and a frame cut off at the
// end.
Bytes NastyStream() {
  Bytes s = ToBytes("garbage\x02\x02 more");
  Append(s, Frame("sRN FirmwareVersion"));
  Bytes bad = Frame(std::string_view("sRA FirmwareVersion \x00\x09V1.80.2  ", 31));
  bad.back() ^= 0x55;
  Append(s, bad);
  Append(s, Frame(kLidInputState));
  Append(s, Bytes{2, 2, 2, 2, 0xFF, 0xFF, 0xFF, 0xFF});
  Append(s, Bytes{2, 2, 2, 2, 0, 0, 0, 0});
  Append(s, Bytes{2, 2, 2});
  Append(s, Frame("sEA LMDscandata \x01"));
  Append(s, Bytes{0x02});
  Append(s, Frame("sWA LMDscandatacfg "));
  const Bytes cut = Frame("sAN Run \x01");
  s.insert(s.end(), cut.begin(), cut.end() - 2);
  return s;
}

TEST(FramerTest, EncodeFrameMatchesTheRealLoginCapture) {
  // Bytes of the LMS111 capture: 02 02 02 02 00 00 00 13 "sRN FirmwareVersion" 24.
  const Bytes expected = [] {
    Bytes b{2, 2, 2, 2, 0, 0, 0, 0x13};
    Append(b, ToBytes("sRN FirmwareVersion"));
    b.push_back(0x24);
    return b;
  }();
  EXPECT_EQ(Frame("sRN FirmwareVersion"), expected);
  Bytes small(10);
  EXPECT_EQ(EncodeFrame(ToBytes("sRN FirmwareVersion"), small), 0u);
}

TEST(FramerTest, ChecksumIsXorOfAllBytesForEveryLength) {
  std::mt19937 rng(3);
  for (std::size_t n = 0; n < 40; ++n) {
    Bytes b(n);
    std::uint8_t expected = 0;
    for (auto& v : b) {
      v = static_cast<std::uint8_t>(rng());
      expected ^= v;
    }
    EXPECT_EQ(Checksum(b), expected) << "length " << n;
  }
}

TEST(FramerTest, SplitsConsecutiveFrames) {
  Bytes s;
  Append(s, Frame("sMN SetAccessMode \x03\xf4\x72\x47\x44"));
  Append(s, Frame("sRN FirmwareVersion"));
  const Trace t = RunWhole(s);
  ASSERT_EQ(t.events.size(), 2u);
  EXPECT_EQ(t.events[0], "F:sMN SetAccessMode \x03\xf4\x72\x47\x44");
  EXPECT_EQ(t.events[1], "F:sRN FirmwareVersion");
  EXPECT_EQ(t.counters.frames, 2u);
  EXPECT_EQ(t.counters.garbage_bytes, 0u);
  EXPECT_EQ(t.counters.bytes_in, s.size());
  EXPECT_EQ(t.buffered, 0u);
}

TEST(FramerTest, StartSequenceInsidePayloadIsNotAFrameStart) {
  Bytes s = Frame(kLidInputState);
  Append(s, Frame("sEA LIDinputstate \x01"));
  for (const Trace& t : {RunWhole(s), RunByteWise(s)}) {
    ASSERT_EQ(t.events.size(), 2u);
    EXPECT_EQ(t.events[0], "F:" + std::string(kLidInputState.begin(), kLidInputState.end()));
    EXPECT_EQ(t.counters.garbage_bytes, 0u);
    EXPECT_EQ(t.counters.bad_checksum, 0u);
  }
}

TEST(FramerTest, GarbageBetweenFramesIsSkippedAndCounted) {
  Bytes s = ToBytes("hello");
  Append(s, Frame("sRN A"));
  Append(s, ToBytes("\x02\x02\x02xyz"));  // an almost-start is garbage too
  Append(s, Frame("sRN B"));
  Append(s, Bytes{0, 0});
  const Trace t = RunWhole(s);
  EXPECT_EQ(t.events, (std::vector<std::string>{"F:sRN A", "F:sRN B"}));
  EXPECT_EQ(t.counters.garbage_bytes, 5u + 6u + 2u);
}

TEST(FramerTest, BadChecksumIsRejectedAndTheNextFrameFound) {
  Bytes bad = Frame("sRN FirmwareVersion");
  bad.back() ^= 1;
  Bytes s = bad;
  Append(s, Frame("sRN SerialNumber"));
  const Trace t = RunWhole(s);
  EXPECT_EQ(t.events,
            (std::vector<std::string>{"B:frame checksum mismatch", "F:sRN SerialNumber"}));
  EXPECT_EQ(t.counters.bad_checksum, 1u);
  EXPECT_EQ(t.counters.frames, 1u);
  EXPECT_EQ(t.counters.garbage_bytes, bad.size());
}

TEST(FramerTest, ResyncAfterBadChecksumStartsRightAfterTheRejectedStart) {
  // A corrupted length field that swallows the next frame: the real frame inside must still be
  // found.
  const Bytes inner = Frame("sRN SerialNumber");
  Bytes s{2, 2, 2, 2, 0, 0, 0, static_cast<std::uint8_t>(inner.size() + 2)};
  Append(s, ToBytes("ab"));
  Append(s, inner);
  s.push_back(0x00);  // wrong checksum for "ab" + inner
  const Trace t = RunWhole(s);
  EXPECT_EQ(t.events,
            (std::vector<std::string>{"B:frame checksum mismatch", "F:sRN SerialNumber"}));
}

TEST(FramerTest, OversizeAndZeroLengthsAreRejectedAndCounted) {
  FramerOptions options;
  options.max_payload_bytes = 100;
  Bytes s{2, 2, 2, 2, 0, 0, 0, 101};
  Append(s, Frame(Bytes(100, 'x')));  // exactly the maximum: accepted
  Append(s, Bytes{2, 2, 2, 2, 0, 0, 0, 0});
  Append(s, Frame("sRN Ok"));
  const Trace t = RunWhole(s, options);
  ASSERT_EQ(t.events.size(), 4u);
  EXPECT_EQ(t.events[0], "B:frame length field above max_payload_bytes");
  EXPECT_EQ(t.events[1], "F:" + std::string(100, 'x'));
  EXPECT_EQ(t.events[2], "B:frame length field is zero");
  EXPECT_EQ(t.events[3], "F:sRN Ok");
  EXPECT_EQ(t.counters.oversize_length, 2u);
  EXPECT_EQ(t.counters.garbage_bytes, 16u);
}

TEST(FramerTest, TruncatedStreamKeepsThePartialFrameUntilReset) {
  const Bytes f = Frame("sSN LMDscandata 0123456789");
  const Bytes cut(f.begin(), f.end() - 3);
  Framer framer;
  EXPECT_EQ(framer.Feed(cut), cut.size());
  EXPECT_EQ(framer.Next(), FrameStatus::kNeedMore);
  EXPECT_EQ(framer.buffered_bytes(), cut.size());
  EXPECT_EQ(framer.counters().frames, 0u);
  framer.Reset();
  EXPECT_EQ(framer.buffered_bytes(), 0u);
  // After the reset the tail of the old frame is garbage and the next frame decodes.
  const Bytes tail(f.end() - 3, f.end());
  framer.Feed(tail);
  const Bytes next = Frame("sRN X");
  framer.Feed(next);
  ASSERT_EQ(framer.Next(), FrameStatus::kFrame);
  EXPECT_EQ(std::string(framer.payload().begin(), framer.payload().end()), "sRN X");
  EXPECT_EQ(framer.counters().garbage_bytes, 3u);
  EXPECT_EQ(framer.counters().bytes_in, cut.size() + tail.size() + next.size());
}

TEST(FramerTest, ByteAtATimeEqualsWholeBuffer) {
  const Bytes s = NastyStream();
  const Trace whole = RunWhole(s);
  ExpectSameTrace(RunByteWise(s), whole);
  // 4 good frames (the start inside LIDinputstate is not one). Rejections: one checksum, the
  // 0xFFFFFFFF and zero lengths, and every stray 0x02 in front of a start makes one more start
  // whose length field holds 0x02 bytes (3 + 1).
  EXPECT_EQ(whole.counters.frames, 4u);
  EXPECT_EQ(whole.counters.bad_checksum, 1u);
  EXPECT_EQ(whole.counters.oversize_length, 6u);
  EXPECT_EQ(whole.buffered, Frame("sAN Run \x01").size() - 2);
}

TEST(FramerTest, RandomChunkingsEqualWholeBuffer) {
  const Bytes s = NastyStream();
  const Trace whole = RunWhole(s);
  std::mt19937 rng(12345);
  for (int trial = 0; trial < 200; ++trial) {
    std::uniform_int_distribution<std::size_t> size(1, 1 + static_cast<std::size_t>(trial % 40));
    ExpectSameTrace(RunChunked(s, [&] { return size(rng); }), whole);
  }
}

TEST(FramerTest, SmallBufferStillDeliversEverythingThroughFeedAll) {
  // Feed takes only what fits; FeedAll drains and continues. Frames of the maximum size still fit.
  FramerOptions options;
  options.max_payload_bytes = 64;
  Bytes s(500, 0xAA);
  for (int i = 0; i < 20; ++i) Append(s, Frame(Bytes(64, static_cast<std::uint8_t>('a' + i))));
  const Trace whole = RunWhole(s, options);
  EXPECT_EQ(whole.counters.frames, 20u);
  EXPECT_EQ(whole.counters.garbage_bytes, 500u);
  ExpectSameTrace(RunByteWise(s, options), whole);

  Framer framer(options);
  EXPECT_LT(framer.Feed(s), s.size());  // bounded: the buffer does not grow
}

TEST(FramerTest, ValidateRejectsUnusableBounds) {
  FramerOptions options;
  EXPECT_FALSE(Validate(options).has_value());
  options.max_payload_bytes = 10;
  EXPECT_TRUE(Validate(options).has_value());
  options.max_payload_bytes = std::size_t{4} << 30;
  EXPECT_TRUE(Validate(options).has_value());
}

}  // namespace
}  // namespace lrfnet::cola
