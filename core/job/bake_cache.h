// The content-addressed result cache (docs/DESIGN.md, "Cache"): entries are folders of files
// under a key, written atomically, verified on read, evicted LRU under a size bound, and
// computed once for concurrent identical requests, also across processes and hosts sharing the
// folder (docs/deployment.md, "Shared cache").
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "core/job/lease.h"

namespace cloudbake {

/// Counters of a BakeCache since it was opened.
struct BakeCacheStats {
  uint64_t hits = 0;      ///< lookups served from a verified entry
  uint64_t misses = 0;    ///< lookups that had to compute
  uint64_t computed = 0;  ///< entries computed and committed
  uint64_t corrupt = 0;   ///< entries dropped because a checksum or the manifest was wrong
  uint64_t evicted = 0;   ///< entries removed by the size bound
  uint64_t shared = 0;    ///< requests that waited for another request's identical computation
  uint64_t shared_across_processes = 0;  ///< of them, waits on another process's lease
  uint64_t leases_taken_over = 0;        ///< computations of a key whose lease went stale
  uint64_t entries = 0;                  ///< entries now held
  uint64_t bytes = 0;                    ///< bytes now held
};

/// How a BakeCache shares its folder with other processes.
struct BakeCacheOptions {
  uint64_t max_bytes = 0;  ///< 0: no bound
  /// Single flight across processes: a computation holds ROOT/leases/<key> (core/job/lease.h).
  LeaseOptions lease;
  /// How often a caller waiting for another process's computation looks for its entry.
  std::chrono::milliseconds poll{200};
  /// Eviction never removes an entry used (looked up, computed) within this long, by this
  /// process or any other: a reader of an entry finishes well within it.
  std::chrono::seconds min_evict_age{600};
  /// Staging folders of other hosts are debris once this old (this host's are debris as soon
  /// as their process is gone).
  std::chrono::hours stale_staging{24};
};

/// On-disk layout: ROOT/entries/<key>/<files> + MANIFEST.json ({"files": {name: {"size",
/// "sha256"}}}), built in ROOT/staging/<host>@<unique>/ and renamed into place in one step, so
/// an entry is either complete or absent (a crash leaves only staging debris, removed on open).
/// Thread safe; safe for many processes on many hosts sharing ROOT with NFS semantics (atomic
/// rename and O_EXCL create; no flock): entries another process committed are found on lookup,
/// identical computations run once while their lease is live, and removal (corrupt entries,
/// eviction) renames into ROOT/trash first, so a reader sees a whole entry or none.
class BakeCache {
 public:
  /// Opens (creating) ROOT, removes staging debris, indexes existing entries by their
  /// manifest's modification time (last use). `max_bytes` 0: no bound.
  BakeCache(std::string root, uint64_t max_bytes);
  BakeCache(std::string root, const BakeCacheOptions& options);

  /// A computation fills the folder it is given with the entry's files (flat, no sub-folders).
  using ComputeFn = std::function<void(const std::string& staging_dir)>;

  /// Returns the folder of entry `key`: a verified existing entry (hit), or one computed by
  /// `compute` now. While a computation for `key` runs, other callers for the same key wait for
  /// it (single flight) instead of computing again; `should_stop` is polled while waiting and
  /// makes the wait throw Cancelled when it returns true. When the computing caller fails with
  /// Cancelled, one waiter takes over; other exceptions reach every waiter of this process.
  /// Another process's computation is waited for through its lease: when it ends without an
  /// entry (failed, killed) or its lease goes stale, one waiter computes.
  /// The returned folder stays valid until the entry is evicted: callers link or copy the files
  /// they keep (linking keeps the bytes alive after eviction).
  std::string getOrCompute(const std::string& key, const ComputeFn& compute,
                           const std::function<bool()>& should_stop = {});

  /// The folder of a verified entry, or nullopt (a corrupt entry is removed). Counts a hit or
  /// nothing; never computes.
  std::optional<std::string> lookup(const std::string& key);

  BakeCacheStats stats() const;
  const std::string& root() const { return root_; }

 private:
  struct InFlight;
  bool presentLocked(const std::string& key);
  bool verifyLocked(const std::string& key);
  void dropLocked(const std::string& key);
  void removeDir(const std::string& dir);
  std::string computeShared(const std::string& key, const ComputeFn& compute,
                            const std::function<bool()>& should_stop);
  void computeInto(const std::string& key, const ComputeFn& compute);
  void commit(const std::string& key, const std::string& staging);
  void evictLocked();
  bool recentlyUsed(const std::string& key, std::filesystem::file_time_type now) const;
  std::filesystem::file_time_type serverNow() const;
  void touch(const std::string& key);
  void removeDebris();
  std::string entryDir(const std::string& key) const;

  std::string root_;
  BakeCacheOptions options_;
  uint64_t max_bytes_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  struct Entry {
    uint64_t bytes = 0;
    uint64_t last_use = 0;  ///< logical clock
  };
  std::map<std::string, Entry> index_;
  std::map<std::string, std::shared_ptr<InFlight>> in_flight_;
  uint64_t clock_ = 0;
  BakeCacheStats stats_;
};

}  // namespace cloudbake
