#include "core/phase/isotropic.h"

#include <algorithm>

namespace cloudbake {

Rgb IsotropicPhase::eval(double /*cos_theta*/) const { return Rgb(kInv4Pi); }

double IsotropicPhase::pdf(double /*cos_theta*/) const { return kInv4Pi; }

double IsotropicPhase::sampleCosTheta(double u) const {
  return std::clamp(1.0 - 2.0 * u, -1.0, 1.0);
}

}  // namespace cloudbake
