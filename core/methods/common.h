// Pieces several methods share: the shot's light direction and sky, the knobs of methods that
// render views from a lattice, the run of a method that bakes light once per light direction and
// renders every view from it, and the lattice's voxel limit.
#pragma once

#include <functional>
#include <map>
#include <string>
#include <vector>

#include "core/bake/bake_progress.h"
#include "core/bake/baked_light.h"
#include "core/bake/render_from_bake.h"
#include "core/methods/method.h"

namespace cloudbake {

/// The direction towards the sun, unit length; (0, 0, 1) when the shot has no sun (the sky's
/// bakes still need a lattice orientation). The one place that default lives.
Vec3 sunDirection(const ShotSpec& shot);

/// A view's header where it was lit from `lit`, not the shot's own sun direction (a cached bake
/// or render reused within --sun-tolerance): cloudbake:lit_sun_direction and
/// cloudbake:lit_sun_angle_deg, beside cloudbake:sun_direction, the shot's. Nothing where the
/// two are the same.
void addLitFrom(const ShotSpec& shot, const Vec3& lit, std::map<std::string, std::string>* out);

/// True when the shot's sky is not black (a bake then needs its sky terms).
bool needsSky(const ShotSpec& shot);

/// True when the shot has a sun that is not black (method photon then traces sun photons).
bool needsSun(const ShotSpec& shot);

/// The knobs of every method that renders views from a lattice; `derived_default` says what a
/// step left out is.
Knob stepKnob(const char* derived_default = "half a lattice voxel");
/// The views' sparse film (core/bake/sparse_film.h): the largest spacing of traced pixels.
Knob filmSpacingKnob();
Knob lightResolutionKnob(int64_t default_resolution, bool aligned_to_grid);

/// The share of a view's pixels whose rays were traced (the sparse film interpolates the rest):
/// a view step's "traced" in --stats-json.
inline double tracedShare(const RenderLayers& layers) {
  const double pixels = double(layers.beauty.width) * layers.beauty.height;
  return pixels > 0 ? double(layers.traced_pixels) / pixels : 0.0;
}

/// How views of a lattice method are rendered: `step`, bake.samples rays per pixel, bake.seed.
BakeRenderOptions bakeRenderOptions(const ShotSpec& shot, int threads);

/// Knobs of the shot that change the bake (view-only knobs left out), as key material.
nlohmann::json bakeKnobMaterial(const BakeMethod& method, const ShotSpec& shot);
/// The key material of a light bake that scatters with the whole medium (albedo and phase
/// included): the canonical medium, the seed, whether the sky is baked, and the bake's knobs.
nlohmann::json wholeMediumLightKey(const BakeMethod& method, const ShotSpec& shot,
                                   const nlohmann::json& canonical);

/// InputError naming `pointer` (the resolution's knob) unless (resolution + 2)^3 *
/// floats_per_voxel * lattices fits max_voxels.
void checkLatticeVoxels(int64_t resolution, double lattices_times_floats, const std::string& what,
                        const MethodLimits& limits, const std::string& source,
                        const std::string& pointer = "/bake/light_resolution");

/// Where the shot gives its volume's bounds (a box or a sphere), the lattice of `resolution`
/// the run would build over them: InputError naming `pointer` when it exceeds the bake lattices'
/// limit (kMaxBakeVoxels, whatever --max-voxels says), so the shot is refused at submit and in
/// a dry run, not after it is queued. Other volumes' bounds are known once their files are read.
void checkAnalyticLattice(const ShotSpec& shot, int resolution, const std::string& source,
                          const std::string& pointer = "/bake/light_resolution");

/// How far from 1 the integral over the sphere of a phase's table (PhaseLut) may be.
constexpr double kMaxPhaseTableError = 0.02;

/// Methods that read the phase from its table (every light bake and its views): InputError
/// naming /medium/phase where the table does not integrate to 1 within kMaxPhaseTableError, a
/// peak narrower than its bins (HG |g| above about 0.999: 0.9995 integrates to 1.04, 0.9999 to
/// 2.4, 0.99999 to 195, and the light scattered through it with it). Lorenz-Mie tables, whose
/// peaks the table resolves, are not built for the check (they take seconds).
void checkPhaseTable(const ShotSpec& shot, const std::string& source, const char* method);

/// InputError naming `pointer` and --max-points when `points` exceeds the server's limit.
void checkPointCount(int64_t points, const std::string& pointer, const MethodLimits& limits,
                     const std::string& source);

/// The dry-run lines every light-baking method starts with (lattice, sun, sky).
std::vector<std::string> lightBakePlanLines(const ShotSpec& shot, int64_t resolution);

/// A dry-run plan for a method whose views are ray-marched from one bake: the method's own
/// component lines first, then one line per view.
MethodPlan lightBakePlan(const ShotSpec& shot, const ShotCacheKeys& keys,
                         const std::function<bool(const std::string&)>& lookup,
                         std::vector<std::string> bake_lines);

/// Bakes the shot's light (the medium's density, extinction, albedo and phase) for its sun
/// direction; returns the lattice. `progress(fraction, stage)` returns false to cancel.
using LightBakeFn = std::function<BakedLight(const Medium& medium, const Vec3& sun_direction,
                                             const BakeProgressFn& progress)>;

/// What a light-baking run's parts cost, predicted in seconds on the reference machine (2 cores),
/// for progress and its ETA only: a part's share of the bar is its share of the predicted work.
/// `bake_seconds`: the bake, computed; `view_seconds_per_ray`: a view's cost per ray (pixels x
/// rays per pixel).
struct LightBakeWork {
  double bake_seconds = 1;
  double view_seconds_per_ray = 1.5e-6;
  /// The bake lattice's light_resolution, for checking the views' step before the bake (0: not
  /// checked there).
  int64_t light_resolution = 0;
};

/// The predicted seconds of one pass over a bake lattice of `resolution` voxels along the longest
/// side (the sun's transmittance; a sky's visibility is a second): 0.04 s and 0.1 us per voxel of
/// half the lattice's cube, fitted by bench/auto_cost_fit.py to `single` bakes of the five bench
/// scenes at 64-256 voxels on two cores (0.007-0.6 us measured; the lattice's box is half empty
/// on them, and below a grid's own resolution the lattice is its voxels).
double latticeSeconds(int64_t resolution);

/// The run of a light-baking method: the bake from the cache (or a cached bake of a sun
/// direction within the tolerance) or computed by `bake`, every view ray-marched from it, and
/// bake.vdb when asked. Progress advances by each part's share of `work`.
void runLightBake(MethodRun& run, const LightBakeFn& bake, const LightBakeWork& work);

}  // namespace cloudbake
