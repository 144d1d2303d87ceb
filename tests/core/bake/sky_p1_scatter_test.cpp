// The sky's single scattering from the transmittance's P1 expansion with the phase function's
// forward peak split off (delta-M): the split's moments, the furnace, and a half-space's sky
// against the exact integral.
#include "core/bake/sky_p1_scatter.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>

#include "core/bake/phase_lut.h"
#include "core/bake/sky_sh_scatter.h"
#include "core/phase/henyey_greenstein.h"
#include "core/phase/isotropic.h"
#include "core/transport/sky.h"

namespace cloudbake {
namespace {

// Henyey-Greenstein's moments are g^l: the peak is g^2, on g's side, and the residual's mean
// cosine g / (1 + |g|); together they keep the phase's mean cosine.
TEST(DeltaSplit, KeepsThePhasesFirstTwoMoments) {
  for (const double g : {-0.95, -0.5, -0.2, 0.2, 0.5, 0.8, 0.95}) {
    const DeltaSplit s = deltaSplit(g, g * g);
    EXPECT_NEAR(s.f, g * g, 1e-12);
    EXPECT_EQ(s.backward, g < 0);
    EXPECT_NEAR(s.g_residual, g / (1 + std::abs(g)), 1e-12);
    // Mean cosine of f delta(+-1) + (1 - f) p~ is the phase's own.
    EXPECT_NEAR((s.backward ? -s.f : s.f) + (1 - s.f) * s.g_residual, g, 1e-12);
  }
  const DeltaSplit iso = deltaSplit(0, 0);
  EXPECT_EQ(iso.f, 0);
  EXPECT_EQ(iso.g_residual, 0);
  // An isotropic phase's moments from its table are rounding, not a peak: none, either way.
  const auto lambda = phaseEigenvalues(PhaseLut(IsotropicPhase()));
  const DeltaSplit table = deltaSplit(lambda[0][1], lambda[0][2]);
  EXPECT_EQ(table.f, 0);
  EXPECT_FALSE(table.backward);
  EXPECT_EQ(deltaSplit(-5e-16, 1.25e-9).f, 0);
  EXPECT_FALSE(deltaSplit(-5e-16, 1.25e-9).backward);
  // A second moment above the first (a phase with lobes both ways) is capped so the residual
  // never peaks the other way; a pure delta leaves no residual.
  const DeltaSplit capped = deltaSplit(0.3, 0.5);
  EXPECT_EQ(capped.f, 0.3);
  EXPECT_EQ(capped.g_residual, 0);
  const DeltaSplit delta = deltaSplit(1, 1);
  EXPECT_EQ(delta.f, 1);
  EXPECT_EQ(delta.g_residual, 0);
  const DeltaSplit back = deltaSplit(-1, 1);
  EXPECT_EQ(back.f, 1);
  EXPECT_TRUE(back.backward);
  EXPECT_EQ(back.g_residual, 0);
}

// A voxel that sees the whole sky (T = 1: V = 1, B = 0) scatters exactly the sky's radiance
// towards any view, for any split: the peak's share sees the sky behind (T = 1) and the
// residual's the mean.
TEST(P1SkyScatter, AnUnshadowedVoxelScattersTheSky) {
  for (const double g : {-0.7, 0.0, 0.6, 0.9}) {
    const DeltaSplit s = deltaSplit(g, g * g);
    for (const Vec3& d : {Vec3(0, 0, 1), normalize(Vec3(0.3, -0.5, 0.8))}) {
      const double j = (1 - s.f) * p1SkyScatter(1, Vec3(0.0), d, s.g_residual, 1) + s.f * 1;
      EXPECT_NEAR(j, 1.0, 1e-12) << "g = " << g;
    }
  }
}

// integral over the sky seen above a plane with normal n (T = 1 where w . n > 0, else 0) of
// HG(w . d), by a fine quadrature in the angle about d.
double halfSpaceExact(double g, const Vec3& n, const Vec3& d) {
  const Vec3 a = std::abs(d.x) < 0.9 ? Vec3(1, 0, 0) : Vec3(0, 1, 0);
  const Vec3 u = normalize(cross(d, a)), v = cross(d, u);
  const int nt = 2000, np = 256;
  double sum = 0;
  for (int it = 0; it < nt; ++it) {
    // Cosines about d, denser towards the forward peak.
    const double x = (it + 0.5) / nt, mu = 1 - 2 * x * x, dmu = 4 * x / nt;
    const double s = std::sqrt(std::max(0.0, 1 - mu * mu));
    int lit = 0;
    for (int ip = 0; ip < np; ++ip) {
      const double ph = (ip + 0.5) * 2 * kPi / np;
      const Vec3 w = d * mu + (u * std::cos(ph) + v * std::sin(ph)) * s;
      lit += dot(w, n) > 0;
    }
    sum += hgEval(g, mu) * dmu * 2 * kPi * lit / np;
  }
  return sum;
}

// A voxel at the top of an opaque half-space sees the upper half of the sky: V = 1/2,
// B = n / 4. Seen along n (the sky behind it: forward scattering) and against n (the medium
// behind it), HG 0.8 scatters 0.95 and 0.05 of the sky; the split P1 is within 0.02 of both,
// and of two oblique views, where the ambient term gave 0.5 to all. HG -0.8 mirrors it (its
// peak sees the sky in front of the voxel).
TEST(P1SkyScatter, AHalfSpacesSkyWithinAFewPercentOfTheExactIntegral) {
  const Vec3 n(0, 0, 1);
  for (const double g : {0.8, -0.8}) {
    const auto lambda = phaseEigenvalues(PhaseLut(HenyeyGreensteinPhase(g)));
    const DeltaSplit s = deltaSplit(lambda[0][1], lambda[0][2]);
    for (const Vec3& d : {n, -n, normalize(Vec3(1, 0, 1)), normalize(Vec3(1, 0, -1))}) {
      const double exact = halfSpaceExact(g, n, d);
      const Vec3 peak_dir = s.backward ? -d : d;
      const double peak = dot(peak_dir, n) > 0 ? 1.0 : 0.0;  // T(x, +-d)
      const double j = (1 - s.f) * p1SkyScatter(0.5, n * 0.25, d, s.g_residual, 1) + s.f * peak;
      EXPECT_NEAR(j, exact, 0.02) << "g = " << g << ", d = " << d.x << " " << d.y << " " << d.z;
    }
  }
  EXPECT_NEAR(halfSpaceExact(0.8, n, n), 0.949, 0.002);
  EXPECT_NEAR(halfSpaceExact(0.8, n, -n), 0.051, 0.002);
  // The expansion of a steep transmittance overshoots both ways; the scattering stays within
  // [0, upper].
  EXPECT_EQ(p1SkyScatter(0.5, n * 0.5, -n, 0.9, 1), 0.0);
  EXPECT_EQ(p1SkyScatter(0.5, n * 0.5, n, 0.9, 1), 1.0);
  EXPECT_EQ(p1SkyScatter(0.2, n * 0.2, n, 0.9, 0.3), 0.3);
}

// The sky's first moment: none for a constant sky; for a gradient sky (1/4 pi) integral L z dw =
// H / 4 + (Z - H) / 6 - G / 4 (azimuth integrated out; L = H + (Z - H) z above the horizon, G
// below), and none across.
TEST(SkyFirstMoment, IsZeroForAConstantSkyAndExactForAGradient) {
  Sky constant;
  constant.radiance = Rgb(0.3, 0.5, 2.0);
  for (const Vec3& m : skyFirstMoment(SkyLight(constant))) EXPECT_EQ(m, Vec3(0.0));
  Sky gradient;
  gradient.type = Sky::Type::kGradient;
  gradient.zenith = Rgb(1.0, 0.5, 0.2);
  gradient.horizon = Rgb(0.4, 0.4, 0.4);
  gradient.ground = Rgb(0.1, 0.0, 0.8);
  const std::array<Vec3, 3> m = skyFirstMoment(SkyLight(gradient));
  for (int c = 0; c < 3; ++c) {
    const double z = gradient.zenith[c], h = gradient.horizon[c], g = gradient.ground[c];
    EXPECT_NEAR(m[size_t(c)].z, h / 4 + (z - h) / 6 - g / 4, 1e-4) << c;
    EXPECT_NEAR(m[size_t(c)].x, 0.0, 1e-12) << c;
    EXPECT_NEAR(m[size_t(c)].y, 0.0, 1e-12) << c;
  }
  Sky black;
  black.radiance = Rgb(0.0);
  for (const Vec3& v : skyFirstMoment(SkyLight(black))) EXPECT_EQ(v, Vec3(0.0));
}

// The per-ray weights: a uniform sky gives p1SkyScatter's, and the product of two P1
// expansions integrates exactly, here for T = 1 (V = 1, B = 0): the residual then scatters
// the sky's P1 radiance convolved with p~, 1 + 3 g~ l . d per unit mean.
TEST(P1RayWeights, ReduceToTheUniformSkysAndScatterTheSkysDipole) {
  const double g[3] = {0.44, 0.0, -0.3};
  const Vec3 d = normalize(Vec3(0.2, -0.4, 0.9)), b(0.05, -0.1, 0.2);
  const std::array<Vec3, 3> none{Vec3(0.0), Vec3(0.0), Vec3(0.0)};
  const P1RayWeights w = p1RayWeights(none, g, d);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(w.alpha[c] * 0.6 + dot(w.beta[c], b), p1SkyScatter(0.6, b, d, g[c], 1), 1e-12);
    EXPECT_EQ(w.upper[c], 1.0);
  }
  const std::array<Vec3, 3> l{Vec3(0, 0, 0.2), Vec3(0.1, 0, 0), Vec3(0, 0.1, -0.1)};
  const P1RayWeights wl = p1RayWeights(l, g, d);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(wl.alpha[c], 1 + 3 * g[c] * dot(l[size_t(c)], d), 1e-12);
    EXPECT_NEAR(wl.upper[c], 1 + 3 * length(l[size_t(c)]), 1e-12);
    // The product's cross terms by quadrature: (1/4 pi) integral of the sky's and the
    // transmittance's P1 expansions times p~'s P1 expansion, (1 + 3 l . w)(V + 3 B . w)
    // (1 + 3 g~ w . d), is exactly alpha V + beta . B (the degree-2 part of the product meets
    // the weight's degree-1 part only in odd terms, which vanish).
    const double v = 0.6;
    const int n = 400;
    double sum = 0;
    for (int i = 0; i < n; ++i) {
      const double z = 1 - 2 * (i + 0.5) / n, r = std::sqrt(1 - z * z);
      for (int j = 0; j < 2 * n; ++j) {
        const double phi = kPi * (j + 0.5) / n;
        const Vec3 w(r * std::cos(phi), r * std::sin(phi), z);
        const double sky = 1 + 3 * dot(l[size_t(c)], w), t = v + 3 * dot(b, w);
        sum += sky * t * (1 + 3 * g[c] * dot(w, d));
      }
    }
    sum /= double(n) * 2 * n;
    EXPECT_NEAR(wl.alpha[c] * v + dot(wl.beta[c], b), sum, 1e-4) << c;
  }
}

}  // namespace
}  // namespace cloudbake
