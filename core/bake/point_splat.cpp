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
// below 1e-9) the point carries no scattered sky light.
std::vector<Rgb> skyFractions(const BakeGrid& g, const float* vis, const PointCloudResult& r) {
  std::vector<Rgb> f(r.co_sky.size(), Rgb(0.0));
  for (size_t p = 0; p < f.size(); ++p) {
    const double removed = 4 * kPi * (1.0 - double(sampleTrilinear(g, vis, r.cloud.position[p])));
    if (removed > 4 * kPi * 1e-9) f[p] = r.co_sky[p] / removed;
  }
  return f;
}

}  // namespace

double splatPoints(BakedLight& bake, const PointCloudResult& result,
                   const std::function<bool(double)>& cancelled) {
  const BakeGrid& g = bake.grid;
  const double rs = std::max(2 * result.cloud.spacing, g.voxel_size);
  const std::vector<uint8_t> support = densitySupport(g, bake.density);
  const std::vector<Vec3>& pos = result.cloud.position;
  const PointGrid grid(pos, rs);
  float* co = bake.add(bake_grids::kMultipleFluence, 3).data.data();
  float* ld = bake.add(bake_grids::kLightDir, 3).data.data();
  float* mr = bake.add(bake_grids::kMieRatio, 1).data.data();
  const bool sky = !result.co_sky.empty();
  float* cs = sky ? bake.add(bake_grids::kSkyMultipleFluence, 3).data.data() : nullptr;
  const BakeChannel* vis_channel = sky ? bake.find(bake_grids::kSkyVisibility) : nullptr;
  const float* vis = vis_channel ? vis_channel->data.data() : nullptr;
  const std::vector<Rgb> sky_fraction = vis ? skyFractions(g, vis, result) : std::vector<Rgb>();
  ParallelOptions rows;
  rows.grain = g.ny;  // a z slice of rows between cancellation polls
  rows.cancelled = cancelled;
  parallelFor(
      0, int64_t(g.nz) * g.ny,
      [&](int64_t row) {
        const int k = int(row / g.ny), j = int(row % g.ny);
        for (int i = 0; i < g.nx; ++i) {
          const size_t v = g.index(i, j, k);
          if (!support[v]) continue;
          const Vec3 c = g.center(i, j, k);
          double wsum = 0, rsum = 0;
          Rgb csum(0.0), ssum(0.0);
          Vec3 lsum(0.0);
          grid.forEachWithin(c, rs, [&](uint32_t p, double d2) {
            const double t = 1 - std::sqrt(d2) / rs;
            const double w = t * t;
            wsum += w;
            csum += result.co[p] * w;
            if (sky) ssum += (vis ? sky_fraction[p] : result.co_sky[p]) * w;
            lsum += result.light_dir[p] * w;
            rsum += double(result.mie_ratio[p]) * w;
          });
          if (!(wsum > 0)) {
            double best = std::numeric_limits<double>::infinity();
            uint32_t nearest = 0;
            grid.forEachWithin(c, 3 * rs, [&](uint32_t p, double d2) {
              if (d2 < best) {
                best = d2;
                nearest = p;
              }
            });
            if (!std::isfinite(best)) continue;
            wsum = 1;
            csum = result.co[nearest];
            if (sky) ssum = vis ? sky_fraction[nearest] : result.co_sky[nearest];
            lsum = result.light_dir[nearest];
            rsum = result.mie_ratio[nearest];
          }
          const Rgb cv = csum / wsum;
          co[3 * v] = float(cv.x);
          co[3 * v + 1] = float(cv.y);
          co[3 * v + 2] = float(cv.z);
          if (sky) {
            const Rgb sv = ssum / wsum * (vis ? 4 * kPi * (1.0 - vis[v]) : 1.0);
            cs[3 * v] = float(sv.x);
            cs[3 * v + 1] = float(sv.y);
            cs[3 * v + 2] = float(sv.z);
          }
          const double len = length(lsum);
          if (len > 1e-12 * wsum) {
            const Vec3 l = lsum / len;
            ld[3 * v] = float(l.x);
            ld[3 * v + 1] = float(l.y);
            ld[3 * v + 2] = float(l.z);
          }
          mr[v] = float(std::clamp(rsum / wsum, 0.0, 1.0));
        }
      },
      rows);
  return rs;
}

}  // namespace cloudbake
