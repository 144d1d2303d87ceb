#include "core/math/rng.h"

#include <gtest/gtest.h>

namespace cloudbake {
namespace {

TEST(Rng, DeterministicPerSeedAndStream) {
  Rng a(42, 7), b(42, 7), c(42, 8);
  bool differs = false;
  for (int i = 0; i < 100; ++i) {
    const double x = a.uniform();
    EXPECT_EQ(x, b.uniform());
    differs |= x != c.uniform();
  }
  EXPECT_TRUE(differs);
}

TEST(Rng, UniformInUnitIntervalWithCorrectMoments) {
  Rng r(1, 2);
  double sum = 0, sum2 = 0;
  const int n = 200000;
  for (int i = 0; i < n; ++i) {
    const double u = r.uniform();
    ASSERT_GE(u, 0.0);
    ASSERT_LT(u, 1.0);
    sum += u;
    sum2 += u * u;
  }
  EXPECT_NEAR(sum / n, 0.5, 3e-3);
  EXPECT_NEAR(sum2 / n, 1.0 / 3.0, 3e-3);
}

}  // namespace
}  // namespace cloudbake
