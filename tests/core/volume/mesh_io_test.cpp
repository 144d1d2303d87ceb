#include "core/volume/mesh_io.h"

#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>

#include "core/error.h"
#include "tests/core/volume/volume_test_util.h"

namespace cloudbake {
namespace {

using testing::writeText;

class MeshIoTest : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = testing::scratchDir("meshio"); }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& text) {
    const std::string path = dir_ + "/" + name;
    writeText(path, text);
    return path;
  }
  // Message of the InputError that reading `text` as `name` throws ("" and a failure if none).
  std::string error(const std::string& name, const std::string& text) {
    const std::string path = write(name, text);
    try {
      readMesh(path);
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(name), std::string::npos) << msg;
      return msg;
    }
    ADD_FAILURE() << "no InputError for " << name << ":\n" << text;
    return "";
  }
  std::string dir_;
};

TEST_F(MeshIoTest, ObjFansNegativeIndicesAndIgnoredStatements) {
  const auto mesh = readMesh(write("quad.OBJ",
                                   "# comment\n"
                                   "mtllib x.mtl\no quad\nv 0 0 0\nv 1 0 0\r\nv 1 1 0\n"
                                   "vt 0 0\nvn 0 0 1\nusemtl red\ns off\n"
                                   "v 0 1 0 1.0\n"
                                   "f 1/1/1 2/1/1 3//1 4\n"
                                   "f -4 -3 -1\n"
                                   "l 1 2\n"));
  ASSERT_EQ(mesh.vertices.size(), 4u);
  ASSERT_EQ(mesh.triangles.size(), 3u);
  EXPECT_EQ(mesh.triangles[0], (std::array<int32_t, 3>{0, 1, 2}));
  EXPECT_EQ(mesh.triangles[1], (std::array<int32_t, 3>{0, 2, 3}));
  EXPECT_EQ(mesh.triangles[2], (std::array<int32_t, 3>{0, 1, 3}));
  EXPECT_EQ(mesh.vertices[3], Vec3(0, 1, 0));
}

// A UTF-8 byte-order mark before the first line (an outside probe: its vertex was dropped and
// the error blamed a face on line 12).
TEST_F(MeshIoTest, ObjWithAByteOrderMark) {
  const auto mesh = readMesh(write("bom.obj", "\xEF\xBB\xBFv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"));
  ASSERT_EQ(mesh.vertices.size(), 3u);
  ASSERT_EQ(mesh.triangles.size(), 1u);
  EXPECT_EQ(mesh.vertices[0], Vec3(0, 0, 0));
}

TEST_F(MeshIoTest, MalformedObjNamesTheLine) {
  EXPECT_NE(error("a.obj", "v 0 0 0\nv 1 2\n").find("a.obj:2"), std::string::npos);
  EXPECT_NE(error("b.obj", "v 0 0 0\nv 1 x 2\nv 1 1 1\nf 1 2 3\n").find("b.obj:2"),
            std::string::npos);
  EXPECT_NE(error("c.obj", "v 0 0 0\nv 1 0 0\nv 1 1 1\nf 1 2 4\n").find("c.obj:4"),
            std::string::npos);
  error("d.obj", "v 0 0 0\nv 1 0 0\nv 1 1 1\nf 1 2\n");
  error("e.obj", "v 0 0 0\nv 1 0 0\nv 1 1 1\nf 0 1 2\n");
  error("f.obj", "v 0 0 0\nv 1 0 0\nv 1 1 1\nf -4 1 2\n");
  error("g.obj", "v 0 0 0\nv 1 0 0\nv 1 1 1\n");  // no faces
  error("h.obj", "v 0 0 nan\nv 1 0 0\nv 1 1 1\nf 1 2 3\n");
  error("i.obj", "");
  error("j.stl", "solid x\n");
  EXPECT_THROW(readMesh(dir_ + "/missing.obj"), InputError);
}

std::string plyHeader(const std::string& format, int nv, int nf) {
  return "ply\nformat " + format + " 1.0\ncomment test\nelement vertex " + std::to_string(nv) +
         "\nproperty float x\nproperty double y\nproperty float z\nproperty uchar red\n"
         "element face " +
         std::to_string(nf) +
         "\nproperty list uchar int vertex_indices\nproperty short flags\n"
         "element edge 1\nproperty int a\nproperty list ushort uint b\nend_header\n";
}

template <typename T>
void put(std::string* out, T v, bool big) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &v, sizeof(T));
  if (big) std::reverse(bytes, bytes + sizeof(T));
  out->append(bytes, sizeof(T));
}

// A unit square (quad) and a triangle, with extra properties and an extra element to skip.
std::string binaryPly(bool big) {
  std::string s = plyHeader(big ? "binary_big_endian" : "binary_little_endian", 5, 2);
  const float xs[5] = {0, 1, 1, 0, 0.5f};
  const double ys[5] = {0, 0, 1, 1, 0.5};
  for (int i = 0; i < 5; ++i) {
    put<float>(&s, xs[i], big);
    put<double>(&s, ys[i], big);
    put<float>(&s, static_cast<float>(i == 4), big);
    put<uint8_t>(&s, 200, big);
  }
  put<uint8_t>(&s, 4, big);
  for (int i : {0, 1, 2, 3}) put<int32_t>(&s, i, big);
  put<int16_t>(&s, -3, big);
  put<uint8_t>(&s, 3, big);
  for (int i : {0, 1, 4}) put<int32_t>(&s, i, big);
  put<int16_t>(&s, 7, big);
  put<int32_t>(&s, 5, big);
  put<uint16_t>(&s, 2, big);
  put<uint32_t>(&s, 9, big);
  put<uint32_t>(&s, 8, big);
  return s;
}

const char* kAsciiBody =
    "0 0 0 200\n1 0 0 200\n1 1 0 200\n0 1 0 200\n0.5 0.5 1 200\n"
    "4 0 1 2 3 -3\n3 0 1 4 7\n5 2 9 8\n";

TEST_F(MeshIoTest, PlyAsciiAndBinaryGiveTheSameMesh) {
  const auto ascii = readMesh(write("a.ply", plyHeader("ascii", 5, 2) + kAsciiBody));
  const auto le = readMesh(write("le.ply", binaryPly(false)));
  const auto be = readMesh(write("be.ply", binaryPly(true)));
  for (const TriangleMesh* m : {&ascii, &le, &be}) {
    ASSERT_EQ(m->vertices.size(), 5u);
    ASSERT_EQ(m->triangles.size(), 3u);
    EXPECT_EQ(m->vertices, ascii.vertices);
    EXPECT_EQ(m->triangles, ascii.triangles);
  }
  EXPECT_EQ(ascii.vertices[4], Vec3(0.5, 0.5, 1));
  EXPECT_EQ(ascii.triangles[1], (std::array<int32_t, 3>{0, 2, 3}));
  EXPECT_EQ(ascii.triangles[2], (std::array<int32_t, 3>{0, 1, 4}));
}

TEST_F(MeshIoTest, MalformedPlyNamesTheLineOrElement) {
  const std::string header = plyHeader("ascii", 5, 2);
  error("a.ply", "plx\n");
  EXPECT_NE(error("b.ply", "ply\nformat ascii 1.0\nelement vertex 3\n").find("header"),
            std::string::npos);
  error("c.ply", "ply\nformat weird 1.0\nend_header\n");
  error("d.ply",
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
        "element face 0\nproperty list uchar int vertex_indices\nend_header\n0 0\n");
  EXPECT_NE(error("e.ply", header + "0 0 0 200\n1 0 0 200\n").find("vertex 2"), std::string::npos);
  EXPECT_NE(error("f.ply", header + "0 0 0 200\n1 0 0 200\n1 1 0 200\n0 1 0 200\n0.5 0.5 1 200\n"
                                    "4 0 1 2 9 -3\n3 0 1 4 7\n5 2 9 8\n")
                .find("face 0"),
            std::string::npos);
  error("g.ply", header + "0 0 0 200\n1 zero 0 200\n");
  error("h.ply",
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty list float int x\nend_header\n");
  error("i.ply", "ply\nformat ascii 1.0\nelement vertex 99999999999\nend_header\n");
  error("j.ply",
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n");  // no faces
  const std::string bin = binaryPly(false);
  for (size_t cut : {bin.size() - 1, bin.size() - 20, bin.size() - 60}) {
    error("k" + std::to_string(cut) + ".ply", bin.substr(0, cut));
  }
}

TEST(MeshIoShared, ReadsBunnyPlyAndObj) {
  const std::string ply = testing::sharedData("bun_zipper.ply");
  const std::string obj = testing::sharedData("stanford-bunny.obj");
  if (!std::filesystem::exists(ply) || !std::filesystem::exists(obj)) {
    GTEST_SKIP() << "shared assets absent: " << ply;
  }
  const auto a = readMesh(ply);
  const auto b = readMesh(obj);
  EXPECT_EQ(a.vertices.size(), 35947u);
  EXPECT_EQ(a.triangles.size(), 69451u);
  EXPECT_EQ(b.vertices.size(), 35947u);
  EXPECT_EQ(b.triangles.size(), 69451u);
}

}  // namespace
}  // namespace cloudbake
