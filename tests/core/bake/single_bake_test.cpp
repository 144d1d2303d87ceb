// Method single's pieces: the lattice, the sun transmittance grid, the sky visibility sweeps, and
// bakeSingle as a whole (determinism, extremes, cancellation, bad input).
#include "core/bake/single_bake.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "core/bake/bake_lattice.h"
#include "core/bake/sky_visibility.h"
#include "core/bake/sun_transmittance.h"
#include "core/error.h"
#include "core/phase/henyey_greenstein.h"
#include "core/volume/analytic.h"
#include "tests/core/bake/bake_test_util.h"

namespace cloudbake {
namespace {

Medium boxMedium(double extinction, const Vec3& lo = Vec3(0.0), const Vec3& hi = Vec3(1.0)) {
  Medium m;
  m.density = std::make_shared<BoxDensity>(lo, hi, 1.0);
  m.extinction = extinction;
  m.phase = std::make_shared<HenyeyGreensteinPhase>(0.5);
  return m;
}

TEST(BakeLattice, KeepsTheMassAndAnEmptyMargin) {
  const SphereDensity sphere(Vec3(1, 2, 3), 0.8, 2.0);
  const BakedLight b = makeBakeLattice(sphere, 40);
  const BakeGrid& g = b.grid;
  EXPECT_EQ(g.nx, 42);  // 40 voxels over the diameter plus one of margin per face
  EXPECT_NEAR(g.voxel_size, 1.6 / 40, 1e-12);
  double mass = 0;
  for (int k = 0; k < g.nz; ++k)
    for (int j = 0; j < g.ny; ++j)
      for (int i = 0; i < g.nx; ++i) {
        const float d = b.density[g.index(i, j, k)];
        mass += d;
        const bool margin =
            i == 0 || j == 0 || k == 0 || i == g.nx - 1 || j == g.ny - 1 || k == g.nz - 1;
        if (margin) {
          EXPECT_EQ(d, 0.f);
        }
      }
  mass *= std::pow(g.voxel_size, 3);
  // Voxel means from 2^3..4^3 samples: the sphere's surface voxels are partly covered.
  EXPECT_NEAR(mass / (2.0 * 4.0 / 3.0 * kPi * 0.8 * 0.8 * 0.8), 1.0, 0.02);
  expectErrorNaming([&] { makeBakeLattice(sphere, 7); }, "light_resolution");
  expectErrorNaming([&] { makeBakeLattice(sphere, 1025); }, "light_resolution");
  // A flat box asks for few voxels in z, a long one is refused when the lattice is too big.
  EXPECT_NO_THROW(makeBakeLattice(BoxDensity(Vec3(0.0), Vec3(1, 1, 0.01), 1), 64));
}

TEST(SunTransmittance, MatchesBeerLambertInsideABox) {
  const double ext = 2.0;
  const Medium m = boxMedium(ext);
  for (const Vec3& sun : {Vec3(0, 0, 1), Vec3(1, 0, 0), normalize(Vec3(1, 1, 2))}) {
    BakedLight b = makeBakeLattice(*m.density, 32);
    computeSunTransmittance(b, sun, ext);
    const auto& t = b.find(bake_grids::kSunTransmittance)->data;
    const BakeGrid& g = b.grid;
    for (int k = 4; k < g.nz - 4; k += 5)
      for (int j = 4; j < g.ny - 4; j += 5)
        for (int i = 4; i < g.nx - 4; i += 5) {
          const Vec3 p = g.center(i, j, k);
          // Distance to the box face along the sun direction.
          double s = 1e300;
          for (int a = 0; a < 3; ++a) {
            if (sun[a] > 0) s = std::min(s, (1 - p[a]) / sun[a]);
          }
          // The lattice's density falls linearly from the last voxel centre inside the face to
          // the empty margin's (trilinear): the same optical depth as the true step along an
          // axis, but near edges, where two faces fade together, an oblique path can gain or
          // lose up to about half a voxel's optical depth.
          const double exact = std::exp(-ext * s);
          const double slack = ext * 0.5 * g.voxel_size / std::max(1e-3, maxComponent(sun));
          const double got = t[g.index(i, j, k)];
          EXPECT_LE(got, exact * std::exp(slack)) << p.x << " " << p.y << " " << p.z;
          EXPECT_GE(got, exact * std::exp(-slack)) << p.x << " " << p.y << " " << p.z;
          if (sun == Vec3(0, 0, 1) || sun == Vec3(1, 0, 0)) {
            EXPECT_NEAR(got / exact, 1.0, 2e-3);  // along an axis: exact up to floats
          }
        }
  }
}

// The sweep's half-voxel trapezoid (steps shared by every voxel) is within the trapezoid's own
// error of a march 32x finer, no worse than a march per voxel at the same step, on an uneven
// lattice (every cell a different trilinear patch), for suns along and between the axes, on the
// density's support and the voxel beyond it (sunTransmittanceSupport, which views read); voxels
// off that stay 0, and a clear medium reads 1 on it.
TEST(SunTransmittance, ConvergesToAFineMarchOnAnUnevenLattice) {
  BakedLight b = emptyBake(Vec3(-1.0, 0.5, 2.0), 0.1, 23, 17, 29);
  const BakeGrid& g = b.grid;
  uint32_t state = 12345;
  for (int k = 2; k < g.nz - 2; ++k)  // two empty voxels on every face, the rest uneven
    for (int j = 2; j < g.ny - 2; ++j)
      for (int i = 2; i < g.nx - 2; ++i) {
        state = state * 1664525u + 1013904223u;
        b.density[g.index(i, j, k)] = float(state >> 8) / float(1 << 24) * 2.f;
      }
  const double ext = 3.0;
  for (const Vec3& sun : {Vec3(0, 0, 1), Vec3(-1, 0, 0), normalize(Vec3(1, -2, 3)),
                          normalize(Vec3(-0.3, 0.2, -1)), normalize(Vec3(1, 1, 1e-9))}) {
    SCOPED_TRACE(::testing::Message() << sun.x << " " << sun.y << " " << sun.z);
    computeSunTransmittance(b, sun, ext);
    const auto& t = b.find(bake_grids::kSunTransmittance)->data;
    const std::vector<uint8_t> support = sunTransmittanceSupport(g, densitySupport(g, b.density));
    double err = 0, err_per_voxel = 0;
    int checked = 0;
    for (int k = 0; k < g.nz; ++k)
      for (int j = 0; j < g.ny; ++j)
        for (int i = 0; i < g.nx; ++i) {
          const size_t v = g.index(i, j, k);
          if (!support[v]) {
            EXPECT_EQ(t[v], 0.f);
            continue;
          }
          const Vec3 p = g.center(i, j, k);
          const double fine =
              marchTransmittance(g, b.density.data(), ext, p, sun, g.voxel_size / 64);
          const double coarse =
              marchTransmittance(g, b.density.data(), ext, p, sun, g.voxel_size / 2);
          ASSERT_GE(t[v], 0.f);
          ASSERT_LE(t[v], 1.f);
          err = std::max(err, std::abs(t[v] - fine));
          err_per_voxel = std::max(err_per_voxel, std::abs(coarse - fine));
          ++checked;
        }
    EXPECT_GT(checked, 5000);
    EXPECT_LT(err, 0.02);
    EXPECT_LE(err, 1.5 * err_per_voxel + 1e-6) << err << " vs " << err_per_voxel;
  }
  computeSunTransmittance(b, Vec3(0, 1, 0), 0.0);
  const auto& clear = b.find(bake_grids::kSunTransmittance)->data;
  EXPECT_EQ(clear[g.index(10, 10, 10)], 1.f);
  // Two voxels from the density: off its support, on the sun's (views read it there).
  EXPECT_EQ(clear[g.index(10, 10, g.nz - 1)], 1.f);
  // A voxel on the lattice's face (never so in a bake, whose outermost voxels are empty): the
  // integral of the trilinear density to where it reaches 0, half a voxel past the face.
  b.density.assign(g.voxelCount(), 0.f);
  b.density[g.index(0, 5, 5)] = 1.f;
  computeSunTransmittance(b, Vec3(-1, 0, 0), ext);
  EXPECT_NEAR(b.find(bake_grids::kSunTransmittance)->data[g.index(0, 5, 5)],
              std::exp(-ext * 0.5 * g.voxel_size), 1e-6);
}

TEST(SkyVisibility, WeightsAreSolidAnglesAndACentreSeesExpOfTau) {
  const LatticeDirection* dirs = latticeDirections();
  double sum = 0, axis = 0, body = 0;
  for (int d = 0; d < 26; ++d) {
    sum += dirs[d].weight;
    const int n = std::abs(dirs[d].dx) + std::abs(dirs[d].dy) + std::abs(dirs[d].dz);
    if (n == 1) axis = dirs[d].weight;
    if (n == 3) body = dirs[d].weight;
  }
  EXPECT_NEAR(sum, 1.0, 1e-12);
  // An independent estimate of the axis cell: directions closer to +z than to any other lattice
  // direction, by a fine latitude-longitude quadrature.
  double cell = 0;
  const int nt = 600, np = 1200;
  for (int it = 0; it < nt; ++it) {
    const double th = (it + 0.5) * kPi / nt;
    for (int ip = 0; ip < np; ++ip) {
      const double ph = (ip + 0.5) * 2 * kPi / np;
      const Vec3 w(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th));
      double best = -2;
      int best_d = -1;
      for (int d = 0; d < 26; ++d) {
        const double c = dot(w, normalize(Vec3(dirs[d].dx, dirs[d].dy, dirs[d].dz)));
        if (c > best) {
          best = c;
          best_d = d;
        }
      }
      if (dirs[best_d].dx == 0 && dirs[best_d].dy == 0 && dirs[best_d].dz == 1) {
        cell += std::sin(th) * (kPi / nt) * (2 * kPi / np);
      }
    }
  }
  EXPECT_NEAR(axis, cell / (4 * kPi), 2e-4);
  EXPECT_GT(axis, body);

  // A homogeneous cube seen from its centre: every lattice direction crosses the same optical
  // depth to the nearest face only along the axes; the visibility is the weighted mean of
  // exp(-tau |e| / 2), which the sweeps reproduce up to the trilinear fade at the faces.
  const double ext = 3.0;
  const Medium m = boxMedium(ext, Vec3(-0.5), Vec3(0.5));
  BakedLight b = makeBakeLattice(*m.density, 41);  // odd: a voxel centre at the origin
  computeSkyVisibility(b, ext);
  const BakeGrid& g = b.grid;
  const int c = g.nx / 2;
  double expected = 0;
  for (int d = 0; d < 26; ++d) {
    const Vec3 e(dirs[d].dx, dirs[d].dy, dirs[d].dz);
    const double path = 0.5 * length(e);  // to the face: each nonzero component reaches 0.5
    expected += dirs[d].weight * std::exp(-ext * path);
  }
  const double got = b.find(bake_grids::kSkyVisibility)->data[g.index(c, c, c)];
  EXPECT_NEAR(got / expected, 1.0, 0.06) << got << " vs " << expected;
}

// Two extinctions in one sweep give each what a sweep of its own gives, bit for bit; the
// thicker medium sees less sky everywhere.
TEST(SkyVisibility, TwoExtinctionsInOneSweepEqualTwoSweeps) {
  const Medium m = boxMedium(1.0, Vec3(-0.5, -0.4, -0.3), Vec3(0.5, 0.4, 0.3));
  BakedLight thin = makeBakeLattice(*m.density, 24);
  BakedLight thick = thin;
  computeSkyVisibility(thin, 2.0);
  computeSkyVisibility(thick, 7.0);
  const std::vector<FirstTouchFloats> both =
      skyVisibilities(thin.grid, thin.density.data(), {2.0, 7.0});
  ASSERT_EQ(both.size(), 2u);
  const auto& a = thin.find(bake_grids::kSkyVisibility)->data;
  const auto& b = thick.find(bake_grids::kSkyVisibility)->data;
  ASSERT_EQ(both[0].size(), a.size());
  ASSERT_EQ(both[1].size(), b.size());
  EXPECT_EQ(std::memcmp(both[0].data(), a.data(), a.size() * sizeof(float)), 0);
  EXPECT_EQ(std::memcmp(both[1].data(), b.data(), b.size() * sizeof(float)), 0);
  int darker = 0;
  for (size_t v = 0; v < a.size(); ++v) {
    ASSERT_LE(b[v], a[v]) << v;
    darker += b[v] < a[v];
  }
  EXPECT_GT(darker, 100);
  EXPECT_THROW(skyVisibilities(thin.grid, thin.density.data(), {}), InternalError);
  EXPECT_THROW(skyVisibilities(thin.grid, thin.density.data(), {1.0, 2.0, 3.0}), InternalError);
}

// The visibility's first moment: 0 in empty space (the weights' directions cancel), pointing
// up out of a dense lower half, and no longer than the visibility anywhere (|B| <= V for any
// transmittance in [0, 1]).
TEST(SkyVisibility, TheVectorPointsToTheOpenSky) {
  const double ext = 200.0;
  const Medium m = boxMedium(ext, Vec3(-1, -1, -1), Vec3(1, 1, 0));
  BakedLight b = makeBakeLattice(*m.density, 33);
  computeSkyVisibility(b, ext, {}, true);
  const BakeChannel* vec = b.find(bake_grids::kSkyVisibilityVector);
  ASSERT_NE(vec, nullptr);
  ASSERT_EQ(vec->components, 3);
  EXPECT_NO_THROW(b.validate("bake"));
  const auto& vis = b.find(bake_grids::kSkyVisibility)->data;
  const BakeGrid& g = b.grid;
  for (size_t v = 0; v < g.voxelCount(); ++v) {
    const Vec3 bv(vec->data[3 * v], vec->data[3 * v + 1], vec->data[3 * v + 2]);
    ASSERT_LE(length(bv), vis[v] + 1e-5) << v;
  }
  // The first voxel above the box's top face (z = 0), mid-lattice: the opaque box hides the
  // lower directions, so B points up. Of the 26 directions the 9 upward ones give
  // B_z = 0.23 (the continuous half-space's 1/4) and V = 0.33, and the 8 level ones, which
  // graze the face, add up to 0.34 to V.
  const int c = g.nx / 2;
  int k = 0;
  while (k < g.nz && !(g.center(c, c, k).z > 0)) ++k;
  ASSERT_LT(k, g.nz);
  const size_t v = g.index(c, c, k);
  EXPECT_GT(vis[v], 0.3);
  EXPECT_LT(vis[v], 0.7);
  EXPECT_NEAR(vec->data[3 * v + 2], 0.23, 0.03);
  EXPECT_NEAR(vec->data[3 * v], 0.0, 0.02);
  EXPECT_NEAR(vec->data[3 * v + 1], 0.0, 0.02);
  // No medium: every voxel sees the whole sky, V = 1 and B = 0.
  BakedLight empty = b;
  std::fill(empty.density.begin(), empty.density.end(), 0.f);
  computeSkyVisibility(empty, ext, {}, true);
  const auto& ev = empty.find(bake_grids::kSkyVisibilityVector)->data;
  for (float x : ev) ASSERT_NEAR(x, 0.f, 1e-6);
  // Without the vector, the visibility is the same, bit for bit.
  BakedLight plain = makeBakeLattice(*m.density, 33);
  computeSkyVisibility(plain, ext);
  EXPECT_EQ(plain.find(bake_grids::kSkyVisibilityVector), nullptr);
  EXPECT_EQ(plain.find(bake_grids::kSkyVisibility)->data, vis);
}

TEST(BakeSingle, IsDeterministicAcrossThreadCounts) {
  Medium m;
  m.density = std::make_shared<SphereDensity>(Vec3(0.0), 1.0, 1.0);
  m.extinction = 4;
  m.phase = std::make_shared<HenyeyGreensteinPhase>(0.7);
  SingleBakeOptions o;
  o.light_resolution = 32;
  const Vec3 sun = normalize(Vec3(0.3, -0.2, 1));
  BakedLight one, two;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = bakeSingle(m, sun, o);
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    two = bakeSingle(m, sun, o);
  }
  EXPECT_EQ(one.density, two.density);
  for (const auto& [name, ch] : one.channels) {
    ASSERT_NE(two.find(name), nullptr);
    EXPECT_EQ(ch.data, two.find(name)->data) << name;
  }
  EXPECT_EQ(one.method, "single");
  EXPECT_NO_THROW(one.validate("bake"));
  for (const char* g : {"sun_transmittance", "sky_visibility", "sky_visibility_vector", "Cd"}) {
    EXPECT_NE(one.find(g), nullptr) << g;
  }
  o.sky = false;
  const BakedLight no_sky = bakeSingle(m, sun, o);
  EXPECT_EQ(no_sky.find("sky_visibility"), nullptr);
  EXPECT_EQ(no_sky.find("sky_visibility_vector"), nullptr);
}

TEST(BakeSingle, ExtremesStayFiniteAndInRange) {
  SingleBakeOptions o;
  o.light_resolution = 16;
  struct Case {
    double ext;
    Vec3 sun;
  };
  for (const Case& c : {Case{0, Vec3(0, 0, 1)}, Case{1e6, Vec3(0, 0, 1)}, Case{1, Vec3(0, 1, 0)},
                        Case{1e-6, normalize(Vec3(1, 1, 1))}}) {
    const Medium m = boxMedium(c.ext);
    const BakedLight b = bakeSingle(m, c.sun, o);
    EXPECT_NO_THROW(b.validate("bake"));
    const auto& t = b.find("sun_transmittance")->data;
    const int mid = b.grid.nx / 2;
    const float centre = t[b.grid.index(mid, mid, mid)];
    if (c.ext == 0) {
      EXPECT_EQ(centre, 1.f);
    }
    if (c.ext == 1e6) {
      EXPECT_EQ(centre, 0.f);
    }
  }
  // A volume far smaller than the lattice's voxel would be at its own default: still one voxel.
  const Medium tiny = boxMedium(1, Vec3(0.0), Vec3(1e-4));
  EXPECT_NO_THROW(bakeSingle(tiny, Vec3(0, 0, 1), o).validate("bake"));
}

TEST(BakeSingle, CancelsAndNamesBadInput) {
  const Medium m = boxMedium(1);
  SingleBakeOptions o;
  o.light_resolution = 16;
  EXPECT_THROW(bakeSingle(m, Vec3(0, 0, 1), o, [](double, const std::string&) { return false; }),
               Cancelled);
  Medium none = m;
  none.density = nullptr;
  expectErrorNaming([&] { bakeSingle(none, Vec3(0, 0, 1), o); }, "density");
  Medium nan = m;
  nan.extinction = std::nan("");
  expectErrorNaming([&] { bakeSingle(nan, Vec3(0, 0, 1), o); }, "extinction");
  expectErrorNaming([&] { bakeSingle(m, Vec3(0, 0, 2), o); }, "direction");
  o.step = -1;
  expectErrorNaming([&] { bakeSingle(m, Vec3(0, 0, 1), o); }, "step");
}

}  // namespace
}  // namespace cloudbake
