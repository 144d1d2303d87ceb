#include "core/bake/sky_visibility.h"

#include <array>
#include <cmath>
#include <mutex>

#include "core/error.h"
#include "core/math/parallel.h"

namespace cloudbake {
namespace {

// The 26 neighbours' directions with the solid angle of their Voronoi cells on the sphere
// (as fractions of 4 pi). By symmetry there are three values (axes, face diagonals, body
// diagonals); they are measured once by assigning a dense Fibonacci lattice of directions to the
// nearest lattice direction and averaging within each class.
std::array<LatticeDirection, 26> buildDirections() {
  std::array<LatticeDirection, 26> dirs{};
  int n = 0;
  for (int dz = -1; dz <= 1; ++dz)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx)
        if (dx || dy || dz) dirs[size_t(n++)] = {dx, dy, dz, 0.0};
  std::array<Vec3, 26> unit;
  for (size_t d = 0; d < 26; ++d) {
    unit[d] = normalize(Vec3(dirs[d].dx, dirs[d].dy, dirs[d].dz));
  }
  constexpr int kSamples = 1 << 18;
  const double golden = kPi * (3.0 - std::sqrt(5.0));
  std::array<double, 26> count{};
  for (int s = 0; s < kSamples; ++s) {
    const double z = 1.0 - (2.0 * s + 1.0) / kSamples;
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    const Vec3 w(r * std::cos(golden * s), r * std::sin(golden * s), z);
    size_t best = 0;
    double best_dot = -2;
    for (size_t d = 0; d < 26; ++d) {
      const double c = dot(w, unit[d]);
      if (c > best_dot) {
        best_dot = c;
        best = d;
      }
    }
    count[best] += 1;
  }
  // Average within each symmetry class (1, 2 or 3 non-zero components) so the weights are
  // exactly symmetric.
  std::array<double, 4> sum{}, members{};
  for (size_t d = 0; d < 26; ++d) {
    const int cls = std::abs(dirs[d].dx) + std::abs(dirs[d].dy) + std::abs(dirs[d].dz);
    sum[size_t(cls)] += count[d];
    members[size_t(cls)] += 1;
  }
  for (size_t d = 0; d < 26; ++d) {
    const int cls = std::abs(dirs[d].dx) + std::abs(dirs[d].dy) + std::abs(dirs[d].dz);
    dirs[d].weight = sum[size_t(cls)] / members[size_t(cls)] / kSamples;
  }
  return dirs;
}

}  // namespace

const LatticeDirection* latticeDirections() {
  static const std::array<LatticeDirection, 26> dirs = buildDirections();  // thread-safe init
  return dirs.data();
}

void computeSkyVisibility(BakedLight& bake, double extinction, const BakeProgressFn& progress) {
  const BakeGrid& g = bake.grid;
  const size_t n = g.voxelCount();
  const float* rho = bake.density.data();
  std::vector<double> sum(n, 0.0);
  std::vector<float> t(n, 1.f);
  const LatticeDirection* dirs = latticeDirections();
  const int dims[3] = {g.nx, g.ny, g.nz};
  for (int d = 0; d < 26; ++d) {
    const int e[3] = {dirs[d].dx, dirs[d].dy, dirs[d].dz};
    const double seg = extinction * g.voxel_size *
                       std::sqrt(double(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])) * 0.5;
    // The slowest axis with a non-zero step is swept in order (upstream slice first); voxels of
    // one slice depend only on the previous slice, so a slice is done in parallel, in any order:
    // rows along x where the slice has them (c, the inner loop, is the contiguous axis).
    const int a = e[2] ? 2 : (e[1] ? 1 : 0);
    const int c = a == 0 ? 1 : 0, b = 3 - a - c;
    for (int s = 0; s < dims[a]; ++s) {
      const int ia = e[a] > 0 ? dims[a] - 1 - s : s;  // upstream (towards +e) first
      parallelFor(0, dims[b], [&](int ib) {
        int idx[3];
        idx[a] = ia;
        idx[b] = ib;
        // Piecewise-constant densities (a mesh's inside) repeat tau along a row: its exp is
        // reused, the same value as computed afresh.
        double last_tau = -1, last_exp = 1;
        for (int ic = 0; ic < dims[c]; ++ic) {
          idx[c] = ic;
          const size_t v = g.index(idx[0], idx[1], idx[2]);
          const int ux = idx[0] + e[0], uy = idx[1] + e[1], uz = idx[2] + e[2];
          float tv = 1.f;
          if (ux >= 0 && uy >= 0 && uz >= 0 && ux < g.nx && uy < g.ny && uz < g.nz) {
            const size_t u = g.index(ux, uy, uz);
            const double tau = seg * (double(rho[v]) + rho[u]);
            if (tau > 0 && tau != last_tau) {
              last_tau = tau;
              last_exp = std::exp(-tau);
            }
            tv = tau > 0 ? float(t[u] * last_exp) : t[u];
          } else if (rho[v] > 0) {
            // The last voxel before leaving the lattice: half a segment of its own density.
            tv = float(std::exp(-seg * rho[v]));
          }
          t[v] = tv;
        }
      });
    }
    const double w = dirs[d].weight;
    parallelFor(0, int64_t(n), [&](size_t v) { sum[v] += w * t[v]; }, {kCheapIterationGrain});
    if (progress && !progress((d + 1) / 26.0, "sky visibility")) {
      throw Cancelled("bake cancelled while computing the sky visibility");
    }
  }
  BakeChannel& out = bake.add(bake_grids::kSkyVisibility, 1);
  for (size_t v = 0; v < n; ++v) out.data[v] = float(std::min(1.0, std::max(0.0, sum[v])));
}

}  // namespace cloudbake
