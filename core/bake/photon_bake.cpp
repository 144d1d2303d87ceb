#include "core/bake/photon_bake.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>

#include "core/bake/bake_lattice.h"
#include "core/bake/render_from_bake.h"
#include "core/bake/sky_p1_scatter.h"
#include "core/bake/sky_visibility.h"
#include "core/bake/sun_transmittance.h"
#include "core/error.h"
#include "core/format.h"
#include "core/math/parallel.h"
#include "core/math/rng.h"
#include "core/math/rounding.h"
#include "core/math/sampling.h"
#include "core/math/sh_basis.h"
#include "core/math/spherical_harmonics.h"
#include "core/phase/forward_peak.h"
#include "core/transport/sky.h"
#include "core/transport/tracking.h"

namespace cloudbake {

namespace bake_grids {
std::string photonSh(int i) { return "ms_sh_" + std::to_string(i); }
std::string photonSkySh(int i) { return "ms_sky_sh_" + std::to_string(i); }
std::string photonSkyDirectSh(int i) { return "ss_sky_sh_" + std::to_string(i); }
std::string photonSkySingleScale() { return "sky_single_scale"; }
std::string photonZonal(int l) { return "ms_zonal_" + std::to_string(l); }
}  // namespace bake_grids

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
// Photons per parallel work unit: few, so a cancel is seen within about a second even where
// every photon scatters thousands of times.
constexpr int64_t kBatch = 64;
constexpr int kRouletteOrder = 3;        // scatterings before the throughput is rouletted
constexpr int kMaxScatterings = 100000;  // as pathtrace's max_depth: bounds every walk
// Counts per unit of (weight / photon weight) x (length / voxel size) x Y_i: fixed point with 32
// fractional bits, so integer sums are exact and their order (the thread schedule) is moot.
constexpr double kFixedScale = 4294967296.0;

void validate(const Medium& medium, const Vec3& sun_dir, const PhotonBakeOptions& o) {
  if (!medium.density) throw InputError("medium: no density field");
  validateMediumOptics(medium);
  if (!isFinite(sun_dir) || std::abs(length(sun_dir) - 1) > 1e-6) {
    throw InputError("lighting.sun.direction: must be a unit vector");
  }
  if (o.photons < 1 || o.photons >= (int64_t(1) << 31)) {
    throw InputError("photons: must be in 1..2147483647, got " + str(o.photons));
  }
  if (o.tally_resolution != 0 && (o.tally_resolution < 8 || o.tally_resolution > 1024)) {
    throw InputError("tally_resolution: must be 0 (light_resolution) or in [8, 1024], got " +
                     str(o.tally_resolution));
  }
  if (o.order < 1 || o.order > kMaxShDegree) {
    throw InputError("order: must be in 1.." + str(kMaxShDegree) + ", got " + str(o.order));
  }
  if (o.zonal_order != 0 && (o.zonal_order <= o.order || o.zonal_order > kMaxZonalDegree)) {
    throw InputError("zonal_order: must be 0 (none) or in " + str(o.order + 1) + ".." +
                     str(kMaxZonalDegree) + " (above order " + str(o.order) + "), got " +
                     str(o.zonal_order));
  }
  if (!(o.step >= 0) || !std::isfinite(o.step)) {
    throw InputError("step: must be finite and >= 0 (0: half a lattice voxel), got " + str(o.step));
  }
}

// Views convolve the tallies with the phase degree by degree, up to the highest degree kept. A
// phase whose Legendre coefficients are still large beyond degree kSpikeDegree has a peak narrower
// than about 7 degrees (a droplet's forward peak, or HG -0.99's backward one), and light scattered
// through it carries that peak too: the truncated sums ring. The real Mie table (10 um, p_24 =
// 0.43) measured 40-140 % off the reference in every view when its peak was tallied; HG 0.85
// (p_24 = 0.02) converges. So a forward peak is split off (ForwardPeak) at the narrowest cut that
// leaves the rest's coefficient at the top degree under kMaxTopLegendre (a bound between the two;
// phases under it are not split), and views add the light scattered only through the peak as a
// beam about the sun's direction (PhotonPeakLight). A peak the cut cannot remove within
// kMaxCutDegrees (a backward one) is refused.
constexpr int kSpikeDegree = 24;
constexpr double kMaxTopLegendre = 0.1;
constexpr double kMaxCutDegrees = 30;
// How far the phase's integral on that grid may be from 1 (phaseIntegralOnPeakGrid).
constexpr double kMaxPeakGridError = 0.005;

/// Per-voxel SH moments of a radiance field, summed as fixed-point integers (TallyWriter adds
/// to it). One colour channel stands for all three where every photon's throughput is grey.
class PhotonTally {
 public:
  /// Degrees 0..order in full and, when zonal_order > order, the zonal degrees order + 1 ..
  /// zonal_order about `axis` (unit); `channels` 1 (grey) or 3.
  PhotonTally(const BakeGrid& grid, int order, double photon_weight, int channels,
              int zonal_order = 0, const Vec3& axis = Vec3(0, 0, 1))
      : grid_(grid),
        ncoef_(shCount(order) + std::max(0, zonal_order - order)),
        order_(order),
        top_(std::max(order, zonal_order)),
        channels_(channels),
        axis_(axis),
        photon_weight_(photon_weight),
        counts_(grid.voxelCount() * size_t(ncoef_) * size_t(channels), 0) {
    // add() rounds a record on the stack; validate() keeps order and zonal_order within it.
    if (ncoef_ * channels_ > kMaxWidth) {
      throw InputError("photon tally: " + str(ncoef_) + " coefficients x " + str(channels_) +
                       " channels exceed " + str(kMaxWidth));
    }
  }

  const BakeGrid& grid() const { return grid_; }
  int order() const { return order_; }
  /// The highest degree kept: zonal_order when it is above order.
  int topDegree() const { return top_; }
  int coefficients() const { return ncoef_; }
  int channels() const { return channels_; }
  double photonWeight() const { return photon_weight_; }
  /// The coefficients of degree l: [first, last) of the index range.
  void degreeRange(int l, int* first, int* last) const {
    *first = l <= order_ ? l * l : shCount(order_) + (l - order_ - 1);
    *last = l <= order_ ? (l + 1) * (l + 1) : *first + 1;
  }

  /// The basis at direction of travel d: full SH to order, then the zonal terms
  /// sqrt((2l + 1) / (4 pi)) P_l(d . axis).
  void basis(const Vec3& d, double* y) const {
    shBasisUpTo(order_, d, y);
    if (top_ > order_) shZonal(order_ + 1, top_, dot(d, axis_), y + shCount(order_));
  }
  /// The raw fixed-point sum of coefficient i, channel c (0..2), at voxel v (a common scale).
  double count(size_t v, int i, int c) const {
    const size_t ch = channels_ == 1 ? 0 : size_t(c);
    return double(counts_[(v * size_t(ncoef_) + size_t(i)) * size_t(channels_) + ch]);
  }

  /// Adds sums[k] (k = coefficient x channels + channel; units of photon weight x voxel sizes
  /// of length x Y_i) to voxel v, rounded to the fixed point: integer sums are exact, so their
  /// order (the thread schedule) is moot.
  void add(size_t v, const double* sums) {
    const int width = ncoef_ * channels_;
    int64_t q[kMaxWidth];
    bool any = false;
    for (int k = 0; k < width; ++k) {
      q[k] = roundHalfAway(std::clamp(sums[k] * kFixedScale, -4e18, 4e18));
      any |= q[k] != 0;
    }
    if (!any) return;
    // One lock per voxel's record, not one atomic add per value: the locked adds were three
    // quarters of a sky photon's tracing (`perf annotate`, issue 18). The sums are the same.
    int64_t* out = &counts_[v * size_t(width)];
    std::lock_guard<SpinLock> hold(locks_[v % kLocks]);
    for (int k = 0; k < width; ++k) out[k] += q[k];
  }

  /// Asks for voxel v's record ahead of add(v): the tally is tens of MB read at random, and a
  /// record's cache misses were most of add's time (`perf annotate`, issue 18).
  void prefetch(size_t v) const {
    const size_t width = size_t(ncoef_) * size_t(channels_);
    const char* first = reinterpret_cast<const char*>(&counts_[v * width]);
    const char* end = first + width * sizeof(int64_t);
    for (const char* p = first; p < end; p += 64) __builtin_prefetch(p, 1);
  }

  /// Writes the radiance coefficients (sum of weight x length x Y_i / voxel volume / photons'
  /// normalisation already in photon_weight) to channels name(i).
  /// The zonal terms go to photonZonal(l).
  void store(BakedLight* bake, std::string (*name)(int)) const {
    const double h = grid_.voxel_size;
    const double unit = photon_weight_ * h / kFixedScale / (h * h * h);
    for (int i = 0; i < ncoef_; ++i) {
      const int first_zonal = shCount(order_);
      BakeChannel& ch = bake->addOnTallyGrid(
          i < first_zonal ? name(i) : bake_grids::photonZonal(order_ + 1 + i - first_zonal), 3);
      for (size_t v = 0; v < grid_.voxelCount(); ++v) {
        for (int c = 0; c < 3; ++c) ch.data[v * 3 + c] = float(count(v, i, c) * unit);
      }
    }
  }

  // Calls fn(voxel index, length) for every lattice voxel the segment crosses (3D DDA).
  template <typename Fn>
  void walkVoxels(const Vec3& p, const Vec3& d, double len, Fn&& fn) const {
    const Bounds3 b = grid_.bounds();
    double t0, t1;
    if (!intersectBounds(b, Ray{p, d}, 0, len, &t0, &t1) || !(t1 > t0)) return;
    const double h = grid_.voxel_size;
    const int n[3] = {grid_.nx, grid_.ny, grid_.nz};
    const Vec3 q = (p + d * t0 - b.min) / h;
    int i[3], step[3];
    double t_next[3], dt[3];
    for (int a = 0; a < 3; ++a) {
      i[a] = std::clamp(int(std::floor(q[a])), 0, n[a] - 1);
      if (d[a] > 0) {
        step[a] = 1;
        t_next[a] = t0 + ((i[a] + 1) - q[a]) * h / d[a];
        dt[a] = h / d[a];
      } else if (d[a] < 0) {
        step[a] = -1;
        t_next[a] = t0 + (i[a] - q[a]) * h / d[a];
        dt[a] = -h / d[a];
      } else {
        step[a] = 0;
        t_next[a] = kInf;
        dt[a] = kInf;
      }
    }
    double t = t0;
    while (t < t1) {
      const int a =
          t_next[0] < t_next[1] ? (t_next[0] < t_next[2] ? 0 : 2) : (t_next[1] < t_next[2] ? 1 : 2);
      const double te = std::min(t_next[a], t1);
      if (te > t) fn(grid_.index(i[0], i[1], i[2]), te - t);
      t = te;
      i[a] += step[a];
      if (i[a] < 0 || i[a] >= n[a]) break;
      t_next[a] += dt[a];
    }
  }

 private:
  const BakeGrid& grid_;
  int ncoef_;
  int order_;
  int top_;
  int channels_;
  Vec3 axis_;
  double photon_weight_;
  std::vector<int64_t> counts_;
  // A lock held for a few dozen additions: std::mutex's calls into pthreads were 5 % of a
  // photon bake (`perf`), where threads rarely meet. One per cache line, so that two threads
  // taking neighbouring locks do not fight over a line; it yields while another holds it, so a
  // holder descheduled on a shared machine is not spun against.
  struct alignas(64) SpinLock {
    std::atomic<bool> held{false};
    void lock() {
      while (held.exchange(true, std::memory_order_acquire)) {
        while (held.load(std::memory_order_relaxed)) std::this_thread::yield();
      }
    }
    void unlock() { held.store(false, std::memory_order_release); }
  };
  // Voxel v's record is written under locks_[v % kLocks]: enough locks that threads rarely meet.
  static constexpr size_t kLocks = 1024;
  static constexpr int kMaxWidth = (shCount(kMaxShDegree) + kMaxZonalDegree) * 3;
  std::unique_ptr<SpinLock[]> locks_{new SpinLock[kLocks]};
};

/// One photon's segments added to a PhotonTally: summed in doubles per voxel, a few voxels at a
/// time, and rounded into the tally once per voxel and photon rather than once per segment. A
/// photon in a thick cloud scatters many times within one tally voxel, and the per-segment
/// rounding and atomic adds were most of the bake's time. The sums hold one photon only and are
/// flushed at its end, so the tally does not depend on which thread traced which photon.
class TallyWriter {
 public:
  explicit TallyWriter(PhotonTally* tally)
      : tally_(tally),
        width_(tally->coefficients() * tally->channels()),
        sums_(size_t(kSlots) * size_t(width_), 0.0) {
    voxel_.fill(kEmpty);
  }

  /// Adds the segment p + t d, t in [0, len], carrying weight `beta`, to the voxels it crosses
  /// (track length: length x weight x Y_i(d) / voxel size, as the photon's share).
  void addSegment(const Vec3& p, const Vec3& d, double len, const Rgb& beta) {
    double y[shCount(kMaxShDegree) + kMaxZonalDegree];
    tally_->basis(d, y);
    const int nc = tally_->coefficients(), channels = tally_->channels();
    const Rgb b = beta / (tally_->photonWeight() * tally_->grid().voxel_size);
    tally_->walkVoxels(p, d, len, [&](size_t voxel, double l) {
      double* s = slot(voxel);
      for (int c = 0; c < channels; ++c) {
        const double bl = b[c] * l;
        for (int i = 0; i < nc; ++i) s[i * channels + c] += bl * y[i];
      }
    });
  }

  /// Rounds every held sum into the tally: at the end of each photon.
  void flush() {
    for (int k = 0; k < kSlots; ++k) {
      if (voxel_[size_t(k)] == kEmpty) continue;
      tally_->add(voxel_[size_t(k)], &sums_[size_t(k) * size_t(width_)]);
      voxel_[size_t(k)] = kEmpty;
    }
  }

 private:
  static constexpr int kSlots = 32;  // voxels held at once, chosen by a hash of the index
  static constexpr size_t kEmpty = ~size_t(0);

  // The sums of `voxel`, after flushing the voxel that held its slot.
  double* slot(size_t voxel) {
    const size_t k = size_t((uint64_t(voxel) * 0x9E3779B97F4A7C15ull) >> 59);
    double* s = &sums_[k * size_t(width_)];
    if (voxel_[k] != voxel) {
      if (voxel_[k] != kEmpty) tally_->add(voxel_[k], s);
      std::fill(s, s + width_, 0.0);
      voxel_[k] = voxel;
      tally_->prefetch(voxel);
    }
    return s;
  }

  PhotonTally* tally_;
  int width_;
  std::vector<double> sums_;
  std::array<size_t, kSlots> voxel_;
};

/// Where photons come from: a start ray and its weight (flux per photon).
struct Emission {
  Ray ray;
  Rgb weight{0.0};
};

/// Photons of unit sun irradiance: uniform over the rectangle, perpendicular to the sun, that
/// covers the lattice's shadow, travelling along -sun_dir. Flux per photon = area / count.
class SunEmitter {
 public:
  SunEmitter(const Bounds3& b, const Vec3& sun_dir, int64_t count) : frame_(Frame::fromZ(sun_dir)) {
    double lo[3] = {kInf, kInf, kInf}, hi[3] = {-kInf, -kInf, -kInf};
    for (int c = 0; c < 8; ++c) {
      const Vec3 corner((c & 1) ? b.max.x : b.min.x, (c & 2) ? b.max.y : b.min.y,
                        (c & 4) ? b.max.z : b.min.z);
      const Vec3 l = frame_.toLocal(corner);
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], l[a]);
        hi[a] = std::max(hi[a], l[a]);
      }
    }
    for (int a = 0; a < 3; ++a) {
      lo_[a] = lo[a];
      size_[a] = hi[a] - lo[a];
    }
    // Start just outside the box on the sun's side.
    start_z_ = hi[2] + 1e-3 * (size_[0] + size_[1] + size_[2]) + 1e-9;
    weight_ = size_[0] * size_[1] / double(count);
  }
  double weight() const { return weight_; }
  Emission emit(Rng& rng) const {
    const double u = rng.uniform(), v = rng.uniform();
    const Vec3 p = frame_.toWorld(Vec3(lo_[0] + u * size_[0], lo_[1] + v * size_[1], start_z_));
    return {{p, -frame_.n}, Rgb(weight_)};
  }

 private:
  Frame frame_;
  double lo_[3], size_[3];
  double start_z_ = 0, weight_ = 0;
};

/// Photons of a sky of unit mean radiance: from the box's bounding sphere of radius R,
/// cosine-distributed inwards; the flux entering a sphere from a uniform sky is pi L 4 pi R^2.
/// With a `shape`, each photon also carries the radiance of the direction it comes from over the
/// sky's mean (per channel), so the tallies hold that sky's light per unit of its mean radiance
/// and views scale them by the mean as for a uniform sky.
class SkyEmitter {
 public:
  SkyEmitter(const Bounds3& b, int64_t count, const SkyLight* shape, const Rgb& mean)
      : centre_((b.min + b.max) * 0.5),
        radius_(0.5 * length(b.extent()) * (1 + 1e-6) + 1e-9),
        shape_(shape) {
    weight_ = kPi * 4 * kPi * radius_ * radius_ / double(count);
    for (int c = 0; c < 3; ++c) inv_mean_[c] = mean[c] > 0 ? 1 / mean[c] : 0.0;
  }
  double weight() const { return weight_; }
  Emission emit(Rng& rng) const {
    const Vec3 n = sampleUniformSphere(rng.uniform(), rng.uniform());
    const Vec3 local = sampleCosineHemisphere(rng.uniform(), rng.uniform());
    const Vec3 d = Frame::fromZ(-n).toWorld(local);
    const Rgb w = shape_ ? shape_->radiance(-d) * inv_mean_ * weight_ : Rgb(weight_);
    return {{centre_ + n * radius_, d}, w};
  }

 private:
  Vec3 centre_;
  double radius_, weight_ = 0;
  const SkyLight* shape_;
  Rgb inv_mean_{0.0};
};

/// Where a photon's segments go: the tallies of one kind of photon (null: not tallied).
struct PhotonWriters {
  TallyWriter* scattered = nullptr;  ///< after its first scattering (through the peak's rest)
  TallyWriter* direct = nullptr;     ///< before its first scattering
  TallyWriter* half = nullptr;       ///< the scattered segments again (odd photons)
};

/// Follows one photon; every segment goes to one of `PhotonWriters` by what it has been through.
class PhotonTracer {
 public:
  /// With an active `split`, a scattering of a photon not yet scattered through the peak's rest
  /// is through the peak with probability peak(mu) / p(mu) (averaged over channels, the weights
  /// corrected per channel): such photons are not tallied (PhotonPeakLight), travelling within its
  /// cone of their first direction.
  PhotonTracer(const Medium& medium, const MajorantGrid& grid, const ForwardPeak* split)
      : medium_(medium),
        grid_(grid),
        lookup_(medium.density->lookup()),
        split_(split && split->active() ? split : nullptr) {}

  void trace(const Emission& e, Rng& rng, const PhotonWriters& to) {
    enum class State { kDirect, kPeak, kScattered };
    Ray ray = e.ray;
    Rgb beta = e.weight;
    State state = State::kDirect;
    const double start = maxComponent(e.weight);
    if (!(start > 0)) return;  // a black part of the sky brings nothing
    for (int order = 0; order <= kMaxScatterings; ++order) {
      // Only over the ray's part inside the density's support (as the path tracer).
      double t0 = 0, t1 = 0;
      const Collision c =
          medium_.density->supportInterval(ray, 0, kInf, &t0, &t1)
              ? decompositionTrack(grid_, *lookup_, medium_.extinction, ray, t0, t1, rng)
              : Collision{};
      const double len = c.hit ? c.t : kInf;
      TallyWriter* w = state == State::kDirect ? to.direct
                       : state == State::kPeak ? nullptr
                                               : to.scattered;
      if (w) w->addSegment(ray.o, ray.d, len, beta);
      if (state == State::kScattered && to.half) to.half->addSegment(ray.o, ray.d, len, beta);
      if (!c.hit) return;
      beta *= medium_.albedo;
      const PhaseSample ps = medium_.phase->sample(ray.d, rng.uniform(), rng.uniform());
      if (!(ps.pdf > 0)) return;
      beta *= ps.value / ps.pdf;
      if (state != State::kScattered) {
        state = (split_ && throughPeak(dot(ray.d, ps.direction), ps.value, rng, &beta))
                    ? State::kPeak
                    : State::kScattered;
      }
      if (!(maxComponent(beta) > 0)) return;
      if (order + 1 >= kRouletteOrder) {
        const double q = std::min(1.0, maxComponent(beta) / start);
        if (q < 1) {
          if (!(rng.uniform() < q)) return;
          beta /= q;
        }
      }
      ray = {c.p, ps.direction};
    }
  }

 private:
  // Chooses the peak or the rest for a scattering by cos theta `mu` with value p_mu, and weights
  // beta by the chosen part over p per channel, over the probability of choosing it.
  bool throughPeak(double mu, const Rgb& p_mu, Rng& rng, Rgb* beta) const {
    const Rgb peak = split_->peak(mu, p_mu);
    const double all = p_mu.x + p_mu.y + p_mu.z;
    const double share = all > 0 ? (peak.x + peak.y + peak.z) / all : 0.0;
    if (!(share > 0)) return false;
    const bool in_peak = share >= 1 || rng.uniform() < share;
    const Rgb part = in_peak ? peak : p_mu - peak;
    const double chosen = in_peak ? share : 1 - share;
    for (int c = 0; c < 3; ++c) {
      (*beta)[c] *= p_mu[c] > 0 ? part[c] / p_mu[c] / chosen : 0.0;
    }
    return in_peak;
  }

  const Medium& medium_;
  const MajorantGrid& grid_;
  std::unique_ptr<DensityField::Lookup> lookup_;
  const ForwardPeak* split_;
};

/// The tallies one kind of photon goes to (PhotonWriters; null: none).
struct PhotonTallies {
  PhotonTally* scattered = nullptr;
  PhotonTally* direct = nullptr;
  PhotonTally* half = nullptr;  // odd photons only
};

// Traces `count` photons from `emit` into `tallies` in parallel batches, one random stream per
// photon, splitting the phase's forward peak off by `split` (null: never); progress(fraction)
// false cancels.
template <typename Emitter>
void tracePhotons(const Medium& medium, const MajorantGrid& grid, const Emitter& emitter,
                  int64_t count, uint64_t seed, uint64_t stream, const PhotonTallies& tallies,
                  const ForwardPeak* split, const std::function<bool(double)>& progress) {
  ParallelOptions po;
  po.cancelled = [&](double f) { return progress && !progress(f); };
  po.cancelled_message = "bake cancelled";
  const int64_t batches = (count + kBatch - 1) / kBatch;
  parallelFor(
      0, batches,
      [&](int64_t b) {
        PhotonTracer tracer(medium, grid, split);
        std::optional<TallyWriter> w[3];
        PhotonTally* const t[3] = {tallies.scattered, tallies.direct, tallies.half};
        for (int k = 0; k < 3; ++k) {
          if (t[k]) w[k].emplace(t[k]);
        }
        auto writer = [&](int k) { return w[k] ? &*w[k] : nullptr; };
        Rng rng;
        for (int64_t i = b * kBatch; i < std::min(count, (b + 1) * kBatch); ++i) {
          rng.setSeed(mixBits(seed, uint64_t(i)), stream);
          PhotonWriters to{writer(0), writer(1), (i & 1) ? writer(2) : nullptr};
          tracer.trace(emitter.emit(rng), rng, to);
          for (auto& one : w) {
            if (one) one->flush();
          }
        }
      },
      po);
}

// The bake's own error estimates (PhotonErrorEstimate), from the full tally, the odd photons'
// degree-0 tally and the phase's Legendre coefficients; voxels weighted by their density.
PhotonErrorEstimate estimateErrors(const PhotonTally& full, const PhotonTally& odd,
                                   const std::vector<Rgb>& p_l, const std::vector<float>& density) {
  double noise_num = 0, noise_den = 0, top = 0, all = 0;
  const int last = full.topDegree();
  for (size_t v = 0; v < density.size(); ++v) {
    const double w = density[v];
    if (!(w > 0)) continue;
    for (int c = 0; c < 3; ++c) {
      const double f = full.count(v, 0, c), o = odd.count(v, 0, c);
      noise_num += w * (f - 2 * o) * (f - 2 * o);  // (even - odd)^2
      noise_den += w * f * f;
      for (int l = 0; l <= last; ++l) {
        double sum = 0;
        int first, end;
        full.degreeRange(l, &first, &end);
        for (int i = first; i < end; ++i) sum += full.count(v, i, c) * full.count(v, i, c);
        const double pl = p_l[size_t(l)][c];
        all += w * pl * pl * sum;
        if (l >= std::max(1, last - 1)) top += w * pl * pl * sum;  // order 1: degree 1
      }
    }
  }
  PhotonErrorEstimate e;
  e.tally_noise = noise_den > 0 ? std::sqrt(noise_num / noise_den) : 0.0;
  e.truncation = all > 0 ? std::sqrt(top / all) : 0.0;
  return e;
}

// Cd = (sun_transmittance + fluence of the scattered sunlight) / (4 pi), the fluence being
// sqrt(4 pi) times coefficient 0 (Y_00 = 1 / sqrt(4 pi)), plus, where the peak was split off
// (`peak_exponent` not null), that of the light scattered through it only (photonPeakFluence):
// the isotropic DCC preview. The tally lies on the tally lattice: read at each voxel centre of
// the bake's lattice.
void addPhotonMeanRadiance(BakedLight* bake, const Rgb* peak_exponent) {
  const BakeChannel* t = bake->find(bake_grids::kSunTransmittance);
  const BakeChannel* l0 = bake->find(bake_grids::photonSh(0));
  BakeChannel& cd = bake->add(bake_grids::kCd, 3);
  const double inv4pi = 1 / (4 * kPi);
  const size_t voxels = bake->grid.voxelCount();
  const std::vector<float> l =
      l0 ? resampleTrilinear(bake->gridOf(*l0), l0->data.data(), 3, bake->grid)
         : std::vector<float>(voxels * 3, 0.f);
  for (size_t v = 0; v < voxels; ++v) {
    const double tsun = t ? t->data[v] : 0.0;
    const Rgb peak = peak_exponent ? photonPeakFluence(tsun, *peak_exponent) : Rgb(0.0);
    for (int c = 0; c < 3; ++c) {
      const double fluence = std::max(0.0, kSqrt4Pi * l[v * 3 + c]) + peak[c];
      cd.data[v * 3 + c] = float((tsun + fluence) * inv4pi);
    }
  }
}

// photonSkySingleScale: the lattice's visibility of the sky at each voxel centre over its mean
// over the tally voxel there (read as the tally is read). The unscattered sky tally is a mean
// over a coarser voxel that reaches out of the cloud, where the sky shines unattenuated, and
// spans a dense cloud's lit skin and the dark below it: an outside probe measured photon 11's
// single layer at 1.3-1.95x the path tracer's on a box of extinction 40 under a sky, against
// 1.04x for `single`, which reads the lattice. The ratio moves the tally's amount to the point,
// and the lattice's own angular error (26 directions, the sky's shape to P1) cancels between
// the point and the mean, so the tally's amount still converges: on the tally's own lattice the
// scale is 1. Summed over the channels the sky lights: it corrects where the light is, the same
// for every colour.
void addSkySingleScale(BakedLight* bake, const FirstTouchFloats& vector, const Sky* shape) {
  const BakeChannel* vis = bake->find(bake_grids::kSkyVisibility);
  const size_t voxels = bake->grid.voxelCount();
  if (!vis || vector.size() != 3 * voxels) {
    throw InternalError("photon: the sky's single-scattering scale needs the sky's visibility");
  }
  // The sky's P1 shape over its mean per channel (0 for a uniform sky): a point's visibility of
  // a sky of that shape is V + 3 l . B, as the tally's photons weight their directions.
  std::array<Vec3, 3> l{Vec3(0.0), Vec3(0.0), Vec3(0.0)};
  std::array<bool, 3> lit{true, true, true};
  if (shape) {
    const SkyLight light(*shape);
    const Rgb mean = meanSkyRadiance(*shape, light);
    const std::array<Vec3, 3> first = skyFirstMoment(light);
    for (int c = 0; c < 3; ++c) {
      lit[size_t(c)] = mean[c] > 0;
      l[size_t(c)] = lit[size_t(c)] ? first[size_t(c)] / mean[c] : Vec3(0.0);
    }
  }
  std::vector<float> point(voxels);
  parallelFor(0, int64_t(voxels),
              [&](int64_t i) {
                const size_t v = size_t(i);
                const Vec3 b(vector[3 * v], vector[3 * v + 1], vector[3 * v + 2]);
                double sum = 0;
                for (int c = 0; c < 3; ++c) {
                  if (lit[size_t(c)]) sum += std::max(0.0, vis->data[v] + 3 * dot(l[size_t(c)], b));
                }
                point[v] = float(sum);
              },
              {kCheapIterationGrain});
  const std::vector<float> tally_mean = boxMean(bake->grid, point.data(), bake->tally_grid);
  const std::vector<float> mean =
      resampleTrilinear(bake->tally_grid, tally_mean.data(), 1, bake->grid);
  BakeChannel& out = bake->add(bake_grids::photonSkySingleScale(), 1);
  parallelFor(0, int64_t(voxels),
              [&](int64_t i) {
                const size_t v = size_t(i);
                const double p = point[v];
                out.data[v] =
                    p > 0 ? float(p / std::max(double(mean[v]), p / kMaxSkySingleScale)) : 0.f;
              },
              {kCheapIterationGrain});
}

}  // namespace

std::vector<Rgb> phaseLegendreCoefficients(const PhaseFunction& phase, int degree) {
  // Midpoint rule in theta: fine enough for a droplet's forward peak (about 1 degree wide).
  constexpr int kSteps = 20000;
  std::vector<Rgb> out(size_t(degree) + 1, Rgb(0.0));
  std::vector<double> p(size_t(degree) + 1);
  const double dtheta = kPi / kSteps;
  for (int k = 0; k < kSteps; ++k) {
    const double theta = (k + 0.5) * dtheta;
    const double mu = std::cos(theta);
    const Rgb f = phase.eval(mu) * (2 * kPi * std::sin(theta) * dtheta);
    legendreP(degree, mu, p.data());
    for (int l = 0; l <= degree; ++l) out[size_t(l)] += f * p[size_t(l)];
  }
  return out;
}

namespace {

// p convolved with the kernel once per scattering through the peak, weighted by the share of
// the peak's fluence that scattered through it that many times (PhotonPeakLight).
PhaseLut peakScatteredPhase(const PhaseLut& phase, const PeakKernel& kernel, const Rgb& r) {
  // 1024 bins (0.08 degrees at either end) keep the four convolutions a few milliseconds each.
  constexpr int kBins = 1024;
  constexpr int kTimes = 4;
  std::vector<PhaseLut> times;  // p convolved k = 1 .. kTimes times
  times.emplace_back(
      [&](double mu) { return kernel.convolve([&](double m) { return phase.eval(m); }, mu); },
      kBins);
  while (int(times.size()) < kTimes) {
    const PhaseLut& last = times.back();
    PhaseLut next(
        [&](double mu) { return kernel.convolve([&](double m) { return last.eval(m); }, mu); },
        kBins);
    times.push_back(std::move(next));
  }
  return PhaseLut(
      [&](double mu) {
        Rgb sum(0.0), share(1.0);  // r^(k - 1)
        for (int k = 0; k < kTimes; ++k) {
          const Rgb w = k + 1 < kTimes ? share * (Rgb(1.0) - r) : share;
          sum += w * times[size_t(k)].eval(mu);
          share *= r;
        }
        return sum;
      },
      kBins);
}

ForwardPeak cutAt(double cut_deg) {
  ForwardPeak split;
  split.cos_cut = std::cos(cut_deg * kPi / 180);
  return split;
}

/// What every kind of photon of one bake shares.
struct PhotonRun {
  const Medium& medium;
  const MajorantGrid& grid;
  const PhotonBakeOptions& options;
  Bounds3 box;                  // the bake's lattice bounds
  int channels;                 // 1 where every throughput stays grey, else 3
  const std::vector<Rgb>& p_l;  // the phase's Legendre coefficients
  BakedLight* bake;
};

// The error estimates of `tally` (whose odd photons are in `odd`) into the bake's metadata.
void recordErrors(const PhotonRun& r, const PhotonTally& tally, const PhotonTally& odd) {
  const PhotonErrorEstimate e = estimateErrors(
      tally, odd, r.p_l,
      resampleTrilinear(r.bake->grid, r.bake->density.data(), 1, r.bake->tally_grid));
  r.bake->metadata["cloudbake:tally_noise"] = str(e.tally_noise);
  r.bake->metadata["cloudbake:truncation"] = str(e.truncation);
}

// The sun's tallies, photonSh and photonZonal: all zero, with no photon traced, for a black sun
// (its light key says so).
void bakeSunPhotons(const PhotonRun& r, const Vec3& sun_dir, const ForwardPeak& split,
                    const std::function<bool(double)>& progress) {
  const PhotonBakeOptions& o = r.options;
  const SunEmitter sun(r.box, sun_dir, o.photons);
  PhotonTally tally(r.bake->tally_grid, o.order, sun.weight(), r.channels, o.zonal_order, -sun_dir);
  if (o.sun) {
    PhotonTally odd(r.bake->tally_grid, 0, sun.weight(), r.channels);
    PhotonTallies to;  // no tally for the light scattered through the peak only: PhotonPeakLight
    to.scattered = &tally;
    to.half = &odd;
    tracePhotons(r.medium, r.grid, sun, o.photons, o.seed, 1, to, &split, progress);
    recordErrors(r, tally, odd);
  }
  tally.store(r.bake, bake_grids::photonSh);
}

// The sky's tallies, photonSkySh and photonSkyDirectSh; under a black sun, the error estimates
// are the sky's.
void bakeSkyPhotons(const PhotonRun& r, const std::function<bool(double)>& progress) {
  const PhotonBakeOptions& o = r.options;
  std::optional<SkyLight> shape;
  if (o.sky_shape) shape.emplace(*o.sky_shape);
  const Rgb mean = shape ? meanSkyRadiance(*o.sky_shape, *shape) : Rgb(1.0);
  const SkyEmitter sky(r.box, o.photons, shape ? &*shape : nullptr, mean);
  // A sky whose shape differs per channel makes sky photons' weights chromatic.
  const int sky_channels = shape ? 3 : r.channels;
  PhotonTally tally(r.bake->tally_grid, o.order, sky.weight(), sky_channels);
  PhotonTally direct(r.bake->tally_grid, o.order, sky.weight(), sky_channels);
  std::optional<PhotonTally> odd;  // the error estimates' half, under a black sun only
  if (!o.sun) odd.emplace(r.bake->tally_grid, 0, sky.weight(), sky_channels);
  PhotonTallies to;
  to.scattered = &tally;
  to.direct = &direct;
  to.half = odd ? &*odd : nullptr;
  tracePhotons(r.medium, r.grid, sky, o.photons, o.seed, 2, to, nullptr, progress);
  if (odd) recordErrors(r, tally, *odd);
  tally.store(r.bake, bake_grids::photonSkySh);
  direct.store(r.bake, bake_grids::photonSkyDirectSh);
}

// The bake's knobs and its peak's cut in its metadata (docs/outputs.md); the cut to full
// precision, since views rebuild the peak's light from it.
void recordKnobs(const PhotonBakeOptions& options, const ForwardPeak& split, int tally_resolution,
                 double extinction, std::map<std::string, std::string>* m) {
  (*m)["cloudbake:angular_model"] = "sh";
  (*m)["cloudbake:photon_order"] = str(options.order);
  (*m)["cloudbake:photon_zonal_order"] =
      str(options.zonal_order > options.order ? options.zonal_order : 0);
  (*m)["cloudbake:photons"] = str(options.photons);
  (*m)["cloudbake:peak_cut_deg"] =
      split.active() ? str(std::acos(split.cos_cut) * 180 / kPi, 15) : "0";
  (*m)["cloudbake:peak_fraction"] = str(split.fraction);
  (*m)["cloudbake:tally_resolution"] = str(tally_resolution);
  (*m)["cloudbake:extinction"] = str(extinction);
  (*m)["cloudbake:sky"] = options.sky ? "baked" : "skipped (black sky)";
  (*m)["cloudbake:sun"] = options.sun ? "baked" : "skipped (black sun)";
}

}  // namespace

ForwardPeak photonPeakSplit(const PhaseFunction& phase, const PhotonBakeOptions& o) {
  // A peak narrower than the grid of angles the split integrates on makes every integral of it
  // wrong, the peak's share of scattering too: HG 0.9999 read 1.12 there and its views came out
  // 12 % bright, 0.99995 1.9x, 0.99999 infinite. Droplets' peaks (Mie tables up to r_eff 50 um)
  // integrate to 1 within 2e-4.
  const int top = std::max({o.order, o.zonal_order, kSpikeDegree});
  bool found = false;
  const ForwardPeak split = splitForwardPeak(phase, top, kMaxTopLegendre, kMaxCutDegrees, &found);
  double worst = 0, worst_integral = 1;
  for (int c = 0; c < 3; ++c) {
    const double error = std::abs(split.integral[c] - 1);
    if (!(error <= worst)) {
      worst = error;
      worst_integral = split.integral[c];
    }
  }
  if (!(worst <= kMaxPeakGridError)) {
    throw InputError(
        "/medium/phase: this phase's forward peak is narrower than method photon's "
        "grid of scattering angles resolves (steps of " +
        str(180.0 / kPeakGridSteps, 2) + " degrees): it integrates to " + str(worst_integral, 4) +
        " there, not 1 (an hg phase resolves up to g = 0.9995). Use method "
        "pathtrace, or a broader phase");
  }
  if (found) return split;
  throw InputError("/medium/phase: this phase's Legendre coefficient p_" + str(top) +
                   " stays above " + str(kMaxTopLegendre) + " with its forward " +
                   str(kMaxCutDegrees) +
                   " degrees cut off: a peak (a backward one?) narrower than method photon's "
                   "expansion to degree " +
                   str(std::max(o.order, o.zonal_order)) + " (order " + str(o.order) +
                   ", zonal_order " + str(o.zonal_order) +
                   ") can hold, and its views would ring. Use method pathtrace, a larger "
                   "zonal_order (at most " +
                   str(kMaxZonalDegree) + "), or a smaller phase.mie_ratio");
}

PhotonPeakLight::PhotonPeakLight(const PhaseLut& phase, double cut_deg, const Rgb& albedo)
    : PhotonPeakLight(phase, PeakKernel(cutAt(cut_deg), [&](double mu) { return phase.eval(mu); }),
                      albedo) {}

PhotonPeakLight::PhotonPeakLight(const PhaseLut& phase, const PeakKernel& kernel, const Rgb& albedo)
    : exponent(Rgb(1.0) - albedo * kernel.fraction()),
      scattered(peakScatteredPhase(phase, kernel, albedo * kernel.fraction())) {}

BakedLight bakePhoton(const Medium& medium, const Vec3& sun_dir, const PhotonBakeOptions& options,
                      const BakeProgressFn& progress) {
  validate(medium, sun_dir, options);
  const std::vector<Rgb> p_l = phaseLegendreCoefficients(
      *medium.phase, std::max({options.order, options.zonal_order, kSpikeDegree}));
  const ForwardPeak split = photonPeakSplit(*medium.phase, options);
  auto stage = [&](double lo, double span, const char* name) {
    return [&progress, lo, span, name](double f) {
      return !progress || progress(lo + span * f, name);
    };
  };
  if (progress && !progress(0, "lattice")) throw Cancelled("bake cancelled");
  auto t0 = std::chrono::steady_clock::now();
  BakedLight bake =
      makeBakeLattice(*medium.density, options.light_resolution, LatticeSampling::kFieldAligned);
  bake.method = "photon";
  bake.sun_direction = sun_dir;
  computeSunTransmittance(bake, sun_dir, medium.extinction, [&](double f, const std::string& s) {
    return !progress || progress(0.05 + 0.1 * f, s);
  });
  FirstTouchFloats sky_vector;  // the visibility's first moment, for addSkySingleScale
  if (options.sky) {
    std::vector<FirstTouchFloats> v = skyVisibilities(
        bake.grid, bake.density.data(), {medium.extinction},
        [&](double f, const std::string& s) { return !progress || progress(0.15 + 0.1 * f, s); },
        &sky_vector);
    bake.add(bake_grids::kSkyVisibility, 1).data = std::move(v[0]);
  }
  bake.metadata["cloudbake:seconds_lattice"] = str(secondsSince(t0));
  t0 = std::chrono::steady_clock::now();
  const int tally_resolution =
      options.tally_resolution > 0 ? options.tally_resolution : options.light_resolution;
  bake.tally_grid = options.tally_resolution > 0
                        ? bakeLatticeGeometry(medium.density->bounds(), tally_resolution,
                                              medium.density->describe(), "tally_resolution")
                        : bake.grid;
  const auto grid = medium.density->trackingGrid({medium.extinction, 0});
  // Grey albedo and phase keep every photon's throughput grey: one channel holds all three.
  const bool grey = !medium.phase->chromatic() && medium.albedo.x == medium.albedo.y &&
                    medium.albedo.y == medium.albedo.z;
  const int channels = grey ? 1 : 3;
  const PhotonRun run{medium, *grid, options, bake.grid.bounds(), channels, p_l, &bake};
  const double sky_share = !options.sky ? 0.0 : options.sun ? 0.35 : 0.75;
  bakeSunPhotons(run, sun_dir, split, stage(0.25, 0.75 - sky_share, "sun photons"));
  if (options.sky) {
    bakeSkyPhotons(run, stage(1.0 - sky_share, sky_share, "sky photons"));
    addSkySingleScale(&bake, sky_vector, options.sky_shape);
    FirstTouchFloats().swap(sky_vector);  // freed before Cd: the peak checkLimits counts
  }
  bake.metadata["cloudbake:seconds_photons"] = str(secondsSince(t0));
  recordKnobs(options, split, tally_resolution, medium.extinction, &bake.metadata);
  const Rgb peak_exponent = Rgb(1.0) - medium.albedo * split.fraction;
  addPhotonMeanRadiance(&bake, split.active() ? &peak_exponent : nullptr);
  bake.trimToSupport();
  if (progress && !progress(1, "done")) throw Cancelled("bake cancelled");
  return bake;
}

}  // namespace cloudbake
