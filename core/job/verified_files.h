// Files checked against their SHA-256 in this process (issue 15, defect 5): a stored asset or a
// job's output is hashed on its first use and again whenever its size or modification time has
// changed, so a corrupted file is found before it is used or served.
#pragma once

#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <utility>

namespace cloudbake {

class VerifiedFiles {
 public:
  /// True when `path` exists and hashes to `sha256` (hashed outside any lock unless it was
  /// verified before and is unchanged since).
  bool check(const std::string& path, const std::string& sha256);
  /// Records `path` as verified as it is now (after a write whose hash is already known).
  void remember(const std::string& path);
  void forget(const std::string& path);

 private:
  using Stamp = std::pair<uintmax_t, int64_t>;  // size, modification time (ns)
  static bool stampOf(const std::string& path, Stamp* stamp);
  std::mutex mutex_;
  std::map<std::string, Stamp> verified_;
};

}  // namespace cloudbake
