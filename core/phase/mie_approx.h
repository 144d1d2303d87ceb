// Jendersie & d'Eon's approximate Mie phase function for water droplets (HG + Draine blend).
#pragma once

#include "core/phase/phase_function.h"

namespace cloudbake {

/// Parameters of the HG + Draine blend for one droplet diameter.
struct MieApproxParams {
  double g_hg = 0;   ///< asymmetry of the Henyey-Greenstein lobe
  double g_d = 0;    ///< asymmetry of the Draine lobe
  double alpha = 0;  ///< Draine's alpha
  double w_d = 0;    ///< weight of the Draine lobe, in [0, 1]
};

/// The paper's fits for 5 <= d <= 50 micrometres (Jendersie & d'Eon 2023, "An Approximate Mie
/// Scattering Function for Fog and Cloud Rendering", SIGGRAPH Talks, eqs. for large droplets).
/// Throws InputError ("phase.d: ...") outside that range.
MieApproxParams mieApproxParams(double diameter_um);

/// p = (1 - w_d) HG(g_hg) + w_d Draine(g_d, alpha), grey. Sampling picks a lobe with
/// probability equal to its weight and then samples it exactly, so pdf == eval.
/// Parameter: droplet diameter d in micrometres, 5..50 (default 20 in PhaseSpec).
class MieApproxPhase final : public PhaseFunction {
 public:
  explicit MieApproxPhase(double diameter_um);

  Rgb eval(double cos_theta) const override { return Rgb(value(cos_theta)); }
  double pdf(double cos_theta) const override { return value(cos_theta); }
  double sampleCosTheta(double u) const override;
  Rgb meanCosine() const override;
  std::string describe() const override;

  const MieApproxParams& params() const { return p_; }

 private:
  double value(double cos_theta) const;
  double diameter_um_;
  MieApproxParams p_;
};

}  // namespace cloudbake
