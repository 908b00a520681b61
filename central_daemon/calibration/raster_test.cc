#include "central_daemon/calibration/raster.h"

#include <gtest/gtest.h>
#include <zlib.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <string>
#include <vector>

#include "central_daemon/calibration/png_test_reader.h"

namespace lrfnet::calib {

namespace testing {

namespace {
std::uint32_t BigEndian(const std::uint8_t* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) |
         std::uint32_t{p[3]};
}
int Paeth(int a, int b, int c) {
  const int p = a + b - c;
  const int pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
  return pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
}
}  // namespace

// An independent, strict PNG reader for 8-bit RGBA (what EncodePng writes): signature, chunk
// CRCs, IHDR first and IEND last, the exact inflated size, all five row filters. Also used by
// report_test.cc (same test binary).
DecodedPng DecodePng(const std::vector<std::uint8_t>& png) {
  DecodedPng out;
  const auto fail = [&out](const std::string& e) {
    out.error = e;
    return out;
  };
  static const std::uint8_t kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (png.size() < 8 || !std::equal(kSignature, kSignature + 8, png.begin()))
    return fail("bad signature");
  std::size_t pos = 8;
  std::vector<std::uint8_t> idat;
  bool have_header = false, have_end = false;
  while (pos < png.size()) {
    if (have_end) return fail("data after IEND");
    if (png.size() - pos < 12) return fail("truncated chunk");
    const std::uint32_t length = BigEndian(&png[pos]);
    if (length > png.size() - pos - 12) return fail("chunk length beyond the file");
    const std::string type(png.begin() + static_cast<long>(pos) + 4,
                           png.begin() + static_cast<long>(pos) + 8);
    const std::uint8_t* data = &png[pos + 8];
    const uLong crc = crc32(0L, &png[pos + 4], length + 4);
    if (crc != BigEndian(&png[pos + 8 + length])) return fail("CRC mismatch in " + type);
    if (!have_header && type != "IHDR") return fail("first chunk is not IHDR");
    if (type == "IHDR") {
      if (length != 13) return fail("IHDR length");
      out.width = static_cast<int>(BigEndian(data));
      out.height = static_cast<int>(BigEndian(data + 4));
      if (data[8] != 8 || data[9] != 6 || data[10] != 0 || data[11] != 0 || data[12] != 0)
        return fail("not 8-bit RGBA, deflate, no interlace");
      have_header = true;
    } else if (type == "IDAT") {
      idat.insert(idat.end(), data, data + length);
      ++out.idat_chunks;
    } else if (type == "IEND") {
      have_end = true;
    }
    pos += 12 + length;
  }
  if (!have_end) return fail("no IEND");
  if (out.width <= 0 || out.height <= 0) return fail("empty image");
  const std::size_t stride = static_cast<std::size_t>(out.width) * 4;
  const std::size_t expected = static_cast<std::size_t>(out.height) * (stride + 1);
  // One byte of room: a stream that inflates to more than the image is an error too.
  std::vector<std::uint8_t> raw(expected + 1);
  uLongf raw_size = static_cast<uLongf>(raw.size());
  const int z = uncompress(raw.data(), &raw_size, idat.data(), static_cast<uLong>(idat.size()));
  if (z != Z_OK) return fail("zlib error " + std::to_string(z));
  if (raw_size != expected)
    return fail("inflated " + std::to_string(raw_size) + " bytes, expected " +
                std::to_string(expected));
  out.rgba.resize(static_cast<std::size_t>(out.height) * stride);
  for (std::size_t y = 0; y < static_cast<std::size_t>(out.height); ++y) {
    const std::uint8_t filter = raw[y * (stride + 1)];
    const std::uint8_t* in = &raw[y * (stride + 1) + 1];
    std::uint8_t* row = &out.rgba[y * stride];
    const std::uint8_t* up = y > 0 ? &out.rgba[(y - 1) * stride] : nullptr;
    for (std::size_t i = 0; i < stride; ++i) {
      const int a = i >= 4 ? row[i - 4] : 0;
      const int b = up != nullptr ? up[i] : 0;
      const int c = up != nullptr && i >= 4 ? up[i - 4] : 0;
      int predicted = 0;
      switch (filter) {
        case 0:
          predicted = 0;
          break;
        case 1:
          predicted = a;
          break;
        case 2:
          predicted = b;
          break;
        case 3:
          predicted = (a + b) / 2;
          break;
        case 4:
          predicted = Paeth(a, b, c);
          break;
        default:
          return fail("bad filter type " + std::to_string(filter));
      }
      row[i] = static_cast<std::uint8_t>(in[i] + predicted);
    }
  }
  out.ok = true;
  return out;
}

}  // namespace testing

namespace {

using testing::DecodePng;

constexpr Rgba kWhite{255, 255, 255};
constexpr Rgba kRed{255, 0, 0};
constexpr Rgba kBlue{0, 0, 255};

TEST(Png, RoundTripsEveryPixelExactly) {
  Canvas canvas(37, 23, kWhite);
  for (int y = 0; y < 23; ++y)
    for (int x = 0; x < 37; ++x)
      canvas.BlendPixel(x, y,
                        {static_cast<std::uint8_t>(x * 7), static_cast<std::uint8_t>(y * 11),
                         static_cast<std::uint8_t>(x * y), static_cast<std::uint8_t>(200 + x)},
                        1.0);
  const std::vector<std::uint8_t> png = EncodePng(canvas);
  const auto decoded = DecodePng(png);
  ASSERT_TRUE(decoded.ok) << decoded.error;
  EXPECT_EQ(decoded.width, 37);
  EXPECT_EQ(decoded.height, 23);
  EXPECT_EQ(decoded.idat_chunks, 1);
  EXPECT_EQ(decoded.rgba, canvas.rgba());
}

TEST(Png, CorruptionIsDetectedByTheChecker) {
  Canvas canvas(8, 8, kRed);
  std::vector<std::uint8_t> png = EncodePng(canvas);
  ASSERT_TRUE(DecodePng(png).ok);
  png[png.size() - 20] ^= 0x40;  // inside IDAT
  const auto decoded = DecodePng(png);
  EXPECT_FALSE(decoded.ok);
  EXPECT_NE(decoded.error.find("CRC"), std::string::npos) << decoded.error;
}

TEST(Canvas, SizeIsClampedNotTrusted) {
  Canvas tiny(0, -5, kWhite);
  EXPECT_EQ(tiny.width(), 1);
  EXPECT_EQ(tiny.height(), 1);
  Canvas huge(100000, 7, kWhite);
  EXPECT_EQ(huge.width(), Canvas::kMaxSide);
  EXPECT_EQ(huge.rgba().size(), static_cast<std::size_t>(Canvas::kMaxSide) * 7 * 4);
}

TEST(Canvas, FilledSquareCoversInsideAndBlendsItsEdges) {
  Canvas canvas(20, 20, kWhite);
  canvas.FillRect(4.0, 4.0, 10.5, 10.0, kBlue);
  EXPECT_EQ(canvas.At(5, 5), kBlue);
  EXPECT_EQ(canvas.At(9, 9), kBlue);
  EXPECT_EQ(canvas.At(3, 5), kWhite);
  EXPECT_EQ(canvas.At(11, 5), kWhite);
  EXPECT_EQ(canvas.At(5, 10), kWhite);
  // Column 10 is half covered: half-way between white and blue.
  const Rgba half = canvas.At(10, 6);
  EXPECT_NEAR(half.r, 128, 2);
  EXPECT_EQ(half.b, 255);
}

TEST(Canvas, AlphaBlendsSourceOver) {
  Canvas canvas(4, 4, kWhite);
  canvas.FillRect(0, 0, 4, 4, {255, 0, 0, 128});
  const Rgba c = canvas.At(1, 1);
  EXPECT_EQ(c.r, 255);
  EXPECT_NEAR(c.g, 127, 1);
  EXPECT_NEAR(c.b, 127, 1);
  EXPECT_EQ(c.a, 255);
}

TEST(Canvas, NonConvexWedgeLeavesItsMissingQuadrantEmpty) {
  // A 270 degree field of view around (50, 50), radius 40, missing the quadrant x > 50, y > 50
  // (the classic LMS1xx blind sector).
  std::vector<PixelPoint> wedge = {{50, 50}};
  for (int i = 0; i <= 54; ++i) {
    const double a =
        -std::numbers::pi / 2 + (3 * std::numbers::pi / 2) * i / 54.0 + std::numbers::pi;
    wedge.push_back({50 + 40 * std::cos(a), 50 + 40 * std::sin(a)});
  }
  Canvas canvas(100, 100, kWhite);
  canvas.FillPolygon(wedge, kRed);
  EXPECT_EQ(canvas.At(70, 70), kWhite);  // the blind quadrant
  EXPECT_EQ(canvas.At(30, 30), kRed);
  EXPECT_EQ(canvas.At(70, 30), kRed);
  EXPECT_EQ(canvas.At(30, 70), kRed);
  EXPECT_EQ(canvas.At(95, 50), kWhite);  // beyond the radius
}

TEST(Canvas, RingHasAHole) {
  Canvas canvas(40, 40, kWhite);
  canvas.StrokeCircle({20, 20}, 10, 3, kBlue);
  EXPECT_EQ(canvas.At(20, 20), kWhite);
  EXPECT_EQ(canvas.At(30, 20), kBlue);
  EXPECT_EQ(canvas.At(20, 10), kBlue);
}

TEST(Canvas, DashedLineHasGaps) {
  Canvas canvas(100, 10, kWhite);
  canvas.DrawDashedLine({0, 5}, {100, 5}, 2.0, 8.0, 5.0, kRed);
  EXPECT_EQ(canvas.At(4, 5), kRed);     // first dash: 0..8
  EXPECT_EQ(canvas.At(10, 5), kWhite);  // gap: 8..13
  EXPECT_EQ(canvas.At(15, 5), kRed);    // second dash: 13..21
}

TEST(Canvas, TextDrawsTheGlyphBitmap) {
  Canvas canvas(20, 10, kWhite);
  canvas.DrawText(1, 1, "1", 1, kRed);
  // '1' is 00100 / 01100 / 00100 ... / 01110: its stem is column 2.
  for (int row = 0; row < 7; ++row) EXPECT_EQ(canvas.At(1 + 2, 1 + row), kRed) << row;
  EXPECT_EQ(canvas.At(1 + 0, 1 + 0), kWhite);
  EXPECT_EQ(canvas.At(1 + 1, 1 + 1), kRed);
  EXPECT_EQ(canvas.At(1 + 4, 1 + 6), kWhite);
  EXPECT_EQ(canvas.At(1 + 3, 1 + 6), kRed);
  EXPECT_DOUBLE_EQ(Canvas::TextWidth("ab", 2), 22.0);
}

TEST(Canvas, UnknownCharactersDrawAsQuestionMarks) {
  Canvas a(10, 10, kWhite), b(10, 10, kWhite);
  a.DrawText(0, 0, "\x01", 1, kRed);
  b.DrawText(0, 0, "?", 1, kRed);
  EXPECT_EQ(a.rgba(), b.rgba());
  Canvas blank(10, 10, kWhite);
  EXPECT_NE(a.rgba(), blank.rgba());
}

TEST(Canvas, HostileCoordinatesNeverCrashOrPaintGarbage) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  Canvas canvas(30, 30, kWhite);
  const std::vector<std::uint8_t> before = canvas.rgba();
  canvas.FillPolygon({{nan, 0}, {10, 10}, {0, 10}}, kRed);
  canvas.FillPolygon({{0, 0}, {inf, 10}, {0, 10}}, kRed);
  canvas.FillPolygon({{1, 1}, {2, 2}}, kRed);  // degenerate
  canvas.DrawLine({nan, nan}, {5, 5}, 2, kRed);
  canvas.DrawLine({5, 5}, {5, 5}, 2, kRed);
  canvas.FillCircle({5, 5}, -1, kRed);
  canvas.FillCircle({5, 5}, inf, kRed);
  canvas.DrawText(nan, 3, "abc", 1, kRed);
  canvas.DrawText(3, 3, "abc", 0, kRed);
  canvas.DrawDashedLine({0, 0}, {1e300, 1e300}, 1, 0, 5, kRed);
  canvas.BlendPixel(-1, 3, kRed, 1.0);
  canvas.BlendPixel(3, 30, kRed, 1.0);
  canvas.BlendPixel(3, 3, kRed, nan);
  EXPECT_EQ(canvas.rgba(), before);
  // Far outside, but covering the canvas: clipped, fills everything, no overflow.
  canvas.FillRect(-1e300, -1e300, 1e300, 1e300, kBlue);
  EXPECT_EQ(canvas.At(0, 0), kBlue);
  EXPECT_EQ(canvas.At(29, 29), kBlue);
  canvas.DrawDashedLine({-1e12, 15}, {1e12, 15}, 2, 8, 5, kRed);
  EXPECT_EQ(canvas.At(15, 15), kRed);
}

}  // namespace
}  // namespace lrfnet::calib
