// The cost and error model behind method `auto`: what each method is predicted to cost and how
// far from the reference it is predicted to land on one scene, from the scene's own numbers
// (SceneTraits) and a short pilot render of it (PilotMeasure). Free functions, so tests reach
// every step; the constants are fitted to bench/photon_bench.py's and bench/trade_bench.py's
// measured curves (docs/methods.md, "Method auto").
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace cloudbake {

/// What the model reads of a scene before any bake.
struct SceneTraits {
  double albedo = 1;           ///< the largest channel's single-scattering albedo
  double phase_spikiness = 0;  ///< V = 4 pi integral(p^2) - 1 (core/transport/sun_guiding.h)
  /// photon bakes this phase by splitting its forward peak off (droplets; photonPeakSplit).
  bool peak_split = false;
  /// photon refuses this phase (a backward peak no forward cut removes).
  bool photon_refuses = false;
  bool sun = false;  ///< a sun with irradiance > 0
  bool sky = false;  ///< a sky that is not black
  /// Optical thickness of one voxel of a 128-voxel lattice over the cloud's box where the
  /// cloud is dense (the 90th percentile of sigma_t inside it): how much a lattice's linear
  /// interpolation of the transmittance errs.
  double tau_voxel_128 = 0;
  /// The share of the cloud's surface that is hard: of the points holding density a quarter of
  /// such a voxel from an empty point (inside the box: not its own faces), those whose sigma_t
  /// is at least half the dense one (tau_voxel_128's). 1 for an analytic sphere; near 0 for a
  /// soft cloud's edge, and for a gridded one (a voxelised mesh's too) whose voxels are not
  /// finer than that quarter voxel.
  double hard_surface = 0;
  /// The share of the views whose axis lies within 90 degrees of the sun's direction (1 where
  /// the shot renders no views): where a hard surface's rim shows (latticeRimError).
  double sunward_views = 1;
  /// Voxels of a 128-voxel lattice across the cloud's bounds along their thinnest side.
  double thinnest_voxels_128 = 128;
  int views = 0;
  double pixels = 0;  ///< over every view
  /// Seconds per pixel of writing a view's EXR at the shot's outputs.exr_compression
  /// (exrWriteSecondsPerPixel).
  double write_seconds_per_pixel = 0.8e-6;  // ZIP's
  bool sequence = false;
  int frames = 1;
};

/// Seconds per pixel of writing a view's EXR (22 float channels, on every core of two) with
/// the named compression (outputs.exr_compression); InputError for an unknown name.
double exrWriteSecondsPerPixel(const std::string& compression);

/// A short path-traced render of the shot's views at a reduced size, two seeds: the noise and
/// cost of the reference on this scene, and how much of the cloud's light is multiply scattered.
struct PilotMeasure {
  /// Relative noise per pixel of the cloud's own light (sun + sky layers, pixels with alpha >=
  /// 0.05) at one path per pixel: the two renders' RMS difference / sqrt 2 / their mean, per
  /// view, averaged over the views, times sqrt(spp).
  double noise_1spp = 0;
  double seconds_per_sample = 0;  ///< per path per pixel, on the pilot's threads
  double multiple_fraction = 0;   ///< multiple / (single + multiple) over the cloud's pixels
  /// Per view, the relative RMSE of leaving the multiply scattered light out (PairNoise::
  /// multipleRms), averaged over the views: at least the fraction, and far more where that
  /// light gathers in a few bright pixels, such as a droplet's silver lining.
  double multiple_rms = 0;
  double cloud_fraction = 0;  ///< the pixels with alpha >= 0.05
  /// Per piloted view, how bright its cloud is where it looks within kAureoleDegrees of the sun,
  /// relative to its cloud as a whole: sqrt(sum of a x b over those pixels' values / all the
  /// cloud's values) / the cloud's mean, a and b the two renders' sun + sky light (their
  /// product has no noise bias). 0 where the view does not look towards the sun through the
  /// cloud; 0.76-4.64 for the droplet benches' views whose sun is behind the cloud. photon's
  /// error on droplet phases gathers there (auto_model.cpp). Views whose cloud covers no pixel
  /// are left out, as they have no error to measure; empty under a black sun.
  std::vector<double> aureole;
  double seconds = 0;  ///< what the pilot itself took
  int samples = 0;     ///< paths per pixel of each pilot render
  int64_t pixels = 0;  ///< pixels of each pilot render, over the views
  /// Per piloted view, its cloud's own light (sun + sky layers) summed over each tile of
  /// kPilotTile x kPilotTile pixels and the channels, row by row, the mean of the two renders;
  /// no tiles where the cloud covers no pixel of the view.
  std::vector<std::vector<double>> view_tiles;
  /// photon's angular truncation by spherical-harmonic order L (measurePhotonTruncation): the
  /// relative RMS difference of small bakes at L and L + 1 over the tiles holding cloud light,
  /// averaged over the views. Empty: not measured.
  std::map<int, double> photon_check;
  /// The small bakes failed (the scene refuses them) or measured no finite value: photon is
  /// not a candidate.
  bool photon_check_failed = false;
  double photon_check_seconds = 0;  ///< what measuring photon_check took
  /// What a photon of those small bakes took to trace and tally, by order, seconds per photon
  /// and light (the bakes' cloudbake:seconds_photons over their photons from each light that
  /// shines), at the shot's threads. Empty: not measured.
  std::map<int, double> photon_seconds;
};

/// The side in pixels of the pilot's tiles (PilotMeasure::view_tiles): large enough that a
/// tile's light is far less noisy than a pixel's at the pilot's paths, small enough that a
/// pattern of bright and dark regions does not cancel within one.
constexpr int kPilotTile = 8;

/// One method and its knobs as the model sees it.
struct AutoCandidate {
  std::string method;
  /// Knob values that differ from the method's defaults (integers; the shot's own bake.seed and
  /// the auto knobs are applied by the caller).
  std::vector<std::pair<std::string, int64_t>> knobs;
  int samples = 1;     ///< bake.samples
  double error = 0;    ///< predicted relative RMSE of the cloud's own light
  double seconds = 0;  ///< predicted seconds of the whole shot
  std::string why;     ///< one line: what the prediction rests on
};

/// Half-angle of the cone about the sun's direction in which PilotMeasure::aureole is measured.
constexpr double kAureoleDegrees = 8.0;
/// An aureole at least this bright (PilotMeasure::aureole of a view) counts fully.
constexpr double kAureoleFull = 0.7;
/// The brightest aureole measured (auto_bench's droplet_sphere): assumed for a shot without
/// views, whose views come later and may look towards the sun.
constexpr double kAureoleWorst = 4.64;
/// Phases peakier than this (droplets' Mie tables; HG 0.85 is 21) give the path tracer
/// heavy-tailed noise: the pilot traces more paths, and the path tracer gets a wider margin.
constexpr double kHeavyTailSpikiness = 100;

/// The photon ladder: each rung one of bench/photon_bench.py's measured settings (and beyond).
struct PhotonRung {
  int64_t photons;
  int order;
  int light_resolution;
  int tally_resolution;
  double bunny_error;  ///< relative RMSE measured on the bunny scene, the model's unit
};
const std::vector<PhotonRung>& photonRungs();

/// Relative error of `photon` on this scene over its error on the bunny scene at the same rung:
/// the worst of the five bench scenes (the rungs' errors across scenes keep their ratios within
/// about 20 %, but no trait of the scene predicted the ratio on held-out scenes; auto_model.cpp).
double photonSceneFactor(const SceneTraits& traits, const PilotMeasure& pilot);

/// photon's measured error at `order` (PilotMeasure::photon_check), 0 where not measured.
double photonCheckedError(const PilotMeasure& pilot, int order);

/// What a view's aureole (the light within kAureoleDegrees of the sun) of brightness A adds to
/// photon's error where its phase's forward peak was split off: min(1, A / kAureoleFull)
/// (0.15 + 0.03 A), fitted in auto_model.cpp.
double aureoleTerm(double brightness);
/// aureoleTerm averaged over the piloted views; 0 for a phase that is not split.
double photonAureoleError(const SceneTraits& traits, const PilotMeasure& pilot);
/// photon's predicted error before its margin: per view hypot(`bound`, aureoleTerm), averaged
/// over the views; `bound` itself for a phase that is not split.
double photonViewsError(const SceneTraits& traits, const PilotMeasure& pilot, double bound);

/// A lattice this many voxels across the cloud or more resolves it; one of fewer blurs its light
/// across them (docs/methods.md, "The lattice").
constexpr double kThinLatticeVoxels = 4;
/// Whether a lattice of `resolution` voxels along the cloud's longest side spans its thinnest
/// side with kThinLatticeVoxels or more: the lattice candidates' errors were measured on such
/// clouds only, and an outside probe's bar of 100:1:1 (2 voxels across) left `photon`'s multiple
/// scattering at 0.39 of the path tracer's.
bool latticeResolves(const SceneTraits& traits, int resolution);

/// The most optical thickness (of extinction, where the cloud is dense) a photon rung's tally
/// voxel may have to be a candidate.
constexpr double kPhotonMaxTallyDepth = 2.0;
/// Whether `rung`'s tally lattice resolves the light near a dense cloud's lit surface: its voxels
/// at most kPhotonMaxTallyDepth thick where the cloud is dense. A tally voxel averages the
/// scattered light over its depth, and where that spans several mean free paths the lit skin's
/// light is spread over the voxel and read too dark: an outside probe measured `photon`'s
/// multiple scattering 0.79 of the path tracer's on a layer of 8.3 optical depths per tally voxel,
/// 0.87 on a sphere of 2.1 and 0.73 on one of 8.3 (albedo 0.5), where auto had predicted 0.1 and
/// 0.3 and missed them. The five bench scenes have 1.5 or less at the rungs' 48 voxels.
bool photonTallyResolves(const SceneTraits& traits, const PhotonRung& rung);

/// Bias of single scattering read from a lattice of `resolution` voxels, relative: tau^2 / 2 per
/// voxel of optical thickness tau (measured on Disney's cloud; auto_model.cpp).
double latticeSingleBias(const SceneTraits& traits, int resolution);

/// The error of single scattering read from a lattice of `resolution` voxels at a hard surface
/// (a relative RMSE of the cloud's light): the blurred surface's rim, first order in the voxel,
/// 5 where every view looks towards the sun's side (0.5 where none does) x the
/// single-scattering share of the light (1 - PilotMeasure::multiple_fraction; 0.1 without a
/// pilot) x SceneTraits::hard_surface x 128 / resolution, less where a 1/128 voxel is optically
/// thin (auto_model.cpp), at most 1. Any cloud, hard or soft, has a rim too, which the bench
/// shots' errors hold for one view in two against the sun: where more of a shot's views look
/// against the sun (PilotMeasure::aureole; every view without a pilot), the surface counts as
/// hard as 0.16 x that excess share, unless the phase's peak was split (a droplet's views
/// against the sun have their own term). Part of `single`'s and `photon`'s predictions, whose
/// sun light comes from such a lattice.
double latticeRimError(const SceneTraits& traits, const PilotMeasure& pilot, int resolution);

/// The candidates the model predicts, cheapest first among those within `tolerance`; `limits`:
/// most samples per pixel a pathtrace candidate may ask (0: 1e6).
std::vector<AutoCandidate> autoCandidates(const SceneTraits& traits, const PilotMeasure& pilot,
                                          double tolerance, int max_samples);

/// How much less noise than the tolerance the path tracer is asked for: 1.2 (the pilot's noise
/// is itself uncertain), 1.75 for droplet phases, whose heavy-tailed noise a pilot reads low.
double pathtraceMargin(const SceneTraits& traits);

/// Paths per pixel that bring the reference's noise to `tolerance` on this scene.
int64_t pathtraceSamplesFor(const SceneTraits& traits, const PilotMeasure& pilot, double tolerance);

}  // namespace cloudbake
