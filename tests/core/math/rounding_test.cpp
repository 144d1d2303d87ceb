#include "core/math/rounding.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

namespace cloudbake {
namespace {

TEST(RoundHalfAway, MatchesLlroundOnHalvesAndTheirNeighbours) {
  for (double base : {0.0, 1.0, 2.0, 3.0, 1e6, 4503599627370495.0}) {
    for (double x : {base + 0.5, base - 0.5, std::nextafter(base + 0.5, 0.0),
                     std::nextafter(base + 0.5, 1e300), std::nextafter(base - 0.5, 0.0),
                     std::nextafter(base - 0.5, 1e300), base}) {
      EXPECT_EQ(roundHalfAway(x), std::llround(x)) << x;
      EXPECT_EQ(roundHalfAway(-x), std::llround(-x)) << -x;
    }
  }
  EXPECT_EQ(roundHalfAway(0.5), 1);
  EXPECT_EQ(roundHalfAway(-0.5), -1);
  EXPECT_EQ(roundHalfAway(2.5), 3);
  EXPECT_EQ(roundHalfAway(-2.5), -3);
  EXPECT_EQ(roundHalfAway(0.49999999999999994), 0);  // where x + 0.5 would round up
}

TEST(RoundHalfAway, MatchesLlroundOverEveryScale) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> mantissa(-1, 1);
  std::uniform_int_distribution<int> exponent(-40, 61);
  for (int i = 0; i < 200000; ++i) {
    const double x = std::ldexp(mantissa(rng), exponent(rng));
    ASSERT_EQ(roundHalfAway(x), std::llround(x)) << x;
  }
  EXPECT_EQ(roundHalfAway(4e18), std::llround(4e18));
  EXPECT_EQ(roundHalfAway(-4e18), std::llround(-4e18));
}

TEST(RoundHalfAway, NanIsZero) {
  EXPECT_EQ(roundHalfAway(std::numeric_limits<double>::quiet_NaN()), 0);
}

}  // namespace
}  // namespace cloudbake
