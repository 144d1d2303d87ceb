// Small 3-vector used for positions, directions and RGB colours throughout core/.
//
// Direction conventions, the one set for all of core/ (every direction is a unit vector):
//  - A travel direction is the way light moves, or a path traced from the camera: Ray::d, the
//    `travel` of the path tracer, PhaseSample::direction, the light_dir grid (L). A camera ray's
//    d points from the camera into the scene, against the light that reaches the camera.
//  - A to-light direction points from the scene towards a light: Sun::direction and every
//    `sun_dir`, SkySample::to_sky, the argument of SkyLight::radiance(). Sunlight travels along
//    -sun_dir.
//  - Where wo/wi are written (formulas, comments) they follow pbrt: both point away from the
//    scattering point, wo towards where the light goes (the camera), wi towards where it comes
//    from (the sun, the sky); so a camera ray's d is -wo and sun_dir is a wi.
//  - The scattering angle theta lies between the travel directions before and after scattering,
//    cos theta = dot(-wi, wo) (phase_function.h): cos theta = 1 is forward scattering. Traced from
//    the camera that is dot(sun_dir, ray.d), and phase sampling turns one travel direction of the
//    path into the next (the same cosine, by reciprocity).
//  - Henyey-Greenstein g (core/phase/henyey_greenstein.h) is that mean cosine: g > 0 scatters
//    forward (clouds, ~0.85), g < 0 backward, g = 0 is isotropic.
#pragma once

#include <algorithm>
#include <cmath>

namespace cloudbake {

/// A 3-vector of doubles. Used for world positions (world units), unit directions, and
/// (as Rgb) linear colour triples. Double precision keeps optical depths and ray distances
/// exact enough across the 1e-6..1e6 extinction range the path tracer is tested at.
struct Vec3 {
  double x = 0, y = 0, z = 0;

  constexpr Vec3() = default;
  constexpr Vec3(double x_, double y_, double z_) : x(x_), y(y_), z(z_) {}
  constexpr explicit Vec3(double v) : x(v), y(v), z(v) {}

  constexpr double operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  double& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }

  constexpr Vec3 operator+(const Vec3& o) const { return {x + o.x, y + o.y, z + o.z}; }
  constexpr Vec3 operator-(const Vec3& o) const { return {x - o.x, y - o.y, z - o.z}; }
  constexpr Vec3 operator*(const Vec3& o) const { return {x * o.x, y * o.y, z * o.z}; }
  constexpr Vec3 operator/(const Vec3& o) const { return {x / o.x, y / o.y, z / o.z}; }
  constexpr Vec3 operator*(double s) const { return {x * s, y * s, z * s}; }
  constexpr Vec3 operator/(double s) const { return {x / s, y / s, z / s}; }
  constexpr Vec3 operator-() const { return {-x, -y, -z}; }
  Vec3& operator+=(const Vec3& o) {
    x += o.x;
    y += o.y;
    z += o.z;
    return *this;
  }
  Vec3& operator-=(const Vec3& o) {
    x -= o.x;
    y -= o.y;
    z -= o.z;
    return *this;
  }
  Vec3& operator*=(const Vec3& o) {
    x *= o.x;
    y *= o.y;
    z *= o.z;
    return *this;
  }
  Vec3& operator*=(double s) {
    x *= s;
    y *= s;
    z *= s;
    return *this;
  }
  Vec3& operator/=(double s) {
    x /= s;
    y /= s;
    z /= s;
    return *this;
  }
  constexpr bool operator==(const Vec3& o) const { return x == o.x && y == o.y && z == o.z; }
  constexpr bool operator!=(const Vec3& o) const { return !(*this == o); }
};

/// Linear RGB triple (radiance, irradiance, albedo, per-channel phase values).
using Rgb = Vec3;

/// Rec. 709 luminance: the weights every luminance-weighted quantity of core/ uses (albedo times
/// mean cosine, sky sampling, convergence sums).
constexpr double luminance(const Rgb& c) { return 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z; }

constexpr Vec3 operator*(double s, const Vec3& v) { return v * s; }
constexpr double dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
constexpr Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double length(const Vec3& v) { return std::sqrt(dot(v, v)); }
inline Vec3 normalize(const Vec3& v) { return v / length(v); }
/// The unit vector along v for any finite non-zero v, however tiny or huge its components (its
/// length would underflow or overflow): v scaled by its largest component first. The zero
/// vector where v is zero or not finite.
inline Vec3 directionOf(const Vec3& v) {
  const double m = std::max({std::abs(v.x), std::abs(v.y), std::abs(v.z)});
  if (!(m > 0) || !std::isfinite(m)) return Vec3(0.0);
  const Vec3 s = v / m;
  return s / length(s);
}
inline Vec3 min(const Vec3& a, const Vec3& b) {
  return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)};
}
inline Vec3 max(const Vec3& a, const Vec3& b) {
  return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)};
}
inline Vec3 exp(const Vec3& v) { return {std::exp(v.x), std::exp(v.y), std::exp(v.z)}; }
constexpr double maxComponent(const Vec3& v) {
  return v.x > v.y ? (v.x > v.z ? v.x : v.z) : (v.y > v.z ? v.y : v.z);
}
constexpr double average(const Vec3& v) { return (v.x + v.y + v.z) / 3.0; }
inline bool isFinite(const Vec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

/// An orthonormal frame with `n` as the local z axis; converts directions between world and
/// local coordinates (phase-function sampling works in the frame of the incident direction).
struct Frame {
  Vec3 s, t, n;
  /// Builds a frame around unit vector `n` (Duff et al. 2017, branchless ONB).
  static Frame fromZ(const Vec3& n) {
    const double sign = std::copysign(1.0, n.z);
    const double a = -1.0 / (sign + n.z);
    const double b = n.x * n.y * a;
    return {Vec3(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
            Vec3(b, sign + n.y * n.y * a, -n.y), n};
  }
  Vec3 toWorld(const Vec3& v) const { return s * v.x + t * v.y + n * v.z; }
  Vec3 toLocal(const Vec3& v) const { return {dot(v, s), dot(v, t), dot(v, n)}; }
};

/// A ray o + t d, t in world units when d is unit length.
struct Ray {
  Vec3 o, d;
  Vec3 at(double t) const { return o + d * t; }
};

/// Axis-aligned box in world units.
struct Bounds3 {
  Vec3 min{1e300, 1e300, 1e300}, max{-1e300, -1e300, -1e300};
  bool empty() const { return min.x > max.x || min.y > max.y || min.z > max.z; }
  Vec3 extent() const { return max - min; }
  Vec3 center() const { return (min + max) * 0.5; }
  void expand(const Vec3& p) {
    min = cloudbake::min(min, p);
    max = cloudbake::max(max, p);
  }
  bool contains(const Vec3& p) const {
    return p.x >= min.x && p.x <= max.x && p.y >= min.y && p.y <= max.y && p.z >= min.z &&
           p.z <= max.z;
  }
};

/// Slab test: the parametric interval [t0, t1] where `ray` is inside `b`, clipped to
/// [tmin, tmax]. Returns false when it misses. Handles axis-parallel rays (division by +-0
/// gives +-inf, which the min/max logic treats correctly unless the origin is on a face and
/// the result is NaN, which we guard).
inline bool intersectBounds(const Bounds3& b, const Ray& ray, double tmin, double tmax, double* t0,
                            double* t1) {
  for (int a = 0; a < 3; ++a) {
    const double inv = 1.0 / ray.d[a];
    double tn = (b.min[a] - ray.o[a]) * inv;
    double tf = (b.max[a] - ray.o[a]) * inv;
    if (tn > tf) std::swap(tn, tf);
    if (!(tn != tn)) tmin = tn > tmin ? tn : tmin;  // NaN-safe
    if (!(tf != tf)) tmax = tf < tmax ? tf : tmax;
    if (tmin > tmax) return false;
  }
  *t0 = tmin;
  *t1 = tmax;
  return true;
}

constexpr double kPi = 3.14159265358979323846;
constexpr double kInvPi = 1.0 / kPi;
constexpr double kInv4Pi = 1.0 / (4.0 * kPi);

}  // namespace cloudbake
