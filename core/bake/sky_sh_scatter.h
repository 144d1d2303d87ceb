// Sky single scattering in the spherical-harmonics domain (seed 002, Eq. 5): the sky radiance
// projected onto order-4 SH, the phase function's Funk-Hecke eigenvalues, and the per-render
// matrix that turns a voxel's transmittance-to-sky SH vector into the radiance it scatters
// towards a view direction.
#pragma once

#include <array>
#include <string>

#include "core/bake/phase_lut.h"
#include "core/math/spherical_harmonics.h"
#include "core/transport/sky.h"

namespace cloudbake {

namespace bake_grids {
/// float: coefficient `i` (0..15) of the SH vector of the transmittance to the sky,
/// T(x, w) = exp(-tau(x, w)) (unitless; seed 002's tau vector), written by method
/// `precomputed`. Grid name "sky_transmittance_sh_<i>".
std::string skyTransmittanceSh(int i);
}  // namespace bake_grids

/// RGB SH vectors of the sky radiance L_sky(w) (the shot's sky radiance units),
/// by quadrature over 4096 spherical-Fibonacci directions.
std::array<ShCoefficients, 3> projectSkyRadiance(const SkyLight& sky);

/// lambda_l (l = 0..3) per channel: integral of p(w . a) Y_lm(w) dw = lambda_l Y_lm(a) for any
/// unit axis a (Funk-Hecke), 2 pi integral_{-1}^{1} p(mu) P_l(mu) dmu, integrated in the lut's own
/// parameter so the forward peak is resolved. lambda_0 = 1 for a normalised phase.
std::array<std::array<double, 4>, 3> phaseEigenvalues(const PhaseLut& lut);

/// Eq. 5 for one render: integral of L_sky(w) T(x, w) p(w . d) dw = sum_i T_i (Gamma y(d))_i,
/// where Gamma (16 x 16 per channel) folds the SH triple product with L_sky and the phase
/// convolution, so each view direction costs one 16 x 16 product and each march sample one
/// dot product.
class SkyShScatter {
 public:
  SkyShScatter(const std::array<ShCoefficients, 3>& sky, const PhaseLut& lut);
  /// The 16 weights per channel for a camera ray of unit direction `d` (from the camera into
  /// the scene; w = d, light from straight behind the voxel, is forward scattering),
  /// out[c * 16 + i].
  void weights(const Vec3& d, double* out) const;

 private:
  std::array<std::array<double, kShCoefficients * kShCoefficients>, 3> gamma_{};
};

}  // namespace cloudbake
