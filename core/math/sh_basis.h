// Real spherical harmonics of any degree up to kMaxShDegree, for radiance fields stored per voxel.
#pragma once

#include <vector>

#include "core/math/vec3.h"

namespace cloudbake {

/// The highest degree l the general basis evaluates.
constexpr int kMaxShDegree = 8;

/// Number of coefficients of degrees 0..degree: (degree + 1)^2.
constexpr int shCount(int degree) { return (degree + 1) * (degree + 1); }

/// The real, orthonormal spherical harmonics Y_lm (integral of Y_i Y_j over the sphere =
/// delta_ij) of degrees 0..degree (<= kMaxShDegree) at unit direction `w` (z the polar axis),
/// written to y[l * l + l + m], m in [-l, l]: Y_lm = sqrt(2) K_lm cos(m phi) P_l^m(cos theta)
/// for m > 0, sqrt(2) K_l|m| sin(|m| phi) P_l^|m| for m < 0, K_l0 P_l for m = 0, with the
/// associated Legendre functions by the standard recurrences (no Condon-Shortley phase).
/// Any consistent sign convention would do: only products of these functions are used.
void shBasisUpTo(int degree, const Vec3& w, double* y);

/// Legendre polynomials P_0..P_degree at x, written to p[0..degree].
void legendreP(int degree, double x, double* p);

/// The highest degree shZonal evaluates.
constexpr int kMaxZonalDegree = 64;

/// The zonal (m = 0) real orthonormal harmonics about an axis, Y_l0 = sqrt((2l + 1) / (4 pi))
/// P_l(mu) with mu the cosine to the axis, for l = first..last (last <= kMaxZonalDegree),
/// written to y[0..last - first].
void shZonal(int first, int last, double mu, double* y);

}  // namespace cloudbake
