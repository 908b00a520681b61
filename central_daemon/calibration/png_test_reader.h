#pragma once
// Test-only: a strict PNG reader (signature, chunk CRCs, IHDR first, exact inflated size, all five
// row filters) that checks what the report's encoder writes. Defined in raster_test.cc.

#include <cstdint>
#include <string>
#include <vector>

#include "central_daemon/calibration/raster.h"

namespace lrfnet::calib::testing {

struct DecodedPng {
  bool ok = false;
  std::string error;
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> rgba;
  int idat_chunks = 0;

  Rgba At(int x, int y) const {
    const std::size_t i = (static_cast<std::size_t>(y) * width + x) * 4;
    return {rgba[i], rgba[i + 1], rgba[i + 2], rgba[i + 3]};
  }
};
DecodedPng DecodePng(const std::vector<std::uint8_t>& png);

}  // namespace lrfnet::calib::testing
