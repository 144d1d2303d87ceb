// A midpoint rule on the unit sphere in cells of equal solid angle: uniform in z = cos(theta)
// and in azimuth. Exact for functions of z alone that are linear in each cell (the gradient
// sky), and a plain, predictable rule for the rest.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>

#include "core/math/vec3.h"

namespace cloudbake {

/// Calls f(i, w) for the centre w of every cell of a kNz x kNphi grid, row i (falling z) by
/// row, each row in rising azimuth; every cell holds 4 pi / (kNz kNphi) sr. The azimuths'
/// cosines and sines are taken once, not once per row.
template <int kNz, int kNphi, typename F>
void forEachEqualAreaCell(F&& f) {
  std::array<double, kNphi> cos_phi, sin_phi;
  for (int j = 0; j < kNphi; ++j) {
    const double phi = 2 * kPi * (j + 0.5) / kNphi;
    cos_phi[size_t(j)] = std::cos(phi);
    sin_phi[size_t(j)] = std::sin(phi);
  }
  for (int i = 0; i < kNz; ++i) {
    const double z = 1 - 2 * (i + 0.5) / kNz;
    const double r = std::sqrt(std::max(0.0, 1 - z * z));
    for (int j = 0; j < kNphi; ++j) f(i, Vec3(r * cos_phi[size_t(j)], r * sin_phi[size_t(j)], z));
  }
}

}  // namespace cloudbake
