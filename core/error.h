// Error types thrown by core/ (never exit/abort in library code).
#pragma once

#include <stdexcept>
#include <string>

namespace cloudbake {

/// Bad user input: a malformed file, an out-of-range value, a missing asset. The message names
/// the file and/or field (e.g. "shot.json: /medium/albedo: must be in [0, 1], got 1.5") so a
/// user can fix it; the service maps it to INVALID_ARGUMENT, the CLI to exit code 2.
class InputError : public std::runtime_error {
 public:
  explicit InputError(const std::string& what) : std::runtime_error(what) {}
};

/// Work stopped because the caller asked (cooperative cancellation from a progress callback).
class Cancelled : public std::runtime_error {
 public:
  explicit Cancelled(const std::string& what = "cancelled") : std::runtime_error(what) {}
};

/// A bug or a broken invariant of our own (never the user's input): a method reading a knob it
/// did not declare, a cache entry that verified but cannot be read. The service maps it to
/// INTERNAL, the CLI to exit code 1.
class InternalError : public std::runtime_error {
 public:
  explicit InternalError(const std::string& what) : std::runtime_error(what) {}
};

}  // namespace cloudbake
