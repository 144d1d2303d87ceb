#include "core/phase/mie_approx.h"

#include <cmath>
#include <sstream>

#include "core/error.h"
#include "core/format.h"
#include "core/phase/draine.h"
#include "core/phase/henyey_greenstein.h"

namespace cloudbake {

MieApproxParams mieApproxParams(double d) {
  if (!std::isfinite(d) || d < 5.0 || d > 50.0) {
    std::ostringstream os;
    os << "phase.d: droplet diameter must be in [5, 50] micrometres, got " << exactNumber(d);
    throw InputError(os.str());
  }
  MieApproxParams p;
  p.g_hg = std::exp(-0.0990567 / (d - 1.67154));
  p.g_d = std::exp(-2.20679 / (d + 3.91029) - 0.428934);
  p.alpha = std::exp(3.62489 - 8.29288 / (d + 5.52825));
  p.w_d = std::exp(-0.599085 / (d - 0.641583) - 0.665888);
  return p;
}

MieApproxPhase::MieApproxPhase(double diameter_um)
    : diameter_um_(diameter_um), p_(mieApproxParams(diameter_um)) {}

double MieApproxPhase::value(double mu) const {
  return (1.0 - p_.w_d) * hgEval(p_.g_hg, mu) + p_.w_d * draineEval(p_.g_d, p_.alpha, mu);
}

double MieApproxPhase::sampleCosTheta(double u) const {
  // Reuse u for the lobe choice and the lobe sample (remapped to [0, 1)), keeping stratification.
  if (u < p_.w_d) {
    const double v = std::min(u / p_.w_d, std::nextafter(1.0, 0.0));
    return draineSampleCosTheta(p_.g_d, p_.alpha, v);
  }
  const double v = std::min((u - p_.w_d) / (1.0 - p_.w_d), std::nextafter(1.0, 0.0));
  return hgSampleCosTheta(p_.g_hg, v);
}

Rgb MieApproxPhase::meanCosine() const {
  return Rgb((1.0 - p_.w_d) * p_.g_hg + p_.w_d * draineMeanCosine(p_.g_d, p_.alpha));
}

std::string MieApproxPhase::describe() const {
  std::ostringstream os;
  os << "mie_approx(d=" << diameter_um_ << "um)";
  return os.str();
}

}  // namespace cloudbake
