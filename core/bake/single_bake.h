// Method `single` (seed 004): precomputed transmittance to the sun, exact single scattering at
// render time, the sky as an ambient term. Multiple scattering is not modelled.
#pragma once

#include "core/bake/bake_progress.h"
#include "core/bake/baked_light.h"
#include "core/transport/scene.h"

namespace cloudbake {

/// Knobs of method `single` (shot keys beside "method": "single"; docs/shot-format.md).
struct SingleBakeOptions {
  /// Lattice voxels along the longest side of the volume's bounds, [8, 1024]; on a grid's own
  /// voxels where it allows (makeBakeLattice, LatticeSampling::kFieldAligned).
  int light_resolution = 128;
  /// Ray-march step of the view renders, world units; 0: half a lattice voxel.
  double step = 0;
  /// Also bake `sky_visibility` (false when the shot's sky is black: nothing to light).
  bool sky = true;
};

/// Bakes `medium` (density, extinction; albedo and phase are applied at render time) for a sun
/// in direction `sun_dir` (unit, towards the sun): the lattice (makeBakeLattice), the
/// sun_transmittance grid, sky_visibility when options.sky, and Cd. metadata records the knobs
/// and the time of each stage. InputError for bad knobs or medium, Cancelled on request.
BakedLight bakeSingle(const Medium& medium, const Vec3& sun_dir, const SingleBakeOptions& options,
                      const BakeProgressFn& progress = {});

}  // namespace cloudbake
