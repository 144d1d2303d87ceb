// Algorithm versions of the pieces every method's output depends on. Each is part of the cache
// key of everything computed with it, beside the method's own version (MethodInfo::version), so
// a server with an old --cache-dir never serves results of older code. Bump the number when the
// piece's output changes (not for a pure speed-up); the golden tests (tests/core/methods) fail
// with the name of the version to bump.
#pragma once

#include <string>

namespace cloudbake {

/// core/volume, core/shot/scene_builder: loading, voxelising and resampling the density.
/// 2: an OBJ's UTF-8 byte-order mark is skipped (its first vertex had been dropped, and a mesh
/// that never used its last vertex loaded with every index off by one).
/// 3: a mesh's faces are wound consistently before the inside test (orientConsistently): a
/// closed mesh with some faces, or all, wound the other way had filled wrong or not at all.
constexpr int kVolumeVersion = 3;
/// core/phase: phase functions, the Lorenz-Mie solution and its tables.
constexpr int kPhaseVersion = 2;
/// core/transport: tracking, sky, camera, the path tracer's estimators and the views' EXR layers.
constexpr int kTransportVersion = 2;
/// core/bake/render_from_bake: views ray-marched from a baked-light lattice.
/// 9 was taken by the reverted commits bd0ae60 and c0838b0 (a sparse film that refined its
/// cells): the next change is 10, so no cache holds two views under one number.
constexpr int kRenderFromBakeVersion = 8;

/// "volume/3 phase/2 transport/2 render_from_bake/8": the shared part of every method's salt.
inline std::string sharedVersionSalt() {
  return "volume/" + std::to_string(kVolumeVersion) + " phase/" + std::to_string(kPhaseVersion) +
         " transport/" + std::to_string(kTransportVersion) + " render_from_bake/" +
         std::to_string(kRenderFromBakeVersion);
}

}  // namespace cloudbake
