// The sky's single scattering towards a view from a voxel's transmittance to the sky in its P1
// expansion (sky_visibility and sky_visibility_vector), with the phase function's forward peak
// split off: how methods single and pointcloud weight the phase function in the sky's light.
#pragma once

#include <algorithm>
#include <array>

#include "core/math/branchless.h"
#include "core/math/vec3.h"
#include "core/transport/sky.h"

namespace cloudbake {

/// A peaked phase function as f delta(wi = +-wo) + (1 - f) p~ (delta-M with M = 2; Wiscombe
/// 1977, J. Atmos. Sci. 34:1408): f is its second Legendre moment lambda2, the peak lies on the
/// side of its first moment lambda1 (`backward` where lambda1 < 0), and p~ keeps the first
/// moment: g_residual = (lambda1 -+ f) / (1 - f). The peak is what a P1 expansion cannot weight:
/// for HG g, f = g^2 (0.64 at g = 0.8) and g_residual = g / (1 + |g|). An isotropic phase has
/// f = 0, and so has any whose |lambda1| or peak is under 1e-6 (a quadrature's rounding). lambda1,
/// lambda2: the Legendre moments 2 pi integral p(mu) P_l(mu) dmu of a normalised phase
/// (phaseEigenvalues).
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
/// forward). Inline: views evaluate it per march sample and channel (with the sky's own P1 part,
/// p1RayWeights).
inline double p1SkyScatter(double v, const Vec3& b, const Vec3& d, double g_residual,
                           double upper) {
  return clampValue(v + 3 * g_residual * dot(b, d), 0.0, std::max(upper, 0.0));
}

/// The sky radiance's first moment per channel, (1 / 4 pi) integral L_sky(w) w dw, so that
/// L_sky(w) ~ L_mean + 3 L1 . w (its P1 expansion). Midpoint rule on 64 x 128 equal-area cells
/// (uniform in cos theta and azimuth, the horizon a cell boundary); components under 1e-12 of
/// the largest radiance met are set to 0, so a constant sky has none.
std::array<Vec3, 3> skyFirstMoment(const SkyLight& sky);

/// Per camera ray, the P1 residual's weights of V and B for each channel: the residual's sky
/// scattering per unit mean sky radiance is clamp(alpha_c V + beta_c . B, 0, upper_c), the DC and
/// P1 terms of the product of the sky's and the transmittance's P1 expansions, the P1 term
/// scaled by g~: V (1 + 3 g~ l . d) + 3 B . (l + g~ d), l = L1 / L_mean, and upper_c =
/// 1 + 3 |l|, the expansion's largest radiance over the mean. A uniform sky gives alpha = 1,
/// beta = 3 g~ d, upper = 1: p1SkyScatter.
struct P1RayWeights {
  double alpha[3];
  Vec3 beta[3];
  double upper[3];
  /// The residual's sky scattering per unit mean sky radiance at a voxel of visibility v and
  /// vector b, channel c (before the (1 - f) weight).
  double residual(int c, double v, const Vec3& b) const {
    return clampValue(alpha[c] * v + dot(beta[c], b), 0.0, upper[c]);
  }
};
/// l[c] = L1 / L_mean of channel c (0 where the mean is 0), g_residual[c] its split's.
P1RayWeights p1RayWeights(const std::array<Vec3, 3>& l, const double* g_residual, const Vec3& d);

}  // namespace cloudbake
