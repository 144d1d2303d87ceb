// Real spherical harmonics up to order 4 (l = 0..3, 16 coefficients), the basis seed 002 stores
// each voxel's optical depth to the sky in.
#pragma once

#include <array>

#include "core/math/vec3.h"

namespace cloudbake {

/// Coefficients of one function on the sphere: index l * l + l + m for l in [0, 3], m in [-l, l].
constexpr int kShCoefficients = 16;

/// sqrt(4 pi): Y_00 = 1 / sqrt(4 pi), so coefficient 0 of a function is sqrt(4 pi) times its
/// mean over the sphere (the constant 1 is (sqrt(4 pi), 0, ..., 0)). The double nearest to it,
/// equal to std::sqrt(4 * kPi).
constexpr double kSqrt4Pi = 3.5449077018110318;
using ShCoefficients = std::array<float, kShCoefficients>;

/// The 16 real, orthonormal spherical harmonics (integral over the sphere of Y_i Y_j = delta_ij;
/// Sloan 2008's conventions, "Stupid SH tricks") at unit direction `w`.
std::array<double, kShCoefficients> shBasis(const Vec3& w);

/// Sum of coefficients times basis at `w`.
double shEvaluate(const ShCoefficients& c, const Vec3& w);

/// The SH projection of the product of the two functions (truncated to order 4), through the
/// triple-product tensor integral(Y_i Y_j Y_k) (computed once by quadrature).
ShCoefficients shProduct(const ShCoefficients& a, const ShCoefficients& b);

}  // namespace cloudbake
