#include "core/job/bake_cache.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <exception>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <vector>

#include "common/json_limits.h"
#include "core/error.h"
#include "core/job/file_util.h"
#include "core/job/sha256.h"

namespace cloudbake {
namespace fs = std::filesystem;
using Json = nlohmann::json;

namespace {
constexpr const char* kManifest = "MANIFEST.json";
}

struct BakeCache::InFlight {
  bool done = false;
  std::exception_ptr error;
  std::string path;
};

BakeCache::BakeCache(std::string root, uint64_t max_bytes)
    : root_(std::move(root)), max_bytes_(max_bytes) {
  fs::create_directories(fs::path(root_) / "entries");
  fs::remove_all(fs::path(root_) / "staging");
  fs::create_directories(fs::path(root_) / "staging");
  // Order existing entries by the manifest's mtime (touched on every use) to rebuild the LRU.
  std::vector<std::pair<fs::file_time_type, std::string>> found;
  for (const auto& dir : fs::directory_iterator(fs::path(root_) / "entries")) {
    const fs::path manifest = dir.path() / kManifest;
    std::error_code ec;
    const auto t = fs::last_write_time(manifest, ec);
    if (ec) {  // not an entry we committed: debris from elsewhere
      fs::remove_all(dir.path(), ec);
      continue;
    }
    found.emplace_back(t, dir.path().filename().string());
  }
  std::sort(found.begin(), found.end());
  for (const auto& [t, key] : found) {
    uint64_t bytes = 0;
    std::error_code ec;
    for (const auto& f : fs::directory_iterator(fs::path(root_) / "entries" / key, ec)) {
      if (f.path().filename() != kManifest && f.is_regular_file()) bytes += f.file_size();
    }
    index_[key] = {bytes, ++clock_};
    stats_.bytes += bytes;
  }
  stats_.entries = index_.size();
  std::lock_guard<std::mutex> lock(mutex_);
  evictLocked();
}

bool BakeCache::verifyLocked(const std::string& key) {
  const fs::path dir = fs::path(root_) / "entries" / key;
  bool ok = false;
  try {
    const Json manifest =
        parseJsonLimited(readWholeFile((dir / kManifest).string()), (dir / kManifest).string());
    ok = manifest.at("key").get<std::string>() == key;
    size_t files = 0;
    for (const auto& [name, info] : manifest.at("files").items()) {
      const fs::path p = dir / name;
      ++files;
      if (!ok || fs::file_size(p) != info.at("size").get<uint64_t>() ||
          sha256File(p.string()) != info.at("sha256").get<std::string>()) {
        ok = false;
        break;
      }
    }
    size_t present = 0;
    for (const auto& f : fs::directory_iterator(dir)) present += f.path().filename() != kManifest;
    ok = ok && present == files;
  } catch (const std::exception&) {
    ok = false;
  }
  if (!ok) {
    spdlog::warn("cache: entry {} failed verification; dropped", key);
    std::error_code ec;
    fs::remove_all(dir, ec);
    auto it = index_.find(key);
    if (it != index_.end()) {
      stats_.bytes -= it->second.bytes;
      index_.erase(it);
    }
    stats_.entries = index_.size();
    ++stats_.corrupt;
  }
  return ok;
}

void BakeCache::touch(const std::string& key) {
  index_[key].last_use = ++clock_;
  std::error_code ec;
  fs::last_write_time(fs::path(root_) / "entries" / key / kManifest,
                      fs::file_time_type::clock::now(), ec);
}

std::optional<std::string> BakeCache::lookup(const std::string& key) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!index_.count(key)) return std::nullopt;
  if (!verifyLocked(key)) return std::nullopt;
  touch(key);
  ++stats_.hits;
  return (fs::path(root_) / "entries" / key).string();
}

void BakeCache::commit(const std::string& key, const std::string& staging) {
  Json files = Json::object();
  uint64_t bytes = 0;
  for (const auto& f : fs::directory_iterator(staging)) {
    if (!f.is_regular_file())
      throw std::runtime_error("cache: " + f.path().string() + " is not a file");
    const uint64_t size = f.file_size();
    files[f.path().filename().string()] = {{"size", size},
                                           {"sha256", sha256File(f.path().string())}};
    bytes += size;
  }
  writeFileAtomic((fs::path(staging) / kManifest).string(),
                  Json{{"key", key}, {"files", files}}.dump(1));
  const fs::path dest = fs::path(root_) / "entries" / key;
  std::lock_guard<std::mutex> lock(mutex_);
  std::error_code ec;
  fs::remove_all(dest, ec);  // a corrupt entry dropped meanwhile, or none
  fs::rename(staging, dest);
  auto it = index_.find(key);
  if (it != index_.end()) stats_.bytes -= it->second.bytes;
  index_[key] = {bytes, ++clock_};
  stats_.bytes += bytes;
  stats_.entries = index_.size();
  ++stats_.computed;
  evictLocked();
}

void BakeCache::evictLocked() {
  if (max_bytes_ == 0) return;
  while (stats_.bytes > max_bytes_ && index_.size() > 1) {
    auto oldest = index_.end();
    for (auto it = index_.begin(); it != index_.end(); ++it) {
      if (in_flight_.count(it->first)) continue;
      if (oldest == index_.end() || it->second.last_use < oldest->second.last_use) oldest = it;
    }
    if (oldest == index_.end()) return;
    // The newest entry is the one just committed: keep it even when it alone exceeds the bound.
    uint64_t newest = 0;
    for (const auto& [k, e] : index_) newest = std::max(newest, e.last_use);
    if (oldest->second.last_use == newest) return;
    std::error_code ec;
    fs::remove_all(fs::path(root_) / "entries" / oldest->first, ec);
    stats_.bytes -= oldest->second.bytes;
    spdlog::debug("cache: evicted {} ({} bytes)", oldest->first, oldest->second.bytes);
    index_.erase(oldest);
    ++stats_.evicted;
  }
  stats_.entries = index_.size();
}

std::string BakeCache::getOrCompute(const std::string& key, const ComputeFn& compute,
                                    const std::function<bool()>& should_stop) {
  std::unique_lock<std::mutex> lock(mutex_);
  bool waited = false;
  for (;;) {
    if (index_.count(key) && verifyLocked(key)) {
      touch(key);
      ++stats_.hits;
      return (fs::path(root_) / "entries" / key).string();
    }
    auto it = in_flight_.find(key);
    if (it == in_flight_.end()) break;
    std::shared_ptr<InFlight> flight = it->second;
    if (!waited) ++stats_.shared;
    waited = true;
    while (!flight->done) {
      cv_.wait_for(lock, std::chrono::milliseconds(100));
      if (!flight->done && should_stop && should_stop()) throw Cancelled("cancelled while waiting");
    }
    if (flight->error) {
      try {
        std::rethrow_exception(flight->error);
      } catch (const Cancelled&) {
        continue;  // the computing request was cancelled, not ours: take over
      }
    }
    if (!flight->path.empty()) {
      // Served by the identical computation we waited for.
      return flight->path;
    }
  }
  ++stats_.misses;
  auto flight = std::make_shared<InFlight>();
  in_flight_[key] = flight;
  lock.unlock();
  const std::string staging = (fs::path(root_) / "staging" / uniqueSuffix()).string();
  std::exception_ptr error;
  try {
    fs::create_directories(staging);
    compute(staging);
    commit(key, staging);
  } catch (...) {
    error = std::current_exception();
    std::error_code ec;
    fs::remove_all(staging, ec);
  }
  lock.lock();
  flight->done = true;
  flight->error = error;
  if (!error) flight->path = (fs::path(root_) / "entries" / key).string();
  in_flight_.erase(key);
  cv_.notify_all();
  if (error) std::rethrow_exception(error);
  return flight->path;
}

BakeCacheStats BakeCache::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

}  // namespace cloudbake
