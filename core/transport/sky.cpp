#include "core/transport/sky.h"

#include <cmath>
#include <sstream>
#include <string>

#include "core/error.h"
#include "core/io/exr_io.h"
#include "core/math/sampling.h"

namespace cloudbake {
namespace {

void checkRadiance(const Rgb& c, const char* field) {
  if (!isFinite(c) || c.x < 0 || c.y < 0 || c.z < 0) {
    std::ostringstream os;
    os << field << ": radiance must be finite and >= 0 per channel, got [" << c.x << ", " << c.y
       << ", " << c.z << "]";
    throw InputError(os.str());
  }
}

bool isBlack(const Rgb& c) { return c.x == 0 && c.y == 0 && c.z == 0; }

// The shot's bound on every radiance and irradiance (shot_parser.cpp): a map's pixels, times its
// scale, keep to it too, or a render's sums overflow a float (3e38 pixels made infinite ones).
constexpr double kMaxMapRadiance = 1e12;

}  // namespace

SkyLight::SkyLight(const Sky& sky) : sky_(sky) {
  switch (sky.type) {
    case Sky::Type::kConstant:
      checkRadiance(sky.radiance, "sky.radiance");
      black_ = isBlack(sky.radiance);
      break;
    case Sky::Type::kGradient:
      checkRadiance(sky.zenith, "sky.zenith");
      checkRadiance(sky.horizon, "sky.horizon");
      checkRadiance(sky.ground, "sky.ground");
      black_ = isBlack(sky.zenith) && isBlack(sky.horizon) && isBlack(sky.ground);
      break;
    case Sky::Type::kMap: {
      if (sky.map_path.empty()) throw InputError("sky.map: path is empty");
      buildMap(readExrRgb(sky.map_path), sky.map_scale, sky.map_path);
      break;
    }
    default:
      throw InputError("sky.type: unknown sky type");
  }
}

SkyLight::SkyLight(const Image& map, double scale, const std::string& what) {
  sky_.type = Sky::Type::kMap;
  sky_.map_scale = scale;
  buildMap(map, scale, what);
}

void SkyLight::buildMap(const Image& map, double scale, const std::string& what) {
  if (!std::isfinite(scale) || scale < 0) {
    std::ostringstream os;
    os << "sky.map_scale: must be finite and >= 0, got " << scale;
    throw InputError(os.str());
  }
  // The sampling tables take ~24 bytes per pixel; 8192 x 4096 is far above useful sky detail.
  if (static_cast<long long>(map.width) * map.height > kMaxSkyMapPixels) {
    throw InputError(what + ": sky map has " + std::to_string(map.width) + "x" +
                     std::to_string(map.height) + " pixels, more than the limit of 2^25");
  }
  if (map.channels != 3 || map.width < 1 || map.height < 1 ||
      map.data.size() != size_t(map.width) * map.height * 3) {
    throw InputError(what + ": sky map must be a non-empty RGB image");
  }
  map_ = map;
  const int nu = map.width, nv = map.height;
  std::vector<double> f(size_t(nu) * nv);
  for (int y = 0; y < nv; ++y) {
    const double sin_theta = std::sin(kPi * (y + 0.5) / nv);
    for (int x = 0; x < nu; ++x) {
      float* p = map_.at(x, y);
      for (int c = 0; c < 3; ++c) {
        if (!std::isfinite(p[c]) || p[c] < 0) {
          std::ostringstream os;
          os << what << ": sky map pixel (" << x << ", " << y << ") must be finite and >= 0, got "
             << p[c];
          throw InputError(os.str());
        }
        if (double(p[c]) * scale > kMaxMapRadiance) {
          std::ostringstream os;
          os << what << ": sky map pixel (" << x << ", " << y << ") times the scale " << scale
             << " is " << double(p[c]) * scale << ", over the largest radiance, "
             << kMaxMapRadiance;
          throw InputError(os.str());
        }
        p[c] = static_cast<float>(p[c] * scale);
      }
      f[size_t(y) * nu + x] = luminance(Rgb(p[0], p[1], p[2])) * sin_theta;
    }
  }
  distribution_ = std::make_unique<PiecewiseConstant2D>(f, nu, nv);
  black_ = !(distribution_->integral() > 0);
}

Rgb SkyLight::radiance(const Vec3& w) const {
  switch (sky_.type) {
    case Sky::Type::kConstant:
      return sky_.radiance;
    case Sky::Type::kGradient:
      if (w.z < 0) return sky_.ground;
      return sky_.horizon + (sky_.zenith - sky_.horizon) * std::min(w.z, 1.0);
    case Sky::Type::kMap: {
      double phi = std::atan2(w.y, w.x);
      if (phi < 0) phi += 2 * kPi;
      const double theta = std::acos(std::clamp(w.z, -1.0, 1.0));
      const int x = std::clamp(static_cast<int>(phi / (2 * kPi) * map_.width), 0, map_.width - 1);
      const int y = std::clamp(static_cast<int>(theta / kPi * map_.height), 0, map_.height - 1);
      const float* p = map_.at(x, y);
      return {p[0], p[1], p[2]};
    }
  }
  return {};
}

SkySample SkyLight::sample(double u1, double u2) const {
  SkySample s;
  if (sky_.type != Sky::Type::kMap) {
    s.to_sky = sampleUniformSphere(u1, u2);
    s.pdf = kInv4Pi;
    s.radiance = radiance(s.to_sky);
    return s;
  }
  if (black_) return s;
  double u, v, pdf_uv;
  distribution_->sample(u1, u2, &u, &v, &pdf_uv);
  const double theta = v * kPi, phi = u * 2 * kPi;
  const double sin_theta = std::sin(theta);
  if (!(sin_theta > 0) || !(pdf_uv > 0)) return s;  // measure-zero pole: discard
  s.to_sky = Vec3(sin_theta * std::cos(phi), sin_theta * std::sin(phi), std::cos(theta));
  s.pdf = pdf_uv / (2 * kPi * kPi * sin_theta);
  // Read the pixel the sample came from (not via atan2 of to_sky) so lookup and pdf always agree.
  const int x = std::clamp(static_cast<int>(u * map_.width), 0, map_.width - 1);
  const int y = std::clamp(static_cast<int>(v * map_.height), 0, map_.height - 1);
  const float* p = map_.at(x, y);
  s.radiance = Rgb(p[0], p[1], p[2]);
  return s;
}

double SkyLight::pdf(const Vec3& w) const {
  if (sky_.type != Sky::Type::kMap) return kInv4Pi;
  if (black_) return 0;
  const double z = std::clamp(w.z, -1.0, 1.0);
  const double sin_theta = std::sqrt(std::max(0.0, 1 - z * z));
  if (!(sin_theta > 0)) return 0;
  double phi = std::atan2(w.y, w.x);
  if (phi < 0) phi += 2 * kPi;
  const double u = phi / (2 * kPi), v = std::acos(z) / kPi;
  return distribution_->pdf(u, v) / (2 * kPi * kPi * sin_theta);
}

Rgb SkyLight::meanRadiance(int n) const {
  if (black_ || n < 1) return Rgb(0.0);
  const double golden = kPi * (3.0 - std::sqrt(5.0));
  Rgb sum(0.0);
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - (2.0 * i + 1.0) / n;
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    const double phi = golden * i;
    sum += radiance(Vec3(r * std::cos(phi), r * std::sin(phi), z));
  }
  return sum / double(n);
}

}  // namespace cloudbake
