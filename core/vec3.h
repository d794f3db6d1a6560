// vec3.h - minimal 3-vector shared by engine/ and servo/ (SI units: m, N, s). Header-only,
// no allocation. Part of isotouch::core (see docs/architecture.md).
#pragma once
#include <cmath>

namespace isotouch::core {

struct Vec3 {
  double x = 0, y = 0, z = 0;
  constexpr Vec3() = default;
  constexpr Vec3(double x_, double y_, double z_) : x(x_), y(y_), z(z_) {}
  constexpr double operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  constexpr Vec3 operator+(const Vec3& o) const { return {x + o.x, y + o.y, z + o.z}; }
  constexpr Vec3 operator-(const Vec3& o) const { return {x - o.x, y - o.y, z - o.z}; }
  constexpr Vec3 operator-() const { return {-x, -y, -z}; }
  constexpr Vec3 operator*(double s) const { return {x * s, y * s, z * s}; }
  constexpr Vec3 operator/(double s) const { return {x / s, y / s, z / s}; }
  constexpr Vec3& operator+=(const Vec3& o) { x += o.x; y += o.y; z += o.z; return *this; }
  constexpr Vec3& operator-=(const Vec3& o) { x -= o.x; y -= o.y; z -= o.z; return *this; }
};
constexpr Vec3 operator*(double s, const Vec3& v) { return v * s; }
constexpr double dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
constexpr Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double norm(const Vec3& a) { return std::sqrt(dot(a, a)); }
inline bool finite(const Vec3& a) {
  return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z);
}
/// Unit vector along a, or `fallback` where |a| is zero or not finite.
inline Vec3 normalized_or(const Vec3& a, const Vec3& fallback) {
  const double n = norm(a);
  return (n > 0.0 && std::isfinite(n)) ? a / n : fallback;
}

/// Scale `f` down to magnitude `limit` if it is longer, keeping its direction; the
/// result is never longer than `limit`, rounding included. Returns true if it scaled.
inline bool saturate(Vec3& f, double limit) {
  const double m = norm(f);
  if (!(m > limit)) return false;
  f = f * (limit / m);
  const double m2 = norm(f);
  if (m2 > limit) f = f * ((limit / m2) * (1.0 - 4e-16));
  return true;
}

}  // namespace isotouch::core
