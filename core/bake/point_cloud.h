// Method `pointcloud`, internal: the points of seed 000's point cloud (Table 1's P, D, Ci) placed
// inside a bake lattice's density.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include "core/bake/bake_grid.h"

namespace cloudbake {

/// Points inside the cloud, each carrying the same mass (density x volume).
///
/// Seed 000 places points by ray marching the geometry; here they are density-weighted instead
/// (systematic sampling of the lattice's mass), so every point stands for the same mass m and a
/// point's volume is V_i = m / D_i: dense regions get more, smaller points.
struct PointCloud {
  std::vector<Vec3> position;  ///< P_i, world units
  std::vector<float> density;  ///< D_i: trilinear lattice density at P_i (> 0)
  std::vector<float> sun;      ///< Ci_i: transmittance from P_i to the sun, [0, 1]
  double mass = 0;             ///< m = M / n, density x world units^3 (M: the lattice's mass)
  size_t occupied_voxels = 0;  ///< lattice voxels with density > 0
  /// Mean point spacing (occupied volume / n)^(1/3), world units: occupied volume = occupied
  /// voxels x voxel_size^3 (not their bounding box, which would overstate it for round clouds).
  double spacing = 0;

  size_t size() const { return position.size(); }
};

/// Places `n` points (n >= 1) in the lattice: voxels are walked in index order accumulating
/// density; the j-th point goes to the voxel where the running sum crosses (j + u0) M / n, u0 one
/// uniform offset drawn from `seed` (systematic sampling), and is jittered uniformly inside that
/// voxel by its own Rng(mixBits(seed, j)), so the cloud does not depend on threads. D_i is the
/// trilinear density at P_i (at least 1/8 of the voxel's own). `sun` is left empty.
/// InputError "volume: empty ..." when the lattice holds no density.
PointCloud placePoints(const BakeGrid& grid, const std::vector<float>& density, int n,
                       uint64_t seed);

/// Fills cloud.sun: Ci_i = marchTransmittance from P_i towards the sun (`sun_dir`, unit, from
/// the scene towards the sun) with steps of `step` world units (seed 000: light attenuated by ray
/// marching). Parallel over points; deterministic. `cancelled(fraction)` is polled between
/// chunks of points (Cancelled when it returns true): millions of points take seconds.
void computePointSunTransmittance(PointCloud& cloud, const BakeGrid& grid,
                                  const std::vector<float>& density, double extinction,
                                  const Vec3& sun_dir, double step,
                                  const std::function<bool(double)>& cancelled = {});

}  // namespace cloudbake
