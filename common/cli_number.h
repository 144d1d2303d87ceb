// A CLI11 check for options that take a real number, shared by cloudbake, cloudctl and
// cloudbake-server. Header-only, beside cli_suggest.h.
//
// CLI::Range and CLI::PositiveNumber let NaN through (every comparison with it is false: a
// `--timeout nan` became a deadline of -2147483648 s) and print their bounds with six decimals
// (PositiveNumber's upper one as 309 digits). This check parses the text itself, refuses what
// does not read whole as a finite number, and names the range as it was written.
#pragma once

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace cloudbake {

/// A bound as one writes it: 0, 86400, 1e6, 1e-8.
inline std::string cliBound(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  std::string s = buf;
  const size_t e = s.find('e');
  if (e == std::string::npos) return s;
  std::string exponent = s.substr(e + 1);  // "+06", "-08"
  const bool negative = exponent[0] == '-';
  exponent.erase(0, exponent.find_first_not_of("+-0"));
  return s.substr(0, e + 1) + (negative ? "-" : "") + (exponent.empty() ? "0" : exponent);
}

/// Accepts a number x with lo <= x <= hi (lo < x where `lo_open`); the error reads
/// "must be a number in (0, 1e6], got nan", which CLI11 prefixes with the option's name. A
/// value too small for a double reads as 0 or a subnormal, as strtod gives it; one too large
/// reads as infinite and is refused.
inline CLI::Validator numberIn(double lo, double hi, bool lo_open = false) {
  const std::string range = (lo_open ? "(" : "[") + cliBound(lo) + ", " + cliBound(hi) + "]";
  return CLI::Validator(
      [lo, hi, lo_open, range](std::string& text) -> std::string {
        const char* begin = text.c_str();
        char* end = nullptr;
        const double x = std::strtod(begin, &end);
        const bool whole = end != begin && *end == '\0';
        const bool inside = std::isfinite(x) && (lo_open ? x > lo : x >= lo) && x <= hi;
        if (whole && inside) return {};
        return "must be a number in " + range + ", got " + text;
      },
      "NUMBER in " + range);
}

}  // namespace cloudbake
