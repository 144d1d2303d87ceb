// Sky radiance lookup and importance sampling for the Sky description of scene.h.
#pragma once

#include <memory>
#include <string>

#include "core/io/image.h"
#include "core/math/vec3.h"
#include "core/transport/piecewise_constant.h"
#include "core/transport/scene.h"

namespace cloudbake {

/// Largest lat-long sky map accepted (pixels; e.g. 8192 x 4096).
constexpr long long kMaxSkyMapPixels = 1ll << 25;

/// A direction sampled towards the sky.
struct SkySample {
  Vec3 to_sky;     ///< unit direction from the scene towards the sky (light travels along -to_sky)
  Rgb radiance;    ///< sky radiance arriving from to_sky (W m^-2 sr^-1 in the lights' units)
  double pdf = 0;  ///< solid-angle density of to_sky, sr^-1 (0: discard the sample)
};

/// Evaluates and samples a Sky.
///  - constant: L(w) = radiance, sampled uniformly over the sphere (pdf 1/(4 pi)).
///  - gradient: L(w) = horizon + (zenith - horizon) * w.z for w.z >= 0 and `ground` below the
///    horizon (w.z < 0); sampled uniformly over the sphere.
///  - map: equirectangular EXR (u = azimuth from +x towards +y over [0, 2 pi), v = polar angle
///    from +z over [0, pi]; pixel (0, 0) top-left), nearest-pixel lookup times map_scale, sampled
///    by a 2D piecewise-constant distribution of luminance * sin(theta) (Pharr et al. 2016,
///    sec. 14.2.4), so the solid-angle pdf is p(u, v) / (2 pi^2 sin theta).
/// Construction validates the description: every radiance finite and >= 0 ("sky.radiance", ...),
/// map_scale finite and >= 0, the map readable with finite non-negative pixels; InputError
/// otherwise. Immutable and thread-safe after construction.
class SkyLight {
 public:
  explicit SkyLight(const Sky& sky);
  /// Builds a map sky from an in-memory lat-long image (3 channels); `what` names it in errors.
  SkyLight(const Image& map, double scale, const std::string& what);

  /// Radiance arriving from direction `w` (unit, pointing from the scene towards the sky).
  Rgb radiance(const Vec3& w) const;
  SkySample sample(double u1, double u2) const;
  /// Solid-angle density with which sample() produces `w`.
  double pdf(const Vec3& w) const;
  /// Mean radiance over the sphere, from n directions of a spherical Fibonacci lattice: the scale
  /// of what an isotropic scatter of the sky brings (for deciding how many rays it is worth).
  Rgb meanRadiance(int n = 512) const;
  /// True when the sky is zero in every direction (callers skip sky work).
  bool black() const { return black_; }

 private:
  void buildMap(const Image& map, double scale, const std::string& what);

  Sky sky_;
  bool black_ = true;
  Image map_;  // scaled radiance, 3 channels
  std::unique_ptr<PiecewiseConstant2D> distribution_;
};

}  // namespace cloudbake
