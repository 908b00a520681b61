// Writes the seed corpus of every fuzz target into OUT/<target>/: windows of the real SICK captures'
// streams, raw packets and segment runs of those captures (when the shared data is present), and
// synthetic telegrams from the encoder (always), so every target has seeds on any machine.
//
//   make_fuzz_corpus OUT

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "firmware_tracker/io/datagram_encoder.h"
#include "firmware_tracker/io/request_decoder.h"
#include "tests/fuzz/capture_seeds.h"
#include "tests/fuzz/cola_seeds.h"
#include "tests/fuzz/daemon_seeds.h"
#include "tests/fuzz/foxglove_seeds.h"
#include "tests/fuzz/live_view_seeds.h"
#include "tests/fuzz/sopas_seeds.h"
#include "tests/support/test_data.h"

namespace {

// request_fuzz: requests for the target's sensor id ("gate-3"), for all and for another sensor, and the
// tracker's own datagram kinds, all made by the uplink's encoders.
void WriteRequestSeeds(const std::filesystem::path& dir) {
  struct Files final : lrfnet::io::DatagramSink {
    std::filesystem::path dir;
    int n = 0;
    void Send(std::span<const std::uint8_t> d, lrfnet::common::UtcNs) override {
      std::ofstream(dir / ("datagram_" + std::to_string(n++)), std::ios::binary)
          .write(reinterpret_cast<const char*>(d.data()), static_cast<std::streamsize>(d.size()));
    }
  } files;
  files.dir = dir;
  for (const char* id : {"gate-3", "", "gate-4"}) {
    for (int flags = 0; flags < 4; ++flags) {
      lrfnet::io::RequestMessage m;
      m.sensor_id = id;
      m.sequence = static_cast<std::uint64_t>(flags) << 40;
      m.sent_ns = 1'700'000'000'000'000'000;
      m.send_sensor_info = (flags & 1) != 0;
      m.send_background = (flags & 2) != 0;
      std::uint8_t buf[lrfnet::io::kMaxDatagramBytes];
      files.Send(std::span<const std::uint8_t>(buf, lrfnet::io::EncodeRequest(m, buf)), 0);
    }
  }
  lrfnet::io::DatagramEncoder encoder({"gate-3", 7});
  lrfnet::tracking::ScanTracks scan;
  for (std::uint32_t i = 0; i < 16; ++i) {
    lrfnet::tracking::TrackReport* t = scan.tracks.emplace_slot();
    t->track_id = i;
    t->x_m = i;
  }
  encoder.EncodeTracks(scan, 1, files);
  const std::vector<float> ranges(500, 4.0f);
  encoder.EncodeBackground({1, -0.1, 0.01, ranges}, 1, files);
  encoder.EncodeHealth({}, 1, files);
  encoder.EncodeSensorInfo({}, 1, files);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: make_fuzz_corpus OUT_DIR\n");
    return 2;
  }
  const std::filesystem::path out = argv[1];
  const std::string cola_dir = (out / "cola_fuzz").string();
  const std::string reassembler_dir = (out / "reassembler_fuzz").string();
  const std::string packet_dir = (out / "packet_fuzz").string();
  const std::string request_dir = (out / "request_fuzz").string();
  const std::string datagram_dir = (out / "datagram_fuzz").string();
  const std::string recording_dir = (out / "recording_fuzz").string();
  const std::string auth_dir = (out / "auth_fuzz").string();
  for (const auto& d :
       {cola_dir, reassembler_dir, packet_dir, request_dir, datagram_dir, recording_dir, auth_dir})
    std::filesystem::create_directories(d);

  std::vector<std::vector<std::uint8_t>> streams;
  for (const auto& name : lrfnet::testing::SickCaptureNames()) {
    const auto path = lrfnet::testing::SharedFile("data/sick/" + name);
    if (!path) {
      std::printf("make_fuzz_corpus: %s absent, using synthetic seeds only for it\n", name.c_str());
      continue;
    }
    lrfnet::fuzz::WriteCaptureSeeds(*path, reassembler_dir, packet_dir);
    streams.push_back(lrfnet::fuzz::ReadSensorStream(*path));
  }
  lrfnet::fuzz::WriteColaSeeds(streams, cola_dir);
  WriteRequestSeeds(request_dir);
  lrfnet::fuzz::WriteDatagramSeeds(datagram_dir);
  lrfnet::fuzz::WriteRecordingSeeds(recording_dir);
  lrfnet::fuzz::WriteAuthSeeds(auth_dir);
  lrfnet::fuzz::WriteLiveViewSeeds((out / "http_request_fuzz").string());
  lrfnet::fuzz::WriteFoxgloveSeeds((out / "foxglove_fuzz").string());
  lrfnet::fuzz::WriteSopasSeeds((out / "sopas_fuzz").string());
  std::filesystem::create_directories(out / "calibration_yaml_fuzz");
  lrfnet::fuzz::WriteCalibrationYamlSeeds((out / "calibration_yaml_fuzz").string());
  std::filesystem::create_directories(out / "config_fuzz");
  lrfnet::fuzz::WriteConfigSeeds((out / "config_fuzz").string());

  std::size_t files = 0;
  for (const auto& d : {cola_dir, reassembler_dir, packet_dir, request_dir, datagram_dir, recording_dir}) {
    for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(d)) ++files;
  }
  std::printf("make_fuzz_corpus: %zu seed files in %s\n", files, out.string().c_str());
  return files > 0 ? 0 : 1;
}
