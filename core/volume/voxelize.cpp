// voxelize(): samples any density field onto a sparse grid (declared in sources.h).
#include <tbb/enumerable_thread_specific.h>

#include <cmath>
#include <sstream>

#include "core/error.h"
#include "core/format.h"
#include "core/volume/openvdb_grid.h"
#include "core/volume/sources.h"

namespace cloudbake {

DensityFieldPtr voxelize(const DensityField& field, double voxel_size, uint64_t max_voxels) {
  if (!std::isfinite(voxel_size) || voxel_size <= 0) {
    std::ostringstream os;
    os << "voxelize: voxel_size must be finite and > 0, got " << voxel_size;
    throw InputError(os.str());
  }
  const Bounds3 b = field.bounds();
  if (b.empty() || !isFinite(b.min) || !isFinite(b.max)) {
    throw InputError("voxelize: field '" + field.describe() + "' has empty or infinite bounds");
  }
  // Voxel ijk is centred at ijk * voxel_size; cover every centre inside the bounds.
  openvdb::Coord lo, hi;
  uint64_t total = 1;
  for (int a = 0; a < 3; ++a) {
    const double l = std::ceil(b.min[a] / voxel_size), h = std::floor(b.max[a] / voxel_size);
    const double dim = std::max(1.0, h - l + 1);
    if (!(dim < 2e9) || !(std::abs(l) < 1e9) || static_cast<double>(total) * dim > 1.8e19) {
      total = UINT64_MAX;
      break;
    }
    lo[a] = static_cast<int>(l);
    hi[a] = std::max(lo[a], static_cast<int>(h));
    total *= static_cast<uint64_t>(hi[a] - lo[a] + 1);
  }
  if (total > max_voxels) {
    std::ostringstream os;
    os << "voxelize: voxel_size " << exactNumber(voxel_size) << " over " << field.describe()
       << " needs " << (total == UINT64_MAX ? std::string("too many") : std::to_string(total))
       << " voxels, more than the limit of " << max_voxels;
    throw InputError(os.str());
  }
  tbb::enumerable_thread_specific<std::unique_ptr<DensityField::Lookup>> lookups(
      [&] { return field.lookup(); });
  auto grid = buildGridFromBlocks(
      openvdb::CoordBBox(lo, hi), voxel_size, [&](const openvdb::Coord& origin, float* values) {
        DensityField::Lookup& lookup = *lookups.local();
        for (int i = 0; i < 512; ++i) {
          const openvdb::Coord c = origin + openvdb::FloatTree::LeafNodeType::offsetToLocalCoord(i);
          values[i] = static_cast<float>(lookup.density(Vec3(c.x(), c.y(), c.z()) * voxel_size));
        }
        return false;
      });
  grid->setName("density");
  if (grid->activeVoxelCount() == 0) {
    throw InputError("voxelize: " + field.describe() + " is zero at every voxel centre of size " +
                     std::to_string(voxel_size));
  }
  return makeGridVolume(grid, "voxelize");
}

}  // namespace cloudbake
