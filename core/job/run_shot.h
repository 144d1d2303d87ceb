// Runs a shot in-process: what `cloudbake render` and each job of cloudbake-server do.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "core/shot/shot.h"

namespace cloudbake {

class BakeCache;
class DirectionIndex;
class VolumeCache;

/// Where a run is: `stage` is "build", "render", "vdb" or "done"; `fraction` in [0, 1] of the
/// whole run (views weigh 1 each, the VDB 1); `view` and `view_fraction` for "render";
/// `message` a human line for logs ("view 'nadir' 32x32, 64 spp: cached").
struct RunProgress {
  std::string stage;
  double fraction = 0;
  std::string view;
  double view_fraction = 0;
  std::string message;
};

/// Return false to cancel: the run then throws Cancelled within about one tile of work.
using RunProgressFn = std::function<bool(const RunProgress&)>;

/// Options of runShot.
struct RunOptions {
  std::string out_dir;               ///< created if missing
  std::string source = "shot.json";  ///< prefix of error messages
  int threads = 0;                   ///< path tracer threads; 0: the caller's TBB arena
  int samples = -1;                  ///< -1: the shot's bake.samples; else 1..1e6
  bool png = false;                  ///< also DIR/<view>.png (auto-exposed sRGB preview)
  /// > 0: the PNG previews multiply radiance by this instead of auto-exposing (so previews of
  /// different lighting compare); finite, at most 1e12.
  double png_exposure = 0;
  RunProgressFn progress;            ///< optional
  BakeCache* cache = nullptr;        ///< optional: reuse/commit renders and VDBs
  VolumeCache* volumes = nullptr;    ///< optional: reuse built density fields
  /// With a cache and a direction index: a view not cached for the shot's own sun direction may
  /// reuse a cached render whose sun direction lies within this angle (degrees, in [0, 90]);
  /// 0 (default): only the exact (quantised) direction.
  DirectionIndex* directions = nullptr;
  double sun_tolerance_deg = 0;
  /// Voxels a volume may have once its files are read (a mesh given by voxel_size, a VDB's
  /// active voxels; core/job/volume_limits.h); 0: no limit.
  uint64_t max_voxels = 0;
};

/// One file a run wrote: `name` relative to out_dir ("nadir.exr", "bake.vdb").
struct OutputFile {
  std::string name;
  std::string path;
  uint64_t size = 0;
  std::string sha256;
};

/// What a run did. `views_rendered` counts path-traced views (scattering computations);
/// `views_cached` views served from the cache (and scaled to the sun irradiance). Bake methods
/// (single, pointcloud) compute their light once per light direction (`bakes_computed`) or
/// reuse it (`bakes_cached`), then ray-march every view from it (`views_from_bake`).
struct RunResult {
  std::vector<OutputFile> files;
  int views_rendered = 0;
  int views_cached = 0;
  int bakes_computed = 0;
  int bakes_cached = 0;
  int views_from_bake = 0;
  /// Views served from a render of another sun direction within the tolerance, and the largest
  /// angle (degrees) between that direction and the shot's.
  int views_reused_direction = 0;
  double reused_angle_deg = 0;
  bool volume_cached = false;
  bool vdb_cached = false;
  double seconds = 0;
};

/// Throws InputError when the shot's method or volume is not implemented by runShot yet
/// (methods precomputed and auto; animated volumes).
void checkRunnable(const ShotSpec& shot, const std::string& source = "shot.json");

/// Renders every view (when outputs.exr) to out_dir/<view>.exr — beauty RGBA unprefixed plus
/// `sun`, `sky`, `single`, `multiple` layers, with the same header attributes as `cloudbake
/// render` — and writes out_dir/bake.vdb when outputs.vdb (the density for pathtrace; the baked
/// light lattice for single and pointcloud). With a cache, a view (pathtrace) or a bake (single,
/// pointcloud) whose key (computeCacheKeys) is present is not computed again. Throws InputError for bad input,
/// Cancelled when `progress` returns false.
RunResult runShot(const ShotSpec& shot, const RunOptions& options);

}  // namespace cloudbake
