#include "core/animation/sample_transfer.h"

#include <limits>
#include <numeric>
#include <queue>
#include <string>

#include "core/error.h"
#include "core/math/parallel.h"
#include "core/math/rng.h"

namespace cloudbake {
namespace {

// Builds the subtree over order[begin, end) and returns its node index. Nodes are appended in
// preorder, so children always follow their parent.
int buildNode(std::vector<Vec3>& pts, std::vector<int>& order, int begin, int end,
              std::vector<SampleTreeNode>& nodes) {
  const int id = int(nodes.size());
  nodes.emplace_back();
  Bounds3 box;
  Vec3 sum;
  for (int i = begin; i < end; ++i) {
    box.expand(pts[size_t(order[size_t(i)])]);
    sum = sum + pts[size_t(order[size_t(i)])];
  }
  SampleTreeNode node;
  node.begin = begin;
  node.end = end;
  node.centroid = sum / double(end - begin);
  for (int i = begin; i < end; ++i) {
    const Vec3 d = pts[size_t(order[size_t(i)])] - node.centroid;
    node.radius = std::max(node.radius, length(d));
    node.spread2 += dot(d, d) / double(end - begin);
  }
  if (end - begin > 1) {
    const Vec3 extent = box.max - box.min;
    int axis = 0;
    for (int c = 1; c < 3; ++c) {
      if (extent[c] > extent[axis]) axis = c;
    }
    const int mid = begin + (end - begin) / 2;
    std::nth_element(order.begin() + begin, order.begin() + mid, order.begin() + end,
                     [&](int p, int q) {
                       const double a = pts[size_t(p)][axis], b = pts[size_t(q)][axis];
                       return a < b || (a == b && p < q);  // a strict order: deterministic
                     });
    node.left = buildNode(pts, order, begin, mid, nodes);
    node.right = buildNode(pts, order, mid, end, nodes);
  }
  nodes[size_t(id)] = node;
  return id;
}

// Optical depth between two world points through the receiver lattice's density: trapezoids
// of at most one receiver voxel. Stops past 50 (a transfer of e^-50 is zero in float).
double opticalDepth(const BakeGrid& g, const float* density, double extinction, const Vec3& a,
                    const Vec3& b) {
  const Vec3 d = b - a;
  const double len = length(d);
  if (len <= 0) return 0;
  const int n = std::max(1, int(std::ceil(len / g.voxel_size)));
  const double dt = len / n;
  double sum = 0.5 * sampleTrilinear(g, density, a);
  for (int i = 1; i <= n; ++i) {
    const double s = sampleTrilinear(g, density, a + d * (double(i) / n));
    sum += i == n ? 0.5 * s : s;
    if (extinction * sum * dt > 50) return extinction * sum * dt;
  }
  return extinction * sum * dt;
}

}  // namespace

double representativeGeometry(const SampleTree& tree, int node, const Vec3& x) {
  const SampleTreeNode& nd = tree.nodes[size_t(node)];
  const Vec3 p = nd.leaf() ? tree.points[size_t(nd.begin)] : nd.centroid;
  const double r2 = dot(p - x, p - x);
  const double a = tree.cell_radius;
  const double convexity = nd.leaf() ? 1.0 : 1.0 + nd.spread2 / (3.0 * std::max(r2, a * a));
  return geometricTerm(r2, a) * convexity;
}

SampleTree buildSampleTree(const BakeGrid& grid, const std::vector<uint8_t>& inside, int count,
                           uint64_t seed) {
  if (count < 1) {
    throw InputError("sample points: K must be at least 1, got " + std::to_string(count));
  }
  if (inside.size() != grid.voxelCount()) {
    throw InputError("sample points: support mask has " + std::to_string(inside.size()) +
                     " voxels, the lattice " + std::to_string(grid.voxelCount()));
  }
  std::vector<size_t> cells;
  for (size_t i = 0; i < inside.size(); ++i) {
    if (inside[i]) cells.push_back(i);
  }
  if (cells.empty()) {
    throw InputError("sample points: the volume is empty (no voxel with density > 0)");
  }
  SampleTree tree;
  const double h = grid.voxel_size;
  tree.volume = double(cells.size()) * h * h * h;
  tree.cell_radius = std::cbrt(3.0 * tree.volume / (4.0 * kPi * count));
  std::vector<Vec3> pts(static_cast<size_t>(count));
  for (int k = 0; k < count; ++k) {
    Rng rng(mixBits(seed, uint64_t(k)), 0x5a3e1u);
    const size_t cell = cells[std::min(cells.size() - 1, size_t(rng.uniform() * cells.size()))];
    const int i = int(cell % size_t(grid.nx));
    const int j = int((cell / size_t(grid.nx)) % size_t(grid.ny));
    const int kz = int(cell / (size_t(grid.nx) * size_t(grid.ny)));
    const double jx = rng.uniform() - 0.5, jy = rng.uniform() - 0.5, jz = rng.uniform() - 0.5;
    pts[size_t(k)] = grid.center(i, j, kz) + Vec3(jx, jy, jz) * h;
  }
  std::vector<int> order(static_cast<size_t>(count));
  std::iota(order.begin(), order.end(), 0);
  tree.nodes.reserve(size_t(2 * count - 1));
  buildNode(pts, order, 0, count, tree.nodes);
  tree.points.resize(size_t(count));
  for (int i = 0; i < count; ++i) tree.points[size_t(i)] = pts[size_t(order[size_t(i)])];
  return tree;
}

namespace {

// A node of a receiver's cut: its clustering error and its mean transfer.
struct CutEntry {
  double error;
  int node;
  double value;  // mean T~ over the node's samples
  bool operator<(const CutEntry& o) const {
    return error < o.error || (error == o.error && node > o.node);
  }
};

// The sample tree as seen from one receiver at x.
struct ReceiverTransfer {
  const SampleTree& tree;
  const BakeGrid& receivers;
  const float* density;
  double extinction;
  Vec3 x;

  // The transfer to a node's representative point: its sample for a leaf, else its centroid.
  double transfer(int id) const {
    const SampleTreeNode& nd = tree.nodes[size_t(id)];
    const Vec3 p = nd.leaf() ? tree.points[size_t(nd.begin)] : nd.centroid;
    return representativeGeometry(tree, id, x) *
           std::exp(-opticalDepth(receivers, density, extinction, x, p));
  }

  // A node's entry from its children's representative transfers (`own`: a leaf's transfer).
  // A receiver within the node's sphere (grown by a sample cell's radius) gives it an infinite
  // error, so it is split before any other.
  CutEntry entry(int id, double own) const {
    const SampleTreeNode& nd = tree.nodes[size_t(id)];
    if (nd.leaf()) return CutEntry{0.0, id, own};
    const double vl = transfer(nd.left), vr = transfer(nd.right);
    const double nl = tree.nodes[size_t(nd.left)].count(),
                 nr = tree.nodes[size_t(nd.right)].count();
    CutEntry e{std::sqrt(nl * nr) * std::abs(vl - vr), id, (nl * vl + nr * vr) / (nl + nr)};
    if (length(x - nd.centroid) < nd.radius + tree.cell_radius) {
      e.error = std::numeric_limits<double>::infinity();
    }
    return e;
  }

  CutEntry entryOf(int id) const {
    return entry(id, tree.nodes[size_t(id)].leaf() ? transfer(id) : 0.0);
  }
};

// One receiver's cut: from the root, the node of largest error is split until every error is
// below cut_error of the cut's total or the cut holds max_cut nodes. The cut's nodes, in the
// order of their samples, and their mean transfers go to `nodes` and `values`.
void receiverCut(const ReceiverTransfer& at, const TransferCutOptions& options,
                 std::vector<uint32_t>& nodes, std::vector<float>& values) {
  const SampleTree& tree = at.tree;
  std::priority_queue<CutEntry> open;
  std::vector<CutEntry> closed;
  double total = 0;  // sum over the cut of count * mean
  auto push = [&](const CutEntry& e) {
    total += tree.nodes[size_t(e.node)].count() * e.value;
    if (tree.nodes[size_t(e.node)].leaf()) {
      closed.push_back(e);
    } else {
      open.push(e);
    }
  };
  push(at.entryOf(0));
  while (!open.empty() && int(open.size() + closed.size()) < options.max_cut) {
    const CutEntry top = open.top();
    if (top.error <= options.cut_error * total) break;
    open.pop();
    const SampleTreeNode& nd = tree.nodes[size_t(top.node)];
    total -= nd.count() * top.value;
    // The children's own transfers were computed for top's estimate; recomputing them is
    // cheaper than keeping them per open node.
    push(at.entryOf(nd.left));
    push(at.entryOf(nd.right));
  }
  while (!open.empty()) {
    closed.push_back(open.top());
    open.pop();
  }
  std::sort(closed.begin(), closed.end(), [&](const CutEntry& p, const CutEntry& q) {
    return tree.nodes[size_t(p.node)].begin < tree.nodes[size_t(q.node)].begin;
  });
  nodes.reserve(closed.size());
  values.reserve(closed.size());
  for (const CutEntry& e : closed) {
    nodes.push_back(uint32_t(e.node));
    values.push_back(float(e.value));
  }
}

// The receivers' cuts in one flat table (offsets, nodes, values).
TransferCuts packCuts(const std::vector<std::vector<uint32_t>>& node_lists,
                      const std::vector<std::vector<float>>& value_lists) {
  const size_t n = node_lists.size();
  TransferCuts cuts;
  cuts.offsets.resize(n + 1, 0);
  for (size_t r = 0; r < n; ++r) cuts.offsets[r + 1] = cuts.offsets[r] + node_lists[r].size();
  cuts.nodes.reserve(cuts.offsets[n]);
  cuts.values.reserve(cuts.offsets[n]);
  for (size_t r = 0; r < n; ++r) {
    cuts.nodes.insert(cuts.nodes.end(), node_lists[r].begin(), node_lists[r].end());
    cuts.values.insert(cuts.values.end(), value_lists[r].begin(), value_lists[r].end());
  }
  return cuts;
}

}  // namespace

TransferCuts computeTransferCuts(const SampleTree& tree, const BakeGrid& receivers,
                                 const std::vector<float>& density, double extinction,
                                 const std::vector<uint8_t>& receiver_mask,
                                 const TransferCutOptions& options,
                                 const std::function<bool(double)>& progress) {
  if (!(options.cut_error > 0 && options.cut_error <= 1)) {
    throw InputError("cut_error: must be in (0, 1], got " + std::to_string(options.cut_error));
  }
  if (options.max_cut < 1 || options.max_cut > (1 << 20)) {
    throw InputError("max_cut: must be in [1, 2^20], got " + std::to_string(options.max_cut));
  }
  if (density.size() != receivers.voxelCount() || receiver_mask.size() != receivers.voxelCount()) {
    throw InputError("transfer cuts: density or mask does not match the receiver lattice");
  }
  if (tree.nodes.empty()) throw InputError("transfer cuts: the sample tree is empty");
  const size_t n = receivers.voxelCount();
  std::vector<std::vector<uint32_t>> node_lists(n);
  std::vector<std::vector<float>> value_lists(n);
  // Receivers in parallel; progress is the cancellation poll.
  ParallelOptions per_receiver;
  if (progress) per_receiver.cancelled = [&](double f) { return !progress(f); };
  parallelFor(
      0, int64_t(n),
      [&](size_t r) {
        if (!receiver_mask[r]) return;
        const int i = int(r % size_t(receivers.nx));
        const int j = int((r / size_t(receivers.nx)) % size_t(receivers.ny));
        const int k = int(r / (size_t(receivers.nx) * size_t(receivers.ny)));
        const ReceiverTransfer at{tree, receivers, density.data(), extinction,
                                  receivers.center(i, j, k)};
        receiverCut(at, options, node_lists[r], value_lists[r]);
      },
      per_receiver);
  return packCuts(node_lists, value_lists);
}

std::vector<float> illuminationTree(const SampleTree& tree, const std::vector<float>& leaf_values) {
  if (leaf_values.size() != 3 * tree.points.size()) {
    throw InputError("illumination tree: expected 3 values per sample point");
  }
  std::vector<float> sums(3 * tree.nodes.size(), 0.f);
  for (size_t id = tree.nodes.size(); id-- > 0;) {
    const SampleTreeNode& nd = tree.nodes[id];
    for (int c = 0; c < 3; ++c) {
      sums[3 * id + size_t(c)] = nd.leaf() ? leaf_values[3 * size_t(nd.begin) + size_t(c)]
                                           : sums[3 * size_t(nd.left) + size_t(c)] +
                                                 sums[3 * size_t(nd.right) + size_t(c)];
    }
  }
  return sums;
}

}  // namespace cloudbake
