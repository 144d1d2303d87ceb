// The Henyey-Greenstein phase function.
#pragma once

#include "core/phase/phase_function.h"

namespace cloudbake {

/// The largest |g| a Henyey-Greenstein phase takes. Beyond it the peak is narrower than double
/// precision resolves: 1 + g^2 - 2 g cos_theta rounds to zero or below near cos_theta = 1 (at
/// g = 1 - 1e-9 the path tracer's pixels came out NaN), and at 1 - 1e-7 the peak's value is
/// already off by per cent. A cloud's phase is never so narrow (a droplet's peak is about a
/// degree wide), and a peak of 1e-6 radians is forward travel to any image's resolution.
constexpr double kMaxHgAsymmetry = 0.999999;

/// HG value p(cos_theta) = (1 - g^2) / (4 pi (1 + g^2 - 2 g cos_theta)^(3/2)), sr^-1.
/// Henyey & Greenstein 1941, ApJ 93:70.
double hgEval(double g, double cos_theta);

/// Inverts the HG CDF: cos_theta for a uniform u in [0, 1). Written as one rational function of
/// g and u so it has no 1/g cancellation and is exact at g = 0 (uniform) and stable near |g| = 1.
double hgSampleCosTheta(double g, double u);

/// Henyey-Greenstein phase function with asymmetry `g`, |g| <= kMaxHgAsymmetry, grey.
/// Its mean cosine equals g, with theta between the travel directions before and after
/// scattering (core/math/vec3.h): g > 0 peaks forward (cos theta = 1), g < 0 backward.
class HenyeyGreensteinPhase final : public PhaseFunction {
 public:
  /// Throws InputError ("phase.g: ...") unless g is finite and |g| <= kMaxHgAsymmetry.
  explicit HenyeyGreensteinPhase(double g);

  Rgb eval(double cos_theta) const override { return Rgb(hgEval(g_, cos_theta)); }
  double pdf(double cos_theta) const override { return hgEval(g_, cos_theta); }
  double sampleCosTheta(double u) const override { return hgSampleCosTheta(g_, u); }
  Rgb meanCosine() const override { return Rgb(g_); }
  std::string describe() const override;

  double g() const { return g_; }

 private:
  double g_;
};

}  // namespace cloudbake
