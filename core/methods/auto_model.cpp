#include "core/methods/auto_model.h"

#include <algorithm>
#include <cmath>

#include "core/bake/render_from_bake.h"
#include "core/error.h"
#include "core/format.h"
#include "core/io/exr_compression.h"
#include "core/math/sh_basis.h"
#include "core/methods/auto_measure.h"
#include "core/methods/common.h"
#include "core/methods/photon.h"

namespace cloudbake {
namespace {

// A pilot's noise is itself uncertain (two renders of a few samples each): the reference is
// asked for this much less noise than the tolerance, so a noise measured 20 % low still meets it.
constexpr double kPathtraceMargin = 1.2;
// A droplet's spike (spikiness above kHeavyTailSpikiness) makes the noise heavy-tailed: 16384-path
// references measured 0.85-1.46x the noise its 32-path pilot read on the three droplet scenes
// (perlin_droplet, auto_bench's droplet_dense and droplet_sphere, whose silver lining the pilot
// read lowest), so the margin covers the worst: 1.2 x 1.46.
constexpr double kHeavyTailMargin = 1.75;
// single's prediction rests on the pilot's multiple-scattering share (itself noisy) and a
// voxel's optical thickness; photon's on the worst factor measured (photonSceneFactor).
constexpr double kModelMargin = 1.25;
constexpr double kPhotonMargin = 1.1;
// The rim's error at a hard surface per voxel of a 128-voxel lattice and per unit of the
// single-scattering share (latticeRimError): towards the sun, what an outside probe's spheres
// needed for their photon rungs to be bounded (2.4-4.9; the developers' own views needed 1.7);
// lit from the front or the side, 0.24-0.38 measured.
constexpr double kRimPerVoxel = 5.0;
constexpr double kRimPerVoxelLitFromFront = 0.5;
// The rim of any cloud, hard or soft, in the share of a shot's views against the sun beyond the
// bench shots' half (latticeRimError), as a hardness: what the Perlin cloud of sharpness 0.05
// needed with both views against the sun (0.07-0.15 over its rungs; at sharpness 0.9, 0.04-0.08).
constexpr double kRimBeyondBench = 0.16;
// The share of their views the bench shots have against the sun, in which their measured errors
// already hold the rim: one of two views in photonSceneFactor's five (one of three in
// perlin_droplet, whose phase has its own term).
constexpr double kBenchAureoleShare = 0.5;
// A 1/128 voxel's optical thickness from which a hard surface's rim is full (the sphere of
// extinction 15: 0.164).
constexpr double kRimFullDepth = 0.15;
// The single-scattering share a shot without views (no pilot) is taken to have: the spheres'
// measured 0.08-0.1 (latticeRimError).
constexpr double kRimShareWithoutPilot = 0.1;
// The rim below which a plan does not mention it (a cloud's whose surface is hard in a few
// places).
constexpr double kRimWorthSaying = 0.005;
constexpr double kPhotonWorstFactor = 2.25;
// Seconds per ray of a view rendered from a bake per coefficient it reads: bench/trade_curve.py's
// photon views at 256x192 took 0.031-0.091 us per ray and coefficient (1.3-4.1 us per ray with
// 37-45 coefficients) on two cores, their writing apart.
constexpr double kViewSecondsPerCoefficient = 6e-8;
// Seconds of one photon over those of one pilot path through the cloud: 0.16-0.68 on the five
// bench scenes at 524288 and 2M photons (bench/auto_cost_fit.py; the thin layer, whose paths are
// short, the highest), median 0.33; their upper quartile, so that a plan more often overstates
// a bake's time than understates it. 1.2 before photon's bake stopped adding its tallies
// atomically (issue 18), against 0.6-1.6 measured then.
constexpr double kPhotonPerPath = 0.43;
// Phase functions peakier than this (HG 0.85 is 21) and not split by photon (HG 0.9 is not,
// droplets are) are outside what photon's error was measured on.
constexpr double kPhotonMaxSpikiness = 50;
// photon's error on a view towards the sun with a droplet phase: a floor, and a part that grows
// with its aureole's brightness (the measurements in photonAureoleError).
constexpr double kAureoleFloor = 0.15;
constexpr double kAureoleSlope = 0.03;
// photon's relative RMSE over the truncation its small bakes measured (measurePhotonTruncation),
// where the truncation is what errs: an outside probe's thin layers under a sun 10 and 20
// degrees high, seen from above (80x60, 16384-path references), measured 0.35 and 0.42-0.43 at
// the order-3 rungs and 0.21-0.22 and 0.28-0.31 at the order-4 rungs, against truncations of
// 33 % and 45 % (order 3) and 23 % and 28 % (order 4): 0.91-1.11x. The five bench scenes read
// 1.7-3.3 %, under the bound at every rung.
constexpr double kPhotonCheckToError = 1.25;
// A rung's seconds per photon over those of the small bakes of measurePhotonTruncation at its
// order (PilotMeasure::photon_seconds), where its tally lattice is finer than theirs (32
// voxels): the larger tallies miss the cache more. Measured on an outside probe's side-lit box
// and two Perlin clouds (a rust albedo, coloured albedos), 2 threads, each bake's seconds with
// its lattice: 65536 photons at 64 / 32 took 3.5-4.0 us a photon and light at order 3 and
// 4.0-5.0 at order 4; 131072 at 64 / 32, order 3, 3.2-3.6 us; 524288 at 128 / 48, order 3,
// 4.0-4.5 us; 2M at 192 / 48, order 4, 4.9-5.8 us: 1.07-1.47x where the tally is 48. Where they
// were not measured the pilot's paths stand in (kPhotonPerPath), which read 0.5-0.9x what the
// bakes took on those scenes.
constexpr double kFinerTallyPhotonSeconds = 1.3;
// The zonal terms of the photon candidates: photon's default, which auto leaves as it is.
const int kZonalOrder = PhotonBakeOptions{}.zonal_order;

// The share of the piloted views that look at the cloud against the sun: each view's aureole
// brightness over kAureoleFull, at most 1; every view without a pilot (a shot without views),
// none without a sun.
double againstSunShare(const SceneTraits& traits, const PilotMeasure& pilot) {
  if (!traits.sun) return 0;
  if (pilot.samples <= 0) return 1;
  if (pilot.aureole.empty()) return 0;
  double sum = 0;
  for (double a : pilot.aureole) sum += std::clamp(a / kAureoleFull, 0.0, 1.0);
  return sum / double(pilot.aureole.size());
}

// Why a lattice's prediction includes latticeRimError (> 0).
std::string rimWhy(const SceneTraits& traits, const PilotMeasure& pilot, double rim) {
  return "; the lattice's rim is " + fixed(100 * rim, 1) +
         " % (in quadrature: " + fixed(100 * traits.hard_surface, 0) +
         " % of the cloud's surface hard, " + fixed(100 * againstSunShare(traits, pilot), 0) +
         " % of the views against the sun)";
}

// Writing every view's EXR: the same for every candidate.
double writeSeconds(const SceneTraits& traits) {
  return traits.pixels * traits.write_seconds_per_pixel;
}

// Rays per pixel of a view from a bake. The bakes' errors were measured at 80x60 with 16 rays
// per pixel, as the reference averages over each pixel (one ray through the centre would count
// thin edges' aliasing as error); the same rays per unit of image keep that error at any size:
// 16 x 4800 / (pixels per view), 1 from 320x240 up.
int bakeViewSamples(const SceneTraits& traits) {
  const double per_view = traits.views > 0 ? traits.pixels / traits.views : 4800;
  return int(std::clamp(std::ceil(16.0 * 4800.0 / std::max(per_view, 1.0)), 1.0, 16.0));
}

AutoCandidate singleCandidate(const SceneTraits& traits, const PilotMeasure& pilot,
                              int resolution) {
  AutoCandidate c;
  c.method = "single";
  c.knobs = {{"light_resolution", resolution}};
  c.samples = bakeViewSamples(traits);
  // It sees no light scattered twice or more: its error is that light's share, plus the bias of
  // its lattice.
  const double bias = latticeSingleBias(traits, resolution);
  // What it leaves out, as the error is measured: the RMS of the multiply scattered light over
  // the cloud's mean, which the fraction understates where that light is concentrated (a
  // droplet's silver lining: auto_bench's droplet_sphere, share 0.82, single measured 1.92 over
  // its two views, 2.9 on the one against the sun).
  const double missing = std::max(pilot.multiple_fraction, pilot.multiple_rms);
  const double rim = latticeRimError(traits, pilot, resolution);
  // hypot of hypot: with no rim, the same bits as before it.
  c.error = kModelMargin * std::hypot(std::hypot(missing, bias), rim);
  c.seconds = latticeSeconds(resolution) * (traits.sky ? 2.0 : 1.0) +
              traits.pixels * c.samples * 1.5e-6 + writeSeconds(traits);
  c.why = "multiple scattering carries " + fixed(100 * pilot.multiple_fraction, 1) +
          " % of the cloud's light in the pilot (" + fixed(100 * missing, 1) +
          " % as an RMS); the lattice's bias " + fixed(100 * bias, 1) + " %";
  if (rim >= kRimWorthSaying) c.why += rimWhy(traits, pilot, rim);
  return c;
}

// A photon view builds its field where it traces at least a quarter as many rays as the tally
// lattice has voxels (at most the rung's resolution plus its border, cubed); smaller views
// weight every coefficient per ray.
double photonViewSecondsPerRay(const SceneTraits& traits, const PhotonRung& rung, int samples) {
  const double rays = traits.views > 0 ? traits.pixels / traits.views * samples : 0.0;
  const int tally = rung.tally_resolution > 0 ? rung.tally_resolution : rung.light_resolution;
  if (viewFieldPays(rays, std::pow(tally + 2.0, 3))) {
    return photonFieldViewSecondsPerRay(rung.light_resolution);
  }
  return kViewSecondsPerCoefficient * double(shCount(rung.order) + kZonalOrder - rung.order);
}

AutoCandidate photonCandidate(const SceneTraits& traits, const PilotMeasure& pilot,
                              const PhotonRung& rung, double factor) {
  AutoCandidate c;
  c.method = "photon";
  c.knobs = {{"photons", rung.photons},
             {"order", rung.order},
             {"light_resolution", rung.light_resolution},
             {"tally_resolution", rung.tally_resolution}};
  const double aureole = photonAureoleError(traits, pilot);
  c.samples = bakeViewSamples(traits);
  // The bound rests on the bench scenes, whose own errors it covers; a scene whose light this
  // order's truncation misses by more (measurePhotonTruncation) is predicted from that instead.
  const double checked = photonCheckedError(pilot, rung.order);
  // The bench scenes' soft edges are in the bound; a hard surface's rim is not.
  const double rim = latticeRimError(traits, pilot, rung.light_resolution);
  c.error = kPhotonMargin *
            std::hypot(std::max(photonViewsError(traits, pilot, rung.bunny_error * factor),
                                kPhotonCheckToError * checked),
                       rim);
  // A photon's walk costs about what a camera path through the cloud does: both random-walk
  // the same medium with a next event per collision (fitted in docs/methods.md); where small
  // bakes measured it, what they took.
  const double path_seconds = pilot.seconds_per_sample / std::max(pilot.cloud_fraction, 0.02);
  const auto measured = pilot.photon_seconds.find(rung.order);
  const double photon_seconds =
      measured != pilot.photon_seconds.end()
          ? (rung.tally_resolution > kCheckTally ? kFinerTallyPhotonSeconds : 1.0) *
                measured->second
          : kPhotonPerPath * path_seconds;
  c.seconds = latticeSeconds(rung.light_resolution) * (traits.sky ? 2.0 : 1.0) +
              photon_seconds * double(rung.photons) *
                  ((traits.sky ? 1.0 : 0.0) + (traits.sun ? 1.0 : 0.0)) +
              traits.pixels * c.samples * photonViewSecondsPerRay(traits, rung, c.samples) +
              writeSeconds(traits);
  c.why = "photon's error at these knobs was " + fixed(100 * rung.bunny_error, 1) +
          " % on the bunny scene and at most " + fixed(factor, 2) +
          " times that on the five bench scenes";
  if (pilot.photon_check.count(rung.order) > 0) {
    c.why += "; small bakes put this order's angular truncation at " + fixed(100 * checked, 1) +
             " % of the light";
  }
  if (measured != pilot.photon_seconds.end()) {
    c.why += " and took " + fixed(1e6 * measured->second, 2) + " us a photon";
  }
  if (rim >= kRimWorthSaying) c.why += rimWhy(traits, pilot, rim);
  if (traits.peak_split) {
    c.why += "; the droplet's aureole adds " + fixed(100 * aureole, 1) +
             " % (views against the sun, " + fixed(100 * kAureoleFloor, 0) + " % + " +
             fixed(100 * kAureoleSlope, 0) + " % per unit of the aureole's brightness)";
  }
  return c;
}

AutoCandidate pathtraceCandidate(const SceneTraits& traits, const PilotMeasure& pilot,
                                 double tolerance, int max_samples) {
  AutoCandidate c;
  c.method = "pathtrace";
  const int64_t cap = max_samples > 0 ? max_samples : 1000000;
  const int64_t spp = std::min(pathtraceSamplesFor(traits, pilot, tolerance), cap);
  c.samples = int(spp);
  c.error = pathtraceMargin(traits) * pilot.noise_1spp / std::sqrt(double(spp));
  c.seconds = traits.pixels * double(spp) * pilot.seconds_per_sample + writeSeconds(traits);
  c.why = "the pilot's noise is " + fixed(pilot.noise_1spp, 3) + " at one path per pixel, " +
          fixed(1e6 * pilot.seconds_per_sample, 2) + " us per path";
  return c;
}

}  // namespace

double exrWriteSecondsPerPixel(const std::string& compression) {
  // bench/exr_compression.py's six pointcloud views at 640x480 on two cores: ZIP 0.15-0.38 s a
  // view, 0.75-0.8 us a pixel in bench/trade_curve.py's views; the others scaled by the median
  // of their writes over the median of ZIP's on the same views (none 0.54, rle 0.58, zips 0.99,
  // piz 0.93).
  constexpr double kZip = 0.8e-6;
  const auto c = exrCompressionFromName(compression);
  if (!c) {
    throw InputError("/outputs/exr_compression: unknown EXR compression '" + compression + "'");
  }
  switch (*c) {
    case ExrCompression::kNone:
      return 0.54 * kZip;
    case ExrCompression::kRle:
      return 0.58 * kZip;
    case ExrCompression::kZips:
      return 0.99 * kZip;
    case ExrCompression::kZip:
      return kZip;
    case ExrCompression::kPiz:
      return 0.93 * kZip;
  }
  return kZip;
}

const std::vector<PhotonRung>& photonRungs() {
  // bench/photon_bench.py --res 80 --ref-spp 8192 (docs/methods.md), the bunny scene's column,
  // measured with photon 5. Photon 6 (lattices on the grid's own voxels) measured 0.1201,
  // 0.0691, 0.0461 and 0.0379, and the same or less on the other four scenes: these stay, a
  // little above, so the predictions stay on the safe side of both versions. The last rung is
  // the far sweep's (--sweep far, 16 rays a pixel as the others), measured with photon 8: there
  // Disney's cloud and the cumulus measured 1.9-2.0x the bunny (photon 4's 0.060 and 0.058), and
  // 1.3-1.5x at 256 rays a pixel, within kPhotonWorstFactor.
  static const std::vector<PhotonRung> kRungs = {
      {131072, 3, 64, 32, 0.1201},   {524288, 3, 128, 48, 0.0730},   {2097152, 4, 192, 48, 0.0465},
      {4194304, 4, 192, 48, 0.0387}, {16777216, 4, 320, 96, 0.0307},
  };
  return kRungs;
}

double photonSceneFactor(const SceneTraits&, const PilotMeasure&) {
  // photon's error over the bunny's at the same knobs on the five scenes of
  // bench/photon_bench.py: perlin 1.2, bunny 1.0, Disney 2.25, thin layer 0.7, backlit cumulus
  // 1.82, stable across the rungs within about 20 %. A fit to the scene's numbers (the
  // multiple-scattering share, a voxel's optical thickness, a small photon bake's own tally
  // noise) explained it within 4 % on those five but was 0.5-2.4x off on the scenes of
  // bench/auto_bench.py: what matters most is how much of each view looks towards the sun,
  // where the transmittance lattice and the truncated forward peak err. So auto predicts the
  // worst of the five, and chooses photon only where even that meets the tolerance (the five
  // held-out scenes measured 0.87-1.4).
  return kPhotonWorstFactor;
}

double aureoleTerm(double brightness) {
  // Where the peak was split, the light scattered through it more than once spreads further
  // than the views' beam model gives (docs/methods.md, "Droplet phases"), and more photons do
  // not reduce it. Measured at 80x60 against 16384-spp references (their noise removed), the
  // views towards the sun of three droplet scenes, as (the pilot's aureole brightness A, what
  // the aureole added to the view's error at every rung): perlin_droplet (2.15, 0.16-0.17: 98 %
  // of the squared error within 8 degrees of the sun), auto_bench's droplet_dense (0.76, 0.17:
  // a fainter aureole, erring 21 % there against 7 %) and droplet_sphere (4.64, 0.26-0.28: the
  // sun just behind a thin limb). 0.15 + 0.03 A bounds all three (0.21, 0.17 and 0.29 in that
  // order); a view whose aureole is fainter than 0.7 pays a share of it. The side and glory
  // views, which do not look towards the sun, stay within the HG scenes' bound.
  return std::min(1.0, brightness / kAureoleFull) * (kAureoleFloor + kAureoleSlope * brightness);
}

double photonCheckedError(const PilotMeasure& pilot, int order) {
  const auto it = pilot.photon_check.find(order);
  return it == pilot.photon_check.end() ? 0.0 : it->second;
}

double photonAureoleError(const SceneTraits& traits, const PilotMeasure& pilot) {
  if (!traits.peak_split || pilot.aureole.empty()) return 0.0;
  double sum = 0;
  for (double a : pilot.aureole) sum += aureoleTerm(a);
  return sum / double(pilot.aureole.size());
}

double photonViewsError(const SceneTraits& traits, const PilotMeasure& pilot, double bound) {
  if (!traits.peak_split || pilot.aureole.empty()) return bound;
  // Per view, the bound and its aureole's term in quadrature, then the mean over the views, as
  // the error of a shot is (the mean of the terms in quadrature would read lower).
  double sum = 0;
  for (double a : pilot.aureole) sum += std::hypot(bound, aureoleTerm(a));
  return sum / double(pilot.aureole.size());
}

double latticeRimError(const SceneTraits& traits, const PilotMeasure& pilot, int resolution) {
  // The lattice blurs a hard surface over one of its voxels, and where the sun lies behind the
  // surface the blurred shell's single scattering is a bright rim the path tracer has not.
  // Measured on spheres of extinction 15 and 50 (radius 0.7, HG 0.8, albedo 0.95; 80x60 views
  // 12 and 5 degrees from the sun, against 8192-path references, their noise removed), the
  // `single` layer's error over the scattered light's mean, each sphere's worst view: 0.24-0.28
  // at 64 voxels, 0.11-0.15 at 128, 0.06-0.08 at 192, 0.04-0.045 at 320, first order in the
  // voxel's size and nearly the same at either extinction. Over the single layer's own mean
  // (the scattered light's times the single-scattering share, 0.08-0.1 there) that is 0.7-1.7
  // per 128 / N over both views, and 0.24-0.38 on views lit from the front or the side (their
  // axis 90 degrees or more from the sun). An outside probe's sphere of extinction 50 against
  // the sun read 0.44 of its single layer at 320 voxels: 1.1 per 128 / N.
  // How much of a view the rim covers depends on where the sun lies behind the limb: another
  // outside probe's spheres (radius 0.6 and 0.7, extinction 15 and 20; views 5-13 degrees from
  // the sun at other distances and framings) measured photon's rungs at up to 0.548 (524288
  // photons, one view 8 degrees from the sun) where 1.7 predicted 0.27. Bounding every rung
  // there takes 2.4-4.9 per 128 / N, of the share, towards the sun: kRimPerVoxel.
  // An optically thin surface has no rim to speak of: a sphere of extinction 3 (0.033 a 1/128
  // voxel) measured 0.019-0.033 per 128 / N, 0.011-0.02 of the thick spheres' 1.7. The square
  // of its optical thickness over kRimFullDepth bounds that by 2.5-4.3x (by 7-13x with 5).
  // Without a pilot (a shot without views, whose bake.vdb later views read) the share is not
  // measured: the thick spheres' 0.1 (kRimShareWithoutPilot), with every view towards the sun.
  // All of the light, a first form, put the 16M rung at 75 % on a sphere of
  // extinction 50, a bake no tolerance could ask for; a thin surface keeps its damping.
  // A NaN share or thickness reads as the largest rim (std::min(1.0, NaN) is 1).
  const double thick = std::min(1.0, std::pow(traits.tau_voxel_128 / kRimFullDepth, 2));
  const double single_share = pilot.samples > 0
                                  ? std::clamp(1.0 - pilot.multiple_fraction, 0.0, 1.0)
                                  : kRimShareWithoutPilot;
  const double sunward = std::clamp(traits.sunward_views, 0.0, 1.0);
  const double per_voxel =
      kRimPerVoxelLitFromFront + (kRimPerVoxel - kRimPerVoxelLitFromFront) * sunward;
  // Soft clouds have a rim too: a gridded cloud's edge is one of its voxels wide, and the bench
  // shots' errors hold it for one view in two against the sun. A shot with more of its views
  // there has more of it: the Perlin cloud of `cumulus_backlit` with both views 12 and 5
  // degrees from the sun (80x60, 16 rays a pixel, against 8192-path references, their noise
  // removed) measured photon's rungs at 0.557 / 0.209 / 0.171 / 0.166 at sharpness 0.05 (an
  // outside probe's like it: 0.468 / 0.207 / 0.166 / 0.164) and 0.414 / 0.146 / 0.112 / 0.107 at
  // 0.9, where 0.297 / 0.181 / 0.115 / 0.096 were predicted. A hardness of kRimBeyondBench
  // times the views' share against the sun beyond the bench's bounds both. A droplet's views
  // against the sun have their own term, measured on such views with their rim
  // (photonAureoleError).
  const double beyond_bench =
      traits.peak_split ? 0.0
                        : std::clamp((againstSunShare(traits, pilot) - kBenchAureoleShare) /
                                         (1 - kBenchAureoleShare),
                                     0.0, 1.0);
  const double hardness =
      std::max(per_voxel * traits.hard_surface, kRimPerVoxel * kRimBeyondBench * beyond_bench);
  return std::min(1.0, hardness * thick * single_share * 128.0 / std::max(resolution, 1));
}

double latticeSingleBias(const SceneTraits& traits, int resolution) {
  // Single scattering read from a lattice is biased where a voxel is optically thick (the
  // interpolated transmittance and density at thin, bright edges). Measured on Disney's cloud
  // (tau_voxel_128 0.575; `single` against `pathtrace` with max_depth 1 at 80x60, 16 rays per
  // pixel): 11-23 % bright at 96 voxels, 4.5-7.8 % at 192, 1.5-1.6 % at 384 (side-lit and
  // towards the sun), about tau^2 / 2 per voxel of optical thickness tau; the curvature of
  // exp(-tau) alone would give tau^2 / 8.
  const double tau = traits.tau_voxel_128 * 128.0 / std::max(resolution, 1);
  return std::min(1.0, tau * tau / 2.0);
}

bool latticeResolves(const SceneTraits& traits, int resolution) {
  return traits.thinnest_voxels_128 * resolution / 128.0 >= kThinLatticeVoxels;
}

bool photonTallyResolves(const SceneTraits& traits, const PhotonRung& rung) {
  const int tally = rung.tally_resolution > 0 ? rung.tally_resolution : rung.light_resolution;
  return traits.tau_voxel_128 * 128.0 / std::max(tally, 1) <= kPhotonMaxTallyDepth;
}

double pathtraceMargin(const SceneTraits& traits) {
  return traits.phase_spikiness > kHeavyTailSpikiness ? kHeavyTailMargin : kPathtraceMargin;
}

int64_t pathtraceSamplesFor(const SceneTraits& traits, const PilotMeasure& pilot,
                            double tolerance) {
  const double ratio = pathtraceMargin(traits) * pilot.noise_1spp / tolerance;
  const double spp = std::ceil(ratio * ratio);
  return spp < 1 ? 1 : spp > 1e12 ? int64_t(1e12) : int64_t(spp);
}

std::vector<AutoCandidate> autoCandidates(const SceneTraits& traits, const PilotMeasure& pilot,
                                          double tolerance, int max_samples) {
  std::vector<AutoCandidate> all;
  // Lattices too coarse across the cloud are left out: what they predict was measured on
  // clouds they resolve.
  for (int resolution : {128, 256}) {
    if (latticeResolves(traits, resolution)) {
      all.push_back(singleCandidate(traits, pilot, resolution));
    }
  }
  const double factor = photonSceneFactor(traits, pilot);
  if (!traits.photon_refuses && !pilot.photon_check_failed &&
      (traits.phase_spikiness <= kPhotonMaxSpikiness || traits.peak_split)) {
    for (const PhotonRung& rung : photonRungs()) {
      if (latticeResolves(traits, rung.light_resolution) && photonTallyResolves(traits, rung)) {
        all.push_back(photonCandidate(traits, pilot, rung, factor));
      }
    }
  }
  // Without views the path tracer makes nothing to be accurate about (a shot of bake.vdb
  // alone wants the baked light).
  if (traits.pixels > 0) all.push_back(pathtraceCandidate(traits, pilot, tolerance, max_samples));
  std::stable_sort(all.begin(), all.end(), [&](const AutoCandidate& a, const AutoCandidate& b) {
    const bool ma = a.error <= tolerance, mb = b.error <= tolerance;
    if (ma != mb) return ma;
    return ma ? a.seconds < b.seconds : a.error < b.error;
  });
  return all;
}

}  // namespace cloudbake
