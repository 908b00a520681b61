#include "central_daemon/calibration/report.h"

#include <spdlog/fmt/fmt.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <numbers>
#include <optional>

#include "central_daemon/calibration/eval.h"
#include "central_daemon/calibration/raster.h"
#include "common/eigen_instances.h"

namespace lrfnet::calib {

namespace {

using Eigen::Vector2d;

constexpr double kInf = std::numeric_limits<double>::infinity();

// ---------------------------------------------------------------------------------------------
// Colours and text.

// Tableau 10: distinct on white and for most colour-blind readers.
constexpr Rgba kPalette[] = {{31, 119, 180},  {255, 127, 14}, {44, 160, 44},   {214, 39, 40},
                             {148, 103, 189}, {140, 86, 75},  {227, 119, 194}, {127, 127, 127},
                             {188, 189, 34},  {23, 190, 207}};
constexpr Rgba kBlack{0, 0, 0};
constexpr Rgba kWhite{255, 255, 255};
constexpr Rgba kGrid{225, 225, 225};
constexpr Rgba kAxisText{90, 90, 90};
constexpr Rgba kGhost{120, 120, 120, 200};
constexpr Rgba kUsedEdge{44, 160, 44};
constexpr Rgba kUnusedEdge{255, 127, 14};
constexpr Rgba kRejectedEdge{214, 39, 40};
constexpr Rgba kFlag{200, 0, 0};

Rgba SensorColor(std::size_t i) { return kPalette[i % std::size(kPalette)]; }
Rgba WithAlpha(Rgba c, std::uint8_t a) { return {c.r, c.g, c.b, a}; }
std::string Hex(Rgba c) { return fmt::format("#{:02x}{:02x}{:02x}", c.r, c.g, c.b); }

// Length of the valid UTF-8 sequence at s[i], or 0.
std::size_t Utf8Length(std::string_view s, std::size_t i) {
  const auto c = static_cast<unsigned char>(s[i]);
  std::size_t n = 0;
  if (c >= 0xc2 && c <= 0xdf)
    n = 2;
  else if (c >= 0xe0 && c <= 0xef)
    n = 3;
  else if (c >= 0xf0 && c <= 0xf4)
    n = 4;
  if (n == 0 || i + n > s.size()) return 0;
  for (std::size_t k = 1; k < n; ++k)
    if ((static_cast<unsigned char>(s[i + k]) & 0xc0) != 0x80) return 0;
  return n;
}

// Text for XML content and attributes: markup characters escaped, valid UTF-8 kept, control
// characters and invalid bytes replaced by '?' (XML 1.0 cannot carry them at all).
std::string Xml(std::string_view s) {
  std::string out;
  for (std::size_t i = 0; i < s.size(); ++i) {
    const auto c = static_cast<unsigned char>(s[i]);
    switch (c) {
      case '&':
        out += "&amp;";
        continue;
      case '<':
        out += "&lt;";
        continue;
      case '>':
        out += "&gt;";
        continue;
      case '"':
        out += "&quot;";
        continue;
      case '\'':
        out += "&apos;";
        continue;
      default:
        break;
    }
    if (c >= 0x80) {
      const std::size_t n = Utf8Length(s, i);
      if (n == 0) {
        out += '?';
      } else {
        out.append(s.substr(i, n));
        i += n - 1;
      }
    } else {
      out += c < 0x20 || c == 0x7f ? '?' : static_cast<char>(c);
    }
  }
  return out;
}

// A label for the bitmap font: at most `max_chars`, non-ASCII bytes as '?'.
std::string Ascii(std::string_view s, std::size_t max_chars = 24) {
  std::string out;
  for (const char ch : s.substr(0, max_chars)) {
    const auto c = static_cast<unsigned char>(ch);
    out += c < 0x20 || c >= 0x7f ? '?' : ch;
  }
  return s.size() > max_chars ? out + ".." : out;
}

// A Markdown table cell: no '|' or newline breaks the table, no HTML gets interpreted.
std::string Md(std::string_view s) {
  std::string out;
  for (const char ch : s) {
    const auto c = static_cast<unsigned char>(ch);
    switch (c) {
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '&':
        out += "&amp;";
        break;
      case '|':
      case '\\':
      case '`':
      case '*':
      case '_':
      case '[':
      case ']':
        out += '\\';
        out += ch;
        break;
      default:
        out += c < 0x20 || c == 0x7f ? ' ' : ch;
    }
  }
  return out;
}

// A CSV field (RFC 4180): quoted when it holds a separator, a quote or a line break.
std::string Csv(std::string_view s) {
  if (s.find_first_of(",\"\r\n") == std::string_view::npos) return std::string(s);
  std::string out = "\"";
  for (const char ch : s) {
    if (ch == '"') out += '"';
    out += ch;
  }
  return out + "\"";
}

std::string Num(double v, int decimals) {
  if (!std::isfinite(v)) return std::isnan(v) ? "nan" : (v > 0 ? "inf" : "-inf");
  return fmt::format("{:.{}f}", v, decimals);
}

bool Finite(const Vector2d& p) { return std::isfinite(p.x()) && std::isfinite(p.y()); }
bool Finite(const PixelPoint& p) { return std::isfinite(p.x) && std::isfinite(p.y); }

// 1, 2 or 5 times a power of ten, near x (> 0).
double NiceStep(double x) {
  if (!(x > 0.0) || !std::isfinite(x)) return 1.0;
  const double p = std::pow(10.0, std::floor(std::log10(x)));
  const double m = x / p;
  return (m < 1.5 ? 1.0 : m < 3.5 ? 2.0 : m < 7.5 ? 5.0 : 10.0) * p;
}

// ---------------------------------------------------------------------------------------------
// One scene, two back ends: the drawing code calls a Painter once and gets the SVG and the PNG.

class Painter {
 public:
  virtual ~Painter() = default;
  virtual void Polygon(const std::vector<PixelPoint>& points, Rgba fill) = 0;
  virtual void Line(PixelPoint a, PixelPoint b, double width, Rgba color, bool dashed,
                    const std::string& tooltip) = 0;
  virtual void Polyline(const std::vector<PixelPoint>& points, double width, Rgba color) = 0;
  virtual void Dots(const std::vector<PixelPoint>& points, double half_side, Rgba color) = 0;
  // A sensor marker: a disc with an outline; `ring` draws the outline only.
  virtual void Marker(PixelPoint c, double radius, Rgba fill, bool ring,
                      const std::string& tooltip) = 0;
  virtual void Text(PixelPoint top_left, const std::string& text, int scale, Rgba color) = 0;
  virtual void Rect(PixelPoint a, PixelPoint b, Rgba fill) = 0;
};

class SvgPainter final : public Painter {
 public:
  SvgPainter(int width, int height) {
    svg_ = fmt::format(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{0}\" height=\"{1}\" "
        "viewBox=\"0 0 {0} {1}\" font-family=\"monospace\">\n"
        "<rect x=\"0\" y=\"0\" width=\"{0}\" height=\"{1}\" fill=\"#ffffff\"/>\n",
        width, height);
  }
  std::string Finish() { return svg_ + "</svg>\n"; }

  void Polygon(const std::vector<PixelPoint>& points, Rgba fill) override {
    if (points.size() < 3 || !AllFinite(points)) return;
    svg_ += "<path d=\"M";
    for (const PixelPoint& p : points) svg_ += fmt::format("{:.1f},{:.1f} ", p.x, p.y);
    svg_ += "Z\"" + Fill(fill) + "/>\n";
  }
  void Line(PixelPoint a, PixelPoint b, double width, Rgba color, bool dashed,
            const std::string& tooltip) override {
    if (!Finite(a) || !Finite(b)) return;
    svg_ +=
        fmt::format("<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\"{}{}", a.x, a.y,
                    b.x, b.y, Stroke(color, width), dashed ? " stroke-dasharray=\"8,5\"" : "");
    if (tooltip.empty()) {
      svg_ += "/>\n";
    } else {
      svg_ += "><title>" + Xml(tooltip) + "</title></line>\n";
    }
  }
  void Polyline(const std::vector<PixelPoint>& points, double width, Rgba color) override {
    if (points.size() < 2 || !AllFinite(points)) return;
    svg_ += "<polyline fill=\"none\"" + Stroke(color, width) + " points=\"";
    for (const PixelPoint& p : points) svg_ += fmt::format("{:.1f},{:.1f} ", p.x, p.y);
    svg_ += "\"/>\n";
  }
  void Dots(const std::vector<PixelPoint>& points, double half_side, Rgba color) override {
    // One path of small squares: far smaller than one element per point.
    std::string d;
    for (const PixelPoint& p : points) {
      if (!Finite(p)) continue;
      d += fmt::format("M{:.1f},{:.1f}h{:.1f}v{:.1f}h-{:.1f}z", p.x - half_side, p.y - half_side,
                       2 * half_side, 2 * half_side, 2 * half_side);
    }
    if (!d.empty()) svg_ += "<path class=\"points\" d=\"" + d + "\"" + Fill(color) + "/>\n";
  }
  void Marker(PixelPoint c, double radius, Rgba fill, bool ring,
              const std::string& tooltip) override {
    if (!Finite(c)) return;
    svg_ += fmt::format("<circle class=\"{}\" cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"{:.1f}\"",
                        ring ? "ghost" : "sensor", c.x, c.y, radius);
    svg_ += ring ? " fill=\"none\"" + Stroke(fill, 2.0) : Fill(fill) + Stroke(kBlack, 1.5);
    if (tooltip.empty()) {
      svg_ += "/>\n";
    } else {
      svg_ += "><title>" + Xml(tooltip) + "</title></circle>\n";
    }
  }
  void Text(PixelPoint top_left, const std::string& text, int scale, Rgba color) override {
    if (!Finite(top_left) || text.empty()) return;
    // 10 px monospace advances ~6 px per character, like the bitmap font at scale 1.
    svg_ += fmt::format("<text x=\"{:.1f}\" y=\"{:.1f}\" font-size=\"{}\"{}>{}</text>\n",
                        top_left.x, top_left.y + 7.5 * scale, 10 * scale, Fill(color), Xml(text));
  }
  void Rect(PixelPoint a, PixelPoint b, Rgba fill) override {
    if (!Finite(a) || !Finite(b)) return;
    svg_ += fmt::format("<rect x=\"{:.1f}\" y=\"{:.1f}\" width=\"{:.1f}\" height=\"{:.1f}\"{}/>\n",
                        std::min(a.x, b.x), std::min(a.y, b.y), std::abs(b.x - a.x),
                        std::abs(b.y - a.y), Fill(fill));
  }

 private:
  static bool AllFinite(const std::vector<PixelPoint>& points) {
    return std::all_of(points.begin(), points.end(), [](const PixelPoint& p) { return Finite(p); });
  }
  static std::string Fill(Rgba c) {
    std::string s = " fill=\"" + Hex(c) + "\"";
    if (c.a != 255) s += fmt::format(" fill-opacity=\"{:.3f}\"", c.a / 255.0);
    return s;
  }
  static std::string Stroke(Rgba c, double width) {
    std::string s = fmt::format(" stroke=\"{}\" stroke-width=\"{:.1f}\"", Hex(c), width);
    if (c.a != 255) s += fmt::format(" stroke-opacity=\"{:.3f}\"", c.a / 255.0);
    return s;
  }

  std::string svg_;
};

class CanvasPainter final : public Painter {
 public:
  explicit CanvasPainter(Canvas* canvas) : canvas_(*canvas) {}

  void Polygon(const std::vector<PixelPoint>& points, Rgba fill) override {
    canvas_.FillPolygon(points, fill);
  }
  void Line(PixelPoint a, PixelPoint b, double width, Rgba color, bool dashed,
            const std::string&) override {
    if (dashed) {
      canvas_.DrawDashedLine(a, b, width, 8.0, 5.0, color);
    } else {
      canvas_.DrawLine(a, b, width, color);
    }
  }
  void Polyline(const std::vector<PixelPoint>& points, double width, Rgba color) override {
    canvas_.DrawPolyline(points, width, color);
  }
  void Dots(const std::vector<PixelPoint>& points, double half_side, Rgba color) override {
    for (const PixelPoint& p : points)
      canvas_.FillRect(p.x - half_side, p.y - half_side, p.x + half_side, p.y + half_side, color);
  }
  void Marker(PixelPoint c, double radius, Rgba fill, bool ring, const std::string&) override {
    if (ring) {
      canvas_.StrokeCircle(c, radius, 2.0, fill);
    } else {
      canvas_.FillCircle(c, radius + 1.5, kBlack);
      canvas_.FillCircle(c, radius, fill);
    }
  }
  void Text(PixelPoint top_left, const std::string& text, int scale, Rgba color) override {
    canvas_.DrawText(top_left.x, top_left.y, Ascii(text, 64), scale, color);
  }
  void Rect(PixelPoint a, PixelPoint b, Rgba fill) override {
    canvas_.FillRect(a.x, a.y, b.x, b.y, fill);
  }

 private:
  Canvas& canvas_;
};

// ---------------------------------------------------------------------------------------------
// World -> pixels.

struct View {
  double min_x_m = 0.0, max_x_m = 1.0, min_y_m = 0.0, max_y_m = 1.0;
  double px_per_m = 1.0;
  double left = 70.0, top = 44.0, right = 24.0, bottom = 80.0;  // margins [px]
  int width = 100, height = 100;

  PixelPoint ToPx(const Vector2d& p) const {
    return {left + (p.x() - min_x_m) * px_per_m, top + (max_y_m - p.y()) * px_per_m};
  }
  double PlotRight() const { return width - right; }
  double PlotBottom() const { return height - bottom; }
};

// A view that shows every finite point with a 5 % border, at most `max_plot_px` along the longer
// side and at least `min_extent_m` across (a single sensor still gets a readable picture).
View FitView(const std::vector<Vector2d>& points, double min_extent_m, double max_plot_px) {
  View v;
  double min_x = kInf, max_x = -kInf, min_y = kInf, max_y = -kInf;
  for (const Vector2d& p : points) {
    if (!Finite(p)) continue;
    min_x = std::min(min_x, p.x());
    max_x = std::max(max_x, p.x());
    min_y = std::min(min_y, p.y());
    max_y = std::max(max_y, p.y());
  }
  // Nothing finite, or a span a double cannot hold: a small view around the origin.
  if (!(min_x <= max_x) || !std::isfinite(max_x - min_x) || !std::isfinite(max_y - min_y))
    min_x = max_x = min_y = max_y = 0.0;
  const auto widen = [min_extent_m](double* lo, double* hi) {
    const double pad = std::max((*hi - *lo) * 0.05, 0.0);
    *lo -= pad;
    *hi += pad;
    if (*hi - *lo < min_extent_m) {
      const double mid = 0.5 * (*lo + *hi);
      *lo = mid - min_extent_m / 2;
      *hi = mid + min_extent_m / 2;
    }
  };
  widen(&min_x, &max_x);
  widen(&min_y, &max_y);
  v.min_x_m = min_x;
  v.max_x_m = max_x;
  v.min_y_m = min_y;
  v.max_y_m = max_y;
  v.px_per_m = max_plot_px / std::max(max_x - min_x, max_y - min_y);
  v.width = static_cast<int>(std::ceil(v.left + v.right + (max_x - min_x) * v.px_per_m));
  v.height = static_cast<int>(std::ceil(v.top + v.bottom + (max_y - min_y) * v.px_per_m));
  // Room for the title and legend even when the scene is a thin strip.
  v.width = std::max(v.width, 480);
  v.height = std::max(v.height, 360);
  return v;
}

void DrawGridAndScale(Painter& p, const View& v) {
  const double extent = std::max(v.max_x_m - v.min_x_m, v.max_y_m - v.min_y_m);
  const double step = NiceStep(extent / 8.0);
  const auto label = [](double m) { return fmt::format("{:g}", std::abs(m) < 1e-9 ? 0.0 : m); };
  // Counted loops: near huge coordinates `x += step` might not advance.
  constexpr int kMaxTicks = 40;
  const double first_x = std::ceil(v.min_x_m / step) * step;
  for (int i = 0; i < kMaxTicks; ++i) {
    const double x = first_x + i * step;
    if (!(x <= v.max_x_m)) break;
    const PixelPoint a = v.ToPx({x, v.min_y_m}), b = v.ToPx({x, v.max_y_m});
    p.Line(a, b, 1.0, kGrid, false, "");
    const std::string text = label(x);
    p.Text({a.x - Canvas::TextWidth(text, 1) / 2, a.y + 6}, text, 1, kAxisText);
  }
  const double first_y = std::ceil(v.min_y_m / step) * step;
  for (int i = 0; i < kMaxTicks; ++i) {
    const double y = first_y + i * step;
    if (!(y <= v.max_y_m)) break;
    const PixelPoint a = v.ToPx({v.min_x_m, y}), b = v.ToPx({v.max_x_m, y});
    p.Line(a, b, 1.0, kGrid, false, "");
    const std::string text = label(y);
    p.Text({a.x - Canvas::TextWidth(text, 1) - 6, a.y - 3}, text, 1, kAxisText);
  }
  p.Text({v.PlotRight() - 80, v.PlotBottom() + 20}, "x [m]", 1, kAxisText);
  p.Text({4, v.top - 14}, "y [m]", 1, kAxisText);

  // Scale bar, bottom left.
  const double bar_m = NiceStep(extent / 5.0);
  const PixelPoint a{v.left, v.height - 24.0}, b{v.left + bar_m * v.px_per_m, v.height - 24.0};
  p.Line(a, b, 3.0, kBlack, false, "");
  p.Line({a.x, a.y - 5}, {a.x, a.y + 5}, 1.5, kBlack, false, "");
  p.Line({b.x, b.y - 5}, {b.x, b.y + 5}, 1.5, kBlack, false, "");
  p.Text({b.x + 8, b.y - 7}, fmt::format("{:g} m", bar_m), 2, kBlack);
}

// Top-left corner of a marker's label (scale 2): right of the marker, or left of it when it
// would run off the picture.
PixelPoint LabelAt(PixelPoint marker, const std::string& text, double gap_px, const View& v) {
  const double w = Canvas::TextWidth(Ascii(text, 64), 2);
  const double x = marker.x + gap_px + w > v.width - 4 ? marker.x - gap_px - w : marker.x + gap_px;
  return {x, marker.y + 6};
}

// ---------------------------------------------------------------------------------------------
// What is drawn, in world coordinates.

struct Wedge {
  std::vector<Vector2d> polygon_world;
};

struct SensorScene {
  std::size_t index = 0;  // into result->sensors
  std::string id;
  Pose2 pose;
  Rgba color;
  std::optional<Wedge> fov;
  std::vector<Vector2d> background_world;
  std::vector<std::vector<Vector2d>> tracks_world;
};

constexpr double kDefaultFovRadiusM = 10.0;
constexpr double kMaxFovRadiusM = 30.0;  // without a background to size it by
constexpr double kMinFovRadiusM = 5.0;

std::optional<Wedge> FovWedge(const SensorTracks& st, const Pose2& pose) {
  double start = 0.0, span = 0.0, max_range = 0.0;
  if (st.description && st.description->fov_rad > 0.0 && std::isfinite(st.description->fov_rad)) {
    start = st.description->first_angle_rad;
    span = st.description->fov_rad * (st.description->angle_step_rad < 0.0 ? -1.0 : 1.0);
    max_range = st.description->max_range_m;
  } else if (st.background && st.background->ranges_mm.size() > 1) {
    start = st.background->first_angle_rad;
    span = st.background->angle_step_rad * static_cast<double>(st.background->ranges_mm.size() - 1);
  } else {
    return std::nullopt;
  }
  if (!std::isfinite(start) || !std::isfinite(span) || span == 0.0) return std::nullopt;
  span = std::clamp(span, -2.0 * common::kPi, 2.0 * common::kPi);
  double radius = max_range > 0.0 && std::isfinite(max_range) ? max_range : kDefaultFovRadiusM;
  // A long-range scanner in a small room: the wedge is sized by what the sensor sees.
  double seen_m = 0.0;
  if (st.background)
    for (const std::uint32_t r : st.background->ranges_mm) seen_m = std::max(seen_m, r / 1000.0);
  radius = seen_m > 0.0 ? std::min(radius, std::max(1.1 * seen_m, kMinFovRadiusM))
                        : std::min(radius, kMaxFovRadiusM);

  Wedge w;
  const bool full = std::abs(span) >= 2.0 * common::kPi - 1e-6;
  if (!full) w.polygon_world.push_back(pose.translation());
  const int n = std::max(2, static_cast<int>(std::ceil(std::abs(span) / common::DegToRad(2.0))));
  for (int i = 0; i <= n; ++i) {
    const double a = start + span * i / n;
    w.polygon_world.push_back(pose * Vector2d(radius * std::cos(a), radius * std::sin(a)));
  }
  return w;
}

// Sutherland-Hodgman against the view's rectangle (correct for concave subjects such as a 270
// degree wedge; at worst it leaves zero-width slivers along the border, which fill nothing).
std::vector<Vector2d> ClipToView(const std::vector<Vector2d>& polygon, const View& v) {
  std::vector<Vector2d> out = polygon;
  const auto clip = [&out](auto inside, auto intersect) {
    std::vector<Vector2d> in;
    in.swap(out);
    for (std::size_t i = 0; i < in.size(); ++i) {
      const Vector2d& a = in[i];
      const Vector2d& b = in[(i + 1) % in.size()];
      if (inside(b)) {
        if (!inside(a)) out.push_back(intersect(a, b));
        out.push_back(b);
      } else if (inside(a)) {
        out.push_back(intersect(a, b));
      }
    }
  };
  const auto at_x = [](double x) {
    return [x](const Vector2d& a, const Vector2d& b) {
      const double t = (x - a.x()) / (b.x() - a.x());
      return Vector2d(x, a.y() + t * (b.y() - a.y()));
    };
  };
  const auto at_y = [](double y) {
    return [y](const Vector2d& a, const Vector2d& b) {
      const double t = (y - a.y()) / (b.y() - a.y());
      return Vector2d(a.x() + t * (b.x() - a.x()), y);
    };
  };
  clip([&](const Vector2d& p) { return p.x() >= v.min_x_m; }, at_x(v.min_x_m));
  clip([&](const Vector2d& p) { return p.x() <= v.max_x_m; }, at_x(v.max_x_m));
  clip([&](const Vector2d& p) { return p.y() >= v.min_y_m; }, at_y(v.min_y_m));
  clip([&](const Vector2d& p) { return p.y() <= v.max_y_m; }, at_y(v.max_y_m));
  return out;
}

std::vector<Vector2d> BackgroundWorld(const BackgroundScan& bg, const Pose2& pose) {
  std::vector<Vector2d> out;
  for (std::size_t i = 0; i < bg.ranges_mm.size(); ++i) {
    if (bg.ranges_mm[i] == 0) continue;
    const double a = bg.first_angle_rad + bg.angle_step_rad * static_cast<double>(i);
    const double r = bg.ranges_mm[i] / 1000.0;
    const Vector2d p = pose * Vector2d(r * std::cos(a), r * std::sin(a));
    if (Finite(p)) out.push_back(p);
  }
  return out;
}

std::string SensorName(const ReportInput& in, std::size_t index) {
  if (index < in.result->sensors.size()) return in.result->sensors[index].id;
  if (in.tracks != nullptr && index < in.tracks->sensors.size())
    return in.tracks->sensors[index].id;
  return "#" + std::to_string(index);
}

// Truth poses in the calibration's world (the reference sensor's frame), or nothing when the
// reference has no truth pose.
std::vector<std::pair<std::string, Pose2>> GhostPoses(const ReportInput& in) {
  std::vector<std::pair<std::string, Pose2>> out;
  if (in.truth == nullptr) return out;
  const CalibrationResult& r = *in.result;
  const auto t = in.truth->Find(r.reference);
  const SensorPose* ref = nullptr;
  for (const SensorPose& s : r.sensors)
    if (s.id == r.reference && s.calibrated) ref = &s;
  if (!t || !in.truth->calibrated[*t] || ref == nullptr) return out;
  const Pose2 world_from_truth_world =
      ref->world_from_sensor * in.truth->sensors[*t].second.inverse();
  for (std::size_t i = 0; i < in.truth->sensors.size(); ++i)
    if (in.truth->calibrated[i])
      out.emplace_back(in.truth->sensors[i].first,
                       world_from_truth_world * in.truth->sensors[i].second);
  return out;
}

// The k-sigma ellipse of a sensor's position (closed ring in the reference frame, 64 vertices);
// empty when the covariance is not finite or zero (the reference). Semi-axes capped at 1 km.
std::vector<Vector2d> SigmaEllipseWorld(const SensorPose& sp, double k) {
  const Eigen::Matrix2d c = sp.covariance.topLeftCorner<2, 2>();
  if (!c.allFinite()) return {};
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(
      Eigen::Matrix2d(0.5 * (c + c.transpose())));
  const Vector2d axes = eig.eigenvalues().cwiseMax(0.0).cwiseSqrt() * k;
  if (axes.maxCoeff() <= 0.0) return {};
  std::vector<Vector2d> ring;
  constexpr int kVertices = 64;
  for (int i = 0; i <= kVertices; ++i) {
    const double a = 2.0 * std::numbers::pi * i / kVertices;
    ring.push_back(sp.world_from_sensor.translation() +
                   eig.eigenvectors() * Vector2d(std::min(axes.x(), 1000.0) * std::cos(a),
                                                 std::min(axes.y(), 1000.0) * std::sin(a)));
  }
  return ring;
}

std::vector<SensorScene> BuildScenes(const ReportInput& in) {
  std::map<std::string, const SensorTracks*> by_id;
  if (in.tracks != nullptr)
    for (const SensorTracks& st : in.tracks->sensors) by_id.emplace(st.id, &st);
  std::vector<SensorScene> scenes;
  for (std::size_t i = 0; i < in.result->sensors.size(); ++i) {
    const SensorPose& sp = in.result->sensors[i];
    const Pose2& pose = sp.world_from_sensor;
    if (!sp.calibrated || !std::isfinite(pose.x_m) || !std::isfinite(pose.y_m) ||
        !std::isfinite(pose.yaw_rad)) {
      continue;
    }
    SensorScene scene;
    scene.index = i;
    scene.id = sp.id;
    scene.pose = pose;
    scene.color = SensorColor(i);
    const auto it = by_id.find(sp.id);
    if (it != by_id.end()) {
      const SensorTracks& st = *it->second;
      scene.fov = FovWedge(st, pose);
      if (st.background) scene.background_world = BackgroundWorld(*st.background, pose);
      for (const GridTrack& track : st.tracks) {
        std::vector<Vector2d> line;
        line.reserve(track.samples.size());
        for (const TrackSample& s : track.samples) {
          const Vector2d p = pose * s.position_m;
          if (Finite(p)) line.push_back(p);
        }
        if (!line.empty()) scene.tracks_world.push_back(std::move(line));
      }
    }
    scenes.push_back(std::move(scene));
  }
  return scenes;
}

// Points closer than `min_px` to the previous kept point are dropped: a minute of tracks at
// 20 Hz draws the same with a fraction of the vertices.
std::vector<PixelPoint> Decimate(const std::vector<Vector2d>& line, const View& v, double min_px) {
  std::vector<PixelPoint> out;
  for (const Vector2d& w : line) {
    const PixelPoint p = v.ToPx(w);
    if (!out.empty() && std::hypot(p.x - out.back().x, p.y - out.back().y) < min_px) continue;
    out.push_back(p);
  }
  if (!out.empty()) {
    const PixelPoint last = v.ToPx(line.back());
    if (out.back().x != last.x || out.back().y != last.y) out.push_back(last);
  }
  return out;
}

struct LegendEntry {
  std::string text;
  Rgba color;
  enum Kind { kSwatch, kLine, kDashedLine } kind = kSwatch;
};

void DrawLegendBox(Painter& p, const View& v, const std::vector<LegendEntry>& entries) {
  if (entries.empty()) return;
  double w = 0.0;
  for (const LegendEntry& e : entries) w = std::max(w, Canvas::TextWidth(Ascii(e.text, 40), 1));
  w += 40;
  const double h = 14.0 * static_cast<double>(entries.size()) + 8;
  const PixelPoint tl{v.PlotRight() - w - 4, v.top + 4};
  p.Rect(tl, {tl.x + w, tl.y + h}, WithAlpha(kWhite, 220));
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const double y = tl.y + 6 + 14.0 * static_cast<double>(i);
    const LegendEntry& e = entries[i];
    if (e.kind == LegendEntry::kSwatch) {
      p.Rect({tl.x + 8, y}, {tl.x + 18, y + 8}, e.color);
    } else {
      p.Line({tl.x + 6, y + 4}, {tl.x + 26, y + 4}, 2.5, e.color,
             e.kind == LegendEntry::kDashedLine, "");
    }
    p.Text({tl.x + 32, y}, Ascii(e.text, 40), 1, kBlack);
  }
}

void DrawWorld(Painter& p, const View& v, const ReportInput& in,
               const std::vector<SensorScene>& scenes,
               const std::vector<std::pair<std::string, Pose2>>& ghosts) {
  DrawGridAndScale(p, v);
  for (const SensorScene& s : scenes) {
    if (!s.fov) continue;
    std::vector<PixelPoint> poly;
    for (const Vector2d& w : ClipToView(s.fov->polygon_world, v)) poly.push_back(v.ToPx(w));
    p.Polygon(poly, WithAlpha(s.color, 34));
  }
  for (const SensorScene& s : scenes) {
    std::vector<PixelPoint> dots;
    for (const Vector2d& w : s.background_world) dots.push_back(v.ToPx(w));
    p.Dots(dots, 1.2, WithAlpha(s.color, 220));
  }
  for (const SensorScene& s : scenes)
    for (const auto& line : s.tracks_world)
      p.Polyline(Decimate(line, v, 1.5), 1.0, WithAlpha(s.color, 150));

  const double marker_px = 7.0, heading_px = 26.0;
  for (const auto& [id, pose] : ghosts) {
    const PixelPoint c = v.ToPx(pose.translation());
    const PixelPoint h = v.ToPx(pose * Vector2d(heading_px / v.px_per_m, 0.0));
    p.Marker(c, marker_px + 3, kGhost, true, "truth: " + id);
    p.Line(c, h, 1.5, kGhost, true, "");
  }
  bool any_flag = false;
  for (const SensorScene& s : scenes) {
    const SensorPose& sp = in.result->sensors[s.index];
    // The 2-sigma ellipse of the position (95 % for 2 dof is 2.45 sigma; 2 sigma is 86 %) and the
    // heading's 2-sigma fan: drawn at true scale, so a well-placed sensor shows a dot.
    const std::vector<Vector2d> ellipse = SigmaEllipseWorld(sp, 2.0);
    if (!ellipse.empty()) {
      std::vector<PixelPoint> ring;
      for (const Vector2d& w : ellipse) ring.push_back(v.ToPx(w));
      p.Polygon(ring, WithAlpha(s.color, 60));
      p.Polyline(ring, 1.5, sp.flag.empty() ? kBlack : kFlag);
    }
    const double yaw_sigma = std::sqrt(std::max(0.0, sp.covariance(2, 2)));
    if (std::isfinite(yaw_sigma) && yaw_sigma > 0.0) {
      for (const double k : {-2.0, 2.0}) {
        const Pose2 edge{s.pose.x_m, s.pose.y_m, s.pose.yaw_rad + k * std::min(yaw_sigma, 1.5)};
        p.Line(v.ToPx(s.pose.translation()), v.ToPx(edge * Vector2d(heading_px / v.px_per_m, 0.0)),
               1.0, kBlack, true, "");
      }
    }
    const PixelPoint c = v.ToPx(s.pose.translation());
    const PixelPoint h = v.ToPx(s.pose * Vector2d(heading_px / v.px_per_m, 0.0));
    p.Line(c, h, 2.5, kBlack, false, "");
    p.Marker(c, marker_px, s.color, false,
             fmt::format(
                 "{}: x={:.3f} m, y={:.3f} m, yaw={:.2f} deg; 2 sigma: {:.3f} m, {:.2f} deg{}",
                 sp.id, s.pose.x_m, s.pose.y_m, common::RadToDeg(s.pose.yaw_rad),
                 2.0 * std::sqrt(std::max(0.0, sp.covariance.topLeftCorner<2, 2>().trace())),
                 common::RadToDeg(2.0 * yaw_sigma), sp.flag.empty() ? "" : " (" + sp.flag + ")"));
    const std::string label = sp.flag.empty() ? s.id : s.id + " (!)";
    any_flag = any_flag || !sp.flag.empty();
    p.Text(LabelAt(c, label, 10, v), label, 2, sp.flag.empty() ? kBlack : kFlag);
  }

  std::vector<LegendEntry> legend;
  for (const SensorScene& s : scenes) legend.push_back({s.id, s.color});
  if (!ghosts.empty()) legend.push_back({"truth (ghost)", kGhost});
  legend.push_back({"2 sigma position, heading", kBlack, LegendEntry::kLine});
  if (any_flag) legend.push_back({"(!) flagged: see report.md", kFlag, LegendEntry::kLine});
  std::size_t uncalibrated = 0;
  for (const SensorPose& s : in.result->sensors) uncalibrated += s.calibrated ? 0 : 1;
  DrawLegendBox(p, v, legend);
  std::string title = fmt::format("calibration ({}), reference {}: {} sensors", in.result->method,
                                  in.result->reference, scenes.size());
  if (uncalibrated > 0) title += fmt::format(", {} not calibrated", uncalibrated);
  p.Text({v.left, 12}, title, 2, kBlack);
}

// ---------------------------------------------------------------------------------------------
// Edges: the pairwise estimates merged with the global step's report.

enum class EdgeClass { kUsed, kNotUsed, kRejected };

struct EdgeRow {
  std::string r, s;
  std::optional<std::size_t> ri, si;  // into result->sensors
  const PairEstimate* pair = nullptr;
  const EdgeReport* report = nullptr;

  // A pair the pairwise step rejected is rejected whatever the global step's report says of it
  // (it reports every pair, the rejected ones as not used).
  EdgeClass Class() const {
    if (pair != nullptr && !pair->accepted) return EdgeClass::kRejected;
    if (report != nullptr) return report->used ? EdgeClass::kUsed : EdgeClass::kNotUsed;
    return pair != nullptr ? EdgeClass::kNotUsed : EdgeClass::kRejected;
  }
  std::string Status() const {
    if (report != nullptr) return report->status;
    return pair != nullptr && pair->accepted ? "accepted" : "rejected";
  }
  std::string Reason() const {
    if (pair != nullptr && !pair->accepted) return pair->reason;
    if (report != nullptr && !report->used) return report->status;
    return "";
  }
  std::size_t Matches() const {
    return report != nullptr ? report->matches : pair != nullptr ? pair->matches : 0;
  }
  double RmsM() const {
    return report != nullptr ? report->rms_m : pair != nullptr ? pair->rms_m : 0.0;
  }
};

std::vector<EdgeRow> MergeEdges(const ReportInput& in) {
  std::vector<EdgeRow> rows;
  const auto index_of = [&](const std::string& id) -> std::optional<std::size_t> {
    for (std::size_t i = 0; i < in.result->sensors.size(); ++i)
      if (in.result->sensors[i].id == id) return i;
    return std::nullopt;
  };
  for (const PairEstimate& pe : in.pairs) {
    EdgeRow row;
    row.r = SensorName(in, pe.r);
    row.s = SensorName(in, pe.s);
    if (pe.r < in.result->sensors.size()) row.ri = pe.r;
    if (pe.s < in.result->sensors.size()) row.si = pe.s;
    row.pair = &pe;
    rows.push_back(std::move(row));
  }
  for (const EdgeReport& e : in.result->edges) {
    auto it = std::find_if(rows.begin(), rows.end(), [&](const EdgeRow& row) {
      return row.report == nullptr &&
             ((row.r == e.r && row.s == e.s) || (row.r == e.s && row.s == e.r));
    });
    if (it == rows.end()) {
      EdgeRow row;
      row.r = e.r;
      row.s = e.s;
      row.ri = index_of(e.r);
      row.si = index_of(e.s);
      rows.push_back(std::move(row));
      it = rows.end() - 1;
    }
    it->report = &e;
  }
  return rows;
}

void DrawGraph(Painter& p, const View& v, const ReportInput& in,
               const std::vector<Vector2d>& positions, const std::vector<EdgeRow>& edges) {
  DrawGridAndScale(p, v);
  for (int pass = 0; pass < 3; ++pass) {
    // Rejected edges underneath, used ones on top.
    const EdgeClass cls = pass == 0   ? EdgeClass::kRejected
                          : pass == 1 ? EdgeClass::kNotUsed
                                      : EdgeClass::kUsed;
    for (const EdgeRow& e : edges) {
      if (e.Class() != cls || !e.ri || !e.si) continue;
      const PixelPoint a = v.ToPx(positions[*e.ri]), b = v.ToPx(positions[*e.si]);
      const Rgba color = cls == EdgeClass::kUsed      ? kUsedEdge
                         : cls == EdgeClass::kNotUsed ? kUnusedEdge
                                                      : WithAlpha(kRejectedEdge, 200);
      std::string tooltip = e.r + " - " + e.s + ": " + e.Status();
      if (!e.Reason().empty() && e.Status().find(e.Reason()) == std::string::npos) {
        tooltip += " (" + e.Reason() + ")";
      }
      tooltip += fmt::format(", matches {}, rms {:.4f} m", e.Matches(), e.RmsM());
      p.Line(a, b, cls == EdgeClass::kRejected ? 1.5 : 2.5, color, cls == EdgeClass::kRejected,
             tooltip);
      const std::string label = cls == EdgeClass::kRejected
                                    ? Ascii(e.Reason(), 28)
                                    : fmt::format("n={} rms={:.3f}", e.Matches(), e.RmsM());
      const PixelPoint mid{(a.x + b.x) / 2, (a.y + b.y) / 2};
      p.Text({mid.x - Canvas::TextWidth(label, 1) / 2, mid.y - 10}, label, 1,
             cls == EdgeClass::kRejected ? kRejectedEdge : kBlack);
    }
  }
  for (std::size_t i = 0; i < in.result->sensors.size(); ++i) {
    const SensorPose& s = in.result->sensors[i];
    const PixelPoint c = v.ToPx(positions[i]);
    p.Marker(c, 9.0, s.calibrated ? SensorColor(i) : kGhost, !s.calibrated,
             s.calibrated ? s.id : s.id + " (not calibrated)");
    const std::string label = s.calibrated ? s.id : s.id + " (not calibrated)";
    p.Text(LabelAt(c, label, 12, v), label, 2, kBlack);
  }
  DrawLegendBox(p, v,
                {{"used", kUsedEdge, LegendEntry::kLine},
                 {"accepted, not used", kUnusedEdge, LegendEntry::kLine},
                 {"rejected (reason on the edge)", kRejectedEdge, LegendEntry::kDashedLine}});
  p.Text({v.left, 12}, fmt::format("pairwise graph: {} pairs", edges.size()), 2, kBlack);
}

// Graph node positions: calibrated sensors where they are, the others in a row underneath.
std::vector<Vector2d> GraphPositions(const CalibrationResult& r) {
  std::vector<Vector2d> pos(r.sensors.size(), Vector2d::Zero());
  double min_x = kInf, max_x = -kInf, min_y = kInf, max_y = -kInf;
  std::vector<std::size_t> loose;
  for (std::size_t i = 0; i < r.sensors.size(); ++i) {
    const Vector2d t = r.sensors[i].world_from_sensor.translation();
    if (!r.sensors[i].calibrated || !Finite(t)) {
      loose.push_back(i);
      continue;
    }
    pos[i] = t;
    min_x = std::min(min_x, t.x());
    max_x = std::max(max_x, t.x());
    min_y = std::min(min_y, t.y());
    max_y = std::max(max_y, t.y());
  }
  if (!(min_x <= max_x)) min_x = max_x = min_y = max_y = 0.0;
  const double extent = std::max({max_x - min_x, max_y - min_y, 4.0});
  for (std::size_t k = 0; k < loose.size(); ++k) {
    const double f =
        loose.size() == 1 ? 0.5 : static_cast<double>(k) / static_cast<double>(loose.size() - 1);
    pos[loose[k]] = {min_x + f * std::max(max_x - min_x, 4.0), min_y - 0.25 * extent};
  }
  return pos;
}

// ---------------------------------------------------------------------------------------------
// Files.

bool WriteFile(const std::filesystem::path& path, const std::string& bytes, std::string* error) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (out) out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) {
    *error = path.string() + ": cannot write";
    return false;
  }
  return true;
}

bool WriteBoth(const std::filesystem::path& dir, const std::string& stem, const View& v,
               const std::function<void(Painter&)>& draw, std::string* error) {
  SvgPainter svg(v.width, v.height);
  draw(svg);
  if (!WriteFile(dir / (stem + ".svg"), svg.Finish(), error)) return false;
  Canvas canvas(v.width, v.height, kWhite);
  CanvasPainter painter(&canvas);
  draw(painter);
  const std::vector<std::uint8_t> png = EncodePng(canvas);
  if (png.empty()) {
    *error = (dir / (stem + ".png")).string() + ": PNG encoding failed";
    return false;
  }
  return WriteFile(dir / (stem + ".png"), std::string(png.begin(), png.end()), error);
}

std::string EdgesCsv(const std::vector<EdgeRow>& edges) {
  std::string csv =
      "r,s,status,reason,accepted,used,intervals,hypotheses,best_error,second_error,matches,"
      "rms_m,mean_residual_m,rotation_residual_deg,translation_residual_m,track_residual_rms_m,"
      "icp_applied,icp_score_before,icp_score_after\n";
  const auto g = [](double v) { return std::isfinite(v) ? fmt::format("{:.6g}", v) : Num(v, 0); };
  for (const EdgeRow& e : edges) {
    const PairEstimate* pe = e.pair;
    const EdgeReport* er = e.report;
    const bool accepted = pe != nullptr ? pe->accepted : er != nullptr;
    csv += fmt::format(
        "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n", Csv(e.r), Csv(e.s),
        Csv(e.Status()), Csv(e.Reason()), accepted ? 1 : 0, er != nullptr && er->used ? 1 : 0,
        pe ? std::to_string(pe->intervals) : "", pe ? std::to_string(pe->hypotheses) : "",
        pe ? g(pe->best_error) : "", pe ? g(pe->second_error) : "", e.Matches(), g(e.RmsM()),
        pe ? g(pe->mean_residual_m) : "", er ? g(er->rotation_residual_deg) : "",
        er ? g(er->translation_residual_m) : "", er ? g(er->track_residual_rms_m) : "",
        (er ? er->icp_applied : pe != nullptr && pe->icp_applied) ? 1 : 0,
        pe ? g(pe->icp_score_before) : "", pe ? g(pe->icp_score_after) : "");
  }
  return csv;
}

struct Stats {
  double mean = 0.0, median = 0.0, max = 0.0;
};
Stats StatsOf(std::vector<double> v) {
  Stats s;
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  double sum = 0.0;
  for (const double x : v) sum += x;
  s.mean = sum / static_cast<double>(v.size());
  const std::size_t n = v.size();
  s.median = n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
  s.max = v.back();
  return s;
}

std::string SummaryMd(const ReportInput& in, const std::vector<EdgeRow>& edges) {
  const CalibrationResult& r = *in.result;
  std::size_t calibrated = 0, used = 0, not_used = 0, rejected = 0;
  for (const SensorPose& s : r.sensors) calibrated += s.calibrated ? 1 : 0;
  for (const EdgeRow& e : edges) {
    switch (e.Class()) {
      case EdgeClass::kUsed:
        ++used;
        break;
      case EdgeClass::kNotUsed:
        ++not_used;
        break;
      case EdgeClass::kRejected:
        ++rejected;
        break;
    }
  }
  // Errors against the truth, when there is one.
  std::optional<EvalResult> eval;
  if (in.truth != nullptr) {
    eval = Evaluate(PoseFileOf(r), *in.truth, std::nullopt);
  }
  const auto error_of = [&](const std::string& id) -> const SensorError* {
    if (!eval || !eval->ok) return nullptr;
    for (const SensorError& e : eval->sensors)
      if (e.id == id) return &e;
    return nullptr;
  };

  std::string md = "# Calibration report\n\n";
  md += fmt::format("- method: {}\n- reference: {}\n- sensors calibrated: {} of {}\n", Md(r.method),
                    Md(r.reference), calibrated, r.sensors.size());
  md += fmt::format("- pairs: {} (used {}, accepted but not used {}, rejected {})\n", edges.size(),
                    used, not_used, rejected);
  if (r.refined) {
    const double gain =
        r.refine_cost_before > 0.0
            ? 100.0 * (r.refine_cost_before - r.refine_cost_after) / r.refine_cost_before
            : 0.0;
    md += fmt::format(
        "- joint refinement: applied; robust cost {:.6g} -> {:.6g} ({:.1f} % lower) over {} "
        "observations\n",
        r.refine_cost_before, r.refine_cost_after, gain, r.refine_observations);
  } else {
    md += "- joint refinement: not applied\n";
  }
  md += fmt::format("- track residual rms: {} m\n", Num(r.track_residual_rms_m, 4));
  std::size_t flagged = 0;
  for (const SensorPose& s : r.sensors) flagged += s.flag.empty() ? 0 : 1;
  md += fmt::format("- sensors flagged: {}\n", flagged);
  for (const SensorPose& s : r.sensors) {
    if (!s.flag.empty()) md += "  - " + Md(s.id) + ": " + Md(s.flag) + "\n";
  }
  if (!r.ambiguity.empty()) md += "- not decided by the data: " + Md(r.ambiguity) + "\n";
  if (!r.scale_note.empty()) md += "- " + Md(r.scale_note) + "\n";
  if (!r.hypotheses.empty()) {
    md +=
        "- placements compared where the pose graph's cycles could not decide (robust cost over "
        "all observations, lower is better):\n";
    for (const HypothesisReport& h : r.hypotheses) {
      md += fmt::format("  - {}: {}{}\n", Md(h.description), Num(h.cost, 1),
                        h.chosen ? " (chosen)" : "");
    }
  }
  md += "\n";
  md +=
      "![sensors, fields of view, background scans and tracks in the reference frame]"
      "(calibration.png)\n\n![pairwise graph](graph.png)\n\n";

  md +=
      "## Poses\n\nIn the frame of the reference sensor; sigma = one standard deviation (the "
      "picture draws 2 sigma).";
  // The joint refinement's shared radial bias per sensor, where it ran.
  bool any_bias = false;
  for (const SensorPose& s : r.sensors) any_bias = any_bias || (s.calibrated && s.radial_bias);
  if (any_bias) {
    md +=
        " Radial bias: how far the sensor's people's centres lie towards it along its line of "
        "sight beyond the measurement model, +- one standard deviation after the joint "
        "refinement; \"estimated\" from the data, or \"prior\": the data do not observe it, "
        "held at 0 and its prior carried in the pose sigmas.";
  }
  md += "\n\n";
  md += "| sensor | x [m] | y [m] | yaw [deg] | sigma x [m] | sigma y [m] | sigma yaw [deg] |";
  if (any_bias) md += " radial bias [m] |";
  md += eval ? " d_R [deg] | d_t [m] |\n" : "\n";
  md += "|---|--:|--:|--:|--:|--:|--:|";
  if (any_bias) md += "--:|";
  md += eval ? "--:|--:|\n" : "\n";
  for (const SensorPose& s : r.sensors) {
    if (!s.calibrated) {
      md += "| " + Md(s.id) + (s.flag.empty() ? "" : " (!)") + " | not calibrated | | | | | |" +
            (any_bias ? " |" : "") + (eval ? " | |\n" : "\n");
      continue;
    }
    const Pose2& p = s.world_from_sensor;
    const auto sigma = [&](int i) { return std::sqrt(std::max(0.0, s.covariance(i, i))); };
    md += fmt::format("| {}{} | {} | {} | {} | {} | {} | {} |", Md(s.id),
                      s.flag.empty() ? "" : " (!)", Num(p.x_m, 4), Num(p.y_m, 4),
                      Num(common::RadToDeg(p.yaw_rad), 3), Num(sigma(0), 4), Num(sigma(1), 4),
                      Num(common::RadToDeg(sigma(2)), 3));
    if (any_bias) {
      md += s.radial_bias ? fmt::format(" {} +- {} ({}) |", Num(s.radial_bias->bias_m, 4),
                                        Num(s.radial_bias->sigma_m, 4),
                                        s.radial_bias->estimated ? "estimated" : "prior")
                          : std::string(" |");
    }
    if (eval) {
      const SensorError* e = error_of(s.id);
      md += e != nullptr ? fmt::format(" {:.4f} | {:.4f} |", e->d_r_deg, e->d_t_m)
                         : std::string(s.id == r.reference ? " (reference) | |" : " | |");
    }
    md += "\n";
  }
  if (eval) {
    md += "\n";
    if (eval->ok) {
      md += fmt::format(
          "Against the truth (both in the frame of {}): d_R mean {:.4f} deg, median {:.4f} deg; "
          "d_t mean {:.4f} m, median {:.4f} m.\n",
          Md(eval->reference), eval->mean_d_r_deg, eval->median_d_r_deg, eval->mean_d_t_m,
          eval->median_d_t_m);
      if (!eval->missing.empty()) {
        std::string ids;
        for (const std::string& id : eval->missing) ids += (ids.empty() ? "" : ", ") + Md(id);
        md += "In the truth but not calibrated: " + ids + ".\n";
      }
    } else {
      md += "No comparison with the truth: " + Md(eval->error) + ".\n";
    }
  }

  md += "\n## Edges\n\nOne row per sensor pair considered (edges.csv has every field).\n\n";
  md +=
      "| r | s | status | matches | rms [m] | rotation residual [deg] | translation residual [m] "
      "| track rms [m] | ICP |\n|---|---|---|--:|--:|--:|--:|--:|---|\n";
  std::vector<double> rot, trans, track;
  for (const EdgeRow& e : edges) {
    // The reason once: a status that already says it ("rejected: <reason>") stays as it is.
    std::string status = e.Status();
    const std::string reason = e.Reason();
    if (!reason.empty() && status.find(reason) == std::string::npos) status += ": " + reason;
    const EdgeReport* er = e.report;
    md += fmt::format(
        "| {} | {} | {} | {} | {} | {} | {} | {} | {} |\n", Md(e.r), Md(e.s), Md(status),
        e.Matches(), Num(e.RmsM(), 4), er ? Num(er->rotation_residual_deg, 4) : "",
        er ? Num(er->translation_residual_m, 4) : "", er ? Num(er->track_residual_rms_m, 4) : "",
        (er ? er->icp_applied : e.pair != nullptr && e.pair->icp_applied) ? "yes" : "no");
    if (er != nullptr && er->used) {
      rot.push_back(er->rotation_residual_deg);
      trans.push_back(er->translation_residual_m);
      track.push_back(er->track_residual_rms_m);
    }
  }
  if (!rot.empty()) {
    md += fmt::format("\nResiduals over the {} used edges:\n\n", rot.size());
    md += "| quantity | mean | median | max |\n|---|--:|--:|--:|\n";
    const auto row = [&](const char* name, const std::vector<double>& v) {
      const Stats s = StatsOf(v);
      md += fmt::format("| {} | {} | {} | {} |\n", name, Num(s.mean, 4), Num(s.median, 4),
                        Num(s.max, 4));
    };
    row("rotation residual [deg]", rot);
    row("translation residual [m]", trans);
    row("track residual rms [m]", track);
  }

  md += "\n## Timings\n\n";
  if (r.timings.empty()) {
    md += "(not measured)\n";
  } else {
    md += "| stage | seconds |\n|---|--:|\n";
    double total = 0.0;
    for (const StageTime& t : r.timings) {
      md += fmt::format("| {} | {} |\n", Md(t.stage), Num(t.seconds, 4));
      total += t.seconds;
    }
    md += fmt::format("| total | {} |\n", Num(total, 4));
  }
  md += "\n## Warnings\n\n";
  if (r.warnings.empty()) md += "(none)\n";
  for (const std::string& w : r.warnings) md += "- " + Md(w) + "\n";
  return md;
}

}  // namespace

bool WriteReport(const std::string& dir, const ReportInput& input, std::string* error) {
  if (input.result == nullptr) {
    *error = "report: no calibration result";
    return false;
  }
  const std::filesystem::path base(dir);
  std::error_code ec;
  std::filesystem::create_directories(base, ec);
  if (ec || !std::filesystem::is_directory(base, ec)) {
    *error = dir + ": cannot create the report folder" + (ec ? " (" + ec.message() + ")" : "");
    return false;
  }

  const std::vector<SensorScene> scenes = BuildScenes(input);
  const auto ghosts = GhostPoses(input);
  // The picture spans what the sensors saw (backgrounds, tracks); the fields of view are cut at
  // its border, or span it when nothing was seen.
  std::vector<Vector2d> extent;
  for (const SensorScene& s : scenes) {
    extent.push_back(s.pose.translation());
    extent.insert(extent.end(), s.background_world.begin(), s.background_world.end());
    for (const auto& line : s.tracks_world) extent.insert(extent.end(), line.begin(), line.end());
  }
  for (const auto& g : ghosts) extent.push_back(g.second.translation());
  if (extent.size() <= scenes.size() + ghosts.size()) {
    for (const SensorScene& s : scenes)
      if (s.fov)
        extent.insert(extent.end(), s.fov->polygon_world.begin(), s.fov->polygon_world.end());
  }
  const View world_view = FitView(extent, 4.0, 1100.0);
  if (!WriteBoth(
          base, "calibration", world_view,
          [&](Painter& p) { DrawWorld(p, world_view, input, scenes, ghosts); }, error)) {
    return false;
  }

  const std::vector<EdgeRow> edges = MergeEdges(input);
  const std::vector<Vector2d> positions = GraphPositions(*input.result);
  const View graph_view = FitView(positions, 4.0, 900.0);
  if (!WriteBoth(
          base, "graph", graph_view,
          [&](Painter& p) { DrawGraph(p, graph_view, input, positions, edges); }, error)) {
    return false;
  }
  if (!WriteFile(base / "edges.csv", EdgesCsv(edges), error)) return false;
  return WriteFile(base / "summary.md", SummaryMd(input, edges), error);
}

}  // namespace lrfnet::calib
