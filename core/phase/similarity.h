// The similarity relations (van de Hulst 1974; Wyman, Hanrahan & Max 1989): multiple scattering
// in a medium of mean cosine g and albedo a is close to that of an isotropic medium of extinction
// (1 - a g) sigma_t and albedo a (1 - g) / (1 - a g). Used by the lattice methods' reduced
// transport (pointcloud's normalised rule, precomputed's frames).
#pragma once

namespace cloudbake {

/// The reduced medium's albedo a (1 - g) / (1 - a g), per channel: 1 where a is 1 (the reduction
/// conserves energy), 0 where a is 0, in [0, 1] for a in [0, 1] and g in (-1, 1).
inline double reducedAlbedo(double a, double g) {
  const double s = 1 - a * g;
  return s > 0 ? a * (1 - g) / s : 0.0;
}

}  // namespace cloudbake
