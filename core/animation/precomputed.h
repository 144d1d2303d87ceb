// Method `precomputed` (seed 002, Iwasaki et al. 2011): per basic volume, the optical depth to
// the sky as SH vectors and the clustered voxel-to-sample transfers; per frame of the endless
// animation, the blended density lit from those precomputes alone (Eq. 2-9) as a BakedLight
// that renderFromBake draws.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <vector>

#include "core/animation/basic_volumes.h"
#include "core/animation/sample_transfer.h"
#include "core/animation/shexp.h"
#include "core/animation/video_texture.h"
#include "core/bake/baked_light.h"
#include "core/math/spherical_harmonics.h"

namespace cloudbake {

/// Knobs of the per-basic-volume precompute.
struct PrecomputeOptions {
  int sample_points = 4096;      ///< K, [1, 2^20]
  int transfer_resolution = 32;  ///< receiver voxels along the longest side, [4, 512]
  TransferCutOptions cuts;       ///< cut_error, max_cut
  int sh_directions = 64;        ///< sweeps per voxel for the optical-depth SH, [16, 4096]
  uint64_t seed = 1;             ///< sample points
};

/// What one basic volume keeps for run time.
struct BasicVolumePrecompute {
  std::vector<ShCoefficients> optical_depth_sh;  ///< per lattice voxel: SH of tau(x, w)
  TransferCuts cuts;                             ///< per receiver
  double seconds = 0;                            ///< wall time of this volume's precompute
  size_t bytes() const;
};

/// The database with everything the run time reads. Every basic volume shares the lattice,
/// the receiver lattice, the sample points and their tree (so cuts merge) and the SHEXP tables.
struct PrecomputedDatabase {
  BasicVolumeDatabase volumes;
  double extinction = 1;  ///< sigma_t per unit density per world unit the precompute used
  BakeGrid receivers;
  std::vector<uint8_t> receiver_mask;  ///< receivers near any basic volume's density
  SampleTree tree;
  ShExp shexp;
  std::vector<BasicVolumePrecompute> basic;
};

/// Precomputes every basic volume of `volumes` (optical depth SH by sweeps, SHEXP tables fitted
/// on voxels of the first volume, cuts over K samples of the union of their supports).
/// Parallel over volumes and inside each. InputError for knobs out of range or an empty database;
/// `progress(fraction)` returning false cancels (Cancelled).
PrecomputedDatabase precomputeBasicVolumes(BasicVolumeDatabase volumes, double extinction,
                                           const PrecomputeOptions& options,
                                           const std::function<bool(double)>& progress = {});

/// The steps of precomputeBasicVolumes, for a farm that precomputes groups of basic volumes as
/// separate tasks (core/job/task_plan.h); run in order they give the same database bit for bit.
/// layoutBasicVolumes: what every basic volume shares (lattices, receiver mask, sample tree),
/// `basic` left empty; InputError as precomputeBasicVolumes.
PrecomputedDatabase layoutBasicVolumes(BasicVolumeDatabase volumes, double extinction,
                                       const PrecomputeOptions& options);
/// Basic volume `f` of a laid-out database; `progress(fraction)` returning false cancels.
BasicVolumePrecompute precomputeBasicVolume(const PrecomputedDatabase& db, size_t f,
                                            const PrecomputeOptions& options,
                                            const std::function<bool(double)>& progress = {});
/// Fits the SHEXP tables once db.basic holds every basic volume (InternalError otherwise).
void finishDatabase(PrecomputedDatabase& db);

/// Knobs of a frame's lighting.
struct FrameLightOptions {
  int max_orders = 64;      ///< multiple-scattering orders after the first, [1, 1000]
  double tolerance = 0.01;  ///< stop when an order adds less than this fraction, (0, 1]
  /// The phase function's mean cosine g per channel. With `similarity`, multiple scattering runs
  /// on the similarity-reduced medium (extinction (1 - lum(a g)) sigma_t, albedo a (1 - g) / that
  /// factor; van de Hulst), and the light scattered into the forward peak travels on with the
  /// sun as a beam; without it (or for g = 0) it is seed 002's plain isotropic scattering.
  Rgb mean_cosine{0, 0, 0};
  bool similarity = true;
  /// Voxels between the sky transmittance's SHEXP evaluations along each axis, 1 or 2. With 2,
  /// SHEXP runs on every second voxel (and the last) of each axis, and a voxel of the cloud
  /// whose corner nodes all hold density and agree on the mean transmittance within 0.1
  /// interpolates the 16 coefficients trilinearly; the others (the support's margin, sheets a
  /// voxel thick, steep edges) are evaluated (version 8). 1 evaluates every voxel of the
  /// support (version 7).
  int sky_spacing = 2;
};

/// What computing one frame measured.
struct FrameLightStats {
  int orders = 0;  ///< scattering orders iterated (Eq. 8)
  double seconds = 0;
  size_t merged_entries = 0;   ///< entries of the merged cuts, summed over receivers
  size_t sky_evaluations = 0;  ///< voxels whose sky transmittance SHEXP evaluated
  size_t support_voxels = 0;   ///< voxels of the blended density's support
  /// Seconds of each stage, which add up to `seconds`: the blended density and its sun
  /// transmittance; the sky transmittance (Eq. 6-7, SHEXP); the receivers' cuts and first-order
  /// sources; the scattering orders (Eq. 8) and the sky's fractions; the multiple-scattering
  /// grids; the mean radiance, the trim to the support and the checks of every grid.
  double seconds_sun = 0, seconds_sky = 0, seconds_receivers = 0, seconds_orders = 0,
         seconds_multiple = 0, seconds_finish = 0;
};

/// Lights the blended frame `frame` (rho = w rho_a + (1 - w) rho_b) for a sun towards
/// `sun_direction` and the sky `sky_sh` (RGB SH of the sky radiance; all zero for a black sky):
/// - sun_transmittance: one sweep through the blended density (Eq. 2's tau; exact phase at
///   render time);
/// - sky_transmittance_sh_0..15: Eq. 6 (blended optical-depth SH) and SHEXP (Eq. 7), for Eq. 5
///   at render time; sky_visibility its mean over the sphere;
/// - Co (per unit sun irradiance) and Co_sky (per unit mean sky radiance, as the render reads
///   it): isotropic multiple scattering by Eq. 8 over the merged cuts (Eq. 9), starting from
///   the single-scattered light of sun and sky, orders until an order adds less than the
///   tolerance.
/// `albedo` is the medium's single-scattering albedo. With the similarity reduction
/// (FrameLightOptions) Co also holds the forward-scattered sun beam T_sun^s - T_sun, with
/// light_dir = -sun_direction and mie_ratio its share of Co, so a view scatters it with the full
/// phase function; otherwise the result holds no light_dir or mie_ratio. It validates.
BakedLight lightAnimationFrame(const PrecomputedDatabase& db, const BlendFrame& frame,
                               const Vec3& sun_direction, const Rgb& albedo,
                               const std::array<ShCoefficients, 3>& sky_sh,
                               const FrameLightOptions& options, FrameLightStats* stats = nullptr);

}  // namespace cloudbake
