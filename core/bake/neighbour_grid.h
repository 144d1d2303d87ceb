// Method `pointcloud`, internal: fixed-radius neighbour queries on a uniform grid and the
// per-pair transfer lists (CSR) the scattering passes gather over.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

#include "core/error.h"
#include "core/math/parallel.h"
#include "core/math/vec3.h"

namespace cloudbake {

/// A uniform grid of cubic cells over a point set (counting sort, points stored cell by cell)
/// for fixed-radius queries: seed 000's neighbourhood cut-off, O(n k) instead of O(n^2).
class PointGrid {
 public:
  /// `cell_size` (world units, > 0) is a lower bound: cells grow when the grid would hold more
  /// than about 2 cells per point (a tiny cut-off must not allocate a huge empty grid).
  PointGrid(const std::vector<Vec3>& points, double cell_size);

  /// Calls f(index, d2) for every point within `radius` of `p` (squared distance d2 <=
  /// radius^2), p itself included when it is one of the points. Cells are visited in index order
  /// and points in index order within a cell, so the sequence is deterministic.
  template <class F>
  void forEachWithin(const Vec3& p, double radius, F&& f) const {
    const double r2 = radius * radius;
    forEachRow(p, radius, [&](uint32_t b, uint32_t e) {
      for (uint32_t s = b; s < e; ++s) {
        const Vec3 d = sorted_[s] - p;
        const double d2 = dot(d, d);
        if (d2 <= r2) f(order_[s], d2);
      }
    });
  }

  /// A point found by collectWithin: its index and squared distance.
  struct Found {
    uint32_t index;
    double d2;
  };

  /// Appends to `found` the points forEachWithin visits, in its order. The distance test is a
  /// select, not a branch: about every other candidate of a query's cells is outside the
  /// sphere, and a branch on it mispredicts as often.
  void collectWithin(const Vec3& p, double radius, std::vector<Found>& found) const {
    const double r2 = radius * radius;
    forEachRow(p, radius, [&](uint32_t b, uint32_t e) {
      size_t at = found.size();
      found.resize(at + (e - b));
      for (uint32_t s = b; s < e; ++s) {
        const Vec3 d = sorted_[s] - p;
        const double d2 = dot(d, d);
        found[at] = {order_[s], d2};
        at += d2 <= r2 ? 1 : 0;
      }
      found.resize(at);
    });
  }

  /// Calls f(index, position) for every point in the cells that overlap the box [lo, hi]: every
  /// point inside it and some around it. Cells are visited column by column along x (cellX
  /// ascending), so a caller can find which points a narrower x range can hold.
  template <class F>
  void forEachInCells(const Vec3& lo, const Vec3& hi, F&& f) const {
    const Vec3 a = (lo - origin_) / cell_, b = (hi - origin_) / cell_;
    const int i0 = clampCell(a.x, nx_), i1 = clampCell(b.x, nx_);
    const int j0 = clampCell(a.y, ny_), j1 = clampCell(b.y, ny_);
    const int k0 = clampCell(a.z, nz_), k1 = clampCell(b.z, nz_);
    for (int i = i0; i <= i1; ++i) {
      for (int k = k0; k <= k1; ++k) {
        for (int j = j0; j <= j1; ++j) {
          const size_t cell = (size_t(k) * size_t(ny_) + size_t(j)) * size_t(nx_) + size_t(i);
          const uint32_t e = start_[cell + 1];
          for (uint32_t s = start_[cell]; s < e; ++s) f(order_[s], sorted_[s]);
        }
      }
    }
  }

  /// The column of cells along x that holds world x (clamped to the grid).
  int cellX(double x) const { return clampCell((x - origin_.x) / cell_, nx_); }

  double cellSize() const { return cell_; }

 private:
  // Calls rows(b, e) for the sorted slots [b, e) of each row of cells (z, then y ascending) that
  // can hold points within `radius` of p. Only the part of a row within the sphere's chord at the
  // row's nearest y and z: the box's corners hold most of its volume. A margin keeps every
  // point the caller's distance test would take (it alone decides, so the sequence is the full
  // box's, filtered).
  template <class Rows>
  void forEachRow(const Vec3& p, double radius, Rows&& rows) const {
    const double r2 = radius * radius;
    const Vec3 lo = (p - Vec3(radius) - origin_) / cell_;
    const Vec3 hi = (p + Vec3(radius) - origin_) / cell_;
    const int j0 = clampCell(lo.y, ny_), j1 = clampCell(hi.y, ny_);
    const int k0 = clampCell(lo.z, nz_), k1 = clampCell(hi.z, nz_);
    const Vec3 q = (p - origin_) / cell_;  // in cells
    for (int k = k0; k <= k1; ++k) {
      const double dz = gapToCell(q.z, k, nz_) * cell_;
      for (int j = j0; j <= j1; ++j) {
        const double dy = gapToCell(q.y, j, ny_) * cell_;
        const double h2 = r2 - dy * dy - dz * dz;
        if (h2 < -1e-9 * r2) continue;
        const double h = std::sqrt(std::max(h2, 0.0)) * (1 + 1e-9) + 1e-9 * radius;
        const int i0 = clampCell(q.x - h / cell_, nx_), i1 = clampCell(q.x + h / cell_, nx_);
        const size_t row = (size_t(k) * size_t(ny_) + size_t(j)) * size_t(nx_);
        rows(start_[row + size_t(i0)], start_[row + size_t(i1) + 1]);
      }
    }
  }

  // Distance, in cells, from coordinate c to cell `i` of an axis of n (the outer cells reach to
  // infinity, as clampCell puts everything beyond them there).
  static double gapToCell(double c, int i, int n) {
    if (i > 0 && c < i) return i - c;
    if (i < n - 1 && c > i + 1) return c - (i + 1);
    return 0;
  }

  static int clampCell(double c, int n) {
    if (!(c > 0)) return 0;
    if (c >= n - 1) return n - 1;
    return int(c);
  }

  Vec3 origin_;
  double cell_ = 1;
  int nx_ = 1, ny_ = 1, nz_ = 1;
  std::vector<uint32_t> start_;  ///< first sorted slot of each cell; one extra entry at the end
  std::vector<uint32_t> order_;  ///< original point index of each sorted slot
  std::vector<Vec3> sorted_;     ///< positions in sorted order
};

/// Mean number of other points within `radius`, from `samples` points spread evenly over the
/// index range (which follows the lattice, so over the whole cloud). Deterministic. Stops early
/// and returns some value above `stop_above` once the mean is known to exceed it.
double estimateMeanNeighbours(const PointGrid& grid, const std::vector<Vec3>& points, double radius,
                              int samples = 256,
                              double stop_above = std::numeric_limits<double>::infinity());

/// std::allocator whose value-initialising resize leaves plain values uninitialised: the pair
/// arrays grow by a chunk of destinations at a time and are filled in parallel right after, so
/// zeroing them first would be a serial pass over every pair.
template <class T>
struct UninitialisedAllocator : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = UninitialisedAllocator<U>;
  };
  UninitialisedAllocator() = default;
  template <class U>
  UninitialisedAllocator(const UninitialisedAllocator<U>&) noexcept {}
  // Only the value-initialising form: with arguments, allocator_traits constructs as usual.
  template <class U>
  void construct(U* p) noexcept {
    ::new (static_cast<void*>(p)) U;
  }
};

/// Every (destination, source) pair within the cut-off with a non-negligible transfer weight,
/// as compressed rows: the sources of destination j are source[offset[j] .. offset[j + 1]).
/// Computed once, read by every pass.
struct NeighbourPairs {
  std::vector<uint64_t> offset;  ///< n + 1 entries
  std::vector<uint32_t, UninitialisedAllocator<uint32_t>> source;
  std::vector<float, UninitialisedAllocator<float>> weight;  ///< geometric weight (rule-specific)
  uint64_t within_radius = 0;  ///< pairs within the cut-off, negligible ones included

  uint64_t size() const { return source.size(); }
};

/// Builds the pairs for all destinations: weight_fn(dst, src, d) (d: distance, world units)
/// returns the pair's weight; pairs with weight <= 0 are dropped (a negligible transmittance).
/// Parallel over blocks of destinations, appended in destination order: deterministic.
/// `cancelled(fraction)` is polled between blocks of destinations; returning true stops the
/// build with Cancelled. `reserve` pre-sizes the arrays (the estimate of the pair count).
template <class WeightFn>
NeighbourPairs buildNeighbourPairs(const PointGrid& grid, const std::vector<Vec3>& points,
                                   double radius, const WeightFn& weight_fn, uint64_t reserve,
                                   const std::function<bool(double)>& cancelled) {
  NeighbourPairs pairs;
  const size_t n = points.size();
  pairs.offset.assign(n + 1, 0);
  pairs.source.reserve(size_t(reserve));
  pairs.weight.reserve(size_t(reserve));
  constexpr size_t kBlock = 256;
  constexpr size_t kChunk = 64 * kBlock;
  struct Block {
    std::vector<uint32_t> source;
    std::vector<float> weight;
    std::vector<uint32_t> count;  // pairs per destination
    uint64_t within = 0;
  };
  std::vector<Block> blocks(kChunk / kBlock);
  for (size_t chunk = 0; chunk < n; chunk += kChunk) {
    const size_t chunk_end = std::min(n, chunk + kChunk);
    const size_t nblocks = (chunk_end - chunk + kBlock - 1) / kBlock;
    ParallelOptions per_block;  // polled between blocks
    if (cancelled) {
      per_block.cancelled = [&](double f) {
        return cancelled((double(chunk) + f * double(chunk_end - chunk)) / double(n));
      };
    }
    parallelFor(
        0, int64_t(nblocks),
        [&](int64_t b) {
          Block& blk = blocks[size_t(b)];
          blk.source.clear();
          blk.weight.clear();
          blk.count.clear();
          blk.within = 0;
          const size_t d0 = chunk + size_t(b) * kBlock, d1 = std::min(chunk_end, d0 + kBlock);
          std::vector<PointGrid::Found> found;
          for (size_t dst = d0; dst < d1; ++dst) {
            uint32_t count = 0;
            found.clear();
            grid.collectWithin(points[dst], radius, found);
            for (const PointGrid::Found& f : found) {
              if (f.index == dst) continue;
              ++blk.within;
              const float w = weight_fn(uint32_t(dst), f.index, std::sqrt(f.d2));
              if (!(w > 0)) continue;
              blk.source.push_back(f.index);
              blk.weight.push_back(w);
              ++count;
            }
            blk.count.push_back(count);
          }
        },
        per_block);
    // The chunk's rows, then its blocks copied into place in parallel: appended one after
    // another they left every other thread idle.
    std::vector<uint64_t> block_start(nblocks);
    for (size_t b = 0; b < nblocks; ++b) {
      const Block& blk = blocks[b];
      const size_t d0 = chunk + b * kBlock;
      block_start[b] = pairs.offset[d0];
      for (size_t t = 0; t < blk.count.size(); ++t) {
        pairs.offset[d0 + t + 1] = pairs.offset[d0 + t] + blk.count[t];
      }
      pairs.within_radius += blk.within;
    }
    const size_t end = size_t(pairs.offset[chunk_end]);
    pairs.source.resize(end);
    pairs.weight.resize(end);
    parallelFor(0, int64_t(nblocks), [&](int64_t b) {
      const Block& blk = blocks[size_t(b)];
      std::copy(blk.source.begin(), blk.source.end(),
                pairs.source.begin() + int64_t(block_start[size_t(b)]));
      std::copy(blk.weight.begin(), blk.weight.end(),
                pairs.weight.begin() + int64_t(block_start[size_t(b)]));
    });
  }
  return pairs;
}

}  // namespace cloudbake
