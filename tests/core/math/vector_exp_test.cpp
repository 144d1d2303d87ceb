#include "core/math/vector_exp.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

namespace cloudbake {
namespace {

// Distance in units in the last place between two positive finite doubles.
int64_t ulpDistance(double a, double b) {
  int64_t ia, ib;
  std::memcpy(&ia, &a, sizeof a);
  std::memcpy(&ib, &b, sizeof b);
  return ia > ib ? ia - ib : ib - ia;
}

TEST(VectorExp, IsWithinTwoUlpOfLibmOverItsRange) {
  int64_t worst = 0;
  double worst_x = 0;
  const int n = 2000000;
  for (int i = 0; i <= n; ++i) {
    const double x = -708.0 + 1417.0 * double(i) / n;
    const int64_t d = ulpDistance(vectorExp(x), std::exp(x));
    if (d > worst) {
      worst = d;
      worst_x = x;
    }
  }
  EXPECT_LE(worst, 2) << "at x = " << worst_x;
  // Near 0, where the reduction leaves r = x: many small arguments, both signs.
  for (double x = 1e-300; x < 1; x *= 1.7) {
    EXPECT_LE(ulpDistance(vectorExp(x), std::exp(x)), 2) << x;
    EXPECT_LE(ulpDistance(vectorExp(-x), std::exp(-x)), 2) << -x;
  }
}

TEST(VectorExp, IsExactWhereExpIsAndHandlesTheEnds) {
  EXPECT_EQ(vectorExp(0.0), 1.0);
  EXPECT_EQ(vectorExp(-0.0), 1.0);
  EXPECT_EQ(vectorExp(-708.5), 0.0);
  EXPECT_EQ(vectorExp(-1e300), 0.0);
  EXPECT_EQ(vectorExp(-std::numeric_limits<double>::infinity()), 0.0);
  EXPECT_GT(vectorExp(-708.0), 0.0);
  EXPECT_TRUE(std::isinf(vectorExp(709.5)));
  EXPECT_TRUE(std::isinf(vectorExp(std::numeric_limits<double>::infinity())));
  EXPECT_TRUE(std::isfinite(vectorExp(709.0)));
  EXPECT_TRUE(std::isnan(vectorExp(std::nan(""))));
  // Powers of e at integers: within 2 ulp, and increasing.
  double prev = 0;
  for (int k = -708; k <= 709; ++k) {
    const double v = vectorExp(double(k));
    EXPECT_LE(ulpDistance(v, std::exp(double(k))), 2) << k;
    EXPECT_GT(v, prev) << k;
    prev = v;
  }
}

// The loop the header is for, over an array: the same values as one call at a time (whatever
// instructions the compiler chose for the loop).
TEST(VectorExp, ALoopGivesEachCallsValue) {
  std::vector<double> x(1027);
  for (size_t i = 0; i < x.size(); ++i) x[i] = -30.0 + 0.0571 * double(i);
  std::vector<double> y(x.size());
  for (size_t i = 0; i < x.size(); ++i) y[i] = vectorExp(x[i]);
  for (size_t i = 0; i < x.size(); ++i) {
    volatile double xi = x[i];
    EXPECT_EQ(y[i], vectorExp(xi)) << x[i];
  }
}

}  // namespace
}  // namespace cloudbake
