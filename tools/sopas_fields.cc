#include "tools/sopas_fields.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <optional>

namespace lrfnet::tools {

using cola::SopasValues;
using S = cola::SopasScalar;

namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

struct Point {
  double x = 0, y = 0;  // metres, x forward, y left
};

// sick_scan_xd's segmentedFieldPointToCarthesian: `raw_deg` in the telegram's convention.
Point PolarPoint(double range_m, double raw_deg) {
  const double a = raw_deg * kDegToRad;
  return {range_m * std::sin(a), -range_m * std::cos(a)};
}

std::string FieldName(int i) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "field%03d", i);
  return buf;
}

// A configured field as a polygon; nullopt for a slot without a field.
struct FieldShape {
  int number = 0;
  float dist_scale = 1.0f;
  float dist_offset = 0.0f;
  std::uint32_t angle_scale = 0;
  std::int32_t angle_offset = 0;
  std::vector<Point> polygon;
};

std::optional<FieldShape> ParseField(const SopasValues& v, double rect_ref_offset_deg) {
  // Positions follow kFieldSchema; a slot answered with one byte has no field.
  if (v.size() < 13) return std::nullopt;
  FieldShape f;
  f.dist_scale = v[0].AsFloat();
  f.dist_offset = v[1].AsFloat();
  f.angle_scale = v[2].bits;
  f.angle_offset = static_cast<std::int32_t>(v[3].AsInt());
  f.number = static_cast<int>(v[5].AsInt());
  const auto dist_m = [&](std::int64_t raw) {
    return (static_cast<double>(raw) * f.dist_scale + f.dist_offset) / 1000.0;
  };
  std::size_t k = 6;
  if (v[k].AsInt() != 0) {  // segmented
    const auto n = static_cast<std::size_t>(v[k + 1].AsInt());
    if (v.size() < k + 2 + 3 * n) return std::nullopt;
    f.polygon.push_back({0, 0});
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t p = k + 2 + 3 * i;
      const double raw_deg =
          (static_cast<double>(v[p].AsInt()) * f.angle_scale + f.angle_offset) / 10000.0;
      f.polygon.push_back(PolarPoint(dist_m(v[p + 2].AsInt()), raw_deg));
    }
    k += 2 + 3 * n;
  } else {
    k += 1;
  }
  const auto rectangle = [&](std::size_t p) {
    const double ref_deg = static_cast<double>(v[p].AsInt()) / 10000.0 + f.angle_offset / 10000.0 -
                           rect_ref_offset_deg;
    const Point ref = PolarPoint(dist_m(v[p + 1].AsInt()), ref_deg);
    const double rot = static_cast<double>(v[p + 2].AsInt()) / 10000.0 * kDegToRad;
    const double w = static_cast<double>(v[p + 3].bits) / 1000.0;
    const double l = static_cast<double>(v[p + 4].bits) / 1000.0;
    for (const Point c : {Point{0, 0}, Point{0, -w}, Point{l, -w}, Point{l, 0}}) {
      f.polygon.push_back({ref.x + c.x * std::cos(rot) - c.y * std::sin(rot),
                           ref.y + c.x * std::sin(rot) + c.y * std::cos(rot)});
    }
  };
  if (k >= v.size()) return std::nullopt;
  if (v[k].AsInt() != 0) {  // rectangle
    if (v.size() < k + 6) return std::nullopt;
    if (f.polygon.empty()) rectangle(k + 1);
    k += 6;
  } else {
    k += 1;
  }
  k += 1;  // radial flag
  if (k < v.size() && v[k].AsInt() != 0 && v.size() >= k + 8 && f.polygon.empty()) {
    rectangle(k + 1);  // dynamic: its rectangle at standstill
  }
  if (f.number == 0 || f.polygon.size() < 3) return std::nullopt;
  return f;
}

bool Inside(const std::vector<Point>& poly, Point p) {
  bool in = false;
  for (std::size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++) {
    const Point a = poly[i];
    const Point b = poly[j];
    if ((a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x) {
      in = !in;
    }
  }
  return in;
}

void AppendTime(std::uint32_t tick_us, SopasValues* out) {
  const std::uint32_t s = tick_us / 1'000'000u;
  out->push_back(S::U16(1970));
  out->push_back(S::U8(1));
  out->push_back(S::U8(1));
  out->push_back(S::U8((s / 3600) % 24));
  out->push_back(S::U8((s / 60) % 60));
  out->push_back(S::U8(s % 60));
  out->push_back(S::U32(tick_us % 1'000'000u));
}

SopasValues EmptyField(const ScanGeometry& g) {
  return {S::F32(1.0f),
          S::F32(0.0f),
          S::U32(g.angle_step_raw),
          S::I32(g.start_angle_raw),
          S::U8(2),
          S::U8(0),
          S::U16(0),
          S::U16(0),
          S::U16(0),
          S::U16(0),
          S::U16(1),
          S::Str(""),
          S::U16(0)};
}

}  // namespace

std::string OutputStateSchema(int outputs) {
  return "u16 u32 " + std::to_string(outputs) + "*[u8 u32] u16?[u16 u8 u8 u8 u8 u8 u32]";
}

SopasValues DefaultField(const ScanGeometry& g, int index, double rect_ref_offset_deg) {
  SopasValues v = EmptyField(g);
  if (index == 0) {
    // Segmented field #1: 1 m ahead over the front 90° (45° .. 135° in the telegram's angles, as
    // far as the field of view reaches), nine points. (Over the whole field of view a 270° device
    // mounted at a wall would see the wall inside it.)
    v[4] = S::U8(2);
    v[5] = S::U8(1);
    v[6] = S::U16(1);
    const auto index_of = [&](std::int64_t raw_angle) {
      const double i = static_cast<double>(raw_angle - g.start_angle_raw) / g.angle_step_raw;
      return std::clamp<std::int64_t>(std::llround(i), 0, g.count - 1);
    };
    const std::int64_t first = index_of(450000);
    const std::int64_t last = index_of(1350000);
    SopasValues seg = {S::U16(9)};
    for (int i = 0; i < 9; ++i) {
      const auto idx = static_cast<std::uint32_t>(first + (last - first) * i / 8);
      seg.push_back(S::U16(idx));
      seg.push_back(S::U16(0));
      seg.push_back(S::U16(1000));
    }
    v.insert(v.begin() + 7, seg.begin(), seg.end());
    v[v.size() - 2] = S::Str("near");
  } else if (index == 1) {
    // Rectangle #2: x in [1, 3] m, y in [-0.5, 0.5] m; the base corner at (1 m, 0.5 m).
    v[4] = S::U8(1);
    v[5] = S::U8(2);
    const double ref_raw_deg = std::atan2(0.5, 1.0) / kDegToRad + 90.0;
    const double ref_field = ref_raw_deg - g.start_angle_raw / 10000.0 + rect_ref_offset_deg;
    const SopasValues rect = {
        S::U16(1),
        S::I32(static_cast<std::int32_t>(std::lround(ref_field * 10000.0))),
        S::U16(static_cast<std::uint32_t>(std::lround(std::hypot(1.0, 0.5) * 1000.0))),
        S::I32(0),
        S::U32(1000),
        S::U32(2000)};
    v.erase(v.begin() + 7);                             // the rectangle flag 0 ...
    v.insert(v.begin() + 7, rect.begin(), rect.end());  // ... becomes the flag 1 and its values
    v[v.size() - 2] = S::Str("front");
  }
  return v;
}

std::vector<std::uint8_t> EvaluateFields(const FieldFamily& family, const SopasValueMap& values,
                                         const cola::ScanTelegram& scan) {
  std::vector<std::uint8_t> results(static_cast<std::size_t>(family.fields), 0);
  const cola::ScanChannel* dist = scan.FindChannel("DIST1");
  std::vector<Point> points;
  if (dist != nullptr) {
    points.reserve(dist->count);
    for (std::size_t i = 0; i < dist->count; ++i) {
      if (dist->raw[i] == 0) continue;  // no echo
      const double raw_deg =
          (dist->start_angle_raw + static_cast<double>(i) * dist->angle_step_raw) / 10000.0;
      points.push_back(PolarPoint(dist->RangeM(i), raw_deg));
    }
  }
  for (int i = 0; i < family.fields; ++i) {
    const auto it = values.find(FieldName(i));
    if (it == values.end()) continue;
    const auto field = ParseField(it->second, family.rect_ref_offset_deg);
    if (!field) continue;
    std::uint8_t r = 1;
    for (const Point p : points) {
      if (Inside(field->polygon, p)) {
        r = 2;
        break;
      }
    }
    results[static_cast<std::size_t>(i)] = r;
  }
  return results;
}

SopasValues InputStateValues(std::uint16_t version, std::uint8_t input_state, bool time_block,
                             std::uint32_t tick_us) {
  SopasValues v = {S::U16(version),           S::U32(tick_us),    S::U8(input_state),
                   S::U8(input_state),        S::U8(input_state), S::U8(input_state),
                   S::U16(time_block ? 1 : 0)};
  if (time_block) AppendTime(tick_us, &v);
  return v;
}

SopasValues OutputStateValues(std::uint16_t version, const std::vector<std::uint8_t>& states,
                              const std::vector<std::uint32_t>& counts, bool time_block,
                              std::uint32_t tick_us) {
  SopasValues v = {S::U16(version), S::U32(tick_us)};
  for (std::size_t i = 0; i < states.size(); ++i) {
    v.push_back(S::U8(states[i]));
    v.push_back(S::U32(counts[i]));
  }
  v.push_back(S::U16(time_block ? 1 : 0));
  if (time_block) AppendTime(tick_us, &v);
  return v;
}

SopasValues LfeRecValues(const FieldFamily& family, const SopasValueMap& values,
                         const std::vector<std::uint8_t>& results, std::uint32_t tick_us) {
  std::vector<int> slots;
  if (family.field_sets) {
    // The three fields of the active field set (TiM781S: field indices 1, 2, 3 for set 1).
    const auto it = values.find("ActiveFieldSet");
    const int set =
        it != values.end() && !it->second.empty() ? static_cast<int>(it->second[0].AsInt()) : 1;
    for (int k = 0; k < 3; ++k) slots.push_back((set - 1) * 3 + k);
  } else {
    for (int i = 0; i < family.fields; ++i) {
      const auto it = values.find(FieldName(i));
      if (it != values.end() && it->second.size() >= 13 && it->second[5].AsInt() != 0) {
        slots.push_back(i);
      }
    }
  }
  SopasValues v = {S::U16(static_cast<std::uint32_t>(slots.size()))};
  for (const int i : slots) {
    const auto it = values.find(FieldName(i));
    const bool structured = it != values.end() && it->second.size() >= 13;
    v.push_back(S::U16(1));
    v.push_back(S::U8(static_cast<std::uint32_t>(family.field_sets ? i % 3 + 1 : i + 1)));
    v.push_back(S::U32(tick_us));
    v.push_back(structured ? it->second[0] : S::F32(1.0f));
    v.push_back(structured ? it->second[1] : S::F32(0.0f));
    v.push_back(structured ? it->second[2] : S::U32(0));
    v.push_back(structured ? it->second[3] : S::I32(0));
    v.push_back(
        S::U8(i < static_cast<int>(results.size()) ? results[static_cast<std::size_t>(i)] : 0));
    v.push_back(S::U16(0));
    v.push_back(S::U16(0));
    v.push_back(S::U16(0));
    v.push_back(S::U16(1));
    AppendTime(tick_us, &v);
  }
  return v;
}

}  // namespace lrfnet::tools
