#pragma once
// Planar primitives for the simulator's world: segments, polygons and ray intersections. Pure
// functions over value types; metres and radians, world frame unless a name says otherwise.

#include <cstddef>
#include <limits>
#include <optional>
#include <string>
#include <vector>

namespace lrfnet::sim {

inline constexpr double kNoHit = std::numeric_limits<double>::infinity();

struct Vec2 {
  double x = 0.0;
  double y = 0.0;
};
inline Vec2 operator+(Vec2 a, Vec2 b) { return {a.x + b.x, a.y + b.y}; }
inline Vec2 operator-(Vec2 a, Vec2 b) { return {a.x - b.x, a.y - b.y}; }
inline Vec2 operator*(double s, Vec2 a) { return {s * a.x, s * a.y}; }
inline double Dot(Vec2 a, Vec2 b) { return a.x * b.x + a.y * b.y; }
inline double Cross(Vec2 a, Vec2 b) { return a.x * b.y - a.y * b.x; }
double Norm(Vec2 a);

struct Segment {
  Vec2 a;
  Vec2 b;
};

// A ray from `origin` along the unit vector `dir`.
struct Ray {
  Vec2 origin;
  Vec2 dir;
};

// Distance along the ray to the segment, or kNoHit. Hits at distance <= 0 do not count. A ray
// running along a collinear segment does not hit it (the neighbouring segments of a polyline
// catch that ray).
double RaySegment(const Ray& ray, const Segment& s);
// Distance along the ray to the circle's boundary from outside, or kNoHit (also when the origin is
// inside the circle).
double RayCircle(const Ray& ray, Vec2 center, double radius);
// Distance to an ellipse with semi-axes a (along the ellipse's x axis, rotated by yaw_rad) and b,
// or kNoHit (also from inside).
double RayEllipse(const Ray& ray, Vec2 center, double a, double b, double yaw_rad);
// Distance to the superellipse |u/a|^p + |v/b|^p = 1 (u along the yaw_rad axis, p >= 2: 2 is the
// ellipse, larger p is boxier), or kNoHit (also from inside). Newton's method from the side of the
// ray origin on the convex function along the ray, so it finds the first crossing.
double RaySuperellipse(const Ray& ray, Vec2 center, double a, double b, double exponent,
                       double yaw_rad);
// Distance to the rectangle with half-lengths a (along the yaw_rad axis) and b, or kNoHit (also
// from inside).
double RayBox(const Ray& ray, Vec2 center, double a, double b, double yaw_rad);

// Whether the closed segments share a point (touching counts).
bool SegmentsIntersect(const Segment& s, const Segment& t);
double PointSegmentDistance(Vec2 p, const Segment& s);
double SegmentSegmentDistance(const Segment& s, const Segment& t);

// Even-odd rule; points on the boundary may land on either side.
bool PointInPolygon(Vec2 p, const std::vector<Vec2>& polygon);
// Signed area (counter-clockwise positive). `polygon` is open: the last vertex connects to the
// first.
double PolygonArea(const std::vector<Vec2>& polygon);
// nullopt when `polygon` (open) is a simple polygon with >= 3 vertices, no repeated vertex and a
// non-zero area; else why not ("edges 1 and 3 cross", ...).
std::optional<std::string> CheckSimplePolygon(const std::vector<Vec2>& polygon);

// The closed edges of an open polygon.
std::vector<Segment> PolygonEdges(const std::vector<Vec2>& polygon);

}  // namespace lrfnet::sim
