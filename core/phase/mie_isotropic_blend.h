// A phase function diluted with isotropic scattering.
#pragma once

#include <memory>

#include "core/phase/phase_function.h"

namespace cloudbake {

/// p = R p_inner + (1 - R) / (4 pi): models a medium whose scattering is the fraction R from
/// `inner` (e.g. Mie droplets) and 1 - R isotropic (e.g. multiple-scattering haze). R in [0, 1].
/// Sampling picks `inner` with probability R, so pdf = R pdf_inner + (1 - R) / (4 pi).
class MieIsotropicBlend final : public PhaseFunction {
 public:
  /// Throws InputError ("phase.ratio: ...") unless 0 <= ratio <= 1; `inner` must be non-null.
  MieIsotropicBlend(std::shared_ptr<const PhaseFunction> inner, double ratio);

  Rgb eval(double cos_theta) const override;
  double pdf(double cos_theta) const override;
  double sampleCosTheta(double u) const override;
  bool chromatic() const override { return inner_->chromatic(); }
  Rgb meanCosine() const override { return inner_->meanCosine() * ratio_; }
  std::string describe() const override;

  double ratio() const { return ratio_; }
  const PhaseFunction& inner() const { return *inner_; }

 private:
  std::shared_ptr<const PhaseFunction> inner_;
  double ratio_;
};

}  // namespace cloudbake
