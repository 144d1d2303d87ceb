// Text from outside made safe to print and send (common/printable.h).
#include "common/printable.h"

#include <gtest/gtest.h>

namespace cloudbake {
namespace {

TEST(Printable, KeepsUtf8AndEscapesTheRest) {
  EXPECT_EQ(printable("plain text, caf\u00e9, \u2601, \U0001F325"),
            "plain text, caf\u00e9, \u2601, \U0001F325");
  EXPECT_EQ(printable("a\nb\rc\td"), "a\\nb\\rc\\td");
  EXPECT_EQ(printable(std::string("nul\0x", 5)), "nul\\x00x");
  EXPECT_EQ(printable("\x7F"), "\\x7F");
  EXPECT_EQ(printable("bad \xFF end"), "bad \\xFF end");
  EXPECT_EQ(printable("cut \xE2\x98"), "cut \\xE2\\x98");            // a truncated sequence
  EXPECT_EQ(printable("overlong \xC0\xAF"), "overlong \\xC0\\xAF");  // '/' in two bytes
  EXPECT_EQ(printable("surrogate \xED\xA0\x80"), "surrogate \\xED\\xA0\\x80");
}

TEST(Printable, FindsTheFirstByteThatIsNotUtf8) {
  EXPECT_EQ(firstInvalidUtf8("caf\u00e9 \u2601"), std::string::npos);
  EXPECT_EQ(firstInvalidUtf8(""), std::string::npos);
  EXPECT_EQ(firstInvalidUtf8("s\xe9q"), 1u);       // Latin-1
  EXPECT_EQ(firstInvalidUtf8("ok \xE2\x98"), 3u);  // a truncated sequence
  EXPECT_EQ(firstInvalidUtf8("ab\xC0\xAF"), 2u);   // overlong
}

}  // namespace
}  // namespace cloudbake
