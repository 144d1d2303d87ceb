// Isotropic scattering: every direction equally likely.
#pragma once

#include "core/phase/phase_function.h"

namespace cloudbake {

/// p = 1 / (4 pi) sr^-1 in every channel; the limit g -> 0 of every other model here.
class IsotropicPhase final : public PhaseFunction {
 public:
  Rgb eval(double cos_theta) const override;
  double pdf(double cos_theta) const override;
  double sampleCosTheta(double u) const override;
  Rgb meanCosine() const override { return Rgb(0.0); }
  std::string describe() const override { return "isotropic"; }
};

}  // namespace cloudbake
