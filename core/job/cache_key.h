// Cache keys of a shot's computed parts (docs/DESIGN.md, "Cache").
#pragma once

#include <string>
#include <vector>

#include "core/shot/shot.h"

namespace cloudbake {

/// Step of the sun-direction quantisation: each component of the unit direction is rounded to
/// a multiple of it before hashing, so directions that differ only by float noise share a bake.
constexpr double kSunDirectionQuantum = 1e-6;

/// Content-addressed keys (hex SHA-256) of the parts of a shot a service can reuse.
///
/// - `volume`: the density field: the volume spec with every referenced file replaced by the
///   SHA-256 of its content (so a renamed or re-uploaded VDB still hits) + code version.
/// - `bake`: what the scattering depends on: volume key, medium (extinction, albedo, phase),
///   quantised sun direction, sky, method and every quality knob (samples, seed, max_depth,
///   method options) + code version. Not in it: views, sun colour/intensity, image size.
/// - `vdb`: DIR/bake.vdb: volume key + vdb voxel size (pathtrace bakes no light grids).
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
  /// `samples` + code version. Not in it: views, sun colour or intensity, sky radiance, image
  /// size. Empty for other methods. `light_family` is the same without the sun direction.
  std::string light;
  std::string light_family;
  /// Method precomputed: the per-basic-volume precompute (optical-depth SH, sample tree, cuts),
  /// keyed by volume key, extinction, seed and the precompute knobs (light_resolution,
  /// sample_points, transfer_resolution, cut_error) + code version. Not in it: sun, sky, albedo,
  /// phase, views, frames and the walk's knobs, so every lighting and every animation of the
  /// same database reuses it. Empty for other methods.
  std::string precompute;
};

/// True for the methods whose views render from a baked-light lattice (single, pointcloud).
bool bakesLight(const ShotSpec& shot);

/// True when the shot's sky is not black (a bake then needs sky_visibility).
bool needsSky(const ShotSpec& shot);

/// Keys of a validated shot (files it names must exist: they are hashed, with an in-memory
/// memo keyed by path, size and modification time). Throws InputError when a file cannot be
/// read.
ShotCacheKeys computeCacheKeys(const ShotSpec& shot);

/// Rounds each component of `direction` (normalised first) to kSunDirectionQuantum.
Vec3 quantiseDirection(const Vec3& direction);

}  // namespace cloudbake
