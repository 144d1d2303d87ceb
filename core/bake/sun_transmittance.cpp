#include "core/bake/sun_transmittance.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/error.h"
#include "core/math/parallel.h"
#include "core/math/vector_clones.h"

namespace cloudbake {
namespace {

constexpr double kSunStepVoxels = 0.5;  // the march's step, in voxels

// Every voxel's ray takes the same steps: after s steps the ray from voxel (i, j, k)'s centre
// is at index point (i, j, k) + s h d, whose floor is (i, j, k) + floor(s h d) and whose
// fraction is frac(s h d). So one step's trilinear corner offsets and weights serve every voxel,
// and a row of voxels along x reads four contiguous rows of density: a loop the compiler
// vectorises, where a march per voxel computed its own position, floors and weights each step.
struct SunStep {
  int fx, fy, fz;  // floor of the step's offset in index units
  float w[8];      // trilinear weights of corners (dx, dy, dz), x fastest; halved at step 0
};

std::vector<SunStep> sunSteps(const BakeGrid& g, const Vec3& sun_dir) {
  // Far enough for any ray from a voxel centre to leave the lattice and its footprint.
  const double diagonal = length(Vec3(g.nx, g.ny, g.nz)) + 4;
  const int n = int(std::ceil(diagonal / kSunStepVoxels)) + 1;
  std::vector<SunStep> steps(static_cast<size_t>(n));
  for (int s = 0; s < n; ++s) {
    const Vec3 o = sun_dir * (s * kSunStepVoxels);
    const double fx = std::floor(o.x), fy = std::floor(o.y), fz = std::floor(o.z);
    const double t[3] = {o.x - fx, o.y - fy, o.z - fz};
    SunStep& st = steps[size_t(s)];
    st.fx = int(fx);
    st.fy = int(fy);
    st.fz = int(fz);
    // The trapezoid's first sample counts half; its last is 0 (the ray has left the footprint).
    const double first = s == 0 ? 0.5 : 1.0;
    for (int c = 0; c < 8; ++c) {
      const double wx = (c & 1) ? t[0] : 1 - t[0], wy = (c & 2) ? t[1] : 1 - t[1];
      st.w[c] = float(first * wx * wy * ((c & 4) ? t[2] : 1 - t[2]));
    }
  }
  return steps;
}

// The density with one voxel of zeros on every face, so that every corner a lookup inside the
// footprint reads is in the array.
struct PaddedDensity {
  std::vector<float> v;
  int nx, ny, nz;  // padded sizes
  PaddedDensity(const BakeGrid& g, const float* rho) : nx(g.nx + 2), ny(g.ny + 2), nz(g.nz + 2) {
    v.assign(size_t(nx) * size_t(ny) * size_t(nz), 0.f);
    for (int k = 0; k < g.nz; ++k)
      for (int j = 0; j < g.ny; ++j) {
        std::copy_n(rho + g.index(0, j, k), g.nx, v.data() + row(j, k) + 1);
      }
  }
  /// Offset of lattice row (j, k)'s voxel x = -1.
  size_t row(int j, int k) const {
    return (size_t(k + 1) * size_t(ny) + size_t(j + 1)) * size_t(nx);
  }
};

// sum[x] += the step's trilinear density at the sample of the x-th voxel, x < n; c00 .. c11 are
// the padded rows (dy, dz) holding the corners, offset so that c[x] is its corner dx = 0.
CLOUDBAKE_VECTOR_CLONES void addStep(const SunStep& st, const float* __restrict c00,
                                     const float* __restrict c10, const float* __restrict c01,
                                     const float* __restrict c11, int n, float* __restrict sum) {
  const float* w = st.w;
  for (int x = 0; x < n; ++x) {
    sum[x] += w[0] * c00[x] + w[1] * c00[x + 1] + w[2] * c10[x] + w[3] * c10[x + 1] +
              w[4] * c01[x] + w[5] * c01[x + 1] + w[6] * c11[x] + w[7] * c11[x + 1];
  }
}

CLOUDBAKE_VECTOR_CLONES float minOver(const float* v, int a, int b) {
  float m = v[a];
  for (int x = a + 1; x <= b; ++x) m = std::min(m, v[x]);
  return m;
}

// The trapezoid sums of row (j, k)'s voxels a0 .. b0: sum[x] times the step length is the
// integral of density along voxel x's ray. Stops once every sum exceeds `stop`.
void sumRow(const BakeGrid& g, const PaddedDensity& pad, const std::vector<SunStep>& steps, int j,
            int k, int a0, int b0, float stop, float* sum) {
  std::fill(sum + a0, sum + b0 + 1, 0.f);
  for (size_t s = 0; s < steps.size(); ++s) {
    const SunStep& st = steps[s];
    const int j0 = j + st.fy, k0 = k + st.fz;
    // Lookups at floor -1 .. n - 1 touch the lattice; the rays move monotonically, so a row
    // whose samples have left stays left.
    if (j0 < -1 || j0 > g.ny - 1 || k0 < -1 || k0 > g.nz - 1) break;
    const int a = std::max(a0, -1 - st.fx), b = std::min(b0, g.nx - 1 - st.fx);
    if (a > b) break;
    // A padded row starts at x = -1, so voxel x's corner dx = 0 is at x + fx + 1 (>= 0).
    const float* v = pad.v.data() + (1 + a + st.fx);
    addStep(st, v + pad.row(j0, k0), v + pad.row(j0 + 1, k0), v + pad.row(j0, k0 + 1),
            v + pad.row(j0 + 1, k0 + 1), b - a + 1, sum + a);
    if (s % 16 == 15 && minOver(sum, a, b) > stop) break;
  }
}

}  // namespace

void computeSunTransmittance(BakedLight& bake, const Vec3& sun_dir, double extinction,
                             const BakeProgressFn& progress) {
  const BakeGrid& g = bake.grid;
  if (!(std::abs(length(sun_dir) - 1) < 1e-6)) {
    throw InputError("sun direction: must be a unit vector");
  }
  BakeChannel& t = bake.add(bake_grids::kSunTransmittance, 1);
  const std::vector<uint8_t> support = sunTransmittanceSupport(g, densitySupport(g, bake.density));
  const PaddedDensity pad(g, bake.density.data());
  const std::vector<SunStep> steps = sunSteps(g, sun_dir);
  const double tau_per_sum = extinction * kSunStepVoxels * g.voxel_size;
  // exp(-16.2) < 1e-7: such voxels read 0, so their sums need not be finished.
  const float stop = extinction > 0 ? float(16.2 / tau_per_sum) * 1.01f : 0.f;
  bake.metadata[kSunTransmittanceMarginKey] = "2";
  ParallelOptions slices;  // one slice per chunk: cancellation within about a second
  if (progress) {
    slices.cancelled = [&](double f) { return !progress(f, "sun transmittance"); };
  }
  slices.cancelled_message = "bake cancelled while computing the sun transmittance";
  parallelFor(
      0, g.nz,
      [&](int k) {
        std::vector<float> sum(size_t(g.nx));
        for (int j = 0; j < g.ny; ++j) {
          const uint8_t* in = support.data() + g.index(0, j, k);
          int a = 0, b = 0;
          if (!supportSpan(in, g.nx, &a, &b)) continue;
          float* out = t.data.data() + g.index(0, j, k);
          if (!(extinction > 0)) {
            for (int x = a; x <= b; ++x) out[x] = in[x] ? 1.f : 0.f;
            continue;
          }
          sumRow(g, pad, steps, j, k, a, b, stop, sum.data());
          for (int x = a; x <= b; ++x) {
            const double tau = tau_per_sum * sum[x];
            out[x] = in[x] && tau <= 16.2 ? float(std::exp(-tau)) : 0.f;
          }
        }
      },
      slices);
}

}  // namespace cloudbake
