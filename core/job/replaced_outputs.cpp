#include "core/job/replaced_outputs.h"

#include <filesystem>
#include <stdexcept>

#include "core/error.h"
#include "core/job/file_util.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;
}  // namespace

ReplacedOutputs::~ReplacedOutputs() { restore(); }

std::string ReplacedOutputs::hiddenName(const std::string& path) {
  const fs::path p(path);
  return (p.parent_path() / ("." + p.filename().string() + ".replaced." + uniqueSuffix())).string();
}

void ReplacedOutputs::keep(const std::string& path) {
  std::lock_guard<std::mutex> lock(mutex_);
  // A second write of the same name replaces this run's own file, which must not come back.
  if (!seen_.insert(path).second) return;
  std::error_code ec;
  // A folder where a file goes is not the user's earlier output: the write fails as before.
  const fs::file_status st = fs::symlink_status(path, ec);
  if (!fs::exists(st) || fs::is_directory(st)) return;
  const std::string hidden = hiddenName(path);
  fs::rename(path, hidden, ec);
  if (ec) {
    seen_.erase(path);
    // As for any other output that cannot be written (a read-only folder, say): the user's to
    // fix, not a bug of ours.
    throw InputError(path + ": cannot write over the earlier file: cannot move it aside (" +
                     ec.message() + ")");
  }
  kept_.push_back({path, hidden});
}

std::vector<std::string> ReplacedOutputs::restore() noexcept {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<std::string> lost;
  for (const auto& [path, hidden] : kept_) {
    std::error_code ec;
    fs::rename(hidden, path, ec);
    if (ec) lost.push_back(hidden);
  }
  kept_.clear();
  seen_.clear();
  return lost;
}

void ReplacedOutputs::commit() noexcept {
  std::lock_guard<std::mutex> lock(mutex_);
  for (const auto& kept : kept_) {
    std::error_code ec;
    fs::remove(kept.second, ec);
  }
  kept_.clear();
  seen_.clear();
}

size_t ReplacedOutputs::kept() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return kept_.size();
}

}  // namespace cloudbake
