// SHEXP against the transmittance projected directly from per-direction optical depths.
#include "core/animation/shexp.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <vector>

#include "core/animation/optical_depth_sh.h"
#include "core/bake/bake_lattice.h"
#include "core/error.h"
#include "core/math/vector_exp.h"
#include "core/volume/sources.h"

namespace cloudbake {
namespace {

double norm(const ShCoefficients& c) {
  double s = 0;
  for (float v : c) s += double(v) * v;
  return std::sqrt(s);
}

TEST(ShProduct, ProjectsTheProductOfTwoFunctions) {
  // Two order-2 functions: their product has degree 4, so compare on a direction set rather
  // than coefficient by coefficient; the truncation to order 4 drops only the l = 4 part.
  ShCoefficients a{}, b{};
  a[0] = 1.0f;
  a[2] = 0.5f;
  a[5] = -0.2f;
  b[0] = 0.3f;
  b[3] = 0.7f;
  const ShCoefficients p = shProduct(a, b);
  // Degree 1 x degree 0 terms are exact: a constant times anything.
  ShCoefficients c{};
  c[0] = float(std::sqrt(4 * kPi));  // the constant function 1
  const ShCoefficients same = shProduct(c, a);
  for (int i = 0; i < kShCoefficients; ++i) EXPECT_NEAR(same[size_t(i)], a[size_t(i)], 1e-4) << i;
  // The projection of the product, by direct quadrature.
  std::array<double, kShCoefficients> direct{};
  const std::vector<Vec3> w = sphereDirections(20000);
  for (const Vec3& d : w) {
    const auto y = shBasis(d);
    const double f = shEvaluate(a, d) * shEvaluate(b, d) * 4 * kPi / double(w.size());
    for (int i = 0; i < kShCoefficients; ++i) direct[size_t(i)] += f * y[size_t(i)];
  }
  for (int i = 0; i < kShCoefficients; ++i) EXPECT_NEAR(p[size_t(i)], direct[size_t(i)], 2e-3) << i;
}

// A small fitting set: a constant optical depth growing with a z gradient.
std::vector<ShCoefficients> gradientSamples() {
  std::vector<ShCoefficients> samples;
  for (int i = 0; i < 16; ++i) {
    ShCoefficients g{};
    g[0] = float(-0.3 * i);
    g[2] = float(0.05 * i);
    samples.push_back(g);
  }
  return samples;
}

TEST(ShExp, ExactForConstantsAndCloseToTheReference) {
  // exp of a constant function is a constant: exactly, whatever the tables.
  const std::vector<ShCoefficients> samples = gradientSamples();
  const ShExp e = ShExp::fit(samples, 8);
  ShCoefficients c{};
  c[0] = -2.0f;
  const ShCoefficients out = e(c);
  EXPECT_NEAR(out[0], std::exp(-2.0 / std::sqrt(4 * kPi)) * std::sqrt(4 * kPi), 1e-5);
  EXPECT_THROW(ShExp::fit(std::vector<ShCoefficients>(3), 8), InputError);
  EXPECT_THROW(ShExp::fit(samples, 2), InputError);
}

// Optically thick voxels (|g^| far beyond the tables) are projected directly: every direction's
// transmittance within [0, 1], so the DC term (4 pi x the mean transmittance / sqrt(4 pi)) is
// within [0, sqrt(4 pi)] and the function stays near [0, 1] everywhere. Scaling and squaring
// with truncated SH products gave 1e18 at optical depths of 1000.
TEST(ShExp, StaysATransmittanceInOpticallyThickVoxels) {
  const ShExp e = ShExp::fit(gradientSamples(), 8);
  for (const double depth : {30.0, 300.0, 1e3, 1e6}) {
    ShCoefficients g{};  // -tau(w) = -depth (1 + 0.9 cos theta): thin towards -z, thick towards +z
    g[0] = float(-depth * std::sqrt(4 * kPi));
    g[2] = float(-0.9 * depth * std::sqrt(4 * kPi / 3));
    const ShCoefficients t = e(g);
    for (float v : t) ASSERT_TRUE(std::isfinite(v)) << depth;
    EXPECT_GE(t[0], 0.f) << depth;
    EXPECT_LE(t[0], float(std::sqrt(4 * kPi)) + 1e-5f) << depth;
    for (const Vec3& w : sphereDirections(64)) {
      const double v = shEvaluate(t, w);
      EXPECT_GT(v, -0.3) << depth;
      EXPECT_LT(v, 1.3) << depth;
    }
  }
}

// The blocked quadrature is the plain direction-at-a-time sum with the same order of every
// addition: equal bit for bit, for direction counts that are and are not whole blocks.
TEST(ShExpReference, EqualsTheDirectionAtATimeSumBitForBit) {
  uint32_t state = 12345u;
  const auto uniform = [&state] {
    state = state * 1664525u + 1013904223u;
    return double(state >> 8) / double(1u << 24);
  };
  for (const int dirs : {64, 100, 256}) {
    std::vector<std::array<double, kShCoefficients>> basis;
    for (const Vec3& w : sphereDirections(dirs)) basis.push_back(shBasis(w));
    for (int trial = 0; trial < 20; ++trial) {
      ShCoefficients g{};
      const double depth = trial < 10 ? 2.0 : 900.0;  // the latter underflows in some directions
      for (float& v : g) v = float(-depth * uniform());
      std::array<double, kShCoefficients> acc{};
      for (const auto& y : basis) {
        double f = 0;
        for (int i = 0; i < kShCoefficients; ++i) f += double(g[size_t(i)]) * y[size_t(i)];
        const double e = vectorExp(f);
        for (int i = 0; i < kShCoefficients; ++i) acc[size_t(i)] += e * y[size_t(i)];
      }
      const ShCoefficients got = shExpReference(g, dirs);
      for (int i = 0; i < kShCoefficients; ++i) {
        const float want = float(acc[size_t(i)] * 4 * kPi / double(dirs));
        ASSERT_EQ(std::memcmp(&want, &got[size_t(i)], sizeof(float)), 0)
            << dirs << " directions, trial " << trial << ", coefficient " << i << ": " << want
            << " vs " << got[size_t(i)];
      }
    }
  }
}

// The frames' path: ShExp beyond its tables (|g^| > 1) projects exp(min(0, g(w))) with the same
// blocked quadrature at 256 directions; equal bit for bit to the plain loop with the clamp, over
// optical depths where g(w) rings positive in some directions and underflows in others.
TEST(ShExp, ThickVoxelsAreThePlainClampedQuadratureBitForBit) {
  uint32_t state = 54321u;
  const auto uniform = [&state] {
    state = state * 1664525u + 1013904223u;
    return double(state >> 8) / double(1u << 24);
  };
  std::vector<ShCoefficients> fit_samples;
  for (int i = 0; i < 64; ++i) {
    ShCoefficients g{};
    for (float& v : g) v = float(-0.2 * uniform());
    fit_samples.push_back(g);
  }
  const ShExp shexp = ShExp::fit(fit_samples);
  std::vector<std::array<double, kShCoefficients>> basis;
  for (const Vec3& w : sphereDirections(256)) basis.push_back(shBasis(w));
  for (int trial = 0; trial < 400; ++trial) {
    const double depth = trial % 4 == 3 ? 1200.0 : 2 + 60 * uniform();
    ShCoefficients g{};
    g[0] = float(-depth * std::sqrt(4 * kPi) * (0.5 + 0.5 * uniform()));
    for (int i = 1; i < kShCoefficients; ++i) g[size_t(i)] = float(depth * (uniform() - 0.5));
    std::array<double, kShCoefficients> acc{};
    for (const auto& y : basis) {
      double f = 0;
      for (int i = 0; i < kShCoefficients; ++i) f += double(g[size_t(i)]) * y[size_t(i)];
      const double e = vectorExp(std::min(0.0, f));
      for (int i = 0; i < kShCoefficients; ++i) acc[size_t(i)] += e * y[size_t(i)];
    }
    const ShCoefficients got = shexp(g);
    for (int i = 0; i < kShCoefficients; ++i) {
      const float want = float(acc[size_t(i)] * 4 * kPi / 256.0);
      ASSERT_EQ(std::memcmp(&want, &got[size_t(i)], sizeof(float)), 0)
          << "trial " << trial << ", coefficient " << i << ": " << want << " vs " << got[size_t(i)];
    }
  }
}

TEST(ShExp, MatchesDirectlyProjectedTransmittanceInACloud) {
  PerlinCloudOptions o;
  o.resolution = 32;
  o.cover = 0.4;
  const BakedLight lattice = makeBakeLattice(*makePerlinCloud(o), 24);
  const BakeGrid& g = lattice.grid;
  const double ext = 6.0;
  const int dirs = 64;
  const std::vector<ShCoefficients> tau = projectOpticalDepth(g, lattice.density, ext, dirs);
  // Directly projected transmittance, per voxel: exp(-tau(w)) on the same sweeps, projected.
  const std::vector<Vec3> w = sphereDirections(dirs);
  std::vector<std::vector<float>> per_dir;
  for (const Vec3& d : w) per_dir.push_back(sweepOpticalDepth(g, lattice.density, ext, d));
  std::vector<size_t> voxels;
  for (size_t v = 0; v < g.voxelCount(); ++v) {
    if (lattice.density[v] > 0) voxels.push_back(v);
  }
  ASSERT_GT(voxels.size(), 200u);
  std::vector<ShCoefficients> fit_set;
  for (size_t i = 0; i < voxels.size(); i += 2) {
    ShCoefficients m = tau[voxels[i]];
    for (float& x : m) x = -x;
    fit_set.push_back(m);
  }
  const ShExp shexp = ShExp::fit(fit_set);
  double err = 0, err_dc = 0, err_fit = 0;
  int n = 0;
  for (size_t i = 1; i < voxels.size(); i += 2) {  // voxels not used by the fit
    const size_t v = voxels[i];
    std::array<double, kShCoefficients> direct{};
    for (size_t d = 0; d < w.size(); ++d) {
      const auto y = shBasis(w[d]);
      const double t = std::exp(-double(per_dir[d][v])) * 4 * kPi / double(w.size());
      for (int k = 0; k < kShCoefficients; ++k) direct[size_t(k)] += t * y[size_t(k)];
    }
    ShCoefficients ref{}, minus = tau[v];
    for (int k = 0; k < kShCoefficients; ++k) ref[size_t(k)] = float(direct[size_t(k)]);
    for (float& x : minus) x = -x;
    const ShCoefficients got = shexp(minus);
    ShCoefficients diff{}, dc_only{};
    dc_only[0] = float(std::exp(minus[0] / std::sqrt(4 * kPi)) * std::sqrt(4 * kPi));
    ShCoefficients diff_dc{};
    for (int k = 0; k < kShCoefficients; ++k) {
      diff[size_t(k)] = got[size_t(k)] - ref[size_t(k)];
      diff_dc[size_t(k)] = dc_only[size_t(k)] - ref[size_t(k)];
    }
    err += norm(diff) / norm(ref);
    err_dc += norm(diff_dc) / norm(ref);
    // SHEXP's own error: against exp of its input's (order-4) function, projected.
    const ShCoefficients own = shExpReference(minus);
    ShCoefficients diff_fit{};
    for (int k = 0; k < kShCoefficients; ++k) diff_fit[size_t(k)] = got[size_t(k)] - own[size_t(k)];
    err_fit += norm(diff_fit) / norm(own);
    ++n;
  }
  err /= n;
  err_dc /= n;
  err_fit /= n;
  std::printf(
      "[ shexp ] mean relative L2 error against directly projected transmittance: %.4f "
      "(exp of the constant term alone: %.4f); against exp of the order-4 optical depth "
      "it approximates: %.4f; %d voxels\n",
      err, err_dc, err_fit, n);
  EXPECT_LT(err_fit, 0.15);
  EXPECT_LT(err, 0.15);
  EXPECT_LT(err, 0.25 * err_dc);
}

}  // namespace
}  // namespace cloudbake
