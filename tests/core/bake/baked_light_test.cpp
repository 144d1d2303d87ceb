// BakedLight: its checks, its support, and its .vdb form (round trip, conventions, bad files).
#include "core/bake/baked_light.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "core/bake/baked_light_vdb.h"
#include "core/bake/sky_sh_scatter.h"
#include "core/error.h"
#include "core/io/vdb_io.h"
#include "core/volume/analytic.h"
#include "tests/core/bake/bake_test_util.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;

// A 10^3 lattice with a 4^3 block of density in the middle and light grids over the support.
BakedLight smallBake() {
  BakedLight b;
  b.grid.origin = Vec3(-1.0, 0.5, 2.0);
  b.grid.voxel_size = 0.25;
  b.grid.nx = b.grid.ny = b.grid.nz = 10;
  b.method = "single";
  b.sun_direction = normalize(Vec3(1, 2, 3));
  b.metadata["cloudbake:light_resolution"] = "8";
  b.density.assign(b.grid.voxelCount(), 0.f);
  for (int k = 3; k < 7; ++k)
    for (int j = 3; j < 7; ++j)
      for (int i = 3; i < 7; ++i) b.density[b.grid.index(i, j, k)] = 0.5f + 0.1f * float(i);
  BakeChannel& t = b.add(bake_grids::kSunTransmittance, 1);
  BakeChannel& co = b.add(bake_grids::kMultipleFluence, 3);
  for (size_t v = 0; v < b.grid.voxelCount(); ++v) {
    t.data[v] = float(v % 97) / 97.f;
    for (int c = 0; c < 3; ++c) co.data[3 * v + size_t(c)] = float(v % 13) * 0.1f + float(c);
  }
  b.trimToSupport();
  return b;
}

class BakeFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("cloudbake_bake_file_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  fs::path dir_;
};

// The light channels keep the voxels next to density; the sun's transmittance two voxels more,
// which views read (sunTransmittanceSupport).
TEST(BakedLight, TrimKeepsTheNeighboursOfDensityOnly) {
  const BakedLight b = smallBake();
  const auto& t = b.find(bake_grids::kSunTransmittance)->data;
  const auto& co = b.find(bake_grids::kMultipleFluence)->data;
  auto original = [&](int i, int j, int k) { return float(b.grid.index(i, j, k) % 97) / 97.f; };
  // (2, 5, 5) touches density at (3, 5, 5); (1, 5, 5) does not but is two voxels from it;
  // (2, 2, 2) touches (3, 3, 3); (0, 0, 0) is three voxels from it, the sun's support's edge.
  EXPECT_EQ(t[b.grid.index(2, 5, 5)], original(2, 5, 5));
  EXPECT_EQ(t[b.grid.index(2, 2, 2)], original(2, 2, 2));
  EXPECT_EQ(t[b.grid.index(1, 5, 5)], original(1, 5, 5));
  EXPECT_EQ(co[3 * b.grid.index(1, 5, 5) + 1], 0.f);
  EXPECT_GT(co[3 * b.grid.index(2, 5, 5) + 1], 0.f);
  EXPECT_EQ(t[b.grid.index(0, 0, 0)], original(0, 0, 0));
  EXPECT_EQ(co[3 * b.grid.index(0, 0, 0) + 1], 0.f);
  EXPECT_EQ(b.find("nothing"), nullptr);
  // One voxel of density: its support is 3^3 voxels, the sun's 7^3.
  BakeGrid g;
  g.nx = g.ny = g.nz = 11;
  std::vector<float> one(g.voxelCount(), 0.f);
  one[g.index(5, 5, 5)] = 1.f;
  const std::vector<uint8_t> support = densitySupport(g, one);
  const std::vector<uint8_t> sun = sunTransmittanceSupport(g, support);
  EXPECT_EQ(std::count(support.begin(), support.end(), 1), 27);
  EXPECT_EQ(std::count(sun.begin(), sun.end(), 1), 343);
  EXPECT_TRUE(sun[g.index(2, 8, 5)]);
  EXPECT_FALSE(sun[g.index(1, 5, 5)]);
}

// The checks scan chunks of voxels in parallel, yet name the first bad voxel, as a scan in
// order does, and its first problem; trimming with a given support equals trimming.
// The support is every voxel with density > 0 among its 27 neighbours, counted one by one here,
// on a sparse random lattice whose density touches every face and edge.
TEST(BakedLight, SupportIsTheDilationOfTheDensityByOneVoxel) {
  BakeGrid g;
  g.nx = 13;
  g.ny = 7;
  g.nz = 9;
  std::vector<float> d(g.voxelCount(), 0.f);
  uint32_t state = 7;
  for (float& v : d) {
    state = state * 1664525u + 1013904223u;
    if ((state >> 24) < 12) v = (state >> 24) < 2 ? -1.f : 0.5f;  // some negative: not support
  }
  d[g.index(0, 0, 0)] = d[g.index(g.nx - 1, g.ny - 1, g.nz - 1)] = 1.f;
  const std::vector<uint8_t> support = densitySupport(g, d);
  ASSERT_EQ(support.size(), g.voxelCount());
  int in = 0;
  for (int k = 0; k < g.nz; ++k)
    for (int j = 0; j < g.ny; ++j)
      for (int i = 0; i < g.nx; ++i) {
        bool any = false;
        for (int c = -1; c <= 1; ++c)
          for (int b = -1; b <= 1; ++b)
            for (int a = -1; a <= 1; ++a) {
              const int x = i + a, y = j + b, z = k + c;
              if (x < 0 || y < 0 || z < 0 || x >= g.nx || y >= g.ny || z >= g.nz) continue;
              any = any || d[g.index(x, y, z)] > 0;
            }
        EXPECT_EQ(support[g.index(i, j, k)], any ? 1 : 0) << i << " " << j << " " << k;
        in += any;
      }
  EXPECT_GT(in, 100);
  EXPECT_LT(in, int(g.voxelCount()));
  // A row's span runs from its first voxel of the support to its last; an empty row has none.
  const std::vector<uint8_t> row = {0, 0, 1, 0, 1, 0}, none(6, 0);
  int first = -1, last = -1;
  EXPECT_TRUE(supportSpan(row.data(), 6, &first, &last));
  EXPECT_EQ(first, 2);
  EXPECT_EQ(last, 4);
  EXPECT_FALSE(supportSpan(none.data(), 6, &first, &last));
}

// Each grid's rule on every value, through the vectorised range scan and the voxel scan that
// names the voxel: values on the rules' edges pass, one value past them anywhere is refused.
TEST(BakedLight, ValidateChecksEveryRuleOnEveryValue) {
  BakedLight b;
  b.grid.voxel_size = 0.1;
  b.grid.nx = b.grid.ny = 40;
  b.grid.nz = 50;  // 80000 voxels, 240000 values of a 3-component grid: several chunks
  b.sun_direction = Vec3(0, 0, 1);
  b.density.assign(b.grid.voxelCount(), 0.f);
  auto& t = b.add(bake_grids::kSunTransmittance, 1).data;
  auto& co = b.add(bake_grids::kMultipleFluence, 3).data;
  auto& sh = b.add(bake_grids::skyTransmittanceSh(1), 1).data;
  std::fill(t.begin(), t.end(), 1.f);
  t[7] = 0.f;
  t[8] = -0.f;
  std::fill(co.begin(), co.end(), 0.f);
  co[100] = std::numeric_limits<float>::max();
  std::fill(sh.begin(), sh.end(), -3.5f);  // SH coefficients may be negative
  sh[9] = -std::numeric_limits<float>::max();
  EXPECT_NO_THROW(b.validate("bake"));
  const size_t last = co.size() - 1;  // the last value of the last voxel
  co[last] = -1e-30f;
  expectErrorNaming([&] { b.validate("bake"); }, "grid 'Co': voxel (39, 39, 49)");
  co[last] = std::numeric_limits<float>::infinity();
  expectErrorNaming([&] { b.validate("bake"); }, "value is not finite");
  co[last] = 0.f;
  t[b.grid.index(0, 0, 49)] = std::nextafter(1.f, 2.f);
  expectErrorNaming([&] { b.validate("bake"); }, "grid 'sun_transmittance': voxel (0, 0, 49)");
  t[b.grid.index(0, 0, 49)] = 1.f;
  sh[12345] = -std::numeric_limits<float>::infinity();
  expectErrorNaming([&] { b.validate("bake"); }, "value is not finite");
  sh[12345] = std::nanf("");
  expectErrorNaming([&] { b.validate("bake"); }, "value is not finite");
  sh[12345] = 0.f;
  EXPECT_NO_THROW(b.validate("bake"));
}

TEST(BakedLight, ValidateNamesTheFirstBadVoxelOfALargeGrid) {
  BakedLight b;
  b.grid.voxel_size = 0.1;
  b.grid.nx = b.grid.ny = 64;
  b.grid.nz = 48;  // 196608 voxels: six chunks of the scan
  b.sun_direction = Vec3(0, 0, 1);
  b.density.assign(b.grid.voxelCount(), 0.5f);
  auto& t = b.add(bake_grids::kSunTransmittance, 1).data;
  std::fill(t.begin(), t.end(), 0.5f);
  t[b.grid.index(3, 2, 40)] = -2.f;  // in a later chunk
  t[b.grid.index(5, 9, 20)] = 7.f;   // the first in order
  t[b.grid.index(6, 9, 20)] = std::nanf("");
  expectErrorNaming([&] { b.validate("bake"); },
                    "grid 'sun_transmittance': voxel (5, 9, 20) at (0.5, 0.9, 2): value 7.000000 "
                    "outside [0, 1]");
  b.density[b.grid.index(60, 1, 47)] = -1.f;
  b.density[b.grid.index(1, 60, 10)] = std::nanf("");
  expectErrorNaming([&] { b.validate("bake"); }, "grid 'density': voxel (1, 60, 10)");

  BakedLight a = smallBake(), c = smallBake();
  for (BakedLight* x : {&a, &c}) {
    for (const char* name : {bake_grids::kSunTransmittance, bake_grids::kMultipleFluence}) {
      auto& d = x->channels[name].data;
      std::fill(d.begin(), d.end(), 0.25f);
    }
  }
  a.trimToSupport();
  c.trimToSupport(densitySupport(c.grid, c.density));
  for (const char* name : {bake_grids::kSunTransmittance, bake_grids::kMultipleFluence}) {
    EXPECT_EQ(a.channels[name].data, c.channels[name].data) << name;
  }
  EXPECT_EQ(a.channels[bake_grids::kMultipleFluence].data[3 * a.grid.index(0, 0, 0)], 0.f);
  EXPECT_EQ(a.channels[bake_grids::kMultipleFluence].data[3 * a.grid.index(4, 4, 4)], 0.25f);
}

TEST(BakedLight, ValidateNamesTheGridAndTheVoxel) {
  EXPECT_NO_THROW(smallBake().validate("bake"));
  {
    BakedLight b = smallBake();
    b.density[b.grid.index(4, 4, 4)] = std::nanf("");
    expectErrorNaming([&] { b.validate("bake"); }, "grid 'density': voxel (4, 4, 4)");
  }
  {
    BakedLight b = smallBake();
    b.density[7] = -1.f;
    expectErrorNaming([&] { b.validate("bake"); }, "negative density");
  }
  {
    BakedLight b = smallBake();
    b.add(bake_grids::kMieRatio, 1).data[b.grid.index(4, 4, 4)] = 1.5f;
    expectErrorNaming([&] { b.validate("bake"); }, "grid 'mie_ratio'");
  }
  {
    BakedLight b = smallBake();
    b.channels[bake_grids::kSunTransmittance].data.pop_back();
    expectErrorNaming([&] { b.validate("bake"); }, "grid 'sun_transmittance' has");
  }
  {
    BakedLight b = smallBake();
    float* l = b.add(bake_grids::kLightDir, 3).data.data() + 3 * b.grid.index(4, 4, 4);
    l[0] = 0.5f;
    expectErrorNaming([&] { b.validate("bake"); }, "grid 'light_dir'");
    l[0] = 1.f;  // unit: fine
    EXPECT_NO_THROW(b.validate("bake"));
  }
  {
    BakedLight b = smallBake();
    b.sun_direction = Vec3(0, 0, 2);
    expectErrorNaming([&] { b.validate("bake"); }, "sun direction");
  }
}

TEST_F(BakeFile, RoundTripsExactlyWithVdbConventions) {
  BakedLight b = smallBake();
  BakeChannel& ld = b.add(bake_grids::kLightDir, 3);
  const std::vector<uint8_t> support = densitySupport(b.grid, b.density);  // what is stored
  for (size_t v = 0; v < support.size(); ++v) ld.data[3 * v + 2] = support[v] ? 1.f : 0.f;
  const std::string file = path("bake.vdb");
  writeBakedLight(file, b);
  EXPECT_FALSE(fs::exists(file + ".tmp"));
  const BakedLight r = readBakedLight(file);
  EXPECT_EQ(r.method, "single");
  EXPECT_NEAR(length(r.sun_direction - b.sun_direction), 0, 1e-15);
  EXPECT_EQ(r.grid.nx, 10);
  EXPECT_NEAR(r.grid.voxel_size, 0.25, 1e-12);
  EXPECT_NEAR(length(r.grid.origin - b.grid.origin), 0, 1e-12);
  EXPECT_EQ(r.density, b.density);
  ASSERT_EQ(r.channels.size(), b.channels.size());
  for (const auto& [name, c] : b.channels) {
    ASSERT_NE(r.find(name), nullptr) << name;
    EXPECT_EQ(r.find(name)->components, c.components) << name;
    EXPECT_EQ(r.find(name)->data, c.data) << name;
  }
  EXPECT_EQ(r.metadata.at("cloudbake:light_resolution"), "8");

  // What other tools see: a fog-volume density, invariant colours, a direction that transforms,
  // one transform whose voxel
  // centres are the lattice's, and the provenance metadata.
  VdbFileReader vdb(file);
  EXPECT_EQ(vdb.fileMetadata().at("cloudbake:method"), "single");
  EXPECT_EQ(vdb.fileMetadata().at("cloudbake:lattice"), "10 10 10");
  EXPECT_EQ(vdb.fileMetadata().at("cloudbake:version"), CLOUDBAKE_VERSION);
  EXPECT_TRUE(vdb.fileMetadata().count("cloudbake:sun_direction"));
  int directions = 0;
  for (const VdbGridInfo& g : vdb.grids()) {
    directions += g.name == "light_dir";
    if (g.name == "density") {
      EXPECT_EQ(g.grid_class, "fog volume");
    }
    if (g.name == "Co") {
      EXPECT_EQ(g.vector_type, "invariant");
    }
    if (g.name == "light_dir") {
      // A direction: a DCC rotates it with the volume (a colour it would leave alone).
      EXPECT_EQ(g.vector_type, "contravariant relative");
    }
    EXPECT_NEAR(g.voxel_size, 0.25, 1e-12) << g.name;
  }
  EXPECT_EQ(directions, 1);
  const Vec3 c = b.grid.center(5, 4, 6);
  EXPECT_FLOAT_EQ(vdb.floatAt("density", c), b.density[b.grid.index(5, 4, 6)]);
  EXPECT_FLOAT_EQ(float(vdb.vec3At("Co", c).z), b.find("Co")->data[3 * b.grid.index(5, 4, 6) + 2]);
}

// Method photon's tallies on a coarser lattice of their own: they keep every value (no trim to
// the density's support), a file stores them on their own transform and reads back the same,
// and a size that does not match their lattice is refused naming the grid.
TEST_F(BakeFile, TallyLatticeRoundTrips) {
  BakedLight b = smallBake();
  b.tally_grid.origin = Vec3(-0.875, 0.625, 2.125);
  b.tally_grid.voxel_size = 0.5;
  b.tally_grid.nx = b.tally_grid.ny = b.tally_grid.nz = 5;
  BakeChannel& sh = b.addOnTallyGrid("ms_sh_0", 3);
  ASSERT_EQ(sh.data.size(), size_t(5 * 5 * 5 * 3));
  for (size_t i = 0; i < sh.data.size(); ++i) sh.data[i] = i % 7 == 0 ? 0.f : float(i) * 0.01f;
  b.trimToSupport();
  EXPECT_FLOAT_EQ(b.find("ms_sh_0")->data[3], 0.03f) << "a tally is not trimmed";
  EXPECT_NO_THROW(b.validate("bake"));
  const std::string file = path("tally.vdb");
  writeBakedLight(file, b);
  const BakedLight r = readBakedLight(file);
  const BakeChannel* t = r.find("ms_sh_0");
  ASSERT_NE(t, nullptr);
  EXPECT_TRUE(t->on_tally_grid);
  EXPECT_EQ(t->data, sh.data);
  EXPECT_EQ(r.tally_grid.nx, 5);
  EXPECT_NEAR(r.tally_grid.voxel_size, 0.5, 1e-12);
  EXPECT_NEAR(length(r.tally_grid.origin - b.tally_grid.origin), 0, 1e-12);
  EXPECT_FALSE(r.find(bake_grids::kSunTransmittance)->on_tally_grid);
  EXPECT_EQ(r.find(bake_grids::kSunTransmittance)->data,
            b.find(bake_grids::kSunTransmittance)->data);
  VdbFileReader vdb(file);
  EXPECT_EQ(vdb.fileMetadata().at("cloudbake:tally_lattice"), "5 5 5");

  BakedLight bad = b;
  bad.channels["ms_sh_0"].data.resize(10);
  expectErrorNaming([&] { bad.validate("bake"); }, "grid 'ms_sh_0'");
  BakedLight lost = b;
  lost.tally_grid.nx = 0;
  expectErrorNaming([&] { lost.validate("bake"); }, "tally lattice");
}

TEST_F(BakeFile, BadFilesAreRefusedNamingThePath) {
  const std::string missing = path("missing.vdb");
  expectErrorNaming([&] { readBakedLight(missing); }, missing);

  const std::string good = path("good.vdb");
  writeBakedLight(good, smallBake());
  std::string bytes;
  {
    std::ifstream in(good, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  const std::string cut = path("cut.vdb");
  std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  expectErrorNaming([&] { readBakedLight(cut); }, cut);

  const std::string junk = path("junk.vdb");
  std::ofstream(junk, std::ios::binary) << "this is not an OpenVDB file at all";
  expectErrorNaming([&] { readBakedLight(junk); }, junk);

  // A valid VDB that is not a bake (a density written by writeVdb).
  const std::string plain = path("plain.vdb");
  VdbWriteOptions o;
  o.voxel_size = 0.25;
  writeVdb(plain, BoxDensity(Vec3(0.0), Vec3(1.0), 1.0), o);
  expectErrorNaming([&] { readBakedLight(plain); }, "not a cloudbake bake");

  // writeBakedLight does not validate; reading does.
  BakedLight nan = smallBake();
  nan.channels[bake_grids::kSunTransmittance].data[nan.grid.index(4, 4, 4)] = std::nanf("");
  const std::string with_nan = path("nan.vdb");
  writeBakedLight(with_nan, nan);
  expectErrorNaming([&] { readBakedLight(with_nan); }, "grid 'sun_transmittance'");
}

}  // namespace
}  // namespace cloudbake
