#include "core/animation/optical_depth_sh.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/error.h"
#include "core/math/parallel.h"

namespace cloudbake {

std::vector<Vec3> sphereDirections(int n) {
  std::vector<Vec3> dirs;
  dirs.reserve(size_t(std::max(n, 0)));
  const double golden = kPi * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - (2.0 * i + 1.0) / n;
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    dirs.emplace_back(r * std::cos(golden * i), r * std::sin(golden * i), z);
  }
  return dirs;
}

std::vector<float> sweepOpticalDepth(const BakeGrid& g, const std::vector<float>& density,
                                     double extinction, const Vec3& w) {
  const int dims[3] = {g.nx, g.ny, g.nz};
  int a = 0;
  for (int c = 1; c < 3; ++c) {
    if (std::abs(w[c]) > std::abs(w[a])) a = c;
  }
  const int b = (a + 1) % 3, c = (a + 2) % 3;
  const int up = w[a] > 0 ? 1 : -1;  // the upstream slice along a
  const double ub = w[b] / std::abs(w[a]), uc = w[c] / std::abs(w[a]);  // offsets in b, c
  const double seg = extinction * g.voxel_size / std::abs(w[a]) * 0.5;  // half a step's tau per
                                                                        // unit density
  std::vector<float> tau(g.voxelCount(), 0.f);
  const size_t stride[3] = {1, size_t(g.nx), size_t(g.nx) * size_t(g.ny)};
  const size_t sa = stride[a], sb = stride[b], sc = stride[c];
  // The upstream point of voxel (ib, ic) is (ib + ub, ic + uc) in the upstream slice: the same
  // fractional offset for every voxel, so the bilinear weights are constants of the sweep.
  const int ob = int(std::floor(ub)), oc = int(std::floor(uc));
  const double tb = ub - ob, tc = uc - oc;
  const double wq[4] = {(1 - tb) * (1 - tc), (1 - tb) * tc, tb * (1 - tc), tb * tc};
  for (int s = 0; s < dims[a]; ++s) {
    const int ia = up > 0 ? dims[a] - 1 - s : s;
    const int iu = ia + up;
    const bool inside = iu >= 0 && iu < dims[a];
    parallelFor(0, dims[b], [&](int ib) {
      const size_t row = size_t(ia) * sa + size_t(ib) * sb;
      for (int ic = 0; ic < dims[c]; ++ic) {
        const size_t v = row + size_t(ic) * sc;
        double t = 0, rho_up = 0;
        if (inside) {
          // Corners (ib + ob + db, ic + oc + dc), db, dc in {0, 1}; outside the lattice is 0.
          for (int q = 0; q < 4; ++q) {
            const int jb = ib + ob + (q >> 1), jc = ic + oc + (q & 1);
            if (jb < 0 || jc < 0 || jb >= dims[b] || jc >= dims[c]) continue;
            const size_t u = size_t(iu) * sa + size_t(jb) * sb + size_t(jc) * sc;
            t += wq[q] * tau[u];
            rho_up += wq[q] * density[u];
          }
        }
        tau[v] = float(t + seg * (double(density[v]) + rho_up));
      }
    });
  }
  return tau;
}

std::vector<ShCoefficients> projectOpticalDepth(const BakeGrid& grid,
                                                const std::vector<float>& density,
                                                double extinction, int directions,
                                                const std::function<bool(double)>& progress) {
  if (directions < 16 || directions > 100000) {
    throw InputError("directions: SH of order 4 need at least 16 (and at most 100000), got " +
                     std::to_string(directions));
  }
  if (density.size() != grid.voxelCount()) {
    throw InputError("optical depth: density of " + std::to_string(density.size()) +
                     " voxels on a lattice of " + std::to_string(grid.voxelCount()));
  }
  const std::vector<Vec3> dirs = sphereDirections(directions);
  const double weight = 4 * kPi / directions;
  const size_t n = grid.voxelCount();
  std::vector<ShCoefficients> out(n, ShCoefficients{});
  std::vector<double> acc(n * kShCoefficients, 0.0);
  // Directions in sequence (each sweep is parallel inside); accumulation in a fixed order keeps
  // the result independent of the thread count.
  for (int d = 0; d < directions; ++d) {
    const std::vector<float> tau = sweepOpticalDepth(grid, density, extinction, dirs[size_t(d)]);
    const auto y = shBasis(dirs[size_t(d)]);
    parallelFor(0, int64_t(n),
                [&](size_t v) {
                  const double t = tau[v] * weight;
                  if (t == 0) return;
                  for (int i = 0; i < kShCoefficients; ++i)
                    acc[v * kShCoefficients + size_t(i)] += t * y[size_t(i)];
                },
                {kCheapIterationGrain});
    if (progress && !progress(double(d + 1) / directions)) throw Cancelled();
  }
  for (size_t v = 0; v < n; ++v)
    for (int i = 0; i < kShCoefficients; ++i)
      out[v][size_t(i)] = float(acc[v * kShCoefficients + size_t(i)]);
  return out;
}

}  // namespace cloudbake
