// SHEXP (Ren et al. 2006), as seed 002 uses it: the SH vector of the transmittance exp(-tau(w))
// from the SH vector of the optical depth tau, with no per-direction work at run time (Eq. 7).
#pragma once

#include <array>
#include <cstddef>
#include <vector>

#include "core/math/spherical_harmonics.h"

namespace cloudbake {

/// The real SH basis at `directions` spherical-Fibonacci directions, in two layouts: by
/// direction, and by coefficient ([i * stride + d], for loops that run across directions; each
/// row padded with zeros to a whole number of kBlock directions).
struct ShQuadrature {
  static constexpr size_t kBlock = 16;
  ShQuadrature() = default;
  explicit ShQuadrature(int directions);
  std::vector<std::array<double, kShCoefficients>> by_direction;
  std::vector<double> by_coefficient;
  size_t stride = 0;
};

/// The SH projection of exp(g(w)) by quadrature over `directions` spherical-Fibonacci directions:
/// the reference SHEXP approximates (and what its tables are fitted to).
ShCoefficients shExpReference(const ShCoefficients& g, int directions = 256);

/// exp_*(g) ~ exp(g_0 / sqrt(4 pi)) (a(|g^|) 1 + b(|g^|) g^), with g^ = g without its constant
/// term, 1 = (sqrt(4 pi), 0, ..., 0), and a, b tables over |g^| fitted by least squares to
/// sample vectors (seed 002: "samples a number of voxels ... applying the least square method").
/// The tables cover |g^| in [0, 1]. Optically thick voxels have larger |g^|, where two scalars
/// cannot follow exp. Ren et al. scale g by 2^-k and square the result k times with SH products
/// (exp(g) = exp(g / 2^k)^(2^k)), but at order 4 each product truncates and the squarings
/// amplify the truncation: voxels of optical depth 300 came out with "transmittances" of 1e4,
/// 1e18 at 1000, and the sky light they scattered with them. Beyond the tables this therefore
/// projects exp(min(0, g(w))) onto the SH basis by quadrature over 256 directions (the
/// reference below, with g(w) = -tau(w) kept <= 0 where the order-4 optical depth rings
/// negative): a function within [0, 1] in every direction, at about 10 us per voxel.
class ShExp {
 public:
  /// Fits the tables to `samples` (SH vectors of -tau, e.g. of a basic volume's voxels) with
  /// `bins` bins over [0, max |g^|]; empty bins take their neighbours' values. InputError for
  /// fewer than 8 samples, bins outside [4, 4096] or a non-finite sample.
  static ShExp fit(const std::vector<ShCoefficients>& samples, int bins = 64, int directions = 256);

  /// Tables as fit() made them (a stored database): InputError unless a and b have equal sizes
  /// in [4, 4096], finite values and range >= 0.
  static ShExp fromTables(std::vector<double> a, std::vector<double> b, double range);

  /// exp_*(g) for |g^| <= 1 (within the fitted range the tables are interpolated, beyond it the
  /// last bin's a and b are used); the quadrature projection for |g^| > 1.
  ShCoefficients operator()(const ShCoefficients& g) const;

  double range() const { return range_; }
  const std::vector<double>& a() const { return a_; }
  const std::vector<double>& b() const { return b_; }

 private:
  static constexpr int kQuadratureDirections = 256;
  ShCoefficients projectTransmittance(const ShCoefficients& g) const;

  std::vector<double> a_, b_;
  double range_ = 0;
  ShQuadrature quadrature_;  // at kQuadratureDirections directions
};

}  // namespace cloudbake
