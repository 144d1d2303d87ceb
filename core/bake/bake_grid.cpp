#include "core/bake/bake_grid.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/math/parallel.h"
#include "core/math/vector_clones.h"

namespace cloudbake {

void sampleTrilinear(const BakeGrid& g, const float* data, int components, const Vec3& p,
                     float* out) {
  sampleTrilinearAtIndex(g, data, components, g.toIndex(p), out);
}

void sampleTrilinearAtIndex(const BakeGrid& g, const float* data, int components, const Vec3& u,
                            float* out) {
  for (int c = 0; c < components; ++c) out[c] = 0.f;
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

float sampleTrilinearAtIndex(const BakeGrid& grid, const float* data, const Vec3& u) {
  float v;
  sampleTrilinearAtIndex(grid, data, 1, u, &v);
  return v;
}

float sampleTrilinear(const BakeGrid& grid, const float* data, const Vec3& p) {
  float v;
  sampleTrilinear(grid, data, 1, p, &v);
  return v;
}

namespace {

// The lattice voxels along one axis that overlap each voxel of a coarser lattice over the same
// bounds, with the share of the coarse voxel's width each covers.
std::vector<std::vector<std::pair<int, double>>> axisOverlaps(double origin, double h, int n,
                                                              double coarse_origin, double coarse_h,
                                                              int coarse_n) {
  std::vector<std::vector<std::pair<int, double>>> out(static_cast<size_t>(coarse_n));
  for (int t = 0; t < coarse_n; ++t) {
    const double lo = coarse_origin + (t - 0.5) * coarse_h, hi = lo + coarse_h;
    const int first = std::max(0, int(std::floor((lo - origin) / h + 0.5)));
    const int last = std::min(n - 1, int(std::floor((hi - origin) / h + 0.5)));
    for (int i = first; i <= last; ++i) {
      const double a = origin + (i - 0.5) * h, b = a + h;
      const double overlap = std::min(hi, b) - std::max(lo, a);
      if (overlap > 0) out[size_t(t)].push_back({i, overlap / coarse_h});
    }
  }
  return out;
}

}  // namespace

std::vector<float> boxMean(const BakeGrid& fine, const float* values, const BakeGrid& coarse) {
  const auto ox = axisOverlaps(fine.origin.x, fine.voxel_size, fine.nx, coarse.origin.x,
                               coarse.voxel_size, coarse.nx);
  const auto oy = axisOverlaps(fine.origin.y, fine.voxel_size, fine.ny, coarse.origin.y,
                               coarse.voxel_size, coarse.ny);
  const auto oz = axisOverlaps(fine.origin.z, fine.voxel_size, fine.nz, coarse.origin.z,
                               coarse.voxel_size, coarse.nz);
  std::vector<float> out(coarse.voxelCount(), 0.f);
  parallelFor(0, coarse.nz, [&](int64_t k) {
    for (int j = 0; j < coarse.ny; ++j) {
      for (int i = 0; i < coarse.nx; ++i) {
        double sum = 0;
        for (const auto& [z, wz] : oz[size_t(k)]) {
          for (const auto& [y, wy] : oy[size_t(j)]) {
            for (const auto& [x, wx] : ox[size_t(i)]) {
              sum += wx * wy * wz * values[fine.index(x, y, z)];
            }
          }
        }
        out[coarse.index(i, j, int(k))] = float(sum);
      }
    }
  });
  return out;
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

namespace {

// marchTransmittance's march with the density read by `sample(index point)`. Samples are
// stepped in index coordinates, u(t) = u(p) + t dir / voxel_size: three divisions a ray where a
// world point's conversion took three a sample.
template <class Sample>
double marchWith(const BakeGrid& grid, double extinction, const Vec3& p, const Vec3& dir,
                 double step, Sample&& sample) {
  double t0 = 0, t1 = 0;
  if (!(step > 0) || extinction <= 0) return 1.0;
  if (!intersectBounds(grid.bounds(), Ray{p, dir}, 0.0, 1e300, &t0, &t1)) return 1.0;
  const double length = t1 - t0;
  const int n = std::max(1, int(std::ceil(length / step)));
  const double dt = length / n;
  const Vec3 u0 = grid.toIndex(p), du = dir / grid.voxel_size;
  double tau = 0;
  double prev = sample(u0 + du * t0);
  for (int s = 1; s <= n; ++s) {
    const double cur = sample(u0 + du * (t0 + s * dt));
    tau += 0.5 * (prev + cur) * dt * extinction;
    prev = cur;
    if (tau > 16.2) return 0.0;  // exp(-16.2) < 1e-7
  }
  return std::exp(-tau);
}

}  // namespace

double marchTransmittance(const BakeGrid& grid, const float* density, double extinction,
                          const Vec3& p, const Vec3& dir, double step) {
  return marchWith(grid, extinction, p, dir, step,
                   [&](const Vec3& u) { return sampleTrilinearAtIndex(grid, density, u); });
}

TransmittanceMarcher::TransmittanceMarcher(const BakeGrid& grid, const float* density,
                                           double extinction)
    : grid_(grid), density_(density), extinction_(extinction) {
  // Block b holds the lookups with floor(index) in [8b - 1, 8b + 6], which read voxels
  // 8b - 1 .. 8b + 7.
  nbx_ = (grid.nx + kBlock) / kBlock;
  nby_ = (grid.ny + kBlock) / kBlock;
  nbz_ = (grid.nz + kBlock) / kBlock;
  occupied_.assign(size_t(nbx_) * size_t(nby_) * size_t(nbz_), 0);
  parallelFor(0, nbz_, [&](int bk) {
    const int k0 = std::max(0, kBlock * bk - 1), k1 = std::min(grid.nz - 1, kBlock * bk + 7);
    for (int bj = 0; bj < nby_; ++bj) {
      const int j0 = std::max(0, kBlock * bj - 1), j1 = std::min(grid.ny - 1, kBlock * bj + 7);
      for (int bi = 0; bi < nbx_; ++bi) {
        const int i0 = std::max(0, kBlock * bi - 1), i1 = std::min(grid.nx - 1, kBlock * bi + 7);
        bool any = false;
        for (int k = k0; k <= k1 && !any; ++k) {
          for (int j = j0; j <= j1 && !any; ++j) {
            const float* row = density + grid.index(0, j, k);
            for (int i = i0; i <= i1; ++i) any = any || row[i] != 0.f;
          }
        }
        occupied_[(size_t(bk) * size_t(nby_) + size_t(bj)) * size_t(nbx_) + size_t(bi)] = any;
      }
    }
  });
}

float TransmittanceMarcher::density(const Vec3& p) const {
  return densityAtIndex(grid_.toIndex(p));
}

float TransmittanceMarcher::densityAtIndex(const Vec3& u) const {
  const BakeGrid& g = grid_;
  const double fx = std::floor(u.x), fy = std::floor(u.y), fz = std::floor(u.z);
  if (!(fx >= -1 && fy >= -1 && fz >= -1 && fx < g.nx && fy < g.ny && fz < g.nz)) return 0.f;
  const int i0 = int(fx), j0 = int(fy), k0 = int(fz);
  const size_t block =
      (size_t((k0 + 1) / kBlock) * size_t(nby_) + size_t((j0 + 1) / kBlock)) * size_t(nbx_) +
      size_t((i0 + 1) / kBlock);
  if (!occupied_[block]) return 0.f;
  if (i0 < 0 || j0 < 0 || k0 < 0 || i0 + 1 >= g.nx || j0 + 1 >= g.ny || k0 + 1 >= g.nz) {
    return sampleTrilinearAtIndex(g, density_, u);
  }
  // sampleTrilinear's sum, in its order, without its bounds checks.
  const double t[3] = {u.x - fx, u.y - fy, u.z - fz};
  const size_t sy = size_t(g.nx), sz = size_t(g.nx) * size_t(g.ny);
  const float* base = density_ + g.index(i0, j0, k0);
  float out = 0.f;
  for (int dk = 0; dk < 2; ++dk) {
    const double wz = dk ? t[2] : 1 - t[2];
    for (int dj = 0; dj < 2; ++dj) {
      const double wyz = wz * (dj ? t[1] : 1 - t[1]);
      const float* row = base + size_t(dk) * sz + size_t(dj) * sy;
      for (int di = 0; di < 2; ++di) {
        const float w = float(wyz * (di ? t[0] : 1 - t[0]));
        if (w == 0.f) continue;
        out += w * row[di];
      }
    }
  }
  return out;
}

CLOUDBAKE_VECTOR_CLONES int TransmittanceMarcher::stepsInEmptyBlock(const Vec3& u, const Vec3& du,
                                                                    double dt) const {
  const BakeGrid& g = grid_;
  const int n[3] = {g.nx, g.ny, g.nz};
  double exit = std::numeric_limits<double>::infinity();  // world units along dir
  size_t block = 0;
  const size_t nb[3] = {size_t(nbx_), size_t(nby_), size_t(nbz_)};
  for (int a = 2; a >= 0; --a) {
    const double f = std::floor(u[a]);
    if (!(f >= -1 && f < n[a])) return 0;
    const int b = (int(f) + 1) / kBlock;
    block = block * nb[a] + size_t(b);
    // The block holds the lookups with index in [8b - 1, 8b + 7) along each axis.
    const double v = du[a];
    if (v > 0) exit = std::min(exit, (kBlock * b + 7 - u[a]) / v);
    if (v < 0) exit = std::min(exit, (kBlock * b - 1 - u[a]) / v);
  }
  if (occupied_[block]) return 0;
  // A margin of 1e-6 step keeps every sample counted inside the block despite rounding.
  const double k = std::floor(exit / dt - 1e-6);
  return k >= 1 ? int(std::min(k, 1e9)) : 0;
}

CLOUDBAKE_VECTOR_CLONES double TransmittanceMarcher::operator()(const Vec3& p, const Vec3& dir,
                                                                double step) const {
  // marchTransmittance's march; runs of samples inside an empty block add exactly 0 to tau and
  // are stepped over. Its three floors a sample are one instruction each in the AVX2 clone: the
  // bunny's sun transmittance 0.63 -> 0.51 s.
  double t0 = 0, t1 = 0;
  if (!(step > 0) || extinction_ <= 0) return 1.0;
  if (!intersectBounds(grid_.bounds(), Ray{p, dir}, 0.0, 1e300, &t0, &t1)) return 1.0;
  const double length = t1 - t0;
  const int n = std::max(1, int(std::ceil(length / step)));
  const double dt = length / n;
  const Vec3 u0 = grid_.toIndex(p), du = dir / grid_.voxel_size;  // as marchWith
  double tau = 0;
  double prev = densityAtIndex(u0 + du * t0);
  for (int s = 1; s <= n; ++s) {
    const Vec3 u = u0 + du * (t0 + s * dt);
    const double cur = densityAtIndex(u);
    if (cur == 0 && prev == 0) {
      s += std::min(stepsInEmptyBlock(u, du, dt), n - s);
      continue;
    }
    tau += 0.5 * (prev + cur) * dt * extinction_;
    prev = cur;
    if (tau > 16.2) return 0.0;  // as marchTransmittance
  }
  return std::exp(-tau);
}

}  // namespace cloudbake
