// Seeds for auth_fuzz: datagrams sealed with its keys (auth_fuzz_keys.h) by the tracker's encoder
// and sealer, plain and encrypted, both directions, both epochs; truncations, flipped bits and
// unsigned datagrams.

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "common/datagram_auth.h"
#include "firmware_tracker/io/datagram_encoder.h"
#include "firmware_tracker/io/request_decoder.h"
#include "tests/fuzz/auth_fuzz_keys.h"
#include "tests/fuzz/daemon_seeds.h"

namespace lrfnet::fuzz {

void WriteAuthSeeds(const std::string& dir) {
  auth::Init();
  int n = 0;
  const auto write = [&](const std::vector<std::uint8_t>& bytes) {
    std::ofstream(std::filesystem::path(dir) / ("seed_" + std::to_string(n++)), std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()),
               static_cast<std::streamsize>(bytes.size()));
  };
  struct Collect final : io::DatagramSink {
    std::vector<std::vector<std::uint8_t>> got;
    void Send(std::span<const std::uint8_t> d, common::UtcNs) override {
      got.emplace_back(d.begin(), d.end());
    }
  } plain;
  io::DatagramEncoder encoder({kAuthFuzzSensor, 9});
  tracking::ScanTracks scan;
  for (std::uint32_t i = 0; i < 3; ++i) scan.tracks.emplace_slot()->track_id = i;
  encoder.EncodeTracks(scan, 1'700'000'000'000'000'000, plain);
  encoder.EncodeHealth({}, 1'700'000'000'000'000'000, plain);
  io::RequestMessage m;
  m.sensor_id = kAuthFuzzSensor;
  m.send_background = true;
  std::uint8_t request[io::kMaxDatagramBytes];
  const std::size_t request_size = io::EncodeRequest(m, request);
  std::uint64_t counter = 1'700'000'000'000'000'000ULL;
  for (const std::uint32_t epoch : {1u, 2u}) {
    for (const bool encrypt : {false, true}) {
      for (const auto direction : {auth::Direction::kToDaemon, auth::Direction::kToTracker}) {
        auth::SealerOptions o;
        o.sensor_id = kAuthFuzzSensor;
        o.keys = AuthFuzzKeys(epoch);
        o.encrypt = encrypt;
        o.direction = direction;
        o.salt = 7 + epoch;
        o.first_counter = counter += 100;
        auth::Sealer sealer(o);
        std::vector<std::vector<std::uint8_t>> payloads = plain.got;
        payloads.emplace_back(request, request + request_size);
        for (const auto& payload : payloads) {
          std::vector<std::uint8_t> sealed(payload.size() + sealer.overhead());
          sealer.Seal(payload, sealed);
          write(sealed);
          write(std::vector<std::uint8_t>(sealed.begin(), sealed.begin() + sealed.size() / 2));
          sealed[sealed.size() / 3] ^= 0x20;
          write(sealed);
        }
      }
    }
  }
  for (const auto& d : plain.got) write(d);
}

}  // namespace lrfnet::fuzz
