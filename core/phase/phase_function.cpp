#include "core/phase/phase_function.h"

#include "core/math/sampling.h"

namespace cloudbake {

PhaseSample PhaseFunction::sample(const Vec3& travel, double u1, double u2) const {
  const double cos_theta = sampleCosTheta(u1);
  PhaseSample s;
  s.direction = directionFromCosTheta(travel, cos_theta, u2);
  s.value = eval(cos_theta);
  s.pdf = pdf(cos_theta);
  return s;
}

}  // namespace cloudbake
