#include "core/math/sh_basis.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "core/math/spherical_harmonics.h"

namespace cloudbake {
namespace {

// Integral over the sphere of Y_i Y_j by a product rule (midpoint in cos theta, exact in phi for
// these degrees): the basis must be orthonormal.
TEST(ShBasis, IsOrthonormalToDegreeEight) {
  constexpr int kL = kMaxShDegree, kN = shCount(kL);
  std::vector<double> gram(size_t(kN) * kN, 0.0);
  const int nt = 600, np = 40;
  double y[kN];
  for (int i = 0; i < nt; ++i) {
    const double z = 1 - 2 * (i + 0.5) / nt, r = std::sqrt(1 - z * z);
    for (int j = 0; j < np; ++j) {
      const double phi = 2 * kPi * (j + 0.5) / np;
      shBasisUpTo(kL, Vec3(r * std::cos(phi), r * std::sin(phi), z), y);
      const double w = 4 * kPi / (nt * np);
      for (int a = 0; a < kN; ++a)
        for (int b = 0; b < kN; ++b) gram[size_t(a) * kN + b] += w * y[a] * y[b];
    }
  }
  for (int a = 0; a < kN; ++a)
    for (int b = 0; b < kN; ++b) {
      EXPECT_NEAR(gram[size_t(a) * kN + b], a == b ? 1.0 : 0.0, 1e-3) << a << "," << b;
    }
}

// The addition theorem: sum over m of Y_lm(a) Y_lm(b) = (2l + 1) / (4 pi) P_l(a . b), whatever
// the sign convention of each function.
TEST(ShBasis, SatisfiesTheAdditionTheorem) {
  const Vec3 a = normalize(Vec3(0.3, -0.5, 0.8)), b = normalize(Vec3(-0.7, 0.1, 0.2));
  double ya[shCount(kMaxShDegree)], yb[shCount(kMaxShDegree)], p[kMaxShDegree + 1];
  shBasisUpTo(kMaxShDegree, a, ya);
  shBasisUpTo(kMaxShDegree, b, yb);
  legendreP(kMaxShDegree, dot(a, b), p);
  for (int l = 0; l <= kMaxShDegree; ++l) {
    double sum = 0;
    for (int i = l * l; i < (l + 1) * (l + 1); ++i) sum += ya[i] * yb[i];
    EXPECT_NEAR(sum, (2 * l + 1) / (4 * kPi) * p[l], 1e-12) << "l " << l;
  }
  // Degree 0 is the constant 1 / sqrt(4 pi), as the order-4 basis has it.
  EXPECT_NEAR(ya[0], 1 / kSqrt4Pi, 1e-15);
  // The poles are finite.
  shBasisUpTo(kMaxShDegree, Vec3(0, 0, -1), ya);
  for (double v : ya) EXPECT_TRUE(std::isfinite(v));
}

// The zonal harmonics about an axis are the m = 0 members of the full basis with that axis as
// its pole, and orthonormal up to high degree (the photon tally's zonal terms).
TEST(ShBasis, ZonalHarmonicsAreTheMZeroMembers) {
  for (double mu : {-0.9, -0.2, 0.0, 0.35, 0.99}) {
    const Vec3 w(std::sqrt(1 - mu * mu), 0, mu);
    double y[shCount(kMaxShDegree)], z[kMaxShDegree + 1];
    shBasisUpTo(kMaxShDegree, w, y);
    shZonal(0, kMaxShDegree, mu, z);
    for (int l = 0; l <= kMaxShDegree; ++l) EXPECT_NEAR(z[l], y[l * l + l], 1e-12) << l;
    double part[4];
    shZonal(5, 8, mu, part);
    for (int l = 5; l <= 8; ++l) EXPECT_DOUBLE_EQ(part[l - 5], z[l]);
  }
  // integral of Y_l0 Y_k0 over the sphere = 2 pi integral over mu: delta_lk, to degree 64.
  constexpr int kSteps = 20000;
  std::vector<double> gram(3, 0.0);
  const int pairs[3][2] = {{64, 64}, {63, 64}, {40, 40}};
  for (int s = 0; s < kSteps; ++s) {
    const double mu = -1 + (s + 0.5) * 2.0 / kSteps;
    double z[kMaxZonalDegree + 1];
    shZonal(0, kMaxZonalDegree, mu, z);
    for (int q = 0; q < 3; ++q) gram[q] += 2 * kPi * z[pairs[q][0]] * z[pairs[q][1]] * 2.0 / kSteps;
  }
  EXPECT_NEAR(gram[0], 1.0, 1e-3);
  EXPECT_NEAR(gram[1], 0.0, 1e-3);
  EXPECT_NEAR(gram[2], 1.0, 1e-3);
}

}  // namespace
}  // namespace cloudbake
