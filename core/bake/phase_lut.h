// A fast tabulated form of any phase function, for the inner loops of bakes and bake renders.
#pragma once

#include <vector>

#include "core/math/vec3.h"
#include "core/phase/phase_function.h"

namespace cloudbake {

/// p(cos theta) per RGB channel, tabulated on u = sin(theta / 2) = sqrt((1 - cos theta) / 2) with
/// linear interpolation. The variable is uniform in theta near the forward direction, so the
/// narrow forward peak of a cloud's Mie phase function (a fraction of a degree wide) is resolved
/// with `size` bins while lookups need only a square root, no acos. Values in sr^-1, theta = 0
/// forward (core/phase/phase_function.h). Default 4096 bins: 0.03 deg near the forward peak.
class PhaseLut {
 public:
  explicit PhaseLut(const PhaseFunction& phase, int size = 4096);
  Rgb eval(double cos_theta) const {
    const double c = cos_theta > 1 ? 1 : (cos_theta < -1 ? -1 : cos_theta);
    const double x = std::sqrt(0.5 * (1 - c)) * (size_ - 1);
    int i = int(x);
    if (i >= size_ - 1) i = size_ - 2;
    const double t = x - i;
    return table_[size_t(i)] * (1 - t) + table_[size_t(i) + 1] * t;
  }
  /// Luminance-weighted value, for scalar weights.
  double evalLuminance(double cos_theta) const { return luminance(eval(cos_theta)); }

 private:
  int size_;
  std::vector<Rgb> table_;
};

}  // namespace cloudbake
