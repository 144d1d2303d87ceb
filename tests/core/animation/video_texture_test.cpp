// The video-texture walk over basic volumes: distances, transitions, the seeded walk, the
// cross-dissolve, and that the endless sequence never jumps.
#include "core/animation/video_texture.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numeric>
#include <set>
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

// A blob drifting along x and never coming back: the input ends in a volume that nothing follows.
BasicVolumes driftingBlob(int n, int size = 16) {
  BasicVolumes frames(size_t(n), std::vector<float>(size_t(size) * size * size));
  for (int f = 0; f < n; ++f) {
    const double cx = size * (0.2 + 0.6 * f / (n - 1));
    for (int k = 0; k < size; ++k)
      for (int j = 0; j < size; ++j)
        for (int i = 0; i < size; ++i) {
          const double r2 = (i - cx) * (i - cx) + (j - size / 2.0) * (j - size / 2.0) +
                            (k - size / 2.0) * (k - size / 2.0);
          frames[size_t(f)][(size_t(k) * size + size_t(j)) * size + size_t(i)] =
              float(std::exp(-r2 / 8));
        }
  }
  return frames;
}

// The share of a walk's later half whose heavier volume is among the last `tail` of n.
double laterShareInTail(const std::vector<BlendFrame>& walk, int n, int tail) {
  int in = 0;
  const size_t half = walk.size() / 2;
  for (size_t i = half; i < walk.size(); ++i) {
    in += (walk[i].w >= 0.5 ? walk[i].a : walk[i].b) >= n - tail;
  }
  return double(in) / double(walk.size() - half);
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
      // The last frame jumps to where the loop goes on: frame 0 (one step from it), or frame 1,
      // whose predecessor looks like it.
      EXPECT_LE(argmax, 1);
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

// Schoedl et al.'s future costs: without them the last volume's best jump is the shortest one
// back that leaves room to dissolve, so the walk ends up looping over the last H + 1 volumes.
TEST(VideoTexture, FutureCostsKeepTheWalkOutOfTheDeadEnd) {
  const int n = 40, h = 4;
  const BasicVolumes frames = driftingBlob(n);
  const std::vector<double> d = frameDistances(frames);
  VideoTextureOptions o;
  o.dissolve_frames = h;
  o.future_cost = 0;
  double trapped = 0, free = 0;
  for (uint64_t seed = 1; seed <= 4; ++seed) {
    o.seed = seed;
    o.future_cost = 0;
    trapped = std::max(
        trapped,
        laterShareInTail(endlessWalk(transitionProbabilities(d, n, o), n, 2000, o), n, h + 1));
    o.future_cost = VideoTextureOptions{}.future_cost;
    free = std::max(free, laterShareInTail(
                              endlessWalk(transitionProbabilities(d, n, o), n, 2000, o), n, h + 1));
  }
  std::printf(
      "[ animation ] later half of a 2000-frame walk in the last %d of %d volumes: %.2f without "
      "future costs, %.2f with (alpha %.3g)\n",
      h + 1, n, trapped, free, VideoTextureOptions{}.future_cost);
  // The control: the dead end does trap the walk without them.
  EXPECT_GT(trapped, 0.9);
  // Uniform play would give (h + 1) / n = 0.125 of the frames there.
  EXPECT_LT(free, 0.4);

  // Why: the last volume's likeliest jump. Its own cost is least for the shortest jump back
  // that leaves room to dissolve (target n - 1 - h); with future costs it goes further back, so
  // that the jump's cost is spread over a longer stretch before the end comes round again.
  auto likeliestFromLast = [&](double alpha) {
    o.future_cost = alpha;
    o.sigma = 1e-3;
    const std::vector<double> p = transitionProbabilities(d, n, o);
    return int(std::max_element(p.begin() + (n - 1) * n, p.end()) - (p.begin() + (n - 1) * n));
  };
  EXPECT_EQ(likeliestFromLast(0), n - 1 - h);
  EXPECT_LT(likeliestFromLast(0.99), n - 1 - 2 * h);
  o.future_cost = 1.0;
  expectErrorNaming([&] { transitionProbabilities(d, n, o); }, "future_cost");
  o.future_cost = -0.1;
  expectErrorNaming([&] { transitionProbabilities(d, n, o); }, "future_cost");
}

// The volumes the later half of a walk shows.
int laterVolumes(const std::vector<BlendFrame>& walk) {
  std::set<int> shown;
  for (size_t i = walk.size() / 2; i < walk.size(); ++i) {
    shown.insert(walk[i].a);
    if (walk[i].w < 1) shown.insert(walk[i].b);
  }
  return int(shown.size());
}

// Future costs minimise the cost per frame played. On D itself, which grows as the square of the
// frames between for a cloud that evolves smoothly, the shortest loops were the cheapest, and a
// short dissolve trapped the walk in the first few volumes (an outside probe); on sqrt(D) it
// keeps to long loops. And a database of 2 volumes, whose last could only jump to itself, froze.
TEST(VideoTexture, TheWalkIsNotTrappedInAShortLoop) {
  const int n = 40;
  const BasicVolumes frames = driftingBlob(n);
  const std::vector<double> d = frameDistances(frames);
  VideoTextureOptions o;
  for (int h : {0, 1, 2, 8}) {
    o.dissolve_frames = h;
    for (uint64_t seed = 1; seed <= 3; ++seed) {
      o.seed = seed;
      const int shown = laterVolumes(endlessWalk(transitionProbabilities(d, n, o), n, 2000, o));
      std::printf("[ animation ] H = %d, seed %d: the later half of 2000 frames shows %d of %d\n",
                  h, int(seed), shown, n);
      EXPECT_GE(shown, 3 * n / 4) << "H = " << h << ", seed " << seed;
    }
  }
  const BasicVolumes two = driftingBlob(2);
  o.dissolve_frames = 0;
  const std::vector<BlendFrame> walk =
      endlessWalk(transitionProbabilities(frameDistances(two), 2, o), 2, 200, o);
  EXPECT_EQ(laterVolumes(walk), 2);
}

// The O(n^2) parts heed a cancel.
TEST(VideoTexture, DistancesAndFutureCostsCancel) {
  const BasicVolumes frames = driftingBlob(20, 8);
  int calls = 0;
  EXPECT_THROW(frameDistances(frames, [&] { return ++calls < 3; }), Cancelled);
  const std::vector<double> d = frameDistances(frames);
  VideoTextureOptions o;
  o.dissolve_frames = 2;
  EXPECT_THROW(transitionProbabilities(d, 20, o, [] { return false; }), Cancelled);
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
