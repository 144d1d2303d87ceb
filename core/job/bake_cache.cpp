#include "core/job/bake_cache.h"

#include <fcntl.h>
#include <signal.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <exception>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <thread>
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

// Host and pid namespace, with '/' (not allowed in a folder name) spelled '~'.
std::string thisHost() {
  std::string holder = leaseHolderName();
  holder = holder.substr(0, holder.rfind(':'));
  std::replace(holder.begin(), holder.end(), '/', '~');
  return holder;
}

// Staging folders are named <host>@<pid>-<time>-<n> (uniqueSuffix). Debris: this host's whose
// process is gone, anyone's older than `stale`, and unnamed ones (a version before sharing).
bool stagingIsDebris(const fs::directory_entry& dir, std::chrono::hours stale) {
  const std::string name = dir.path().filename().string();
  const size_t at = name.rfind('@');
  if (at == std::string::npos) return true;
  if (name.substr(0, at) == thisHost()) {
    const long pid = std::strtol(name.c_str() + at + 1, nullptr, 10);
    if (pid == long(getpid())) return false;
    return pid <= 0 || (::kill(pid_t(pid), 0) != 0 && errno == ESRCH);
  }
  std::error_code ec;
  const auto t = fs::last_write_time(dir.path(), ec);
  return !ec && fs::file_time_type::clock::now() - t > stale;
}

uint64_t entryBytes(const fs::path& dir) {
  uint64_t bytes = 0;
  std::error_code ec;
  for (const auto& f : fs::directory_iterator(dir, ec)) {
    if (f.path().filename() != kManifest && f.is_regular_file(ec)) bytes += f.file_size(ec);
  }
  return bytes;
}
}  // namespace

struct BakeCache::InFlight {
  bool done = false;
  std::exception_ptr error;
  std::string path;
};

BakeCache::BakeCache(std::string root, uint64_t max_bytes)
    : BakeCache(std::move(root), [max_bytes] {
        BakeCacheOptions o;
        o.max_bytes = max_bytes;
        return o;
      }()) {}

BakeCache::BakeCache(std::string root, const BakeCacheOptions& options)
    : root_(std::move(root)), options_(options), max_bytes_(options.max_bytes) {
  for (const char* sub : {"entries", "staging", "leases", "trash"}) {
    fs::create_directories(fs::path(root_) / sub);
  }
  removeDebris();
  // Order existing entries by the manifest's mtime (touched on every use) to rebuild the LRU.
  std::vector<std::pair<fs::file_time_type, std::string>> found;
  for (const auto& dir : fs::directory_iterator(fs::path(root_) / "entries")) {
    std::error_code ec;
    const auto t = fs::last_write_time(dir.path() / kManifest, ec);
    if (!ec) found.emplace_back(t, dir.path().filename().string());
  }
  std::sort(found.begin(), found.end());
  for (const auto& [t, key] : found) {
    const uint64_t bytes = entryBytes(entryDir(key));
    index_[key] = {bytes, ++clock_};
    stats_.bytes += bytes;
  }
  stats_.entries = index_.size();
  std::lock_guard<std::mutex> lock(mutex_);
  evictLocked();
}

// Staging debris (core/job/bake_cache.h), trash left by a crash between rename and removal,
// and lease files moved aside by a takeover. Entries are never debris: a folder reaches
// entries/ only by the rename of a complete staging folder.
void BakeCache::removeDebris() {
  std::error_code ec;
  for (const auto& dir : fs::directory_iterator(fs::path(root_) / "staging", ec)) {
    if (stagingIsDebris(dir, options_.stale_staging)) fs::remove_all(dir.path(), ec);
  }
  for (const auto& dir : fs::directory_iterator(fs::path(root_) / "trash", ec)) {
    fs::remove_all(dir.path(), ec);
  }
  // Leases moved aside by a takeover, and a heartbeat's temporary file left by a crash (an hour
  // old: a live one is renamed within a heartbeat).
  for (const auto& f : fs::directory_iterator(fs::path(root_) / "leases", ec)) {
    const std::string name = f.path().filename().string();
    const auto t = fs::last_write_time(f.path(), ec);
    const bool old = !ec && fs::file_time_type::clock::now() - t > std::chrono::hours(1);
    if (name.find(".stale.") != std::string::npos ||
        (old && name.find(".tmp.") != std::string::npos)) {
      fs::remove(f, ec);
    }
  }
}

std::string BakeCache::entryDir(const std::string& key) const {
  return (fs::path(root_) / "entries" / key).string();
}

// Removal in two steps so another process never sees half an entry: a rename into trash/ (atomic),
// then the removal of what was renamed.
void BakeCache::removeDir(const std::string& dir) {
  const fs::path aside = fs::path(root_) / "trash" / (thisHost() + "@" + uniqueSuffix());
  std::error_code ec;
  fs::rename(dir, aside, ec);
  if (!ec) fs::remove_all(aside, ec);
}

void BakeCache::dropLocked(const std::string& key) {
  removeDir(entryDir(key));
  auto it = index_.find(key);
  if (it != index_.end()) {
    stats_.bytes -= it->second.bytes;
    index_.erase(it);
  }
  stats_.entries = index_.size();
}

// Known to this process, or committed by another since.
bool BakeCache::presentLocked(const std::string& key) {
  if (index_.count(key)) return true;
  std::error_code ec;
  if (!fs::exists(fs::path(entryDir(key)) / kManifest, ec)) return false;
  const uint64_t bytes = entryBytes(entryDir(key));
  index_[key] = {bytes, ++clock_};
  stats_.bytes += bytes;
  stats_.entries = index_.size();
  return true;
}

bool BakeCache::verifyLocked(const std::string& key) {
  const fs::path dir = entryDir(key);
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
    std::error_code ec;
    if (!fs::exists(dir, ec)) {  // removed by another process meanwhile: just absent
      dropLocked(key);
      return false;
    }
    spdlog::warn("cache: entry {} failed verification; dropped", key);
    dropLocked(key);
    ++stats_.corrupt;
  }
  return ok;
}

// The file server's clock sets the time (utimensat with no time given: NFS sends "set to server
// time"), so uses and their age are judged on one clock whatever the hosts' clocks say; it
// also needs only write access, not ownership, when several users share the folder.
static void touchNow(const fs::path& path) { ::utimensat(AT_FDCWD, path.c_str(), nullptr, 0); }

void BakeCache::touch(const std::string& key) {
  index_[key].last_use = ++clock_;
  touchNow(fs::path(entryDir(key)) / kManifest);
}

std::optional<std::string> BakeCache::lookup(const std::string& key) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!presentLocked(key) || !verifyLocked(key)) return std::nullopt;
  touch(key);
  ++stats_.hits;
  return entryDir(key);
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
  std::lock_guard<std::mutex> lock(mutex_);
  // Another process may have committed the same key (its lease went stale while it still
  // worked): keep a verified entry, replace a corrupt one.
  if (presentLocked(key) && verifyLocked(key)) {
    std::error_code ec;
    fs::remove_all(staging, ec);
    touch(key);
    return;
  }
  std::error_code ec;
  fs::create_directories(fs::path(entryDir(key)).parent_path(), ec);  // removed while running
  fs::rename(staging, entryDir(key), ec);
  if (ec) {
    // Another process committed the key meanwhile (its entry may not have been visible yet: NFS
    // caches "not found" for a while): keep the one there when it verifies.
    std::error_code rm;
    fs::remove_all(staging, rm);
    if (fs::exists(entryDir(key), rm) && presentLocked(key) && verifyLocked(key)) {
      touch(key);
      return;
    }
    throw std::runtime_error("cache: cannot commit entry " + key + ": " + ec.message());
  }
  auto it = index_.find(key);
  if (it != index_.end()) stats_.bytes -= it->second.bytes;
  index_[key] = {bytes, ++clock_};
  stats_.bytes += bytes;
  stats_.entries = index_.size();
  ++stats_.computed;
  evictLocked();
}

// Now on the file server's clock: the time a file touched now gets.
fs::file_time_type BakeCache::serverNow() const {
  const fs::path clock = fs::path(root_) / "clock";
  std::error_code ec;
  if (!fs::exists(clock, ec)) writeFileAtomic(clock.string(), "");
  touchNow(clock);
  const auto t = fs::last_write_time(clock, ec);
  return ec ? fs::file_time_type::clock::now() : t;
}

// Used within min_evict_age by any process: the manifest's mtime is touched on every use.
bool BakeCache::recentlyUsed(const std::string& key, fs::file_time_type now) const {
  std::error_code ec;
  const auto t = fs::last_write_time(fs::path(entryDir(key)) / kManifest, ec);
  return !ec && now - t < options_.min_evict_age;
}

void BakeCache::evictLocked() {
  if (max_bytes_ == 0) return;
  // The newest entry is the one just committed: kept even when it alone exceeds the bound.
  uint64_t newest = 0;
  for (const auto& [k, e] : index_) newest = std::max(newest, e.last_use);
  std::vector<std::pair<uint64_t, std::string>> by_age;
  for (const auto& [k, e] : index_) {
    if (e.last_use != newest && !in_flight_.count(k)) by_age.emplace_back(e.last_use, k);
  }
  std::sort(by_age.begin(), by_age.end());
  const fs::file_time_type now = serverNow();
  for (const auto& [use, key] : by_age) {
    if (stats_.bytes <= max_bytes_) break;
    if (recentlyUsed(key, now)) continue;
    const uint64_t bytes = index_[key].bytes;
    dropLocked(key);
    spdlog::debug("cache: evicted {} ({} bytes)", key, bytes);
    ++stats_.evicted;
  }
}

// Computes `key` into a fresh staging folder and commits it; the staging folder is removed on
// failure.
void BakeCache::computeInto(const std::string& key, const ComputeFn& compute) {
  const std::string staging =
      (fs::path(root_) / "staging" / (thisHost() + "@" + uniqueSuffix())).string();
  try {
    fs::create_directories(staging);
    compute(staging);
    commit(key, staging);
  } catch (...) {
    std::error_code ec;
    fs::remove_all(staging, ec);
    throw;
  }
}

// Single flight across processes: compute under the key's lease, or wait while another process
// holds it live, until its entry appears (a hit) or its lease ends without one (then take it).
std::string BakeCache::computeShared(const std::string& key, const ComputeFn& compute,
                                     const std::function<bool()>& should_stop) {
  const std::string lease_path = (fs::path(root_) / "leases" / (key + ".lease")).string();
  LeaseObserver observer;
  bool waited = false;
  for (;;) {
    bool took_over = false;
    std::unique_ptr<Lease> lease =
        Lease::tryAcquire(lease_path, options_.lease, observer, &took_over);
    if (lease) {
      if (took_over) {
        std::lock_guard<std::mutex> lock(mutex_);
        ++stats_.leases_taken_over;
      }
      {
        // Committed by the holder we waited for, between our last look and its release.
        std::lock_guard<std::mutex> lock(mutex_);
        if (presentLocked(key) && verifyLocked(key)) return entryDir(key);
      }
      computeInto(key, compute);
      return entryDir(key);
    }
    if (!waited) {
      std::lock_guard<std::mutex> lock(mutex_);
      ++stats_.shared_across_processes;
      waited = true;
    }
    std::this_thread::sleep_for(options_.poll);
    if (should_stop && should_stop()) throw Cancelled("cancelled while waiting");
    std::lock_guard<std::mutex> lock(mutex_);
    if (presentLocked(key) && verifyLocked(key)) return entryDir(key);
  }
}

std::string BakeCache::getOrCompute(const std::string& key, const ComputeFn& compute,
                                    const std::function<bool()>& should_stop) {
  std::unique_lock<std::mutex> lock(mutex_);
  bool waited = false;
  for (;;) {
    if (presentLocked(key) && verifyLocked(key)) {
      touch(key);
      ++stats_.hits;
      return entryDir(key);
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
    if (!flight->path.empty()) return flight->path;  // the identical computation we waited for
  }
  ++stats_.misses;
  auto flight = std::make_shared<InFlight>();
  in_flight_[key] = flight;
  lock.unlock();
  std::exception_ptr error;
  std::string path;
  try {
    path = computeShared(key, compute, should_stop);
  } catch (...) {
    error = std::current_exception();
  }
  lock.lock();
  flight->done = true;
  flight->error = error;
  flight->path = path;
  in_flight_.erase(key);
  cv_.notify_all();
  if (error) std::rethrow_exception(error);
  return path;
}

BakeCacheStats BakeCache::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

}  // namespace cloudbake
