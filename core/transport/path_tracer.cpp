#include "core/transport/path_tracer.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>

#include "core/error.h"
#include "core/format.h"
#include "core/math/rng.h"
#include "core/transport/camera.h"
#include "core/transport/shadow_splitting.h"
#include "core/transport/sky.h"
#include "core/transport/sun_guiding.h"
#include "core/transport/tiled_render.h"
#include "core/transport/tracking.h"
#include "core/transport/transmittance_predictor.h"

namespace cloudbake {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();
// Russian roulette starts after this many scattering events; earlier orders carry most of the
// image and are cheap, later ones are rouletted on the throughput (unbiased, Arvo & Kirk 1990).
constexpr int kRouletteDepth = 3;

void validateMedium(const Medium& m) {
  if (!m.density) throw InputError("medium.density: no density field given");
  validateMediumOptics(m);
  const double max_density = m.density->maxDensity();
  if (!std::isfinite(max_density) || max_density < 0) {
    throw InputError("medium.density: maximum density must be finite and >= 0, got " +
                     str(max_density));
  }
  if (!std::isfinite(m.extinction * max_density) ||
      !std::isfinite(m.extinction * static_cast<double>(m.density->majorants().maxValue()))) {
    throw InputError("medium.extinction: extinction * max density overflows");
  }
}

Vec3 validateSun(const Sun& sun) {
  if (!isFinite(sun.direction)) {
    throw InputError("sun.direction: must be finite, got " + str(sun.direction));
  }
  const double len = length(sun.direction);
  if (!(len > 0) || !std::isfinite(len)) {
    throw InputError("sun.direction: must be a non-zero vector, got " + str(sun.direction));
  }
  if (!isFinite(sun.irradiance) || sun.irradiance.x < 0 || sun.irradiance.y < 0 ||
      sun.irradiance.z < 0) {
    throw InputError("sun.irradiance: must be finite and >= 0 per channel, got " +
                     str(sun.irradiance));
  }
  return sun.direction / len;
}

void validateOptions(const PathTracerOptions& o) {
  if (o.samples_per_pixel < 1 || o.samples_per_pixel > (1 << 24)) {
    throw InputError("samples_per_pixel: must be in 1..16777216, got " + str(o.samples_per_pixel));
  }
  if (o.max_depth < 1) throw InputError("max_depth: must be >= 1, got " + str(o.max_depth));
  if (!(o.sun_guiding < 1) || std::isnan(o.sun_guiding)) {
    throw InputError("sun_guiding: must be < 1 (negative: chosen from the phase), got " +
                     str(o.sun_guiding));
  }
  if (o.sun_split_max == 0 || o.sun_split_max > 64) {
    throw InputError("sun_split_max: must be in 1..64 (negative: chosen from the phase), got " +
                     str(o.sun_split_max));
  }
  if (o.majorant_cell < 0 || o.majorant_cell > 64 ||
      (o.majorant_cell & (o.majorant_cell - 1)) != 0) {
    throw InputError("majorant_cell: must be 0 (chosen) or a power of two in 1..64, got " +
                     str(o.majorant_cell));
  }
  if (o.threads < 0 || o.threads > 4096) {
    throw InputError("threads: must be in 0..4096 (0 = all), got " + str(o.threads));
  }
  if (o.tile_size < 1 || o.tile_size > 4096) {
    throw InputError("tile_size: must be in 1..4096, got " + str(o.tile_size));
  }
}

inline double powerHeuristic(double pdf_a, double pdf_b) {
  const double a2 = pdf_a * pdf_a, b2 = pdf_b * pdf_b;
  return a2 > 0 ? a2 / (a2 + b2) : 0.0;
}

/// Per-sample estimates of the layers (radiance) and of 1 - transmittance.
struct PathSample {
  Rgb sun, sky, single, multiple, background;
  double alpha = 0;
};

/// The per-path estimator: delta tracking to real collisions; at each, next-event estimation
/// of the sun (delta light, shadowed by ratio tracking, split or rouletted by its predicted
/// size) and of the sky (one light sample, MIS with phase sampling by the power heuristic,
/// Veach 1997); with probability eps_t a second walk along the lobe about the sun
/// (core/transport/sun_guiding.h); then phase sampling for the next direction, whose MIS weight
/// against the lobe multiplies all that follows its collision. Throughput carries
/// sigma_s/sigma_t = albedo per channel and value/pdf per channel of a chromatic phase
/// function; the real/null decision uses the grey sigma_t, so no spectral MIS is needed.
class Integrator {
 public:
  Integrator(const Medium& medium, const Vec3& sun_dir, const Rgb& sun_e, const SkyLight& sky,
             const PathTracerOptions& options, double sun_guiding, int sun_split_max)
      : phase_(*medium.phase),
        density_(*medium.density),
        extinction_(medium.extinction),
        albedo_(medium.albedo),
        sun_dir_(sun_dir),
        sun_e_(sun_e),
        sun_on_(maxComponent(sun_e) > 0),
        sky_(sky),
        guide_(*medium.phase, sun_dir, sun_on_ ? sun_guiding : 0.0),
        max_depth_(options.max_depth),
        split_max_(sun_split_max),
        decomposition_(options.decomposition_tracking),
        grid_(trackingGridFor(medium, options)),
        predictor_(*predictorGrid(medium, options), extinction_, sun_on_ ? &sun_dir_ : nullptr,
                   !sky_.black()),
        sky_scale_(sky_.black() ? 1.0 : std::max(1e-300, maxComponent(sky_.meanRadiance()))) {
    // Where the predictor knows how much sun reaches a collision, splitting goes to the
    // collisions it reaches: measured to pay for HG too (bench/reference_bench.py, docs).
    if (split_max_ <= 0) split_max_ = predictor_.active() ? 8 : autoSunSplitMax(*medium.phase);
  }

  void trace(const Ray& ray, DensityField::Lookup& lookup, Rng& rng, PathSample* out) const {
    walk(Walk{ray}, lookup, rng, out);
  }

 private:
  // One walk: the camera path (generation 0) or a branch the lobe spawned (generation >= 1).
  struct Walk {
    Ray ray;
    Rgb beta{1.0};
    int depth = 0;         // scattering events before `ray`'s collision
    double phase_pdf = 0;  // pdf of the phase sample that produced `ray` (depth > 0)
    // The MIS weight of `ray`'s direction against the other technique, for all that follows a
    // real collision along it (1 where there is no other technique).
    double segment_mis = 1;
    int generation = 0;
    bool lobe_segment = false;  // `ray` came from the lobe: only its collisions are weighted
  };

  // Branches of branches stop here, so a walk's recursion stays shallow.
  static constexpr int kMaxGeneration = 16;

  static std::shared_ptr<const MajorantGrid> trackingGridFor(const Medium& medium,
                                                             const PathTracerOptions& o) {
    if (!o.decomposition_tracking && o.majorant_cell == 0) {
      return DensityField::nonOwning(medium.density->majorants());
    }
    return medium.density->trackingGrid({medium.extinction, o.majorant_cell});
  }

  // The predictor integrates minorants, so it wants the tightest: cells of 2 voxels (1 would
  // cost 8x the cell crossings for a few percent more of the density).
  static std::shared_ptr<const MajorantGrid> predictorGrid(const Medium& medium,
                                                           const PathTracerOptions& o) {
    if (!o.decomposition_tracking) return std::make_shared<const MajorantGrid>();
    return medium.density->trackingGrid({medium.extinction, 2});
  }

  // Both trackers run over the ray's part inside the density's support only (exactly zero
  // outside it, so nothing is lost): no null collisions in the empty corners of the cells.
  Collision track(const Ray& ray, DensityField::Lookup& lookup, Rng& rng) const {
    double t0 = 0, t1 = 0;
    if (!density_.supportInterval(ray, 0, kInfinity, &t0, &t1)) return Collision{};
    return decomposition_ ? decompositionTrack(*grid_, lookup, extinction_, ray, t0, t1, rng)
                          : deltaTrack(*grid_, lookup, extinction_, ray, t0, t1, rng);
  }

  double transmittance(const Ray& ray, DensityField::Lookup& lookup, Rng& rng) const {
    double t0 = 0, t1 = 0;
    if (!density_.supportInterval(ray, 0, kInfinity, &t0, &t1)) return 1.0;
    return decomposition_ ? residualRatioTrack(*grid_, lookup, extinction_, ray, t0, t1, rng)
                          : ratioTrack(*grid_, lookup, extinction_, ray, t0, t1, rng);
  }

  void walk(Walk w, DensityField::Lookup& lookup, Rng& rng, PathSample* out) const {
    for (;; ++w.depth) {
      const Collision c = track(w.ray, lookup, rng);
      if (!c.hit) {
        escape(w, out);
        return;
      }
      if (w.depth == 0) out->alpha = 1.0;
      if (w.depth >= max_depth_) return;
      w.beta *= albedo_ * w.segment_mis;
      if (!(maxComponent(w.beta) > 0)) return;  // pure absorber: nothing scatters
      const int order = w.depth + 1;
      // The path's travel direction (-wo): cos theta to a light is dot(travel, to-light).
      const Vec3 travel = w.ray.d;
      if (sun_on_) sunEvent(c.p, travel, w.beta, order, lookup, rng, out);
      if (!sky_.black()) skyEvent(c.p, travel, w.beta, order, lookup, rng, out);
      const double eps_t = w.generation < kMaxGeneration ? guide_.epsAt(travel) : 0.0;
      if (eps_t > 0 && order < max_depth_ && rng.uniform() < eps_t) {
        branch(w, c.p, eps_t, lookup, rng, out);
      }

      const double u1 = rng.uniform(), u2 = rng.uniform();
      const PhaseSample ps = phase_.sample(travel, u1, u2);
      if (!(ps.pdf > 0)) return;
      w.beta *= ps.value / ps.pdf;
      w.phase_pdf = ps.pdf;
      const SunGuide::PhaseSampleWeights pw =
          guide_.phaseSampleWeights(ps.pdf, ps.direction, eps_t);
      w.segment_mis = pw.mis;
      w.lobe_segment = false;
      w.ray = {c.p, ps.direction};
      if (order >= kRouletteDepth || w.generation > 0) {
        // Decided on the walk's expected next contribution, not its throughput alone: a walk
        // the MIS weight made faint but pointed along the sun's spike is worth continuing.
        const double q = std::min(1.0, maxComponent(w.beta) * w.segment_mis * pw.importance);
        if (q < 1.0) {
          if (!(rng.uniform() < q)) return;
          w.beta /= q;
        }
      }
    }
  }

  // The sky seen along a walk's ray that left the medium: behind the cloud for a camera ray,
  // else MIS-weighted against the sky's light sample. The lobe's directions only stand for
  // what follows a collision, so a lobe segment that escapes adds nothing.
  void escape(const Walk& w, PathSample* out) const {
    if (w.depth == 0) {
      out->background = sky_.radiance(w.ray.d);
    } else if (!sky_.black() && !w.lobe_segment) {
      const double mis = powerHeuristic(w.phase_pdf, sky_.pdf(w.ray.d));
      add(out, /*from_sun=*/false, w.depth, w.beta * sky_.radiance(w.ray.d) * mis);
    }
  }

  // The lobe technique at a collision at p of walk w (before its phase sample): a direction
  // about the sun, walked on as a path of its own with the lobe's MIS weight.
  void branch(const Walk& w, const Vec3& p, double eps_t, DensityField::Lookup& lookup, Rng& rng,
              PathSample* out) const {
    const double u1 = rng.uniform(), u2 = rng.uniform();
    const SunGuide::LobeSample s = guide_.sampleLobe(w.ray.d, eps_t, u1, u2);
    if (!(maxComponent(s.weight) > 0)) return;
    Walk b;
    b.ray = {p, s.direction};
    b.beta = w.beta * s.weight;
    b.depth = w.depth + 1;
    b.generation = w.generation + 1;
    b.lobe_segment = true;
    walk(b, lookup, rng, out);
  }

  void sunEvent(const Vec3& p, const Vec3& travel, const Rgb& beta, int order,
                DensityField::Lookup& lookup, Rng& rng, PathSample* out) const {
    const Rgb f = phase_.eval(dot(travel, sun_dir_));
    if (!(maxComponent(f) > 0)) return;
    const Rgb l = beta * f * sun_e_;
    const bool roulette = predictor_.active();
    const double predicted = 4 * kPi * maxComponent(beta * f) * predictor_.sun(p);
    const double u = split_max_ > 1 || roulette ? rng.uniform() : 0;
    const ShadowRays rays =
        sunShadowRays(predicted, split_max_, u, roulette, roulette ? kPredictedMinSurvival : 0.0);
    double tr = 0;
    for (int k = 0; k < rays.count; ++k) {
      tr += transmittance({p, sun_dir_}, lookup, rng);
    }
    if (tr > 0) add(out, true, order, l * (tr * rays.weight));
  }

  void skyEvent(const Vec3& p, const Vec3& travel, const Rgb& beta, int order,
                DensityField::Lookup& lookup, Rng& rng, PathSample* out) const {
    const double u1 = rng.uniform(), u2 = rng.uniform();
    const SkySample s = sky_.sample(u1, u2);
    if (!(s.pdf > 0 && maxComponent(s.radiance) > 0)) return;
    const double cos_theta = dot(travel, s.to_sky);
    const Rgb f = phase_.eval(cos_theta);
    if (!(maxComponent(f) > 0)) return;
    const double w = powerHeuristic(s.pdf, phase_.pdf(cos_theta));
    const Rgb l = beta * f * s.radiance * (w / s.pdf);
    double keep = 1;
    if (predictor_.active()) {  // roulette the events the sky cannot reach
      keep =
          shadowSurvival(maxComponent(l) / sky_scale_ * predictor_.sky(p), kPredictedMinSurvival);
      if (!(rng.uniform() < keep)) return;
    }
    const double tr = transmittance({p, s.to_sky}, lookup, rng);
    if (tr > 0) add(out, false, order, l * (tr / keep));
  }

  static void add(PathSample* out, bool from_sun, int order, const Rgb& l) {
    (from_sun ? out->sun : out->sky) += l;
    (order == 1 ? out->single : out->multiple) += l;
  }

  const PhaseFunction& phase_;
  const DensityField& density_;
  double extinction_;
  Rgb albedo_;
  Vec3 sun_dir_;
  Rgb sun_e_;
  bool sun_on_;
  const SkyLight& sky_;
  SunGuide guide_;
  int max_depth_;
  int split_max_;
  bool decomposition_;
  std::shared_ptr<const MajorantGrid> grid_;
  TransmittancePredictor predictor_;
  double sky_scale_;  // what an isotropic scatter of the sky at unit throughput brings
};

void store(Image& im, int x, int y, const Rgb& v, double scale) {
  float* p = im.at(x, y);
  p[0] = static_cast<float>(v.x * scale);
  p[1] = static_cast<float>(v.y * scale);
  p[2] = static_cast<float>(v.z * scale);
}

}  // namespace

RenderLayers renderPathTraced(const Medium& medium, const Sun& sun, const Sky& sky,
                              const Camera& camera, const PathTracerOptions& options,
                              const ProgressFn& progress) {
  validateMedium(medium);
  const Vec3 sun_dir = validateSun(sun);
  validateOptions(options);
  const CameraRays rays(camera);
  const SkyLight sky_light(sky);
  const double guiding =
      options.sun_guiding >= 0 ? options.sun_guiding : autoSunGuiding(*medium.phase);
  const int split_max = options.sun_split_max;  // negative: the integrator chooses
  const Integrator integrator(medium, sun_dir, sun.irradiance, sky_light, options, guiding,
                              split_max);

  const int w = camera.width_px, h = camera.height_px;
  const int spp = options.samples_per_pixel;
  const double inv_spp = 1.0 / spp;
  RenderLayers out = makeRenderLayers(w, h);

  auto render_tile = [&](const TileRect& t, const TilePoll& poll) {
    const int tw = t.x1 - t.x0;
    std::vector<PathSample> acc(size_t(tw) * (t.y1 - t.y0));
    const auto lookup = medium.density->lookup();
    Rng rng;
    for (int s = 0; s < spp; ++s) {
      // One stream per (tile, sample): the image does not depend on which thread runs a tile.
      rng.setSeed(mixBits(options.seed, mixBits(uint64_t(t.index), uint64_t(s))),
                  mixBits(uint64_t(t.index), options.seed));
      for (int y = t.y0; y < t.y1; ++y) {
        for (int x = t.x0; x < t.x1; ++x) {
          // A dense, white medium's paths take long: a cancel must not wait for the tile.
          if (poll.stop()) return;
          const double fx = x + rng.uniform(), fy = y + rng.uniform();
          PathSample ps;
          integrator.trace(rays.generate(fx, fy), *lookup, rng, &ps);
          PathSample& a = acc[size_t(y - t.y0) * tw + (x - t.x0)];
          a.sun += ps.sun;
          a.sky += ps.sky;
          a.single += ps.single;
          a.multiple += ps.multiple;
          a.background += ps.background;
          a.alpha += ps.alpha;
        }
      }
    }
    for (int y = t.y0; y < t.y1; ++y) {
      for (int x = t.x0; x < t.x1; ++x) {
        const PathSample& a = acc[size_t(y - t.y0) * tw + (x - t.x0)];
        store(out.beauty, x, y, a.sun + a.sky + a.background, inv_spp);
        out.beauty.at(x, y)[3] = static_cast<float>(a.alpha * inv_spp);
        store(out.background, x, y, a.background, inv_spp);
        store(out.sun, x, y, a.sun, inv_spp);
        store(out.sky, x, y, a.sky, inv_spp);
        store(out.single, x, y, a.single, inv_spp);
        store(out.multiple, x, y, a.multiple, inv_spp);
      }
    }
  };
  const bool finished =
      renderTiles(w, h, options.tile_size, options.threads, progress, render_tile);
  if (!finished) throw Cancelled("path tracing of view '" + camera.name + "' cancelled");
  return out;
}

}  // namespace cloudbake
