// What the tools say about a mistyped subcommand (common/cli_suggest.h).
#include "common/cli_suggest.h"

#include <gtest/gtest.h>

namespace cloudbake {
namespace {

const std::vector<std::string> kCommands = {"submit", "status", "watch",  "list", "cancel",
                                            "fetch",  "render", "health", "info"};

TEST(CliSuggest, EditDistanceCountsASwapAsOneEdit) {
  EXPECT_EQ(editDistance("submit", "submit"), 0u);
  EXPECT_EQ(editDistance("sumbit", "submit"), 1u);
  EXPECT_EQ(editDistance("submt", "submit"), 1u);
  EXPECT_EQ(editDistance("", "abc"), 3u);
  EXPECT_EQ(editDistance("kitten", "sitting"), 3u);
}

TEST(CliSuggest, NearestCommandOnlyWhenNear) {
  EXPECT_EQ(nearestCommand("sumbit", kCommands), "submit");
  EXPECT_EQ(nearestCommand("stauts", kCommands), "status");
  EXPECT_EQ(nearestCommand("frobnicate", kCommands), "");
}

TEST(CliSuggest, FindsTheMistypedCommandAmongOptions) {
  const char* argv[] = {"cloudctl", "--server", "h:1", "--json", "sumbit", "shot.json"};
  EXPECT_EQ(unknownCommand(6, argv, kCommands, {"--server"}), "sumbit");
  const char* ok[] = {"cloudctl", "--server", "h:1", "submit", "shot.json"};
  EXPECT_EQ(unknownCommand(5, ok, kCommands, {"--server"}), "");
  const char* none[] = {"cloudctl", "--json"};
  EXPECT_EQ(unknownCommand(2, none, kCommands, {}), "");
  EXPECT_EQ(unknownCommandMessage("sumbit", {"submit", "status"}),
            "unknown command 'sumbit' (did you mean 'submit'?); commands: submit, status");
}

}  // namespace
}  // namespace cloudbake
