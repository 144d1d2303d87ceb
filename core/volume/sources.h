// Factories that turn user-facing volume descriptions into density fields.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "core/math/vec3.h"
#include "core/volume/density_field.h"

namespace cloudbake {

/// Fractal (fBm) noise used to modulate mesh densities and in the Perlin cloud (seeds 000, 004).
struct NoiseOptions {
  double frequency = 4.0;    ///< base frequency, cycles per unit of the shape's largest extent
  int octaves = 4;           ///< number of fBm octaves, 1..12
  double persistence = 0.5;  ///< amplitude ratio between octaves, (0, 1]
  double amount = 0.5;       ///< 0: no modulation, 1: density fully multiplied by noise in [0,1]
  uint64_t seed = 1;
};

/// Loads a float grid from an OpenVDB file.
struct VdbSourceOptions {
  std::string path;              ///< .vdb file (already resolved to an absolute path)
  std::string grid = "density";  ///< float grid name
};

/// Voxelises a triangle mesh (OBJ or PLY, ASCII or binary) into a fog volume whose interior
/// is filled. Exactly one of voxel_size (> 0, world units) or resolution (> 0, voxels along the
/// largest extent of the mesh bounds) must be set.
struct MeshSourceOptions {
  std::string path;
  double voxel_size = 0;
  int resolution = 0;
  double density = 1.0;  ///< density inside the mesh
  bool noise_enabled = false;
  NoiseOptions noise;
};

/// The Perlin-noise cloud of seed 004: fBm noise shaped by an ellipsoidal envelope, with cloud
/// cover and sharpness (Hugo Elias's exponential mapping). Never touches the grid boundary.
struct PerlinCloudOptions {
  Vec3 center{0, 0, 0.5};    ///< world centre of the cloud's box
  Vec3 size{2, 2, 1};        ///< world extent of the box (x, y, z)
  int resolution = 128;      ///< voxels along the largest extent, 8..1024
  double cover = 0.45;       ///< 0..1: higher = more sky showing through (less cloud)
  double sharpness = 0.9;    ///< (0, 1): lower = harder edges
  double density = 1.0;      ///< peak density
  int octaves = 5;           ///< 1..12
  double frequency = 3.0;    ///< base frequency, cycles per box
  double persistence = 0.5;  ///< (0, 1]
  uint64_t seed = 1;
  /// Cloud time (|time| <= 1e6): each octave's noise drifts through its own lattice at a speed
  /// growing with the octave, so small puffs change faster than the large shapes and the cloud
  /// evolves in place inside its fixed envelope (seed 002's "dynamic clouds" as frames of a
  /// procedural sequence). 0: the static cloud.
  double time = 0;
};

/// All three return a GridVolume (core/volume/grid_volume.h) and throw InputError naming the
/// file / option on bad input. loadVdbVolume converts level sets to fog volumes
/// (openvdb::tools::sdfToFogVolume: 1 inside, linear ramp across the inner narrow band) and
/// rejects non-float, empty, non-finite or negative grids (vdb_source.cpp). meshToVolume fills
/// voxels whose generalised winding number exceeds 1/2 (core/volume/mesh_volume.h), so open
/// meshes get a sensible solid. makePerlinCloud is described in core/volume/perlin_cloud.h. The
/// two that evaluate blocks poll `stop`, when given, between blocks and throw Cancelled when it
/// says so (a mesh at a high resolution takes tens of seconds).
DensityFieldPtr loadVdbVolume(const VdbSourceOptions& options);
DensityFieldPtr meshToVolume(const MeshSourceOptions& options,
                             const std::function<bool()>& stop = {});
DensityFieldPtr makePerlinCloud(const PerlinCloudOptions& options,
                                const std::function<bool()>& stop = {});

/// Samples any density field onto a sparse grid of the given voxel size (world units), e.g. to
/// write analytic shapes to a .vdb. Throws InputError if it would exceed max_voxels.
DensityFieldPtr voxelize(const DensityField& field, double voxel_size,
                         uint64_t max_voxels = 512ull * 512 * 512);

}  // namespace cloudbake
