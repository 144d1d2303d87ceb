#include "core/phase/size_distribution.h"

#include <cmath>
#include <sstream>

#include "core/error.h"
#include "core/format.h"

namespace cloudbake {

GammaSizeDistribution::GammaSizeDistribution(double r_eff, double v) : r_eff_(r_eff), v_(v) {
  if (!std::isfinite(r_eff) || r_eff < 1.0 || r_eff > 50.0) {
    std::ostringstream os;
    os << "phase.reff: effective radius must be in [1, 50] micrometres, got " << exactNumber(r_eff);
    throw InputError(os.str());
  }
  if (!std::isfinite(v) || v < 0.01 || v >= 0.5) {
    std::ostringstream os;
    os << "phase.veff: effective variance must be in [0.01, 0.5), got " << exactNumber(v);
    throw InputError(os.str());
  }
  alpha_ = (1.0 - 3.0 * v) / v;
  b_ = r_eff * v;
  log_norm_ = -std::lgamma(alpha_ + 1.0) - (alpha_ + 1.0) * std::log(b_);
}

double GammaSizeDistribution::density(double r) const {
  if (!(r > 0.0)) return 0.0;
  return std::exp(log_norm_ + alpha_ * std::log(r) - r / b_);
}

std::pair<double, double> GammaSizeDistribution::support(double relative) const {
  // log of r^k n(r) relative to its maximum at r = (alpha + k) b.
  const double log_rel = std::log(relative);
  auto solve = [&](double k, bool upper) {
    const double e = alpha_ + k;
    const double r_mode = e * b_;
    auto f = [&](double r) { return e * std::log(r / r_mode) - (r - r_mode) / b_ - log_rel; };
    double lo = upper ? r_mode : r_mode * 1e-12, hi = r_mode;
    if (upper) {
      while (f(hi) > 0.0) hi = hi * 1.5 + b_;
    }
    for (int i = 0; i < 200; ++i) {
      const double mid = 0.5 * (lo + hi);
      if ((f(mid) > 0.0) == upper)
        lo = mid;
      else
        hi = mid;
    }
    return 0.5 * (lo + hi);
  };
  // alpha > -1, so both exponents are positive and each side has exactly one crossing.
  return {solve(2.0, false), solve(4.0, true)};
}

}  // namespace cloudbake
