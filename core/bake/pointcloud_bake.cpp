#include "core/bake/pointcloud_bake.h"

#include <chrono>
#include <cmath>
#include <string>

#include "core/bake/bake_lattice.h"
#include "core/bake/point_splat.h"
#include "core/bake/scattering_passes.h"
#include "core/bake/sky_visibility.h"
#include "core/bake/sun_transmittance.h"
#include "core/error.h"
#include "core/format.h"

namespace cloudbake {
namespace {

using Clock = std::chrono::steady_clock;

// Significant digits of the floating-point metadata (a float's worth, as the files have always
// had).
constexpr int kMetadataDigits = 9;

// Progress of one stage mapped into [from, to] of the whole bake.
BakeProgressFn subRange(const BakeProgressFn& progress, double from, double to) {
  if (!progress) return {};
  return [progress, from, to](double f, const std::string& stage) {
    return progress(from + (to - from) * f, stage);
  };
}

// Wall-clock seconds of the stages bakePointcloud runs itself (runPointcloud times its own).
struct StageSeconds {
  double lattice = 0, sun = 0, sky = 0, splat = 0;
};

// The bake's metadata: every option and result a reader needs to tell how it was made, and
// what it cost.
void addPointcloudMetadata(const PointcloudOptions& options, const PointCloudResult& result,
                           double splat_radius, const StageSeconds& seconds, BakedLight* bake) {
  const bool paper = options.rule == PointcloudOptions::Rule::kPaper;
  auto& md = bake->metadata;
  md["cloudbake:method"] = "pointcloud";
  md["cloudbake:points"] = str(result.cloud.size());
  md["cloudbake:passes"] = str(options.passes);
  md["cloudbake:passes_run"] = str(result.passes_run);
  md["cloudbake:radius"] = str(result.radius, kMetadataDigits);
  md["cloudbake:radius_option"] = str(options.radius, kMetadataDigits);
  md["cloudbake:mean_neighbours"] = str(result.mean_neighbours, kMetadataDigits);
  md["cloudbake:point_spacing"] = str(result.cloud.spacing, kMetadataDigits);
  md["cloudbake:splat_radius"] = str(splat_radius, kMetadataDigits);
  md["cloudbake:rule"] = paper ? "paper" : "normalized";
  // How a view turns Co, R and light_dir into in-scattered light (render_from_bake.cpp).
  md["cloudbake:angular_model"] = paper ? "beam" : "p1";
  md["cloudbake:output_mapping"] = options.output_mapping ? "true" : "false";
  md["cloudbake:tolerance"] = str(options.tolerance, kMetadataDigits);
  md["cloudbake:last_relative_change"] = str(result.last_relative_change, kMetadataDigits);
  md["cloudbake:tail_ratio"] = str(result.tail_ratio, kMetadataDigits);
  md["cloudbake:pair_interactions"] = str(result.pair_interactions);
  md["cloudbake:pairs"] = str(result.pairs);
  md["cloudbake:light_resolution"] = str(options.light_resolution);
  md["cloudbake:seed"] = str(options.seed);
  if (!result.transfer_scale.empty()) {
    double mean = 0;
    for (const float k : result.transfer_scale) mean += k;
    md["cloudbake:mean_transfer_scale"] =
        str(mean / double(result.transfer_scale.size()), kMetadataDigits);
  }
  md["cloudbake:sky"] = options.sky ? "true" : "false";
  md["cloudbake:seconds_lattice"] = str(seconds.lattice, kMetadataDigits);
  md["cloudbake:seconds_sun_transmittance"] = str(seconds.sun, kMetadataDigits);
  md["cloudbake:seconds_sky_visibility"] = str(seconds.sky, kMetadataDigits);
  md["cloudbake:seconds_points"] = str(result.seconds_points, kMetadataDigits);
  md["cloudbake:seconds_neighbours"] = str(result.seconds_neighbours, kMetadataDigits);
  md["cloudbake:seconds_passes"] = str(result.seconds_passes, kMetadataDigits);
  md["cloudbake:seconds_splat"] = str(seconds.splat, kMetadataDigits);
}

PointcloudStats pointcloudStats(const PointCloudResult& result, double seconds_splat) {
  PointcloudStats stats;
  stats.points = int(result.cloud.size());
  stats.passes_run = result.passes_run;
  stats.radius = result.radius;
  stats.mean_neighbours = result.mean_neighbours;
  stats.pair_interactions = result.pair_interactions;
  stats.last_relative_change = result.last_relative_change;
  stats.seconds_points = result.seconds_points;
  stats.seconds_neighbours = result.seconds_neighbours;
  stats.seconds_passes = result.seconds_passes;
  stats.seconds_splat = seconds_splat;
  return stats;
}

}  // namespace

BakedLight bakePointcloud(const Medium& medium, const Vec3& sun_dir_in,
                          const PointcloudOptions& options, const BakeProgressFn& progress,
                          PointcloudStats* stats) {
  checkPointcloudInput(medium, options);
  if (!isFinite(sun_dir_in) || !(length(sun_dir_in) > 0)) {
    throw InputError("sun: direction: must be a finite nonzero vector");
  }
  const Vec3 sun_dir = normalize(sun_dir_in);
  auto report = [&](double f, const std::string& stage) {
    if (progress && !progress(f, stage)) throw Cancelled();
  };
  // Stage fractions of the whole bake.
  constexpr double kLattice = 0.05, kSun = 0.15, kSky = 0.25, kPoints = 0.9;

  StageSeconds seconds;
  auto t0 = Clock::now();
  report(0.0, "lattice");
  BakedLight bake =
      makeBakeLattice(*medium.density, options.light_resolution, LatticeSampling::kFieldAligned);
  seconds.lattice = secondsSince(t0);

  t0 = Clock::now();
  report(kLattice, "sun transmittance");
  computeSunTransmittance(bake, sun_dir, medium.extinction, subRange(progress, kLattice, kSun));
  seconds.sun = secondsSince(t0);

  // sky_visibility is also the escape probability the normalised rule conserves energy with.
  t0 = Clock::now();
  // The normalised rule's passes also need the reduced medium's (passExtinction): both come
  // from one sweep of the lattice.
  const bool normalised = options.rule == PointcloudOptions::Rule::kNormalized;
  const bool need_sky = options.sky || normalised;
  const double pass_ext = passExtinction(medium, options);
  FirstTouchFloats pass_vis;
  if (need_sky) {
    report(kSun, "sky visibility");
    std::vector<double> ext{medium.extinction};
    if (normalised && pass_ext != medium.extinction) ext.push_back(pass_ext);
    FirstTouchFloats vector;
    std::vector<FirstTouchFloats> v =
        skyVisibilities(bake.grid, bake.density.data(), ext, subRange(progress, kSun, kSky),
                        options.sky ? &vector : nullptr);
    bake.add(bake_grids::kSkyVisibility, 1).data = std::move(v[0]);
    if (options.sky) bake.add(bake_grids::kSkyVisibilityVector, 3).data = std::move(vector);
    if (v.size() > 1) pass_vis = std::move(v[1]);
  }
  seconds.sky = secondsSince(t0);

  const BakeChannel* vis = bake.find(bake_grids::kSkyVisibility);
  const PointCloudResult result =
      runPointcloud(bake.grid, bake.density, vis ? vis->data : FirstTouchFloats(), medium, sun_dir,
                    options, options.tail, subRange(progress, kSky, kPoints), pass_vis);
  if (!options.sky) bake.channels.erase(bake_grids::kSkyVisibility);

  t0 = Clock::now();
  report(kPoints, "splat");
  const double splat_radius = splatPoints(bake, result, [&](double f) {
    return progress && !progress(kPoints + (1 - kPoints) * f, "splat");
  });
  bake.addMeanRadiance();
  bake.trimToSupport();
  seconds.splat = secondsSince(t0);

  bake.method = "pointcloud";
  bake.sun_direction = sun_dir;
  addPointcloudMetadata(options, result, splat_radius, seconds, &bake);
  report(1.0, "done");

  if (stats) *stats = pointcloudStats(result, seconds.splat);
  return bake;
}

}  // namespace cloudbake
