// The phase-function interface every scattering model implements.
#pragma once

#include <string>

#include "core/math/vec3.h"

namespace cloudbake {

/// Result of sampling a phase function.
struct PhaseSample {
  Vec3 direction;  ///< travel direction after scattering (unit; core/math/vec3.h)
  Rgb value;       ///< phase value p(theta) per channel, sr^-1
  double pdf = 0;  ///< density of `direction` in sr^-1 (>0 whenever any channel of value is > 0)
};

/// A normalised phase function: for each RGB channel, the integral of p over the sphere is 1.
///
/// Angle convention (the direction conventions of core/math/vec3.h): theta is the angle between
/// the direction light travels *before* scattering and the direction it travels *after*; theta = 0
/// (cos = 1) is forward scattering, theta = 180 deg (cos = -1) is backscatter (glory). Phase
/// functions here are rotationally symmetric, so they are functions of cos(theta) only.
///
/// Chromatic phase functions (the tabulated Mie solution) return a different value per channel
/// but a single sampling pdf; estimators weight by value/pdf per channel, which is unbiased as
/// long as the pdf is positive wherever any channel is (one-sample MIS over channels).
class PhaseFunction {
 public:
  virtual ~PhaseFunction() = default;

  /// Phase value per channel for a scattering angle with cosine `cos_theta`, in sr^-1.
  virtual Rgb eval(double cos_theta) const = 0;

  /// Sampling density for `cos_theta`, in sr^-1 (solid angle measure).
  virtual double pdf(double cos_theta) const = 0;

  /// Samples cos(theta) given a uniform `u` in [0,1) (the azimuth is uniform and handled by
  /// sample()). Must be distributed as pdf(cos_theta) * 2 pi on [-1, 1].
  virtual double sampleCosTheta(double u) const = 0;

  /// Samples the travel direction after scattering of light travelling along `travel` (unit).
  PhaseSample sample(const Vec3& travel, double u1, double u2) const;

  /// Value for explicit travel directions: light travelling along `before`, then along `after`.
  Rgb eval(const Vec3& before, const Vec3& after) const { return eval(dot(before, after)); }

  /// True if channels differ (callers may then skip per-channel work when false).
  virtual bool chromatic() const { return false; }

  /// Mean cosine <cos theta> per channel (the asymmetry parameter g).
  virtual Rgb meanCosine() const = 0;

  /// Short human-readable description, e.g. "hg(g=0.75)".
  virtual std::string describe() const = 0;
};

}  // namespace cloudbake
