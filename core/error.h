// Error types thrown by core/ (never exit/abort in library code). Each stands for one kind of
// failure that the programs report in one way (common/exit_codes.h: exit codes of cloudbake and
// cloudctl; server/status_mapping.cpp: gRPC statuses).
#pragma once

#include <cerrno>
#include <stdexcept>
#include <string>
#include <utility>

namespace cloudbake {

/// Bad user input: a malformed file, an out-of-range value, a missing asset. The message names
/// the file and/or field (e.g. "shot.json: /medium/albedo: must be in [0, 1], got 1.5") so a
/// user can fix it; the service maps it to INVALID_ARGUMENT, the CLI to exit code 2.
class InputError : public std::runtime_error {
 public:
  explicit InputError(const std::string& what) : std::runtime_error(withControlsEscaped(what)) {}

  /// `text` with its control characters but newline and tab as \xNN: messages quote the user's
  /// values, and a NUL would cut what() short, an escape sequence would reach the terminal.
  static std::string withControlsEscaped(const std::string& text) {
    std::string out;
    out.reserve(text.size());
    for (const char ch : text) {
      const unsigned char c = static_cast<unsigned char>(ch);
      if ((c < 0x20 && c != '\n' && c != '\t') || c == 0x7F) {
        static const char kHex[] = "0123456789ABCDEF";
        out += "\\x";
        out += kHex[c >> 4];
        out += kHex[c & 15];
      } else {
        out += ch;
      }
    }
    return out;
  }
};

/// A file named by the shot (or the shot file itself) does not exist. An InputError, so callers
/// that only care about "bad input" need not distinguish; the CLI maps it to exit code 3.
class MissingFileError : public InputError {
 public:
  explicit MissingFileError(const std::string& what) : InputError(what) {}
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

/// A job id or an asset hash that does not exist (gRPC NOT_FOUND, exit code 3).
class NotFoundError : public std::runtime_error {
 public:
  explicit NotFoundError(const std::string& what) : std::runtime_error(what) {}
};

/// The queue or another bounded resource is full; retry later (gRPC RESOURCE_EXHAUSTED, exit
/// code 4).
class ResourceExhaustedError : public std::runtime_error {
 public:
  explicit ResourceExhaustedError(const std::string& what) : std::runtime_error(what) {}
};

/// A write failed because the volume has no space left (ENOSPC, or EDQUOT past a quota). A
/// ResourceExhaustedError: retry once space is freed. `what()` is the one message clients see,
/// which names no server path; `detail()` keeps the path and the system's words for the log.
class StorageFullError : public ResourceExhaustedError {
 public:
  explicit StorageFullError(std::string detail)
      : ResourceExhaustedError("no space left on the server's cache volume"),
        detail_(std::move(detail)) {}
  const std::string& detail() const { return detail_; }

 private:
  std::string detail_;
};

/// True for the errno values of a full volume.
inline bool isNoSpaceErrno(int err) { return err == ENOSPC || err == EDQUOT; }

/// Throws StorageFullError(detail) when `err` is such a value; returns otherwise.
inline void throwIfNoSpace(int err, const std::string& detail) {
  if (isNoSpaceErrno(err)) throw StorageFullError(detail);
}

/// The request is valid but the job is not in a state that allows it, e.g. fetching the result
/// of a job that has not succeeded (gRPC FAILED_PRECONDITION, exit code 5).
class FailedPreconditionError : public std::runtime_error {
 public:
  explicit FailedPreconditionError(const std::string& what) : std::runtime_error(what) {}
};

}  // namespace cloudbake
