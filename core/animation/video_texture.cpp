#include "core/animation/video_texture.h"

#include <algorithm>
#include <atomic>
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
  if (!(o.future_cost >= 0 && o.future_cost <= kMaxFutureCost)) {
    throw InputError("future_cost: alpha must be in [0, " + std::to_string(kMaxFutureCost) +
                     "], got " + std::to_string(o.future_cost));
  }
}

// fn(l, then, cost) for every transition allowed out of frame k: to frame l, at the cost of how
// unlike what would naturally come next it is, after which the walk goes on from frame `then`
// (past the dissolve). Computed from the distances on each call, so the walk holds no n x n
// table beyond them and the probabilities.
//
// A cost is sqrt(D), Schoedl et al.'s exponent p = 1/2: for a cloud that evolves smoothly D
// grows as the square of the frames between, so with D itself a loop of g frames costs g per
// frame and future costs (which minimise the cost per frame played) settle in the shortest
// loops there are; with sqrt(D) every loop length costs alike, and the walk keeps to long ones
// (an outside probe: a dissolve of 2 frames trapped the walk in volumes 0-5 of 12).
template <typename Fn>
void forTransitions(const std::vector<double>& distances, int n, int h, int k, Fn&& fn) {
  auto cost = [&](int a, int b) { return std::sqrt(distances[size_t(a) * size_t(n) + size_t(b)]); };
  for (int l = 0; l < n; ++l) {
    const bool successor = k + 1 < n && l == k + 1;
    const bool room = l + h <= n - 1;
    const int then = successor || h == 0 ? l : l + h - 1;
    if (k + 1 < n) {
      if (successor || room) fn(l, then, cost(k + 1, l));
    } else if (l >= 1 && room) {
      fn(l, then, cost(k, l - 1));  // the last frame: its look-alike's successor
    } else if (l == 0 && room) {
      // Volume 0 has no predecessor to look like the last frame: the jump costs the two
      // volumes' own distance (without it a database of 2 volumes froze on its last).
      fn(l, then, cost(k, 0));
    }
  }
}

// Schoedl et al.'s future costs: V(k) = min over transitions (cost + alpha V(then)), by value
// iteration. Sweeping from the last frame down lets a chain of natural successors settle in
// one sweep; only jumps back need more. It converges geometrically (alpha < 1); the cap keeps a
// pathological database from running long, at a tolerance far below any temperature.
std::vector<double> futureCosts(const std::vector<double>& distances, int n, int h, double alpha,
                                const std::function<bool()>& keep_going) {
  std::vector<double> v(size_t(n), 0.0);
  if (alpha <= 0) return v;
  const double scale = std::sqrt(*std::max_element(distances.begin(), distances.end()));
  const double tolerance = 1e-12 * scale / (1 - alpha);
  for (int sweep = 0; sweep < 100000; ++sweep) {
    if (keep_going && !keep_going()) throw Cancelled("the walk's future costs");
    double change = 0;
    for (int k = n - 1; k >= 0; --k) {
      double best = 1e300;
      forTransitions(distances, n, h, k, [&](int, int then, double cost) {
        best = std::min(best, cost + alpha * v[size_t(then)]);
      });
      change = std::max(change, std::abs(best - v[size_t(k)]));
      v[size_t(k)] = best;
    }
    if (change <= tolerance) break;
  }
  return v;
}

}  // namespace

std::vector<double> frameDistances(const BasicVolumes& frames,
                                   const std::function<bool()>& keep_going) {
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
  std::atomic<bool> stop{false};
  parallelFor(0, n, [&](int k) {
    if (stop || (keep_going && !keep_going())) {
      stop = true;
      return;
    }
    for (int l = k + 1; l < n; ++l) {
      d[size_t(k) * size_t(n) + size_t(l)] =
          squaredDifference(frames[size_t(k)], frames[size_t(l)]);
    }
  });
  if (stop) throw Cancelled("the distances between basic volumes");
  for (int k = 0; k < n; ++k)
    for (int l = 0; l < k; ++l)
      d[size_t(k) * size_t(n) + size_t(l)] = d[size_t(l) * size_t(n) + size_t(k)];
  return d;
}

std::vector<double> transitionProbabilities(const std::vector<double>& distances, int n,
                                            const VideoTextureOptions& options,
                                            const std::function<bool()>& keep_going) {
  if (n < 2 || distances.size() != size_t(n) * size_t(n)) {
    throw InputError("basic volumes: a distance matrix of " + std::to_string(n) +
                     "^2 entries needs at least 2 volumes");
  }
  checkOptions(n, options);
  const int h = options.dissolve_frames;
  const std::vector<double> v = futureCosts(distances, n, h, options.future_cost, keep_going);
  double mean = 0;
  for (int k = 0; k < n; ++k) {
    for (int l = 0; l < n; ++l) {
      mean += k == l ? 0.0 : std::sqrt(distances[size_t(k) * size_t(n) + size_t(l)]);
    }
  }
  mean /= double(n) * double(n - 1);
  // Identical frames everywhere: any scale will do, every candidate is equally good.
  const double temperature = options.sigma * (mean > 0 ? mean : 1.0);
  std::vector<double> p(size_t(n) * size_t(n), 0.0);
  for (int k = 0; k < n; ++k) {
    double* row = &p[size_t(k) * size_t(n)];
    // D'' per target (kept in the row), then weights relative to the best, so they never all
    // underflow.
    std::vector<int> targets;
    double best = 1e300;
    forTransitions(distances, n, h, k, [&](int l, int then, double cost) {
      row[l] = cost + options.future_cost * v[size_t(then)];
      targets.push_back(l);
      best = std::min(best, row[l]);
    });
    double z = 0;
    for (int l : targets) z += std::exp(-(row[l] - best) / temperature);
    for (int l : targets) row[l] = std::exp(-(row[l] - best) / temperature) / z;
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
