#include "core/transport/camera.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "core/error.h"

namespace cloudbake {
namespace {

Camera baseCamera() {
  Camera c;
  c.name = "cam";
  c.position = Vec3(1, -5, 2);
  c.look_at = Vec3(1, 0, 2);
  c.up = Vec3(0, 0, 1);
  c.fov_deg = 60;
  c.width_px = 200;
  c.height_px = 100;
  return c;
}

TEST(Camera, PerspectiveCentreCornersAndOrientation) {
  const Camera c = baseCamera();
  const CameraRays rays(c);
  const Ray centre = rays.generate(100, 50);
  EXPECT_NEAR(length(centre.d), 1.0, 1e-12);
  EXPECT_NEAR(centre.d.y, 1.0, 1e-12);
  EXPECT_EQ(centre.o, c.position);
  // The left and right film edges at mid-height span the horizontal field of view.
  const Ray left = rays.generate(0, 50), right = rays.generate(200, 50);
  EXPECT_NEAR(std::acos(dot(left.d, right.d)) * 180 / kPi, 60.0, 1e-9);
  EXPECT_LT(left.d.x, 0);  // +x is to the right when looking along +y with +z up
  EXPECT_GT(right.d.x, 0);
  // Vertical extent follows the aspect ratio: tan(v/2) = tan(30 deg) * 100 / 200.
  const Ray top = rays.generate(100, 0);
  EXPECT_GT(top.d.z, 0);  // row 0 is the top of the image
  EXPECT_NEAR(top.d.z / top.d.y, std::tan(kPi / 6) * 0.5, 1e-12);
}

// p (a point) through a row-vector 4x4 matrix, divided by w.
Vec3 transformPoint(const std::array<double, 16>& m, const Vec3& p) {
  double out[4];
  for (int c = 0; c < 4; ++c) {
    out[c] =
        p.x * m[size_t(c)] + p.y * m[size_t(4 + c)] + p.z * m[size_t(8 + c)] + m[size_t(12 + c)];
  }
  return Vec3(out[0], out[1], out[2]) / out[3];
}

// The matrices compositing packages read: the camera looks down -z with +x right and +y up,
// and a point seen through a film position lands at that position's NDC (-1..1 across the
// width and the height), for both camera types.
TEST(Camera, WorldToCameraAndNdcFollowOpenExrConventions) {
  for (const Camera::Type type : {Camera::Type::kPerspective, Camera::Type::kOrthographic}) {
    Camera c = baseCamera();
    c.type = type;
    c.width = 3;
    const CameraRays rays(c);
    const Vec3 ahead = transformPoint(rays.worldToCamera(), c.look_at);
    EXPECT_NEAR(ahead.x, 0, 1e-12);
    EXPECT_NEAR(ahead.y, 0, 1e-12);
    EXPECT_NEAR(ahead.z, -5, 1e-12);
    const Vec3 upward = transformPoint(rays.worldToCamera(), c.position + Vec3(0.3, 0, 1));
    EXPECT_NEAR(upward.y, 1, 1e-12);    // world +z (the up vector) is camera +y
    EXPECT_NEAR(upward.x, 0.3, 1e-12);  // world +x is to the right
    for (const auto& [fx, fy] :
         {std::pair{0.0, 0.0}, std::pair{200.0, 100.0}, std::pair{50.0, 80.0}}) {
      const Ray r = rays.generate(fx, fy);
      const Vec3 ndc = transformPoint(rays.worldToNdc(), r.o + r.d * 7.0);
      EXPECT_NEAR(ndc.x, 2 * fx / 200 - 1, 1e-9) << fx << " " << fy;
      EXPECT_NEAR(ndc.y, 1 - 2 * fy / 100, 1e-9) << fx << " " << fy;
    }
  }
}

TEST(Camera, OrthographicIsParallelWithHorizontalWidth) {
  Camera c = baseCamera();
  c.type = Camera::Type::kOrthographic;
  c.width = 4.0;
  const CameraRays rays(c);
  const Ray a = rays.generate(0, 0), b = rays.generate(200, 100);
  EXPECT_EQ(a.d, b.d);
  EXPECT_NEAR(a.d.y, 1.0, 1e-12);
  EXPECT_NEAR(b.o.x - a.o.x, 4.0, 1e-12);
  EXPECT_NEAR(a.o.z - b.o.z, 2.0, 1e-12);  // aspect 1:2
  EXPECT_NEAR(a.o.x, 1 - 2.0, 1e-12);      // top-left is left and up
  EXPECT_NEAR(a.o.z, 2 + 1.0, 1e-12);
}

TEST(Camera, NadirViewWithYUp) {
  Camera c;
  c.type = Camera::Type::kOrthographic;
  c.position = Vec3(0, 0, 10);
  c.look_at = Vec3(0, 0, 0);
  c.up = Vec3(0, 1, 0);
  c.width = 2;
  c.width_px = c.height_px = 4;
  const CameraRays rays(c);
  const Ray r = rays.generate(0.5, 0.5);
  EXPECT_EQ(r.d, Vec3(0, 0, -1));
  EXPECT_NEAR(r.o.x, -0.75, 1e-12);
  EXPECT_NEAR(r.o.y, 0.75, 1e-12);
}

void expectInvalid(const Camera& c, const std::string& field) {
  try {
    validateCamera(c);
    ADD_FAILURE() << "expected InputError naming " << field;
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("'cam'"), std::string::npos) << e.what();
  }
}

// An outside probe: an up of [0, 1e-200, 0] was refused as "a non-zero vector" (its length
// underflows), and a huge one as well. Any finite non-zero vector is a direction.
TEST(Camera, TinyAndHugeDirectionsAreDirections) {
  const Camera base = baseCamera();
  const CameraRays reference(base);
  for (const Vec3& up : {Vec3(0, 0, 1e-200), Vec3(0, 0, 1e-320), Vec3(0, 1e-300, 1e-200),
                         Vec3(0, 0, 1e300), Vec3(1e-5, 1e200, 1e200)}) {
    Camera c = base;
    c.up = up;
    ASSERT_NO_THROW(validateCamera(c)) << up.z;
    const CameraRays rays(c);
    for (const auto& [x, y] : {std::pair{0, 0}, std::pair{200, 100}, std::pair{37, 80}}) {
      const Vec3 d = rays.generate(x, y).d, r = reference.generate(x, y).d;
      if (up.y == 0) {
        EXPECT_NEAR(length(d - r), 0.0, 1e-12) << up.z << " " << x;
      }
      EXPECT_TRUE(isFinite(d)) << up.y << " " << up.z;
    }
  }
  Camera near = base;  // a look_at 1e-200 from the position looks along the difference
  near.position = Vec3(0.0);
  near.look_at = Vec3(0, 1e-200, 0);
  ASSERT_NO_THROW(validateCamera(near));
  EXPECT_NEAR(length(CameraRays(near).generate(37, 80).d - reference.generate(37, 80).d), 0.0,
              1e-12);
}

TEST(Camera, ValidationNamesTheField) {
  Camera c = baseCamera();
  EXPECT_NO_THROW(validateCamera(c));
  c.position = Vec3(std::nan(""), 0, 0);
  expectInvalid(c, "camera.position");
  c = baseCamera();
  c.look_at = Vec3(0, INFINITY, 0);
  expectInvalid(c, "camera.look_at");
  c = baseCamera();
  c.look_at = c.position;
  expectInvalid(c, "camera.look_at");
  c = baseCamera();
  c.up = Vec3(0, 3, 0);  // parallel to the view direction
  expectInvalid(c, "camera.up");
  c.up = Vec3(0, 0, 0);
  expectInvalid(c, "camera.up");
  for (double fov : {0.0, -10.0, 180.0, 200.0, std::nan("")}) {
    c = baseCamera();
    c.fov_deg = fov;
    expectInvalid(c, "camera.fov_deg");
  }
  c = baseCamera();
  c.type = Camera::Type::kOrthographic;
  c.width = 0;
  expectInvalid(c, "camera.width");
  c.width = -1;
  expectInvalid(c, "camera.width");
  c = baseCamera();
  c.width_px = 0;
  expectInvalid(c, "camera.resolution");
  c.width_px = 16385;
  expectInvalid(c, "camera.resolution");
  c.width_px = 16384;
  c.height_px = 16384;  // 2^28 pixels > 2^26
  expectInvalid(c, "camera.resolution");
  c.height_px = 4096;  // exactly 2^26
  EXPECT_NO_THROW(validateCamera(c));
}

}  // namespace
}  // namespace cloudbake
