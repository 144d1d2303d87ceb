#include "core/bake/phase_lut.h"

#include <algorithm>
#include <cmath>

namespace cloudbake {

PhaseLut::PhaseLut(const PhaseFunction& phase, int size) : size_(std::max(size, 16)) {
  table_.resize(size_t(size_));
  for (int i = 0; i < size_; ++i) {
    const double u = double(i) / (size_ - 1);
    table_[size_t(i)] = phase.eval(1 - 2 * u * u);
  }
}

}  // namespace cloudbake
