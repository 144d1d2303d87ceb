// Rounding to integers in hot loops. std::llround is a call into libm that GCC does not inline
// without -ffast-math: in method photon's bake it was 10 % of the whole run (`perf`, issue 18),
// once per coefficient and channel of every voxel a photon crosses.
#pragma once

#include <cstdint>

namespace cloudbake {

/// x rounded to the nearest integer, halves away from zero: std::llround's result, bit for bit,
/// for every finite |x| < 2^63 (the caller clamps). NaN gives 0.
inline int64_t roundHalfAway(double x) {
  if (!(x == x)) return 0;
  // t is trunc(x), a double, so it converts back exactly, and x - t is x's fractional bits:
  // exact too.
  const int64_t t = static_cast<int64_t>(x);
  const double f = x - static_cast<double>(t);
  return t + (f >= 0.5 ? 1 : 0) - (f <= -0.5 ? 1 : 0);
}

}  // namespace cloudbake
