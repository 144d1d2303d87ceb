// Majorant and minorant grids for tracking, at a resolution chosen for the density's structure.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace cloudbake {

/// Density values on a dense box of voxels, x fastest (value (x, y, z) at
/// values[(z * n[1] + y) * n[0] + x]); voxel centres at integer index coordinates, and lookups
/// interpolate trilinearly between them (as GridVolume's do).
struct DenseView {
  const float* values = nullptr;
  int n[3] = {0, 0, 0};
};

/// Bounds of trilinear lookups per cell of `m` voxels per edge. Cell (i, j, k) covers the
/// index box [m i, m (i + 1)] x ... (voxel centres as corners): a trilinear lookup there is a
/// convex combination of the (m + 1)^3 voxels on and inside that box, so their maximum and
/// minimum bound it exactly (voxels outside the dense box count as 0; negative values as 0, as
/// lookups clamp them).
struct CellBounds {
  int m = 1;
  int n[3] = {0, 0, 0};               ///< cells per axis: ceil((dense n - 1) / m), at least 1
  std::vector<float> maxima, minima;  ///< x fastest
  size_t size() const { return maxima.size(); }
};

/// The bounds at one voxel per cell (m = 1).
CellBounds trilinearCellBounds(const DenseView& dense);
/// The bounds at twice the cell size, exactly: a cell of 2m is the union of the corner sets of
/// its eight children of m.
CellBounds coarsenCellBounds(const CellBounds& fine);

/// Cost of tracking through a grid of cells, in units of one density lookup.
struct TrackingCostModel {
  /// Cost of crossing one cell (the DDA step, a free-path bookkeeping step and, in ratio
  /// tracking, one exponential of the minorant's optical depth) relative to a density lookup.
  double crossing_cost = 0.5;
};

/// Expected cost per voxel length of a path through the grid's box, averaged uniformly over
/// it: a random chord of a cube of edge m is 2m/3 long on average, so a path crosses 1.5 / m
/// cells per voxel; decomposition tracking looks up the density at rate sigma (max - min) per
/// unit length, i.e. sigma_per_voxel x (max - min) lookups per voxel.
/// `sigma_per_voxel` = extinction x voxel size (sigma_t per voxel length at density 1).
double trackingCost(const CellBounds& b, double sigma_per_voxel, const TrackingCostModel& model);

/// The levels m = 1, 2, 4, ... up to `max_m` whose cell count is at most `max_cells`, finest
/// first (at least the coarsest level, however many cells it has).
std::vector<CellBounds> cellBoundsLevels(const DenseView& dense, int64_t max_cells, int max_m = 64);

/// Index into `levels` of the cheapest level by trackingCost (ties: the coarser).
size_t cheapestLevel(const std::vector<CellBounds>& levels, double sigma_per_voxel,
                     const TrackingCostModel& model = {});

}  // namespace cloudbake
