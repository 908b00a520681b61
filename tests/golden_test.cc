// `lrfnet dump` (its library function) against the golden files of the shared SICK captures: same
// number of scans, and for every golden key the value exactly as the golden file prints it. And
// the emulated device against the recorded ones: for every request of the captures' start-up
// dialogues, at its recorded time, the device model's reply equals the real device's reply.

#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "firmware_tracker/cola/framer.h"
#include "firmware_tracker/cola/sopas_value.h"
#include "common/capture/capture_stream.h"
#include "tests/support/test_data.h"
#include "tools/dump.h"
#include "tools/scan_source.h"
#include "tools/sopas_device.h"

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

// ---- the recorded devices' replies

struct Telegram {
  common::UtcNs t = 0;
  std::vector<std::uint8_t> payload;
  std::string Text() const {
    std::string out;
    for (const std::uint8_t b : payload) {
      if (b >= 0x20 && b < 0x7F) {
        out += static_cast<char>(b);
      } else {
        char hex[8];
        std::snprintf(hex, sizeof hex, "\\x%02x", b);
        out += hex;
      }
    }
    return out;
  }
  bool IsEvent() const { return payload.size() > 4 && std::memcmp(payload.data(), "sSN ", 4) == 0; }
};

std::vector<Telegram> Telegrams(const std::string& path, bool from_sensor) {
  capture::CaptureStreamOptions options;
  options.from_sensor = from_sensor;
  std::string error;
  auto stream = capture::CaptureStream::Open(path, options, &error);
  EXPECT_NE(stream, nullptr) << error;
  std::vector<Telegram> out;
  if (!stream) return out;
  cola::Framer framer;
  capture::StreamChunk chunk;
  while (stream->Next(&chunk)) {
    framer.FeedAll(
        chunk.bytes,
        [&](std::span<const std::uint8_t> p) {
          out.push_back({chunk.receive_time_ns, std::vector<std::uint8_t>(p.begin(), p.end())});
        },
        [](const char*) {});
  }
  return out;
}

struct Exchange {
  Telegram request;
  Telegram reply;
  std::vector<Telegram> events;  // events the device sent after the reply, before the next one
};

// Requests and replies pair in order: a driver waits for each reply before the next request.
std::vector<Exchange> Dialogue(const std::string& path) {
  const std::vector<Telegram> requests = Telegrams(path, false);
  const std::vector<Telegram> from_device = Telegrams(path, true);
  std::vector<Exchange> out;
  std::size_t r = 0;
  for (const Telegram& t : from_device) {
    if (t.IsEvent()) {
      if (!out.empty() &&
          (t.payload.size() < 16 || std::memcmp(t.payload.data(), "sSN LMDscandata ", 16) != 0)) {
        out.back().events.push_back(t);
      }
      continue;
    }
    if (r >= requests.size()) break;
    out.push_back({requests[r++], t, {}});
  }
  EXPECT_EQ(r, requests.size()) << path << ": every request has its reply";
  return out;
}

tools::SopasDeviceOptions DeviceOf(const tools::DeviceIdentity& identity) {
  tools::SopasDeviceOptions o;
  o.identity = identity;
  o.family =
      tools::FamilyFromDeviceName(identity.name)
          .value_or(tools::ParseDeviceFamily(identity.name).value_or(tools::DeviceFamily::kLms5xx));
  return o;
}

std::string Name(const Telegram& t) {
  cola::TelegramHeader h;
  if (cola::ParseTelegramHeader(t.payload, &h) != cola::HeaderStatus::kOk) return "?";
  return std::string(cola::CommandTypeName(h.type)) + " " + std::string(h.name);
}

// Values of a live telegram that follow the clock (system counter, time of day) are not compared.
bool SameApartFromTheClock(const Telegram& ours, const Telegram& recorded, std::string_view schema,
                           std::size_t prefix) {
  cola::SopasValues a, b;
  const auto s = cola::SopasSchema::Compile(schema);
  if (!cola::DecodeValues(s, cola::Dialect::kColaB, std::span(ours.payload).subspan(prefix), &a)
           .ok() ||
      !cola::DecodeValues(s, cola::Dialect::kColaB, std::span(recorded.payload).subspan(prefix), &b)
           .ok() ||
      a.size() != b.size()) {
    return false;
  }
  // Version, the states and the time flag; the counter (index 1) and the time of day are live.
  for (std::size_t i = 0; i < a.size() && i < 7; ++i) {
    if (i != 1 && !(a[i] == b[i])) return false;
  }
  return true;
}

struct DialogueCase {
  const char* capture;
  std::size_t exchanges;  // request / reply pairs in the capture
};

class GoldenDialogueTest : public ::testing::TestWithParam<DialogueCase> {};

// The device model with the recorded device's identity and stored values (as `lrfnet emulate
// CAPTURE` builds it), fed every recorded request at its recorded time: every reply is the
// recorded one byte for byte; LIDinputstate up to its clock values. What this shows beyond the
// stored values: every write, method and event answer, every refusal with its code (field030 and
// on, the MRS1104's out-of-range LMPoutputRange and its IMU event), the trailing-space quirks, and
// the state machine's timing (SCdevicestate busy after login, the MRS1104 ready 15 s after Run).
TEST_P(GoldenDialogueTest, EveryReplyEqualsTheRecordedDevicesReply) {
  const DialogueCase& c = GetParam();
  LRFNET_REQUIRE_SHARED_FILE(capture, std::string("data/sick/") + c.capture);
  const std::vector<Exchange> dialogue = Dialogue(capture);
  ASSERT_EQ(dialogue.size(), c.exchanges);
  std::string error;
  const auto source = tools::OpenCaptureScanSource(capture, {}, &error);
  ASSERT_NE(source, nullptr) << error;
  tools::SopasDevice device(DeviceOf(source->identity()));
  const common::UtcNs t0 = dialogue.front().request.t;
  std::size_t equal = 0;
  std::vector<Telegram> our_events;
  for (const Exchange& x : dialogue) {
    std::vector<tools::SopasOutput> out;
    device.HandleRequest(cola::Dialect::kColaB, x.request.payload, x.request.t - t0, &out);
    ASSERT_FALSE(out.empty());
    const Telegram ours{0, out[0].payload};
    const std::string name = Name(x.request);
    if (name == "sRN LIDinputstate") {
      EXPECT_TRUE(SameApartFromTheClock(ours, x.reply, tools::kInputStateSchema, 18))
          << "ours " << ours.Text() << "\nrecorded " << x.reply.Text();
    } else {
      EXPECT_EQ(ours.Text(), x.reply.Text())
          << c.capture << ": reply to " << x.request.Text() << " at "
          << common::NsToSeconds(x.request.t - t0) << " s";
    }
    equal += ours.payload == x.reply.payload;
    for (std::size_t i = 1; i < out.size(); ++i) our_events.push_back(Telegram{0, out[i].payload});
  }
  // The events the recorded device sent during its dialogue (the LMS511's output state after its
  // subscription) are there in the model's too, with the same layout.
  const common::UtcNs end = dialogue.back().reply.t + 50 * common::kNsPerMs;
  for (const Exchange& x : dialogue) {
    for (const Telegram& e : x.events) {
      if (e.t > end) continue;
      bool found = false;
      for (const Telegram& o : our_events) {
        found |= o.payload.size() == e.payload.size() && Name(o) == Name(e);
      }
      EXPECT_TRUE(found) << c.capture << ": no " << Name(e) << " of " << e.payload.size()
                         << " bytes";
    }
  }
  std::printf("%s: %zu of %zu replies byte-equal to the recorded device's\n", c.capture, equal,
              dialogue.size());
}

// A device of the same family with nothing recorded (`lrfnet emulate --synthetic`): the replies
// that do not depend on the unit's identity or its stored configuration are the recorded ones.
TEST_P(GoldenDialogueTest, AFreshDeviceOfTheFamilyAnswersLikeTheRecordedOne) {
  const DialogueCase& c = GetParam();
  LRFNET_REQUIRE_SHARED_FILE(capture, std::string("data/sick/") + c.capture);
  const std::vector<Exchange> dialogue = Dialogue(capture);
  std::string error;
  const auto source = tools::OpenCaptureScanSource(capture, {}, &error);
  ASSERT_NE(source, nullptr) << error;
  tools::DeviceIdentity fresh;
  fresh.name = source->identity().name;
  tools::SopasDevice device(DeviceOf(fresh));
  const common::UtcNs t0 = dialogue.front().request.t;
  std::size_t compared = 0;
  for (const Exchange& x : dialogue) {
    std::vector<tools::SopasOutput> out;
    device.HandleRequest(cola::Dialect::kColaB, x.request.payload, x.request.t - t0, &out);
    ASSERT_FALSE(out.empty());
    const std::string name = Name(x.request);
    const bool identity_or_stored =
        name.rfind("sRN ", 0) == 0 && name != "sRN SCdevicestate" &&
        !(name.rfind("sRN field", 0) == 0 && std::atoi(name.c_str() + 9) >= 30);
    if (identity_or_stored) continue;
    ++compared;
    EXPECT_EQ(Telegram({0, out[0].payload}).Text(), x.reply.Text())
        << c.capture << ": reply to " << x.request.Text();
  }
  EXPECT_GT(compared, 8u);
}

INSTANTIATE_TEST_SUITE_P(SharedCaptures, GoldenDialogueTest,
                         ::testing::Values(DialogueCase{"lms111_20210302.pcap", 49},
                                           DialogueCase{"lms511_20210301.pcap", 67},
                                           DialogueCase{"mrs1104_20210722.pcap", 38}),
                         [](const ::testing::TestParamInfo<DialogueCase>& param_info) {
                           const std::string name = param_info.param.capture;
                           return name.substr(0, name.find('_'));
                         });

}  // namespace
}  // namespace lrfnet
