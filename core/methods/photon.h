// Method `photon`: a path-traced radiance cache. Light that has scattered at least once is traced
// from the sun and the sky as photons and tallied per lattice voxel in spherical harmonics; views
// add exact single scattering to the Funk-Hecke convolution of the tally with the phase function.
#pragma once

#include "core/bake/photon_bake.h"
#include "core/methods/method.h"

namespace cloudbake {

const BakeMethod& photonMethod();

/// The shot's knobs as the bake's options (the shot's method is `photon`).
PhotonBakeOptions photonBakeOptions(const ShotSpec& shot);

}  // namespace cloudbake
