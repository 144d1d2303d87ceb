// What method `auto` measures of a scene before it chooses: the traits read from the density
// and lights (cheap), and a pilot: a short path-traced render of the views at a reduced size with
// two seeds, which gives the reference's noise and cost on this very scene and how much of the
// cloud's light is multiply scattered.
#pragma once

#include <functional>
#include <map>
#include <vector>

#include "core/methods/auto_model.h"
#include "core/shot/shot.h"
#include "core/transport/path_tracer.h"
#include "core/transport/scene.h"

namespace cloudbake {

/// The shot's traits; `scene` must have its density built.
SceneTraits measureSceneTraits(const ShotSpec& shot, const Scene& scene);

struct PilotOptions {
  int longest_side_px = 64;  ///< each view is rendered at most this size (aspect kept)
  int samples = 8;           ///< paths per pixel of each of the two renders
  /// Every view is piloted; beyond this many they share these views' pixels (pilotSide).
  int full_size_views = 4;
  int max_depth = 100000;
  int threads = 0;
  /// Return false to stop (the pilot then throws Cancelled).
  std::function<bool(double fraction)> progress;
};

/// The longest side, in pixels, of each of `views` pilot views: options.longest_side_px for up
/// to options.full_size_views views, smaller beyond so that the pixels stay about the same,
/// and at least 16.
int pilotSide(const PilotOptions& options, int views);

/// Renders the pilot and measures it. A scene whose cloud covers no pixel of any view measures
/// noise and multiple fraction 0 (there is no cloud light to be wrong about).
PilotMeasure runPilot(const Scene& scene, const PilotOptions& options);

/// The small photon bakes measurePhotonTruncation renders: photons (from the sun, and as many
/// from a sky), their light and tally lattices, and rays per pixel of their views.
constexpr int64_t kCheckPhotons = 65536;
constexpr int kCheckLattice = 64;
constexpr int kCheckTally = 32;
constexpr int kCheckRays = 4;

/// The relative RMS difference of two renders' tiles `a` and `b` (PilotMeasure::view_tiles) over
/// the tiles where `reference` holds light, relative to the reference's mean there, as a shot's
/// error is taken over the cloud's pixels only; 0 where the sizes differ or no tile holds light.
double tileDifference(const std::vector<double>& a, const std::vector<double>& b,
                      const std::vector<double>& reference);

/// What photon's angular truncation at each of `orders` (spherical-harmonic degrees of its
/// tallies) leaves out on this scene: small photon bakes (kCheckPhotons, one seed, so the same
/// photons) at the order and the next, their views rendered at the pilot's size, and the
/// relative RMS of their tiles' difference (PilotMeasure::view_tiles; relative to the pilot's
/// light), averaged over the views: the next degree's share of the light, which the order
/// misses. photon's bound (auto_model.cpp) was measured on the bench scenes, whose light the
/// expansion holds; where it does not (a thin layer under a low sun, seen from above: 0.49x the
/// path tracer's light at order 3, 1.27x at order 4, in an outside probe) the bound fails at any
/// photon count. Empty where the pilot rendered no views. Cancelled when options.progress asks.
/// `seconds_per_photon` (if not null) receives each baked order's seconds per photon and light
/// (PilotMeasure::photon_seconds).
std::map<int, double> measurePhotonTruncation(const ShotSpec& shot, const Scene& scene,
                                              const PilotOptions& options,
                                              const PilotMeasure& pilot,
                                              const std::vector<int>& orders,
                                              std::map<int, double>* seconds_per_photon = nullptr);

/// The relative noise and mean of the cloud's own light (sun + sky layers over the pixels with
/// alpha >= 0.05 in both) between two renders of different seeds: RMS difference / sqrt 2 /
/// mean. Accumulated over views by `add`.
struct PairNoise {
  /// Sums over the cloud's pixels and channels: squared differences, the pair's mean of the
  /// cloud's own light (sun + sky) and of its multiply scattered part.
  double sum_sq_diff = 0, sum_mean = 0, sum_multiple = 0;
  /// Sum over the same values of the product of the two renders' multiply scattered light.
  double sum_multiple_product = 0;
  int64_t values = 0, cloud_pixels = 0, pixels = 0;
  void add(const RenderLayers& a, const RenderLayers& b);
  /// Adds another accumulation's sums (one view's into the shot's).
  void merge(const PairNoise& other);
  double relativeNoise() const;
  double multipleFraction() const;
  /// sqrt(sum_multiple_product / values) / the mean: the relative RMSE of leaving the multiply
  /// scattered light out (method single), which the fraction understates where that light is
  /// concentrated in a few pixels.
  double multipleRms() const;
};

/// PilotMeasure::aureole of one view: over the pair's cloud pixels (alpha >= 0.05 in both) whose
/// centre ray lies within kAureoleDegrees of `sun_dir` (unit, towards the sun), the sum of the
/// product of the two renders' light (sun + sky layers). The view's mean comes from its
/// PairNoise, which sums the same pixels.
struct AureoleLight {
  double sum_product = 0;
  void add(const RenderLayers& a, const RenderLayers& b, const Camera& camera, const Vec3& sun_dir);
  /// sqrt(sum_product / the view's values) / the view's mean; 0 where either is empty.
  double relativeRms(const PairNoise& view) const;
};

}  // namespace cloudbake
