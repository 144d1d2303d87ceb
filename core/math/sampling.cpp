#include "core/math/sampling.h"

#include <algorithm>
#include <cmath>

namespace cloudbake {

Vec3 sampleUniformSphere(double u1, double u2) {
  const double z = 1.0 - 2.0 * u1;
  const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
  const double phi = 2.0 * kPi * u2;
  return {r * std::cos(phi), r * std::sin(phi), z};
}

Vec3 sampleCosineHemisphere(double u1, double u2) {
  const double r = std::sqrt(u1);
  const double phi = 2.0 * kPi * u2;
  return {r * std::cos(phi), r * std::sin(phi), std::sqrt(std::max(0.0, 1.0 - u1))};
}

Vec3 directionFromCosTheta(const Vec3& axis, double cos_theta, double u) {
  cos_theta = std::clamp(cos_theta, -1.0, 1.0);
  const double sin_theta = std::sqrt(std::max(0.0, 1.0 - cos_theta * cos_theta));
  const double phi = 2.0 * kPi * u;
  const Frame f = Frame::fromZ(axis);
  return f.toWorld({sin_theta * std::cos(phi), sin_theta * std::sin(phi), cos_theta});
}

}  // namespace cloudbake
