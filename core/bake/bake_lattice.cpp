#include "core/bake/bake_lattice.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <string>

#include "core/error.h"
#include "core/format.h"
#include "core/math/parallel.h"

namespace cloudbake {

namespace {

// A request down to 4/5 of the field's own voxels still gets them (at most 1.25x per axis more
// than asked): box means blur what every view sees (Disney's cloud, 154 voxels, at the default
// 128: the background through it 0.26-0.35 off the reference, 0.07-0.09 on its own voxels), and
// the grid's own voxels cost a photon bake 8 % more there, a pointcloud bake 12 %.
constexpr double kSnapToOwnVoxels = 0.2;

// The lattice of spacing lat.spacing / m aligned with `lat` that covers `b`; m = floor(resolution
// / n + kSnapToOwnVoxels), n the field's own voxels along b's longest side; nullopt where m is 0.
// A grid's bounds include one voxel of trilinear footprint beyond its outermost samples on each
// side: n is the extent in voxels less one.
std::optional<BakeGrid> alignedGeometry(const SampleLattice& lat, int resolution,
                                        const Bounds3& b) {
  if (!(lat.spacing > 0)) return std::nullopt;
  const double own = std::max(1.0, std::round(maxComponent(b.extent()) / lat.spacing) - 1);
  const double m = std::floor(resolution / own + kSnapToOwnVoxels);
  if (!(m >= 1)) return std::nullopt;
  const double h = lat.spacing / m;
  BakeGrid g;
  g.voxel_size = h;
  int lo[3], n[3];
  for (int a = 0; a < 3; ++a) {
    // Vertices from the last one at or below b.min to the first at or above b.max: the field
    // is 0 there (a grid's are the zeros of its footprint), so lookups fade to 0 beyond them.
    const double first = std::floor((b.min[a] - lat.origin[a]) / h + 1e-6);
    const double last = std::ceil((b.max[a] - lat.origin[a]) / h - 1e-6);
    // A grid far from its index origin, finely divided, leaves int range: box means then.
    if (!(std::abs(first) < 1e9 && std::abs(last) < 1e9)) return std::nullopt;
    lo[a] = int(first);
    n[a] = int(last) - lo[a] + 1;
  }
  g.nx = n[0];
  g.ny = n[1];
  g.nz = n[2];
  g.origin = lat.origin + Vec3(lo[0], lo[1], lo[2]) * h;
  // The servers' limits count a lattice as (resolution + 2)^3 voxels, a cube with the margin
  // (core/methods/common.h, checkLatticeVoxels); an aligned one may take a voxel more per face
  // for the grid's footprint, no more. One holding more (a cube-shaped grid a little finer than
  // asked for, or a grid of so few voxels that its footprint is wide for its size: a single
  // voxel at 128 would take 257^3) stays box means.
  const double cube = std::pow(double(resolution) + 4, 3);
  if (double(g.voxelCount()) > cube || g.voxelCount() > kMaxBakeVoxels) return std::nullopt;
  return g;
}

// Fills bake->density voxel by voxel, value(lookup, centre) each, in parallel over z slices
// with one density lookup per thread.
template <typename Value>
void fillVoxels(const DensityField& field, BakedLight* bake, const Value& value) {
  const BakeGrid& g = bake->grid;
  parallelFor(0, g.nz, [&](int64_t k0, int64_t k1) {
    std::unique_ptr<DensityField::Lookup> lookup = field.lookup();
    for (int k = int(k0); k < k1; ++k) {
      for (int j = 0; j < g.ny; ++j) {
        for (int i = 0; i < g.nx; ++i) {
          bake->density[g.index(i, j, k)] = value(*lookup, g.center(i, j, k));
        }
      }
    }
  });
}

// Each voxel the field's value at its centre (exact on an aligned lattice).
void sampleCentres(const DensityField& field, BakedLight* bake) {
  const MajorantGrid& maj = field.majorants();
  fillVoxels(field, bake, [&](DensityField::Lookup& lookup, const Vec3& c) {
    Bounds3 point;
    point.min = c;
    point.max = c;
    return maj.maxOver(point) > 0 ? float(lookup.density(c)) : 0.f;
  });
}

}  // namespace

BakedLight makeBakeLattice(const DensityField& field, int resolution, LatticeSampling sampling) {
  const Bounds3 b = field.bounds();
  const std::optional<SampleLattice> lat = field.sampleLattice();
  if (sampling == LatticeSampling::kFieldAligned && lat) {
    bakeLatticeGeometry(b, resolution, field.describe());  // validates the request
    if (std::optional<BakeGrid> g = alignedGeometry(*lat, resolution, b)) {
      BakedLight bake;
      bake.grid = *g;
      bake.density.assign(g->voxelCount(), 0.f);
      bake.metadata["cloudbake:light_resolution"] = std::to_string(resolution);
      sampleCentres(field, &bake);
      return bake;
    }
  }
  return makeBakeLatticeOver(field, b, resolution);
}

BakeGrid bakeLatticeGeometry(const Bounds3& b, int resolution, const std::string& what,
                             const char* knob) {
  if (resolution < 8 || resolution > 1024) {
    throw InputError(std::string(knob) + ": must be in [8, 1024], got " +
                     std::to_string(resolution));
  }
  if (b.empty() || !isFinite(b.min) || !isFinite(b.max)) {
    throw InputError("volume: '" + what + "' has empty or infinite bounds");
  }
  const Vec3 ext = b.extent();
  if (!isFinite(ext)) {
    throw InputError("volume: '" + what + "' has bounds too wide to measure (" + str(ext) + ")");
  }
  const double longest = maxComponent(ext);
  if (!(longest > 0)) {
    throw InputError("volume: '" + what + "' has zero extent; nothing to bake");
  }
  const double h = longest / resolution;
  // Far from the origin, world coordinates keep few digits of a voxel (a sphere of radius 1 at
  // 1e40 had no extent along x, and its pointcloud bake crashed): beyond 4e9 voxels, refused.
  double far = 0;
  for (int a = 0; a < 3; ++a) far = std::max({far, std::abs(b.min[a]), std::abs(b.max[a])});
  if (!(far / h <= kMaxLatticeOffsetVoxels)) {
    throw InputError("volume: '" + what + "' reaches " + str(far) +
                     " world units from the origin, more than " + str(kMaxLatticeOffsetVoxels) +
                     " of its lattice's voxels of " + str(h) +
                     " (their coordinates would lose their precision); move it nearer the "
                     "origin or use a coarser " +
                     knob);
  }
  BakeGrid g;
  g.voxel_size = h;
  // Voxels covering the bounds, plus one empty voxel of margin on every face, centred on the
  // bounds so the cloud sits in the middle of the lattice.
  int n[3];
  uint64_t total = 1;
  for (int a = 0; a < 3; ++a) {
    n[a] = std::max(1, int(std::ceil(ext[a] / h - 1e-9))) + 2;
    total *= uint64_t(n[a]);
  }
  if (total > kMaxBakeVoxels) {
    throw InputError(std::string(knob) + ": " + std::to_string(resolution) +
                     " gives a lattice of " + std::to_string(n[0]) + "x" + std::to_string(n[1]) +
                     "x" + std::to_string(n[2]) + " voxels, more than the limit of " +
                     std::to_string(kMaxBakeVoxels));
  }
  g.nx = n[0];
  g.ny = n[1];
  g.nz = n[2];
  g.origin = b.center() - Vec3(g.nx - 1, g.ny - 1, g.nz - 1) * (0.5 * h);
  return g;
}

BakedLight makeBakeLatticeOver(const DensityField& field, const Bounds3& b, int resolution) {
  BakedLight bake;
  bake.grid = bakeLatticeGeometry(b, resolution, field.describe());
  const BakeGrid& g = bake.grid;
  const double h = g.voxel_size;
  bake.density.assign(g.voxelCount(), 0.f);
  bake.metadata["cloudbake:light_resolution"] = std::to_string(resolution);

  // Mean density over each voxel: a box filter keeps optical depths right where the lattice is
  // coarser than the field. The field's own detail decides how many samples per axis it needs.
  const double feature = field.featureSize();
  const int ss = std::clamp(int(std::ceil(2.0 * h / std::max(feature, 1e-300))), 2, 4);
  const double inv = 1.0 / (double(ss) * ss * ss);
  const MajorantGrid& maj = field.majorants();
  fillVoxels(field, &bake, [&](DensityField::Lookup& lookup, const Vec3& c) {
    // Skip voxels outside the field's bounds (the margin) without sampling.
    Bounds3 vb;
    vb.min = c - Vec3(0.5 * h);
    vb.max = c + Vec3(0.5 * h);
    if (vb.max.x < b.min.x || vb.max.y < b.min.y || vb.max.z < b.min.z || vb.min.x > b.max.x ||
        vb.min.y > b.max.y || vb.min.z > b.max.z) {
      return 0.f;
    }
    // Every lookup inside a cell of bound 0 reads 0: the mean is 0 without sampling.
    if (!(maj.maxOver(vb) > 0)) return 0.f;
    // Where the field knows its mean (a box: sampled, one thinner than a quarter voxel fell
    // between the samples and vanished, and one of a third doubled its optical depth).
    if (const std::optional<double> mean = field.cellMean(vb)) return float(*mean);
    double sum = 0;
    for (int sz = 0; sz < ss; ++sz)
      for (int sy = 0; sy < ss; ++sy)
        for (int sx = 0; sx < ss; ++sx) {
          sum += lookup.density(vb.min + Vec3(sx + 0.5, sy + 0.5, sz + 0.5) * (h / ss));
        }
    return float(sum * inv);
  });
  return bake;
}

}  // namespace cloudbake
