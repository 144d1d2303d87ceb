// The last write of a command-line program: what it printed to standard output is flushed and
// checked, so a result piped into a full disk (a farm's `plan --json > plan.json`) fails the
// run instead of leaving an empty file behind an exit code of 0.
#pragma once

#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <string>

#include "common/exit_codes.h"
#include "core/error.h"

namespace cloudbake {

/// `code` when standard output took everything written to it; otherwise an error on standard
/// error naming `program`, and kUnavailable for a full volume (retry once space is freed) or
/// kFailure for any other write error.
inline int checkStdout(int code, const char* program) {
  std::cout.flush();
  errno = 0;
  const bool flushed = std::fflush(stdout) == 0 && !std::ferror(stdout) && std::cout.good();
  if (flushed) return code;
  int err = errno;
  if (err == 0) {
    // The failure happened in an earlier flush whose errno is gone: one more byte, on a
    // stream already broken, says why (ENOSPC on a full disk or /dev/full).
    if (::write(fileno(stdout), "\n", 1) < 0) err = errno;
  }
  std::cerr << program << ": error: cannot write to standard output"
            << (err ? std::string(": ") + std::strerror(err) : std::string()) << "\n";
  if (code != kOk) return code;
  return isNoSpaceErrno(err) ? kUnavailable : kFailure;
}

}  // namespace cloudbake
