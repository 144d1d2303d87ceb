#include "core/math/vec3.h"

#include <gtest/gtest.h>

#include "core/math/sampling.h"

namespace cloudbake {
namespace {

TEST(Vec3, FrameIsOrthonormalForAnyAxis) {
  for (const Vec3 n :
       {Vec3(0, 0, 1), Vec3(0, 0, -1), normalize(Vec3(1, 2, 3)), normalize(Vec3(-1e-9, 0, -1))}) {
    const Frame f = Frame::fromZ(n);
    EXPECT_NEAR(dot(f.s, f.t), 0, 1e-12);
    EXPECT_NEAR(dot(f.s, f.n), 0, 1e-12);
    EXPECT_NEAR(length(f.s), 1, 1e-12);
    EXPECT_NEAR(length(f.t), 1, 1e-12);
    const Vec3 v(0.3, -0.4, 0.5);
    const Vec3 back = f.toWorld(f.toLocal(v));
    EXPECT_NEAR(back.x, v.x, 1e-12);
    EXPECT_NEAR(back.y, v.y, 1e-12);
    EXPECT_NEAR(back.z, v.z, 1e-12);
  }
}

TEST(Vec3, RayBoxIntersection) {
  Bounds3 b;
  b.min = Vec3(-1, -1, 0);
  b.max = Vec3(1, 1, 1);
  double t0, t1;
  ASSERT_TRUE(intersectBounds(b, {Vec3(0, 0, 10), Vec3(0, 0, -1)}, 0, 1e30, &t0, &t1));
  EXPECT_DOUBLE_EQ(t0, 9);
  EXPECT_DOUBLE_EQ(t1, 10);
  EXPECT_FALSE(intersectBounds(b, {Vec3(5, 0, 10), Vec3(0, 0, -1)}, 0, 1e30, &t0, &t1));
  // Origin inside: t0 is clipped to tmin.
  ASSERT_TRUE(intersectBounds(b, {Vec3(0, 0, 0.5), Vec3(1, 0, 0)}, 0, 1e30, &t0, &t1));
  EXPECT_DOUBLE_EQ(t0, 0);
  EXPECT_DOUBLE_EQ(t1, 1);
}

TEST(Sampling, DirectionFromCosThetaHasRequestedAngle) {
  const Vec3 axis = normalize(Vec3(0.2, -0.7, 0.1));
  for (double c : {-1.0, -0.5, 0.0, 0.9, 1.0}) {
    const Vec3 d = directionFromCosTheta(axis, c, 0.37);
    EXPECT_NEAR(length(d), 1, 1e-12);
    EXPECT_NEAR(dot(d, axis), c, 1e-12);
  }
}

TEST(Sampling, UniformSphereIsUnitAndCentred) {
  Vec3 mean;
  const int n = 20000;
  for (int i = 0; i < n; ++i) {
    const Vec3 d = sampleUniformSphere((i + 0.5) / n, std::fmod(i * 0.6180339887, 1.0));
    ASSERT_NEAR(length(d), 1, 1e-12);
    mean += d / n;
  }
  EXPECT_NEAR(length(mean), 0, 1e-2);
}

}  // namespace
}  // namespace cloudbake
