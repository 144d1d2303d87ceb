#include "core/bake/sky_sh_scatter.h"

#include <cmath>

namespace cloudbake {

namespace bake_grids {
std::string skyTransmittanceSh(int i) { return "sky_transmittance_sh_" + std::to_string(i); }
}  // namespace bake_grids

namespace {
int degree(int i) { return i < 1 ? 0 : i < 4 ? 1 : i < 9 ? 2 : 3; }
}  // namespace

std::array<ShCoefficients, 3> projectSkyRadiance(const SkyLight& sky) {
  std::array<std::array<double, kShCoefficients>, 3> sum{};
  constexpr int kDirections = 4096;
  const double golden = kPi * (3.0 - std::sqrt(5.0));
  for (int n = 0; n < kDirections; ++n) {
    const double z = 1.0 - (2.0 * n + 1.0) / kDirections;
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    const Vec3 w(r * std::cos(golden * n), r * std::sin(golden * n), z);
    const Rgb l = sky.radiance(w);
    const auto y = shBasis(w);
    for (int c = 0; c < 3; ++c)
      for (int i = 0; i < kShCoefficients; ++i) sum[size_t(c)][size_t(i)] += l[c] * y[size_t(i)];
  }
  std::array<ShCoefficients, 3> out{};
  for (int c = 0; c < 3; ++c)
    for (int i = 0; i < kShCoefficients; ++i) {
      out[size_t(c)][size_t(i)] = float(sum[size_t(c)][size_t(i)] * 4 * kPi / kDirections);
    }
  return out;
}

std::array<std::array<double, 4>, 3> phaseEigenvalues(const PhaseLut& lut) {
  // Midpoint rule in u = sin(theta / 2) over the forward hemisphere and v = cos(theta / 2) over
  // the backward one (mu = 1 - 2 u^2 = 2 v^2 - 1, |dmu| = 4 u du = 4 v dv): steps uniform in
  // theta at both ends, so a forward and a backward peak are resolved alike (PhaseLut).
  std::array<std::array<double, 4>, 3> lambda{};
  constexpr int kSteps = 10000;  // per hemisphere
  const double half = std::sqrt(0.5);
  for (int side = 0; side < 2; ++side) {
    for (int n = 0; n < kSteps; ++n) {
      const double s = (n + 0.5) / kSteps * half;
      const double mu = side == 0 ? 1 - 2 * s * s : 2 * s * s - 1;
      const double legendre[4] = {1, mu, 0.5 * (3 * mu * mu - 1),
                                  0.5 * (5 * mu * mu * mu - 3 * mu)};
      const Rgb p = lut.eval(mu);
      const double w = 2 * kPi * 4 * s * half / kSteps;
      for (int c = 0; c < 3; ++c)
        for (int l = 0; l < 4; ++l) lambda[size_t(c)][size_t(l)] += w * p[c] * legendre[l];
    }
  }
  return lambda;
}

SkyShScatter::SkyShScatter(const std::array<ShCoefficients, 3>& sky, const PhaseLut& lut) {
  const auto lambda = phaseEigenvalues(lut);
  for (int c = 0; c < 3; ++c) {
    // Column j: the triple product of L_sky with lambda_l(j) Y_j, i.e. the projection of
    // L_sky(w) p(w . d) restricted to the Y_j(d) part, d the view direction.
    for (int j = 0; j < kShCoefficients; ++j) {
      ShCoefficients e{};
      e[size_t(j)] = float(lambda[size_t(c)][size_t(degree(j))]);
      const ShCoefficients col = shProduct(sky[size_t(c)], e);
      for (int i = 0; i < kShCoefficients; ++i) {
        gamma_[size_t(c)][size_t(i * kShCoefficients + j)] = col[size_t(i)];
      }
    }
  }
}

void SkyShScatter::weights(const Vec3& d, double* out) const {
  // The phase is evaluated as p(w . d), w towards the sky: w = d is straight-on forward
  // scattering (as the sun term's p(sun_dir . d)).
  const auto y = shBasis(d);
  for (int c = 0; c < 3; ++c)
    for (int i = 0; i < kShCoefficients; ++i) {
      double s = 0;
      for (int j = 0; j < kShCoefficients; ++j) {
        s += gamma_[size_t(c)][size_t(i * kShCoefficients + j)] * y[size_t(j)];
      }
      out[c * kShCoefficients + i] = s;
    }
}

}  // namespace cloudbake
