// Primary-ray generation for the pinhole and orthographic cameras of scene.h.
#pragma once

#include <array>

#include "core/math/vec3.h"
#include "core/transport/scene.h"

namespace cloudbake {

/// Largest image side and pixel count a camera may ask for (16384 per side, 2^26 pixels).
constexpr int kMaxImageSide = 16384;
constexpr long long kMaxImagePixels = 1ll << 26;

/// Throws InputError naming the field ("camera.fov_deg", "camera.up", ...) and the camera's name
/// when the camera is unusable: non-finite vectors, position == look_at, up parallel to the view
/// direction, fov outside (0, 180) degrees, width <= 0, resolution outside 1..16384 per side or
/// above 2^26 pixels.
void validateCamera(const Camera& camera);

/// Turns image-plane positions into world rays. Pixel (0, 0) is the top-left pixel; a film
/// position (fx, fy) in pixels (fx in [0, width_px), fy in [0, height_px), y down) maps to a ray
/// whose direction is unit length. Perspective rays start at the camera position; orthographic
/// rays start on the plane through the position perpendicular to the view direction.
class CameraRays {
 public:
  /// Validates (see validateCamera) and precomputes the camera frame.
  explicit CameraRays(const Camera& camera);
  Ray generate(double fx, double fy) const;

  const Vec3& forward() const { return forward_; }
  const Vec3& right() const { return right_; }
  const Vec3& up() const { return up_; }

  /// The camera for compositing packages, in OpenEXR's standard attributes' convention (what
  /// Nuke reads as exr/worldToCamera and exr/worldToNDC): row-vector 4x4 matrices (p' = p M,
  /// m[4 * row + column]); camera space looks down -z with +x right and +y up; NDC x and y run
  /// over [-1, 1] across the image's width and height (after dividing by w: for a perspective
  /// camera w = -z, and z_ndc = 1 / -z; an orthographic camera keeps w = 1 and z).
  std::array<double, 16> worldToCamera() const;
  std::array<double, 16> worldToNdc() const;

 private:
  Camera camera_;
  Vec3 forward_, right_, up_;
  double half_w_ = 1, half_h_ = 1;  // half extent of the image plane (tan units or world units)
};

}  // namespace cloudbake
