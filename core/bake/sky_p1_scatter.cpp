#include "core/bake/sky_p1_scatter.h"

#include <algorithm>
#include <cmath>

#include "core/math/sphere_quadrature.h"

namespace cloudbake {

DeltaSplit deltaSplit(double lambda1, double lambda2) {
  DeltaSplit s;
  // A quadrature's rounding leaves an isotropic phase's moments at 1e-16 to 1e-9, not 0: a peak
  // that small would only cost each view a march behind the camera.
  constexpr double kNoPeak = 1e-6;
  if (std::abs(lambda1) < kNoPeak) {
    s.g_residual = lambda1;
    return s;
  }
  s.backward = lambda1 < 0;
  const double g = std::abs(lambda1);
  // lambda2 <= |lambda1| keeps the residual's mean cosine on the peak's side; a peak of f = 1
  // leaves no residual to weight.
  s.f = std::clamp(lambda2, 0.0, std::min(g, 1.0));
  if (s.f < kNoPeak) s.f = 0;
  const double g_res = s.f < 1 ? (g - s.f) / (1 - s.f) : 0.0;
  s.g_residual = s.backward ? -g_res : g_res;
  return s;
}

std::array<Vec3, 3> skyFirstMoment(const SkyLight& sky) {
  std::array<Vec3, 3> m{Vec3(0.0), Vec3(0.0), Vec3(0.0)};
  if (sky.black()) return m;
  constexpr int kNz = 64, kNphi = 128;
  double largest = 0;
  forEachEqualAreaCell<kNz, kNphi>([&](int, const Vec3& w) {
    const Rgb l = sky.radiance(w);
    for (int c = 0; c < 3; ++c) {
      m[size_t(c)] += w * l[c];
      largest = std::max(largest, l[c]);
    }
  });
  for (Vec3& v : m) {
    v = v / (double(kNz) * kNphi);
    for (int a = 0; a < 3; ++a) {
      if (std::abs(v[a]) < 1e-12 * largest) v[a] = 0;
    }
  }
  return m;
}

P1RayWeights p1RayWeights(const std::array<Vec3, 3>& l, const double* g_residual, const Vec3& d) {
  P1RayWeights w;
  for (int c = 0; c < 3; ++c) {
    const Vec3& lc = l[size_t(c)];
    const double g = g_residual[c];
    w.alpha[c] = 1 + 3 * g * dot(lc, d);
    w.beta[c] = (lc + d * g) * 3.0;
    w.upper[c] = 1 + 3 * length(lc);
  }
  return w;
}

}  // namespace cloudbake
