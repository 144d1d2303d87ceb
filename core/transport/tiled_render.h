// The tile loop both view renderers share (the path tracer, the render from a bake).
#pragma once

#include <atomic>
#include <functional>

#include "core/transport/path_tracer.h"

namespace cloudbake {

/// One tile of an image: pixels [x0, x1) x [y0, y1); `index` in row-major tile order.
struct TileRect {
  int index = 0, x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};

/// What a tile's renderer polls between pixels: stop() is true once the render is cancelled.
/// It also asks the caller's progress (at most every 0.1 s across all threads), so a cancel
/// reaches a tile that takes long (a dense medium's paths), not only the next tile's start.
class TilePoll {
 public:
  explicit TilePoll(std::function<bool()> stop) : stop_(std::move(stop)) {}
  bool stop() const { return stop_(); }

 private:
  std::function<bool()> stop_;
};

/// Renders a width x height image tile by tile: tiles of `tile_size` pixels run in parallel on
/// TBB (inside an arena of `threads` when > 0, else the caller's), `setup` first inside that
/// arena (so its own parallel work uses the same threads). After each tile, and while tiles
/// run when they poll, `progress` gets the fraction of finished tiles (monotonic whatever the
/// finishing order); when it returns false the remaining work is skipped and renderTiles
/// returns false. `render_tile` polls `TilePoll::stop()` between pixels.
bool renderTiles(int width, int height, int tile_size, int threads, const ProgressFn& progress,
                 const std::function<void(const TileRect&, const TilePoll&)>& render_tile,
                 const std::function<void()>& setup = {});

/// Zeroed layers of a width x height view: beauty RGBA, the others RGB.
RenderLayers makeRenderLayers(int width, int height);

}  // namespace cloudbake
