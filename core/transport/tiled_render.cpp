#include "core/transport/tiled_render.h"

#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <mutex>

#include "core/math/parallel.h"

namespace cloudbake {

bool renderTiles(int width, int height, int tile_size, int threads, const ProgressFn& progress,
                 const std::function<void(const TileRect&, const TilePoll&)>& render_tile,
                 const std::function<void()>& setup) {
  const int tiles_x = (width + tile_size - 1) / tile_size;
  const int tiles = tiles_x * ((height + tile_size - 1) / tile_size);
  std::atomic<bool> cancelled{false};
  std::atomic<int> tiles_done{0};
  std::mutex progress_mutex;
  int reported = 0;
  ParallelOptions per_tile;  // the flag is polled before every tile
  per_tile.cancelled = [&](double) { return cancelled.load(std::memory_order_relaxed); };
  // Inside tiles: the flag, and the caller's progress once per kPollInterval whichever thread
  // comes first (the others go on without waiting for the lock).
  using Clock = std::chrono::steady_clock;
  constexpr auto kPollInterval = std::chrono::milliseconds(100);
  std::atomic<int64_t> next_poll{(Clock::now() + kPollInterval).time_since_epoch().count()};
  const TilePoll poll([&] {
    if (cancelled.load(std::memory_order_relaxed)) return true;
    if (!progress) return false;
    const auto now = Clock::now();
    int64_t due = next_poll.load(std::memory_order_relaxed);
    if (now.time_since_epoch().count() < due) return false;
    if (!next_poll.compare_exchange_strong(due, (now + kPollInterval).time_since_epoch().count())) {
      return false;
    }
    std::unique_lock<std::mutex> lock(progress_mutex, std::try_to_lock);
    if (!lock.owns_lock()) return false;
    if (!progress(double(reported) / tiles)) cancelled = true;
    return cancelled.load();
  });
  auto run = [&] {
    if (setup) setup();
    parallelFor(
        0, tiles,
        [&](int t) {
          TileRect rect;
          rect.index = t;
          rect.x0 = (t % tiles_x) * tile_size;
          rect.y0 = (t / tiles_x) * tile_size;
          rect.x1 = std::min(rect.x0 + tile_size, width);
          rect.y1 = std::min(rect.y0 + tile_size, height);
          render_tile(rect, poll);
          const int done = ++tiles_done;
          if (progress) {
            std::lock_guard<std::mutex> lock(progress_mutex);
            reported = std::max(reported, done);
            if (!cancelled.load() && !progress(double(reported) / tiles)) cancelled = true;
          }
        },
        per_tile);
  };
  try {
    if (threads > 0) {
      tbb::task_arena arena(threads);
      arena.execute(run);
    } else {
      run();
    }
  } catch (const Cancelled&) {
    if (!cancelled) throw;  // not our flag: someone else's cancellation
  }
  return !cancelled;
}

RenderLayers makeRenderLayers(int width, int height) {
  RenderLayers out;
  out.beauty = Image(width, height, 4);
  out.background = Image(width, height, 3);
  out.sun = Image(width, height, 3);
  out.sky = Image(width, height, 3);
  out.single = Image(width, height, 3);
  out.multiple = Image(width, height, 3);
  out.traced_pixels = int64_t(width) * height;
  return out;
}

}  // namespace cloudbake
