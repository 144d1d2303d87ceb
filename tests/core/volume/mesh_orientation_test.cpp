#include "core/volume/mesh_orientation.h"

#include <gtest/gtest.h>

#include <array>
#include <filesystem>
#include <map>
#include <utility>

#include "tests/core/volume/volume_test_util.h"

namespace cloudbake {
namespace {

// A closed tetrahedron wound outwards (signed volume > 0).
TriangleMesh tetrahedron(const Vec3& at = Vec3(0.0)) {
  TriangleMesh m;
  m.vertices = {at + Vec3(0, 0, 0), at + Vec3(1, 0, 0), at + Vec3(0, 1, 0), at + Vec3(0, 0, 1)};
  m.triangles = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}};
  return m;
}

void flip(TriangleMesh* m, size_t f) { std::swap(m->triangles[f][1], m->triangles[f][2]); }

// Every edge two faces share is traversed once each way.
bool consistent(const TriangleMesh& m) {
  std::map<std::pair<int32_t, int32_t>, int> directed;
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k) ++directed[{t[size_t(k)], t[size_t((k + 1) % 3)]}];
  for (const auto& [edge, n] : directed)
    if (n > 1) return false;
  return true;
}

TEST(MeshOrientation, AConsistentMeshIsLeftAsItIs) {
  TriangleMesh m = tetrahedron();
  const TriangleMesh before = m;
  const MeshOrientation o = orientConsistently(&m);
  EXPECT_EQ(o.faces_flipped, 0u);
  EXPECT_FALSE(o.whole_mesh_flipped);
  EXPECT_EQ(o.components, 1u);
  EXPECT_EQ(m.triangles, before.triangles);
}

// A minority of faces wound the other way is turned, whichever face the walk starts from.
TEST(MeshOrientation, TheMinorityOfFacesIsTurned) {
  for (size_t wrong = 0; wrong < 4; ++wrong) {
    TriangleMesh m = tetrahedron();
    const TriangleMesh right = m;
    flip(&m, wrong);
    EXPECT_FALSE(consistent(m));
    const MeshOrientation o = orientConsistently(&m);
    EXPECT_EQ(o.faces_flipped, 1u) << wrong;
    EXPECT_TRUE(consistent(m)) << wrong;
    EXPECT_EQ(m.triangles, right.triangles) << wrong;
  }
}

// A mesh wound inwards throughout encloses a negative volume: every face is turned.
TEST(MeshOrientation, AMeshWoundInwardsIsTurnedWhole) {
  TriangleMesh m = tetrahedron();
  const TriangleMesh right = m;
  for (size_t f = 0; f < 4; ++f) flip(&m, f);
  const MeshOrientation o = orientConsistently(&m);
  EXPECT_TRUE(o.whole_mesh_flipped);
  EXPECT_EQ(m.triangles, right.triangles);
}

// Parts are wound each by its own majority: a cavity's inner shell wound inwards on purpose
// stays so (the winding number is then 0 inside it), and a small part wound wrongly throughout
// within a larger right one is kept as authored too (no rule joins two parts).
TEST(MeshOrientation, EachPartKeepsItsMajoritysWinding) {
  TriangleMesh outer = tetrahedron(), inner = tetrahedron(Vec3(0.1));
  for (Vec3& v : inner.vertices) v = Vec3(0.1) + (v - Vec3(0.1)) * 0.2;
  for (size_t f = 0; f < 4; ++f) flip(&inner, f);  // the cavity
  flip(&inner, 2);                                 // and one of its faces wrong
  TriangleMesh m = outer;
  for (const Vec3& v : inner.vertices) m.vertices.push_back(v);
  for (auto t : inner.triangles) m.triangles.push_back({t[0] + 4, t[1] + 4, t[2] + 4});
  const MeshOrientation o = orientConsistently(&m);
  EXPECT_EQ(o.components, 2u);
  EXPECT_EQ(o.faces_flipped, 1u);
  EXPECT_FALSE(o.whole_mesh_flipped);
  EXPECT_TRUE(consistent(m));
  for (size_t f = 0; f < 4; ++f) EXPECT_EQ(m.triangles[f], outer.triangles[f]);
}

// Borders (an open mesh), non-manifold edges and degenerate triangles join nothing, and
// do not stop the walk elsewhere.
TEST(MeshOrientation, OpenAndDegenerateMeshesAreWalkedWhereTheyCanBe) {
  TriangleMesh m = tetrahedron();
  m.triangles.pop_back();  // open: three faces around a missing one
  flip(&m, 1);
  m.triangles.push_back({0, 0, 1});  // degenerate
  m.vertices.push_back(Vec3(1, 1, 1));
  m.triangles.push_back({1, 2, 4});  // a third face on edge 1-2: non-manifold
  orientConsistently(&m);
  EXPECT_EQ(m.triangles[1], (std::array<int32_t, 3>{0, 1, 3}));
}

// The shared assets are wound consistently already: the walk changes nothing of them (so the
// bunny's and the teapot's clouds are the same since volume version 3).
TEST(MeshOrientation, TheSharedMeshesAreLeftAsTheyAre) {
  for (const char* name : {"bun_zipper.ply", "teapot.obj"}) {
    const std::string path = testing::sharedData(name);
    if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared asset absent: " << path;
    TriangleMesh m = readMesh(path);
    const MeshOrientation o = orientConsistently(&m);
    std::printf("%s: %zu parts, %zu faces turned, whole %d\n", name, o.components, o.faces_flipped,
                int(o.whole_mesh_flipped));
    EXPECT_EQ(o.faces_flipped, 0u) << name;
    EXPECT_FALSE(o.whole_mesh_flipped) << name;
  }
}

}  // namespace
}  // namespace cloudbake
