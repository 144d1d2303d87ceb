#include "core/volume/mesh_volume.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <sstream>
#include <vector>

#include "core/error.h"
#include "core/format.h"
#include "core/volume/mesh_orientation.h"
#include "core/volume/noise.h"
#include "core/volume/openvdb_grid.h"
#include "core/volume/voxel_limits.h"
#include "core/volume/winding_number.h"

namespace cloudbake {
namespace {

Bounds3 meshBounds(const TriangleMesh& mesh) {
  Bounds3 b;
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) b.expand(mesh.vertices[t[k]]);
  return b;
}

struct IndexBox {
  int lo[3], hi[3];
};

IndexBox voxelRange(const Bounds3& b, double h) {
  IndexBox r;
  for (int a = 0; a < 3; ++a) {
    r.lo[a] = static_cast<int>(std::floor(b.min[a] / h)) - 1;
    r.hi[a] = static_cast<int>(std::ceil(b.max[a] / h)) + 1;
  }
  return r;
}

// Offset (voxels) of the 2^3 coverage sub-samples from the voxel centre.
constexpr double kSubSample = 0.25;

// Triangle bounding boxes in continuous index units (voxel centre ijk at ijk).
struct TriBox {
  float lo[3], hi[3];
};

// Triangle / axis-aligned box overlap by the separating axis theorem (Akenine-Moller 2001):
// box face normals, triangle normal and the 9 edge cross products.
bool triangleOverlapsBox(const Vec3& center, const Vec3& half, const std::array<Vec3, 3>& tri) {
  const Vec3 v[3] = {tri[0] - center, tri[1] - center, tri[2] - center};
  const Vec3 e[3] = {v[1] - v[0], v[2] - v[1], v[0] - v[2]};
  auto separated = [&](const Vec3& axis) {
    const double p0 = dot(v[0], axis), p1 = dot(v[1], axis), p2 = dot(v[2], axis);
    const double r =
        half.x * std::abs(axis.x) + half.y * std::abs(axis.y) + half.z * std::abs(axis.z);
    return std::min({p0, p1, p2}) > r || std::max({p0, p1, p2}) < -r;
  };
  for (int a = 0; a < 3; ++a) {
    Vec3 unit;
    unit[a] = 1;
    if (separated(unit)) return false;
    for (const Vec3& edge : e)
      if (separated(cross(unit, edge))) return false;
  }
  return !separated(cross(e[0], e[1]));
}

class MeshBlockEvaluator {
 public:
  MeshBlockEvaluator(const TriangleMesh& mesh, const MeshSourceOptions& options, double h,
                     const IndexBox& range, const std::function<bool()>& stop)
      : wn_(mesh), options_(options), h_(h), noise_(options.noise.seed), stop_(stop) {
    const Bounds3 b = meshBounds(mesh);
    max_extent_ = maxComponent(b.extent());
    for (int a = 0; a < 3; ++a) {
      b0_[a] = blockOf(range.lo[a]);
      nb_[a] = blockOf(range.hi[a]) - b0_[a] + 1;
    }
    // Bin triangles into the 8^3 blocks whose box of voxel centres their bounding box
    // overlaps (CSR lists).
    const double eps = 1e-4;
    boxes_.resize(mesh.triangles.size());
    tris_.resize(mesh.triangles.size());
    std::vector<int> block_lo(mesh.triangles.size() * 3), block_hi(mesh.triangles.size() * 3);
    offsets_.assign(static_cast<size_t>(nb_[0]) * nb_[1] * nb_[2] + 1, 0);
    for (size_t t = 0; t < mesh.triangles.size(); ++t) {
      TriBox& tb = boxes_[t];
      for (int k = 0; k < 3; ++k) tris_[t][k] = mesh.vertices[mesh.triangles[t][k]] / h;
      for (int a = 0; a < 3; ++a) {
        double lo = 1e300, hi = -1e300;
        for (int k = 0; k < 3; ++k) {
          lo = std::min(lo, mesh.vertices[mesh.triangles[t][k]][a] / h);
          hi = std::max(hi, mesh.vertices[mesh.triangles[t][k]][a] / h);
        }
        // Widened by the sub-sample offset, so "no triangle box overlaps the box of voxel
        // centres" also covers the coverage sub-samples at +-1/4 voxel.
        tb.lo[a] = static_cast<float>(lo - kSubSample - eps);
        tb.hi[a] = static_cast<float>(hi + kSubSample + eps);
        // Block b holds centres [8b, 8b + 7].
        block_lo[t * 3 + a] = std::max(blockOf(static_cast<int>(std::ceil(tb.lo[a]))), b0_[a]);
        block_hi[t * 3 + a] =
            std::min(blockOf(static_cast<int>(std::floor(tb.hi[a]))), b0_[a] + nb_[a] - 1);
      }
      forBlocks(&block_lo[t * 3], &block_hi[t * 3], [&](size_t b) { ++offsets_[b + 1]; });
    }
    for (size_t b = 1; b < offsets_.size(); ++b) offsets_[b] += offsets_[b - 1];
    ids_.resize(offsets_.back());
    std::vector<int64_t> fill(offsets_.begin(), offsets_.end() - 1);
    for (size_t t = 0; t < mesh.triangles.size(); ++t) {
      forBlocks(&block_lo[t * 3], &block_hi[t * 3],
                [&](size_t b) { ids_[fill[b]++] = static_cast<int32_t>(t); });
    }
  }

  bool operator()(const openvdb::Coord& origin, float* values) const {
    const size_t b = blockIndex(blockOf(origin.x()), blockOf(origin.y()), blockOf(origin.z()));
    std::vector<int32_t> tris(ids_.begin() + offsets_[b], ids_.begin() + offsets_[b + 1]);
    float inside[512];
    const bool uniform = classify(origin, 8, tris, inside);
    if (uniform && (!options_.noise_enabled || inside[0] == 0.f)) {
      values[0] = inside[0] * static_cast<float>(options_.density);
      return true;
    }
    for (int i = 0; i < 512; ++i) {
      const float in = uniform ? inside[0] : inside[i];
      values[i] =
          in == 0.f ? 0.f : static_cast<float>(in * options_.density * modulation(origin, i));
    }
    return false;
  }

 private:
  template <typename Fn>
  void forBlocks(const int* lo, const int* hi, Fn&& fn) const {
    for (int z = lo[2]; z <= hi[2]; ++z)
      for (int y = lo[1]; y <= hi[1]; ++y)
        for (int x = lo[0]; x <= hi[0]; ++x) fn(blockIndex(x, y, z));
  }
  size_t blockIndex(int bx, int by, int bz) const {
    return (static_cast<size_t>(bz - b0_[2]) * nb_[1] + (by - b0_[1])) * nb_[0] + (bx - b0_[0]);
  }

  bool insideAt(int x, int y, int z) const {
    pollStop();
    return wn_(Vec3(x, y, z) * h_) > 0.5;
  }

  // Polled at every voxel a block evaluates, not only between blocks: on a degenerate mesh (a
  // soup of large overlapping triangles) one winding number costs the whole mesh, and a block
  // took tens of seconds (an outside probe: a cancel answered after 86 s).
  void pollStop() const {
    if (stop_ && stop_()) throw Cancelled("mesh voxelisation cancelled");
  }

  // Fraction of the voxel inside, from a 2^3 stratified sub-sample at +-1/4 voxel: voxels the
  // surface passes through get fractional density, so the boundary is placed to sub-voxel
  // accuracy instead of in voxel-sized steps.
  float surfaceCoverage(int x, int y, int z) const {
    pollStop();
    int inside = 0;
    for (int k = 0; k < 8; ++k) {
      const Vec3 p(x + ((k & 1) ? kSubSample : -kSubSample),
                   y + ((k & 2) ? kSubSample : -kSubSample),
                   z + ((k & 4) ? kSubSample : -kSubSample));
      inside += wn_(p * h_) > 0.5;
    }
    return static_cast<float>(inside) / 8.f;
  }

  // Fills inside[] (leaf order) for the cube of `size` voxels at `c`; when no triangle box
  // touches it, the winding number is constant there: returns true with only inside[0] set
  // if the cube is the whole block, else fills the cube's entries.
  bool classify(const openvdb::Coord& c, int size, const std::vector<int32_t>& tris,
                float* inside) const {
    if (tris.empty()) {
      const bool centre = insideAt(c.x(), c.y(), c.z());
      // No surface here, but for open meshes the 1/2 level of the winding number also runs
      // across holes (the teapot's missing bottom); refine where the cube's corners disagree.
      if (size >= 4) {
        bool mixed = false;
        for (int k = 1; k < 8 && !mixed; ++k) {
          mixed = insideAt(c.x() + (k & 1) * (size - 1), c.y() + ((k >> 1) & 1) * (size - 1),
                           c.z() + (k >> 2) * (size - 1)) != centre;
        }
        if (mixed) {
          const int half = size / 2;
          for (int k = 0; k < 8; ++k) {
            classify(c.offsetBy((k & 1) * half, ((k >> 1) & 1) * half, (k >> 2) * half), half, tris,
                     inside);
          }
          return false;
        }
      }
      const float v = centre ? 1.f : 0.f;
      if (size == 8) {
        inside[0] = v;
        return true;
      }
      for (int x = 0; x < size; ++x)
        for (int y = 0; y < size; ++y)
          for (int z = 0; z < size; ++z)
            inside[(((c.x() + x) & 7) << 6) | (((c.y() + y) & 7) << 3) | ((c.z() + z) & 7)] = v;
      return false;
    }
    if (size == 1) {
      inside[((c.x() & 7) << 6) | ((c.y() & 7) << 3) | (c.z() & 7)] =
          surfaceCoverage(c.x(), c.y(), c.z());
      return false;
    }
    const int half = size / 2;
    // Sub-cube of voxel centres o .. o + half - 1, widened to its coverage sub-samples.
    const double r = 0.5 * (half - 1) + kSubSample + 1e-4;
    std::vector<int32_t> sub;
    for (int k = 0; k < 8; ++k) {
      const openvdb::Coord o = c.offsetBy((k & 1) * half, ((k >> 1) & 1) * half, (k >> 2) * half);
      const Vec3 centre = Vec3(o.x(), o.y(), o.z()) + Vec3(0.5 * (half - 1));
      sub.clear();
      for (int32_t t : tris) {
        const TriBox& tb = boxes_[t];
        bool overlap = true;
        for (int a = 0; a < 3 && overlap; ++a) {
          overlap = tb.hi[a] >= o[a] && tb.lo[a] <= o[a] + half - 1;
        }
        if (overlap && triangleOverlapsBox(centre, Vec3(r), tris_[t])) sub.push_back(t);
      }
      classify(o, half, sub, inside);
    }
    return false;
  }

  double modulation(const openvdb::Coord& origin, int i) const {
    if (!options_.noise_enabled) return 1.0;
    const openvdb::Coord c = origin + openvdb::FloatTree::LeafNodeType::offsetToLocalCoord(i);
    const Vec3 q = Vec3(c.x(), c.y(), c.z()) * (h_ / max_extent_ * options_.noise.frequency);
    const double n = fbm01(noise_, q, options_.noise.octaves, options_.noise.persistence);
    return (1.0 - options_.noise.amount) + options_.noise.amount * n;
  }

  FastWindingNumber wn_;
  const MeshSourceOptions& options_;
  double h_, max_extent_ = 1;
  PerlinNoise noise_;
  const std::function<bool()>& stop_;
  int b0_[3], nb_[3];
  std::vector<TriBox> boxes_;
  std::vector<std::array<Vec3, 3>> tris_;  // vertices in index units
  std::vector<int64_t> offsets_;
  std::vector<int32_t> ids_;
};

}  // namespace

double meshVoxelSize(const MeshSourceOptions& o, const Bounds3& b) {
  const bool has_size = o.voxel_size != 0, has_res = o.resolution != 0;
  if (has_size == has_res) {
    throw InputError(o.path + ": mesh: set exactly one of voxel_size and resolution");
  }
  const double extent = maxComponent(b.extent());
  if (!(extent > 0)) throw InputError(o.path + ": mesh has zero extent");
  double h = 0;
  if (has_size) {
    if (!std::isfinite(o.voxel_size) || o.voxel_size <= 0) {
      std::ostringstream os;
      os << o.path << ": mesh.voxel_size: must be finite and > 0, got " << o.voxel_size;
      throw InputError(os.str());
    }
    h = o.voxel_size;
  } else {
    if (o.resolution < 1 || o.resolution > 1022) {
      throw InputError(o.path + ": mesh.resolution: must be in [1, 1022], got " +
                       std::to_string(o.resolution));
    }
    h = extent / o.resolution;
  }
  // Errors below name the key that set the voxel.
  const std::string field = o.path + ": mesh." + (has_size ? "voxel_size" : "resolution") + ": ";
  if (!(h >= kMinVoxelSize)) {
    std::ostringstream os;
    os << field << "gives voxels of " << exactNumber(h) << " world units, below the smallest "
       << exactNumber(kMinVoxelSize) << ": scale the mesh up";
    throw InputError(os.str());
  }
  double total = 1;
  for (int a = 0; a < 3; ++a) {
    if (!(std::abs(b.min[a] / h) < 1e9 && std::abs(b.max[a] / h) < 1e9)) {
      // OpenVDB's index coordinates are 32-bit: the mesh is too far out for this voxel.
      std::ostringstream os;
      os << field << "the mesh reaches "
         << exactNumber(std::max(std::abs(b.min[a]), std::abs(b.max[a])))
         << " world units from the origin, beyond 1e9 voxels of " << exactNumber(h)
         << " (the grid's index range); move it nearer the origin or use coarser voxels";
      throw InputError(os.str());
    }
    total *= std::ceil(b.max[a] / h) - std::floor(b.min[a] / h) + 3;
  }
  if (!(total <= static_cast<double>(kMaxMeshVoxels))) {
    std::ostringstream os;
    os << field << (has_size ? exactNumber(o.voxel_size) : std::to_string(o.resolution))
       << " needs " << (total < 1e18 ? exactNumber(total) : std::string("more than 1e18"))
       << " voxels, more than the limit of " << kMaxMeshVoxels
       << " (1024^3); use a coarser voxel size";
    throw InputError(os.str());
  }
  return h;
}

DensityFieldPtr meshToVolume(const TriangleMesh& mesh, const MeshSourceOptions& options,
                             const std::function<bool()>& stop) {
  if (!std::isfinite(options.density) || !(options.density > 0)) {
    std::ostringstream os;
    os << options.path << ": mesh.density: must be finite and > 0, got " << options.density;
    throw InputError(os.str());
  }
  if (options.noise_enabled) validateNoiseOptions(options.noise, options.path + ": mesh.noise.");
  if (mesh.triangles.empty()) throw InputError(options.path + ": mesh has no triangles");
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    for (int32_t v : mesh.triangles[t]) {
      if (v < 0 || static_cast<size_t>(v) >= mesh.vertices.size()) {
        throw InputError(options.path + ": triangle " + std::to_string(t) + " has vertex index " +
                         std::to_string(v) + " out of range");
      }
      if (!isFinite(mesh.vertices[v])) {
        throw InputError(options.path + ": vertex " + std::to_string(v) +
                         " has a non-finite coordinate");
      }
    }
  }
  const Bounds3 b = meshBounds(mesh);
  const double h = meshVoxelSize(options, b);
  const IndexBox range = voxelRange(b, h);
  // The winding number counts a face wound the other way as a hole's negative: a closed cube
  // with two of its twelve faces reversed came out hollow with a sheet below it, and one wound
  // inwards throughout as empty (an outside probe).
  TriangleMesh oriented = mesh;
  orientConsistently(&oriented);
  const MeshBlockEvaluator eval(oriented, options, h, range, stop);
  auto grid = buildGridFromBlocks(
      openvdb::CoordBBox(openvdb::Coord(range.lo[0], range.lo[1], range.lo[2]),
                         openvdb::Coord(range.hi[0], range.hi[1], range.hi[2])),
      h, [&](const openvdb::Coord& origin, float* values) { return eval(origin, values); }, stop);
  grid->setName("density");
  if (grid->activeVoxelCount() == 0) {
    std::ostringstream os;
    // The bounds too: one stray vertex far out (1e39) sets a resolution's voxel size, and the
    // advice to shrink it then only meets the voxel budget.
    os << options.path << ": mesh encloses no voxel centre at voxel size " << h
       << " over its bounds [" << exactNumber(b.min.x) << ", " << exactNumber(b.min.y) << ", "
       << exactNumber(b.min.z) << "] - [" << exactNumber(b.max.x) << ", " << exactNumber(b.max.y)
       << ", " << exactNumber(b.max.z)
       << "] (too thin or open, or a vertex far from the rest; try a smaller voxel size)";
    throw InputError(os.str());
  }
  return makeGridVolume(grid, options.path);
}

DensityFieldPtr meshToVolume(const MeshSourceOptions& options, const std::function<bool()>& stop) {
  return meshToVolume(readMesh(options.path), options, stop);
}

}  // namespace cloudbake
