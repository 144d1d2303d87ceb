// Seed 002's per-voxel optical depth to the sky, projected onto order-4 spherical harmonics:
// the per-basic-volume precompute that sky light and its blending (Eq. 6) read at run time.
#pragma once

#include <functional>
#include <vector>

#include "core/bake/bake_grid.h"
#include "core/math/spherical_harmonics.h"

namespace cloudbake {

/// `n` directions spread evenly over the sphere (a spherical Fibonacci lattice), each standing
/// for the solid angle 4 pi / n. n >= 1.
std::vector<Vec3> sphereDirections(int n);

/// Optical depth tau(x, w) = extinction * integral_0^inf density(x + t w) dt from every voxel
/// centre along unit direction `w` to outside the lattice, by one sweep: slices across the
/// dominant axis of w are visited upstream first, and each voxel adds the trapezoid of its
/// segment to the bilinear value of the upstream slice (O(voxels); the interpolation smooths
/// tau over about a voxel). Density outside the lattice is 0.
std::vector<float> sweepOpticalDepth(const BakeGrid& grid, const std::vector<float>& density,
                                     double extinction, const Vec3& w);

/// tau(x, w) of every voxel projected onto the 16 real SH of order 4 by quadrature over
/// `directions` sweeps (sphereDirections). Parallel over directions in groups; deterministic.
/// InputError for directions < 16 or a density of the wrong size; `progress(fraction)` returning
/// false cancels (Cancelled).
std::vector<ShCoefficients> projectOpticalDepth(const BakeGrid& grid,
                                                const std::vector<float>& density,
                                                double extinction, int directions = 64,
                                                const std::function<bool(double)>& progress = {});

}  // namespace cloudbake
