// The sky's single scattering towards a view from a voxel's transmittance to the sky in its P1
// expansion (sky_visibility and sky_visibility_vector), with the phase function's forward peak
// split off: how methods single and pointcloud weight the phase function in the sky's light.
#pragma once

#include <algorithm>

#include "core/math/vec3.h"

namespace cloudbake {

/// A peaked phase function as f delta(wi = +-wo) + (1 - f) p~ (delta-M with M = 2; Wiscombe
/// 1977, J. Atmos. Sci. 34:1408): f is its second Legendre moment lambda2, the peak lies on the
/// side of its first moment lambda1 (`backward` where lambda1 < 0), and p~ keeps the first
/// moment: g_residual = (lambda1 -+ f) / (1 - f). The peak is what a P1 expansion cannot weight:
/// for HG g, f = g^2 (0.64 at g = 0.8) and g_residual = g / (1 + |g|). An isotropic phase has
/// f = 0. lambda1, lambda2: the Legendre moments 2 pi integral p(mu) P_l(mu) dmu of a normalised
/// phase (phaseEigenvalues).
struct DeltaSplit {
  double f = 0;
  double g_residual = 0;
  bool backward = false;
};
DeltaSplit deltaSplit(double lambda1, double lambda2);

/// integral T(w) p~(w . d) dw for the transmittance's P1 expansion T(w) ~ v + 3 b . w, where
/// v = (1 / 4 pi) integral T dw and b = (1 / 4 pi) integral T w dw (w towards the sky) and p~
/// has mean cosine g_residual: v + 3 g_residual b . d, clamped to [0, upper]. The expansion of a
/// transmittance that changes steeply across directions over- and undershoots, while the
/// integral of T <= 1 against a normalised p~ lies in [0, 1]: upper = 1 for one voxel. d: unit
/// direction of the camera ray, from the camera into the scene (sky light from w = d scatters
/// forward). Linear in (v, b) before the clamp, so a view applies it to the integrals of v and b
/// along a ray, with upper the integral of 1 (the ray's opacity).
/// Inline: a view evaluates it per march sample and channel.
inline double p1SkyScatter(double v, const Vec3& b, const Vec3& d, double g_residual,
                           double upper) {
  return std::clamp(v + 3 * g_residual * dot(b, d), 0.0, std::max(upper, 0.0));
}

}  // namespace cloudbake
