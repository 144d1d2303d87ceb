#include "core/bake/sky_sh_scatter.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/bake/phase_lut.h"
#include "core/phase/henyey_greenstein.h"
#include "core/phase/isotropic.h"

namespace cloudbake {
namespace {

// Henyey-Greenstein's Funk-Hecke eigenvalues are g^l (lambda_0 = 1: normalised), for either sign
// of g: the quadrature must resolve a backward peak as well as a forward one.
TEST(PhaseEigenvalues, AreGToTheLForHenyeyGreenstein) {
  for (const double g : {-0.99, -0.9, -0.5, 0.0, 0.5, 0.9, 0.99}) {
    const auto lambda = phaseEigenvalues(PhaseLut(HenyeyGreensteinPhase(g)));
    for (int l = 0; l < 4; ++l) {
      EXPECT_NEAR(lambda[0][size_t(l)], std::pow(g, l), 2e-3) << "g = " << g << ", l = " << l;
    }
  }
}

// Under a uniform sky of radiance L with nothing in the way (T = 1: only the DC coefficient,
// sqrt(4 pi)), any normalised phase scatters exactly L towards every view direction.
TEST(SkyShScatter, UnshadowedUniformSkyScattersItsRadiance) {
  Sky sky;
  sky.radiance = Rgb(0.5, 1.0, 2.0);
  const SkyLight light(sky);
  for (const double g : {-0.9, 0.0, 0.85}) {
    const SkyShScatter scatter(projectSkyRadiance(light), PhaseLut(HenyeyGreensteinPhase(g)));
    double w[3 * kShCoefficients];
    scatter.weights(normalize(Vec3(0.3, -0.5, 0.8)), w);
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(w[c * kShCoefficients] * std::sqrt(4 * kPi), sky.radiance[c],
                  2e-3 * sky.radiance[c])
          << "g = " << g << ", channel " << c;
    }
  }
}

}  // namespace
}  // namespace cloudbake
