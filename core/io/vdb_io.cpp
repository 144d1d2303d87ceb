#include "core/io/vdb_io.h"

#include <openvdb/io/File.h>
#include <openvdb/io/Stream.h>
#include <openvdb/tree/LeafManager.h>

#include <cerrno>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <set>

#include "core/error.h"
#include "core/io/file_sync.h"
#include "core/io/openvdb_file.h"
#include "core/volume/grid_volume.h"
#include "core/volume/openvdb_grid.h"
#include "core/volume/sources.h"
#include "core/volume/vdb_header_check.h"

namespace cloudbake {
namespace {

// Evaluates `fn` at every active voxel of `topology` into a grid of the same topology.
template <typename GridT, typename Fn>
typename GridT::Ptr gridFromTopology(const openvdb::FloatGrid& topology, Fn&& fn) {
  using TreeT = typename GridT::TreeType;
  using ValueT = typename GridT::ValueType;
  auto tree =
      std::make_shared<TreeT>(topology.tree(), openvdb::zeroVal<ValueT>(), openvdb::TopologyCopy());
  tree->voxelizeActiveTiles();
  const openvdb::math::Transform& xform = topology.transform();
  openvdb::tree::LeafManager<TreeT> leaves(*tree);
  leaves.foreach ([&](typename TreeT::LeafNodeType& leaf, size_t) {
    for (auto it = leaf.beginValueOn(); it; ++it) {
      const openvdb::Vec3d w = xform.indexToWorld(it.getCoord());
      const ValueT v = fn(Vec3(w.x(), w.y(), w.z()));
      if (v == openvdb::zeroVal<ValueT>()) {
        it.setValueOff();
      } else {
        it.setValue(v);
      }
    }
  });
  tree->prune();
  auto grid = GridT::create(tree);
  grid->setTransform(xform.copy());
  return grid;
}

void addMetadata(openvdb::GridBase& grid, const std::map<std::string, std::string>& meta) {
  for (const auto& [k, v] : meta) grid.insertMeta(k, openvdb::StringMetadata(v));
}

}  // namespace

void writeVdb(const std::string& path, const DensityField& density,
              const VdbWriteOptions& options) {
  initOpenVdb();
  std::set<std::string> names{"density"};
  for (const auto& g : options.float_grids)
    if (g.name.empty() || !g.value || !names.insert(g.name).second)
      throw InputError(path + ": extra float grid name '" + g.name +
                       "' is empty, duplicated or has no value function");
  for (const auto& g : options.vec3_grids)
    if (g.name.empty() || !g.value || !names.insert(g.name).second)
      throw InputError(path + ": extra vec3 grid name '" + g.name +
                       "' is empty, duplicated or has no value function");

  openvdb::FloatGrid::Ptr grid;
  const auto* volume = dynamic_cast<const GridVolume*>(&density);
  if (!volume && density.maxDensity() == 0) {
    // An empty cloud is a valid shot: its grid has no active voxel, at the voxel size asked.
    if (!std::isfinite(options.voxel_size) || !(options.voxel_size > 0)) {
      throw InputError(path + ": voxel_size must be finite and > 0");
    }
    grid = openvdb::FloatGrid::create(0.f);
    grid->setTransform(openvdb::math::Transform::createLinearTransform(options.voxel_size));
  } else {
    DensityFieldPtr voxelized;
    if (!volume) {
      voxelized = voxelize(density, options.voxel_size, options.max_voxels);
      volume = dynamic_cast<const GridVolume*>(voxelized.get());
    }
    // A shallow copy shares the (immutable) tree; only its metadata changes.
    grid = openvdb::ConstPtrCast<openvdb::FloatGrid>(openvdbGrid(*volume)->copy());
  }
  grid->setName("density");
  grid->setGridClass(openvdb::GRID_FOG_VOLUME);
  addMetadata(*grid, options.grid_metadata);
  openvdb::GridPtrVec grids{grid};
  for (const auto& spec : options.float_grids) {
    auto g = gridFromTopology<openvdb::FloatGrid>(*grid, spec.value);
    g->setName(spec.name);
    addMetadata(*g, options.grid_metadata);
    grids.push_back(g);
  }
  for (const auto& spec : options.vec3_grids) {
    auto g = gridFromTopology<openvdb::Vec3SGrid>(*grid, [&](const Vec3& p) {
      const Vec3 v = spec.value(p);
      return openvdb::Vec3s(static_cast<float>(v.x), static_cast<float>(v.y),
                            static_cast<float>(v.z));
    });
    g->setName(spec.name);
    g->setVectorType(openvdb::VEC_INVARIANT);
    addMetadata(*g, options.grid_metadata);
    grids.push_back(g);
  }
  openvdb::MetaMap file_meta;
  // Every file says which cloudbake wrote it (DESIGN.md: outputs carry the code version).
  file_meta.insertMeta("cloudbake:version", openvdb::StringMetadata(CLOUDBAKE_VERSION));
  for (const auto& [k, v] : options.file_metadata)
    file_meta.insertMeta(k, openvdb::StringMetadata(v));

  writeVdbFileAtomically(path, grids, file_meta);
}

struct VdbFileReader::Impl {
  std::string path;
  std::map<std::string, std::string> file_meta;
  std::vector<VdbGridInfo> infos;
  openvdb::GridPtrVec grids;

  openvdb::GridBase::ConstPtr find(const std::string& name) const {
    for (const auto& g : grids)
      if (g->getName() == name) return g;
    throw InputError(path + ": no grid named '" + name + "'");
  }
};

VdbFileReader::VdbFileReader(const std::string& path) : impl_(std::make_unique<Impl>()) {
  initOpenVdb();
  impl_->path = path;
  VdbFileContents contents = readVdbFileChecked(path);
  impl_->grids = std::move(contents.grids);
  impl_->file_meta = std::move(contents.metadata);
  for (const auto& g : impl_->grids) {
    VdbGridInfo info;
    info.name = g->getName();
    info.value_type = g->valueType();
    info.grid_class = openvdb::GridBase::gridClassToString(g->getGridClass());
    if (info.value_type.rfind("vec3", 0) == 0) {
      info.vector_type = openvdb::GridBase::vecTypeToString(g->getVectorType());
    }
    info.active_voxels = g->activeVoxelCount();
    info.voxel_size = g->voxelSize()[0];
    info.metadata = stringMetadata(*g);
    impl_->infos.push_back(info);
  }
}

VdbFileReader::~VdbFileReader() = default;

const std::map<std::string, std::string>& VdbFileReader::fileMetadata() const {
  return impl_->file_meta;
}
const std::vector<VdbGridInfo>& VdbFileReader::grids() const { return impl_->infos; }

float VdbFileReader::floatAt(const std::string& name, const Vec3& p) const {
  auto grid = openvdb::gridConstPtrCast<openvdb::FloatGrid>(impl_->find(name));
  if (!grid) throw InputError(impl_->path + ": grid '" + name + "' is not a float grid");
  const openvdb::Coord ijk =
      grid->transform().worldToIndexCellCentered(openvdb::Vec3d(p.x, p.y, p.z));
  return grid->tree().getValue(ijk);
}

Vec3 VdbFileReader::vec3At(const std::string& name, const Vec3& p) const {
  auto grid = openvdb::gridConstPtrCast<openvdb::Vec3SGrid>(impl_->find(name));
  if (!grid) throw InputError(impl_->path + ": grid '" + name + "' is not a Vec3s grid");
  const openvdb::Coord ijk =
      grid->transform().worldToIndexCellCentered(openvdb::Vec3d(p.x, p.y, p.z));
  const openvdb::Vec3s v = grid->tree().getValue(ijk);
  return {v.x(), v.y(), v.z()};
}

void initOpenVdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

namespace {

// io::File::write neither checks its stream nor closes it checked, so a full disk left 0-byte or
// truncated files that "succeeded". The same seekable archive format (what File writes), written
// to a stream that throws on any failed write, flush or close.
class CheckedVdbArchive : public openvdb::io::Archive {
 public:
  void writeTo(std::ostream& os, const openvdb::GridPtrVec& grids,
               const openvdb::MetaMap& meta) const {
    Archive::write(os, grids, /*seekable=*/true, meta);
  }
};

}  // namespace

void writeVdbFileAtomically(const std::string& path, const openvdb::GridPtrVec& grids,
                            const openvdb::MetaMap& meta) {
  initOpenVdb();
  const std::string tmp = temporaryNameFor(path);
  try {
    std::ofstream os;
    os.exceptions(std::ios::failbit | std::ios::badbit);
    os.open(tmp, std::ios::out | std::ios::binary | std::ios::trunc);
    CheckedVdbArchive().writeTo(os, grids, meta);
    os.close();
    syncFile(tmp);
  } catch (const StorageFullError&) {
    std::remove(tmp.c_str());
    throw;
  } catch (const std::exception& e) {
    const int err = errno;
    std::remove(tmp.c_str());
    throwIfNoSpace(err, path + ": cannot write VDB file (" + e.what() + ")");
    throw InputError(path + ": cannot write VDB file (" + e.what() + ")");
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::remove(tmp.c_str());
    throw InputError(path + ": cannot rename " + tmp + " into place (" + ec.message() + ")");
  }
}

VdbFileContents readVdbFileChecked(const std::string& path) {
  initOpenVdb();
  if (!std::filesystem::is_regular_file(path)) throw InputError(path + ": VDB file not found");
  checkVdbHeader(path);
  VdbFileContents out;
  try {
    // Like loadVdbVolume: a stream that throws on short reads catches truncated files.
    std::ifstream in(path, std::ios::binary);
    in.exceptions(std::ios::failbit | std::ios::badbit);
    openvdb::io::Stream stream(in, /*delayLoad=*/false);
    out.grids = *stream.getGrids();
    out.metadata = stringMetadata(*stream.getMetadata());
  } catch (const std::exception& e) {
    throw InputError(path + ": not a readable OpenVDB file (" + e.what() + ")");
  }
  return out;
}

std::map<std::string, std::string> stringMetadata(const openvdb::MetaMap& meta) {
  std::map<std::string, std::string> out;
  for (auto it = meta.beginMeta(); it != meta.endMeta(); ++it) {
    if (it->second && it->second->typeName() == openvdb::StringMetadata::staticTypeName()) {
      out[it->first] = it->second->str();
    }
  }
  return out;
}

}  // namespace cloudbake
