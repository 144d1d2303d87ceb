#include "core/bake/phase_lut.h"

#include <algorithm>
#include <cmath>

#include "core/math/parallel.h"

namespace cloudbake {

PhaseLut::PhaseLut(const PhaseFunction& phase, int bins)
    : bins_(std::max(bins, 8)), scale_(bins_ * std::sqrt(2.0)) {
  table_.resize(size_t(nodes()));
  for (int i = 0; i < nodes(); ++i) table_[size_t(i)] = phase.eval(nodeCosine(i));
}

PhaseLut::PhaseLut(const std::function<Rgb(double)>& p, int bins)
    : bins_(std::max(bins, 8)), scale_(bins_ * std::sqrt(2.0)) {
  table_.resize(size_t(nodes()));
  // In parallel: a droplet's convolved peak evaluates 512 values a node (PhotonPeakLight, four
  // tables of 2049 nodes for every view), and the nodes do not depend on each other (the same
  // table on any thread count).
  parallelFor(0, nodes(), [&](int64_t i) { table_[size_t(i)] = p(nodeCosine(int(i))); });
}

double PhaseLut::nodeCosine(int i) const {
  if (i <= bins_) {
    const double u = i / scale_;
    return 1 - 2 * u * u;
  }
  const double v = (2 * bins_ - i) / scale_;
  return 2 * v * v - 1;
}

}  // namespace cloudbake
