// Seed 004's precomputed transmittance-to-light grid.
#pragma once

#include "core/bake/bake_progress.h"
#include "core/bake/baked_light.h"

namespace cloudbake {

/// Adds the `sun_transmittance` channel: for every voxel of the density's support, the
/// transmittance from its centre towards the sun (`sun_dir`, unit, from the scene towards the
/// sun) by marchTransmittance with steps of half a voxel; voxels outside the support stay 0.
/// Parallel over z slices; deterministic. Throws Cancelled when progress returns false.
void computeSunTransmittance(BakedLight& bake, const Vec3& sun_dir, double extinction,
                             const BakeProgressFn& progress = {});

}  // namespace cloudbake
