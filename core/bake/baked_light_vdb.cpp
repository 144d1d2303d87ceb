#include "core/bake/baked_light_vdb.h"

#include <openvdb/openvdb.h>

#include <cmath>
#include <cstdio>
#include <sstream>

#include "core/error.h"
#include "core/io/openvdb_file.h"

namespace cloudbake {
namespace {

std::string exact(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

openvdb::math::Transform::Ptr latticeTransform(const BakeGrid& g) {
  auto xform = openvdb::math::Transform::createLinearTransform(g.voxel_size);
  xform->postTranslate(openvdb::Vec3d(g.origin.x, g.origin.y, g.origin.z));
  return xform;
}

template <typename GridT, typename Get>
typename GridT::Ptr makeGrid(const BakedLight& b, const std::vector<uint8_t>& mask,
                             const std::string& name, Get&& get) {
  const BakeGrid& g = b.grid;
  auto grid = GridT::create(openvdb::zeroVal<typename GridT::ValueType>());
  grid->setName(name);
  grid->setTransform(latticeTransform(g));
  auto acc = grid->getAccessor();
  for (int k = 0; k < g.nz; ++k)
    for (int j = 0; j < g.ny; ++j)
      for (int i = 0; i < g.nx; ++i) {
        const size_t v = g.index(i, j, k);
        if (mask[v]) acc.setValueOn(openvdb::Coord(i, j, k), get(v));
      }
  return grid;
}

}  // namespace

void writeBakedLight(const std::string& path, const BakedLight& bake) {
  initOpenVdb();
  const BakeGrid& g = bake.grid;
  if (bake.density.size() != g.voxelCount()) {
    throw InputError(path + ": bake density does not match its lattice");
  }
  const std::vector<uint8_t> mask = densitySupport(g, bake.density);
  openvdb::GridPtrVec grids;
  auto density = makeGrid<openvdb::FloatGrid>(bake, mask, bake_grids::kDensity,
                                              [&](size_t v) { return bake.density[v]; });
  density->setGridClass(openvdb::GRID_FOG_VOLUME);
  grids.push_back(density);
  for (const auto& [name, c] : bake.channels) {
    if (c.data.size() != g.voxelCount() * size_t(c.components)) {
      throw InputError(path + ": bake grid '" + name + "' does not match its lattice");
    }
    if (c.components == 1) {
      grids.push_back(
          makeGrid<openvdb::FloatGrid>(bake, mask, name, [&](size_t v) { return c.data[v]; }));
    } else if (c.components == 3) {
      auto grid = makeGrid<openvdb::Vec3SGrid>(bake, mask, name, [&](size_t v) {
        return openvdb::Vec3s(c.data[3 * v], c.data[3 * v + 1], c.data[3 * v + 2]);
      });
      // light_dir is a direction: a DCC's transform of the volume must rotate it (with the
      // transform's linear part, not its translation); colours and fluences stay as they are.
      grid->setVectorType(name == bake_grids::kLightDir ? openvdb::VEC_CONTRAVARIANT_RELATIVE
                                                        : openvdb::VEC_INVARIANT);
      grids.push_back(grid);
    } else {
      throw InputError(path + ": bake grid '" + name + "' has " + std::to_string(c.components) +
                       " components (1 or 3 expected)");
    }
  }
  openvdb::MetaMap meta;
  for (const auto& [k, v] : bake.metadata) meta.insertMeta(k, openvdb::StringMetadata(v));
  auto put = [&](const char* k, const std::string& v) {
    meta.removeMeta(k);
    meta.insertMeta(k, openvdb::StringMetadata(v));
  };
  put("cloudbake:version", CLOUDBAKE_VERSION);
  put("cloudbake:method", bake.method);
  put("cloudbake:sun_direction", exact(bake.sun_direction.x) + " " + exact(bake.sun_direction.y) +
                                     " " + exact(bake.sun_direction.z));
  put("cloudbake:units",
      "density unitless; sun_transmittance, sky_visibility, Co per unit sun irradiance; Cd sr^-1 "
      "per unit sun irradiance");
  put("cloudbake:lattice",
      std::to_string(g.nx) + " " + std::to_string(g.ny) + " " + std::to_string(g.nz));
  writeVdbFileAtomically(path, grids, meta);
}

namespace {

// The method, sun direction and lattice size from the file's metadata; the rest of the
// metadata is the caller's (a bake's own keys are recomputed when it is written again).
void readBakeMetadata(const std::string& path, const std::map<std::string, std::string>& meta,
                      BakedLight* bake) {
  auto need = [&](const char* key) {
    auto it = meta.find(key);
    if (it == meta.end()) {
      throw InputError(path + ": not a cloudbake bake (no '" + std::string(key) +
                       "' metadata; bakes are written by methods single and pointcloud)");
    }
    return it->second;
  };
  bake->method = need("cloudbake:method");
  std::istringstream s(need("cloudbake:sun_direction"));
  if (!(s >> bake->sun_direction.x >> bake->sun_direction.y >> bake->sun_direction.z)) {
    throw InputError(path + ": malformed cloudbake:sun_direction metadata");
  }
  std::istringstream l(need("cloudbake:lattice"));
  BakeGrid& g = bake->grid;
  if (!(l >> g.nx >> g.ny >> g.nz) || g.nx < 1 || g.ny < 1 || g.nz < 1 ||
      uint64_t(g.nx) * uint64_t(g.ny) * uint64_t(g.nz) > (uint64_t(1) << 31)) {
    throw InputError(path + ": malformed cloudbake:lattice metadata");
  }
  for (const auto& [k, v] : meta) {
    if (k != "cloudbake:method" && k != "cloudbake:sun_direction" && k != "cloudbake:lattice" &&
        k != "cloudbake:units" && k != "cloudbake:version") {
      bake->metadata[k] = v;
    }
  }
}

// The density grid's transform, which places the lattice (voxel size and origin); every other
// grid must share it.
const openvdb::math::Transform& readLatticePlacement(const std::string& path,
                                                     const openvdb::GridPtrVec& grids,
                                                     BakeGrid* g) {
  openvdb::GridBase::Ptr density_grid;
  for (const auto& grid : grids) {
    if (grid->getName() == bake_grids::kDensity) density_grid = grid;
  }
  if (!density_grid) throw InputError(path + ": no 'density' grid");
  const openvdb::math::Transform& xform = density_grid->transform();
  if (!xform.isLinear() || !xform.hasUniformScale()) {
    throw InputError(path + ": grid 'density' does not have a uniform linear transform");
  }
  g->voxel_size = xform.voxelSize()[0];
  const openvdb::Vec3d o = xform.indexToWorld(openvdb::Coord(0, 0, 0));
  g->origin = Vec3(o.x(), o.y(), o.z());
  return xform;
}

// Copies one grid's active voxels into the bake's dense lattice: the density, or a 1- or
// 3-component channel of the grid's name.
void readGridVoxels(const std::string& path, const openvdb::GridBase::Ptr& grid, BakedLight* bake) {
  const BakeGrid& g = bake->grid;
  const std::string name = grid->getName();
  auto place = [&](const openvdb::Coord& c) -> size_t {
    if (c.x() < 0 || c.y() < 0 || c.z() < 0 || c.x() >= g.nx || c.y() >= g.ny || c.z() >= g.nz) {
      throw InputError(path + ": grid '" + name + "' has a voxel outside the bake's lattice");
    }
    return g.index(c.x(), c.y(), c.z());
  };
  auto noTiles = [&](const auto& it) {
    if (!it.isVoxelValue()) {
      throw InputError(path + ": grid '" + name + "' has tiles (bakes store voxels)");
    }
  };
  if (auto f = openvdb::GridBase::grid<openvdb::FloatGrid>(grid)) {
    std::vector<float>* out = &bake->density;
    if (name != bake_grids::kDensity) out = &bake->add(name, 1).data;
    for (auto it = f->cbeginValueOn(); it; ++it) {
      noTiles(it);
      (*out)[place(it.getCoord())] = *it;
    }
  } else if (auto v = openvdb::GridBase::grid<openvdb::Vec3SGrid>(grid)) {
    if (name == bake_grids::kDensity) throw InputError(path + ": grid 'density' is not float");
    std::vector<float>& out = bake->add(name, 3).data;
    for (auto it = v->cbeginValueOn(); it; ++it) {
      noTiles(it);
      const size_t i = place(it.getCoord());
      const openvdb::Vec3s x = *it;
      out[3 * i] = x[0];
      out[3 * i + 1] = x[1];
      out[3 * i + 2] = x[2];
    }
  } else {
    throw InputError(path + ": grid '" + name + "' has value type " + grid->valueType() +
                     " (bakes hold float and vec3s grids)");
  }
}

}  // namespace

BakedLight readBakedLight(const std::string& path) {
  VdbFileContents contents = readVdbFileChecked(path);
  BakedLight bake;
  readBakeMetadata(path, contents.metadata, &bake);
  const openvdb::math::Transform& xform = readLatticePlacement(path, contents.grids, &bake.grid);
  bake.density.assign(bake.grid.voxelCount(), 0.f);
  for (const auto& grid : contents.grids) {
    if (grid->transform() != xform) {
      throw InputError(path + ": grid '" + grid->getName() +
                       "' is not on the density grid's transform");
    }
    readGridVoxels(path, grid, &bake);
  }
  bake.validate(path);
  return bake;
}

}  // namespace cloudbake
