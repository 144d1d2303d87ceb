// Triangle-mesh readers for the mesh volume source: Wavefront OBJ and Stanford PLY.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "core/math/vec3.h"

namespace cloudbake {

/// An indexed triangle mesh (world units). Triangles index `vertices` (0-based).
struct TriangleMesh {
  std::vector<Vec3> vertices;
  std::vector<std::array<int32_t, 3>> triangles;
};

/// Reads a Wavefront OBJ: `v x y z [w]` and `f` lines (indices 1-based or negative = relative to
/// the latest vertex, `i`, `i/t`, `i/t/n` or `i//n`); polygons are split into triangle fans;
/// every other statement (vt, vn, usemtl, o, g, s, l, p, ...) is ignored. Throws InputError
/// naming the file and line for unreadable numbers, faces with fewer than 3 vertices or
/// out-of-range indices, and for a file without triangles.
TriangleMesh readObj(const std::string& path);

/// Reads a Stanford PLY (Turk 1994): format ascii 1.0, binary_little_endian 1.0 or
/// binary_big_endian 1.0. Element "vertex" needs float or double properties x, y, z (others of
/// any scalar type are skipped); element "face" needs a list property "vertex_indices" (or
/// "vertex_index") with an integer count type and integer indices; polygons become fans;
/// other elements and properties are skipped by type. Throws InputError naming the file and
/// the header line or the element for malformed or truncated input.
TriangleMesh readPly(const std::string& path);

/// readObj or readPly by the file extension (case-insensitive); InputError for others.
TriangleMesh readMesh(const std::string& path);

}  // namespace cloudbake
