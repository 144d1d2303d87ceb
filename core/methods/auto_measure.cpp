#include "core/methods/auto_measure.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>

#include "core/bake/photon_bake.h"
#include "core/bake/render_from_bake.h"
#include "core/error.h"
#include "core/format.h"
#include "core/math/rng.h"
#include "core/methods/common.h"
#include "core/transport/camera.h"
#include "core/transport/path_tracer.h"
#include "core/transport/sun_guiding.h"

namespace cloudbake {
namespace {

constexpr double kCloudAlpha = 0.05;
constexpr double kEdgeProbeFraction = 1.0 / 512;  // hardSurfaceShare's step, of the box's side

// The 90th percentile of sigma_t over the cloud's box where there is any density: a lattice's
// interpolation errs where the cloud is dense, and a percentile ignores the odd spike.
double denseSigmaT(const Medium& medium) {
  const DensityField& field = *medium.density;
  const Bounds3 b = field.bounds();
  auto lookup = field.lookup();
  Rng rng(0x5ca1ab1eULL, 7);
  std::vector<double> inside;
  constexpr int kPoints = 8192;
  for (int i = 0; i < kPoints; ++i) {
    const Vec3 p{b.min.x + (b.max.x - b.min.x) * rng.uniform(),
                 b.min.y + (b.max.y - b.min.y) * rng.uniform(),
                 b.min.z + (b.max.z - b.min.z) * rng.uniform()};
    const double d = lookup->density(p);
    if (d > 0) inside.push_back(d * medium.extinction);
  }
  if (inside.empty()) return 0;
  const size_t k = std::min(inside.size() - 1, size_t(0.9 * double(inside.size())));
  std::nth_element(inside.begin(), inside.begin() + long(k), inside.end());
  return inside[k];
}

// The share of the cloud's surface that is hard: random points holding density with an empty
// point kEdgeProbeFraction of the box's longest side away along an axis (a quarter of a 1/128
// voxel), counted where sigma_t is at least half `dense_sigma_t`. Empty points outside the box
// do not count: a box's own faces are flat and read as soft clouds do (an outside probe's boxes
// measured 0.01-0.06 from 128 voxels); the rim is a curved limb's. An analytic sphere is hard
// all over; a soft cloud's edge fades to 0 within that distance, and so does a gridded cloud's
// (a voxelised mesh's, a VDB's) unless its voxels are finer than that distance: the bench
// scenes, an outside probe's nine and the Stanford bunny voxelised at 96 and 256 read 0. A
// lattice's trilinear density blurs a hard surface over one of its voxels (latticeRimError).
double hardSurfaceShare(const Medium& medium, double dense_sigma_t) {
  if (!(dense_sigma_t > 0)) return 0;  // no extinction: no surface to speak of
  const DensityField& field = *medium.density;
  const Bounds3 b = field.bounds();
  const Vec3 size = b.max - b.min;
  const double h = std::max({size.x, size.y, size.z}) * kEdgeProbeFraction;
  auto lookup = field.lookup();
  Rng rng(0xed9e5eedULL, 11);
  int64_t edge = 0, hard = 0;
  constexpr int kPoints = 32768;
  for (int i = 0; i < kPoints; ++i) {
    const Vec3 p{b.min.x + size.x * rng.uniform(), b.min.y + size.y * rng.uniform(),
                 b.min.z + size.z * rng.uniform()};
    const double d = lookup->density(p);
    if (!(d > 0)) continue;
    bool empty_near = false;
    for (int a = 0; a < 3 && !empty_near; ++a) {
      for (double sign : {-1.0, 1.0}) {
        Vec3 q = p;
        q[a] += sign * h;
        if (q[a] < b.min[a] || q[a] > b.max[a]) continue;
        if (!(lookup->density(q) > 0)) {
          empty_near = true;
          break;
        }
      }
    }
    if (!empty_near) continue;
    ++edge;
    if (d * medium.extinction >= 0.5 * dense_sigma_t) ++hard;
  }
  return edge > 0 ? double(hard) / double(edge) : 0.0;
}

// The share of the views that look towards the sun's side (their axis within 90 degrees of the
// sun's direction); 1 without views, as the views of a later render may.
double sunwardShare(const std::vector<Camera>& views, const Vec3& sun_direction) {
  if (views.empty()) return 1;
  int sunward = 0;
  for (const Camera& c : views) sunward += dot(c.look_at - c.position, sun_direction) > 0 ? 1 : 0;
  return double(sunward) / double(views.size());
}

// A view's cloud light summed over each tile of kPilotTile pixels (the edge tiles smaller) and
// the channels, row by row: the sun and sky layers hold the cloud's scattered light alone, so
// no alpha mask is needed and the sums compare between renders whose alphas differ.
std::vector<double> tileLight(const RenderLayers& r) {
  const int w = r.sun.width, h = r.sun.height;
  const int tx = (w + kPilotTile - 1) / kPilotTile, ty = (h + kPilotTile - 1) / kPilotTile;
  std::vector<double> tiles(size_t(tx) * size_t(ty), 0.0);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      double& t = tiles[size_t(y / kPilotTile) * size_t(tx) + size_t(x / kPilotTile)];
      for (int c = 0; c < 3; ++c) t += double(r.sun.at(x, y)[c]) + r.sky.at(x, y)[c];
    }
  }
  return tiles;
}

Camera pilotCamera(const Camera& c, int longest) {
  Camera p = c;
  const int side = std::max(c.width_px, c.height_px);
  if (side > longest) {
    const double s = double(longest) / side;
    p.width_px = std::max(1, int(std::lround(c.width_px * s)));
    p.height_px = std::max(1, int(std::lround(c.height_px * s)));
  }
  return p;
}

}  // namespace

SceneTraits measureSceneTraits(const ShotSpec& shot, const Scene& scene) {
  SceneTraits t;
  const Medium& m = scene.medium;
  t.albedo = maxComponent(m.albedo);
  t.phase_spikiness = phaseSpikiness(*m.phase);
  try {
    t.peak_split = photonPeakSplit(*m.phase, PhotonBakeOptions{}).active();
  } catch (const InputError&) {
    t.photon_refuses = true;
  }
  t.sun = shot.lighting.has_sun && maxComponent(scene.sun.irradiance) > 0;
  t.sky = needsSky(shot);
  const Bounds3 b = m.density->bounds();
  const double extent = std::max({b.max.x - b.min.x, b.max.y - b.min.y, b.max.z - b.min.z});
  const double dense_sigma_t = denseSigmaT(m);
  t.tau_voxel_128 = dense_sigma_t * extent / 128.0;
  t.hard_surface = hardSurfaceShare(m, dense_sigma_t);
  const double thinnest = std::min({b.max.x - b.min.x, b.max.y - b.min.y, b.max.z - b.min.z});
  t.thinnest_voxels_128 = extent > 0 ? 128.0 * thinnest / extent : 128.0;
  if (shot.outputs.exr) {  // views are rendered only then
    t.views = int(shot.views.size());
    for (const Camera& c : shot.views) t.pixels += double(c.width_px) * c.height_px;
    t.sunward_views = sunwardShare(shot.views, scene.sun.direction);
    // The writes were measured with every layer, 22 channels; a view of fewer writes in about
    // their share (measured: four 640x480 views' ZIP writes 2.2-2.4 s -> 0.4-0.5 s with `cloud`
    // alone, docs/methods.md).
    double channels = 0;
    for (const std::string& layer : shot.outputs.exr_layers) channels += layer == "cloud" ? 4 : 3;
    t.write_seconds_per_pixel =
        exrWriteSecondsPerPixel(shot.outputs.exr_compression) * (channels / 22.0);
  } else {
    t.write_seconds_per_pixel = 0;  // nothing is written
  }
  if (const auto* seq = std::get_if<SequenceVolumeSpec>(&shot.volume)) {
    t.sequence = true;
    t.frames = seq->frames;
  }
  return t;
}

void PairNoise::add(const RenderLayers& a, const RenderLayers& b) {
  const int w = a.beauty.width, h = a.beauty.height;
  pixels += int64_t(w) * h;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      if (a.beauty.at(x, y)[3] < kCloudAlpha || b.beauty.at(x, y)[3] < kCloudAlpha) continue;
      ++cloud_pixels;
      for (int c = 0; c < 3; ++c) {
        const double va = double(a.sun.at(x, y)[c]) + a.sky.at(x, y)[c];
        const double vb = double(b.sun.at(x, y)[c]) + b.sky.at(x, y)[c];
        sum_sq_diff += (va - vb) * (va - vb);
        sum_mean += 0.5 * (va + vb);
        const double ma = a.multiple.at(x, y)[c], mb = b.multiple.at(x, y)[c];
        sum_multiple += 0.5 * (ma + mb);
        sum_multiple_product += ma * mb;
        ++values;
      }
    }
  }
}

void AureoleLight::add(const RenderLayers& a, const RenderLayers& b, const Camera& camera,
                       const Vec3& sun_dir) {
  const CameraRays rays(camera);
  const double cos_max = std::cos(kAureoleDegrees * kPi / 180.0);
  for (int y = 0; y < a.beauty.height; ++y) {
    for (int x = 0; x < a.beauty.width; ++x) {
      if (a.beauty.at(x, y)[3] < kCloudAlpha || b.beauty.at(x, y)[3] < kCloudAlpha) continue;
      if (dot(rays.generate(x + 0.5, y + 0.5).d, sun_dir) < cos_max) continue;
      for (int c = 0; c < 3; ++c) {
        const double va = double(a.sun.at(x, y)[c]) + a.sky.at(x, y)[c];
        const double vb = double(b.sun.at(x, y)[c]) + b.sky.at(x, y)[c];
        sum_product += va * vb;
      }
    }
  }
}

double AureoleLight::relativeRms(const PairNoise& view) const {
  if (view.values == 0 || !(view.sum_mean > 0) || !(sum_product > 0)) return 0;
  const double n = double(view.values);
  return std::sqrt(sum_product / n) / (view.sum_mean / n);
}

void PairNoise::merge(const PairNoise& o) {
  sum_sq_diff += o.sum_sq_diff;
  sum_mean += o.sum_mean;
  sum_multiple += o.sum_multiple;
  sum_multiple_product += o.sum_multiple_product;
  values += o.values;
  cloud_pixels += o.cloud_pixels;
  pixels += o.pixels;
}

double PairNoise::relativeNoise() const {
  if (values == 0 || !(sum_mean > 0)) return 0;
  return std::sqrt(sum_sq_diff / double(values) / 2.0) / (sum_mean / double(values));
}

double PairNoise::multipleRms() const {
  if (values == 0 || !(sum_mean > 0) || !(sum_multiple_product > 0)) return 0;
  return std::sqrt(sum_multiple_product / double(values)) / (sum_mean / double(values));
}

double PairNoise::multipleFraction() const {
  return sum_mean > 0 ? std::clamp(sum_multiple / sum_mean, 0.0, 1.0) : 0.0;
}

int pilotSide(const PilotOptions& o, int views) {
  if (views <= o.full_size_views) return o.longest_side_px;
  const double scale = std::sqrt(double(std::max(o.full_size_views, 1)) / double(views));
  return std::max(std::min(16, o.longest_side_px), int(std::lround(o.longest_side_px * scale)));
}

PilotMeasure runPilot(const Scene& scene, const PilotOptions& o) {
  PilotMeasure pm;
  pm.samples = o.samples;
  const auto t0 = std::chrono::steady_clock::now();
  PairNoise noise;
  double noise_sum = 0, multiple_rms_sum = 0;
  int noise_views = 0;
  const bool sun = maxComponent(scene.sun.irradiance) > 0;
  // Every view: a shot's error is the mean over its views, and one left out would count as none
  // (a shot whose first four views saw only sky, when only four were piloted, was given one
  // path a pixel for a fifth that saw the cloud, which then measured 0.68 against 0.05).
  const int n = int(scene.cameras.size());
  const int side = pilotSide(o, n);
  for (int v = 0; v < n; ++v) {
    const Camera cam = pilotCamera(scene.cameras[size_t(v)], side);
    RenderLayers pair[2];
    for (int s = 0; s < 2; ++s) {
      PathTracerOptions pt;
      pt.samples_per_pixel = o.samples;
      pt.seed = 0x9170 + uint64_t(s);
      pt.max_depth = o.max_depth;
      pt.threads = o.threads;
      const double done = double(2 * v + s) / double(2 * n);
      pair[s] = renderPathTraced(scene.medium, scene.sun, scene.sky, cam, pt, [&](double f) {
        return !o.progress || o.progress(done + f / double(2 * n));
      });
    }
    PairNoise view_noise;
    view_noise.add(pair[0], pair[1]);
    std::vector<double> mean_tiles;
    if (view_noise.values > 0) {
      const std::vector<double> a = tileLight(pair[0]), b = tileLight(pair[1]);
      for (size_t t = 0; t < a.size(); ++t) mean_tiles.push_back(0.5 * (a[t] + b[t]));
    }
    pm.view_tiles.push_back(std::move(mean_tiles));
    noise.merge(view_noise);
    if (view_noise.values > 0 && view_noise.sum_mean > 0) {
      noise_sum += view_noise.relativeNoise();
      multiple_rms_sum += view_noise.multipleRms();
      ++noise_views;
    }
    if (sun && view_noise.values > 0) {
      AureoleLight aureole;
      aureole.add(pair[0], pair[1], cam, normalize(scene.sun.direction));
      pm.aureole.push_back(aureole.relativeRms(view_noise));
    }
  }
  pm.seconds = secondsSince(t0);
  pm.pixels = noise.pixels;
  // The noise and the aureole per view, then averaged, as the error of a shot is: each view's
  // against its own cloud, not pooled with darker views beside it (a droplet's view against
  // the sun, bright and noisy, made the pooled noise of perlin_droplet's three views 15.6 at one
  // path, the mean of theirs 5.1, and the references measured 4.4).
  pm.noise_1spp = noise_views > 0 ? noise_sum / noise_views * std::sqrt(double(o.samples)) : 0.0;
  pm.multiple_fraction = noise.multipleFraction();
  pm.multiple_rms = noise_views > 0 ? multiple_rms_sum / noise_views : 0.0;
  pm.cloud_fraction = noise.pixels > 0 ? double(noise.cloud_pixels) / double(noise.pixels) : 0;
  // Cost per path: measured at the pilot's size; a pixel at full size costs the same (the
  // framing is the same, only finer).
  pm.seconds_per_sample =
      noise.pixels > 0 ? pm.seconds / (2.0 * double(o.samples) * double(noise.pixels)) : 0;
  return pm;
}

double tileDifference(const std::vector<double>& a, const std::vector<double>& b,
                      const std::vector<double>& reference) {
  if (a.size() != reference.size() || b.size() != reference.size()) return 0;
  double sq = 0, sum = 0;
  int64_t lit = 0;
  for (size_t t = 0; t < reference.size(); ++t) {
    if (!(reference[t] > 0)) continue;  // background: no cloud light to be wrong about
    sq += (a[t] - b[t]) * (a[t] - b[t]);
    sum += reference[t];
    ++lit;
  }
  if (lit == 0 || !(sum > 0)) return 0;
  return std::sqrt(sq / double(lit)) / (sum / double(lit));
}

std::map<int, double> measurePhotonTruncation(const ShotSpec& shot, const Scene& scene,
                                              const PilotOptions& o, const PilotMeasure& pilot,
                                              const std::vector<int>& orders,
                                              std::map<int, double>* seconds_per_photon) {
  std::map<int, double> truncation;
  const int n = int(scene.cameras.size());
  // No pilot, or no view with cloud light: nothing to check.
  if (pilot.view_tiles.size() != size_t(n) ||
      std::all_of(pilot.view_tiles.begin(), pilot.view_tiles.end(),
                  [](const std::vector<double>& t) { return t.empty(); })) {
    return truncation;
  }
  const int side = pilotSide(o, n);
  PhotonBakeOptions po;
  po.photons = kCheckPhotons;
  po.light_resolution = kCheckLattice;
  po.tally_resolution = kCheckTally;
  po.sky = needsSky(shot);
  po.sun = needsSun(shot);
  po.seed = shot.bake.seed;
  if (po.sky && shot.lighting.sky.type != Sky::Type::kConstant) po.sky_shape = &scene.sky;
  BakeRenderOptions ro;
  ro.samples_per_pixel = kCheckRays;
  ro.seed = shot.bake.seed;
  ro.threads = o.threads;
  auto cancelled = [&] { return o.progress && !o.progress(1.0); };
  // Each order's views' tiles (the same photons at every order: one seed).
  std::map<int, std::vector<std::vector<double>>> tiles;
  auto tilesAt = [&](int order) -> const std::vector<std::vector<double>>& {
    auto it = tiles.find(order);
    if (it != tiles.end()) return it->second;
    po.order = order;
    const BakedLight bake = bakePhoton(scene.medium, sunDirection(shot), po,
                                       [&](double, const std::string&) { return !cancelled(); });
    // Its seconds per photon and light, for the orders the rungs use (not the next orders
    // the check compares them with); a value that does not read as a positive time is left
    // out, and the pilot's paths price that order instead.
    const auto spent = bake.metadata.find("cloudbake:seconds_photons");
    const int lights = (po.sun ? 1 : 0) + (po.sky ? 1 : 0);
    const bool rung_order = std::find(orders.begin(), orders.end(), order) != orders.end();
    if (seconds_per_photon && rung_order && spent != bake.metadata.end() && lights > 0) {
      char* end = nullptr;
      const double s = std::strtod(spent->second.c_str(), &end) / double(po.photons * lights);
      if (end != spent->second.c_str() && std::isfinite(s) && s > 0) {
        (*seconds_per_photon)[order] = s;
      }
    }
    std::vector<std::vector<double>> views(static_cast<size_t>(n));
    for (int v = 0; v < n; ++v) {
      if (pilot.view_tiles[size_t(v)].empty()) continue;  // no cloud here: nothing to be wrong
      const Camera cam = pilotCamera(scene.cameras[size_t(v)], side);
      views[size_t(v)] = tileLight(renderFromBake(bake, scene.medium, scene.sun, scene.sky, cam, ro,
                                                  [&](double) { return !cancelled(); }));
    }
    return tiles.emplace(order, std::move(views)).first->second;
  };
  for (int order : orders) {
    if (order >= kMaxShDegree) continue;  // nothing above it to compare with
    const auto& lo = tilesAt(order);
    const auto& hi = tilesAt(order + 1);
    double sum = 0;
    int views = 0;
    for (int v = 0; v < n; ++v) {
      const std::vector<double>& reference = pilot.view_tiles[size_t(v)];
      if (reference.empty()) continue;
      sum += tileDifference(lo[size_t(v)], hi[size_t(v)], reference);
      ++views;
    }
    if (views > 0) truncation[order] = sum / views;
  }
  return truncation;
}

}  // namespace cloudbake
