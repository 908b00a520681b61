#include "firmware_tracker/cola/scan_telegram.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <ostream>
#include <string>
#include <vector>

#include "common/geometry.h"
#include "firmware_tracker/cola/cola_test_util.h"
#include "tests/support/test_data.h"

#ifdef LRFNET_HAVE_NLOHMANN_JSON
#include <nlohmann/json.hpp>
#endif

namespace lrfnet::cola {
namespace {

using Bytes = std::vector<std::uint8_t>;
constexpr char kScanPrefix[] = "sSN LMDscandata ";

// Offsets in a payload (counted from the 's' of "sSN"; scan_telegram.h / shared README).
constexpr std::size_t kEncoderCountOffset = 52;
constexpr std::size_t kChannel16CountOffset = 54;  // with no encoders
constexpr std::size_t kFirstChannelCountOffset = 56 + 19;

std::uint16_t ReadBe16(const Bytes& b, std::size_t at) {
  return static_cast<std::uint16_t>((b[at] << 8) | b[at + 1]);
}
void WriteBe16(Bytes& b, std::size_t at, std::uint16_t v) {
  b[at] = static_cast<std::uint8_t>(v >> 8);
  b[at + 1] = static_cast<std::uint8_t>(v);
}

Bytes Encode(const ScanTelegram& scan) {
  Bytes out(MaxEncodedSize(scan));
  out.resize(EncodeScanTelegram(scan, out));
  return out;
}

DecodeResult Decode(std::span<const std::uint8_t> payload, ScanTelegram* out) {
  return DecodeScanTelegram(payload, out);
}

// ---- real captures

struct CaptureCase {
  const char* file;
  std::size_t scans;  // LMDscandata telegrams in the stream after dropping retransmissions (README)
};
const CaptureCase kCaptures[] = {
    {"test.pcapng", 16},
    {"lms111_20210302.pcap", 172},
    {"lms511_20210301.pcap", 136},
    {"mrs1104_20210722.pcap", 96},
};

std::vector<Bytes> ScanPayloads(const std::string& path) {
  const Bytes file = testing::ReadFileBytes(path);
  return test::ExtractFrames(test::SensorStreamFromCapture(file), kScanPrefix);
}

void PrintTo(const CaptureCase& c, std::ostream* os) { *os << c.file; }

class RealCaptureTest : public ::testing::TestWithParam<CaptureCase> {};

TEST_P(RealCaptureTest, EveryTelegramDecodesAndReencodesByteForByte) {
  LRFNET_REQUIRE_SHARED_FILE(path, std::string("data/sick/") + GetParam().file);
  const std::vector<Bytes> payloads = ScanPayloads(path);
  ASSERT_EQ(payloads.size(), GetParam().scans);
  auto scan = std::make_unique<ScanTelegram>();
  for (const Bytes& p : payloads) {
    const DecodeResult r = Decode(p, scan.get());
    ASSERT_TRUE(r.ok) << r.reason << " at " << r.offset;
    EXPECT_EQ(r.offset, p.size());
    EXPECT_EQ(MaxEncodedSize(*scan), p.size());
    ASSERT_EQ(Encode(*scan), p) << "telegram " << scan->telegram_counter;
    // The shared README: no encoders or optional blocks except time, DIST1 scale 1 and offset 0.
    EXPECT_TRUE(scan->encoders.empty());
    EXPECT_FALSE(scan->has_position || scan->has_name || scan->has_comment || scan->has_event);
    EXPECT_TRUE(scan->has_time);
    EXPECT_EQ(scan->time.year, 1970);
    const ScanChannel* dist = scan->FindChannel("DIST1");
    ASSERT_NE(dist, nullptr);
    EXPECT_EQ(dist->scale_factor, 1.0f);
    EXPECT_EQ(dist->scale_offset, 0.0f);
  }
}

#ifdef LRFNET_HAVE_NLOHMANN_JSON
TEST_P(RealCaptureTest, DecodedValuesMatchTheGoldenFile) {
  LRFNET_REQUIRE_SHARED_FILE(path, std::string("data/sick/") + GetParam().file);
  std::string golden_name = GetParam().file;
  golden_name = golden_name.substr(0, golden_name.rfind('.')) + ".scans.jsonl";
  LRFNET_REQUIRE_SHARED_FILE(golden_path, "data/sick/" + golden_name);
  std::map<int, nlohmann::json> golden;
  std::ifstream in(golden_path);
  for (std::string line; std::getline(in, line);) {
    if (line.empty()) continue;
    const auto j = nlohmann::json::parse(line);
    golden[j.at("telegram_counter").get<int>()] = j;
  }
  ASSERT_EQ(golden.size(), GetParam().scans);

  auto scan = std::make_unique<ScanTelegram>();
  std::size_t matched = 0;
  for (const Bytes& p : ScanPayloads(path)) {
    ASSERT_TRUE(Decode(p, scan.get()).ok);
    const auto it = golden.find(scan->telegram_counter);
    ASSERT_NE(it, golden.end()) << "telegram " << scan->telegram_counter
                                << " not in the golden file";
    const nlohmann::json& g = it->second;
    SCOPED_TRACE("telegram " + std::to_string(scan->telegram_counter));
    ++matched;
    EXPECT_EQ(scan->scan_counter, g.at("scan_counter").get<int>());
    EXPECT_EQ(scan->time_since_startup_us, g.at("time_since_startup_us").get<std::uint32_t>());
    EXPECT_EQ(scan->time_of_transmission_us, g.at("time_of_transmission_us").get<std::uint32_t>());
    EXPECT_DOUBLE_EQ(scan->scan_frequency_hz(), g.at("scan_frequency_hz").get<double>());
    const ScanChannel* dist = scan->FindChannel("DIST1");
    ASSERT_NE(dist, nullptr);
    EXPECT_EQ(dist->bits, 16);
    EXPECT_NEAR(dist->start_angle_deg(), g.at("start_angle_deg").get<double>(), 1e-9);
    EXPECT_NEAR(dist->angle_step_deg(), g.at("angle_step_deg").get<double>(), 1e-9);
    EXPECT_EQ(dist->count, g.at("n_points").get<int>());
    std::int64_t dist_sum = 0;
    for (std::size_t i = 0; i < dist->count; ++i) dist_sum += dist->raw[i];
    EXPECT_EQ(dist_sum, g.at("dist1_raw_sum").get<std::int64_t>());
    EXPECT_EQ(dist->scale_factor, g.at("dist1_scale").get<float>());
    const auto first3 = g.at("dist1_first3_m").get<std::vector<double>>();
    ASSERT_EQ(first3.size(), 3u);
    for (std::size_t i = 0; i < 3; ++i) {
      EXPECT_NEAR(std::round(dist->RangeM(i) * 1e4) / 1e4, first3[i], 1e-9) << "beam " << i;
    }
    const ScanChannel* rssi = scan->FindChannel("RSSI1");
    if (g.at("rssi_n").get<int>() == 0) {
      EXPECT_EQ(rssi, nullptr);
      EXPECT_EQ(g.at("rssi_bits").get<int>(), 0);
    } else {
      ASSERT_NE(rssi, nullptr);
      EXPECT_EQ(rssi->count, g.at("rssi_n").get<int>());
      EXPECT_EQ(rssi->bits, g.at("rssi_bits").get<int>());
      std::int64_t rssi_sum = 0;
      for (std::size_t i = 0; i < rssi->count; ++i) rssi_sum += rssi->raw[i];
      EXPECT_EQ(rssi_sum, g.at("rssi_raw_sum").get<std::int64_t>());
    }
    const auto& tb = g.at("time_block");
    ASSERT_TRUE(scan->has_time);
    ASSERT_TRUE(tb.is_array());
    const std::vector<std::int64_t> expected = tb.get<std::vector<std::int64_t>>();
    const std::vector<std::int64_t> actual = {
        scan->time.year,   scan->time.month,  scan->time.day,        scan->time.hour,
        scan->time.minute, scan->time.second, scan->time.microsecond};
    EXPECT_EQ(actual, expected);
  }
  EXPECT_EQ(matched, golden.size());
}
#else
TEST_P(RealCaptureTest, DecodedValuesMatchTheGoldenFile) {
  GTEST_SKIP() << "built without nlohmann-json: golden-file comparison not compiled";
}
#endif

INSTANTIATE_TEST_SUITE_P(SharedCaptures, RealCaptureTest, ::testing::ValuesIn(kCaptures),
                         [](const ::testing::TestParamInfo<CaptureCase>& param_info) {
                           std::string name = param_info.param.file;
                           return name.substr(0, name.find_first_of("_."));
                         });

TEST(ScanTelegramTest, Lms511CarriesRssi1InThe8BitBlock) {
  LRFNET_REQUIRE_SHARED_FILE(path, "data/sick/lms511_20210301.pcap");
  const std::vector<Bytes> payloads = ScanPayloads(path);
  ASSERT_FALSE(payloads.empty());
  auto scan = std::make_unique<ScanTelegram>();
  ASSERT_TRUE(Decode(payloads.front(), scan.get()).ok);
  EXPECT_EQ(scan->version, 0);
  ASSERT_EQ(scan->channels16.size(), 1u);
  ASSERT_EQ(scan->channels8.size(), 1u);
  const ScanChannel& rssi = scan->channels8[0];
  EXPECT_EQ(rssi.name_view(), "RSSI1");
  EXPECT_EQ(rssi.bits, 8);
  EXPECT_EQ(rssi.count, 1141);
  std::size_t saturated = 0;
  for (std::size_t i = 0; i < rssi.count; ++i) saturated += rssi.raw[i] == 254 ? 1 : 0;
  EXPECT_GT(saturated, rssi.count / 8);  // "about a quarter of the values are 254"
  EXPECT_EQ(scan->FindChannel("RSSI1"), &rssi);
}

TEST(ScanTelegramTest, Mrs1104LayerAnglesCycle) {
  LRFNET_REQUIRE_SHARED_FILE(path, "data/sick/mrs1104_20210722.pcap");
  const std::vector<Bytes> payloads = ScanPayloads(path);
  ASSERT_EQ(payloads.size(), 96u);
  auto scan = std::make_unique<ScanTelegram>();
  std::vector<int> layers;
  for (const Bytes& p : payloads) {
    ASSERT_TRUE(Decode(p, scan.get()).ok);
    layers.push_back(scan->layer_angle_raw);
    EXPECT_EQ(scan->scan_frequency_raw, 5000u);
    EXPECT_EQ(scan->measurement_frequency_raw, 180u);
  }
  const std::vector<int> cycle = {250, -500, 0, -250};
  std::size_t phase = 0;
  while (phase < 4 && cycle[phase] != layers[0]) ++phase;
  ASSERT_LT(phase, 4u) << "first layer angle " << layers[0];
  for (std::size_t i = 0; i < layers.size(); ++i) EXPECT_EQ(layers[i], cycle[(phase + i) % 4]) << i;
}

TEST(ScanTelegramTest, TruncationAtEveryOffsetIsAnErrorWithAReason) {
  // A real LMS511 telegram (both channel blocks) when present; the all-blocks synthetic one always.
  std::vector<Bytes> telegrams = {Encode(*test::MakeFullScan(40))};
  if (const auto path = testing::SharedFile("data/sick/lms511_20210301.pcap")) {
    telegrams.push_back(ScanPayloads(*path).at(0));
  }
  auto scan = std::make_unique<ScanTelegram>();
  for (const Bytes& full : telegrams) {
    ASSERT_TRUE(Decode(full, scan.get()).ok);
    for (std::size_t cut = 0; cut < full.size(); ++cut) {
      // A copy of exactly `cut` bytes, so a read past the end is caught by ASan.
      const Bytes part(full.begin(), full.begin() + static_cast<std::ptrdiff_t>(cut));
      const DecodeResult r = Decode(part, scan.get());
      ASSERT_FALSE(r.ok) << "cut at " << cut;
      ASSERT_NE(std::string(r.reason), "") << "cut at " << cut;
      ASSERT_LE(r.offset, cut);
      if (cut < 16) {
        EXPECT_STREQ(r.reason, "not an sSN LMDscandata telegram");
      } else {
        EXPECT_NE(std::string(r.reason).find("truncated"), std::string::npos)
            << r.reason << " at " << cut;
      }
    }
  }
}

TEST(ScanTelegramTest, TrailingBytesAreAnError) {
  Bytes p = Encode(*test::MakeSimpleScan(10, 1));
  const std::size_t size = p.size();
  p.push_back(0);
  auto scan = std::make_unique<ScanTelegram>();
  const DecodeResult r = Decode(p, scan.get());
  EXPECT_FALSE(r.ok);
  EXPECT_STREQ(r.reason, "trailing bytes after the event flag");
  EXPECT_EQ(r.offset, size);
}

TEST(ScanTelegramTest, CorruptedCountsAreRejected) {
  const Bytes good = Encode(*test::MakeSimpleScan(100, 1));
  auto scan = std::make_unique<ScanTelegram>();
  ASSERT_EQ(ReadBe16(good, kFirstChannelCountOffset), 100);

  Bytes p = good;
  WriteBe16(p, kFirstChannelCountOffset, 60000);
  DecodeResult r = Decode(p, scan.get());
  EXPECT_FALSE(r.ok);
  EXPECT_STREQ(r.reason, "too many points in channel for the fixed capacity");
  EXPECT_EQ(r.offset, kChannel16CountOffset + 2);

  p = good;
  WriteBe16(p, kFirstChannelCountOffset, 101);  // plausible but longer than the data
  r = Decode(p, scan.get());
  EXPECT_FALSE(r.ok);

  p = good;
  WriteBe16(p, kChannel16CountOffset, 11);
  r = Decode(p, scan.get());
  EXPECT_STREQ(r.reason, "too many 16-bit channels for the fixed capacity");

  p = good;
  WriteBe16(p, kEncoderCountOffset, 5);
  r = Decode(p, scan.get());
  EXPECT_STREQ(r.reason, "too many encoders for the fixed capacity");

  p = good;
  WriteBe16(p, kEncoderCountOffset, 1);  // shifts everything by 6 bytes
  EXPECT_FALSE(Decode(p, scan.get()).ok);

  p = good;
  WriteBe16(p, p.size() - 2, 2);  // event flag
  r = Decode(p, scan.get());
  EXPECT_STREQ(r.reason, "event flag is neither 0 nor 1");
  EXPECT_EQ(r.offset, p.size() - 2);

  const Bytes not_scan = {'s', 'S', 'N', ' ', 'L', 'M', 'D', 's', 'c',
                          'a', 'n', 'd', 'a', 't', 'a', 'm', 'o', 'n'};
  EXPECT_STREQ(Decode(not_scan, scan.get()).reason, "not an sSN LMDscandata telegram");
}

TEST(ScanTelegramTest, CapacityLimitsAreErrorsNotTruncation) {
  auto at_capacity = test::MakeSimpleScan(static_cast<std::uint16_t>(kMaxPointsPerChannel), 9);
  const Bytes p = Encode(*at_capacity);
  ASSERT_FALSE(p.empty());
  auto scan = std::make_unique<ScanTelegram>();
  ASSERT_TRUE(Decode(p, scan.get()).ok);
  EXPECT_EQ(scan->channels16[0].count, kMaxPointsPerChannel);

  // One point more (counts fixed up consistently) is refused by the decoder, and the encoder
  // refuses it too.
  Bytes over = p;
  const std::size_t dist_data_end = kFirstChannelCountOffset + 2 + 2 * kMaxPointsPerChannel;
  over.insert(over.begin() + static_cast<std::ptrdiff_t>(dist_data_end), {0, 1});
  WriteBe16(over, kFirstChannelCountOffset, static_cast<std::uint16_t>(kMaxPointsPerChannel + 1));
  const DecodeResult r = Decode(over, scan.get());
  EXPECT_FALSE(r.ok);
  EXPECT_STREQ(r.reason, "too many points in channel for the fixed capacity");
  at_capacity->channels16[0].count = static_cast<std::uint16_t>(kMaxPointsPerChannel + 1);
  Bytes out(MaxEncodedSize(*at_capacity));
  EXPECT_EQ(EncodeScanTelegram(*at_capacity, out), 0u);
}

TEST(ScanTelegramTest, SyntheticTelegramWithEveryBlockRoundTrips) {
  const auto full = test::MakeFullScan(300);
  const Bytes p = Encode(*full);
  ASSERT_EQ(p.size(), MaxEncodedSize(*full));
  auto scan = std::make_unique<ScanTelegram>();
  const DecodeResult r = Decode(p, scan.get());
  ASSERT_TRUE(r.ok) << r.reason << " at " << r.offset;
  EXPECT_TRUE(test::SameScan(*scan, *full));
  EXPECT_EQ(Encode(*scan), p);
  // Spot checks of what the user reads.
  EXPECT_EQ(scan->encoders.size(), 2u);
  EXPECT_EQ(scan->encoders[1].position, 0xFFFFFFF0u);
  EXPECT_EQ(scan->encoders[0].speed, -42);
  EXPECT_EQ(scan->channels16.size(), 5u);
  EXPECT_EQ(scan->channels8.size(), 5u);
  EXPECT_EQ(scan->FindChannel("DIST5"), &scan->channels16[4]);
  EXPECT_EQ(scan->FindChannel("RSSI3"), &scan->channels8[2]);
  EXPECT_EQ(scan->FindChannel("ANGL1"), nullptr);
  EXPECT_DOUBLE_EQ(scan->channels16[1].RangeM(3), scan->channels16[1].raw[3] * 2.0 / 1000.0 + 0.25);
  EXPECT_EQ(scan->position.z_rotation, -3.0f);
  EXPECT_EQ(scan->name.view(), "gateway-7");
  EXPECT_EQ(scan->comment.view(), std::string_view("mounted at the door\x01\xff", 21));
  EXPECT_EQ(std::string(scan->event.type.data()), "FDIN");
  EXPECT_EQ(scan->event.angle_raw, -123456);
  EXPECT_EQ(scan->layer_angle_raw, -250);
}

TEST(ScanTelegramTest, DecodingIntoAUsedTelegramClearsOldBlocks) {
  auto scan = std::make_unique<ScanTelegram>();
  ASSERT_TRUE(Decode(Encode(*test::MakeFullScan(20)), scan.get()).ok);
  const auto simple = test::MakeSimpleScan(20, 5);
  ASSERT_TRUE(Decode(Encode(*simple), scan.get()).ok);
  EXPECT_TRUE(test::SameScan(*scan, *simple));
  EXPECT_TRUE(scan->encoders.empty());
  EXPECT_TRUE(scan->channels8.empty());
  EXPECT_FALSE(scan->has_event);
}

TEST(ScanTelegramTest, EncoderRefusesWhatTheWireCannotCarry) {
  auto s = test::MakeFullScan(10);
  Bytes out(MaxEncodedSize(*s));
  EXPECT_EQ(EncodeScanTelegram(*s, std::span<std::uint8_t>(out).first(out.size() - 1)), 0u);
  EXPECT_EQ(EncodeScanTelegram(*s, out), out.size());
  s->channels8[0].raw[3] = 256;  // does not fit an 8-bit channel
  EXPECT_EQ(EncodeScanTelegram(*s, out), 0u);
  s = test::MakeFullScan(10);
  s->name.length = kMaxBlockTextBytes + 1;
  out.resize(MaxEncodedSize(*s));
  EXPECT_EQ(EncodeScanTelegram(*s, out), 0u);
}

TEST(ScanTelegramTest, OversizeTextBlockIsRejectedByTheDecoder) {
  auto s = test::MakeFullScan(4);
  s->has_comment = false;
  s->has_event = false;
  s->has_time = false;
  Bytes p = Encode(*s);
  // The name block is the last block before the three u16 flags and the name is 9 chars long: make
  // its length byte claim 65 (above kMaxBlockTextBytes) and supply the bytes.
  const std::size_t length_at = p.size() - 6 - 9 - 1;
  ASSERT_EQ(p[length_at], 9);
  p[length_at] = static_cast<std::uint8_t>(kMaxBlockTextBytes + 1);
  p.insert(p.begin() + static_cast<std::ptrdiff_t>(length_at + 1), kMaxBlockTextBytes + 1 - 9, 'x');
  auto scan = std::make_unique<ScanTelegram>();
  const DecodeResult r = Decode(p, scan.get());
  EXPECT_FALSE(r.ok);
  EXPECT_STREQ(r.reason, "device name longer than the fixed capacity");
  EXPECT_EQ(r.offset, length_at);
}

TEST(ToPolarScanTest, AnglesAreInTheSensorFrameAndRangesInMetres) {
  auto s = test::MakeSimpleScan(811, 77);  // TiM781S shape: start -45°, step 0.3333°
  s->channels16[0].scale_factor = 2.0f;
  s->layer_angle_raw = -250;
  auto polar = std::make_unique<PolarScan>();
  ASSERT_TRUE(ToPolarScan(*s, polar.get()));
  EXPECT_EQ(polar->count, 811);
  EXPECT_EQ(polar->telegram_counter, 77);
  EXPECT_EQ(polar->scan_counter, s->scan_counter);
  EXPECT_EQ(polar->time_since_startup_us, s->time_since_startup_us);
  EXPECT_EQ(polar->time_of_transmission_us, s->time_of_transmission_us);
  EXPECT_DOUBLE_EQ(polar->scan_frequency_hz, 15.0);
  EXPECT_DOUBLE_EQ(polar->layer_angle_deg, -2.5);
  EXPECT_NEAR(polar->first_angle_rad, common::DegToRad(-135.0), 1e-12);
  EXPECT_NEAR(polar->angle_step_rad, common::DegToRad(0.3333), 1e-12);
  // The middle beam of a 270° device looks straight ahead (0 rad).
  EXPECT_NEAR(polar->first_angle_rad + 405 * polar->angle_step_rad, 0.0, common::DegToRad(0.02));
  EXPECT_FLOAT_EQ(polar->range_m[10], static_cast<float>(s->channels16[0].raw[10] * 2.0 / 1000.0));
  ASSERT_TRUE(polar->has_intensity);
  EXPECT_FLOAT_EQ(polar->intensity[5], static_cast<float>(s->channels16[1].raw[5]));
}

TEST(ToPolarScanTest, MissingOrMismatchedChannels) {
  auto s = test::MakeSimpleScan(50, 1);
  auto polar = std::make_unique<PolarScan>();
  s->channels16[1].count = 49;  // RSSI1 does not line up with DIST1: intensity dropped, ranges kept
  ASSERT_TRUE(ToPolarScan(*s, polar.get()));
  EXPECT_FALSE(polar->has_intensity);
  EXPECT_EQ(polar->count, 50);
  s->channels16.pop_back();  // no RSSI at all (LMS111)
  ASSERT_TRUE(ToPolarScan(*s, polar.get()));
  EXPECT_FALSE(polar->has_intensity);
  std::memcpy(s->channels16[0].name.data(), "DIST2", 5);
  EXPECT_FALSE(ToPolarScan(*s, polar.get()));
}

TEST(ToPolarScanTest, RealTim781) {
  LRFNET_REQUIRE_SHARED_FILE(path, "data/sick/test.pcapng");
  const std::vector<Bytes> payloads = ScanPayloads(path);
  ASSERT_FALSE(payloads.empty());
  auto scan = std::make_unique<ScanTelegram>();
  ASSERT_TRUE(Decode(payloads.front(), scan.get()).ok);
  auto polar = std::make_unique<PolarScan>();
  ASSERT_TRUE(ToPolarScan(*scan, polar.get()));
  EXPECT_EQ(polar->count, 811);
  EXPECT_NEAR(polar->first_angle_rad, common::DegToRad(-135.0), 1e-12);
  EXPECT_TRUE(polar->has_intensity);
  // Golden file, first telegram (44977): first three ranges 0.626, 0.657, 0.616 m.
  EXPECT_EQ(polar->telegram_counter, 44977);
  EXPECT_NEAR(polar->range_m[0], 0.626, 1e-6);
  EXPECT_NEAR(polar->range_m[1], 0.657, 1e-6);
  EXPECT_NEAR(polar->range_m[2], 0.616, 1e-6);
}

}  // namespace
}  // namespace lrfnet::cola
