#include "firmware_tracker/cola/stream_decoder.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <memory>
#include <ostream>
#include <random>
#include <string>
#include <vector>

#include "firmware_tracker/cola/cola_test_util.h"
#include "tests/support/test_data.h"

namespace lrfnet::cola {
namespace {

using Bytes = std::vector<std::uint8_t>;

using test::Append;
using test::Frame;

struct Recorder : TelegramListener {
  std::vector<std::uint16_t> scan_counters;
  std::vector<common::UtcNs> scan_times;
  std::vector<std::string> telegrams;  // "<type> <name>"
  std::vector<std::string> errors;
  void OnScan(const ScanTelegram& scan, common::UtcNs t) override {
    scan_counters.push_back(scan.telegram_counter);
    scan_times.push_back(t);
  }
  void OnTelegram(const TelegramHeader& h, std::span<const std::uint8_t>, common::UtcNs) override {
    telegrams.push_back(std::string(CommandTypeName(h.type)) + " " + std::string(h.name));
  }
  void OnError(const char* reason, common::UtcNs) override { errors.emplace_back(reason); }
};

void ExpectCountersConsistent(const StreamCounters& c) {
  EXPECT_EQ(c.framer.frames, c.bad_headers + c.scans + c.scan_decode_errors + c.other_telegrams);
  std::uint64_t typed = 0;
  for (const auto n : c.by_type) typed += n;
  EXPECT_EQ(typed, c.framer.frames - c.bad_headers);
}

struct StreamCase {
  const char* file;
  std::uint64_t frames;  // README summary table
  std::uint64_t scans;
  std::uint64_t errors_sfa;
};
const StreamCase kStreams[] = {
    {"test.pcapng", 16, 16, 0},
    {"lms111_20210302.pcap", 222, 172, 0},
    {"lms511_20210301.pcap", 209, 136, 18},
    {"mrs1104_20210722.pcap", 134, 96, 2},
};

void PrintTo(const StreamCase& c, std::ostream* os) { *os << c.file; }

class RealStreamTest : public ::testing::TestWithParam<StreamCase> {};

TEST_P(RealStreamTest, CountsMatchTheCaptureSummary) {
  LRFNET_REQUIRE_SHARED_FILE(path, std::string("data/sick/") + GetParam().file);
  const Bytes stream = test::SensorStreamFromCapture(testing::ReadFileBytes(path));
  ASSERT_FALSE(stream.empty());
  auto decoder = std::make_unique<StreamDecoder>();
  Recorder rec;
  // TCP-like chunks of varying size.
  std::mt19937 rng(7);
  std::uniform_int_distribution<std::size_t> chunk(1, 2000);
  std::span<const std::uint8_t> rest(stream);
  common::UtcNs t = 0;
  while (!rest.empty()) {
    const std::size_t n = std::min(rest.size(), chunk(rng));
    decoder->Feed(rest.first(n), t++, rec);
    rest = rest.subspan(n);
  }
  const StreamCounters c = decoder->counters();
  EXPECT_EQ(c.framer.frames, GetParam().frames);
  EXPECT_EQ(c.scans, GetParam().scans);
  EXPECT_EQ(c.other_telegrams, GetParam().frames - GetParam().scans);
  EXPECT_EQ(c.framer.bad_checksum, 0u);
  EXPECT_EQ(c.framer.oversize_length, 0u);
  EXPECT_EQ(c.framer.garbage_bytes, 0u);
  EXPECT_EQ(c.framer.bytes_in, stream.size());
  EXPECT_EQ(c.bad_headers, 0u);
  EXPECT_EQ(c.scan_decode_errors, 0u);
  EXPECT_EQ(c.by_type[static_cast<std::size_t>(CommandType::kError)], GetParam().errors_sfa);
  EXPECT_TRUE(rec.errors.empty());
  ExpectCountersConsistent(c);
  // Retransmissions dropped: telegram counters increase by exactly one.
  ASSERT_EQ(rec.scan_counters.size(), GetParam().scans);
  for (std::size_t i = 1; i < rec.scan_counters.size(); ++i) {
    EXPECT_EQ(static_cast<std::uint16_t>(rec.scan_counters[i - 1] + 1), rec.scan_counters[i]) << i;
  }
}

INSTANTIATE_TEST_SUITE_P(SharedCaptures, RealStreamTest, ::testing::ValuesIn(kStreams),
                         [](const ::testing::TestParamInfo<StreamCase>& param_info) {
                           std::string name = param_info.param.file;
                           return name.substr(0, name.find_first_of("_."));
                         });

TEST(StreamDecoderTest, Lms111LoginDialogueReachesOnTelegram) {
  LRFNET_REQUIRE_SHARED_FILE(path, "data/sick/lms111_20210302.pcap");
  const Bytes stream = test::SensorStreamFromCapture(testing::ReadFileBytes(path));
  auto decoder = std::make_unique<StreamDecoder>();
  Recorder rec;
  for (const std::uint8_t b : stream)
    decoder->Feed(std::span(&b, 1), 0, rec);  // one byte at a time
  ASSERT_GE(rec.telegrams.size(), 3u);
  EXPECT_EQ(rec.telegrams[0], "sAN SetAccessMode");
  EXPECT_EQ(rec.telegrams[1], "sWA EIHstCola");
  EXPECT_EQ(rec.telegrams[2], "sRA FirmwareVersion");
  EXPECT_EQ(std::count(rec.telegrams.begin(), rec.telegrams.end(), "sRA LIDinputstate"), 1);
  EXPECT_EQ(std::count(rec.telegrams.begin(), rec.telegrams.end(), "sSN LIDoutputstate"), 1);
  EXPECT_EQ(decoder->counters().scans, 172u);
}

TEST(StreamDecoderTest, ScanTimeIsTheTimeOfTheChunkThatCompletedTheFrame) {
  const Bytes f = test::EncodeScanFrame(*test::MakeSimpleScan(100, 31));
  auto decoder = std::make_unique<StreamDecoder>();
  Recorder rec;
  decoder->Feed(std::span(f).first(50), 1000, rec);
  EXPECT_TRUE(rec.scan_times.empty());
  decoder->Feed(std::span(f).subspan(50), 2000, rec);
  ASSERT_EQ(rec.scan_times.size(), 1u);
  EXPECT_EQ(rec.scan_times[0], 2000);
  EXPECT_EQ(rec.scan_counters[0], 31);
}

TEST(StreamDecoderTest, EveryKindOfFailureIsReportedAndCounted) {
  Bytes s;
  Bytes bad = Frame("sRN FirmwareVersion");
  bad.back() ^= 0xFF;
  Append(s, bad);             // framer: bad checksum
  Append(s, Frame("hello"));  // header: unknown type
  Bytes scan = test::EncodeScanFrame(*test::MakeSimpleScan(10, 1));
  const Bytes scan_payload(scan.begin() + 8, scan.end() - 1);
  Append(s, Frame(Bytes(scan_payload.begin(), scan_payload.end() - 3)));  // scan: truncated
  Append(s, Frame("sSN LMDscandatamon \x01"));           // not a scan: another telegram
  Append(s, Frame(std::string_view("sFA\x00\x0f", 5)));  // device error reply
  Append(s, scan);                                       // a good scan
  auto decoder = std::make_unique<StreamDecoder>();
  Recorder rec;
  decoder->Feed(s, 5, rec);
  const StreamCounters c = decoder->counters();
  EXPECT_EQ(c.framer.bad_checksum, 1u);
  EXPECT_EQ(c.bad_headers, 1u);
  EXPECT_EQ(c.scan_decode_errors, 1u);
  EXPECT_EQ(c.other_telegrams, 2u);
  EXPECT_EQ(c.scans, 1u);
  EXPECT_EQ(c.by_type[static_cast<std::size_t>(CommandType::kEventData)], 3u);
  EXPECT_EQ(c.by_type[static_cast<std::size_t>(CommandType::kError)], 1u);
  ExpectCountersConsistent(c);
  ASSERT_EQ(rec.errors.size(), 3u);
  EXPECT_EQ(rec.errors[0], "frame checksum mismatch");
  EXPECT_EQ(rec.errors[1], HeaderStatusName(HeaderStatus::kUnknownType));
  EXPECT_NE(rec.errors[2].find("truncated"), std::string::npos) << rec.errors[2];
  EXPECT_EQ(rec.telegrams, (std::vector<std::string>{"sSN LMDscandatamon", "sFA "}));
  EXPECT_EQ(rec.scan_counters, (std::vector<std::uint16_t>{1}));
}

TEST(StreamDecoderTest, ResetDropsAPartialFrameButKeepsCounters) {
  const Bytes f = test::EncodeScanFrame(*test::MakeSimpleScan(100, 2));
  auto decoder = std::make_unique<StreamDecoder>();
  Recorder rec;
  decoder->Feed(f, 0, rec);
  decoder->Feed(std::span(f).first(100), 0, rec);
  decoder->Reset();
  decoder->Feed(f, 0, rec);
  EXPECT_EQ(rec.scan_counters.size(), 2u);
  EXPECT_TRUE(rec.errors.empty());
  EXPECT_EQ(decoder->counters().scans, 2u);
  EXPECT_EQ(decoder->counters().framer.bytes_in, 2 * f.size() + 100);
}

}  // namespace
}  // namespace lrfnet::cola
