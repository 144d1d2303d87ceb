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

/// Seconds per ray of a photon view that reads its field (viewFieldPays), on two cores: 0.9-1.3
/// us measured at lattice 128 and 2.0-2.9 us at 320 (docs/methods.md), so 1.5 us per 128 voxels
/// of `light_resolution` (the march's samples), 0.75 us at the least. Shared by photon's ETA and
/// auto's cost model.
double photonFieldViewSecondsPerRay(int light_resolution);

}  // namespace cloudbake
