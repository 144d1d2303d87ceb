// Sampling helpers shared by phase functions, lights and the path tracer.
#pragma once

#include "core/math/vec3.h"

namespace cloudbake {

/// Uniform direction on the unit sphere from two uniforms in [0,1). pdf = 1/(4 pi) sr^-1.
Vec3 sampleUniformSphere(double u1, double u2);

/// Cosine-weighted direction on the hemisphere around +z. pdf = cos(theta)/pi.
Vec3 sampleCosineHemisphere(double u1, double u2);

/// Direction with polar cosine `cos_theta` about `axis` and azimuth 2 pi u (phase sampling).
Vec3 directionFromCosTheta(const Vec3& axis, double cos_theta, double u);

}  // namespace cloudbake
