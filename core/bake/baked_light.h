// The result of every bake method: light scattering computed once for one sun direction, stored
// per unit sun irradiance on a voxel lattice, so any view and any sun colour renders from it.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "core/bake/bake_grid.h"
#include "core/math/first_touch_allocator.h"
#include "core/math/vec3.h"

namespace cloudbake {

/// Names of the grids a bake may hold (also their names in the .vdb file; docs/outputs.md).
/// Light values are per unit sun irradiance E, so a render multiplies them by the shot's E.
namespace bake_grids {
/// float, unitless: the shot's density (sigma_t = extinction * density per world unit).
constexpr const char* kDensity = "density";
/// float in [0, 1]: transmittance from the voxel centre to the sun, i.e. the direct sun
/// irradiance reaching the voxel per unit E (seed 004's precomputed transmittance; seed 000's Ci).
constexpr const char* kSunTransmittance = "sun_transmittance";
/// float in [0, 1]: transmittance to the sky averaged over all directions (only when the shot's
/// sky is not black).
constexpr const char* kSkyVisibility = "sky_visibility";
/// Vec3, unitless, length <= sky_visibility: the first moment of the transmittance to the sky,
/// B = (1 / 4 pi) integral T(x, w) w dw, w the unit direction from the voxel towards the sky,
/// from the same 26 directions (methods single and pointcloud, when the sky is not black). With
/// sky_visibility it is the transmittance's P1 expansion, T(w) ~ V + 3 B . w, by which a view
/// weights the phase function in the sky's single scattering (docs/methods.md).
constexpr const char* kSkyVisibilityVector = "sky_visibility_vector";
/// Vec3 (RGB), unitless: fluence (radiance integrated over the sphere) of sun light that has
/// already been scattered at least once, per unit E (seed 000's Co; what it scatters towards a
/// view is multiple scattering; arbitrary scale under the paper's rule).
constexpr const char* kMultipleFluence = "Co";
/// Vec3 (RGB), unitless: fluence of sky light scattered at least once, per unit radiance of a
/// uniform sky (the normalised pointcloud rule; a view scales it by the sky's mean radiance).
constexpr const char* kSkyMultipleFluence = "Co_sky";
/// Vec3, unit or zero: the prominent direction in which multiply scattered light travels at the
/// voxel (seed 000's L).
constexpr const char* kLightDir = "light_dir";
/// float in [0, 1]: the Mie fraction R of the multiply scattered light (seed 000's R; 1 = all
/// along light_dir with the full phase function, 0 = isotropic).
constexpr const char* kMieRatio = "mie_ratio";
/// Vec3 (RGB), sr^-1: mean radiance of the light arriving at the voxel per unit E,
/// (sun_transmittance + Co) / (4 pi): the isotropic preview DCCs (Houdini, Blender) can shade
/// with emission = sigma_s * Cd * E.
constexpr const char* kCd = "Cd";
}  // namespace bake_grids

/// The density's support on a lattice: 1 for every voxel with a density > 0 in its
/// 26-neighbourhood (itself included), the voxels a trilinear lookup can weight with non-zero
/// density; 0 elsewhere. `density` holds grid.voxelCount() values. Parallel, deterministic.
std::vector<uint8_t> densitySupport(const BakeGrid& grid, const std::vector<float>& density);

/// `mask` (one byte a voxel of `grid`) grown by one voxel: 1 where any voxel of the
/// 26-neighbourhood (itself included) is set. Parallel, deterministic.
std::vector<uint8_t> dilateSupport(const BakeGrid& grid, const std::vector<uint8_t>& mask);

/// Where a bake holds the sun's transmittance: the density's support (densitySupport) grown by
/// two voxels, so within three voxels of any density > 0. A view's short characteristic reads
/// it in the plane of voxels up to two voxels towards the sun and one across from a sample
/// next to density (render_from_bake.cpp, BakeMarcher::sunTransmittanceAt).
std::vector<uint8_t> sunTransmittanceSupport(const BakeGrid& grid,
                                             const std::vector<uint8_t>& support);

/// The first and last voxels of the support within one lattice row of n voxels (`row`, from
/// densitySupport): what a per-row loop needs to visit. False when the row has none.
bool supportSpan(const uint8_t* row, int n, int* first, int* last);

/// One grid of a bake: `components` floats per voxel (1 or 3), interleaved, in BakeGrid order.
struct BakeChannel {
  int components = 1;
  /// On BakedLight::tally_grid rather than BakedLight::grid (method photon's tallies).
  bool on_tally_grid = false;
  /// Its pages first touched by the worker threads (first_touch_allocator.h).
  FirstTouchFloats data;
};

/// A bake: the lattice, the density and the light grids, and where they came from.
///
/// `sun_direction` (unit, from the scene towards the sun) is the direction the light was baked
/// for; `metadata` holds provenance written to the .vdb file as string metadata (method knobs,
/// medium, statistics, code version; keys "cloudbake:*").
struct BakedLight {
  BakeGrid grid;
  /// The lattice of the channels with on_tally_grid (method photon's radiance tallies): the same
  /// bounds as `grid`, usually coarser, so the smooth scattered light costs fewer voxels than the
  /// density and the transmittance to the sun need. Empty (no voxels) when no channel uses it.
  BakeGrid tally_grid;
  std::string method;  ///< "single" or "pointcloud"
  Vec3 sun_direction{0, 0, 1};
  std::map<std::string, std::string> metadata;
  std::vector<float> density;                   ///< grid.voxelCount() values
  std::map<std::string, BakeChannel> channels;  ///< every grid but density, by name

  /// The channel, or nullptr when the bake has none of that name.
  const BakeChannel* find(const std::string& name) const;
  /// Adds (or replaces) a zero-filled channel of grid.voxelCount() * components floats.
  BakeChannel& add(const std::string& name, int components);
  /// The same on tally_grid.
  BakeChannel& addOnTallyGrid(const std::string& name, int components);
  /// The lattice channel `c` lies on.
  const BakeGrid& gridOf(const BakeChannel& c) const { return c.on_tally_grid ? tally_grid : grid; }

  /// Adds (or replaces) Cd = (sun_transmittance + Co) / (4 pi) per channel, the mean radiance
  /// arriving per unit E for an isotropic preview; a missing grid counts as 0.
  void addMeanRadiance();

  /// Zeroes every light channel outside the support of the density (voxels within one voxel,
  /// in the 26-neighbourhood, of a voxel with density > 0): trilinear lookups never read them
  /// with a non-zero density weight, and a .vdb file stores only that support, so a bake and its
  /// file read back are identical. The sun's transmittance keeps two voxels more
  /// (sunTransmittanceSupport), which views read. Bake methods call it last. Channels on
  /// tally_grid keep their values (a file stores their non-zero voxels).
  void trimToSupport();
  /// The same with the support already computed (densitySupport of this density).
  void trimToSupport(const std::vector<uint8_t>& support);

  /// Throws InputError("<what>: grid '<name>': ...") naming the grid and the first bad voxel
  /// (index and world position) when: a size does not match the lattice; a value is NaN or
  /// infinite; density < 0; sun_transmittance, sky_visibility or mie_ratio outside [0, 1];
  /// Co < 0; light_dir neither unit (within 1e-3) nor zero; the lattice is empty or its voxel size
  /// not finite and > 0; sun_direction not unit.
  void validate(const std::string& what) const;
};

}  // namespace cloudbake
