// Internal bridge between GridVolume and OpenVDB. Include only from .cpp files: it pulls in the
// (slow to compile) OpenVDB headers that the public headers keep out.
#pragma once

#include <openvdb/openvdb.h>

#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "core/volume/grid_volume.h"
#include "core/volume/tracking_grid.h"

namespace cloudbake {

struct GridVolume::Impl {
  openvdb::FloatGrid::ConstPtr grid;
  std::string name;
  Bounds3 bounds;
  MajorantGrid majorants;
  int majorant_block = 8;
  double voxel_size = 0;
  double max_density = 0;
  uint64_t active_voxels = 0;
  openvdb::CoordBBox active_box;
  /// World -> index affine map, row-vector convention: idx_j = sum_i w_i * m[i][j] + m[3][j].
  double world_to_index[4][3] = {};
  /// The grid's values over the active box grown by one voxel, x fastest (empty when that box
  /// exceeds kMaxDenseVoxels): lookups read it instead of walking the tree.
  std::vector<float> dense;
  openvdb::Coord dense_min;
  int dense_n[3] = {0, 0, 0};
  static constexpr int64_t kMaxDenseVoxels = int64_t(1) << 24;  // 64 MiB of floats
  /// Index -> world affine map; axis_aligned: no rotation (mirrored axes allowed).
  openvdb::Mat4d index_to_world;
  bool axis_aligned = true;
  /// Tracking grids (trackingGrid()), built from the dense copy on first request: the cell
  /// bounds of every level, and the grids made of them so far, by voxels per cell.
  mutable std::mutex tracking_mutex;
  mutable std::vector<CellBounds> tracking_levels;
  mutable std::map<int, std::shared_ptr<const MajorantGrid>> tracking_grids;
};

/// Wraps `grid` (ownership passes to the volume; it must not be modified afterwards). Inactive
/// voxels and tiles are reset to 0 first, since trilinear lookups read them too. Throws
/// InputError (messages start with `context`, e.g. the file name) when the transform is not
/// linear with uniform scale, when the background is not 0, or when the grid has no active
/// voxels. Values are not validated here (loadVdbVolume does that for user files).
std::shared_ptr<const GridVolume> makeGridVolume(openvdb::FloatGrid::Ptr grid,
                                                 const std::string& context = "grid");

/// The OpenVDB grid behind a GridVolume (shared, read-only), e.g. to write it to a file.
openvdb::FloatGrid::ConstPtr openvdbGrid(const GridVolume& volume);

/// Evaluates one 8^3 block whose first voxel is `origin` (index space, multiple of 8) into
/// `values` (512 floats in OpenVDB leaf order: offset = x*64 + y*8 + z). Returns true when the
/// whole block has the single value values[0] (only values[0] need be written then).
using BlockEvaluator = std::function<bool(const openvdb::Coord& origin, float* values)>;

/// Builds a grid over the inclusive index box `box` with a uniform-scale transform of
/// `voxel_size` (voxel ijk centred at world ijk * voxel_size), evaluating the leaf-aligned 8^3
/// blocks in parallel (parallelFor) and inserting them serially, so the result does not
/// depend on the thread count. Voxels outside `box` and voxels with value 0 stay inactive;
/// uniform non-zero blocks become active tiles. The evaluator is called concurrently. `stop`,
/// when given, is polled between blocks (parallelFor's cancellation): true throws Cancelled.
openvdb::FloatGrid::Ptr buildGridFromBlocks(const openvdb::CoordBBox& box, double voxel_size,
                                            const BlockEvaluator& eval,
                                            const std::function<bool()>& stop = {});

/// Floor division by 8 that is correct for negative coordinates.
inline int blockOf(int i) { return i >= 0 ? i / 8 : -((-i + 7) / 8); }

}  // namespace cloudbake
