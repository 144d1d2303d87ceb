// What a render needs: the participating medium, the lights and the cameras.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "core/math/vec3.h"
#include "core/phase/phase_function.h"
#include "core/volume/density_field.h"

namespace cloudbake {

/// The cloud's optical properties. sigma_t(x) = extinction * density(x) per world unit (grey);
/// sigma_s = albedo * sigma_t per channel; the phase function may be chromatic.
struct Medium {
  DensityFieldPtr density;
  double extinction = 1.0;  ///< per world unit per unit density, >= 0
  Rgb albedo{1, 1, 1};      ///< single-scattering albedo per channel, in [0, 1]
  std::shared_ptr<const PhaseFunction> phase;
};

/// InputError naming the field unless the medium has a phase function, a finite extinction
/// >= 0 and an albedo in [0, 1] per channel (the density is each caller's to check).
void validateMediumOptics(const Medium& m);

/// A distant sun. `direction` points from the scene towards the sun (unit). `irradiance` E per
/// channel is measured on a plane perpendicular to the sun direction (W m^-2 when radiance is
/// W m^-2 sr^-1). Treated as a delta light (no angular extent).
struct Sun {
  Vec3 direction{0, 0, 1};
  Rgb irradiance{0, 0, 0};
};

/// Sky radiance arriving from every direction not blocked by the cloud. One of: constant;
/// gradient (linear in the z component of the direction, from horizon to zenith, mirrored below
/// the horizon from `ground`); or an equirectangular (lat-long) EXR map with +z up.
struct Sky {
  enum class Type { kConstant, kGradient, kMap };
  Type type = Type::kConstant;
  Rgb radiance{0, 0, 0};   ///< constant
  Rgb zenith{0, 0, 0};     ///< gradient: radiance looking straight up
  Rgb horizon{0, 0, 0};    ///< gradient: radiance at the horizon
  Rgb ground{0, 0, 0};     ///< gradient: radiance of every direction below the horizon
  std::string map_path;    ///< map: lat-long EXR (u = azimuth from +x towards +y, v = 0 at zenith)
  double map_scale = 1.0;  ///< map: multiplier on the map's values
};

/// A pinhole or orthographic camera. `up` need not be orthogonal to the view direction.
/// Perspective: `fov_deg` is the horizontal field of view. Orthographic: `width` is the
/// horizontal extent of the view in world units; the vertical extent follows the aspect ratio.
struct Camera {
  enum class Type { kPerspective, kOrthographic };
  std::string name = "view";
  Type type = Type::kPerspective;
  Vec3 position{0, -5, 1};
  Vec3 look_at{0, 0, 0.5};
  Vec3 up{0, 0, 1};
  double fov_deg = 40.0;
  double width = 2.0;
  int width_px = 64;
  int height_px = 64;
};

/// A shot's renderable scene. `cameras` are in the shot's view order, named as the views.
struct Scene {
  Medium medium;
  Sun sun;  ///< irradiance 0 when the shot has no sun
  Sky sky;
  std::vector<Camera> cameras;
};

}  // namespace cloudbake
