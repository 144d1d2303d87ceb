// Tests of method `pointcloud` (seed 000): point placement, neighbour queries, the normalised
// rule against closed-form integrals, the paper rule, R and L, bad input, determinism across
// thread counts, cancellation, and the baked grids.
#include "core/bake/pointcloud_bake.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "core/bake/bake_grid.h"
#include "core/bake/neighbour_grid.h"
#include "core/bake/point_cloud.h"
#include "core/bake/point_splat.h"
#include "core/bake/render_from_bake.h"
#include "core/bake/scattering_passes.h"
#include "core/bake/sky_visibility.h"
#include "core/error.h"
#include "core/math/rng.h"
#include "core/phase/henyey_greenstein.h"
#include "core/phase/isotropic.h"
#include "core/volume/analytic.h"
#include "core/volume/sources.h"
#include "tests/core/bake/bake_test_util.h"

namespace cloudbake {
namespace {

/// A lattice for the homogeneous sphere of radius a at the origin: `res` voxels across the
/// diameter plus one empty voxel of margin, each voxel the fraction of it inside (4^3 samples).
struct Lattice {
  BakeGrid grid;
  std::vector<float> density;
};
Lattice sphereLattice(double a, double density, int res) {
  Lattice l;
  const double h = 2 * a / res;
  l.grid.voxel_size = h;
  l.grid.origin = Vec3(-a - 0.5 * h);
  l.grid.nx = l.grid.ny = l.grid.nz = res + 2;
  l.density.assign(l.grid.voxelCount(), 0.f);
  for (int k = 0; k < l.grid.nz; ++k) {
    for (int j = 0; j < l.grid.ny; ++j) {
      for (int i = 0; i < l.grid.nx; ++i) {
        int inside = 0;
        for (int s = 0; s < 64; ++s) {
          const Vec3 o((s % 4 + 0.5) / 4 - 0.5, ((s / 4) % 4 + 0.5) / 4 - 0.5,
                       (s / 16 + 0.5) / 4 - 0.5);
          const Vec3 p = l.grid.center(i, j, k) + o * h;
          if (dot(p, p) <= a * a) ++inside;
        }
        l.density[l.grid.index(i, j, k)] = float(density * inside / 64.0);
      }
    }
  }
  return l;
}

Medium sphereMedium(double a, double extinction, Rgb albedo,
                    std::shared_ptr<const PhaseFunction> phase) {
  Medium m;
  m.density = std::make_shared<SphereDensity>(Vec3(0.0), a, 1.0);
  m.extinction = extinction;
  m.albedo = albedo;
  m.phase = std::move(phase);
  return m;
}

std::shared_ptr<const PhaseFunction> isotropic() { return std::make_shared<IsotropicPhase>(); }

void expectAllFinite(const BakedLight& bake) {
  for (const auto& [name, ch] : bake.channels) {
    for (size_t v = 0; v < ch.data.size(); ++v) {
      ASSERT_TRUE(std::isfinite(ch.data[v])) << name << " value " << v;
    }
  }
}

TEST(PointCloud, PointsAreDensityWeightedAndDeterministic) {
  // Two halves of equal volume, densities 1 and 3: systematic sampling puts exactly 3/4 of the
  // points (to within one) in the dense half, each inside its voxel.
  BakeGrid g;
  g.voxel_size = 0.5;
  g.origin = Vec3(0.0);
  g.nx = 8;
  g.ny = g.nz = 4;
  std::vector<float> d(g.voxelCount());
  for (int k = 0; k < 4; ++k)
    for (int j = 0; j < 4; ++j)
      for (int i = 0; i < 8; ++i) d[g.index(i, j, k)] = i < 4 ? 1.f : 3.f;
  const int n = 4096;
  const PointCloud pc = placePoints(g, d, n, 7);
  ASSERT_EQ(pc.size(), size_t(n));
  int dense = 0;
  for (size_t p = 0; p < pc.size(); ++p) {
    const Vec3 x = pc.position[p];
    EXPECT_TRUE(g.bounds().contains(x));
    if (x.x > 1.75) ++dense;  // voxel faces: i = 4 starts at x = 1.75
    EXPECT_GT(pc.density[p], 0.f);
  }
  EXPECT_NEAR(dense, 3 * n / 4, 1);
  // Mass: sum of densities x h^3 over n.
  EXPECT_NEAR(pc.mass, (64 * 1.0 + 64 * 3.0) * 0.125 / n, 1e-12);
  EXPECT_NEAR(pc.spacing, std::cbrt(128 * 0.125 / n), 1e-12);
  const PointCloud same = placePoints(g, d, n, 7);
  const PointCloud other = placePoints(g, d, n, 8);
  EXPECT_EQ(same.position, pc.position);
  EXPECT_NE(other.position, pc.position);
}

// An empty cloud is a valid shot (it renders the background): no points and a zero bake, for
// every method alike (docs/methods.md, "Empty clouds"). placePoints itself still refuses it.
TEST(PointCloud, EmptyVolumeGivesAZeroBake) {
  Lattice l = sphereLattice(1, 0, 8);
  const Medium m = sphereMedium(1, 1, Rgb(1.0), isotropic());
  PointcloudOptions o;
  o.points = 100;
  const PointCloudResult r = runPointcloud(l.grid, l.density, {}, m, Vec3(0, 0, 1), o);
  EXPECT_EQ(r.cloud.size(), 0u);
  EXPECT_TRUE(r.co.empty());
  EXPECT_EQ(r.passes_run, 0);
  EXPECT_THROW(placePoints(l.grid, l.density, 100, 1), InputError);
}

// Cells of the radius and finer (whose queries skip the rows and columns outside the sphere),
// with points on a lattice of the radius' own spacing, so that many lie exactly on its surface.
TEST(NeighbourGrid, FindsExactlyThePointsWithinTheRadius) {
  Rng rng(3);
  std::vector<Vec3> pts(1500);
  for (Vec3& p : pts) p = Vec3(rng.uniform(), 2 * rng.uniform(), 0.5 * rng.uniform());
  for (int i = 0; i < 6; ++i) {
    for (int j = 0; j < 6; ++j) {
      for (int k = 0; k < 6; ++k) pts.push_back(Vec3(0.2 * i, 0.2 * j, 0.1 * k));
    }
  }
  for (const double cell : {1.0, 0.5, 0.3}) {
    for (const double radius : {1e-4, 0.03, 0.1, 0.2, 0.9}) {
      const PointGrid grid(pts, cell * radius);
      for (size_t q = 0; q < pts.size(); q += 37) {
        std::vector<uint32_t> found, expected;
        grid.forEachWithin(pts[q], radius, [&](uint32_t i, double d2) {
          found.push_back(i);
          const Vec3 d = pts[i] - pts[q];
          EXPECT_DOUBLE_EQ(d2, dot(d, d));
        });
        for (size_t i = 0; i < pts.size(); ++i) {
          const Vec3 d = pts[i] - pts[q];
          if (dot(d, d) <= radius * radius) expected.push_back(uint32_t(i));
        }
        std::sort(found.begin(), found.end());
        EXPECT_EQ(found, expected) << "radius " << radius << ", cells of " << cell << " radius";
      }
    }
  }
}

// The box query visits every point inside the box, column by column along x.
TEST(NeighbourGrid, CellsOfABoxHoldItsPointsInColumnOrder) {
  Rng rng(5);
  std::vector<Vec3> pts(2000);
  for (Vec3& p : pts) p = Vec3(rng.uniform(), rng.uniform(), 2 * rng.uniform());
  const PointGrid grid(pts, 0.1);
  const Vec3 lo(0.2, 0.3, 0.5), hi(0.75, 0.42, 1.1);
  std::set<uint32_t> visited;
  int column = -1;
  grid.forEachInCells(lo, hi, [&](uint32_t i, const Vec3& q) {
    EXPECT_EQ(q, pts[i]);
    EXPECT_GE(grid.cellX(q.x), column);
    column = grid.cellX(q.x);
    EXPECT_TRUE(visited.insert(i).second) << "twice: " << i;
  });
  size_t inside = 0;
  for (size_t i = 0; i < pts.size(); ++i) {
    const Vec3& q = pts[i];
    if (q.x < lo.x || q.y < lo.y || q.z < lo.z || q.x > hi.x || q.y > hi.y || q.z > hi.z) continue;
    EXPECT_EQ(visited.count(uint32_t(i)), 1u) << i;
    ++inside;
  }
  EXPECT_GT(inside, 20u);
}

// Every voxel of the support is the Shepard average of the points within rs of its centre,
// weights (1 - d / rs)^2, summed here point by point over the whole cloud; a voxel with none

// The pair rows are every other point within the radius whose weight is positive, in the grid's
// visiting order, the same on one thread and two, across the build's chunks of destinations
// (over 16384 points) and with rows that drop every pair.
TEST(NeighbourGrid, PairRowsHoldThePositiveWeightsWithinTheRadius) {
  Rng rng(9);
  std::vector<Vec3> pts(40000);
  for (Vec3& p : pts) p = Vec3(rng.uniform(), rng.uniform(), 0.25 * rng.uniform());
  const double radius = 0.02;
  const PointGrid grid(pts, radius);
  // Drops pairs by a rule of both ends, and every pair of destinations divisible by 97.
  auto weight = [&](uint32_t dst, uint32_t src, double d) -> float {
    if (dst % 97 == 0 || (dst + src) % 5 == 0) return 0.f;
    return float(1 + dst % 7 + d);
  };
  auto build = [&](int threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
    return buildNeighbourPairs(grid, pts, radius, weight, 1000, {});
  };
  const NeighbourPairs one = build(1), two = build(2);
  ASSERT_EQ(one.offset.size(), pts.size() + 1);
  EXPECT_EQ(one.offset, two.offset);
  EXPECT_TRUE(
      std::equal(one.source.begin(), one.source.end(), two.source.begin(), two.source.end()));
  EXPECT_TRUE(
      std::equal(one.weight.begin(), one.weight.end(), two.weight.begin(), two.weight.end()));
  EXPECT_EQ(one.within_radius, two.within_radius);
  uint64_t within = 0;
  for (uint32_t dst = 0; dst < pts.size(); dst += 7) {
    std::vector<uint32_t> expected;
    std::vector<float> expected_w;
    grid.forEachWithin(pts[dst], radius, [&](uint32_t src, double d2) {
      if (src == dst) return;
      ++within;
      const float w = weight(dst, src, std::sqrt(d2));
      if (w > 0) {
        expected.push_back(src);
        expected_w.push_back(w);
      }
    });
    const auto b = one.offset[dst], e = one.offset[dst + 1];
    ASSERT_EQ(e - b, expected.size()) << "destination " << dst;
    for (size_t k = 0; k < expected.size(); ++k) {
      EXPECT_EQ(one.source[b + k], expected[k]);
      EXPECT_EQ(one.weight[b + k], expected_w[k]);
    }
  }
  EXPECT_GT(within, 10000u);
  EXPECT_EQ(one.size(), one.offset.back());
  EXPECT_EQ(one.offset[97 + 1] - one.offset[97], 0u);
}
// that close copies the nearest point within 3 rs, and one with none there stays 0.
TEST(PointSplat, IsTheShepardAverageOfThePointsWithinTheRadius) {
  BakedLight b = emptyBake(Vec3(0.0), 0.05, 40, 24, 30);
  const BakeGrid& g = b.grid;
  for (int k = 1; k < g.nz - 1; ++k)
    for (int j = 1; j < g.ny - 1; ++j)
      for (int i = 1; i < g.nx - 1; ++i) b.density[g.index(i, j, k)] = 1.f;
  PointCloudResult r;
  Rng rng(11);
  // Points fill only x < 1 of the 2-wide box: voxels beyond reach fall back, then stay 0.
  for (int p = 0; p < 3000; ++p) {
    r.cloud.position.push_back(Vec3(rng.uniform(), 1.2 * rng.uniform(), 1.5 * rng.uniform()));
    r.co.push_back(Rgb(rng.uniform(), rng.uniform(), 2 * rng.uniform()));
    r.light_dir.push_back(normalize(Vec3(rng.uniform() - 0.5, rng.uniform() - 0.5, 1)));
    r.mie_ratio.push_back(float(rng.uniform()));
  }
  r.cloud.spacing = 0.04;
  const double rs = splatPoints(b, r);
  EXPECT_DOUBLE_EQ(rs, 0.08);
  const auto& co = b.find(bake_grids::kMultipleFluence)->data;
  const auto& mr = b.find(bake_grids::kMieRatio)->data;
  const std::vector<uint8_t> support = densitySupport(g, b.density);
  int averaged = 0, copied = 0, empty = 0;
  for (int k = 0; k < g.nz; k += 3)
    for (int j = 0; j < g.ny; j += 2)
      for (int i = 0; i < g.nx; ++i) {
        const size_t v = g.index(i, j, k);
        const Vec3 c = g.center(i, j, k);
        double w = 0, sum_r = 0, best = 1e300;
        Rgb sum_co(0.0);
        size_t nearest = 0;
        for (size_t p = 0; p < r.cloud.position.size(); ++p) {
          const double d = length(r.cloud.position[p] - c);
          if (d < best) {
            best = d;
            nearest = p;
          }
          if (d > rs) continue;
          const double u = (1 - d / rs) * (1 - d / rs);
          w += u;
          sum_co += r.co[p] * u;
          sum_r += r.mie_ratio[p] * u;
        }
        Rgb want(0.0);
        double want_r = 0;
        if (!support[v]) {
        } else if (w > 0) {
          want = sum_co / w;
          want_r = sum_r / w;
          ++averaged;
        } else if (best <= 3 * rs) {
          want = r.co[nearest];
          want_r = r.mie_ratio[nearest];
          ++copied;
        } else {
          ++empty;
        }
        EXPECT_NEAR(co[3 * v], want.x, 1e-5 * (1 + want.x)) << i << " " << j << " " << k;
        EXPECT_NEAR(co[3 * v + 2], want.z, 1e-5 * (1 + want.z)) << i << " " << j << " " << k;
        EXPECT_NEAR(mr[v], want_r, 1e-5) << i << " " << j << " " << k;
      }
  EXPECT_GT(averaged, 1000);
  EXPECT_GT(copied, 20);
  EXPECT_GT(empty, 100);
}

/// Distance from x (inside) to the surface of the sphere of radius a at the origin along unit w.
double toSphereSurface(double a, const Vec3& x, const Vec3& w) {
  const double b = dot(x, w);
  return -b + std::sqrt(std::max(0.0, b * b - dot(x, x) + a * a));
}

/// Fluence of first-scattered sunlight (per unit E) at x inside a homogeneous sphere of radius a
/// with sigma_t = sigma_s = s, sun along +z: Int_4pi dw Int_0^smax s/(4 pi) Ci(x + t w)
/// exp(-s t) dt, by the midpoint rule in (cos theta, phi, t).
double firstScatteredAt(double a, double s, const Vec3& x) {
  const int nmu = 48, nphi = 48, nt = 64;
  const Vec3 sun(0, 0, 1);
  double sum = 0;
  for (int im = 0; im < nmu; ++im) {
    const double mu = -1 + (im + 0.5) * 2.0 / nmu, st = std::sqrt(1 - mu * mu);
    for (int ip = 0; ip < nphi; ++ip) {
      const double phi = (ip + 0.5) * 2 * kPi / nphi;
      const Vec3 w(st * std::cos(phi), st * std::sin(phi), mu);
      const double smax = toSphereSurface(a, x, w);
      for (int it = 0; it < nt; ++it) {
        const double t = (it + 0.5) * smax / nt;
        const Vec3 y = x + w * t;
        sum += std::exp(-s * (toSphereSurface(a, y, sun) + t)) * smax / nt;
      }
    }
  }
  return s / (4 * kPi) * sum * (2.0 / nmu) * (2 * kPi / nphi);
}

TEST(NormalisedRule, ThinSphereSecondOrderNearTheCentreMatchesTheIntegral) {
  const double a = 1, ext = 0.02;  // tau = 0.02
  const Lattice l = sphereLattice(a, 1, 32);
  const Medium m = sphereMedium(a, ext, Rgb(1.0), isotropic());
  PointcloudOptions o;
  o.points = 6000;
  o.passes = 1;
  o.radius = 1.25 * a;  // points near the centre see the whole sphere
  const PointCloudResult r = runPointcloud(l.grid, l.density, {}, m, Vec3(0, 0, 1), o, false);
  ASSERT_EQ(r.passes_run, 1);
  double sum = 0, expected = 0;
  int count = 0;
  for (size_t j = 0; j < r.cloud.size(); ++j) {
    if (length(r.cloud.position[j]) < 0.25 * a) {
      sum += r.co[j].x;
      expected += firstScatteredAt(a, ext, r.cloud.position[j]);
      ++count;
    }
  }
  ASSERT_GT(count, 40);
  // To first order in tau the value at the centre is sigma_s a (the seed's thin-sphere check).
  EXPECT_NEAR(firstScatteredAt(a, ext, Vec3(0.0)), ext * a, 0.03 * ext * a);
  EXPECT_NEAR(sum / count, expected / count, 0.1 * expected / count);
  std::printf("thin sphere: %d points near the centre, %.5g vs %.5g (%d pairs)\n", count,
              sum / count, expected / count, int(r.pairs));
}

TEST(NormalisedRule, AlbedoScalesTheScatteredLight) {
  const Lattice l = sphereLattice(1, 1, 24);
  PointcloudOptions o;
  o.points = 6000;
  o.passes = 12;
  const Vec3 sun(0.3, 0.2, 1);
  auto run = [&](double albedo) {
    return runPointcloud(l.grid, l.density, {}, sphereMedium(1, 3, Rgb(albedo), isotropic()), sun,
                         o);
  };
  const PointCloudResult one = run(1.0), half = run(0.5), zero = run(0.0);
  double s1 = 0, s05 = 0;
  for (size_t j = 0; j < one.co.size(); ++j) {
    s1 += luminance(one.co[j]);
    s05 += luminance(half.co[j]);
    EXPECT_LE(half.co[j].x, one.co[j].x * (1 + 1e-9));
    EXPECT_EQ(zero.co[j], Rgb(0.0));
  }
  // Order k scales as albedo^k: the sum is below half, far above the first order's quarter.
  EXPECT_LT(s05, 0.5 * s1);
  EXPECT_GT(s05, 0.1 * s1);
}

// Each channel keeps its own reduced albedo: a white channel of a coloured albedo conserves
// energy as a white medium does. With one reduced albedo a (1 - g) / (1 - lum(a g)) for all, red
// of a = [1, 0, 0.5] at g = 0.5 became 0.57 and its light 0.2-0.3 of the white medium's and of
// the path tracer's (an outside probe). The passes still share one extinction, so the two differ
// in how far the light spreads (0.95 here), not in the energy kept.
// The passes of 6000 points on a unit sphere of optical radius `tau`, HG g, lit from (1, 0, 1).
PointCloudResult colouredSphere(const Rgb& albedo, double g, double tau) {
  static const Lattice l = sphereLattice(1, 1, 24);
  PointcloudOptions o;
  o.points = 6000;
  o.passes = 12;
  const Medium m = sphereMedium(1, tau, albedo, std::make_shared<HenyeyGreensteinPhase>(g));
  return runPointcloud(l.grid, l.density, {}, m, Vec3(1, 0, 1), o);
}

TEST(NormalisedRule, AWhiteChannelOfAColouredAlbedoKeepsItsLight) {
  const PointCloudResult white = colouredSphere(Rgb(1.0), 0.5, 4),
                         coloured = colouredSphere(Rgb(1, 0, 0.5), 0.5, 4);
  double red_white = 0, red_coloured = 0;
  for (size_t j = 0; j < white.co.size(); ++j) {
    red_white += white.co[j].x;
    red_coloured += coloured.co[j].x;
  }
  std::printf("red's light, coloured over white: %.3f\n", red_coloured / red_white);
  EXPECT_GT(red_coloured, 0.75 * red_white);
  EXPECT_LT(red_coloured, 1.25 * red_white);
}

// Each channel of a coloured albedo scatters about what a grey medium of that channel's albedo
// does, as in the path tracer, where channels are independent. The forward beam of the shared
// reduction gave the dark channel the luminance's: blue (albedo 0.2) came out 2.3x the grey
// medium's in a view (an outside probe).
TEST(NormalisedRule, EachChannelOfAColouredAlbedoScattersAsItsGreyMedium) {
  auto total = [&](const Rgb& albedo) {
    const PointCloudResult r = colouredSphere(albedo, 0.6, 3);
    Rgb sum(0.0);
    for (const Rgb& co : r.co) sum += co;
    return sum;
  };
  const Rgb albedo(0.9, 0.5, 0.2), coloured = total(albedo);
  for (int c = 0; c < 3; ++c) {
    const double grey = total(Rgb(albedo[c]))[c];
    std::printf("channel %d (albedo %.1f): coloured over grey %.3f\n", c, albedo[c],
                coloured[c] / grey);
    EXPECT_GT(coloured[c], 0.85 * grey) << c;
    EXPECT_LT(coloured[c], 1.15 * grey) << c;
  }
}

// A sphere of radius 1 and extinction 5 on a lattice of `resolution`, lit from above: `passes`
// passes and the geometric tail (first), and the passes until an order changes Co by less than
// `all_tolerance`, without a tail (second).
std::pair<PointCloudResult, PointCloudResult> tailAndAllOrders(const Rgb& albedo, int resolution,
                                                               int points, int passes,
                                                               double all_tolerance) {
  const Lattice l = sphereLattice(1, 1, resolution);
  const Medium m = sphereMedium(1, 5, albedo, isotropic());
  PointcloudOptions o;
  o.points = points;
  o.passes = passes;
  o.tolerance = 1e-6;
  PointCloudResult tail = runPointcloud(l.grid, l.density, {}, m, Vec3(0, 0, 1), o, true);
  o.passes = 1000;
  o.tolerance = all_tolerance;
  PointCloudResult all = runPointcloud(l.grid, l.density, {}, m, Vec3(0, 0, 1), o, false);
  return {std::move(tail), std::move(all)};
}

TEST(NormalisedRule, GeometricTailMatchesRunningAllOrders) {
  // A thick conservative sphere: 24 passes plus the tail vs passes until < 1e-4 change. (The
  // ratio of successive orders still creeps up after 24 passes, so the tail is a little low.)
  const auto [tail, all] = tailAndAllOrders(Rgb(1.0), 24, 4000, 24, 1e-4);
  EXPECT_GT(tail.tail_ratio, 0);
  EXPECT_LT(tail.tail_ratio, 1);
  EXPECT_GT(all.passes_run, 20);
  double st = 0, sa = 0, s24 = 0;
  for (size_t j = 0; j < all.co.size(); ++j) {
    st += luminance(tail.co[j]);
    sa += luminance(all.co[j]);
  }
  for (int k = 1; k <= 24; ++k) s24 += all.order_luminance[size_t(k)];
  std::printf("tail: q %.4f, %.5g vs %.5g after %d passes; ratios", tail.tail_ratio, st, sa,
              all.passes_run);
  for (int k = 1; k < 40 && k < int(all.order_luminance.size()); ++k) {
    std::printf(" %.3f", all.order_luminance[size_t(k)] / all.order_luminance[size_t(k - 1)]);
  }
  std::printf("\n");
  EXPECT_NEAR(st, sa, 0.03 * sa);
  EXPECT_LT(s24, 0.9 * sa);  // the tail matters here
}

// A coloured albedo's channels fall by their own ratios, order by order: the tail after the last
// pass takes each channel's (one ratio from their luminance gave albedo (0.99, 0.7, 0.4)'s red
// 8 % too little multiple scattering after 3 passes on an outside probe's cloud). Measured here,
// 8 passes and the tail against all orders: -1.9 / -0.0 / -0.0 % per channel, against -4.7 /
// +0.7 / +0.0 % with the luminance's ratio.
TEST(NormalisedRule, GeometricTailPerChannel) {
  const auto [tail, all] = tailAndAllOrders(Rgb(0.9, 0.6, 0.3), 20, 3000, 8, 1e-5);
  Rgb st(0.0), sa(0.0);
  for (size_t j = 0; j < all.co.size(); ++j) {
    st += tail.co[j];
    sa += all.co[j];
  }
  for (int c = 0; c < 3; ++c) {
    std::printf("channel %d: 8 passes and the tail %.4g, all orders %.4g (%+.1f %%)\n", c, st[c],
                sa[c], 100 * (st[c] / sa[c] - 1));
    EXPECT_NEAR(st[c], sa[c], 0.03 * sa[c]) << c;
  }
}

TEST(NormalisedRule, TinyRadiusLeavesOnlyEachPointsOwnSphere) {
  const Lattice l = sphereLattice(1, 1, 16);
  const double ext = 2, albedo = 0.8;
  const Medium m = sphereMedium(1, ext, Rgb(albedo), isotropic());
  PointcloudOptions o;
  o.points = 2000;
  o.passes = 4;
  o.tolerance = 1e-9;
  o.radius = 1e-6;
  const PointCloudResult r = runPointcloud(l.grid, l.density, {}, m, Vec3(0, 0, 1), o, false);
  EXPECT_EQ(r.pairs, 0u);
  EXPECT_EQ(r.passes_run, 4);
  for (size_t j = 0; j < r.cloud.size(); ++j) {
    // The own sphere collides 1 - exp(-sigma_t r) of the point's emission; energy conservation
    // scales it to the point's collision fraction 1 - P_escape: q = albedo (1 - P_escape).
    const double d = r.cloud.density[j];
    const double radius = std::cbrt(3 * r.cloud.mass / (4 * kPi * d));
    const double self = 1 - std::exp(-ext * d * radius);
    ASSERT_NEAR(r.transfer_scale[j] * self, r.collision[j], 1e-6);
    const double q = albedo * r.collision[j];
    const double expected = r.cloud.sun[j] * (q + q * q + q * q * q + q * q * q * q);
    ASSERT_NEAR(r.co[j].x, expected, 1e-6 * expected);
    EXPECT_EQ(r.mie_ratio[j], 0.f);  // all of it isotropic
  }
}

TEST(NormalisedRule, TinyRadiusSkyOrdersAreTheOwnSphereSeries) {
  // Header, step 8: the sky passes start from the fluence 4 pi V of a unit-radiance uniform sky
  // and, with only each point's own sphere left, multiply it by q = albedo (1 - P_escape) per
  // order (isotropic phase: the reduced medium is the medium, so there is no beam term).
  const Lattice l = sphereLattice(1, 1, 16);
  const double ext = 2, albedo = 0.8;
  const Medium m = sphereMedium(1, ext, Rgb(albedo), isotropic());
  BakedLight vis;
  vis.grid = l.grid;
  vis.density = l.density;
  computeSkyVisibility(vis, ext);
  PointcloudOptions o;
  o.points = 2000;
  o.passes = 3;
  o.tolerance = 1e-9;
  o.radius = 1e-6;
  o.sky = true;
  const PointCloudResult r =
      runPointcloud(l.grid, l.density, vis.channels.at(bake_grids::kSkyVisibility).data, m,
                    Vec3(0, 0, 1), o, false);
  ASSERT_EQ(r.co_sky.size(), r.cloud.size());
  for (size_t j = 0; j < r.cloud.size(); ++j) {
    const double v = 1 - double(r.collision[j]);  // P_escape = sky visibility at the point
    const double q = albedo * r.collision[j];
    const double expected = 4 * kPi * v * (q + q * q + q * q * q);
    ASSERT_NEAR(r.co_sky[j].x, expected, 1e-5 * expected + 1e-9);
  }
}

// The reduced medium's passes gather the sun's orders and the sky's in one loop over the pairs.
// Against the isotropic phase's passes, which run apart (g = 0 takes the beam model, the same
// physics for an isotropic phase), a phase of g = 1e-4 gives the same light to about 1e-4; and
// the sun's light is the same bits with the sky's passes or without them.
TEST(NormalisedRule, SunAndSkyPassesTogetherMatchThemApart) {
  const Lattice l = sphereLattice(1, 1, 16);
  const double ext = 3;
  BakedLight vis;
  vis.grid = l.grid;
  vis.density = l.density;
  computeSkyVisibility(vis, ext);
  const auto& v = vis.channels.at(bake_grids::kSkyVisibility).data;
  PointcloudOptions o;
  o.points = 3000;
  o.passes = 6;
  o.tolerance = 1e-9;
  o.sky = true;
  auto run = [&](std::shared_ptr<const PhaseFunction> phase, bool sky) {
    PointcloudOptions oo = o;
    oo.sky = sky;
    return runPointcloud(l.grid, l.density, sky ? v : FirstTouchFloats(),
                         sphereMedium(1, ext, Rgb(0.9), phase), Vec3(0, 0, 1), oo);
  };
  const auto hg = std::make_shared<HenyeyGreensteinPhase>(1e-4);
  const PointCloudResult apart = run(isotropic(), true), together = run(hg, true);
  ASSERT_EQ(together.co_sky.size(), apart.co_sky.size());
  double sky = 0, sky_diff = 0, sun = 0, sun_diff = 0;
  for (size_t j = 0; j < apart.cloud.size(); ++j) {
    sky += apart.co_sky[j].x;
    sky_diff += std::abs(together.co_sky[j].x - apart.co_sky[j].x);
    sun += apart.co[j].x;
    sun_diff += std::abs(together.co[j].x - apart.co[j].x);
  }
  EXPECT_GT(sky, 0);
  EXPECT_LT(sky_diff, 5e-4 * sky);
  EXPECT_LT(sun_diff, 5e-4 * sun);
  const auto hg6 = std::make_shared<HenyeyGreensteinPhase>(0.6);
  const PointCloudResult with_sky = run(hg6, true), without = run(hg6, false);
  for (size_t j = 0; j < with_sky.cloud.size(); ++j) {
    ASSERT_EQ(with_sky.co[j], without.co[j]) << j;
    ASSERT_EQ(with_sky.light_dir[j], without.light_dir[j]) << j;
    ASSERT_EQ(with_sky.mie_ratio[j], without.mie_ratio[j]) << j;
  }
}

// The same cloud 5e5 world units from the origin (floats there are 0.03 apart, half the points'
// spacing) gives the same light: the passes keep positions relative to the cloud. Both rules.
TEST(Pointcloud, ACloudFarFromTheOriginGivesTheSameLight) {
  const Lattice near = sphereLattice(1, 3, 16);
  Lattice far = near;
  far.grid.origin += Vec3(5e5, -2e5, 1e5);
  using Rule = PointcloudOptions::Rule;
  // The beam model (g = 0), the reduced medium's passes (g = 0.6) and the paper rule.
  for (const auto& [g, rule] : {std::pair{0.0, Rule::kNormalized},
                                std::pair{0.6, Rule::kNormalized}, std::pair{0.0, Rule::kPaper}}) {
    const Medium m = sphereMedium(1, 3, Rgb(0.9), std::make_shared<HenyeyGreensteinPhase>(g));
    PointcloudOptions o;
    o.points = 3000;
    o.passes = 4;
    o.rule = rule;
    const PointCloudResult a = runPointcloud(near.grid, near.density, {}, m, Vec3(0, 0, 1), o);
    const PointCloudResult b = runPointcloud(far.grid, far.density, {}, m, Vec3(0, 0, 1), o);
    ASSERT_EQ(a.cloud.size(), b.cloud.size());
    double sum = 0, diff = 0, dir = 0;
    for (size_t j = 0; j < a.cloud.size(); ++j) {
      sum += a.co[j].x;
      diff += std::abs(a.co[j].x - b.co[j].x);
      dir += length(a.light_dir[j] - b.light_dir[j]);
    }
    EXPECT_GT(sum, 0);
    EXPECT_LT(diff, 1e-4 * sum) << "g " << g << ", rule " << int(rule);
    EXPECT_LT(dir / double(a.cloud.size()), 1e-4) << "g " << g << ", rule " << int(rule);
  }
}

// An outside probe: at extinction 1e-320 a point's discretised collision fraction is a
// denormal, its ratio to the target overflowed, and inf times a zero sphere gave NaN light.
TEST(NormalisedRule, ANearlyTransparentCloudScattersNothingAndStaysFinite) {
  const Lattice l = sphereLattice(1, 1, 12);
  for (const double g : {0.0, 0.6}) {
    for (const double extinction : {1e-320, 1e-300, 1e-40}) {
      const Medium m =
          sphereMedium(1, extinction, Rgb(0.9), std::make_shared<HenyeyGreensteinPhase>(g));
      PointcloudOptions o;
      o.points = 500;
      o.passes = 3;
      const PointCloudResult r = runPointcloud(l.grid, l.density, {}, m, Vec3(0, 0, 1), o);
      ASSERT_GT(r.cloud.size(), 0u);
      for (size_t j = 0; j < r.cloud.size(); ++j) {
        ASSERT_TRUE(std::isfinite(r.transfer_scale[j])) << extinction << " g " << g << " " << j;
        ASSERT_TRUE(isFinite(r.co[j]) && isFinite(r.light_dir[j])) << extinction << " " << j;
        ASSERT_LE(maxComponent(r.co[j]), 1e-20) << extinction << " g " << g << " " << j;
        ASSERT_GE(r.co[j].x, 0.0);
      }
    }
  }
}

TEST(NormalisedRule, MieRatioIsHigherOnTheShadowSide) {
  // Seed 000's Figure 8: on the lit side light arrives forward and back scattered (more
  // isotropic), in the shadow it flows on, away from the sun (more beam-like).
  const Lattice l = sphereLattice(1, 1, 24);
  const Medium m = sphereMedium(1, 4, Rgb(1.0), std::make_shared<HenyeyGreensteinPhase>(0.8));
  PointcloudOptions o;
  o.points = 12000;
  o.passes = 12;
  const Vec3 sun(1, 0, 0);
  const PointCloudResult r = runPointcloud(l.grid, l.density, {}, m, sun, o);
  double lit = 0, shadow = 0, shadow_dir = 0;
  int nl = 0, ns = 0;
  for (size_t j = 0; j < r.cloud.size(); ++j) {
    ASSERT_GE(r.mie_ratio[j], 0.f);
    ASSERT_LE(r.mie_ratio[j], 1.f);
    const double len = length(r.light_dir[j]);
    ASSERT_TRUE(len == 0 || std::abs(len - 1) < 1e-9);
    const double x = r.cloud.position[j].x;
    if (x > 0.5) {
      lit += r.mie_ratio[j];
      ++nl;
    } else if (x < -0.5) {
      shadow += r.mie_ratio[j];
      shadow_dir += dot(r.light_dir[j], -sun);
      ++ns;
    }
  }
  ASSERT_GT(nl, 100);
  ASSERT_GT(ns, 100);
  EXPECT_GT(shadow / ns, lit / nl + 0.05);
  EXPECT_GT(shadow_dir / ns, 0.5);  // light in the shadow travels away from the sun
}

TEST(PaperRule, RunsAndStaysFiniteWithBothOutputs) {
  const Lattice l = sphereLattice(1, 1, 16);
  const Medium m = sphereMedium(1, 2, Rgb(1.0), std::make_shared<HenyeyGreensteinPhase>(0.7));
  PointcloudOptions o;
  o.points = 3000;
  o.passes = 6;
  o.rule = PointcloudOptions::Rule::kPaper;
  for (const bool mapping : {false, true}) {
    o.output_mapping = mapping;
    const PointCloudResult r = runPointcloud(l.grid, l.density, {}, m, Vec3(0, 1, 0), o);
    EXPECT_GT(r.passes_run, 0);
    double total = 0;
    for (size_t j = 0; j < r.co.size(); ++j) {
      ASSERT_TRUE(isFinite(r.co[j]));
      ASSERT_GE(r.co[j].x, 0);
      if (mapping) {
        ASSERT_LE(r.co[j].x, 1);
      }
      ASSERT_GE(r.mie_ratio[j], 0.f);
      ASSERT_LE(r.mie_ratio[j], 1.f);
      ASSERT_NEAR(length(r.light_dir[j]), 1, 1e-9);
      total += luminance(r.co[j]);
    }
    EXPECT_GT(total, 0);
    // Eq. 1 lowers R where the scattered light arrives from all sides (Lsum short).
    EXPECT_LT(*std::min_element(r.mie_ratio.begin(), r.mie_ratio.end()), 0.9f);
  }
  // No extinction: every pair has A_d = 1 and Ci grows without bound; it saturates, finite.
  o.passes = 40;
  o.output_mapping = false;
  o.tolerance = 1e-9;
  const PointCloudResult r = runPointcloud(
      l.grid, l.density, {}, sphereMedium(1, 0, Rgb(1.0), isotropic()), Vec3(0, 1, 0), o);
  for (const Rgb& c : r.co) ASSERT_TRUE(isFinite(c) && c.x <= 1e30);
}

TEST(Pointcloud, KnobsOutOfRangeAreNamed) {
  const Medium m = sphereMedium(1, 1, Rgb(1.0), isotropic());
  auto expectError = [&](PointcloudOptions o, const std::string& knob) {
    try {
      bakePointcloud(m, Vec3(0, 0, 1), o);
      ADD_FAILURE() << "no error for " << knob;
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()).rfind(knob + ":", 0), 0u) << e.what();
    }
  };
  PointcloudOptions o;
  o.points = 63;
  expectError(o, "points");
  o.points = (1 << 24) + 1;
  expectError(o, "points");
  o = PointcloudOptions();
  for (const int p : {0, 1001}) {
    o.passes = p;
    expectError(o, "passes");
  }
  o = PointcloudOptions();
  for (const double t : {0.0, -0.1, 1.5, std::nan("")}) {
    o.tolerance = t;
    expectError(o, "tolerance");
  }
  o = PointcloudOptions();
  for (const double r : {-1.0, std::nan(""), HUGE_VAL}) {
    o.radius = r;
    expectError(o, "radius");
  }
}

TEST(Pointcloud, UnusableRadiusIsNamed) {
  const Lattice l = sphereLattice(1, 1, 16);
  const Medium m = sphereMedium(1, 1, Rgb(1.0), isotropic());
  PointcloudOptions o;
  o.points = 1000;
  o.radius = 10;  // the lattice's diagonal is about 3.9
  EXPECT_THROW(
      {
        try {
          runPointcloud(l.grid, l.density, {}, m, Vec3(0, 0, 1), o);
        } catch (const InputError& e) {
          EXPECT_NE(std::string(e.what()).find("radius"), std::string::npos) << e.what();
          throw;
        }
      },
      InputError);
  // Every point a neighbour of every other: 30000^2 pairs do not fit.
  o.points = 30000;
  o.radius = 3.5;
  try {
    runPointcloud(l.grid, l.density, {}, m, Vec3(0, 0, 1), o);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()).rfind("radius:", 0), 0u) << e.what();
    EXPECT_NE(std::string(e.what()).find("memory"), std::string::npos) << e.what();
  }
}

PointcloudOptions smallBake() {
  PointcloudOptions o;
  o.points = 3000;
  o.passes = 8;
  o.light_resolution = 20;
  return o;
}

TEST(Pointcloud, BakeHoldsTheDocumentedGrids) {
  const Medium m =
      sphereMedium(1, 3, Rgb(0.9, 0.95, 1.0), std::make_shared<HenyeyGreensteinPhase>(0.6));
  PointcloudStats stats;
  const BakedLight bake = bakePointcloud(m, Vec3(0, 0, 2), smallBake(), {}, &stats);
  EXPECT_NO_THROW(bake.validate("pointcloud bake"));
  EXPECT_EQ(bake.method, "pointcloud");
  EXPECT_EQ(bake.sun_direction, Vec3(0, 0, 1));
  for (const char* name :
       {bake_grids::kSunTransmittance, bake_grids::kSkyVisibility, bake_grids::kMultipleFluence,
        bake_grids::kLightDir, bake_grids::kMieRatio, bake_grids::kCd}) {
    EXPECT_NE(bake.find(name), nullptr) << name;
  }
  const auto& sun = bake.find(bake_grids::kSunTransmittance)->data;
  const auto& co = bake.find(bake_grids::kMultipleFluence)->data;
  const auto& cd = bake.find(bake_grids::kCd)->data;
  double co_sum = 0;
  // Cd on the density's support; the sun's transmittance reaches a voxel beyond it, for views.
  const std::vector<uint8_t> support = densitySupport(bake.grid, bake.density);
  for (size_t v = 0; v < bake.grid.voxelCount(); ++v) {
    for (int c = 0; c < 3; ++c) {
      const double expected = support[v] ? (sun[v] + co[3 * v + c]) / (4 * kPi) : 0.0;
      ASSERT_NEAR(cd[3 * v + c], expected, 1e-6);
    }
    co_sum += co[3 * v];
  }
  EXPECT_GT(co_sum, 0);
  EXPECT_EQ(stats.points, 3000);
  EXPECT_GE(stats.passes_run, 1);
  EXPECT_LE(stats.passes_run, 8);
  EXPECT_GT(stats.radius, 0);
  EXPECT_GT(stats.mean_neighbours, 10);
  // The sun's passes, plus the sky's (a uniform sky of unit radiance) when the bake has a sky.
  const uint64_t sun_interactions =
      std::stoull(bake.metadata.at("cloudbake:pairs")) * uint64_t(stats.passes_run);
  EXPECT_GT(stats.pair_interactions, sun_interactions);
  EXPECT_EQ(stats.pair_interactions % std::stoull(bake.metadata.at("cloudbake:pairs")), 0u);
  ASSERT_NE(bake.find(bake_grids::kSkyMultipleFluence), nullptr);
  for (const char* key :
       {"cloudbake:points", "cloudbake:passes_run", "cloudbake:radius", "cloudbake:rule",
        "cloudbake:tolerance", "cloudbake:last_relative_change", "cloudbake:tail_ratio",
        "cloudbake:pair_interactions", "cloudbake:seconds_passes"}) {
    EXPECT_EQ(bake.metadata.count(key), 1u) << key;
  }
  EXPECT_EQ(bake.metadata.at("cloudbake:rule"), "normalized");
}

TEST(Pointcloud, ExtremeMediaGiveFiniteValidBakes) {
  struct Case {
    double extinction;
    double albedo;
    PointcloudOptions::Rule rule;
  };
  for (const Case c : {Case{1e6, 1.0, PointcloudOptions::Rule::kNormalized},
                       Case{1e6, 0.0, PointcloudOptions::Rule::kNormalized},
                       Case{5, 0.0, PointcloudOptions::Rule::kNormalized},
                       Case{5, 1.0, PointcloudOptions::Rule::kNormalized},
                       Case{1e-6, 1.0, PointcloudOptions::Rule::kNormalized},
                       Case{1e6, 1.0, PointcloudOptions::Rule::kPaper},
                       Case{0, 1.0, PointcloudOptions::Rule::kPaper}}) {
    SCOPED_TRACE("extinction " + std::to_string(c.extinction) + " albedo " +
                 std::to_string(c.albedo));
    PointcloudOptions o = smallBake();
    o.rule = c.rule;
    o.passes = 30;
    const BakedLight bake =
        bakePointcloud(sphereMedium(1, c.extinction, Rgb(c.albedo), isotropic()), Vec3(1, 1, 1), o);
    expectAllFinite(bake);
    EXPECT_NO_THROW(bake.validate("extreme"));
  }
}

TEST(Pointcloud, SameGridsOnOneAndTwoThreads) {
  const Medium m = sphereMedium(1, 4, Rgb(1.0), std::make_shared<HenyeyGreensteinPhase>(0.8));
  PointcloudOptions o = smallBake();
  o.points = 20000;  // several chunks of destinations and blocks of pairs
  auto bake = [&](int threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
    return bakePointcloud(m, Vec3(0.2, 1, 0.5), o);
  };
  const BakedLight one = bake(1), two = bake(2);
  EXPECT_EQ(one.density, two.density);
  ASSERT_EQ(one.channels.size(), two.channels.size());
  for (const auto& [name, ch] : one.channels) {
    EXPECT_TRUE(ch.data == two.channels.at(name).data) << name;
  }
}

TEST(Pointcloud, ProgressCancelsBetweenPasses) {
  const Medium m = sphereMedium(1, 3, Rgb(1.0), isotropic());
  double last = -1;
  bool monotone = true;
  auto progress = [&](double f, const std::string& stage) {
    monotone = monotone && f >= last && f <= 1;
    last = f;
    return stage.find("pass 2/") == std::string::npos;
  };
  EXPECT_THROW(bakePointcloud(m, Vec3(0, 0, 1), smallBake(), progress), Cancelled);
  EXPECT_TRUE(monotone);
  EXPECT_GT(last, 0.25);
}

// The sky's passes follow the sun's in one range: progress never goes back (it restarted at the
// sun's first pass, 18% then 14%), and each stage says whose pass it is.
TEST(Pointcloud, ProgressGoesOnThroughTheSkysPasses) {
  const Medium m = sphereMedium(1, 3, Rgb(0.9), isotropic());
  PointcloudOptions o = smallBake();
  o.tolerance = 1e-9;  // every pass runs
  o.sky = true;
  double last = -1;
  bool monotone = true, sun = false, sky = false;
  auto progress = [&](double f, const std::string& stage) {
    monotone = monotone && f >= last && f <= 1;
    last = f;
    sun = sun || stage.rfind("sun pass ", 0) == 0;
    sky = sky || stage.rfind("sky pass 8/8", 0) == 0;
    return true;
  };
  bakePointcloud(m, Vec3(0, 0, 1), o, progress);
  EXPECT_TRUE(monotone);
  EXPECT_TRUE(sun);
  EXPECT_TRUE(sky);
  EXPECT_DOUBLE_EQ(last, 1.0);
}

// Under a sky alone, a white cloud's scattered sky light is at most what the medium removes, in
// every voxel: Co_sky <= 4 pi (1 - V). The passes put some points of this optically thick sphere
// above it (views up to 1.055x the sky, an outside probe); they are set to the bound and counted.
TEST(Pointcloud, ScatteredSkyLightStaysWithinTheFurnaceBound) {
  const Medium m = sphereMedium(1, 20, Rgb(1.0), isotropic());
  PointcloudOptions o;
  o.points = 4096;
  o.light_resolution = 32;
  o.sky = true;
  const BakedLight bake = bakePointcloud(m, Vec3(0, 0, 1), o);
  const auto& co_sky = bake.find(bake_grids::kSkyMultipleFluence)->data;
  const auto& vis = bake.find(bake_grids::kSkyVisibility)->data;
  double worst = 0;
  for (size_t v = 0; v < vis.size(); ++v) {
    const double removed = 4 * kPi * (1 - double(vis[v]));
    for (int c = 0; c < 3; ++c) {
      ASSERT_LE(co_sky[3 * v + c], removed * (1 + 1e-5) + 1e-7) << v;
      if (removed > 1e-3) worst = std::max(worst, double(co_sky[3 * v + c]) / removed);
    }
  }
  EXPECT_GT(worst, 0.9);  // the bound is nearly reached, as it is exactly in truth
  EXPECT_GT(std::stoi(bake.metadata.at("cloudbake:sky_fraction_capped")), 0);
}

// A white cloud under a uniform sky alone is a furnace: every view of it is the sky, L alpha. Its
// single scattering now weights the phase (sky_p1_scatter.h), and the scattered sky light takes
// the complementary shape, Co_sky / (4 pi (1 - V)) times one minus the single scattering, as
// precomputed's does (measured 0.99 and 0.96 of the sky here). With the phase-weighted single
// scattering and the isotropic shape, the extremes matrix's white sphere of HG -0.999 had a sky
// layer 1.09x the sky: its single scattering about half the sky, and its multiple term 0.6.
TEST(Pointcloud, AWhiteCloudUnderASkyAloneRendersTheSky) {
  for (const double g : {0.8, -0.95}) {
    const Medium m = sphereMedium(1, 6, Rgb(1.0), std::make_shared<HenyeyGreensteinPhase>(g));
    PointcloudOptions o;
    o.points = 8192;
    o.light_resolution = 32;
    o.sky = true;
    const BakedLight bake = bakePointcloud(m, Vec3(0, 0, 1), o);
    ASSERT_NE(bake.find(bake_grids::kSkyVisibilityVector), nullptr);
    Sun sun;
    sun.direction = Vec3(0, 0, 1);
    sun.irradiance = Rgb(0.0);
    Sky sky;
    sky.type = Sky::Type::kConstant;
    sky.radiance = Rgb(0.5);
    Camera cam;
    cam.position = Vec3(0.5, -4, 0.3);
    cam.look_at = Vec3(0.0);
    cam.width_px = 24;
    cam.height_px = 24;
    const RenderLayers l = renderFromBake(bake, m, sun, sky, cam, {});
    double sum = 0, covered = 0;
    for (int y = 0; y < l.sky.height; ++y) {
      for (int x = 0; x < l.sky.width; ++x) {
        const double alpha = l.beauty.at(x, y)[3];
        const double v = l.sky.at(x, y)[0] / 0.5;
        EXPECT_LE(v, alpha + 0.02) << "g " << g << " pixel " << x << ", " << y;
        sum += v;
        covered += alpha;
      }
    }
    ASSERT_GT(covered, 10);
    EXPECT_GT(sum / covered, 0.94) << "g " << g;
    EXPECT_LE(sum / covered, 1.0) << "g " << g;
  }
}

// The points' sun transmittance (a march per point: seconds for millions of points) polls the
// progress: a cancel there stops the bake before its neighbours (it ran on for 6.7 s with 2M
// points: an outside probe).
TEST(Pointcloud, ACancelWhileThePointsAreLitStopsTheBake) {
  const Medium m = sphereMedium(1, 3, Rgb(0.9), std::make_shared<HenyeyGreensteinPhase>(0.7));
  PointcloudOptions o = smallBake();
  o.points = 20000;
  bool inside = false, neighbours = false;
  auto progress = [&](double f, const std::string& stage) {
    neighbours = neighbours || stage == "neighbours";
    if (stage == "points" && f > 0) {
      inside = true;
      return false;
    }
    return true;
  };
  EXPECT_THROW(bakePointcloud(m, Vec3(0, 0, 1), o, progress), Cancelled);
  EXPECT_TRUE(inside);
  EXPECT_FALSE(neighbours);
}

// With a phase the passes reduce, the sun's and the sky's orders share their passes: one range.
TEST(Pointcloud, ProgressCountsTheSharedPassesOnce) {
  const Medium m = sphereMedium(1, 3, Rgb(0.9), std::make_shared<HenyeyGreensteinPhase>(0.7));
  PointcloudOptions o = smallBake();
  o.tolerance = 1e-9;  // every pass runs
  o.sky = true;
  double last = -1;
  bool monotone = true, last_pass = false;
  auto progress = [&](double f, const std::string& stage) {
    monotone = monotone && f >= last && f <= 1;
    last = f;
    last_pass = last_pass || stage.rfind("sun and sky pass 8/8", 0) == 0;
    return true;
  };
  bakePointcloud(m, Vec3(0, 0, 1), o, progress);
  EXPECT_TRUE(monotone);
  EXPECT_TRUE(last_pass);
  EXPECT_DOUBLE_EQ(last, 1.0);
  // A cancel during the shared passes stops the bake.
  auto cancel = [&](double, const std::string& stage) {
    return stage.rfind("sun and sky pass 3/", 0) != 0;
  };
  EXPECT_THROW(bakePointcloud(m, Vec3(0, 0, 1), o, cancel), Cancelled);
}

// Speed on the Stanford bunny (not run by ctest): 100k points, 8 passes, 1 and 2 threads.
TEST(Pointcloud, DISABLED_BunnySpeed) {
  const std::string path = std::string(CLOUDBAKE_SHARED_DIR) + "/data/bun_zipper.ply";
  if (!std::ifstream(path).good()) GTEST_SKIP() << "no " << path;
  MeshSourceOptions mesh;
  mesh.path = path;
  mesh.resolution = 128;
  Medium m;
  m.density = meshToVolume(mesh);
  const Vec3 extent = m.density->bounds().extent();
  m.extinction = 20 / maxComponent(extent);  // optical depth ~20 across the bunny
  m.albedo = Rgb(1.0);
  m.phase = std::make_shared<HenyeyGreensteinPhase>(0.85);
  PointcloudOptions o;
  o.points = 100000;
  o.passes = 8;
  o.tolerance = 1e-6;
  o.light_resolution = 128;
  for (const int threads : {1, 2}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
    PointcloudStats s;
    const auto t0 = std::chrono::steady_clock::now();
    const BakedLight bake = bakePointcloud(m, Vec3(1, 0.3, 0.5), o, {}, &s);
    const double total =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf(
        "threads %d: total %.2f s (lattice+sun+sky %.2f, points %.2f, neighbours %.2f, passes "
        "%.2f, splat %.2f); radius %.4g, %.1f neighbours/point, %llu pair interactions, "
        "%.3g pairs/s in passes, passes run %d, last change %.3g, tail %s\n",
        threads, total,
        total - s.seconds_points - s.seconds_neighbours - s.seconds_passes - s.seconds_splat,
        s.seconds_points, s.seconds_neighbours, s.seconds_passes, s.seconds_splat, s.radius,
        s.mean_neighbours, static_cast<unsigned long long>(s.pair_interactions),
        double(s.pair_interactions) / s.seconds_passes, s.passes_run, s.last_relative_change,
        bake.metadata.at("cloudbake:tail_ratio").c_str());
  }
}

}  // namespace
}  // namespace cloudbake
