// Small text and timing helpers shared by every module's progress and plan lines, so a number
// reads the same everywhere ("2.58 s", "0.05", "1e+06").
#pragma once

#include <charconv>
#include <chrono>
#include <cstdio>
#include <string>
#include <type_traits>

#include "core/math/vec3.h"

namespace cloudbake {

/// A number with `digits` decimals ("2.58" rather than "2.581958").
inline std::string fixed(double value, int digits) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, value);
  return buf;
}

/// A number in %g form ("0.05", "1e+06").
inline std::string shortNumber(double value) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", value);
  return buf;
}

/// A number as the user wrote it: the shortest text that reads back as the same double, so an
/// error about 1.0000000000000002 does not say "got 1" and 1e-300 is not "0.000000".
inline std::string exactNumber(double value) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, value);
  return std::string(buf, r.ptr);
}

inline double secondsSince(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

/// Numbers in messages and metadata as an iostream prints them by default, so text reads as it
/// always has: integers in full, floating point in %g form with `significant` digits (6 by
/// default, the same as shortNumber()).
template <class T, std::enable_if_t<std::is_integral_v<T>, int> = 0>
std::string str(T value) {
  return std::to_string(value);
}
inline std::string str(double value, int significant = 6) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.*g", significant, value);
  return buf;
}
/// "[x, y, z]".
inline std::string str(const Vec3& v) {
  return "[" + str(v.x) + ", " + str(v.y) + ", " + str(v.z) + "]";
}

}  // namespace cloudbake
