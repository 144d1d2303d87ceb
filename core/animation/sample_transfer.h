// Seed 002's multiple scattering (Section 3.2, Fig. 3): K sample points in the volume, a binary
// tree over them, and per receiver voxel a cut of that tree holding the clustered
// voxel-to-sample transfer T~(q, x) = T(q, x) G(q, x), so that a scattering order is a sum over
// the cut (Eq. 8) and a blended frame merges two basic volumes' cuts in log space (Eq. 9).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <vector>

#include "core/bake/bake_grid.h"

namespace cloudbake {

/// One node of the sample tree: the samples [begin, end) of SampleTree::points (a leaf holds
/// one), its children (-1 for a leaf), the samples' centroid, the radius of the sphere about
/// it that holds them (world units) and their mean squared distance from the centroid.
struct SampleTreeNode {
  int begin = 0, end = 0;
  int left = -1, right = -1;
  Vec3 centroid;
  double radius = 0;
  double spread2 = 0;
  int count() const { return end - begin; }
  bool leaf() const { return left < 0; }
};

/// K sample points uniformly distributed over a volume's support (seed 002: "sample points are
/// uniformly distributed in the volume") in the leaf order of a balanced binary tree (median
/// splits across the longest side, as lightcuts' light trees; Walter et al. 2005). Children
/// follow their parent in `nodes` (nodes[0] is the root), so a reverse sweep sums bottom-up.
struct SampleTree {
  std::vector<Vec3> points;
  std::vector<SampleTreeNode> nodes;
  double volume = 0;       ///< world volume of the support the samples are spread over
  double cell_radius = 0;  ///< a: radius of the ball of volume volume / K one sample stands for
};

/// Draws `count` points uniformly (seeded; jittered inside voxels) over the voxels of `grid`
/// whose `inside` flag is non-zero and builds their tree. InputError for count < 1 ("K = 0"),
/// an empty support or a mask of the wrong size.
SampleTree buildSampleTree(const BakeGrid& grid, const std::vector<uint8_t>& inside, int count,
                           uint64_t seed);

/// The geometric term of Eq. 8: 1 / r^2, capped at 3 / a^2, the mean of 1 / r^2 over the ball
/// of radius a a sample stands for, so a receiver on top of a sample gets that ball's exact
/// contribution instead of a singularity.
inline double geometricTerm(double r2, double cell_radius) {
  return 1.0 / std::max(r2, cell_radius * cell_radius / 3.0);
}

/// The geometric part of a cut entry's transfer at receiver `x`: G of the node's representative
/// (a leaf's sample; an inner node's centroid with the convexity correction), as the cut
/// estimate used it. A cut value divided by it is the node's transmittance.
double representativeGeometry(const SampleTree& tree, int node, const Vec3& x);

/// Options of computeTransferCuts.
struct TransferCutOptions {
  /// A cut is refined (lightcuts-style, largest error first) until every node's estimated
  /// clustering error, count * L2 error of T~ over its samples, is at most cut_error times the
  /// receiver's total sum of T~ (0, 1].
  double cut_error = 0.001;
  int max_cut = 4096;  ///< nodes per cut at most, [1, 2^20]
};

/// The cuts of one basic volume: for every receiver voxel r the entries [offsets[r],
/// offsets[r + 1]) in increasing SampleTreeNode::begin order, each a node and the mean of
/// T~(q, x_r) = G exp(-tau(q, x_r)) over its samples (world^-2). Receivers outside the mask hold
/// no entries.
struct TransferCuts {
  std::vector<uint64_t> offsets;
  std::vector<uint32_t> nodes;
  std::vector<float> values;
  size_t entries(size_t r) const { return size_t(offsets[r + 1] - offsets[r]); }
};

/// Computes the cuts of the basic volume whose density on the receiver lattice is `density`.
/// A node's mean and error are estimated from its two children's representative transfers
/// (a leaf's sample; for an inner node the transfer to its centroid with the geometric term's
/// second-order correction for the node's spread, 1 + spread2 / (3 r^2), since 1 / r^2 is
/// convex: laplacian(r^-2) = 2 r^-4): mean = (n_l v_l + n_r v_r) / n, error = sqrt(n_l n_r)
/// |v_l - v_r| (the count-weighted L2 deviation of the two-point distribution); a node whose
/// sphere (grown by a) holds the receiver is always opened. tau is marched through `density`
/// with steps of one receiver voxel. Parallel over receivers; deterministic.
/// `progress(fraction)` returning false cancels (Cancelled).
TransferCuts computeTransferCuts(const SampleTree& tree, const BakeGrid& receivers,
                                 const std::vector<float>& density, double extinction,
                                 const std::vector<uint8_t>& receiver_mask,
                                 const TransferCutOptions& options,
                                 const std::function<bool(double)>& progress = {});

/// Eq. 9 over merged cuts: calls visit(node, value) once per node of the common refinement of
/// receiver r's cuts in `a` and `b`, with value = exp(w log a + (1 - w) log b), the transfer of
/// the blended density rho = w rho_a + (1 - w) rho_b (exact for a single ray, since G is shared
/// and tau is linear in the density). A coarser node's value stands for each finer node under it.
template <typename Visit>
void mergeCuts(const TransferCuts& a, const TransferCuts& b, const SampleTree& tree, size_t r,
               double w, Visit&& visit);

/// The illumination tree: `leaf_values[k]` (3 floats per sample, in tree leaf order) summed up
/// the tree, 3 floats per node.
std::vector<float> illuminationTree(const SampleTree& tree, const std::vector<float>& leaf_values);

// ---- implementation of the template ----

template <typename Visit>
void mergeCuts(const TransferCuts& a, const TransferCuts& b, const SampleTree& tree, size_t r,
               double w, Visit&& visit) {
  uint64_t ia = a.offsets[r], ea = a.offsets[r + 1];
  uint64_t ib = b.offsets[r], eb = b.offsets[r + 1];
  auto blend = [w](double va, double vb) {
    if (w >= 1) return va;
    if (w <= 0) return vb;
    if (va <= 0 || vb <= 0) return 0.0;
    return std::exp(w * std::log(va) + (1 - w) * std::log(vb));
  };
  while (ia < ea && ib < eb) {
    const SampleTreeNode& na = tree.nodes[a.nodes[ia]];
    const SampleTreeNode& nb = tree.nodes[b.nodes[ib]];
    const double v = blend(a.values[ia], b.values[ib]);
    // Both cuts partition the leaves and tree ranges nest, so the two entries start at the same
    // leaf and the shorter one lies inside the longer.
    if (na.end == nb.end) {
      visit(na.count() <= nb.count() ? a.nodes[ia] : b.nodes[ib], v);
      ++ia;
      ++ib;
    } else if (na.end < nb.end) {
      visit(a.nodes[ia], v);
      ++ia;
    } else {
      visit(b.nodes[ib], v);
      ++ib;
    }
  }
}

}  // namespace cloudbake
