// The parts of lrfnet-tracker's runs that need no process: the scan lines and the stop rule, the
// summary's parts and the outputs.

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "firmware_tracker/app/node_test_util.h"
#include "firmware_tracker/app/outputs.h"
#include "firmware_tracker/app/run_report.h"
#include "firmware_tracker/app/tracker_node.h"

namespace lrfnet::tracker {
namespace {

namespace fs = std::filesystem;
using testing::SyntheticDevice;
using testing::Wall;

TrackerConfig RunConfig() {
  TrackerConfig config;
  config.sensor_id = "run.s1";
  return config;
}

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::size_t start = 0;
  for (std::size_t end; (end = text.find('\n', start)) != std::string::npos; start = end + 1) {
    lines.push_back(text.substr(start, end - start));
  }
  return lines;
}

TEST(TrackerRun, FormatUtcIsMicrosecondsInUtc) {
  EXPECT_EQ(FormatUtc(0), "1970-01-01T00:00:00.000000Z");
  EXPECT_EQ(FormatUtc(1'609'502'403'123'456'789), "2021-01-01T12:00:03.123456Z");
  // Before 1970 the fraction still counts forward from the whole second below.
  EXPECT_EQ(FormatUtc(-1), "1969-12-31T23:59:59.999999Z");
  EXPECT_EQ(FormatUtc(-1'500'000'000), "1969-12-31T23:59:58.500000Z");
}

TEST(TrackerRun, DecoderSummaryNamesEveryCounter) {
  cola::StreamCounters c;
  c.framer.frames = 7;
  c.framer.bad_checksum = 1;
  c.framer.oversize_length = 2;
  c.framer.garbage_bytes = 3;
  c.other_telegrams = 4;
  c.bad_headers = 5;
  c.scan_decode_errors = 6;
  EXPECT_EQ(DecoderSummary(c),
            "frames=7 bad_checksums=1 oversize_lengths=2 garbage_bytes=3 other_telegrams=4 "
            "bad_headers=5 scan_decode_errors=6");
}

TEST(TrackerRun, PipelineSummaryNamesEveryCounter) {
  tracking::PipelineCounters c;
  c.scans = 99;  // the summary's own scans= says it
  c.rejected_scans = 1;
  c.learning_scans = 2;
  c.segments = 3;
  c.dropped_segments = 4;
  c.ellipse_measurements = 5;
  c.com_measurements = 6;
  c.shape_fits = 7;
  c.failed_shape_fits = 8;
  c.leg_pairs = 9;
  c.single_legs = 10;
  c.legs_behind = 11;
  c.veiled_segments = 12;
  c.shadowed_legs = 13;
  c.absorbed_objects = 14;
  c.seen_through = 15;
  c.unseen_coasting = 16;
  c.single_beam_legs = 17;
  c.legs_across_walk = 18;
  c.split_few_point_legs = 19;
  c.legs_seen_through = 20;
  c.deep_pieces_kept = 21;
  c.outline_departure_widened = 22;
  c.legs_side_uncertain = 23;
  c.legs_side_from_view = 24;
  c.legs_side_view_contested = 25;
  c.deep_leg_pairs = 26;
  c.recently_veiled = 27;
  c.leg_edges_in_mixed_beam = 28;
  c.stance_weighted_pairs = 29;
  c.touching_leg_pairs = 30;
  c.box_occluded_fits = 31;
  c.box_sizes_unseen = 32;
  c.legs_along_from_standing = 33;
  c.single_beam_partners = 34;
  c.edge_echo_births = 35;
  c.person_sizes_across_ray = 36;
  c.partial_view_widened = 37;
  c.underdetermined_fit_widened = 38;
  c.box_pieces_rejoined = 39;
  c.legs_coasting_uncertain = 40;
  c.coasting_uncertain = 41;
  c.box_unseen_widened = 42;
  c.neighbour_widened = 43;
  c.lone_beam_edge_echoes = 44;
  c.far_leg_births = 45;
  c.see_through_splits = 46;
  c.torso_edge_echoes = 47;
  c.step_seam_splits = 48;
  c.mixed_pixel_legs = 49;
  c.segment_excess_widened = 50;
  c.box_view_widened = 51;
  c.still_leg_pairs = 52;
  c.occluded_gap_widened = 53;
  c.deep_tail_cuts = 54;
  EXPECT_EQ(PipelineSummary(c),
            "rejected_scans=1 learning_scans=2 segments=3 dropped_segments=4 "
            "ellipse_measurements=5 com_measurements=6 shape_fits=7 failed_shape_fits=8 "
            "leg_pairs=9 single_legs=10 legs_behind=11 veiled_segments=12 shadowed_legs=13 "
            "absorbed_objects=14 seen_through=15 unseen_coasting=16 single_beam_legs=17 "
            "legs_across_walk=18 split_few_point_legs=19 legs_seen_through=20 "
            "deep_pieces_kept=21 outline_departure_widened=22 legs_side_uncertain=23 "
            "legs_side_from_view=24 legs_side_view_contested=25 deep_leg_pairs=26 "
            "recently_veiled=27 leg_edges_in_mixed_beam=28 stance_weighted_pairs=29 "
            "touching_leg_pairs=30 box_occluded_fits=31 box_sizes_unseen=32 "
            "legs_along_from_standing=33 single_beam_partners=34 edge_echo_births=35 "
            "person_sizes_across_ray=36 partial_view_widened=37 "
            "underdetermined_fit_widened=38 box_pieces_rejoined=39 legs_coasting_uncertain=40 "
            "coasting_uncertain=41 box_unseen_widened=42 neighbour_widened=43 "
            "lone_beam_edge_echoes=44 far_leg_births=45 see_through_splits=46 torso_edge_echoes=47 "
            "step_seam_splits=48 mixed_pixel_legs=49 segment_excess_widened=50 "
            "box_view_widened=51 still_leg_pairs=52 occluded_gap_widened=53 deep_tail_cuts=54");
}

TEST(TrackerRun, MultiTrackerSummaryNamesEveryCounterButTheTwoBeforeIt) {
  tracking::MultiTrackerCounters c;
  c.scans = 99;      // the summary's scans=
  c.created = 98;    // tracks_created=
  c.confirmed = 97;  // tracks_confirmed=
  c.measurements = 1;
  c.associations = 2;
  c.deleted_tentative = 3;
  c.deleted_coast_timeout = 4;
  c.deleted_covariance = 5;
  c.deleted_time_reset = 6;
  c.deleted_static = 7;
  c.dropped_capacity = 8;
  c.births_suppressed = 9;
  c.rejected_measurements = 10;
  c.measurements_over_capacity = 11;
  c.failed_updates = 12;
  c.time_steps_backwards = 13;
  c.time_resets = 14;
  c.refine_failures = 15;
  c.speed_clamps = 16;
  c.recovered = 17;
  c.resumed = 18;
  c.coasting_unreported = 19;
  c.adopted = 20;
  EXPECT_EQ(MultiTrackerSummary(c),
            "measurements=1 associations=2 deleted_tentative=3 deleted_coast_timeout=4 "
            "deleted_covariance=5 deleted_time_reset=6 deleted_static=7 dropped_capacity=8 "
            "births_suppressed=9 rejected_measurements=10 measurements_over_capacity=11 "
            "failed_updates=12 time_steps_backwards=13 time_resets=14 refine_failures=15 "
            "speed_clamps=16 recovered=17 resumed=18 coasting_unreported=19 adopted=20");
}

TEST(TrackerRun, NodeSummaryEndsWithThePipelinesCounters) {
  // Two seconds of a room: the node's summary carries the pipeline's counters as they are.
  testing::CollectingSink sink;
  TrackerNode node(RunConfig(), 1, sink);
  SyntheticDevice device;
  const std::vector<Wall> walls = testing::Room();
  for (std::int64_t k = 0; k < 60; ++k) {
    common::UtcNs rx = 0;
    const cola::ScanTelegram& scan = device.Scan(k, walls, {}, &rx);
    node.OnScan(scan, rx, rx);
  }
  const tracking::PipelineCounters& c = node.pipeline().counters();
  EXPECT_GT(c.learning_scans, 0u);
  const std::string summary = NodeSummary(node);
  const std::string pipeline =
      PipelineSummary(c) + " " + MultiTrackerSummary(node.pipeline().tracker().counters());
  ASSERT_GE(summary.size(), pipeline.size());
  EXPECT_EQ(summary.substr(summary.size() - pipeline.size()), pipeline) << summary;
  EXPECT_NE(summary.find(" veiled_segments=0 shadowed_legs=0 "), std::string::npos) << summary;
  EXPECT_NE(summary.find(" learning_scans=" + std::to_string(c.learning_scans) + " "),
            std::string::npos)
      << summary;
}

TEST(TrackerRun, ScanLogPrintsEveryNthScanAndStopsAtMaxScans) {
  testing::CollectingSink sink;
  TrackerNode node(RunConfig(), 1, sink);
  SyntheticDevice device;
  const std::vector<Wall> walls = testing::Room();
  ScanLog log(/*print_every=*/2, /*max_scans=*/3);
  std::vector<bool> go_on;
  std::vector<common::UtcNs> receive_ns;
  ::testing::internal::CaptureStdout();
  for (std::int64_t k = 0; k < 3; ++k) {
    common::UtcNs rx = 0;
    const cola::ScanTelegram& scan = device.Scan(k, walls, {}, &rx);
    node.OnScan(scan, rx, rx);
    go_on.push_back(log.OnScan("run.s1", scan, rx, node));
    receive_ns.push_back(rx);
  }
  const std::vector<std::string> lines = Lines(::testing::internal::GetCapturedStdout());
  EXPECT_EQ(go_on, (std::vector<bool>{true, true, false}));
  EXPECT_EQ(log.scans(), 3u);
  ASSERT_EQ(lines.size(), 2u);  // scans 1 and 3
  const std::string points = std::to_string(device.scanner().config().beams);
  EXPECT_EQ(lines[0].rfind("run.s1 tc=1 sc=1 points=" + points + " rx=" + FormatUtc(receive_ns[0]) +
                               " scan_start=",
                           0),
            0u)
      << lines[0];
  EXPECT_EQ(
      lines[1].rfind("run.s1 tc=3 sc=3 points=" + points + " rx=" + FormatUtc(receive_ns[2]), 0),
      0u)
      << lines[1];
  EXPECT_NE(lines[1].find(" tracks=0 []"), std::string::npos) << lines[1];

  ScanLog endless(0, 0);  // neither printing nor stopping
  common::UtcNs rx = 0;
  ::testing::internal::CaptureStdout();
  for (std::int64_t k = 3; k < 6; ++k) {
    EXPECT_TRUE(endless.OnScan("run.s1", device.Scan(k, walls, {}, &rx), rx, node));
  }
  EXPECT_EQ(::testing::internal::GetCapturedStdout(), "");
}

class TrackerOutputs : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("lrfnet_tracker_run_test_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(TrackerOutputs, RecordingCountsEveryDatagramOfTheNode) {
  Outputs outputs;
  const std::string path = (dir_ / "s1.lrfrec").string();
  ASSERT_EQ(outputs.Open(RunConfig(), path, 1'700'000'000'000'000'000), std::nullopt);
  TrackerNode node(RunConfig(), 7, outputs.sink());
  SyntheticDevice device;
  const std::vector<Wall> walls = testing::Room();
  for (std::int64_t k = 0; k < 30; ++k) {
    common::UtcNs rx = 0;
    node.OnScan(device.Scan(k, walls, {}, &rx), rx, rx);
    node.OnTick(rx, LinkHealth{}, io::ClockStatus{});
  }
  ASSERT_TRUE(outputs.Close());
  const std::uint64_t datagrams = node.encoder().counters().datagrams;
  ASSERT_GT(datagrams, 0u);
  EXPECT_EQ(outputs.send_errors(), 0u);
  const std::string summary = outputs.Summary();
  EXPECT_EQ(summary.rfind(" recorded=" + std::to_string(datagrams) + " recording_bytes=", 0), 0u)
      << summary;
  EXPECT_NE(summary.find(" write_errors=0"), std::string::npos) << summary;
  EXPECT_EQ(summary.find("udp_sent"), std::string::npos) << summary;
  EXPECT_GT(fs::file_size(path), node.encoder().counters().bytes);
}

TEST_F(TrackerOutputs, NoOutputsCountOnly) {
  Outputs outputs;
  ASSERT_EQ(outputs.Open(RunConfig(), "", 0), std::nullopt);
  EXPECT_EQ(outputs.Summary(), "");
  EXPECT_TRUE(outputs.Close());
}

TEST_F(TrackerOutputs, ErrorsNameTheFlag) {
  const std::string missing_dir = (dir_ / "no_such_dir" / "s1.lrfrec").string();
  Outputs out;
  const auto e = out.Open(RunConfig(), missing_dir, 0);
  ASSERT_TRUE(e.has_value());
  EXPECT_EQ(e->rfind("--out " + missing_dir + ": ", 0), 0u) << *e;

  TrackerConfig config = RunConfig();
  config.uplink_address = "127.0.0.1";  // no port
  Outputs uplink;
  const auto u = uplink.Open(config, "", 0);
  ASSERT_TRUE(u.has_value());
  EXPECT_NE(u->find("--uplink"), std::string::npos) << *u;

  config = RunConfig();
  config.key_file = (dir_ / "no_such.key").string();
  Outputs keyed;
  const auto k = keyed.Open(config, "", 0);
  ASSERT_TRUE(k.has_value());
  EXPECT_EQ(k->rfind("--key ", 0), 0u) << *k;
}

}  // namespace
}  // namespace lrfnet::tracker
