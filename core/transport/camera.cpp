#include "core/transport/camera.h"

#include <cmath>

#include "core/error.h"
#include "core/format.h"

namespace cloudbake {
namespace {

[[noreturn]] void fail(const Camera& camera, const std::string& field, const std::string& why) {
  throw InputError("view '" + camera.name + "': camera." + field + ": " + why);
}

// v itself where its length is a normal number (so every camera keeps the bits it had), else
// the unit vector along it: an up of [0, 1e-200, 0] is a direction, though its length underflows.
Vec3 tameLength(const Vec3& v) {
  const double len = length(v);
  return len > 1e-150 && len < 1e150 ? v : directionOf(v);
}

}  // namespace

void validateCamera(const Camera& c) {
  if (!isFinite(c.position)) fail(c, "position", "must be finite, got " + str(c.position));
  if (!isFinite(c.look_at)) fail(c, "look_at", "must be finite, got " + str(c.look_at));
  if (!isFinite(c.up)) fail(c, "up", "must be finite, got " + str(c.up));
  const Vec3 view = normalize(tameLength(c.look_at - c.position));
  if (!(length(view) > 0)) {
    fail(c, "look_at", "must differ from camera.position (both " + str(c.position) + ")");
  }
  const Vec3 up = normalize(tameLength(c.up));
  if (!(length(up) > 0)) fail(c, "up", "must be a non-zero vector");
  // Relative test: |sin(angle between up and view)| below 1e-6 leaves no usable right axis.
  if (length(cross(view, up)) < 1e-6) {
    fail(c, "up", "must not be parallel to the view direction, got " + str(c.up));
  }
  if (c.type == Camera::Type::kPerspective) {
    if (!std::isfinite(c.fov_deg) || !(c.fov_deg > 0) || !(c.fov_deg < 180)) {
      fail(c, "fov_deg", "must be in (0, 180) degrees, got " + str(c.fov_deg));
    }
  } else if (c.type == Camera::Type::kOrthographic) {
    if (!std::isfinite(c.width) || !(c.width > 0)) {
      fail(c, "width", "must be finite and > 0 world units, got " + str(c.width));
    }
  } else {
    fail(c, "type", "unknown camera type");
  }
  if (c.width_px < 1 || c.width_px > kMaxImageSide || c.height_px < 1 ||
      c.height_px > kMaxImageSide ||
      static_cast<long long>(c.width_px) * c.height_px > kMaxImagePixels) {
    fail(c, "resolution",
         "must be 1..16384 pixels per side and at most 2^26 pixels, got " + str(c.width_px) + "x" +
             str(c.height_px));
  }
}

CameraRays::CameraRays(const Camera& camera) : camera_(camera) {
  validateCamera(camera);
  forward_ = normalize(tameLength(camera.look_at - camera.position));
  right_ = normalize(cross(forward_, tameLength(camera.up)));
  up_ = cross(right_, forward_);
  const double aspect = static_cast<double>(camera.height_px) / camera.width_px;
  half_w_ = camera.type == Camera::Type::kPerspective ? std::tan(0.5 * camera.fov_deg * kPi / 180.0)
                                                      : 0.5 * camera.width;
  half_h_ = half_w_ * aspect;
}

std::array<double, 16> CameraRays::worldToCamera() const {
  const Vec3 back = -forward_;
  const Vec3& p = camera_.position;
  return {right_.x,        up_.x,        back.x,        0,  //
          right_.y,        up_.y,        back.y,        0,  //
          right_.z,        up_.z,        back.z,        0,  //
          -dot(p, right_), -dot(p, up_), -dot(p, back), 1};
}

std::array<double, 16> CameraRays::worldToNdc() const {
  // Camera space to clip space, then the product (row vectors: world -> camera -> clip).
  const bool persp = camera_.type == Camera::Type::kPerspective;
  const std::array<double, 16> proj =
      persp ? std::array<double, 16>{1 / half_w_, 0, 0, 0,  0, 1 / half_h_, 0, 0,  //
                                     0,           0, 0, -1, 0, 0,           1, 0}
            : std::array<double, 16>{1 / half_w_, 0, 0, 0, 0, 1 / half_h_, 0, 0,  //
                                     0,           0, 1, 0, 0, 0,           0, 1};
  const std::array<double, 16> w2c = worldToCamera();
  std::array<double, 16> m{};
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) {
      for (int k = 0; k < 4; ++k)
        m[size_t(4 * r + c)] += w2c[size_t(4 * r + k)] * proj[size_t(4 * k + c)];
    }
  }
  return m;
}

Ray CameraRays::generate(double fx, double fy) const {
  // Film coordinates in [-1, 1], +x right, +y up (pixel rows grow downwards).
  const double sx = 2.0 * fx / camera_.width_px - 1.0;
  const double sy = 1.0 - 2.0 * fy / camera_.height_px;
  if (camera_.type == Camera::Type::kPerspective) {
    const Vec3 d = forward_ + right_ * (sx * half_w_) + up_ * (sy * half_h_);
    return {camera_.position, normalize(d)};
  }
  return {camera_.position + right_ * (sx * half_w_) + up_ * (sy * half_h_), forward_};
}

}  // namespace cloudbake
