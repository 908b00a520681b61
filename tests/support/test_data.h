#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace lrfnet::testing {

// The shared test-data folder (CMake cache variable LRFNET_SHARED_DIR, overridable at run time by the
// environment variable LRFNET_SHARED_DIR). Empty when it does not exist.
std::string SharedDir();

// Path of a file under SharedDir(), or nullopt when the file is absent. Tests call
// LRFNET_REQUIRE_SHARED_FILE, which skips with a message naming the missing path.
std::optional<std::string> SharedFile(const std::string& relative_path);

// Whole file as bytes; aborts the test on a read error.
std::vector<std::uint8_t> ReadFileBytes(const std::string& path);

// The real SICK captures shipped in shared/data/sick (file names only).
const std::vector<std::string>& SickCaptureNames();

}  // namespace lrfnet::testing

#define LRFNET_REQUIRE_SHARED_FILE(var, rel)                                                  \
  std::string var;                                                                            \
  do {                                                                                        \
    auto lrfnet_found_ = ::lrfnet::testing::SharedFile(rel);                                  \
    if (!lrfnet_found_) {                                                                     \
      GTEST_SKIP() << "shared test data absent: " << (rel) << " not found under '"           \
                   << ::lrfnet::testing::SharedDir()                                          \
                   << "' (configure with -DLRFNET_SHARED_DIR=... or set LRFNET_SHARED_DIR)"; \
    }                                                                                         \
    var = *lrfnet_found_;                                                                     \
  } while (0)
