#include "core/bake/sky_visibility.h"

#include <array>
#include <cmath>
#include <mutex>
#include <string>
#include <vector>

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

namespace {

// One slice of one direction's sweep for every extinction: t[x] of the voxels with index ia
// along axis a from their upstream neighbours (offset e), rows along axis c.
struct SweepSlice {
  const BakeGrid& g;
  const float* rho;
  const int* e;
  int a, b, c;
  const std::vector<double>& seg;      // per extinction: extinction x half the step length
  std::vector<std::vector<float>>& t;  // per extinction
};

// K extinctions (1 or 2), a compile-time count so that one extinction's loop is as tight as it
// was alone.
template <size_t K>
void sweepRow(const SweepSlice& sl, int ia, int ib) {
  const BakeGrid& g = sl.g;
  const int dims[3] = {g.nx, g.ny, g.nz};
  float* ts[K];
  double seg[K];
  for (size_t x = 0; x < K; ++x) {
    ts[x] = sl.t[x].data();
    seg[x] = sl.seg[x];
  }
  int idx[3];
  idx[sl.a] = ia;
  idx[sl.b] = ib;
  // Piecewise-constant densities (a mesh's inside) repeat tau along a row: its exp is reused,
  // the same value as computed afresh.
  double last_tau[K], last_exp[K];
  for (size_t x = 0; x < K; ++x) {
    last_tau[x] = -1;
    last_exp[x] = 1;
  }
  for (int ic = 0; ic < dims[sl.c]; ++ic) {
    idx[sl.c] = ic;
    const size_t v = g.index(idx[0], idx[1], idx[2]);
    const int ux = idx[0] + sl.e[0], uy = idx[1] + sl.e[1], uz = idx[2] + sl.e[2];
    const bool inside = ux >= 0 && uy >= 0 && uz >= 0 && ux < g.nx && uy < g.ny && uz < g.nz;
    const size_t u = inside ? g.index(ux, uy, uz) : 0;
    for (size_t x = 0; x < K; ++x) {
      float* t = ts[x];
      float tv = 1.f;
      if (inside) {
        const double tau = seg[x] * (double(sl.rho[v]) + sl.rho[u]);
        if (tau > 0 && tau != last_tau[x]) {
          last_tau[x] = tau;
          last_exp[x] = std::exp(-tau);
        }
        tv = tau > 0 ? float(t[u] * last_exp[x]) : t[u];
      } else if (sl.rho[v] > 0) {
        // The last voxel before leaving the lattice: half a segment of its own density.
        tv = float(std::exp(-seg[x] * sl.rho[v]));
      }
      t[v] = tv;
    }
  }
}

}  // namespace

std::vector<std::vector<float>> skyVisibilities(const BakeGrid& g, const float* rho,
                                                const std::vector<double>& extinctions,
                                                const BakeProgressFn& progress) {
  if (extinctions.empty() || extinctions.size() > 2) {
    throw InternalError("skyVisibilities: one or two extinctions, got " +
                        std::to_string(extinctions.size()));
  }
  const size_t n = g.voxelCount(), k = extinctions.size();
  std::vector<std::vector<double>> sum(k, std::vector<double>(n, 0.0));
  std::vector<std::vector<float>> t(k, std::vector<float>(n, 1.f));
  std::vector<double> seg(k);
  const LatticeDirection* dirs = latticeDirections();
  const int dims[3] = {g.nx, g.ny, g.nz};
  for (int d = 0; d < 26; ++d) {
    const int e[3] = {dirs[d].dx, dirs[d].dy, dirs[d].dz};
    for (size_t x = 0; x < k; ++x) {
      seg[x] = extinctions[x] * g.voxel_size *
               std::sqrt(double(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])) * 0.5;
    }
    // The slowest axis with a non-zero step is swept in order (upstream slice first); voxels of
    // one slice depend only on the previous slice, so a slice is done in parallel, in any order:
    // rows along x where the slice has them (c, the inner loop, is the contiguous axis).
    const int a = e[2] ? 2 : (e[1] ? 1 : 0);
    const int c = a == 0 ? 1 : 0, b = 3 - a - c;
    const SweepSlice slice{g, rho, e, a, b, c, seg, t};
    for (int s = 0; s < dims[a]; ++s) {
      const int ia = e[a] > 0 ? dims[a] - 1 - s : s;  // upstream (towards +e) first
      parallelFor(0, dims[b], [&](int ib) {
        if (k == 1) {
          sweepRow<1>(slice, ia, ib);
        } else {
          sweepRow<2>(slice, ia, ib);
        }
      });
    }
    const double w = dirs[d].weight;
    for (size_t x = 0; x < k; ++x) {
      double* sx = sum[x].data();
      const float* tx = t[x].data();
      parallelFor(0, int64_t(n), [&](size_t v) { sx[v] += w * tx[v]; }, {kCheapIterationGrain});
    }
    if (progress && !progress((d + 1) / 26.0, "sky visibility")) {
      throw Cancelled("bake cancelled while computing the sky visibility");
    }
  }
  std::vector<std::vector<float>> out(k, std::vector<float>(n));
  for (size_t x = 0; x < k; ++x) {
    for (size_t v = 0; v < n; ++v) out[x][v] = float(std::min(1.0, std::max(0.0, sum[x][v])));
  }
  return out;
}

void computeSkyVisibility(BakedLight& bake, double extinction, const BakeProgressFn& progress) {
  std::vector<std::vector<float>> v =
      skyVisibilities(bake.grid, bake.density.data(), {extinction}, progress);
  bake.add(bake_grids::kSkyVisibility, 1).data = std::move(v[0]);
}

}  // namespace cloudbake
