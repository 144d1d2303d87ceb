// Pearson chi-square goodness-of-fit on binned sample counts, shared by the sampler tests. Same
// conventions as the phase sampler tests (merge to >= 5 expected, Wilson-Hilferty
// critical value), but on caller-binned counts so any sampler and binning can use it.
#pragma once

#include <cmath>
#include <ostream>
#include <utility>
#include <vector>

namespace cloudbake {
namespace testing_util {

/// Upper-tail standard normal quantiles for the usual significance levels.
constexpr double kZ1e3 = 3.090;
constexpr double kZ1e4 = 3.719;

/// Upper critical value of chi-square with `dof` degrees of freedom at normal quantile z
/// (Wilson-Hilferty; accurate to < 1% for dof >= 10).
inline double chiSquareCritical(int dof, double z) {
  const double k = dof;
  const double a = 2.0 / (9.0 * k);
  return k * std::pow(1.0 - a + z * std::sqrt(a), 3.0);
}

struct BinnedChiSquare {
  double chi2 = 0;
  int dof = 0;
  double critical = 0;
  /// Samples in bins with zero expected count: the sampler produced points where the pdf says it
  /// cannot. Merging would hide them inside a neighbour's cell, so they fail the test on their own.
  double stray = 0;
  bool passes() const { return stray == 0 && dof > 0 && chi2 <= critical; }
};

inline std::ostream& operator<<(std::ostream& os, const BinnedChiSquare& r) {
  return os << "chi2 = " << r.chi2 << ", dof = " << r.dof << ", critical = " << r.critical
            << ", stray = " << r.stray;
}

/// Compares observed counts with expected counts (same binning, expected summing to the number of
/// samples). Consecutive bins in the given order are merged until each cell expects at least
/// `min_expected` samples; a short tail joins the last cell. The critical value is at normal
/// quantile `z` (kZ1e4: significance 1e-4).
inline BinnedChiSquare chiSquareBinned(const std::vector<double>& observed,
                                       const std::vector<double>& expected, double z = kZ1e4,
                                       double min_expected = 5.0) {
  BinnedChiSquare r;
  std::vector<std::pair<double, double>> cells;  // (observed, expected)
  double obs_acc = 0.0, exp_acc = 0.0;
  for (size_t b = 0; b < observed.size() && b < expected.size(); ++b) {
    if (expected[b] <= 0.0) r.stray += observed[b];
    obs_acc += observed[b];
    exp_acc += expected[b];
    if (exp_acc >= min_expected) {
      cells.emplace_back(obs_acc, exp_acc);
      obs_acc = exp_acc = 0.0;
    }
  }
  if (!cells.empty()) {
    cells.back().first += obs_acc;
    cells.back().second += exp_acc;
  }
  for (const auto& [o, e] : cells) r.chi2 += (o - e) * (o - e) / e;
  r.dof = static_cast<int>(cells.size()) - 1;
  r.critical = r.dof > 0 ? chiSquareCritical(r.dof, z) : 0.0;
  return r;
}

}  // namespace testing_util
}  // namespace cloudbake
