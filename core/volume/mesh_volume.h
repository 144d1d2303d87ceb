// Mesh -> fog volume conversion (meshToVolume in sources.h) and its testable pieces.
//
// Inside/outside rule: a voxel centre p is inside when the generalised winding number of the
// mesh at p exceeds 1/2 (Jacobson et al. 2013), evaluated with the fast hierarchical
// approximation of Barill et al. 2018 (see winding_number.h). For closed meshes this is the
// usual inside test, independent of ray directions; for meshes with holes (the Stanford bunny's
// base) or open and self-overlapping parts (the Newell teapot: no bottom, separate lid) it still
// gives the intuitive solid, because the winding number degrades gracefully from 1 to 0 across
// a hole instead of flipping. Inside voxels get `density` (optionally times fBm noise), outside
// voxels stay inactive, so the interior is filled, not a shell. Voxels the surface passes
// through get density times the fraction of 2^3 sub-samples (at +-1/4 voxel) that are inside,
// which places the boundary to sub-voxel accuracy.
//
// Cost: the inside/outside state only changes across the surface, so each 8^3 block (and,
// within blocks the surface passes through, each 4^3 and 2^3 sub-block) that no triangle
// overlaps (bounding box, then exact separating-axis test) is evaluated at its first voxel and
// filled; only voxels next to the surface are evaluated one by one. Across holes of open
// meshes the 1/2 level runs through empty space, so empty cubes of 8^3 and 4^3 whose 8 corner
// voxels disagree with the first are split further. Blocks are processed in parallel (tbb).
#pragma once

#include <cstdint>
#include <string>

#include "core/volume/mesh_io.h"
#include "core/volume/sources.h"

namespace cloudbake {

/// Most voxels meshToVolume will allocate (the bounding box of the mesh, padded by one voxel).
constexpr uint64_t kMaxMeshVoxels = 1024ull * 1024 * 1024;

/// The voxel size for `options` (exactly one of voxel_size / resolution set, finite and > 0)
/// over a mesh with bounds `b`. Throws InputError naming "mesh.voxel_size" or "mesh.resolution"
/// when invalid or when the padded box would exceed kMaxMeshVoxels.
double meshVoxelSize(const MeshSourceOptions& options, const Bounds3& b);

/// Voxelises an in-memory mesh (options.path is only used in messages).
DensityFieldPtr meshToVolume(const TriangleMesh& mesh, const MeshSourceOptions& options,
                             const std::function<bool()>& stop = {});

}  // namespace cloudbake
