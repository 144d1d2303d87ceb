// Shared by the libFuzzer targets: bad input must end in InputError (the error a user sees);
// anything else escaping (another exception, a crash, a sanitizer report, running past
// -rss_limit_mb) is a finding.
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <functional>
#include <string>

#include "core/error.h"

namespace cloudbake::fuzz {

/// Writes the input to a private temporary file with `suffix` (readers take paths and choose
/// the format by extension), runs `read` on it and removes it.
inline void withTempFile(const uint8_t* data, size_t size, const std::string& suffix,
                         const std::function<void(const std::string&)>& read) {
  static const std::string dir = [] {
    char tmpl[] = "/tmp/cloudbake-fuzz-XXXXXX";
    const char* made = mkdtemp(tmpl);
    return std::string(made ? made : "/tmp");
  }();
  const std::string path = dir + "/input" + suffix;
  if (FILE* f = std::fopen(path.c_str(), "wb")) {
    const bool ok = std::fwrite(data, 1, size, f) == size;
    if (std::fclose(f) != 0 || !ok) return;
  } else {
    return;
  }
  try {
    read(path);
  } catch (const InputError&) {
    // The expected answer to bad bytes.
  }
  std::remove(path.c_str());
}

}  // namespace cloudbake::fuzz
