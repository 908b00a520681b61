#include "tools/scan_source.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "tests/support/test_data.h"

namespace lrfnet::tools {
namespace {

struct Geometry {
  const char* model;
  std::uint16_t points;
  std::int32_t start_raw;
  std::uint16_t step_raw;
  std::uint8_t rssi_bits;
  std::uint32_t measurement_frequency_raw;  // as the real devices send it
  const char* guessed;
};

class SyntheticSourceTest : public ::testing::TestWithParam<Geometry> {};

TEST_P(SyntheticSourceTest, ScansHaveTheModelsLayoutAndSurviveEncoding) {
  const Geometry g = GetParam();
  SyntheticScanOptions options;
  options.model = g.model;
  ASSERT_FALSE(Validate(options).has_value());
  std::unique_ptr<ScanSource> source = MakeSyntheticScanSource(options);
  ASSERT_NE(source, nullptr);
  auto scan = std::make_unique<cola::ScanTelegram>();
  auto decoded = std::make_unique<cola::ScanTelegram>();
  std::vector<std::uint8_t> payload;
  std::uint32_t last_tick = 0;
  for (int k = 0; k < 3; ++k) {
    common::DurationNs gap = -1;
    ASSERT_TRUE(source->Next(scan.get(), &gap));
    EXPECT_EQ(gap, k == 0 ? 0 : source->nominal_period_ns());
    EXPECT_EQ(scan->telegram_counter, k + 1);
    if (k > 0) {
      EXPECT_GT(scan->time_since_startup_us, last_tick);
    }
    last_tick = scan->time_since_startup_us;

    payload.resize(cola::MaxEncodedSize(*scan));
    payload.resize(cola::EncodeScanTelegram(*scan, payload));
    ASSERT_FALSE(payload.empty());
    ASSERT_TRUE(cola::DecodeScanTelegram(payload, decoded.get()).ok);
    const cola::ScanChannel* dist = decoded->FindChannel("DIST1");
    ASSERT_NE(dist, nullptr);
    EXPECT_EQ(dist->count, g.points);
    EXPECT_EQ(dist->start_angle_raw, g.start_raw);
    EXPECT_EQ(dist->angle_step_raw, g.step_raw);
    EXPECT_EQ(decoded->measurement_frequency_raw, g.measurement_frequency_raw);
    const DeviceIdentity& id = source->identity();
    EXPECT_EQ(id.geometry.count, g.points);
    EXPECT_EQ(id.geometry.start_angle_raw, g.start_raw);
    EXPECT_EQ(id.geometry.angle_step_raw, g.step_raw);
    EXPECT_EQ(id.geometry.scan_frequency_raw, decoded->scan_frequency_raw);
    const cola::ScanChannel* rssi = decoded->FindChannel("RSSI1");
    if (g.rssi_bits == 0) {
      EXPECT_EQ(rssi, nullptr);
    } else {
      ASSERT_NE(rssi, nullptr);
      EXPECT_EQ(rssi->bits, g.rssi_bits);
    }
    // The forward beam sees the room's far wall (9.5 m) or the blob in front of it.
    int echoes = 0;
    for (std::size_t i = 0; i < dist->count; ++i) echoes += dist->raw[i] != 0 ? 1 : 0;
    EXPECT_GT(echoes, dist->count / 2);
  }
  EXPECT_EQ(GuessModelName(*scan), g.guessed);
}

INSTANTIATE_TEST_SUITE_P(
    Models, SyntheticSourceTest,
    ::testing::Values(Geometry{"lms511", 1141, -50000, 1667, 8, 540, "LMS5xx"},
                      Geometry{"lms111", 541, -450000, 5000, 0, 360, "LMS1xx"},
                      Geometry{"tim561", 811, -450000, 3333, 16, 162, "TiM7xx"},
                      Geometry{"tim781", 811, -450000, 3333, 16, 162, "TiM7xx"},
                      Geometry{"tim781s", 811, -450000, 3333, 16, 162, "TiM7xx"},
                      Geometry{"mrs1104", 1101, -475000, 2500, 8, 180, "MRS1xxx"}));

TEST(SyntheticSource, TheBlobMovesAndTheSeedFixesTheNoise) {
  SyntheticScanOptions options;
  auto a = MakeSyntheticScanSource(options);
  auto b = MakeSyntheticScanSource(options);
  options.seed = 2;
  auto c = MakeSyntheticScanSource(options);
  auto sa = std::make_unique<cola::ScanTelegram>();
  auto sb = std::make_unique<cola::ScanTelegram>();
  auto sc = std::make_unique<cola::ScanTelegram>();
  common::DurationNs gap = 0;
  ASSERT_TRUE(a->Next(sa.get(), &gap) && b->Next(sb.get(), &gap) && c->Next(sc.get(), &gap));
  const auto& da = sa->channels16[0];
  const auto& db = sb->channels16[0];
  const auto& dc = sc->channels16[0];
  EXPECT_TRUE(std::equal(da.raw.begin(), da.raw.begin() + da.count, db.raw.begin()));
  EXPECT_FALSE(std::equal(da.raw.begin(), da.raw.begin() + da.count, dc.raw.begin()));

  // 2.5 s later (a quarter lap) the blob occludes other beams: many ranges change by more than
  // noise.
  std::vector<std::uint16_t> first(da.raw.begin(), da.raw.begin() + da.count);
  for (int k = 0; k < 63; ++k) ASSERT_TRUE(a->Next(sa.get(), &gap));
  int moved = 0;
  for (std::size_t i = 0; i < first.size(); ++i) {
    moved += std::abs(int{sa->channels16[0].raw[i]} - int{first[i]}) > 100 ? 1 : 0;
  }
  EXPECT_GT(moved, 10);
}

TEST(SyntheticSource, UnknownModelIsRejectedWithTheKnownOnes) {
  SyntheticScanOptions options;
  options.model = "lms999";
  const auto error = Validate(options);
  ASSERT_TRUE(error.has_value());
  EXPECT_NE(error->find("lms511"), std::string::npos);
  EXPECT_EQ(MakeSyntheticScanSource(options), nullptr);
}

TEST(CaptureScanSource, ServesEveryScanWithTheRecordedSpacingAndIdentity) {
  LRFNET_REQUIRE_SHARED_FILE(path, "data/sick/mrs1104_20210722.pcap");
  std::string error;
  std::unique_ptr<ScanSource> source = OpenCaptureScanSource(path, {}, &error);
  ASSERT_NE(source, nullptr) << error;
  // The MRS capture carries sRA DeviceIdent "MRS1xxxx" "1.0.0.0R" and a SerialNumber reply.
  EXPECT_EQ(source->identity().name, "MRS1xxxx");
  EXPECT_EQ(source->identity().version, "1.0.0.0R");
  EXPECT_FALSE(source->identity().serial_number.empty());
  auto scan = std::make_unique<cola::ScanTelegram>();
  common::DurationNs gap = 0;
  int n = 0;
  common::DurationNs total_ns = 0;
  while (source->Next(scan.get(), &gap)) {
    ++n;
    total_ns += gap;
  }
  EXPECT_EQ(n, 96);
  // 96 telegrams at 50 Hz: about 1.9 s of recording.
  EXPECT_GT(total_ns, common::SecondsToNs(1.5));
  EXPECT_LT(total_ns, common::SecondsToNs(2.5));
  source->Rewind();
  EXPECT_TRUE(source->Next(scan.get(), &gap));
  EXPECT_EQ(gap, 0);
}

TEST(CaptureScanSource, MissingFileIsAnError) {
  std::string error;
  EXPECT_EQ(OpenCaptureScanSource("does/not/exist.pcap", {}, &error), nullptr);
  EXPECT_NE(error.find("does/not/exist.pcap"), std::string::npos) << error;
}

}  // namespace
}  // namespace lrfnet::tools
