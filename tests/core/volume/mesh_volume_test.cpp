#include "core/volume/mesh_volume.h"

#include <gtest/gtest.h>
#include <openvdb/openvdb.h>
#include <tbb/global_control.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <sstream>

#include "core/error.h"
#include "core/volume/grid_volume.h"
#include "core/volume/openvdb_grid.h"
#include "core/volume/winding_number.h"
#include "tests/core/volume/volume_test_util.h"

namespace cloudbake {
namespace {

// Axis-aligned box [lo, hi] as 6 outward-facing quads.
std::string cubeObj(const Vec3& lo, const Vec3& hi) {
  std::ostringstream os;
  os.precision(17);
  for (int i = 0; i < 8; ++i) {
    os << "v " << ((i & 1) ? hi.x : lo.x) << " " << ((i & 2) ? hi.y : lo.y) << " "
       << ((i & 4) ? hi.z : lo.z) << "\n";
  }
  // Counter-clockwise seen from outside.
  os << "f 1 3 4 2\nf 5 6 8 7\nf 1 2 6 5\nf 3 7 8 4\nf 1 5 7 3\nf 2 4 8 6\n";
  return os.str();
}

TriangleMesh tetrahedron() {
  TriangleMesh m;
  m.vertices = {{0.1, 0.05, 0.02}, {1.03, 0.11, 0.07}, {0.2, 0.91, 0.13}, {0.27, 0.33, 1.01}};
  m.triangles = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}};
  return m;
}

// Integral of density / max density: the volume of the filled interior, counting boundary
// voxels by their coverage.
double filledVolume(const DensityField& field) {
  const auto& volume = dynamic_cast<const GridVolume&>(field);
  const auto grid = openvdbGrid(volume);
  double sum = 0;
  for (auto it = grid->cbeginValueOn(); it; ++it) sum += *it * it.getVoxelCount();
  return sum / volume.maxDensity() * std::pow(volume.voxelSize(), 3);
}

MeshSourceOptions withResolution(int res, const std::string& path = "test") {
  MeshSourceOptions o;
  o.path = path;
  o.resolution = res;
  return o;
}

class MeshVolumeTest : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = testing::scratchDir("meshvol"); }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string dir_;
};

TEST(WindingNumber, SolidAngleAndExactValues) {
  TriangleMesh tet = tetrahedron();
  EXPECT_NEAR(windingNumberExact(tet, Vec3(0.3, 0.3, 0.3)), 1.0, 1e-9);
  EXPECT_NEAR(windingNumberExact(tet, Vec3(2, 2, 2)), 0.0, 1e-9);
  // Reversing the orientation negates it.
  for (auto& t : tet.triangles) std::swap(t[1], t[2]);
  EXPECT_NEAR(windingNumberExact(tet, Vec3(0.3, 0.3, 0.3)), -1.0, 1e-9);
  // A large triangle right in front of p covers nearly a hemisphere: solid angle -> 2 pi.
  const double omega =
      triangleSolidAngle(Vec3(-1e4, -1e4, 1), Vec3(1e4, -1e4, 1), Vec3(0, 1e4, 1), Vec3(0, 0, 0));
  EXPECT_NEAR(std::abs(omega), 2 * kPi, 1e-3);
}

TEST(WindingNumber, FastMatchesExactOnTeapot) {
  const std::string path = testing::sharedData("teapot.obj");
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared asset absent: " << path;
  const TriangleMesh mesh = readMesh(path);
  const FastWindingNumber fast(mesh);
  Rng rng(11);
  double max_err = 0;
  int agree = 0;
  const int n = 400;
  for (int i = 0; i < n; ++i) {
    const Vec3 p(rng.uniform() * 7 - 3.5, rng.uniform() * 3.6 - 0.2, rng.uniform() * 4.4 - 2.2);
    const double exact = windingNumberExact(mesh, p), approx = fast(p);
    max_err = std::max(max_err, std::abs(exact - approx));
    agree += (exact > 0.5) == (approx > 0.5);
  }
  EXPECT_LT(max_err, 0.05);
  EXPECT_GE(agree, n - 2);
}

TEST_F(MeshVolumeTest, CubeVolumeAndCentreFromFiles) {
  const Vec3 lo(0.013, -0.21, 0.37), hi(0.987, 0.61, 1.07);
  const std::string obj = dir_ + "/cube.obj";
  testing::writeText(obj, cubeObj(lo, hi));
  const auto field = meshToVolume(withResolution(48, obj));
  const Vec3 e = hi - lo;
  std::printf("cube: exact volume %.6f, voxelised %.6f (res 48)\n", e.x * e.y * e.z,
              filledVolume(*field));
  EXPECT_NEAR(filledVolume(*field), e.x * e.y * e.z, 0.01 * e.x * e.y * e.z);
  auto lookup = field->lookup();
  EXPECT_NEAR(lookup->density((lo + hi) * 0.5), 1.0, 1e-6);
  EXPECT_EQ(lookup->density(hi + Vec3(0.1)), 0.0);
  testing::checkMajorants(*field, 20000);
}

// A closed mesh fills the same whatever its faces' winding (an outside probe's cube with two of
// its twelve triangles reversed came out hollow with a sheet of density below it; wound inwards
// throughout it was refused as enclosing nothing).
TEST_F(MeshVolumeTest, AClosedMeshFillsTheSameWhateverItsWinding) {
  const Vec3 lo(0.013, -0.21, 0.37), hi(0.987, 0.61, 1.07);
  const std::string obj = dir_ + "/cube.obj";
  testing::writeText(obj, cubeObj(lo, hi));
  const TriangleMesh right = readMesh(obj);
  const double expected = filledVolume(*meshToVolume(right, withResolution(24)));
  TriangleMesh some = right, all = right;
  for (size_t f : {0, 1, 7}) std::swap(some.triangles[f][1], some.triangles[f][2]);
  for (auto& t : all.triangles) std::swap(t[1], t[2]);
  for (const TriangleMesh* m : {&some, &all}) {
    const auto field = meshToVolume(*m, withResolution(24));
    EXPECT_DOUBLE_EQ(filledVolume(*field), expected);
    EXPECT_NEAR(field->lookup()->density((lo + hi) * 0.5), 1.0, 1e-6);
    EXPECT_EQ(field->lookup()->density(Vec3(0.5, 0.2, lo.z - 0.05)), 0.0);  // below the cube
  }
}

TEST_F(MeshVolumeTest, TetrahedronVolumeMatchesAnalytic) {
  const TriangleMesh tet = tetrahedron();
  const Vec3 a = tet.vertices[1] - tet.vertices[0], b = tet.vertices[2] - tet.vertices[0],
             c = tet.vertices[3] - tet.vertices[0];
  const double exact = std::abs(dot(a, cross(b, c))) / 6.0;
  const auto field = meshToVolume(tet, withResolution(96));
  std::printf("tetrahedron: exact volume %.6f, voxelised %.6f (res 96)\n", exact,
              filledVolume(*field));
  EXPECT_NEAR(filledVolume(*field), exact, 0.01 * exact);
  MeshSourceOptions o;
  o.path = "tet";
  o.voxel_size = 0.02;
  o.density = 2.5;
  const auto coarse = meshToVolume(tet, o);
  EXPECT_NEAR(filledVolume(*coarse), exact, 0.06 * exact);
  EXPECT_FLOAT_EQ(coarse->maxDensity(), 2.5f);
  EXPECT_DOUBLE_EQ(coarse->featureSize(), 0.02);
}

TEST_F(MeshVolumeTest, ObjAndPlyVariantsGiveIdenticalGrids) {
  // The cube as OBJ, ASCII PLY and binary PLY (little- and big-endian).
  const Vec3 lo(-0.4, 0.1, 0.05), hi(0.5, 0.8, 0.6);
  testing::writeText(dir_ + "/c.obj", cubeObj(lo, hi));
  const TriangleMesh mesh = readMesh(dir_ + "/c.obj");
  std::ostringstream ascii;
  ascii.precision(9);
  ascii << "ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\n"
           "property float z\nelement face "
        << mesh.triangles.size() << "\nproperty list uchar int vertex_indices\nend_header\n";
  for (const Vec3& v : mesh.vertices) {
    ascii << static_cast<float>(v.x) << " " << static_cast<float>(v.y) << " "
          << static_cast<float>(v.z) << "\n";
  }
  for (const auto& t : mesh.triangles) ascii << "3 " << t[0] << " " << t[1] << " " << t[2] << "\n";
  testing::writeText(dir_ + "/c_ascii.ply", ascii.str());
  for (const char* fmt : {"binary_little_endian", "binary_big_endian"}) {
    const bool big = std::string(fmt) == "binary_big_endian";
    std::string s = std::string("ply\nformat ") + fmt +
                    " 1.0\nelement vertex 8\nproperty float x\nproperty float y\n"
                    "property float z\nelement face " +
                    std::to_string(mesh.triangles.size()) +
                    "\nproperty list uchar int vertex_indices\nend_header\n";
    auto put = [&](const void* p, size_t n) {
      std::string bytes(static_cast<const char*>(p), n);
      if (big) std::reverse(bytes.begin(), bytes.end());
      s += bytes;
    };
    for (const Vec3& v : mesh.vertices)
      for (int a = 0; a < 3; ++a) {
        const float f = static_cast<float>(v[a]);
        put(&f, 4);
      }
    for (const auto& t : mesh.triangles) {
      s += '\x03';
      for (int k = 0; k < 3; ++k) put(&t[k], 4);
    }
    testing::writeText(dir_ + "/c_" + fmt + ".ply", s);
  }
  // Float coordinates in all files so the meshes are bit-identical.
  std::ostringstream fobj;
  fobj.precision(9);
  for (const Vec3& v : mesh.vertices) {
    fobj << "v " << static_cast<float>(v.x) << " " << static_cast<float>(v.y) << " "
         << static_cast<float>(v.z) << "\n";
  }
  for (const auto& t : mesh.triangles)
    fobj << "f " << t[0] + 1 << " " << t[1] + 1 << " " << t[2] + 1 << "\n";
  testing::writeText(dir_ + "/c_float.obj", fobj.str());

  const auto ref = meshToVolume(withResolution(40, dir_ + "/c_float.obj"));
  const auto ref_grid = openvdbGrid(dynamic_cast<const GridVolume&>(*ref));
  for (const char* name :
       {"c_ascii.ply", "c_binary_little_endian.ply", "c_binary_big_endian.ply"}) {
    const auto other = meshToVolume(withResolution(40, dir_ + "/" + name));
    const auto grid = openvdbGrid(dynamic_cast<const GridVolume&>(*other));
    EXPECT_EQ(grid->activeVoxelCount(), ref_grid->activeVoxelCount()) << name;
    EXPECT_TRUE(grid->tree().hasSameTopology(ref_grid->tree())) << name;
    EXPECT_EQ(grid->evalActiveVoxelBoundingBox(), ref_grid->evalActiveVoxelBoundingBox()) << name;
  }
}

TEST_F(MeshVolumeTest, ValidatesOptions) {
  const TriangleMesh tet = tetrahedron();
  MeshSourceOptions o;
  o.path = "tet.obj";
  EXPECT_THROW(meshToVolume(tet, o), InputError);  // neither set
  o.resolution = 32;
  o.voxel_size = 0.1;
  EXPECT_THROW(meshToVolume(tet, o), InputError);  // both set
  o.voxel_size = 0;
  o.resolution = -4;
  EXPECT_THROW(meshToVolume(tet, o), InputError);
  o.resolution = 0;
  o.voxel_size = std::nan("");
  EXPECT_THROW(meshToVolume(tet, o), InputError);
  // Refused with a message holding `words`.
  auto refusedSaying = [&](std::initializer_list<const char*> words) {
    try {
      meshToVolume(tet, o);
      FAIL();
    } catch (const InputError& e) {
      for (const char* w : words) EXPECT_NE(std::string(e.what()).find(w), std::string::npos);
    }
  };
  o.voxel_size = 3e-5;
  refusedSaying({"limit", "mesh.voxel_size"});
  // Finer than OpenVDB's transforms allow (kMinVoxelSize).
  o.voxel_size = 1e-5;
  refusedSaying({"below the smallest", "mesh.voxel_size"});
  // Small, but 1e12 from the origin: beyond the grid's index range, whatever its voxel count
  // (the message had said "more than 1e18 voxels").
  TriangleMesh far = tet;
  for (Vec3& v : far.vertices) v += Vec3(1e12, 0, 0);
  o.voxel_size = 0;
  o.resolution = 16;
  try {
    meshToVolume(far, o);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("index range"), std::string::npos) << e.what();
    EXPECT_EQ(std::string(e.what()).find("1e18"), std::string::npos) << e.what();
  }
  o.resolution = 0;
  o.voxel_size = 0.05;
  o.density = -1;
  EXPECT_THROW(meshToVolume(tet, o), InputError);
  o.density = 1;
  o.noise_enabled = true;
  o.noise.octaves = 0;
  EXPECT_THROW(meshToVolume(tet, o), InputError);
  // A single open triangle encloses nothing.
  TriangleMesh flat;
  flat.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0.2}};
  flat.triangles = {{0, 1, 2}};
  EXPECT_THROW(meshToVolume(flat, withResolution(16)), InputError);
  TriangleMesh broken = tetrahedron();
  broken.triangles[2][1] = 4;
  EXPECT_THROW(meshToVolume(broken, withResolution(16)), InputError);
  broken = tetrahedron();
  broken.vertices[0].x = std::nan("");
  EXPECT_THROW(meshToVolume(broken, withResolution(16)), InputError);
  // One stray vertex far out: the message shows the bounds it made, not only "too thin".
  broken = tetrahedron();
  broken.vertices.push_back({1e39, 1, 1});
  broken.triangles.push_back({0, 1, 4});
  try {
    meshToVolume(broken, withResolution(16));
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("over its bounds [0.1, 0.05, 0.02] - [1e+39, 1, 1.01]"),
              std::string::npos)
        << e.what();
  }
}

TEST_F(MeshVolumeTest, NoiseModulatesDensityDeterministically) {
  MeshSourceOptions o = withResolution(48);
  o.density = 2.0;
  o.noise_enabled = true;
  o.noise.amount = 0.8;
  o.noise.seed = 3;
  const TriangleMesh tet = tetrahedron();
  const auto a = meshToVolume(tet, o);
  const auto b = meshToVolume(tet, o);
  o.noise_enabled = false;
  const auto plain = meshToVolume(tet, o);
  EXPECT_EQ(dynamic_cast<const GridVolume&>(*a).activeVoxelCount(),
            dynamic_cast<const GridVolume&>(*plain).activeVoxelCount());
  auto la = a->lookup(), lb = b->lookup();
  Rng rng(5);
  double lo = 1e9, hi = 0;
  for (int i = 0; i < 3000; ++i) {
    const Vec3 p = Vec3(0.25, 0.25, 0.2) + Vec3(rng.uniform(), rng.uniform(), rng.uniform()) * 0.15;
    const double d = la->density(p);
    EXPECT_EQ(d, lb->density(p));
    lo = std::min(lo, d);
    hi = std::max(hi, d);
  }
  EXPECT_GE(lo, 2.0 * 0.2 - 1e-6);
  EXPECT_LE(hi, 2.0 + 1e-6);
  EXPECT_GT(hi - lo, 0.2) << "noise should vary the density";
}

// A run's cancellation reaches the voxelisation, which at a high resolution takes tens of
// seconds (an outside test waited 32-56 s for a cancelled bunny at 600 voxels): a stop that
// fires throws Cancelled from between blocks; one that never fires changes nothing.
TEST_F(MeshVolumeTest, AStopPredicateCancelsTheVoxelisation) {
  const TriangleMesh tet = tetrahedron();
  MeshSourceOptions o = withResolution(256);
  o.noise_enabled = true;
  std::atomic<int> polls{0};
  EXPECT_THROW(meshToVolume(tet, o, [&] { return ++polls > 1; }), Cancelled);
  EXPECT_GE(polls.load(), 2);
  o = withResolution(24);
  const auto plain = meshToVolume(tet, o);
  const auto polled = meshToVolume(tet, o, [] { return false; });
  EXPECT_EQ(dynamic_cast<const GridVolume&>(*plain).activeVoxelCount(),
            dynamic_cast<const GridVolume&>(*polled).activeVoxelCount());
}

// Within a block too: on a degenerate mesh (a soup of large overlapping triangles) one 8^3 block
// took tens of seconds, and an outside probe's cancel was answered after 86 s. A tetrahedron at
// 6 voxels is one block, so a stop polled only between blocks would let it finish.
TEST_F(MeshVolumeTest, AStopIsPolledWithinABlock) {
  const TriangleMesh tet = tetrahedron();
  const MeshSourceOptions o = withResolution(6);
  std::atomic<int> polls{0};
  EXPECT_THROW(meshToVolume(tet, o, [&] { return ++polls > 3; }), Cancelled);
}

TEST_F(MeshVolumeTest, IndependentOfThreadCount) {
  MeshSourceOptions o = withResolution(40);
  o.noise_enabled = true;
  DensityFieldPtr one;
  {
    tbb::global_control single(tbb::global_control::max_allowed_parallelism, 1);
    one = meshToVolume(tetrahedron(), o);
  }
  const auto many = meshToVolume(tetrahedron(), o);
  const auto a = openvdbGrid(dynamic_cast<const GridVolume&>(*one));
  const auto b = openvdbGrid(dynamic_cast<const GridVolume&>(*many));
  ASSERT_TRUE(a->tree().hasSameTopology(b->tree()));
  auto acc = b->getConstAccessor();
  for (auto it = a->cbeginValueOn(); it; ++it) ASSERT_EQ(*it, acc.getValue(it.getCoord()));
}

TEST(MeshVolumeShared, BunnyIsFilledAndFast) {
  const std::string path = testing::sharedData("bun_zipper.ply");
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared asset absent: " << path;
  const TriangleMesh mesh = readMesh(path);
  const auto t0 = std::chrono::steady_clock::now();
  const auto field = meshToVolume(mesh, withResolution(128, path));
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  Bounds3 mb;
  for (const Vec3& v : mesh.vertices) mb.expand(v);
  const Vec3 e = mb.extent();
  const double fraction = filledVolume(*field) / (e.x * e.y * e.z);
  std::printf(
      "bunny res 128: %.2f s, %llu voxels, %.3f of the bounding box\n", secs,
      static_cast<unsigned long long>(dynamic_cast<const GridVolume&>(*field).activeVoxelCount()),
      fraction);
  EXPECT_GT(fraction, 0.2);
  EXPECT_LT(fraction, 0.5);
  // The body (centre of the bounding box) is inside, as the exact winding number says.
  const Vec3 centre = mb.center();
  ASSERT_GT(windingNumberExact(mesh, centre), 0.9);
  EXPECT_NEAR(field->lookup()->density(centre), 1.0, 1e-6);
  EXPECT_EQ(field->lookup()->density(mb.max + Vec3(0.01)), 0.0);
  testing::checkMajorants(*field, 20000);
}

TEST(MeshVolumeShared, OpenTeapotGivesASolidBody) {
  const std::string path = testing::sharedData("teapot.obj");
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared asset absent: " << path;
  const auto field = meshToVolume(withResolution(64, path));
  auto lookup = field->lookup();
  // Inside the body (the pot has no bottom, the lid is separate).
  EXPECT_NEAR(lookup->density(Vec3(0, 1.0, 0)), 1.0, 1e-6);
  EXPECT_NEAR(lookup->density(Vec3(1.0, 0.8, 0.5)), 1.0, 1e-6);
  EXPECT_NEAR(lookup->density(Vec3(0, 2.0, 0)), 1.0, 1e-6);
  // Just above the missing bottom the winding number is still above 1/2 (~0.6).
  EXPECT_NEAR(lookup->density(Vec3(0, 0.3, 0)), 1.0, 1e-6);
  // Outside: above the lid and beyond the handle's reach.
  EXPECT_EQ(lookup->density(Vec3(0, 3.4, 0)), 0.0);
  EXPECT_EQ(lookup->density(Vec3(0, 1.0, 2.5)), 0.0);
  const double v = filledVolume(*field);
  // The body alone is roughly a squashed sphere of radius ~2 and height ~2.4.
  EXPECT_GT(v, 15.0);
  EXPECT_LT(v, 45.0);
}

}  // namespace
}  // namespace cloudbake
