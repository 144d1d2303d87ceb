#include "core/transport/tiled_render.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <mutex>

namespace cloudbake {

bool renderTiles(int width, int height, int tile_size, int threads, const ProgressFn& progress,
                 const std::function<void(const TileRect&, const std::atomic<bool>&)>& render_tile,
                 const std::function<void()>& setup) {
  const int tiles_x = (width + tile_size - 1) / tile_size;
  const int tiles = tiles_x * ((height + tile_size - 1) / tile_size);
  std::atomic<bool> cancelled{false};
  std::atomic<int> tiles_done{0};
  std::mutex progress_mutex;
  int reported = 0;
  auto run = [&] {
    if (setup) setup();
    tbb::parallel_for(tbb::blocked_range<int>(0, tiles, 1), [&](const tbb::blocked_range<int>& r) {
      for (int t = r.begin(); t != r.end(); ++t) {
        if (cancelled.load(std::memory_order_relaxed)) return;
        TileRect rect;
        rect.index = t;
        rect.x0 = (t % tiles_x) * tile_size;
        rect.y0 = (t / tiles_x) * tile_size;
        rect.x1 = std::min(rect.x0 + tile_size, width);
        rect.y1 = std::min(rect.y0 + tile_size, height);
        render_tile(rect, cancelled);
        const int done = ++tiles_done;
        if (progress) {
          std::lock_guard<std::mutex> lock(progress_mutex);
          reported = std::max(reported, done);
          if (!cancelled.load() && !progress(double(reported) / tiles)) cancelled = true;
        }
      }
    });
  };
  if (threads > 0) {
    tbb::task_arena arena(threads);
    arena.execute(run);
  } else {
    run();
  }
  return !cancelled;
}

RenderLayers makeRenderLayers(int width, int height) {
  RenderLayers out;
  out.beauty = Image(width, height, 4);
  out.sun = Image(width, height, 3);
  out.sky = Image(width, height, 3);
  out.single = Image(width, height, 3);
  out.multiple = Image(width, height, 3);
  return out;
}

}  // namespace cloudbake
