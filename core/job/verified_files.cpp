#include "core/job/verified_files.h"

#include <filesystem>

#include "core/job/sha256.h"

namespace cloudbake {
namespace fs = std::filesystem;

bool VerifiedFiles::stampOf(const std::string& path, Stamp* stamp) {
  std::error_code ec;
  const uintmax_t size = fs::file_size(path, ec);
  if (ec) return false;
  const auto mtime = fs::last_write_time(path, ec);
  if (ec) return false;
  *stamp = {size, int64_t(mtime.time_since_epoch().count())};
  return true;
}

bool VerifiedFiles::check(const std::string& path, const std::string& sha256) {
  Stamp before;
  if (!stampOf(path, &before)) return false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto it = verified_.find(path);
    if (it != verified_.end() && it->second == before) return true;
  }
  std::string got;
  try {
    got = sha256File(path);
  } catch (const std::exception&) {
    return false;
  }
  Stamp after;
  if (got != sha256 || !stampOf(path, &after) || after != before) {
    forget(path);
    return false;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  verified_[path] = after;
  return true;
}

void VerifiedFiles::remember(const std::string& path) {
  Stamp stamp;
  if (!stampOf(path, &stamp)) return;
  std::lock_guard<std::mutex> lock(mutex_);
  verified_[path] = stamp;
}

void VerifiedFiles::forget(const std::string& path) {
  std::lock_guard<std::mutex> lock(mutex_);
  verified_.erase(path);
}

}  // namespace cloudbake
