// Seed 004's precomputed transmittance-to-light grid.
#pragma once

#include "core/bake/bake_progress.h"
#include "core/bake/baked_light.h"

namespace cloudbake {

/// Metadata key of a bake whose sun transmittance covers sunTransmittanceSupport, the density's
/// support and two voxels more ("2"), which views need for their short characteristic; a bake
/// without it (written before) is read the old way.
constexpr const char* kSunTransmittanceMarginKey = "cloudbake:sun_transmittance_margin";

/// Adds the `sun_transmittance` channel: for every voxel of sunTransmittanceSupport (the
/// density's support and two voxels more, where views read it; its metadata says so), the
/// transmittance from its centre towards the sun (`sun_dir`, unit, from the scene towards the
/// sun): exp(-extinction x the trapezoidal integral of the lattice's trilinear density) in steps
/// of half a voxel until the density has fallen to 0 (half a voxel past the lattice's faces);
/// 0 below 1e-7. Voxels outside that support stay 0. Within the trapezoid's error of
/// marchTransmittance at the same step, which stops at the faces (the same where the outermost
/// voxels are empty, as in every bake). Parallel over z slices; deterministic. Throws Cancelled
/// when progress returns false.
void computeSunTransmittance(BakedLight& bake, const Vec3& sun_dir, double extinction,
                             const BakeProgressFn& progress = {});

}  // namespace cloudbake
