#include "core/bake/scattering_passes.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <functional>
#include <optional>
#include <string>

#include "core/bake/neighbour_grid.h"
#include "core/bake/phase_lut.h"
#include "core/bake/sky_visibility.h"
#include "core/error.h"
#include "core/format.h"
#include "core/math/parallel.h"
#include "core/phase/similarity.h"

namespace cloudbake {
namespace {

// The grain of the passes' per-point loops between their gathers (a few nanoseconds a point):
// run on one thread, those loops held the passes' scaling from 1 to 2 threads to 1.3-1.65x.
constexpr int64_t kPointGrain = 2048;

using Clock = std::chrono::steady_clock;

constexpr double kMaxPaperCi = 1e30;  // the paper rule grows without bound; keep floats finite
constexpr int64_t kDestinationGrain = 128;  // destinations per chunk

// The similarity (transport) reduction of the normalised rule: s = 1 - lum(a g) scales the
// extinction, `albedo` = a (1 - g) / (1 - a g) per channel, each channel's own reduced albedo
// (a (1 - g) / s made a white channel of a coloured albedo absorb: 0.57 for a = [1, 0, 0.5] at
// g = 0.5, its light 0.23 of the path tracer's; the passes share one extinction, so a channel
// whose a g is far from lum(a g) keeps its energy but not quite its spread); `isotropic` is
// false only for g = 0, where the reduction is the identity and the beam model of R and L is
// used as it is. Backscattering
// phases (g < 0) are reduced too (s > 1): their beam model concentrates each source's light on
// the few neighbours behind it without normalising the phase over them, and its passes grew
// without bound (Co 3e10 at g = -0.8, 5e28 at -0.9), while the reduced medium conserves energy
// like any other (the similarity relations hold for either sign of g: the diffusion
// coefficient depends on sigma_s (1 - g) alone).
struct TransportScaling {
  double s = 1;
  Rgb albedo{1, 1, 1};
  bool isotropic = false;
  // Each channel's own s_c = 1 - a_c g_c, for the sun's forward beam Ci^(s_c) - Ci: the light
  // each channel scatters into its forward peak. With the shared s, a channel of low albedo got
  // the beam of the luminance's: an albedo of (0.9, 0.5, 0.2) at g = 0.6 put 3.5x the path
  // tracer's multiply scattered light in blue (an outside probe).
  Rgb s_channel{1, 1, 1};
};

TransportScaling transportScaling(const Medium& medium) {
  TransportScaling ts;
  const Rgb g = medium.phase->meanCosine();
  const Rgb a = medium.albedo;
  if (luminance(g) == 0) {
    ts.albedo = a;
    return ts;
  }
  ts.s = 1 - luminance(a * g);
  ts.isotropic = true;
  for (int c = 0; c < 3; ++c) {
    ts.albedo[c] = reducedAlbedo(a[c], g[c]);
    ts.s_channel[c] = 1 - a[c] * g[c];
  }
  return ts;
}

// What the passes of either rule read; runPointcloud sets it up once.
struct PassInputs {
  const NeighbourPairs& pairs;
  const Medium& medium;
  Vec3 sun_dir;  // unit, towards the sun
  const PointcloudOptions& options;
  bool geometric_tail;
  // Polled with (fraction of the pass, pass) between chunks of destinations; may be empty.
  // The sky's passes of the beam model (normalised rule, g = 0), which run after the sun's,
  // poll sky_cancelled instead, so progress goes on past the sun's passes rather than starting
  // them again; the reduced medium's passes gather the sun and the sky together.
  std::function<bool(double, int)> cancelled = {};
  std::function<bool(double, int)> sky_cancelled = {};
  // The normalised rule only: the lattice, the reduced medium's sky visibility (the escape
  // probability of header step 6), the reduction itself and, for sky light, the true medium's
  // sky visibility (null: no sky passes).
  const BakeGrid* grid = nullptr;
  const FirstTouchFloats* escape_visibility = nullptr;
  TransportScaling ts = {};
  const FirstTouchFloats* true_visibility = nullptr;
};

// What a source contributes, packed for the gather loop (one cache line per source).
struct NormalisedSource {
  float px, py, pz;  // P
  float lx, ly, lz;  // L (zero when R = 0)
  float ar, ag, ab;  // R * Delta
  float br, bg, bb;  // (1 - R) * Delta / (4 pi)
};

struct PaperSource {
  float px, py, pz;
  float lx, ly, lz;
  float r;           // R
  float cr, cg, cb;  // Ci
};

// A point's position relative to the cloud's first point: the gather loops keep positions in
// single precision and use only their differences, and a cloud far from the origin kept none
// of them in world coordinates (floats 1e6 world units out are 0.06 apart).
Vec3 localPosition(const PointCloud& pc, size_t i) { return pc.position[i] - pc.position.front(); }

// The sum q / (1 - q) of the orders after the last one computed, per channel, with q the last
// order's sum over the one before (0 where q is not in (0, 1)). Each channel's orders fall by
// its own ratio: with one ratio from their luminance, the red of albedo (0.99, 0.7, 0.4) after
// 3 passes was 8 % short of all its orders on an outside probe's cloud, the blue given the
// red's long tail.
Rgb geometricTail(const Rgb& last, const Rgb& before) {
  Rgb g(0.0);
  for (int c = 0; c < 3; ++c) {
    const double q = before[c] > 0 ? last[c] / before[c] : 0.0;
    if (q > 0 && q < 1) g[c] = q / (1 - q);
  }
  return g;
}

// Runs `body(dst)` for every destination of a pass, in parallel, polling the cancellation.
template <class Body>
void forEachDestination(const PassInputs& in, size_t n, int pass, const Body& body) {
  ParallelOptions chunks;
  chunks.grain = kDestinationGrain;
  if (in.cancelled) chunks.cancelled = [&](double f) { return in.cancelled(f, pass); };
  parallelFor(
      0, int64_t(n), [&](int64_t j) { body(size_t(j)); }, chunks);
}

// The gather loop of both rules, for destination j at `q`: per source, in the sources' float
// precision, the unit vector from the source to j and the phase value between the source's L
// and it, handed to add(source, weight, phase, dx, dy, dz). With `lut` null no source has a
// beam (R = 0: the reduced medium's passes after the first) and the phase is handed as 0, which
// the beam's zero weight makes the same sum without the lookup (a third of a pair's cost).
template <class Source, class Add>
void gatherTransfers(const NeighbourPairs& pairs, const std::vector<Source>& src,
                     const PhaseLut* lut, size_t j, const Vec3& q, Add&& add) {
  const float qx = float(q.x), qy = float(q.y), qz = float(q.z);
  const uint64_t e = pairs.offset[j + 1];
  for (uint64_t k = pairs.offset[j]; k < e; ++k) {
    const Source& s = src[pairs.source[k]];
    float dx = qx - s.px, dy = qy - s.py, dz = qz - s.pz;
    const float inv = 1.f / std::sqrt(dx * dx + dy * dy + dz * dz);
    dx *= inv;
    dy *= inv;
    dz *= inv;
    const Rgb ph = lut ? lut->eval(double(s.lx * dx + s.ly * dy + s.lz * dz)) : Rgb(0.0);
    add(s, double(pairs.weight[k]), ph, dx, dy, dz);
  }
}

// A point's discretised collision fraction below which k_i is left at 1 (scaledOwnSpheres).
constexpr double kMinCaptured = 1e-30;

// The normalised rule's own-sphere factor 1 - exp(-sigma_t r) per point, scaled by k_i, the
// ratio of the medium's collision fraction 1 - P_escape to the discretised one c_i = self_i +
// sum_j w_ij / (4 pi) (header, step 6); k_i and 1 - P_escape go to `out`.
std::vector<double> scaledOwnSpheres(const PassInputs& in, PointCloudResult& out) {
  const PointCloud& pc = out.cloud;
  const size_t n = pc.size();
  const double ext = in.medium.extinction * in.ts.s;
  std::vector<double> self(n), captured(n);
  parallelFor(0, int64_t(n),
              [&](int64_t j) {
                const double r = std::cbrt(3 * pc.mass / (4 * kPi * pc.density[size_t(j)]));
                self[size_t(j)] = -std::expm1(-ext * pc.density[size_t(j)] * r);
                captured[size_t(j)] = self[size_t(j)];
              },
              {kPointGrain});
  for (uint64_t q = 0; q < in.pairs.size(); ++q) {
    captured[in.pairs.source[q]] += in.pairs.weight[q] * kInv4Pi;
  }
  out.collision.resize(n);
  out.transfer_scale.resize(n);
  parallelFor(0, int64_t(n),
              [&](int64_t ii) {
                const size_t i = size_t(ii);
                const double vis =
                    sampleTrilinear(*in.grid, in.escape_visibility->data(), pc.position[i]);
                const double target = std::clamp(1 - vis, 0.0, 1.0);
                out.collision[i] = float(target);
                // Below kMinCaptured a point scatters nothing a view can show, and the ratio of two
                // such numbers (the target read from a float grid) is noise: at extinction 1e-320
                // it overflowed to inf, and inf times a zero sphere gave NaN.
                const double k = captured[i] >= kMinCaptured ? target / captured[i] : 1.0;
                out.transfer_scale[i] = float(k);
                self[i] *= k;
              },
              {kPointGrain});
  return self;
}

// The sun's orders of the normalised rule, per point (header, steps 3-5 and 7).
struct SunOrders {
  SunOrders(size_t n, const Vec3& sun_dir)
      : delta(n),
        next(n),
        dir(n, -sun_dir),
        next_dir(n),
        ratio(n, 1.0),
        next_ratio(n),
        flux(n),
        total_flux(n, Vec3(0.0)),
        incoming(n),
        total_incoming(n, 0.0),
        co(n, Rgb(0.0)),
        ci_reduced(n) {}
  std::vector<Rgb> delta, next;                  // Delta^k, Delta^{k+1}
  std::vector<Vec3> dir, next_dir;               // L
  std::vector<double> ratio, next_ratio;         // R
  std::vector<Vec3> flux, total_flux;            // F of the last pass, and of all
  std::vector<double> incoming, total_incoming;  // lum of the gathered light, likewise
  std::vector<Rgb> co;                           // the orders so far
  std::vector<Rgb> ci_reduced;                   // Ci^(s_c): each channel's reduced beam
  // The reduced (isotropic) passes defer the flux: it is linear in what each source emits, so
  // sum_k F^k_j = sum_i w_ij lum(b^k_i summed over k) w_ij, gathered once after the passes.
  // emitted: each source's lum(b) summed over the passes so far; last_emitted: the last pass's.
  std::vector<double> emitted, last_emitted;
};

// Sky light (header, step 8): the same transfers for a uniform sky of unit radiance, as state
// that each pass advances, so that the reduced medium's passes can gather the sun's orders and
// the sky's in one read of the pairs (gatherReducedPass).
struct SkyOrders {
  SkyOrders(const PassInputs& in, const PointCloud& pc)
      : d(pc.size()), next(pc.size()), acc(pc.size(), Rgb(0.0)), beam(pc.size()) {
    parallelFor(
        0, int64_t(pc.size()),
        [&](int64_t jj) {
          const size_t j = size_t(jj);
          const double vr = sampleTrilinear(*in.grid, in.escape_visibility->data(), pc.position[j]);
          const double vt = sampleTrilinear(*in.grid, in.true_visibility->data(), pc.position[j]);
          d[j] = Rgb(4 * kPi * vr);
          beam[j] = 4 * kPi * (vr - vt);  // signed, as the sun's beam (finishSunOrders)
        },
        {kPointGrain});
  }

  // What source i emits in this pass.
  std::array<float, 3> emission(const PointCloudResult& out, size_t i) const {
    const Rgb e = d[i] * (out.transfer_scale[i] * kInv4Pi);
    return {float(e.x), float(e.y), float(e.z)};
  }

  // Adds the order just gathered into `next`; true when the passes stop (converged or the
  // last), after adding the geometric tail of the orders not computed.
  bool add(const PassInputs& in, int pass, PointCloudResult& out) {
    parallelFor(0, int64_t(acc.size()), [&](int64_t j) { acc[size_t(j)] += next[size_t(j)]; },
                {kPointGrain});
    // The sums in point order, so the stopping test is the same at any thread count.
    double sum = 0, acc_sum = 0;
    Rgb order(0.0);
    for (size_t j = 0; j < acc.size(); ++j) {
      order += next[j];
      sum += luminance(next[j]);
      acc_sum += luminance(acc[j]);
    }
    d.swap(next);
    out.pair_interactions += in.pairs.size();
    const bool done = !(acc_sum > 0) || sum / acc_sum < in.options.tolerance;
    if (!done && pass + 1 != in.options.passes) {
      prev = order;
      return false;
    }
    if (in.geometric_tail) {
      const Rgb g = geometricTail(order, prev);
      parallelFor(0, int64_t(acc.size()), [&](int64_t j) { acc[size_t(j)] += d[size_t(j)] * g; },
                  {kPointGrain});
    }
    return true;
  }

  void finish(PointCloudResult& out) const {
    out.co_sky.resize(acc.size());
    parallelFor(0, int64_t(acc.size()),
                [&](int64_t j) {
                  out.co_sky[size_t(j)] = max(acc[size_t(j)] + Rgb(beam[size_t(j)]), Rgb(0.0));
                },
                {kPointGrain});
  }

  std::vector<Rgb> d, next, acc;  // this order, the next, all so far
  std::vector<double> beam;
  Rgb prev{0.0};  // the order before d, summed over the points per channel
};

// What each source emits in one pass, for the gather loop: the sun's order and the sky's, three
// floats each (Delta_i k_i / (4 pi), with R = 0 in the reduced medium).
struct PassEmission {
  std::array<float, 3> sun, sky;
};

// One pass over the pairs: Delta^{k+1} of the sun's orders where kSun (in the reduced medium's
// passes, where R = 0 everywhere: every source emits isotropically and its flux is only summed,
// deferredSunFlux) and the sky's next order where kSky. Each pair costs a weighted sum of three
// floats for each: no direction, no phase; and the two share one read of the pair arrays, which
// bounds these passes more than their arithmetic.
template <bool kSun, bool kSky>
void gatherReducedPass(const PassInputs& in, const std::vector<double>& self,
                       const std::vector<PassEmission>& emit, int pass, SunOrders& o,
                       SkyOrders* sky) {
  const NeighbourPairs& pairs = in.pairs;
  forEachDestination(in, emit.size(), pass, [&](size_t j) {
    double sr = 0, sg = 0, sb = 0, kr = 0, kg = 0, kb = 0;
    const uint64_t e = pairs.offset[j + 1];
    for (uint64_t k = pairs.offset[j]; k < e; ++k) {
      const PassEmission& s = emit[pairs.source[k]];
      const double w = pairs.weight[k];
      if constexpr (kSun) {
        sr += w * s.sun[0];
        sg += w * s.sun[1];
        sb += w * s.sun[2];
      }
      if constexpr (kSky) {
        kr += w * s.sky[0];
        kg += w * s.sky[1];
        kb += w * s.sky[2];
      }
    }
    if constexpr (kSun) {
      const Rgb in_light = Rgb(sr, sg, sb) + o.delta[j] * self[j];
      // R stays 0 (addSunOrder sets it), so L is never read: next_dir and next_ratio are left.
      o.next[j] = in.ts.albedo * in_light;
      o.incoming[j] = luminance(in_light);
    }
    if constexpr (kSky) sky->next[j] = in.ts.albedo * (Rgb(kr, kg, kb) + sky->d[j] * self[j]);
  });
}

// The flux of every reduced pass at once, with the tail's share of the last pass (weight
// `tail`): sum over pairs of w_ij (emitted_i + tail last_emitted_i) times the unit vector from i
// to j, added to total_flux.
void deferredSunFlux(const PassInputs& in, const PointCloudResult& out, int last_pass, double tail,
                     SunOrders& o) {
  // gatherTransfers' sources; L is read only with a phase table, which this gather has none of.
  struct FluxSource {
    float px, py, pz, lx, ly, lz, e;
  };
  const PointCloud& pc = out.cloud;
  const size_t n = pc.size();
  std::vector<FluxSource> src(n);
  for (size_t i = 0; i < n; ++i) {
    const Vec3 p = localPosition(pc, i);
    src[i] = {float(p.x),
              float(p.y),
              float(p.z),
              0.f,
              0.f,
              0.f,
              float(o.emitted[i] + tail * o.last_emitted[i])};
  }
  ParallelOptions chunks;  // polled as the end of the last pass: progress never goes back
  chunks.grain = kDestinationGrain;
  if (in.cancelled) chunks.cancelled = [&](double) { return in.cancelled(1.0, last_pass); };
  parallelFor(
      0, int64_t(n),
      [&](int64_t jj) {
        const size_t j = size_t(jj);
        double fx = 0, fy = 0, fz = 0;
        gatherTransfers(
            in.pairs, src, nullptr, j, localPosition(pc, j),
            [&](const FluxSource& s, double w, const Rgb&, float dx, float dy, float dz) {
              const double l = w * s.e;
              fx += l * dx;
              fy += l * dy;
              fz += l * dz;
            });
        o.total_flux[j] += Vec3(fx, fy, fz);
      },
      chunks);
}

// One pass of the sun's orders: Delta^{k+1}, and its flux for the next R and L.
void gatherSunOrder(const PassInputs& in, const PhaseLut& lut, const std::vector<double>& self,
                    const PointCloudResult& out, int pass, SunOrders& o,
                    std::vector<NormalisedSource>& src) {
  const PointCloud& pc = out.cloud;
  const size_t n = pc.size();
  bool beam = false;
  for (size_t i = 0; i < n; ++i) {
    const Vec3 p = localPosition(pc, i);
    const double r = o.ratio[i];
    const Vec3 l = r > 0 ? o.dir[i] : Vec3(0.0);
    const double k = out.transfer_scale[i];
    const Rgb a = o.delta[i] * (r * k), b = o.delta[i] * ((1 - r) * kInv4Pi * k);
    src[i] = {float(p.x), float(p.y), float(p.z), float(l.x), float(l.y), float(l.z),
              float(a.x), float(a.y), float(a.z), float(b.x), float(b.y), float(b.z)};
    const NormalisedSource& si = src[i];
    beam = beam || !(si.ar == 0 && si.ag == 0 && si.ab == 0);
  }
  forEachDestination(in, n, pass, [&](size_t j) {
    double sr = 0, sg = 0, sb = 0, fx = 0, fy = 0, fz = 0;
    gatherTransfers(
        in.pairs, src, beam ? &lut : nullptr, j, localPosition(pc, j),
        [&](const NormalisedSource& s, double w, const Rgb& ph, float dx, float dy, float dz) {
          const double jr = w * (s.ar * ph.x + s.br), jg = w * (s.ag * ph.y + s.bg),
                       jb = w * (s.ab * ph.z + s.bb);
          sr += jr;
          sg += jg;
          sb += jb;
          const double l = luminance(Rgb(jr, jg, jb));
          fx += l * dx;
          fy += l * dy;
          fz += l * dz;
        });
    const Rgb in_light = Rgb(sr, sg, sb) + o.delta[j] * self[j];
    o.next[j] = in.ts.albedo * in_light;
    const Vec3 f(fx, fy, fz);
    const double fl = length(f), il = luminance(in_light);
    o.flux[j] = f;
    o.incoming[j] = il;
    if (fl > 0 && il > 0) {
      o.next_dir[j] = f / fl;
      o.next_ratio[j] = std::min(1.0, fl / il);
    } else {
      o.next_dir[j] = Vec3(0.0);
      o.next_ratio[j] = 0;
    }
  });
}

// Adds the order just gathered; true when the passes stop (converged or the last), after
// adding the geometric tail of the orders not computed (header, step 5).
bool addSunOrder(const PassInputs& in, int pass, double prev_sum, SunOrders& o,
                 PointCloudResult& out, double* sum_out) {
  const size_t n = o.co.size();
  parallelFor(0, int64_t(n),
              [&](int64_t jj) {
                const size_t j = size_t(jj);
                o.co[j] += o.next[j];
                o.total_flux[j] += o.flux[j];
                o.total_incoming[j] += o.incoming[j];
              },
              {kPointGrain});
  // The sums in point order, so the stopping test is the same at any thread count.
  double sum = 0, co_sum = 0;
  Rgb order(0.0), before(0.0);  // this order and the one it came from, per channel
  for (size_t j = 0; j < n; ++j) {
    order += o.next[j];
    before += o.delta[j];
    sum += luminance(o.next[j]);
    co_sum += luminance(o.co[j]);
  }
  o.delta.swap(o.next);
  o.dir.swap(o.next_dir);
  o.ratio.swap(o.next_ratio);
  if (in.ts.isotropic) std::fill(o.ratio.begin(), o.ratio.end(), 0.0);
  out.order_luminance.push_back(sum);
  out.pair_interactions += in.pairs.size();
  out.passes_run = pass + 1;
  out.last_relative_change = co_sum > 0 ? sum / co_sum : 0.0;
  *sum_out = sum;
  const bool done = out.last_relative_change < in.options.tolerance;
  if (!done && pass + 1 != in.options.passes) return false;
  const double q = prev_sum > 0 ? sum / prev_sum : 0.0;
  if (in.geometric_tail && q > 0 && q < 1) {
    out.tail_ratio = q;
    // The flux and the incoming light are luminances: their tail is the luminance's; the light
    // itself takes each channel's own.
    const double g = q / (1 - q);
    const Rgb gc = geometricTail(order, before);
    parallelFor(0, int64_t(n),
                [&](int64_t jj) {
                  const size_t j = size_t(jj);
                  o.co[j] += o.delta[j] * gc;
                  o.total_flux[j] += o.flux[j] * g;
                  o.total_incoming[j] += o.incoming[j] * g;
                },
                {kPointGrain});
  }
  return true;
}

// Co, light_dir and mie_ratio of point j from the sun's orders plus the forward-scattered beam
// Ci' - Ci, which travels along the sun's direction. For backscattering phases (s > 1) the beam
// is negative: the reduced medium counts as scattered light that is still unscattered in truth,
// so it is taken back; Co stays >= 0 (it can only reach 0 where albedo leaves no orders).
void finishSunOrder(const PassInputs& in, const PointCloud& pc, size_t j, SunOrders& o,
                    PointCloudResult& out) {
  const Rgb beam = o.ci_reduced[j] - Rgb(double(pc.sun[j]));
  o.co[j] = max(o.co[j] + beam, Rgb(0.0));
  o.total_flux[j] += -in.sun_dir * luminance(beam);
  o.total_incoming[j] = std::max(0.0, o.total_incoming[j] + luminance(beam));
  out.co[j] = o.co[j];
  const double fl = length(o.total_flux[j]);
  if (fl > 0 && o.total_incoming[j] > 0) {
    out.light_dir[j] = o.total_flux[j] / fl;
    out.mie_ratio[j] = float(std::min(1.0, fl / o.total_incoming[j]));
  } else {
    out.light_dir[j] = Vec3(0.0);
    out.mie_ratio[j] = 0.f;
  }
}

void finishSunOrders(const PassInputs& in, SunOrders& o, PointCloudResult& out) {
  const PointCloud& pc = out.cloud;
  const size_t n = pc.size();
  out.co.resize(n);
  out.light_dir.resize(n);
  out.mie_ratio.resize(n);
  parallelFor(0, int64_t(n), [&](int64_t j) { finishSunOrder(in, pc, size_t(j), o, out); },
              {kPointGrain});
}

// The reduced medium's passes (every phase with g != 0): the sun's orders and, with a sky, the
// sky's, gathered together while both run; then the sun's flux of all of them at once.
void runReducedPasses(const PassInputs& in, const std::vector<double>& self, SunOrders& o,
                      PointCloudResult& out) {
  const size_t n = o.co.size();
  std::optional<SkyOrders> sky;
  if (in.true_visibility) sky.emplace(in, out.cloud);
  std::vector<PassEmission> emit(n);
  o.emitted.assign(n, 0.0);
  o.last_emitted.assign(n, 0.0);
  bool sun_on = true, sky_on = sky.has_value();
  double prev_sum = out.order_luminance.front();
  int last = 0;
  for (int pass = 0; pass < in.options.passes && (sun_on || sky_on); ++pass) {
    last = pass;
    parallelFor(0, int64_t(n),
                [&](int64_t ii) {
                  const size_t i = size_t(ii);
                  if (sun_on) {
                    const Rgb b = o.delta[i] * (kInv4Pi * double(out.transfer_scale[i]));
                    emit[i].sun = {float(b.x), float(b.y), float(b.z)};
                    const double lum =
                        luminance(Rgb(emit[i].sun[0], emit[i].sun[1], emit[i].sun[2]));
                    o.emitted[i] += lum;
                    o.last_emitted[i] = lum;
                  }
                  if (sky_on) emit[i].sky = sky->emission(out, i);
                },
                {kPointGrain});
    if (sun_on && sky_on) {
      gatherReducedPass<true, true>(in, self, emit, pass, o, &*sky);
    } else if (sun_on) {
      gatherReducedPass<true, false>(in, self, emit, pass, o, nullptr);
    } else {
      gatherReducedPass<false, true>(in, self, emit, pass, o, &*sky);
    }
    if (sun_on) {
      double sum = 0;
      sun_on = !addSunOrder(in, pass, prev_sum, o, out, &sum);
      prev_sum = sum;
    }
    if (sky_on) sky_on = !sky->add(in, pass, out);
  }
  const double q = out.tail_ratio;
  deferredSunFlux(in, out, last, q > 0 ? q / (1 - q) : 0.0, o);
  finishSunOrders(in, o, out);
  if (sky) sky->finish(out);
}

// The beam model's passes (g = 0, where the reduction is the identity): the sun's orders with
// their R and L, then the sky's orders.
void runBeamPasses(const PassInputs& in, const PhaseLut& lut, const std::vector<double>& self,
                   SunOrders& o, PointCloudResult& out) {
  const size_t n = o.co.size();
  std::vector<NormalisedSource> src(n);
  double prev_sum = out.order_luminance.front();
  for (int pass = 0; pass < in.options.passes; ++pass) {
    gatherSunOrder(in, lut, self, out, pass, o, src);
    double sum = 0;
    if (addSunOrder(in, pass, prev_sum, o, out, &sum)) break;
    prev_sum = sum;
  }
  finishSunOrders(in, o, out);
  if (!in.true_visibility) return;
  PassInputs sky_in = in;
  sky_in.cancelled = in.sky_cancelled;
  SkyOrders sky(in, out.cloud);
  std::vector<PassEmission> emit(n);
  for (int pass = 0; pass < in.options.passes; ++pass) {
    for (size_t i = 0; i < n; ++i) emit[i].sky = sky.emission(out, i);
    gatherReducedPass<false, true>(sky_in, self, emit, pass, o, &sky);
    if (sky.add(in, pass, out)) break;
  }
  sky.finish(out);
}

// The normalised rule (derivation in the header). The passes run on the similarity-reduced
// medium (header, step 7): isotropic scattering with extinction s * sigma_t and albedo
// a (1 - g) / s.
void runNormalised(const PassInputs& in, PointCloudResult& out) {
  const PointCloud& pc = out.cloud;
  const size_t n = pc.size();
  const std::vector<double> self = scaledOwnSpheres(in, out);
  SunOrders o(n, in.sun_dir);
  // Order 0 of the reduced problem: the sun's beam attenuated by the reduced extinction, which
  // counts light scattered into the forward peak as not scattered: Ci^s in the passes' shared
  // medium. The beam added back at the end is each channel's own, Ci^(s_c) - Ci: with the
  // probe's albedo (0.9, 0.5, 0.2), the multiple layer over the path tracer's measured 1.10 /
  // 1.33 / 1.55, against 1.04 / 1.31 / 1.53 for grey media of each channel's albedo (0.94 /
  // 1.44 / 3.49 with the shared beam; 1.30 / 1.32 / 1.45 with each channel's Ci^(s_c) as the
  // passes' order 0 too, whose shared extinction then over-scatters the bright channel).
  parallelFor(0, int64_t(n),
              [&](int64_t j) {
                const double ci = pc.sun[size_t(j)];
                const Rgb& sc = in.ts.s_channel;
                o.ci_reduced[size_t(j)] =
                    Rgb(std::pow(ci, sc.x), std::pow(ci, sc.y), std::pow(ci, sc.z));
                o.delta[size_t(j)] = Rgb(std::pow(ci, in.ts.s));
              },
              {kPointGrain});
  double order_sum = 0;  // in point order, as every sum of the passes
  for (size_t j = 0; j < n; ++j) order_sum += luminance(o.delta[j]);
  std::fill(o.ratio.begin(), o.ratio.end(), in.ts.isotropic ? 0.0 : 1.0);
  out.order_luminance.assign(1, order_sum);
  if (in.ts.isotropic) {
    runReducedPasses(in, self, o, out);
  } else {
    runBeamPasses(in, PhaseLut(*in.medium.phase), self, o, out);
  }
}

// Seed 000's Eq. 1-5 (readings in the header).
void runPaper(const PassInputs& in, PointCloudResult& out) {
  const PointCloud& pc = out.cloud;
  const size_t n = pc.size();
  const PhaseLut lut(*in.medium.phase);
  const Rgb albedo = in.medium.albedo;
  std::vector<Rgb> ci(n), co(n);
  std::vector<Vec3> dir(n, -in.sun_dir), lsum(n);
  std::vector<double> ratio(n, 1.0);
  std::vector<PaperSource> src(n);
  double ci_sum = 0;
  for (size_t j = 0; j < n; ++j) {
    ci[j] = Rgb(double(pc.sun[j]));
    ci_sum += luminance(ci[j]);
  }
  out.order_luminance.assign(1, ci_sum);
  for (int pass = 0; pass < in.options.passes; ++pass) {
    for (size_t i = 0; i < n; ++i) {
      const Vec3 p = localPosition(pc, i), l = dir[i];
      src[i] = {float(p.x), float(p.y),      float(p.z),     float(l.x),     float(l.y),
                float(l.z), float(ratio[i]), float(ci[i].x), float(ci[i].y), float(ci[i].z)};
    }
    forEachDestination(in, n, pass, [&](size_t j) {
      double cr = 0, cg = 0, cb = 0, lx = 0, ly = 0, lz = 0;
      gatherTransfers(
          in.pairs, src, &lut, j, localPosition(pc, j),
          [&](const PaperSource& s, double ad, const Rgb& ph, float dx, float dy, float dz) {
            const Rgb am = ph * (4 * kPi);
            const double r = s.r;
            cr += ad * (am.x * r + (1 - r)) * s.cr;
            cg += ad * (am.y * r + (1 - r)) * s.cg;
            cb += ad * (am.z * r + (1 - r)) * s.cb;
            const double l = ad * (luminance(am) * r + (1 - r));
            lx += l * dx;
            ly += l * dy;
            lz += l * dz;
          });
      co[j] = albedo * Rgb(cr, cg, cb);
      lsum[j] = Vec3(lx, ly, lz);
    });
    double co_sum = 0;
    ci_sum = 0;
    for (size_t j = 0; j < n; ++j) {
      const double len = length(lsum[j]);
      ratio[j] -= ratio[j] * std::exp(-len);  // Eq. 1
      if (len > 0) dir[j] = lsum[j] / len;
      ci[j] = min(ci[j] + co[j], Rgb(kMaxPaperCi));
      co_sum += luminance(co[j]);
      ci_sum += luminance(ci[j]);
    }
    out.order_luminance.push_back(ci_sum);
    out.pair_interactions += in.pairs.size();
    out.passes_run = pass + 1;
    out.last_relative_change = ci_sum > 0 ? std::min(1.0, co_sum / ci_sum) : 0.0;
    if (out.last_relative_change < in.options.tolerance) break;
  }
  out.co.resize(n);
  out.light_dir = dir;
  out.mie_ratio.resize(n);
  for (size_t j = 0; j < n; ++j) {
    const Rgb initial(double(pc.sun[j]));
    out.co[j] = in.options.output_mapping ? Rgb(1.0) - exp(-ci[j])
                                          : max(ci[j] - initial, Rgb(0.0));  // Eq. 2 or scattered
    out.mie_ratio[j] = float(std::clamp(ratio[j], 0.0, 1.0));
  }
}

// Pair weights of the normalised rule: the source's mass times the transmittance along the
// pair (Simpson's rule over the two ends and the midpoint) over the squared distance, clamped to
// the source's own sphere so that near pairs stay finite.
NeighbourPairs normalisedPairs(const PointGrid& point_grid, const PointCloud& pc,
                               const BakeGrid& grid, const std::vector<float>& density, double ext,
                               double radius, uint64_t reserve,
                               const std::function<bool(double)>& cancelled) {
  const size_t n = pc.size();
  std::vector<float> clamp_r2(n);  // r_i^2: a source's own sphere
  for (size_t i = 0; i < n; ++i) {
    const double r = std::cbrt(3 * pc.mass / (4 * kPi * pc.density[i]));
    clamp_r2[i] = float(r * r);
  }
  const double em = ext * pc.mass, ext6 = ext / 6;
  // sampleTrilinear bit for bit, without its bounds checks inside the lattice, at the midpoint
  // of the points' lattice coordinates (affine in their positions: no division per pair).
  const TransmittanceMarcher lookup(grid, density.data(), ext);
  std::vector<Vec3> u(n);
  for (size_t i = 0; i < n; ++i) u[i] = grid.toIndex(pc.position[i]);
  auto weight = [&](uint32_t dst, uint32_t src, double d) -> float {
    const double ends = double(pc.density[src]) + double(pc.density[dst]);
    if (ext6 * d * ends > 16.2) return 0.f;  // T < 1e-7 whatever the midpoint holds
    const double mid = lookup.densityAtIndex((u[src] + u[dst]) * 0.5);
    const double tau = ext6 * d * (ends + 4 * mid);
    if (tau > 16.2) return 0.f;
    return float(em * std::exp(-tau) / std::max(d * d, double(clamp_r2[src])));
  };
  return buildNeighbourPairs(point_grid, pc.position, radius, weight, reserve, cancelled);
}

// Pair weights of the paper rule: the transmittance from the densities at the two ends.
NeighbourPairs paperPairs(const PointGrid& point_grid, const PointCloud& pc, double ext,
                          double radius, uint64_t reserve,
                          const std::function<bool(double)>& cancelled) {
  auto weight = [&](uint32_t dst, uint32_t src, double d) -> float {
    const double tau = d * 0.5 * (double(pc.density[src]) + double(pc.density[dst])) * ext;
    return tau > 16.2 ? 0.f : float(std::exp(-tau));  // Eq. 3; below 1e-7 negligible
  };
  return buildNeighbourPairs(point_grid, pc.position, radius, weight, reserve, cancelled);
}

// The neighbour stage: the cut-off (the option, or 3x the mean point spacing), refused while it
// is wider than the volume or its pairs would not fit in memory, then the weighted pairs of the
// rule. Sets out.radius, out.pairs and out.mean_neighbours.
NeighbourPairs findNeighbours(const BakeGrid& grid, const std::vector<float>& density,
                              const PointcloudOptions& options, double ext,
                              const BakeProgressFn& progress, PointCloudResult& out) {
  const PointCloud& pc = out.cloud;
  const size_t n = pc.size();
  const double diagonal = length(grid.bounds().extent());
  out.radius = options.radius > 0 ? options.radius : 3 * pc.spacing;
  if (out.radius > diagonal) {
    throw InputError("radius: " + str(out.radius) + " is larger than the volume (lattice " +
                     "diagonal " + str(diagonal) + " world units)");
  }
  const PointGrid point_grid(pc.position, 0.5 * out.radius);
  const double max_mean = kMaxNeighbourPairs / double(n);
  const double mean_estimate =
      estimateMeanNeighbours(point_grid, pc.position, out.radius, 256, max_mean);
  if (mean_estimate > max_mean) {
    throw InputError("radius: " + str(out.radius) + " gives about " +
                     str(uint64_t(mean_estimate * double(n))) + " neighbour pairs for " + str(n) +
                     " points, more than the " + str(kMaxNeighbourPairs) +
                     " that fit in memory; use a smaller radius or fewer points");
  }
  const uint64_t reserve = uint64_t(std::min(mean_estimate * 1.1 + 8, max_mean) * double(n));
  auto cancelled_build = [&](double f) {
    return progress && !progress(0.1 + 0.2 * f, "neighbours");
  };
  NeighbourPairs pairs =
      options.rule == PointcloudOptions::Rule::kNormalized
          ? normalisedPairs(point_grid, pc, grid, density, ext, out.radius, reserve,
                            cancelled_build)
          : paperPairs(point_grid, pc, ext, out.radius, reserve, cancelled_build);
  out.pairs = pairs.size();
  out.mean_neighbours = double(pairs.within_radius) / double(n);
  return pairs;
}

// The escape probability of the reduced medium, whose extinction is `ext`: the caller's sky
// visibility serves only when there is one and no reduction (s = 1); else it is computed into
// `computed`.
const FirstTouchFloats* escapeVisibility(const BakeGrid& grid, const std::vector<float>& density,
                                         const FirstTouchFloats& sky_visibility,
                                         const FirstTouchFloats& pass_sky_visibility, double s,
                                         double ext, FirstTouchFloats* computed) {
  if (sky_visibility.size() == grid.voxelCount() && s == 1) return &sky_visibility;
  if (pass_sky_visibility.size() == grid.voxelCount()) return &pass_sky_visibility;
  *computed = std::move(skyVisibilities(grid, density.data(), {ext})[0]);
  return computed;
}

}  // namespace

void checkPointcloudInput(const Medium& medium, const PointcloudOptions& o) {
  if (o.points < 64 || o.points > (1 << 24)) {
    throw InputError("points: must be in [64, 16777216], got " + str(o.points));
  }
  if (o.passes < 1 || o.passes > 1000) {
    throw InputError("passes: must be in [1, 1000], got " + str(o.passes));
  }
  if (!(o.tolerance > 0 && o.tolerance <= 1)) {
    throw InputError("tolerance: must be in (0, 1], got " + str(o.tolerance));
  }
  if (!(o.radius >= 0) || !std::isfinite(o.radius)) {
    throw InputError("radius: must be finite and >= 0 (0: 3x the mean point spacing), got " +
                     str(o.radius));
  }
  if (!(o.step >= 0) || !std::isfinite(o.step)) {
    throw InputError("step: must be finite and >= 0, got " + str(o.step));
  }
  if (!medium.density) throw InputError("medium: density: no volume");
  if (!medium.phase) throw InputError("medium: phase: no phase function");
  if (!(medium.extinction >= 0) || !std::isfinite(medium.extinction)) {
    throw InputError("medium: extinction: must be finite and >= 0, got " + str(medium.extinction));
  }
  for (int c = 0; c < 3; ++c) {
    if (!(medium.albedo[c] >= 0 && medium.albedo[c] <= 1)) {
      throw InputError("medium: albedo: must be in [0, 1], got " + str(medium.albedo[c]));
    }
  }
}

double passExtinction(const Medium& medium, const PointcloudOptions& options) {
  const bool normalised = options.rule == PointcloudOptions::Rule::kNormalized;
  const TransportScaling ts = normalised ? transportScaling(medium) : TransportScaling{};
  return medium.extinction * ts.s;
}

PointCloudResult runPointcloud(const BakeGrid& grid, const std::vector<float>& density,
                               const FirstTouchFloats& sky_visibility, const Medium& medium,
                               const Vec3& sun_dir_in, const PointcloudOptions& options,
                               bool geometric_tail, const BakeProgressFn& progress,
                               const FirstTouchFloats& pass_sky_visibility) {
  checkPointcloudInput(medium, options);
  if (!isFinite(sun_dir_in) || !(length(sun_dir_in) > 0)) {
    throw InputError("sun: direction: must be a finite nonzero vector");
  }
  if (density.size() != grid.voxelCount() || grid.voxelCount() == 0) {
    throw InputError("volume: density grid of " + str(density.size()) + " voxels on a lattice of " +
                     str(grid.voxelCount()));
  }
  const Vec3 sun_dir = normalize(sun_dir_in);
  PointCloudResult out;
  // An empty cloud is a valid shot (it renders the background): no points, a zero bake.
  if (std::none_of(density.begin(), density.end(), [](float d) { return d > 0; })) return out;
  // Stage fractions: points 0-0.1, neighbours 0.1-0.3, passes 0.3-1.
  auto report = [&](double f, const std::string& stage) {
    if (progress && !progress(f, stage)) throw Cancelled();
  };

  auto t0 = Clock::now();
  report(0.0, "points");
  out.cloud = placePoints(grid, density, options.points, options.seed);
  computePointSunTransmittance(out.cloud, grid, density, medium.extinction, sun_dir,
                               0.5 * grid.voxel_size,
                               [&](double f) { return progress && !progress(0.1 * f, "points"); });
  out.seconds_points = secondsSince(t0);

  t0 = Clock::now();
  report(0.1, "neighbours");
  const bool normalised = options.rule == PointcloudOptions::Rule::kNormalized;
  const TransportScaling ts = normalised ? transportScaling(medium) : TransportScaling{};
  const double ext = passExtinction(medium, options);
  const NeighbourPairs pairs = findNeighbours(grid, density, options, ext, progress, out);
  out.seconds_neighbours = secondsSince(t0);

  t0 = Clock::now();
  const int passes = options.passes;
  PassInputs in{pairs, medium, sun_dir, options, geometric_tail};
  if (progress) {
    // The sun's passes, then as many for the sky: one range, never going back. The reduced
    // medium's passes gather both at once.
    const bool sky = normalised && options.sky && sky_visibility.size() == grid.voxelCount();
    const bool apart = sky && !ts.isotropic;
    const double all = passes * (apart ? 2.0 : 1.0);
    const std::string name = apart ? "sun pass " : sky ? "sun and sky pass " : "pass ";
    in.cancelled = [&progress, passes, all, name](double f, int pass) {
      return !progress(0.3 + 0.7 * (pass + f) / all, name + str(pass + 1) + "/" + str(passes));
    };
    in.sky_cancelled = [&progress, passes, all](double f, int pass) {
      const std::string stage = "sky pass " + str(pass + 1) + "/" + str(passes);
      return !progress(0.3 + 0.7 * (passes + pass + f) / all, stage);
    };
  }
  if (normalised) {
    FirstTouchFloats computed;
    const FirstTouchFloats* vis =
        escapeVisibility(grid, density, sky_visibility, pass_sky_visibility, ts.s, ext, &computed);
    const bool sky = options.sky && sky_visibility.size() == grid.voxelCount();
    in.grid = &grid;
    in.escape_visibility = vis;
    in.ts = ts;
    in.true_visibility = sky ? &sky_visibility : nullptr;
    runNormalised(in, out);
  } else {
    runPaper(in, out);
  }
  out.seconds_passes = secondsSince(t0);
  report(1.0, "passes done");
  return out;
}

}  // namespace cloudbake
