// SHEXP (Ren et al. 2006), as seed 002 uses it: the SH vector of the transmittance exp(-tau(w))
// from the SH vector of the optical depth tau, with no per-direction work at run time (Eq. 7).
#pragma once

#include <vector>

#include "core/math/spherical_harmonics.h"

namespace cloudbake {

/// The SH projection of exp(g(w)) by quadrature over `directions` spherical-Fibonacci directions:
/// the reference SHEXP approximates (and what its tables are fitted to).
ShCoefficients shExpReference(const ShCoefficients& g, int directions = 256);

/// exp_*(g) ~ exp(g_0 / sqrt(4 pi)) (a(|g^|) 1 + b(|g^|) g^), with g^ = g without its constant
/// term, 1 = (sqrt(4 pi), 0, ..., 0), and a, b tables over |g^| fitted by least squares to
/// sample vectors (seed 002: "samples a number of voxels ... applying the least square method").
/// Optically thick voxels have large |g^|, where two scalars cannot follow exp; so, as Ren et al.
/// do, g is first scaled by 2^-k to |g^| <= 1 and the result squared k times with SH products
/// (exp(g) = exp(g / 2^k)^(2^k)); the tables cover [0, 1].
class ShExp {
 public:
  /// Fits the tables to `samples` (SH vectors of -tau, e.g. of a basic volume's voxels) with
  /// `bins` bins over [0, max |g^|]; empty bins take their neighbours' values. InputError for
  /// fewer than 8 samples, bins outside [4, 4096] or a non-finite sample.
  static ShExp fit(const std::vector<ShCoefficients>& samples, int bins = 64, int directions = 256);

  /// Tables as fit() made them (a stored database): InputError unless a and b have equal sizes
  /// in [4, 4096], finite values and range >= 0.
  static ShExp fromTables(std::vector<double> a, std::vector<double> b, double range);

  /// exp_*(g). Beyond the fitted range the last bin's a and b are used (reported by range()).
  ShCoefficients operator()(const ShCoefficients& g) const;

  double range() const { return range_; }
  const std::vector<double>& a() const { return a_; }
  const std::vector<double>& b() const { return b_; }

 private:
  std::vector<double> a_, b_;
  double range_ = 0;
};

}  // namespace cloudbake
