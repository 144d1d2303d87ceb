#include "core/phase/henyey_greenstein.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "core/error.h"
#include "core/format.h"

namespace cloudbake {

double hgEval(double g, double cos_theta) {
  const double denom = 1.0 + g * g - 2.0 * g * cos_theta;
  return kInv4Pi * (1.0 - g * g) / (denom * std::sqrt(denom));
}

double hgSampleCosTheta(double g, double u) {
  // The textbook inverse (1 + g^2 - ((1 - g^2) / (1 + g t))^2) / (2 g) with t = 2u - 1, with the
  // common factor g divided out of the numerator analytically.
  const double t = 2.0 * u - 1.0;
  const double d = 1.0 + g * t;
  const double num = 2.0 * t + g * (3.0 + t * t) + 2.0 * g * g * t + g * g * g * (t * t - 1.0);
  return std::clamp(num / (2.0 * d * d), -1.0, 1.0);
}

HenyeyGreensteinPhase::HenyeyGreensteinPhase(double g) : g_(g) {
  if (!std::isfinite(g) || !(std::abs(g) <= kMaxHgAsymmetry)) {
    std::ostringstream os;
    os << "phase.g: must be in [-" << kMaxHgAsymmetry << ", " << kMaxHgAsymmetry << "], got "
       << exactNumber(g);
    throw InputError(os.str());
  }
}

std::string HenyeyGreensteinPhase::describe() const {
  std::ostringstream os;
  os << "hg(g=" << g_ << ")";
  return os.str();
}

}  // namespace cloudbake
