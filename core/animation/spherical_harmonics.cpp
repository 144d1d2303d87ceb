#include "core/animation/spherical_harmonics.h"

#include <cmath>

namespace cloudbake {

std::array<double, kShCoefficients> shBasis(const Vec3& w) {
  const double x = w.x, y = w.y, z = w.z;
  std::array<double, kShCoefficients> b{};
  // Normalisation constants of the real SH, l <= 3.
  b[0] = 0.28209479177387814;                       // l0
  b[1] = -0.48860251190291992 * y;                  // l1 m-1
  b[2] = 0.48860251190291992 * z;                   // l1 m0
  b[3] = -0.48860251190291992 * x;                  // l1 m1
  b[4] = 1.0925484305920792 * x * y;                // l2 m-2
  b[5] = -1.0925484305920792 * y * z;               // l2 m-1
  b[6] = 0.31539156525252005 * (3 * z * z - 1);     // l2 m0
  b[7] = -1.0925484305920792 * x * z;               // l2 m1
  b[8] = 0.54627421529603959 * (x * x - y * y);     // l2 m2
  b[9] = -0.59004358992664352 * y * (3 * x * x - y * y);   // l3 m-3
  b[10] = 2.8906114426405538 * x * y * z;                   // l3 m-2
  b[11] = -0.45704579946446572 * y * (5 * z * z - 1);       // l3 m-1
  b[12] = 0.3731763325901154 * z * (5 * z * z - 3);         // l3 m0
  b[13] = -0.45704579946446572 * x * (5 * z * z - 1);       // l3 m1
  b[14] = 1.4453057213202769 * z * (x * x - y * y);         // l3 m2
  b[15] = -0.59004358992664352 * x * (x * x - 3 * y * y);   // l3 m3
  return b;
}

double shEvaluate(const ShCoefficients& c, const Vec3& w) {
  const auto b = shBasis(w);
  double s = 0;
  for (int i = 0; i < kShCoefficients; ++i) s += double(c[size_t(i)]) * b[size_t(i)];
  return s;
}

}  // namespace cloudbake
