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

double RaySuperellipse(const Ray& ray, Vec2 center, double a, double b, double exponent,
                       double yaw_rad) {
  if (exponent == 2.0) return RayEllipse(ray, center, a, b, yaw_rad);
  // The superellipse lies inside the rectangle [-a, a] x [-b, b]: start where the ray enters it.
  const double t_box = RayBox(ray, center, a, b, yaw_rad);
  if (t_box == kNoHit) return kNoHit;
  const double c = std::cos(yaw_rad), s = std::sin(yaw_rad);
  const Vec2 d = ray.origin - center;
  // Local coordinates scaled to the unit superellipse: q(t) = o + t v.
  const Vec2 o{(c * d.x + s * d.y) / a, (-s * d.x + c * d.y) / b};
  const Vec2 v{(c * ray.dir.x + s * ray.dir.y) / a, (-s * ray.dir.x + c * ray.dir.y) / b};
  const double p = exponent;
  // F(t) = |qx|^p + |qy|^p - 1 is convex along the line; from a point where F > 0 on the near side
  // Newton's iterates increase monotonically to the first root, or F' stops being negative (miss).
  double t = t_box;
  for (int iter = 0; iter < 60; ++iter) {
    const double qx = o.x + t * v.x, qy = o.y + t * v.y;
    const double ax = std::abs(qx), ay = std::abs(qy);
    const double px = std::pow(ax, p - 1.0), py = std::pow(ay, p - 1.0);
    const double f = px * ax + py * ay - 1.0;
    if (f <= 1e-12) return t > kMinHitDistanceM ? t : kNoHit;
    const double df = p * (px * (qx < 0 ? -v.x : v.x) + py * (qy < 0 ? -v.y : v.y));
    if (!(df < 0.0)) return kNoHit;
    const double step = -f / df;
    t += step;
    if (step < 1e-10) return t > kMinHitDistanceM ? t : kNoHit;
  }
  return kNoHit;
}

double RayBox(const Ray& ray, Vec2 center, double a, double b, double yaw_rad) {
  const double c = std::cos(yaw_rad), s = std::sin(yaw_rad);
  const Vec2 d = ray.origin - center;
  const double o[2] = {c * d.x + s * d.y, -s * d.x + c * d.y};
  const double v[2] = {c * ray.dir.x + s * ray.dir.y, -s * ray.dir.x + c * ray.dir.y};
  const double half[2] = {a, b};
  if (std::abs(o[0]) <= a && std::abs(o[1]) <= b) return kNoHit;  // origin inside
  // Slabs: the ray is inside both between the larger entry and the smaller exit.
  double enter = -kNoHit, leave = kNoHit;
  for (int k = 0; k < 2; ++k) {
    if (std::abs(v[k]) < 1e-15) {
      if (std::abs(o[k]) > half[k]) return kNoHit;
      continue;
    }
    double t0 = (-half[k] - o[k]) / v[k], t1 = (half[k] - o[k]) / v[k];
    if (t0 > t1) std::swap(t0, t1);
    enter = std::max(enter, t0);
    leave = std::min(leave, t1);
  }
  if (enter > leave || enter <= kMinHitDistanceM) return kNoHit;
  return enter;
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
