// The branch-free forms of std::max(0.0, x) and std::clamp give the same bits as the standard
// ones, NaN, signed zeros and infinities included.
#include "core/math/branchless.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

namespace cloudbake {
namespace {

uint64_t bits(double x) {
  uint64_t b;
  std::memcpy(&b, &x, sizeof b);
  return b;
}

const std::vector<double>& values() {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  static const std::vector<double> v = {0.0,
                                        -0.0,
                                        1e-300,
                                        -1e-300,
                                        0.25,
                                        -0.25,
                                        0.5,
                                        1.0,
                                        -1.0,
                                        1.5,
                                        3.0,
                                        -3.0,
                                        1e300,
                                        -1e300,
                                        kInf,
                                        -kInf,
                                        std::numeric_limits<double>::quiet_NaN(),
                                        std::numeric_limits<double>::denorm_min(),
                                        -std::numeric_limits<double>::denorm_min()};
  return v;
}

TEST(Branchless, PositivePartIsStdMaxWithZero) {
  for (double x : values()) EXPECT_EQ(bits(positivePart(x)), bits(std::max(0.0, x))) << x;
}

TEST(Branchless, ClampValueIsStdClampWhereLoIsAtMostHi) {
  int checked = 0;
  for (double lo : values()) {
    for (double hi : values()) {
      if (!(lo <= hi)) continue;  // std::clamp's precondition (NaN bounds fail it too)
      for (double v : values()) {
        EXPECT_EQ(bits(clampValue(v, lo, hi)), bits(std::clamp(v, lo, hi)))
            << v << " in [" << lo << ", " << hi << "]";
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 1000);
}

}  // namespace
}  // namespace cloudbake
