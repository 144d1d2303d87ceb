// Builds a phase function from its user-facing description (shot files, `cloudbake phase`).
#pragma once

#include <functional>
#include <memory>
#include <string>

#include "core/phase/phase_function.h"

namespace cloudbake {

/// Description of a phase function, mirroring shot-format `medium.phase`.
struct PhaseSpec {
  enum class Type { kIsotropic, kHenyeyGreenstein, kMieApprox, kMie };
  Type type = Type::kIsotropic;
  double g = 0.0;                     ///< hg: asymmetry in (-1, 1)
  double diameter_um = 20.0;          ///< mie_approx: droplet diameter, micrometres (5..50)
  double effective_radius_um = 10.0;  ///< mie: effective radius of the gamma size distribution
  double effective_variance = 0.1;    ///< mie: effective variance (dimensionless, > 0)
  /// Any type: Mie/isotropic ratio R in [0, 1]; p = R p_type + (1 - R) / (4 pi). 1 = unblended.
  double mie_ratio = 1.0;
};

/// Throws InputError naming the parameter when a value is out of range. `keep_going`: as for
/// MieTablePhase (only a Lorenz-Mie table takes long enough to need it).
std::shared_ptr<const PhaseFunction> makePhaseFunction(
    const PhaseSpec& spec, const std::function<bool()>& keep_going = {});

/// Parses the compact CLI form, e.g. "isotropic", "hg:g=0.75", "mie_approx:d=20",
/// "mie:reff=10,veff=0.1"; any form may add "ratio=R" (e.g. "mie:reff=10,ratio=0.3").
/// Throws InputError on unknown names or bad values.
PhaseSpec parsePhaseSpec(const std::string& text);

}  // namespace cloudbake
