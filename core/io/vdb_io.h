// Writing (and reading back) OpenVDB files: the density grid plus baked extra grids.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "core/math/vec3.h"
#include "core/volume/density_field.h"

namespace cloudbake {

/// An extra float grid sharing the density grid's topology and transform: `value` is called
/// for every active voxel of the density grid with its world-space centre and must be
/// thread-safe (it is called concurrently). Voxels where it returns 0 stay inactive.
struct VdbFloatGridSpec {
  std::string name;  ///< e.g. "temperature"
  std::function<float(const Vec3& world)> value;
};

/// An extra Vec3s grid (class "unknown", vector type VEC_INVARIANT, e.g. "Cd" for baked RGB
/// radiance), same rules as VdbFloatGridSpec.
struct VdbVec3GridSpec {
  std::string name;
  std::function<Vec3(const Vec3& world)> value;
};

/// What writeVdb writes besides the density grid (named "density", class GRID_FOG_VOLUME).
struct VdbWriteOptions {
  /// Voxel size (world units) used to voxelize fields that are not GridVolumes (via
  /// voxelize()); ignored for GridVolumes, which are written as they are.
  double voxel_size = 0;
  uint64_t max_voxels = 512ull * 512 * 512;
  std::vector<VdbFloatGridSpec> float_grids;
  std::vector<VdbVec3GridSpec> vec3_grids;
  std::map<std::string, std::string> file_metadata;  ///< string metadata on the file
  std::map<std::string, std::string> grid_metadata;  ///< string metadata on every grid
};

/// Writes `density` and the extra grids to `path` atomically: the file is written to
/// PATH.tmp and renamed over PATH, so readers never see a partial file. Throws InputError for
/// an invalid voxel size or grid name (empty, duplicate, or "density" reused) and for I/O
/// failures (naming the path); PATH.tmp is removed on failure.
void writeVdb(const std::string& path, const DensityField& density,
              const VdbWriteOptions& options = {});

/// Summary of one grid of a .vdb file, as read back by readVdbInfo.
struct VdbGridInfo {
  std::string name;
  std::string value_type;   ///< "float", "vec3s", ...
  std::string grid_class;   ///< "fog volume", "level set", "unknown", ...
  std::string vector_type;  ///< "invariant", ... (vector grids only)
  uint64_t active_voxels = 0;
  double voxel_size = 0;
  std::map<std::string, std::string> metadata;  ///< string-valued grid metadata only
};

/// A .vdb file's string metadata and grid summaries, with point lookups of voxel values.
/// Throws InputError naming the path when it cannot be read.
class VdbFileReader {
 public:
  explicit VdbFileReader(const std::string& path);
  ~VdbFileReader();
  const std::map<std::string, std::string>& fileMetadata() const;
  const std::vector<VdbGridInfo>& grids() const;
  /// Value of the voxel containing world point `p` (nearest voxel centre) in float grid `grid`.
  float floatAt(const std::string& grid, const Vec3& p) const;
  /// Same for a Vec3s grid.
  Vec3 vec3At(const std::string& grid, const Vec3& p) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace cloudbake
