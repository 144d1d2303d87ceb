// Draine's phase function, the second lobe of the Jendersie & d'Eon approximate Mie model.
#pragma once

#include "core/phase/phase_function.h"

namespace cloudbake {

/// Draine (2003, ApJ 598:1017, eq. 4) phase function
///   p(mu) = 1/(4 pi) (1 - g^2) / (1 + g^2 - 2 g mu)^(3/2) (1 + alpha mu^2) / (1 + alpha (1 + 2
///   g^2) / 3)
/// in sr^-1; alpha = 0 is Henyey-Greenstein, g = 0 is a Rayleigh-like lobe.
double draineEval(double g, double alpha, double cos_theta);

/// Cumulative distribution of Draine's function in cos_theta, P(mu' <= mu) in [0, 1]. Closed form
/// for |g| >= 0.1, 32-point Gauss-Legendre below (the integrand is then analytic far beyond
/// [-1, 1], so both are exact to rounding).
double draineCdf(double g, double alpha, double cos_theta);

/// Samples cos_theta exactly from Draine's function by inverting draineCdf (safeguarded Newton).
double draineSampleCosTheta(double g, double alpha, double u);

/// Mean cosine: (g + alpha (3 g + 2 g^3) / 5) / (1 + alpha (1 + 2 g^2) / 3).
double draineMeanCosine(double g, double alpha);

/// Draine's phase function as a grey PhaseFunction: g in (-1, 1), alpha >= 0.
class DrainePhase final : public PhaseFunction {
 public:
  /// Throws InputError naming "draine.g" / "draine.alpha" on out-of-range values.
  DrainePhase(double g, double alpha);

  Rgb eval(double cos_theta) const override { return Rgb(draineEval(g_, alpha_, cos_theta)); }
  double pdf(double cos_theta) const override { return draineEval(g_, alpha_, cos_theta); }
  double sampleCosTheta(double u) const override { return draineSampleCosTheta(g_, alpha_, u); }
  Rgb meanCosine() const override { return Rgb(draineMeanCosine(g_, alpha_)); }
  std::string describe() const override;

 private:
  double g_, alpha_;
};

}  // namespace cloudbake
