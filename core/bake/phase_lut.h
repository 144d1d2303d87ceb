// A fast tabulated form of any phase function, for the inner loops of bakes and bake renders.
#pragma once

#include <functional>
#include <vector>

#include "core/math/vec3.h"
#include "core/phase/phase_function.h"

namespace cloudbake {

/// p(cos theta) per RGB channel, tabulated on two variables that are uniform in theta at either
/// end: u = sin(theta / 2) = sqrt((1 - cos theta) / 2) over the forward hemisphere and
/// v = cos(theta / 2) = sqrt((1 + cos theta) / 2) over the backward one, `bins` bins each, with
/// linear interpolation. So the narrow forward peak of a cloud's Mie phase function (a fraction
/// of a degree wide) and the backward peak of a strongly backscattering one (HG g = -0.99: 0.6
/// degrees) are both resolved while lookups need only a square root, no acos. (A table in u
/// alone has bins of 2.5 degrees at the backward end: it smeared HG -0.99's peak over four
/// times its solid angle, and every integral of the phase there came out 4x too large.) Values
/// in sr^-1, theta = 0 forward (core/phase/phase_function.h). Default 4096 bins per hemisphere:
/// 0.02 deg at either peak.
class PhaseLut {
 public:
  explicit PhaseLut(const PhaseFunction& phase, int bins = 4096);
  /// The same table of any function of cos theta (such as a phase convolved with a PeakKernel),
  /// which it calls from several threads at once.
  PhaseLut(const std::function<Rgb(double)>& p, int bins);
  Rgb eval(double cos_theta) const {
    // NaN reads as -1 rather than an index outside the table.
    const double c = cos_theta >= -1 ? (cos_theta > 1 ? 1 : cos_theta) : -1;
    const double x =
        c >= 0 ? std::sqrt(0.5 * (1 - c)) * scale_ : 2 * bins_ - std::sqrt(0.5 * (1 + c)) * scale_;
    int i = int(x);
    if (i >= 2 * bins_) i = 2 * bins_ - 1;
    const double t = x - i;
    return table_[size_t(i)] * (1 - t) + table_[size_t(i) + 1] * t;
  }
  /// Luminance-weighted value, for scalar weights.
  double evalLuminance(double cos_theta) const { return luminance(eval(cos_theta)); }

  /// cos theta of table node `i` in [0, 2 bins] (ascending theta), for quadratures that follow
  /// the table's resolution.
  double nodeCosine(int i) const;
  int nodes() const { return 2 * bins_ + 1; }

  /// The same table: equal bin counts and == values (what a table's users compute from it
  /// depends on nothing else; +0 and -0 compare equal and give the same results).
  bool operator==(const PhaseLut& o) const { return bins_ == o.bins_ && table_ == o.table_; }

 private:
  int bins_;
  double scale_;  // bins / sqrt(1/2): node index per unit of u or v
  std::vector<Rgb> table_;
};

}  // namespace cloudbake
