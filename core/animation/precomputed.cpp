#include "core/animation/precomputed.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <mutex>
#include <stdexcept>
#include <string>

#include "core/animation/optical_depth_sh.h"
#include "core/bake/sky_sh_scatter.h"
#include "core/bake/sun_transmittance.h"
#include "core/error.h"
#include "core/format.h"
#include "core/math/parallel.h"
#include "core/math/spherical_harmonics.h"
#include "core/phase/similarity.h"

namespace cloudbake {
namespace {

// The receiver lattice: `resolution` voxels along the longest side of the lattice's box, its
// lower corner on the box's.
BakeGrid receiverLattice(const BakeGrid& g, int resolution) {
  const Bounds3 box = g.bounds();
  const Vec3 extent = box.extent();
  const double longest = std::max({extent.x, extent.y, extent.z});
  BakeGrid r;
  r.voxel_size = std::max(g.voxel_size, longest / resolution);
  r.nx = std::max(1, int(std::ceil(extent.x / r.voxel_size - 1e-9)));
  r.ny = std::max(1, int(std::ceil(extent.y / r.voxel_size - 1e-9)));
  r.nz = std::max(1, int(std::ceil(extent.z / r.voxel_size - 1e-9)));
  r.origin = box.min + Vec3(0.5 * r.voxel_size);
  return r;
}

// The mean density of the lattice voxels whose centres fall in each receiver voxel.
std::vector<float> boxFilter(const BakeGrid& g, const std::vector<float>& density,
                             const BakeGrid& r) {
  std::vector<double> sum(r.voxelCount(), 0.0);
  std::vector<uint32_t> count(r.voxelCount(), 0);
  for (int k = 0; k < g.nz; ++k)
    for (int j = 0; j < g.ny; ++j)
      for (int i = 0; i < g.nx; ++i) {
        const Vec3 p = r.toIndex(g.center(i, j, k));
        const int ri = std::clamp(int(std::lround(p.x)), 0, r.nx - 1);
        const int rj = std::clamp(int(std::lround(p.y)), 0, r.ny - 1);
        const int rk = std::clamp(int(std::lround(p.z)), 0, r.nz - 1);
        sum[r.index(ri, rj, rk)] += density[g.index(i, j, k)];
        ++count[r.index(ri, rj, rk)];
      }
  std::vector<float> out(r.voxelCount(), 0.f);
  for (size_t v = 0; v < out.size(); ++v) out[v] = count[v] ? float(sum[v] / count[v]) : 0.f;
  return out;
}

// Eq. 6 at a world point: the SH vector of minus the blended frame's optical depth to the sky,
// trilinear in the two basic volumes' precomputed vectors (SHEXP's argument for T).
ShCoefficients negativeBlendedDepth(const PrecomputedDatabase& db, const BlendFrame& frame,
                                    const Vec3& p) {
  float fa[kShCoefficients], fb[kShCoefficients];
  sampleTrilinear(db.volumes.grid,
                  reinterpret_cast<const float*>(db.basic[size_t(frame.a)].optical_depth_sh.data()),
                  kShCoefficients, p, fa);
  sampleTrilinear(db.volumes.grid,
                  reinterpret_cast<const float*>(db.basic[size_t(frame.b)].optical_depth_sh.data()),
                  kShCoefficients, p, fb);
  ShCoefficients g;
  for (int i = 0; i < kShCoefficients; ++i) {
    g[size_t(i)] = float(-(frame.w * fa[i] + (1 - frame.w) * fb[i]));
  }
  return g;
}

// Energy conservation of Eq. 8's discrete operator, per emitting sample k: the light it
// scatters collides again somewhere with probability 1 - P_esc(q_k), where P_esc is its mean
// transmittance to outside (the DC term of its transmittance SH: Eq. 6 and 7 at q_k). The
// discrete operator collides C_k = sum_r m_r T~(q_k, x_r) of it, read through the merged cuts,
// where m_r is the collision weight the samples give receiver r through the interpolation that
// reads their fluence from the receivers (sigma_t(q) V / K / (4 pi) splatted trilinearly).
// C_k misses 1 - P_esc by the clusters' convexity bias in thin parts and exceeds it where a
// sample's cell is optically thick; a gain above 1 with albedo near 1 makes the orders diverge.
// So sample k's emission is scaled by (1 - P_esc) / C_k, at most 4 (where C_k is nearly 0 the sum
// is too coarse to correct; the cap only ever lowers C_k s_k below 1 - P_esc). Every column of
// the operator then sums to at most 1 - P_esc, and the orders converge for any albedo.
std::vector<double> collisionNormalisation(const PrecomputedDatabase& db, const BlendFrame& frame,
                                           const std::vector<std::vector<uint32_t>>& nodes,
                                           const std::vector<std::vector<float>>& values,
                                           const std::vector<float>& sigma_q, double s) {
  const SampleTree& tree = db.tree;
  const BakeGrid& rg = db.receivers;
  std::vector<double> weight(rg.voxelCount(), 0.0);
  for (size_t k = 0; k < tree.points.size(); ++k) {
    const Vec3 p = rg.toIndex(tree.points[k]);
    const int i0 = int(std::floor(p.x)), j0 = int(std::floor(p.y)), k0 = int(std::floor(p.z));
    const double fx = p.x - i0, fy = p.y - j0, fz = p.z - k0;
    for (int c = 0; c < 8; ++c) {
      const int i = i0 + (c & 1), j = j0 + ((c >> 1) & 1), kk = k0 + ((c >> 2) & 1);
      if (i < 0 || j < 0 || kk < 0 || i >= rg.nx || j >= rg.ny || kk >= rg.nz) continue;
      const double w =
          ((c & 1) ? fx : 1 - fx) * (((c >> 1) & 1) ? fy : 1 - fy) * (((c >> 2) & 1) ? fz : 1 - fz);
      weight[rg.index(i, j, kk)] += w * sigma_q[k] / (4 * kPi);
    }
  }
  std::vector<double> mass(tree.nodes.size(), 0.0);
  for (size_t r = 0; r < nodes.size(); ++r) {
    if (weight[r] <= 0) continue;
    for (size_t e = 0; e < nodes[r].size(); ++e) mass[nodes[r][e]] += weight[r] * values[r][e];
  }
  // A node's value stands for each of its samples: push the sums down to the leaves.
  for (size_t id = 0; id < tree.nodes.size(); ++id) {
    const SampleTreeNode& n = tree.nodes[id];
    if (n.leaf()) continue;
    mass[size_t(n.left)] += mass[id];
    mass[size_t(n.right)] += mass[id];
  }
  std::vector<double> scale(tree.points.size(), 1.0);
  parallelFor(0, int64_t(tree.nodes.size()), [&](size_t id) {
    const SampleTreeNode& n = tree.nodes[id];
    if (!n.leaf()) return;
    ShCoefficients g = negativeBlendedDepth(db, frame, tree.points[size_t(n.begin)]);
    for (float& x : g) x = float(s * x);
    const double escape = std::clamp(double(db.shexp(g)[0]) / kSqrt4Pi, 0.0, 1.0);
    const double c = mass[id];
    scale[size_t(n.begin)] = c > 0 ? std::min(4.0, (1 - escape) / c) : 0.0;
  });
  return scale;
}

// The frame's blend and the iteration knobs, InputError naming the one out of range.
void checkFrameInput(const PrecomputedDatabase& db, const BlendFrame& frame,
                     const FrameLightOptions& options) {
  const int nvol = int(db.basic.size());
  if (frame.a < 0 || frame.a >= nvol || frame.b < 0 || frame.b >= nvol ||
      !(frame.w >= 0 && frame.w <= 1)) {
    throw InputError("animation frame: basic volumes " + std::to_string(frame.a) + ", " +
                     std::to_string(frame.b) + " or weight " + std::to_string(frame.w) +
                     " out of range");
  }
  if (options.max_orders < 1 || options.max_orders > 1000) {
    throw InputError("iterations: must be in [1, 1000], got " + std::to_string(options.max_orders));
  }
  if (options.sky_spacing != 1 && options.sky_spacing != 2) {
    throw InputError("sky_spacing: must be 1 or 2, got " + std::to_string(options.sky_spacing));
  }
  if (!(options.tolerance > 0 && options.tolerance <= 1)) {
    throw InputError("tolerance: must be in (0, 1], got " + std::to_string(options.tolerance));
  }
  for (int c = 0; c < 3; ++c) {
    if (!(std::abs(options.mean_cosine[c]) < 1)) {
      throw InputError("mean cosine: must be in (-1, 1) per channel, got " +
                       std::to_string(options.mean_cosine[c]));
    }
  }
}

// The similarity reduction (forward-peaked phases only): multiple scattering on a medium of
// extinction s sigma_t, s = 1 - lum(a g), and each channel's own reduced albedo a (1 - g) /
// (1 - a g) (a (1 - g) / s made a white channel of a coloured albedo absorb).
struct Similarity {
  double s = 1;
  Rgb albedo;
  // Each channel's own 1 - a_c g_c, for its forward beam T^(s_c) - T (the shared s gave a dark
  // channel of a coloured albedo the luminance's beam; pointcloud measured 3.5x the path
  // tracer's multiple light in blue for an albedo of (0.9, 0.5, 0.2): an outside probe).
  Rgb s_channel{1, 1, 1};
};

Similarity similarityReduction(const Rgb& albedo, const FrameLightOptions& options) {
  Similarity sim{1, albedo};
  if (!options.similarity) return sim;
  const Rgb ag(albedo.x * options.mean_cosine.x, albedo.y * options.mean_cosine.y,
               albedo.z * options.mean_cosine.z);
  const double lum = luminance(ag);
  if (lum > 0) {
    sim.s = 1 - lum;
    for (int c = 0; c < 3; ++c) {
      sim.albedo[c] = reducedAlbedo(albedo[c], options.mean_cosine[c]);
      sim.s_channel[c] = 1 - ag[c];
    }
  }
  return sim;
}

// Eq. 2's transmittance to the sun: one sweep through the blended density, over every voxel,
// so it holds where views read it (kSunTransmittanceMarginKey; trimToSupport keeps it there).
void addSunTransmittance(const PrecomputedDatabase& db, BakedLight& bake) {
  const std::vector<float> tau =
      sweepOpticalDepth(bake.grid, bake.density, db.extinction, bake.sun_direction);
  BakeChannel& t = bake.add(bake_grids::kSunTransmittance, 1);
  parallelFor(0, int64_t(bake.grid.voxelCount()),
              [&](size_t v) { t.data[v] = float(std::exp(-double(tau[v]))); },
              {kCheapIterationGrain});
  bake.metadata[kSunTransmittanceMarginKey] = "2";
}

// The nodes of the coarse lattice on one axis of n voxels: the even indices and the last.
struct CoarseAxis {
  explicit CoarseAxis(int n) : n(n), nodes(n / 2 + 1) {}
  int n, nodes;
  int voxelOf(int node) const { return std::min(2 * node, n - 1); }
  // The two nodes around voxel i and the second's weight.
  void around(int i, int* lo, int* hi, float* t) const {
    *lo = i / 2;
    *hi = std::min(*lo + (i % 2), nodes - 1);
    const int v0 = voxelOf(*lo), v1 = voxelOf(*hi);
    *t = v1 > v0 ? float(i - v0) / float(v1 - v0) : 0.f;
  }
};

// Every second voxel along each axis (and the last) of a lattice, with the 8 nodes around each
// voxel and their trilinear weights.
struct CoarseLattice {
  explicit CoarseLattice(const BakeGrid& g) : g(g), x(g.nx), y(g.ny), z(g.nz) {}
  const BakeGrid& g;
  CoarseAxis x, y, z;
  size_t count() const { return size_t(x.nodes) * y.nodes * z.nodes; }
  size_t index(int i, int j, int k) const { return (size_t(k) * y.nodes + j) * x.nodes + i; }
  size_t voxelOf(size_t n) const {
    const int i = int(n % size_t(x.nodes)), j = int((n / size_t(x.nodes)) % size_t(y.nodes));
    const int k = int(n / (size_t(x.nodes) * y.nodes));
    return g.index(x.voxelOf(i), y.voxelOf(j), z.voxelOf(k));
  }
  // fn(node, weight) for the nodes around voxel (i, j, k) with a weight > 0.
  template <typename Fn>
  void forCorners(int i, int j, int k, Fn&& fn) const {
    int i0, i1, j0, j1, k0, k1;
    float tx, ty, tz;
    x.around(i, &i0, &i1, &tx);
    y.around(j, &j0, &j1, &ty);
    z.around(k, &k0, &k1, &tz);
    for (int c = 0; c < 8; ++c) {
      const float w = (c & 1 ? tx : 1 - tx) * (c & 2 ? ty : 1 - ty) * (c & 4 ? tz : 1 - tz);
      if (w > 0) fn(index(c & 1 ? i1 : i0, c & 2 ? j1 : j0, c & 4 ? k1 : k0), w);
    }
  }
};

// Interpolating the transmittance is safe only among voxels of the cloud: a node in the empty
// margin beside a surface (or on both sides of a sheet one voxel thick) sees the open sky, and
// voxels between it and the cloud would take its light. And where the evaluated mean
// transmittance of the corners differs by more than this, the voxels between are evaluated too.
constexpr float kSkyInterpolationSpread = 0.1f;

// Per voxel of the support: 1 where its corner nodes may be interpolated (the voxel and every
// node it reads hold density), else 0 (evaluated directly).
std::vector<uint8_t> interpolableVoxels(const CoarseLattice& c, const std::vector<uint8_t>& support,
                                        const std::vector<float>& density) {
  const BakeGrid& g = c.g;
  std::vector<uint8_t> ok(g.voxelCount(), 0);
  parallelFor(0, int64_t(g.nz), [&](int k) {
    for (int j = 0; j < g.ny; ++j) {
      for (int i = 0; i < g.nx; ++i) {
        const size_t v = g.index(i, j, k);
        if (!support[v] || !(density[v] > 0)) continue;
        bool inside = true;
        c.forCorners(i, j, k,
                     [&](size_t n, float) { inside = inside && density[c.voxelOf(n)] > 0; });
        ok[v] = inside;
      }
    }
  });
  return ok;
}

// The nodes the interpolable voxels read.
std::vector<uint8_t> nodesRead(const CoarseLattice& c, const std::vector<uint8_t>& interpolable) {
  std::vector<uint8_t> needed(c.count(), 0);
  const BakeGrid& g = c.g;
  for (int k = 0; k < g.nz; ++k) {
    for (int j = 0; j < g.ny; ++j) {
      for (int i = 0; i < g.nx; ++i) {
        if (!interpolable[g.index(i, j, k)]) continue;
        c.forCorners(i, j, k, [&](size_t n, float) { needed[n] = 1; });
      }
    }
  }
  return needed;
}

// Eq. 6 and 7: the blended optical depth's SH, exponentiated, and its DC term as the sky
// visibility. With spacing 2, SHEXP runs on the coarse lattice's nodes inside the cloud, and
// the voxels between interpolate its coefficients trilinearly where their corners agree; the
// others (the support's margin, thin sheets, steep edges) are evaluated. Returns the SHEXP
// evaluations.
size_t addSkyTransmittance(const PrecomputedDatabase& db, const BlendFrame& frame,
                           const std::vector<uint8_t>& support, int spacing, BakedLight& bake) {
  const double w = frame.w;
  const BasicVolumePrecompute& va = db.basic[size_t(frame.a)];
  const BasicVolumePrecompute& vb = db.basic[size_t(frame.b)];
  std::array<float*, kShCoefficients> out{};
  for (int i = 0; i < kShCoefficients; ++i) {
    out[size_t(i)] = bake.add(bake_grids::skyTransmittanceSh(i), 1).data.data();
  }
  float* vis = bake.add(bake_grids::kSkyVisibility, 1).data.data();
  auto shexpAt = [&](size_t v) {
    ShCoefficients f;
    for (int i = 0; i < kShCoefficients; ++i) {
      f[size_t(i)] = float(
          -(w * va.optical_depth_sh[v][size_t(i)] + (1 - w) * vb.optical_depth_sh[v][size_t(i)]));
    }
    ShCoefficients t = db.shexp(f);
    for (float& x : t) x = std::isfinite(x) ? x : 0.f;
    return t;
  };
  auto store = [&](size_t v, const float* t) {
    for (int i = 0; i < kShCoefficients; ++i) out[size_t(i)][v] = t[i];
    vis[v] = float(std::clamp(double(t[0]) / kSqrt4Pi, 0.0, 1.0));
  };
  const BakeGrid& g = bake.grid;
  if (spacing == 1) {
    parallelFor(0, int64_t(g.voxelCount()),
                [&](size_t v) {
                  if (support[v]) store(v, shexpAt(v).data());
                },
                {kCheapIterationGrain});
    return size_t(std::count_if(support.begin(), support.end(), [](uint8_t s) { return s; }));
  }
  const CoarseLattice coarse(g);
  const std::vector<uint8_t> interpolable = interpolableVoxels(coarse, support, bake.density);
  const std::vector<uint8_t> needed = nodesRead(coarse, interpolable);
  std::vector<ShCoefficients> node_t(coarse.count());
  parallelFor(0, int64_t(coarse.count()),
              [&](size_t n) {
                if (needed[n]) node_t[n] = shexpAt(coarse.voxelOf(n));
              },
              {kCheapIterationGrain});
  std::atomic<size_t> direct{0};
  parallelFor(0, int64_t(g.nz), [&](int k) {
    size_t evaluated = 0;
    for (int j = 0; j < g.ny; ++j) {
      for (int i = 0; i < g.nx; ++i) {
        const size_t v = g.index(i, j, k);
        if (!support[v]) continue;
        float t[kShCoefficients] = {};
        float lo = 1e30f, hi = -1e30f;
        if (interpolable[v]) {
          coarse.forCorners(i, j, k, [&](size_t n, float wc) {
            for (int q = 0; q < kShCoefficients; ++q) t[q] += wc * node_t[n][size_t(q)];
            lo = std::min(lo, node_t[n][0]);
            hi = std::max(hi, node_t[n][0]);
          });
        }
        if (!interpolable[v] || hi - lo > kSkyInterpolationSpread * float(kSqrt4Pi)) {
          const ShCoefficients e = shexpAt(v);
          std::copy(e.begin(), e.end(), t);
          ++evaluated;
        }
        store(v, t);
      }
    }
    direct += evaluated;
  });
  return direct + size_t(std::count_if(needed.begin(), needed.end(), [](uint8_t s) { return s; }));
}

// integral L_sky (1 - T) dw for one channel's sky SH and a transmittance SH: the sky light the
// medium removes at a point (>= 0).
double skyRemoved(const ShCoefficients& sky, const ShCoefficients& t) {
  double e = 0;
  for (int q = 0; q < kShCoefficients; ++q) e += double(sky[size_t(q)]) * t[size_t(q)];
  return std::max(0.0, 4 * kPi * double(sky[0]) / kSqrt4Pi - e);
}

// Per receiver: the merged cut (Eq. 9) and the first-order sources.
struct FrameReceivers {
  std::vector<std::vector<uint32_t>> nodes;
  std::vector<std::vector<float>> values;
  // Isotropic source radiance per unit sigma_t, sun (per unit E) then sky, 6 floats each.
  std::vector<float> source;
  // Sky light scattered into the forward peak, integral L_sky (T^s - T), 3 floats each: its
  // fluence is added to Co_sky as it is (light from every direction, so no one beam direction).
  std::vector<float> sky_beam;
  // Sky light the true medium removes, integral L_sky (1 - T), 3 floats each (skyFractions).
  std::vector<float> sky_removed;
};

FrameReceivers frameReceivers(const PrecomputedDatabase& db, const BlendFrame& frame, double s,
                              const Rgb& inv4pi_albedo, bool sky,
                              const std::array<ShCoefficients, 3>& sky_sh, const float* tsun) {
  const BakeGrid& g = db.volumes.grid;
  const BakeGrid& rg = db.receivers;
  const size_t nr = rg.voxelCount();
  const BasicVolumePrecompute& va = db.basic[size_t(frame.a)];
  const BasicVolumePrecompute& vb = db.basic[size_t(frame.b)];
  FrameReceivers rec;
  rec.nodes.resize(nr);
  rec.values.resize(nr);
  rec.source.assign(6 * nr, 0.f);
  rec.sky_beam.assign(3 * nr, 0.f);
  rec.sky_removed.assign(3 * nr, 0.f);
  parallelFor(0, int64_t(nr), [&](size_t r) {
    if (!db.receiver_mask[r]) return;
    const int i = int(r % size_t(rg.nx)), j = int((r / size_t(rg.nx)) % size_t(rg.ny)),
              k = int(r / (size_t(rg.nx) * size_t(rg.ny)));
    const Vec3 x = rg.center(i, j, k);
    mergeCuts(va.cuts, vb.cuts, db.tree, r, frame.w, [&](uint32_t node, double v) {
      if (s < 1 && v > 0) {
        // The reduced medium's transfer G T^s from the cut's G T.
        const double geo = representativeGeometry(db.tree, int(node), x);
        v = std::exp(s * std::log(v) + (1 - s) * std::log(geo));
      }
      rec.nodes[r].push_back(node);
      rec.values[r].push_back(float(v));
    });
    const double ts = std::pow(sampleTrilinear(g, tsun, x), s);
    for (int c = 0; c < 3; ++c) rec.source[6 * r + size_t(c)] = float(inv4pi_albedo[c] * ts);
    if (!sky) return;
    const ShCoefficients full = negativeBlendedDepth(db, frame, x);
    ShCoefficients reduced;
    for (int q = 0; q < kShCoefficients; ++q) reduced[size_t(q)] = float(s * full[size_t(q)]);
    const ShCoefficients t = db.shexp(reduced);
    const ShCoefficients t_full = s < 1 ? db.shexp(full) : t;
    for (int c = 0; c < 3; ++c) {
      double e = 0, beam = 0;  // integrals of L_sky T^s and of L_sky (T^s - T)
      for (int q = 0; q < kShCoefficients; ++q) {
        e += sky_sh[size_t(c)][size_t(q)] * t[size_t(q)];
        beam += sky_sh[size_t(c)][size_t(q)] * (t[size_t(q)] - t_full[size_t(q)]);
      }
      rec.source[6 * r + 3 + size_t(c)] = float(inv4pi_albedo[c] * std::max(0.0, e));
      rec.sky_beam[3 * r + size_t(c)] = float(std::max(0.0, beam));
      rec.sky_removed[3 * r + size_t(c)] = float(skyRemoved(sky_sh[size_t(c)], t_full));
    }
  });
  return rec;
}

// sigma_t V / K per sample of the reduced medium, scaled to conserve energy
// (collisionNormalisation).
std::vector<float> sampleCollisionWeights(const PrecomputedDatabase& db, const BlendFrame& frame,
                                          const std::vector<float>& density,
                                          const FrameReceivers& rec, double s) {
  const SampleTree& tree = db.tree;
  const size_t K = tree.points.size();
  std::vector<float> sigma_q(K);
  for (size_t k = 0; k < K; ++k) {
    sigma_q[k] =
        float(s * db.extinction * sampleTrilinear(db.volumes.grid, density.data(), tree.points[k]) *
              tree.volume / double(K));
  }
  const std::vector<double> scale =
      collisionNormalisation(db, frame, rec.nodes, rec.values, sigma_q, s);
  for (size_t k = 0; k < K; ++k) sigma_q[k] = float(sigma_q[k] * scale[k]);
  return sigma_q;
}

// One order of Eq. 8: the illumination tree of the samples' scattered light, then the fluence
// at every receiver as the sum over its merged cut (sun then sky, 6 floats per receiver).
void gatherOrder(const PrecomputedDatabase& db, const std::vector<float>& sigma_q,
                 const FrameReceivers& rec, std::vector<float>& fluence) {
  const SampleTree& tree = db.tree;
  const size_t K = tree.points.size();
  std::vector<float> leaf_sun(3 * K), leaf_sky(3 * K);
  for (size_t k = 0; k < K; ++k) {
    float at[6];
    sampleTrilinear(db.receivers, rec.source.data(), 6, tree.points[k], at);
    for (int c = 0; c < 3; ++c) {
      leaf_sun[3 * k + size_t(c)] = sigma_q[k] * at[c];
      leaf_sky[3 * k + size_t(c)] = sigma_q[k] * at[3 + c];
    }
  }
  const std::vector<float> sun_tree = illuminationTree(tree, leaf_sun);
  const std::vector<float> sky_tree = illuminationTree(tree, leaf_sky);
  parallelFor(0, int64_t(rec.nodes.size()), [&](size_t r) {
    double phi[6] = {0, 0, 0, 0, 0, 0};
    for (size_t e = 0; e < rec.nodes[r].size(); ++e) {
      const size_t node = rec.nodes[r][e];
      const double v = rec.values[r][e];
      for (int c = 0; c < 3; ++c) {
        phi[c] += sun_tree[3 * node + size_t(c)] * v;
        phi[3 + c] += sky_tree[3 * node + size_t(c)] * v;
      }
    }
    for (int c = 0; c < 6; ++c) fluence[6 * r + size_t(c)] = float(phi[c]);
  });
}

// Eq. 8, order by order until an order adds less than the tolerance; the orders not iterated
// as a geometric tail of the last one (the pointcloud method's tail): their sum is
// last * q / (1 - q) with q the last ratio between orders. Without it a tolerance of 1% leaves
// ~10% of the light out where q is ~0.9 (high albedo, thick cloud). Returns Co per receiver
// (sun then sky, with the sky's forward beam; the sky's tail apart, in `sky_tail`, for
// skyFractions); rec.source is left at the last order.
std::vector<float> scatterOrders(const PrecomputedDatabase& db, const std::vector<float>& sigma_q,
                                 const Rgb& inv4pi_albedo, const FrameLightOptions& options,
                                 FrameReceivers& rec, int* orders_out,
                                 std::vector<float>* sky_tail) {
  const size_t nr = rec.nodes.size();
  std::vector<float> co(6 * nr, 0.f), fluence(6 * nr, 0.f);
  double total = 0, previous = 0, ratio = 0;
  int orders = 0;
  for (int order = 0; order < options.max_orders; ++order) {
    gatherOrder(db, sigma_q, rec, fluence);
    double added = 0;
    for (size_t r = 0; r < nr; ++r) {
      for (int c = 0; c < 6; ++c) {
        co[6 * r + size_t(c)] += fluence[6 * r + size_t(c)];
        added += fluence[6 * r + size_t(c)];
        rec.source[6 * r + size_t(c)] = float(inv4pi_albedo[c % 3] * fluence[6 * r + size_t(c)]);
      }
    }
    total += added;
    ++orders;
    ratio = previous > 0 ? added / previous : 0;
    previous = added;
    if (!(added > options.tolerance * total)) break;
  }
  sky_tail->assign(3 * nr, 0.f);
  if (orders >= 2 && ratio > 0 && ratio < 1) {
    const double tail = std::min(ratio, 0.99) / (1 - std::min(ratio, 0.99));
    for (size_t r = 0; r < nr; ++r) {
      for (int c = 0; c < 3; ++c) {
        co[6 * r + size_t(c)] += float(tail * fluence[6 * r + size_t(c)]);
        (*sky_tail)[3 * r + size_t(c)] = float(tail * fluence[6 * r + 3 + size_t(c)]);
      }
    }
  }
  for (size_t r = 0; r < nr; ++r) {
    for (int c = 0; c < 3; ++c) co[6 * r + 3 + size_t(c)] += rec.sky_beam[3 * r + size_t(c)];
  }
  *orders_out = orders;
  return co;
}

// The receivers' scattered sky fluence as a fraction of the sky light the medium removes there
// (rec.sky_removed), in place, with the geometric tail of the orders not iterated. A furnace
// bounds the fraction by 1 at any albedo <= 1. So the tail, an extrapolation from the global
// ratio between the last orders, is bounded by what that leaves: in thick white media (optical
// depth 600, albedo 1) the orders still grow in the interior after 64 of them while those near
// the surface decay, and the global ratio (0.99) extrapolated near the surface doubled their
// light. addMultipleScattering scales the fractions by each voxel's own removed light, so
// interpolating from the coarser receivers cannot put more scattered light into a voxel than
// the sky it shadows either: with the fluence itself interpolated, edge voxels took the fluence
// of receivers deeper inside (a white isotropic sphere under a uniform sky came out 1.4x
// brighter than the sky). Where the iterated orders alone exceed the bound, the receivers'
// cells are optically too thick for the cut transfer (optical depth 50 per cell: a white
// sphere of optical depth 600 at transfer_resolution 12 put 1.6x the removed light into some
// receivers near its surface while its interior stayed dark after 64 orders). The fraction is
// then set to the bound, and the number of such receivers returned (the bake's metadata
// cloudbake:sky_fraction_capped; docs/methods.md: raise transfer_resolution, or use photon).
int64_t skyFractions(const FrameReceivers& rec, const std::vector<float>& sky_tail,
                     std::vector<float>& co) {
  int64_t capped = 0;
  for (size_t r = 0; r < rec.sky_removed.size() / 3; ++r) {
    bool over = false;
    for (int c = 0; c < 3; ++c) {
      const double removed = rec.sky_removed[3 * r + size_t(c)];
      float& v = co[6 * r + 3 + size_t(c)];
      const double tail =
          std::min(double(sky_tail[3 * r + size_t(c)]), std::max(0.0, removed - double(v)));
      const double fraction = removed > 1e-12 ? (v + tail) / removed : 0.0;
      over = over || fraction > 1;
      v = float(std::min(1.0, fraction));
    }
    capped += over ? 1 : 0;
  }
  return capped;
}

// The lattice's transmittance-to-sky SH grids (addSkyTransmittance), or nulls without a sky.
std::array<const float*, kShCoefficients> skyShGrids(const BakedLight& bake) {
  std::array<const float*, kShCoefficients> t{};
  for (int i = 0; i < kShCoefficients; ++i) {
    const BakeChannel* ch = bake.find(bake_grids::skyTransmittanceSh(i));
    t[size_t(i)] = ch ? ch->data.data() : nullptr;
  }
  return t;
}

// Back onto the lattice: Co per unit E; Co_sky per unit mean sky radiance (the render scales
// it by the sky's mean, so the sky's actual distribution is baked in); null `sky_sh`: no sky.
// Co_sky arrives as fractions of the removed sky light (skyFractions).
// The sun light scattered into the forward peak travels on with the sun: each channel's beam
// T^(s_c) - T (per unit E), scattered towards a view with the full phase function.
void addMultipleScattering(const PrecomputedDatabase& db, const std::vector<float>& co,
                           const Similarity& sim, const std::array<ShCoefficients, 3>* sky_sh,
                           const float* tsun, const std::vector<uint8_t>& support,
                           BakedLight& bake) {
  const BakeGrid& g = bake.grid;
  const BakeGrid& rg = db.receivers;
  BakeChannel& co_sun = bake.add(bake_grids::kMultipleFluence, 3);
  Rgb sky_mean;
  if (sky_sh) {
    for (int c = 0; c < 3; ++c) sky_mean[c] = (*sky_sh)[size_t(c)][0] / kSqrt4Pi;
  }
  BakeChannel* co_sky = sky_sh ? &bake.add(bake_grids::kSkyMultipleFluence, 3) : nullptr;
  const std::array<const float*, kShCoefficients> tsh = skyShGrids(bake);
  float* ratio_out = sim.s < 1 ? bake.add(bake_grids::kMieRatio, 1).data.data() : nullptr;
  float* dir_out = sim.s < 1 ? bake.add(bake_grids::kLightDir, 3).data.data() : nullptr;
  const Vec3 travel = -bake.sun_direction;
  parallelFor(0, int64_t(g.voxelCount()),
              [&](size_t v) {
                if (!support[v]) return;
                const int i = int(v % size_t(g.nx)), j = int((v / size_t(g.nx)) % size_t(g.ny)),
                          k = int(v / (size_t(g.nx) * size_t(g.ny)));
                float f[6];
                sampleTrilinear(rg, co.data(), 6, g.center(i, j, k), f);
                Rgb beam(0.0);
                for (int c = 0; ratio_out && c < 3; ++c) {
                  beam[c] = std::max(0.0, std::pow(double(tsun[v]), sim.s_channel[c]) - tsun[v]);
                }
                for (int c = 0; c < 3; ++c) {
                  co_sun.data[3 * v + size_t(c)] = float(std::max(0.0, double(f[c]) + beam[c]));
                  if (co_sky && sky_mean[c] > 0) {
                    ShCoefficients t{};
                    for (int q = 0; q < kShCoefficients; ++q) t[size_t(q)] = tsh[size_t(q)][v];
                    const double removed = skyRemoved((*sky_sh)[size_t(c)], t);
                    co_sky->data[3 * v + size_t(c)] =
                        float(std::max(0.0, f[3 + c] * removed / sky_mean[c]));
                  }
                }
                if (ratio_out && luminance(beam) > 0) {
                  const double diffuse = std::max(0.0, luminance(Rgb(f[0], f[1], f[2])));
                  const double b = luminance(beam);
                  ratio_out[v] = float(std::clamp(b / (b + diffuse), 0.0, 1.0));
                  for (int c = 0; c < 3; ++c) dir_out[3 * v + size_t(c)] = float(travel[c]);
                }
              },
              {kCheapIterationGrain});
}

void checkPrecomputeInput(const BasicVolumeDatabase& volumes, double extinction,
                          const PrecomputeOptions& options) {
  if (options.sample_points < 1 || options.sample_points > (1 << 20)) {
    throw InputError("sample_points: must be in [1, 2^20], got " +
                     std::to_string(options.sample_points));
  }
  if (options.transfer_resolution < 4 || options.transfer_resolution > 512) {
    throw InputError("transfer_resolution: must be in [4, 512], got " +
                     std::to_string(options.transfer_resolution));
  }
  if (!(extinction >= 0 && extinction <= 1e6)) {
    throw InputError("extinction: must be in [0, 1e6], got " + std::to_string(extinction));
  }
  if (volumes.frames.empty()) throw InputError("basic volumes: the database is empty");
  const size_t n = volumes.grid.voxelCount();
  for (size_t f = 0; f < volumes.frames.size(); ++f) {
    if (volumes.frames[f].size() != n) {
      throw InputError("basic volumes: volume " + std::to_string(f) +
                       " does not match the lattice");
    }
  }
}

// What every basic volume shares: the receiver lattice and its mask, and the sample points,
// both covering the union of the volumes' densities.
void placeReceiversAndSamples(const BasicVolumeDatabase& volumes, const PrecomputeOptions& options,
                              PrecomputedDatabase& db) {
  const BakeGrid& g = volumes.grid;
  const size_t n = g.voxelCount();
  db.receivers = receiverLattice(g, options.transfer_resolution);
  const BakeGrid& rg = db.receivers;
  // 1 where any basic volume has density, on the lattice and on the receivers.
  std::vector<float> any(n, 0.f), near(rg.voxelCount(), 0.f);
  for (size_t f = 0; f < volumes.frames.size(); ++f) {
    for (size_t v = 0; v < n; ++v) {
      if (volumes.frames[f][v] > 0) any[v] = 1.f;
    }
    const std::vector<float> receiver_density = boxFilter(g, volumes.frames[f], rg);
    for (size_t v = 0; v < near.size(); ++v) {
      if (receiver_density[v] > 0) near[v] = 1.f;
    }
  }
  // Receivers next to density too: trilinear reads at the cloud's edge weight them. Samples
  // spread over the trilinear density's support as well, so the sum over samples of sigma_t
  // covers the integral of the field the render sees.
  db.receiver_mask = densitySupport(rg, near);
  const std::vector<uint8_t> spread = densitySupport(g, any);
  db.tree = buildSampleTree(g, spread, options.sample_points, options.seed);
}

// The SHEXP tables, fitted on up to 2000 voxels of one basic volume's cloud (the database
// fits them on its first).
ShExp fitShExp(const std::vector<float>& density,
               const std::vector<ShCoefficients>& optical_depth_sh) {
  std::vector<ShCoefficients> samples;
  std::vector<size_t> inside;
  for (size_t v = 0; v < density.size(); ++v) {
    if (density[v] > 0) inside.push_back(v);
  }
  const size_t stride = std::max<size_t>(1, inside.size() / 2000);
  for (size_t i = 0; i < inside.size(); i += stride) {
    ShCoefficients c = optical_depth_sh[inside[i]];
    for (float& x : c) x = -x;
    samples.push_back(c);
  }
  while (samples.size() < 8) samples.push_back(ShCoefficients{});  // an all-empty volume
  return ShExp::fit(samples);
}

}  // namespace

size_t BasicVolumePrecompute::bytes() const {
  return optical_depth_sh.size() * sizeof(ShCoefficients) + cuts.offsets.size() * 8 +
         cuts.nodes.size() * 4 + cuts.values.size() * 4;
}

PrecomputedDatabase layoutBasicVolumes(BasicVolumeDatabase volumes, double extinction,
                                       const PrecomputeOptions& options) {
  checkPrecomputeInput(volumes, extinction, options);
  PrecomputedDatabase db;
  db.extinction = extinction;
  placeReceiversAndSamples(volumes, options, db);
  db.volumes = std::move(volumes);
  return db;
}

BasicVolumePrecompute precomputeBasicVolume(const PrecomputedDatabase& db, size_t f,
                                            const PrecomputeOptions& options,
                                            const std::function<bool(double)>& progress) {
  if (f >= db.volumes.frames.size()) {
    throw InputError("basic volume " + std::to_string(f) + ": the database has " +
                     std::to_string(db.volumes.frames.size()));
  }
  const auto t0 = std::chrono::steady_clock::now();
  const BakeGrid& g = db.volumes.grid;
  const std::vector<float>& density = db.volumes.frames[f];
  auto report = [&](double x) { return !progress || progress(x); };
  BasicVolumePrecompute b;
  b.optical_depth_sh = projectOpticalDepth(g, density, db.extinction, options.sh_directions,
                                           [&](double x) { return report(0.3 * x); });
  // The same box filter the layout's mask came from, so a volume precomputed alone (a farm
  // task) equals one precomputed with the whole database.
  b.cuts = computeTransferCuts(db.tree, db.receivers, boxFilter(g, density, db.receivers),
                               db.extinction, db.receiver_mask, options.cuts,
                               [&](double x) { return report(0.3 + 0.7 * x); });
  b.seconds = secondsSince(t0);
  return b;
}

void finishDatabase(PrecomputedDatabase& db) {
  if (db.basic.size() != db.volumes.frames.size() || db.basic.empty() ||
      db.basic[0].optical_depth_sh.size() != db.volumes.frames[0].size()) {
    throw InternalError("finishDatabase: every basic volume must be precomputed first");
  }
  db.shexp = fitShExp(db.volumes.frames[0], db.basic[0].optical_depth_sh);
}

PrecomputedDatabase precomputeBasicVolumes(BasicVolumeDatabase volumes, double extinction,
                                           const PrecomputeOptions& options,
                                           const std::function<bool(double)>& progress) {
  PrecomputedDatabase db = layoutBasicVolumes(std::move(volumes), extinction, options);
  // Basic volumes in parallel (each also parallel inside: TBB shares the threads). Progress
  // is the mean of the volumes' fractions, reported under a lock since any task may report.
  const size_t nvol = db.volumes.frames.size();
  db.basic.resize(nvol);
  std::vector<double> fraction(nvol, 0.0);
  std::mutex progress_mutex;
  auto report = [&](size_t f, double x) {
    if (!progress) return true;
    std::lock_guard<std::mutex> lock(progress_mutex);
    fraction[f] = x;
    double sum = 0;
    for (double v : fraction) sum += v;
    return progress(sum / double(nvol));
  };
  parallelFor(0, int64_t(nvol), [&](size_t f) {
    db.basic[f] = precomputeBasicVolume(db, f, options, [&](double x) { return report(f, x); });
  });
  finishDatabase(db);
  return db;
}

BakedLight lightAnimationFrame(const PrecomputedDatabase& db, const BlendFrame& frame,
                               const Vec3& sun_direction, const Rgb& albedo,
                               const std::array<ShCoefficients, 3>& sky_sh,
                               const FrameLightOptions& options, FrameLightStats* stats) {
  const auto t0 = std::chrono::steady_clock::now();
  checkFrameInput(db, frame, options);
  const Similarity sim = similarityReduction(albedo, options);
  const BakeGrid& g = db.volumes.grid;

  BakedLight bake;
  bake.grid = g;
  bake.method = "precomputed";
  bake.sun_direction = normalize(sun_direction);
  FrameLightStats local;
  FrameLightStats& st = stats ? *stats : local;
  auto lap = [t = t0]() mutable {
    const double s = secondsSince(t);
    t = std::chrono::steady_clock::now();
    return s;
  };
  bake.density = blendFrame(db.volumes.frames, frame);
  const std::vector<uint8_t> support = densitySupport(g, bake.density);
  st.support_voxels =
      size_t(std::count_if(support.begin(), support.end(), [](uint8_t s) { return s; }));
  addSunTransmittance(db, bake);
  st.seconds_sun = lap();
  bool sky = false;
  for (const auto& c : sky_sh)
    for (float x : c) sky = sky || x != 0;
  if (sky) st.sky_evaluations = addSkyTransmittance(db, frame, support, options.sky_spacing, bake);
  st.seconds_sky = lap();

  const float* tsun = bake.find(bake_grids::kSunTransmittance)->data.data();
  const Rgb inv4pi_albedo = sim.albedo / (4 * kPi);
  FrameReceivers rec = frameReceivers(db, frame, sim.s, inv4pi_albedo, sky, sky_sh, tsun);
  size_t merged = 0;
  for (const auto& m : rec.nodes) merged += m.size();
  const std::vector<float> sigma_q = sampleCollisionWeights(db, frame, bake.density, rec, sim.s);
  st.seconds_receivers = lap();
  int orders = 0;
  std::vector<float> sky_tail;
  std::vector<float> co =
      scatterOrders(db, sigma_q, inv4pi_albedo, options, rec, &orders, &sky_tail);
  const int64_t capped = sky ? skyFractions(rec, sky_tail, co) : 0;
  st.seconds_orders = lap();
  addMultipleScattering(db, co, sim, sky ? &sky_sh : nullptr, tsun, support, bake);
  st.seconds_multiple = lap();

  bake.metadata["cloudbake:frame_blend"] =
      std::to_string(frame.a) + "," + std::to_string(frame.b) + "," + std::to_string(frame.w);
  bake.metadata["cloudbake:orders"] = std::to_string(orders);
  if (sky) bake.metadata["cloudbake:sky_fraction_capped"] = std::to_string(capped);
  bake.metadata["cloudbake:similarity_scale"] = std::to_string(sim.s);
  if (sim.s < 1) bake.metadata["cloudbake:angular_model"] = "p1";
  bake.metadata["cloudbake:sample_points"] = std::to_string(db.tree.points.size());
  bake.addMeanRadiance();
  bake.trimToSupport(support);
  try {
    bake.validate("precomputed frame");
  } catch (const InputError& e) {
    // Never NaN or out-of-range light in an output; and not the shot's fault if it happens.
    throw std::runtime_error(std::string("internal error: ") + e.what());
  }
  st.orders = orders;
  st.merged_entries = merged;
  st.seconds_finish = lap();
  st.seconds = secondsSince(t0);
  return bake;
}

}  // namespace cloudbake
