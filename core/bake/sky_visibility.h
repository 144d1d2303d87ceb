// How much of the sky each voxel sees: the ambient term of the bake renders.
#pragma once

#include <vector>

#include "core/bake/bake_progress.h"
#include "core/bake/baked_light.h"

namespace cloudbake {

/// Adds the `sky_visibility` channel: transmittance to the outside of the lattice averaged over
/// the sphere of directions, estimated from the 26 lattice directions (6 axes, 12 face and 8
/// body diagonals), each weighted by the solid angle of its cell on the sphere. Along a lattice
/// direction the transmittance of a voxel is the transmittance of its upstream neighbour times
/// the exact trapezoidal segment between the two voxel centres, so each direction is one O(voxels)
/// sweep with no interpolation. Deterministic. Throws Cancelled when progress returns false.
/// `with_vector` also adds `sky_visibility_vector`, the first moment of the same transmittances
/// (the view's sky single scattering reads it to weight the phase function).
void computeSkyVisibility(BakedLight& bake, double extinction, const BakeProgressFn& progress = {},
                          bool with_vector = false);

/// The same visibility for one or two extinctions (InternalError otherwise) of the lattice `g`
/// with density `rho`: each the values computeSkyVisibility gives, bit for bit. Each direction's
/// sweep multiplies precomputed half-segment transmittances, exp(-extinction x half the segment
/// x density) of each voxel, in rows along x that the compiler vectorises. A non-null `vector`
/// receives the first extinction's sky_visibility_vector (3 floats a voxel, interleaved).
std::vector<FirstTouchFloats> skyVisibilities(const BakeGrid& g, const float* rho,
                                              const std::vector<double>& extinctions,
                                              const BakeProgressFn& progress = {},
                                              FirstTouchFloats* vector = nullptr);

/// The 26 lattice directions (unit) and their solid-angle weights (summing to 1), for tests.
struct LatticeDirection {
  int dx, dy, dz;
  double weight;
};
const LatticeDirection* latticeDirections();  ///< 26 entries

}  // namespace cloudbake
