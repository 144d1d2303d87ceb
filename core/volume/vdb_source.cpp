// loadVdbVolume(): reads a float grid from an OpenVDB file (declared in sources.h).
//
// Level sets (grid class "level set") are converted with openvdb::tools::sdfToFogVolume: the
// interior becomes density 1, falling linearly to 0 across the inner half of the narrow band,
// and the exterior 0. Inactive voxels are treated as empty (set to 0), since OpenVDB tools may
// leave stale values there.
#include <openvdb/io/Stream.h>
#include <openvdb/tools/LevelSetUtil.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <sstream>

#include "core/error.h"
#include "core/format.h"
#include "core/volume/openvdb_grid.h"
#include "core/volume/sources.h"
#include "core/volume/vdb_header_check.h"

namespace cloudbake {
namespace {

void initOpenVdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

// Throws naming the first active value (in tree order) that is not finite or negative.
void checkValues(const openvdb::FloatGrid& grid, const std::string& where) {
  auto fail = [&](const openvdb::Coord& ijk, float v) {
    std::ostringstream os;
    os << where << ": density must be finite and >= 0, got " << v << " at voxel (" << ijk.x()
       << ", " << ijk.y() << ", " << ijk.z() << ")";
    throw InputError(os.str());
  };
  for (auto leaf = grid.tree().cbeginLeaf(); leaf; ++leaf) {
    const float* data = leaf->buffer().data();
    for (auto it = leaf->cbeginValueOn(); it; ++it) {
      const float v = data[it.pos()];
      if (!std::isfinite(v) || v < 0.f) fail(it.getCoord(), v);
    }
  }
  auto tile = grid.tree().cbeginValueOn();
  tile.setMaxDepth(openvdb::FloatTree::ValueOnCIter::LEAF_DEPTH - 1);
  for (; tile; ++tile) {
    if (!std::isfinite(*tile) || *tile < 0.f) fail(tile.getCoord(), *tile);
  }
}

// A grid's world extent is bounded as a shot's coordinates are (kMaxCoordinate in
// core/shot/json_reader.h): beyond it a lattice has no float precision left.
constexpr double kMaxWorldCoordinate = 1e15;

// The grid's transform maps its voxels to a finite, non-degenerate box: a file may store a zero,
// tiny, huge or NaN scale, which OpenVDB reads and only refuses (ArithmeticError) when the
// transform is first inverted, or which makes the cloud's box infinite.
void checkTransform(const openvdb::FloatGrid& grid, const std::string& where) {
  const openvdb::math::Transform& xf = grid.transform();
  try {
    xf.baseMap()->getAffineMap();  // inverts the matrix: throws where it is nearly singular
  } catch (const openvdb::Exception& e) {
    throw InputError(where + ": its transform is singular (voxel size " +
                     exactNumber(xf.voxelSize()[0]) + "; " + e.what() + ")");
  }
  const openvdb::Vec3d v = xf.voxelSize();
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(v[a]) || !(v[a] > 0)) {
      throw InputError(where + ": its transform's voxel size must be finite and > 0");
    }
  }
  const openvdb::CoordBBox box = grid.evalActiveVoxelBoundingBox();
  for (int c = 0; c < 8; ++c) {
    const openvdb::Vec3d ijk((c & 1 ? box.max() : box.min()).x(),
                             (c & 2 ? box.max() : box.min()).y(),
                             (c & 4 ? box.max() : box.min()).z());
    const openvdb::Vec3d w = xf.indexToWorld(ijk);
    for (int a = 0; a < 3; ++a) {
      if (!(std::abs(w[a]) <= kMaxWorldCoordinate)) {
        throw InputError(where + ": its active voxels reach world coordinate " + exactNumber(w[a]) +
                         " (voxel size " + exactNumber(v[0]) + "), beyond +-1e15");
      }
    }
  }
}

}  // namespace

DensityFieldPtr loadVdbVolume(const VdbSourceOptions& options) {
  initOpenVdb();
  const std::string& path = options.path;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    throw InputError(path + ": VDB file not found (or not a regular file)");
  }
  checkVdbHeader(path);  // before OpenVDB sizes its allocations from the file's lengths
  openvdb::GridBase::Ptr base;
  std::vector<std::string> names;
  try {
    // openvdb::io::File ignores short reads (a truncated file loads as a partial grid, or
    // spins on garbage counts), so read through our own stream that throws on any short read.
    std::ifstream in(path, std::ios::binary);
    in.exceptions(std::ios::failbit | std::ios::badbit);
    openvdb::io::Stream stream(in, /*delayLoad=*/false);
    openvdb::GridPtrVecPtr grids = stream.getGrids();
    for (const auto& g : *grids) {
      names.push_back(g->getName());
      if (!base && g->getName() == options.grid) base = g;
    }
  } catch (const openvdb::Exception& e) {
    throw InputError(path + ": not a readable OpenVDB file (" + e.what() + ")");
  } catch (const std::ios_base::failure&) {
    throw InputError(path + ": not a readable OpenVDB file (truncated or corrupt)");
  } catch (const std::exception& e) {
    throw InputError(path + ": failed to read OpenVDB file (" + e.what() + ")");
  }
  if (!base) {
    std::string list;
    for (const auto& n : names) list += (list.empty() ? "'" : ", '") + n + "'";
    throw InputError(path + ": no grid named '" + options.grid +
                     "' (available: " + (list.empty() ? std::string("none") : list) + ")");
  }
  const std::string where = path + ": grid '" + options.grid + "'";
  auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
  if (!grid) {
    throw InputError(where + ": must be a float grid, got " + base->valueType() + " (" +
                     base->type() + ")");
  }
  if (grid->activeVoxelCount() == 0) throw InputError(where + ": grid is empty");
  if (grid->getGridClass() == openvdb::GRID_LEVEL_SET) {
    if (!std::isfinite(grid->background()) || !(grid->background() > 0.f)) {
      throw InputError(where + ": level set background (narrow-band width) must be > 0");
    }
    try {
      openvdb::tools::sdfToFogVolume(*grid);
    } catch (const std::exception& e) {
      throw InputError(where + ": level set to fog conversion failed (" + e.what() + ")");
    }
    if (grid->activeVoxelCount() == 0) {
      throw InputError(where + ": level set has no interior");
    }
  }
  checkTransform(*grid, where);
  checkValues(*grid, where);
  return makeGridVolume(grid, path);
}

}  // namespace cloudbake
