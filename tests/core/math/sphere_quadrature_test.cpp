#include "core/math/sphere_quadrature.h"

#include <gtest/gtest.h>

namespace cloudbake {
namespace {

// Every cell once, rows of falling z, unit directions, and the sphere's moments: the mean of w
// is 0 and of each w_a^2 is 1/3 (z^2 to the midpoint rule's h^2 / 12 per row).
TEST(SphereQuadrature, CoversTheSphereInCellsOfEqualSolidAngle) {
  constexpr int kNz = 32, kNphi = 64;
  int n = 0, last_row = -1;
  bool rows_in_order = true;
  double len_err = 0;
  Vec3 mean(0.0), second(0.0);
  forEachEqualAreaCell<kNz, kNphi>([&](int i, const Vec3& w) {
    rows_in_order = rows_in_order && i >= last_row;
    last_row = i;
    len_err = std::max(len_err, std::abs(length(w) - 1));
    mean += w;
    second += Vec3(w.x * w.x, w.y * w.y, w.z * w.z);
    ++n;
  });
  EXPECT_EQ(n, kNz * kNphi);
  EXPECT_TRUE(rows_in_order);
  EXPECT_EQ(last_row, kNz - 1);
  EXPECT_LT(len_err, 1e-12);
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR(mean[a] / n, 0.0, 1e-12);
    EXPECT_NEAR(second[a] / n, 1.0 / 3.0, 1e-3);
  }
}

}  // namespace
}  // namespace cloudbake
