// Consistent winding of a triangle mesh's faces, for the winding-number inside test
// (mesh_volume.h), which counts a face wound the other way as a hole's negative.
#pragma once

#include <cstddef>

#include "core/volume/mesh_io.h"

namespace cloudbake {

/// What orientConsistently changed.
struct MeshOrientation {
  size_t faces_flipped = 0;         ///< triangles whose winding it reversed
  size_t components = 0;            ///< edge-connected parts of the mesh
  bool whole_mesh_flipped = false;  ///< every face was wound inwards (negative signed volume)
};

/// Winds every edge-connected part of `mesh` consistently: across an edge two triangles share
/// (and no third does), they traverse it in opposite directions. Each part keeps the winding of
/// the majority of its faces, so a few faces wound the wrong way are turned, and a part wound
/// the other way on purpose (a cavity's inner shell) stays so. Then, when the whole mesh
/// encloses a negative signed volume (every face wound inwards), every face is turned. A
/// part that cannot be wound consistently (a Moebius strip) keeps what its walk gives.
MeshOrientation orientConsistently(TriangleMesh* mesh);

}  // namespace cloudbake
