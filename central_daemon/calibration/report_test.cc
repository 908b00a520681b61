#include "central_daemon/calibration/report.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "central_daemon/calibration/png_test_reader.h"
#include "central_daemon/calibration/raster.h"

namespace lrfnet::calib {


namespace {

using Eigen::Vector2d;

std::string ReadText(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

std::vector<std::uint8_t> ReadBytes(const std::filesystem::path& path) {
  const std::string s = ReadText(path);
  return {s.begin(), s.end()};
}

std::size_t Count(const std::string& text, const std::string& needle) {
  std::size_t n = 0;
  for (auto pos = text.find(needle); pos != std::string::npos; pos = text.find(needle, pos + 1))
    ++n;
  return n;
}

// A small well-formedness check: every tag is closed in order, attribute values are quoted, text
// holds no raw '<', and every '&' starts an entity. Returns "" or what is wrong.
std::string XmlProblem(const std::string& xml) {
  std::vector<std::string> stack;
  std::size_t i = 0;
  bool root_seen = false;
  while (i < xml.size()) {
    if (xml[i] == '&') {
      const auto semi = xml.find(';', i);
      const std::string entity = xml.substr(i, semi == std::string::npos ? 8 : semi - i + 1);
      if (entity != "&amp;" && entity != "&lt;" && entity != "&gt;" && entity != "&quot;" &&
          entity != "&apos;")
        return "bad entity at " + std::to_string(i) + ": " + entity;
      i = semi + 1;
      continue;
    }
    if (xml[i] != '<') {
      ++i;
      continue;
    }
    if (xml.compare(i, 2, "<?") == 0) {
      const auto end = xml.find("?>", i);
      if (end == std::string::npos) return "unterminated <?";
      i = end + 2;
      continue;
    }
    const bool closing = xml.compare(i, 2, "</") == 0;
    std::size_t j = i + (closing ? 2 : 1);
    const std::size_t name_begin = j;
    while (j < xml.size() && (std::isalnum(static_cast<unsigned char>(xml[j])) || xml[j] == '-'))
      ++j;
    const std::string name = xml.substr(name_begin, j - name_begin);
    if (name.empty()) return "raw '<' in text at " + std::to_string(i);
    bool self_closing = false;
    while (j < xml.size() && xml[j] != '>') {
      if (xml[j] == '"') {
        const auto end = xml.find('"', j + 1);
        if (end == std::string::npos) return "unterminated attribute";
        const std::string value = xml.substr(j + 1, end - j - 1);
        if (value.find('<') != std::string::npos) return "'<' in attribute";
        j = end + 1;
        continue;
      }
      if (xml[j] == '/')
        self_closing = true;
      else if (xml[j] == '<' || xml[j] == '\'')
        return "unexpected character in tag " + name;
      ++j;
    }
    if (j >= xml.size()) return "unterminated tag " + name;
    if (closing) {
      if (stack.empty() || stack.back() != name) return "mismatched </" + name + ">";
      stack.pop_back();
    } else if (!self_closing) {
      if (stack.empty() && root_seen) return "second root element " + name;
      root_seen = true;
      stack.push_back(name);
    }
    i = j + 1;
  }
  if (!stack.empty()) return "unclosed <" + stack.back() + ">";
  return root_seen ? "" : "no root element";
}

struct Marker {
  double cx, cy;
};
std::vector<Marker> SensorMarkers(const std::string& svg) {
  std::vector<Marker> out;
  const std::regex re("<circle class=\"sensor\" cx=\"([-0-9.]+)\" cy=\"([-0-9.]+)\"");
  for (auto it = std::sregex_iterator(svg.begin(), svg.end(), re); it != std::sregex_iterator();
       ++it) {
    out.push_back({std::stod((*it)[1]), std::stod((*it)[2])});
  }
  return out;
}

SensorDescription Lms111() {
  SensorDescription d;
  d.model = "LMS111";
  d.first_angle_rad = common::DegToRad(-135);
  d.angle_step_rad = common::DegToRad(0.5);
  d.beam_count = 541;
  d.fov_rad = common::DegToRad(270);
  d.max_range_m = 20.0;
  return d;
}

// The background a sensor at `world_from_sensor` sees of a 20 x 12 m room.
BackgroundScan RoomScan(const Pose2& world_from_sensor) {
  BackgroundScan bg;
  bg.first_angle_rad = common::DegToRad(-135);
  bg.angle_step_rad = common::DegToRad(0.5);
  const Pose2 sensor_from_world = world_from_sensor.inverse();
  for (int i = 0; i < 541; ++i) {
    const double a = bg.first_angle_rad + bg.angle_step_rad * i;
    const Vector2d dir = world_from_sensor.rotation() * Vector2d(std::cos(a), std::sin(a));
    const Vector2d o = world_from_sensor.translation();
    double t = 1e9;
    // Walls x = 0, x = 20, y = 0, y = 12.
    if (dir.x() > 1e-9) t = std::min(t, (20 - o.x()) / dir.x());
    if (dir.x() < -1e-9) t = std::min(t, (0 - o.x()) / dir.x());
    if (dir.y() > 1e-9) t = std::min(t, (12 - o.y()) / dir.y());
    if (dir.y() < -1e-9) t = std::min(t, (0 - o.y()) / dir.y());
    bg.ranges_mm.push_back(t < 20 ? static_cast<std::uint32_t>(t * 1000) : 0);
  }
  (void)sensor_from_world;
  return bg;
}

class ReportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("lrfnet_report_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  // Three calibrated sensors in a room (one with a hostile id), one not connected; one person
  // walking a line seen by all; three pairs: used, rotation outlier, rejected.
  void MakeScene() {
    const std::vector<std::pair<std::string, Pose2>> poses = {
        {"s1", {1, 1, common::DegToRad(45)}},
        {"<s&1>", {19, 1, common::DegToRad(135)}},
        {"s3", {10, 11, common::DegToRad(-90)}},
        {"s4", {0, 0, 0}}};
    result_.method = "quenzel";
    result_.reference = "s1";
    tracks_.steps = 100;
    for (std::size_t i = 0; i < poses.size(); ++i) {
      SensorPose sp;
      sp.id = poses[i].first;
      sp.calibrated = i < 3;
      sp.world_from_sensor = sp.calibrated ? poses[i].second : Pose2{};
      sp.covariance = Eigen::Vector3d(1e-4, 1e-4, 1e-6).asDiagonal();
      result_.sensors.push_back(sp);

      SensorTracks st;
      st.id = sp.id;
      st.description = Lms111();
      st.background = RoomScan(poses[i].second);
      GridTrack track;
      track.track_id = 7;
      const Pose2 sensor_from_world = poses[i].second.inverse();
      for (int k = 0; k < 100; ++k) {
        TrackSample s;
        s.position_m = sensor_from_world * Vector2d(3 + 0.14 * k, 6 + std::sin(k * 0.1));
        track.samples.push_back(s);
      }
      st.tracks.push_back(track);
      tracks_.sensors.push_back(st);
    }
    EdgeReport used;
    used.r = "s1";
    used.s = "<s&1>";
    used.used = true;
    used.status = "used";
    used.matches = 512;
    used.rms_m = 0.021;
    EdgeReport outlier;
    outlier.r = "s1";
    outlier.s = "s3";
    outlier.status = "rotation outlier";
    outlier.matches = 40;
    outlier.rotation_residual_deg = 31.0;
    result_.edges = {used, outlier};
    result_.timings = {{"align", 0.01}, {"pairwise", 0.2}};
    result_.warnings = {"s4 | not connected"};

    PairEstimate p01;
    p01.r = 0;
    p01.s = 1;
    p01.accepted = true;
    p01.matches = 512;
    PairEstimate p02 = p01;
    p02.s = 2;
    PairEstimate p12;
    p12.r = 1;
    p12.s = 2;
    p12.accepted = false;
    p12.reason = "no hypothesis, too few matches";
    input_.pairs = {p01, p02, p12};
    input_.result = &result_;
    input_.tracks = &tracks_;

    truth_.sensors = {{"s1", {101, 1, common::DegToRad(45)}},
                      {"<s&1>", {119, 1.2, common::DegToRad(135)}},
                      {"s3", {110, 11, common::DegToRad(-90)}},
                      {"s4", {100, 0, 0}}};
    truth_.calibrated = {true, true, true, true};
    input_.truth = &truth_;
  }

  std::filesystem::path dir_;
  CalibrationResult result_;
  AlignedTracks tracks_;
  PoseFile truth_;
  ReportInput input_;
};

TEST_F(ReportTest, WritesEveryFileWellFormed) {
  MakeScene();
  std::string error;
  ASSERT_TRUE(WriteReport(dir_.string(), input_, &error)) << error;
  for (const char* name :
       {"calibration.svg", "calibration.png", "graph.svg", "graph.png", "edges.csv", "summary.md"})
    EXPECT_TRUE(std::filesystem::is_regular_file(dir_ / name)) << name;

  for (const char* name : {"calibration.svg", "graph.svg"}) {
    const std::string svg = ReadText(dir_ / name);
    EXPECT_EQ(XmlProblem(svg), "") << name;
    // The hostile id is escaped, never raw markup.
    EXPECT_EQ(svg.find("<s&1>"), std::string::npos) << name;
    EXPECT_NE(svg.find("&lt;s&amp;1&gt;"), std::string::npos) << name;
  }
}

TEST_F(ReportTest, WorldPictureShowsTheCalibratedSensorsInTheirColours) {
  MakeScene();
  std::string error;
  ASSERT_TRUE(WriteReport(dir_.string(), input_, &error)) << error;
  const std::string svg = ReadText(dir_ / "calibration.svg");
  const std::vector<Marker> markers = SensorMarkers(svg);
  ASSERT_EQ(markers.size(), 3u);                  // s4 is not calibrated: not drawn
  EXPECT_EQ(Count(svg, "class=\"ghost\""), 4u);   // truth of all four
  EXPECT_EQ(Count(svg, "<polyline"), 6u);  // one track and one 2-sigma ring per calibrated sensor
  EXPECT_EQ(Count(svg, "class=\"points\""), 3u);  // one background per calibrated sensor
  // Three FoV wedges, translucent.
  EXPECT_GE(Count(svg, "fill-opacity=\"0.133\""), 3u);
  EXPECT_NE(svg.find(" m</text>"), std::string::npos);  // scale bar label

  // The reference s1 sits at (1, 1) and s3 at (10, 11): s3 is right of and above s1 (y up).
  EXPECT_GT(markers[2].cx, markers[0].cx);
  EXPECT_LT(markers[2].cy, markers[0].cy);

  // The PNG draws the same scene: each marker's centre carries its sensor's colour.
  const auto png = testing::DecodePng(ReadBytes(dir_ / "calibration.png"));
  ASSERT_TRUE(png.ok) << png.error;
  const std::regex size_re("width=\"([0-9]+)\" height=\"([0-9]+)\"");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(svg, m, size_re));
  EXPECT_EQ(png.width, std::stoi(m[1]));
  EXPECT_EQ(png.height, std::stoi(m[2]));
  const Rgba expected[] = {{31, 119, 180}, {255, 127, 14}, {44, 160, 44}};
  for (std::size_t i = 0; i < 3; ++i) {
    const Rgba c = png.At(static_cast<int>(markers[i].cx), static_cast<int>(markers[i].cy));
    EXPECT_EQ(c, expected[i]) << "sensor " << i << " got " << int(c.r) << "," << int(c.g) << ","
                              << int(c.b);
  }
  // The uncalibrated sensor's colour (palette entry 3) appears nowhere.
  std::size_t reds = 0;
  for (int y = 0; y < png.height; ++y)
    for (int x = 0; x < png.width; ++x) reds += png.At(x, y) == Rgba{214, 39, 40} ? 1 : 0;
  EXPECT_EQ(reds, 0u);
}

TEST_F(ReportTest, GraphShowsUsedOutlierAndRejectedEdges) {
  MakeScene();
  std::string error;
  ASSERT_TRUE(WriteReport(dir_.string(), input_, &error)) << error;
  const std::string svg = ReadText(dir_ / "graph.svg");
  EXPECT_EQ(SensorMarkers(svg).size(), 3u);
  EXPECT_EQ(Count(svg, "class=\"ghost\""), 1u);  // s4, not calibrated, below the graph
  // Three edges with tooltips, one dashed (plus the dashed legend sample).
  EXPECT_EQ(Count(svg, "</title></line>"), 3u);
  EXPECT_EQ(Count(svg, "stroke-dasharray"), 2u);
  EXPECT_NE(svg.find("rejected (no hypothesis, too few matches)"), std::string::npos);
  EXPECT_NE(svg.find("s1 - s3: rotation outlier"), std::string::npos);
  EXPECT_NE(svg.find("stroke=\"#2ca02c\""), std::string::npos);  // used: green
  EXPECT_NE(svg.find("stroke=\"#ff7f0e\""), std::string::npos);  // outlier: orange
  EXPECT_NE(svg.find("n=512 rms=0.021"), std::string::npos);

  const auto png = testing::DecodePng(ReadBytes(dir_ / "graph.png"));
  ASSERT_TRUE(png.ok) << png.error;
  std::size_t green = 0;
  for (int y = 0; y < png.height; ++y)
    for (int x = 0; x < png.width; ++x) green += png.At(x, y) == Rgba{44, 160, 44} ? 1 : 0;
  EXPECT_GT(green, 100u);  // the used edge (and the third sensor, same palette colour)
}

TEST_F(ReportTest, EdgesCsvHasOneRowPerPair) {
  MakeScene();
  std::string error;
  ASSERT_TRUE(WriteReport(dir_.string(), input_, &error)) << error;
  const std::string csv = ReadText(dir_ / "edges.csv");
  std::vector<std::string> lines;
  std::istringstream in(csv);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  ASSERT_EQ(lines.size(), 4u) << csv;
  EXPECT_EQ(lines[0].rfind("r,s,status,reason,", 0), 0u);
  EXPECT_EQ(lines[1].rfind("s1,<s&1>,used,,1,1,", 0), 0u) << lines[1];
  EXPECT_EQ(lines[2].rfind("s1,s3,rotation outlier,rotation outlier,1,0,", 0), 0u) << lines[2];
  // The reason holds a comma: quoted.
  EXPECT_EQ(lines[3].rfind("<s&1>,s3,rejected,\"no hypothesis, too few matches\",0,0,", 0), 0u)
      << lines[3];
  const std::size_t columns = Count(lines[0], ",") + 1;
  EXPECT_EQ(columns, 19u);
  EXPECT_EQ(Count(lines[1], ",") + 1, columns);
}

TEST_F(ReportTest, SummaryHasPosesTruthErrorsEdgesAndTimings) {
  MakeScene();
  std::string error;
  ASSERT_TRUE(WriteReport(dir_.string(), input_, &error)) << error;
  const std::string md = ReadText(dir_ / "summary.md");
  EXPECT_NE(md.find("| s1 | 1.0000 | 1.0000 | 45.000 |"), std::string::npos) << md;
  EXPECT_NE(md.find("| &lt;s&amp;1&gt; | 19.0000 |"), std::string::npos) << md;
  EXPECT_NE(md.find("| s4 | not calibrated |"), std::string::npos) << md;
  // <s&1> is 0.2 m off in the truth (seen from s1's frame the offset is rotated, same length).
  EXPECT_NE(md.find("0.0000 | 0.2000 |"), std::string::npos) << md;
  EXPECT_NE(md.find("In the truth but not calibrated: s4."), std::string::npos) << md;
  EXPECT_NE(md.find("pairs: 3 (used 1, accepted but not used 1, rejected 1)"), std::string::npos);
  EXPECT_NE(md.find("| total | 0.2100 |"), std::string::npos) << md;
  EXPECT_NE(md.find("- s4 \\| not connected"), std::string::npos) << md;  // '|' escaped
  EXPECT_NE(md.find("Residuals over the 1 used edges"), std::string::npos) << md;
}

TEST_F(ReportTest, SummaryShowsEachSensorsRadialBiasWhereTheRefinementRan) {
  MakeScene();
  std::string error;
  ASSERT_TRUE(WriteReport(dir_.string(), input_, &error)) << error;
  EXPECT_EQ(ReadText(dir_ / "summary.md").find("radial bias"), std::string::npos);  // not run

  result_.sensors[0].radial_bias = RadialBiasEstimate{-0.0213, 0.0042, true};
  result_.sensors[1].radial_bias = RadialBiasEstimate{0.0, 0.02, false};
  ASSERT_TRUE(WriteReport(dir_.string(), input_, &error)) << error;
  const std::string md = ReadText(dir_ / "summary.md");
  EXPECT_NE(md.find("| sigma yaw [deg] | radial bias [m] | d_R [deg] |"), std::string::npos) << md;
  EXPECT_NE(md.find("| -0.0213 +- 0.0042 (estimated) | (reference) | |"), std::string::npos) << md;
  EXPECT_NE(md.find("| 0.0000 +- 0.0200 (prior) | 0.0000 | 0.2000 |"), std::string::npos) << md;
  EXPECT_NE(md.find("| s4 | not calibrated | | | | | | | | |"), std::string::npos) << md;
  // Every row of the table has as many cells as its header.
  const std::size_t header = md.find("| sensor | x [m]");
  ASSERT_NE(header, std::string::npos);
  const std::size_t table_end = md.find("\n\n", header);
  std::istringstream rows(md.substr(header, table_end - header));
  std::size_t cells = 0;
  for (std::string row; std::getline(rows, row);) {
    const std::size_t bars = Count(row, "|") - Count(row, "\\|");
    if (cells == 0) cells = bars;
    EXPECT_EQ(bars, cells) << row;
  }
}

TEST_F(ReportTest, RejectedPairsAreCountedAsRejectedWithTheirReasonOnce) {
  // The global step reports every pair, the rejected ones as "rejected: <reason>", not used.
  MakeScene();
  EdgeReport rejected;
  rejected.r = "<s&1>";
  rejected.s = "s3";
  rejected.status = "rejected: ambiguous: two hypotheses explain the tracks";
  input_.pairs[2].reason = "ambiguous: two hypotheses explain the tracks";
  result_.edges.push_back(rejected);
  std::string error;
  ASSERT_TRUE(WriteReport(dir_.string(), input_, &error)) << error;
  const std::string md = ReadText(dir_ / "summary.md");
  EXPECT_NE(md.find("pairs: 3 (used 1, accepted but not used 1, rejected 1)"), std::string::npos)
      << md;
  EXPECT_EQ(Count(md, "ambiguous: two hypotheses"), 1u) << md;
  // The tooltip says it once (the edge's label is a shortened copy).
  EXPECT_EQ(Count(ReadText(dir_ / "graph.svg"), "ambiguous: two hypotheses explain the tracks"), 1u);
}

TEST_F(ReportTest, FlagsAndTheUncertaintyEllipsesAreShown) {
  MakeScene();
  // s3 hangs on a weak pair: 1.5 m sigma along x, 0.3 m along y.
  result_.sensors[2].flag = "placed by a weak pair only (few matches)";
  result_.sensors[2].covariance = Eigen::Vector3d(2.25, 0.09, 1e-4).asDiagonal();
  result_.sensors[3].flag = "ambiguous: two placements explain the data equally";
  result_.ambiguity = "s4: two placements explain the data equally; walk where s1 and s4 see";
  result_.scale_note =
      "scale not observable: the people's size and the layout's scale explain the data alike";
  std::string error;
  ASSERT_TRUE(WriteReport(dir_.string(), input_, &error)) << error;
  const std::string md = ReadText(dir_ / "summary.md");
  EXPECT_NE(md.find("- sensors flagged: 2"), std::string::npos) << md;
  EXPECT_NE(md.find("  - s3: placed by a weak pair only (few matches)"), std::string::npos) << md;
  EXPECT_NE(md.find("| s3 (!) | 10.0000 |"), std::string::npos) << md;
  EXPECT_NE(md.find("| s4 (!) | not calibrated |"), std::string::npos) << md;
  EXPECT_NE(md.find("not decided by the data: s4: two placements"), std::string::npos) << md;
  EXPECT_NE(md.find("- scale not observable: the people"), std::string::npos) << md;

  // s3's ring: 2 sigma = 3 m along x and 0.6 m along y around (10, 11), in the flag colour.
  const std::string svg = ReadText(dir_ / "calibration.svg");
  EXPECT_NE(svg.find("s3 (!)"), std::string::npos);
  const std::regex ring_re("<polyline fill=\"none\" stroke=\"#c80000\"[^>]*points=\"([^\"]*)\"");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(svg, m, ring_re)) << svg;
  std::istringstream points(m[1].str());
  double min_x = 1e9, max_x = -1e9, min_y = 1e9, max_y = -1e9;
  for (std::string xy; points >> xy;) {
    const std::size_t comma = xy.find(',');
    const double x = std::stod(xy.substr(0, comma)), y = std::stod(xy.substr(comma + 1));
    min_x = std::min(min_x, x), max_x = std::max(max_x, x);
    min_y = std::min(min_y, y), max_y = std::max(max_y, y);
  }
  // Five times wider than high, as 3 m to 0.6 m.
  EXPECT_NEAR((max_x - min_x) / (max_y - min_y), 5.0, 0.3);
}

TEST_F(ReportTest, DegenerateCaseOneSensorNoTracks) {
  CalibrationResult result;
  result.method = "quenzel";
  result.reference = "only";
  SensorPose sp;
  sp.id = "only";
  sp.calibrated = true;
  result.sensors.push_back(sp);
  ReportInput input;
  input.result = &result;
  std::string error;
  ASSERT_TRUE(WriteReport(dir_.string(), input, &error)) << error;
  for (const char* name : {"calibration.png", "graph.png"}) {
    const auto png = testing::DecodePng(ReadBytes(dir_ / name));
    ASSERT_TRUE(png.ok) << name << ": " << png.error;
    EXPECT_GE(png.width, 100);
  }
  for (const char* name : {"calibration.svg", "graph.svg"}) {
    const std::string svg = ReadText(dir_ / name);
    EXPECT_EQ(XmlProblem(svg), "") << name;
    EXPECT_EQ(SensorMarkers(svg).size(), 1u) << name;
  }
  EXPECT_EQ(Count(ReadText(dir_ / "edges.csv"), "\n"), 1u);  // header only
  const std::string md = ReadText(dir_ / "summary.md");
  EXPECT_NE(md.find("| only | 0.0000 | 0.0000 | 0.000 |"), std::string::npos) << md;
  EXPECT_NE(md.find("(not measured)"), std::string::npos);

  // Nothing calibrated at all, and tracks whose samples are not finite.
  result.sensors[0].calibrated = false;
  AlignedTracks tracks;
  SensorTracks st;
  st.id = "only";
  GridTrack t;
  TrackSample s;
  s.position_m = Vector2d(std::nan(""), 1.0);
  t.samples = {s, s};
  st.tracks = {t};
  tracks.sensors = {st};
  input.tracks = &tracks;
  ASSERT_TRUE(WriteReport(dir_.string(), input, &error)) << error;
  EXPECT_EQ(XmlProblem(ReadText(dir_ / "calibration.svg")), "");
  EXPECT_TRUE(testing::DecodePng(ReadBytes(dir_ / "calibration.png")).ok);
}

TEST_F(ReportTest, AbsurdValuesStillGiveAReport) {
  CalibrationResult result;
  result.method = "quenzel";
  result.reference = "a";
  const double nan = std::nan("");
  const std::vector<Pose2> poses = {{0, 0, 0}, {1e300, -1e300, 1}, {1.7e308, 0, 0}, {nan, 0, 0}};
  for (std::size_t i = 0; i < poses.size(); ++i) {
    SensorPose sp;
    sp.id = std::string(1, static_cast<char>('a' + i));
    sp.calibrated = true;
    sp.world_from_sensor = poses[i];
    sp.covariance = Eigen::Matrix3d::Constant(nan);
    result.sensors.push_back(sp);
  }
  AlignedTracks tracks;
  SensorTracks st;
  st.id = "a";
  st.description = Lms111();
  st.description->max_range_m = 1e300;
  st.description->fov_rad = 1e9;
  st.background = RoomScan({0, 0, 0});
  st.background->ranges_mm.push_back(0xffffffffu);
  st.background->angle_step_rad = 1e-300;
  tracks.sensors = {st};
  ReportInput input;
  input.result = &result;
  input.tracks = &tracks;
  PairEstimate pair;
  pair.r = 0;
  pair.s = 99;  // not a sensor
  input.pairs = {pair};
  std::string error;
  ASSERT_TRUE(WriteReport(dir_.string(), input, &error)) << error;
  for (const char* name : {"calibration.svg", "graph.svg"})
    EXPECT_EQ(XmlProblem(ReadText(dir_ / name)), "") << name;
  for (const char* name : {"calibration.png", "graph.png"})
    EXPECT_TRUE(testing::DecodePng(ReadBytes(dir_ / name)).ok) << name;
  EXPECT_NE(ReadText(dir_ / "edges.csv").find("a,#99,rejected"), std::string::npos);
}

TEST_F(ReportTest, FailuresAreReported) {
  ReportInput input;
  std::string error;
  EXPECT_FALSE(WriteReport(dir_.string(), input, &error));
  EXPECT_EQ(error, "report: no calibration result");

  CalibrationResult result;
  input.result = &result;
  std::filesystem::create_directories(dir_);
  const std::string file = (dir_ / "a_file").string();
  std::ofstream(file) << "x";
  EXPECT_FALSE(WriteReport(file, input, &error));
  EXPECT_EQ(error.rfind(file + ": cannot create the report folder", 0), 0u) << error;
}

}  // namespace
}  // namespace lrfnet::calib
