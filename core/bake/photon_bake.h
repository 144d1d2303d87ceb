// Method `photon`: multiply scattered light traced from the sun and the sky as photons and
// tallied per lattice voxel in spherical harmonics; single scattering exact at render time.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "core/bake/bake_progress.h"
#include "core/bake/baked_light.h"
#include "core/bake/phase_lut.h"
#include "core/math/sh_basis.h"
#include "core/phase/forward_peak.h"
#include "core/phase/phase_function.h"
#include "core/transport/scene.h"

namespace cloudbake {

namespace bake_grids {
/// Vec3 (RGB): coefficient i (l * l + l + m, core/math/sh_basis.h) of the radiance of sunlight
/// that has scattered at least once, per unit sun irradiance (W m^-2 sr^-1 per W m^-2, times
/// the basis' sr^1/2 normalisation: integral of L Y_i over directions of travel).
std::string photonSh(int i);
/// Vec3 (RGB): the same for sky light, per unit mean radiance of the baked sky (a uniform sky of
/// unit radiance unless PhotonBakeOptions::sky_shape).
std::string photonSkySh(int i);
/// Vec3 (RGB): the same for sky light not yet scattered (the sky seen through the cloud): its
/// convolution with the phase is the sky's single scattering, view-dependent for any phase.
std::string photonSkyDirectSh(int i);
/// float, on the bake's lattice: the factor by which a view scales the sky's single scattering
/// from photonSkyDirectSh at that point (since photon 14): the lattice's visibility of the sky
/// there (sky_visibility and its first moment, weighted by the sky's own P1 shape) over its
/// mean over the tally voxel, read as the tally is read. It moves the tally's amount, a mean
/// over the coarser voxel, to the point; 1 where the tally is on the bake's lattice. In
/// [0, kMaxSkySingleScale].
std::string photonSkySingleScale();
/// Vec3 (RGB): the zonal coefficient of degree l (order < l <= zonal_order) of the radiance of
/// sunlight scattered at least once, about the axis along which sunlight travels (-sun
/// direction): integral of L(w) sqrt((2l + 1) / (4 pi)) P_l(w . axis) over directions of travel,
/// per unit sun irradiance. The forward peak of scattered sunlight lies about that axis.
std::string photonZonal(int l);
}  // namespace bake_grids

/// Knobs of method `photon` (docs/shot-format.md).
struct PhotonBakeOptions {
  /// Lattice voxels along the longest side of the volume's bounds, [8, 1024] (on a grid's own
  /// voxels where it allows, LatticeSampling::kFieldAligned): the density and the transmittance
  /// to the sun, which the exact single scattering of every view reads.
  int light_resolution = 128;
  /// The tallies' lattice over the same bounds, [8, 1024], or 0 for the bake's lattice: the
  /// scattered light is smooth, so a coarser lattice gathers more photons per voxel.
  int tally_resolution = 48;
  /// Photons from the sun, and as many from the sky when it is not black, [1, 2^31).
  int64_t photons = 1 << 19;
  /// Highest spherical-harmonic degree of the tally, [1, 8]: (order + 1)^2 coefficients.
  int order = 3;
  /// Highest degree of the extra zonal terms about the sun's axis, 0 (none) or in
  /// (order, kMaxZonalDegree]: the degrees the full expansion truncates, kept where the forward
  /// peak of scattered sunlight puts most of them (zonal_order - order coefficients more).
  int zonal_order = 24;
  uint64_t seed = 1;  ///< photon streams: the same bake at any thread count
  /// Ray-march step of the view renders, world units; 0: half a lattice voxel.
  double step = 0;
  bool sky = true;  ///< trace sky photons and bake sky_visibility (false for a black sky)
  /// Trace sun photons (false for a black sun: its tallies are zero, the error estimates the
  /// sky's).
  bool sun = true;
  /// The sky whose light sky photons carry, per unit of its mean radiance (meanSkyRadiance):
  /// each photon is weighted by the radiance of the direction it comes from over that mean, per
  /// channel. Null: a uniform sky, whose bake serves every sky colour. A gradient or map sky's
  /// bake is of its shape (the light key holds it).
  const Sky* sky_shape = nullptr;
};

/// The largest photonSkySingleScale: a point that sees far more sky than its tally voxel's mean
/// lies at a dense voxel's lit corner, where a larger factor would multiply the tally's noise.
constexpr double kMaxSkySingleScale = 4;

/// A bake's own estimates of its error in the multiply scattered sunlight (the sky's light under
/// a black sun; relative, over the voxels weighted by density), written to its metadata as
/// cloudbake:tally_noise and cloudbake:truncation.
struct PhotonErrorEstimate {
  /// The tally's noise: the fluence of the even and the odd photons compared, RMS of their
  /// difference over RMS of the fluence (the difference of two independent halves has the
  /// variance of their sum). Per voxel: a view averages several, so its noise is lower.
  double tally_noise = 0;
  /// The truncation: the RMS over directions of what the two highest degrees the tally keeps
  /// (the zonal ones when it has them) add to the in-scattered light (its Funk-Hecke
  /// convolution with the phase, L against L - 2), over that of all of it.
  double truncation = 0;
};

/// p_l = 2 pi integral of p(mu) P_l(mu) dmu for l = 0..degree, per channel: the Funk-Hecke
/// factors with which a phase function convolves degree l of a spherical-harmonic expansion
/// (p_0 = 1 for a normalised phase, p_1 = its mean cosine g). Integrated in theta on a fine grid
/// so droplet peaks are resolved.
std::vector<Rgb> phaseLegendreCoefficients(const PhaseFunction& phase, int degree);

/// Where a photon bake with options `o` splits `phase`'s forward peak off: no cut (inactive)
/// where its Legendre coefficient at degree max(order, zonal_order, 24) is at most 0.1, else
/// the narrowest cut (at most 30 degrees) that brings the rest's under it. InputError naming
/// /medium/phase where none does (a backward peak), before any work: methods check it at submit
/// where the phase is cheap to build.
ForwardPeak photonPeakSplit(const PhaseFunction& phase, const PhotonBakeOptions& o);

/// The fluence of the sunlight scattered through the forward peak only, per unit sun irradiance,
/// where the sun's transmittance is `tsun`: Tsun^e - Tsun per channel (PhotonPeakLight). Single
/// precision: views evaluate it at every sample of the march.
inline Rgb photonPeakFluence(double tsun, const Rgb& e) {
  if (!(tsun > 0)) return Rgb(0.0);
  const float l = std::log(float(tsun));
  // A grey albedo's channels share one exponential (the same value: a sixth of a view's time
  // was these exponentials).
  if (e.x == e.y && e.y == e.z) return Rgb(double(std::exp(l * float(e.x))) - tsun);
  return Rgb(std::exp(l * float(e.x)), std::exp(l * float(e.y)), std::exp(l * float(e.z))) -
         Rgb(tsun);
}

/// Sunlight scattered through the phase's forward peak only, where a bake split it off
/// (cloudbake:peak_cut_deg > 0): it travels within the cut of the sun's direction, attenuated by
/// every scattering but those through the peak, so its fluence per unit sun irradiance is
/// Tsun^e - Tsun with e = 1 - albedo x the peak's fraction per channel (the scaled direct beam of
/// delta-M less the direct beam). Views scatter it with `phase` convolved with the peak once per
/// scattering through it (PeakKernel): the light scattered k times through it holds a share
/// (1 - r) r^(k - 1) of that fluence, r = albedo x fraction, summed to k = 4 (the rest with the
/// fourth). Tabulated as `phase` is.
struct PhotonPeakLight {
  PhotonPeakLight(const PhaseLut& phase, double cut_deg, const Rgb& albedo);
  Rgb exponent;        ///< e per channel
  PhaseLut scattered;  ///< the convolved phase, sr^-1

  Rgb fluence(double tsun) const { return photonPeakFluence(tsun, exponent); }

 private:
  PhotonPeakLight(const PhaseLut& phase, const PeakKernel& kernel, const Rgb& albedo);
};

/// Bakes `medium` for a sun in direction `sun_dir` (unit, towards the sun): the lattice, the
/// sun_transmittance grid (exact single scattering at render time), sky_visibility when
/// options.sky, the photon tallies photonSh(i) (and photonSkySh(i)) of the light that has
/// scattered at least once, photonZonal(l) of the sunlight's zonal degrees above the order, and
/// photonSkyDirectSh(i) of the sky light that has not. Photons are
/// emitted per unit sun irradiance over the lattice's shadow (and per unit mean radiance of the
/// sky, options.sky_shape or uniform, from its bounding sphere), tracked by decomposition tracking
/// through the medium's own density (core/transport/tracking.h), scatter with the albedo and the
/// exact phase function (throughput value / pdf per channel; where the phase's Legendre
/// coefficient at degree max(order, zonal_order, 24) is above 0.1, a sun photon's scatterings
/// through its forward peak, split off at the narrowest cut that brings it under (ForwardPeak,
/// at most 30 degrees, else InputError) are not tallied until it scatters through the rest: see
/// PhotonPeakLight), are rouletted on their throughput
/// after three scatterings, and add every segment after their first scattering (for the sky: every
/// segment, the ones before it to the direct tally) to the voxels it crosses (track-length
/// estimator: segment length x weight x Y_i(direction of travel) / voxel volume). Tallies are
/// fixed-point integers added atomically, so the bake is the same at any thread count. InputError
/// for bad options or medium, Cancelled on request.
BakedLight bakePhoton(const Medium& medium, const Vec3& sun_dir, const PhotonBakeOptions& options,
                      const BakeProgressFn& progress = {});

}  // namespace cloudbake
