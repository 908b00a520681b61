#include <gtest/gtest.h>

#include <limits>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "central_daemon/fusion/fusion.h"

namespace lrfnet::fusion {
namespace {

using nlohmann::json;

FusedTrack Track(std::uint64_t id, double x, double y, std::size_t sources = 2) {
  FusedTrack t;
  t.id = id;
  t.state = FusedState::kConfirmed;
  t.x_m = x;
  t.y_m = y;
  t.vx_mps = 0.5;
  t.vy_mps = -0.25;
  t.covariance = Eigen::Matrix4d::Identity() * 0.0123456789;
  t.covariance(0, 1) = t.covariance(1, 0) = -0.001;
  for (std::size_t s = 0; s < sources; ++s) {
    t.sources.push_back(
        FusedSource{"sensor_" + std::to_string(s), static_cast<std::uint32_t>(s + 1), 0});
  }
  return t;
}

TEST(FusedTracksJsonTest, ParsesBackWithTheDocumentedFields) {
  FusedTrack coasting = Track(9, -1.0, 2.0, 0);
  coasting.state = FusedState::kCoasting;
  const std::string text = FusedTracksJson({Track(7, 1.23456, -9.87654), coasting}, 1234567890123);
  EXPECT_EQ(text.find('\n'), std::string::npos);
  const json j = json::parse(text);
  EXPECT_EQ(j["type"], "fused");
  EXPECT_EQ(j["stamp_ns"].get<std::int64_t>(), 1234567890123);
  ASSERT_EQ(j["tracks"].size(), 2u);
  const json& t = j["tracks"][0];
  EXPECT_EQ(t["id"].get<std::uint64_t>(), 7u);
  EXPECT_EQ(t["state"], "confirmed");
  EXPECT_DOUBLE_EQ(t["x_m"].get<double>(), 1.235);  // millimetres
  EXPECT_DOUBLE_EQ(t["y_m"].get<double>(), -9.877);
  EXPECT_DOUBLE_EQ(t["vx_mps"].get<double>(), 0.5);
  EXPECT_DOUBLE_EQ(t["vy_mps"].get<double>(), -0.25);
  ASSERT_EQ(t["cov_xy"].size(), 3u);
  EXPECT_DOUBLE_EQ(t["cov_xy"][0].get<double>(), 0.012346);
  EXPECT_DOUBLE_EQ(t["cov_xy"][1].get<double>(), -0.001);
  ASSERT_EQ(t["sources"].size(), 2u);
  EXPECT_EQ(t["sources"][1]["sensor"], "sensor_1");
  EXPECT_EQ(t["sources"][1]["track"].get<std::uint32_t>(), 2u);
  EXPECT_EQ(j["tracks"][1]["state"], "coasting");
  EXPECT_TRUE(j["tracks"][1]["sources"].empty());
  EXPECT_EQ(json::parse(FusedTracksJson({}, 5))["tracks"].size(), 0u);
}

TEST(FusedTracksJsonTest, AnyInputGivesValidJson) {
  FusedTrack t = Track(std::numeric_limits<std::uint64_t>::max(), 0, 0);
  t.x_m = std::numeric_limits<double>::quiet_NaN();
  t.y_m = std::numeric_limits<double>::infinity();
  t.vx_mps = -std::numeric_limits<double>::infinity();
  t.vy_mps = 1e300;
  t.covariance(0, 0) = std::numeric_limits<double>::quiet_NaN();
  t.state = static_cast<FusedState>(200);
  t.sources = {FusedSource{"quote\" backslash\\ newline\n tab\t", 1, 0},
               FusedSource{std::string("bad utf8 \xff\xfe\xc3", 13), 2, 0},
               FusedSource{std::string("nul\0inside", 10), 3, 0}};
  const std::string text = FusedTracksJson({t}, std::numeric_limits<std::int64_t>::min());
  const json j = json::parse(text);  // throws on invalid JSON
  const json& jt = j["tracks"][0];
  EXPECT_TRUE(jt["x_m"].is_null());
  EXPECT_TRUE(jt["y_m"].is_null());
  EXPECT_TRUE(jt["vx_mps"].is_null());
  EXPECT_DOUBLE_EQ(jt["vy_mps"].get<double>(), 1e300);
  EXPECT_TRUE(jt["cov_xy"][0].is_null());
  EXPECT_EQ(jt["state"], "invalid");
  EXPECT_EQ(jt["sources"][0]["sensor"], "quote\" backslash\\ newline\n tab\t");
  EXPECT_EQ(jt["sources"][2]["sensor"].get<std::string>(), std::string("nul\0inside", 10));
  EXPECT_EQ(text.find('\n'), std::string::npos);
  for (const std::string& d : FusedTrackDatagrams({t}, 0, 1400)) {
    EXPECT_TRUE(json::accept(d)) << d;
  }
}

// Checks every datagram: at most max_bytes, valid, part/parts consistent; returns the ids in order.
std::vector<std::uint64_t> CheckDatagrams(const std::vector<std::string>& datagrams,
                                          std::size_t max_bytes, std::int64_t stamp_ns) {
  std::vector<std::uint64_t> ids;
  for (std::size_t i = 0; i < datagrams.size(); ++i) {
    EXPECT_LE(datagrams[i].size(), max_bytes);
    const json j = json::parse(datagrams[i]);
    EXPECT_EQ(j["type"], "fused");
    EXPECT_EQ(j["stamp_ns"].get<std::int64_t>(), stamp_ns);
    EXPECT_EQ(j["part"].get<std::size_t>(), i);
    EXPECT_EQ(j["parts"].get<std::size_t>(), datagrams.size());
    for (const json& t : j["tracks"]) ids.push_back(t["id"].get<std::uint64_t>());
  }
  return ids;
}

TEST(FusedTrackDatagramsTest, SplitOnTrackBoundariesWithinTheLimit) {
  std::vector<FusedTrack> tracks;
  std::vector<std::uint64_t> expected;
  for (std::uint64_t i = 0; i < 200; ++i) {
    tracks.push_back(Track(i + 1, 0.1 * static_cast<double>(i), -3.0, 1 + i % 4));
    expected.push_back(i + 1);
  }
  const auto datagrams = FusedTrackDatagrams(tracks, 99, 1400);
  EXPECT_GT(datagrams.size(), 10u);
  EXPECT_EQ(CheckDatagrams(datagrams, 1400, 99), expected);
  // Packed: every datagram but the last is more than two thirds full.
  for (std::size_t i = 0; i + 1 < datagrams.size(); ++i)
    EXPECT_GT(datagrams[i].size(), 1400u * 2 / 3);
}

TEST(FusedTrackDatagramsTest, RandomSizesAndLimits) {
  std::mt19937 rng(3);
  for (int round = 0; round < 200; ++round) {
    const std::size_t n = rng() % 40;
    // From a little more than a track without sources needs (below, tracks are left out).
    const std::size_t max_bytes = 300 + rng() % 2000;
    std::vector<FusedTrack> tracks;
    std::vector<std::uint64_t> expected;
    for (std::size_t i = 0; i < n; ++i) {
      tracks.push_back(
          Track(rng() % 1000000, static_cast<double>(rng() % 100000) * 0.001, -1.0, rng() % 4));
      expected.push_back(tracks.back().id);
    }
    const std::int64_t stamp = static_cast<std::int64_t>(rng()) * 1000000;
    const auto datagrams = FusedTrackDatagrams(tracks, stamp, max_bytes);
    ASSERT_FALSE(datagrams.empty());
    EXPECT_EQ(CheckDatagrams(datagrams, max_bytes, stamp), expected) << "max_bytes " << max_bytes;
  }
}

TEST(FusedTrackDatagramsTest, EmptyOversizedAndTinyLimits) {
  const auto empty = FusedTrackDatagrams({}, 1, 1400);
  ASSERT_EQ(empty.size(), 1u);
  EXPECT_TRUE(json::parse(empty[0])["tracks"].empty());
  EXPECT_EQ(json::parse(empty[0])["parts"], 1);

  // A track with many long-named sources does not fit alone: sent without them.
  FusedTrack big = Track(5, 1, 2, 0);
  for (int s = 0; s < 40; ++s) big.sources.push_back(FusedSource{std::string(40, 'x'), 1, 0});
  const auto parts = FusedTrackDatagrams({Track(1, 0, 0), big, Track(2, 0, 0)}, 1, 600);
  EXPECT_EQ(CheckDatagrams(parts, 600, 1), (std::vector<std::uint64_t>{1, 5, 2}));
  bool truncated = false;
  for (const auto& d : parts) {
    const json j = json::parse(d);
    for (const json& t : j["tracks"]) {
      if (t["id"] == 5) {
        truncated = t.value("sources_truncated", false);
        EXPECT_TRUE(t["sources"].empty());
      }
    }
  }
  EXPECT_TRUE(truncated);

  EXPECT_TRUE(FusedTrackDatagrams({Track(1, 0, 0)}, 1, 20).empty());
  EXPECT_TRUE(FusedTrackDatagrams({}, 1, 0).empty());
  // Room for the header only: the tracks are left out, the datagram stays valid.
  const auto header_only = FusedTrackDatagrams({Track(1, 0, 0)}, 1, 70);
  EXPECT_EQ(CheckDatagrams(header_only, 70, 1).size(), 0u);
}

}  // namespace
}  // namespace lrfnet::fusion
