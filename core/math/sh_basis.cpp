#include "core/math/sh_basis.h"

#include <algorithm>
#include <cmath>

namespace cloudbake {
namespace {

// K_lm = sqrt((2l + 1) / (4 pi) (l - m)! / (l + m)!), the orthonormalising constant.
double shNorm(int l, int m) {
  double ratio = 1;  // (l - m)! / (l + m)!
  for (int k = l - m + 1; k <= l + m; ++k) ratio /= k;
  return std::sqrt((2 * l + 1) / (4 * kPi) * ratio);
}

// K_lm for every l, m >= 0 up to kMaxShDegree, computed once: the basis is evaluated per photon
// segment, where the factorial loops would cost more than the recurrences.
struct ShNorms {
  double k[kMaxShDegree + 1][kMaxShDegree + 1] = {};
  ShNorms() {
    for (int l = 0; l <= kMaxShDegree; ++l)
      for (int m = 0; m <= l; ++m) k[l][m] = shNorm(l, m);
  }
};

}  // namespace

void legendreP(int degree, double x, double* p) {
  p[0] = 1;
  if (degree >= 1) p[1] = x;
  for (int l = 2; l <= degree; ++l) p[l] = ((2 * l - 1) * x * p[l - 1] - (l - 1) * p[l - 2]) / l;
}

void shZonal(int first, int last, double mu, double* y) {
  static const struct ZonalNorms {
    double k[kMaxZonalDegree + 1];
    ZonalNorms() {
      for (int l = 0; l <= kMaxZonalDegree; ++l) k[l] = std::sqrt((2 * l + 1) / (4 * kPi));
    }
  } norms;
  double p[kMaxZonalDegree + 1];
  legendreP(last, std::clamp(mu, -1.0, 1.0), p);
  for (int l = first; l <= last; ++l) y[l - first] = norms.k[l] * p[l];
}

void shBasisUpTo(int degree, const Vec3& w, double* y) {
  const double z = std::clamp(w.z, -1.0, 1.0);
  const double s = std::sqrt(std::max(0.0, 1 - z * z));  // sin theta
  const double phi = std::atan2(w.y, w.x);
  static const ShNorms norms;
  // P_l^m(z) for every l >= m, from P_m^m = (2m - 1)!! s^m, P_{m+1}^m = (2m + 1) z P_m^m and
  // (l - m) P_l^m = (2l - 1) z P_{l-1}^m - (l + m - 1) P_{l-2}^m.
  double pmm = 1;
  for (int m = 0; m <= degree; ++m) {
    if (m > 0) pmm *= (2 * m - 1) * s;
    // Once per order m, not per degree: libm's sincos was 4-8 % of a photon bake (`perf`).
    const double cos_m = m > 0 ? std::cos(m * phi) : 1.0;
    const double sin_m = m > 0 ? std::sin(m * phi) : 0.0;
    double p_prev = 0, p = pmm;
    for (int l = m; l <= degree; ++l) {
      if (l == m + 1) {
        p_prev = p;
        p = (2 * m + 1) * z * pmm;
      } else if (l > m + 1) {
        const double next = ((2 * l - 1) * z * p - (l + m - 1) * p_prev) / (l - m);
        p_prev = p;
        p = next;
      }
      const double k = norms.k[l][m];
      if (m == 0) {
        y[l * l + l] = k * p;
      } else {
        y[l * l + l + m] = std::sqrt(2.0) * k * cos_m * p;
        y[l * l + l - m] = std::sqrt(2.0) * k * sin_m * p;
      }
    }
  }
}

}  // namespace cloudbake
