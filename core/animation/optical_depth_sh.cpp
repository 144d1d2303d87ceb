#include "core/animation/optical_depth_sh.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "core/error.h"

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
  const int up = w[a] > 0 ? 1 : -1;                 // the upstream slice along a
  const double ub = w[b] / std::abs(w[a]), uc = w[c] / std::abs(w[a]);  // offsets in b, c
  const double seg = extinction * g.voxel_size / std::abs(w[a]) * 0.5;  // half a step's tau per
                                                                         // unit density
  std::vector<float> tau(g.voxelCount(), 0.f);
  auto index = [&](int ia, int ib, int ic) {
    int ijk[3];
    ijk[a] = ia;
    ijk[b] = ib;
    ijk[c] = ic;
    return g.index(ijk[0], ijk[1], ijk[2]);
  };
  // Bilinear read of `values` in slice `ia` at fractional (fb, fc); 0 outside.
  auto bilinear = [&](const float* values, int ia, double fb, double fc) {
    const double b0 = std::floor(fb), c0 = std::floor(fc);
    const double tb = fb - b0, tc = fc - c0;
    double sum = 0;
    for (int db = 0; db < 2; ++db)
      for (int dc = 0; dc < 2; ++dc) {
        const int ib = int(b0) + db, ic = int(c0) + dc;
        if (ib < 0 || ic < 0 || ib >= dims[b] || ic >= dims[c]) continue;
        sum += (db ? tb : 1 - tb) * (dc ? tc : 1 - tc) * values[index(ia, ib, ic)];
      }
    return sum;
  };
  for (int s = 0; s < dims[a]; ++s) {
    const int ia = up > 0 ? dims[a] - 1 - s : s;
    const int iu = ia + up;
    const bool inside = iu >= 0 && iu < dims[a];
    tbb::parallel_for(tbb::blocked_range<int>(0, dims[b]), [&](const tbb::blocked_range<int>& r) {
      for (int ib = r.begin(); ib != r.end(); ++ib) {
        for (int ic = 0; ic < dims[c]; ++ic) {
          const size_t v = index(ia, ib, ic);
          double t = 0, rho_up = 0;
          if (inside) {
            t = bilinear(tau.data(), iu, ib + ub, ic + uc);
            rho_up = bilinear(density.data(), iu, ib + ub, ic + uc);
          }
          tau[v] = float(t + seg * (double(density[v]) + rho_up));
        }
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
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 4096), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t v = r.begin(); v != r.end(); ++v) {
        const double t = tau[v] * weight;
        if (t == 0) continue;
        for (int i = 0; i < kShCoefficients; ++i) acc[v * kShCoefficients + size_t(i)] += t * y[size_t(i)];
      }
    });
    if (progress && !progress(double(d + 1) / directions)) throw Cancelled();
  }
  for (size_t v = 0; v < n; ++v)
    for (int i = 0; i < kShCoefficients; ++i) out[v][size_t(i)] = float(acc[v * kShCoefficients + size_t(i)]);
  return out;
}

}  // namespace cloudbake
