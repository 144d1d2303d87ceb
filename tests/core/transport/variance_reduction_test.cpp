// The path tracer's variance reduction (sun-guided lobe, shadow-ray splitting and roulette) must
// not move the mean: on scenes where each technique matters (a forward-peaked phase at high
// albedo, the sun beside the camera, behind it and behind the cloud), the image mean with the
// technique agrees with the mean without it within 4 sigma of their difference, with sigma
// estimated from independent renders. The samplers' maths is tested on its own below.

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/math/rng.h"
#include "core/math/sampling.h"
#include "core/phase/henyey_greenstein.h"
#include "core/phase/isotropic.h"
#include "core/phase/phase_factory.h"
#include "core/transport/path_tracer.h"
#include "core/transport/shadow_splitting.h"
#include "core/transport/sun_guiding.h"
#include "core/volume/analytic.h"
#include "core/volume/sources.h"
#include "tests/chi_square_util.h"
#include "tests/core/transport/test_util.h"

namespace cloudbake {
namespace {

using testing_util::BinnedChiSquare;
using testing_util::perspectiveCamera;
using testing_util::Stats;

// ---------------------------------------------------------------------------------------------
// Spikiness and the automatic lobe probability

// 4 pi integral(p^2) - 1 for HG in closed form: (1 - g^2)^2 / (8 g) ((1 - g)^-4 - (1 + g)^-4) - 1.
double hgSpikiness(double g) {
  return (1 - g * g) * (1 - g * g) / (8 * g) * (std::pow(1 - g, -4) - std::pow(1 + g, -4)) - 1;
}

TEST(SunGuiding, SpikinessMatchesClosedFormForHg) {
  for (double g : {0.3, 0.5, 0.85, 0.95}) {
    const HenyeyGreensteinPhase hg(g);
    EXPECT_NEAR(phaseSpikiness(hg), hgSpikiness(g), 0.01 * hgSpikiness(g) + 1e-3) << g;
  }
  EXPECT_NEAR(phaseSpikiness(IsotropicPhase()), 0.0, 1e-12);
}

TEST(SunGuiding, AutoProbabilityGrowsWithThePeakAndStaysBelowHalf) {
  EXPECT_NEAR(autoSunGuiding(IsotropicPhase()), 0.0, 1e-12);
  double last = 0;
  for (double g : {0.2, 0.5, 0.8, 0.9, 0.97}) {
    const double eps = autoSunGuiding(HenyeyGreensteinPhase(g));
    EXPECT_GT(eps, last) << g;
    EXPECT_LT(eps, 0.5) << g;
    last = eps;
  }
  EXPECT_NEAR(autoSunGuiding(HenyeyGreensteinPhase(0.85)), 0.5 * 21.37 / 61.37, 0.01);
}

// A phase whose sampled values overflow (a peak narrower than double precision) has an infinite
// spikiness; the lobe's probability takes its limit, 0.5, not inf / inf.
TEST(SunGuiding, AutoProbabilityOfAnOverflowingPeakIsItsLimit) {
  struct Overflowing final : PhaseFunction {
    Rgb eval(double) const override { return Rgb(INFINITY); }
    double pdf(double) const override { return INFINITY; }
    double sampleCosTheta(double) const override { return 1.0; }
    Rgb meanCosine() const override { return Rgb(1.0); }
    std::string describe() const override { return "overflowing"; }
  };
  EXPECT_EQ(phaseSpikiness(Overflowing()), INFINITY);
  EXPECT_EQ(autoSunGuiding(Overflowing()), 0.5);
}

TEST(SunGuiding, RejectsBadProbabilityAndDirection) {
  const HenyeyGreensteinPhase hg(0.8);
  EXPECT_THROW(SunGuide(hg, Vec3(0, 0, 1), 1.0), InputError);
  EXPECT_THROW(SunGuide(hg, Vec3(0, 0, 1), -0.1), InputError);
  EXPECT_THROW(SunGuide(hg, Vec3(0, 0, 1), std::nan("")), InputError);
  EXPECT_THROW(SunGuide(hg, Vec3(0, 0, 2), 0.3), InputError);
}

// The lobe is rarer where the walk already travels into the sun's spike.
TEST(SunGuiding, LobeProbabilityFallsInsideTheSpike) {
  const HenyeyGreensteinPhase hg(0.9);
  const Vec3 to_sun(0, 0, 1);
  const SunGuide guide(hg, to_sun, 0.4);
  EXPECT_EQ(guide.epsAt(Vec3(0, 0, -1)), 0.4);
  EXPECT_EQ(guide.epsAt(Vec3(1, 0, 0)), 0.4);
  EXPECT_NEAR(guide.epsAt(to_sun), 0.4 / (4 * kPi * hgEval(0.9, 1.0)), 1e-12);
  EXPECT_NEAR(guide.phaseSampleWeights(1.0, to_sun, 0.4).importance, 4 * kPi * hgEval(0.9, 1.0),
              1e-9);
  EXPECT_EQ(guide.phaseSampleWeights(1.0, Vec3(0, 0, -1), 0.4).importance, 1.0);
  EXPECT_EQ(SunGuide(hg, to_sun, 0.0).phaseSampleWeights(1.0, to_sun, 0.0).importance, 1.0);
}

// The two techniques' weights partition unity for every direction: phase sampling's weight plus
// eps p_sun times the lobe's per-unit-f weight is 1 (the balance heuristic), and eps = 0 leaves
// phase sampling's weight at exactly 1.
TEST(SunGuiding, WeightsPartitionUnity) {
  const HenyeyGreensteinPhase hg(0.9);
  const Vec3 to_sun = normalize(Vec3(0.3, -0.2, 1));
  const SunGuide guide(hg, to_sun, 0.4);
  const SunGuide off(hg, to_sun, 0.0);
  Rng rng(7, 1);
  for (int i = 0; i < 2000; ++i) {
    const Vec3 travel = sampleUniformSphere(rng.uniform(), rng.uniform());
    const double eps_t = guide.epsAt(travel);
    EXPECT_GT(eps_t, 0.0);
    EXPECT_LE(eps_t, 0.4);
    const SunGuide::LobeSample s = guide.sampleLobe(travel, eps_t, rng.uniform(), rng.uniform());
    const double f = hg.pdf(dot(travel, s.direction));
    const double lobe_weight = eps_t * hg.pdf(dot(to_sun, s.direction)) * s.weight.x / f;
    EXPECT_NEAR(guide.phaseSampleWeights(f, s.direction, eps_t).mis + lobe_weight, 1.0, 1e-9);
    EXPECT_EQ(off.epsAt(travel), 0.0);
    EXPECT_EQ(off.phaseSampleWeights(f, s.direction, off.epsAt(travel)).mis, 1.0);
  }
}

// The lobe's directions are distributed as p(dot(to_sun, d)): chi-square over cos and azimuth
// about the sun, with a negative control (the same test against a slightly different g).
BinnedChiSquare lobeChiSquare(double g_sampled, double g_expected) {
  constexpr int kCos = 40, kPhi = 8, kN = 400000;
  const HenyeyGreensteinPhase sampled(g_sampled);
  const Vec3 to_sun = normalize(Vec3(0.5, 0.5, -0.7));
  const SunGuide guide(sampled, to_sun, 0.3);
  const Frame frame = Frame::fromZ(to_sun);
  std::vector<double> observed(kCos * kPhi, 0.0), expected(kCos * kPhi, 0.0);
  // Bins uniform in theta^(1/2) about the sun, so the forward peak gets many bins.
  auto bin_of_cos = [&](double c) {
    const double t = std::sqrt(std::acos(std::clamp(c, -1.0, 1.0)) / kPi);
    return std::min(kCos - 1, int(t * kCos));
  };
  Rng rng(11, 3);
  const Vec3 travel(0, 0, 1);
  for (int i = 0; i < kN; ++i) {
    const Vec3 d =
        frame.toLocal(guide.sampleLobe(travel, 0.3, rng.uniform(), rng.uniform()).direction);
    const double phi = std::atan2(d.y, d.x) + kPi;
    const int ip = std::min(kPhi - 1, int(phi / (2 * kPi) * kPhi));
    observed[size_t(bin_of_cos(d.z)) * kPhi + ip] += 1;
  }
  for (int ic = 0; ic < kCos; ++ic) {
    const double th0 = kPi * std::pow(double(ic) / kCos, 2),
                 th1 = kPi * std::pow(double(ic + 1) / kCos, 2);
    double mass = 0;
    constexpr int kSteps = 200;
    for (int k = 0; k < kSteps; ++k) {
      const double th = th0 + (th1 - th0) * (k + 0.5) / kSteps;
      mass += 2 * kPi * hgEval(g_expected, std::cos(th)) * std::sin(th) * (th1 - th0) / kSteps;
    }
    for (int ip = 0; ip < kPhi; ++ip) expected[size_t(ic) * kPhi + ip] = mass / kPhi * kN;
  }
  return testing_util::chiSquareBinned(observed, expected);
}

TEST(SamplerChiSquare, SunLobeMatchesThePhaseAboutTheSun) {
  const BinnedChiSquare good = lobeChiSquare(0.85, 0.85);
  EXPECT_TRUE(good.passes()) << good;
  const BinnedChiSquare wrong = lobeChiSquare(0.85, 0.83);
  EXPECT_FALSE(wrong.passes()) << wrong;
}

// ---------------------------------------------------------------------------------------------
// Shadow-ray splitting and roulette

TEST(ShadowSplitting, ExpectedWeightIsOneAndOffIsOneRay) {
  for (double predicted : {1e-4, 0.01, 0.019, 0.021, 0.05, 0.1, 0.5, 1.0, 1.5, 7.2, 1e3}) {
    // E[count x weight] over u, integrated exactly on a fine grid of u.
    double expect = 0, expect_roulette = 0;
    constexpr int kU = 100000;
    for (int i = 0; i < kU; ++i) {
      const ShadowRays r = sunShadowRays(predicted, 8, (i + 0.5) / kU);
      expect += r.count * r.weight / kU;
      EXPECT_LE(r.count, 8);
      // Roulette alone (the transmittance predictor's): never more than one ray.
      const ShadowRays q = sunShadowRays(predicted, 1, (i + 0.5) / kU, /*roulette=*/true);
      expect_roulette += q.count * q.weight / kU;
      EXPECT_LE(q.count, 1);
    }
    EXPECT_NEAR(expect, 1.0, 1e-3) << predicted;
    EXPECT_NEAR(expect_roulette, 1.0, 1e-3) << predicted;
    // With a floor on survival (the predictor's roulette): still one in expectation.
    double expect_floor = 0;
    for (int i = 0; i < kU; ++i) {
      const ShadowRays q = sunShadowRays(predicted * 1e-6, 1, (i + 0.5) / kU, true, 1e-3);
      expect_floor += q.count * q.weight / kU;
    }
    EXPECT_NEAR(expect_floor, 1.0, 1e-3) << predicted;
    EXPECT_NEAR(shadowSurvival(predicted), std::min(1.0, predicted / kShadowRouletteBelow), 1e-12);
    EXPECT_GE(shadowSurvival(predicted * 1e-9, kPredictedMinSurvival), kPredictedMinSurvival);
    const ShadowRays off = sunShadowRays(predicted, 1, 0.999);
    EXPECT_EQ(off.count, 1);
    EXPECT_EQ(off.weight, 1.0);
  }
  EXPECT_EQ(sunShadowRays(7.2, 8, 0.5).count, 8);
  EXPECT_EQ(sunShadowRays(100, 8, 0.5).count, 8);
  EXPECT_EQ(sunShadowRays(2.5, 8, 0.5).count, 3);
  EXPECT_EQ(sunShadowRays(0, 8, 0.5).count, 0);
  EXPECT_EQ(autoSunSplitMax(HenyeyGreensteinPhase(0.85)), 1);
  EXPECT_EQ(autoSunSplitMax(IsotropicPhase()), 1);
  EXPECT_EQ(autoSunSplitMax(HenyeyGreensteinPhase(0.97)), 8);  // V about 555
}

// ---------------------------------------------------------------------------------------------
// Unbiasedness on whole renders

struct Estimate {
  Stats sun, scattered;  // image means of independent renders
};

// Image means of the sun layer and of sun + sky over `renders` renders of different seeds.
Estimate estimate(const Medium& m, const Vec3& to_sun, PathTracerOptions opt, int renders) {
  Sun sun;
  sun.direction = to_sun;
  sun.irradiance = Rgb(1.0);
  Sky sky;
  sky.type = Sky::Type::kConstant;
  sky.radiance = Rgb(0.1);
  Estimate e;
  for (int r = 0; r < renders; ++r) {
    opt.seed = 1000 + r;
    const RenderLayers l = renderPathTraced(m, sun, sky, perspectiveCamera(8, 30), opt);
    Stats s, t;
    for (int y = 0; y < 8; ++y)
      for (int x = 0; x < 8; ++x) {
        s.add(l.sun.at(x, y)[0]);
        t.add(l.sun.at(x, y)[0] + l.sky.at(x, y)[0]);
      }
    e.sun.add(s.mean());
    e.scattered.add(t.mean());
  }
  return e;
}

void expectAgree(const Stats& a, const Stats& b, const std::string& what) {
  const double sigma = std::sqrt(a.stderror() * a.stderror() + b.stderror() * b.stderror());
  EXPECT_LT(std::abs(a.mean() - b.mean()), 4 * sigma)
      << what << ": " << a.mean() << " +- " << a.stderror() << " vs " << b.mean() << " +- "
      << b.stderror();
  // The test must be able to fail: the error bar is a few percent of the mean, not of order 1.
  EXPECT_LT(sigma, 0.08 * std::abs(b.mean())) << what;
}

struct Case {
  const char* name;
  Vec3 to_sun;
  int max_depth;
};

// Sun beside the camera (side light), behind the camera (the camera sees the lit face), and
// behind the cloud (the camera looks at the sun through it: the forward peak).
std::vector<Case> cases() {
  return {{"beside", normalize(Vec3(1, 0, 0.3)), 100000},
          {"behind camera", normalize(Vec3(0.2, -1, 0.3)), 100000},
          {"behind cloud", normalize(Vec3(0.15, 1, 0.1)), 100000},
          {"beside, double scattering", normalize(Vec3(1, 0, 0.3)), 2}};
}

// Every technique together against none, in every case; each technique alone in the first
// (splitting or decomposition tracking alone leave the Mie spike's variance too high for a test
// of power: HG only).
// Without the techniques the forward spike gives the estimate a heavy tail, whose sample mean
// is low more often than high: the reference without them gets four times the samples.
void expectTechniquesUnbiased(const Medium& m, int spp, int renders, const char* phase,
                              bool split_alone = true) {
  bool first = true;
  for (const Case& c : cases()) {
    PathTracerOptions off;
    off.samples_per_pixel = spp;
    off.max_depth = c.max_depth;
    off.sun_guiding = 0;
    off.sun_split_max = 1;
    off.decomposition_tracking = false;
    PathTracerOptions guide = off, split = off, all = off, decomposition = off;
    guide.sun_guiding = -1;
    split.sun_split_max = 8;
    all.sun_guiding = 0.5;
    all.sun_split_max = 8;
    all.decomposition_tracking = true;
    decomposition.decomposition_tracking = true;
    std::vector<std::pair<const char*, PathTracerOptions>> configs{{"all", all}};
    if (first) configs.emplace_back("guide", guide);
    if (first && split_alone) configs.emplace_back("split", split);
    if (first && split_alone) configs.emplace_back("decomposition", decomposition);
    first = false;
    PathTracerOptions off_long = off;
    off_long.samples_per_pixel = 4 * spp;
    const Estimate e_off = estimate(m, c.to_sun, off_long, renders);
    const std::string what = std::string(phase) + ", sun " + c.name;
    for (const auto& [name, opt] : configs) {
      const Estimate e = estimate(m, c.to_sun, opt, renders);
      expectAgree(e.sun, e_off.sun, what + ", " + name + ", sun layer");
      expectAgree(e.scattered, e_off.scattered, what + ", " + name + ", sun + sky");
    }
  }
}

Medium sphere(std::shared_ptr<const PhaseFunction> phase) {
  Medium m;
  m.density = std::make_shared<SphereDensity>(Vec3(0, 0, 0.5), 0.8, 1.0);
  m.extinction = 4;
  m.albedo = Rgb(0.995);
  m.phase = std::move(phase);
  return m;
}

TEST(VarianceReduction, UnbiasedWithForwardPeakedHg) {
  expectTechniquesUnbiased(sphere(std::make_shared<HenyeyGreensteinPhase>(0.9)), 128, 32, "HG 0.9");
}

// The sphere voxelised: a grid volume, whose tracking grid has minorants (decomposition and
// residual ratio tracking, and the transmittance predictor's roulette of shadow rays, at work)
// and a trilinear edge.
TEST(VarianceReduction, UnbiasedOnAGridWithMinorants) {
  Medium m = sphere(std::make_shared<HenyeyGreensteinPhase>(0.9));
  m.density = voxelize(*m.density, 0.05);
  ASSERT_TRUE(m.density->trackingGrid({m.extinction, 0})->hasMinorants());
  expectTechniquesUnbiased(m, 128, 32, "HG 0.9, grid");
}

TEST(VarianceReduction, UnbiasedWithMieTable) {
  PhaseSpec spec;
  spec.type = PhaseSpec::Type::kMie;
  spec.effective_radius_um = 6;
  spec.effective_variance = 0.1;
  expectTechniquesUnbiased(sphere(makePhaseFunction(spec)), 128, 32, "Mie 6 um",
                           /*split_alone=*/false);
}

TEST(VarianceReduction, OptionsAreValidated) {
  const Medium m = sphere(std::make_shared<HenyeyGreensteinPhase>(0.9));
  Sun sun;
  sun.irradiance = Rgb(1.0);
  PathTracerOptions opt;
  opt.sun_guiding = 1.0;
  EXPECT_THROW(renderPathTraced(m, sun, Sky{}, perspectiveCamera(4, 30), opt), InputError);
  opt.sun_guiding = std::nan("");
  EXPECT_THROW(renderPathTraced(m, sun, Sky{}, perspectiveCamera(4, 30), opt), InputError);
  opt.sun_guiding = 0;
  opt.sun_split_max = 0;
  EXPECT_THROW(renderPathTraced(m, sun, Sky{}, perspectiveCamera(4, 30), opt), InputError);
  opt.sun_split_max = 65;
  EXPECT_THROW(renderPathTraced(m, sun, Sky{}, perspectiveCamera(4, 30), opt), InputError);
  opt.sun_split_max = -1;
  for (int cell : {-1, 3, 128}) {
    opt.majorant_cell = cell;
    EXPECT_THROW(renderPathTraced(m, sun, Sky{}, perspectiveCamera(4, 30), opt), InputError)
        << cell;
  }
}

}  // namespace
}  // namespace cloudbake
