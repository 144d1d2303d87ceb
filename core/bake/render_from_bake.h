// Any view of a bake: a ray march through the baked grids with the phase function evaluated for
// the view's directions (seed 000 Eq. 6-8, seed 004's marcher). No scattering is recomputed.
#pragma once

#include <cstdint>
#include <memory>

#include "core/bake/baked_light.h"
#include "core/bake/sparse_film.h"
#include "core/transport/path_tracer.h"
#include "core/transport/scene.h"

namespace cloudbake {

/// The most rays per pixel a view from a bake traces (bake.samples of the light-bake methods).
constexpr int kMaxViewSamples = 1024;

class SkyLight;

/// The longest march step a view takes, in lattice voxels (BakeRenderOptions::step).
constexpr double kMaxStepVoxels = 4;

/// What the views of one bake share whatever their camera, built by the first view that reads
/// it and reused by the rest (render_from_bake.cpp): the empty-space blocks' densest voxels, a
/// byte per lattice cell saying whether it holds density, and the grids a sample reads, packed
/// per voxel. Building them is a fifth of a 640x480 view of a
/// 128-voxel cloud's bake (docs/methods.md, "A further view reuses its bake's blocks and
/// packs"); they stay allocated while the cache lives. It holds the grids' addresses as its key and
/// rebuilds what a render's grids or their layout (a black sky reads fewer) do not match; so
/// use it only while the bake it was filled from is alive and unchanged, one render at a time,
/// and forget() it before the views of a bake made after that one was freed (which may take
/// its addresses). It also keeps method photon's light scattered through a droplet's peak
/// (PhotonPeakLight: four convolutions of the phase, 0.012-0.015 s of a 640x480 view), keyed on
/// the phase's table, cut and albedo themselves, which forget() keeps.
class BakeViewCache {
 public:
  BakeViewCache();
  ~BakeViewCache();
  BakeViewCache(const BakeViewCache&) = delete;
  BakeViewCache& operator=(const BakeViewCache&) = delete;

  /// How many blocks, packs and peak lights the renders that used it have built.
  int builds() const;
  /// Forgets the bake it was filled from and keeps its memory for the next one's packs: each
  /// frame of an animation is a bake of its own, and packing into pages already mapped made
  /// a `precomputed` frame's view 1.38x faster (docs/methods.md).
  void forget();

  struct Impl;
  Impl& impl() { return *impl_; }

 private:
  std::unique_ptr<Impl> impl_;
};

/// Options of renderFromBake.
struct BakeRenderOptions {
  double step = 0;  ///< march step, world units, at most kMaxStepVoxels voxels; 0: half a voxel
  int samples_per_pixel = 1;  ///< stratified jittered rays per pixel, [1, kMaxViewSamples]
  uint64_t seed = 1;          ///< jitter; same image at any thread count
  /// The march stops where the view transmittance falls below this (the rest is < 1e-4 of
  /// what is behind, and of the in-scattering left).
  double min_transmittance = 1e-4;
  int threads = 0;  ///< 0: the caller's TBB arena
  /// Method photon's views: read the tallies' light towards the camera from a field built per
  /// view (render_from_bake.cpp, buildViewField) where it pays; false: weight the tallies per
  /// ray everywhere (the same image within the field's second-order difference; for tests).
  bool view_field = true;
  /// The largest spacing of a sparse film (core/bake/sparse_film.h), 1..4 pixels, rounded down
  /// to a power of two; 1 traces every pixel.
  int max_film_spacing = kMaxFilmSpacing;
  /// Not owned; null: the render builds what it needs for itself (BakeViewCache).
  BakeViewCache* cache = nullptr;
};

/// Whether a photon view builds its field of the tallies' light towards the camera
/// (BakeRenderOptions::view_field): where it traces `rays` at least a quarter of the tally
/// lattice's `tally_voxels`, since the field costs about as much per voxel as a ray's reads.
inline bool viewFieldPays(double rays, double tally_voxels) { return 4 * rays >= tally_voxels; }

/// The spacing of the traced pixels of a view of `bake` by `camera` (core/bake/sparse_film.h): 1
/// where every pixel is traced, else 2 or 4 (at most options.max_film_spacing). Recorded in each
/// view's EXR as cloudbake:film_spacing.
int filmSpacingOf(const BakedLight& bake, const Camera& camera, const BakeRenderOptions& options);

/// The sky's radiance averaged over the sphere (exact for a constant sky, else an equal-area
/// 256 x 512 quadrature, exact for the gradient sky): the scale of every per-unit-radiance sky
/// term of a bake.
Rgb meanSkyRadiance(const Sky& sky, const SkyLight& light);

/// Renders `camera` from `bake` lit by `sun` (its irradiance scales the baked light; its
/// direction is not read: a bake holds one light direction, bake.sun_direction) and `sky`, with
/// medium.extinction, albedo and phase (medium.density is not read: the bake's own density is).
/// Layers and units as renderPathTraced (path_tracer.h): `sun` = single + multiple scattering of
/// sunlight, `sky` = the sky's ambient term, `single` = sun single scattering + sky term,
/// `multiple` = the baked Co term, beauty = sun + sky
/// + the sky seen through the cloud, alpha = 1 - transmittance. Empty space is skipped by 8^3
/// blocks (the VDB leaf size), integration is trapezoidal. InputError for bad camera/options, a
/// bake lacking sky_visibility under a non-black sky, or a missing sun_transmittance grid.
RenderLayers renderFromBake(const BakedLight& bake, const Medium& medium, const Sun& sun,
                            const Sky& sky, const Camera& camera, const BakeRenderOptions& options,
                            const ProgressFn& progress = {});

}  // namespace cloudbake
