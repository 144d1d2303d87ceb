// The bake methods of a shot (single, pointcloud): its knobs as option structs, the bake itself.
#pragma once

#include <string>
#include <vector>

#include "core/bake/baked_light.h"
#include "core/bake/pointcloud_bake.h"
#include "core/bake/render_from_bake.h"
#include "core/bake/single_bake.h"
#include "core/shot/shot.h"

namespace cloudbake {

/// `bake` knobs of a method-`single` shot (defaults where absent; docs/shot-format.md).
SingleBakeOptions singleBakeOptions(const ShotSpec& shot);

/// `bake` knobs of a method-`pointcloud` shot, with bake.seed.
PointcloudOptions pointcloudOptions(const ShotSpec& shot);

/// How views of a bake-method shot are rendered: `step`, bake.samples rays per pixel, bake.seed.
BakeRenderOptions bakeRenderOptions(const ShotSpec& shot, int threads);

/// What baking the shot's light involves, one line per component, for dry runs ("sun
/// transmittance: 128-voxel lattice", "sky visibility: skipped (black sky)", ...). `cached`: the
/// bake exists, so the only line says so.
std::vector<std::string> planBake(const ShotSpec& shot, bool cached);

/// Bakes the shot's light with its method (single or pointcloud) for its sun direction
/// ((0, 0, 1) when the shot has no sun), with medium's density, extinction, albedo and phase.
/// Throws InputError for other methods.
BakedLight bakeShotLight(const ShotSpec& shot, const Medium& medium,
                         const BakeProgressFn& progress = {}, PointcloudStats* stats = nullptr);

}  // namespace cloudbake
