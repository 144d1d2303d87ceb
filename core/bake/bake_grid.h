// The dense voxel lattice every bake method computes on and the render-from-bake marcher reads.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/math/vec3.h"

namespace cloudbake {

/// A dense lattice of nx*ny*nz voxels of edge `voxel_size` (world units). Voxel (i, j, k) has its
/// centre at origin + voxel_size * (i, j, k) and is stored at index() (x fastest). This is the
/// in-memory form of a bake; a .vdb file stores the same voxels sparsely on an OpenVDB transform
/// with this voxel size whose index (0, 0, 0) is `origin` (core/bake/baked_light_vdb.h).
struct BakeGrid {
  Vec3 origin;            ///< world position of the centre of voxel (0, 0, 0)
  double voxel_size = 1;  ///< world units, > 0
  int nx = 0, ny = 0, nz = 0;

  size_t voxelCount() const { return size_t(nx) * size_t(ny) * size_t(nz); }
  size_t index(int i, int j, int k) const {
    return (size_t(k) * size_t(ny) + size_t(j)) * size_t(nx) + size_t(i);
  }
  Vec3 center(int i, int j, int k) const { return origin + Vec3(i, j, k) * voxel_size; }
  /// Continuous index coordinates of a world point (voxel centres at integers).
  Vec3 toIndex(const Vec3& world) const { return (world - origin) / voxel_size; }
  /// The world box covered by the voxels (outer faces).
  Bounds3 bounds() const {
    Bounds3 b;
    b.min = origin - Vec3(0.5 * voxel_size);
    b.max = origin + Vec3(nx - 0.5, ny - 0.5, nz - 0.5) * voxel_size;
    return b;
  }
};

/// Trilinear interpolation of a channel with `components` floats per voxel (interleaved,
/// grid.voxelCount() * components values) at world point `p`, written to out[0..components).
/// Voxels outside the lattice read as 0, like an OpenVDB grid's zero background.
void sampleTrilinear(const BakeGrid& grid, const float* data, int components, const Vec3& p,
                     float* out);

/// sampleTrilinear at index coordinates u (BakeGrid::toIndex of the point).
void sampleTrilinearAtIndex(const BakeGrid& grid, const float* data, int components, const Vec3& u,
                            float* out);

/// Single-component form of sampleTrilinearAtIndex.
float sampleTrilinearAtIndex(const BakeGrid& grid, const float* data, const Vec3& u);

/// Single-component convenience form of sampleTrilinear.
float sampleTrilinear(const BakeGrid& grid, const float* data, const Vec3& p);

/// A channel of `from` (`components` floats per voxel) read by sampleTrilinear at every voxel
/// centre of `to`: to.voxelCount() * components values. Parallel, deterministic.
std::vector<float> resampleTrilinear(const BakeGrid& from, const float* data, int components,
                                     const BakeGrid& to);

/// The mean of `values` (one float per voxel of `fine`, taken as constant over each voxel) over
/// every voxel of `coarse`, a lattice over the same bounds, by the voxels' overlaps (a mean over
/// a coarse voxel's volume, as a track-length tally holds): coarse.voxelCount() values; parts
/// of a coarse voxel outside `fine` count as 0. Parallel, deterministic.
std::vector<float> boxMean(const BakeGrid& fine, const float* values, const BakeGrid& coarse);

/// Transmittance exp(-extinction * integral of density) from `p` along unit direction `dir` to
/// where the ray leaves the lattice, by ray marching the trilinear density with steps of at most
/// `step` world units and trapezoidal integration of the optical depth (seed 004's
/// transmittance march). Stops early once the transmittance falls below 1e-7 (returns 0).
double marchTransmittance(const BakeGrid& grid, const float* density, double extinction,
                          const Vec3& p, const Vec3& dir, double step);

/// marchTransmittance for many rays through one lattice (a bake's sun transmittance, a point
/// cloud's): the same values bit for bit, faster. Samples whose eight voxels lie in an 8^3 block
/// of zero density read 0 without a lookup (the trilinear sum of zeros), and samples inside the
/// lattice take a lookup without per-corner bounds checks.
class TransmittanceMarcher {
 public:
  /// `density` must outlive the marcher; densities must be finite and >= 0.
  TransmittanceMarcher(const BakeGrid& grid, const float* density, double extinction);
  /// marchTransmittance(grid, density, extinction, p, dir, step).
  double operator()(const Vec3& p, const Vec3& dir, double step) const;
  /// sampleTrilinear(grid, density, p).
  float density(const Vec3& p) const;
  /// The same at index coordinates u.
  float densityAtIndex(const Vec3& u) const;

 private:
  /// How many further samples dt apart (du index units per world unit) from index point u lie
  /// in u's block when it is empty (0 when it is not).
  int stepsInEmptyBlock(const Vec3& u, const Vec3& du, double dt) const;

  static constexpr int kBlock = 8;
  const BakeGrid& grid_;
  const float* density_;
  double extinction_;
  int nbx_ = 0, nby_ = 0, nbz_ = 0;
  std::vector<uint8_t> occupied_;  // per block of lookups (floor(index) + 1) / 8: any density
};

}  // namespace cloudbake
