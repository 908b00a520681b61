#pragma once
// A small RGBA canvas and a PNG encoder for the calibration report (no image library needed).
//
// Pixel coordinates: x to the right, y down, in pixels; pixel (i, j) covers [i, i+1) x [j, j+1),
// so its centre is (i + 0.5, j + 0.5). Everything drawn is clipped to the canvas; non-finite
// coordinates draw nothing. Shapes are anti-aliased by area coverage (4 sub-scanlines per row,
// exact horizontal coverage) and blended "source over" with the colour's alpha.
//
// Not thread-safe; a Canvas is a value.

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace lrfnet::calib {

struct Rgba {
  std::uint8_t r = 0;
  std::uint8_t g = 0;
  std::uint8_t b = 0;
  std::uint8_t a = 255;  // 255 = opaque
  bool operator==(const Rgba&) const = default;
};

struct PixelPoint {
  double x = 0.0;
  double y = 0.0;
};

class Canvas {
 public:
  // Sides are clamped to [1, kMaxSide] (a 4096 x 4096 canvas is 64 MiB).
  static constexpr int kMaxSide = 4096;
  // The built-in font: 5 x 7 glyphs in a 6 x 8 cell, times `scale`. Printable ASCII letters,
  // digits, the punctuation . - _ : / ( ) [ ] = + , % ? ! < > # & * ' " and space; any other byte
  // draws as '?'.
  static constexpr int kGlyphAdvance = 6;
  static constexpr int kGlyphHeight = 7;

  Canvas(int width, int height, Rgba background);

  int width() const { return width_; }
  int height() const { return height_; }
  Rgba At(int x, int y) const;  // precondition: inside
  // Row-major RGBA, 4 bytes per pixel, width() * height() pixels.
  const std::vector<std::uint8_t>& rgba() const { return pixels_; }

  // Blends `color` into one pixel with its alpha times coverage (0..1). Outside: nothing.
  void BlendPixel(int x, int y, Rgba color, double coverage = 1.0);

  // Fills the region inside an odd number of the closed contours (even-odd rule), so a contour
  // inside another cuts a hole (rings). Contours need not be convex; each is closed implicitly.
  void FillContours(const std::vector<std::vector<PixelPoint>>& contours, Rgba color);
  void FillPolygon(const std::vector<PixelPoint>& polygon, Rgba color);
  void FillCircle(PixelPoint centre, double radius_px, Rgba color);
  void StrokeCircle(PixelPoint centre, double radius_px, double width_px, Rgba color);
  void FillRect(double x0, double y0, double x1, double y1, Rgba color);
  // A segment as a rectangle of the given width (butt caps).
  void DrawLine(PixelPoint a, PixelPoint b, double width_px, Rgba color);
  void DrawDashedLine(PixelPoint a, PixelPoint b, double width_px, double dash_px, double gap_px,
                      Rgba color);
  void DrawPolyline(const std::vector<PixelPoint>& points, double width_px, Rgba color);
  // Text with its top-left corner at (x, y); one line ('\n' draws as '?').
  void DrawText(double x, double y, std::string_view text, int scale, Rgba color);
  static double TextWidth(std::string_view text, int scale);

 private:
  int width_;
  int height_;
  std::vector<std::uint8_t> pixels_;
  std::vector<double> coverage_;  // scratch row for FillContours
};

// The canvas as a PNG file (8-bit RGBA, one IDAT, zlib via compress2, CRCs via crc32). Empty when
// zlib fails (out of memory).
std::vector<std::uint8_t> EncodePng(const Canvas& canvas);

}  // namespace lrfnet::calib
