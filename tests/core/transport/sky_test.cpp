#include "core/transport/sky.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>

#include "core/error.h"
#include "core/io/exr_io.h"
#include "core/math/rng.h"
#include "core/transport/piecewise_constant.h"
#include "tests/core/transport/test_util.h"

namespace cloudbake {
namespace {

using testing_util::Stats;

// A lat-long map with structure: a bright small "sun disc" block, a gradient and a black band.
Image testMap(int w, int h) {
  Image im(w, h, 3);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      float* p = im.at(x, y);
      const float base = y < h / 2 ? 0.2f + 0.8f * float(y) / h : 0.05f;
      p[0] = base;
      p[1] = base * 0.8f;
      p[2] = (x >= w / 4 && x < w / 4 + 2) ? 0.0f : base * 1.5f;
      if (x == 3 && y == 2) p[0] = p[1] = p[2] = 200.f;
    }
  }
  return im;
}

// Exact integral of a nearest-pixel lat-long map over the sphere.
Rgb mapIntegral(const Image& m, double scale) {
  Rgb sum;
  for (int y = 0; y < m.height; ++y) {
    const double solid =
        (2 * kPi / m.width) * (std::cos(kPi * y / m.height) - std::cos(kPi * (y + 1) / m.height));
    for (int x = 0; x < m.width; ++x) {
      const float* p = m.at(x, y);
      sum += Rgb(p[0], p[1], p[2]) * (solid * scale);
    }
  }
  return sum;
}

TEST(Sky, ConstantAndGradientRadiance) {
  Sky s;
  s.radiance = Rgb(1, 2, 3);
  const SkyLight constant(s);
  EXPECT_EQ(constant.radiance(Vec3(0, 0, -1)), Rgb(1, 2, 3));
  EXPECT_FALSE(constant.black());
  EXPECT_DOUBLE_EQ(constant.pdf(Vec3(1, 0, 0)), 1 / (4 * kPi));

  s.type = Sky::Type::kGradient;
  s.zenith = Rgb(1, 1, 1);
  s.horizon = Rgb(0.2, 0.4, 0.6);
  s.ground = Rgb(0.05, 0.05, 0.05);
  const SkyLight gradient(s);
  EXPECT_EQ(gradient.radiance(Vec3(0, 0, 1)), Rgb(1, 1, 1));
  EXPECT_EQ(gradient.radiance(Vec3(1, 0, 0)), Rgb(0.2, 0.4, 0.6));
  const Rgb mid = gradient.radiance(normalize(Vec3(1, 0, 1)));
  EXPECT_NEAR(mid.x, 0.2 + 0.8 * std::sqrt(0.5), 1e-12);
  EXPECT_EQ(gradient.radiance(normalize(Vec3(1, 0, -0.01))), Rgb(0.05, 0.05, 0.05));

  Sky black;
  EXPECT_TRUE(SkyLight(black).black());
}

TEST(Sky, GradientSamplingEstimatesItsIntegral) {
  Sky s;
  s.type = Sky::Type::kGradient;
  s.zenith = Rgb(1, 0.5, 0.2);
  s.horizon = Rgb(0.2, 0.4, 0.6);
  s.ground = Rgb(0.1, 0.2, 0.3);
  const SkyLight sky(s);
  // Upper hemisphere: 2 pi (horizon + (zenith - horizon) / 2); lower: 2 pi ground.
  const Rgb exact = (s.horizon + (s.zenith - s.horizon) * 0.5) * (2 * kPi) + s.ground * (2 * kPi);
  Rng rng(1, 2);
  Stats est[3];
  for (int i = 0; i < 200000; ++i) {
    const SkySample smp = sky.sample(rng.uniform(), rng.uniform());
    for (int c = 0; c < 3; ++c) est[c].add(smp.radiance[c] / smp.pdf);
  }
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(est[c].mean(), exact[c], 4 * est[c].stderror());
}

TEST(Sky, MapImportanceSamplingIsConsistentAndUnbiased) {
  const Image map = testMap(32, 16);
  const double scale = 0.5;
  const SkyLight sky(map, scale, "test map");
  const Rgb exact = mapIntegral(map, scale);
  Rng rng(3, 4);
  Stats est[3];
  const int n = 400000;
  for (int i = 0; i < n; ++i) {
    const SkySample smp = sky.sample(rng.uniform(), rng.uniform());
    if (!(smp.pdf > 0)) {
      for (int c = 0; c < 3; ++c) est[c].add(0);
      continue;
    }
    // Sampling and evaluation agree.
    if (i < 2000) {
      ASSERT_NEAR(length(smp.to_sky), 1.0, 1e-12);
      ASSERT_NEAR(sky.pdf(smp.to_sky) / smp.pdf, 1.0, 1e-6);
      const Rgb l = sky.radiance(smp.to_sky);
      ASSERT_NEAR(l.x, smp.radiance.x, 1e-6 * (1 + l.x));
    }
    for (int c = 0; c < 3; ++c) est[c].add(smp.radiance[c] / smp.pdf);
  }
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(est[c].mean(), exact[c], 4 * est[c].stderror()) << "channel " << c;
  }
  // Importance sampling on luminance: far lower variance than uniform sphere sampling.
  Stats uniform;
  for (int i = 0; i < n; ++i) {
    const double z = 1 - 2 * rng.uniform(), phi = 2 * kPi * rng.uniform();
    const double r = std::sqrt(std::max(0.0, 1 - z * z));
    uniform.add(sky.radiance(Vec3(r * std::cos(phi), r * std::sin(phi), z)).y * 4 * kPi);
  }
  EXPECT_NEAR(uniform.mean(), exact.y, 4 * uniform.stderror());
  EXPECT_LT(est[1].variance(), 0.1 * uniform.variance());

  // The pdf integrates to one over the sphere (midpoint rule on a fine grid).
  double integral = 0;
  const int nt = 400, np = 800;
  for (int i = 0; i < nt; ++i) {
    const double theta = kPi * (i + 0.5) / nt;
    for (int j = 0; j < np; ++j) {
      const double phi = 2 * kPi * (j + 0.5) / np;
      const Vec3 w(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi),
                   std::cos(theta));
      integral += sky.pdf(w) * std::sin(theta) * (kPi / nt) * (2 * kPi / np);
    }
  }
  EXPECT_NEAR(integral, 1.0, 2e-3);
}

TEST(Sky, MapOrientationFollowsTheContract) {
  // u = azimuth from +x towards +y, v = 0 at the zenith: pixel (x, y) of a w x h map is seen
  // from theta = pi (y + 0.5) / h, phi = 2 pi (x + 0.5) / w.
  Image map(8, 4, 3);
  map.at(2, 0)[0] = 7.f;  // near the zenith, phi in [90, 135) degrees
  map.at(0, 3)[1] = 5.f;  // near the nadir, phi in [0, 45)
  const SkyLight sky(map, 1.0, "orientation map");
  const double t0 = kPi * 0.5 / 4, p0 = 2 * kPi * 2.5 / 8;
  EXPECT_EQ(
      sky.radiance(Vec3(std::sin(t0) * std::cos(p0), std::sin(t0) * std::sin(p0), std::cos(t0))).x,
      7.0);
  const double t1 = kPi * 3.5 / 4, p1 = 2 * kPi * 0.5 / 8;
  EXPECT_EQ(
      sky.radiance(Vec3(std::sin(t1) * std::cos(p1), std::sin(t1) * std::sin(p1), std::cos(t1))).y,
      5.0);
}

TEST(Sky, MapFromExrFileAndValidation) {
  const std::string path =
      ::testing::TempDir() + "/cloudbake_sky_" + std::to_string(::getpid()) + ".exr";
  const Image map = testMap(16, 8);
  writeExr(path, {{"", map}});
  Sky s;
  s.type = Sky::Type::kMap;
  s.map_path = path;
  s.map_scale = 2.0;
  const SkyLight sky(s);
  EXPECT_FALSE(sky.black());
  EXPECT_FLOAT_EQ(sky.radiance(Vec3(0, 0, 1)).x, 2.0f * map.at(0, 0)[0]);

  s.map_scale = -1;
  EXPECT_THROW(SkyLight{s}, InputError);
  s.map_scale = 1;
  s.map_path = path + ".missing";
  EXPECT_THROW(SkyLight{s}, InputError);
  s.map_path = "";
  EXPECT_THROW(SkyLight{s}, InputError);

  Image bad = map;
  bad.at(1, 1)[2] = std::nanf("");
  EXPECT_THROW(SkyLight(bad, 1.0, "nan map"), InputError);
  bad.at(1, 1)[2] = -1.f;
  EXPECT_THROW(SkyLight(bad, 1.0, "negative map"), InputError);
  // Pixels times the scale keep to the shot's largest radiance, 1e12: 3e38 made renders infinite.
  bad.at(1, 1)[2] = 3e38f;
  try {
    SkyLight(bad, 1.0, "bright map");
    ADD_FAILURE() << "a 3e38 pixel must be refused";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("bright map: sky map pixel (1, 1) times the scale 1 is"),
              std::string::npos)
        << e.what();
  }
  bad.at(1, 1)[2] = 1e6f;
  EXPECT_THROW(SkyLight(bad, 1e7, "scaled map"), InputError);
  EXPECT_NO_THROW(SkyLight(bad, 1e6, "scaled map"));

  Sky g;
  g.type = Sky::Type::kGradient;
  g.zenith = Rgb(1, std::nan(""), 1);
  EXPECT_THROW(SkyLight{g}, InputError);
  std::remove(path.c_str());

  // Oversized maps are refused before building tables.
  Image huge;  // only the header: the size check comes before any pixel is read
  huge.width = 8193;
  huge.height = 4097;
  huge.channels = 3;
  EXPECT_THROW(SkyLight(huge, 1.0, "huge map"), InputError);

  // A black map is black and never produces samples.
  const SkyLight dark(Image(4, 2, 3), 1.0, "dark");
  EXPECT_TRUE(dark.black());
  EXPECT_EQ(dark.sample(0.3, 0.7).pdf, 0.0);
}

TEST(PiecewiseConstant, SamplesFollowTheTable) {
  const PiecewiseConstant1D d({1.0, 0.0, 3.0, 4.0});
  EXPECT_DOUBLE_EQ(d.integral(), 2.0);
  Rng rng(5, 6);
  int counts[4] = {0, 0, 0, 0};
  const int n = 100000;
  for (int i = 0; i < n; ++i) {
    double pdf;
    int bin;
    const double x = d.sample(rng.uniform(), &pdf, &bin);
    ASSERT_EQ(static_cast<int>(x * 4), bin);
    ASSERT_DOUBLE_EQ(pdf, d.pdf(x));
    ++counts[bin];
  }
  EXPECT_EQ(counts[1], 0);
  const double p[4] = {1 / 8.0, 0, 3 / 8.0, 4 / 8.0};
  for (int b = 0; b < 4; ++b) {
    EXPECT_NEAR(counts[b] / double(n), p[b], 4 * std::sqrt(p[b] * (1 - p[b]) / n) + 1e-12);
  }
}

}  // namespace
}  // namespace cloudbake
