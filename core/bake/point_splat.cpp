#include "core/bake/point_splat.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "core/bake/neighbour_grid.h"
#include "core/error.h"
#include "core/math/parallel.h"

namespace cloudbake {
namespace {

// Co_sky_p / (4 pi (1 - V_p)) per point: the scattered sky light as a fraction of the sky light
// the medium removes at the point (V_p its sky visibility). A furnace bounds it by 1 at any
// albedo <= 1, so averaging it over points and scaling by the voxel's own 4 pi (1 - V) keeps
// every voxel within the bound. Averaging Co_sky itself did not: voxels at the cloud's edge,
// whose V is high, took the fluence of points deeper inside, and a white, thick sphere under a
// uniform sky came out up to 1.5x brighter than the sky. Where the medium removes nothing (1 - V
// below 1e-9) the point carries no scattered sky light. The passes' discretisation can put a
// point's fraction above the bound (a white sphere of optical radius 20 under a sky alone: views
// up to 1.055-1.097x the sky, an outside probe): such points are set to it and counted in
// `capped`.
std::vector<Rgb> skyFractions(const BakeGrid& g, const float* vis, const PointCloudResult& r,
                              size_t* capped) {
  std::vector<Rgb> f(r.co_sky.size(), Rgb(0.0));
  *capped = 0;
  for (size_t p = 0; p < f.size(); ++p) {
    const double removed = 4 * kPi * (1.0 - double(sampleTrilinear(g, vis, r.cloud.position[p])));
    if (!(removed > 4 * kPi * 1e-9)) continue;
    f[p] = r.co_sky[p] / removed;
    if (maxComponent(f[p]) > 1) {
      f[p] = min(f[p], Rgb(1.0));
      ++*capped;
    }
  }
  return f;
}

// The points that can reach the voxels a..b of row (j, k): those within rs of the row's axis
// (yz2, their squared distance from it), by column of cells along x, so that each voxel's points
// within rs lie in a window of columns that slides along the row. Per voxel that tests about
// twice the points it takes, where a query per voxel tested the 2-3 cells of rs per axis around
// it, about 4x.
struct RowCandidate {
  double x, yz2;
  uint32_t p;
  int column;  // PointGrid::cellX(x)
};

void rowCandidates(const PointGrid& grid, const BakeGrid& g, int a, int b, int j, int k, double rs,
                   std::vector<RowCandidate>& out) {
  out.clear();
  const Vec3 c0 = g.center(a, j, k), c1 = g.center(b, j, k);
  const double r2 = rs * rs;
  grid.forEachInCells(c0 - Vec3(rs), c1 + Vec3(rs), [&](uint32_t p, const Vec3& q) {
    const double dy = q.y - c0.y, dz = q.z - c0.z, yz2 = dy * dy + dz * dz;
    if (yz2 <= r2) out.push_back({q.x, yz2, p, grid.cellX(q.x)});
  });
}

// A voxel's weighted sums over its points.
struct SplatSums {
  double w = 0, r = 0;
  Rgb co{0.0}, sky{0.0};
  Vec3 l{0.0};
};

// What splatPoints reads and writes.
struct SplatTarget {
  const PointCloudResult& result;
  const std::vector<Rgb>& sky_fraction;  // per point, when there is a sky visibility
  const float* vis;                      // sky visibility per voxel, or null
  bool sky;
  float *co, *ld, *mr, *cs;

  void add(SplatSums& s, uint32_t p, double w) const {
    s.w += w;
    s.co += result.co[p] * w;
    if (sky) s.sky += (vis ? sky_fraction[p] : result.co_sky[p]) * w;
    s.l += result.light_dir[p] * w;
    s.r += double(result.mie_ratio[p]) * w;
  }

  void write(size_t v, const SplatSums& s) const {
    const Rgb cv = s.co / s.w;
    co[3 * v] = float(cv.x);
    co[3 * v + 1] = float(cv.y);
    co[3 * v + 2] = float(cv.z);
    if (sky) {
      const Rgb sv = s.sky / s.w * (vis ? 4 * kPi * (1.0 - vis[v]) : 1.0);
      cs[3 * v] = float(sv.x);
      cs[3 * v + 1] = float(sv.y);
      cs[3 * v + 2] = float(sv.z);
    }
    const double len = length(s.l);
    if (len > 1e-12 * s.w) {
      const Vec3 l = s.l / len;
      ld[3 * v] = float(l.x);
      ld[3 * v + 1] = float(l.y);
      ld[3 * v + 2] = float(l.z);
    }
    mr[v] = float(std::clamp(s.r / s.w, 0.0, 1.0));
  }
};

// A voxel with no point within rs copies the nearest within 3 rs; false when there is none.
bool nearestPoint(const PointGrid& grid, const SplatTarget& t, const Vec3& c, double rs,
                  SplatSums* s) {
  double best = std::numeric_limits<double>::infinity();
  uint32_t nearest = 0;
  grid.forEachWithin(c, 3 * rs, [&](uint32_t p, double d2) {
    if (d2 < best) {
      best = d2;
      nearest = p;
    }
  });
  if (!std::isfinite(best)) return false;
  t.add(*s, nearest, 1.0);
  return true;
}

// Splats row (j, k): the voxels of the support take the Shepard average of their points.
void splatRow(const BakeGrid& g, const uint8_t* support, const PointGrid& grid,
              const SplatTarget& t, double rs, int j, int k, std::vector<RowCandidate>& cand,
              std::vector<PointGrid::Found>& taken) {
  const uint8_t* in = support + g.index(0, j, k);
  int a = 0, b = 0;
  if (!supportSpan(in, g.nx, &a, &b)) return;
  rowCandidates(grid, g, a, b, j, k, rs, cand);
  const double r2 = rs * rs;
  size_t lo = 0, hi = 0;
  for (int i = a; i <= b; ++i) {
    if (!in[i]) continue;
    const Vec3 c = g.center(i, j, k);
    // Columns behind the window are too far for this voxel and every later one.
    const int first = grid.cellX(c.x - rs), last = grid.cellX(c.x + rs);
    while (lo < cand.size() && cand[lo].column < first) ++lo;
    hi = std::max(hi, lo);
    while (hi < cand.size() && cand[hi].column <= last) ++hi;
    // The points within rs first, by a select rather than a branch (a third of the window's
    // candidates are outside, unpredictably), then their sums.
    taken.resize(hi - lo);
    size_t m = 0;
    for (size_t q = lo; q < hi; ++q) {
      const double dx = cand[q].x - c.x, d2 = dx * dx + cand[q].yz2;
      taken[m] = {cand[q].p, d2};
      m += d2 <= r2 ? 1 : 0;
    }
    SplatSums s;
    for (size_t q = 0; q < m; ++q) {
      const double u = 1 - std::sqrt(taken[q].d2) / rs;
      t.add(s, taken[q].index, u * u);
    }
    if (!(s.w > 0) && !nearestPoint(grid, t, c, rs, &s)) continue;
    t.write(g.index(i, j, k), s);
  }
}

}  // namespace

double splatPoints(BakedLight& bake, const PointCloudResult& result,
                   const std::function<bool(double)>& cancelled) {
  const BakeGrid& g = bake.grid;
  const double rs = std::max(2 * result.cloud.spacing, g.voxel_size);
  const std::vector<uint8_t> support = densitySupport(g, bake.density);
  const PointGrid grid(result.cloud.position, rs);
  float* co = bake.add(bake_grids::kMultipleFluence, 3).data.data();
  float* ld = bake.add(bake_grids::kLightDir, 3).data.data();
  float* mr = bake.add(bake_grids::kMieRatio, 1).data.data();
  const bool sky = !result.co_sky.empty();
  float* cs = sky ? bake.add(bake_grids::kSkyMultipleFluence, 3).data.data() : nullptr;
  const BakeChannel* vis_channel = sky ? bake.find(bake_grids::kSkyVisibility) : nullptr;
  const float* vis = vis_channel ? vis_channel->data.data() : nullptr;
  size_t capped = 0;
  const std::vector<Rgb> sky_fraction =
      vis ? skyFractions(g, vis, result, &capped) : std::vector<Rgb>();
  if (vis) bake.metadata["cloudbake:sky_fraction_capped"] = std::to_string(capped);
  const SplatTarget target{result, sky_fraction, vis, sky, co, ld, mr, cs};
  ParallelOptions slices;  // a z slice of rows between cancellation polls
  slices.cancelled = cancelled;
  parallelFor(
      0, g.nz,
      [&](int k) {
        std::vector<RowCandidate> cand;
        std::vector<PointGrid::Found> taken;
        for (int j = 0; j < g.ny; ++j) {
          splatRow(g, support.data(), grid, target, rs, j, k, cand, taken);
        }
      },
      slices);
  return rs;
}

}  // namespace cloudbake
