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

/// Renders a width x height image tile by tile: tiles of `tile_size` pixels run in parallel on
/// TBB (inside an arena of `threads` when > 0, else the caller's), `setup` first inside that
/// arena (so its own parallel work uses the same threads). After each tile, `progress` gets the
/// fraction of finished tiles (monotonic whatever the finishing order); when it returns false
/// the remaining tiles are skipped and renderTiles returns false. `render_tile` receives the
/// cancellation flag to poll inside long tiles.
bool renderTiles(int width, int height, int tile_size, int threads, const ProgressFn& progress,
                 const std::function<void(const TileRect&, const std::atomic<bool>&)>& render_tile,
                 const std::function<void()>& setup = {});

/// Zeroed layers of a width x height view: beauty RGBA, the others RGB.
RenderLayers makeRenderLayers(int width, int height);

}  // namespace cloudbake
