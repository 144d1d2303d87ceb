// Method auto: the model's pieces (samples for a tolerance, the scene factor fitted on the five
// bench scenes, the lattice bias), the choice among candidates (what meets the tolerance,
// cheapest first; limits and peaky phases; a clear error naming /bake/tolerance when nothing
// meets it), the pilot's noise against the noise measured between two longer renders, and what
// it measures of the light's orders.
#include "core/methods/auto.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "core/error.h"
#include "core/methods/auto_measure.h"
#include "core/methods/registry.h"
#include "core/shot/scene_builder.h"
#include "core/shot/shot_parser.h"
#include "core/transport/camera.h"

namespace cloudbake {
namespace {

std::string shot(const std::string& bake, double albedo = 0.95, double extinction = 3,
                 int px = 16) {
  return R"({"version": 1, "name": "a",
    "volume": {"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}},
    "medium": {"extinction": )" +
         std::to_string(extinction) + R"(, "albedo": )" + std::to_string(albedo) +
         R"(, "phase": {"type": "hg", "g": 0.6}},
    "lighting": {"sun": {"direction": [0.5, 0, 0.8660254], "irradiance": [1, 1, 1]},
                 "sky": {"radiance": [0.1, 0.1, 0.1]}},
    "bake": )" +
         bake + R"(,
    "views": [{"name": "v", "camera": {"type": "orthographic", "position": [0, -5, 0],
               "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 2.5}, "resolution": [)" +
         std::to_string(px) + ", " + std::to_string(px) + R"(]}]})";
}

PilotMeasure pilotOf(double noise, double multiple, double seconds_per_sample = 1e-6) {
  PilotMeasure p;
  p.noise_1spp = noise;
  p.multiple_fraction = multiple;
  p.seconds_per_sample = seconds_per_sample;
  p.cloud_fraction = 0.25;
  p.samples = 8;
  return p;
}

SceneTraits traitsOf(double tau_voxel, double pixels = 4 * 640.0 * 480) {
  SceneTraits t;
  t.sun = t.sky = true;
  t.phase_spikiness = 21.4;
  t.tau_voxel_128 = tau_voxel;
  t.views = 4;
  t.pixels = pixels;
  return t;
}

TEST(AutoModel, PathtraceSamplesMeetTheToleranceWithTheMargin) {
  const PilotMeasure p = pilotOf(2.0, 0.7);
  const SceneTraits t = traitsOf(0.1);
  const int64_t spp = pathtraceSamplesFor(t, p, 0.1);
  EXPECT_EQ(spp, 576);  // (1.2 x 2 / 0.1)^2
  EXPECT_LE(1.2 * 2.0 / std::sqrt(double(spp)), 0.1 + 1e-12);
  EXPECT_EQ(pathtraceSamplesFor(t, pilotOf(0, 0), 0.1), 1);  // no cloud light: one path
  EXPECT_GT(pathtraceSamplesFor(t, p, 0.01), 4 * pathtraceSamplesFor(t, p, 0.02) - 4);
  // A droplet's heavy-tailed noise gets the wider margin: (1.75 x 2 / 0.1)^2.
  SceneTraits droplet = t;
  droplet.phase_spikiness = 1474;
  EXPECT_EQ(pathtraceSamplesFor(droplet, p, 0.1), 1225);
}

TEST(AutoModel, PhotonFactorBoundsEveryMeasuredScene) {
  // photon's measured error over the bunny's on the five bench scenes and the five held out
  // (auto_model.cpp, docs/methods.md).
  for (double measured : {1.2, 1.0, 2.25, 0.70, 1.82, 0.87, 1.05, 1.4, 1.12, 1.3}) {
    EXPECT_GE(photonSceneFactor(traitsOf(0.1), pilotOf(2, 0.7)), measured);
  }
  // and its predicted error is never below the bunny's own measured error at a rung.
  for (const AutoCandidate& c : autoCandidates(traitsOf(0.1), pilotOf(2, 0.7), 0.5, 0)) {
    if (c.method != "photon") continue;
    for (const PhotonRung& r : photonRungs()) {
      if (c.knobs.front().second == r.photons) {
        EXPECT_GE(c.error, 2.25 * r.bunny_error);
      }
    }
  }
}

TEST(AutoModel, LatticeBiasFallsWithResolution) {
  const SceneTraits t = traitsOf(0.5);
  EXPECT_NEAR(latticeSingleBias(t, 128), 0.25 / 2, 1e-12);
  EXPECT_LT(latticeSingleBias(t, 256), latticeSingleBias(t, 128) / 3.9);
  EXPECT_LE(latticeSingleBias(traitsOf(1e6), 8), 1.0);
}

// A hard surface's rim (auto_model.cpp, latticeRimError): the photon rungs' predictions bound
// what they measured on spheres of extinction 15 and 50 seen against the sun (80x60, two views
// 12 and 5 degrees from the sun, 8192-path references; the pilot measured 90 % of the light
// multiply scattered), and a soft cloud's are as they were.
TEST(AutoModel, AHardSurfacesRimRaisesTheLatticesPredictions) {
  const PilotMeasure pilot = pilotOf(2, 0.9);
  SceneTraits hard = traitsOf(0.547);
  hard.hard_surface = 1;
  EXPECT_NEAR(latticeRimError(hard, pilot, 256), latticeRimError(hard, pilot, 128) / 2, 1e-12);
  EXPECT_NEAR(latticeRimError(hard, pilotOf(2, 0.8), 128), 2 * latticeRimError(hard, pilot, 128),
              1e-12);
  EXPECT_EQ(latticeRimError(traitsOf(0.547), pilot, 64), 0.0);
  // A sphere of extinction 3 (0.033 a 1/128 voxel) against the sun measured 0.022-0.028 at 64
  // voxels, with 43 % of its light scattered once: thin surfaces have little rim (a tenth of a
  // thick one's here).
  SceneTraits thin = traitsOf(0.033);
  thin.hard_surface = 1;
  EXPECT_GE(latticeRimError(thin, pilotOf(2, 0.57), 64), 0.028);
  EXPECT_LE(latticeRimError(thin, pilotOf(2, 0.57), 64), 0.25);
  // Views lit from the front or the side measured a quarter as much rim as views towards the
  // sun; a shot without views (no pilot) takes every view as towards it and the thick spheres'
  // share of light scattered once, 0.1.
  SceneTraits front = hard;
  front.sunward_views = 0;
  EXPECT_NEAR(latticeRimError(front, pilot, 128), latticeRimError(hard, pilot, 128) * 0.5 / 5,
              1e-12);
  PilotMeasure none;
  none.multiple_fraction = 1;  // what auto puts there without views
  EXPECT_NEAR(latticeRimError(hard, none, 128), 5 * 0.1, 1e-12);
  // single's prediction carries it too.
  auto singleError = [&](const SceneTraits& t) {
    for (const AutoCandidate& c : autoCandidates(t, pilotOf(2, 0.3), 0.3, 0)) {
      if (c.method == "single") return c.error;
    }
    ADD_FAILURE() << "no single candidate";
    return 0.0;
  };
  EXPECT_GT(singleError(hard), singleError(traitsOf(0.547)) * 1.2);
  EXPECT_LE(latticeRimError(hard, pilotOf(2, 0), 1), 1.0);
  auto photon = [&](const SceneTraits& t, int64_t photons) {
    for (const AutoCandidate& c : autoCandidates(t, pilot, 0.3, 0)) {
      if (c.method == "photon" && c.knobs.front().second == photons) return c;
    }
    ADD_FAILURE() << "no photon rung of " << photons;
    return AutoCandidate{};
  };
  struct Sphere {
    double tau;
    std::vector<std::pair<int64_t, double>> measured;  // photons, relative RMSE
  };
  // At extinction 50 the 131072 rung's tally is too thick to be a candidate. The last two are an
  // outside probe's: the sphere of extinction 15 framed otherwise, and one of extinction 20 and
  // radius 0.6 seen 8 degrees from the sun (one view; its pilot put 89 % of the light multiply
  // scattered, as this test's does 90 %).
  const std::vector<Sphere> spheres = {
      {0.164, {{131072, 0.347}, {524288, 0.189}, {2097152, 0.104}, {4194304, 0.095}}},
      {0.547, {{524288, 0.219}, {2097152, 0.128}, {4194304, 0.111}, {16777216, 0.069}}},
      {0.164, {{524288, 0.359}, {2097152, 0.214}}},
      {0.188, {{524288, 0.548}, {2097152, 0.323}}}};
  for (const Sphere& sphere : spheres) {
    SceneTraits h = traitsOf(sphere.tau), s = traitsOf(sphere.tau), n = traitsOf(sphere.tau);
    h.hard_surface = 1;
    s.hard_surface = 0.02;  // a few hard places (every bench scene reads 0)
    int missed_before = 0;
    for (const auto& [photons, error] : sphere.measured) {
      const AutoCandidate with_rim = photon(h, photons);
      EXPECT_GE(with_rim.error, error) << photons;
      EXPECT_NE(with_rim.why.find("the lattice's rim"), std::string::npos) << with_rim.why;
      const AutoCandidate soft_edge = photon(s, photons), without = photon(n, photons);
      EXPECT_LT(soft_edge.error, without.error * 1.005) << photons;
      if (without.error < error) ++missed_before;
    }
    // Without the rim, predictions fell short of what was measured: the test can fail.
    EXPECT_GE(missed_before, 2) << sphere.tau;
  }
}

// A soft cloud's rim: the bench shots' errors hold it for one view in two against the sun; a
// shot whose every view looks against the sun has more. The Perlin cloud of `cumulus_backlit`
// (a 1/128 voxel 0.415 optical depths) with both views 12 and 5 degrees from the sun, each
// view's pilot aureole as measured, photon's rungs measured at sharpness 0.05 and 0.9.
TEST(AutoModel, ViewsAgainstTheSunBeyondTheBenchsShareRaiseTheLatticesPredictions) {
  struct Cloud {
    double multiple;
    std::vector<double> aureole;
    std::vector<std::pair<int64_t, double>> measured;  // photons, relative RMSE
  };
  const std::vector<Cloud> clouds = {
      {0.713, {1.44, 0.77}, {{131072, 0.557}, {524288, 0.209}, {2097152, 0.171}, {4194304, 0.166}}},
      {0.685, {1.30, 0.74}, {{131072, 0.414}, {524288, 0.146}, {2097152, 0.112}, {4194304, 0.107}}},
      // Held out of the fit: seed 9, cover 0.5, sharpness 0.3. Its 131072 rung (64 voxels, coarser
      // than the grid) measured 0.614 against 0.516, a rung no tolerance under 0.5 chooses.
      {0.748, {1.49, 0.67}, {{524288, 0.204}, {2097152, 0.150}, {4194304, 0.143}}}};
  SceneTraits traits = traitsOf(0.415, 2 * 80.0 * 60);
  traits.views = 2;
  traits.phase_spikiness = 11.65;  // HG 0.8
  auto photon = [&](const PilotMeasure& pilot, int64_t photons) {
    for (const AutoCandidate& c : autoCandidates(traits, pilot, 0.3, 0)) {
      if (c.method == "photon" && c.knobs.front().second == photons) return c;
    }
    ADD_FAILURE() << "no photon rung of " << photons;
    return AutoCandidate{};
  };
  int missed_before = 0;
  for (const Cloud& cloud : clouds) {
    PilotMeasure against = pilotOf(2.9, cloud.multiple), bench = against, side = against;
    against.aureole = cloud.aureole;
    bench.aureole = {cloud.aureole[0], 0.0};  // as the bench shots: one view of two
    side.aureole = {0.0, 0.0};
    for (const auto& [photons, error] : cloud.measured) {
      const AutoCandidate with_rim = photon(against, photons);
      EXPECT_GE(with_rim.error, error) << photons;
      EXPECT_NE(with_rim.why.find("% of the views against the sun"), std::string::npos)
          << with_rim.why;
      // The bench's share and none at all predict the same bits: their errors hold the rim.
      const double without = photon(side, photons).error;
      EXPECT_EQ(photon(bench, photons).error, without) << photons;
      if (without < error) ++missed_before;
    }
  }
  EXPECT_GE(missed_before, 4);  // without it, the test can fail
  // Half-bright aureoles count for half; a droplet's views against the sun have their own term.
  PilotMeasure half = pilotOf(2.9, 0.7), full = half;
  half.aureole = {0.35, 0.7, 0.7, 0.7};  // 7/8 against the sun: 3/4 beyond the bench's half
  full.aureole = {0.7, 0.7, 0.7, 0.7};
  EXPECT_NEAR(latticeRimError(traits, half, 128), 0.75 * latticeRimError(traits, full, 128), 1e-12);
  SceneTraits droplet = traits;
  droplet.peak_split = true;
  EXPECT_EQ(latticeRimError(droplet, full, 128), 0.0);
  SceneTraits no_sun = traits;
  no_sun.sun = false;
  EXPECT_EQ(latticeRimError(no_sun, full, 128), 0.0);
  // A shot without views (a bake that later views read) takes every view as against the sun,
  // with the single-scattering share of the hard surfaces' rule: 5 x 0.16 x 0.1 at 128 voxels.
  PilotMeasure none;
  none.multiple_fraction = 1;  // what auto puts there without views
  EXPECT_NEAR(latticeRimError(traits, none, 128), 5 * 0.16 * 0.1, 1e-12);
}

TEST(AutoModel, CandidatesMeetingTheToleranceComeFirstCheapestFirst) {
  const std::vector<AutoCandidate> c = autoCandidates(traitsOf(0.1), pilotOf(2, 0.6), 0.1, 0);
  ASSERT_FALSE(c.empty());
  size_t meeting = 0;
  while (meeting < c.size() && c[meeting].error <= 0.1) ++meeting;
  ASSERT_GT(meeting, 0u);
  for (size_t i = meeting; i < c.size(); ++i) EXPECT_GT(c[i].error, 0.1);
  for (size_t i = 1; i < meeting; ++i) EXPECT_LE(c[i - 1].seconds, c[i].seconds);
  // Four 640x480 views at 10 %: a bake is far cheaper than the path tracer.
  EXPECT_EQ(c.front().method, "photon");
}

// A lattice fewer than 4 voxels across the cloud blurs its light across them (an outside probe:
// a bar of 100:1:1 with photon's multiple scattering at 0.39; a sheet a tenth of a voxel thick
// that auto gave to photon at a predicted 18 % came out 25 % dark): auto leaves such lattices
// out, and a cloud no rung resolves goes to the path tracer.
TEST(AutoModel, LatticesThatDoNotResolveTheCloudAreLeftOut) {
  const PilotMeasure p = pilotOf(2, 0.6);
  SceneTraits t = traitsOf(0.1);
  t.thinnest_voxels_128 = 3.0;  // a bar of about 40:1:1: 4 voxels across from lattice 171 up
  EXPECT_FALSE(latticeResolves(t, 128));
  EXPECT_TRUE(latticeResolves(t, 192));
  for (const AutoCandidate& c : autoCandidates(t, p, 0.1, 0)) {
    for (const auto& [knob, value] : c.knobs) {
      if (knob == "light_resolution") {
        EXPECT_GE(value, 192) << c.method;
      }
    }
  }
  EXPECT_EQ(autoCandidates(t, p, 0.1, 0).front().method, "photon");  // the 192 and 320 rungs
  t.thinnest_voxels_128 = 0.128;  // the probe's sheet: no rung resolves it
  for (const AutoCandidate& c : autoCandidates(t, p, 0.3, 0)) EXPECT_EQ(c.method, "pathtrace");
}

// A tally voxel spanning several mean free paths reads a dense cloud's lit skin too dark (an
// outside probe: photon's multiple scattering 0.73-0.87 of the path tracer's on dense spheres and
// a layer, where auto had predicted 0.1 and 0.3): rungs whose tally voxels are thicker than
// kPhotonMaxTallyDepth are left out, and the five bench scenes (at most 0.575 a 1/128 voxel,
// Disney's cloud) keep every rung of 48 tally voxels.
TEST(AutoModel, PhotonRungsWhoseTalliesAreOpticallyThickAreLeftOut) {
  const PilotMeasure p = pilotOf(2, 0.6);
  SceneTraits t = traitsOf(0.575);
  int rungs = 0;
  for (const PhotonRung& r : photonRungs()) rungs += r.tally_resolution >= 48;
  int offered = 0;
  for (const AutoCandidate& c : autoCandidates(t, p, 0.1, 0)) offered += c.method == "photon";
  EXPECT_EQ(offered, rungs);
  t.tau_voxel_128 = 0.78;  // the probe's sphere at extinction 50: 2.1 a voxel of 48
  for (const AutoCandidate& c : autoCandidates(t, p, 0.1, 0)) {
    if (c.method != "photon") continue;
    for (const auto& [knob, value] : c.knobs) {
      if (knob == "tally_resolution") {
        EXPECT_GE(value, 96);
      }
    }
  }
  t.tau_voxel_128 = 3.1;  // the probe's sphere at extinction 200: even 96 is 4.1
  for (const AutoCandidate& c : autoCandidates(t, p, 0.3, 0)) EXPECT_NE(c.method, "photon");
}

// The last rung (16M photons, lattices 320/96) is what reaches the tolerances between the 4M
// rung's prediction (1.1 x 2.25 x 0.0387 = 0.096) and its own (0.076) on four 640x480 views; below
// that only the path tracer is predicted to meet them. A Disney-like pilot: 2.08 at one path a
// pixel (the reference's 0.023 at 8192), 3.8 us a path.
TEST(AutoModel, TheLastRungMeetsTolerancesTheOthersCannot) {
  const PilotMeasure p = pilotOf(2.08, 0.7, 3.8e-6);
  const SceneTraits t = traitsOf(0.3);
  const PhotonRung& last = photonRungs().back();
  EXPECT_EQ(last.photons, int64_t(1) << 24);
  EXPECT_NEAR(1.1 * 2.25 * last.bunny_error, 0.076, 0.001);
  const AutoCandidate at8 = autoCandidates(t, p, 0.08, 0).front();
  EXPECT_EQ(at8.method, "photon");
  EXPECT_EQ(at8.knobs.front().second, last.photons) << at8.why;
  EXPECT_LT(at8.seconds, 600) << "a bake of minutes, against the path tracer's hour";
  EXPECT_EQ(autoCandidates(t, p, 0.07, 0).front().method, "pathtrace");
  const AutoCandidate at10 = autoCandidates(t, p, 0.1, 0).front();
  EXPECT_EQ(at10.method, "photon");
  EXPECT_LT(at10.knobs.front().second, last.photons) << "a cheaper rung meets 10 %";
}

TEST(AutoModel, WritingFollowsTheCompressionAndLeavesTheChoice) {
  EXPECT_LT(exrWriteSecondsPerPixel("none"), exrWriteSecondsPerPixel("rle"));
  EXPECT_LT(exrWriteSecondsPerPixel("rle"), exrWriteSecondsPerPixel("piz"));
  EXPECT_LT(exrWriteSecondsPerPixel("piz"), exrWriteSecondsPerPixel("zip"));
  EXPECT_EQ(exrWriteSecondsPerPixel("zip"), SceneTraits{}.write_seconds_per_pixel);
  EXPECT_THROW(exrWriteSecondsPerPixel("dwaa"), InputError);
  SceneTraits zip = traitsOf(0.1), none = zip;
  none.write_seconds_per_pixel = exrWriteSecondsPerPixel("none");
  const auto a = autoCandidates(zip, pilotOf(2, 0.6), 0.1, 0);
  const auto b = autoCandidates(none, pilotOf(2, 0.6), 0.1, 0);
  ASSERT_EQ(a.size(), b.size());
  // Every candidate writes the same views, so each saves the same seconds and the order holds.
  const double saved = zip.pixels * (zip.write_seconds_per_pixel - none.write_seconds_per_pixel);
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].method, b[i].method);
    EXPECT_NEAR(a[i].seconds - b[i].seconds, saved, 1e-9 * a[i].seconds);
  }
}

TEST(AutoModel, SingleWhereMultipleScatteringIsNegligible) {
  const std::vector<AutoCandidate> c = autoCandidates(traitsOf(0.05), pilotOf(2, 0.02), 0.1, 0);
  EXPECT_EQ(c.front().method, "single");
  // ... and never where it is not.
  for (const AutoCandidate& x : autoCandidates(traitsOf(0.05), pilotOf(2, 0.5), 0.3, 0)) {
    if (x.method == "single") {
      EXPECT_GT(x.error, 0.5);
    }
  }
}

TEST(AutoModel, NoPhotonPredictionForPeakyPhasesItDoesNotSplit) {
  SceneTraits t = traitsOf(0.1);
  t.phase_spikiness = 3000;  // peaky, but not split by photon: outside what it was measured on
  for (const AutoCandidate& x : autoCandidates(t, pilotOf(4, 0.6), 0.1, 0)) {
    EXPECT_NE(x.method, "photon");
  }
  t = traitsOf(0.1);
  t.photon_refuses = true;  // a backward peak: photon would refuse the shot
  for (const AutoCandidate& x : autoCandidates(t, pilotOf(4, 0.6), 0.5, 0)) {
    EXPECT_NE(x.method, "photon");
  }
}

// A droplet phase, whose peak photon splits off: photon is a candidate, predicted with the HG
// scenes' bound where no view looks towards the sun, and with the aureole's error added in
// quadrature where one does (0.15 + 0.03 A per view towards the sun, A its aureole's brightness,
// averaged over the views; auto_model.cpp).
TEST(AutoModel, DropletPhasesGetPhotonWithTheAureolesError) {
  SceneTraits hg = traitsOf(0.1), droplet = traitsOf(0.1);
  droplet.phase_spikiness = 1474;  // the Mie table at 10 um
  droplet.peak_split = true;
  PilotMeasure side = pilotOf(4, 0.6), facing = side;
  side.aureole = {0.0};
  facing.aureole = {4.64};  // one view, against the sun just behind a thin limb
  EXPECT_EQ(photonAureoleError(droplet, side), 0.0);
  EXPECT_EQ(photonAureoleError(hg, facing), 0.0);  // a phase that is not split
  // Not below what the three views towards the sun measured, as (A, error):
  for (const auto& [a, measured] : {std::pair{2.15, 0.17}, {0.76, 0.17}, {4.64, 0.28}}) {
    PilotMeasure p = side;
    p.aureole = {a};
    EXPECT_GE(photonAureoleError(droplet, p), measured) << a;
  }
  PilotMeasure two = facing;
  two.aureole = {0.0, 0.35};  // a faint aureole in one view of two counts for half of it
  EXPECT_NEAR(photonAureoleError(droplet, two), 0.5 * 0.5 * (0.15 + 0.03 * 0.35), 1e-12);
  // Per view in quadrature, then averaged, as a shot's error is: not the mean term in quadrature.
  EXPECT_NEAR(photonViewsError(droplet, two, 0.1),
              0.5 * (0.1 + std::hypot(0.1, 0.5 * (0.15 + 0.03 * 0.35))), 1e-12);
  EXPECT_GT(photonViewsError(droplet, two, 0.1), std::hypot(0.1, photonAureoleError(droplet, two)));
  auto photon = [](const std::vector<AutoCandidate>& all, int64_t photons) {
    for (const AutoCandidate& c : all) {
      if (c.method == "photon" && c.knobs.front().second == photons) return c;
    }
    ADD_FAILURE() << "no photon candidate with " << photons << " photons";
    return AutoCandidate{};
  };
  for (const PhotonRung& r : photonRungs()) {
    const double base = photon(autoCandidates(hg, side, 0.2, 0), r.photons).error;
    EXPECT_DOUBLE_EQ(photon(autoCandidates(droplet, side, 0.2, 0), r.photons).error, base);
    const AutoCandidate c = photon(autoCandidates(droplet, facing, 0.2, 0), r.photons);
    // Not below what the view against the sun measured at any rung (0.26-0.28) ...
    EXPECT_GE(c.error, 0.28);
    EXPECT_NEAR(c.error, std::hypot(base, 1.1 * (0.15 + 0.03 * 4.64)), 1e-12);
    EXPECT_NE(c.why.find("aureole"), std::string::npos) << c.why;
  }
  // ... so against the sun photon is chosen for 40 %, not for 20 %.
  EXPECT_EQ(autoCandidates(droplet, facing, 0.4, 0).front().method, "photon");
  EXPECT_NE(autoCandidates(droplet, facing, 0.2, 0).front().method, "photon");
}

// A shot of bake.vdb alone with a droplet phase: its views come later, so photon is predicted
// with the worst aureole measured.
TEST(AutoChoice, ADropletBakeWithoutViewsAssumesTheWorstAureole) {
  std::string text = shot(R"({"method": "auto", "tolerance": 0.35})");
  text.replace(text.find(R"({"type": "hg", "g": 0.6})"), 24,
               R"({"type": "mie_approx", "diameter_um": 20})");
  text.insert(text.rfind('}'),
              R"(, "outputs": {"exr": false, "vdb": true, "vdb_voxel_size": 0.25})");
  const ShotSpec s = parseShot(text, "");
  const AutoChoice c = chooseAuto(s, buildScene(s, "shot.json"), AutoOptions{});
  EXPECT_EQ(c.pilot.aureole, std::vector<double>{kAureoleWorst});
  ASSERT_EQ(c.chosen.method, "photon");
  EXPECT_GE(c.chosen.error, 1.1 * aureoleTerm(kAureoleWorst));
}

TEST(AutoModel, SmallViewsGoToThePathTracer) {
  // One 32x32 view: a bake's fixed cost is not worth it.
  const std::vector<AutoCandidate> c =
      autoCandidates(traitsOf(0.1, 32 * 32), pilotOf(2, 0.6), 0.1, 0);
  EXPECT_EQ(c.front().method, "pathtrace");
}

TEST(AutoChoice, ChoosesRunsNothingAndSaysWhy) {
  const ShotSpec s = parseShot(shot(R"({"method": "auto", "tolerance": 0.2})"), "");
  const Scene scene = buildScene(s, "shot.json");
  AutoOptions o;
  o.threads = 2;
  const AutoChoice c = chooseAuto(s, scene, o);
  EXPECT_EQ(c.shot.bake.method, c.chosen.method);
  EXPECT_NE(c.shot.bake.method, "auto");
  EXPECT_LE(c.chosen.error, 0.2);
  EXPECT_EQ(c.considered.front().method, c.chosen.method);
  EXPECT_GT(c.pilot.noise_1spp, 0);
  EXPECT_GT(c.pilot.multiple_fraction, 0.05);
  EXPECT_LT(c.pilot.multiple_fraction, 0.95);
  ASSERT_FALSE(c.planLines().empty());
  EXPECT_NE(c.planLines().front().find("auto: chose " + c.chosen.method), std::string::npos);
  EXPECT_EQ(c.toJson()["chosen"]["method"], c.chosen.method);
  // The resolved shot passes its method's own checks.
  EXPECT_NO_THROW(methodOf(c.shot).validate(c.shot, "shot.json"));
}

// A shot of bake.vdb alone gets a light bake (photon, predicted by its bound), not the path
// tracer, which would write the density only.
TEST(AutoChoice, ABakeForAShotWithoutViews) {
  std::string text = shot(R"({"method": "auto", "tolerance": 0.3})");
  text.insert(text.rfind('}'),
              R"(, "outputs": {"exr": false, "vdb": true, "vdb_voxel_size": 0.25})");
  const ShotSpec s = parseShot(text, "");
  const AutoChoice c = chooseAuto(s, buildScene(s, "shot.json"), AutoOptions{});
  EXPECT_EQ(c.chosen.method, "photon");
  EXPECT_EQ(c.pilot.samples, 0);  // no views, no pilot
  // The voxel size the sphere needs, should the path tracer be chosen, is not photon's: the
  // choice says so rather than drop it silently, and its shot passes photon's own checks.
  ASSERT_EQ(c.notes.size(), 1u);
  EXPECT_NE(c.notes[0].find("outputs.vdb_voxel_size 0.25 is not used: photon's bake.vdb is its "
                            "bake lattice (light_resolution "),
            std::string::npos)
      << c.notes[0];
  EXPECT_EQ(c.shot.outputs.vdb_voxel_size, 0);
  EXPECT_EQ(c.toJson().at("notes"), nlohmann::json(c.notes));
  const std::vector<std::string> plan = c.planLines();
  EXPECT_NE(std::find(plan.begin(), plan.end(), "auto: " + c.notes[0]), plan.end());
}

// What a photon of the small bakes took (PilotMeasure::photon_seconds) prices a rung's photons
// in place of the pilot's paths, by its order: an outside probe's box took 2.8-5.7x what the
// paths predicted. The rest of the prediction (lattice, views, writes) stays.
TEST(AutoModel, PhotonsSecondsComeFromTheSmallBakesWhereTheyWereTimed) {
  const SceneTraits t = traitsOf(0.1);
  const PilotMeasure plain = pilotOf(2, 0.6);
  PilotMeasure instant = plain, slow = plain, slower = plain;
  instant.photon_seconds = {{3, 0.0}, {4, 0.0}};
  slow.photon_seconds = {{3, 4e-6}, {4, 5e-6}};
  slower.photon_seconds = {{3, 8e-6}, {4, 10e-6}};
  const std::vector<AutoCandidate> base = autoCandidates(t, plain, 0.3, 0);
  const std::vector<AutoCandidate> z = autoCandidates(t, instant, 0.3, 0);
  const std::vector<AutoCandidate> a = autoCandidates(t, slow, 0.3, 0);
  const std::vector<AutoCandidate> b = autoCandidates(t, slower, 0.3, 0);
  int photons = 0;
  for (const AutoCandidate& c : base) {
    auto same = [&](const std::vector<AutoCandidate>& list) {
      const auto it = std::find_if(list.begin(), list.end(), [&](const AutoCandidate& x) {
        return x.method == c.method && x.knobs == c.knobs && x.samples == c.samples;
      });
      EXPECT_NE(it, list.end()) << c.method;
      return it == list.end() ? c : *it;
    };
    const AutoCandidate cz = same(z), ca = same(a), cb = same(b);
    EXPECT_DOUBLE_EQ(ca.error, c.error) << c.method;  // the error is not the cost's business
    if (c.method != "photon") {
      EXPECT_DOUBLE_EQ(ca.seconds, c.seconds) << c.method;
      continue;
    }
    ++photons;
    const auto knob = [&](const char* name) {
      return std::find_if(c.knobs.begin(), c.knobs.end(),
                          [&](const auto& k) { return k.first == name; })
          ->second;
    };
    // The photons' part is linear in the seconds measured at the rung's order, for each of
    // the two lights, times a factor where the rung's tally is finer than the small bakes'
    // (1.07-1.47x measured).
    const double per_photon = knob("order") == 3 ? 4e-6 : 5e-6;
    const double part = ca.seconds - cz.seconds;
    EXPECT_NEAR(cb.seconds - ca.seconds, part, 1e-9 * part);
    const double factor = part / (per_photon * double(knob("photons")) * 2);
    if (knob("tally_resolution") > kCheckTally) {
      EXPECT_GE(factor, 1.05);
      EXPECT_LE(factor, 1.5);
    } else {
      EXPECT_NEAR(factor, 1.0, 1e-9);
    }
    EXPECT_NE(ca.why.find("us a photon"), std::string::npos) << ca.why;
  }
  EXPECT_GE(photons, 3);
}

// What photon's small bakes measured of its angular truncation (PilotMeasure::photon_check)
// raises a rung's prediction where it exceeds the bench scenes' bound, by its order, and leaves
// it alone where the bound covers it (the bench scenes read 1.7-3.3 %).
TEST(AutoModel, APhotonTruncationTheBakesMeasuredRaisesItsPrediction) {
  const SceneTraits t = traitsOf(0.1);
  const PilotMeasure plain = pilotOf(2, 0.6);
  PilotMeasure small = plain, large = plain;
  small.photon_check = {{3, 0.05}, {4, 0.05}};
  large.photon_check = {{3, 0.49}, {4, 0.30}};  // the probe's layer under a sun 20 degrees high
  EXPECT_EQ(photonCheckedError(plain, 4), 0.0);
  EXPECT_EQ(photonCheckedError(large, 3), 0.49);
  const std::vector<AutoCandidate> base = autoCandidates(t, plain, 0.3, 0);
  const std::vector<AutoCandidate> with_small = autoCandidates(t, small, 0.3, 0);
  const std::vector<AutoCandidate> with_large = autoCandidates(t, large, 0.3, 0);
  ASSERT_EQ(base.size(), with_large.size());
  int photons = 0;
  for (const AutoCandidate& b : base) {
    if (b.method != "photon") continue;
    ++photons;
    const int order = int(std::find_if(b.knobs.begin(), b.knobs.end(), [](const auto& k) {
                            return k.first == "order";
                          })->second);
    for (const auto* list : {&with_small, &with_large}) {
      const auto it = std::find_if(list->begin(), list->end(), [&](const AutoCandidate& c) {
        return c.method == "photon" && c.knobs == b.knobs;
      });
      ASSERT_NE(it, list->end());
      if (list == &with_small) {
        EXPECT_DOUBLE_EQ(it->error, b.error);  // under the bound: unchanged
      } else {
        // What the probe measured at these rungs: 0.42-0.43 at order 3, 0.28-0.31 at order 4.
        EXPECT_GE(it->error, order == 3 ? 0.43 : 0.31) << order;
        EXPECT_GE(it->error, b.error);
        EXPECT_NE(it->why.find("angular truncation at"), std::string::npos) << it->why;
      }
    }
  }
  EXPECT_GE(photons, 3);
  EXPECT_EQ(base.front().method, "photon");
  EXPECT_EQ(with_small.front().method, "photon");
  EXPECT_NE(with_large.front().method, "photon");
}

// The truncation check compares two bakes' tiles where the pilot saw cloud light, relative to
// the pilot's mean there: background tiles count for nothing, as a shot's error is taken over
// the cloud's pixels.
TEST(AutoPilot, TileDifferenceCountsTheCloudsTilesOnly) {
  const std::vector<double> pilot{1, 2, 3, 2}, a = pilot;
  EXPECT_EQ(tileDifference(a, pilot, pilot), 0.0);
  const std::vector<double> b{1.2, 2.4, 3.6, 2.4};
  // RMS of 0.2 x (1, 2, 3, 2) over the mean 2: sqrt(0.04 x 18 / 4) / 2.
  EXPECT_NEAR(tileDifference(a, b, pilot), std::sqrt(0.04 * 18 / 4) / 2, 1e-12);
  EXPECT_NEAR(tileDifference(b, a, pilot), tileDifference(a, b, pilot), 1e-15);
  // The same cloud in a frame four times as large, the rest background: the same value.
  std::vector<double> wide = pilot, wide_a = a, wide_b = b;
  for (int k = 0; k < 12; ++k) {
    wide.push_back(0);
    wide_a.push_back(0);
    wide_b.push_back(0.5);  // light where the pilot saw none is not counted either
  }
  EXPECT_NEAR(tileDifference(wide_a, wide_b, wide), tileDifference(a, b, pilot), 1e-15);
  EXPECT_EQ(tileDifference({}, {}, {}), 0.0);
  EXPECT_EQ(tileDifference({1, 2}, a, pilot), 0.0);  // mismatched views: nothing to say
  EXPECT_EQ(tileDifference(a, b, std::vector<double>(4, 0.0)), 0.0);  // no cloud light
}

// Small bakes the scene refuses, or that measure no finite value, rule photon out.
TEST(AutoModel, AFailedPhotonCheckRulesPhotonOut) {
  PilotMeasure p = pilotOf(2, 0.6);
  EXPECT_EQ(autoCandidates(traitsOf(0.1), p, 0.3, 0).front().method, "photon");
  p.photon_check_failed = true;
  for (const AutoCandidate& c : autoCandidates(traitsOf(0.1), p, 0.3, 0)) {
    EXPECT_NE(c.method, "photon");
  }
}

// A thin layer under a sun 20 degrees high, seen from above: photon's expansion at orders 3 and
// 4 misses its light (an outside probe measured 0.42 and 0.28-0.31 at every rung), which the
// bench scenes' bound did not foresee. Its small bakes measure that before photon is chosen;
// a sphere's light is well within the bound and photon is chosen there.
TEST(AutoChoice, PhotonsTruncationIsCheckedBeforeItIsChosen) {
  const std::string layer = R"({"version": 1, "name": "layer",
    "volume": {"procedural": {"type": "perlin_cloud", "seed": 17, "center": [0, 0, 1],
      "size": [4, 4, 0.4], "resolution": 64, "cover": 0.45, "sharpness": 0.6, "density": 1,
      "octaves": 5, "frequency": 2.5, "persistence": 0.5}},
    "medium": {"extinction": 8, "albedo": 0.99, "phase": {"type": "hg", "g": 0.85}},
    "lighting": {"sun": {"direction": [0.8457, 0.4096, 0.3420], "irradiance": [3, 3, 3]}},
    "bake": {"method": "auto", "tolerance": 0.3},
    "views": [{"name": "down", "resolution": [320, 240], "camera": {"type": "perspective",
                "fov_deg": 50, "position": [0.2, -0.3, 4.5], "look_at": [0, 0, 1],
                "up": [0, 1, 0]}},
              {"name": "steep", "resolution": [320, 240], "camera": {"type": "perspective",
                "fov_deg": 50, "position": [-1.2, -1, 4], "look_at": [0, 0, 1],
                "up": [0, 0, 1]}}]})";
  AutoOptions o;
  o.threads = 2;
  const ShotSpec s = parseShot(layer, "");
  const AutoChoice c = chooseAuto(s, buildScene(s, "shot.json"), o);
  ASSERT_EQ(c.pilot.photon_check.size(), 2u);
  EXPECT_GT(photonCheckedError(c.pilot, 3), 0.3);
  EXPECT_GT(photonCheckedError(c.pilot, 4), 0.25);
  EXPECT_EQ(c.chosen.method, "pathtrace");
  EXPECT_EQ(c.toJson()["pilot"]["photon_check"].size(), 2u);
  const std::vector<std::string> plan = c.planLines();
  EXPECT_TRUE(std::any_of(plan.begin(), plan.end(), [](const std::string& l) {
    return l.find("photon's angular truncation") != std::string::npos;
  }));

  const ShotSpec sphere =
      parseShot(shot(R"({"method": "auto", "tolerance": 0.3})", 0.95, 3, 640), "");
  const AutoChoice p = chooseAuto(sphere, buildScene(sphere, "shot.json"), o);
  EXPECT_EQ(p.chosen.method, "photon");
  ASSERT_EQ(p.pilot.photon_check.size(), 2u);
  EXPECT_LT(photonCheckedError(p.pilot, 3), 0.1);
  EXPECT_LT(photonCheckedError(p.pilot, 4), 0.1);
  // The small bakes' seconds per photon, at the orders the rungs use, price the rungs.
  ASSERT_EQ(p.pilot.photon_seconds.size(), 2u);
  for (int order : {3, 4}) {
    ASSERT_EQ(p.pilot.photon_seconds.count(order), 1u) << order;
    EXPECT_GT(p.pilot.photon_seconds.at(order), 1e-8) << order;  // 3-5 us measured
    EXPECT_LT(p.pilot.photon_seconds.at(order), 1e-3) << order;
  }
  EXPECT_NE(p.chosen.why.find("us a photon"), std::string::npos) << p.chosen.why;
}

TEST(AutoChoice, ToleranceNoMethodMeetsIsAClearError) {
  const ShotSpec s = parseShot(shot(R"({"method": "auto", "tolerance": 0.001})"), "");
  const Scene scene = buildScene(s, "shot.json");
  AutoOptions o;
  o.threads = 2;
  o.max_samples = 1000;  // the path tracer would need ~1e6 paths per pixel
  try {
    chooseAuto(s, scene, o);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("shot.json: /bake/tolerance: no method is predicted to meet 0.001"),
              std::string::npos)
        << what;
    EXPECT_NE(what.find("the best predicted is"), std::string::npos) << what;
  }
}

TEST(AutoChoice, SequencesArePrecomputedsOrAClearError) {
  const std::string seq = R"({"version": 1, "name": "s",
    "volume": {"sequence": {"procedural": {"type": "perlin_cloud", "resolution": 16}, "frames": 2}},
    "medium": {"extinction": 3, "albedo": 0.9, "phase": {"type": "hg", "g": 0.6}},
    "lighting": {"sun": {"direction": [0, 0, 1], "irradiance": [1, 1, 1]}},
    "bake": {"method": "auto", "tolerance": TOL},
    "views": [{"name": "v", "camera": {"type": "orthographic", "position": [0, -5, 0],
               "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 2.5}, "resolution": [8, 8]}]})";
  auto with = [&](const std::string& tol) {
    std::string t = seq;
    t.replace(t.find("TOL"), 3, tol);
    return parseShot(t, "");
  };
  const ShotSpec ok = with("0.5");
  const AutoChoice c = chooseAuto(ok, Scene{}, AutoOptions{});
  EXPECT_EQ(c.shot.bake.method, "precomputed");
  try {
    chooseAuto(with("0.1"), Scene{}, AutoOptions{});
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/bake/tolerance: 0.1 cannot be met for an animated"),
              std::string::npos)
        << e.what();
  }
}

// The pilot's noise at one path per pixel predicts the noise of longer renders: measured between
// two 64-spp renders of the same view, within 25 % (both estimates are themselves noisy).
TEST(AutoPilot, NoiseMatchesTheNoiseOfLongerRenders) {
  const ShotSpec s = parseShot(shot(R"({"method": "pathtrace"})", 0.95, 3, 32), "");
  const Scene scene = buildScene(s, "shot.json");
  PilotOptions po;
  po.threads = 2;
  const PilotMeasure p = runPilot(scene, po);
  PairNoise pair;
  RenderLayers r[2];
  for (int k = 0; k < 2; ++k) {
    PathTracerOptions pt;
    pt.samples_per_pixel = 64;
    pt.seed = 50 + uint64_t(k);
    pt.threads = 2;
    r[k] = renderPathTraced(scene.medium, scene.sun, scene.sky, scene.cameras[0], pt);
  }
  pair.add(r[0], r[1]);
  EXPECT_NEAR(p.noise_1spp / (pair.relativeNoise() * 8.0), 1.0, 0.25);
  EXPECT_NEAR(p.multiple_fraction, pair.multipleFraction(), 0.1);
  EXPECT_GT(p.cloud_fraction, 0.3);
  EXPECT_LT(p.cloud_fraction, 0.7);  // a sphere of radius 1 in a 2.5-wide square: ~0.5
}

// The aureole's brightness: the RMS of the light within kAureoleDegrees of the sun over the
// cloud's values, relative to its mean, from the product of the two renders.
TEST(AutoPilot, AureoleIsTheLightTowardsTheSun) {
  Camera cam;
  cam.type = Camera::Type::kPerspective;
  cam.position = Vec3(0, -5, 0);
  cam.look_at = Vec3(0, 0, 0);
  cam.fov_deg = 60;  // neighbours 6.6 degrees apart at the centre, diagonals 9.3
  cam.width_px = cam.height_px = 10;
  RenderLayers r[2];
  for (RenderLayers& l : r) {
    l.beauty = Image(10, 10, 4);
    l.sun = l.sky = l.multiple = Image(10, 10, 3);
    for (int y = 0; y < 10; ++y) {
      for (int x = 0; x < 10; ++x) {
        l.beauty.at(x, y)[3] = 1;
        for (int c = 0; c < 3; ++c) l.sun.at(x, y)[c] = (x == 5 && y == 5) ? 10.f : 1.f;
      }
    }
  }
  r[1].sun.at(5, 5)[0] = 12.f;  // the two renders differ: the product, not the square
  const CameraRays rays(cam);
  // The sun behind pixel (5, 5): it and its four edge neighbours lie within 8 degrees.
  const Vec3 towards = rays.generate(5.5, 5.5).d;
  PairNoise view;
  view.add(r[0], r[1]);
  AureoleLight a;
  a.add(r[0], r[1], cam, towards);
  const double mean = (99 * 3 + 10 + 11 + 10) / 300.0;
  EXPECT_NEAR(a.relativeRms(view), std::sqrt((120.0 + 100 + 100 + 4 * 3) / 300.0) / mean, 1e-9);
  AureoleLight away;
  away.add(r[0], r[1], cam, -towards);
  EXPECT_EQ(away.relativeRms(view), 0.0);
  AureoleLight empty;
  EXPECT_EQ(empty.relativeRms(PairNoise{}), 0.0);
}

// Leaving out multiply scattered light that gathers in one pixel costs more, as an RMSE, than its
// share of the light says; spread evenly, the two agree.
TEST(AutoPilot, MultipleRmsExceedsTheShareWhereTheLightGathers) {
  auto layers = [](bool gathered) {
    RenderLayers l;
    l.beauty = Image(10, 10, 4);
    l.sun = l.sky = l.multiple = Image(10, 10, 3);
    for (int y = 0; y < 10; ++y) {
      for (int x = 0; x < 10; ++x) {
        l.beauty.at(x, y)[3] = 1;
        const bool bright = x == 3 && y == 4;
        for (int c = 0; c < 3; ++c) {
          l.multiple.at(x, y)[c] = gathered ? (bright ? 50.f : 0.f) : 0.5f;
          l.sun.at(x, y)[c] = 0.5f + l.multiple.at(x, y)[c];  // single 0.5 everywhere
        }
      }
    }
    return l;
  };
  PairNoise even, gathered;
  even.add(layers(false), layers(false));
  gathered.add(layers(true), layers(true));
  EXPECT_NEAR(even.multipleFraction(), 0.5, 1e-9);
  EXPECT_NEAR(even.multipleRms(), 0.5, 1e-9);
  EXPECT_NEAR(gathered.multipleFraction(), 0.5, 1e-9);         // 50 / 100 pixels over a mean of 1
  EXPECT_NEAR(gathered.multipleRms(), std::sqrt(25.0), 1e-9);  // sqrt(2500 / 100) / 1
  // Merging the two views' sums is accumulating both views.
  PairNoise both, merged = even;
  both.add(layers(false), layers(false));
  both.add(layers(true), layers(true));
  merged.merge(gathered);
  EXPECT_EQ(merged.values, both.values);
  EXPECT_EQ(merged.pixels, both.pixels);
  EXPECT_DOUBLE_EQ(merged.multipleRms(), both.multipleRms());
  EXPECT_DOUBLE_EQ(merged.multipleFraction(), both.multipleFraction());
  // single's prediction follows the RMS.
  SceneTraits t = traitsOf(0.05);
  PilotMeasure p = pilotOf(2, 0.5);
  p.multiple_rms = 5;
  for (const AutoCandidate& c : autoCandidates(t, p, 0.3, 0)) {
    if (c.method == "single") {
      EXPECT_GE(c.error, 1.25 * 5);
    }
  }
}

// The pilot counts a view towards the sun through the cloud, and not one from the side.
TEST(AutoPilot, CountsTheViewsTowardsTheSun) {
  PilotOptions po;
  po.threads = 2;
  const ShotSpec side = parseShot(shot(R"({"method": "pathtrace"})"), "");
  const PilotMeasure ps = runPilot(buildScene(side, ""), po);
  EXPECT_EQ(ps.aureole, std::vector<double>{0.0});
  std::string text = shot(R"({"method": "pathtrace"})");
  text.replace(text.find("[0.5, 0, 0.8660254]"), 19, "[0, 1, 0.05]");  // behind the sphere
  const ShotSpec facing = parseShot(text, "");
  const PilotMeasure pf = runPilot(buildScene(facing, ""), po);
  ASSERT_EQ(pf.aureole.size(), 1u);
  EXPECT_GE(pf.aureole[0], 0.99);  // every cloud pixel looks at the sun: the RMS over the mean
  // Under a black sun there is no aureole to measure.
  std::string black = text;
  const std::string lit = R"("irradiance": [1, 1, 1])";
  black.replace(black.find(lit), lit.size(), R"("irradiance": [0, 0, 0])");
  EXPECT_TRUE(runPilot(buildScene(parseShot(black, ""), ""), po).aureole.empty());
}

// Every view is piloted, however many: a shot whose first four views see only sky and whose
// fifth sees the cloud is measured on the fifth (before, only the first four were piloted and
// auto chose one path a pixel, predicted 0 error). Beyond four views they share four views'
// pixels.
TEST(AutoPilot, PilotsEveryViewInTheSamePixels) {
  PilotOptions po;
  po.threads = 2;
  EXPECT_EQ(pilotSide(po, 1), 64);
  EXPECT_EQ(pilotSide(po, 4), 64);
  EXPECT_EQ(pilotSide(po, 16), 32);
  EXPECT_EQ(pilotSide(po, 64), 16);
  EXPECT_EQ(pilotSide(po, 1000), 16);
  std::string text = shot(R"({"method": "auto", "tolerance": 0.05})", 0.95, 3, 32);
  const std::string view_at = R"("views": [)";
  const size_t at = text.find(view_at) + view_at.size();
  for (int k = 0; k < 4; ++k) {
    text.insert(at, R"({"name": "sky)" + std::to_string(k) + R"(", "camera": {"type": "perspective",
        "position": [0, -5, 0], "look_at": [0, -9, 0], "up": [0, 0, 1], "fov_deg": 30},
        "resolution": [8, 8]}, )");
  }
  const ShotSpec s = parseShot(text, "");
  ASSERT_EQ(s.views.size(), 5u);
  const Scene scene = buildScene(s, "shot.json");
  const PilotMeasure p = runPilot(scene, po);
  EXPECT_GT(p.noise_1spp, 0.1);
  EXPECT_GT(p.cloud_fraction, 0.05);
  EXPECT_EQ(p.aureole.size(), 1u) << "the one view with cloud pixels";
  AutoOptions ao;
  ao.threads = 2;
  const AutoChoice c = chooseAuto(s, scene, ao);
  EXPECT_LE(c.chosen.error, 0.05);
  EXPECT_GT(c.chosen.error, 0.0);
  if (c.chosen.method == "pathtrace") {
    EXPECT_GT(c.chosen.samples, 100);
  }
}

// What auto reads of the phase: whether photon splits its peak, or refuses it.
TEST(AutoPilot, TraitsSayWhetherPhotonSplitsOrRefusesThePhase) {
  auto traits = [](const std::string& phase) {
    std::string text = shot(R"({"method": "auto", "tolerance": 0.2})");
    text.replace(text.find(R"({"type": "hg", "g": 0.6})"), 24, phase);
    const ShotSpec s = parseShot(text, "");
    return measureSceneTraits(s, buildScene(s, "shot.json"));
  };
  const SceneTraits hg = traits(R"({"type": "hg", "g": 0.6})");
  EXPECT_FALSE(hg.peak_split);
  EXPECT_FALSE(hg.photon_refuses);
  const SceneTraits droplet = traits(R"({"type": "mie_approx", "diameter_um": 20})");
  EXPECT_TRUE(droplet.peak_split);
  EXPECT_GT(droplet.phase_spikiness, 50);
  const SceneTraits back = traits(R"({"type": "hg", "g": -0.99})");
  EXPECT_TRUE(back.photon_refuses);
}

// The surface's hardness: a sphere keeps its density to its edge; a Perlin cloud's fades; a
// box's faces are the box's own, which the lattice's planes follow, so they do not count.
TEST(AutoPilot, TraitsTellAHardSurfaceFromASoftEdge) {
  auto traits = [](const std::string& volume) {
    std::string text = shot(R"({"method": "auto", "tolerance": 0.2})", 0.95, 20);
    const std::string sphere = R"({"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}})";
    text.replace(text.find(sphere), sphere.size(), volume);
    const ShotSpec s = parseShot(text, "");
    return measureSceneTraits(s, buildScene(s, "shot.json"));
  };
  const SceneTraits sphere =
      traits(R"({"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}})");
  EXPECT_GT(sphere.tau_voxel_128, 0.3);
  EXPECT_EQ(sphere.hard_surface, 1.0);
  EXPECT_EQ(sphere.sunward_views, 0.0);  // its one view looks across the sun's direction
  const SceneTraits box = traits(R"({"box": {"min": [-1, -1, -1], "max": [1, 1, 1]}})");
  EXPECT_GT(box.tau_voxel_128, 0.3);
  EXPECT_EQ(box.hard_surface, 0.0);
  const SceneTraits perlin = traits(
      R"({"procedural": {"type": "perlin_cloud", "seed": 7, "center": [0, 0, 0],
          "size": [2, 2, 1], "resolution": 64, "cover": 0.55, "sharpness": 0.8,
          "density": 1.0, "octaves": 5, "frequency": 3.0, "persistence": 0.5}})");
  EXPECT_GT(perlin.tau_voxel_128, 0.0);
  EXPECT_LT(perlin.hard_surface, 0.05);
}

// A view of fewer layers writes fewer channels: the write's price follows them (cloud 4 of 22).
TEST(AutoPilot, TraitsPriceTheWriteOfTheLayersAsked) {
  ShotSpec s = parseShot(shot(R"({"method": "auto", "tolerance": 0.2})"), "");
  const Scene scene = buildScene(s, "shot.json");
  const double every = measureSceneTraits(s, scene).write_seconds_per_pixel;
  EXPECT_EQ(every, exrWriteSecondsPerPixel("zip"));
  s.outputs.exr_layers = {"cloud", "sun"};
  EXPECT_NEAR(measureSceneTraits(s, scene).write_seconds_per_pixel, every * 7.0 / 22.0,
              1e-12 * every);
}

// Absorbing media scatter once at most: the pilot measures no multiple scattering there, and a
// thick white one mostly multiple scattering.
TEST(AutoPilot, MultipleFractionFollowsAlbedoAndThickness) {
  PilotOptions po;
  po.threads = 2;
  const ShotSpec black = parseShot(shot(R"({"method": "pathtrace"})", 0.0), "");
  EXPECT_EQ(runPilot(buildScene(black, ""), po).multiple_fraction, 0.0);
  const ShotSpec white = parseShot(shot(R"({"method": "pathtrace"})", 1.0, 30), "");
  EXPECT_GT(runPilot(buildScene(white, ""), po).multiple_fraction, 0.6);
}

}  // namespace
}  // namespace cloudbake
