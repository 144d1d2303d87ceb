#include "core/job/volume_limits.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <sstream>
#include <variant>

#include "core/error.h"
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
     << " voxels, over this server's limit of " << max_voxels << " (--max-voxels)";
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
  if (shot.bake.method == BakeSpec::Method::kSingle ||
      shot.bake.method == BakeSpec::Method::kPointcloud) {
    // The bake lattice: light_resolution voxels along the longest side plus a margin, counted
    // as a cube (an upper bound: the volume's bounds are not known before its files are read).
    const auto knobs = nlohmann::json::parse(shot.bake.options_json, nullptr, false);
    const int res = knobs.is_object() ? knobs.value("light_resolution", 128) : 128;
    const double n = std::pow(double(res + 2), 3);
    if (n > limit) {
      overLimit(source, "/bake/light_resolution",
                "a bake lattice of up to (" + std::to_string(res) + " + 2)^3", n, max_voxels);
    }
  }
  if (shot.bake.method == BakeSpec::Method::kPrecomputed) {
    // The database in memory: every basic volume's lattice, each voxel holding its density and
    // 16 optical-depth SH coefficients, so it counts 17 times (the cuts are on the much coarser
    // receiver lattice).
    const auto knobs = nlohmann::json::parse(shot.bake.options_json, nullptr, false);
    const int res = knobs.is_object() ? knobs.value("light_resolution", 64) : 64;
    const auto* seq = std::get_if<SequenceVolumeSpec>(&shot.volume);
    const int volumes = seq ? seq->frames : 1;
    const double n = 17.0 * volumes * std::pow(double(res + 2), 3);
    if (n > limit) {
      overLimit(source, "/bake/light_resolution",
                "a database of " + std::to_string(volumes) + " basic volume(s) of up to (" +
                    std::to_string(res) + " + 2)^3 voxels, 17 floats each,",
                n, max_voxels);
    }
  }
  if (shot.outputs.vdb && shot.outputs.vdb_voxel_size > 0) {
    Vec3 extent;
    bool analytic = true;
    if (auto* b = std::get_if<BoxVolumeSpec>(&shot.volume)) {
      extent = b->max - b->min;
    } else if (auto* s = std::get_if<SphereVolumeSpec>(&shot.volume)) {
      extent = Vec3(2 * s->radius);
    } else {
      analytic = false;
    }
    const double n = analytic ? boxVoxels(extent, shot.outputs.vdb_voxel_size) : 0;
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
  if (shot.bake.method == BakeSpec::Method::kPrecomputed) {
    const nlohmann::json knobs = nlohmann::json::parse(shot.bake.options_json);
    const auto it = knobs.find("frames");
    if (it != knobs.end() && it->is_number_integer() && it->get<int64_t>() > max_frames) {
      throw InputError(source + ": /bake/frames: " + std::to_string(it->get<int64_t>()) +
                       " output frames exceed this server's limit of " +
                       std::to_string(max_frames) + " (--max-frames)");
    }
  }
}

void checkShotPoints(const ShotSpec& shot, int64_t max_points, const std::string& source) {
  if (max_points <= 0) return;
  const char* key = shot.bake.method == BakeSpec::Method::kPointcloud    ? "points"
                    : shot.bake.method == BakeSpec::Method::kPrecomputed ? "sample_points"
                                                                         : nullptr;
  if (!key) return;
  // The parser has validated the knobs; options_json is its canonical text.
  const nlohmann::json knobs = nlohmann::json::parse(shot.bake.options_json);
  const auto it = knobs.find(key);
  if (it == knobs.end() || !it->is_number_integer()) return;
  const int64_t points = it->get<int64_t>();
  if (points > max_points) {
    throw InputError(source + ": /bake/" + key + ": " + std::to_string(points) +
                     " points exceed this server's limit of " + std::to_string(max_points) +
                     " (--max-points)");
  }
}

void checkMeshVoxels(const ShotSpec& shot, uint64_t max_voxels, const std::string& source) {
  const auto* m = std::get_if<MeshVolumeSpec>(&shot.volume);
  if (!m || max_voxels == 0) return;
  const TriangleMesh mesh = readMesh(m->path);
  Bounds3 b;
  b.min = b.max = mesh.vertices.at(0);
  for (const Vec3& v : mesh.vertices) {
    b.min = Vec3(std::min(b.min.x, v.x), std::min(b.min.y, v.y), std::min(b.min.z, v.z));
    b.max = Vec3(std::max(b.max.x, v.x), std::max(b.max.y, v.y), std::max(b.max.z, v.z));
  }
  const double h = meshVoxelSize(*m, b);
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
                     " active voxels, over this server's limit of " + std::to_string(max_voxels) +
                     " (--max-voxels)");
  }
}

}  // namespace cloudbake
