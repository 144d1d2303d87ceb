#include "core/bake/sky_p1_scatter.h"

#include <algorithm>

namespace cloudbake {

DeltaSplit deltaSplit(double lambda1, double lambda2) {
  DeltaSplit s;
  s.backward = lambda1 < 0;
  const double g = std::abs(lambda1);
  // lambda2 <= |lambda1| keeps the residual's mean cosine on the peak's side; a peak of f = 1
  // leaves no residual to weight.
  s.f = std::clamp(lambda2, 0.0, std::min(g, 1.0));
  const double g_res = s.f < 1 ? (g - s.f) / (1 - s.f) : 0.0;
  s.g_residual = s.backward ? -g_res : g_res;
  return s;
}

}  // namespace cloudbake
