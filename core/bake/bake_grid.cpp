#include "core/bake/bake_grid.h"

#include <algorithm>
#include <cmath>

#include "core/math/parallel.h"

namespace cloudbake {

void sampleTrilinear(const BakeGrid& g, const float* data, int components, const Vec3& p,
                     float* out) {
  for (int c = 0; c < components; ++c) out[c] = 0.f;
  const Vec3 u = g.toIndex(p);
  const double fx = std::floor(u.x), fy = std::floor(u.y), fz = std::floor(u.z);
  // Far outside (or NaN): nothing to read. Keeps the int conversions below in range.
  if (!(fx >= -1 && fy >= -1 && fz >= -1 && fx < g.nx && fy < g.ny && fz < g.nz)) return;
  const int i0 = int(fx), j0 = int(fy), k0 = int(fz);
  const double tx = u.x - fx, ty = u.y - fy, tz = u.z - fz;
  for (int dk = 0; dk < 2; ++dk) {
    const int k = k0 + dk;
    if (k < 0 || k >= g.nz) continue;
    const double wz = dk ? tz : 1 - tz;
    for (int dj = 0; dj < 2; ++dj) {
      const int j = j0 + dj;
      if (j < 0 || j >= g.ny) continue;
      const double wyz = wz * (dj ? ty : 1 - ty);
      for (int di = 0; di < 2; ++di) {
        const int i = i0 + di;
        if (i < 0 || i >= g.nx) continue;
        const float w = float(wyz * (di ? tx : 1 - tx));
        if (w == 0.f) continue;
        const float* v = data + g.index(i, j, k) * size_t(components);
        for (int c = 0; c < components; ++c) out[c] += w * v[c];
      }
    }
  }
}

float sampleTrilinear(const BakeGrid& grid, const float* data, const Vec3& p) {
  float v;
  sampleTrilinear(grid, data, 1, p, &v);
  return v;
}

std::vector<float> resampleTrilinear(const BakeGrid& from, const float* data, int components,
                                     const BakeGrid& to) {
  std::vector<float> out(to.voxelCount() * size_t(components));
  parallelFor(0, to.nz, [&](int k) {
    for (int j = 0; j < to.ny; ++j) {
      for (int i = 0; i < to.nx; ++i) {
        sampleTrilinear(from, data, components, to.center(i, j, k),
                        out.data() + to.index(i, j, k) * size_t(components));
      }
    }
  });
  return out;
}

double marchTransmittance(const BakeGrid& grid, const float* density, double extinction,
                          const Vec3& p, const Vec3& dir, double step) {
  double t0 = 0, t1 = 0;
  if (!(step > 0) || extinction <= 0) return 1.0;
  if (!intersectBounds(grid.bounds(), Ray{p, dir}, 0.0, 1e300, &t0, &t1)) return 1.0;
  const double length = t1 - t0;
  const int n = std::max(1, int(std::ceil(length / step)));
  const double dt = length / n;
  double tau = 0;
  double prev = sampleTrilinear(grid, density, p + dir * t0);
  for (int s = 1; s <= n; ++s) {
    const double cur = sampleTrilinear(grid, density, p + dir * (t0 + s * dt));
    tau += 0.5 * (prev + cur) * dt * extinction;
    prev = cur;
    if (tau > 16.2) return 0.0;  // exp(-16.2) < 1e-7
  }
  return std::exp(-tau);
}

}  // namespace cloudbake
