// std::max(0.0, x) and std::clamp by value, in the forms that compile to one maxsd / minsd each.
// std::max and std::clamp return references, and in the view march's per-channel loops GCC
// compiled them to a branch per channel (whose sign the view's angles scatter) with each channel
// written to the stack and read back as one vector, which stalled: `perf` put a fifth of
// method pointcloud's source terms there (issue 18).
#pragma once

namespace cloudbake {

/// std::max(0.0, x), bit for bit: x where x > 0, else +0 (NaN and -0 too).
inline double positivePart(double x) { return x > 0 ? x : 0.0; }

/// std::clamp(v, lo, hi), bit for bit, for lo <= hi: lo where v < lo, hi where hi < v, else v
/// (NaN stays NaN, -0 stays -0).
inline double clampValue(double v, double lo, double hi) {
  const double m = v < lo ? lo : v;
  return hi < m ? hi : m;
}

}  // namespace cloudbake
