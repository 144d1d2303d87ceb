// Service limits on the size of a shot's volume (voxels) and sequence (frames): what
// cloudbake-server's --max-voxels and --max-frames enforce (docs/api.md, "Server").
#pragma once

#include <cstdint>
#include <string>

#include "core/shot/shot.h"
#include "core/volume/density_field.h"

namespace cloudbake {

/// Voxels of a Perlin cloud grid: lround(size_a / h) per axis, h = max(size) / resolution, as
/// core/volume/perlin_cloud.cpp allocates them.
uint64_t perlinCloudVoxels(const PerlinCloudOptions& options);

/// Voxels of a box covering `extent` (world units) at voxel size `h`: prod ceil(extent_a / h);
/// +inf (as a double) for non-finite input.
double boxVoxels(const Vec3& extent, double h);

/// Checks at submit what the shot alone tells (no file is read): a mesh's resolution^3, a
/// procedural cloud's grid (also of a procedural sequence), and the bake.vdb grid of a box or
/// sphere (bounds / outputs.vdb_voxel_size) and the method's lattices against `max_voxels` (0:
/// no limit). Throws
/// InputError naming the JSON pointer of the field, prefixed by `source`.
void checkShotVoxels(const ShotSpec& shot, uint64_t max_voxels, const std::string& source);

/// Throws InputError naming /volume/sequence/frames when a sequence has more than `max_frames`
/// frames, or the method's field (/bake/frames) when it asks for more output frames (0: no
/// limit). This and the other two checks hand the method's part to BakeMethod::checkLimits.
void checkShotFrames(const ShotSpec& shot, int64_t max_frames, const std::string& source);

/// Throws InputError naming the method's point count (/bake/points, /bake/sample_points) when
/// it exceeds `max_points` (0: no limit).
void checkShotPoints(const ShotSpec& shot, int64_t max_points, const std::string& source);

/// Run-time check of a mesh given by voxel_size, whose voxel count needs the mesh's bounds:
/// reads the mesh (cheap next to voxelising it) and counts the padded box meshToVolume would
/// allocate. No-op for other volumes or max_voxels 0.
void checkMeshVoxels(const ShotSpec& shot, uint64_t max_voxels, const std::string& source);

/// Run-time check of a loaded grid (a VDB's active voxels): throws InputError naming
/// /volume/vdb/path when `field` is a grid with more active voxels than `max_voxels`.
void checkLoadedVoxels(const ShotSpec& shot, const DensityField& field, uint64_t max_voxels,
                       const std::string& source);

}  // namespace cloudbake
