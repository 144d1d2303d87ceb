// Chi-square goodness-of-fit of the transport samplers against their own pdf(): sample() must
// produce exactly the density pdf() reports, or every estimator dividing by that pdf is biased.
// Each positive test has a negative control showing the same test, at the same sample count,
// rejects a slightly wrong density, so a passing positive test is known to mean something.

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <iostream>
#include <string>
#include <vector>

#include "core/io/exr_io.h"
#include "core/io/image.h"
#include "core/math/rng.h"
#include "core/math/vec3.h"
#include "core/transport/piecewise_constant.h"
#include "core/transport/scene.h"
#include "core/transport/sky.h"
#include "tests/chi_square_util.h"

namespace cloudbake {
namespace {

using testing_util::BinnedChiSquare;
using testing_util::chiSquareBinned;

constexpr uint64_t kSeed = 20240611;

// ---------------------------------------------------------------------------------------------
// PiecewiseConstant2D

constexpr int kTableNu = 7, kTableNv = 5;
// Bin counts deliberately share no factor with the table size, so bins straddle cell edges and
// the placement of samples inside a cell is tested, not only the choice of cell.
constexpr int kGridNu = 24, kGridNv = 18;
constexpr int kTableSamples = 1000000;

// Rows of very different mass, an all-zero row (the marginal must never pick it), an isolated
// peak between zeros and a row whose mass sits at both ends.
std::vector<double> testTable() {
  return {
      0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5,  // ramp
      0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,  // empty row
      0.0, 0.2, 0.0, 12., 0.0, 0.2, 0.0,  // peak
      1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0,  // flat
      5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.1,  // both ends
  };
}

int gridBin(double u, double v) {
  const int iu = std::clamp(static_cast<int>(u * kGridNu), 0, kGridNu - 1);
  const int iv = std::clamp(static_cast<int>(v * kGridNv), 0, kGridNv - 1);
  return iv * kGridNu + iu;
}

std::vector<double> tableObserved(const PiecewiseConstant2D& d, int n, uint64_t seed) {
  std::vector<double> observed(size_t(kGridNu) * kGridNv, 0.0);
  Rng rng(seed, 1);
  for (int i = 0; i < n; ++i) {
    const double u1 = rng.uniform(), u2 = rng.uniform();
    double u, v, pdf;
    d.sample(u1, u2, &u, &v, &pdf);
    observed[gridBin(u, v)] += 1.0;
  }
  return observed;
}

// The bin [lo, hi] split at the table's cell edges k / n_table: the pdf is constant on each piece,
// so the midpoint rule on the pieces is exact.
std::vector<double> pieceEdges(double lo, double hi, int n_table) {
  std::vector<double> e{lo, hi};
  for (int k = 1; k < n_table; ++k) {
    const double x = double(k) / n_table;
    if (x > lo && x < hi) e.push_back(x);
  }
  std::sort(e.begin(), e.end());
  return e;
}

// Expected counts from d.pdf() integrated exactly over each grid bin.
std::vector<double> tableExpected(const PiecewiseConstant2D& d, int n) {
  std::vector<double> expected(size_t(kGridNu) * kGridNv, 0.0);
  for (int iv = 0; iv < kGridNv; ++iv) {
    const auto ev = pieceEdges(double(iv) / kGridNv, double(iv + 1) / kGridNv, kTableNv);
    for (int iu = 0; iu < kGridNu; ++iu) {
      const auto eu = pieceEdges(double(iu) / kGridNu, double(iu + 1) / kGridNu, kTableNu);
      double prob = 0.0;
      for (size_t j = 0; j + 1 < ev.size(); ++j) {
        for (size_t i = 0; i + 1 < eu.size(); ++i) {
          const double area = (eu[i + 1] - eu[i]) * (ev[j + 1] - ev[j]);
          prob += area * d.pdf(0.5 * (eu[i] + eu[i + 1]), 0.5 * (ev[j] + ev[j + 1]));
        }
      }
      expected[size_t(iv) * kGridNu + iu] = prob * n;
    }
  }
  return expected;
}

void report(const char* what, const BinnedChiSquare& r) {
  std::cout << "[ chi2     ] " << what << ": " << r << "\n";
}

TEST(SamplerChiSquare, PiecewiseConstant2DMatchesItsPdf) {
  const std::vector<double> f = testTable();
  const PiecewiseConstant2D d(f, kTableNu, kTableNv);
  // pdf() is the table over its mean, so the expected counts below describe the table itself.
  for (int v = 0; v < kTableNv; ++v) {
    for (int u = 0; u < kTableNu; ++u) {
      ASSERT_NEAR(d.pdf((u + 0.5) / kTableNu, (v + 0.5) / kTableNv),
                  f[size_t(v) * kTableNu + u] / d.integral(), 1e-12)
          << "cell " << u << ", " << v;
    }
  }
  const std::vector<double> expected = tableExpected(d, kTableSamples);
  double total = 0.0;
  for (double e : expected) total += e;
  EXPECT_NEAR(total / kTableSamples, 1.0, 1e-12);

  const BinnedChiSquare r = chiSquareBinned(tableObserved(d, kTableSamples, kSeed), expected);
  report("PiecewiseConstant2D", r);
  EXPECT_EQ(r.stray, 0.0) << "samples in zero cells";
  EXPECT_GT(r.dof, 200);
  EXPECT_LE(r.chi2, r.critical) << r;
}

TEST(SamplerChiSquare, PiecewiseConstant2DRejectsAWrongPdf) {
  const std::vector<double> f = testTable();
  std::vector<double> g = f;
  g[size_t(3) * kTableNu + 2] *= 1.15;  // one flat cell, 2.6% of the mass, 15% heavier
  const PiecewiseConstant2D sampled(f, kTableNu, kTableNv), claimed(g, kTableNu, kTableNv);
  const BinnedChiSquare r = chiSquareBinned(tableObserved(sampled, kTableSamples, kSeed),
                                            tableExpected(claimed, kTableSamples));
  report("PiecewiseConstant2D vs perturbed table", r);
  EXPECT_EQ(r.stray, 0.0);
  EXPECT_GT(r.chi2, r.critical) << r;
}

// ---------------------------------------------------------------------------------------------
// SkyLight map sampling

constexpr int kMapW = 24, kMapH = 12;
// Equal-area bins: bands uniform in z = cos(theta) times sectors uniform in phi. Neither edge set
// lines up with the map's equal-angle pixel rows, and the sectors only partly with its columns.
constexpr int kBinsZ = 18, kBinsPhi = 40;
constexpr int kSkySamples = 1000000;
// Midpoint sub-samples per bin and axis for integrating pdf(w). Pixel edges cut through bins, where
// the rule is only first order: against a 512 reference, 64 left quadrature error worth ~22 in
// chi2 and 128 about 4, small next to the chi2 spread sqrt(2 dof) ~ 33.
constexpr int kSubSamples = 128;

// A small sun, a sky gradient down to a black band just below the horizon (zero-pdf bands must
// get no samples), and a ground with column structure. Row 0 touches the zenith, where the
// sin(theta) Jacobian matters most.
Image skyMap() {
  Image im(kMapW, kMapH, 3);
  for (int y = 0; y < kMapH; ++y) {
    for (int x = 0; x < kMapW; ++x) {
      float* p = im.at(x, y);
      float base = 0.2f + 0.8f * float(y) / kMapH;
      if (y >= kMapH / 2) base = (y < kMapH / 2 + 2) ? 0.0f : 0.05f + 0.1f * float(x % 3);
      p[0] = base;
      p[1] = base * 0.8f;
      p[2] = (x >= 15 && x < 17) ? 0.0f : base * 1.5f;
    }
  }
  for (int y = 2; y < 4; ++y) {
    for (int x = 5; x < 7; ++x) im.at(x, y)[0] = im.at(x, y)[1] = im.at(x, y)[2] = 8.f;
  }
  return im;
}

double azimuth(const Vec3& w) {
  const double phi = std::atan2(w.y, w.x);
  return phi < 0 ? phi + 2 * kPi : phi;
}

int sphereBin(const Vec3& w) {
  const int iz = std::clamp(static_cast<int>((w.z + 1) * 0.5 * kBinsZ), 0, kBinsZ - 1);
  const int ip = std::clamp(static_cast<int>(azimuth(w) / (2 * kPi) * kBinsPhi), 0, kBinsPhi - 1);
  return iz * kBinsPhi + ip;
}

// Sample directions binned on the sphere; discarded samples (pdf 0) are counted in `discarded`.
std::vector<double> skyObserved(const SkyLight& sky, int n, uint64_t seed, int* discarded) {
  std::vector<double> observed(size_t(kBinsZ) * kBinsPhi, 0.0);
  Rng rng(seed, 2);
  *discarded = 0;
  for (int i = 0; i < n; ++i) {
    const double u1 = rng.uniform(), u2 = rng.uniform();
    const SkySample s = sky.sample(u1, u2);
    if (!(s.pdf > 0)) {
      ++*discarded;
      continue;
    }
    observed[sphereBin(s.to_sky)] += 1.0;
  }
  return observed;
}

// Expected counts: pdf(w) integrated over each bin by the midpoint rule in (theta, phi), where the
// integrand pdf * sin(theta) stays bounded at the poles (in z it has a 1/sin(theta) singularity).
std::vector<double> skyExpected(const std::function<double(const Vec3&)>& pdf, int n) {
  std::vector<double> expected(size_t(kBinsZ) * kBinsPhi, 0.0);
  std::vector<double> cos_p(kSubSamples), sin_p(kSubSamples);
  const double dphi = 2 * kPi / kBinsPhi / kSubSamples;
  for (int iz = 0; iz < kBinsZ; ++iz) {
    const double t_lo = std::acos(-1 + 2.0 * (iz + 1) / kBinsZ);
    const double t_hi = std::acos(-1 + 2.0 * iz / kBinsZ);
    const double dtheta = (t_hi - t_lo) / kSubSamples;
    for (int ip = 0; ip < kBinsPhi; ++ip) {
      for (int k = 0; k < kSubSamples; ++k) {
        const double phi = 2 * kPi * ip / kBinsPhi + (k + 0.5) * dphi;
        cos_p[k] = std::cos(phi);
        sin_p[k] = std::sin(phi);
      }
      double prob = 0.0;
      for (int j = 0; j < kSubSamples; ++j) {
        const double theta = t_lo + (j + 0.5) * dtheta;
        const double st = std::sin(theta), ct = std::cos(theta);
        double row = 0.0;
        for (int k = 0; k < kSubSamples; ++k) row += pdf(Vec3(st * cos_p[k], st * sin_p[k], ct));
        prob += row * st * dtheta * dphi;
      }
      expected[size_t(iz) * kBinsPhi + ip] = prob * n;
    }
  }
  return expected;
}

double sum(const std::vector<double>& v) {
  double s = 0.0;
  for (double x : v) s += x;
  return s;
}

// The map goes through an EXR file and Sky::Type::kMap, the path scenes use.
SkyLight skyFromExr(const Image& map, double scale) {
  const std::string path =
      ::testing::TempDir() + "/cloudbake_chi2_sky_" + std::to_string(::getpid()) + ".exr";
  writeExr(path, {{"", map}});
  Sky s;
  s.type = Sky::Type::kMap;
  s.map_path = path;
  s.map_scale = scale;
  SkyLight sky(s);
  std::remove(path.c_str());
  return sky;
}

TEST(SamplerChiSquare, SkyMapSamplingMatchesItsPdf) {
  const SkyLight sky = skyFromExr(skyMap(), 1.5);
  ASSERT_FALSE(sky.black());
  const std::vector<double> expected =
      skyExpected([&](const Vec3& w) { return sky.pdf(w); }, kSkySamples);
  // Quadrature check: pdf(w) integrates to one over the sphere.
  EXPECT_NEAR(sum(expected) / kSkySamples, 1.0, 1e-3);

  int discarded = 0;
  const BinnedChiSquare r =
      chiSquareBinned(skyObserved(sky, kSkySamples, kSeed, &discarded), expected);
  report("SkyLight map", r);
  EXPECT_EQ(discarded, 0);
  EXPECT_EQ(r.stray, 0.0) << "samples in the black band";
  EXPECT_GT(r.dof, 400);
  EXPECT_LE(r.chi2, r.critical) << r;
}

TEST(SamplerChiSquare, SkyMapRejectsAWrongPdf) {
  const Image map = skyMap();
  Image other = map;
  // A 6 x 2 patch of ground, 1.8% of the mass, 30% brighter.
  for (int y = 8; y < 10; ++y) {
    for (int x = 9; x < 15; ++x) {
      for (int c = 0; c < 3; ++c) other.at(x, y)[c] *= 1.3f;
    }
  }
  const SkyLight sampled = skyFromExr(map, 1.5);
  const SkyLight claimed(other, 1.5, "perturbed map");
  int discarded = 0;
  const BinnedChiSquare r =
      chiSquareBinned(skyObserved(sampled, kSkySamples, kSeed, &discarded),
                      skyExpected([&](const Vec3& w) { return claimed.pdf(w); }, kSkySamples));
  report("SkyLight map vs perturbed map", r);
  EXPECT_EQ(r.stray, 0.0);
  EXPECT_GT(r.chi2, r.critical) << r;
}

}  // namespace
}  // namespace cloudbake
