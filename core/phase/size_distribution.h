// Droplet size distributions for polydisperse Mie scattering.
#pragma once

#include <utility>

namespace cloudbake {

/// Gamma distribution of droplet radii (Hansen & Travis 1974, Space Sci. Rev. 16:527, eq. 2.56):
///   n(r) = r^alpha exp(-r / b) / (Gamma(alpha + 1) b^(alpha + 1)),
///   alpha = (1 - 3 v) / v,  b = r_eff v,
/// normalised to one droplet, r in micrometres, n in um^-1. r_eff is the area-weighted mean
/// radius and v the effective variance. Defaults: r_eff = 10 um, v = 0.1 (typical cumulus).
class GammaSizeDistribution {
 public:
  /// Throws InputError ("phase.reff: ..." / "phase.veff: ...") unless 1 <= r_eff <= 50 um and
  /// 0.01 <= v < 0.5 (narrower distributions would need resonance-resolving size sampling; at
  /// v >= 0.5 n(r) is not normalisable).
  GammaSizeDistribution(double effective_radius_um, double effective_variance);

  /// Number density n(r), um^-1; 0 for r <= 0.
  double density(double r_um) const;

  /// Radius interval holding all but a negligible tail of the scattering: outside it r^2 n(r)
  /// (lower end) and r^4 n(r) (upper end; the diffraction peak scales with r^4) are below
  /// `relative` times their maximum.
  std::pair<double, double> support(double relative = 1e-7) const;

  double effectiveRadius() const { return r_eff_; }
  double effectiveVariance() const { return v_; }
  double shape() const { return alpha_; }  ///< alpha = (1 - 3v)/v
  double scale() const { return b_; }      ///< b = r_eff v, um

 private:
  double r_eff_, v_, alpha_, b_, log_norm_;
};

}  // namespace cloudbake
