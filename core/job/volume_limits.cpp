#include "core/job/volume_limits.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <variant>

#include "core/error.h"
#include "core/methods/registry.h"
#include "core/shot/scene_builder.h"
#include "core/volume/grid_volume.h"
#include "core/volume/mesh_io.h"
#include "core/volume/mesh_volume.h"

namespace cloudbake {
namespace {

[[noreturn]] void overLimit(const std::string& source, const std::string& pointer,
                            const std::string& what, double voxels, uint64_t max_voxels) {
  std::ostringstream os;
  os.precision(15);
  os << source << ": " << pointer << ": " << what << " gives " << voxels
     << " voxels, over the limit of " << max_voxels << " (--max-voxels)";
  throw InputError(os.str());
}

}  // namespace

uint64_t perlinCloudVoxels(const PerlinCloudOptions& o) {
  const double h = std::max({o.size.x, o.size.y, o.size.z}) / o.resolution;
  uint64_t n = 1;
  for (double s : {o.size.x, o.size.y, o.size.z}) {
    n *= uint64_t(std::max(1L, std::lround(s / h)));
  }
  return n;
}

double boxVoxels(const Vec3& extent, double h) {
  double n = 1;
  for (double e : {extent.x, extent.y, extent.z}) n *= std::ceil(e / h);
  return std::isfinite(n) ? n : HUGE_VAL;
}

void checkShotVoxels(const ShotSpec& shot, uint64_t max_voxels, const std::string& source) {
  if (max_voxels == 0) return;
  const double limit = double(max_voxels);
  if (auto* m = std::get_if<MeshVolumeSpec>(&shot.volume); m && m->resolution > 0) {
    const double n = std::pow(double(m->resolution), 3);
    if (n > limit) {
      overLimit(source, "/volume/mesh/resolution",
                "resolution " + std::to_string(m->resolution) + " (cubed)", n, max_voxels);
    }
  }
  auto procedural = [&](const ProceduralVolumeSpec& p, const std::string& pointer) {
    const double n = double(perlinCloudVoxels(p.perlin));
    if (n > limit) {
      overLimit(source, pointer, "resolution " + std::to_string(p.perlin.resolution), n,
                max_voxels);
    }
  };
  if (auto* p = std::get_if<ProceduralVolumeSpec>(&shot.volume)) {
    procedural(*p, "/volume/procedural/resolution");
  }
  if (auto* s = std::get_if<SequenceVolumeSpec>(&shot.volume); s && s->procedural) {
    procedural(*s->procedural, "/volume/sequence/procedural/resolution");
  }
  methodOf(shot).checkLimits(shot, MethodLimits{max_voxels, 0, 0}, source);
  if (shot.outputs.vdb && shot.outputs.vdb_voxel_size > 0) {
    const std::optional<Bounds3> b = statedBounds(shot.volume);
    const double n = b ? boxVoxels(b->extent(), shot.outputs.vdb_voxel_size) : 0;
    if (n > limit) {
      std::ostringstream what;
      what << "voxel size " << shot.outputs.vdb_voxel_size << " over the volume's bounds";
      overLimit(source, "/outputs/vdb_voxel_size", what.str(), n, max_voxels);
    }
  }
}

void checkShotFrames(const ShotSpec& shot, int64_t max_frames, const std::string& source) {
  if (max_frames <= 0) return;
  if (auto* s = std::get_if<SequenceVolumeSpec>(&shot.volume); s && s->frames > max_frames) {
    throw InputError(source + ": /volume/sequence/frames: " + std::to_string(s->frames) +
                     " frames exceed this server's limit of " + std::to_string(max_frames) +
                     " (--max-frames)");
  }
  methodOf(shot).checkLimits(shot, MethodLimits{0, 0, max_frames}, source);
}

void checkShotPoints(const ShotSpec& shot, int64_t max_points, const std::string& source) {
  if (max_points > 0) methodOf(shot).checkLimits(shot, MethodLimits{0, max_points, 0}, source);
}

void checkMeshVoxels(const ShotSpec& shot, uint64_t max_voxels, const std::string& source) {
  const auto* m = std::get_if<MeshVolumeSpec>(&shot.volume);
  if (!m || max_voxels == 0) return;
  // Read here before the scene builder reads it: its errors name the field as the builder's do.
  TriangleMesh mesh;
  try {
    mesh = readMesh(m->path);
  } catch (const MissingFileError& e) {
    throw MissingFileError(source + ": /volume/mesh: " + e.what());
  } catch (const InputError& e) {
    throw InputError(source + ": /volume/mesh: " + e.what());
  }
  Bounds3 b;
  b.min = b.max = mesh.vertices.at(0);
  for (const Vec3& v : mesh.vertices) {
    b.min = Vec3(std::min(b.min.x, v.x), std::min(b.min.y, v.y), std::min(b.min.z, v.z));
    b.max = Vec3(std::max(b.max.x, v.x), std::max(b.max.y, v.y), std::max(b.max.z, v.z));
  }
  double h = 0;
  try {
    h = meshVoxelSize(*m, b);
  } catch (const InputError& e) {
    throw InputError(source + ": " + volumeErrorAt("/volume/mesh", e.what(), "mesh."));
  }
  // The padded index box of meshToVolume (core/volume/mesh_volume.cpp).
  double n = 1;
  for (int a = 0; a < 3; ++a) n *= std::ceil(b.max[a] / h) - std::floor(b.min[a] / h) + 3;
  if (n > double(max_voxels)) {
    std::ostringstream what;
    what.precision(15);
    what << (m->voxel_size > 0 ? "voxel size " : "resolution ")
         << (m->voxel_size > 0 ? m->voxel_size : double(m->resolution))
         << " over the mesh's bounds";
    overLimit(source, m->voxel_size > 0 ? "/volume/mesh/voxel_size" : "/volume/mesh/resolution",
              what.str(), n, max_voxels);
  }
}

void checkLoadedVoxels(const ShotSpec& shot, const DensityField& field, uint64_t max_voxels,
                       const std::string& source) {
  const auto* vdb = std::get_if<VdbVolumeSpec>(&shot.volume);
  const auto* grid = dynamic_cast<const GridVolume*>(&field);
  if (!vdb || !grid || max_voxels == 0) return;
  const uint64_t n = grid->activeVoxelCount();
  if (n > max_voxels) {
    throw InputError(source + ": /volume/vdb/path: " + vdb->path + " has " + std::to_string(n) +
                     " active voxels, over the limit of " + std::to_string(max_voxels) +
                     " (--max-voxels)");
  }
}

}  // namespace cloudbake
