// A lease on a name, held by one process among many processes and hosts that share a folder:
// the cache's single flight across processes (docs/deployment.md, "Shared cache").
//
// Only what NFS guarantees is relied on: creating a file with O_EXCL and renaming within one
// folder are atomic; flock is not used and the hosts' clocks need not agree. The holder rewrites
// its lease file with a new heartbeat count every `heartbeat`; an observer judges a lease stale
// when its content has not changed for `stale_after` by the observer's own clock, or at once
// when the holder is a dead process on the observer's own host.
#pragma once

#include <chrono>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

namespace cloudbake {

/// Timing of leases. `stale_after` must be several heartbeats (InputError otherwise).
struct LeaseOptions {
  std::chrono::milliseconds heartbeat{2000};
  std::chrono::milliseconds stale_after{20000};
};

/// What one observer saw of a lease it does not hold, to judge staleness by its own clock.
struct LeaseObserver {
  bool seen = false;  ///< content and changed are valid
  std::string content;
  std::chrono::steady_clock::time_point changed{};
};

/// "<hostname>/<pid namespace>:<pid>" of this process: who a lease file names. The namespace
/// tells apart processes of containers that share a host name but not their process ids.
std::string leaseHolderName();

/// A lease this process holds: it beats until destroyed, then removes its file if it is still
/// its own (a lease taken over meanwhile is left to its new holder).
class Lease {
 public:
  /// Takes the lease at `path` when it is free, or stale as `observer` has seen it (the stale
  /// file is renamed away first, so one taker wins); nullptr when another holds it. `observer`
  /// carries what this caller saw between calls; `took_over` says whether a stale lease was
  /// replaced. Throws std::runtime_error when the folder cannot be written.
  static std::unique_ptr<Lease> tryAcquire(const std::string& path, const LeaseOptions& options,
                                           LeaseObserver& observer, bool* took_over = nullptr);
  ~Lease();
  Lease(const Lease&) = delete;
  Lease& operator=(const Lease&) = delete;

  /// False once another process took the lease over (this one then stopped beating).
  bool held() const;
  const std::string& path() const { return path_; }

 private:
  Lease(std::string path, std::string content, const LeaseOptions& options);
  void beat();

  std::string path_;
  std::string content_;
  LeaseOptions options_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  bool stop_ = false;
  bool lost_ = false;
  std::thread thread_;
};

}  // namespace cloudbake
