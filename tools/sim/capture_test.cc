// Simulated captures read back through the same path as real ones: CaptureStream (libpcap, packet
// parser, TCP reassembly), cola::StreamDecoder, and `lrfnet dump`.

#include <gtest/gtest.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "common/capture/capture_stream.h"
#include "common/time.h"
#include "firmware_tracker/cola/commands.h"
#include "firmware_tracker/cola/stream_decoder.h"
#include "tools/dump.h"
#include "tools/sim/sim_output.h"
#include "tools/sim/simulator.h"

namespace lrfnet::sim {
namespace {

namespace fs = std::filesystem;

// A two-room world, an LMS111 (one TCP segment per scan), an LMS511 (three segments, 8-bit RSSI)
// and a TiM781 whose µs tick wraps during the run, a walking person and a standing cylinder.
const char* const kScenario = R"(name: capture_test
seed: 17
duration_s: 2.0
world:
  walls: [[[0, 0], [20, 0], [20, 10], [0, 10], [0, 0]], [[10, 0], [10, 4]]]
  obstacles: [[[4, 4], [6, 4], [6, 6], [4, 6]]]
sensors:
  - {id: lms, model: lms111, x_m: 0.5, y_m: 0.5, yaw_deg: 45}
  - {id: big, model: lms511, x_m: 19.5, y_m: 0.5, yaw_deg: 135,
     clock: {offset_s: 100, drift_ppm: -20}}
  - {id: tim, model: tim781, x_m: 19.5, y_m: 9.5, yaw_deg: -135,
     clock: {offset_s: 4294.5, drift_ppm: 15}, network: {latency_ms: 1.5, jitter_ms: 2}}
targets:
  - {id: walker, shape: person, path: [[2, 2], [18, 8], [2, 8]], speed_mps: 1.2, loop: true}
  - {id: post, shape: cylinder, radius_m: 0.3, path: [[14, 5]]}
)";

class TempDir {
 public:
  TempDir() {
    path_ = fs::temp_directory_path() /
            ("lrfnet_sim_test_" + std::to_string(::getpid()) + "_" + std::to_string(counter_++));
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  std::string operator/(const std::string& name) const { return (path_ / name).string(); }
  std::string str() const { return path_.string(); }

 private:
  static inline int counter_ = 0;
  fs::path path_;
};

std::unique_ptr<Simulator> MakeSim(const std::string& text = kScenario) {
  Scenario s;
  std::string error;
  EXPECT_TRUE(ParseScenario(text, "capture_test.yaml", &s, &error)) << error;
  auto sim = Simulator::Create(s, &error);
  EXPECT_NE(sim, nullptr) << error;
  return sim;
}

std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

struct Decoded {
  std::vector<std::unique_ptr<cola::ScanTelegram>> scans;
  std::vector<common::UtcNs> receive_ns;
  std::vector<std::string> replies;  // "<type> <name>"
  std::map<std::string, std::string>
      text_replies;  // DeviceIdent name, FirmwareVersion, SerialNumber
  capture::CaptureCounters capture;
  cola::StreamCounters stream;
};

class Collector : public cola::TelegramListener {
 public:
  explicit Collector(Decoded* out) : out_(out) {}
  void OnScan(const cola::ScanTelegram& scan, common::UtcNs t) override {
    out_->scans.push_back(std::make_unique<cola::ScanTelegram>(scan));
    out_->receive_ns.push_back(t);
  }
  void OnTelegram(const cola::TelegramHeader& h, std::span<const std::uint8_t>,
                  common::UtcNs) override {
    out_->replies.push_back(std::string(cola::CommandTypeName(h.type)) + " " + std::string(h.name));
    if (h.name == "DeviceIdent") {
      cola::DeviceIdent id;
      if (cola::DecodeDeviceIdent(h.args, &id))
        out_->text_replies["DeviceIdent"] = std::string(id.name);
    }
    cola::FlexString text;
    if ((h.name == "FirmwareVersion" || h.name == "SerialNumber") &&
        cola::DecodeFlexString(h.args, &text)) {
      out_->text_replies[std::string(h.name)] = std::string(text.text);
    }
  }

 private:
  Decoded* out_;
};

Decoded Decode(const std::string& path, bool from_sensor = true) {
  Decoded d;
  capture::CaptureStreamOptions options;
  options.from_sensor = from_sensor;
  std::string error;
  auto capture = capture::CaptureStream::Open(path, options, &error);
  EXPECT_NE(capture, nullptr) << error;
  if (!capture) return d;
  auto decoder = std::make_unique<cola::StreamDecoder>();
  Collector collector(&d);
  capture::StreamChunk chunk;
  while (capture->Next(&chunk)) {
    if (chunk.discontinuity) decoder->Reset();
    decoder->Feed(chunk.bytes, chunk.receive_time_ns, collector);
  }
  EXPECT_EQ(capture->error(), "");
  d.capture = capture->counters();
  d.stream = decoder->counters();
  return d;
}

class SimulatedCaptures : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    sim_ = MakeSim().release();
    std::string error;
    ASSERT_TRUE(WriteSimulation(*sim_, dir_->str(), {}, &summary_, &error)) << error;
  }
  static void TearDownTestSuite() {
    delete sim_;
    delete dir_;
  }
  static inline TempDir* dir_ = nullptr;
  static inline Simulator* sim_ = nullptr;
  static inline std::vector<CaptureSummary> summary_;
};

TEST_F(SimulatedCaptures, CaptureStreamReadsEveryScanInOrderWithTheDevicesGeometry) {
  const std::int64_t start_ns = sim_->scenario().start_utc_ns;
  for (std::size_t i = 0; i < sim_->sensor_count(); ++i) {
    const SensorSetup& sensor = sim_->sensor(i);
    SCOPED_TRACE(sensor.id);
    const Decoded d = Decode(*dir_ / (sensor.id + ".pcap"));
    ASSERT_EQ(d.scans.size(), sensor.scan_count);
    EXPECT_EQ(summary_[i].scans, sensor.scan_count);
    // A clean session: nothing malformed, retransmitted, missing or rejected.
    EXPECT_EQ(d.capture.malformed_packets, 0u);
    EXPECT_EQ(d.capture.retransmitted_bytes, 0u);
    EXPECT_EQ(d.capture.gaps, 0u);
    EXPECT_EQ(d.capture.connections, 1u);
    EXPECT_EQ(d.stream.framer.bad_checksum, 0u);
    EXPECT_EQ(d.stream.scan_decode_errors, 0u);
    // The start-up dialogue's answers come first.
    const std::vector<std::string> expected_replies = {
        "sAN SetAccessMode", "sRA DeviceIdent", "sRA FirmwareVersion", "sRA SerialNumber",
        "sAN LMCstartmeas",  "sAN Run",         "sEA LMDscandata"};
    EXPECT_EQ(d.replies, expected_replies);
    EXPECT_EQ(d.text_replies.at("DeviceIdent"), std::string(sensor.device.model->ident_name));
    EXPECT_EQ(std::stoul(d.text_replies.at("SerialNumber")), sensor.serial_number);

    common::TickUnwrapper unwrap;
    std::int64_t first_tick = 0;
    for (std::size_t k = 0; k < d.scans.size(); ++k) {
      const cola::ScanTelegram& scan = *d.scans[k];
      const cola::ScanChannel* dist = scan.FindChannel("DIST1");
      ASSERT_NE(dist, nullptr);
      EXPECT_EQ(dist->count, sensor.device.count);
      EXPECT_EQ(dist->start_angle_raw, sensor.device.start_angle_raw);
      EXPECT_EQ(dist->angle_step_raw, sensor.device.step_raw);
      EXPECT_EQ(scan.scan_frequency_raw, sensor.device.frequency_raw);
      EXPECT_EQ(scan.serial_number, sensor.serial_number);
      EXPECT_EQ(scan.telegram_counter,
                static_cast<std::uint16_t>(sensor.first_telegram_counter + k));
      // Receive times increase and come after the device sent the scan (UTC of its transmission).
      const ScanTiming timing = sim_->Timing(i, k);
      const auto sent_ns =
          start_ns + static_cast<std::int64_t>(std::llround(timing.transmit_s * 1e9));
      EXPECT_GT(d.receive_ns[k], sent_ns);
      EXPECT_LT(d.receive_ns[k], sent_ns + 200 * common::kNsPerMs);
      if (k > 0) {
        EXPECT_GT(d.receive_ns[k], d.receive_ns[k - 1]);
      }
      // Device ticks: the period apart, through the uint32 wrap.
      const auto u = unwrap.Unwrap(scan.time_since_startup_us);
      EXPECT_FALSE(u.restarted);
      if (k == 0) first_tick = u.ticks_us;
      EXPECT_NEAR(static_cast<double>(u.ticks_us - first_tick),
                  static_cast<double>(k) * sensor.period_us, 320.0);  // start jitter <= 3 sigma
      EXPECT_EQ(u.ticks_us, timing.start_tick_us - (sim_->Timing(i, 0).start_tick_us - first_tick));
    }
    // The RSSI channel as the model sends it.
    const cola::ScanChannel* rssi = d.scans[0]->FindChannel("RSSI1");
    if (sensor.device.model->rssi_bits == 0) {
      EXPECT_EQ(rssi, nullptr);
    } else {
      ASSERT_NE(rssi, nullptr);
      EXPECT_EQ(rssi->bits, sensor.device.model->rssi_bits);
    }
  }
}

TEST_F(SimulatedCaptures, RangesMatchTheGeometryWithinTheNoise) {
  for (std::size_t i = 0; i < sim_->sensor_count(); ++i) {
    const SensorSetup& sensor = sim_->sensor(i);
    SCOPED_TRACE(sensor.id);
    const Decoded d = Decode(*dir_ / (sensor.id + ".pcap"));
    ASSERT_FALSE(d.scans.empty());
    int compared = 0, outliers = 0, echoes = 0;
    for (std::size_t k = 0; k < d.scans.size(); k += 7) {
      const cola::ScanChannel& dist = *d.scans[k]->FindChannel("DIST1");
      const ScanTiming timing = sim_->Timing(i, k);
      for (std::size_t b = 0; b < dist.count; ++b) {
        // Each beam at its own time within the scan (the mirror turns while the person walks).
        const double t = timing.start_s + static_cast<double>(b) * sensor.device.beam_time_s;
        const double truth = sim_->NoiselessRange(i, b, t);
        const double measured = dist.RangeM(b);
        if (measured > 0) ++echoes;
        if (truth > sensor.device.range_m || measured == 0) continue;
        ++compared;
        const double sigma = sensor.device.noise_m + sensor.device.noise_per_m * truth;
        if (std::abs(measured - truth) > 5 * sigma + 0.001) ++outliers;
      }
    }
    EXPECT_GT(compared, 1000);
    EXPECT_GT(echoes, compared / 2);
    EXPECT_LE(outliers, compared / 1000) << outliers << " of " << compared;
  }
}

TEST_F(SimulatedCaptures, DecodedPointsLieOnTheWallsInTheTruthPoseFrame) {
  // Independent of the simulator's ray caster: the tracker's polar conversion (telegram angles, x
  // forward = the 90° beam) and the pose of truth.yaml put the echoes onto the world's walls.
  const YAML::Node truth = YAML::LoadFile(*dir_ / "truth.yaml");
  const WorldSpec& world = sim_->scenario().world;
  std::vector<Segment> segments;
  for (const auto& wall : world.walls) {
    for (std::size_t k = 0; k + 1 < wall.size(); ++k) segments.push_back({wall[k], wall[k + 1]});
  }
  for (const auto& o : world.obstacles) {
    for (const Segment& e : PolygonEdges(o)) segments.push_back(e);
  }
  auto polar = std::make_unique<cola::PolarScan>();
  for (std::size_t i = 0; i < sim_->sensor_count(); ++i) {
    const YAML::Node pose = truth["sensors"][i];
    SCOPED_TRACE(pose["id"].as<std::string>());
    const double x = pose["x_m"].as<double>(), y = pose["y_m"].as<double>();
    const double yaw = pose["yaw_deg"].as<double>() * 3.14159265358979323846 / 180.0;
    const Decoded d = Decode(*dir_ / (pose["id"].as<std::string>() + ".pcap"));
    ASSERT_FALSE(d.scans.empty());
    ASSERT_TRUE(cola::ToPolarScan(*d.scans.back(), polar.get()));
    int points = 0, on_walls = 0;
    for (std::size_t b = 0; b < polar->count; ++b) {
      const double r = polar->range_m[b];
      if (r <= 0) continue;
      const double a =
          yaw + polar->first_angle_rad + static_cast<double>(b) * polar->angle_step_rad;
      const Vec2 p{x + r * std::cos(a), y + r * std::sin(a)};
      double nearest = kNoHit;
      for (const Segment& s : segments) nearest = std::min(nearest, PointSegmentDistance(p, s));
      ++points;
      on_walls += nearest < 0.08 ? 1 : 0;
    }
    EXPECT_GT(points, 100);
    // The rest: the two targets and mixed pixels at edges.
    EXPECT_GT(on_walls, points * 9 / 10) << on_walls << " of " << points;
  }
}

TEST_F(SimulatedCaptures, TheClientSideCarriesTheLiveClientsCommands) {
  const Decoded d = Decode(*dir_ / "lms.pcap", /*from_sensor=*/false);
  const std::vector<std::string> expected = {
      "sMN SetAccessMode", "sRN DeviceIdent", "sRN FirmwareVersion", "sRN SerialNumber",
      "sMN LMCstartmeas",  "sMN Run",         "sEN LMDscandata"};
  EXPECT_EQ(d.replies, expected);
}

TEST_F(SimulatedCaptures, ScansAreSegmentedLikeTheRealDevices) {
  // LMS111: 1191-byte frames in one segment; LMS511 (1141 points, 8-bit RSSI) 3553-byte frames in
  // 1448 + 1448 + 657; both as in the shared captures. Device packets = SYN-ACK + 7 replies +
  // scans.
  const Decoded lms = Decode(*dir_ / "lms.pcap");
  EXPECT_EQ(lms.capture.stream_packets, 1 + 7 + sim_->sensor(0).scan_count);
  const Decoded big = Decode(*dir_ / "big.pcap");
  EXPECT_EQ(big.capture.stream_packets, 1 + 7 + 3 * sim_->sensor(1).scan_count);
  std::vector<std::uint8_t> payload(cola::MaxEncodedSize(*big.scans[0]));
  EXPECT_EQ(cola::EncodeScanTelegram(*big.scans[0], payload) + 9, 3553u);
  payload.resize(cola::MaxEncodedSize(*lms.scans[0]));
  EXPECT_EQ(cola::EncodeScanTelegram(*lms.scans[0], payload) + 9, 1191u);
}

TEST_F(SimulatedCaptures, DumpReadsThemLikeRealCaptures) {
  std::ostringstream lines;
  tools::DumpSummary summary;
  std::string error;
  ASSERT_TRUE(tools::DumpCapture(*dir_ / "tim.pcap", {}, &lines, &summary, &error)) << error;
  EXPECT_EQ(summary.scans, sim_->sensor(2).scan_count);
  EXPECT_EQ(summary.other_by_type.at("sRA"), 3u);
  std::istringstream in(lines.str());
  std::string first;
  std::getline(in, first);
  EXPECT_NE(first.find("\"n_points\": 811"), std::string::npos) << first;
  EXPECT_NE(first.find("\"angle_step_deg\": 0.3333"), std::string::npos) << first;
  EXPECT_NE(first.find("\"rssi_bits\": 16"), std::string::npos) << first;
  EXPECT_NE(first.find("\"scan_frequency_hz\": 15.0"), std::string::npos) << first;
}

TEST_F(SimulatedCaptures, TruthYamlHoldsTheScenarioPosesExactly) {
  const YAML::Node truth = YAML::LoadFile(*dir_ / "truth.yaml");
  const Scenario& s = sim_->scenario();
  ASSERT_EQ(truth["sensors"].size(), s.sensors.size());
  for (std::size_t i = 0; i < s.sensors.size(); ++i) {
    const YAML::Node n = truth["sensors"][i];
    EXPECT_EQ(n["id"].as<std::string>(), s.sensors[i].id);
    EXPECT_EQ(n["x_m"].as<double>(), s.sensors[i].x_m);
    EXPECT_EQ(n["y_m"].as<double>(), s.sensors[i].y_m);
    EXPECT_EQ(n["yaw_deg"].as<double>(), s.sensors[i].yaw_deg);
    EXPECT_EQ(n.size(), 4u);  // exactly the pose contract
    const YAML::Node dev = truth["devices"][i];
    EXPECT_EQ(dev["capture"].as<std::string>(), s.sensors[i].id + ".pcap");
    EXPECT_EQ(dev["clock"]["drift_ppm"].as<double>(), sim_->sensor(i).drift_ppm);
    EXPECT_EQ(dev["serial_number"].as<std::uint32_t>(), sim_->sensor(i).serial_number);
  }
  EXPECT_EQ(truth["sensors"][1]["yaw_deg"].as<double>(), 135.0);
  EXPECT_EQ(truth["devices"][2]["clock"]["offset_s"].as<double>(), 4294.5);
  EXPECT_EQ(truth["start_utc_ns"].as<std::int64_t>(), s.start_utc_ns);
  ASSERT_EQ(truth["targets"].size(), 2u);
  EXPECT_EQ(truth["targets"][1]["shape"].as<std::string>(), "cylinder");
}

TEST_F(SimulatedCaptures, TruthTracksListEveryTargetAtTheTruthRate) {
  std::ifstream in(*dir_ / "truth_tracks.csv");
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "time_s,utc_ns,target,x_m,y_m,heading_deg,vx_mps,vy_mps,kind");
  int rows = 0;
  double last_post_x = 0;
  while (std::getline(in, line)) {
    ++rows;
    if (line.find(",post,") != std::string::npos) {
      std::istringstream cells(line);
      std::string cell;
      for (int c = 0; c < 4; ++c) std::getline(cells, cell, ',');
      last_post_x = std::stod(cell);
    }
  }
  // 2 s at 50 Hz (0 ... 1.98 s), two targets.
  EXPECT_EQ(rows, 2 * 100);
  EXPECT_DOUBLE_EQ(last_post_x, 14.0);
}

TEST(SimulatedCapturesDeterminism, SameSeedGivesByteIdenticalFiles) {
  TempDir a, b, c;
  std::string error;
  auto sim1 = MakeSim();
  auto sim2 = MakeSim();
  ASSERT_TRUE(WriteSimulation(*sim1, a.str(), {}, nullptr, &error)) << error;
  OutputOptions parallel;
  parallel.jobs = 3;  // threads do not change the bytes
  ASSERT_TRUE(WriteSimulation(*sim2, b.str(), parallel, nullptr, &error)) << error;
  for (const char* name : {"lms.pcap", "big.pcap", "tim.pcap", "truth.yaml", "truth_tracks.csv"}) {
    const std::string fa = ReadAll(a / name);
    EXPECT_GT(fa.size(), 100u) << name;
    EXPECT_TRUE(fa == ReadAll(b / name)) << name << " differs between two runs with the same seed";
  }
  std::string other = kScenario;
  other.replace(other.find("seed: 17"), 8, "seed: 18");
  auto sim3 = MakeSim(other);
  ASSERT_TRUE(WriteSimulation(*sim3, c.str(), {}, nullptr, &error)) << error;
  EXPECT_FALSE(ReadAll(a / "lms.pcap") == ReadAll(c / "lms.pcap"));
}

TEST(SimulatedCapturesErrors, UnwritableFolderIsAnError) {
  auto sim = MakeSim();
  TempDir dir;
  const std::string file = dir / "a_file";
  std::ofstream(file) << "x";
  std::string error;
  EXPECT_FALSE(WriteSimulation(*sim, file + "/sub", {}, nullptr, &error));
  EXPECT_NE(error.find("a_file"), std::string::npos) << error;
}

}  // namespace
}  // namespace lrfnet::sim
