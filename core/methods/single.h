// Method `single`: single scattering from a precomputed transmittance-to-sun lattice, as in
// slsdo's "Volumetric Clouds" voxel ray marcher (2010), with the exact phase function applied
// when a view is rendered; multiple scattering is not modelled.
#pragma once

#include "core/bake/single_bake.h"
#include "core/methods/method.h"

namespace cloudbake {

const BakeMethod& singleMethod();

/// The shot's knobs as the bake's options (the shot's method is `single`).
SingleBakeOptions singleBakeOptions(const ShotSpec& shot);

}  // namespace cloudbake
