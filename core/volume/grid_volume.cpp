#include "core/volume/grid_volume.h"

#include <openvdb/tools/Interpolation.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <vector>

#include "core/error.h"
#include "core/math/parallel.h"
#include "core/volume/openvdb_grid.h"

namespace cloudbake {
namespace {

class GridLookup final : public DensityField::Lookup {
 public:
  explicit GridLookup(const GridVolume::Impl& impl)
      : impl_(impl), accessor_(impl.grid->getConstAccessor()) {}

  double density(const Vec3& p) override {
    if (!impl_.bounds.contains(p)) return 0.0;
    const auto& m = impl_.world_to_index;
    const openvdb::Vec3d idx(p.x * m[0][0] + p.y * m[1][0] + p.z * m[2][0] + m[3][0],
                             p.x * m[0][1] + p.y * m[1][1] + p.z * m[2][1] + m[3][1],
                             p.x * m[0][2] + p.y * m[1][2] + p.z * m[2][2] + m[3][2]);
    float v;
    if (!denseSample(idx, &v)) v = openvdb::tools::BoxSampler::sample(accessor_, idx);
    return v > 0.f ? static_cast<double>(v) : 0.0;
  }

 private:
  // BoxSampler::sample from the dense copy: the same corners, the same interpolation, so the
  // same bits, without the tree walk of eight accessor reads. False outside the copy.
  bool denseSample(const openvdb::Vec3d& idx, float* v) const {
    if (impl_.dense.empty()) return false;
    const openvdb::Vec3i i0 = openvdb::tools::local_util::floorVec3(idx);
    const openvdb::Vec3d uvw = idx - i0;
    int r[3];
    for (int a = 0; a < 3; ++a) {
      r[a] = i0[a] - impl_.dense_min[a];
      if (r[a] < 0 || r[a] + 1 >= impl_.dense_n[a]) return false;
    }
    const size_t nx = size_t(impl_.dense_n[0]), nxy = nx * size_t(impl_.dense_n[1]);
    const float* c = &impl_.dense[size_t(r[2]) * nxy + size_t(r[1]) * nx + size_t(r[0])];
    float data[2][2][2];
    for (int dx = 0; dx < 2; ++dx)
      for (int dy = 0; dy < 2; ++dy)
        for (int dz = 0; dz < 2; ++dz)
          data[dx][dy][dz] = c[size_t(dz) * nxy + size_t(dy) * nx + dx];
    *v = openvdb::tools::BoxSampler::trilinearInterpolation(data, uvw);
    return true;
  }

  const GridVolume::Impl& impl_;
  openvdb::FloatGrid::ConstAccessor accessor_;
};

int floorDiv(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

// Dense array of majorant cells aligned with the index grid: cell c covers the m^3 blocks of
// 8^3 voxels starting at block b0 + c * m, and holds the maximum over those voxels dilated by
// one voxel on every side.
struct CellMaxima {
  openvdb::Coord b0;  // first block
  int m = 1;          // blocks per cell along each axis
  int n[3] = {0, 0, 0};
  std::vector<float> v;
  int cellOfBlock(int a, int b) const { return floorDiv(b - b0[a], m); }
  float* at(int cx, int cy, int cz) {
    if (cx < 0 || cy < 0 || cz < 0 || cx >= n[0] || cy >= n[1] || cz >= n[2]) return nullptr;
    return &v[(static_cast<size_t>(cz) * n[1] + cy) * n[0] + cx];
  }
  float get(int cx, int cy, int cz) const {
    if (cx < 0 || cy < 0 || cz < 0 || cx >= n[0] || cy >= n[1] || cz >= n[2]) return 0.f;
    return v[(static_cast<size_t>(cz) * n[1] + cy) * n[0] + cx];
  }
};

CellMaxima dilatedCellMaxima(const openvdb::FloatTree& tree, const openvdb::CoordBBox& active) {
  CellMaxima cm;
  const openvdb::Coord lo = active.min().offsetBy(-1), hi = active.max().offsetBy(1);
  cm.b0 = openvdb::Coord(blockOf(lo.x()), blockOf(lo.y()), blockOf(lo.z()));
  int64_t nb[3];
  for (int a = 0; a < 3; ++a) nb[a] = static_cast<int64_t>(blockOf(hi[a])) - cm.b0[a] + 1;
  auto cells = [&](int a) { return (nb[a] + cm.m - 1) / cm.m; };
  while (cells(0) * cells(1) * cells(2) > GridVolume::kMaxMajorantCells) cm.m *= 2;
  for (int a = 0; a < 3; ++a) cm.n[a] = static_cast<int>(cells(a));
  cm.v.assign(static_cast<size_t>(cm.n[0]) * cm.n[1] * cm.n[2], 0.f);

  // Each leaf contributes its maximum to its own block and the maxima of its boundary layers to
  // the 26 neighbouring blocks (a voxel on face x = 0 lies in the dilation of block x - 1).
  using LeafT = openvdb::FloatTree::LeafNodeType;
  std::vector<const LeafT*> leaves;
  leaves.reserve(tree.leafCount());
  for (auto it = tree.cbeginLeaf(); it; ++it) leaves.push_back(it.getLeaf());
  std::vector<float> local(leaves.size() * 27, 0.f);
  parallelFor(0, int64_t(leaves.size()), [&](size_t l) {
    float* m = &local[l * 27];
    const float* data = leaves[l]->buffer().data();
    // Neighbour slots a voxel at local coordinate c feeds: its own block (1), plus the lower
    // neighbour (0) when c == 0 and the upper one (2) when c == 7.
    static constexpr int kSlots[8][2] = {{0, 1}, {1, 1}, {1, 1}, {1, 1},
                                         {1, 1}, {1, 1}, {1, 1}, {1, 2}};
    for (int x = 0; x < 8; ++x)
      for (int y = 0; y < 8; ++y)
        for (int z = 0; z < 8; ++z) {
          const float value = data[(x << 6) | (y << 3) | z];
          if (!(value > 0.f)) continue;
          for (int dx : kSlots[x])
            for (int dy : kSlots[y])
              for (int dz : kSlots[z]) {
                float& slot = m[(dx * 3 + dy) * 3 + dz];
                slot = std::max(slot, value);
              }
        }
  });
  for (size_t l = 0; l < leaves.size(); ++l) {
    const openvdb::Coord o = leaves[l]->origin();
    const int b[3] = {blockOf(o.x()), blockOf(o.y()), blockOf(o.z())};
    for (int dx = 0; dx < 3; ++dx)
      for (int dy = 0; dy < 3; ++dy)
        for (int dz = 0; dz < 3; ++dz) {
          const float value = local[l * 27 + (dx * 3 + dy) * 3 + dz];
          if (!(value > 0.f)) continue;
          if (float* slot =
                  cm.at(cm.cellOfBlock(0, b[0] + dx - 1), cm.cellOfBlock(1, b[1] + dy - 1),
                        cm.cellOfBlock(2, b[2] + dz - 1))) {
            *slot = std::max(*slot, value);
          }
        }
  }
  // Active tiles above the leaf level cover whole blocks (and feed their neighbours).
  openvdb::FloatTree::ValueOnCIter tile = tree.cbeginValueOn();
  tile.setMaxDepth(openvdb::FloatTree::ValueOnCIter::LEAF_DEPTH - 1);
  for (; tile; ++tile) {
    const float value = *tile;
    if (!(value > 0.f)) continue;
    const openvdb::CoordBBox b = tile.getBoundingBox();
    int c0[3], c1[3];
    for (int a = 0; a < 3; ++a) {
      c0[a] = std::max(cm.cellOfBlock(a, blockOf(b.min()[a] - 1)), 0);
      c1[a] = std::min(cm.cellOfBlock(a, blockOf(b.max()[a] + 1)), cm.n[a] - 1);
    }
    for (int cz = c0[2]; cz <= c1[2]; ++cz)
      for (int cy = c0[1]; cy <= c1[1]; ++cy)
        for (int cx = c0[0]; cx <= c1[0]; ++cx) {
          float* slot = cm.at(cx, cy, cz);
          *slot = std::max(*slot, value);
        }
  }
  return cm;
}

Vec3 applyAffine(const openvdb::Mat4d& m, double x, double y, double z) {
  const openvdb::Vec3d w = m.transform(openvdb::Vec3d(x, y, z));
  return {w.x(), w.y(), w.z()};
}

// The majorants of an axis-aligned grid: one world cell per index cell. Cell c spans index
// [8s - 1/2, 8e - 1/2] (blocks s..e-1): its lookups read voxels 8s-1 .. 8e, exactly the dilated
// blocks s..e-1. Mirrored axes reverse the cell order.
MajorantGrid alignedMajorants(const CellMaxima& cm, const openvdb::Mat4d& i2w) {
  const int* n = cm.n;
  const openvdb::Vec3d clo = cm.b0.asVec3d() * 8.0 - openvdb::Vec3d(0.5);
  const openvdb::Vec3d chi =
      (cm.b0.asVec3d() + openvdb::Vec3d(n[0], n[1], n[2]) * cm.m) * 8.0 - openvdb::Vec3d(0.5);
  Bounds3 mbounds;
  mbounds.expand(applyAffine(i2w, clo.x(), clo.y(), clo.z()));
  mbounds.expand(applyAffine(i2w, chi.x(), chi.y(), chi.z()));
  bool flip[3];
  for (int a = 0; a < 3; ++a) flip[a] = i2w(a, a) < 0;
  std::vector<float> maxima(cm.v.size());
  for (int cz = 0; cz < n[2]; ++cz)
    for (int cy = 0; cy < n[1]; ++cy)
      for (int cx = 0; cx < n[0]; ++cx) {
        const int wx = flip[0] ? n[0] - 1 - cx : cx, wy = flip[1] ? n[1] - 1 - cy : cy,
                  wz = flip[2] ? n[2] - 1 - cz : cz;
        maxima[(static_cast<size_t>(wz) * n[1] + wy) * n[0] + wx] = cm.get(cx, cy, cz);
      }
  return MajorantGrid(mbounds, n[0], n[1], n[2], std::move(maxima));
}

// The majorants of a rotated grid: world-aligned cells of the same size; each takes the maxima
// of all index cells its index-space bounding box (plus the trilinear footprint) touches.
MajorantGrid rotatedMajorants(const CellMaxima& cm, const openvdb::Mat4d& w2i,
                              const Bounds3& bounds, double voxel_size) {
  const int* n = cm.n;
  const double cell = voxel_size * 8 * cm.m;
  Bounds3 mbounds;
  mbounds.min = bounds.min;
  int nw[3];
  for (int a = 0; a < 3; ++a) {
    nw[a] = std::max(1, static_cast<int>(std::ceil(bounds.extent()[a] / cell)));
  }
  while (static_cast<int64_t>(nw[0]) * nw[1] * nw[2] > GridVolume::kMaxMajorantCells) {
    for (int a = 0; a < 3; ++a) nw[a] = (nw[a] + 1) / 2;
  }
  for (int a = 0; a < 3; ++a) {
    mbounds.max[a] = bounds.max[a];
  }
  const Vec3 csize = mbounds.extent() / Vec3(nw[0], nw[1], nw[2]);
  std::vector<float> maxima(static_cast<size_t>(nw[0]) * nw[1] * nw[2], 0.f);
  parallelFor(0, nw[2], [&](int cz) {
    for (int cy = 0; cy < nw[1]; ++cy)
      for (int cx = 0; cx < nw[0]; ++cx) {
        openvdb::Vec3d lo(1e300), hi(-1e300);
        for (int c = 0; c < 8; ++c) {
          const Vec3 wp =
              mbounds.min + csize * Vec3(cx + (c & 1), cy + ((c >> 1) & 1), cz + ((c >> 2) & 1));
          const openvdb::Vec3d ip = w2i.transform(openvdb::Vec3d(wp.x, wp.y, wp.z));
          lo = openvdb::math::minComponent(lo, ip);
          hi = openvdb::math::maxComponent(hi, ip);
        }
        int c0[3], c1[3];
        for (int a = 0; a < 3; ++a) {
          const double l = std::max(lo[a], -2e9), h = std::min(hi[a], 2e9);
          c0[a] = std::max(cm.cellOfBlock(a, blockOf(static_cast<int>(std::floor(l)) - 1)), 0);
          c1[a] =
              std::min(cm.cellOfBlock(a, blockOf(static_cast<int>(std::floor(h)) + 2)), n[a] - 1);
        }
        float value = 0.f;
        for (int z = c0[2]; z <= c1[2]; ++z)
          for (int y = c0[1]; y <= c1[1]; ++y)
            for (int x = c0[0]; x <= c1[0]; ++x) value = std::max(value, cm.get(x, y, z));
        maxima[(static_cast<size_t>(cz) * nw[1] + cy) * nw[0] + cx] = value;
      }
  });
  return MajorantGrid(mbounds, nw[0], nw[1], nw[2], std::move(maxima));
}

// The dense copy of the active box grown by one voxel (every trilinear corner a lookup inside
// the bounds reads), when it fits kMaxDenseVoxels.
void fillDense(const openvdb::FloatGrid& grid, GridVolume::Impl* impl) {
  const openvdb::Coord lo = impl->active_box.min().offsetBy(-1);
  const openvdb::Coord hi = impl->active_box.max().offsetBy(1);
  int64_t count = 1;
  for (int a = 0; a < 3; ++a) {  // checked per axis: the product of far-apart extents overflows
    count *= int64_t(hi[a]) - lo[a] + 1;
    if (count > GridVolume::Impl::kMaxDenseVoxels) return;
  }
  for (int a = 0; a < 3; ++a) impl->dense_n[a] = hi[a] - lo[a] + 1;
  impl->dense_min = lo;
  impl->dense.assign(size_t(count), 0.f);
  const int nx = impl->dense_n[0], ny = impl->dense_n[1];
  parallelFor(0, impl->dense_n[2], [&](size_t z) {
    auto acc = grid.getConstAccessor();
    float* row = &impl->dense[z * size_t(nx) * ny];
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x) {
        row[size_t(y) * nx + x] = acc.getValue(lo.offsetBy(x, y, int(z)));
      }
  });
}

// A tracking grid from cell bounds over the dense copy: cell c spans index
// [dense_min + m c, dense_min + m (c + 1)] (voxel centres as corners). Mirrored axes reverse the
// cell order, as in alignedMajorants.
MajorantGrid gridFromCellBounds(const CellBounds& b, const GridVolume::Impl& impl) {
  const openvdb::Vec3d lo = impl.dense_min.asVec3d();
  const openvdb::Vec3d hi = lo + openvdb::Vec3d(b.n[0], b.n[1], b.n[2]) * double(b.m);
  const openvdb::Mat4d& i2w = impl.index_to_world;
  Bounds3 wb;
  wb.expand(applyAffine(i2w, lo.x(), lo.y(), lo.z()));
  wb.expand(applyAffine(i2w, hi.x(), hi.y(), hi.z()));
  bool flip[3];
  for (int a = 0; a < 3; ++a) flip[a] = i2w(a, a) < 0;
  const int* n = b.n;
  if (!flip[0] && !flip[1] && !flip[2]) {
    return MajorantGrid(wb, n[0], n[1], n[2], b.maxima, b.minima);
  }
  std::vector<float> maxima(b.size()), minima(b.size());
  for (int cz = 0; cz < n[2]; ++cz)
    for (int cy = 0; cy < n[1]; ++cy)
      for (int cx = 0; cx < n[0]; ++cx) {
        const int wx = flip[0] ? n[0] - 1 - cx : cx, wy = flip[1] ? n[1] - 1 - cy : cy,
                  wz = flip[2] ? n[2] - 1 - cz : cz;
        const size_t from = (size_t(cz) * n[1] + cy) * n[0] + cx;
        const size_t to = (size_t(wz) * n[1] + wy) * n[0] + wx;
        maxima[to] = b.maxima[from];
        minima[to] = b.minima[from];
      }
  return MajorantGrid(wb, n[0], n[1], n[2], std::move(maxima), std::move(minima));
}

}  // namespace

std::shared_ptr<const GridVolume> makeGridVolume(openvdb::FloatGrid::Ptr grid,
                                                 const std::string& context) {
  if (!grid) throw InternalError("makeGridVolume: null grid");
  auto impl = std::make_shared<GridVolume::Impl>();
  impl->name = grid->getName();
  const std::string where = context + ": grid '" + impl->name + "'";
  const openvdb::math::Transform& xform = grid->transform();
  if (!xform.isLinear() || !xform.hasUniformScale()) {
    throw InputError(where + ": only linear transforms with uniform scale are supported, got " +
                     xform.mapType());
  }
  if (grid->background() != 0.f) {
    std::ostringstream os;
    os << where << ": background value must be 0, got " << grid->background();
    throw InputError(os.str());
  }
  // Trilinear lookups read inactive values too; OpenVDB leaves may hold stale ones there.
  for (auto it = grid->tree().beginValueOff(); it; ++it) {
    if (*it != 0.f) it.setValue(0.f);
  }
  impl->active_voxels = grid->activeVoxelCount();
  if (impl->active_voxels == 0) throw InputError(where + ": grid has no active voxels");
  impl->active_box = grid->evalActiveVoxelBoundingBox();
  impl->voxel_size = xform.voxelSize()[0];

  const openvdb::Mat4d i2w = xform.baseMap()->getAffineMap()->getMat4();
  const openvdb::Mat4d w2i = i2w.inverse();
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 3; ++j) impl->world_to_index[i][j] = w2i(i, j);

  // Trilinear footprint: lookups at index x read voxels floor(x) and floor(x)+1.
  const openvdb::Vec3d ilo = impl->active_box.min().asVec3d() - openvdb::Vec3d(1.0);
  const openvdb::Vec3d ihi = impl->active_box.max().asVec3d() + openvdb::Vec3d(1.0);
  for (int c = 0; c < 8; ++c) {
    impl->bounds.expand(applyAffine(i2w, (c & 1) ? ihi.x() : ilo.x(), (c & 2) ? ihi.y() : ilo.y(),
                                    (c & 4) ? ihi.z() : ilo.z()));
  }

  CellMaxima cm = dilatedCellMaxima(grid->tree(), impl->active_box);
  float max_value = 0.f;
  for (float v : cm.v) max_value = std::max(max_value, v);
  impl->max_density = max_value;
  impl->majorant_block = 8 * cm.m;
  bool axis_aligned = true;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      if (i != j && std::abs(i2w(i, j)) > 1e-9 * impl->voxel_size) axis_aligned = false;
  impl->index_to_world = i2w;
  impl->axis_aligned = axis_aligned;
  impl->majorants = axis_aligned ? alignedMajorants(cm, i2w)
                                 : rotatedMajorants(cm, w2i, impl->bounds, impl->voxel_size);
  fillDense(*grid, impl.get());
  impl->grid = grid;
  return std::make_shared<GridVolume>(std::move(impl));
}

openvdb::FloatGrid::ConstPtr openvdbGrid(const GridVolume& volume) { return volume.impl().grid; }

GridVolume::GridVolume(std::shared_ptr<const Impl> impl) : impl_(std::move(impl)) {}
GridVolume::~GridVolume() = default;

Bounds3 GridVolume::bounds() const { return impl_->bounds; }
double GridVolume::maxDensity() const { return impl_->max_density; }
std::unique_ptr<DensityField::Lookup> GridVolume::lookup() const {
  return std::make_unique<GridLookup>(*impl_);
}
const MajorantGrid& GridVolume::majorants() const { return impl_->majorants; }

std::shared_ptr<const MajorantGrid> GridVolume::trackingGrid(
    const TrackingGridRequest& request) const {
  const Impl& im = *impl_;
  if (im.dense.empty() || !im.axis_aligned) return DensityField::trackingGrid(request);
  std::lock_guard<std::mutex> lock(im.tracking_mutex);
  if (im.tracking_levels.empty()) {
    DenseView view;
    view.values = im.dense.data();
    for (int a = 0; a < 3; ++a) view.n[a] = im.dense_n[a];
    // Isolated: a worker waiting inside this parallel build must not steal a task that calls
    // trackingGrid() on this volume and waits for the lock it holds.
    tbb::this_task_arena::isolate(
        [&] { im.tracking_levels = cellBoundsLevels(view, kMaxMajorantCells); });
  }
  const std::vector<CellBounds>& levels = im.tracking_levels;
  size_t level = 0;
  if (request.cell_voxels > 0) {  // the finest level no finer than asked
    while (level + 1 < levels.size() && levels[level + 1].m <= request.cell_voxels) ++level;
  } else {
    level = cheapestLevel(levels, request.extinction * im.voxel_size);
  }
  const int m = levels[level].m;
  auto& cached = im.tracking_grids[m];
  if (!cached) cached = std::make_shared<const MajorantGrid>(gridFromCellBounds(levels[level], im));
  return cached;
}
std::optional<SampleLattice> GridVolume::sampleLattice() const {
  if (!impl_->axis_aligned) return std::nullopt;
  const openvdb::Mat4d& i2w = impl_->index_to_world;
  return SampleLattice{applyAffine(i2w, 0, 0, 0), impl_->voxel_size};
}
double GridVolume::voxelSize() const { return impl_->voxel_size; }
uint64_t GridVolume::activeVoxelCount() const { return impl_->active_voxels; }
const std::string& GridVolume::gridName() const { return impl_->name; }
int GridVolume::majorantBlockSize() const { return impl_->majorant_block; }

void GridVolume::activeIndexBox(int min[3], int max[3]) const {
  for (int a = 0; a < 3; ++a) {
    min[a] = impl_->active_box.min()[a];
    max[a] = impl_->active_box.max()[a];
  }
}

std::string GridVolume::describe() const {
  const openvdb::Coord d = impl_->active_box.dim();
  std::ostringstream os;
  os << "vdb '" << impl_->name << "' " << d.x() << "x" << d.y() << "x" << d.z() << " voxels of "
     << impl_->voxel_size << " (" << impl_->active_voxels << " active, max " << impl_->max_density
     << ")";
  return os.str();
}

}  // namespace cloudbake
