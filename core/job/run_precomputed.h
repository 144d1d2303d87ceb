// Method `precomputed` in a run (seed 002): the database of basic volumes and its precompute
// (from the bake cache when present), the endless walk, and every frame lit from the
// precomputes and rendered as an EXR sequence (and per-frame VDBs on request).
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "core/animation/precomputed.h"
#include "core/animation/video_texture.h"
#include "core/job/cache_key.h"
#include "core/job/run_shot.h"
#include "core/shot/scene_builder.h"
#include "core/transport/scene.h"

namespace cloudbake {

/// The `bake` knobs of a method-precomputed shot with their defaults (docs/shot-format.md).
struct PrecomputedShotOptions {
  int light_resolution = 64;  ///< lattice voxels along the longest side
  PrecomputeOptions precompute;
  FrameLightOptions frame;
  VideoTextureOptions walk;
  int frames = 1;         ///< output frames; default: the database's size
  int basic_volumes = 1;  ///< the sequence's frames (1 for a static volume)
};
PrecomputedShotOptions precomputedOptions(const ShotSpec& shot);

/// Dry-run lines for a precomputed shot; `cached`: the precompute is in the cache.
std::vector<std::string> planPrecomputed(const ShotSpec& shot, bool cached);

/// Output names of frame `f`: "<stem>.<ffff>" (4 digits at least, as DCC frame sequences).
std::string frameStem(const std::string& stem, int frame);

/// Runs the shot: `lights` holds medium (extinction, albedo, phase), sun, sky and cameras;
/// `density` builds a static volume's field (not called for a sequence). Writes
/// DIR/<view>.<ffff>.exr per frame and view, DIR/bake.<ffff>.vdb per frame when outputs.vdb,
/// and DIR/animation.json (the walk: per frame the two basic volumes and the weight).
/// `report(stage, fraction of the run, message)` returns false to cancel.
void runPrecomputed(
    const ShotSpec& shot, const RunOptions& opt, const ShotCacheKeys& keys, const Scene& lights,
    const std::function<DensityFieldPtr()>& density,
    const std::function<bool(const std::string&, double, const std::string&)>& report,
    RunResult& result);

}  // namespace cloudbake
