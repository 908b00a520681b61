#pragma once
// Helpers of the recording and datagram-file tests: a per-process temporary folder, file bytes in
// and out, and reading a DatagramSource to its end.

#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "central_daemon/io/datagram_source.h"

namespace lrfnet::daemon::test_util {

inline std::filesystem::path TempDir() {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("lrfnet_daemon_io_test_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  return dir;
}

inline std::string TempPath(const std::string& name) { return (TempDir() / name).string(); }

inline std::vector<std::uint8_t> ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

inline void WriteBytes(const std::string& path, const std::vector<std::uint8_t>& bytes) {
  // A new file rather than a truncated one: ext4 (auto_da_alloc) syncs a file truncated and
  // rewritten on close, which made a test writing a file per byte offset slow.
  std::filesystem::remove(path);
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
}

// Deterministic datagram bytes of `size`, different for every seed.
inline std::vector<std::uint8_t> MakeDatagram(std::size_t size, std::uint32_t seed) {
  std::vector<std::uint8_t> d(size);
  for (std::size_t i = 0; i < size; ++i) d[i] = static_cast<std::uint8_t>(seed * 131 + i * 7);
  return d;
}

struct ReadResult {
  std::vector<ReceivedDatagram> datagrams;
  SourceStatus end = SourceStatus::kDatagram;
  std::string error;
};

// Reads a source to kEnd or kError (bounded, so a source that never ends fails the test instead
// of hanging it).
inline ReadResult ReadToEnd(DatagramSource& source, std::size_t limit = 1'000'000) {
  ReadResult r;
  ReceivedDatagram d;
  while (r.datagrams.size() < limit) {
    r.end = source.Next(&d);
    if (r.end != SourceStatus::kDatagram) break;
    r.datagrams.push_back(d);
  }
  r.error = source.error();
  return r;
}

}  // namespace lrfnet::daemon::test_util
