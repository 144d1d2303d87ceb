// Level 2 of the verification ladder: the plane-parallel slab of van de Hulst (1980).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <functional>
#include <memory>
#include <string>

#include "core/io/exr_io.h"
#include "core/math/rng.h"
#include "core/phase/henyey_greenstein.h"
#include "core/transport/path_tracer.h"
#include "core/transport/tracking.h"
#include "core/volume/analytic.h"
#include "tests/core/transport/test_util.h"

namespace cloudbake {
namespace {

using testing_util::Stats;

// HG g = 0.75, albedo 0.9, optical thickness 2, normal incidence. Diffuse reflectance and total
// transmittance from van de Hulst (1980), as quoted in the MCML validation table (Wang, Jacques &
// Zheng 1995, Table 3): R_d = 0.09739, T_t = 0.66096.
constexpr double kG = 0.75, kAlbedo = 0.9, kTau = 2.0;
constexpr double kVdhReflectance = 0.09739, kVdhTransmittance = 0.66096;
// Reflection function pi L / (mu0 E) at mu = mu0 = 1 for the same slab (van de Hulst 1980),
// quoted to 3 significant digits: the comparison allows the rounding (5e-5) plus 4 sigma.
constexpr double kVdhNadirReflectivity = 0.0618;

// A slab wide enough that no particle leaves through the sides: z in [0, 1], extinction 2.
std::shared_ptr<BoxDensity> makeSlab() {
  return std::make_shared<BoxDensity>(Vec3(-1e4, -1e4, 0), Vec3(1e4, 1e4, 1), 1.0);
}

// Light tracing built from the transport building blocks: particles enter at the top moving
// down, each real collision scatters (probability = albedo) or absorbs; the exit side is tallied.
TEST(VanDeHulstSlab, ReflectanceAndTransmittanceByParticleTracing) {
  const auto slab = makeSlab();
  const HenyeyGreensteinPhase phase(kG);
  auto lookup = slab->lookup();
  Rng rng(2024, 1);
  const int n = 4000000;
  Stats reflected, transmitted;
  for (int i = 0; i < n; ++i) {
    Ray ray{Vec3(0, 0, 1), Vec3(0, 0, -1)};
    double r = 0, t = 0;
    while (true) {
      const Collision c = deltaTrack(*slab, *lookup, kTau, ray, 0, 1e300, rng);
      if (!c.hit) {
        (ray.d.z > 0 ? r : t) = 1;
        break;
      }
      if (rng.uniform() >= kAlbedo) break;  // absorbed
      const double u1 = rng.uniform(), u2 = rng.uniform();
      ray = {c.p, phase.sample(ray.d, u1, u2).direction};
    }
    reflected.add(r);
    transmitted.add(t);
  }
  std::printf("particle tracing: R_d = %.5f +- %.5f (vdH %.5f), T_t = %.5f +- %.5f (vdH %.5f)\n",
              reflected.mean(), reflected.stderror(), kVdhReflectance, transmitted.mean(),
              transmitted.stderror(), kVdhTransmittance);
  EXPECT_NEAR(reflected.mean(), kVdhReflectance, 4 * reflected.stderror());
  EXPECT_NEAR(transmitted.mean(), kVdhTransmittance, 4 * transmitted.stderror());
}

Camera nadirCamera(int px) {
  Camera cam;
  cam.name = "nadir";
  cam.type = Camera::Type::kOrthographic;
  cam.position = Vec3(0, 0, 10);
  cam.look_at = Vec3(0, 0, 0);
  cam.up = Vec3(0, 1, 0);
  cam.width = 2.0;
  cam.width_px = cam.height_px = px;
  return cam;
}

Medium slabMedium() {
  Medium m;
  m.density = makeSlab();
  m.extinction = kTau;
  m.albedo = Rgb(kAlbedo);
  m.phase = std::make_shared<HenyeyGreensteinPhase>(kG);
  return m;
}

TEST(VanDeHulstSlab, NadirReflectivityFromThePathTracer) {
  Sun sun;
  sun.direction = Vec3(0, 0, 1);
  sun.irradiance = Rgb(1.0, 2.0, 0.5);  // per-channel scale must cancel in pi L / E
  PathTracerOptions opt;
  opt.samples_per_pixel = 512;
  opt.seed = 5;
  const RenderLayers layers = renderPathTraced(slabMedium(), sun, Sky{}, nadirCamera(128), opt);
  for (int c = 0; c < 3; ++c) {
    // Every pixel is an independent estimate of the same radiance (the slab is infinite).
    const Stats s = testing_util::pixelStats(layers.beauty, c, kPi / sun.irradiance[c]);
    std::printf("nadir reflectivity channel %d: %.5f +- %.5f (vdH %.4f)\n", c, s.mean(),
                s.stderror(), kVdhNadirReflectivity);
    EXPECT_NEAR(s.mean(), kVdhNadirReflectivity, 4 * s.stderror() + 5e-5);
  }
  // The sky is black: the sky layer is exactly zero, and sun = single + multiple.
  const Stats sky = testing_util::pixelStats(layers.sky, 0);
  EXPECT_EQ(sky.sum2, 0.0);
  const Stats alpha = testing_util::pixelStats(layers.beauty, 3);
  EXPECT_NEAR(alpha.mean(), 1 - std::exp(-kTau), 4 * alpha.stderror());
  for (int y = 0; y < layers.sun.height; ++y) {
    for (int x = 0; x < layers.sun.width; ++x) {
      EXPECT_NEAR(layers.sun.at(x, y)[1], layers.single.at(x, y)[1] + layers.multiple.at(x, y)[1],
                  1e-6);
      // Alpha estimates 1 - exp(-tau) with a per-sample indicator: within [0, 1].
      EXPECT_GE(layers.beauty.at(x, y)[3], 0.0f);
      EXPECT_LE(layers.beauty.at(x, y)[3], 1.0f);
    }
  }
}

// Single scattering seen from the nadir with the sun at the zenith has a closed form:
// L1 = albedo p(cos = -1) E (1 - exp(-2 tau)) / 2 (both paths are vertical, so the optical
// path is tau' down and tau' back up).
TEST(VanDeHulstSlab, SingleScatteringLayerMatchesClosedForm) {
  Sun sun;
  sun.direction = Vec3(0, 0, 1);
  sun.irradiance = Rgb(1.0);
  PathTracerOptions opt;
  opt.samples_per_pixel = 128;
  opt.seed = 9;
  const RenderLayers layers = renderPathTraced(slabMedium(), sun, Sky{}, nadirCamera(96), opt);
  const double exact = kAlbedo * hgEval(kG, -1.0) * (1 - std::exp(-2 * kTau)) / 2;
  const Stats s = testing_util::pixelStats(layers.single, 0);
  std::printf("single scattering: %.6f +- %.6f (exact %.6f)\n", s.mean(), s.stderror(), exact);
  EXPECT_NEAR(s.mean(), exact, 4 * s.stderror());
}

// Sky single scattering seen from the nadir, by quadrature over the incoming direction w
// (z = mu): L1 = albedo * integral p(-mu) L_sky(w) G(mu) dw, where G is the optical-path
// integral over the depth t of the scattering point below the top face:
//   mu > 0 (light from above):  G = int_0^tau e^-t e^(-t/mu) dt
//   mu < 0 (light from below):  G = int_0^tau e^-t e^(-(tau - t)/|mu|) dt.
double skySingleScatterNadir(const std::function<double(double)>& sky_of_mu, double g,
                             double albedo, double tau) {
  const int n = 400000;
  double sum = 0;
  for (int i = 0; i < n; ++i) {
    const double theta = kPi * (i + 0.5) / n;
    const double mu = std::cos(theta);
    double geo;
    if (mu > 0) {
      const double k = 1 + 1 / mu;
      geo = (1 - std::exp(-tau * k)) / k;
    } else {
      // = (e^-tau - e^(-tau/m)) / (1/m - 1) with m = |mu| <= 1, stable for small m.
      const double k = 1 / -mu - 1;
      geo = k < 1e-9 ? tau * std::exp(-tau) : (std::exp(-tau) - std::exp(-tau / -mu)) / k;
    }
    sum += hgEval(g, -mu) * sky_of_mu(mu) * geo * 2 * kPi * std::sin(theta) * (kPi / n);
  }
  return albedo * sum;
}

Medium thinSlab() {
  Medium m;
  m.density = makeSlab();
  m.extinction = 0.5;
  m.albedo = Rgb(0.8);
  m.phase = std::make_shared<HenyeyGreensteinPhase>(0.6);
  return m;
}

// Exercises sky next-event estimation, phase sampling that escapes to the sky and their MIS
// weights together: only their sum is right.
TEST(SkySingleScattering, GradientSkyMatchesQuadrature) {
  Sky sky;
  sky.type = Sky::Type::kGradient;
  sky.zenith = Rgb(0.2, 0.5, 1.0);
  sky.horizon = Rgb(1.0, 0.8, 0.6);
  sky.ground = Rgb(0.3, 0.2, 0.1);
  PathTracerOptions opt;
  opt.samples_per_pixel = 256;
  opt.seed = 12;
  const RenderLayers layers = renderPathTraced(thinSlab(), Sun{}, sky, nadirCamera(64), opt);
  for (int c = 0; c < 3; ++c) {
    const double exact = skySingleScatterNadir(
        [&](double mu) {
          return mu >= 0 ? sky.horizon[c] + (sky.zenith[c] - sky.horizon[c]) * mu : sky.ground[c];
        },
        0.6, 0.8, 0.5);
    const Stats s = testing_util::pixelStats(layers.single, c);
    std::printf("gradient sky single scattering channel %d: %.5f +- %.5f (quadrature %.5f)\n", c,
                s.mean(), s.stderror(), exact);
    EXPECT_NEAR(s.mean(), exact, 4 * s.stderror());
  }
}

TEST(SkySingleScattering, LatLongMapWithBrightBandMatchesQuadrature) {
  // Radiance depends on the row only: a dim sky with a bright band 20-30 degrees from the zenith
  // and a dark ground; map importance sampling concentrates on the band.
  const int w = 64, h = 32;
  Image map(w, h, 3);
  auto row_value = [&](int y) {
    const double theta_deg = 180.0 * (y + 0.5) / h;
    if (theta_deg > 20 && theta_deg < 30) return 40.0;
    return theta_deg < 90 ? 0.5 : 0.05;
  };
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      float* p = map.at(x, y);
      p[0] = p[1] = p[2] = static_cast<float>(row_value(y));
    }
  }
  const std::string path =
      ::testing::TempDir() + "/cloudbake_band_sky_" + std::to_string(::getpid()) + ".exr";
  writeExr(path, {{"", map}});
  Sky sky;
  sky.type = Sky::Type::kMap;
  sky.map_path = path;
  sky.map_scale = 0.5;
  PathTracerOptions opt;
  opt.samples_per_pixel = 256;
  opt.seed = 13;
  const RenderLayers layers = renderPathTraced(thinSlab(), Sun{}, sky, nadirCamera(64), opt);
  std::remove(path.c_str());
  const double exact = skySingleScatterNadir(
      [&](double mu) {
        const double theta = std::acos(std::clamp(mu, -1.0, 1.0));
        const int y = std::min(h - 1, static_cast<int>(theta / kPi * h));
        return 0.5 * static_cast<double>(static_cast<float>(row_value(y)));
      },
      0.6, 0.8, 0.5);
  const Stats s = testing_util::pixelStats(layers.single, 1);
  std::printf("map sky single scattering: %.5f +- %.5f (quadrature %.5f)\n", s.mean(), s.stderror(),
              exact);
  EXPECT_NEAR(s.mean(), exact, 4 * s.stderror());
}

}  // namespace
}  // namespace cloudbake
