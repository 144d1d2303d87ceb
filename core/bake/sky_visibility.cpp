#include "core/bake/sky_visibility.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/math/parallel.h"
#include "core/math/vector_clones.h"

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

// exp(-seg x rho[v]) for every voxel: half a segment's transmittance from the voxel's centre, so
// that a whole segment between neighbours u and v is e[u] e[v], the exact trapezoid of the two.
// A run of equal densities (a mesh's inside, empty space) reuses one exponential.
void halfSegments(const float* rho, size_t n, double seg, float* e) {
  const int64_t chunks = int64_t((n + kCheapIterationGrain - 1) / kCheapIterationGrain);
  parallelFor(0, chunks, [&](int64_t c) {
    const size_t v0 = size_t(c) * kCheapIterationGrain;
    const size_t v1 = std::min(n, v0 + size_t(kCheapIterationGrain));
    float last_rho = 0.f, last = 1.f;
    for (size_t v = v0; v < v1; ++v) {
      if (rho[v] != last_rho) {
        last_rho = rho[v];
        last = float(std::exp(-seg * double(rho[v])));
      }
      e[v] = last;
    }
  });
}

// Where one direction's weighted transmittances go: the visibility's sum and, when `b` is set,
// the vector's three sums (one array each, so a row's adds vectorise), at a row's first voxel.
struct RowSums {
  double* v;
  float* b[3];
};

// What one direction adds to the sums: its weight, and its weight times its unit vector.
struct DirectionWeights {
  double w;
  float wb[3];
};

// Adds a row's weighted transmittances `tv` to the sums.
CLOUDBAKE_VECTOR_CLONES void addRow(const float* __restrict tv, int nx, const DirectionWeights& dw,
                                    const RowSums& s) {
  double* __restrict v = s.v;
  for (int i = 0; i < nx; ++i) v[i] += dw.w * double(tv[i]);
  if (!s.b[0]) return;
  for (int a = 0; a < 3; ++a) {
    float* __restrict b = s.b[a];
    const float wa = dw.wb[a];
    for (int i = 0; i < nx; ++i) b[i] += wa * tv[i];
  }
}

// One row of voxels along x, each from its upstream neighbour x + ex in the upstream row `tu`
// (null where that row lies outside the lattice: then every voxel is the last before leaving,
// half a segment of its own density), and its weighted value added to the row's sums.
CLOUDBAKE_VECTOR_CLONES void sweepRowX(const float* __restrict ev, const float* __restrict eu,
                                       const float* __restrict tu, int nx, int ex,
                                       const DirectionWeights& dw, float* __restrict tv,
                                       const RowSums& sums) {
  int lo = 0, hi = nx;  // voxels whose upstream neighbour is in the row
  if (!tu) {
    hi = 0;
  } else if (ex > 0) {
    hi = nx - 1;
  } else if (ex < 0) {
    lo = 1;
  }
  for (int i = 0; i < lo; ++i) tv[i] = ev[i];
  for (int i = lo; i < hi; ++i) tv[i] = tu[i + ex] * (ev[i] * eu[i + ex]);
  for (int i = std::max(hi, lo); i < nx; ++i) tv[i] = ev[i];
  addRow(tv, nx, dw, sums);
}

// Direction (+-1, 0, 0): the row's own voxels are upstream of each other, so it runs in order.
void sweepAlongX(const float* ev, int nx, int ex, const DirectionWeights& dw, float* tv,
                 const RowSums& sums) {
  const int first = ex > 0 ? nx - 1 : 0;
  tv[first] = ev[first];
  for (int n = 1; n < nx; ++n) {
    const int i = ex > 0 ? nx - 1 - n : n, u = i + ex;
    tv[i] = tv[u] * (ev[i] * ev[u]);
  }
  addRow(tv, nx, dw, sums);
}

// One direction's sweep for one extinction: t over the lattice and w t added to `sum`. A row
// along x depends only on its upstream row, one slice further along the slowest axis with a
// non-zero step, so the rows form independent chains: each starts at a row whose upstream lies
// outside the lattice and runs downstream. One task per chain: no wait between slices, which
// cost the sweep half its scaling to two threads.
void sweepDirection(const BakeGrid& g, const LatticeDirection& d, const float* e, float* t,
                    double* sum, float* const* b) {
  const int nx = g.nx, ny = g.ny, nz = g.nz;
  DirectionWeights dw{d.weight, {}};
  const Vec3 unit = normalize(Vec3(d.dx, d.dy, d.dz));
  for (int a = 0; a < 3; ++a) dw.wb[a] = float(d.weight * unit[a]);
  auto sums = [&](size_t v) {
    RowSums s{sum + v, {}};
    for (int a = 0; b && a < 3; ++a) s.b[a] = b[a] + v;
    return s;
  };
  if (!d.dy && !d.dz) {
    parallelFor(0, int64_t(ny) * nz, [&](int64_t r) {
      const size_t v = size_t(r) * size_t(nx);
      sweepAlongX(e + v, nx, d.dx, dw, t + v, sums(v));
    });
    return;
  }
  // Rows (ia, ib): ia along the swept axis (z, else y), ib along the other of y and z.
  const bool by_z = d.dz != 0;
  const int na = by_z ? nz : ny, nb = by_z ? ny : nz;
  const int ea = by_z ? d.dz : d.dy, eb = by_z ? d.dy : 0;
  auto row = [&](int ia, int ib) { return by_z ? g.index(0, ib, ia) : g.index(0, ia, ib); };
  // Chain c < nb starts in the most upstream slice at ib = c; chain nb + m starts in the m-th
  // slice downstream of it, at the b edge that its upstream row falls off (when eb != 0).
  const int chains = nb + (eb != 0 ? na - 1 : 0);
  parallelFor(0, chains, [&](int c) {
    int s = c < nb ? 0 : c - nb + 1;
    int ib = c < nb ? c : (eb > 0 ? nb - 1 : 0);
    for (; s < na && ib >= 0 && ib < nb; ++s, ib -= eb) {
      const int ia = ea > 0 ? na - 1 - s : s;
      const int ua = ia + ea, ub = ib + eb;
      const bool inside = ua >= 0 && ua < na && ub >= 0 && ub < nb;
      const size_t v = row(ia, ib), u = inside ? row(ua, ub) : 0;
      sweepRowX(e + v, e + u, inside ? t + u : nullptr, nx, d.dx, dw, t + v, sums(v));
    }
  });
}

}  // namespace

std::vector<FirstTouchFloats> skyVisibilities(const BakeGrid& g, const float* rho,
                                              const std::vector<double>& extinctions,
                                              const BakeProgressFn& progress,
                                              FirstTouchFloats* vector) {
  if (extinctions.empty() || extinctions.size() > 2) {
    throw InternalError("skyVisibilities: one or two extinctions, got " +
                        std::to_string(extinctions.size()));
  }
  const size_t n = g.voxelCount(), k = extinctions.size();
  std::vector<double, FirstTouchAllocator<double>> sum(n);
  FirstTouchFloats t(n), e(n);
  // The vector's components while the first extinction's directions are swept.
  FirstTouchFloats b_sums[3];
  if (vector) {
    for (auto& b : b_sums) b.assign(n, 0.f);
  }
  float* const b_ptrs[3] = {b_sums[0].data(), b_sums[1].data(), b_sums[2].data()};
  std::vector<FirstTouchFloats> out(k, FirstTouchFloats(n));
  const LatticeDirection* dirs = latticeDirections();
  int done = 0;
  for (size_t x = 0; x < k; ++x) {
    std::fill(sum.begin(), sum.end(), 0.0);
    float* const* b = vector && x == 0 ? b_ptrs : nullptr;
    // By segment length (axes, face diagonals, body diagonals): one set of half segments each.
    for (int cls = 1; cls <= 3; ++cls) {
      halfSegments(rho, n, extinctions[x] * g.voxel_size * std::sqrt(double(cls)) * 0.5, e.data());
      for (int d = 0; d < 26; ++d) {
        if (std::abs(dirs[d].dx) + std::abs(dirs[d].dy) + std::abs(dirs[d].dz) != cls) continue;
        sweepDirection(g, dirs[d], e.data(), t.data(), sum.data(), b);
        if (progress && !progress(double(++done) / (26.0 * double(k)), "sky visibility")) {
          throw Cancelled("bake cancelled while computing the sky visibility");
        }
      }
    }
    float* const o = out[x].data();
    parallelFor(0, int64_t(n),
                [&](int64_t v) { o[v] = float(std::min(1.0, std::max(0.0, sum[size_t(v)]))); },
                {kCheapIterationGrain});
  }
  if (vector) {
    vector->resize(3 * n);
    // |B| <= V <= 1 holds for the exact sums; rounding may leave a component a hair over.
    parallelFor(0, int64_t(n),
                [&](int64_t v) {
                  for (int a = 0; a < 3; ++a) {
                    (*vector)[3 * size_t(v) + size_t(a)] =
                        std::clamp(b_sums[a][size_t(v)], -1.f, 1.f);
                  }
                },
                {kCheapIterationGrain});
  }
  return out;
}

void computeSkyVisibility(BakedLight& bake, double extinction, const BakeProgressFn& progress,
                          bool with_vector) {
  FirstTouchFloats vector;
  std::vector<FirstTouchFloats> v = skyVisibilities(bake.grid, bake.density.data(), {extinction},
                                                    progress, with_vector ? &vector : nullptr);
  bake.add(bake_grids::kSkyVisibility, 1).data = std::move(v[0]);
  if (with_vector) bake.add(bake_grids::kSkyVisibilityVector, 3).data = std::move(vector);
}

}  // namespace cloudbake
