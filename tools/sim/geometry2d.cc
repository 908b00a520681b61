#include "tools/sim/geometry2d.h"

#include <algorithm>
#include <cmath>

namespace lrfnet::sim {

namespace {
// Rays starting on a surface must not hit it again at distance ~0.
constexpr double kMinHitDistanceM = 1e-9;

int Orientation(Vec2 a, Vec2 b, Vec2 c) {
  const double v = Cross(b - a, c - a);
  const double scale = std::max({1.0, std::abs(a.x), std::abs(a.y), std::abs(b.x), std::abs(b.y),
                                 std::abs(c.x), std::abs(c.y)});
  if (std::abs(v) <= 1e-12 * scale * scale) return 0;
  return v > 0 ? 1 : -1;
}

bool OnSegment(Vec2 a, Vec2 b, Vec2 p) {
  return std::min(a.x, b.x) - 1e-12 <= p.x && p.x <= std::max(a.x, b.x) + 1e-12 &&
         std::min(a.y, b.y) - 1e-12 <= p.y && p.y <= std::max(a.y, b.y) + 1e-12;
}
}  // namespace

double Norm(Vec2 a) { return std::hypot(a.x, a.y); }

double RaySegment(const Ray& ray, const Segment& s) {
  const Vec2 e = s.b - s.a;
  const double den = Cross(ray.dir, e);
  if (std::abs(den) < 1e-15) return kNoHit;
  const Vec2 ao = s.a - ray.origin;
  const double t = Cross(ao, e) / den;
  const double u = Cross(ao, ray.dir) / den;
  if (t <= kMinHitDistanceM || u < 0.0 || u > 1.0) return kNoHit;
  return t;
}

double RayCircle(const Ray& ray, Vec2 center, double radius) {
  const Vec2 oc = center - ray.origin;
  const double b = Dot(ray.dir, oc);
  const double c = Dot(oc, oc) - radius * radius;
  if (c <= 0.0) return kNoHit;  // origin inside
  const double disc = b * b - c;
  if (disc < 0.0 || b <= 0.0) return kNoHit;
  const double t = b - std::sqrt(disc);
  return t > kMinHitDistanceM ? t : kNoHit;
}

double RayEllipse(const Ray& ray, Vec2 center, double a, double b, double yaw_rad) {
  // In the ellipse frame scaled to a unit circle the ray stays a line; its parameter t is the same.
  const double c = std::cos(yaw_rad), s = std::sin(yaw_rad);
  const Vec2 d = ray.origin - center;
  const Vec2 o{(c * d.x + s * d.y) / a, (-s * d.x + c * d.y) / b};
  const Vec2 v{(c * ray.dir.x + s * ray.dir.y) / a, (-s * ray.dir.x + c * ray.dir.y) / b};
  const double qa = Dot(v, v);
  const double qb = Dot(o, v);
  const double qc = Dot(o, o) - 1.0;
  if (qc <= 0.0) return kNoHit;  // origin inside
  const double disc = qb * qb - qa * qc;
  if (disc < 0.0 || qb >= 0.0) return kNoHit;
  const double t = (-qb - std::sqrt(disc)) / qa;
  return t > kMinHitDistanceM ? t : kNoHit;
}

bool SegmentsIntersect(const Segment& s, const Segment& t) {
  const int o1 = Orientation(s.a, s.b, t.a);
  const int o2 = Orientation(s.a, s.b, t.b);
  const int o3 = Orientation(t.a, t.b, s.a);
  const int o4 = Orientation(t.a, t.b, s.b);
  if (o1 != o2 && o3 != o4) return true;
  if (o1 == 0 && OnSegment(s.a, s.b, t.a)) return true;
  if (o2 == 0 && OnSegment(s.a, s.b, t.b)) return true;
  if (o3 == 0 && OnSegment(t.a, t.b, s.a)) return true;
  if (o4 == 0 && OnSegment(t.a, t.b, s.b)) return true;
  return false;
}

double PointSegmentDistance(Vec2 p, const Segment& s) {
  const Vec2 e = s.b - s.a;
  const double len2 = Dot(e, e);
  double u = len2 > 0.0 ? Dot(p - s.a, e) / len2 : 0.0;
  u = std::clamp(u, 0.0, 1.0);
  return Norm(p - (s.a + u * e));
}

double SegmentSegmentDistance(const Segment& s, const Segment& t) {
  if (SegmentsIntersect(s, t)) return 0.0;
  return std::min({PointSegmentDistance(s.a, t), PointSegmentDistance(s.b, t),
                   PointSegmentDistance(t.a, s), PointSegmentDistance(t.b, s)});
}

bool PointInPolygon(Vec2 p, const std::vector<Vec2>& polygon) {
  bool inside = false;
  const std::size_t n = polygon.size();
  for (std::size_t i = 0, j = n - 1; i < n; j = i++) {
    const Vec2 a = polygon[i], b = polygon[j];
    if ((a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x) {
      inside = !inside;
    }
  }
  return inside;
}

double PolygonArea(const std::vector<Vec2>& polygon) {
  double twice = 0.0;
  const std::size_t n = polygon.size();
  for (std::size_t i = 0; i < n; ++i) twice += Cross(polygon[i], polygon[(i + 1) % n]);
  return 0.5 * twice;
}

std::vector<Segment> PolygonEdges(const std::vector<Vec2>& polygon) {
  std::vector<Segment> edges;
  const std::size_t n = polygon.size();
  edges.reserve(n);
  for (std::size_t i = 0; i < n; ++i) edges.push_back({polygon[i], polygon[(i + 1) % n]});
  return edges;
}

std::optional<std::string> CheckSimplePolygon(const std::vector<Vec2>& polygon) {
  const std::size_t n = polygon.size();
  if (n < 3) return "a polygon needs at least 3 vertices, got " + std::to_string(n);
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j) {
      if (Norm(polygon[i] - polygon[j]) < 1e-9) {
        return "vertices " + std::to_string(i) + " and " + std::to_string(j) +
               " are the same point";
      }
    }
  }
  const std::vector<Segment> edges = PolygonEdges(polygon);
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j) {
      const bool adjacent = j == i + 1 || (i == 0 && j == n - 1);
      if (adjacent) {
        // Adjacent edges share one vertex; they must not fold back onto each other.
        const Vec2 shared = j == i + 1 ? edges[i].b : edges[i].a;
        const Vec2 p = j == i + 1 ? edges[i].a : edges[i].b;
        const Vec2 q = j == i + 1 ? edges[j].b : edges[j].a;
        if (Orientation(p, shared, q) == 0 && Dot(p - shared, q - shared) > 0.0) {
          return "edges " + std::to_string(i) + " and " + std::to_string(j) + " overlap";
        }
        continue;
      }
      if (SegmentsIntersect(edges[i], edges[j])) {
        return "edges " + std::to_string(i) + " and " + std::to_string(j) + " cross";
      }
    }
  }
  if (std::abs(PolygonArea(polygon)) < 1e-9) return "the polygon has no area";
  return std::nullopt;
}

}  // namespace lrfnet::sim
