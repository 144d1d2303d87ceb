// Method `pointcloud`: multiple scattering between points inside the cloud, pass by pass, with a
// Mie/isotropic ratio per point (Reimschuessel 2011, "Rendering Realistic Cloud Effects for
// Computer Generated Films"), beside the lattice of method `single`.
#pragma once

#include "core/bake/pointcloud_bake.h"
#include "core/methods/method.h"

namespace cloudbake {

const BakeMethod& pointcloudMethod();

/// The shot's knobs as the bake's options, with bake.seed (the shot's method is `pointcloud`).
PointcloudOptions pointcloudOptions(const ShotSpec& shot);

}  // namespace cloudbake
