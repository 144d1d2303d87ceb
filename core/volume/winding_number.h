// Generalised winding number of a triangle soup, exact and fast hierarchical approximation.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "core/math/vec3.h"
#include "core/volume/mesh_io.h"

namespace cloudbake {

/// Signed solid angle (steradians) subtended at `p` by triangle (a, b, c), positive when p sees
/// the triangle's back side, i.e. for p inside a closed outward-oriented (counter-clockwise
/// seen from outside) mesh (Van Oosterom & Strackee 1983).
double triangleSolidAngle(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& p);

/// Exact generalised winding number: sum of solid angles / 4 pi (Jacobson et al. 2013). 1
/// inside a closed outward-oriented mesh, 0 outside, and a smooth "insideness" in [0, 1] for
/// open meshes and meshes with holes. O(triangles) per query; used by tests as the reference.
double windingNumberExact(const TriangleMesh& mesh, const Vec3& p);

/// Fast winding number (Barill et al. 2018): a bounding-volume hierarchy over the triangles
/// (median splits, <= 8 triangles per leaf) where each node stores its area-weighted centroid,
/// total area vector and radius; a node farther than beta * radius from the query point is
/// replaced by its dipole term dot(c - p, N) / (4 pi |c - p|^3) (first-order expansion), nearer
/// nodes are opened and leaves summed exactly. beta = 2 keeps the error well below the 0.5
/// inside/outside threshold. Immutable after construction; safe to query from many threads.
class FastWindingNumber {
 public:
  explicit FastWindingNumber(const TriangleMesh& mesh, double beta = 2.0);
  double operator()(const Vec3& p) const;

 private:
  struct Node {
    Vec3 center, area;  // area-weighted centroid; sum of area vectors (1/2 cross products)
    double radius = 0;  // max distance from center to any vertex below
    int32_t first = 0, count = 0;  // triangles [first, first + count) when leaf
    int32_t left = -1, right = -1;
  };
  int32_t build(int32_t first, int32_t count);

  std::vector<std::array<Vec3, 3>> tris_;
  std::vector<Node> nodes_;
  double beta_;
};

}  // namespace cloudbake
