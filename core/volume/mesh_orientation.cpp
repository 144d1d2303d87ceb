#include "core/volume/mesh_orientation.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <unordered_map>
#include <utility>
#include <vector>

namespace cloudbake {
namespace {

// The (at most two) triangles on one undirected edge, and whether each traverses it from the
// smaller vertex index to the larger.
struct EdgeUse {
  int32_t face[2] = {-1, -1};
  bool ascending[2] = {false, false};
  int count = 0;
};

uint64_t edgeKey(int32_t a, int32_t b) {
  const auto lo = uint32_t(std::min(a, b)), hi = uint32_t(std::max(a, b));
  return (uint64_t(lo) << 32) | hi;
}

// A triangle that repeats a vertex has no area and no winding: it joins nothing (its edge
// there, traversed both ways, would make a manifold edge look shared by three faces).
bool degenerate(const std::array<int32_t, 3>& t) {
  return t[0] == t[1] || t[1] == t[2] || t[2] == t[0];
}

std::unordered_map<uint64_t, EdgeUse> edgeUses(const TriangleMesh& mesh) {
  std::unordered_map<uint64_t, EdgeUse> edges;
  edges.reserve(mesh.triangles.size() * 2);
  for (size_t f = 0; f < mesh.triangles.size(); ++f) {
    const auto& t = mesh.triangles[f];
    if (degenerate(t)) continue;
    for (int k = 0; k < 3; ++k) {
      const int32_t a = t[size_t(k)], b = t[size_t((k + 1) % 3)];
      EdgeUse& e = edges[edgeKey(a, b)];
      if (e.count < 2) {
        e.face[e.count] = int32_t(f);
        e.ascending[e.count] = a < b;
      }
      ++e.count;
    }
  }
  return edges;
}

// Walks one part from `seed`, setting flip[] so that neighbours traverse shared edges in
// opposite directions; returns the part's faces.
std::vector<int32_t> walkPart(const TriangleMesh& mesh,
                              const std::unordered_map<uint64_t, EdgeUse>& edges, int32_t seed,
                              std::vector<int8_t>* flip) {
  std::vector<int32_t> part{seed};
  (*flip)[size_t(seed)] = 0;
  for (size_t next = 0; next < part.size(); ++next) {
    const int32_t f = part[next];
    const auto& t = mesh.triangles[size_t(f)];
    if (degenerate(t)) continue;
    for (int k = 0; k < 3; ++k) {
      const int32_t a = t[size_t(k)], b = t[size_t((k + 1) % 3)];
      const EdgeUse& e = edges.at(edgeKey(a, b));
      if (e.count != 2) continue;  // a border, or a non-manifold edge: no rule across it
      const int q = e.face[0] == f ? 1 : 0;
      const int32_t g = e.face[q];
      if (g == f || (*flip)[size_t(g)] >= 0) continue;
      // f traverses the edge ascending iff (a < b) != flip[f]; g must traverse it the other way.
      const bool f_ascending = (a < b) != ((*flip)[size_t(f)] != 0);
      (*flip)[size_t(g)] = int8_t(e.ascending[q] == f_ascending ? 1 : 0);
      part.push_back(g);
    }
  }
  return part;
}

// About the bounds' centre: an open mesh's "volume" depends on the point its cones meet at,
// and a far one (a mesh placed at 1e6) makes the sum cancel to rounding.
double signedVolume(const TriangleMesh& mesh) {
  Bounds3 bounds;
  for (const Vec3& v : mesh.vertices) bounds.expand(v);
  const Vec3 c = bounds.center();
  double six_v = 0;
  for (const auto& t : mesh.triangles) {
    six_v += dot(mesh.vertices[size_t(t[0])] - c,
                 cross(mesh.vertices[size_t(t[1])] - c, mesh.vertices[size_t(t[2])] - c));
  }
  return six_v / 6;
}

}  // namespace

MeshOrientation orientConsistently(TriangleMesh* mesh) {
  MeshOrientation out;
  const auto edges = edgeUses(*mesh);
  std::vector<int8_t> flip(mesh->triangles.size(), -1);
  for (size_t seed = 0; seed < flip.size(); ++seed) {
    if (flip[seed] >= 0) continue;
    ++out.components;
    const std::vector<int32_t> part = walkPart(*mesh, edges, int32_t(seed), &flip);
    size_t flipped = 0;
    for (int32_t f : part) flipped += size_t(flip[size_t(f)]);
    // The walk's seed set the part's winding: keep its majority's instead.
    if (2 * flipped > part.size()) {
      for (int32_t f : part) flip[size_t(f)] = int8_t(1 - flip[size_t(f)]);
    }
  }
  for (size_t f = 0; f < flip.size(); ++f) {
    if (!flip[f]) continue;
    std::swap(mesh->triangles[f][1], mesh->triangles[f][2]);
    ++out.faces_flipped;
  }
  if (signedVolume(*mesh) < 0) {
    for (auto& t : mesh->triangles) std::swap(t[1], t[2]);
    out.whole_mesh_flipped = true;
  }
  return out;
}

}  // namespace cloudbake
