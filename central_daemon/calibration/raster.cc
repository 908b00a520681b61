#include "central_daemon/calibration/raster.h"

#include <zlib.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>

namespace lrfnet::calib {

namespace {

constexpr int kSubRows = 4;  // sub-scanlines per pixel row (vertical anti-aliasing)

// 5 x 7 glyphs, one byte per row, bit 4 = leftmost column.
struct Glyph {
  char c;
  std::array<std::uint8_t, 7> rows;
};

constexpr Glyph kFont[] = {
    {' ', {0, 0, 0, 0, 0, 0, 0}},
    {'0', {0b01110, 0b10001, 0b10011, 0b10101, 0b11001, 0b10001, 0b01110}},
    {'1', {0b00100, 0b01100, 0b00100, 0b00100, 0b00100, 0b00100, 0b01110}},
    {'2', {0b01110, 0b10001, 0b00001, 0b00010, 0b00100, 0b01000, 0b11111}},
    {'3', {0b11111, 0b00010, 0b00100, 0b00010, 0b00001, 0b10001, 0b01110}},
    {'4', {0b00010, 0b00110, 0b01010, 0b10010, 0b11111, 0b00010, 0b00010}},
    {'5', {0b11111, 0b10000, 0b11110, 0b00001, 0b00001, 0b10001, 0b01110}},
    {'6', {0b00110, 0b01000, 0b10000, 0b11110, 0b10001, 0b10001, 0b01110}},
    {'7', {0b11111, 0b00001, 0b00010, 0b00100, 0b01000, 0b01000, 0b01000}},
    {'8', {0b01110, 0b10001, 0b10001, 0b01110, 0b10001, 0b10001, 0b01110}},
    {'9', {0b01110, 0b10001, 0b10001, 0b01111, 0b00001, 0b00010, 0b01100}},
    {'A', {0b01110, 0b10001, 0b10001, 0b10001, 0b11111, 0b10001, 0b10001}},
    {'B', {0b11110, 0b10001, 0b10001, 0b11110, 0b10001, 0b10001, 0b11110}},
    {'C', {0b01110, 0b10001, 0b10000, 0b10000, 0b10000, 0b10001, 0b01110}},
    {'D', {0b11100, 0b10010, 0b10001, 0b10001, 0b10001, 0b10010, 0b11100}},
    {'E', {0b11111, 0b10000, 0b10000, 0b11110, 0b10000, 0b10000, 0b11111}},
    {'F', {0b11111, 0b10000, 0b10000, 0b11110, 0b10000, 0b10000, 0b10000}},
    {'G', {0b01110, 0b10001, 0b10000, 0b10111, 0b10001, 0b10001, 0b01111}},
    {'H', {0b10001, 0b10001, 0b10001, 0b11111, 0b10001, 0b10001, 0b10001}},
    {'I', {0b01110, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b01110}},
    {'J', {0b00111, 0b00010, 0b00010, 0b00010, 0b00010, 0b10010, 0b01100}},
    {'K', {0b10001, 0b10010, 0b10100, 0b11000, 0b10100, 0b10010, 0b10001}},
    {'L', {0b10000, 0b10000, 0b10000, 0b10000, 0b10000, 0b10000, 0b11111}},
    {'M', {0b10001, 0b11011, 0b10101, 0b10101, 0b10001, 0b10001, 0b10001}},
    {'N', {0b10001, 0b10001, 0b11001, 0b10101, 0b10011, 0b10001, 0b10001}},
    {'O', {0b01110, 0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b01110}},
    {'P', {0b11110, 0b10001, 0b10001, 0b11110, 0b10000, 0b10000, 0b10000}},
    {'Q', {0b01110, 0b10001, 0b10001, 0b10001, 0b10101, 0b10010, 0b01101}},
    {'R', {0b11110, 0b10001, 0b10001, 0b11110, 0b10100, 0b10010, 0b10001}},
    {'S', {0b01111, 0b10000, 0b10000, 0b01110, 0b00001, 0b00001, 0b11110}},
    {'T', {0b11111, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100}},
    {'U', {0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b01110}},
    {'V', {0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b01010, 0b00100}},
    {'W', {0b10001, 0b10001, 0b10001, 0b10101, 0b10101, 0b10101, 0b01010}},
    {'X', {0b10001, 0b10001, 0b01010, 0b00100, 0b01010, 0b10001, 0b10001}},
    {'Y', {0b10001, 0b10001, 0b10001, 0b01010, 0b00100, 0b00100, 0b00100}},
    {'Z', {0b11111, 0b00001, 0b00010, 0b00100, 0b01000, 0b10000, 0b11111}},
    {'a', {0b00000, 0b00000, 0b01110, 0b00001, 0b01111, 0b10001, 0b01111}},
    {'b', {0b10000, 0b10000, 0b10110, 0b11001, 0b10001, 0b10001, 0b11110}},
    {'c', {0b00000, 0b00000, 0b01110, 0b10000, 0b10000, 0b10001, 0b01110}},
    {'d', {0b00001, 0b00001, 0b01101, 0b10011, 0b10001, 0b10001, 0b01111}},
    {'e', {0b00000, 0b00000, 0b01110, 0b10001, 0b11111, 0b10000, 0b01110}},
    {'f', {0b00110, 0b01001, 0b01000, 0b11100, 0b01000, 0b01000, 0b01000}},
    {'g', {0b00000, 0b01111, 0b10001, 0b10001, 0b01111, 0b00001, 0b01110}},
    {'h', {0b10000, 0b10000, 0b10110, 0b11001, 0b10001, 0b10001, 0b10001}},
    {'i', {0b00100, 0b00000, 0b01100, 0b00100, 0b00100, 0b00100, 0b01110}},
    {'j', {0b00010, 0b00000, 0b00110, 0b00010, 0b00010, 0b10010, 0b01100}},
    {'k', {0b10000, 0b10000, 0b10010, 0b10100, 0b11000, 0b10100, 0b10010}},
    {'l', {0b01100, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b01110}},
    {'m', {0b00000, 0b00000, 0b11010, 0b10101, 0b10101, 0b10001, 0b10001}},
    {'n', {0b00000, 0b00000, 0b10110, 0b11001, 0b10001, 0b10001, 0b10001}},
    {'o', {0b00000, 0b00000, 0b01110, 0b10001, 0b10001, 0b10001, 0b01110}},
    {'p', {0b00000, 0b00000, 0b11110, 0b10001, 0b11110, 0b10000, 0b10000}},
    {'q', {0b00000, 0b00000, 0b01111, 0b10001, 0b01111, 0b00001, 0b00001}},
    {'r', {0b00000, 0b00000, 0b10110, 0b11001, 0b10000, 0b10000, 0b10000}},
    {'s', {0b00000, 0b00000, 0b01110, 0b10000, 0b01110, 0b00001, 0b11110}},
    {'t', {0b01000, 0b01000, 0b11100, 0b01000, 0b01000, 0b01001, 0b00110}},
    {'u', {0b00000, 0b00000, 0b10001, 0b10001, 0b10001, 0b10011, 0b01101}},
    {'v', {0b00000, 0b00000, 0b10001, 0b10001, 0b10001, 0b01010, 0b00100}},
    {'w', {0b00000, 0b00000, 0b10001, 0b10001, 0b10101, 0b10101, 0b01010}},
    {'x', {0b00000, 0b00000, 0b10001, 0b01010, 0b00100, 0b01010, 0b10001}},
    {'y', {0b00000, 0b00000, 0b10001, 0b10001, 0b01111, 0b00001, 0b01110}},
    {'z', {0b00000, 0b00000, 0b11111, 0b00010, 0b00100, 0b01000, 0b11111}},
    {'.', {0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b01100, 0b01100}},
    {'-', {0b00000, 0b00000, 0b00000, 0b11111, 0b00000, 0b00000, 0b00000}},
    {'_', {0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b11111}},
    {':', {0b00000, 0b01100, 0b01100, 0b00000, 0b01100, 0b01100, 0b00000}},
    {'/', {0b00000, 0b00001, 0b00010, 0b00100, 0b01000, 0b10000, 0b00000}},
    {'(', {0b00010, 0b00100, 0b01000, 0b01000, 0b01000, 0b00100, 0b00010}},
    {')', {0b01000, 0b00100, 0b00010, 0b00010, 0b00010, 0b00100, 0b01000}},
    {'=', {0b00000, 0b00000, 0b11111, 0b00000, 0b11111, 0b00000, 0b00000}},
    {'+', {0b00000, 0b00100, 0b00100, 0b11111, 0b00100, 0b00100, 0b00000}},
    {',', {0b00000, 0b00000, 0b00000, 0b00000, 0b01100, 0b00100, 0b01000}},
    {'%', {0b11000, 0b11001, 0b00010, 0b00100, 0b01000, 0b10011, 0b00011}},
    {'?', {0b01110, 0b10001, 0b00001, 0b00010, 0b00100, 0b00000, 0b00100}},
    {'<', {0b00010, 0b00100, 0b01000, 0b10000, 0b01000, 0b00100, 0b00010}},
    {'>', {0b01000, 0b00100, 0b00010, 0b00001, 0b00010, 0b00100, 0b01000}},
    {'#', {0b01010, 0b01010, 0b11111, 0b01010, 0b11111, 0b01010, 0b01010}},
    {'&', {0b01100, 0b10010, 0b10100, 0b01000, 0b10101, 0b10010, 0b01101}},
    {'*', {0b00000, 0b00100, 0b10101, 0b01110, 0b10101, 0b00100, 0b00000}},
    {'[', {0b01110, 0b01000, 0b01000, 0b01000, 0b01000, 0b01000, 0b01110}},
    {']', {0b01110, 0b00010, 0b00010, 0b00010, 0b00010, 0b00010, 0b01110}},
    {'\'', {0b00100, 0b00100, 0b01000, 0b00000, 0b00000, 0b00000, 0b00000}},
    {'"', {0b01010, 0b01010, 0b10100, 0b00000, 0b00000, 0b00000, 0b00000}},
    {'!', {0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b00000, 0b00100}},
};

const Glyph& GlyphFor(char c) {
  static const Glyph* const question = [] {
    for (const Glyph& g : kFont)
      if (g.c == '?') return &g;
    return &kFont[0];
  }();
  for (const Glyph& g : kFont)
    if (g.c == c) return g;
  return *question;
}

bool Finite(PixelPoint p) { return std::isfinite(p.x) && std::isfinite(p.y); }

// Vertices of a circle approximation fine enough that the chord error stays below ~0.1 px.
std::vector<PixelPoint> CirclePolygon(PixelPoint c, double r) {
  const int n = std::clamp(static_cast<int>(std::ceil(2.0 * std::numbers::pi * r / 1.5)), 12, 256);
  std::vector<PixelPoint> p(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    const double a = 2.0 * std::numbers::pi * i / n;
    p[static_cast<std::size_t>(i)] = {c.x + r * std::cos(a), c.y + r * std::sin(a)};
  }
  return p;
}

void AppendBigEndian(std::vector<std::uint8_t>* out, std::uint32_t v) {
  out->push_back(static_cast<std::uint8_t>(v >> 24));
  out->push_back(static_cast<std::uint8_t>(v >> 16));
  out->push_back(static_cast<std::uint8_t>(v >> 8));
  out->push_back(static_cast<std::uint8_t>(v));
}

void AppendChunk(std::vector<std::uint8_t>* out, const char (&type)[5], const std::uint8_t* data,
                 std::size_t size) {
  AppendBigEndian(out, static_cast<std::uint32_t>(size));
  const std::size_t crc_from = out->size();
  out->insert(out->end(), type, type + 4);
  if (size > 0) out->insert(out->end(), data, data + size);
  // The CRC covers the chunk type and data (PNG spec 5.3).
  const uLong crc = crc32(0L, out->data() + crc_from, static_cast<uInt>(out->size() - crc_from));
  AppendBigEndian(out, static_cast<std::uint32_t>(crc));
}

}  // namespace

Canvas::Canvas(int width, int height, Rgba background)
    : width_(std::clamp(width, 1, kMaxSide)), height_(std::clamp(height, 1, kMaxSide)) {
  pixels_.resize(static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_) * 4);
  for (std::size_t i = 0; i < pixels_.size(); i += 4) {
    pixels_[i] = background.r;
    pixels_[i + 1] = background.g;
    pixels_[i + 2] = background.b;
    pixels_[i + 3] = background.a;
  }
  coverage_.resize(static_cast<std::size_t>(width_) + 1);
}

Rgba Canvas::At(int x, int y) const {
  const std::size_t i = (static_cast<std::size_t>(y) * width_ + x) * 4;
  return {pixels_[i], pixels_[i + 1], pixels_[i + 2], pixels_[i + 3]};
}

void Canvas::BlendPixel(int x, int y, Rgba color, double coverage) {
  if (x < 0 || y < 0 || x >= width_ || y >= height_ || !(coverage > 0.0)) return;
  // Integer source-over with alpha in 0..255 (exact for opaque colours at full coverage).
  const int a = static_cast<int>(std::min(coverage, 1.0) * color.a + 0.5);
  if (a == 0) return;
  std::uint8_t* p = &pixels_[(static_cast<std::size_t>(y) * width_ + x) * 4];
  if (a == 255) {
    p[0] = color.r;
    p[1] = color.g;
    p[2] = color.b;
    p[3] = 255;
    return;
  }
  const auto mix = [a](int dst, int src) {
    // Rounded division by 255 without a divide (exact for 0..255*255).
    const int v = dst * (255 - a) + src * a + 128;
    return static_cast<std::uint8_t>((v + (v >> 8)) >> 8);
  };
  p[0] = mix(p[0], color.r);
  p[1] = mix(p[1], color.g);
  p[2] = mix(p[2], color.b);
  p[3] = mix(p[3], 255);
}

void Canvas::FillContours(const std::vector<std::vector<PixelPoint>>& contours, Rgba color) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  double min_y = kInf, max_y = -kInf, min_x = kInf, max_x = -kInf;
  for (const auto& contour : contours) {
    for (const PixelPoint& p : contour) {
      if (!Finite(p)) return;
      min_x = std::min(min_x, p.x);
      max_x = std::max(max_x, p.x);
      min_y = std::min(min_y, p.y);
      max_y = std::max(max_y, p.y);
    }
  }
  if (!(min_y < max_y) || !(min_x < max_x)) return;
  // Clamped in double before any conversion to int: coordinates may be huge.
  const int row_begin = static_cast<int>(std::floor(std::clamp(min_y, 0.0, double(height_))));
  const int row_end = static_cast<int>(std::ceil(std::clamp(max_y, 0.0, double(height_))));
  const double x_lo = std::clamp(min_x, 0.0, double(width_));
  const double x_hi = std::clamp(max_x, 0.0, double(width_));
  if (row_begin >= row_end || !(x_lo < x_hi)) return;
  const int col_begin = static_cast<int>(std::floor(x_lo));
  const int col_end = std::min(static_cast<int>(std::ceil(x_hi)), width_);

  std::vector<double> crossings;
  const double weight = 1.0 / kSubRows;
  for (int row = row_begin; row < row_end; ++row) {
    std::fill(coverage_.begin() + col_begin, coverage_.begin() + col_end, 0.0);
    bool any = false;
    for (int sub = 0; sub < kSubRows; ++sub) {
      const double sy = row + (sub + 0.5) / kSubRows;
      crossings.clear();
      for (const auto& contour : contours) {
        const std::size_t n = contour.size();
        for (std::size_t i = 0; i < n; ++i) {
          const PixelPoint& a = contour[i];
          const PixelPoint& b = contour[(i + 1) % n];
          if ((a.y <= sy) == (b.y <= sy)) continue;
          crossings.push_back(a.x + (sy - a.y) * (b.x - a.x) / (b.y - a.y));
        }
      }
      std::sort(crossings.begin(), crossings.end());
      for (std::size_t k = 0; k + 1 < crossings.size(); k += 2) {
        const double xa = std::clamp(crossings[k], x_lo, x_hi);
        const double xb = std::clamp(crossings[k + 1], x_lo, x_hi);
        if (!(xa < xb)) continue;
        any = true;
        // Exact horizontal coverage of the span [xa, xb) per pixel column.
        const int ia = static_cast<int>(std::floor(xa));
        const int ib = std::min(static_cast<int>(std::floor(xb)), width_);
        if (ia == ib) {
          coverage_[ia] += (xb - xa) * weight;
          continue;
        }
        coverage_[ia] += (ia + 1 - xa) * weight;
        for (int i = ia + 1; i < ib; ++i) coverage_[i] += weight;
        if (ib < width_) coverage_[ib] += (xb - ib) * weight;
      }
    }
    if (!any) continue;
    for (int col = col_begin; col < col_end; ++col) BlendPixel(col, row, color, coverage_[col]);
  }
}

void Canvas::FillPolygon(const std::vector<PixelPoint>& polygon, Rgba color) {
  FillContours({polygon}, color);
}

void Canvas::FillCircle(PixelPoint centre, double radius_px, Rgba color) {
  if (!Finite(centre) || !(radius_px > 0.0) || !std::isfinite(radius_px)) return;
  FillContours({CirclePolygon(centre, radius_px)}, color);
}

void Canvas::StrokeCircle(PixelPoint centre, double radius_px, double width_px, Rgba color) {
  if (!Finite(centre) || !(radius_px > 0.0) || !std::isfinite(radius_px) || !(width_px > 0.0))
    return;
  const double outer = radius_px + width_px / 2.0;
  const double inner = radius_px - width_px / 2.0;
  if (inner <= 0.0) return FillCircle(centre, outer, color);
  FillContours({CirclePolygon(centre, outer), CirclePolygon(centre, inner)}, color);
}

void Canvas::FillRect(double x0, double y0, double x1, double y1, Rgba color) {
  FillContours({{{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}}}, color);
}

void Canvas::DrawLine(PixelPoint a, PixelPoint b, double width_px, Rgba color) {
  if (!Finite(a) || !Finite(b) || !(width_px > 0.0)) return;
  const double dx = b.x - a.x, dy = b.y - a.y;
  const double length = std::hypot(dx, dy);
  if (!(length > 1e-9) || !std::isfinite(length)) return;
  const double nx = -dy / length * width_px / 2.0, ny = dx / length * width_px / 2.0;
  FillPolygon(
      {{a.x + nx, a.y + ny}, {b.x + nx, b.y + ny}, {b.x - nx, b.y - ny}, {a.x - nx, a.y - ny}},
      color);
}

void Canvas::DrawDashedLine(PixelPoint a, PixelPoint b, double width_px, double dash_px,
                            double gap_px, Rgba color) {
  if (!Finite(a) || !Finite(b) || !(dash_px > 0.0) || !(gap_px >= 0.0)) return;
  const double length = std::hypot(b.x - a.x, b.y - a.y);
  const double period = dash_px + gap_px;
  // Bounded work: more dashes than this (a hostile length or a tiny dash) draw as a solid line.
  constexpr double kMaxDashes = 10000.0;
  if (!std::isfinite(length) || !(length / period <= kMaxDashes))
    return DrawLine(a, b, width_px, color);
  const auto at = [&](double t) {
    return PixelPoint{a.x + (b.x - a.x) * t / length, a.y + (b.y - a.y) * t / length};
  };
  const int dashes = static_cast<int>(std::ceil(length / period));
  for (int i = 0; i < dashes; ++i) {
    const double s = i * period;
    DrawLine(at(s), at(std::min(s + dash_px, length)), width_px, color);
  }
}

void Canvas::DrawPolyline(const std::vector<PixelPoint>& points, double width_px, Rgba color) {
  for (std::size_t i = 1; i < points.size(); ++i)
    DrawLine(points[i - 1], points[i], width_px, color);
}

void Canvas::DrawText(double x, double y, std::string_view text, int scale, Rgba color) {
  if (!std::isfinite(x) || !std::isfinite(y) || scale < 1) return;
  const int ox = static_cast<int>(std::lround(std::clamp(x, -1e6, 1e6)));
  const int oy = static_cast<int>(std::lround(std::clamp(y, -1e6, 1e6)));
  for (std::size_t k = 0; k < text.size(); ++k) {
    const int gx = ox + static_cast<int>(k) * kGlyphAdvance * scale;
    if (gx >= width_) break;
    const Glyph& glyph = GlyphFor(text[k]);
    for (int row = 0; row < kGlyphHeight; ++row) {
      for (int col = 0; col < 5; ++col) {
        if ((glyph.rows[static_cast<std::size_t>(row)] & (0b10000 >> col)) == 0) continue;
        for (int dy = 0; dy < scale; ++dy)
          for (int dx = 0; dx < scale; ++dx)
            BlendPixel(gx + col * scale + dx, oy + row * scale + dy, color);
      }
    }
  }
}

double Canvas::TextWidth(std::string_view text, int scale) {
  if (text.empty()) return 0.0;
  return (static_cast<double>(text.size()) * kGlyphAdvance - 1.0) * scale;
}

std::vector<std::uint8_t> EncodePng(const Canvas& canvas) {
  const std::size_t w = static_cast<std::size_t>(canvas.width());
  const std::size_t h = static_cast<std::size_t>(canvas.height());
  const std::size_t stride = w * 4;
  // Filter "Sub" (type 1) on every row: flat colour areas become runs of zeros that deflate well.
  std::vector<std::uint8_t> raw(h * (stride + 1));
  const std::vector<std::uint8_t>& px = canvas.rgba();
  for (std::size_t y = 0; y < h; ++y) {
    std::uint8_t* out = &raw[y * (stride + 1)];
    const std::uint8_t* in = &px[y * stride];
    out[0] = 1;
    for (std::size_t i = 0; i < stride; ++i)
      out[1 + i] = static_cast<std::uint8_t>(in[i] - (i >= 4 ? in[i - 4] : 0));
  }
  uLongf compressed_size = compressBound(static_cast<uLong>(raw.size()));
  std::vector<std::uint8_t> compressed(compressed_size);
  if (compress2(compressed.data(), &compressed_size, raw.data(), static_cast<uLong>(raw.size()),
                Z_DEFAULT_COMPRESSION) != Z_OK) {
    return {};
  }

  std::vector<std::uint8_t> png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  std::vector<std::uint8_t> header;
  AppendBigEndian(&header, static_cast<std::uint32_t>(w));
  AppendBigEndian(&header, static_cast<std::uint32_t>(h));
  // Bit depth 8, colour type 6 (RGBA), deflate, adaptive filtering, no interlace.
  header.insert(header.end(), {8, 6, 0, 0, 0});
  AppendChunk(&png, "IHDR", header.data(), header.size());
  AppendChunk(&png, "IDAT", compressed.data(), compressed_size);
  AppendChunk(&png, "IEND", nullptr, 0);
  return png;
}

}  // namespace lrfnet::calib
