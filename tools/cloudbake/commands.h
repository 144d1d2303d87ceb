// Subcommands of the `cloudbake` tool. Each adds itself to the app and returns its exit code
// through the shared result slot when it runs.
#pragma once

#include <CLI/CLI.hpp>

namespace cloudbake::tool {

/// Exit codes shared by cloudbake and cloudctl (documented in docs/cli.md).
enum ExitCode : int {
  kOk = 0,
  kFailure = 1,     ///< internal error
  kBadInput = 2,    ///< invalid shot, asset or argument
  kNotFound = 3,    ///< a file or job does not exist
  kUnavailable = 4, ///< server unreachable
  kJobFailed = 5,
  kCancelled = 6,
};

}  // namespace cloudbake::tool
