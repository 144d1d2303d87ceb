#include "core/phase/mie_isotropic_blend.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "core/error.h"
#include "core/format.h"

namespace cloudbake {

MieIsotropicBlend::MieIsotropicBlend(std::shared_ptr<const PhaseFunction> inner, double ratio)
    : inner_(std::move(inner)), ratio_(ratio) {
  if (!inner_) throw InputError("phase: blend needs a phase function to wrap");
  if (!std::isfinite(ratio) || ratio < 0.0 || ratio > 1.0) {
    std::ostringstream os;
    os << "phase.ratio: Mie/isotropic ratio must be in [0, 1], got " << exactNumber(ratio);
    throw InputError(os.str());
  }
}

Rgb MieIsotropicBlend::eval(double cos_theta) const {
  return inner_->eval(cos_theta) * ratio_ + Rgb((1.0 - ratio_) * kInv4Pi);
}

double MieIsotropicBlend::pdf(double cos_theta) const {
  return ratio_ * inner_->pdf(cos_theta) + (1.0 - ratio_) * kInv4Pi;
}

double MieIsotropicBlend::sampleCosTheta(double u) const {
  if (u < ratio_) {
    return inner_->sampleCosTheta(std::min(u / ratio_, std::nextafter(1.0, 0.0)));
  }
  const double v = (u - ratio_) / (1.0 - ratio_);
  return std::clamp(1.0 - 2.0 * v, -1.0, 1.0);
}

std::string MieIsotropicBlend::describe() const {
  std::ostringstream os;
  os << "blend(" << ratio_ << " * " << inner_->describe() << " + " << (1.0 - ratio_)
     << " * isotropic)";
  return os.str();
}

}  // namespace cloudbake
