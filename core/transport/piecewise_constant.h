// Piecewise-constant 1D and 2D distributions for importance sampling tabulated functions.
#pragma once

#include <vector>

namespace cloudbake {

/// A 1D piecewise-constant density on [0, 1) proportional to `f` (n >= 1 non-negative bins);
/// sampling inverts the CDF (pbrt-v3 Distribution1D, Pharr et al. 2016, sec. 13.3.1). When all
/// values are zero the density is uniform, so sampling stays well defined; integral() is then 0.
class PiecewiseConstant1D {
 public:
  explicit PiecewiseConstant1D(std::vector<double> f);
  /// Continuous sample in [0, 1) from u in [0, 1); writes the density (w.r.t. [0,1)) and bin.
  double sample(double u, double* pdf, int* bin) const;
  /// Density at x in [0, 1).
  double pdf(double x) const;
  /// Mean of f over [0, 1) (sum f / n).
  double integral() const { return integral_; }
  int size() const { return static_cast<int>(f_.size()); }

 private:
  std::vector<double> f_, cdf_;
  double integral_ = 0;
};

/// A 2D piecewise-constant density on [0,1)^2 over an nu x nv table (u fastest): the marginal over
/// rows v, then the conditional along u within the row (pbrt-v3 Distribution2D).
class PiecewiseConstant2D {
 public:
  PiecewiseConstant2D(const std::vector<double>& f, int nu, int nv);
  /// Samples (u, v) in [0,1)^2 from two uniforms; writes the joint density.
  void sample(double u1, double u2, double* u, double* v, double* pdf) const;
  double pdf(double u, double v) const;
  /// Mean of the table.
  double integral() const { return marginal_.integral(); }

 private:
  std::vector<PiecewiseConstant1D> conditional_;
  PiecewiseConstant1D marginal_;
};

}  // namespace cloudbake
