// The view renderer of a bake (seed 000 "Final Rendering", Eq. 6-8; seed 004 "Volumetric
// Rendering"): a ray march through the baked grids, no scattering recomputed.
//
// Along a camera ray r(t) = o + t d (unit d, t in world units):
//   sigma_t(t) = medium.extinction * density(r(t))   (trilinear from bake.density)
//   T_v(t)     = exp(-integral_0^t sigma_t)           (view transmittance)
//   L          = integral T_v(t) S(t) dt + T_v(end) Lsky(d)
// with the in-scattered radiance S = sigma_s J towards the camera, sigma_s = albedo * sigma_t
// (RGB), and the source J (radiance per unit sigma_s) the sum of
//   sun single  J_ss  = E p(cos_s) Tsun(x), cos_s = dot(bake.sun_direction, d) (light travels
//                       along -sun_direction and leaves towards the camera along -d; constant
//                       per ray, so p is looked up once per ray); Tsun(x) by a short
//                       characteristic (BakeMarcher::sunTransmittanceAt): Tsun at the nearest
//                       lattice plane towards the sun, interpolated within the plane, times the
//                       segment's transmittance, its optical depth by Simpson's rule, going on
//                       plane by plane while the voxels around the plane's point differ by more
//                       than kSunCornerRatio; trilinear in optically thin blocks and in bakes
//                       without cloudbake:sun_transmittance_margin (written before); between
//                       two samples whose Tsun differ by more than that ratio, Tsun is taken as
//                       exponential in the view's optical depth (sunStep), not linear;
//   multiple    J_ms  = E a(Ldir . -d) Co, only with a Co grid, with the angular model the
//                       bake names in its metadata (cloudbake:angular_model):
//                       "beam" (seed 000 Eq. 8 with A_iso = 1 / (4 pi); the default):
//                         a = R p(dot(Ldir, -d)) + (1 - R) / (4 pi), the light a beam of fraction
//                         R along Ldir plus an isotropic rest;
//                       "p1" (the normalised pointcloud rule): the radiance expanded to first
//                         order, L(w) = Co (1 + 3 R Ldir.w) / (4 pi) (net flux R Co Ldir), whose
//                         convolution with any phase function of mean cosine g is
//                         a = max(0, 1 + 3 g R dot(Ldir, -d)) / (4 pi) per channel. The beam model
//                         puts the whole non-beam rest into the isotropic term, which overstates
//                         the light scattered against the flux (a slab seen from the lit side:
//                         2.4x too bright for HG 0.75); P1 is within 15% there.
//                       A missing mie_ratio grid means R = 0, and where light_dir is zero (or
//                       missing) only the isotropic part;
//                       "sh" (method photon): J_ms = E sum over l, m of p_l L_lm(x) Y_lm(-d),
//                       the Funk-Hecke convolution of the photons' radiance tally ms_sh_* with
//                       the phase's Legendre coefficients p_l, plus, with ms_zonal_<l>, the
//                       zonal degrees about the sun's axis, p_l Z_l sqrt((2l + 1) / (4 pi))
//                       P_l(d . sun), clamped at 0 (weighted per tally voxel for the direction
//                       to the eye where a view builds its field: BakeMarcher::buildViewField);
//                       the sky's tallies
//                       ms_sky_sh_* (scattered) and ss_sky_sh_* (unscattered: the sky's single
//                       scattering, replacing the ambient term) likewise, per unit sky radiance,
//                       the unscattered one split by delta-M along the phase's peak (weights
//                       p_l - f, f = p_(order+1), and f albedo L_sky(d) T(x, d) for the delta;
//                       a backward peak's mirror: addSkyPeak) and scaled by sky_single_scale
//                       (photonSkySingleScale) where the bake has it;
//                       where the bake split the phase's forward peak off
//                       (cloudbake:peak_cut_deg > 0), plus the sunlight scattered through that
//                       peak only, E p_peak(cos_s) (Tsun^e - Tsun) per channel
//                       (PhotonPeakLight: e = 1 - albedo x the peak's fraction, p_peak the phase
//                       convolved with the peak);
//   sky ambient J_sky = Lsky_mean Vsky(x), Lsky_mean the sky radiance averaged over the sphere,
//                       for bakes without the grids below;
//                       with sky_visibility_vector B (methods single and pointcloud), per
//                       channel (1 - f) Lsky_mean clamp(alpha Vsky + beta . B, 0, upper) +
//                       f Lsky(+-d) T(x, +-d): the phase's residual weights the product of the
//                       transmittance's and the sky's P1 expansions (P1RayWeights) and its peak
//                       f (delta-M; forward +, backward -) scatters the sky behind or in front
//                       of x on, in closed form along the ray (BakeMarcher::addSkyP1,
//                       sky_p1_scatter.h);
//                       or, when the bake holds sky_transmittance_sh_0..15 (method
//                       precomputed), seed 002's Eq. 5: J_sky = integral Lsky(w) T(x, w)
//                       p(w . d) dw = sum_i T_i(x) (Gamma y(d))_i (core/bake/sky_sh_scatter.h),
//                       view-dependent and for any sky, not only its mean;
//   sky multiple J_skm = Lsky_mean Co_sky(x) / (4 pi), only with a Co_sky grid (the normalised
//                       pointcloud rule bakes the sky's scattered light for a uniform sky); with
//                       sky_visibility_vector too, shaped as the sky light removed: Co_sky /
//                       (4 pi (1 - Vsky)) x (1 - J_sky per unit uniform sky) (skyMsShape);
// E = sun.irradiance (the baked grids are per unit E), p = medium.phase via a PhaseLut. Layers:
// sun = J_ss + J_ms terms, sky = J_sky + J_skm terms, single = J_ss + J_sky terms, multiple =
// J_ms + J_skm terms,
// beauty = sun + sky + T_v(end) Lsky(d), alpha = 1 - T_v(end). The march stops once T_v <
// options.min_transmittance; T_v(end) is then the value reached (< min_transmittance).
//
// Quadrature (seed 000: "the volume covered by each step is summed using trapezoidal
// integration"): per step of length dt between samples i and i+1, the optical depth is the
// trapezoid Delta = (sigma_i + sigma_{i+1}) dt / 2 and T_v(i+1) = T_v(i) exp(-Delta). The source
// is integrated trapezoidally in optical depth: J linear between the samples, sigma_t T_v
// integrated exactly over the step, which gives
//   integral = T_v(i) [w_i J_i + w_{i+1} J_{i+1}],  w_{i+1} = (1 - e^-Delta) / Delta - e^-Delta,
//                                                    w_i = (1 - e^-Delta) - w_{i+1}.
// For optically thin steps w_i = w_{i+1} = Delta / 2 + O(Delta^2): the plain trapezoid of
// T_v sigma_s J. Unlike the plain trapezoid it stays bounded (by J) when a step is optically
// thick (extinction 1e6), where the plain rule would return sigma_t dt / 2 times the source, and
// it is exact for a homogeneous medium with constant J. The trilinear density bends where the
// ray crosses a plane of voxel centres, and is 0 up to one of them where it enters the medium:
// the step that enters it, and those up to a voxel beyond, are split at those crossings
// (cellCrossings), so that the trapezoid does not spread a dense cloud's edge over a whole step.
//
// Empty space: per 8^3 block of the lattice (the VDB leaf size) the maximum density the trilinear
// lookup can return inside it; a 3D DDA (Amanatides & Woo 1987) over the blocks skips those whose
// maximum is 0. Density is exactly 0 there and on their faces, so T_v does not change and the
// skipped part of the integral is exactly 0; runs of non-empty blocks are marched with uniform
// steps of at most options.step. The march covers the whole support of the trilinear field,
// index coordinates (-1, n) per axis (half a voxel beyond BakeGrid::bounds()).
//
// Pixels: samples_per_pixel film positions on a jittered sqrt(spp) x sqrt(spp) grid (the rest
// uniform), one random stream per pixel from (seed, pixel), tiles of 16^2 pixels in parallel:
// the image does not depend on the thread count. spp = 1 is the pixel centre.
#include "core/bake/render_from_bake.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "core/bake/phase_lut.h"
#include "core/bake/photon_bake.h"
#include "core/bake/sky_p1_scatter.h"
#include "core/bake/sky_sh_scatter.h"
#include "core/bake/sparse_film.h"
#include "core/bake/sun_transmittance.h"
#include "core/error.h"
#include "core/format.h"
#include "core/math/branchless.h"
#include "core/math/large_array.h"
#include "core/math/parallel.h"
#include "core/math/rng.h"
#include "core/math/sh_basis.h"
#include "core/math/sphere_quadrature.h"
#include "core/math/vector_clones.h"
#include "core/transport/camera.h"
#include "core/transport/sky.h"
#include "core/transport/tiled_render.h"

namespace cloudbake {
namespace {

// The multiple term's angular model named by the bake (header comment); "beam" by default.
std::string angularModel(const BakedLight& bake) {
  auto it = bake.metadata.find("cloudbake:angular_model");
  return it == bake.metadata.end() ? "beam" : it->second;
}

constexpr int kBlock = 8;      // empty-space block side, voxels (an OpenVDB leaf)
constexpr int kTileSize = 16;  // pixels per tile side (work unit)
// Optical thickness of a voxel below which a view interpolates the sun's transmittance in 3D:
// its error along the sun is then under this^2 / 8 (docs/methods.md).
constexpr double kThinVoxelDepth = 0.25;
// The sun's trilinear transmittance below which a view keeps it as it is (sunTransmittanceAt
// would change light of at most this fraction of the sun's): deep in a thick cloud's shadow,
// where most of a backlit view's samples lie.
constexpr float kDarkSun = 1e-3f;
// The characteristic goes on to the next lattice plane towards the sun while the bake's
// transmittance at the voxels around its end differs by more than this ratio: interpolating it
// linearly there would be too bright (by at most (1 + r) / (2 sqrt(r)) - 1, 6 % at 2, where
// it falls exponentially), as it is where a low sun grazes a cloud's top or skims a thick
// cloud's rim. So these samples march towards the sun until the lattice is smooth around them.
constexpr float kSunCornerRatio = 2.0f;
// ... unless the light still to come through them is below this fraction of the sun's.
constexpr double kSunNegligible = 1e-4;
// The most lattice planes a march step crosses (kMaxStepVoxels + 1 per axis).
constexpr int kMaxCrossings = 3 * (int(kMaxStepVoxels) + 1);

void validateOptions(const BakeRenderOptions& o, double voxel_size) {
  if (!std::isfinite(o.step) || o.step < 0) {
    throw InputError("step: must be finite and >= 0 world units (0 = half a voxel), got " +
                     str(o.step));
  }
  // Far finer than any lattice needs; bounds the step count of a march.
  if (o.step > 0 && o.step < 1e-4 * voxel_size) {
    // (0 is the default, half a voxel, which the shot says by leaving `step` out.)
    throw InputError("step: must be at least 1e-4 voxel (" + str(1e-4 * voxel_size) +
                     " world units) or left out for half a voxel, got " + str(o.step));
  }
  // A run of non-empty blocks is marched from its first face to its last, so a step beyond
  // half a block puts no sample inside a lone block: the cloud would vanish from the view.
  if (o.step > kMaxStepVoxels * voxel_size) {
    throw InputError("step: must be at most " + str(kMaxStepVoxels) + " lattice voxels (" +
                     str(kMaxStepVoxels * voxel_size) +
                     " world units; a coarser step would pass over the cloud between its "
                     "samples), got " +
                     str(o.step));
  }
  if (o.samples_per_pixel < 1 || o.samples_per_pixel > kMaxViewSamples) {
    throw InputError("samples_per_pixel: must be in 1.." + std::to_string(kMaxViewSamples) +
                     ", got " + str(o.samples_per_pixel));
  }
  if (!(o.min_transmittance >= 0 && o.min_transmittance < 1)) {  // also rejects NaN
    throw InputError("min_transmittance: must be in [0, 1), got " + str(o.min_transmittance));
  }
  if (o.threads < 0 || o.threads > 4096) {
    throw InputError("threads: must be in 0..4096 (0 = the caller's arena), got " + str(o.threads));
  }
  if (o.max_film_spacing < 1 || o.max_film_spacing > kMaxFilmSpacing) {
    throw InputError("film_spacing: must be in 1.." + str(kMaxFilmSpacing) + " pixels, got " +
                     str(o.max_film_spacing));
  }
}

/// The channel `name` with `components` floats per voxel, or nullptr when absent (or, with
/// `required`, InputError); InputError too when it is not on the lattice `on_tally_grid` says.
const float* channel(const BakedLight& bake, const char* name, int components, bool required,
                     const std::string& why, bool on_tally_grid = false) {
  const auto it = bake.channels.find(name);
  if (it == bake.channels.end()) {
    if (required) throw InputError(std::string("bake: grid '") + name + "' is missing" + why);
    return nullptr;
  }
  const BakeChannel& ch = it->second;
  const BakeGrid& g = bake.gridOf(ch);
  const size_t expected = g.voxelCount() * size_t(components);
  if (ch.components != components || ch.data.size() != expected) {
    throw InputError(std::string("bake: grid '") + name + "': expected " + str(components) +
                     " component(s) and " + str(expected) + " values for the " + str(g.nx) + "x" +
                     str(g.ny) + "x" + str(g.nz) + " lattice, got " + str(ch.components) + " and " +
                     str(ch.data.size()));
  }
  if (ch.on_tally_grid != on_tally_grid) {
    throw InputError(
        std::string("bake: grid '") + name + "' must lie on the " +
        (on_tally_grid ? "tally lattice (cloudbake:tally_lattice)" : "bake's lattice"));
  }
  return ch.data.data();
}

/// The sun's term of one step, integral over [0, delta] of exp(-tau) Tsun(tau) in the view's
/// optical depth tau: Tsun linear between the step's ends (the weights w0, w1 of stepWeights),
/// or, where it changes by more than kSunCornerRatio across the step, exponential,
/// Tsun0 (Tsun1 / Tsun0)^(tau / delta): a sun that falls by e^7 across a step (a low sun grazing
/// a dense layer's top, seen from above) gave the linear rule half the step's first light, where
/// the light falls within a few per cent of the step.
inline double sunStep(double delta, double w0, double w1, double tsun0, double tsun1) {
  const double lo = std::min(tsun0, tsun1), hi = std::max(tsun0, tsun1);
  if (!(hi > kSunCornerRatio * lo)) return w0 * tsun0 + w1 * tsun1;
  const double floor = 1e-12 * hi;  // a zero end: a fall of 27.6 optical depths
  const double j0 = std::max(tsun0, floor), j1 = std::max(tsun1, floor);
  const double x = delta + std::log(j0 / j1);
  const double f = std::abs(x) < 1e-6 ? 1 - 0.5 * x : -std::expm1(-x) / x;
  return j0 * delta * f;
}

/// Weights of one step of the optical-depth trapezoid (see the file comment): transmittance
/// factor e = exp(-delta) and w0, w1 with integral = T(i) (w0 J_i + w1 J_{i+1}).
inline void stepWeights(double delta, double* e, double* w0, double* w1) {
  if (delta < 1e-3) {
    // Series: (1 - e) / delta - e cancels for small delta. Truncation < 2e-14 relative.
    const double a = delta * (1 - 0.5 * delta * (1 - delta / 3 * (1 - 0.25 * delta)));
    *e = 1 - a;
    *w1 = delta * (0.5 - delta * (1.0 / 3 - delta * (0.125 - delta / 30)));
    *w0 = a - *w1;
  } else {
    *e = std::exp(-delta);
    const double a = 1 - *e;
    *w1 = a / delta - *e;
    *w0 = a - *w1;
  }
}

/// The eight lattice voxels a trilinear lookup reads and their weights; voxels outside the
/// lattice get weight 0 (zero background) and a clamped, valid offset.
struct Corners {
  size_t offset[8];
  float weight[8];
};

/// Where a lookup reads the lattice: inside (all eight voxels exist; the common case) by the
/// lower corner's offset and the fractions, otherwise by explicit corners.
/// Floats of the march's packed record per voxel, at most (BakeMarcher::buildPack).
constexpr int kMaxRecord = 32;

struct Cell {
  double t = 0;      // distance of the point along the view ray (set by the march)
  double sigma = 0;  // extinction there (set by the march)
  bool interior = false;
  size_t base = 0;
  float fx = 0, fy = 0, fz = 0;
  Corners corners;
  alignas(16) float record[kMaxRecord];  // the packed record read here (BakeMarcher::read)
};

/// Trilinear interpolation from the lower corner `p` with the x, y and z strides in floats.
inline float lerp3(const float* p, size_t sx, size_t sy, size_t sz, float fx, float fy, float fz) {
  const float c00 = p[0] + fx * (p[sx] - p[0]);
  const float c10 = p[sy] + fx * (p[sy + sx] - p[sy]);
  const float c01 = p[sz] + fx * (p[sz + sx] - p[sz]);
  const float c11 = p[sz + sy] + fx * (p[sz + sy + sx] - p[sz + sy]);
  const float c0 = c00 + fy * (c10 - c00), c1 = c01 + fy * (c11 - c01);
  return c0 + fz * (c1 - c0);
}

/// lerp3 of each float of a record of N floats: a loop of a known length the compiler
/// vectorises, where the loop over a record's stride it is not told stays scalar or pays for its
/// run-time length (callgrind: two 640x480 views of bench/speed/view_mie.json took 5.64e9
/// instructions with that loop and 4.74e9 with this one for single's 8 floats; precomputed's
/// frame view of bench/speed/frames.json took 0.155 s with the loop over its 32 floats' stride
/// and 0.140 s with this one, and pointcloud's 16 floats 0.96x the instructions for the same
/// seconds). The same arithmetic per float, so the same bits.
template <size_t N>
inline void lerpRecordFixed(const float* __restrict p, size_t sy, size_t sz, float fx, float fy,
                            float fz, float* __restrict out) {
  for (size_t k = 0; k < N; ++k) out[k] = lerp3(p + k, N, sy, sz, fx, fy, fz);
}

/// lerp3 of each of a record's `stride` floats into out, 8 floats an instruction where the CPU
/// has AVX2: the records the views read (single's 8 floats under a sky, photon's view field of
/// 9, pointcloud's 16, precomputed's 32) by loops of their own length, any other of 16 or more
/// by the loop over the stride. False, with nothing read, for a shorter record of another length.
CLOUDBAKE_VECTOR_CLONES bool lerpRecordWide(const float* __restrict p, size_t stride, size_t sy,
                                            size_t sz, float fx, float fy, float fz,
                                            float* __restrict out) {
  switch (stride) {
    case 8:
      lerpRecordFixed<8>(p, sy, sz, fx, fy, fz, out);
      return true;
    case 9:
      lerpRecordFixed<9>(p, sy, sz, fx, fy, fz, out);
      return true;
    case 16:
      lerpRecordFixed<16>(p, sy, sz, fx, fy, fz, out);
      return true;
    case 32:
      lerpRecordFixed<32>(p, sy, sz, fx, fy, fz, out);
      return true;
    default:
      if (stride < 16) return false;
      for (size_t k = 0; k < stride; ++k) out[k] = lerp3(p + k, stride, sy, sz, fx, fy, fz);
      return true;
  }
}

/// Trilinear lookups on one lattice by index coordinates (voxel centres at integers); voxels
/// outside it read as zero.
class LatticeReader {
 public:
  explicit LatticeReader(const BakeGrid& g)
      : nx_(g.nx),
        ny_(g.ny),
        nz_(g.nz),
        stride_y_(size_t(g.nx)),
        stride_z_(size_t(g.nx) * size_t(g.ny)) {}

  /// Finds the cell of index point u.
  void locate(const Vec3& u, Cell* cell) const {
    if (u.x >= 0 && u.y >= 0 && u.z >= 0 && u.x < nx_ - 1 && u.y < ny_ - 1 && u.z < nz_ - 1) {
      const int i = int(u.x), j = int(u.y), k = int(u.z);
      cell->interior = true;
      cell->base = size_t(k) * stride_z_ + size_t(j) * stride_y_ + size_t(i);
      cell->fx = float(u.x - i);
      cell->fy = float(u.y - j);
      cell->fz = float(u.z - k);
    } else {
      cell->interior = false;
      corners(u, &cell->corners);
    }
  }

  /// Channels [first, first + count) of a packed lattice (`stride` floats per voxel, see
  /// packChannels) into out[first..]: the same arithmetic per channel as read(), so the same
  /// values, with the eight records read once for every channel.
  void readPacked(const float* pack, size_t stride, const Cell& c, int first, int count,
                  float* out) const {
    if (c.interior) {
      const float* p = pack + c.base * stride;
      const size_t sy = stride * stride_y_, sz = stride * stride_z_;
      for (int k = first; k < first + count; ++k) {
        out[k] = lerp3(p + k, stride, sy, sz, c.fx, c.fy, c.fz);
      }
      return;
    }
    for (int k = first; k < first + count; ++k) out[k] = 0;
    for (int q = 0; q < 8; ++q) {
      const float wq = c.corners.weight[q];
      const float* v = pack + c.corners.offset[q] * stride;
      for (int k = first; k < first + count; ++k) out[k] += wq * v[k];
    }
  }

  /// Every channel of a packed lattice, as readPacked (the same arithmetic per channel); the
  /// loop over channels compiles to vector instructions.
  void readRecord(const float* pack, size_t stride, const Cell& c, float* __restrict out) const {
    if (!c.interior) {
      readPacked(pack, stride, c, 0, int(stride), out);
      return;
    }
    const size_t sy = stride * stride_y_, sz = stride * stride_z_;
    if (lerpRecordWide(pack + c.base * stride, stride, sy, sz, c.fx, c.fy, c.fz, out)) return;
    const float* __restrict p = pack + c.base * stride;
    const float fx = c.fx, fy = c.fy, fz = c.fz;
    for (size_t k = 0; k < stride; ++k) out[k] = lerp3(p + k, stride, sy, sz, fx, fy, fz);
  }

  /// The smallest and largest of float `slot` (of `stride` per voxel) over the voxels a lookup
  /// at c reads with a weight above 0. c must be interior (the characteristic stops before any
  /// other).
  void cornerRange(const float* data, size_t stride, int slot, const Cell& c, float* lo,
                   float* hi) const {
    *lo = std::numeric_limits<float>::max();
    *hi = std::numeric_limits<float>::lowest();
    for (int q = 0; q < 8; ++q) {
      const bool x = q & 1, y = q & 2, z = q & 4;
      if ((x ? c.fx : 1 - c.fx) > 0 && (y ? c.fy : 1 - c.fy) > 0 && (z ? c.fz : 1 - c.fz) > 0) {
        const size_t voxel = c.base + (x ? 1 : 0) + (y ? stride_y_ : 0) + (z ? stride_z_ : 0);
        *lo = std::min(*lo, data[voxel * stride + size_t(slot)]);
        *hi = std::max(*hi, data[voxel * stride + size_t(slot)]);
      }
    }
  }

  /// read() of one float of a record of `stride` floats per voxel, p at the cell's first
  /// record (the same arithmetic, so the same value).
  float lerpAt(const float* p, size_t stride, float fx, float fy, float fz) const {
    return lerp3(p, stride, stride * stride_y_, stride * stride_z_, fx, fy, fz);
  }

  float read(const float* data, const Cell& c) const {
    if (c.interior) return lerp3(data + c.base, 1, stride_y_, stride_z_, c.fx, c.fy, c.fz);
    float v = 0;
    for (int q = 0; q < 8; ++q) v += c.corners.weight[q] * data[c.corners.offset[q]];
    return v;
  }

  /// Reads a 3-component (interleaved) channel.
  void read3(const float* data, const Cell& c, float out[3]) const {
    if (c.interior) {
      const float* p = data + 3 * c.base;
      for (int k = 0; k < 3; ++k) {
        out[k] = lerp3(p + k, 3, 3 * stride_y_, 3 * stride_z_, c.fx, c.fy, c.fz);
      }
      return;
    }
    out[0] = out[1] = out[2] = 0;
    for (int q = 0; q < 8; ++q) {
      const float wq = c.corners.weight[q];
      const float* v = data + 3 * c.corners.offset[q];
      out[0] += wq * v[0];
      out[1] += wq * v[1];
      out[2] += wq * v[2];
    }
  }

 private:
  /// Corner offsets and weights of the trilinear lookup at index point u.
  void corners(const Vec3& u, Corners* c) const {
    size_t o[3][2];
    float f[3][2];
    const int n[3] = {nx_, ny_, nz_};
    const size_t stride[3] = {1, stride_y_, stride_z_};
    for (int a = 0; a < 3; ++a) {
      double fl = std::floor(u[a]);
      fl = std::min(std::max(fl, -1.0), double(n[a] - 1));
      const int i0 = int(fl);
      const float t = float(std::min(std::max(u[a] - fl, 0.0), 1.0));
      int lo = i0, hi = i0 + 1;
      float wlo = 1 - t, whi = t;
      if (lo < 0) {
        lo = 0;
        wlo = 0;
      }
      if (hi > n[a] - 1) {
        hi = n[a] - 1;
        whi = 0;
      }
      o[a][0] = size_t(lo) * stride[a];
      o[a][1] = size_t(hi) * stride[a];
      f[a][0] = wlo;
      f[a][1] = whi;
    }
    int q = 0;
    for (int k = 0; k < 2; ++k) {
      for (int j = 0; j < 2; ++j) {
        const float wjk = f[2][k] * f[1][j];
        const size_t ojk = o[2][k] + o[1][j];
        for (int i = 0; i < 2; ++i, ++q) {
          c->offset[q] = ojk + o[0][i];
          c->weight[q] = wjk * f[0][i];
        }
      }
    }
  }

  int nx_, ny_, nz_;
  size_t stride_y_, stride_z_;
};

/// One channel of a packed lattice: `components` floats per voxel from `data` (voxel-major,
/// components interleaved) into the record's floats from `slot` on.
struct PackedChannel {
  const float* data = nullptr;
  int components = 1;
  int slot = 0;
};

/// The channels interleaved in one record of `stride` floats per voxel (unused floats 0): a
/// trilinear lookup then reads eight contiguous records instead of eight voxels of every grid,
/// which is what the march's reads cost (issue 18's profile: scattered loads, not arithmetic).
void packChannels(const std::vector<PackedChannel>& channels, size_t voxels, size_t stride,
                  float* pack) {
  constexpr size_t kChunk = 1 << 14;
  // Voxels whose records stay in the core's cache while every channel is copied into them: a
  // photon tally's records are up to 208 floats, and a chunk's 13 MB of them went through
  // memory once per channel (69 times), a tenth of a small photon view.
  constexpr size_t kBlock = 64;
  parallelFor(0, int64_t((voxels + kChunk - 1) / kChunk), [&](int64_t chunk) {
    const size_t v0 = size_t(chunk) * kChunk, v1 = std::min(voxels, v0 + kChunk);
    for (size_t b0 = v0; b0 < v1; b0 += kBlock) {
      const size_t b1 = std::min(v1, b0 + kBlock);
      // Zeroed here, in parallel: the slots no channel fills read as 0.
      std::fill(pack + b0 * stride, pack + b1 * stride, 0.f);
      for (const PackedChannel& ch : channels) {
        const size_t n = size_t(ch.components);
        for (size_t v = b0; v < b1; ++v) {
          float* out = pack + v * stride + size_t(ch.slot);
          const float* in = ch.data + v * n;
          for (size_t k = 0; k < n; ++k) out[k] = in[k];
        }
      }
    }
  });
}

bool operator==(const PackedChannel& a, const PackedChannel& b) {
  return a.data == b.data && a.components == b.components && a.slot == b.slot;
}

}  // namespace

/// The cached blocks and packs, each with the key it was built for (BakeViewCache).
struct BakeViewCache::Impl {
  struct Blocks {
    const float* density = nullptr;  // null: none built
    int nx = 0, ny = 0, nz = 0;
    std::vector<float> max;  // per 8^3 block, dilated by a voxel (BakeMarcher::buildBlockMax)
    double max_density = 0;
    std::vector<uint8_t> occupied;  // per cell: any of its 8 voxels' density is not 0
  };
  struct Pack {
    std::vector<PackedChannel> layout;
    size_t voxels = 0, stride = 0;
    LargeArray<float> data;
  };
  // photon's light scattered through a droplet's peak (PhotonPeakLight): four convolutions of
  // the phase, the same for every view of a bake, keyed on the phase's table itself.
  struct Peak {
    std::optional<PhaseLut> phase;  // none: none built
    double cut_deg = 0;
    Rgb albedo;
    std::optional<PhotonPeakLight> light;
  };
  Blocks blocks;
  Pack march, tally;  // the march's record per voxel; photon's tallies per voxel of theirs
  Peak peak;
  int builds = 0;

  const PhotonPeakLight& peakLight(const PhaseLut& phase, double cut_deg, const Rgb& albedo) {
    Peak& p = peak;
    if (!p.phase || !(*p.phase == phase) || p.cut_deg != cut_deg || !(p.albedo == albedo)) {
      p.phase.reset();  // no key while it is built
      p.light.emplace(phase, cut_deg, albedo);
      p.cut_deg = cut_deg;
      p.albedo = albedo;
      p.phase.emplace(phase);
      ++builds;
    }
    return *p.light;
  }

  /// The pack of `channels`, built unless the last one of *p had the same key.
  const float* pack(Pack* p, const std::vector<PackedChannel>& channels, size_t voxels,
                    size_t stride) {
    if (p->layout.empty() || p->layout != channels || p->voxels != voxels || p->stride != stride) {
      p->layout.clear();  // no key while it is built
      if (p->data.size() != voxels * stride) {
        p->data = LargeArray<float>();  // the old one's memory goes before the new one's comes
        p->data = LargeArray<float>(voxels * stride);
      }
      packChannels(channels, voxels, stride, p->data.data());
      p->layout = channels;
      p->voxels = voxels;
      p->stride = stride;
      ++builds;
    }
    return p->data.data();
  }
};

BakeViewCache::BakeViewCache() : impl_(std::make_unique<Impl>()) {}
BakeViewCache::~BakeViewCache() = default;
void BakeViewCache::forget() {
  // The peak's light is keyed on the values it was built from, whatever the bake: it stays.
  impl_->blocks.density = nullptr;
  impl_->march.layout.clear();
  impl_->tally.layout.clear();
}
int BakeViewCache::builds() const { return impl_->builds; }

namespace {

/// Per-pixel sums of the layers (radiance per the lights' units).
struct PixelSum {
  Rgb sun_single, multiple, sky, sky_multiple, background;
  double alpha = 0;
};

/// Where a view's rays come from: every ray of a pinhole camera leaves `eye`; every ray of an
/// orthographic camera travels along `forward`. `rays` is how many the view traces; `cancelled`
/// is polled while a field is built for the view (BakeMarcher::buildViewField).
struct ViewGeometry {
  bool pinhole = true;
  Vec3 eye, forward;
  double rays = 0;
  std::function<bool(double)> cancelled;
};

/// Everything constant over a render: the grids, the block maxima and the lights.
class BakeMarcher {
 public:
  BakeMarcher(const BakedLight& bake, const Medium& medium, const Sun& sun, const SkyLight& sky,
              const Rgb& sky_mean, const Vec3& sun_dir, double step, double min_transmittance,
              const ViewGeometry& view, BakeViewCache::Impl& cache)
      : grid_(bake.grid),
        lattice_(bake.grid),
        density_(bake.density.data()),
        sky_(sky),
        lut_(*medium.phase),
        g_(medium.phase->meanCosine()),
        p1_(angularModel(bake) == "p1"),
        phase_grey_(!medium.phase->chromatic()),
        sun_dir_(sun_dir),
        extinction_(medium.extinction),
        step_(step),
        min_transmittance_(min_transmittance),
        cache_(cache) {
    tsun_ = channel(bake, bake_grids::kSunTransmittance, 1, true, "");
    // The bake holds the sun's transmittance where the short characteristic reads it.
    sun_characteristic_ = bake.metadata.count(kSunTransmittanceMarginKey) > 0;
    for (int a = 1; a < 3; ++a) {
      if (std::abs(sun_dir[a]) > std::abs(sun_dir[sun_axis_])) sun_axis_ = a;
    }
    if (!sky.black()) {
      vsky_ = channel(bake, bake_grids::kSkyVisibility, 1, true, " (needed under a non-black sky)");
    }
    if (!sky.black()) csky_ = channel(bake, bake_grids::kSkyMultipleFluence, 3, false, "");
    if (!sky.black() && bake.find(bake_grids::skyTransmittanceSh(0))) {
      // Seed 002's Eq. 5: the view-dependent sky term from the transmittance's SH vector.
      for (int i = 0; i < kShCoefficients; ++i) {
        sh_[size_t(i)] = channel(bake, bake_grids::skyTransmittanceSh(i).c_str(), 1, true, "");
      }
      sky_sh_.emplace(projectSkyRadiance(sky), lut_);
      albedo_ = medium.albedo;
      Sky unit;
      unit.radiance = Rgb(1.0);
      if (csky_) sky_unit_sh_.emplace(projectSkyRadiance(SkyLight(unit)), lut_);
    } else if (!sky.black()) {
      svec_ = channel(bake, bake_grids::kSkyVisibilityVector, 3, false, "");
      if (svec_) {
        const std::array<std::array<double, 4>, 3> lambda = phaseEigenvalues(lut_);
        for (int c = 0; c < 3; ++c) {
          sky_split_[size_t(c)] = deltaSplit(lambda[size_t(c)][1], lambda[size_t(c)][2]);
          const bool peak = sky_split_[size_t(c)].f > 0;
          forward_peak_ = forward_peak_ || (peak && !sky_split_[size_t(c)].backward);
          backward_peak_ = backward_peak_ || (peak && sky_split_[size_t(c)].backward);
        }
        // The sky's first moment over its mean per channel: a non-uniform sky's P1 part.
        const std::array<Vec3, 3> l1 = skyFirstMoment(sky);
        for (int c = 0; c < 3; ++c) {
          sky_l_[size_t(c)] = sky_mean[c] > 0 ? l1[size_t(c)] / sky_mean[c] : Vec3(0.0);
          sky_uniform_ = sky_uniform_ && sky_l_[size_t(c)] == Vec3(0.0);
          sky_g_res_[c] = sky_split_[size_t(c)].g_residual;
        }
        sky_split_grey_ = phase_grey_ && sky_uniform_;
        albedo_ = medium.albedo;
      }
    }
    if (angularModel(bake) == "sh") {
      loadPhotonTallies(bake, medium, sky);
      const BakeGrid& tally_grid = tally_ ? bake.tally_grid : bake.grid;
      buildViewField(tally_grid, view);
      // Samples the field does not serve weight the coefficients per ray, read from a pack of
      // them per voxel: a view whose field serves every sample needs none (at the default knobs
      // with a droplet phase, 207 floats a voxel, 54 MB, a sixth of a view's time).
      if (!fieldServesEverySample(view)) buildTallyPack(tally_grid.voxelCount());
    }
    co_ = channel(bake, bake_grids::kMultipleFluence, 3, false, "");
    if (co_) {
      ldir_ = channel(bake, bake_grids::kLightDir, 3, false, "");
      mie_ = channel(bake, bake_grids::kMieRatio, 1, false, "");
    }
    nx_ = grid_.nx;
    ny_ = grid_.ny;
    nz_ = grid_.nz;
    stride_y_ = size_t(nx_);
    stride_z_ = size_t(nx_) * size_t(ny_);
    inv_h_ = 1.0 / grid_.voxel_size;
    scale_ss_ = medium.albedo * sun.irradiance;
    scale_ms_ = medium.albedo * sun.irradiance;
    scale_sky_ = medium.albedo * sky_mean;
    buildBlockMax();
    buildPack();
    thick_density_ = kThinVoxelDepth / (extinction_ * grid_.voxel_size);
  }

  /// Per-thread scratch of trace, reused from ray to ray: photon's per-ray phase weights,
  /// written before they are read (zeroing 2.5 kB a ray was a tenth of a `single` view's
  /// per-ray cost).
  struct Scratch {
    // Photon tallies: p_l Y_lm(-d) per coefficient, then the zonal terms'.
    Rgb shw[shCount(kMaxShDegree) + kMaxZonalDegree];
    Rgb shw_ss[shCount(kMaxShDegree)];  // the sky single scattering's (phaseWeights)
  };

  /// Marches `ray` (unit direction) and adds its layers to `sum`.
  void trace(const Ray& ray, PixelSum* sum, Scratch* scratch) const {
    RayState s;
    s.d = ray.d;
    if (svec_) s.p1w = p1RayWeights(sky_l_, sky_g_res_, ray.d);
    s.shw = scratch->shw;
    s.shw_ss = ssky_sh_.empty() ? nullptr : scratch->shw_ss;
    // Block space: w = index + 1, so the support of the trilinear field, index in (-1, n),
    // is w in (0, n + 1).
    s.w0 = (ray.o - grid_.origin) * inv_h_ + Vec3(1.0);
    s.dw = ray.d * inv_h_;
    if (!isFinite(s.w0) || !isFinite(s.dw)) return;
    double t_in = 0, t_out = 0;
    if (domainSpan(s.w0, s.dw, &t_in, &t_out)) march(&s, t_in, t_out);
    if (s.ss > 0) sum->sun_single += lut_.eval(dot(sun_dir_, ray.d)) * scale_ss_ * s.ss;
    if (svec_) {
      // A backward peak sees the sky in front of each sample through the medium between the
      // camera and the lattice's face behind it too (an outside probe: a camera inside a
      // sphere of HG -0.9 was 14.6x the path tracer's without it).
      const double t_back = backward_peak_ && s.tau > 0 ? transmittanceBehind(ray, s) : 1.0;
      addSkyP1(ray.d, t_back, &s, sum);
    } else if (s.sky > 0) {
      sum->sky += scale_sky_ * s.sky;
    }
    sum->sky += scale_sky_ * s.sky_ss;
    if (ssky_delta_) addSkyPeak(ray, s, sum);
    addSkyShTerms(ray.d, &s, sum);
    sum->sky_multiple += scale_sky_ * s.sky_ms;
    sum->multiple += s.ms;
    sum->alpha += 1 - s.transmittance;
    if (s.transmittance > 0 && !sky_.black()) {
      sum->background += sky_.radiance(ray.d) * s.transmittance;
    }
  }

 private:
  /// The tallies' in-scattered light at t = k x tally_dt_ along a ray.
  struct TallyAnchor {
    int64_t k = std::numeric_limits<int64_t>::min();
    Rgb ms, ssky, csky;
  };

  struct RayState {
    Vec3 w0, dw, d;
    double transmittance = 1;
    double ss = 0, sky = 0;  // integrals of T_v sigma_t Tsun and T_v sigma_t Vsky
    // With sky_visibility_vector: integral of T_v sigma_t J~ (the residual's sky scattering per
    // unit sky, sky_p1_scatter.h), the optical depth marched, and the peak's share of the
    // shaped sky multiple term (skyPeakSums)
    Rgb sky_res;
    double tau = 0;
    Rgb sky_peak_ahead, sky_peak_behind;
    P1RayWeights p1w;                     // the P1 residual's weights for this ray's direction
    Rgb ms;                               // integral of T_v sigma_t J_ms, scaled
    Rgb sky_ms;                           // integral of T_v sigma_t Co_sky / (4 pi)
    Rgb sky_ss;                           // integral of T_v sigma_t J_sky (photon tally)
    double sky_sh[kShCoefficients] = {};  // integrals of T_v sigma_t T_sky,i (Eq. 5)
    // precomputed: integrals of T_v sigma_t f T_sky,i, channel-major ([c][i]) so the march's
    // sums run over i in vector registers
    double sky_ms_sh[3][kShCoefficients] = {};
    Rgb* shw = nullptr;          // photon: the per-ray weights, in the caller's Scratch
    Rgb* shw_ss = nullptr;       // and the sky single scattering's
    bool weights_ready = false;  // shw (rayWeights)
    Rgb peak_phase;              // photon: PhotonPeakLight::scattered towards the camera
    bool peak_ready = false;     // peak_phase (peakPhase)
    TallyAnchor anchor[2];       // the last two tally anchors along the ray (tallySources)
    bool done = false;
  };

  /// The span [t_in, t_out] (world units, t >= 0) of a block-space ray w0 + dw t inside the
  /// trilinear field's support, w in (0, n + 1); false where it misses.
  bool domainSpan(const Vec3& w0, const Vec3& dw, double* t_in, double* t_out) const {
    Bounds3 domain;
    domain.min = Vec3(0.0);
    domain.max = Vec3(nx_ + 1, ny_ + 1, nz_ + 1);
    return intersectBounds(domain, Ray{w0, dw}, 0.0, std::numeric_limits<double>::infinity(), t_in,
                           t_out) &&
           *t_out > *t_in;
  }

  /// The transmittance from the ray's origin back along -d to where it leaves the lattice
  /// (marchTransmittance, the view's step): 1 for an origin outside it.
  double transmittanceBehind(const Ray& ray, const RayState& s) const {
    double t_in = 0, t_out = 0;
    // A line meets the box in one interval: from an origin outside it, nothing lies behind.
    if (!domainSpan(s.w0, -s.dw, &t_in, &t_out) || t_in > 0) return 1.0;
    return marchTransmittance(grid_, density_, extinction_, ray.o, -ray.d, step_);
  }

  // The sky's single scattering of bakes with sky_visibility_vector (sky_p1_scatter.h): per
  // channel, the phase's residual weights the transmittance's P1 expansion (mean sky
  // radiance), and its peak scatters the sky straight behind (forward) or in front (backward)
  // of each sample, in closed form along the ray (peakSky).
  void addSkyP1(const Vec3& d, double t_back, RayState* s, PixelSum* sum) const {
    if (!(s->tau > 0)) return;
    const double t_end = s->transmittance;
    Rgb ahead, behind;  // what the forward and the backward peak scatter
    if (forward_peak_) ahead = peakSky(d, t_back, *s, false);
    if (backward_peak_) behind = peakSky(d, t_back, *s, true);
    for (int c = 0; c < 3; ++c) {
      const DeltaSplit& split = sky_split_[size_t(c)];
      const double peak = split.backward ? behind[c] : ahead[c];
      sum->sky[c] += scale_sky_[c] * s->sky_res[c] + split.f * albedo_[c] * peak;
      if (!csky_) continue;
      // The shaped multiple term's complement of the peak (skyMsShape).
      const double peak_ms =
          split.backward ? t_back * s->sky_peak_behind[c] : t_end * s->sky_peak_ahead[c];
      s->sky_ms[c] = std::max(0.0, s->sky_ms[c] - split.f * peak_ms);
    }
  }

  // The integral along the ray of T_v sigma_t L T of the sky a phase's peak scatters on
  // (addSkyP1's and addSkyPeak's): a forward peak the sky straight behind each sample,
  // L(d) T(x, d), and along the ray T_v(t) T(x, d) is the ray's whole transmittance, so the
  // integral is L(d) T_v(end) tau; a backward one the sky in front, L(-d) T(x, -d) =
  // L(-d) T_v t_back (t_back: transmittanceBehind), whose integral is
  // L(-d) t_back (1 - T_v(end)^2) / 2.
  Rgb peakSky(const Vec3& d, double t_back, const RayState& s, bool backward) const {
    const double t_end = s.transmittance;
    return backward ? sky_.radiance(-d) * (t_back * 0.5 * (1 - t_end * t_end))
                    : sky_.radiance(d) * (t_end * s.tau);
  }

  // photon's delta-M peak of the sky's single scattering (loadPhotonTallies): f albedo times
  // peakSky.
  void addSkyPeak(const Ray& ray, const RayState& s, PixelSum* sum) const {
    if (!(s.tau > 0)) return;
    const double t_back = ssky_backward_ ? transmittanceBehind(ray, s) : 1.0;
    sum->sky += ssky_peak_ * peakSky(ray.d, t_back, s, ssky_backward_);
  }

  // Seed 002's Eq. 5 terms of the sky (precomputed's bakes): its single scattering and the
  // view-dependent shape of its multiple scattering, from the ray's SH sums.
  void addSkyShTerms(const Vec3& d, RayState* s, PixelSum* sum) const {
    // The sky's SH terms weight sums that stay exactly 0 on a ray that met no medium: their
    // weights (243 products each, issue 18's frame profile) are then skipped, with the same
    // result.
    if (sky_sh_ &&
        std::any_of(std::begin(s->sky_sh), std::end(s->sky_sh), [](double v) { return v != 0; })) {
      double wts[3 * kShCoefficients];
      sky_sh_->weights(d, wts);
      Rgb sky_single;
      for (int c = 0; c < 3; ++c) {
        double v = 0;
        for (int i = 0; i < kShCoefficients; ++i) v += s->sky_sh[i] * wts[c * kShCoefficients + i];
        sky_single[c] = albedo_[c] * std::max(0.0, v);
      }
      sum->sky += sky_single;
    }
    if (!sky_unit_sh_) return;
    // Precomputed: the scattered sky light seen along d, f (1 - integral T p), f per unit (see
    // SkyMsShape).
    const bool met = std::any_of(&s->sky_ms_sh[0][0], &s->sky_ms_sh[0][0] + 3 * kShCoefficients,
                                 [](double v) { return v != 0; });
    double wts[3 * kShCoefficients];
    if (met) sky_unit_sh_->weights(d, wts);
    for (int c = 0; c < 3; ++c) {
      double v = 0;
      for (int i = 0; met && i < kShCoefficients; ++i) {
        v += s->sky_ms_sh[c][i] * wts[c * kShCoefficients + i];
      }
      s->sky_ms[c] = std::max(0.0, s->sky_ms[c] - v);
    }
  }

  // Method photon's tallies (angular model "sh"): radiance coefficients of scattered sun and
  // sky light, and the phase's Legendre coefficients for the Funk-Hecke convolution.
  void loadPhotonTallies(const BakedLight& bake, const Medium& medium, const SkyLight& sky) {
    const auto it = bake.metadata.find("cloudbake:photon_order");
    int order = 0;
    try {
      order = it == bake.metadata.end() ? 0 : std::stoi(it->second);
    } catch (const std::exception&) {
      order = 0;
    }
    if (order < 1 || order > kMaxShDegree) {
      throw InputError("bake: metadata cloudbake:photon_order must be in 1.." + str(kMaxShDegree) +
                       " for angular model 'sh'");
    }
    sh_order_ = order;
    useTallyLattice(bake);
    const bool on = tally_.has_value();
    auto tally = [&](const std::string& name) {
      return channel(bake, name.c_str(), 3, true, "", on);
    };
    for (int i = 0; i < shCount(order); ++i) msh_.push_back(tally(bake_grids::photonSh(i)));
    if (!sky.black() && bake.find(bake_grids::photonSkySh(0))) {
      for (int i = 0; i < shCount(order); ++i) {
        msky_sh_.push_back(tally(bake_grids::photonSkySh(i)));
      }
    }
    // The sky's single scattering from the tally of its unscattered light, for the view's
    // direction and the whole phase, instead of the isotropic ambient term.
    if (!sky.black() && bake.find(bake_grids::photonSkyDirectSh(0))) {
      for (int i = 0; i < shCount(order); ++i) {
        ssky_sh_.push_back(tally(bake_grids::photonSkyDirectSh(i)));
      }
      // Its amount at the point, from the finer lattice (photonSkySingleScale; since photon 14).
      sscale_ = channel(bake, bake_grids::photonSkySingleScale().c_str(), 1, false, "");
    }
    zonal_order_ = photonZonalOrder(bake, order);
    zonal_sinc_.assign(size_t(zonal_order_) + 1, 0.0);
    for (int l = 1; l <= zonal_order_; ++l) {
      const double x = kPi * l / (zonal_order_ + 1);
      zonal_sinc_[size_t(l)] = 1 - std::sin(x) / x;  // zonalTaper's, once per degree
    }
    for (int l = order + 1; l <= zonal_order_; ++l) {
      msh_.push_back(tally(bake_grids::photonZonal(l)));
    }
    const double cut_deg = peakCutDegrees(bake);
    if (cut_deg > 0) peak_ = &cache_.peakLight(lut_, cut_deg, medium.albedo);
    phase_l_ = phaseLegendreCoefficients(*medium.phase, std::max(order + 1, zonal_order_));
    if (!ssky_sh_.empty()) {
      // delta-M (Wiscombe 1977) for the sky's single scattering: the phase's degrees above the
      // order are taken as a delta of weight f along its peak, which scatters the sky straight
      // behind (a forward peak) or in front of (a backward one) each sample on (addSkyPeak),
      // and the tally's degrees are convolved with p_l - f (forward) or p_l - (-1)^l f
      // (backward: the delta's Legendre coefficients), f = |p_(order+1)| where its sign is the
      // peak's. Truncated without it, a forward-peaked phase scatters a dense cloud's lit
      // hemisphere back towards a camera in front of it; a backward split taken as a forward one
      // made a sphere of HG -0.8 seen from below against a bright zenith 17x too bright.
      ssky_backward_ = phase_l_[1].x < 0 && phase_l_[1].y < 0 && phase_l_[1].z < 0;
      const bool forward = phase_l_[1].x > 0 && phase_l_[1].y > 0 && phase_l_[1].z > 0;
      const double sign = (order + 1) % 2 == 0 ? 1.0 : -1.0;  // the backward delta's p_(order+1)
      Rgb f(0.0);                                             // the delta's weight per channel
      for (int c = 0; c < 3; ++c) {
        const double p = phase_l_[size_t(order + 1)][c];
        f[c] = forward          ? std::clamp(p, 0.0, 1.0)
               : ssky_backward_ ? std::clamp(sign * p, 0.0, 1.0)
                                : 0.0;
      }
      ssky_delta_ = maxComponent(f) > 0;
      ssky_peak_ = f * medium.albedo;
      for (int l = 0; l <= order; ++l) {
        ssky_p_l_.push_back(phase_l_[size_t(l)] - (ssky_backward_ && l % 2 ? -1.0 : 1.0) * f);
      }
    }
  }

  // The photon tallies' coefficients packed per voxel of their lattice: the radiance first, then
  // the sky's unscattered and scattered light.
  void buildTallyPack(size_t voxels) {
    std::vector<PackedChannel> ch;
    int slot = 0;
    auto add = [&](const std::vector<const float*>& grids) {
      const int first = slot;
      for (const float* g : grids) {
        ch.push_back({g, 3, slot});
        slot += 3;
      }
      return first;
    };
    add(msh_);
    ssky_slot_ = add(ssky_sh_);
    msky_slot_ = add(msky_sh_);
    tally_floats_ = slot;
    tally_stride_ = size_t((slot + 3) / 4 * 4);
    tally_pack_ = cache_.pack(&cache_.tally, ch, voxels, tally_stride_);
  }

  // Where the tallies lie on a lattice of their own: its reader, and the map from the bake
  // lattice's index coordinates to its own.
  void useTallyLattice(const BakedLight& bake) {
    const BakeChannel* first = bake.find(bake_grids::photonSh(0));
    if (!first || !first->on_tally_grid) return;
    const BakeGrid& t = bake.tally_grid;
    tally_.emplace(t);
    tally_scale_ = grid_.voxel_size / t.voxel_size;
    tally_offset_ = (grid_.origin - t.origin) / t.voxel_size;
    tally_dt_ = 0.5 * t.voxel_size;
  }

  /// The photon tallies' per-ray weights: computed when the ray first reads a tally without the
  /// view's field, so the rays that miss the cloud (most of a view's pixels, often) skip their
  /// dozens of SH terms. Not inlined: its 1.2 kB of basis values would weigh on the stack frame
  /// of every anchor and sample that reads the view's field instead.
  [[gnu::noinline]] void rayWeights(RayState* s) const {
    s->weights_ready = true;
    if (sh_order_ > 0) phaseWeights(s->d, s->shw, s->shw_ss);
  }

  /// The weights w_i of the tallies' coefficients for light leaving towards the camera along -d
  /// (d the direction of travel of the view's ray). Funk-Hecke: the light travelling along w'
  /// scatters towards the camera with p(w' . -d), so J(-d) = sum over l, m of p_l L_lm Y_lm(-d).
  /// `w_ss` (shCount(order) entries, or null) receives the sky single scattering's, split by
  /// delta-M: (p_l - f) Y_lm(-d).
  void phaseWeights(const Vec3& d, Rgb* w, Rgb* w_ss) const {
    double y[shCount(kMaxShDegree)];
    shBasisUpTo(sh_order_, -d, y);
    for (int l = 0; l <= sh_order_; ++l) {
      for (int i = l * l; i < (l + 1) * (l + 1); ++i) w[i] = phase_l_[size_t(l)] * y[i];
    }
    if (w_ss) {
      for (int l = 0; l <= sh_order_; ++l) {
        for (int i = l * l; i < (l + 1) * (l + 1); ++i) {
          w_ss[i] = ssky_p_l_[size_t(l)] * y[i];
        }
      }
    }
    if (zonal_order_ > sh_order_) {
      // The zonal terms about the axis of travel of sunlight, -sun: Y_l0 there at -d is
      // sqrt((2l + 1) / (4 pi)) P_l(d . sun).
      double z[kMaxZonalDegree];
      const double mu = dot(d, sun_dir_);
      shZonal(sh_order_ + 1, zonal_order_, mu, z);
      for (int l = sh_order_ + 1; l <= zonal_order_; ++l) {
        const int i = l - sh_order_ - 1;
        w[shCount(sh_order_) + i] = phase_l_[size_t(l)] * z[i] * zonalTaper(l, mu);
      }
    }
  }

  /// Sunlight scattered through the phase's forward peak only, about -sun, towards the camera.
  const Rgb& peakPhase(RayState* s) const {
    if (!s->peak_ready) {
      s->peak_phase = peak_->scattered.eval(dot(sun_dir_, s->d));
      s->peak_ready = true;
    }
    return s->peak_phase;
  }

  // Photon's in-scattered light towards this view, per voxel of the tallies' lattice: each
  // voxel's coefficients weighted for the direction from its centre to the camera, 9 floats (ms,
  // ssky, csky), clamped at 0 only where read (clamping first would brighten by up to 4 % where
  // a truncated sum dips below 0). Every ray of a pinhole camera passes a point travelling
  // directly away from the eye (and every orthographic ray along one direction), so a sample
  // reads this field instead of interpolating up to 207 coefficients and weighting them for its
  // ray: a photon view 0.79 -> 0.42 s at 640x480 (docs/methods.md). The two differ only by how
  // the weights turn across a voxel, which the trilinear read follows to first order; near the
  // eye they turn fast, so samples closer than field_near_ (2 x the top degree, in voxels: a
  // voxel subtends under 1 / (2 l) radian beyond) keep the per-ray weights. Measured against them
  // on view_mie.json's to_sun view (droplet phase, zonal degree 24): 0.6 % relative RMSE in the
  // scattered light, -0.1 % in its mean. Built where the view traces rays enough to pay for it (a
  // quarter of the voxels or more).
  void buildViewField(const BakeGrid& g, const ViewGeometry& view) {
    const size_t voxels = g.voxelCount();
    if (!viewFieldPays(view.rays, double(voxels))) return;
    field_near_ = view.pinhole ? 2.0 * std::max(sh_order_, zonal_order_) * g.voxel_size : 0.0;
    // A sample at t >= field_near_ reads voxels at least field_near_ - sqrt(3) h from the eye:
    // nearer ones are never read, and a lattice all nearer than field_near_ needs no field.
    const double skip = field_near_ - 2 * g.voxel_size;
    if (view.pinhole && farthestCentre(g, view.eye) < field_near_) return;
    field_ = LargeArray<float>(voxels * kFieldFloats);
    // A slice's voxels take about 0.3 us each: a tally lattice near the memory's limit takes
    // seconds, so the loop stops when the view is cancelled.
    ParallelOptions slices;
    slices.cancelled = view.cancelled;
    slices.cancelled_message = "render from bake cancelled while building the view's field";
    parallelFor(
        0, g.nz,
        [&](int64_t k) {
          FieldRow row(size_t(g.nx), msh_.size(), ssky_sh_.size());
          for (int j = 0; j < g.ny; ++j) buildFieldRow(g, view, skip, j, int(k), &row);
        },
        slices);
  }

  // One row of the field's voxels at once, channel by channel: each coefficient's grid is read
  // along the row (the tallies are stored one grid per coefficient), and every voxel's sums run
  // over the coefficients in the order weightedSum takes them.
  struct FieldRow {
    FieldRow(size_t nx, size_t coefficients, size_t sky_coefficients)
        : n(coefficients),
          n_ss(sky_coefficients),
          active(nx),
          w(nx * coefficients),
          w_ss(nx * sky_coefficients),
          sum(3 * nx) {}
    size_t n, n_ss;               // weights per voxel, and the sky single scattering's
    std::vector<uint8_t> active;  // holds a tally and is read from the field
    std::vector<Rgb> w;           // [i * nx + x]: coefficient i's weight at voxel x
    std::vector<Rgb> w_ss;        // the same for the sky single scattering (phaseWeights)
    std::vector<Rgb> sum;         // [q * nx + x]: ms, ssky, csky
  };

  void buildFieldRow(const BakeGrid& g, const ViewGeometry& view, double skip, int j, int k,
                     FieldRow* r) {
    const size_t nx = size_t(g.nx);
    const size_t v0 = size_t(g.index(0, j, k));
    const std::vector<const float*>* lists[3] = {&msh_, &ssky_sh_, &msky_sh_};
    std::fill(r->active.begin(), r->active.end(), uint8_t(0));
    for (const auto* list : lists) {
      for (const float* grid : *list) {
        const float* p = grid + 3 * v0;
        // Voxel by voxel, not float by float with a division: a fortieth of a view's
        // instructions before (callgrind), the same flags.
        for (size_t x = 0; x < nx; ++x) {
          r->active[x] |= uint8_t((p[3 * x] != 0) | (p[3 * x + 1] != 0) | (p[3 * x + 2] != 0));
        }
      }
    }
    Rgb w[shCount(kMaxShDegree) + kMaxZonalDegree];
    Rgb w_ss[shCount(kMaxShDegree)];
    for (size_t x = 0; x < nx; ++x) {
      if (!r->active[x]) continue;
      Vec3 d = view.forward;
      if (view.pinhole) {
        const Vec3 to = g.center(int(x), j, k) - view.eye;
        const double dist = length(to);
        if (dist < skip) {
          r->active[x] = 0;
          continue;
        }
        if (dist > 0) d = to / dist;
      }
      phaseWeights(d, w, r->n_ss > 0 ? w_ss : nullptr);
      for (size_t i = 0; i < r->n; ++i) r->w[i * nx + x] = w[i];
      for (size_t i = 0; i < r->n_ss; ++i) r->w_ss[i * nx + x] = w_ss[i];
    }
    std::fill(r->sum.begin(), r->sum.end(), Rgb(0.0));
    for (int q = 0; q < 3; ++q) {
      Rgb* sum = r->sum.data() + size_t(q) * nx;
      for (size_t i = 0; i < lists[q]->size(); ++i) {
        const float* p = (*lists[q])[i] + 3 * v0;
        const Rgb* wi = (q == 1 ? r->w_ss.data() : r->w.data()) + i * nx;
        for (size_t x = 0; x < nx; ++x) {
          if (r->active[x]) sum[x] += wi[x] * Rgb(p[3 * x], p[3 * x + 1], p[3 * x + 2]);
        }
      }
    }
    float* out = field_.data() + v0 * kFieldFloats;
    for (size_t x = 0; x < nx; ++x) {
      for (int q = 0; q < 3; ++q) {
        const Rgb& v = r->sum[size_t(q) * nx + x];
        for (int c = 0; c < 3; ++c) out[x * kFieldFloats + size_t(3 * q + c)] = float(v[c]);
      }
    }
  }

  // Whether every sample of the view reads the field: it was built and, for a pinhole, the
  // whole support of the lattice (index (-1, n), with the anchor before a sample and a voxel to
  // spare) lies beyond field_near_.
  bool fieldServesEverySample(const ViewGeometry& view) const {
    if (field_.size() == 0) return false;
    if (!view.pinhole) return true;
    const double h = grid_.voxel_size;
    Bounds3 support;
    support.min = grid_.origin - Vec3(2 * h);
    support.max = grid_.origin + Vec3(grid_.nx + 1, grid_.ny + 1, grid_.nz + 1) * h;
    double d2 = 0;
    for (int a = 0; a < 3; ++a) {
      const double e = std::max({support.min[a] - view.eye[a], 0.0, view.eye[a] - support.max[a]});
      d2 += e * e;
    }
    return std::sqrt(d2) > field_near_ + (tally_ ? tally_dt_ : 0.0) + h;
  }

  // The largest distance from `eye` to a voxel centre of `g` (at one of the lattice's corners).
  static double farthestCentre(const BakeGrid& g, const Vec3& eye) {
    double far = 0;
    for (int c = 0; c < 8; ++c) {
      const Vec3 p = g.center(c & 1 ? g.nx - 1 : 0, c & 2 ? g.ny - 1 : 0, c & 4 ? g.nz - 1 : 0);
      far = std::max(far, length(p - eye));
    }
    return far;
  }

  // Whether a sample at distance t along the ray reads the view's field (buildViewField).
  bool fieldAt(double t) const { return field_.size() > 0 && t >= field_near_; }

  void readField(const Cell& c, Rgb* ms, Rgb* ssky, Rgb* csky) const {
    float v[kFieldFloats];
    (tally_ ? *tally_ : lattice_).readRecord(field_.data(), kFieldFloats, c, v);
    auto clamped = [&](int q) {
      return Rgb(std::max(0.f, v[q]), std::max(0.f, v[q + 1]), std::max(0.f, v[q + 2]));
    };
    *ms = clamped(0);
    *ssky = clamped(3);
    *csky = clamped(6);
  }

  // The tallies' terms at distance t along the ray, interpolated linearly between anchors
  // every tally_dt_ (half a tally voxel, as the march steps half a voxel of its own lattice):
  // the tallies vary on their coarser lattice, and their coefficient reads are most of a
  // sample's cost. Anchors lie at fixed distances along the ray, so an image does not depend on
  // how the march splits it.
  void tallySources(RayState* rs, double t, Rgb* ms, Rgb* ssky, Rgb* csky) const {
    const double x = t / tally_dt_;
    const double fk = std::floor(x);
    const int64_t k = int64_t(fk);
    const double f = x - fk;
    TallyAnchor* a = anchor(rs, k, nullptr);
    const TallyAnchor* b = anchor(rs, k + 1, a);
    *ms = a->ms * (1 - f) + b->ms * f;
    *ssky = a->ssky * (1 - f) + b->ssky * f;
    *csky = a->csky * (1 - f) + b->csky * f;
  }

  // The ray's anchor k, evaluated unless one of its two slots holds it (not `keep`).
  TallyAnchor* anchor(RayState* rs, int64_t k, const TallyAnchor* keep) const {
    for (TallyAnchor& slot : rs->anchor) {
      if (slot.k == k) return &slot;
    }
    TallyAnchor* slot = &rs->anchor[0] == keep              ? &rs->anchor[1]
                        : &rs->anchor[1] == keep            ? &rs->anchor[0]
                        : rs->anchor[0].k < rs->anchor[1].k ? &rs->anchor[0]
                                                            : &rs->anchor[1];
    // Index coordinates on the bake's lattice (block space minus one), then on the tallies'.
    const Vec3 u = rs->w0 + rs->dw * (double(k) * tally_dt_) - Vec3(1.0);
    Cell tc;
    tally_->locate(u * tally_scale_ + tally_offset_, &tc);
    slot->k = k;
    if (fieldAt(double(k) * tally_dt_)) {
      readField(tc, &slot->ms, &slot->ssky, &slot->csky);
    } else {
      if (!rs->weights_ready) rayWeights(rs);
      shSources(tc, rs->shw, rs->shw_ss, &slot->ms, &slot->ssky, &slot->csky);
    }
    return slot;
  }

  // Where the bake split a droplet's peak off, its phase's p_l are still 0.3-0.5 at the top
  // zonal degree, so the truncated sum rings where its true value is small, away from the
  // forward axis, while towards it the high degrees carry the peak of the scattered sunlight. So
  // degree l is weighted by 1 - w (1 - sinc(pi l / (top + 1))) (half a Lanczos factor), w = 1/2
  // for mu = d . sun <= 0, 0 at mu = 1, linear between. Measured (Perlin cloud, real Mie table,
  // 1M photons, relative RMSE; a Mie sphere's mean multiple scattering with the sun behind the
  // camera): no taper 0.110 on the glory side, -0.1 % on the sphere; this 0.092, -2.1 %; a full
  // Lanczos factor 0.083, -3.9 %; the full factor everywhere also dulled the view against the
  // sun (0.177 to 0.228). A phase under the split's bound is not tapered.
  double zonalTaper(int l, double mu) const {
    if (!peak_) return 1.0;
    const double w = 0.5 * std::clamp(1 - mu, 0.0, 1.0);
    return 1 - w * zonal_sinc_[size_t(l)];
  }

  // The bake's cut of the phase's forward peak: cloudbake:peak_cut_deg, 0 (absent: none) or in
  // (0, 90].
  static double peakCutDegrees(const BakedLight& bake) {
    const auto it = bake.metadata.find("cloudbake:peak_cut_deg");
    double deg = 0;
    try {
      deg = it == bake.metadata.end() ? 0.0 : std::stod(it->second);
    } catch (const std::exception&) {
      deg = -1;
    }
    if (!(deg >= 0 && deg <= 90)) {
      throw InputError("bake: metadata cloudbake:peak_cut_deg must be 0 or in (0, 90]");
    }
    return deg;
  }

  // cloudbake:photon_zonal_order: 0 (absent: none) or in (order, kMaxZonalDegree].
  static int photonZonalOrder(const BakedLight& bake, int order) {
    const auto it = bake.metadata.find("cloudbake:photon_zonal_order");
    if (it == bake.metadata.end()) return 0;
    int zonal = -1;
    try {
      zonal = std::stoi(it->second);
    } catch (const std::exception&) {
      zonal = -1;
    }
    if (zonal != 0 && (zonal <= order || zonal > kMaxZonalDegree)) {
      throw InputError("bake: metadata cloudbake:photon_zonal_order must be 0 or in " +
                       str(order + 1) + ".." + str(kMaxZonalDegree));
    }
    return zonal;
  }

  // The tallies' in-scattered light at cell c: sums over coefficients of w_i L_i(x) per
  // channel, clamped at 0 (a truncated expansion can dip below zero where the true
  // in-scattered radiance is small). Its read of up to 207 floats is a vector loop, so it is
  // compiled for wider vectors too (7 % of a photon view).
  CLOUDBAKE_VECTOR_CLONES void shSources(const Cell& c, const Rgb* w, const Rgb* w_ss, Rgb* ms,
                                         Rgb* ssky, Rgb* csky) const {
    float v[kMaxTallyFloats];
    (tally_ ? *tally_ : lattice_).readPacked(tally_pack_, tally_stride_, c, 0, tally_floats_, v);
    *ms = shSum(v, msh_.size(), w);
    *ssky = ssky_sh_.empty() ? Rgb(0.0) : shSum(v + ssky_slot_, ssky_sh_.size(), w_ss);
    *csky = msky_sh_.empty() ? Rgb(0.0) : shSum(v + msky_slot_, msky_sh_.size(), w);
  }

  static Rgb weightedSum(const float* v, size_t n, const Rgb* w) {
    Rgb sum(0.0);
    for (size_t i = 0; i < n; ++i) sum += w[i] * Rgb(v[3 * i], v[3 * i + 1], v[3 * i + 2]);
    return sum;
  }

  static Rgb shSum(const float* v, size_t n, const Rgb* w) {
    const Rgb sum = weightedSum(v, n, w);
    return Rgb(positivePart(sum.x), positivePart(sum.y), positivePart(sum.z));
  }

  /// The densest voxel of each 8^3 block, from the cache where it holds this density's.
  void buildBlockMax() {
    nbx_ = (nx_ + 1 + kBlock - 1) / kBlock;
    nby_ = (ny_ + 1 + kBlock - 1) / kBlock;
    nbz_ = (nz_ + 1 + kBlock - 1) / kBlock;
    BakeViewCache::Impl::Blocks& b = cache_.blocks;
    if (b.density != density_ || b.nx != nx_ || b.ny != ny_ || b.nz != nz_) {
      b.density = nullptr;  // no key while it is built: a bad voxel throws
      b.max = blockMaxima();
      b.occupied = occupiedCells();
      b.max_density = 0;
      for (float v : b.max) b.max_density = std::max(b.max_density, double(v));
      b.density = density_;
      b.nx = nx_;
      b.ny = ny_;
      b.nz = nz_;
      ++cache_.builds;
    }
    block_max_ = b.max.data();
    occupied_ = b.occupied.data();
    if (!std::isfinite(extinction_ * b.max_density)) {
      throw InputError("medium.extinction: extinction * max density overflows");
    }
  }

  /// buildBlockMax's maxima; InputError naming the first voxel whose density is negative or
  /// not finite.
  std::vector<float> blockMaxima() const {
    std::vector<float> block_max(size_t(nbx_) * nby_ * nbz_, 0.f);
    // Block b covers w in [8b, 8b + 8), i.e. lookups with floor(index) in [8b - 1, 8b + 6],
    // which read voxels 8b - 1 .. 8b + 7: the block dilated by one voxel.
    std::atomic<bool> bad{false};
    parallelFor(0, nbz_, [&](int bk) {
      const int k0 = std::max(0, kBlock * bk - 1), k1 = std::min(nz_ - 1, kBlock * bk + 7);
      for (int bj = 0; bj < nby_; ++bj) {
        const int j0 = std::max(0, kBlock * bj - 1), j1 = std::min(ny_ - 1, kBlock * bj + 7);
        for (int bi = 0; bi < nbx_; ++bi) {
          const int i0 = std::max(0, kBlock * bi - 1), i1 = std::min(nx_ - 1, kBlock * bi + 7);
          float m = 0;
          for (int k = k0; k <= k1; ++k) {
            for (int j = j0; j <= j1; ++j) {
              const float* row = density_ + grid_.index(0, j, k);
              for (int i = i0; i <= i1; ++i) {
                const float v = row[i];
                if (!(v >= 0) || !std::isfinite(v)) bad = true;
                m = std::max(m, v);
              }
            }
          }
          block_max[(size_t(bk) * nby_ + bj) * nbx_ + bi] = m;
        }
      }
    });
    if (bad) {
      // Name the first bad voxel (serial scan only on the error path).
      for (int k = 0; k < nz_; ++k) {
        for (int j = 0; j < ny_; ++j) {
          for (int i = 0; i < nx_; ++i) {
            const float v = density_[grid_.index(i, j, k)];
            if (!(v >= 0) || !std::isfinite(v)) {
              throw InputError("bake: grid 'density': voxel (" + str(i) + ", " + str(j) + ", " +
                               str(k) + ") at " + str(grid_.center(i, j, k)) +
                               " must be finite and >= 0, got " + str(v));
            }
          }
        }
      }
    }
    return block_max;
  }

  /// Per cell of the lattice (indexed as Cell::base, the voxel at its lower corner), 1 where
  /// any of the eight voxels a lookup in it reads has a density other than 0. The empty-space
  /// blocks are 8 voxels wide, and within those that hold density many samples lie in cells
  /// that hold none: their read of eight densities is skipped (the same value, +0). `single`'s
  /// views of bench/speed/view_mie.json 0.089-0.092 -> 0.083-0.085 s, `pointcloud`'s 2-3 %.
  std::vector<uint8_t> occupiedCells() const {
    const size_t sy = size_t(nx_), sz = sy * size_t(ny_);
    std::vector<uint8_t> occupied(sz * size_t(nz_), 0);
    parallelFor(0, std::max(nz_ - 1, 0), [&](int k) {
      std::vector<uint8_t> row(static_cast<size_t>(nx_));
      for (int j = 0; j + 1 < ny_; ++j) {
        const float* d = density_ + size_t(k) * sz + size_t(j) * sy;
        // The four rows of voxels the cells of this row read, each voxel or its next in x.
        for (int i = 0; i < nx_; ++i) {
          row[size_t(i)] = d[i] != 0 || d[i + sy] != 0 || d[i + sz] != 0 || d[i + sy + sz] != 0;
        }
        uint8_t* out = occupied.data() + size_t(k) * sz + size_t(j) * sy;
        for (int i = 0; i + 1 < nx_; ++i) out[i] = row[size_t(i)] | row[size_t(i) + 1];
      }
    });
    return occupied;
  }

  /// Finds the cell of block-space point w on the bake's lattice.
  void locate(const Vec3& w, Cell* cell) const { lattice_.locate(w - Vec3(1.0), cell); }
  float density(const Cell& c) const { return lattice_.read(density_, c); }

  // The record of the grids a source reads at c: one vectorised read of the packed record, or,
  // for the few grids of method single (no pack), a read of each.
  void readSources(Cell& c) const {
    if (pack_) {
      lattice_.readRecord(pack_, stride_, c, c.record);
      return;
    }
    c.record[kTsun] = lattice_.read(tsun_, c);
    // Photon's sky light comes from its tallies: its views do not read the visibility.
    if (vsky_ && ssky_sh_.empty()) c.record[kVsky] = lattice_.read(vsky_, c);
    if (mie_) c.record[kMie] = lattice_.read(mie_, c);
    if (sscale_) c.record[sscale_slot_] = lattice_.read(sscale_, c);
  }

  // Slots of the march's packed record (packChannels): every grid a sample reads.
  enum Slot : int {
    kDensity = 0,
    kTsun = 1,
    kVsky = 2,
    kMie = 3,
    kCo = 4,
    kLdir = 7,
    kCsky = 10,
    kSh = 13,
    kSlotCount = kSh + kShCoefficients
  };

  void buildPack() {
    std::vector<PackedChannel> ch{{density_, 1, kDensity}, {tsun_, 1, kTsun}};
    if (vsky_) ch.push_back({vsky_, 1, kVsky});
    if (mie_) ch.push_back({mie_, 1, kMie});
    if (co_) ch.push_back({co_, 3, kCo});
    if (ldir_) ch.push_back({ldir_, 3, kLdir});
    if (csky_) ch.push_back({csky_, 3, kCsky});
    int used = co_ || csky_ ? kSh : kCo;
    if (sky_sh_) {
      for (int i = 0; i < kShCoefficients; ++i) ch.push_back({sh_[size_t(i)], 1, kSh + i});
      used = kSlotCount;
    }
    if (svec_) {  // never with sky_sh_, whose slots it may take
      svec_slot_ = used;
      ch.push_back({svec_, 3, used});
      used += 3;
    }
    // A record of 4 floats (method single) is read faster grid by grid (measured: 0.34 against
    // 0.37 s a view): pack only where a sample reads more. photon's sky_single_scale does not
    // count: packing a 192^3 lattice for it cost a small view more than its reads save.
    const bool packs = used > kCo;
    if (sscale_) {  // photon's: never with sky_sh_ either
      sscale_slot_ = used;
      ch.push_back({sscale_, 1, used});
      used += 1;
    }
    stride_ = size_t((used + 3) / 4 * 4);
    if (packs) pack_ = cache_.pack(&cache_.march, ch, grid_.voxelCount(), stride_);
  }

  /// Precomputed's scattered sky light has the angular shape of the sky light the medium
  /// removes: radiance f L_sky (1 - T(x, w)) from direction w, with f = (Co_sky / 4 pi) / (1 - V)
  /// the scattered fraction of it (<= 1 in a furnace at any albedo <= 1), so that seen along d
  /// it is f L_sky (1 - integral T p(w . d) dw), the complement of the view-dependent single
  /// scattering (Eq. 5). Isotropic phases give the old f L_sky (1 - V) = L_sky Co_sky / (4 pi);
  /// a strong backward peak, whose single scattering alone returns half the sky towards a
  /// viewer behind it, no longer adds an isotropic multiple term on top (HG -0.999 at albedo 1
  /// was 1.45x the sky).
  static Rgb skyMsShape(const Rgb& co_sky_4pi, double v) {
    return 1 - v > 1e-6 ? co_sky_4pi / (1 - v) : Rgb(0.0);
  }

  /// Whether c lies in an 8^3 block whose densest voxel is optically thicker than
  /// kThinVoxelDepth: there the sun's transmittance takes the short characteristic, elsewhere
  /// its 3D interpolation, within about 1 % there (docs/methods.md) and cheaper.
  /// `w`: the sample's block-space position.
  bool thickBlock(const Vec3& w) const {
    int b[3];
    const int nb[3] = {nbx_, nby_, nbz_};
    for (int a = 0; a < 3; ++a) b[a] = std::min(std::max(int(w[a] / kBlock), 0), nb[a] - 1);
    return block_max_[(size_t(b[2]) * nby_ + b[1]) * nbx_ + b[0]] > thick_density_;
  }

  /// The sun's transmittance at the march's sample c by a characteristic: from c towards the
  /// sun to the nearest plane of lattice voxels across the sun's main axis, the bake's
  /// transmittance there, interpolated within the plane, times that of the segment, whose
  /// optical depth is Simpson's rule on the density the view reads. The transmittance
  /// interpolated in 3D is too bright where it falls exponentially within a voxel (thick
  /// media); along the sun that part is now exact, and across it the interpolation keeps the
  /// bound from above that convexity gives (the optical depth interpolated instead was too dark
  /// where a low sun grazes a cloud's top). Where the voxels around the plane's point still
  /// differ by more than kSunCornerRatio, it goes on plane by plane. Measured in
  /// docs/methods.md ("The sun's transmittance between voxels").
  /// `w`: c's block-space position (index + 1).
  double sunTransmittanceAt(const Cell& c, const Vec3& w) const {
    Vec3 u = w - Vec3(1.0);
    const int a = sun_axis_;
    const double la = sun_dir_[a];
    double sigma_u = c.sigma, depth = 0, previous = -1;
    for (;;) {
      const double plane = la > 0 ? std::floor(u[a]) + 1 : std::ceil(u[a]) - 1;
      const double s = (plane - u[a]) / la;  // voxels, in (0, sqrt(3)]
      Vec3 y = u + sun_dir_ * s;
      y[a] = plane;
      Cell cy, cm;
      lattice_.locate(y, &cy);
      lattice_.locate(u + sun_dir_ * (0.5 * s), &cm);
      float at_y[2];  // density and the sun's transmittance at y
      if (pack_) {
        lattice_.readPacked(pack_, stride_, cy, kDensity, 2, at_y);
      } else {
        at_y[kDensity] = density(cy);
        at_y[kTsun] = lattice_.read(tsun_, cy);
      }
      double t_y = at_y[kTsun];
      if (!cy.interior) {
        // Beyond the lattice there is no medium: the sun's transmittance is 1 there, not the
        // lookup's zero background (that darkened samples by a lattice face towards the sun).
        double outside = 1;
        for (const float wq : cy.corners.weight) outside -= wq;
        t_y += outside;
      }
      const double sigma_y = extinction_ * at_y[kDensity], sigma_m = extinction_ * density(cm);
      depth += s * grid_.voxel_size * (sigma_u + 4 * sigma_m + sigma_y) / 6;
      const double beyond = std::exp(-depth), estimate = t_y * beyond;
      // A lattice's margin voxels are empty, so a point off its interior has smooth light.
      if (!cy.interior) return estimate;
      float lo, hi;
      sunCornerRange(cy, &lo, &hi);
      // The bake holds Tsun within three voxels of the density (sunTransmittanceSupport) and 0
      // beyond, where a plane after the first may reach: its own light is then unknown. Where
      // the plane's point holds density its voxels lie within that support, and a 0 there is a
      // transmittance under the bake's floor (exp(-16.2)): returning there made a dense slab's
      // lit top 2.5x too bright under a sun 5 degrees over it.
      if (previous >= 0 && lo == 0 && !(at_y[kDensity] > 0)) return previous;
      if (!(double(hi) * beyond > kSunNegligible && hi > kSunCornerRatio * lo)) return estimate;
      previous = estimate;
      u = y;
      sigma_u = sigma_y;
    }
  }

  /// The smallest and largest of the bake's sun transmittance over the voxels a lookup at c
  /// (interior) reads.
  void sunCornerRange(const Cell& c, float* lo, float* hi) const {
    if (pack_) {
      lattice_.cornerRange(pack_, stride_, kTsun, c, lo, hi);
    } else {
      lattice_.cornerRange(tsun_, 1, 0, c, lo, hi);
    }
  }

  /// The source terms at a sample: Tsun, Vsky, and the multiple term J_ms (RGB, per unit E).
  struct Source {
    double tsun = 0, vsky = 0;
    // the phase's residual's sky scattering per unit mean sky radiance (sky_p1_scatter.h), and
    // per unit of a uniform sky (Co_sky's complement)
    Rgb sky_res, sky_res_unit;
    Rgb csky_peak;  // with sky_res: Co_sky / (4 pi) / (1 - Vsky), which the peak's part takes
    Rgb ms, csky;   // csky: Co_sky / (4 pi)
    Rgb ssky;       // photon: the sky's single scattering per unit sky radiance
    float tsh[kShCoefficients] = {};
  };

  /// The residual's share of the sky's single scattering at a sample of record v, per channel
  /// and per unit mean sky radiance: (1 - f) clamp(alpha V + beta . B, 0, upper) with the ray's
  /// P1RayWeights; and, with Co_sky, that of a uniform sky (sky_p1_scatter.h).
  void skyP1Source(const float* v, const RayState& rs, Source* s) const {
    const Vec3 b(v[svec_slot_], v[svec_slot_ + 1], v[svec_slot_ + 2]);
    const double vis = v[kVsky];
    const P1RayWeights& w = rs.p1w;
    if (sky_split_grey_) {
      s->sky_res = Rgb((1 - sky_split_[0].f) * w.residual(0, vis, b));
      s->sky_res_unit = s->sky_res;
      return;
    }
    // Each channel's value into one Rgb, not channel by channel into memory that the march
    // then reads as a vector (core/math/branchless.h).
    auto residual = [&](int c) { return (1 - sky_split_[size_t(c)].f) * w.residual(c, vis, b); };
    s->sky_res = Rgb(residual(0), residual(1), residual(2));
    if (!csky_) return;
    // The shaped multiple term's complement is that of a uniform sky, which Co_sky is baked for.
    if (sky_uniform_) {
      s->sky_res_unit = s->sky_res;
      return;
    }
    if (phase_grey_) {  // every channel's split is the first's: the same value, once
      const DeltaSplit& split = sky_split_[0];
      s->sky_res_unit = Rgb((1 - split.f) * p1SkyScatter(vis, b, rs.d, split.g_residual, 1));
      return;
    }
    auto unit = [&](int c) {
      const DeltaSplit& split = sky_split_[size_t(c)];
      return (1 - split.f) * p1SkyScatter(vis, b, rs.d, split.g_residual, 1);
    };
    s->sky_res_unit = Rgb(unit(0), unit(1), unit(2));
  }

  void source(Cell& c, RayState* rs, Source* s) const {
    const Vec3& d = rs->d;
    readSources(c);
    const float* v = c.record;
    // Where even the trilinear transmittance (an overestimate: see sunTransmittanceAt) is under
    // kDarkSun, the characteristic would change light no image shows.
    s->tsun = v[kTsun];
    if (sun_characteristic_ && v[kTsun] >= kDarkSun) {
      const Vec3 w = rs->w0 + rs->dw * c.t;
      if (thickBlock(w)) s->tsun = sunTransmittanceAt(c, w);
    }
    if (tally_) {
      tallySources(rs, c.t, &s->ms, &s->ssky, &s->csky);
    } else if (!msh_.empty() && fieldAt(c.t)) {
      readField(c, &s->ms, &s->ssky, &s->csky);
    } else if (!msh_.empty()) {
      if (!rs->weights_ready) rayWeights(rs);
      shSources(c, rs->shw, rs->shw_ss, &s->ms, &s->ssky, &s->csky);
    }
    if (sscale_) s->ssky *= double(v[sscale_slot_]);
    if (peak_) s->ms += peakPhase(rs) * peak_->fluence(s->tsun);
    if (sky_sh_) {
      for (int i = 0; i < kShCoefficients; ++i) s->tsh[i] = v[kSh + i];
    } else if (vsky_ && ssky_sh_.empty()) {
      s->vsky = v[kVsky];
    }
    if (svec_) skyP1Source(v, *rs, s);
    if (csky_) {
      s->csky = Rgb(v[kCsky], v[kCsky + 1], v[kCsky + 2]) * kInv4Pi;
      if (sky_unit_sh_) s->csky = skyMsShape(s->csky, v[kVsky]);
      if (svec_) {
        // The scattered sky light has the shape of the sky light removed, as precomputed's
        // (skyMsShape): the complement of the single scattering, whose peak's part
        // addSkyP1 takes off.
        s->csky_peak = skyMsShape(s->csky, v[kVsky]);
        s->csky = s->csky_peak * (Rgb(1.0) - s->sky_res_unit);
      }
    }
    if (co_) {
      const float* co = v + kCo;
      const float* ld = v + kLdir;
      const double r = mie_ ? v[kMie] : 0.0;
      Vec3 l(0.0);
      if (ldir_ && r > 0) l = Vec3(ld[0], ld[1], ld[2]);
      const double len = length(l);
      Rgb phase(kInv4Pi);
      if (r > 0 && len > 1e-6) {
        // Interpolated directions are shorter than unit; only the direction is meaningful.
        const double cs = -dot(l, d) / len;
        if (p1_ && phase_grey_) {
          phase = Rgb(kInv4Pi * positivePart(1 + 3 * g_[0] * r * cs));
        } else if (p1_) {
          phase = Rgb(kInv4Pi * positivePart(1 + 3 * g_[0] * r * cs),
                      kInv4Pi * positivePart(1 + 3 * g_[1] * r * cs),
                      kInv4Pi * positivePart(1 + 3 * g_[2] * r * cs));
        } else {
          phase = lut_.eval(cs) * r + Rgb((1 - r) * kInv4Pi);
        }
      }
      s->ms = phase * Rgb(co[0], co[1], co[2]);
    }
  }

  /// 3D DDA over the blocks from t_in to t_out, integrating runs of non-empty blocks.
  void march(RayState* s, double t_in, double t_out) const {
    const int nb[3] = {nbx_, nby_, nbz_};
    int b[3], step[3];
    double t_max[3], t_delta[3];
    const Vec3 w_in = s->w0 + s->dw * t_in;
    for (int a = 0; a < 3; ++a) {
      b[a] = std::min(std::max(int(std::floor(w_in[a] / kBlock)), 0), nb[a] - 1);
      const double dw = s->dw[a];
      if (dw > 0) {
        step[a] = 1;
        t_max[a] = (kBlock * (b[a] + 1) - s->w0[a]) / dw;
        t_delta[a] = kBlock / dw;
      } else if (dw < 0) {
        step[a] = -1;
        t_max[a] = (kBlock * b[a] - s->w0[a]) / dw;
        t_delta[a] = -kBlock / dw;
      } else {
        step[a] = 0;
        t_max[a] = std::numeric_limits<double>::infinity();
        t_delta[a] = 0;
      }
    }
    double t = t_in, run_start = -1;
    for (;;) {
      const bool occupied = block_max_[(size_t(b[2]) * nby_ + b[1]) * nbx_ + b[0]] > 0;
      if (occupied && run_start < 0) run_start = t;
      if (!occupied && run_start >= 0) {
        integrate(s, run_start, t);
        run_start = -1;
        if (s->done) return;
      }
      const int a =
          t_max[0] < t_max[1] ? (t_max[0] < t_max[2] ? 0 : 2) : (t_max[1] < t_max[2] ? 1 : 2);
      if (!(t_max[a] < t_out)) break;
      t = std::max(t, t_max[a]);
      b[a] += step[a];
      if (b[a] < 0 || b[a] >= nb[a]) break;
      t_max[a] += t_delta[a];
    }
    if (run_start >= 0) integrate(s, run_start, t_out);
  }

  /// One step's terms of the sky's SH sums (precomputed): the products a T_sky,i are shared by
  /// both sums, and each sum runs over i per channel, the same arithmetic as term by term. Kept
  /// out of the march's loop and compiled for wider vectors too: 0.64 -> 0.52 s a frame's view.
  CLOUDBAKE_VECTOR_CLONES void addSkyShSums(double a0, const Source& p0, double a1,
                                            const Source& p1, RayState* s) const {
    double b0[kShCoefficients], b1[kShCoefficients];
    for (int q = 0; q < kShCoefficients; ++q) {
      b0[q] = a0 * p0.tsh[q];
      b1[q] = a1 * p1.tsh[q];
    }
    if (sky_sh_) {
      for (int q = 0; q < kShCoefficients; ++q) s->sky_sh[q] += b0[q] + b1[q];
    }
    if (!sky_unit_sh_) return;
    for (int c = 0; c < 3; ++c) {
      const double f0 = p0.csky[c], f1 = p1.csky[c];
      double* sum = s->sky_ms_sh[c];
      for (int q = 0; q < kShCoefficients; ++q) sum[q] += f0 * b0[q] + f1 * b1[q];
    }
  }

  /// The ray's sums while a run is marched (kept in registers; stored back on every exit), and
  /// the sources of the step's two ends.
  struct MarchSums {
    MarchSums(const BakeMarcher& bm, const RayState& s)
        : has_ms(bm.co_ || !bm.msh_.empty()),
          has_sky_ms(bm.csky_ || !bm.msky_sh_.empty()),
          has_sky_ss(!bm.ssky_sh_.empty()),
          has_sky_vec(bm.svec_ != nullptr),
          transmittance(s.transmittance),
          ss(s.ss),
          sky(s.sky),
          ms(s.ms),
          sky_ms(s.sky_ms),
          sky_ss(s.sky_ss),
          sky_res(s.sky_res),
          tau(s.tau),
          sky_peak_ahead(s.sky_peak_ahead),
          sky_peak_behind(s.sky_peak_behind) {}

    /// Adds the step from sample `a` to sample `b`, whose sources are *src_prev and *src_cur;
    /// false once the ray's transmittance is below the march's floor.
    [[gnu::always_inline]] bool add(const BakeMarcher& bm, RayState* s, const Cell& a,
                                    const Cell& b) {
      const double delta = 0.5 * (a.sigma + b.sigma) * (b.t - a.t);
      double e, w0, w1;
      stepWeights(delta, &e, &w0, &w1);
      const double a0 = transmittance * w0, a1 = transmittance * w1;
      const Source& p0 = *src_prev;
      const Source& p1 = *src_cur;
      ss += transmittance * sunStep(delta, w0, w1, p0.tsun, p1.tsun);
      sky += a0 * p0.vsky + a1 * p1.vsky;
      if (has_ms) ms += (p0.ms * a0 + p1.ms * a1) * bm.scale_ms_;
      if (has_sky_ms) sky_ms += p0.csky * a0 + p1.csky * a1;
      if (has_sky_ss) sky_ss += p0.ssky * a0 + p1.ssky * a1;
      if (has_sky_vec) {
        sky_res += p0.sky_res * a0 + p1.sky_res * a1;
        if (bm.csky_) skyPeakSums(bm, a, b, a0, a1, e);
      }
      tau += delta;
      if (bm.sky_sh_ || bm.sky_unit_sh_) bm.addSkyShSums(a0, p0, a1, p1, s);
      transmittance *= e;
      std::swap(src_prev, src_cur);
      have_prev = true;
      if (transmittance < bm.min_transmittance_ || !(transmittance > 0)) {
        s->done = true;
        return false;
      }
      return true;
    }

    /// The peak's part of the shaped sky multiple term (addSkyP1): the forward peak's
    /// integral of T_v sigma_t c T(x, d) is T_v(end) times that of sigma_t c; the backward
    /// peak's is that of T_v^2 sigma_t c (T(x, -d) = T_v), c = Source::csky_peak.
    void skyPeakSums(const BakeMarcher& bm, const Cell& a, const Cell& b, double a0, double a1,
                     double e) {
      const Source& p0 = *src_prev;
      const Source& p1 = *src_cur;
      if (bm.forward_peak_) {
        sky_peak_ahead += (p0.csky_peak * a.sigma + p1.csky_peak * b.sigma) * (0.5 * (b.t - a.t));
      }
      if (bm.backward_peak_) {
        sky_peak_behind += (p0.csky_peak * a0 + p1.csky_peak * (a1 * e)) * transmittance;
      }
    }

    void store(RayState* s) const {
      s->transmittance = transmittance;
      s->ss = ss;
      s->sky = sky;
      s->ms = ms;
      s->sky_ms = sky_ms;
      s->sky_ss = sky_ss;
      s->sky_res = sky_res;
      s->tau = tau;
      s->sky_peak_ahead = sky_peak_ahead;
      s->sky_peak_behind = sky_peak_behind;
    }

    // the layers this bake's sources carry
    const bool has_ms, has_sky_ms, has_sky_ss, has_sky_vec;
    double transmittance, ss, sky;
    Rgb ms, sky_ms, sky_ss;
    Rgb sky_res;
    double tau;
    Rgb sky_peak_ahead, sky_peak_behind;
    Source sources[2];
    Source* src_prev = &sources[0];
    Source* src_cur = &sources[1];
    bool have_prev = false;  // *src_prev holds the sources of the step's first sample
  };

  /// Marches [t0, t1] with uniform steps of at most step_, accumulating into `s`. Where the ray
  /// enters the medium in an optically thick block (thickBlock), the steps up to a voxel beyond
  /// are split where they cross the lattice's cells (cellCrossings): in thinner blocks the
  /// trapezoid's error at the edge is a small part of the light, and splitting every edge's
  /// steps made the views of bench/speed/view_mie.json 4-8 % slower.
  void integrate(RayState* s, double t0, double t1) const {
    const double len = t1 - t0;
    if (!(len > 0)) return;
    const int64_t n = std::max<int64_t>(1, int64_t(std::ceil(len / step_)));
    const double dt = len / double(n);
    Cell buf[3];
    Cell* prev = &buf[0];
    Cell* cur = &buf[1];
    Cell* piece = &buf[2];
    sample(s, t0, prev);
    MarchSums m(*this, *s);
    double split_until = -std::numeric_limits<double>::infinity();
    for (int64_t i = 1; i <= n; ++i) {
      sample(s, i == n ? t1 : t0 + double(i) * dt, cur);
      if (!(prev->sigma > 0) && cur->sigma > 0 && thickBlock(s->w0 + s->dw * cur->t)) {
        split_until = cur->t + grid_.voxel_size;
      }
      if (prev->t < split_until && cur->sigma > 0) {
        double ts[kMaxCrossings];
        const int k = cellCrossings(s, prev->t, cur->t, ts);
        for (int q = 0; q < k; ++q) {
          sample(s, ts[q], piece);
          if (!marchStep(s, &m, *prev, *piece)) return m.store(s);
          std::swap(prev, piece);
        }
      }
      if (!marchStep(s, &m, *prev, *cur)) return m.store(s);
      std::swap(prev, cur);
    }
    m.store(s);
  }

  /// Adds the step from sample a to sample b to the ray's sums (their sources into m, a's
  /// unless m holds them already); false once the ray is done. A step with no medium at either
  /// end adds nothing.
  [[gnu::always_inline]] bool marchStep(RayState* s, MarchSums* m, Cell& a, Cell& b) const {
    if (!(a.sigma > 0) && !(b.sigma > 0)) {
      m->have_prev = false;  // sources are read only next to density
      return true;
    }
    if (!m->have_prev) source(a, s, m->src_prev);
    source(b, s, m->src_cur);
    return m->add(*this, s, a, b);
  }

  /// The distances in (ta, tb), ascending, at which the ray crosses a plane of the lattice's
  /// voxel centres (at most kMaxCrossings; tb - ta is at most a march step). The trilinear
  /// density is smooth between them, and where a ray enters or leaves the medium it does so on
  /// one: a step across the edge marched as one trapezoid took the density as linear from the
  /// outside sample, and so in a dense medium up to twice the optical depth the lattice holds
  /// there, and as much more of the light scattered within it (a low sun grazing a dense
  /// layer: 1.23x the path tracer's single scattering; docs/methods.md).
  int cellCrossings(const RayState* s, double ta, double tb, double* ts) const {
    int k = 0;
    for (int a = 0; a < 3; ++a) {
      const double dw = s->dw[a];
      if (dw == 0) continue;
      const double ua = s->w0[a] + dw * ta, ub = s->w0[a] + dw * tb;
      // Voxel centres lie at integer w (index + 1).
      const double lo = std::min(ua, ub), hi = std::max(ua, ub);
      for (double c = std::floor(lo) + 1; c < hi && k < kMaxCrossings; c += 1) {
        const double t = (c - s->w0[a]) / dw;
        if (!(t > ta && t < tb)) continue;
        int q = k++;  // insertion: a handful of crossings
        for (; q > 0 && ts[q - 1] > t; --q) ts[q] = ts[q - 1];
        ts[q] = t;
      }
    }
    return k;
  }

  /// Locates the march's sample at distance t along the ray and reads its extinction.
  void sample(const RayState* s, double t, Cell* c) const {
    locate(s->w0 + s->dw * t, c);
    c->t = t;
    // A cell whose voxels are all 0 interpolates to +0 whatever the weights: the read's value.
    if (c->interior && !occupied_[c->base]) {
      c->sigma = 0.0;
    } else if (pack_ && c->interior) {
      // The packed record's first float is the density, the same values as the density grid:
      // reading it there brings in the cache lines the sample's sources read next (pointcloud's
      // views of bench/speed/view_mie.json 2-5 % faster at 1 thread, the same bits).
      const float* p = pack_ + c->base * stride_;
      c->sigma = extinction_ * lattice_.lerpAt(p, stride_, c->fx, c->fy, c->fz);
    } else {
      c->sigma = extinction_ * density(*c);
    }
  }

  const BakeGrid& grid_;
  LatticeReader lattice_;
  std::optional<LatticeReader> tally_;  // photon's tallies on a lattice of their own
  double tally_scale_ = 1;              // index on tally_ = index on the lattice x scale + offset
  Vec3 tally_offset_;
  double tally_dt_ = 1;  // world units between the tallies' anchors along a ray
  const float* density_;
  const float* tsun_ = nullptr;
  bool sun_characteristic_ = false;  // the bake has cloudbake:sun_transmittance_margin
  int sun_axis_ = 0;                 // the sun direction's largest component

  // Densities above which a voxel is optically thicker than kThinVoxelDepth (thickBlock).
  double thick_density_ = 0;
  const float* vsky_ = nullptr;
  const float* svec_ = nullptr;    // sky_visibility_vector (sky_p1_scatter.h)
  int svec_slot_ = 0;              // its first slot in the packed record
  const float* sscale_ = nullptr;  // photon's sky_single_scale (photonSkySingleScale)
  int sscale_slot_ = 0;            // its slot in the packed record
  Rgb ssky_peak_{0.0};             // f x albedo
  bool ssky_delta_ = false;        // f > 0 in some channel
  bool ssky_backward_ = false;     // the phase's peak is backward in every channel (p_1 < 0)
  std::vector<Rgb> ssky_p_l_;      // the residual's Legendre coefficients, p_l -/+ f, to order
  std::array<DeltaSplit, 3> sky_split_{};              // the phase per channel, split for it
  bool forward_peak_ = false, backward_peak_ = false;  // any channel's split has one
  std::array<Vec3, 3> sky_l_{};  // the sky's first moment over its mean, per channel
  double sky_g_res_[3] = {};     // the splits' residual mean cosines
  bool sky_uniform_ = true;      // sky_l_ is 0: a constant sky
  bool sky_split_grey_ = false;  // one split for every channel (a grey phase) and a constant sky
  const float* co_ = nullptr;
  const float* csky_ = nullptr;
  const float* ldir_ = nullptr;
  const float* mie_ = nullptr;
  std::array<const float*, kShCoefficients> sh_{};
  std::optional<SkyShScatter> sky_sh_;
  std::optional<SkyShScatter> sky_unit_sh_;  // precomputed with Co_sky: the unit sky's Eq. 5
  int sh_order_ = 0;                         // photon tallies' degree (0: none)
  int zonal_order_ = 0;                      // their zonal terms' top degree (0: none)
  std::vector<const float*> msh_, msky_sh_, ssky_sh_;
  std::vector<Rgb> phase_l_;
  Rgb albedo_;
  const SkyLight& sky_;
  PhaseLut lut_;
  const PhotonPeakLight* peak_ = nullptr;  // photon: the light scattered through the peak only
  Rgb g_;                                  // mean cosine per channel, for the P1 model
  bool p1_;          // the multiple term's angular model (see the header comment)
  bool phase_grey_;  // the phase is every channel's: one split, one P1 phase for all three
  Vec3 sun_dir_;
  double extinction_;
  double step_;
  double min_transmittance_;
  int nx_ = 0, ny_ = 0, nz_ = 0;
  size_t stride_y_ = 0, stride_z_ = 0;
  double inv_h_ = 1;
  Rgb scale_ss_, scale_ms_, scale_sky_;
  int nbx_ = 0, nby_ = 0, nbz_ = 0;
  const float* block_max_ = nullptr;   // the densest voxel per block (buildBlockMax)
  const uint8_t* occupied_ = nullptr;  // per cell, whether it holds density (occupiedCells)
  const float* pack_ = nullptr;  // the grids a sample reads, per voxel (buildPack; null: none)
  size_t stride_ = 4;
  // Photon tallies per voxel of their lattice (buildTallyPack): radiance, then the sky's.
  static constexpr int kMaxTallyFloats = 3 * (3 * shCount(kMaxShDegree) + kMaxZonalDegree) + 4;
  const float* tally_pack_ = nullptr;
  size_t tally_stride_ = 4;
  int tally_floats_ = 0, ssky_slot_ = 0, msky_slot_ = 0;
  std::vector<double> zonal_sinc_;  // 1 - sinc(pi l / (top + 1)) per zonal degree l
  // photon: the tallies' light towards the view per voxel (buildViewField; empty: none)
  static constexpr int kFieldFloats = 9;
  LargeArray<float> field_;
  double field_near_ = 0;       // samples nearer the eye than this keep the per-ray weights
  BakeViewCache::Impl& cache_;  // the blocks and packs, this render's own or shared by views
};

// Below this fraction of the light's scale (an isotropic scattering of the sun, plus the sky's
// mean), a film cell's differences are not worth tracing its pixels for.
constexpr double kFilmLightFloor = 1e-3;
// The share of a sparse film's progress its first pass reports.
constexpr double kFilmFirstPass = 0.3;

void put(FilmPixel* p, int k, const Rgb& v, double scale) {
  p->v[k] = static_cast<float>(v.x * scale);
  p->v[k + 1] = static_cast<float>(v.y * scale);
  p->v[k + 2] = static_cast<float>(v.z * scale);
}

// A pixel's layers as stored (sparse_film.h's layout): the per-ray sums over the rays.
FilmPixel filmPixel(const PixelSum& sum, double inv_spp) {
  FilmPixel p;
  const Rgb sun_total = sum.sun_single + sum.multiple;
  const Rgb sky_total = sum.sky + sum.sky_multiple;
  put(&p, 0, sun_total + sky_total + sum.background, inv_spp);
  p.v[3] = static_cast<float>(sum.alpha * inv_spp);
  put(&p, 4, sum.background, inv_spp);
  put(&p, 7, sun_total, inv_spp);
  put(&p, 10, sky_total, inv_spp);
  put(&p, 13, sum.sun_single + sum.sky, inv_spp);
  put(&p, 16, sum.multiple + sum.sky_multiple, inv_spp);
  return p;
}

void storeFilm(RenderLayers& out, int x, int y, const FilmPixel& p) {
  std::copy(p.v, p.v + 4, out.beauty.at(x, y));
  std::copy(p.v + 4, p.v + 7, out.background.at(x, y));
  std::copy(p.v + 7, p.v + 10, out.sun.at(x, y));
  std::copy(p.v + 10, p.v + 13, out.sky.at(x, y));
  std::copy(p.v + 13, p.v + 16, out.single.at(x, y));
  std::copy(p.v + 16, p.v + 19, out.multiple.at(x, y));
}

// The width of a pixel, world units, where it is widest over the lattice: at the lattice's
// farthest corner from the eye for a pinhole (by the centre pixel's angle, the widest of a
// planar film), everywhere the same for an orthographic camera.
double pixelFootprint(const CameraRays& rays, const Camera& camera, const BakeGrid& grid) {
  const double cx = 0.5 * camera.width_px, cy = 0.5 * camera.height_px;
  const Ray a = rays.generate(cx, cy), b = rays.generate(cx + 1, cy), c = rays.generate(cx, cy + 1);
  if (camera.type != Camera::Type::kPerspective) {
    return std::max(length(b.o - a.o), length(c.o - a.o));
  }
  const double angle = std::max(std::acos(std::clamp(dot(a.d, b.d), -1.0, 1.0)),
                                std::acos(std::clamp(dot(a.d, c.d), -1.0, 1.0)));
  const Bounds3 box = grid.bounds();
  double far = 0;
  for (int q = 0; q < 8; ++q) {
    const Vec3 p(q & 1 ? box.max.x : box.min.x, q & 2 ? box.max.y : box.min.y,
                 q & 4 ? box.max.z : box.min.z);
    far = std::max(far, length(p - a.o));
  }
  return far * angle;
}

// An interpolated pixel's background and beauty: the sky behind it (its rays' mean radiance)
// times its interpolated transmittance, 1 - alpha, as the march gives a traced ray's, since the
// sky (a map's detail) is not read from the lattice and may vary faster than it.
void seeSkyThrough(const Rgb& sky, FilmPixel* p) {
  const double transmittance = std::max(0.0, 1.0 - double(p->v[3]));
  for (int c = 0; c < 3; ++c) {
    p->v[4 + c] = static_cast<float>(sky[c] * transmittance);
    p->v[c] = p->v[7 + c] + p->v[10 + c] + p->v[4 + c];
  }
}

// Whether film column (or row) x of `size` is traced in every view of a sparse film: every
// `spacing`-th, and the last.
bool onFilmLine(int x, int size, int spacing) { return x % spacing == 0 || x == size - 1; }

// The film's traced columns (or rows), in order.
std::vector<int> filmLine(int size, int spacing) {
  std::vector<int> xs;
  for (int x = 0; x < size; ++x) {
    if (onFilmLine(x, size, spacing)) xs.push_back(x);
  }
  return xs;
}

FilmPixel readFilm(const RenderLayers& out, int x, int y) {
  FilmPixel p;
  std::copy(out.beauty.at(x, y), out.beauty.at(x, y) + 4, p.v);
  std::copy(out.background.at(x, y), out.background.at(x, y) + 3, p.v + 4);
  std::copy(out.sun.at(x, y), out.sun.at(x, y) + 3, p.v + 7);
  std::copy(out.sky.at(x, y), out.sky.at(x, y) + 3, p.v + 10);
  std::copy(out.single.at(x, y), out.single.at(x, y) + 3, p.v + 13);
  std::copy(out.multiple.at(x, y), out.multiple.at(x, y) + 3, p.v + 16);
  return p;
}

// Per film position in [lo, hi): the index of the traced position at or before it in xs, and
// whether it is one.
void locateOnLine(const std::vector<int>& xs, int lo, int hi, std::vector<int>* cell,
                  std::vector<uint8_t>* on) {
  cell->assign(size_t(hi - lo), 0);
  on->assign(size_t(hi - lo), 0);
  size_t i = 0;
  for (int x = lo; x < hi; ++x) {
    while (i + 1 < xs.size() && xs[i + 1] <= x) ++i;
    (*cell)[size_t(x - lo)] = int(i);
    (*on)[size_t(x - lo)] = xs[i] == x;
  }
}

// The traced positions of the film line `all` that a tile's pixels [lo, hi) read: the corners
// of their cells and two more on each side, so that each of their cells, and each cell beside
// them, is judged with its corners' second differences (as over the whole film: the image does
// not depend on the tiling).
std::vector<int> tileLine(const std::vector<int>& all, int lo, int hi, int spacing) {
  const int last = int(all.size()) - 1;
  const int a = std::max(0, lo / spacing - 2), b = std::min(last, (hi - 1) / spacing + 3);
  return std::vector<int>(all.begin() + a, all.begin() + b + 1);
}

// One tile of a sparse film after its traced pixels are stored in `out` (sparse_film.h): every
// other pixel traced where a cell it lies in or borders bends, interpolated elsewhere, with the
// sky behind it (sky_behind(x, y)) seen through its interpolated transmittance.
template <typename Trace, typename SkyBehind>
void fillSparseTile(const TileRect& t, const std::vector<int>& film_xs,
                    const std::vector<int>& film_ys, int spacing, const FilmTolerance& tol,
                    const TilePoll& poll, RenderLayers& out, Trace&& trace,
                    SkyBehind&& sky_behind) {
  const std::vector<int> xs = tileLine(film_xs, t.x0, t.x1, spacing);
  const std::vector<int> ys = tileLine(film_ys, t.y0, t.y1, spacing);
  const int nx = int(xs.size()), ny = int(ys.size());
  std::vector<FilmPixel> grid(size_t(nx) * ny);
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) grid[size_t(j) * nx + i] = readFilm(out, xs[i], ys[j]);
  }
  const std::vector<uint8_t> cells = filmCellsToTrace(grid, xs, ys, tol);
  auto traced = [&](int i, int j) {
    return i >= 0 && j >= 0 && i < nx - 1 && j < ny - 1 && cells[size_t(j) * (nx - 1) + i];
  };
  auto at = [&](int i, int j) -> const FilmPixel& { return grid[size_t(j) * nx + i]; };
  std::vector<int> ci, cj;
  std::vector<uint8_t> on_x, on_y;
  locateOnLine(xs, t.x0, t.x1, &ci, &on_x);
  locateOnLine(ys, t.y0, t.y1, &cj, &on_y);
  for (int y = t.y0; y < t.y1; ++y) {
    const int j = cj[size_t(y - t.y0)];
    const bool row = on_y[size_t(y - t.y0)];
    for (int x = t.x0; x < t.x1; ++x) {
      const int i = ci[size_t(x - t.x0)];
      const bool col = on_x[size_t(x - t.x0)];
      if (row && col) continue;  // traced in the first pass
      // A pixel on a traced row or column borders the cells on both sides of it.
      if (traced(i, j) || (row && traced(i, j - 1)) || (col && traced(i - 1, j))) {
        if (poll.stop()) return;
        storeFilm(out, x, y, trace(x, y));
        continue;
      }
      const int i1 = col ? i : i + 1, j1 = row ? j : j + 1;
      const double fx = col ? 0.0 : double(x - xs[i]) / (xs[i1] - xs[i]);
      const double fy = row ? 0.0 : double(y - ys[j]) / (ys[j1] - ys[j]);
      FilmPixel p = interpolateFilm(at(i, j), at(i1, j), at(i, j1), at(i1, j1), fx, fy);
      seeSkyThrough(sky_behind(x, y), &p);
      storeFilm(out, x, y, p);
    }
  }
}

// Renders a film of w x h pixels into `out`, each traced by trace_pixel(x, y, rng, scratch):
// every pixel (spacing 1), or a sparse film in two passes over the tiles (sparse_film.h), the
// traced pixels and then the cells between them, whose interpolated pixels see the sky
// sky_behind(x, y, rng) through the cloud. `setup` runs first, in the render's arena. False if
// `progress` cancelled it.
template <typename TracePixel, typename SkyBehind>
bool renderFilm(int w, int h, int spacing, const FilmTolerance& tolerance, int threads,
                const ProgressFn& progress, RenderLayers& out, TracePixel&& trace_pixel,
                SkyBehind&& sky_behind, const std::function<void()>& setup) {
  std::atomic<int64_t> traced{0};  // out.traced_pixels
  auto counted = [&](int x, int y, Rng& rng, BakeMarcher::Scratch* scratch) {
    traced.fetch_add(1, std::memory_order_relaxed);
    return trace_pixel(x, y, rng, scratch);
  };
  auto trace_tile = [&](const TileRect& t, const TilePoll& poll) {
    Rng rng;
    BakeMarcher::Scratch scratch;
    for (int y = t.y0; y < t.y1; ++y) {
      if (!onFilmLine(y, h, spacing)) continue;
      for (int x = t.x0; x < t.x1; ++x) {
        if (!onFilmLine(x, w, spacing)) continue;
        if (poll.stop()) return;
        storeFilm(out, x, y, counted(x, y, rng, &scratch));
      }
    }
  };
  bool finished = false;
  if (spacing == 1) {
    finished = renderTiles(w, h, kTileSize, threads, progress, trace_tile, setup);
  } else {
    const std::vector<int> film_xs = filmLine(w, spacing), film_ys = filmLine(h, spacing);
    auto fill_tile = [&](const TileRect& t, const TilePoll& poll) {
      Rng rng;
      BakeMarcher::Scratch scratch;
      fillSparseTile(
          t, film_xs, film_ys, spacing, tolerance, poll, out,
          [&](int x, int y) { return counted(x, y, rng, &scratch); },
          [&](int x, int y) { return sky_behind(x, y, rng); });
    };
    // The traced pixels are about a third of the work, the cells that bend the rest.
    ProgressFn first, second;
    if (progress) {
      first = [&](double f) { return progress(kFilmFirstPass * f); };
      second = [&](double f) { return progress(kFilmFirstPass + (1 - kFilmFirstPass) * f); };
    }
    finished = renderTiles(w, h, kTileSize, threads, first, trace_tile, setup) &&
               renderTiles(w, h, kTileSize, threads, second, fill_tile);
  }
  out.traced_pixels = traced.load();
  return finished;
}

void validateBake(const BakedLight& bake) {
  const BakeGrid& g = bake.grid;
  if (g.nx < 1 || g.ny < 1 || g.nz < 1) {
    throw InputError("bake: lattice is empty (" + str(g.nx) + "x" + str(g.ny) + "x" + str(g.nz) +
                     " voxels)");
  }
  if (!std::isfinite(g.voxel_size) || !(g.voxel_size > 0)) {
    throw InputError("bake: voxel size must be finite and > 0, got " + str(g.voxel_size));
  }
  if (!isFinite(g.origin)) throw InputError("bake: lattice origin must be finite");
  if (bake.density.size() != g.voxelCount()) {
    throw InputError("bake: grid 'density': expected " + str(g.voxelCount()) + " values for the " +
                     str(g.nx) + "x" + str(g.ny) + "x" + str(g.nz) + " lattice, got " +
                     str(bake.density.size()));
  }
  const double len = length(bake.sun_direction);
  if (!isFinite(bake.sun_direction) || !(len > 0) || !std::isfinite(len)) {
    throw InputError("bake: sun_direction must be a finite non-zero vector, got " +
                     str(bake.sun_direction));
  }
}

}  // namespace

// A midpoint rule on directions uniform in z = cos(theta) and azimuth (equal-area cells, equal
// weights). The horizon z = 0 is a cell boundary, so a gradient sky (linear in z above, constant
// below) is integrated exactly.
Rgb meanSkyRadiance(const Sky& sky, const SkyLight& light) {
  if (light.black()) return Rgb(0.0);
  if (sky.type == Sky::Type::kConstant) return sky.radiance;
  constexpr int kNz = 256, kNphi = 512;
  // Row by row, then the rows in order: a row's sum is of like terms (the gradient sky's are
  // equal), which keeps its rounding small.
  std::array<Rgb, kNz> rows;
  rows.fill(Rgb(0.0));
  forEachEqualAreaCell<kNz, kNphi>(
      [&](int i, const Vec3& w) { rows[size_t(i)] += light.radiance(w); });
  Rgb sum(0.0);
  for (const Rgb& row : rows) sum += row;
  return sum / (double(kNz) * kNphi);
}

int filmSpacingOf(const BakedLight& bake, const Camera& camera, const BakeRenderOptions& options) {
  if (options.max_film_spacing <= 1 || camera.width_px < 2 || camera.height_px < 2) return 1;
  return sparseFilmSpacing(pixelFootprint(CameraRays(camera), camera, bake.grid),
                           bake.grid.voxel_size, options.max_film_spacing);
}

namespace {

void validateSunIrradiance(const Sun& sun) {
  if (!isFinite(sun.irradiance) || sun.irradiance.x < 0 || sun.irradiance.y < 0 ||
      sun.irradiance.z < 0) {
    throw InputError("sun.irradiance: must be finite and >= 0 per channel, got " +
                     str(sun.irradiance));
  }
}

}  // namespace

RenderLayers renderFromBake(const BakedLight& bake, const Medium& medium, const Sun& sun,
                            const Sky& sky, const Camera& camera, const BakeRenderOptions& options,
                            const ProgressFn& progress) {
  validateMediumOptics(medium);
  validateBake(bake);
  validateOptions(options, bake.grid.voxel_size);
  validateSunIrradiance(sun);
  const CameraRays rays(camera);
  const SkyLight sky_light(sky);
  const Rgb sky_mean = meanSkyRadiance(sky, sky_light);
  const double step = options.step > 0 ? options.step : 0.5 * bake.grid.voxel_size;
  const Vec3 sun_dir = normalize(bake.sun_direction);

  const int w = camera.width_px, h = camera.height_px;
  const int spp = options.samples_per_pixel;
  const double inv_spp = 1.0 / spp;
  // Stratified film positions: an sx x sy jittered grid, the remainder uniform in the pixel.
  const int sx = std::max(1, int(std::floor(std::sqrt(double(spp)))));
  const int sy = spp / sx;

  ViewGeometry view;
  const Ray centre = rays.generate(0.5 * w, 0.5 * h);
  view.pinhole = camera.type == Camera::Type::kPerspective;
  view.eye = centre.o;
  view.forward = centre.d;
  view.rays = options.view_field ? double(w) * double(h) * spp : 0.0;
  if (progress) view.cancelled = [&progress](double) { return !progress(0.0); };

  RenderLayers out = makeRenderLayers(w, h);
  std::optional<BakeViewCache> own_cache;  // where options.cache is null; outlives the marcher
  std::optional<BakeMarcher> marcher;
  // Calls f(ray) for each of pixel (x, y)'s rays.
  auto for_each_ray = [&](int x, int y, Rng& rng, auto&& f) {
    if (spp == 1) {
      f(rays.generate(x + 0.5, y + 0.5));
      return;
    }
    // One stream per pixel: the image depends neither on threads nor on tiling.
    const uint64_t pixel = uint64_t(y) * uint64_t(w) + uint64_t(x);
    rng.setSeed(mixBits(options.seed, pixel), mixBits(pixel, options.seed));
    for (int s = 0; s < spp; ++s) {
      double fx, fy;
      if (s < sx * sy) {
        fx = x + ((s % sx) + rng.uniform()) / sx;
        fy = y + ((s / sx) + rng.uniform()) / sy;
      } else {
        fx = x + rng.uniform();
        fy = y + rng.uniform();
      }
      f(rays.generate(fx, fy));
    }
  };
  auto trace_pixel = [&](int x, int y, Rng& rng, BakeMarcher::Scratch* scratch) {
    PixelSum sum;
    for_each_ray(x, y, rng, [&](const Ray& ray) { marcher->trace(ray, &sum, scratch); });
    return filmPixel(sum, inv_spp);
  };
  // The sky behind an interpolated pixel: its rays' mean sky radiance (sparse_film.h).
  auto sky_behind = [&](int x, int y, Rng& rng) {
    Rgb sum(0.0);
    if (!sky_light.black()) {
      for_each_ray(x, y, rng, [&](const Ray& ray) { sum += sky_light.radiance(ray.d); });
    }
    return sum * inv_spp;
  };
  const int spacing = filmSpacingOf(bake, camera, options);
  FilmTolerance tolerance;
  tolerance.light_floor =
      kFilmLightFloor * (maxComponent(sun.irradiance) * kInv4Pi + maxComponent(sky_mean));
  // The marcher is built inside the render's arena: its block maxima are computed in parallel.
  const bool finished = renderFilm(
      w, h, spacing, tolerance, options.threads, progress, out, trace_pixel, sky_behind, [&] {
        marcher.emplace(bake, medium, sun, sky_light, sky_mean, sun_dir, step,
                        options.min_transmittance, view,
                        options.cache ? options.cache->impl() : own_cache.emplace().impl());
      });
  if (!finished) throw Cancelled("render from bake of view '" + camera.name + "' cancelled");
  return out;
}

}  // namespace cloudbake
