// The exponential in loops the compiler vectorises. std::exp is a call into libm, which GCC
// does not inline without -ffast-math, so a loop of it runs one value at a time: in a
// `precomputed` frame's sky transmittance (SHEXP, 256 exponentials a voxel) libm's exp and its
// wrapper took more time than the quadrature's sums around them (`perf`, issue 18).
#pragma once

#include <cstdint>
#include <limits>

namespace cloudbake {

/// e^x within 2 ulp of libm's exp for x in [-708, 709], written as plain arithmetic so that a
/// loop of it compiles to vector instructions (and, under CLOUDBAKE_VECTOR_CLONES, to the same
/// bits in every clone: no FMA). Outside that range: 0 below -708 (libm gives at most 3.3e-308
/// there, subnormal below -708.4), +inf above 709 (libm overflows above 709.78). NaN gives NaN.
/// GCC if-converts its range tests, and so vectorises the loop, only where floating-point
/// comparisons may not trap: compile the caller's file with -fno-trapping-math (which changes no
/// value), as core/animation/CMakeLists.txt does for shexp.cpp.
inline double vectorExp(double x) {
  // Cody & Waite's reduction, x = n ln2 + r with |r| <= ln2 / 2: ln2's high part has 32 trailing
  // zero bits, so n * kLn2Hi is exact for every |n| <= 1023 (fdlibm's constants).
  constexpr double kLog2e = 1.44269504088896338700e+00;
  constexpr double kLn2Hi = 6.93147180369123816490e-01;
  constexpr double kLn2Lo = 1.90821492927058770002e-10;
  // Adding 1.5 x 2^52 rounds to an integer (the ulp there is 1), which then sits in the low
  // bits of the sum's mantissa: the sum's bits are kShift's plus n.
  constexpr double kShift = 6755399441055744.0;
  const double xc = x < -708.0 ? -708.0 : (x > 709.0 ? 709.0 : x);
  const double t = xc * kLog2e + kShift;
  const double n = t - kShift;
  const double r = (xc - n * kLn2Hi) - n * kLn2Lo;
  // Taylor's series to degree 13 (the first term left out is under 5e-18 relative at |r| =
  // 0.35), by Estrin's scheme: a tree of products rather than Horner's chain of 13, whose
  // latency bounded the vectorised loop.
  const double r2 = r * r, r4 = r2 * r2, r8 = r4 * r4;
  const double p01 = 1.0 + r, p23 = 0.5 + r * (1.0 / 6.0);
  const double p45 = 1.0 / 24.0 + r * (1.0 / 120.0), p67 = 1.0 / 720.0 + r * (1.0 / 5040.0);
  const double p89 = 1.0 / 40320.0 + r * (1.0 / 362880.0);
  const double p1011 = 1.0 / 3628800.0 + r * (1.0 / 39916800.0);
  const double p1213 = 1.0 / 479001600.0 + r * (1.0 / 6227020800.0);
  const double q0 = p01 + r2 * p23, q1 = p45 + r2 * p67, q2 = p89 + r2 * p1011;
  const double p = (q0 + r4 * q1) + r8 * (q2 + r4 * p1213);
  // 2^n as a double: the biased exponent n + 1023 (2 to 2046 here) shifted into place; the bits
  // of kShift itself shift out of the word.
  const std::uint64_t bits = (__builtin_bit_cast(std::uint64_t, t) + 1023u) << 52;
  const double e = p * __builtin_bit_cast(double, bits);
  return x < -708.0 ? 0.0 : (x > 709.0 ? std::numeric_limits<double>::infinity() : e);
}

}  // namespace cloudbake
