#include "firmware_tracker/cola/sopas_framer.h"

#include <gtest/gtest.h>

#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "firmware_tracker/cola/cola_test_util.h"

namespace lrfnet::cola {
namespace {

using Bytes = std::vector<std::uint8_t>;

using test::B;

Bytes Cat(std::initializer_list<Bytes> parts) {
  Bytes out;
  for (const Bytes& p : parts) out.insert(out.end(), p.begin(), p.end());
  return out;
}

struct Collected {
  std::vector<std::pair<Dialect, std::string>> frames;
  std::vector<std::string> bad;
};

Collected FeedInChunks(SopasFramer& framer, const Bytes& stream, std::size_t chunk) {
  Collected c;
  for (std::size_t i = 0; i < stream.size(); i += chunk) {
    const std::size_t n = std::min(chunk, stream.size() - i);
    framer.FeedAll(
        std::span<const std::uint8_t>(stream.data() + i, n),
        [&](Dialect d, std::span<const std::uint8_t> p) {
          c.frames.emplace_back(d, std::string(p.begin(), p.end()));
        },
        [&](const char* reason) { c.bad.emplace_back(reason); });
  }
  return c;
}

TEST(SopasFramerTest, BothDialectsOnOneStreamWhateverTheChunking) {
  // What SICK's driver does on connect: a CoLa-B probe, the same in CoLa-A, then CoLa-B again.
  const Bytes stream =
      Cat({EncodeSopasFrame(Dialect::kColaB, B("sRN SCdevicestate")),
           EncodeSopasFrame(Dialect::kColaA, B("sRN SCdevicestate")),
           EncodeSopasFrame(Dialect::kColaA, B("sMN SetAccessMode 3 F4724744")),
           EncodeSopasFrame(Dialect::kColaB, B(std::string_view("sEN LMDscandata \x01", 17)))});
  for (const std::size_t chunk : {std::size_t{1}, std::size_t{2}, std::size_t{7}, stream.size()}) {
    SopasFramer framer;
    const Collected c = FeedInChunks(framer, stream, chunk);
    ASSERT_EQ(c.frames.size(), 4u) << "chunk " << chunk;
    EXPECT_TRUE(c.bad.empty());
    EXPECT_EQ(c.frames[0], std::make_pair(Dialect::kColaB, std::string("sRN SCdevicestate")));
    EXPECT_EQ(c.frames[1], std::make_pair(Dialect::kColaA, std::string("sRN SCdevicestate")));
    EXPECT_EQ(c.frames[2],
              std::make_pair(Dialect::kColaA, std::string("sMN SetAccessMode 3 F4724744")));
    EXPECT_EQ(c.frames[3],
              std::make_pair(Dialect::kColaB, std::string("sEN LMDscandata \x01", 17)));
    EXPECT_EQ(framer.counters().frames_cola_a, 2u);
    EXPECT_EQ(framer.counters().frames_cola_b, 2u);
    EXPECT_EQ(framer.counters().garbage_bytes, 0u);
    EXPECT_EQ(framer.buffered_bytes(), 0u);
  }
}

TEST(SopasFramerTest, StartSequenceInsideACoLaBPayloadIsNoFrame) {
  // The LMS111's `sRA LIDinputstate` reply carries 02 02 02 02 in its arguments.
  const Bytes payload =
      B(std::string_view("sRA LIDinputstate \x00\x01\x00\x00\x00\x00\x02\x02\x02\x02\x00\x00", 30));
  SopasFramer framer;
  const Collected c = FeedInChunks(framer, EncodeSopasFrame(Dialect::kColaB, payload), 3);
  ASSERT_EQ(c.frames.size(), 1u);
  EXPECT_EQ(c.frames[0].second, std::string(payload.begin(), payload.end()));
}

TEST(SopasFramerTest, GarbageAndBrokenFramesAreCountedAndSkipped) {
  Bytes bad_checksum = EncodeSopasFrame(Dialect::kColaB, B("sRN DeviceIdent"));
  bad_checksum.back() ^= 0x55;
  const Bytes stream = Cat({B("xyz"),                                       // garbage
                            bad_checksum,                                   // rejected
                            Bytes{0x02}, B("sRN Cut"),                      // cut by the next STX
                            EncodeSopasFrame(Dialect::kColaA, B("sRN A")),  // fine
                            Bytes{0x02, 0x03},                              // empty CoLa-A
                            Bytes{0x02, 0x02, 0x02, 0x02, 0, 0, 0, 0},      // zero length
                            EncodeSopasFrame(Dialect::kColaB, B("sRN B"))});
  SopasFramer framer;
  const Collected c = FeedInChunks(framer, stream, stream.size());
  ASSERT_EQ(c.frames.size(), 2u);
  EXPECT_EQ(c.frames[0], std::make_pair(Dialect::kColaA, std::string("sRN A")));
  EXPECT_EQ(c.frames[1], std::make_pair(Dialect::kColaB, std::string("sRN B")));
  EXPECT_EQ(framer.counters().bad_checksum, 1u);
  EXPECT_EQ(framer.counters().oversize_length, 1u);
  EXPECT_GE(framer.counters().bad_cola_a, 2u);  // the cut one and the empty one
  EXPECT_GE(c.bad.size(), 4u);
  EXPECT_GT(framer.counters().garbage_bytes, 3u);
  EXPECT_EQ(framer.counters().bytes_in, stream.size());
}

TEST(SopasFramerTest, OverlongCoLaAFrameIsDroppedAndTheStreamRecovers) {
  SopasFramerOptions options;
  options.max_payload_bytes = 64;
  SopasFramer framer(options);
  Bytes stream{0x02};
  stream.resize(1 + 5000, 'a');  // never ends
  const Bytes good = EncodeSopasFrame(Dialect::kColaA, B("sRN SCdevicestate"));
  stream.insert(stream.end(), good.begin(), good.end());
  const Collected c = FeedInChunks(framer, stream, 1);  // byte by byte: the slow-client case
  ASSERT_EQ(c.frames.size(), 1u);
  EXPECT_EQ(c.frames[0].second, "sRN SCdevicestate");
  EXPECT_EQ(framer.counters().bad_cola_a, 1u);
  EXPECT_LE(framer.buffered_bytes(), 64u + 9u);
}

TEST(SopasFramerTest, StrayStartBytesBeforeACoLaAFrame) {
  // 02 02 's'...: the first 02 is stray, the frame starts at the second.
  const Bytes stream = Cat({Bytes{0x02}, EncodeSopasFrame(Dialect::kColaA, B("sRN X"))});
  SopasFramer framer;
  const Collected c = FeedInChunks(framer, stream, 1);
  ASSERT_EQ(c.frames.size(), 1u);
  EXPECT_EQ(c.frames[0].second, "sRN X");
  EXPECT_EQ(framer.counters().garbage_bytes, 1u);
}

TEST(SopasFramerTest, EncodeRefusesWhatCoLaACannotCarry) {
  EXPECT_TRUE(EncodeSopasFrame(Dialect::kColaA, B(std::string_view("sRA X \x03", 7))).empty());
  EXPECT_TRUE(EncodeSopasFrame(Dialect::kColaA, {}).empty());
  EXPECT_EQ(EncodeSopasFrame(Dialect::kColaA, B("sRA X 1")),
            Cat({Bytes{2}, B("sRA X 1"), Bytes{3}}));
}

}  // namespace
}  // namespace lrfnet::cola
