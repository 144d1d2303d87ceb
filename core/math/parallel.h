// The one parallel loop of core/: every loop's grain size and cooperative cancellation are decided
// here, so a change of scheduling policy or of how cancellation is polled is made in one place.
#pragma once

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <type_traits>

#include "core/error.h"

namespace cloudbake {

/// The grain of loops whose iterations cost a few nanoseconds (one voxel's arithmetic): enough
/// indices per chunk that a chunk is worth scheduling.
constexpr int64_t kCheapIterationGrain = 4096;

struct ParallelOptions {
  /// Indices per chunk: TBB never splits work below this (except at the end of the range). The
  /// default of 1 suits iterations that cost a microsecond or more (a slice, a row, a tile, a
  /// receiver); TBB's partitioner still hands out large chunks while threads are busy.
  int64_t grain = 1;
  /// Optional cooperative cancellation, polled with the fraction of indices done (in [0, 1)):
  /// before the first chunk, then before a chunk at most every kCancelPollInterval. Chunks are
  /// then at most `grain` indices, so a grain of well under a second of work stops a loop within
  /// about a second. It may be a progress callback: calls come from worker threads but never two
  /// at once, and the fractions they see never decrease. Returning true skips every chunk not yet
  /// started, and parallelFor throws Cancelled(cancelled_message) once the running ones are done.
  std::function<bool(double fraction_done)> cancelled = {};
  std::string cancelled_message = "cancelled";
};

/// Polls of a cancellation predicate are at least this far apart, so polling is cheap at any
/// grain.
constexpr std::chrono::milliseconds kCancelPollInterval{10};

namespace parallel_detail {

template <class F>
void runChunk(F& body, int64_t lo, int64_t hi) {
  if constexpr (std::is_invocable_v<F&, int64_t, int64_t>) {
    body(lo, hi);
  } else {
    for (int64_t i = lo; i < hi; ++i) body(i);
  }
}

// Spaces out and serialises the polls of one loop's cancellation predicate; remembers a stop.
class CancelPoll {
 public:
  using Clock = std::chrono::steady_clock;

  CancelPoll(const std::function<bool(double)>& cancelled, int64_t total)
      : cancelled_(cancelled), total_(double(total)) {}

  // Polls when due and no other thread is polling; true once any poll asked to stop.
  bool stop() {
    if (stopped()) return true;
    const Clock::rep now = Clock::now().time_since_epoch().count();
    if (now < next_poll_.load(std::memory_order_relaxed)) return false;
    std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
    if (!lock.owns_lock()) return stopped();
    next_poll_ = now + std::chrono::duration_cast<Clock::duration>(kCancelPollInterval).count();
    if (cancelled_(double(done_.load()) / total_)) stopped_ = true;
    return stopped();
  }
  bool stopped() const { return stopped_.load(std::memory_order_relaxed); }
  void finished(int64_t count) { done_ += count; }

 private:
  const std::function<bool(double)>& cancelled_;
  const double total_;
  std::mutex mutex_;
  std::atomic<Clock::rep> next_poll_{0};
  std::atomic<int64_t> done_{0};
  std::atomic<bool> stopped_{false};
};

}  // namespace parallel_detail

/// Runs `body` over [begin, end) on TBB. `body` is either body(i) per index or body(lo, hi) per
/// chunk [lo, hi) (for state set up once per chunk: a density lookup, scratch buffers). Chunk
/// boundaries depend on scheduling, so results must not: each index writes its own outputs, or
/// per-chunk results are combined in index order afterwards. Throws Cancelled as described at
/// ParallelOptions::cancelled; exceptions thrown by `body` or the predicate propagate.
template <class F>
void parallelFor(int64_t begin, int64_t end, F&& body, const ParallelOptions& options = {}) {
  if (begin >= end) return;
  const int64_t grain = std::max<int64_t>(1, options.grain);
  const tbb::blocked_range<int64_t> range(begin, end, size_t(grain));
  if (!options.cancelled) {
    tbb::parallel_for(range, [&](const tbb::blocked_range<int64_t>& r) {
      parallel_detail::runChunk(body, r.begin(), r.end());
    });
    return;
  }
  parallel_detail::CancelPoll poll(options.cancelled, end - begin);
  // Polled once here, before any chunk: inside the loop a thread that finds another polling
  // goes on with its chunk, so a loop asked to stop from the start ran a few chunks (6 of 1000
  // in a CI run) before the first poll's answer was seen.
  if (poll.stop()) throw Cancelled(options.cancelled_message);
  tbb::parallel_for(range, [&](const tbb::blocked_range<int64_t>& r) {
    for (int64_t lo = r.begin(); lo < r.end(); lo += grain) {
      if (poll.stop()) return;
      const int64_t hi = std::min(r.end(), lo + grain);
      parallel_detail::runChunk(body, lo, hi);
      poll.finished(hi - lo);
    }
  });
  if (poll.stopped()) throw Cancelled(options.cancelled_message);
}

}  // namespace cloudbake
