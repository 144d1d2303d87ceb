// The check of real-valued options (common/cli_number.h): the text must read whole as a
// finite number inside the range, and the error names the range as written.
#include "common/cli_number.h"

#include <gtest/gtest.h>

#include <string>

namespace cloudbake {
namespace {

std::string check(const CLI::Validator& v, std::string text) { return v(text); }

TEST(CliNumber, AcceptsTheRangeWithItsEndsAsWritten) {
  const CLI::Validator closed = numberIn(0, 86400);
  for (const char* ok : {"0", "86400", "1.5", "1e3", "  7", "0x10"}) {
    EXPECT_EQ(check(closed, ok), "") << ok;
  }
  const CLI::Validator open = numberIn(0, 1e6, true);
  EXPECT_EQ(check(open, "1e-300"), "");
  EXPECT_EQ(check(open, "1e-310"), "");    // subnormal, still above 0
  EXPECT_EQ(check(closed, "1e-400"), "");  // too small for a double: 0, which is allowed
  EXPECT_EQ(check(open, "1e6"), "");
  EXPECT_EQ(check(open, "0"), "must be a number in (0, 1e6], got 0");
  EXPECT_EQ(check(open, "-0"), "must be a number in (0, 1e6], got -0");
}

TEST(CliNumber, RefusesNanInfinityOverflowAndTrailingText) {
  const CLI::Validator v = numberIn(0, 1e9);
  for (const char* bad : {"nan", "NaN", "-nan", "inf", "-inf", "infinity", "1e400", "1e9x", "5 s",
                          "", " ", "x", "1e1000000", "-1", "1000000001"}) {
    EXPECT_EQ(check(v, bad), "must be a number in [0, 1e9], got " + std::string(bad)) << bad;
  }
  EXPECT_EQ(numberIn(0, 1).get_description(), "NUMBER in [0, 1]");
  EXPECT_EQ(numberIn(1e-8, 1e5).get_description(), "NUMBER in [1e-8, 100000]");
  EXPECT_EQ(numberIn(-2.5, 1e12, true).get_description(), "NUMBER in (-2.5, 1e12]");
}

}  // namespace
}  // namespace cloudbake
