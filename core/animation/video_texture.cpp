#include "core/animation/video_texture.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/error.h"
#include "core/math/parallel.h"
#include "core/math/rng.h"

namespace cloudbake {
namespace {

double squaredDifference(const std::vector<float>& a, const std::vector<float>& b) {
  double d = 0;
  for (size_t v = 0; v < a.size(); ++v) {
    const double x = double(a[v]) - double(b[v]);
    d += x * x;
  }
  return d;
}

void checkOptions(int n, const VideoTextureOptions& o) {
  if (!(o.sigma > 0 && o.sigma <= 1e6)) {
    throw InputError("sigma: must be in (0, 1e6] (relative to the mean frame distance), got " +
                     std::to_string(o.sigma));
  }
  if (o.dissolve_frames < 0 || o.dissolve_frames > n - 2) {
    throw InputError("dissolve_frames: H must be in [0, " + std::to_string(n - 2) +
                     "] for a database of " + std::to_string(n) + " volumes, got " +
                     std::to_string(o.dissolve_frames));
  }
}

}  // namespace

std::vector<double> frameDistances(const BasicVolumes& frames) {
  const int n = int(frames.size());
  if (n < 2) {
    throw InputError("basic volumes: an endless animation needs at least 2, got " +
                     std::to_string(n));
  }
  for (int k = 0; k < n; ++k) {
    if (frames[size_t(k)].size() != frames[0].size()) {
      throw InputError("basic volumes: volume " + std::to_string(k) + " has " +
                       std::to_string(frames[size_t(k)].size()) + " voxels, volume 0 has " +
                       std::to_string(frames[0].size()) + " (all must share one lattice)");
    }
    for (float v : frames[size_t(k)]) {
      if (!std::isfinite(v)) {
        throw InputError("basic volumes: volume " + std::to_string(k) +
                         " has a non-finite density");
      }
    }
  }
  std::vector<double> d(size_t(n) * size_t(n), 0.0);
  parallelFor(0, n, [&](int k) {
    for (int l = k + 1; l < n; ++l) {
      d[size_t(k) * size_t(n) + size_t(l)] =
          squaredDifference(frames[size_t(k)], frames[size_t(l)]);
    }
  });
  for (int k = 0; k < n; ++k)
    for (int l = 0; l < k; ++l)
      d[size_t(k) * size_t(n) + size_t(l)] = d[size_t(l) * size_t(n) + size_t(k)];
  return d;
}

std::vector<double> transitionProbabilities(const std::vector<double>& distances, int n,
                                            const VideoTextureOptions& options) {
  if (n < 2 || distances.size() != size_t(n) * size_t(n)) {
    throw InputError("basic volumes: a distance matrix of " + std::to_string(n) +
                     "^2 entries needs at least 2 volumes");
  }
  checkOptions(n, options);
  const int h = options.dissolve_frames;
  auto dist = [&](int k, int l) { return distances[size_t(k) * size_t(n) + size_t(l)]; };
  double mean = 0;
  for (int k = 0; k < n; ++k)
    for (int l = 0; l < n; ++l) mean += k == l ? 0.0 : dist(k, l);
  mean /= double(n) * double(n - 1);
  // Identical frames everywhere: any scale will do, every candidate is equally good.
  const double temperature = options.sigma * (mean > 0 ? mean : 1.0);
  std::vector<double> p(size_t(n) * size_t(n), 0.0);
  for (int k = 0; k < n; ++k) {
    // Candidates and their distance to what would naturally come next.
    std::vector<std::pair<int, double>> cand;
    for (int l = 0; l < n; ++l) {
      const bool successor = k + 1 < n && l == k + 1;
      const bool room = l + h <= n - 1;
      if (k + 1 < n) {
        if (successor || room) cand.push_back({l, dist(k + 1, l)});
      } else if (l >= 1 && room) {
        cand.push_back({l, dist(k, l - 1)});  // the last frame: its look-alike's successor
      }
    }
    // Weights relative to the best candidate, so they never all underflow.
    double best = 1e300;
    for (const auto& c : cand) best = std::min(best, c.second);
    double z = 0;
    for (const auto& c : cand) z += std::exp(-(c.second - best) / temperature);
    for (const auto& c : cand) {
      p[size_t(k) * size_t(n) + size_t(c.first)] = std::exp(-(c.second - best) / temperature) / z;
    }
  }
  return p;
}

std::vector<BlendFrame> endlessWalk(const std::vector<double>& probabilities, int n, int length,
                                    const VideoTextureOptions& options) {
  checkOptions(n, options);
  if (length < 1) throw InputError("frames: must be >= 1, got " + std::to_string(length));
  if (probabilities.size() != size_t(n) * size_t(n)) {
    throw InputError("basic volumes: transition matrix does not match " + std::to_string(n) +
                     " volumes");
  }
  const int h = options.dissolve_frames;
  Rng rng(options.seed);
  std::vector<BlendFrame> out;
  out.reserve(size_t(length));
  out.push_back({0, 0, 1.0});
  int cur = 0;
  while (int(out.size()) < length) {
    // Inverse CDF over row `cur`.
    const double u = rng.uniform();
    double acc = 0;
    int next = -1, last_nonzero = -1;
    for (int l = 0; l < n; ++l) {
      const double q = probabilities[size_t(cur) * size_t(n) + size_t(l)];
      if (q <= 0) continue;
      last_nonzero = l;
      acc += q;
      if (u < acc) {
        next = l;
        break;
      }
    }
    if (next < 0) next = last_nonzero;  // rounding: the row sums to 1 within a few ulps
    if (cur + 1 < n && next == cur + 1) {
      out.push_back({next, next, 1.0});
      cur = next;
      continue;
    }
    if (h == 0) {
      out.push_back({next, next, 1.0});
      cur = next;
      continue;
    }
    for (int t = 0; t < h && int(out.size()) < length; ++t) {
      out.push_back({std::min(cur + 1 + t, n - 1), next + t, 1.0 - double(t + 1) / (h + 1)});
    }
    cur = next + h - 1;
  }
  return out;
}

std::vector<float> blendFrame(const BasicVolumes& frames, const BlendFrame& f) {
  const std::vector<float>& a = frames.at(size_t(f.a));
  const std::vector<float>& b = frames.at(size_t(f.b));
  std::vector<float> out(a.size());
  const float w = float(f.w);
  for (size_t v = 0; v < a.size(); ++v) out[v] = w * a[v] + (1 - w) * b[v];
  return out;
}

double maxFrameChange(const BasicVolumes& frames, const std::vector<BlendFrame>& walk) {
  if (walk.size() < 2 || frames.empty() || frames[0].empty()) return 0;
  double worst = 0;
  std::vector<float> prev = blendFrame(frames, walk[0]);
  for (size_t i = 1; i < walk.size(); ++i) {
    std::vector<float> cur = blendFrame(frames, walk[i]);
    worst = std::max(worst, std::sqrt(squaredDifference(prev, cur) / double(cur.size())));
    prev.swap(cur);
  }
  return worst;
}

double maxInputFrameChange(const BasicVolumes& frames) {
  double worst = 0;
  for (size_t k = 1; k < frames.size(); ++k) {
    worst = std::max(worst, std::sqrt(squaredDifference(frames[k - 1], frames[k]) /
                                      double(std::max<size_t>(1, frames[k].size()))));
  }
  return worst;
}

}  // namespace cloudbake
