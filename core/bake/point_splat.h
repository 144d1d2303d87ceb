// Method `pointcloud`, internal: the points' light turned into lattice grids (seed 000's brickmap).
#pragma once

#include <functional>

#include "core/bake/baked_light.h"
#include "core/bake/scattering_passes.h"

namespace cloudbake {

/// Adds the Co (RGB), light_dir (unit or zero), mie_ratio and (when the result has it) Co_sky
/// channels to `bake` from the points
/// of `result`. Every voxel of the density's support (the 26-neighbourhood of density > 0) takes
/// the Shepard average of the points within rs = max(2 x spacing, voxel size) of its centre,
/// weights (1 - d / rs)^2; light_dir is the normalised weighted sum of the points' L. With no
/// point that close, the nearest point within 3 rs is copied; beyond that the voxel stays 0.
/// Returns rs. Parallel over z slices, deterministic; `cancelled(fraction)` is polled between
/// slices (Cancelled when it returns true).
double splatPoints(BakedLight& bake, const PointCloudResult& result,
                   const std::function<bool(double)>& cancelled = {});

}  // namespace cloudbake
