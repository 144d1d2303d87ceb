#include "core/math/spherical_harmonics.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

namespace cloudbake {

std::array<double, kShCoefficients> shBasis(const Vec3& w) {
  const double x = w.x, y = w.y, z = w.z;
  std::array<double, kShCoefficients> b{};
  // Normalisation constants of the real SH, l <= 3.
  b[0] = 0.28209479177387814;                              // l0
  b[1] = -0.48860251190291992 * y;                         // l1 m-1
  b[2] = 0.48860251190291992 * z;                          // l1 m0
  b[3] = -0.48860251190291992 * x;                         // l1 m1
  b[4] = 1.0925484305920792 * x * y;                       // l2 m-2
  b[5] = -1.0925484305920792 * y * z;                      // l2 m-1
  b[6] = 0.31539156525252005 * (3 * z * z - 1);            // l2 m0
  b[7] = -1.0925484305920792 * x * z;                      // l2 m1
  b[8] = 0.54627421529603959 * (x * x - y * y);            // l2 m2
  b[9] = -0.59004358992664352 * y * (3 * x * x - y * y);   // l3 m-3
  b[10] = 2.8906114426405538 * x * y * z;                  // l3 m-2
  b[11] = -0.45704579946446572 * y * (5 * z * z - 1);      // l3 m-1
  b[12] = 0.3731763325901154 * z * (5 * z * z - 3);        // l3 m0
  b[13] = -0.45704579946446572 * x * (5 * z * z - 1);      // l3 m1
  b[14] = 1.4453057213202769 * z * (x * x - y * y);        // l3 m2
  b[15] = -0.59004358992664352 * x * (x * x - 3 * y * y);  // l3 m3
  return b;
}

namespace {

// integral over the sphere of Y_i Y_j Y_k by a latitude-longitude rule (exact in azimuth,
// midpoint in cos theta on 384 rings): errors below 1e-4, far under the order-4 truncation.
std::vector<double> buildTripleTensor() {
  std::vector<double> t(size_t(kShCoefficients) * kShCoefficients * kShCoefficients, 0.0);
  const int nt = 96, np = 192;
  for (int it = 0; it < nt; ++it) {
    const double z0 = 1 - 2.0 * it / nt, z1 = 1 - 2.0 * (it + 1) / nt;
    for (int s = 0; s < 4; ++s) {
      const double z = z0 + (z1 - z0) * (s + 0.5) / 4;
      const double r = std::sqrt(std::max(0.0, 1 - z * z));
      for (int ip = 0; ip < np; ++ip) {
        const double ph = 2 * kPi * (ip + 0.5) / np;
        const auto y = shBasis(Vec3(r * std::cos(ph), r * std::sin(ph), z));
        const double w = (2.0 / nt / 4) * (2 * kPi / np);
        for (int i = 0; i < kShCoefficients; ++i)
          for (int j = 0; j < kShCoefficients; ++j) {
            const double yij = y[size_t(i)] * y[size_t(j)] * w;
            for (int k = 0; k < kShCoefficients; ++k) {
              t[(size_t(i) * kShCoefficients + size_t(j)) * kShCoefficients + size_t(k)] +=
                  yij * y[size_t(k)];
            }
          }
      }
    }
  }
  return t;
}

// The non-zero entries of the tensor (the Gaunt coefficients of real SH are mostly zero by
// symmetry): a product then costs a few hundred multiplications instead of 16^3.
struct TensorEntry {
  uint8_t i, j, k;
  float value;
};

std::vector<TensorEntry> sparseTripleTensor() {
  const std::vector<double> t = buildTripleTensor();
  std::vector<TensorEntry> entries;
  for (int i = 0; i < kShCoefficients; ++i)
    for (int j = 0; j < kShCoefficients; ++j)
      for (int k = 0; k < kShCoefficients; ++k) {
        const double v = t[(size_t(i) * kShCoefficients + size_t(j)) * kShCoefficients + size_t(k)];
        // Quadrature leaves ~1e-16 where the exact integral is 0; true entries are >= ~0.01.
        if (std::abs(v) > 1e-7) entries.push_back({uint8_t(i), uint8_t(j), uint8_t(k), float(v)});
      }
  return entries;
}

}  // namespace

ShCoefficients shProduct(const ShCoefficients& a, const ShCoefficients& b) {
  static const std::vector<TensorEntry> tensor = sparseTripleTensor();  // thread-safe init
  std::array<double, kShCoefficients> sum{};
  for (const TensorEntry& e : tensor) sum[e.k] += double(a[e.i]) * b[e.j] * e.value;
  ShCoefficients out{};
  for (int k = 0; k < kShCoefficients; ++k) out[size_t(k)] = float(sum[size_t(k)]);
  return out;
}

double shEvaluate(const ShCoefficients& c, const Vec3& w) {
  const auto b = shBasis(w);
  double s = 0;
  for (int i = 0; i < kShCoefficients; ++i) s += double(c[size_t(i)]) * b[size_t(i)];
  return s;
}

}  // namespace cloudbake
