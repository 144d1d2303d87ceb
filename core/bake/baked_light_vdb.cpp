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
typename GridT::Ptr makeGrid(const BakeGrid& g, const std::vector<uint8_t>& mask,
                             const std::string& name, Get&& get) {
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

std::vector<uint8_t> nonZeroVoxels(const BakeChannel& c) {
  const size_t n = c.data.size() / size_t(c.components);
  std::vector<uint8_t> mask(n, 0);
  for (size_t v = 0; v < n; ++v) {
    for (int e = 0; e < c.components; ++e) {
      if (c.data[v * size_t(c.components) + size_t(e)] != 0) mask[v] = 1;
    }
  }
  return mask;
}

}  // namespace

void writeBakedLight(const std::string& path, const BakedLight& bake) {
  initOpenVdb();
  const BakeGrid& g = bake.grid;
  if (bake.density.size() != g.voxelCount()) {
    throw InputError(path + ": bake density does not match its lattice");
  }
  const std::vector<uint8_t> support = densitySupport(g, bake.density);
  const std::vector<uint8_t> sun_support = sunTransmittanceSupport(g, support);
  openvdb::GridPtrVec grids;
  auto density = makeGrid<openvdb::FloatGrid>(g, support, bake_grids::kDensity,
                                              [&](size_t v) { return bake.density[v]; });
  density->setGridClass(openvdb::GRID_FOG_VOLUME);
  grids.push_back(density);
  bool tallies = false;
  for (const auto& entry : bake.channels) {
    // Named, not a structured binding: lambdas below capture it (C++17 clang cannot capture
    // bindings).
    const std::string& name = entry.first;
    const auto& c = entry.second;
    const BakeGrid& cg = bake.gridOf(c);
    if (c.data.size() != cg.voxelCount() * size_t(c.components)) {
      throw InputError(path + ": bake grid '" + name + "' does not match its lattice");
    }
    tallies = tallies || c.on_tally_grid;
    // The lattice's grids store the density's support (trimToSupport zeroed the rest); the
    // tallies' coarser lattice stores its non-zero voxels, so a file reads back as the bake.
    // The sun's transmittance keeps two voxels more, which views read (sunTransmittanceSupport).
    const bool sun = name == bake_grids::kSunTransmittance;
    std::vector<uint8_t> tally_mask;
    if (c.on_tally_grid) tally_mask = nonZeroVoxels(c);
    const std::vector<uint8_t>& mask = c.on_tally_grid ? tally_mask : sun ? sun_support : support;
    if (c.components == 1) {
      grids.push_back(
          makeGrid<openvdb::FloatGrid>(cg, mask, name, [&](size_t v) { return c.data[v]; }));
    } else if (c.components == 3) {
      auto grid = makeGrid<openvdb::Vec3SGrid>(cg, mask, name, [&](size_t v) {
        return openvdb::Vec3s(c.data[3 * v], c.data[3 * v + 1], c.data[3 * v + 2]);
      });
      // light_dir and the sky's vector are directions: a DCC's transform of the volume must
      // rotate them (with the transform's linear part, not its translation); colours and
      // fluences stay as they are.
      const bool directional =
          name == bake_grids::kLightDir || name == bake_grids::kSkyVisibilityVector;
      grid->setVectorType(directional ? openvdb::VEC_CONTRAVARIANT_RELATIVE
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
  meta.removeMeta("cloudbake:tally_lattice");
  if (tallies) {
    const BakeGrid& t = bake.tally_grid;
    put("cloudbake:tally_lattice",
        std::to_string(t.nx) + " " + std::to_string(t.ny) + " " + std::to_string(t.nz));
  }
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
                       "' metadata; light bakes are written by methods single, pointcloud, photon "
                       "and precomputed)");
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
  auto tl = meta.find("cloudbake:tally_lattice");
  if (tl != meta.end()) {
    std::istringstream t(tl->second);
    BakeGrid& tg = bake->tally_grid;
    if (!(t >> tg.nx >> tg.ny >> tg.nz) || tg.nx < 1 || tg.ny < 1 || tg.nz < 1 ||
        uint64_t(tg.nx) * uint64_t(tg.ny) * uint64_t(tg.nz) > (uint64_t(1) << 31)) {
      throw InputError(path + ": malformed cloudbake:tally_lattice metadata");
    }
  }
  for (const auto& [k, v] : meta) {
    if (k != "cloudbake:method" && k != "cloudbake:sun_direction" && k != "cloudbake:lattice" &&
        k != "cloudbake:tally_lattice" && k != "cloudbake:units" && k != "cloudbake:version") {
      bake->metadata[k] = v;
    }
  }
}

// A lattice's voxel size and origin from a grid's transform.
void placeLattice(const std::string& path, const openvdb::GridBase& grid, BakeGrid* g) {
  const openvdb::math::Transform& xform = grid.transform();
  if (!xform.isLinear() || !xform.hasUniformScale()) {
    throw InputError(path + ": grid '" + grid.getName() +
                     "' does not have a uniform linear transform");
  }
  g->voxel_size = xform.voxelSize()[0];
  const openvdb::Vec3d o = xform.indexToWorld(openvdb::Coord(0, 0, 0));
  g->origin = Vec3(o.x(), o.y(), o.z());
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
  placeLattice(path, *density_grid, g);
  return density_grid->transform();
}

// Copies one grid's active voxels into the bake's dense lattice: the density, or a 1- or
// 3-component channel of the grid's name.
void readGridVoxels(const std::string& path, const openvdb::GridBase::Ptr& grid, BakedLight* bake,
                    bool on_tally_grid) {
  const BakeGrid& g = on_tally_grid ? bake->tally_grid : bake->grid;
  auto add = [&](int components) -> FirstTouchFloats& {
    return (on_tally_grid ? bake->addOnTallyGrid(grid->getName(), components)
                          : bake->add(grid->getName(), components))
        .data;
  };
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
    float* out = bake->density.data();
    if (name != bake_grids::kDensity) out = add(1).data();
    for (auto it = f->cbeginValueOn(); it; ++it) {
      noTiles(it);
      out[place(it.getCoord())] = *it;
    }
  } else if (auto v = openvdb::GridBase::grid<openvdb::Vec3SGrid>(grid)) {
    if (name == bake_grids::kDensity) throw InputError(path + ": grid 'density' is not float");
    FirstTouchFloats& out = add(3);
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
  // Grids off the density's transform are tallies, on one transform of their own.
  const openvdb::math::Transform* tally_xform = nullptr;
  for (const auto& grid : contents.grids) {
    const bool on_tally_grid = grid->transform() != xform;
    if (on_tally_grid) {
      if (bake.tally_grid.voxelCount() == 0 || grid->getName() == bake_grids::kDensity ||
          (tally_xform && grid->transform() != *tally_xform)) {
        throw InputError(path + ": grid '" + grid->getName() +
                         "' is neither on the density grid's transform nor on the tally "
                         "lattice's (cloudbake:tally_lattice)");
      }
      if (!tally_xform) {
        tally_xform = &grid->transform();
        placeLattice(path, *grid, &bake.tally_grid);
      }
    }
    readGridVoxels(path, grid, &bake, on_tally_grid);
  }
  bake.validate(path);
  return bake;
}

}  // namespace cloudbake
