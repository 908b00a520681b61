// `lrfnet dump` (its library function) against the golden files of the shared SICK captures: same
// number of scans, and for every golden key the value exactly as the golden file prints it.

#include <gtest/gtest.h>

#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "tests/support/test_data.h"
#include "tools/dump.h"

namespace lrfnet {
namespace {

// Splits a flat JSON object line ({"k": v, ...} with numbers, null and arrays of numbers as values)
// into key -> value text as printed, keeping the key order. Returns false on anything else.
bool SplitFlatJson(const std::string& line, std::vector<std::pair<std::string, std::string>>* out) {
  out->clear();
  std::size_t i = 0;
  if (line.empty() || line[i++] != '{') return false;
  while (i < line.size()) {
    if (line[i] != '"') return false;
    const std::size_t key_end = line.find('"', i + 1);
    if (key_end == std::string::npos) return false;
    std::string key = line.substr(i + 1, key_end - i - 1);
    i = key_end + 1;
    if (line.compare(i, 2, ": ") != 0) return false;
    i += 2;
    int depth = 0;
    const std::size_t value_start = i;
    for (; i < line.size(); ++i) {
      const char c = line[i];
      if (c == '[') ++depth;
      if (c == ']') --depth;
      if (depth == 0 && (c == ',' || c == '}')) break;
    }
    if (i >= line.size()) return false;
    out->emplace_back(std::move(key), line.substr(value_start, i - value_start));
    if (line[i] == '}') return i + 1 == line.size();
    if (line.compare(i, 2, ", ") != 0) return false;
    i += 2;
  }
  return false;
}

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

struct GoldenCase {
  const char* capture;
  const char* golden;
  std::size_t scans;
  // Summary facts from the shared data README.
  std::uint64_t frames;
  std::uint64_t other_telegrams;
  std::uint64_t sfa;
  std::uint64_t retransmitted_bytes;
};

class GoldenTest : public ::testing::TestWithParam<GoldenCase> {};

TEST_P(GoldenTest, DumpMatchesTheGoldenFileOnEveryGoldenKey) {
  const GoldenCase& c = GetParam();
  LRFNET_REQUIRE_SHARED_FILE(capture, std::string("data/sick/") + c.capture);
  LRFNET_REQUIRE_SHARED_FILE(golden_path, std::string("data/sick/") + c.golden);

  std::ostringstream out;
  tools::DumpSummary summary;
  std::string error;
  ASSERT_TRUE(tools::DumpCapture(capture, tools::DumpOptions{}, &out, &summary, &error)) << error;
  const std::vector<std::string> ours = Lines(out.str());
  std::ifstream golden_in(golden_path);
  std::stringstream golden_text;
  golden_text << golden_in.rdbuf();
  const std::vector<std::string> golden = Lines(golden_text.str());

  ASSERT_EQ(golden.size(), c.scans) << "golden file changed?";
  ASSERT_EQ(ours.size(), c.scans);
  for (std::size_t n = 0; n < ours.size(); ++n) {
    std::vector<std::pair<std::string, std::string>> our_fields, golden_fields;
    ASSERT_TRUE(SplitFlatJson(ours[n], &our_fields)) << "line " << n + 1 << ": " << ours[n];
    ASSERT_TRUE(SplitFlatJson(golden[n], &golden_fields)) << golden[n];
    ASSERT_TRUE(nlohmann::json::accept(ours[n])) << "not valid JSON: " << ours[n];
    for (std::size_t k = 1; k < our_fields.size(); ++k) {
      ASSERT_LT(our_fields[k - 1].first, our_fields[k].first) << "keys not sorted: " << ours[n];
    }
    const std::map<std::string, std::string> our_map(our_fields.begin(), our_fields.end());
    for (const auto& [key, value] : golden_fields) {
      const auto it = our_map.find(key);
      ASSERT_NE(it, our_map.end()) << "line " << n + 1 << " lacks key " << key;
      ASSERT_EQ(it->second, value) << c.capture << " line " << n + 1 << " key " << key;
    }
  }

  EXPECT_EQ(summary.scans, c.scans);
  EXPECT_EQ(summary.stream.framer.frames, c.frames);
  EXPECT_EQ(summary.stream.framer.bad_checksum, 0u);
  EXPECT_EQ(summary.stream.scan_decode_errors, 0u);
  std::uint64_t others = 0;
  for (const auto& [type, n] : summary.other_by_type) others += n;
  EXPECT_EQ(others, c.other_telegrams);
  EXPECT_EQ(summary.other_by_type.count("sFA") ? summary.other_by_type.at("sFA") : 0u, c.sfa);
  EXPECT_EQ(summary.capture.retransmitted_bytes, c.retransmitted_bytes);
}

INSTANTIATE_TEST_SUITE_P(
    SharedCaptures, GoldenTest,
    ::testing::Values(
        GoldenCase{"test.pcapng", "test.scans.jsonl", 16, 16, 0, 0, 0},
        GoldenCase{"lms111_20210302.pcap", "lms111_20210302.scans.jsonl", 172, 222, 50, 0, 3663},
        GoldenCase{"lms511_20210301.pcap", "lms511_20210301.scans.jsonl", 136, 209, 73, 18, 117},
        GoldenCase{"mrs1104_20210722.pcap", "mrs1104_20210722.scans.jsonl", 96, 134, 38, 2, 0}),
    [](const ::testing::TestParamInfo<GoldenCase>& param_info) {
      std::string name = param_info.param.capture;
      return name.substr(0, name.find('.'));
    });

TEST(GoldenEvents, Lms511StreamHoldsItsFieldEvaluationAndOutputEvents) {
  LRFNET_REQUIRE_SHARED_FILE(capture, "data/sick/lms511_20210301.pcap");
  tools::DumpSummary summary;
  std::string error;
  ASSERT_TRUE(tools::DumpCapture(capture, tools::DumpOptions{}, nullptr, &summary, &error))
      << error;
  EXPECT_EQ(summary.events_by_name["LFErec"], 3u);
  EXPECT_EQ(summary.events_by_name["LIDoutputstate"], 3u);
}

}  // namespace
}  // namespace lrfnet
