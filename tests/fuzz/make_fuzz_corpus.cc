// Writes the seed corpus of every fuzz target into OUT/<target>/: windows of the real SICK captures'
// streams, raw packets and segment runs of those captures (when the shared data is present), and
// synthetic telegrams from the encoder (always), so every target has seeds on any machine.
//
//   make_fuzz_corpus OUT

#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "tests/fuzz/capture_seeds.h"
#include "tests/fuzz/cola_seeds.h"
#include "tests/support/test_data.h"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: make_fuzz_corpus OUT_DIR\n");
    return 2;
  }
  const std::filesystem::path out = argv[1];
  const std::string cola_dir = (out / "cola_fuzz").string();
  const std::string reassembler_dir = (out / "reassembler_fuzz").string();
  const std::string packet_dir = (out / "packet_fuzz").string();
  for (const auto& d : {cola_dir, reassembler_dir, packet_dir}) std::filesystem::create_directories(d);

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

  std::size_t files = 0;
  for (const auto& d : {cola_dir, reassembler_dir, packet_dir}) {
    for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(d)) ++files;
  }
  std::printf("make_fuzz_corpus: %zu seed files in %s\n", files, out.string().c_str());
  return files > 0 ? 0 : 1;
}
