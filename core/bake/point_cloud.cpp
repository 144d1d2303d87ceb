#include "core/bake/point_cloud.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "core/math/parallel.h"
#include "core/math/rng.h"

namespace cloudbake {

PointCloud placePoints(const BakeGrid& grid, const std::vector<float>& density, int n,
                       uint64_t seed) {
  PointCloud cloud;
  double total = 0;  // sum of voxel densities; the mass is total * h^3
  for (const float d : density) {
    if (d > 0) {
      total += d;
      ++cloud.occupied_voxels;
    }
  }
  if (!(total > 0) || !std::isfinite(total) || n < 1) {
    throw InputError(
        "volume: empty (no voxel of the bake lattice has density > 0): no points can be placed");
  }
  const double h = grid.voxel_size;
  cloud.mass = total * h * h * h / n;
  cloud.spacing = std::cbrt(double(cloud.occupied_voxels) * h * h * h / n);

  // Systematic sampling: one random offset, then every M/n of mass. Voxel indices first, so the
  // jitter below can run in parallel.
  Rng offset_rng(mixBits(seed, uint64_t(1) << 40));
  const double u0 = offset_rng.uniform();
  const double step = total / n;
  std::vector<uint32_t> voxel_of(size_t(n), 0);
  size_t voxel_count = density.size();
  size_t last_occupied = 0;
  double running = 0;
  int j = 0;
  for (size_t v = 0; v < voxel_count && j < n; ++v) {
    const float d = density[v];
    if (!(d > 0)) continue;
    last_occupied = v;
    running += d;
    while (j < n && (j + u0) * step < running) voxel_of[size_t(j++)] = uint32_t(v);
  }
  // Rounding can leave the last threshold a hair above the final running sum.
  for (; j < n; ++j) voxel_of[size_t(j)] = uint32_t(last_occupied);

  cloud.position.resize(size_t(n));
  cloud.density.resize(size_t(n));
  const size_t nxy = size_t(grid.nx) * size_t(grid.ny);
  parallelFor(0, n,
              [&](size_t p) {
                const size_t v = voxel_of[p];
                const int k = int(v / nxy), jj = int((v % nxy) / size_t(grid.nx)),
                          i = int(v % size_t(grid.nx));
                Rng rng(mixBits(seed, p));
                const double ux = rng.uniform(), uy = rng.uniform(), uz = rng.uniform();
                const Vec3 pos = grid.center(i, jj, k) + Vec3(ux - 0.5, uy - 0.5, uz - 0.5) * h;
                cloud.position[p] = pos;
                // Inside its own voxel the trilinear weight of that voxel is >= 1/8, so D > 0; the
                // floor only guards denormal densities.
                const float dv = sampleTrilinear(grid, density.data(), pos);
                cloud.density[p] = std::max(dv, 0.125f * density[v]);
                if (!(cloud.density[p] > 0)) cloud.density[p] = 1e-30f;
              },
              {kCheapIterationGrain});
  return cloud;
}

void computePointSunTransmittance(PointCloud& cloud, const BakeGrid& grid,
                                  const std::vector<float>& density, double extinction,
                                  const Vec3& sun_dir, double step,
                                  const std::function<bool(double)>& cancelled) {
  cloud.sun.assign(cloud.size(), 0.f);
  const TransmittanceMarcher march(grid, density.data(), extinction);
  ParallelOptions chunks;
  chunks.cancelled = cancelled;
  parallelFor(
      0, int64_t(cloud.size()),
      [&](size_t p) { cloud.sun[p] = float(march(cloud.position[p], sun_dir, step)); }, chunks);
}

}  // namespace cloudbake
