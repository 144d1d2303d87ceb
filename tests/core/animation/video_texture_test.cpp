// The video-texture walk over basic volumes: distances, transitions, the seeded walk, the
// cross-dissolve, and that the endless sequence never jumps.
#include "core/animation/video_texture.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numeric>
#include <string>

#include "core/error.h"

namespace cloudbake {
namespace {

// A Gaussian blob circling once around a 16^3 lattice over n frames: frame n-1 flows into frame
// 0, so an endless walk exists that never jumps.
BasicVolumes circlingBlob(int n, int size = 16) {
  BasicVolumes frames(size_t(n), std::vector<float>(size_t(size) * size * size));
  for (int f = 0; f < n; ++f) {
    const double a = 2 * M_PI * f / n;
    const double cx = size / 2.0 + size / 4.0 * std::cos(a),
                 cy = size / 2.0 + size / 4.0 * std::sin(a);
    for (int k = 0; k < size; ++k)
      for (int j = 0; j < size; ++j)
        for (int i = 0; i < size; ++i) {
          const double r2 =
              (i - cx) * (i - cx) + (j - cy) * (j - cy) + (k - size / 2.0) * (k - size / 2.0);
          frames[size_t(f)][(size_t(k) * size + size_t(j)) * size + size_t(i)] =
              float(std::exp(-r2 / 8));
        }
  }
  return frames;
}

void expectErrorNaming(const std::function<void()>& fn, const std::string& what) {
  try {
    fn();
    ADD_FAILURE() << "no error; expected one naming " << what;
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
  }
}

TEST(VideoTexture, DistancesAreSumsOfSquaredDensityDifferences) {
  const BasicVolumes f = {{0, 1, 2}, {1, 1, 0}, {0, 0, 0}};
  const std::vector<double> d = frameDistances(f);
  EXPECT_EQ(d[0 * 3 + 1], 1.0 + 0.0 + 4.0);
  EXPECT_EQ(d[1 * 3 + 0], d[0 * 3 + 1]);
  EXPECT_EQ(d[2 * 3 + 0], 5.0);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(d[size_t(k) * 4], 0.0);
  expectErrorNaming([] { frameDistances({{1, 2}}); }, "at least 2");
  expectErrorNaming([] { frameDistances({{1, 2}, {1, 2, 3}}); }, "volume 1 has 3 voxels");
  expectErrorNaming([] { frameDistances({{1, 2}, {1, std::nanf("")}}); }, "volume 1");
}

TEST(VideoTexture, TransitionsFavourTheNaturalSuccessorAndLeaveRoomToDissolve) {
  const int n = 30;
  const BasicVolumes frames = circlingBlob(n);
  const std::vector<double> d = frameDistances(frames);
  VideoTextureOptions o;
  o.dissolve_frames = 4;
  const std::vector<double> p = transitionProbabilities(d, n, o);
  for (int k = 0; k < n; ++k) {
    double sum = 0;
    int argmax = -1;
    double best = -1;
    for (int l = 0; l < n; ++l) {
      const double q = p[size_t(k) * n + size_t(l)];
      sum += q;
      if (q > best) {
        best = q;
        argmax = l;
      }
      if (l != k + 1 && q > 0) {
        EXPECT_LE(l + o.dissolve_frames, n - 1) << "no room to dissolve into " << l;
      }
    }
    EXPECT_NEAR(sum, 1.0, 1e-12) << k;
    if (k + 1 < n) {
      EXPECT_EQ(argmax, k + 1) << k;
    } else {
      // The last frame jumps to the frame whose predecessor looks like it: the loop's frame 1.
      EXPECT_EQ(argmax, 1);
    }
  }
  // A huge temperature makes every allowed target equally likely; a tiny one only the successor.
  o.sigma = 1e6;
  const std::vector<double> flat = transitionProbabilities(d, n, o);
  EXPECT_NEAR(flat[0 * n + 1], flat[0 * n + 5], 1e-6);
  o.sigma = 1e-6;
  EXPECT_NEAR(transitionProbabilities(d, n, o)[0 * n + 1], 1.0, 1e-9);
  o.sigma = 0;
  expectErrorNaming([&] { transitionProbabilities(d, n, o); }, "sigma");
  o.sigma = 0.05;
  o.dissolve_frames = n - 1;
  expectErrorNaming([&] { transitionProbabilities(d, n, o); }, "dissolve_frames");
}

TEST(VideoTexture, TheEndlessWalkIsSeededAndNeverJumps) {
  const int n = 30;
  const BasicVolumes frames = circlingBlob(n);
  const std::vector<double> d = frameDistances(frames);
  VideoTextureOptions o;
  o.sigma = 0.05;
  o.dissolve_frames = 6;
  o.seed = 7;
  const std::vector<double> p = transitionProbabilities(d, n, o);
  const std::vector<BlendFrame> walk = endlessWalk(p, n, 1000, o);
  ASSERT_EQ(walk.size(), 1000u);
  int jumps = 0;
  for (size_t i = 0; i < walk.size(); ++i) {
    EXPECT_GE(walk[i].a, 0);
    EXPECT_LT(walk[i].b, n);
    EXPECT_GT(walk[i].w, 0.0);
    EXPECT_LE(walk[i].w, 1.0);
    if (walk[i].w < 1) ++jumps;
  }
  EXPECT_GT(jumps, 0) << "the walk must leave the input order to be endless";
  // Same seed, same walk; another seed, another walk.
  const std::vector<BlendFrame> again = endlessWalk(p, n, 1000, o);
  for (size_t i = 0; i < walk.size(); ++i) {
    EXPECT_EQ(walk[i].a, again[i].a);
    EXPECT_EQ(walk[i].w, again[i].w);
  }
  o.seed = 8;
  const std::vector<BlendFrame> other = endlessWalk(p, n, 1000, o);
  int differ = 0;
  for (size_t i = 0; i < walk.size(); ++i) differ += walk[i].b != other[i].b;
  EXPECT_GT(differ, 0);

  // The largest frame-to-frame change of the endless sequence stays near the input's own.
  const double input = maxInputFrameChange(frames);
  const double endless = maxFrameChange(frames, walk);
  std::printf(
      "[ animation ] largest frame-to-frame RMS density change: input %.4f, 1000-frame walk"
      " %.4f (%d dissolved frames)\n",
      input, endless, jumps);
  EXPECT_LE(endless, 1.5 * input);
  // Control: hard cuts to random frames do jump, so the check above can fail.
  o.dissolve_frames = 0;
  o.sigma = 1e6;
  const std::vector<double> uniform = transitionProbabilities(d, n, o);
  EXPECT_GT(maxFrameChange(frames, endlessWalk(uniform, n, 1000, o)), 3 * input);
}

TEST(VideoTexture, ThreeHundredVolumesWork) {
  const int n = 300;
  const BasicVolumes frames = circlingBlob(n, 8);
  const std::vector<double> d = frameDistances(frames);
  VideoTextureOptions o;
  o.dissolve_frames = 12;
  const std::vector<double> p = transitionProbabilities(d, n, o);
  const std::vector<BlendFrame> walk = endlessWalk(p, n, 1000, o);
  EXPECT_EQ(walk.size(), 1000u);
  const std::vector<float> blended = blendFrame(frames, {3, 200, 0.25});
  EXPECT_FLOAT_EQ(blended[100], 0.25f * frames[3][100] + 0.75f * frames[200][100]);
  expectErrorNaming([&] { endlessWalk(p, n, 0, o); }, "frames");
}

}  // namespace
}  // namespace cloudbake
