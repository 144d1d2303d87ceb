#include "core/transport/shadow_splitting.h"

#include <algorithm>
#include <cmath>

#include "core/transport/sun_guiding.h"

namespace cloudbake {

ShadowRays sunShadowRays(double predicted, int max_rays, double u, bool roulette,
                         double min_survival) {
  if (max_rays <= 1 && !roulette) return {};
  if (!(predicted > 0) && !(min_survival > 0)) return {0, 0};
  if (predicted > 1 && max_rays > 1) {
    const int n = int(std::min<double>(max_rays, std::ceil(predicted)));
    return {n, 1.0 / n};
  }
  if (predicted < kShadowRouletteBelow) {
    const double survive = shadowSurvival(predicted, min_survival);
    if (u < survive) return {1, 1.0 / survive};
    return {0, 0};
  }
  return {};
}

int autoSunSplitMax(const PhaseFunction& phase) { return phaseSpikiness(phase) > 100 ? 8 : 1; }

}  // namespace cloudbake
