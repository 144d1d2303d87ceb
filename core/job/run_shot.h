// Runs a shot in-process: what `cloudbake render` and each job of cloudbake-server do.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/job/vdb_gate.h"
#include "core/methods/auto.h"
#include "core/methods/run_types.h"
#include "core/shot/shot.h"

namespace cloudbake {

class BakeCache;
class DirectionIndex;
class PhaseCache;
class VolumeCache;

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
  RunProgressFn progress;          ///< optional
  BakeCache* cache = nullptr;      ///< optional: reuse/commit renders and VDBs
  VolumeCache* volumes = nullptr;  ///< optional: reuse built density fields
  PhaseCache* phases = nullptr;    ///< optional: reuse built phase functions (Mie tables)
  /// With a cache and a direction index: a view not cached for the shot's own sun direction may
  /// reuse a cached render whose sun direction lies within this angle (degrees, in [0, 90]);
  /// 0 (default): only the exact (quantised) direction.
  DirectionIndex* directions = nullptr;
  double sun_tolerance_deg = 0;
  /// Voxels a volume may have once its files are read (a mesh given by voxel_size, a VDB's
  /// active voxels; core/job/volume_limits.h); 0: no limit.
  uint64_t max_voxels = 0;
  /// Most bake.samples and photon-lattice voxels method `auto` may choose (0: no limit beyond
  /// the methods' own ranges).
  int max_samples = 0;
  /// The part of the shot to compute (a farm task, core/job/task_plan.h); all by default. A
  /// part other than all needs `cache`, where the parts meet.
  RunScope scope;
  /// A shot of method `auto` whose choice was made already (by a farm plan, so its tasks do
  /// not each measure the scene): runShot runs `shot` with `summary` in every view's header
  /// and writes `record` (AutoChoice::toJson) as auto.json.
  struct AutoPreset {
    ShotSpec shot;
    std::string summary;
    nlohmann::json record;
  };
  std::optional<AutoPreset> auto_preset;
  /// How user VDB files are read: with a command, each is first rewritten by it in a child
  /// process and the run reads the rewrite (core/job/vdb_gate.h; the server's default).
  VdbReaderOptions vdb_reader;
};

/// InputError naming `field` unless `samples` is -1 (unset) or in [1, 1e6]: the one check of
/// a samples override, shared by the CLI, runShot and the server.
void checkSamplesOverride(int samples, const std::string& field);

/// Throws InputError when runShot cannot run the shot as given: a method that is not runnable,
/// an animated volume for a method that does not animate, or an EXR compression that is not
/// one of kExrCompressionNames (a shot built in code rather than parsed).
void checkRunnable(const ShotSpec& shot, const std::string& source = "shot.json");

/// Renders every view (when outputs.exr) to out_dir/<view>.exr — beauty RGBA unprefixed plus
/// `sun`, `sky`, `single`, `multiple` layers, with the same header attributes as `cloudbake
/// render` — and writes out_dir/bake.vdb when outputs.vdb (the density for pathtrace; the baked
/// light lattice for single and pointcloud). With a cache, a view (pathtrace) or a bake (single,
/// pointcloud) whose key (computeCacheKeys) is present is not computed again. Throws InputError for
/// bad input, Cancelled when `progress` returns false.
RunResult runShot(const ShotSpec& shot, const RunOptions& options);

/// For a shot of method `auto`: builds its scene through the options' caches, measures it and
/// returns the choice (core/methods/auto.h) without running it; runShot runs choice.shot and
/// writes the choice to DIR/auto.json. Optional: `steps` receives the volume and pilot times,
/// `density` the field it built (none for a sequence).
AutoChoice chooseAutoForRun(const ShotSpec& shot, const RunOptions& options,
                            std::vector<StepTime>* steps = nullptr,
                            DensityFieldPtr* density = nullptr);

}  // namespace cloudbake
