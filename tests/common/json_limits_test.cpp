// The one bounded JSON parser of every program (common/json_limits.h).
#include "common/json_limits.h"

#include <gtest/gtest.h>

#include <string>

namespace cloudbake {
namespace {

std::string errorOf(const std::string& text, const JsonLimits& limits = {}) {
  try {
    parseJsonLimited(text, "views_json", limits);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(JsonLimits, DeepNestingIsAClearErrorNotACrash) {
  // 100,000 levels: found at level 33, before anything deeper is built.
  const std::string deep = std::string(100000, '[') + std::string(100000, ']');
  EXPECT_EQ(errorOf(deep), "views_json: nested deeper than 32 levels");
  const std::string objects = [] {
    std::string s;
    for (int i = 0; i < 100000; ++i) s += "{\"a\":";
    return s + "1" + std::string(100000, '}');
  }();
  EXPECT_EQ(errorOf(objects), "views_json: nested deeper than 32 levels");
  // 32 levels are fine.
  EXPECT_EQ(errorOf(std::string(32, '[') + std::string(32, ']')), "");
}

TEST(JsonLimits, SizeAndSyntaxErrorsNameWhatWasParsed) {
  JsonLimits small;
  small.max_bytes = 10;
  EXPECT_EQ(errorOf("[1, 2, 3, 4, 5]", small),
            "views_json: 15 bytes of JSON, more than the 10 allowed");
  const std::string bad = errorOf("[1, 2");
  EXPECT_EQ(bad.rfind("views_json: invalid JSON: ", 0), 0u) << bad;
  EXPECT_EQ(bad.find("[json.exception"), std::string::npos) << bad;
  EXPECT_EQ(parseJsonLimited("{\"a\": [1, {\"b\": 2}]}", "x").at("a").at(1).at("b"), 2);
}

TEST(JsonLimits, ANulByteIsNotTheEndOfTheText) {
  // The parser's lexer stops at a NUL: what follows it would have been ignored.
  const std::string text = std::string("{\"a\": 1}") + '\0' + "this is not json {{{";
  EXPECT_EQ(errorOf(text), "views_json: invalid JSON: a NUL byte at offset 8");
  EXPECT_EQ(errorOf(std::string("[1,") + '\0' + "2]"),
            "views_json: invalid JSON: a NUL byte at offset 3");
}

}  // namespace
}  // namespace cloudbake
