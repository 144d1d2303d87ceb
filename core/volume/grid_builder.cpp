// Parallel construction of sparse grids from per-block evaluators (see openvdb_grid.h).
#include <memory>
#include <vector>

#include "core/math/parallel.h"
#include "core/volume/openvdb_grid.h"

namespace cloudbake {

openvdb::FloatGrid::Ptr buildGridFromBlocks(const openvdb::CoordBBox& box, double voxel_size,
                                            const BlockEvaluator& eval,
                                            const std::function<bool()>& stop) {
  using LeafT = openvdb::FloatTree::LeafNodeType;
  auto grid = openvdb::FloatGrid::create(0.f);
  grid->setTransform(openvdb::math::Transform::createLinearTransform(voxel_size));
  grid->setGridClass(openvdb::GRID_FOG_VOLUME);
  if (box.empty()) return grid;

  int b_lo[3], n[3];
  for (int a = 0; a < 3; ++a) {
    b_lo[a] = blockOf(box.min()[a]);
    n[a] = blockOf(box.max()[a]) - b_lo[a] + 1;
  }
  const size_t count = static_cast<size_t>(n[0]) * n[1] * n[2];
  struct Result {
    float tile = 0.f;  // non-zero: whole block is an active tile of this value
    std::unique_ptr<LeafT> leaf;
  };
  std::vector<Result> results(count);
  // A mesh's voxelisation at a high resolution runs for tens of seconds: a cancelled run stops
  // between blocks.
  ParallelOptions options;
  if (stop) options.cancelled = [&](double) { return stop(); };
  parallelFor(
      0, int64_t(count),
      [&](int64_t lo, int64_t hi) {
        float values[LeafT::SIZE];
        for (size_t b = size_t(lo); b < size_t(hi); ++b) {
          const int bx = static_cast<int>(b % n[0]);
          const int by = static_cast<int>((b / n[0]) % n[1]);
          const int bz = static_cast<int>(b / (static_cast<size_t>(n[0]) * n[1]));
          const openvdb::Coord origin((b_lo[0] + bx) * 8, (b_lo[1] + by) * 8, (b_lo[2] + bz) * 8);
          const openvdb::CoordBBox block(origin, origin.offsetBy(7));
          const bool inside = box.isInside(block);
          const bool uniform = eval(origin, values);
          if (uniform) {
            if (values[0] == 0.f) continue;
            if (inside) {
              results[b].tile = values[0];
              continue;
            }
            for (float& v : values) v = values[0];
          }
          auto leaf = std::make_unique<LeafT>(origin, 0.f, false);
          bool any = false;
          for (openvdb::Index i = 0; i < LeafT::SIZE; ++i) {
            if (values[i] == 0.f) continue;
            const openvdb::Coord xyz = origin + LeafT::offsetToLocalCoord(i);
            if (!inside && !box.isInside(xyz)) continue;
            leaf->setValueOn(i, values[i]);
            any = true;
          }
          if (any) results[b].leaf = std::move(leaf);
        }
      },
      options);
  openvdb::FloatTree& tree = grid->tree();
  for (size_t b = 0; b < count; ++b) {
    if (results[b].leaf) {
      tree.addLeaf(results[b].leaf.release());
    } else if (results[b].tile != 0.f) {
      const int bx = static_cast<int>(b % n[0]);
      const int by = static_cast<int>((b / n[0]) % n[1]);
      const int bz = static_cast<int>(b / (static_cast<size_t>(n[0]) * n[1]));
      tree.addTile(1, openvdb::Coord((b_lo[0] + bx) * 8, (b_lo[1] + by) * 8, (b_lo[2] + bz) * 8),
                   results[b].tile, true);
    }
  }
  return grid;
}

}  // namespace cloudbake
