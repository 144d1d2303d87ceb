// Plain types a run and its method share: the cache keys of a shot, what a run reports as it
// goes, and what it wrote. Kept apart from core/job so methods (core/methods) can use them.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace cloudbake {

/// Content-addressed keys (hex SHA-256) of the parts of a shot a service can reuse.
///
/// - `volume`: the density field: the volume spec with every referenced file replaced by the
///   SHA-256 of its content (so a renamed or re-uploaded VDB still hits) + the volume code's
///   algorithm version (core/methods/versions.h).
/// - `bake`: what the scattering depends on: volume key, medium (extinction, albedo, phase),
///   quantised sun direction, sky, method and every quality knob (samples, seed, max_depth,
///   method options) + the method's and the shared pieces' algorithm versions (algorithmSalt). Not
///   in it: views, sun colour/intensity, image size.
/// - `vdb`: DIR/bake.vdb of pathtrace (the density grid): volume key + vdb voxel size + shot
///   name (it is in the file's metadata) + versions.
/// - `views[i]`: one rendered view: bake key + that camera and its pixel size; plus the sun
///   irradiance only when `sun_scaled` is false.
///
/// `sun_scaled` is true when the shot has a sun with non-zero irradiance and a black sky: then
/// every rendered channel is linear in the sun irradiance per channel (the path tracer's random
/// decisions do not depend on it), so a view is rendered once at unit irradiance and scaled, and
/// a new sun colour or intensity recomputes nothing.
struct ShotCacheKeys {
  std::string volume;
  std::string bake;
  /// The bake key's material without the sun direction: bakes that differ only in their light
  /// direction share it (used to find a cached bake within a direction tolerance).
  std::string family;
  std::string vdb;
  std::vector<std::string> views;
  bool sun_scaled = false;
  /// Methods that bake light (single, pointcloud): the baked-light lattice, keyed by what the
  /// scattering depends on: volume key, medium (single: extinction only, since albedo and phase
  /// are applied when a view is rendered), quantised sun direction, whether the sky term is
  /// baked (not the sky's radiance), method, seed and knobs other than the view-only `step` and
  /// `samples` + versions. Not in it: views, sun colour or intensity, sky radiance, image
  /// size. Empty for other methods. `light_family` is the same without the sun direction.
  std::string light;
  std::string light_family;
  /// Method precomputed: the per-basic-volume precompute (optical-depth SH, sample tree, cuts),
  /// keyed by volume key, extinction, seed and the precompute knobs (light_resolution,
  /// sample_points, transfer_resolution, cut_error) + versions. Not in it: sun, sky, albedo,
  /// phase, views, frames and the walk's knobs, so every lighting and every animation of the
  /// same database reuses it. Empty for other methods.
  std::string precompute;
  /// Its parts, for `sequence` volumes only: the layout (lattice densities, receivers, sample
  /// tree) and each basic volume's precompute, which farm tasks compute apart (RunScope).
  std::string precompute_layout;
  std::vector<std::string> precompute_basic;
  /// The material of `bake`, `light` and each view's key without the sun direction (JSON
  /// text), so the key of another direction is one hash (lightKeyAt, viewKeyAt).
  std::string bake_material;
  std::string light_material;
  std::vector<std::string> view_materials;
};

/// Which part of a shot a run computes: all of it (the default), or one task of a farm plan
/// (core/job/task_plan.h). Tasks run in the plan's order over one bake cache leave exactly the
/// files the whole run writes, since each computes the same cache entries and outputs as the
/// whole run and skips the rest.
/// - kLayout (precomputed, sequences): the database's shared layout, into the cache.
/// - kPrecompute: basic volumes [begin, end) of the layout, into the cache.
/// - kBake: the light bake of the shot's sun direction (precomputed: the whole database), into
///   the cache; writes no output.
/// - kRender: views [begin, end) (precomputed: frames [begin, end), every view).
/// - kGather: the shot's own files (bake.vdb, animation.json, auto.json), no views.
struct RunScope {
  enum class Part { kAll, kLayout, kPrecompute, kBake, kRender, kGather };
  Part part = Part::kAll;
  int begin = 0;
  int end = 0;

  bool all() const { return part == Part::kAll; }
  /// View `i` (or frame `i` of precomputed) is rendered by this run.
  bool renders(int i) const {
    return part == Part::kAll || (part == Part::kRender && i >= begin && i < end);
  }
  bool rendersAny() const { return part == Part::kAll || part == Part::kRender; }
  /// bake.vdb, animation.json and auto.json.
  bool writesShotFiles() const { return part == Part::kAll || part == Part::kGather; }
};

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

/// One file a run wrote: `name` relative to out_dir ("nadir.exr", "bake.vdb").
struct OutputFile {
  std::string name;
  std::string path;
  uint64_t size = 0;
  std::string sha256;
};

/// One timed step of a run, for `cloudbake render --stats-json` and the benchmarks: `step` is
/// "volume" (building the density), "bake" (a light bake, or its read from the cache),
/// "precompute" (method precomputed's database), "light" (one animation frame's lighting) or
/// "view" (one view rendered or served); `view` and `frame` say which (frame -1: none);
/// `values` holds the step's own numbers ("orders", "mib_per_basic_volume", "cached" 0/1).
struct StepTime {
  std::string step;
  std::string view;
  int frame = -1;
  double seconds = 0;
  std::map<std::string, double> values;
};

/// What a run did. `views_rendered` counts path-traced views (scattering computations);
/// `views_cached` views served from the cache (and scaled to the sun irradiance). Bake methods
/// (single, pointcloud) compute their light once per light direction (`bakes_computed`) or
/// reuse it (`bakes_cached`), then ray-march every view from it (`views_from_bake`).
struct RunResult {
  std::string method;  ///< the bake method that ran (for a shot of `auto`: the one it chose)
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
  std::vector<StepTime> steps;  ///< in the order they ran
  /// The bake's own error estimates, where its method gives them (photon: tally_noise and
  /// truncation, as in bake.vdb's metadata).
  std::map<std::string, double> bake_estimates;
};

}  // namespace cloudbake
