// Bakes as OpenVDB files: the form a bake is cached in, fetched by clients and loaded by DCCs.
#pragma once

#include <string>

#include "core/bake/baked_light.h"

namespace cloudbake {

/// Writes `bake` to `path` atomically (PATH.tmp then rename): one grid per channel on one
/// transform (voxel size grid.voxel_size, index (0,0,0) at grid.origin), `density` as a float
/// GRID_FOG_VOLUME, float channels as float grids, 3-component channels as Vec3s grids of class
/// unknown with vector type VEC_INVARIANT (colours, as Houdini's Cd), except the direction
/// light_dir, VEC_CONTRAVARIANT_RELATIVE (rotated and scaled by a transform, not translated:
/// renormalise it after a non-uniform scale); only the
/// density's support is stored (BakedLight::trimToSupport). File metadata: cloudbake:version,
/// cloudbake:method, cloudbake:sun_direction ("x y z"), cloudbake:units, cloudbake:lattice
/// ("nx ny nz"), plus bake.metadata. Throws InputError for I/O failures naming the path.
void writeBakedLight(const std::string& path, const BakedLight& bake);

/// Reads a file written by writeBakedLight back into the same lattice and channels, then
/// validate()s it. Throws InputError naming the path for an unreadable, truncated or foreign
/// file, a missing `density` grid or cloudbake:method/sun_direction/lattice metadata, grids on
/// different transforms, and every check of BakedLight::validate (NaN, ranges).
BakedLight readBakedLight(const std::string& path);

}  // namespace cloudbake
