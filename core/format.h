// Small text and timing helpers shared by every module's progress and plan lines, so a number
// reads the same everywhere ("2.58 s", "0.05", "1e+06").
#pragma once

#include <chrono>
#include <cstdio>
#include <string>

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

inline double secondsSince(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

}  // namespace cloudbake
