#include "core/transport/path_tracer.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include "core/error.h"
#include "core/io/exr_io.h"
#include "core/phase/henyey_greenstein.h"
#include "core/phase/isotropic.h"
#include "core/phase/phase_factory.h"
#include "core/transport/layers_exr.h"
#include "core/volume/analytic.h"
#include "tests/core/transport/test_util.h"

namespace cloudbake {
namespace {

using testing_util::perspectiveCamera;
using testing_util::Stats;

Medium sphereMedium(double extinction, double albedo, std::shared_ptr<const PhaseFunction> phase) {
  Medium m;
  m.density = std::make_shared<SphereDensity>(Vec3(0, 0, 0.5), 0.8, 1.0);
  m.extinction = extinction;
  m.albedo = Rgb(albedo);
  m.phase = std::move(phase);
  return m;
}

Sky constantSky(const Rgb& l) {
  Sky s;
  s.type = Sky::Type::kConstant;
  s.radiance = l;
  return s;
}

bool allFinite(const Image& im) {
  for (float v : im.data) {
    if (!std::isfinite(v)) return false;
  }
  return true;
}

bool allFinite(const RenderLayers& l) {
  return allFinite(l.beauty) && allFinite(l.sun) && allFinite(l.sky) && allFinite(l.single) &&
         allFinite(l.multiple);
}

// White furnace: a non-absorbing cloud under a uniform sky is invisible. Every pixel's expected
// beauty is the sky radiance, whatever the density and phase function.
void expectFurnace(const Medium& medium, const char* what, bool grey_phase = true) {
  const Rgb sky_l(0.5, 1.0, 2.0);
  PathTracerOptions opt;
  opt.samples_per_pixel = 256;
  opt.seed = 3;
  const RenderLayers l =
      renderPathTraced(medium, Sun{}, constantSky(sky_l), perspectiveCamera(24), opt);
  ASSERT_TRUE(allFinite(l)) << what;
  for (int c = 0; c < 3; ++c) {
    Stats covered;
    for (int y = 0; y < 24; ++y) {
      for (int x = 0; x < 24; ++x) {
        const float* p = l.beauty.at(x, y);
        if (p[3] > 0) {
          covered.add(p[c]);
        } else {
          EXPECT_EQ(p[c], static_cast<float>(sky_l[c])) << what << " background pixel " << x;
        }
      }
    }
    ASSERT_GT(covered.n, 100) << what;
    std::printf("%s furnace channel %d: %.5f +- %.5f (expected %.3f, pixel sd %.4f)\n", what, c,
                covered.mean(), covered.stderror(), sky_l[c], std::sqrt(covered.variance()));
    EXPECT_NEAR(covered.mean(), sky_l[c], 4 * covered.stderror()) << what;
    // Low variance: with a grey phase function the estimator is close to exact here. (A
    // chromatic one multiplies per-channel value/pdf ratios along the path: unbiased, noisier.)
    if (grey_phase) {
      EXPECT_LT(std::sqrt(covered.variance()), 0.1 * sky_l[c]) << what;
    }
  }
}

TEST(PathTracer, WhiteFurnaceSphereIsotropic) {
  expectFurnace(sphereMedium(4.0, 1.0, std::make_shared<IsotropicPhase>()), "sphere/isotropic");
}

TEST(PathTracer, WhiteFurnaceSphereForwardHg) {
  expectFurnace(sphereMedium(4.0, 1.0, std::make_shared<HenyeyGreensteinPhase>(0.9)),
                "sphere/hg0.9");
}

TEST(PathTracer, WhiteFurnaceBoxHg) {
  Medium m = sphereMedium(3.0, 1.0, std::make_shared<HenyeyGreensteinPhase>(0.9));
  m.density = std::make_shared<BoxDensity>(Vec3(-0.6, -0.6, 0), Vec3(0.6, 0.6, 1), 1.0);
  expectFurnace(m, "box/hg0.9");
  m.phase = std::make_shared<IsotropicPhase>();
  expectFurnace(m, "box/isotropic");
}

// A chromatic phase function: HG with a different g per channel, sampled from the equal mixture
// of the three (one pdf for all channels), as the tabulated Mie phase function does.
class ChromaticHgPhase final : public PhaseFunction {
 public:
  explicit ChromaticHgPhase(const Rgb& g) : g_(g) {}
  Rgb eval(double cos_theta) const override {
    return {hgEval(g_.x, cos_theta), hgEval(g_.y, cos_theta), hgEval(g_.z, cos_theta)};
  }
  double pdf(double cos_theta) const override { return average(eval(cos_theta)); }
  double sampleCosTheta(double u) const override {
    const int k = std::min(2, static_cast<int>(u * 3));
    return hgSampleCosTheta(g_[k], std::min(u * 3 - k, 1.0 - 1e-16));
  }
  bool chromatic() const override { return true; }
  Rgb meanCosine() const override { return g_; }
  std::string describe() const override { return "chromatic hg"; }

 private:
  Rgb g_;
};

TEST(PathTracer, WhiteFurnaceChromaticPhase) {
  expectFurnace(sphereMedium(4.0, 1.0, std::make_shared<ChromaticHgPhase>(Rgb(0.85, 0.6, 0.3))),
                "sphere/chromatic", /*grey_phase=*/false);
}

TEST(PathTracer, WhiteFurnaceWithSkyMapImportanceSampling) {
  // A constant lat-long map is also a uniform sky, but goes through map sampling and MIS.
  const std::string path =
      ::testing::TempDir() + "/cloudbake_furnace_map_" + std::to_string(::getpid()) + ".exr";
  Image map(16, 8, 3);
  for (size_t i = 0; i < map.data.size(); i += 3) {
    map.data[i] = 0.25f;
    map.data[i + 1] = 0.5f;
    map.data[i + 2] = 1.0f;
  }
  writeExr(path, {{"", map}});
  Sky sky;
  sky.type = Sky::Type::kMap;
  sky.map_path = path;
  sky.map_scale = 2.0;
  PathTracerOptions opt;
  opt.samples_per_pixel = 64;
  const RenderLayers l =
      renderPathTraced(sphereMedium(4.0, 1.0, std::make_shared<HenyeyGreensteinPhase>(0.5)), Sun{},
                       sky, perspectiveCamera(24), opt);
  Stats covered;
  for (int y = 0; y < 24; ++y) {
    for (int x = 0; x < 24; ++x) {
      if (l.beauty.at(x, y)[3] > 0) covered.add(l.beauty.at(x, y)[1]);
    }
  }
  EXPECT_NEAR(covered.mean(), 1.0, 4 * covered.stderror());
  std::remove(path.c_str());
}

TEST(PathTracer, LayersAddUp) {
  Medium m = sphereMedium(5.0, 0.95, std::make_shared<HenyeyGreensteinPhase>(0.6));
  m.albedo = Rgb(0.99, 0.9, 0.5);
  Sun sun;
  sun.direction = normalize(Vec3(1, -1, 1));
  sun.irradiance = Rgb(3, 2, 1);
  Sky sky;
  sky.type = Sky::Type::kGradient;
  sky.zenith = Rgb(0.1, 0.2, 0.5);
  sky.horizon = Rgb(0.3, 0.3, 0.4);
  sky.ground = Rgb(0.1, 0.1, 0.1);
  PathTracerOptions opt;
  opt.samples_per_pixel = 8;
  const RenderLayers l = renderPathTraced(m, sun, sky, perspectiveCamera(20), opt);
  ASSERT_TRUE(allFinite(l));
  double sun_total = 0, sky_total = 0, multiple_total = 0;
  for (int y = 0; y < 20; ++y) {
    for (int x = 0; x < 20; ++x) {
      for (int c = 0; c < 3; ++c) {
        const double sum = l.sun.at(x, y)[c] + l.sky.at(x, y)[c];
        EXPECT_NEAR(sum, l.single.at(x, y)[c] + l.multiple.at(x, y)[c], 1e-5 * (1 + sum));
        EXPECT_GE(l.beauty.at(x, y)[c], l.sun.at(x, y)[c] + l.sky.at(x, y)[c] - 1e-5);
        EXPECT_GE(l.sun.at(x, y)[c], 0.f);
        sun_total += l.sun.at(x, y)[c];
        sky_total += l.sky.at(x, y)[c];
        multiple_total += l.multiple.at(x, y)[c];
      }
      // The sky seen behind the cloud is in beauty only; with alpha 0 beauty is the sky.
      if (l.beauty.at(x, y)[3] == 0) {
        EXPECT_EQ(l.sun.at(x, y)[0], 0.f);
      }
    }
  }
  EXPECT_GT(sun_total, 0);
  EXPECT_GT(sky_total, 0);
  EXPECT_GT(multiple_total, 0);
}

// The EXR is compositing-ready: the cloud premultiplied in RGBA (RGB = sun + sky, A = coverage),
// the background seen through it in its own layer, the full beauty kept; and `cloud over` a
// plate of the constant sky reproduces the beauty (Nuke's over: A + (1 - a) B), as does cloud +
// background.
TEST(PathTracer, LayersWrittenAsOneCompositingReadyExr) {
  Sun sun;
  sun.irradiance = Rgb(1, 2, 3);
  PathTracerOptions opt;
  opt.samples_per_pixel = 2;
  const Rgb sky(0.1, 0.2, 0.3);
  const RenderLayers l =
      renderPathTraced(sphereMedium(3.0, 0.9, std::make_shared<IsotropicPhase>()), sun,
                       constantSky(sky), perspectiveCamera(12), opt);
  const std::string path =
      ::testing::TempDir() + "/cloudbake_layers_" + std::to_string(::getpid()) + ".exr";
  writeRenderLayers(path, l, {{"cloudbake:method", "pathtrace"}});
  const ExrContents in = readExr(path);
  EXPECT_EQ(in.channel_names.at(""), (std::vector<std::string>{"R", "G", "B", "A"}));
  EXPECT_EQ(in.layers.at("sun").data, l.sun.data);
  EXPECT_EQ(in.layers.at("sky").data, l.sky.data);
  EXPECT_EQ(in.layers.at("single").data, l.single.data);
  EXPECT_EQ(in.layers.at("multiple").data, l.multiple.data);
  EXPECT_EQ(in.layers.at("background").data, l.background.data);
  EXPECT_EQ(in.attributes.at("cloudbake:method"), "pathtrace");
  const Image& cloud = in.layers.at("");
  const Image& background = in.layers.at("background");
  const Image& beauty = in.layers.at("beauty");
  double covered = 0;
  for (int y = 0; y < cloud.height; ++y) {
    for (int x = 0; x < cloud.width; ++x) {
      const float a = cloud.at(x, y)[3];
      EXPECT_EQ(a, l.beauty.at(x, y)[3]);
      covered += a;
      for (int c = 0; c < 3; ++c) {
        const double premult = cloud.at(x, y)[c];
        EXPECT_NEAR(premult, l.sun.at(x, y)[c] + l.sky.at(x, y)[c], 1e-6);
        EXPECT_NEAR(beauty.at(x, y)[c], l.beauty.at(x, y)[c], 1e-6);
        EXPECT_NEAR(premult + background.at(x, y)[c], beauty.at(x, y)[c], 1e-5);
        EXPECT_NEAR(premult + (1 - a) * sky[c], beauty.at(x, y)[c], 1e-5);  // cloud over plate
      }
    }
  }
  EXPECT_GT(covered, 1.0);  // the cloud covers part of the frame
  std::remove(path.c_str());
}

TEST(PathTracer, MaxDepthOneKeepsOnlySingleScattering) {
  Sun sun;
  sun.direction = normalize(Vec3(0.2, -0.4, 1));
  sun.irradiance = Rgb(1);
  PathTracerOptions opt;
  opt.samples_per_pixel = 8;
  opt.max_depth = 1;
  const RenderLayers l =
      renderPathTraced(sphereMedium(4.0, 1.0, std::make_shared<IsotropicPhase>()), sun,
                       constantSky(Rgb(0.5)), perspectiveCamera(16), opt);
  for (float v : l.multiple.data) ASSERT_EQ(v, 0.f);
  EXPECT_GT(testing_util::pixelStats(l.single, 0).sum, 0.0);
  EXPECT_GT(testing_util::pixelStats(l.sky, 0).sum, 0.0);
}

TEST(PathTracer, PureAbsorberScattersNothing) {
  Sun sun;
  sun.irradiance = Rgb(1);
  const RenderLayers l =
      renderPathTraced(sphereMedium(3.0, 0.0, std::make_shared<IsotropicPhase>()), sun,
                       constantSky(Rgb(1)), perspectiveCamera(16), PathTracerOptions{});
  ASSERT_TRUE(allFinite(l));
  for (const Image* im : {&l.sun, &l.sky, &l.single, &l.multiple}) {
    for (float v : im->data) ASSERT_EQ(v, 0.f);
  }
  // Beauty is the sky attenuated by the cloud: per sample 0 or 1, so exactly 1 - alpha.
  for (int y = 0; y < 16; ++y) {
    for (int x = 0; x < 16; ++x) {
      const float* p = l.beauty.at(x, y);
      EXPECT_NEAR(p[0], 1.0 - p[3], 1e-6);
    }
  }
}

struct ExtremeCase {
  double extinction, albedo, g;
  Vec3 sun_dir;
  bool tiny;
};

// Level 4 of the verification ladder. The cloud is a box, whose majorant grid is exact: a
// sphere's single-cell majorant makes tracking at extinction 1e6 take ~1e6 null collisions per
// ray through its empty bounding-box corners (correct, but slow).
TEST(PathTracer, ExtremesStayFiniteAndFast) {
  const Vec3 zenith(0, 0, 1), horizon(1, 0, 0), oblique = normalize(Vec3(-1, 2, 0.3));
  std::vector<ExtremeCase> cases;
  for (double ext : {1e-6, 1.0, 1e6}) {
    for (double albedo : {0.0, 1.0}) {
      for (double g : {-0.999, 0.0, 0.999}) {
        for (Vec3 d : {zenith, horizon, oblique}) cases.push_back({ext, albedo, g, d, false});
      }
    }
  }
  cases.push_back({1e6, 1.0, 0.9, zenith, true});
  cases.push_back({1e-6, 1.0, 0.9, horizon, true});
  cases.push_back({1.0, 0.8, 0.9, oblique, true});
  const auto start = std::chrono::steady_clock::now();
  for (const ExtremeCase& k : cases) {
    Medium m = sphereMedium(k.extinction, k.albedo, std::make_shared<HenyeyGreensteinPhase>(k.g));
    m.density = std::make_shared<BoxDensity>(Vec3(-0.5, -0.5, 0), Vec3(0.5, 0.5, 1), 1.0);
    Camera cam = perspectiveCamera(12);
    if (k.tiny) {
      // A one-voxel-like box 1e-3 across, seen filling part of the view.
      m.density = std::make_shared<BoxDensity>(Vec3(-5e-4, -5e-4, 0.5 - 5e-4),
                                               Vec3(5e-4, 5e-4, 0.5 + 5e-4), 1.0);
      cam.position = Vec3(0, -4e-3, 0.5);
      cam.fov_deg = 40;
    }
    Sun sun;
    sun.direction = k.sun_dir;
    sun.irradiance = Rgb(2.0, 1.0, 0.5);
    PathTracerOptions opt;
    opt.samples_per_pixel = 4;
    // g = 0.999 at extinction 1e6 diffuses with ~1000 scatterings per transport mean free path;
    // a lower cap keeps this finiteness check quick (the default is tested below).
    opt.max_depth = 10000;
    const RenderLayers l = renderPathTraced(m, sun, constantSky(Rgb(0.2, 0.3, 0.4)), cam, opt);
    const std::string what = "ext " + std::to_string(k.extinction) + " albedo " +
                             std::to_string(k.albedo) + " g " + std::to_string(k.g) + " sun " +
                             std::to_string(k.sun_dir.x) + "," + std::to_string(k.sun_dir.z) +
                             (k.tiny ? " tiny" : "");
    ASSERT_TRUE(allFinite(l)) << what;
    const Stats alpha = testing_util::pixelStats(l.beauty, 3);
    const Stats sun_layer = testing_util::pixelStats(l.sun, 0);
    if (k.extinction == 1e-6) {
      // Practically transparent: beauty is the background sky, nothing scattered.
      EXPECT_LT(alpha.mean(), 1e-3) << what;
      for (int y = 0; y < l.beauty.height; ++y) {
        for (int x = 0; x < l.beauty.width; ++x) {
          EXPECT_NEAR(l.beauty.at(x, y)[2], 0.4, 1e-3) << what;
        }
      }
    } else if (!k.tiny || k.extinction == 1e6) {
      EXPECT_GT(alpha.mean(), k.extinction == 1e6 ? 0.1 : 0.02) << what;  // box in view
    }
    if (k.albedo == 0) {
      EXPECT_EQ(sun_layer.sum, 0.0) << what;
    }
    // At extinction 1e6 the faces the camera sees are only lit if they face the sun (none of
    // these sun directions does; the lit-face case is checked against Chandrasekhar below).
    if (k.albedo == 1 && k.extinction == 1.0 && !k.tiny) {
      EXPECT_GT(sun_layer.sum, 0.0) << what;
    }
    for (float v : l.beauty.data) ASSERT_GE(v, 0.f) << what;
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("%zu extreme cases in %.2f s\n", cases.size(), seconds);
  EXPECT_LT(seconds, 40.0);
}

// An optically semi-infinite (extinction 1e6), conservative, isotropic medium lit and viewed at
// normal incidence reflects L = E H(1)^2 / (8 pi) (Chandrasekhar 1960, sec. 26; H(1) = 2.90781
// for albedo 1): a check that the long random walks carry the light back out with the default
// max_depth (truncation at 1e5 scatterings loses well under 1%).
TEST(PathTracer, OpaqueWhiteBoxMatchesChandrasekhar) {
  Medium m = sphereMedium(1e6, 1.0, std::make_shared<IsotropicPhase>());
  m.density = std::make_shared<BoxDensity>(Vec3(-0.6, -0.6, 0), Vec3(0.6, 0.6, 1), 1.0);
  Sun sun;
  sun.direction = Vec3(0, -1, 0);  // from behind the camera, normal to the face y = -0.6
  sun.irradiance = Rgb(1);
  Camera cam;
  cam.type = Camera::Type::kOrthographic;
  cam.position = Vec3(0, -4, 0.5);
  cam.look_at = Vec3(0, 0, 0.5);
  cam.up = Vec3(0, 0, 1);
  cam.width = 0.8;
  cam.width_px = cam.height_px = 32;
  PathTracerOptions opt;
  opt.samples_per_pixel = 16;
  const auto start = std::chrono::steady_clock::now();
  const RenderLayers l = renderPathTraced(m, sun, Sky{}, cam, opt);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_TRUE(allFinite(l));
  const Stats s = testing_util::pixelStats(l.beauty, 0, kPi);
  const double h1 = 2.90781, exact = h1 * h1 / 8;
  std::printf("semi-infinite white medium: pi L / E = %.4f +- %.4f (Chandrasekhar %.4f), %.2f s\n",
              s.mean(), s.stderror(), exact, seconds);
  EXPECT_NEAR(s.mean(), exact, 4 * s.stderror() + 0.01 * exact);
  EXPECT_EQ(testing_util::pixelStats(l.beauty, 3).mean(), 1.0);
}

TEST(PathTracer, DeterministicForSeedAndThreadCount) {
  Medium m = sphereMedium(6.0, 0.95, std::make_shared<HenyeyGreensteinPhase>(0.7));
  Sun sun;
  sun.direction = normalize(Vec3(0.3, -0.5, 1));
  sun.irradiance = Rgb(1, 0.9, 0.8);
  PathTracerOptions opt;
  opt.samples_per_pixel = 4;
  opt.tile_size = 8;
  opt.seed = 42;
  opt.threads = 1;
  const Camera cam = perspectiveCamera(40);
  const Sky sky = constantSky(Rgb(0.1, 0.2, 0.3));
  const RenderLayers a = renderPathTraced(m, sun, sky, cam, opt);
  opt.threads = 2;
  const RenderLayers b = renderPathTraced(m, sun, sky, cam, opt);
  opt.threads = 0;
  const RenderLayers c = renderPathTraced(m, sun, sky, cam, opt);
  EXPECT_EQ(a.beauty.data, b.beauty.data);
  EXPECT_EQ(a.multiple.data, b.multiple.data);
  EXPECT_EQ(a.beauty.data, c.beauty.data);
  opt.seed = 43;
  const RenderLayers d = renderPathTraced(m, sun, sky, cam, opt);
  EXPECT_NE(a.beauty.data, d.beauty.data);
}

TEST(PathTracer, ProgressAndCancellation) {
  Medium m = sphereMedium(2.0, 0.9, std::make_shared<IsotropicPhase>());
  PathTracerOptions opt;
  opt.samples_per_pixel = 2;
  opt.tile_size = 4;
  std::atomic<int> calls{0};
  double last = 0;
  bool monotonic = true;
  renderPathTraced(m, Sun{}, constantSky(Rgb(1)), perspectiveCamera(16), opt, [&](double f) {
    monotonic = monotonic && f >= last && f <= 1.0;
    last = f;
    ++calls;
    return true;
  });
  EXPECT_GE(calls.load(), 16);  // once per tile, and between pixels of a tile past 0.1 s
  EXPECT_TRUE(monotonic);
  EXPECT_DOUBLE_EQ(last, 1.0);

  calls = 0;
  EXPECT_THROW(renderPathTraced(m, Sun{}, constantSky(Rgb(1)), perspectiveCamera(64), opt,
                                [&](double) {
                                  ++calls;
                                  return false;
                                }),
               Cancelled);
  EXPECT_LT(calls.load(), 256);  // stopped well before all tiles were done
}

// A cancel reaches a tile whose paths take long (a thick white sphere, paths capped at 1e6
// events, one 32x32 tile: minutes of work): progress is asked between pixels, at most every
// 0.1 s, so the render stops within about that (it waited for the whole tile: 13 s and more).
TEST(PathTracer, CancelReachesALongTile) {
  Medium m = sphereMedium(1e4, 1.0, std::make_shared<IsotropicPhase>());
  PathTracerOptions opt;
  opt.samples_per_pixel = 4;
  opt.tile_size = 32;
  opt.max_depth = 1000000;
  opt.threads = 1;
  int calls = 0;
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_THROW(renderPathTraced(m, Sun{}, constantSky(Rgb(1)), perspectiveCamera(32), opt,
                                [&](double f) {
                                  EXPECT_EQ(f, 0.0);  // no tile finished
                                  ++calls;
                                  return false;
                                }),
               Cancelled);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(calls, 1);
  EXPECT_LT(seconds, 5.0);
}

TEST(PathTracer, RejectsInvalidInput) {
  const Medium good = sphereMedium(2.0, 0.9, std::make_shared<IsotropicPhase>());
  const Camera cam = perspectiveCamera(8);
  const Sky sky = constantSky(Rgb(1));
  const PathTracerOptions opt;
  auto expectError = [&](const Medium& m, const Sun& s, const Sky& k, const Camera& c,
                         const PathTracerOptions& o, const std::string& field) {
    try {
      renderPathTraced(m, s, k, c, o);
      ADD_FAILURE() << "expected InputError for " << field;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  };
  Medium m = good;
  m.density = nullptr;
  expectError(m, Sun{}, sky, cam, opt, "medium.density");
  m = good;
  m.phase = nullptr;
  expectError(m, Sun{}, sky, cam, opt, "medium.phase");
  for (double ext : {-1.0, std::nan(""), static_cast<double>(INFINITY)}) {
    m = good;
    m.extinction = ext;
    expectError(m, Sun{}, sky, cam, opt, "medium.extinction");
  }
  for (Rgb albedo : {Rgb(1.1, 0.5, 0.5), Rgb(-0.1), Rgb(0.5, std::nan(""), 0.5)}) {
    m = good;
    m.albedo = albedo;
    expectError(m, Sun{}, sky, cam, opt, "medium.albedo");
  }
  Sun sun;
  sun.direction = Vec3(0, 0, 0);
  expectError(good, sun, sky, cam, opt, "sun.direction");
  sun.direction = Vec3(std::nan(""), 0, 1);
  expectError(good, sun, sky, cam, opt, "sun.direction");
  sun = Sun{};
  sun.irradiance = Rgb(1, -1, 1);
  expectError(good, sun, sky, cam, opt, "sun.irradiance");
  sun.irradiance = Rgb(1, INFINITY, 1);
  expectError(good, sun, sky, cam, opt, "sun.irradiance");
  Sky bad_sky = constantSky(Rgb(-1));
  expectError(good, Sun{}, bad_sky, cam, opt, "sky.radiance");
  bad_sky.type = Sky::Type::kMap;
  bad_sky.map_path = "/nonexistent/sky.exr";
  expectError(good, Sun{}, bad_sky, cam, opt, "/nonexistent/sky.exr");
  PathTracerOptions o = opt;
  o.samples_per_pixel = 0;
  expectError(good, Sun{}, sky, cam, o, "samples_per_pixel");
  o = opt;
  o.tile_size = 0;
  expectError(good, Sun{}, sky, cam, o, "tile_size");
  o = opt;
  o.threads = -2;
  expectError(good, Sun{}, sky, cam, o, "threads");
  o = opt;
  o.max_depth = 0;
  expectError(good, Sun{}, sky, cam, o, "max_depth");
  Camera c = cam;
  c.fov_deg = 180;
  expectError(good, Sun{}, sky, c, opt, "camera.fov_deg");
}

}  // namespace
}  // namespace cloudbake

namespace cloudbake {
namespace {

// The real tabulated cloud phase function (polydisperse Lorenz-Mie, chromatic, forward peak
// ~1e3 sr^-1) through the whole renderer: still energy-conserving and finite.
TEST(PathTracer, WhiteFurnaceRealMieTable) {
  PhaseSpec spec;
  spec.type = PhaseSpec::Type::kMie;
  spec.effective_radius_um = 6.0;  // smaller droplets: a faster table build, same code path
  const auto mie = makePhaseFunction(spec);
  ASSERT_TRUE(mie->chromatic());
  expectFurnace(sphereMedium(4.0, 1.0, mie), "sphere/mie_table", /*grey_phase=*/false);
}

}  // namespace
}  // namespace cloudbake
