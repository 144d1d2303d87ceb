#include "core/transport/sun_guiding.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "core/format.h"
#include "core/math/sampling.h"

namespace cloudbake {

double phaseSpikiness(const PhaseFunction& phase, int n) {
  // E_p[pdf] = integral(p^2): the phase's own sampler puts its samples where p is large, which is
  // exactly where p^2 is; stratified u keeps the estimate deterministic.
  double sum = 0;
  for (int i = 0; i < n; ++i) sum += phase.pdf(phase.sampleCosTheta((i + 0.5) / n));
  return std::max(0.0, 4 * kPi * sum / n - 1);
}

double autoSunGuiding(const PhaseFunction& phase) {
  const double v = phaseSpikiness(phase);
  return std::isinf(v) ? 0.5 : 0.5 * v / (v + 40);  // inf / inf would be NaN
}

SunGuide::SunGuide(const PhaseFunction& phase, const Vec3& to_sun, double eps)
    : phase_(phase), to_sun_(to_sun), eps_(eps) {
  if (!(eps >= 0 && eps < 1)) {
    throw InputError("sun_guiding: must be in [0, 1), got " + str(eps));
  }
  if (!isFinite(to_sun) || std::abs(length(to_sun) - 1) > 1e-6) {
    throw InputError("sun direction: must be a unit vector, got " + str(to_sun));
  }
}

double SunGuide::epsAt(const Vec3& travel) const {
  if (eps_ == 0) return 0;
  const double p_sun = 4 * kPi * phase_.pdf(std::clamp(dot(travel, to_sun_), -1.0, 1.0));
  return p_sun > 1 ? eps_ / p_sun : eps_;
}

SunGuide::PhaseSampleWeights SunGuide::phaseSampleWeights(double p_phase, const Vec3& direction,
                                                          double eps_t) const {
  PhaseSampleWeights w;
  if (eps_ == 0) return w;
  const double p_sun = phase_.pdf(std::clamp(dot(to_sun_, direction), -1.0, 1.0));
  w.importance = std::max(1.0, 4 * kPi * p_sun);
  if (eps_t > 0) {
    const double sum = p_phase + eps_t * p_sun;
    w.mis = sum > 0 ? p_phase / sum : 0;
  }
  return w;
}

SunGuide::LobeSample SunGuide::sampleLobe(const Vec3& travel, double eps_t, double u1,
                                          double u2) const {
  const double cos_sun = phase_.sampleCosTheta(u1);
  LobeSample s;
  s.direction = directionFromCosTheta(to_sun_, cos_sun, u2);
  const double cos_theta = std::clamp(dot(travel, s.direction), -1.0, 1.0);
  const double sum = phase_.pdf(cos_theta) + eps_t * phase_.pdf(cos_sun);
  s.weight = sum > 0 ? phase_.eval(cos_theta) / sum : Rgb(0.0);
  return s;
}

}  // namespace cloudbake
