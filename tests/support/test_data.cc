#include "tests/support/test_data.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>

namespace lrfnet::testing {

std::string SharedDir() {
  const char* env = std::getenv("LRFNET_SHARED_DIR");
  std::string dir = (env != nullptr && *env != '\0') ? env : LRFNET_SHARED_DIR;
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) return {};
  return std::filesystem::weakly_canonical(dir, ec).string();
}

std::optional<std::string> SharedFile(const std::string& relative_path) {
  const std::string dir = SharedDir();
  if (dir.empty()) return std::nullopt;
  std::filesystem::path p = std::filesystem::path(dir) / relative_path;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(p, ec)) return std::nullopt;
  return p.string();
}

std::vector<std::uint8_t> ReadFileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  EXPECT_TRUE(in.good()) << "cannot open " << path;
  return std::vector<std::uint8_t>(std::istreambuf_iterator<char>(in), {});
}

const std::vector<std::string>& SickCaptureNames() {
  static const std::vector<std::string> kNames = {"test.pcapng", "lms111_20210302.pcap",
                                                  "lms511_20210301.pcap", "mrs1104_20210722.pcap"};
  return kNames;
}

}  // namespace lrfnet::testing
